"""Scene: induced deformation (thesis §8.3, Table 8.1, Appendix A): a current-carrying slack
plain weave moved by a magnetic field, mechanics + potential (+ temperature) + contact
integrated with SDIRK (docs/induced_deformation.md).

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
``setup(cfg, mode=None) -> InducedProblem``: the ``ContactSystem`` of the validated
``InducedDeformationConfig`` (``rve.config.induced_deformation``) with its boundary
conditions, the initial state and the circuit bookkeeping; ``mode`` "post" (fields mech, V;
T post-solved after every accepted step) or "monolithic" (mech, T, V).
``solve(cfg, record=True) -> SceneResult``: integrates from the crimped initial state at
rest to ``time.t_end`` with ONE ``rve.solvers.dirk.integrate`` call (so the stage predictor's
history and the kept stage factorisation of the modified Newton survive the contact-map
rebuilds); the map is rebuilt from ``on_step`` every ``contact.rebuild_every`` accepted steps
that end on the nominal grid (Appendix A), and at once when a centroid has moved half the
search margin since the last rebuild. A rebuild that changes the union sparsity pattern
leaves the stepper's mass matrix on the old pattern (same values: the solvers' triplet path
assembles the stage matrix then; counted in ``contact_structure_changes``). ``state`` ``x``,
``w``, ``T`` at t_end; ``summary`` the figures of ``run``; with ``record`` the stored states
(every ``time.store_every`` accepted steps) and the balance terms of every accepted step
under ``"history"``.
``run(cfg, out_dir) -> dict``: ``solve`` + ``induced_deformation.nc`` (netCDF time series),
``tubes/induced.pvd`` (tube meshes coloured by current and temperature), PNG frames
(``frames.png``, ``temperature.png``) and the summary (keys of issue 11: orientation,
t_end_ms, steps_accepted, steps_rejected, newton_iterations, dofs, mean_displacement_mm,
max_temperature_K, terminal_current_A, charge_balance_error, energy_balance_error,
wall_time_s). A failed integration raises ``SceneFailure`` (last good state; ``run`` saves
it to ``induced_deformation_last_good_state.npz``).

Set-up: ``rve.scenes.induced_fabric.slack_weave`` (single-fibril yarns, L0 = 12.5 mm natural
length between ends 10 mm apart, crimped so that the fibrils start unstretched and apart).
Every fibril end's centroid pinned (directors free). Warp: V = 0 at the x+ end, the mixed
condition J_n = r_bar V + J_bar at the x- end (J_bar < 0: current along +x). Weft: the
weakened insulation of §8.2 at the y- end (r_bar = 0.001, J_bar = 0: a pull-down to 0 V),
insulated at the y+ end. T = 0 at every end. B = |B| * orientation (B1, B2, B3 or a vector).
"""
from __future__ import annotations

import logging
import math
import time
import tracemalloc
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .dynamic_wire import field_ramp  # the one C2 switch-on of B
from ..fem.assembly import DofLayout
from ..fabrics.setup import contact_params
from ..model import BeamMaterial, BeamModel, CircuitBC, ContactSystem, Couplings, DirichletBC
from ..model import RowScaledSystem
from ..solvers.dirk import IntegrationFailure, integrate, sdirk
from .induced_balances import StateBalances, ThermalOperators, ThermalPostSolver, balance_errors
from .induced_fabric import slack_weave
from .protocol import SceneFailure, SceneResult

__all__ = ["InducedProblem", "setup", "solve", "run", "field_vector", "field_ramp", "warp_circuit"]

log = logging.getLogger("rve.scenes.induced_deformation")


def field_vector(cfg) -> np.ndarray:
    """B (kT) of the config: |B| times the normalised orientation."""
    from ..config.induced_deformation import ORIENTATIONS

    o = cfg.field.orientation
    d = np.asarray(ORIENTATIONS[o] if isinstance(o, str) else o, float)
    return cfg.field.magnitude * d / np.linalg.norm(d)


@dataclass
class InducedProblem:
    system: ContactSystem
    weave: object
    mode: str
    x0: np.ndarray
    circuit_in: list
    circuit_leak: list
    dirichlet_V: np.ndarray
    fixed_T_nodes: np.ndarray
    ends: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def model(self) -> BeamModel:
        return self.system.base


def warp_circuit(weave, layout, ends, cfg):
    """The circuit of §8.3 on a weave: every warp driven at its first end (``CircuitBC``
    with ``cfg.warp.r_bar``, ``cfg.warp.J_bar``) and grounded at its last (returned as the
    V dofs to hold at 0), every weft on the weakened insulation at its first end
    (``cfg.weft``). ``ends``: (n_fibrils, 2) end nodes. -> (circuit_in, circuit_leak, dirichlet_V)."""
    mesh = weave.mesh
    area = np.pi * mesh.radius ** 2
    circuit_in = [CircuitBC(int(ends[f, 0]), cfg.warp.r_bar, cfg.warp.J_bar, float(area[f])) for f in weave.warp]
    circuit_leak = [CircuitBC(int(ends[f, 0]), cfg.weft.r_bar, cfg.weft.J_bar, float(area[f])) for f in weave.weft]
    dirichlet_V = layout.dofs("V", [int(ends[f, 1]) for f in weave.warp])
    return circuit_in, circuit_leak, dirichlet_V


def setup(cfg, mode: str | None = None) -> InducedProblem:
    """The problem of the scene (module docstring); no solve."""
    mode = mode or cfg.coupling.temperature
    if mode not in ("post", "monolithic"):
        raise ValueError(f"coupling.temperature must be 'post' or 'monolithic', got {mode!r}")
    m = cfg.material
    if mode == "post" and (m.seebeck != 0.0 or m.alpha_mu != 0.0):
        raise ValueError("coupling.temperature = 'post' needs S = 0 and alpha_mu = 0 (T feeds back otherwise)")
    g = cfg.geometry
    weave = slack_weave(g.n_warp, g.n_weft, g.span, g.natural_length, cfg.warp.radius, cfg.weft.radius,
                        cfg.mesh.elements)
    mesh = weave.mesh
    fields = ("mech", "T", "V") if mode == "monolithic" else ("mech", "V")
    layout = DofLayout(mesh.n_nodes, fields)
    ends = np.array([mesh.end_nodes(f) for f in range(mesh.n_fibrils)], dtype=np.int64)  # (nf, 2)
    bcs = [DirichletBC(layout.dofs("r", ends.ravel()), 0.0)]
    circuit_in, circuit_leak, dirichlet_V = warp_circuit(weave, layout, ends, cfg)
    bcs.append(DirichletBC(dirichlet_V, 0.0))
    if mode == "monolithic":
        bcs.append(DirichletBC(layout.dofs("T", ends.ravel()), cfg.end_temperature))
    mat = BeamMaterial(youngs_modulus=m.youngs_modulus, poisson_ratio=m.poisson_ratio, density=m.density,
                       damping=m.damping, electrical_conductivity=m.electrical_conductivity, seebeck=m.seebeck,
                       heat_capacity=m.heat_capacity, thermal_conductivity=m.thermal_conductivity,
                       alpha_mu=m.alpha_mu)
    B = field_vector(cfg)
    c = cfg.coupling
    couplings = Couplings(B=tuple(B), lorentz=c.lorentz, back_emf=c.back_emf, joule=mode == "monolithic",
                          seebeck=False, thermal_softening=False)
    base = BeamModel(mesh, mat, disk_points=cfg.mesh.disk_points, fields=fields, bcs=bcs, couplings=couplings,
                     circuits=circuit_in + circuit_leak, field_ramp=field_ramp(cfg.field.ramp_time))
    k = cfg.contact
    params = contact_params(k, k.rebuild_every)
    x0 = np.zeros(base.n)
    base.nodal(x0)[:, :9] = weave.x0
    system = ContactSystem(base, params, x0)
    info = {"amplitude_warp_mm": weave.amplitude_warp, "amplitude_weft_mm": weave.amplitude_weft,
            "initial_clearance_mm": weave.clearance, "B_kT": [float(v) for v in B]}
    return InducedProblem(system, weave, mode, x0, circuit_in, circuit_leak, dirichlet_V, ends.ravel(), ends, info)


class _StageRecorder:
    """Wraps a system: remembers the last evaluated state at every time (the converged stage
    states of a step are the last evaluations at its stage times, rve.solvers.dirk)."""

    def __init__(self, system, c):
        self.system = system
        self.n, self.mech = system.n, system.mech
        self.last: dict = {}
        self.wall = 0.0
        self.c = [float(v) for v in c]   # stage times of the tableau (all > 0 for SDIRK)
        self.t_accepted, self.attempts, self.accepted, self._attempt = 0.0, 0, 0, None

    def mass(self):
        return self.system.mass()

    def constraints(self, t):
        """The stepper asks for the constraints once per stage, in stage order: a call that is
        not the next stage time t0 + c_i h of the open attempt opens a new step attempt."""
        tau = t - self.t_accepted
        a = self._attempt
        if a is not None and a[1] < len(self.c) and abs(tau - self.c[a[1]] * a[0]) <= 1e-9 * max(a[0], 1e-300):
            self._attempt = (a[0], a[1] + 1)
        else:
            self.attempts += 1
            self._attempt = (tau / self.c[0], 1)
        return self.system.constraints(t)

    def accept(self, t):
        """An attempt was accepted and ended at t."""
        self.accepted += 1
        self.t_accepted = t
        self._attempt = None

    @property
    def rejected(self) -> int:
        return self.attempts - self.accepted

    def admissible(self, x):
        return self.system.admissible(x)

    def evaluate(self, x, w, t, jacobian=True):
        t0 = time.perf_counter()
        out = self.system.evaluate(x, w, t, jacobian)
        self.wall += time.perf_counter() - t0
        self.last[t] = (np.array(x, copy=True), np.array(w, copy=True), np.array(out[0], dtype=float, copy=True))
        return out

    def residual_at(self, x, w, t):
        """F of the last evaluation at time t if it was at exactly (x, w), else None."""
        hit = self.last.get(t)
        if hit is None and self.last:
            tk = max(self.last)  # the step's end time t0 + h may differ from t in the last bit
            hit = self.last[tk] if abs(tk - t) <= 1e-12 * max(1.0, abs(t)) else None
        if hit is not None and np.array_equal(hit[0], x) and np.array_equal(hit[1], w):
            return hit[2]
        return None


class _Restart(Exception):
    """Raised from on_step to restart the integrator after a rebuild changed the sparsity pattern."""

    def __init__(self, t, x, w):
        self.t, self.x, self.w = t, x, w


def _initial_w(problem, system, x0, t0, nopts):
    from ..solvers.dirk import consistent_initialization

    w0 = np.zeros(system.n)
    return consistent_initialization(system, x0, w0, t0, nopts)


def solve(cfg, *, record: bool = True, mode: str | None = None, t_end: float | None = None,
          steps: int | None = None, progress: bool = False, integrator_options: dict | None = None,
          measure_memory: bool = False, post_reuse: bool = True) -> SceneResult:
    """Run the scene in memory (module docstring). ``t_end``/``steps`` override the config
    (short horizons for tests and the convergence study); ``post_reuse`` False: the T
    post-solve's former path (``ThermalPostSolver(reuse=False)``, the reference of the
    tests and benchmarks). Raises ``SceneFailure``."""
    wall0 = time.perf_counter()
    if measure_memory:
        tracemalloc.start()
    problem = setup(cfg, mode)
    mode = problem.mode
    sysm, base = problem.system, problem.model
    mesh = base.mesh
    t_end = float(cfg.time.t_end if t_end is None else t_end)
    steps = int(cfg.time.steps if steps is None else steps)
    h0 = t_end / steps
    tab = sdirk(cfg.time.stages)
    nopts = {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}
    iopts = {"jacobian_reuse": cfg.newton.jacobian_reuse, "reuse_contraction": cfg.newton.reuse_contraction,
             "linear_backend": None if cfg.newton.linear_backend in (None, "auto") else cfg.newton.linear_backend}
    iopts.update(integrator_options or {})
    x = problem.x0.copy()
    scale = base.row_scales(h0, x, np.zeros(base.n))
    rec = _StageRecorder(sysm, tab.c)
    thermal = ThermalOperators(sysm, cfg.contact.heat_transfer, problem.fixed_T_nodes)
    post = ThermalPostSolver(thermal, tab, cfg.end_temperature, reuse=post_reuse) if mode == "post" else None
    balances = StateBalances(sysm, thermal, problem.circuit_in, problem.circuit_leak, problem.dirichlet_V)
    w, init = _initial_w(problem, RowScaledSystem(sysm, scale), x, 0.0, nopts)
    T = np.full(mesh.n_nodes, cfg.end_temperature) if mode == "post" else None

    def T_of(w_):
        return T if mode == "post" else base.nodal(w_)[:, base.oT].copy()

    if mode == "post":
        T = np.zeros(mesh.n_nodes) + 0.0
        T[problem.fixed_T_nodes] = cfg.end_temperature
    bal_t = [0.0]
    b0 = balances(x, w, 0.0, T_of(w))
    b0["contact_active_pairs"] = float(sysm.term.active_pairs(x).size)
    bal = {k: [v] for k, v in b0.items()}
    stored = {"t": [0.0], "x": [base.nodal(x)[:, :9].copy()], "w": [w.copy()], "T": [T_of(w)]}
    guard = 0.5 * float(sysm.params.margin)
    wall = {"integration": 0.0, "balances": 0.0, "thermal_post": 0.0, "rebuild": 0.0}
    counters = {"steps": 0, "rejected": 0, "newton": 0, "linear_solves": 0, "extra_rebuilds": 0,
                "structure_changes": 0, "residual_reused": 0, "factorizations": 0, "jacobians": 0,
                "integrate_calls": 0, "stage_iterations": [], "since_store": 0, "since_rebuild": 0}
    kk = max(1, int(cfg.contact.rebuild_every))

    def on_step(t, x_, w_, info):
        nonlocal T
        counters["steps"] += 1
        rec.accept(t)
        counters["stage_iterations"].append(list(info.stage_iterations))
        counters["linear_solves"] += info.linear_solves
        counters["factorizations"] += info.factorizations
        counters["jacobians"] += info.jacobians
        if post is not None:
            stages = []
            for i in range(tab.stages - 1):
                ti = info.t + tab.c[i] * info.h
                stages.append(rec.last[ti][:2])
            stages.append((x_, w_))
            T = post.step(T, stages, info.t, info.h)
        F_end = rec.residual_at(x_, w_, t)
        counters["residual_reused"] += int(F_end is not None)
        rec.last.clear()
        tb = time.perf_counter()
        b = balances(x_, w_, t, T_of(w_), F_end)
        b["contact_active_pairs"] = float(thermal.active_pairs(x_).size)  # memoised by the post-solve / balances
        for k_, v in b.items():
            bal[k_].append(v)
        bal_t.append(t)
        wall["balances"] += time.perf_counter() - tb
        counters["since_store"] += 1
        if record and (counters["since_store"] >= cfg.time.store_every or t >= t_end * (1 - 1e-12)):
            counters["since_store"] = 0
            stored["t"].append(t)
            stored["x"].append(base.nodal(x_)[:, :9].copy())
            stored["w"].append(np.array(w_, copy=True))
            stored["T"].append(T_of(w_))
        if progress and counters["steps"] % 100 == 0:
            log.info("t = %.5g / %.5g ms: %d steps accepted, %d Newton iterations, max T %.3g K, %.1f s",
                     t, t_end, counters["steps"], sum(map(sum, counters["stage_iterations"])),
                     float(np.max(T_of(w_))), time.perf_counter() - wall0)
        # contact map: rebuilt every ``rebuild_every`` accepted steps (Appendix A),
        # and at once when a centroid has moved half the search margin since the last rebuild
        counters["since_rebuild"] += 1
        if t >= t_end * (1 - 1e-12):
            return
        early = guard > 0 and sysm.max_displacement_since_rebuild(x_) > guard
        if early or counters["since_rebuild"] >= kk:
            tr_ = time.perf_counter()
            kept = sysm.assembler.reused
            sysm.rebuild(x_)
            changed = sysm.assembler.reused == kept
            counters["structure_changes"] += int(changed)
            counters["extra_rebuilds"] += int(early and counters["since_rebuild"] < kk)
            counters["since_rebuild"] = 0
            wall["rebuild"] += time.perf_counter() - tr_
            if changed:  # a new sparsity pattern: restart the integrator on it (fast stage-matrix path)
                raise _Restart(t, x_, w_)

    t = 0.0
    sysm.rebuild(x)
    while t < t_end * (1 - 1e-12):
        n_left = max(1, int(math.ceil((t_end - t) / h0 - 1e-6)))   # the nominal grid from t (t on it but after an early rebuild)
        ti = time.perf_counter()
        counters["integrate_calls"] += 1
        try:
            res = integrate(RowScaledSystem(rec, scale), x, w, t, t_end, n_left, stages=tab.stages,
                            newton_opts=nopts, max_cuts=cfg.time.max_cuts, on_step=on_step,
                            fixed_step=not cfg.time.step_control, consistent=False, **iopts)
            x, w, t = res.x, res.w, res.t
        except _Restart as stop:
            x, w, t = stop.x, stop.w, stop.t
            if progress:
                log.info("integrator restarted at t = %.6g ms (contact pattern changed)", t)
        except IntegrationFailure as exc:
            wall["integration"] += time.perf_counter() - ti
            raise SceneFailure(
                "induced_deformation", f"time integration failed with step size h = {exc.h:.6g} ms: {exc}",
                phase="time integration", time=exc.t, step=f"h = {exc.h:.6g} ms",
                state={"x": exc.x, "w": exc.w, "T": T_of(exc.w)}, model=base,
                details={"h": exc.h, "residuals": [float(r) for r in exc.residuals],
                         "history": {"stored": stored, "balances": {"t": bal_t, **bal}}}) from exc
        wall["integration"] += time.perf_counter() - ti
    counters["rejected"] = rec.rejected
    # newton iterations: count from the stage iterations of the accepted steps (+ rejected attempts)
    stage_its = counters["stage_iterations"]
    newton_acc = int(sum(sum(s) for s in stage_its))
    hist_bal = {"t": np.asarray(bal_t), **{k_: np.asarray(v) for k_, v in bal.items()}}
    errs = balance_errors(hist_bal)
    wall_post = post.wall if post is not None else 0.0
    wall["thermal_post"] = wall_post
    stats = sysm.stats
    wall["assembly"] = stats.get("base_s", 0.0)
    wall["contact"] = stats.get("contact_s", 0.0) + wall["rebuild"]
    wall["linear_solves_and_other"] = wall["integration"] - rec.wall - wall_post - wall["balances"]
    wall["total"] = time.perf_counter() - wall0
    peak = None
    if measure_memory:
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    xn = base.nodal(x)[:, :3]
    warp_nodes = np.concatenate([mesh.fibril_nodes(f) for f in problem.weave.warp])
    disp = (xn[warp_nodes] - problem.x0.reshape(mesh.n_nodes, -1)[warp_nodes, :3]).mean(axis=0)
    T_final = T_of(w)
    n_stages = max(1, len(stage_its) * tab.stages)
    summary = {
        "orientation": cfg.field.orientation if isinstance(cfg.field.orientation, str)
        else [float(v) for v in cfg.field.orientation],
        "B_kT": problem.info["B_kT"],
        "temperature_mode": mode,
        "t_end_ms": t_end,
        "h_nominal_ms": h0,
        "stages": tab.stages,
        "steps_accepted": counters["steps"],
        "steps_rejected": counters["rejected"],
        "newton_iterations": newton_acc,
        "newton_iterations_per_stage": newton_acc / n_stages,
        "linear_solves": counters["linear_solves"],
        "factorizations": counters["factorizations"],
        "jacobian_evaluations": counters["jacobians"],
        "contact_structure_changes": counters["structure_changes"],
        "integrator_restarts": counters["integrate_calls"] - 1,
        "balance_residuals_reused": counters["residual_reused"],
        "contact_rebuilds": int(stats.get("rebuilds", 0)),
        "extra_rebuilds": counters["extra_rebuilds"],
        "dofs": {**base.dof_counts(), **({"thermal_post_solve": int(mesh.n_nodes)} if mode == "post" else {})},
        "mean_displacement_mm": [float(v) for v in disp],
        "max_temperature_K": float(np.max(T_final)),
        "terminal_current_A": float(hist_bal["current_in"][-1]),
        "terminal_currents_A": [float(v) for v in hist_bal["terminal_currents"][-1]],
        "leak_current_A": float(hist_bal["current_leak"][-1]),
        "charge_balance_error": errs["charge"],
        "energy_balance_error": errs["total"],
        "balance_errors": {k_: errs[k_] for k_ in ("charge", "electrical", "mechanical", "thermal", "total")},
        "energies_mJ": {k_: errs[k_] for k_ in ("work_lorentz_mJ", "work_circuit_mJ", "joule_heat_mJ",
                                                "damping_mJ", "delta_mechanical_energy_mJ")},
        "contact_active_pairs_max": int(max(bal["contact_active_pairs"])),
        "thermal_post_solves": post.solves if post is not None else 0,
        "thermal_post_refinements": getattr(post, "refinements", 0),
        "thermal_post_fallbacks": getattr(post, "fallbacks", 0),
        "geometry": problem.info,
        "wall_time_s": wall,
    }
    if peak is not None:
        summary["peak_memory_MiB"] = peak
    if record:
        summary["history"] = {"stored": {k_: np.asarray(v) for k_, v in stored.items()}, "balances": hist_bal,
                              "balance_series": errs["series"]}
    return SceneResult(state={"x": x, "w": w, "T": T_final}, model=base, summary=summary)


def run(cfg, out_dir: Path) -> dict:
    from .induced_output import write_outputs

    out_dir = Path(out_dir)
    try:
        res = solve(cfg, record=True, progress=True)
    except SceneFailure as failure:
        failure.save(out_dir / "induced_deformation_last_good_state.npz")
        log.error("%s", failure)
        raise
    summary = dict(res.summary)
    hist = summary.pop("history")
    files = write_outputs(cfg, res, hist, out_dir)
    summary["files"] = files
    return summary


def orientation_job(config_path, orientation: str, out_dir, summary_path, log_path, overrides=()) -> dict:
    """One Snakemake job (workflow/rules/induced_deformation.smk): the scene of ``config_path``
    with ``field.orientation = orientation`` (+ ``overrides``), outputs under ``out_dir``,
    the summary written (atomically) to ``summary_path``, the log to ``log_path``."""
    import json

    from ..config.loader import load_config
    from ..io.atomic import atomic_write_text
    from .registry import run_scene

    handler = logging.FileHandler(log_path, mode="w")
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    root = logging.getLogger("rve")
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    try:
        cfg = load_config(config_path, [f"field.orientation={orientation}", *overrides])
        summary = run_scene(cfg, out_dir)
        atomic_write_text(Path(summary_path), json.dumps(summary, indent=2, default=str))
        return summary
    finally:
        root.removeHandler(handler)
        handler.close()
