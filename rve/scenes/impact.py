"""Scene: electromagnetically enhanced armour (thesis §8.4, Table 8.2; SPEC §9): a projectile
(one director-beam element whose end nodes act as hemispheres) into a current-carrying
plain weave in a magnetic field (docs/impact.md).

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
``setup(cfg, phase="impact") -> ImpactProblem``: the ``ImpactSystem``
(``rve.model.projectile``: fabric ``ContactSystem`` + projectile ``BeamModel`` + sphere
contact) of the validated ``ImpactConfig`` with its boundary conditions and the crimped
start state (projectile above the weave centre, at rest). ``phase="relax"``: the same dofs,
B off, the projectile held, the fabric damped by ``relaxation.damping``.
``relax(cfg) -> (x, info)``: damped dynamic relaxation of the fabric with the projectile
present and at rest; ``load_or_relax(cfg, path)`` reuses a saved relaxed state
(``relaxed_state.npz``: x, config digest of the sections it depends on).
``solve(cfg, x_start=None, ...) -> SceneResult``: from the relaxed state, the projectile gets
``-speed e_z``, B on (a step at t = 0); SDIRK (``time.stages``) over ``time.t_end`` in chunks
of ``contact.rebuild_every`` nominal steps (both contact maps rebuilt before every chunk,
and early when a centroid or an end node moved half the margin); the temperature is
post-solved on the fabric after every accepted step (S = alpha_mu = 0); balances every
accepted step; ``checkpoint`` (path) written every ``time.checkpoint_every`` steps at a
chunk boundary and resumed from when present (same config digest).
``run(cfg, out_dir) -> dict``: load_or_relax + solve + outputs (``rve.scenes.impact_output``)
+ the summary (docs/impact.md).

Sampled yarns: the warp yarns nearest y = -R_p/2 (``minus_y``) and +R_p/2 (``plus_y``) of the
projectile axis, and the warp yarn j = 0 (``edge``, the -y edge).
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import time
import tracemalloc
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..fem.assembly import DofLayout
from ..fabrics.setup import contact_params
from ..model import BeamMaterial, BeamModel, CircuitBC, ContactSystem, Couplings, DirichletBC
from ..model import RowScaledSystem
from ..model.projectile import ImpactSystem, projectile_mesh
from ..model.terms.projectile_contact import SphereContactTerm
from ..solvers.dirk import IntegrationFailure, consistent_initialization, integrate, sdirk
from .impact_balances import ImpactBalances, impact_balance_errors
from .impact_thermal import ImpactThermal
from .induced_balances import ThermalPostSolver
from .induced_deformation import warp_circuit
from .impact_fabric import chord_clearance, taut_weave, weave_with_chord_clearance
from .protocol import SceneFailure, SceneResult

__all__ = ["ImpactProblem", "setup", "relax", "load_or_relax", "solve", "run", "time_step_rule",
           "angular_velocity", "config_digest"]

log = logging.getLogger("rve.scenes.impact")

def time_step_rule(cfg) -> float:
    """Thesis §8.4: dt_max = R_min / (20 v_max), v_max the impact speed (ms)."""
    R_min = min(cfg.warp.radius, cfg.weft.radius)
    return R_min / (20.0 * max(cfg.projectile.speed, 1e-300))


def nominal_steps(cfg) -> int:
    if cfg.time.steps == "auto":
        return int(math.ceil(cfg.time.t_end / time_step_rule(cfg) - 1e-9))
    return int(cfg.time.steps)


def config_digest(cfg, sections=("geometry", "warp", "weft", "material", "projectile", "contact", "mesh",
                                 "relaxation")) -> str:
    """sha256 of the config sections a relaxed state depends on (relaxation.state_file and the
    impact speed excluded)."""
    d = {k: cfg.model_dump(mode="json")[k] for k in sections}
    d.get("relaxation", {}).pop("state_file", None)
    # the factorisation backend changes round-off only (docs/engine.md "Unsymmetric stage matrices": states equal to
    # 4e-15 between superlu_pruned and PARDISO): a checkpoint resumes on another backend
    d.get("newton", {}).pop("linear_backend", None)
    if "time" not in sections:  # a relaxed state: B is off, the circuits and the speed do not matter
        d.get("projectile", {}).pop("speed", None)
        for y in ("warp", "weft", "projectile"):
            d.get(y, {}).pop("J_bar", None)
            d.get(y, {}).pop("r_bar", None)
    return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16]


@dataclass
class ImpactProblem:
    system: ImpactSystem
    weave: object
    x0: np.ndarray
    circuit_in: list
    circuit_leak: list
    projectile_circuits: list
    dirichlet_V: np.ndarray
    fixed_T_nodes: np.ndarray
    ends: np.ndarray
    sampled: dict
    info: dict = field(default_factory=dict)

    @property
    def fabric(self) -> ContactSystem:
        return self.system.fabric

    @property
    def projectile(self) -> BeamModel:
        return self.system.projectile


def field_vector(cfg) -> np.ndarray:
    d = np.asarray(cfg.field.orientation, float)
    return cfg.field.magnitude * d / np.linalg.norm(d)


def setup(cfg, phase: str = "impact") -> ImpactProblem:
    """The problem of the scene (module docstring); no solve."""
    if phase not in ("impact", "relax"):
        raise ValueError(f"phase must be 'impact' or 'relax', got {phase!r}")
    g, R_w, R_f = cfg.geometry, cfg.warp.radius, cfg.weft.radius
    if g.reference == "crimped":
        weave = weave_with_chord_clearance(g.n_warp, g.span, R_w, R_f, cfg.mesh.elements, g.crimp_clearance)
    else:
        weave = taut_weave(g.n_warp, g.span, R_w, R_f, cfg.mesh.elements, g.crimp_clearance, g.pretension, "straight")
    A, L0 = weave.amplitude_warp, float(weave.mesh.elem_length.sum() / weave.mesh.n_fibrils)
    mesh = weave.mesh
    fields = ("mech", "V")
    layout = DofLayout(mesh.n_nodes, fields)
    ends = np.array([mesh.end_nodes(f) for f in range(mesh.n_fibrils)], dtype=np.int64)
    bcs = [DirichletBC(layout.dofs("r", ends.ravel()), 0.0)]
    circuit_in, circuit_leak, dirichlet_V = warp_circuit(weave, layout, ends, cfg)
    bcs.append(DirichletBC(dirichlet_V, 0.0))
    m = cfg.material
    relaxing = phase == "relax"
    mat = BeamMaterial(youngs_modulus=m.youngs_modulus, poisson_ratio=m.poisson_ratio, density=m.density,
                       damping=cfg.relaxation.damping if relaxing else m.damping,
                       electrical_conductivity=m.electrical_conductivity, heat_capacity=m.heat_capacity,
                       thermal_conductivity=m.thermal_conductivity)
    B = np.zeros(3) if relaxing else field_vector(cfg)
    couplings = Couplings(B=tuple(B), lorentz=True, back_emf=True, joule=False, seebeck=False,
                          thermal_softening=False)
    base = BeamModel(mesh, mat, disk_points=cfg.mesh.disk_points, fields=fields, bcs=bcs, couplings=couplings,
                     circuits=circuit_in + circuit_leak)
    k = cfg.contact
    params = contact_params(k, k.rebuild_every)
    xf = np.zeros(base.n)
    base.nodal(xf)[:, :9] = weave.x0
    fabric = ContactSystem(base, params, xf)
    # projectile: one element along z above the weave centre
    pr = cfg.projectile
    Lp = pr.cylinder_length + 2.0 * pr.radius
    top = float(weave.x0[:, 2].max()) + max(R_w, R_f)
    bottom = (pr.offset[0], pr.offset[1], top + pr.gap + pr.radius)
    pmesh = projectile_mesh(pr.radius, Lp, bottom)
    pl = DofLayout(pmesh.n_nodes, fields)
    pbcs = [DirichletBC(pl.dofs("mech"), 0.0)] if relaxing else []
    pmat = BeamMaterial(youngs_modulus=pr.youngs_modulus, poisson_ratio=m.poisson_ratio, density=pr.density,
                        damping=pr.damping, electrical_conductivity=pr.electrical_conductivity)
    parea = float(np.pi * pr.radius ** 2)
    pcirc = [CircuitBC(int(nd), pr.r_bar, pr.J_bar, parea) for nd in pmesh.end_nodes(0)]
    proj = BeamModel(pmesh, pmat, disk_points=cfg.mesh.disk_points, fields=fields, bcs=pbcs, couplings=couplings,
                     circuits=pcirc)
    xp = np.zeros(proj.n)
    proj.nodal(xp)[:, :9] = pmesh.X0
    sphere = SphereContactTerm(mesh, pr.radius, k.penalty, k.margin)
    x0 = np.concatenate([xf, xp])
    system = ImpactSystem(fabric, proj, sphere, x0)
    # sampled warp yarns
    ywarp = weave.x0[[mesh.end_nodes(int(f))[0] for f in weave.warp], 1]
    yc = pr.offset[1]
    sampled = {"minus_y": int(np.argmin(np.abs(ywarp - (yc - 0.5 * pr.radius)))),
               "plus_y": int(np.argmin(np.abs(ywarp - (yc + 0.5 * pr.radius)))), "edge": 0}
    info = {"crimp_amplitude_mm": A, "natural_length_mm": L0, "initial_clearance_mm": weave.clearance,
            "initial_chord_clearance_mm": chord_clearance(weave),
            "B_kT": [float(v) for v in B], "projectile_length_mm": Lp, "projectile_bottom_mm": list(bottom),
            "projectile_mass_g": float(pr.density * parea * Lp), "sampled_warp_y_mm":
                {k_: float(ywarp[v]) for k_, v in sampled.items()}}
    return ImpactProblem(system, weave, x0, circuit_in, circuit_leak, pcirc, dirichlet_V, ends.ravel(), ends, sampled,
                         info)


class ChunkedRebuild:
    """The impact's ``StructureHook`` (rve.solvers.dirk): both contact maps are rebuilt on
    segments of ``contact.rebuild_every`` nominal steps of the grid ``k h0`` from t = 0, and
    early when a centroid or an end node moved half the margin since the last rebuild;
    every rebuild restarts the step control. ``at_boundary(t, x, w)`` runs at every segment
    boundary before the rebuild (progress, checkpoints)."""

    def __init__(self, sysm, t_end: float, steps: int, every: int, guard: float, at_boundary=None):
        self.sysm, self.t_end, self.steps = sysm, float(t_end), int(steps)
        self.h0 = (self.t_end - 0.0) / self.steps
        self.every, self.guard, self.at_boundary = max(1, int(every)), float(guard), at_boundary
        self.t_stop = None
        self.rebuilds, self.early, self.wall = 0, 0, 0.0

    def horizon(self, t: float):
        k_cur = int(math.floor(t / self.h0 + 1e-9))
        k_b = min(self.steps, k_cur + self.every)
        self.t_stop = self.t_end if k_b >= self.steps else k_b * self.h0
        return self.t_stop, max(1, k_b - k_cur)

    def rebuild(self, x) -> None:
        t0 = time.perf_counter()
        self.sysm.rebuild(x)
        self.wall += time.perf_counter() - t0
        self.rebuilds += 1

    def __call__(self, t, x, w) -> bool:
        if t >= self.t_end * (1 - 1e-12):
            return False
        early = self.guard > 0 and self.sysm.max_displacement_since_rebuild(x) > self.guard
        if not (early or t >= self.t_stop):
            return False
        self.early += int(early)
        if self.at_boundary is not None:
            self.at_boundary(t, x, w)
        self.rebuild(x)
        return True


def _integrator_options(cfg, sysm=None) -> dict:
    """Integrator options; the linear backend eliminates the projectile's free dofs (the last
    ones of the restricted stage matrix: its dofs come last and ``FreeDofs`` keeps the order)
    by a Schur complement (rve.scenes.impact_solver)."""
    from .impact_solver import register

    border = 0
    if sysm is not None:
        idx, _ = sysm.constraints(0.0)
        border = int(sysm.n - sysm.nf - np.count_nonzero(np.asarray(idx) >= sysm.nf))
    register(border)
    return {"jacobian_reuse": cfg.newton.jacobian_reuse, "reuse_contraction": cfg.newton.reuse_contraction,
            "linear_backend": cfg.newton.linear_backend}


def _initial_w(sysm, x, scale, nopts, t=0.0, w=None):
    w0 = np.zeros(sysm.n) if w is None else w
    return consistent_initialization(RowScaledSystem(sysm, scale), x, w0, t, nopts)


def relax(cfg, progress: bool = False):
    """Damped dynamic relaxation (B off, projectile held); returns (x, info)."""
    wall0 = time.perf_counter()
    problem = setup(cfg, "relax")
    sysm = problem.system
    r = cfg.relaxation
    tab = sdirk(cfg.time.stages)
    nopts = {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}
    iopts = _integrator_options(cfg, sysm)
    x = problem.x0.copy()
    scale = sysm.row_scales(r.t_end / r.steps, x, np.zeros(sysm.n))
    w, _ = _initial_w(sysm, x, scale, nopts)

    def at_boundary(t, x_, w_):
        if progress:
            log.info("relaxation t = %.4g ms", t)

    hook = ChunkedRebuild(sysm, r.t_end, r.steps, cfg.contact.rebuild_every, 0.5 * cfg.contact.margin, at_boundary)
    try:
        hook.rebuild(x)
        res = integrate(RowScaledSystem(sysm, scale), x, w, 0.0, r.t_end, r.steps, stages=tab.stages,
                        newton_opts=nopts, max_cuts=cfg.time.max_cuts,
                        fixed_step=not cfg.time.step_control, consistent=False, rebuild=hook, **iopts)
        x, w = res.x, res.w
        at_boundary(res.t, x, w)
    except IntegrationFailure as exc:
        raise SceneFailure("impact", f"relaxation failed: {exc}", phase="relaxation", time=exc.t,
                           state={"x": exc.x, "w": exc.w}, model=sysm) from exc
    vmax = float(np.abs(w[sysm.mech]).max())
    disp = float(np.abs((x - problem.x0)[sysm.mech]).max())
    info = {"steps": res.steps, "rejected": res.rejected, "max_velocity_mm_per_ms": vmax,
            "max_displacement_mm": disp, "wall_time_s": time.perf_counter() - wall0,
            "active_pairs": int(sysm.fabric.active_pairs(sysm.split(x)[0]).size)}
    log.info("relaxation: %s", info)
    return x, info


def load_or_relax(cfg, path: Path | None):
    """The relaxed state of ``path`` when its digest matches the config, else relax (and save)."""
    from ..io.atomic import atomic_path

    digest = config_digest(cfg)
    if path is not None and Path(path).exists():
        d = np.load(path, allow_pickle=False)
        if str(d["digest"]) == digest:
            info = json.loads(str(d["info"]))
            info["loaded_from"] = str(path)
            return d["x"], info
        log.warning("relaxed state %s is for another config (digest %s != %s): relaxing again", path,
                    str(d["digest"]), digest)
    x, info = relax(cfg)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(Path(path)) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, x=x, digest=np.array(digest), info=np.array(json.dumps(info)))
    return x, info


def angular_velocity(q_top, q_bot, v_top, v_bot, L):
    """Rigid-body estimate of §8.4: omega = r x v_rel / (r . r), r = (q_top - q_bot)/2 + L/2 e_z,
    v_rel = (v_top - v_bot)/2 (q: displacements of the end nodes). Arrays (..., 3)."""
    r = 0.5 * (np.asarray(q_top) - np.asarray(q_bot))
    r = r + np.array([0.0, 0.0, 0.5 * L])
    v = 0.5 * (np.asarray(v_top) - np.asarray(v_bot))
    return np.cross(r, v) / np.einsum("...i,...i->...", r, r)[..., None]


def _probe(problem, x, w, X0p, L, bal):
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


def solve(cfg, *, x_start=None, relax_info=None, record: bool = True, t_end: float | None = None,
          steps: int | None = None, progress: bool = False, integrator_options: dict | None = None,
          measure_memory: bool = False, checkpoint: Path | None = None, stop_after_steps: int | None = None
          ) -> SceneResult:
    """The impact (module docstring). ``x_start`` the relaxed state (default: ``relax(cfg)``);
    ``t_end``/``steps`` override the config; ``checkpoint`` a file to write every
    ``time.checkpoint_every`` steps and to resume from; ``stop_after_steps`` ends the run (as a
    kill would) after that many accepted steps, at a chunk boundary, for the resume test."""
    wall0 = time.perf_counter()
    if measure_memory:
        tracemalloc.start()
    if x_start is None:
        x_start, relax_info = relax(cfg)
    problem = setup(cfg, "impact")
    sysm = problem.system
    fab, proj = sysm.fabric, sysm.projectile
    mesh = fab.mesh
    t_end = float(cfg.time.t_end if t_end is None else t_end)
    steps = int(nominal_steps(cfg) if steps is None else steps)
    h0 = t_end / steps
    tab = sdirk(cfg.time.stages)
    nopts = {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}
    iopts = _integrator_options(cfg, sysm)
    iopts.update(integrator_options or {})
    X0p = proj.nodal(sysm.split(problem.x0)[1])[:, :9].copy()
    L = float(problem.info["projectile_length_mm"])
    x = np.array(x_start, float, copy=True)
    w = np.zeros(sysm.n)
    w[sysm._r_end[:, 2]] = -cfg.projectile.speed
    scale = sysm.row_scales(h0, x, w)
    thermal = ImpactThermal(sysm, cfg.contact.heat_transfer, problem.fixed_T_nodes,
                            sink=cfg.contact.projectile_heat_sink)
    post = ThermalPostSolver(thermal, tab, cfg.end_temperature)
    balances = ImpactBalances(problem, thermal)
    digest = config_digest(cfg, ("geometry", "warp", "weft", "material", "projectile", "contact", "field", "mesh",
                                 "relaxation", "time", "newton"))
    wall = {"integration": 0.0, "balances": 0.0, "thermal_post": 0.0, "contact_rebuild": 0.0, "checkpoint": 0.0}
    counters = {"steps": 0, "rejected": 0, "chunks": 0, "extra_rebuilds": 0, "factorizations": 0,
                "linear_solves": 0, "since_store": 0, "since_checkpoint": 0}
    series = {"t": [], "v_com": [], "v_bottom": [], "v_top": [], "omega": [], "com": [], "yarn_currents": [],
              "max_T": [], "mean_T": [], "sphere_pairs_active": [], "contact_active_pairs": []}
    bal: dict = {}
    stored = {"t": [], "x": [], "w": [], "T": []}
    stage_its: list = []
    T = np.full(mesh.n_nodes, float(cfg.end_temperature))
    t = 0.0
    resumed = None
    if checkpoint is not None and Path(checkpoint).exists():
        d = np.load(checkpoint, allow_pickle=True)
        if str(d["digest"]) == digest and float(d["t_end"]) == t_end and int(d["steps"]) == steps:
            st = d["state"].item()
            x, w, T, t = st["x"], st["w"], st["T"], float(st["t"])
            series, bal, stored = st["series"], st["bal"], st["stored"]
            counters.update(st["counters"])
            stage_its = st["stage_iterations"]
            resumed = t
            log.info("resumed from %s at t = %.6g ms", checkpoint, t)
        else:
            log.warning("checkpoint %s is for another run: starting afresh", checkpoint)
    if resumed is None:
        w, _ = _initial_w(sysm, x, scale, nopts, 0.0, w)

    def record_state(t_, x_, w_):
        tb = time.perf_counter()
        b = balances(x_, w_, t_, T)
        c, r = sysm.positions(x_)
        b["contact_active_pairs"] = float(fab.active_pairs(sysm.split(x_)[0]).size)
        for k_, v in b.items():
            bal.setdefault(k_, []).append(v)
        bal.setdefault("t", []).append(t_)
        pr = _probe(problem, x_, w_, X0p, L, b)
        series["t"].append(t_)
        for k_ in ("v_com", "v_bottom", "v_top", "omega", "com", "yarn_currents"):
            series[k_].append(pr[k_])
        series["max_T"].append(float(T.max()))
        series["mean_T"].append(float(T.mean()))
        series["sphere_pairs_active"].append(int(sysm.sphere.active_pairs(c, r).size))
        series["contact_active_pairs"].append(b["contact_active_pairs"])
        wall["balances"] += time.perf_counter() - tb

    def store(t_, x_, w_):
        stored["t"].append(t_)
        stored["x"].append(fab.nodal(sysm.split(x_)[0])[:, :9].copy())
        stored["w"].append(np.array(sysm.split(w_)[0], copy=True))
        stored["T"].append(T.copy())
        stored.setdefault("xp", []).append(proj.nodal(sysm.split(x_)[1])[:, :9].copy())

    if resumed is None:
        record_state(0.0, x, w)
        store(0.0, x, w)

    def on_step(t_, x_, w_, info):
        nonlocal T
        counters["steps"] += 1
        counters["rejected"] += info.rejected_attempts
        counters["factorizations"] += info.factorizations
        counters["linear_solves"] += info.linear_solves
        stage_its.append(list(info.stage_iterations))
        tp = time.perf_counter()
        T = post.step(T, info.stage_states, info.t, info.h)
        wall["thermal_post"] += time.perf_counter() - tp
        record_state(t_, x_, w_)
        counters["since_store"] += 1
        counters["since_checkpoint"] += 1
        if record and (counters["since_store"] >= cfg.time.store_every or t_ >= t_end * (1 - 1e-12)):
            counters["since_store"] = 0
            store(t_, x_, w_)

    def save_checkpoint(t_, x_, w_):
        from ..io.atomic import atomic_path

        tc = time.perf_counter()
        st = {"x": x_, "w": w_, "T": T, "t": t_, "series": series, "bal": bal, "stored": stored,
              "counters": dict(counters, chunks=hook.rebuilds, extra_rebuilds=hook.early),
              "stage_iterations": stage_its}
        with atomic_path(Path(checkpoint)) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, digest=np.array(digest), t_end=np.array(t_end), steps=np.array(steps),
                         state=np.array(st, dtype=object))
        wall["checkpoint"] += time.perf_counter() - tc

    def at_boundary(t_, x_, w_):
        if progress:
            log.info("impact t = %.5g ms, steps %d, rejected %d, v_z = %.5g mm/ms", t_, counters["steps"],
                     counters["rejected"], series["v_com"][-1][2])
        if checkpoint is not None and counters["since_checkpoint"] >= cfg.time.checkpoint_every:
            counters["since_checkpoint"] = 0
            save_checkpoint(t_, x_, w_)
        if stop_after_steps is not None and counters["steps"] >= stop_after_steps and t_ < t_end * (1 - 1e-12):
            if checkpoint is not None:
                save_checkpoint(t_, x_, w_)
            raise SceneFailure("impact", f"stopped after {counters['steps']} steps (stop_after_steps)",
                               phase="impact", time=t_, state={"x": x_, "w": w_, "T": T}, model=sysm)

    hook = ChunkedRebuild(sysm, t_end, steps, cfg.contact.rebuild_every, 0.5 * float(cfg.contact.margin),
                          at_boundary)
    hook.rebuilds, hook.early = counters["chunks"], counters["extra_rebuilds"]
    ti = time.perf_counter()
    try:
        if t < t_end * (1 - 1e-12):
            hook.rebuild(x)
            res = integrate(RowScaledSystem(sysm, scale), x, w, t, t_end, steps, stages=tab.stages,
                            newton_opts=nopts, max_cuts=cfg.time.max_cuts, on_step=on_step,
                            fixed_step=not cfg.time.step_control, consistent=False, rebuild=hook, **iopts)
            x, w, t = res.x, res.w, res.t
            at_boundary(t, x, w)
    except IntegrationFailure as exc:
        raise SceneFailure("impact", f"time integration failed with step size h = {exc.h:.6g} ms: {exc}",
                           phase="impact", time=exc.t, step=f"h = {exc.h:.6g} ms",
                           state={"x": exc.x, "w": exc.w, "T": T}, model=sysm) from exc
    finally:
        wall["integration"] += time.perf_counter() - ti
    counters["chunks"], counters["extra_rebuilds"] = hook.rebuilds, hook.early
    wall["contact_rebuild"] = hook.wall
    # ------------------------------------------------------------------ summary
    errs = impact_balance_errors({k_: np.asarray(v) for k_, v in bal.items()})
    stats = fab.stats
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
    peak = None
    if measure_memory:
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    n_st = max(1, len(stage_its) * tab.stages)
    newton_acc = int(sum(sum(s_) for s_ in stage_its))
    yc = np.asarray(series["yarn_currents"][-1])
    summary = {
        "t_end_ms": t_end, "h_nominal_ms": h0, "dt_rule_ms": time_step_rule(cfg), "stages": tab.stages,
        "steps_accepted": counters["steps"], "steps_rejected": counters["rejected"],
        "newton_iterations": newton_acc, "newton_iterations_per_stage": newton_acc / n_st,
        "factorizations": counters["factorizations"], "factorizations_per_stage": counters["factorizations"] / n_st,
        "linear_solves": counters["linear_solves"],
        "contact_rebuilds": counters["chunks"], "extra_rebuilds": counters["extra_rebuilds"],
        "dofs": {**fab.base.dof_counts(), "projectile": int(proj.n), "total": int(sysm.n),
                 "thermal_post_solve": int(mesh.n_nodes)},
        "contact_pairs_max": int(max(series["contact_active_pairs"])),
        "sphere_pairs_active_max": int(max(series["sphere_pairs_active"])),
        "projectile_velocity_mm_per_ms": [float(v) for v in series["v_com"][-1]],
        "projectile_angular_velocity_x_rad_per_ms": float(series["omega"][-1][0]),
        "projectile_angular_velocity_x_extreme_rad_per_ms": float(
            np.asarray(series["omega"])[:, 0][np.argmax(np.abs(np.asarray(series["omega"])[:, 0]))]),
        "yarn_current_A": {"minus_y": float(yc[0]), "plus_y": float(yc[1]), "edge": float(yc[2])},
        "max_temperature_K": float(np.max(T)),
        "momentum_balance_error": max(errs["momentum_projectile"], errs["momentum_total"]),
        "energy_balance_error": errs["total"],
        "balance_errors": {k_: errs[k_] for k_ in ("momentum_projectile", "momentum_total", "charge", "electrical",
                                                   "mechanical", "thermal", "total")},
        "impulses_Nms": {k_: errs[k_] for k_ in ("impulse_sphere_on_projectile_Nms", "impulse_clamp_Nms",
                                                 "impulse_lorentz_Nms")},
        "energies_mJ": {k_: errs[k_] for k_ in ("work_lorentz_mJ", "work_circuit_mJ", "joule_heat_mJ",
                                                "damping_mJ", "delta_mechanical_energy_mJ")},
        "geometry": problem.info, "sampled_yarns": problem.sampled, "relaxation": relax_info,
        "resumed_from_ms": resumed, "wall_time_s": wall,
    }
    import resource

    summary["peak_rss_MiB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    if peak is not None:
        summary["peak_memory_MiB"] = peak
    if record:
        summary["history"] = {"stored": {k_: np.asarray(v) for k_, v in stored.items()},
                              "series": {k_: np.asarray(v) for k_, v in series.items()},
                              "balances": {k_: np.asarray(v) for k_, v in bal.items()},
                              "balance_series": errs["series"]}
    return SceneResult(state={"x": x, "w": w, "T": T}, model=sysm, summary=summary)


def run(cfg, out_dir: Path) -> dict:
    from .impact_output import write_outputs

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    state_file = Path(cfg.relaxation.state_file) if cfg.relaxation.state_file else out_dir / "relaxed_state.npz"
    t0 = time.perf_counter()
    x0, rinfo = load_or_relax(cfg, state_file)
    t_relax = time.perf_counter() - t0
    try:
        res = solve(cfg, x_start=x0, relax_info=rinfo, record=True, progress=True,
                    checkpoint=out_dir / "checkpoint.npz", measure_memory=False)
    except SceneFailure as failure:
        failure.save(out_dir / "impact_last_good_state.npz")
        log.error("%s", failure)
        raise
    summary = dict(res.summary)
    summary["wall_time_s"]["relaxation_or_load"] = t_relax
    hist = summary.pop("history")
    summary["files"] = write_outputs(cfg, res, hist, out_dir)
    return summary


def impact_job(config_path, out_dir, summary_path, log_path, overrides=(), relaxed=None, relax_only=False) -> dict:
    """One Snakemake job (workflow/rules/impact.smk): the scene of ``config_path`` (+
    ``overrides``), outputs under ``out_dir``, the summary written atomically to
    ``summary_path``, the log to ``log_path``; ``relaxed`` the relaxed-state file to use
    (made if missing); ``relax_only``: only the relaxation (the summary is its record)."""
    from ..config.loader import load_config
    from ..io.atomic import atomic_write_text
    from ..io.provenance import to_jsonable

    handler = logging.FileHandler(log_path, mode="w")
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    root = logging.getLogger("rve")
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    try:
        ov = list(overrides)
        if relaxed is not None:
            ov.append(f"relaxation.state_file={relaxed}")
        cfg = load_config(config_path, ov)
        if relax_only:
            _, info = load_or_relax(cfg, Path(relaxed) if relaxed else Path(out_dir) / "relaxed_state.npz")
            summary = {"relaxation": info, "digest": config_digest(cfg)}
        else:
            summary = run(cfg, Path(out_dir))
        atomic_write_text(Path(summary_path), json.dumps(to_jsonable(summary), indent=2, default=str))
        return summary
    finally:
        root.removeHandler(handler)
        handler.close()


def sweep_curve(summary_paths, currents, out_png, out_json) -> dict:
    """The designer's curve of a current-density sweep: final projectile speed, tilt rate and
    peak temperature against |J_bar| (one summary.json per current)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path, atomic_write_text

    rows = []
    for p, J in zip(summary_paths, currents):
        s = json.loads(Path(p).read_text())
        rows.append({"J_A_per_mm2": float(J), "speed_mm_per_ms": -float(s["projectile_velocity_mm_per_ms"][2]),
                     "omega_x_rad_per_ms": float(s["projectile_angular_velocity_x_rad_per_ms"]),
                     "max_temperature_K": float(s["max_temperature_K"])})
    J = [r["J_A_per_mm2"] for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.6), dpi=110)
    for a, key, lab in zip(ax, ("speed_mm_per_ms", "omega_x_rad_per_ms", "max_temperature_K"),
                           ("final speed (m/s)", "omega_x at t_end (rad/ms)", "max T (K)")):
        a.plot(J, [r[key] for r in rows], "o-")
        a.set_xlabel("|J_bar| warp (A/mm^2)")
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
    fig.suptitle("Impact: current-density sweep", fontsize=10)
    fig.tight_layout()
    with atomic_path(Path(out_png)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    atomic_write_text(Path(out_json), json.dumps(rows, indent=2))
    return {"rows": rows}
