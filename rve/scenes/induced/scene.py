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
rest to ``time.t_end`` with ONE ``rve.solvers.dirk.integrate`` call (the thesis's steps
of ``t_end/steps``, or with ``time.adaptive.enabled`` error-controlled steps landing on the
store grid: ``adaptive_control``) (so the stage predictor's
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
(``frames.png``, ``temperature.png``) and the summary (orientation,
t_end_ms, steps_accepted, steps_rejected, newton_iterations, dofs, mean_displacement_mm,
max_temperature_K, terminal_current_A, charge_balance_error, energy_balance_error,
wall_time_s). A failed integration raises ``SceneFailure`` (last good state; ``run`` saves
it to ``induced_deformation_last_good_state.npz``).

Friction (``cfg.friction``, some mu > 0; ``InducedProblem.friction``, a
``rve.scenes.dynamic_friction.DynamicFriction``): the history is committed after every
accepted step, before the balances (which then include the friction terms) and the map
rebuilds. mu = 0: the frictionless scene.

Set-up: ``rve.fabrics.slack.slack_weave`` (single-fibril yarns, L0 = 12.5 mm natural
length between ends 10 mm apart, crimped so that the fibrils start unstretched and apart).
Every fibril end's centroid pinned (directors free). Warp: V = 0 at the x+ end, the mixed
condition J_n = r_bar V + J_bar at the x- end (J_bar < 0: current along +x). Weft: the
weakened insulation of §8.2 at the y- end (r_bar = 0.001, J_bar = 0: a pull-down to 0 V),
insulated at the y+ end. T = 0 at every end. B = |B| * orientation (B1, B2, B3 or a vector).
"""
from __future__ import annotations

import logging
import time
import tracemalloc
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..dynamic_wire import field_ramp  # the one C2 switch-on of B
from ...fem.assembly import DofLayout
from ...fabrics.setup import contact_params
from ...model import BeamMaterial, BeamModel, CircuitBC, ContactSystem, Couplings, DirichletBC
from ...model import RowScaledSystem
from ...solvers.dirk import AdaptiveControl, IntegrationFailure, integrate, sdirk
from ...solvers.dirk import integrator_options as integrator_options_of
from ...model.balances import StateBalances
from ...model.thermal_post import ThermalOperators
from ..thermal_post import ThermalPostSolver
from ..dynamic_friction import DynamicFriction, FrictionBalances, contact_params_with_friction
from .record import InducedRecorder, induced_summary
from ..rebuild import MapRebuild
from ...fabrics.slack import slack_weave
from ..protocol import SceneFailure, SceneResult

__all__ = ["InducedProblem", "setup", "solve", "run", "field_vector", "field_ramp", "warp_circuit",
           "adaptive_control"]

log = logging.getLogger("rve.scenes.induced")


def field_vector(cfg) -> np.ndarray:
    """B (kT) of the config: |B| times the normalised orientation."""
    from ...config.induced_deformation import ORIENTATIONS

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
    #: the friction between fibrils (``rve.scenes.dynamic_friction``), None when frictionless
    friction: DynamicFriction | None = None

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
    params = contact_params_with_friction(contact_params(k, k.rebuild_every), cfg.friction)
    x0 = np.zeros(base.n)
    base.nodal(x0)[:, :9] = weave.x0
    system = ContactSystem(base, params, x0)
    info = {"amplitude_warp_mm": weave.amplitude_warp, "amplitude_weft_mm": weave.amplitude_weft,
            "initial_clearance_mm": weave.clearance, "B_kT": [float(v) for v in B]}
    return InducedProblem(system, weave, mode, x0, circuit_in, circuit_leak, dirichlet_V, ends.ravel(), ends, info,
                          DynamicFriction.of(system, weave.direction))


def adaptive_control(cfg) -> AdaptiveControl:
    """The ``AdaptiveControl`` of ``time.adaptive``; the steps land on the store grid
    (``time.store_every`` nominal steps), so the stored states are on fixed times."""
    a = cfg.time.adaptive
    return AdaptiveControl(rtol=a.rtol, atol=a.atol, atol_w=a.atol_velocity, safety=a.safety,
                           min_factor=a.min_factor, max_factor=a.max_factor, hold_band=a.hold_band,
                           controller=a.controller, h_max=a.h_max, land_every=cfg.time.store_every)


def _initial_w(problem, system, x0, t0, nopts):
    from ...solvers.dirk import consistent_initialization

    w0 = np.zeros(system.n)
    return consistent_initialization(system, x0, w0, t0, nopts)


def _induced_start(cfg, problem, h0, tab, nopts, record, progress, t_end, post_reuse):
    """The row-scaled system, the consistent start ``w`` and the recorder of ``solve``."""
    sysm, base = problem.system, problem.model
    x = problem.x0.copy()
    rs = RowScaledSystem(sysm, base.row_scales(h0, x, np.zeros(base.n)))
    thermal = ThermalOperators(sysm, cfg.contact.heat_transfer, problem.fixed_T_nodes)
    post = None
    if problem.mode == "post":
        post = ThermalPostSolver(thermal, tab, cfg.end_temperature, reuse=post_reuse)
    balances = StateBalances(sysm, thermal, problem.circuit_in, problem.circuit_leak, problem.dirichlet_V)
    if problem.friction is not None:
        balances = FrictionBalances(balances, problem.friction)
    w, _ = _initial_w(problem, rs, x, 0.0, nopts)
    T0 = None
    if post is not None:  # the clamped ends at the end temperature, the rest at the reference
        T0 = np.zeros(base.mesh.n_nodes)
        T0[problem.fixed_T_nodes] = cfg.end_temperature
    rec = InducedRecorder(problem, rs, balances, thermal, post, T0, x, w, cfg.time.store_every, t_end, record,
                          progress)
    return rs, x, w, rec


def solve(cfg, *, record: bool = True, mode: str | None = None, t_end: float | None = None,
          steps: int | None = None, progress: bool = False, integrator_options: dict | None = None,
          measure_memory: bool = False, post_reuse: bool = True) -> SceneResult:
    """Run the scene in memory (module docstring). ``t_end``/``steps`` override the config
    (short horizons for tests and the convergence study); ``post_reuse`` False: the T
    post-solve without reuse (``ThermalPostSolver(reuse=False)``, the reference of the
    tests and benchmarks). Raises ``SceneFailure``."""
    wall0 = time.perf_counter()
    if measure_memory:
        tracemalloc.start()
    problem = setup(cfg, mode)
    sysm, base = problem.system, problem.model
    t_end = float(cfg.time.t_end if t_end is None else t_end)
    steps = int(cfg.time.steps if steps is None else steps)
    tab = sdirk(cfg.time.stages)
    nopts = {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}
    iopts = integrator_options_of(**{
        "max_cuts": cfg.time.max_cuts, "fixed_step": not cfg.time.step_control,
        "jacobian_reuse": cfg.newton.jacobian_reuse, "reuse_contraction": cfg.newton.reuse_contraction,
        "linear_backend": None if cfg.newton.linear_backend in (None, "auto") else cfg.newton.linear_backend,
        **({"adaptive": adaptive_control(cfg)} if cfg.time.adaptive.enabled else {}),
        **(integrator_options or {})})
    rs, x, w, rec = _induced_start(cfg, problem, t_end / steps, tab, nopts, record, progress, t_end, post_reuse)
    if iopts.get("adaptive") is not None:   # the steps land on the store grid: store by time there
        rec.store_dt = iopts["adaptive"].land_every * t_end / steps
    every = cfg.contact.rebuild_every if cfg.contact.rebuild == "every" else None
    hook = MapRebuild(sysm, t_end, every, 0.5 * float(sysm.params.margin))
    sysm.rebuild(x)
    # with friction the accepted step is the history of the next (committed before the
    # balances read it and before a map rebuild carries it)
    on_step = rec.on_step if problem.friction is None else problem.friction.on_step(rec.on_step)
    ti = time.perf_counter()
    try:
        res = integrate(rs, x, w, 0.0, t_end, steps, stages=tab.stages, newton_opts=nopts, on_step=on_step,
                        consistent=False, rebuild=hook, **iopts)
        x, w = res.x, res.w
    except IntegrationFailure as exc:
        raise SceneFailure(
            "induced_deformation", f"time integration failed with step size h = {exc.h:.6g} ms: {exc}",
            phase="time integration", time=exc.t, step=f"h = {exc.h:.6g} ms",
            state={"x": exc.x, "w": exc.w, "T": rec.T_of(exc.w)}, model=base,
            details={"h": exc.h, "residuals": [float(r) for r in exc.residuals],
                     "history": {"stored": rec.stored, "balances": {"t": rec.bal_t, **rec.bal}}}) from exc
    wall = {"integration": time.perf_counter() - ti, **rec.wall, "rebuild": hook.wall}
    summary, errs = induced_summary(cfg, problem, rec, tab, t_end, t_end / steps, res, hook, wall, wall0, x, w)
    if measure_memory:
        summary["peak_memory_MiB"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    if record:
        summary["history"] = {"stored": {k: np.asarray(v) for k, v in rec.stored.items()},
                              "balances": rec.history(), "balance_series": errs["series"],
                              "h": np.asarray(rec.h_used)}
    return SceneResult(state={"x": x, "w": w, "T": rec.T_of(w)}, model=base, summary=summary)


def run(cfg, out_dir: Path) -> dict:
    from .outputs import write_outputs

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
