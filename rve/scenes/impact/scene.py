"""Scene: electromagnetically enhanced armour (thesis §8.4, Table 8.2; SPEC §9): a projectile
(one director-beam element whose end nodes act as hemispheres) into a current-carrying
plain weave in a magnetic field (docs/impact.md).

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
``setup(cfg, phase="impact") -> ImpactProblem``: the ``ImpactSystem``
(``rve.model.projectile``: fabric ``ContactSystem`` + projectile ``BeamModel`` + sphere
contact) of the validated ``ImpactConfig`` with its boundary conditions and the crimped
start state (projectile above the weave centre, at rest). ``phase="relax"``: the same dofs,
B off, the projectile held, the fabric damped by ``relaxation.damping``, the fibril friction
only with ``relaxation.friction`` (never the sphere's).
``relax(cfg) -> (x, info)``: damped dynamic relaxation of the fabric with the projectile
present and at rest (``info`` a ``RelaxInfo``: drift, speed, mechanical balance, and with
``relaxation.friction`` the friction history); ``load_or_relax(cfg, path)`` reuses a saved
relaxed state (``relaxed_state.npz``: x, config digest of the sections it depends on, the
friction history as ``friction/...`` arrays).
``solve(cfg, x_start=None, ...) -> SceneResult``: from the relaxed state, the projectile gets
``-speed e_z``, B on (a step at t = 0); SDIRK (``time.stages``) over ``time.t_end`` in chunks
of ``contact.rebuild_every`` nominal steps (both contact maps rebuilt before every chunk,
and early when a centroid or an end node moved half the margin); the temperature is
post-solved on the fabric after every accepted step (S = alpha_mu = 0); balances every
accepted step, from the residual the last stage's Newton left at the step's end state
(``RowScaledSystem.residual_at``; evaluated again only when that is not at the state); ``checkpoint`` (path) written every ``time.checkpoint_every`` steps at a
chunk boundary and resumed from when present (same config digest).
``run(cfg, out_dir) -> dict``: load_or_relax + solve + outputs (``rve.scenes.impact.outputs``)
+ the summary (docs/impact.md).
Friction (``cfg.friction``, some mu > 0; ``ImpactProblem.friction``, a
``rve.scenes.dynamic_friction.DynamicFriction``): between the fibrils in the impact phase, and
in the relaxation with ``relaxation.friction`` (``rve.scenes.impact.relaxation``: the history
starts at the start state with no elastic gap, is committed after every accepted step, and
is saved with the relaxed state and its digest; the impact then starts from it, else afresh
at its start state); the history is committed after every accepted step,
before the balances (which then include the friction terms) and the rebuilds, and is part
of the checkpoint (and of its digest). mu = 0: the frictionless scene. At the sphere contact
(``friction.projectile`` mu_p > 0, impact phase only; ``rve.scenes.impact.friction``): the
same, ``ImpactProblem.friction`` then an ``ImpactFriction`` of both drivers.

Sampled yarns: the warp yarns nearest y = -R_p/2 (``minus_y``) and +R_p/2 (``plus_y``) of the
projectile axis, and the warp yarn j = 0 (``edge``, the -y edge).
"""
from __future__ import annotations

import functools
import hashlib
import json
import logging
import math
import time
import tracemalloc
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...fem.assembly import DofLayout
from ...fabrics.setup import contact_params
from ...model import BeamMaterial, BeamModel, CircuitBC, ContactSystem, Couplings, DirichletBC
from ...model import RowScaledSystem
from ...model.projectile import ImpactSystem, projectile_mesh
from ...model.terms.projectile_contact import SphereContactTerm
from ...solvers.backends.pruned import NAME, NAME_AUTO, PardisoOrPruned, PrunedSuperLU
from ...solvers.dirk import IntegrationFailure, consistent_initialization, integrate, integrator_options, sdirk
from ...model.balances import ImpactBalances
from .record import (ImpactCheckpoint, ImpactRecorder, angular_velocity, impact_summary,
                            wall_split)
from .thermal import ImpactThermal
from ..rebuild import ChunkedRebuild
from ..thermal_post import ThermalPostSolver
from ..dynamic_friction import DynamicFriction, FrictionBalances, contact_params_with_friction
from .friction import ImpactFriction, SphereFriction, sphere_friction_args
from .relaxation import RelaxationRecorder, RelaxInfo, relaxation_friction, seed_impact_friction
from ..induced.scene import warp_circuit
from ...fabrics.taut import chord_clearance, taut_weave, weave_with_chord_clearance
from ..protocol import SceneFailure, SceneResult

__all__ = ["ImpactProblem", "setup", "relax", "load_or_relax", "solve", "run", "time_step_rule", "schur_border",
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
    dump = cfg.model_dump(mode="json")
    d = {k: dump[k] for k in sections}
    d.get("relaxation", {}).pop("state_file", None)
    if "relaxation" in d:
        # a frictionless relaxation (the option off, or every fibril mu = 0) keeps the digests
        # it had; a frictional one depends on the fibrils' law (not on the projectile's mu_p)
        if relaxation_friction(cfg):
            d.setdefault("friction", {k: v for k, v in dump["friction"].items() if k != "projectile"})
        else:
            d["relaxation"].pop("friction", None)
    if d.get("friction", {}).get("projectile", None) == 0.0:   # the fibril-friction runs keep their digests
        d["friction"].pop("projectile")
    # the factorisation backend changes round-off only (docs/engine.md "Unsymmetric stage matrices": states equal to
    # 4e-15 between superlu_pruned and PARDISO): a checkpoint resumes on another backend
    d.get("newton", {}).pop("linear_backend", None)
    if "time" not in sections:  # a relaxed state: B is off, the circuits and the speed do not matter
        d.get("contact", {}).pop("rebuild", None)   # the impact phase's rule (the relaxation rebuilds every k)
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
    #: the friction between fibrils (``rve.scenes.dynamic_friction``) and at the projectile
    #: (``rve.scenes.impact.friction.ImpactFriction`` when mu_p > 0), None when frictionless
    friction: DynamicFriction | ImpactFriction | None = None

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
    if not relaxing or cfg.relaxation.friction:
        # the relaxation is frictionless unless asked: its crimped start is an exact
        # equilibrium at rest, where friction changes nothing; the straight reference slides
        # off its crossings without it (docs/impact.md "Relaxation with friction")
        params = contact_params_with_friction(params, cfg.friction)
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
    sphere = SphereContactTerm(mesh, pr.radius, k.penalty, k.margin,
                               friction=None if relaxing else sphere_friction_args(cfg.friction))
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
    friction = ImpactFriction.of(DynamicFriction.of(fabric, weave.direction, lambda x_: system.split(x_)[0]),
                                 SphereFriction.of(system))
    return ImpactProblem(system, weave, x0, circuit_in, circuit_leak, pcirc, dirichlet_V, ends.ravel(), ends, sampled,
                         info, friction)


def _integrator_options(cfg, sysm=None, extra: dict | None = None) -> dict:
    """``integrate`` keywords (``extra``, flat option names, over the config's). The pruned
    backends eliminate the projectile's free dofs (the last ones of the restricted stage
    matrix: its dofs come last and ``FreeDofs`` keeps the order) by a Schur complement
    (rve.solvers.backends.pruned): their names become factories with that border."""
    opts = {"max_cuts": cfg.time.max_cuts, "fixed_step": not cfg.time.step_control,
            "jacobian_reuse": cfg.newton.jacobian_reuse, "reuse_contraction": cfg.newton.reuse_contraction,
            "linear_backend": cfg.newton.linear_backend, "reuse_across_restarts": cfg.newton.reuse_across_restarts,
            "predictor_across_restarts": cfg.newton.predictor_across_restarts, **(extra or {})}
    pruned = {NAME: PrunedSuperLU, NAME_AUTO: PardisoOrPruned}.get(opts["linear_backend"])
    if pruned is not None:
        opts["linear_backend"] = functools.partial(pruned, border=0 if sysm is None else schur_border(sysm))
    return integrator_options(**opts)


def schur_border(sysm) -> int:
    """The projectile's free dofs: the last unknowns of the restricted stage matrix."""
    idx, _ = sysm.constraints(0.0)
    return int(sysm.n - sysm.nf - np.count_nonzero(np.asarray(idx) >= sysm.nf))


def _initial_w(sysm, x, scale, nopts, t=0.0, w=None):
    w0 = np.zeros(sysm.n) if w is None else w
    return consistent_initialization(RowScaledSystem(sysm, scale), x, w0, t, nopts)


def relax(cfg, progress: bool = False):
    """Damped dynamic relaxation (B off, projectile held); returns (x, info), ``info`` a
    ``RelaxInfo`` (with ``relaxation.friction``: the relaxed state's friction history in
    ``info.friction``)."""
    wall0 = time.perf_counter()
    cpu0 = time.process_time()
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
    # the fibril friction (relaxation.friction): its history starts at the start state with no
    # elastic gap (the first map rebuild) and the accepted step is the history of the next
    friction = problem.friction if relaxation_friction(cfg) else None
    rec = RelaxationRecorder(problem, friction)
    try:
        hook.rebuild(x)
        rec.record(0.0, x, w)
        on_step = rec.on_step if friction is None else friction.on_step(rec.on_step)
        res = integrate(RowScaledSystem(sysm, scale), x, w, 0.0, r.t_end, r.steps, stages=tab.stages,
                        newton_opts=nopts, on_step=on_step, consistent=False, rebuild=hook, **iopts)
        x, w = res.x, res.w
        at_boundary(res.t, x, w)
    except IntegrationFailure as exc:
        raise SceneFailure("impact", f"relaxation failed: {exc}", phase="relaxation", time=exc.t,
                           state={"x": exc.x, "w": exc.w}, model=sysm) from exc
    vmax = float(np.abs(w[sysm.mech]).max())
    disp = float(np.abs((x - problem.x0)[sysm.mech]).max())
    info = {"steps": res.steps, "rejected": res.rejected, "max_velocity_mm_per_ms": vmax,
            "max_displacement_mm": disp, "wall_time_s": time.perf_counter() - wall0,
            "cpu_time_s": time.process_time() - cpu0,
            "active_pairs": int(sysm.fabric.active_pairs(sysm.split(x)[0]).size),
            "with_friction": friction is not None, **rec.summary()}
    log.info("relaxation: %s", info)
    return x, RelaxInfo(info, None if friction is None else friction.arrays())


def load_or_relax(cfg, path: Path | None):
    """The relaxed state of ``path`` when its digest matches the config, else relax (and save)."""
    from ...io.atomic import atomic_path

    digest = config_digest(cfg)
    if path is not None and Path(path).exists():
        with np.load(path, allow_pickle=False) as d:
            if str(d["digest"]) == digest:
                info = json.loads(str(d["info"]))
                info["loaded_from"] = str(path)
                fr = {k: d[k].copy() for k in d.files if k.startswith("friction/")}
                return d["x"].copy(), RelaxInfo(info, fr or None)
            log.warning("relaxed state %s is for another config (digest %s != %s): relaxing again", path,
                        str(d["digest"]), digest)
    x, info = relax(cfg)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(Path(path)) as tmp:
            with open(tmp, "wb") as fh:
                # the friction history (relaxation.friction) as plain arrays beside the state
                np.savez(fh, x=x, digest=np.array(digest), info=np.array(json.dumps(info)),
                         **(info.friction or {}))
    return x, info


def _impact_start(cfg, problem, x_start, t_end, steps, tab, nopts, checkpoint, record):
    """The recorder, the checkpoint and the start state ``(t, x, w, resumed, rebuilds, early)``
    of ``solve``: a matching checkpoint's state, else the relaxed state with the impact speed
    and consistent massless dofs (recorded and stored)."""
    sysm = problem.system
    X0p = sysm.projectile.nodal(sysm.split(problem.x0)[1])[:, :9].copy()
    x = np.array(x_start, float, copy=True)
    w = np.zeros(sysm.n)
    w[sysm._r_end[:, 2]] = -cfg.projectile.speed
    thermal = ImpactThermal(sysm, cfg.contact.heat_transfer, problem.fixed_T_nodes,
                            sink=cfg.contact.projectile_heat_sink)
    balances, post = ImpactBalances(problem, thermal), ThermalPostSolver(thermal, tab, cfg.end_temperature)
    if problem.friction is not None:
        balances = FrictionBalances(balances, problem.friction)
    rec = ImpactRecorder(problem, balances, post, np.full(sysm.fabric.mesh.n_nodes, float(cfg.end_temperature)), X0p,
                         float(problem.info["projectile_length_mm"]), cfg.time.store_every, t_end, record)
    sections = ("geometry", "warp", "weft", "material", "projectile", "contact", "field", "mesh", "relaxation", "time",
                "newton")
    if problem.friction is not None:   # frictionless runs keep the digests (and checkpoints) they had
        sections = sections + ("friction",)
    digest = config_digest(cfg, sections)
    ck = None if checkpoint is None else ImpactCheckpoint(checkpoint, digest, t_end, steps, problem.friction)
    scale = sysm.row_scales(t_end / steps, x, w)
    start = None if ck is None else ck.load(rec)
    if start is not None:
        t, x, w, rebuilds, early = start
        return rec, ck, scale, (t, x, w, t, rebuilds, early)
    w, _ = _initial_w(sysm, x, scale, nopts, 0.0, w)
    rec.record_state(0.0, x, w)
    rec.store(0.0, x, w)
    return rec, ck, scale, (0.0, x, w, None, 0, 0)


class _Boundary:
    """What ``solve`` does at every contact-rebuild boundary: progress, checkpoints, and the
    ``stop_after_steps`` end (as a kill would, after a checkpoint)."""

    def __init__(self, rec, ck, every: int, stop_after, t_end: float, progress: bool):
        self.rec, self.ck, self.every, self.stop_after = rec, ck, int(every), stop_after
        self.t_end, self.progress, self.hook = float(t_end), progress, None

    def __call__(self, t, x, w) -> None:
        c = self.rec.counters
        if self.progress:
            log.info("impact t = %.5g ms, steps %d, rejected %d, v_z = %.5g mm/ms", t, c["steps"], c["rejected"],
                     self.rec.series["v_com"][-1][2])
        if c["since_checkpoint"] >= self.every:
            # a checkpoint boundary (with or without a file): the restart after it starts
            # afresh, as the run resumed from the checkpoint does, so both give the same bits
            c["since_checkpoint"] = 0
            self.hook.fresh = True
            if self.ck is not None:
                self.ck.save(self.rec, t, x, w, self.hook.rebuilds, self.hook.early)
        if self.stop_after is not None and c["steps"] >= self.stop_after and t < self.t_end * (1 - 1e-12):
            if self.ck is not None:
                self.ck.save(self.rec, t, x, w, self.hook.rebuilds, self.hook.early)
            raise SceneFailure("impact", f"stopped after {c['steps']} steps (stop_after_steps)", phase="impact",
                               time=t, state={"x": x, "w": w, "T": self.rec.T}, model=self.rec.problem.system)


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
    carried = None
    if relaxation_friction(cfg):
        # the impact continues from the frictional relaxation's stick state, not afresh
        carried = getattr(relax_info, "friction", None)
        if carried is None:
            raise ValueError("relaxation.friction: the impact needs the relaxed state's friction history "
                             "(relax_info as relax or load_or_relax return it)")
    problem = setup(cfg, "impact")
    sysm = problem.system
    t_end = float(cfg.time.t_end if t_end is None else t_end)
    steps = int(nominal_steps(cfg) if steps is None else steps)
    tab = sdirk(cfg.time.stages)
    nopts = {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}
    iopts = _integrator_options(cfg, sysm, integrator_options)
    rec, ck, scale, (t, x, w, resumed, rebuilds, early) = _impact_start(cfg, problem, x_start, t_end, steps, tab,
                                                                        nopts, checkpoint, record)
    boundary = _Boundary(rec, ck, cfg.time.checkpoint_every, stop_after_steps, t_end, progress)
    every = cfg.contact.rebuild_every if cfg.contact.rebuild == "every" else None
    hook = boundary.hook = ChunkedRebuild(sysm, t_end, steps, every,
                                          0.5 * float(cfg.contact.margin), boundary)
    hook.rebuilds, hook.early = rebuilds, early
    ti = time.perf_counter()
    try:
        if t < t_end * (1 - 1e-12):
            hook.rebuild(x)
            on_step = rec.on_step
            if problem.friction is not None:
                if resumed is not None:
                    problem.friction.restore(x, ck.friction_arrays)
                elif carried is not None:
                    seed_impact_friction(problem.friction, x, carried)
                # the accepted step is the friction history of the next (committed before
                # the balances read it and before a map rebuild carries it)
                on_step = problem.friction.on_step(rec.on_step)
            rec.system = RowScaledSystem(sysm, scale)
            res = integrate(rec.system, x, w, t, t_end, steps, stages=tab.stages,
                            newton_opts=nopts, on_step=on_step, consistent=False, rebuild=hook, **iopts)
            x, w, t = res.x, res.w, res.t
            boundary(t, x, w)
    except IntegrationFailure as exc:
        raise SceneFailure("impact", f"time integration failed with step size h = {exc.h:.6g} ms: {exc}",
                           phase="impact", time=exc.t, step=f"h = {exc.h:.6g} ms",
                           state={"x": exc.x, "w": exc.w, "T": rec.T}, model=sysm) from exc
    finally:
        wall = {"integration": time.perf_counter() - ti, **rec.wall, "contact_rebuild": hook.wall,
                "checkpoint": 0.0 if ck is None else ck.wall}
    summary, errs = impact_summary(problem, rec, tab, t_end, t_end / steps, time_step_rule(cfg), hook,
                                   wall_split(sysm, wall, wall0), relax_info, resumed)
    _add_memory(summary, measure_memory)
    if record:
        summary["history"] = {"stored": {k: np.asarray(v) for k, v in rec.stored.items()},
                              "series": {k: np.asarray(v) for k, v in rec.series.items()},
                              "balances": {k: np.asarray(v) for k, v in rec.bal.items()},
                              "balance_series": errs["series"]}
    return SceneResult(state={"x": x, "w": w, "T": rec.T}, model=sysm, summary=summary)


def _add_memory(summary: dict, measure_memory: bool) -> None:
    """Peak RSS of the process and, when traced, the peak of Python's allocations (MiB)."""
    import resource

    summary["peak_rss_MiB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    if measure_memory:
        summary["peak_memory_MiB"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()


def run(cfg, out_dir: Path) -> dict:
    from .outputs import write_outputs

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
