"""What the induced-deformation run keeps while it integrates: the recorder of the balances
and stored states, and the summary.

Contract
--------
* ``InducedRecorder(problem, system, balances, thermal, post, T0, x0, w0, store_every,
  t_end, record)``: ``T_of(w)`` is the temperature of a state (the post-solve's T, or the
  monolithic T dofs); ``on_step(t, x, w, info)`` is the integrator's callback: the counters,
  the thermal post-solve on the step's converged stage states (``info.stage_states``), the
  balances of the accepted state (reusing the residual of its last stage evaluation when
  ``system.residual_at`` has it) and, every ``store_every`` steps and at ``t_end``, the
  stored state (with ``store_dt`` set, error-controlled steps: at the times k store_dt, where
  the steps land). ``history()`` gives the balance series as arrays.
* ``induced_summary(cfg, problem, rec, tab, t_end, h0, res, hook, wall, x, w) -> (summary,
  errors)``: the summary of ``rve.scenes.induced.solve`` (its module docstring).
"""
from __future__ import annotations

import logging
import time

import numpy as np

from ...model.balances import balance_errors

__all__ = ["InducedRecorder", "induced_summary"]

log = logging.getLogger("rve.scenes.induced")


class InducedRecorder:
    """The balances, stored states and counters of one induced-deformation run."""

    def __init__(self, problem, system, balances, thermal, post, T0, x0, w0, store_every: int, t_end: float,
                 record: bool, progress: bool = False):
        self.problem, self.system, self.balances, self.thermal, self.post = problem, system, balances, thermal, post
        self.base = problem.model
        self.T = T0
        self.store_every, self.t_end, self.record, self.progress = int(store_every), float(t_end), record, progress
        self.wall0 = time.perf_counter()
        b0 = balances(x0, w0, 0.0, self.T_of(w0))
        b0["contact_active_pairs"] = float(problem.system.term.active_pairs(x0).size)
        self.bal_t = [0.0]
        self.bal = {k: [v] for k, v in b0.items()}
        self.stored = {"t": [0.0], "x": [self.base.nodal(x0)[:, :9].copy()], "w": [w0.copy()], "T": [self.T_of(w0)]}
        self.counters = {"steps": 0, "linear_solves": 0, "residual_reused": 0, "factorizations": 0, "jacobians": 0,
                         "since_store": 0}
        self.stage_its: list = []
        self.wall = {"balances": 0.0}
        self.store_dt = None   # error-controlled steps: store on the time grid k store_dt instead of by count
        self.h_used: list = []

    def T_of(self, w):
        return self.T if self.post is not None else self.base.nodal(w)[:, self.base.oT].copy()

    def on_step(self, t, x, w, info) -> None:
        c = self.counters
        c["steps"] += 1
        self.stage_its.append(list(info.stage_iterations))
        c["linear_solves"] += info.linear_solves
        c["factorizations"] += info.factorizations
        c["jacobians"] += info.jacobians
        if self.post is not None:
            self.T = self.post.step(self.T, info.stage_states, info.t, info.h)
        F_end = self.system.residual_at(x, w, t)
        c["residual_reused"] += int(F_end is not None)
        tb = time.perf_counter()
        b = self.balances(x, w, t, self.T_of(w), F_end)
        b["contact_active_pairs"] = float(self.thermal.active_pairs(x).size)  # memoised by the post-solve / balances
        for k, v in b.items():
            self.bal[k].append(v)
        self.bal_t.append(t)
        self.wall["balances"] += time.perf_counter() - tb
        c["since_store"] += 1
        self.h_used.append(info.h)
        due = (c["since_store"] >= self.store_every if self.store_dt is None
               else abs(t / self.store_dt - round(t / self.store_dt)) < 1e-6)
        if self.record and (due or t >= self.t_end * (1 - 1e-12)):
            c["since_store"] = 0
            self.stored["t"].append(t)
            self.stored["x"].append(self.base.nodal(x)[:, :9].copy())
            self.stored["w"].append(np.array(w, copy=True))
            self.stored["T"].append(self.T_of(w))
        if self.progress and c["steps"] % 100 == 0:
            log.info("t = %.5g / %.5g ms: %d steps accepted, %d Newton iterations, max T %.3g K, %.1f s",
                     t, self.t_end, c["steps"], sum(map(sum, self.stage_its)), float(np.max(self.T_of(w))),
                     time.perf_counter() - self.wall0)

    def history(self) -> dict:
        return {"t": np.asarray(self.bal_t), **{k: np.asarray(v) for k, v in self.bal.items()}}


def _wall_split(sysm, post, wall: dict, wall0: float) -> dict:
    stats = sysm.stats
    wall_post = post.wall if post is not None else 0.0
    wall["thermal_post"] = wall_post
    wall["assembly"] = stats.get("base_s", 0.0)
    wall["contact"] = stats.get("contact_s", 0.0) + wall["rebuild"]
    wall["linear_solves_and_other"] = wall["integration"] - stats.get("base_s", 0.0) - stats.get("contact_s", 0.0) \
        - wall_post - wall["balances"]
    wall["total"] = time.perf_counter() - wall0
    return wall


def induced_summary(cfg, problem, rec: InducedRecorder, tab, t_end, h0, res, hook, wall: dict, wall0: float, x, w):
    """``(summary, balance errors)`` of ``solve`` (module docstring of the scene)."""
    base, mesh, post, c = problem.model, problem.model.mesh, rec.post, rec.counters
    hist_bal = rec.history()
    errs = balance_errors(hist_bal)
    newton_acc = int(sum(sum(s) for s in rec.stage_its))
    xn = base.nodal(x)[:, :3]
    warp_nodes = np.concatenate([mesh.fibril_nodes(f) for f in problem.weave.warp])
    disp = (xn[warp_nodes] - problem.x0.reshape(mesh.n_nodes, -1)[warp_nodes, :3]).mean(axis=0)
    n_stages = max(1, len(rec.stage_its) * tab.stages)
    orientation = cfg.field.orientation
    return {
        "orientation": orientation if isinstance(orientation, str) else [float(v) for v in orientation],
        "B_kT": problem.info["B_kT"], "temperature_mode": problem.mode,
        "t_end_ms": t_end, "h_nominal_ms": h0, "stages": tab.stages,
        "time_control": "adaptive" if rec.store_dt is not None else "fixed",
        "steps_accepted": c["steps"], "steps_rejected": res.rejected,
        "steps_rejected_by_error": res.error_rejections,
        "step_ms": {"min": float(np.min(rec.h_used)), "median": float(np.median(rec.h_used)),
                    "max": float(np.max(rec.h_used))} if rec.h_used else {},
        "newton_iterations": newton_acc, "newton_iterations_per_stage": newton_acc / n_stages,
        "linear_solves": c["linear_solves"], "factorizations": c["factorizations"],
        "jacobian_evaluations": c["jacobians"],
        "contact_structure_changes": hook.changes, "integrator_restarts": res.restarts,
        "balance_residuals_reused": c["residual_reused"],
        "contact_rebuilds": int(problem.system.stats.get("rebuilds", 0)), "extra_rebuilds": hook.early,
        "dofs": {**base.dof_counts(), **({"thermal_post_solve": int(mesh.n_nodes)} if post is not None else {})},
        "mean_displacement_mm": [float(v) for v in disp],
        "max_temperature_K": float(np.max(rec.T_of(w))),
        "terminal_current_A": float(hist_bal["current_in"][-1]),
        "terminal_currents_A": [float(v) for v in hist_bal["terminal_currents"][-1]],
        "leak_current_A": float(hist_bal["current_leak"][-1]),
        "charge_balance_error": errs["charge"], "energy_balance_error": errs["total"],
        "balance_errors": {k: errs[k] for k in ("charge", "electrical", "mechanical", "thermal", "total")},
        "energies_mJ": {k: errs[k] for k in ("work_lorentz_mJ", "work_circuit_mJ", "joule_heat_mJ", "damping_mJ",
                                             "delta_mechanical_energy_mJ", "friction_work_mJ",
                                             "friction_dissipated_mJ", "friction_elastic_energy_mJ") if k in errs},
        "contact_active_pairs_max": int(max(rec.bal["contact_active_pairs"])),
        "thermal_post_solves": post.solves if post is not None else 0,
        "thermal_post_refinements": getattr(post, "refinements", 0),
        "thermal_post_fallbacks": getattr(post, "fallbacks", 0),
        "geometry": problem.info,
        "wall_time_s": _wall_split(problem.system, post, wall, wall0),
    }, errs
