"""What the impact run keeps while it integrates: the recorder of the per-step series, the
resumable checkpoint and the summary.

Contract
--------
* ``ImpactRecorder(problem, balances, post, T0, X0p, L, store_every, t_end, record)``:
  ``record_state(t, x, w)`` appends the balances (``ImpactBalances``), the projectile probes
  and the temperature figures of a state to ``bal`` and ``series``; ``store(t, x, w)``
  appends the fabric / projectile nodal states and T to ``stored``; ``on_step(t, x, w, info)``
  is the integrator's callback: the counters, the thermal post-solve on the step's
  converged stage states (``info.stage_states``), ``record_state`` and, every
  ``store_every`` steps and at ``t_end``, ``store``. ``system``: the row-scaled system the
  integrator solves, if set; its ``residual_at`` hands the balances the residual of the
  last stage's Newton at the step's end state (counted in ``residual_reused``), so they do
  not evaluate it again. ``wall`` holds the seconds of the balances and of the post-solve.
* ``ImpactCheckpoint(path, digest, t_end, steps, friction=None)``: ``save(rec, t, x, w, rebuilds,
  early)`` writes an npz of plain arrays (no pickle: every series is stacked, the counters are
  integers, the run's identity is the digest, ``t_end`` and ``steps``; with ``friction``, a
  ``rve.scenes.dynamic_friction.DynamicFriction``, its history as ``friction/...``);
  ``load(rec)`` fills a fresh recorder from a matching file and returns ``(t, x, w, rebuilds,
  early)``, or None when there is none or it is for another run (the friction history in
  ``friction_arrays``, for ``DynamicFriction.restore`` after the map rebuild).
* ``impact_summary(...) -> (summary, errors)``: the summary of ``rve.scenes.impact.solve``
  (docs/impact.md) and ``impact_balance_errors`` of the run; ``wall_split``: its wall-time split.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from ...model.balances import impact_balance_errors

__all__ = ["ImpactRecorder", "ImpactCheckpoint", "impact_summary", "wall_split", "angular_velocity", "probe"]

log = logging.getLogger("rve.scenes.impact")

SERIES = ("t", "v_com", "v_bottom", "v_top", "omega", "com", "yarn_currents", "max_T", "mean_T",
          "sphere_pairs_active", "contact_active_pairs")
COUNTERS = ("steps", "rejected", "factorizations", "linear_solves", "since_store", "since_checkpoint",
            "residual_reused")


def angular_velocity(q_top, q_bot, v_top, v_bot, L):
    """Rigid-body estimate of §8.4: omega = r x v_rel / (r . r), r = (q_top - q_bot)/2 + L/2 e_z,
    v_rel = (v_top - v_bot)/2 (q: displacements of the end nodes). Arrays (..., 3)."""
    r = 0.5 * (np.asarray(q_top) - np.asarray(q_bot))
    r = r + np.array([0.0, 0.0, 0.5 * L])
    v = 0.5 * (np.asarray(v_top) - np.asarray(v_bot))
    return np.cross(r, v) / np.einsum("...i,...i->...", r, r)[..., None]


def probe(problem, x, w, X0p, L, bal):
    """Projectile CoM velocity, end velocities, omega, sampled yarn currents of a state."""
    sysm = problem.system
    xp, wp = sysm.split(x)[1], sysm.split(w)[1]
    pn, pv = problem.projectile.nodal(xp), problem.projectile.nodal(wp)
    Mp = problem.projectile.assembler.mass()
    rdofs = problem.projectile.layout.dofs("r").reshape(-1, 3)
    mass = float(problem.info["projectile_mass_g"])
    v_com = (Mp @ np.asarray(wp, float))[rdofs].sum(axis=0) / mass
    bot, top = sysm.ends
    om = angular_velocity(pn[top, :3] - X0p[top, :3], pn[bot, :3] - X0p[bot, :3], pv[top, :3], pv[bot, :3], L)
    cur = bal["terminal_currents"]
    return {"v_com": v_com, "v_bottom": pv[bot, :3].copy(), "v_top": pv[top, :3].copy(), "omega": om,
            "com": 0.5 * (pn[bot, :3] + pn[top, :3]),
            "yarn_currents": np.array([cur[problem.sampled[k]] for k in ("minus_y", "plus_y", "edge")])}


class ImpactRecorder:
    """The series, balances, stored states and counters of one impact run (module docstring)."""

    def __init__(self, problem, balances, post, T0, X0p, L: float, store_every: int, t_end: float, record: bool):
        self.problem, self.balances, self.post = problem, balances, post
        self.T, self.X0p, self.L = T0, X0p, float(L)
        self.store_every, self.t_end, self.record = int(store_every), float(t_end), bool(record)
        self.series = {k: [] for k in SERIES}
        self.bal: dict = {}
        self.stored = {"t": [], "x": [], "w": [], "T": [], "xp": []}
        self.stage_its: list = []
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.wall = {"balances": 0.0, "thermal_post": 0.0}
        self.system = None

    def record_state(self, t, x, w, F=None) -> None:
        """``F``: the unscaled residual of the whole system at (x, w, t), if known."""
        tb = time.perf_counter()
        sysm = self.problem.system
        b = self.balances(x, w, t, self.T, F)
        c, r = sysm.positions(x)
        b["contact_active_pairs"] = float(sysm.fabric.active_pairs(sysm.split(x)[0]).size)
        for k, v in b.items():
            self.bal.setdefault(k, []).append(v)
        self.bal.setdefault("t", []).append(t)
        pr = probe(self.problem, x, w, self.X0p, self.L, b)
        s = self.series
        s["t"].append(t)
        for k in ("v_com", "v_bottom", "v_top", "omega", "com", "yarn_currents"):
            s[k].append(pr[k])
        s["max_T"].append(float(self.T.max()))
        s["mean_T"].append(float(self.T.mean()))
        s["sphere_pairs_active"].append(int(sysm.sphere.active_pairs(c, r).size))
        s["contact_active_pairs"].append(b["contact_active_pairs"])
        self.wall["balances"] += time.perf_counter() - tb

    def store(self, t, x, w) -> None:
        sysm = self.problem.system
        xf, xp = sysm.split(x)
        self.stored["t"].append(t)
        self.stored["x"].append(sysm.fabric.nodal(xf)[:, :9].copy())
        self.stored["w"].append(np.array(sysm.split(w)[0], copy=True))
        self.stored["T"].append(self.T.copy())
        self.stored["xp"].append(sysm.projectile.nodal(xp)[:, :9].copy())

    def on_step(self, t, x, w, info) -> None:
        c = self.counters
        c["steps"] += 1
        c["rejected"] += info.rejected_attempts
        c["factorizations"] += info.factorizations
        c["linear_solves"] += info.linear_solves
        self.stage_its.append(list(info.stage_iterations))
        tp = time.perf_counter()
        self.T = self.post.step(self.T, info.stage_states, info.t, info.h)
        self.wall["thermal_post"] += time.perf_counter() - tp
        F_end = None if self.system is None else self.system.residual_at(x, w, t)
        c["residual_reused"] += int(F_end is not None)
        self.record_state(t, x, w, F_end)
        c["since_store"] += 1
        c["since_checkpoint"] += 1
        if self.record and (c["since_store"] >= self.store_every or t >= self.t_end * (1 - 1e-12)):
            c["since_store"] = 0
            self.store(t, x, w)


def _lists(d: dict, prefix: str, npz) -> None:
    """Fill ``d`` with the ``prefix``/key arrays of ``npz`` as lists of their rows."""
    for name in npz.files:
        if name.startswith(prefix):
            d[name[len(prefix):]] = list(npz[name])


class ImpactCheckpoint:
    """The resumable state of an impact run as an npz of plain arrays (module docstring)."""

    def __init__(self, path, digest: str, t_end: float, steps: int, friction=None):
        self.path, self.digest, self.t_end, self.steps = Path(path), str(digest), float(t_end), int(steps)
        self.wall = 0.0
        #: the run's ``DynamicFriction`` (None: frictionless); ``friction_arrays`` its saved history after ``load``
        self.friction, self.friction_arrays = friction, None

    def save(self, rec: ImpactRecorder, t, x, w, rebuilds: int, early: int) -> None:
        from ...io.atomic import atomic_path

        tc = time.perf_counter()
        arrays = {"digest": np.array(self.digest), "t_end": np.array(self.t_end), "steps": np.array(self.steps),
                  "t": np.array(float(t)), "x": np.asarray(x), "w": np.asarray(w), "T": np.asarray(rec.T),
                  "stage_iterations": np.asarray(rec.stage_its, dtype=np.int64).reshape(len(rec.stage_its), -1),
                  "rebuilds": np.array(int(rebuilds)), "early": np.array(int(early))}
        arrays.update({f"counter/{k}": np.array(int(v)) for k, v in rec.counters.items()})
        if self.friction is not None:
            arrays.update(self.friction.arrays())
        for prefix, d in (("series/", rec.series), ("bal/", rec.bal), ("stored/", rec.stored)):
            arrays.update({prefix + k: np.asarray(v) for k, v in d.items() if len(v)})
        with atomic_path(self.path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        self.wall += time.perf_counter() - tc

    def load(self, rec: ImpactRecorder):
        if not self.path.exists():
            return None
        with np.load(self.path, allow_pickle=False) as d:
            if "state" in d.files or not (str(d["digest"]) == self.digest and float(d["t_end"]) == self.t_end
                                          and int(d["steps"]) == self.steps):
                log.warning("checkpoint %s is for another run: starting afresh", self.path)
                return None
            rec.T = d["T"].copy()
            rec.counters.update({k: int(d[f"counter/{k}"]) for k in COUNTERS if f"counter/{k}" in d.files})
            rec.stage_its = [list(map(int, row)) for row in d["stage_iterations"]]
            _lists(rec.series, "series/", d)
            _lists(rec.bal, "bal/", d)
            _lists(rec.stored, "stored/", d)
            if self.friction is not None:
                self.friction_arrays = {k: d[k].copy() for k in d.files if k.startswith("friction/")}
            out = float(d["t"]), d["x"].copy(), d["w"].copy(), int(d["rebuilds"]), int(d["early"])
        log.info("resumed from %s at t = %.6g ms", self.path, out[0])
        return out


def impact_summary(problem, rec: ImpactRecorder, tab, t_end, h0, dt_rule, hook, wall: dict, relax_info,
                   resumed):
    """``(summary, balance errors)`` of ``solve`` (docs/impact.md): counts, the final
    projectile motion, the balance errors, the wall-time split."""
    sysm = problem.system
    fab, proj, series, c = sysm.fabric, sysm.projectile, rec.series, rec.counters
    errs = impact_balance_errors({k: np.asarray(v) for k, v in rec.bal.items()})
    n_st = max(1, len(rec.stage_its) * tab.stages)
    newton_acc = int(sum(sum(s) for s in rec.stage_its))
    yc = np.asarray(series["yarn_currents"][-1])
    omega_x = np.asarray(series["omega"])[:, 0]
    return {
        "t_end_ms": t_end, "h_nominal_ms": h0, "dt_rule_ms": dt_rule, "stages": tab.stages,
        "steps_accepted": c["steps"], "steps_rejected": c["rejected"],
        "newton_iterations": newton_acc, "newton_iterations_per_stage": newton_acc / n_st,
        "factorizations": c["factorizations"], "factorizations_per_stage": c["factorizations"] / n_st,
        "linear_solves": c["linear_solves"], "balance_residuals_reused": c["residual_reused"],
        "contact_rebuilds": hook.rebuilds, "extra_rebuilds": hook.early,
        "dofs": {**fab.base.dof_counts(), "projectile": int(proj.n), "total": int(sysm.n),
                 "thermal_post_solve": int(fab.mesh.n_nodes)},
        "contact_pairs_max": int(max(series["contact_active_pairs"])),
        "sphere_pairs_active_max": int(max(series["sphere_pairs_active"])),
        "projectile_velocity_mm_per_ms": [float(v) for v in series["v_com"][-1]],
        "projectile_angular_velocity_x_rad_per_ms": float(series["omega"][-1][0]),
        "projectile_angular_velocity_x_extreme_rad_per_ms": float(omega_x[np.argmax(np.abs(omega_x))]),
        "yarn_current_A": {"minus_y": float(yc[0]), "plus_y": float(yc[1]), "edge": float(yc[2])},
        "max_temperature_K": float(np.max(rec.T)),
        "momentum_balance_error": max(errs["momentum_projectile"], errs["momentum_total"]),
        "energy_balance_error": errs["total"],
        "balance_errors": {k: errs[k] for k in ("momentum_projectile", "momentum_total", "charge", "electrical",
                                                "mechanical", "thermal", "total")},
        "impulses_Nms": {k: errs[k] for k in ("impulse_sphere_on_projectile_Nms", "impulse_clamp_Nms",
                                              "impulse_lorentz_Nms")},
        "energies_mJ": {k: errs[k] for k in ("work_lorentz_mJ", "work_circuit_mJ", "joule_heat_mJ", "damping_mJ",
                                             "delta_mechanical_energy_mJ", "friction_work_mJ",
                                             "friction_dissipated_mJ", "friction_elastic_energy_mJ",
                                             "friction_work_sphere_mJ", "friction_dissipated_sphere_mJ",
                                             "friction_elastic_energy_sphere_mJ") if k in errs},
        "geometry": problem.info, "sampled_yarns": problem.sampled, "relaxation": relax_info,
        "resumed_from_ms": resumed, "wall_time_s": wall,
    }, errs


def wall_split(sysm, wall: dict, wall0: float) -> dict:
    """The wall-time split of the summary: evaluation parts from the systems' own counters,
    the linear solves and Newton as the rest of the integration."""
    stats = sysm.fabric.stats
    wall["assembly_fabric"] = stats.get("base_s", 0.0)
    wall["contact_fabric"] = stats.get("contact_s", 0.0)
    wall["contact_sphere"] = sysm.stats["sphere_s"]
    wall["compose"] = sysm.stats["compose_s"]
    wall["contact_search"] = wall["contact_rebuild"]
    evaluation = stats.get("base_s", 0.0) + stats.get("contact_s", 0.0) + sysm.stats["sphere_s"] \
        + sysm.stats["compose_s"]
    wall["linear_solve_and_newton"] = wall["integration"] - evaluation - wall["thermal_post"] - wall["balances"] \
        - wall["contact_rebuild"]
    wall["temperature"] = wall["thermal_post"]
    wall["total"] = time.perf_counter() - wall0
    return wall
