"""Mechanics of the RVE homogenisation: relaxation and the strain steps of Algorithm 7.1.

Thesis §7.3-7.4 (Algorithm 7.1); docs/rve_pipeline.md, docs/relaxation.md.

Boundary conditions (§7.3)
--------------------------
The centroid of every fibril end (every ``Fabric.end_tags`` entry) is pinned: its
velocity is prescribed (zero, or the driving field during a driven phase); the directors
are free (no applied torque). A twist gauge holds g1_z at each fibril's first node (the
relaxation scene's choice, docs/relaxation.md): it removes only the free spin of a fibril
about its own axis. Mechanics only (docs/relaxation.md): no T or V dofs. The fabric, the
clamps, the contact law and the system come from ``rve.fabrics.setup``; the energy path
of the relaxation is ``rve.fabrics.relaxation.relax`` (the relaxation scene's).

One strain step (``strain_step``)
---------------------------------
From the stored state at strain eps_{n-1} to eps_n = eps_{n-1} + d with d = total/steps:

1. **driven phase** (Algorithm 7.1, 1a-1b): the velocity field

       uniaxial: v = (d / t_step) X1 e1,    shear: v = (d / t_step) X1 e2,
       uniaxial_y: v = (d / t_step) X2 e2,
       trellis (picture frame, strain = the angle drop theta in rad, F(theta) of
       ``trellis_gradient``: both yarn families keep their length):
       v = (F(theta_n) - F(theta_{n-1})) X / t_step (the secant of the step)

   (the thesis writes (Delta_step / t_step)(X1 / L0): Delta_step is then the elongation
   d L0 of the box length L0 per step) is prescribed on the pinned end centroids for
   ``t_step`` and is the initial velocity of every node (centroids and directors: the
   affine field of the material points r + xi_a g_a). X is the **origin** of the strain
   path, the relaxed state, so after n steps the ends sit exactly at X + eps_n X1 e_i
   (uniaxial_y: X + eps_n X2 e2; trellis: F(theta_n) X).
   Backward Euler (``integrate`` through ``rve.solvers.relaxation.relax_to_equilibrium`` with
   ``static=False``: chunks of ``rebuild_every`` steps, the contact map rebuilt between)
   with the light damping ``strain.damping`` (Table 7.1's gamma).
2. **heavily damped relaxation** (1c-1d): velocities set to zero, the ends held, damping
   ``strain.relax_damping`` for ``t_relax``;
3. **static solve**: velocities zeroed, capped-step static Newton with map rebuilds
   (``relax_to_equilibrium``'s static phase, docs/relaxation.md).

Then (Algorithm 7.1, 2b) the reaction forces: the clamp forces summed per box side, 3
components (``rve.fabrics.setup.clamp_reactions``: the residual at the pinned
centroids, contact included).

With ``strain.follow_branch`` the step goes through ``rve.homogenisation.branch.follow_branch``
(one equilibrium path): the energy balance of the step (potential change against the clamps'
work, ``pinned_energy``) and the minimiser's inertia verdict are tested, and a step that
jumped to another equilibrium is followed from the previous state in halves
(``strain.branch_method: halving``, the default) or by pseudo-arclength continuation through
its limit points (``arc_length``, ``rve.homogenisation.continuation``; halving where it fails); the record is ``info["branch"]`` (docs/table_accuracy.md, "One equilibrium path").

``strain.path: quasi_static`` replaces 1.-3. by ``strain.substeps`` sub-increments, each the
affine increment applied to every node as the predictor (the ends exactly on their targets)
and the static solve from there (``_quasi_static_step``): no dynamics, so with friction every
sub-increment is one committed backward-Euler step of the slip.

Friction (``friction`` with mu > 0; docs/contact.md "Friction in the RVE pipeline"): the
relaxation is frictionless; the strain path's systems carry the friction law
(``mech_system``), the history passes from the input state to each phase's system
(``seed_friction``) and is committed by every accepted time step and by the static solve;
``friction_record`` is what the checkpoint stores, ``friction_start`` the relaxed state's
history (no elastic gap), ``friction_summary`` the step's record. A loading-unloading cycle
(``strain.cycle_modes``) is the same step between the levels of ``cycle_levels``
(``strain_step(levels=...)``).

If the driven phase fails (step control exhausted), the remaining part of the field is
applied kinematically (an affine move of every node) and the failure is recorded in
the step's ``info``; the ends always land exactly on X + eps_n X1 e_i.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from types import SimpleNamespace

import numpy as np

from ..fabrics.setup import clamped_ends, contact_params, mechanics_system
from ..model import ContactSystem
from ..solvers.frictional import friction_of
from ..solvers.relaxation import RelaxSettings, relax_to_equilibrium
from .branch import BRANCH_COUNTS
from .cell_statics import (cut_retries, cycle_levels, free_residual, static_minimize, static_polish, strain_levels,
                           trellis_gradient)
from .continuation import arc_settings, periodic_arc, pinned_arc
from .friction_history import friction_law, friction_record, friction_summary, seed_friction
from .multipliers import equilibrium, multiplier_record, seed_multipliers

__all__ = ["mech_system", "relax_fabric", "strain_step", "strain_levels", "cycle_levels", "affine_velocity", "free_residual",
           "static_polish", "static_minimize", "MODE_DIRECTION", "MODE_SOURCE", "trellis_gradient", "secant_velocity",
           "end_targets", "pinned_energy", "cut_step", "friction_law", "friction_record", "seed_friction",
           "friction_start", "friction_summary"]

log = logging.getLogger("rve.homogenisation.strain")

#: component of the velocity field of each mode (e1 for uniaxial, e2 for shear and uniaxial_y)
MODE_DIRECTION = {"uniaxial": 0, "shear": 1, "uniaxial_y": 1, "trellis": 0}
#: reference coordinate the velocity is proportional to (X1 by default; X2 for uniaxial_y)
MODE_SOURCE = {"uniaxial_y": 1}


def mech_system(fab, mesh, cfg, damping: float, x, end_velocity=None, twist_gauge: str = "first",
                friction: bool = True) -> ContactSystem:
    """Mechanics-only ``ContactSystem`` of a strain-path phase (``rve.fabrics.setup.mechanics_system``):
    ends pinned (centroid velocity ``end_velocity``, (n_ends, 3), default 0), twist gauge,
    volumetric damping ``damping``, the contact law without conduction, the map rebuilt
    every ``strain.rebuild_every`` steps. With ``friction`` and a config whose friction is on
    (``cfg.has_friction``) the contact term carries the friction law, every fibril's family
    its yarn direction (warp, weft, loop: the keys of ``friction.pairs``), and a history that
    starts at ``x`` with no elastic gap (seed it: :func:`seed_friction`)."""
    params = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=False)
    law = friction_law(cfg) if friction else None
    if law is not None:
        params = dataclasses.replace(params, friction=law)
    system = mechanics_system(fab, mesh, cfg, params, damping, x, end_velocity=end_velocity, twist_gauge=twist_gauge)
    fr = friction_of(system)
    if fr is not None:
        fr.set_families([fab.yarns[int(y)].direction for y in fab.fibril_yarn])
    return system


def friction_start(cfg, fab, mesh, x):
    """The friction history of a state with no elastic gap anywhere (the relaxed state: the
    relaxation is frictionless, friction starts on the strain path), committed at ``x``;
    None without friction."""
    if friction_law(cfg) is None:
        return None
    if getattr(cfg, "boundary", "pinned") == "periodic":
        from .periodic import periodic_friction_start

        return periodic_friction_start(cfg, fab, mesh, x)
    system = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, np.asarray(x, float).reshape(-1))
    friction_of(system).start(np.asarray(x, float).reshape(-1))
    return friction_record(system)


def _settings(duration, steps, k, rtol, max_iter, atol, static, static_rounds=4, static_max_iter=80):
    return RelaxSettings(duration=float(duration), steps=int(steps), rebuild_every=int(k), newton_rtol=rtol,
                         newton_max_iter=int(max_iter), newton_atol=atol, static=static, static_atol=atol,
                         static_rounds=int(static_rounds), static_max_iter=int(static_max_iter))


def _summary(res, system, x) -> dict:
    st = system.contact_state(x)
    return {"converged": bool(res.static_converged) if res.static_result is not None else None,
            "dynamic_steps": int(res.dynamic_steps), "dynamic_newton_iterations": int(res.dynamic_newton_iterations),
            "static_newton_iterations": int(res.static_newton_iterations),
            "static_residuals": [float(v) for v in getattr(res.static_result, "residuals", [])][-6:],
            "t_end": float(res.t), "pairs": int(st["pairs"]), "active_pairs": int(st["active_pairs"]),
            "active_points": int(st["active_points"]), "max_overlap_over_R": float(st["max_overlap_over_R"]),
            "wall_s": {k: float(v) for k, v in res.timings.items()}}


def relax_fabric(cfg, fab, mesh, x0):
    """Relax the designed initial state (n_nodes, 9) to static equilibrium:

    1. the relaxation scene's heavily damped dynamics (``cfg.relaxation``: resolves the
       initial interpenetrations), then
    2. the settling phase (``cfg.settle``: moderate damping, the soft modes relax), then
    3. the capped-step static Newton (``cfg.relaxation``'s static settings), at most
       ``static_rounds`` x ``static_max_iter`` iterations.

    Returns ``(x (n_nodes, 9), system, info)``; ``info["residual_N"]`` is |F| on the free
    dofs at the end (the equilibrium error)."""
    if getattr(cfg, "boundary", "pinned") == "periodic":
        from .periodic import periodic_relax

        return periodic_relax(cfg, fab, mesh, x0)
    r, st = cfg.relaxation, cfg.settle
    t0 = time.perf_counter()
    x = np.asarray(x0, float).reshape(-1)
    info = {}
    if getattr(r, "method", "dynamic") == "energy":
        return _relax_energy_scene(cfg, fab, mesh, x, t0)
    system = mech_system(fab, mesh, cfg, r.damping, x, friction=False)
    s = _settings(r.duration, r.steps, r.rebuild_every, r.newton_rtol, r.newton_max_iter, r.static_atol, static=False)
    res = relax_to_equilibrium(system, x, np.zeros(system.n), s)
    info["relax"] = _summary(res, system, res.x)
    x = res.x
    if st.duration > 0:
        system = mech_system(fab, mesh, cfg, st.damping, x, friction=False)
        s2 = _settings(st.duration, st.steps, r.rebuild_every, r.newton_rtol, r.newton_max_iter, r.static_atol,
                       static=False)
        res = relax_to_equilibrium(system, x, np.zeros(system.n), s2)
        info["settle"] = _summary(res, system, res.x)
        x = res.x
    if r.static:
        t1 = time.perf_counter()
        x, sinfo = equilibrium(system, lambda xs: static_polish(system, xs, r.static_atol, r.static_rounds,
                                                                r.static_max_iter), x)
        sinfo["wall_s"] = time.perf_counter() - t1
        info["static"] = sinfo
    info.update({"converged": bool(info.get("static", {}).get("converged", False)),
                 "residual_N": free_residual(system, x), "wall_s": time.perf_counter() - t0, "dofs": int(system.n)})
    if not info["converged"]:
        log.warning("relaxation: static solve did not reach %.1e N (|F| = %.3e N)", r.static_atol, info["residual_N"])
    return x.reshape(mesh.n_nodes, 9), system, info


def _relax_energy_scene(cfg, fab, mesh, x0, t0):
    """The relaxation scene's energy path (``rve.fabrics.relaxation.relax``: onset
    continuation, optional mesh sequencing), from the designed state ``x0``."""
    from ..fabrics.relaxation import relax

    relaxed = relax(cfg)
    summary = relaxed.summary
    if not np.array_equal(relaxed.x0.reshape(mesh.n_nodes, -1)[:, :9], np.asarray(x0).reshape(mesh.n_nodes, 9)):
        raise ValueError("the relaxation started from another initial state than the fabric stage's")
    system, x = relaxed.system, relaxed.x
    if system.layout.block != 9:
        raise ValueError("relaxation system is not mechanics-only")
    x = np.asarray(x, float)
    # our clamps: the scene's (centroids of every end pinned, g1_z gauge at first nodes)
    sys_out = mech_system(fab, mesh, cfg, cfg.relaxation.damping, x, friction=False)
    al = None
    if sys_out.augmented:   # the scene relaxed with the penalty: the multipliers from here
        r = cfg.relaxation
        x, al = equilibrium(sys_out, lambda xs: static_minimize(sys_out, xs, r.static_atol, r.static_max_iter), x)
    info = {"relax": {k: summary.get(k) for k in ("static_converged", "static_newton_iterations", "map_rebuilds",
                                                 "max_overlap_over_R", "active_contact_pairs", "stack",
                                                 "static_residuals", "coarse") if k in summary},
            "method": "energy", "converged": bool(summary.get("static_converged")),
            "residual_N": free_residual(sys_out, x), "wall_s": time.perf_counter() - t0, "dofs": int(system.n)}
    if al is not None:
        info["static"] = al
        info["converged"] = bool(al["converged"])
    if not info["converged"]:
        log.warning("relaxation (energy): not converged (|F| = %.3e N)", info["residual_N"])
    return x.reshape(mesh.n_nodes, 9), sys_out, info


def affine_velocity(origin, mode: str, rate: float) -> np.ndarray:
    """The driving velocity field at the nodes, (n_nodes, 9): rate * X1 e_i on the
    centroids and rate * (g_a)_1 e_i on the directors (X, g_a of ``origin``); uniaxial_y:
    rate * X2 e2 (and (g_a)_2 e2)."""
    d = MODE_DIRECTION[mode]
    src = MODE_SOURCE.get(mode, 0)
    origin = np.asarray(origin, float)
    w = np.zeros_like(origin)
    for blk in range(3):  # r, g1, g2: the src component of each drives component d
        w[:, 3 * blk + d] = rate * origin[:, 3 * blk + src]
    return w


def secant_velocity(origin, F_prev: np.ndarray, F_next: np.ndarray, t_step: float) -> np.ndarray:
    """Driving field of a mode whose F is not linear in the strain (trellis): the constant
    velocity (F_n - F_{n-1}) X / t_step on the centroids and (F_n - F_{n-1}) g_a / t_step on
    the directors (X, g_a of ``origin``), so the ends land exactly on F_n X after t_step."""
    dF = (np.asarray(F_next, float) - np.asarray(F_prev, float)) / float(t_step)
    origin = np.asarray(origin, float)
    w = np.zeros_like(origin)
    for blk in range(3):
        w[:, 3 * blk:3 * blk + 3] = origin[:, 3 * blk:3 * blk + 3] @ dF.T
    return w


def end_targets(origin_ends: np.ndarray, mode: str, eps: float) -> np.ndarray:
    """Positions (n_ends, 3) of the pinned end centroids at strain ``eps`` of ``mode``."""
    target = np.asarray(origin_ends, float).copy()
    if mode == "trellis":
        return target @ trellis_gradient(eps).T
    d, src = MODE_DIRECTION[mode], MODE_SOURCE.get(mode, 0)
    target[:, d] += eps * origin_ends[:, src]
    return target


def strain_step(cfg, fab, mesh, x_prev, origin, mode: str, step: int, multipliers=None, friction=None,
                levels=None, loading_start=None):
    """One step of Algorithm 7.1 (or of the periodic cell, ``boundary: periodic``) from
    ``x_prev`` (n_nodes, 9) at strain eps_{step-1} to eps_step (module docstring).
    ``multipliers``: the contact multipliers of ``x_prev`` (``multipliers.multiplier_record``,
    the checkpoint's; None: zero), for ``contact.enforcement: augmented_lagrangian``.
    ``friction``: the friction history of ``x_prev`` (``friction_record``, the checkpoint's),
    with the config's friction on. ``levels``: ``(eps_from, eps_to)`` of the step instead of
    ``strain_levels`` (a loading-unloading cycle, ``cycle_levels``). ``loading_start``: the
    step starts a loading (True) or reverses it ("reversal"): the friction's stick transient
    is at its start (default: True at step 1). Returns ``(x (n_nodes, 9), system, info)``; the system holds the
    multipliers and the committed friction history of ``x``."""
    if mode not in MODE_DIRECTION:
        raise ValueError(f"mode must be one of {tuple(MODE_DIRECTION)}, got {mode!r}")
    sp_ = cfg.strain
    periodic = getattr(cfg, "boundary", "pinned") == "periodic"
    if periodic:
        from .periodic import periodic_energy, periodic_strain_step

        def part(x, e_from, e_to, whole=False, lam=multipliers, fr=friction):
            return periodic_strain_step(cfg, fab, mesh, x, origin, mode, step, None if whole else (e_from, e_to),
                                        multipliers=lam, friction=fr)

        def energy(system, x, e):
            return periodic_energy(cfg, fab, mesh, x, mode, e, multipliers if system is None else multiplier_record(system))
    else:
        stepper = _quasi_static_step if sp_.path == "quasi_static" else _algorithm_step

        def part(x, e_from, e_to, whole=False, lam=multipliers, fr=friction):
            return cut_step(lambda xs, a, b, lam_, fr_, stall: stepper(
                cfg, fab, mesh, xs, origin, mode, step, a, b, multipliers=lam_, friction=fr_, fallback_stall=stall),
                x, e_from, e_to, lam, fr, int(sp_.max_cuts), f"{mode} step {step}")

        def energy(system, x, e):
            if system is None:
                system = mech_system(fab, mesh, cfg, sp_.relax_damping, np.asarray(x, float).reshape(-1))
            return pinned_energy(fab, mesh, system, x, origin, mode, e)
    if levels is not None:
        eps_prev, eps = float(levels[0]), float(levels[1])
    else:
        if not 1 <= step <= sp_.steps:
            raise ValueError(f"step must be in 1..{sp_.steps}, got {step}")
        levels = strain_levels(cfg)
        eps_prev, eps = float(levels[step - 1]), float(levels[step])
    if sp_.follow_branch and friction_law(cfg) is not None:
        if sp_.path == "quasi_static":
            from .friction_path import frictional_branch_step

            cell = SimpleNamespace(periodic=periodic, part=part, fab=fab, mesh=mesh, origin=origin, mode=mode,
                                   branch_step=_branch_step,
                                   system=lambda xf: mech_system(fab, mesh, cfg, sp_.relax_damping, xf),
                                   energy=lambda system, xf, e: pinned_energy(fab, mesh, system, xf, origin, mode, e))
            start = step == 1 if loading_start is None else loading_start
            return frictional_branch_step(cfg, cell, x_prev, eps_prev, eps, multipliers, friction, start)
        # off the quasi-static path the balance cannot close: Algorithm 7.1's driven phase slips
        # the contacts on a dynamic path of its own, and a periodic step without sub-increments
        # is one backward-Euler increment of the slip (docs/table_accuracy.md "One equilibrium
        # path"); the step is solved once and its record says it was not tested
        x, system, info = part(x_prev, eps_prev, eps, whole=True)
        info["branch"] = {**{k: 0 for k in BRANCH_COUNTS}, "kept": "naive", "untested": "friction"}
        return x, system, info
    if sp_.follow_branch:   # one equilibrium path: detect a jump, follow the branch (rve.homogenisation.branch)
        if periodic:
            arc = periodic_arc(cfg, fab, mesh, mode, arc_settings(cfg), multipliers=multipliers)
        else:
            cell = SimpleNamespace(system=lambda xf: mech_system(fab, mesh, cfg, sp_.relax_damping, xf),
                                   targets=end_targets,
                                   energy=lambda system, xf, e: pinned_energy(fab, mesh, system, xf, origin, mode, e))
            arc = pinned_arc(cfg, fab, mesh, origin, mode, cell, arc_settings(cfg))
        return _branch_step(mesh, x_prev, eps_prev, eps, sp_, part, energy, multipliers, arc)
    return part(x_prev, eps_prev, eps, whole=True)


def cut_step(solve, x_prev, e_from: float, e_to: float, multipliers, friction, max_cuts: int, label: str = "step"):
    """``solve(x, e_a, e_b, multipliers, friction, fallback_stall) -> (x, system, info)`` from
    ``x_prev`` over [e_from, e_to], cut where it fails (``cell_statics.cut_retries``): again
    from ``x_prev`` (its multipliers and friction history) in 2, then 4, ... equal parts, each
    from the state, multipliers and committed friction history of the part before. The
    pinned cell's step cut (the periodic cell cuts into sub-increments of its own step,
    ``periodic.periodic_strain_step``). The record is the last part's, over the whole range,
    with ``cuts`` (each failed try's parts and |F|) and ``parts`` (strain, converged, wall
    time of each part) where cut; the step's friction dissipation sums the parts'."""
    t0 = time.perf_counter()

    def attempt(n, stall):
        x, lam, fr, parts, dissipated = x_prev, multipliers, friction, [], 0.0
        for k in range(n):
            b = e_to if k == n - 1 else e_from + (e_to - e_from) * (k + 1) / n
            x, system, info = solve(x, e_from + (e_to - e_from) * k / n, b, lam, fr, stall)
            parts.append({"strain": float(b), "converged": bool(info["converged"]),
                          "wall_s": float(info.get("wall_s", 0.0))})
            dissipated += float((info.get("friction") or {}).get("step_dissipated", 0.0))
            if not info["converged"]:
                break
            lam, fr = multiplier_record(system), friction_record(system)
        return (x, system, info, parts, dissipated), info["converged"], float(info.get("residual_N", np.nan))

    (x, system, info, parts, dissipated), n, cuts = cut_retries(attempt, 1, max_cuts, label)
    if n > 1:
        info = dict(info, strain=float(e_to), strain_increment=float(e_to - e_from), parts=parts,
                    wall_s=time.perf_counter() - t0)
        if info.get("friction"):
            info["friction"] = dict(info["friction"], step_dissipated=dissipated)
    if cuts:
        info = dict(info, cuts=cuts)
    return x, system, info


def _branch_step(mesh, x_prev, eps_prev, eps, sp_, part, energy_of, multipliers=None, arc=None, friction=None,
                 start=None):
    """The step ``part(x, eps_from, eps_to)`` through ``branch.follow_branch``: the potential
    of a state and its load derivative ``energy_of(system, x, eps)`` (pinned: the clamp
    forces times the end velocity per unit strain, ``pinned_energy``; periodic: the
    Hill-Mandel work rate, ``periodic.periodic_energy``); the inertia from the energy
    minimiser's definiteness verdict. A part starts from the multipliers and the friction
    history of the state it starts from (``multipliers``, ``friction`` for the step's start
    ``x_prev``, or ``start``, a ``StepSolution`` at ``eps_prev`` with its system). ``arc``:
    the continuation of a detected step (``rve.homogenisation.continuation``;
    ``strain.branch_method``)."""
    from .branch import BranchSettings, StepSolution, follow_branch

    t0 = time.perf_counter()
    nn = mesh.n_nodes

    def solve(start, e_from, e_to):
        lam = multipliers if start.extra is None else multiplier_record(start.extra)
        fr = friction if start.extra is None else friction_record(start.extra)
        x2, sys2, inf = part(start.x, e_from, e_to, lam=lam, fr=fr)
        return StepSolution(x2, inf, sys2)

    def energy(sol, e):
        return energy_of(sol.extra, sol.x, e)

    def inertia(sol):
        k = (sol.info.get("static") or {}).get("negative_pivots")
        return None if k is None or k < 0 else int(k)

    def distance(xa, xb):   # centroid distance (mm)
        return float(np.abs(np.asarray(xa).reshape(nn, 9)[:, :3] - np.asarray(xb).reshape(nn, 9)[:, :3]).max())

    settings = BranchSettings(energy_rtol=float(sp_.branch_energy_rtol), max_halvings=int(sp_.branch_max_halvings),
                              state_tol=float(sp_.branch_state_tol), method=str(sp_.branch_method),
                              persist_ratio=float(sp_.branch_persist_ratio))
    if start is None:
        start = StepSolution(np.array(x_prev, float).reshape(nn, 9))
    sol, binfo = follow_branch(solve, start, eps_prev, eps, energy, inertia=inertia, distance=distance,
                               settings=settings, arc=arc)
    info = dict(sol.info)
    info.update({"strain": float(eps), "strain_increment": float(eps - eps_prev), "branch": binfo,
                 "wall_s": time.perf_counter() - t0})
    return sol.x, sol.extra, info


def pinned_energy(fab, mesh, system, x, origin, mode: str, eps: float) -> tuple:
    """``(Pi, dPi/deps)`` of an equilibrium of the pinned cell at strain ``eps``: the
    potential ``system.energy(x)`` (N mm) and the work rate of the clamps, sum over the
    pinned centroids of the clamp force (the residual there) times d(end target)/d eps (N mm
    per unit strain): along a branch dPi/deps equals it, the free residual being zero."""
    xf = np.asarray(x, float).reshape(-1)
    ends, pinned, _ = clamped_ends(fab, mesh)
    F, _, _ = system.evaluate(xf, np.zeros(system.n), 0.0, jacobian=False)
    origin_ends = np.asarray(origin, float)[ends, :3]
    h = 1e-6
    rate = (end_targets(origin_ends, mode, eps + h) - end_targets(origin_ends, mode, eps - h)) / (2.0 * h)
    work_rate = float(np.asarray(F)[np.asarray(pinned, dtype=np.int64)] @ rate.reshape(-1))
    return float(system.energy(xf)), work_rate


def _quasi_static_step(cfg, fab, mesh, x_prev, origin, mode: str, step: int, eps_prev: float, eps: float,
                       multipliers=None, friction=None, fallback_stall=None):
    """``strain.path: quasi_static`` from ``x_prev`` at ``eps_prev`` to ``eps``: ``strain.substeps``
    equal sub-increments, each the affine increment of the mode applied to every node as the
    predictor (``affine_velocity`` / ``secant_velocity`` times a unit time; the ends exactly on
    their targets) and the static solve from there (``cell_statics.static_minimize``: the energy
    minimiser, or with friction the committed frictional residual solve from the history of
    the last sub-increment; in the Uzawa loop with the augmented Lagrangian). No dynamics: with
    friction each sub-increment is one backward-Euler step of the slip, so the return-map
    dissipation is that of the quasi-static path (Algorithm 7.1's driven phase makes contacts
    slip on its way, docs/contact.md "Friction in the RVE pipeline")."""
    sp_ = cfg.strain
    t_start = time.perf_counter()
    nn = mesh.n_nodes
    origin = np.asarray(origin, float)
    x = np.array(x_prev, float).reshape(nn, 9)
    ends, _, _ = clamped_ends(fab, mesh)
    system = mech_system(fab, mesh, cfg, sp_.relax_damping, x.reshape(-1))
    seed_multipliers(system, multipliers)
    seed_friction(system, friction, x.reshape(-1))
    fr = friction_of(system)
    d_start = 0.0 if fr is None else float(fr.dissipated)
    n = int(sp_.substeps)
    levels = [eps_prev + (eps - eps_prev) * k / n for k in range(n)] + [float(eps)]
    info = {"mode": mode, "step": int(step), "strain": float(eps), "strain_increment": float(eps - eps_prev),
            "path": "quasi_static", "substeps": []}

    def static(xs):
        return static_minimize(system, xs, sp_.static_atol, sp_.static_max_iter, commit=False,
                               fallback_stall=fallback_stall)

    sinfo = {"converged": True}
    for k in range(1, n + 1):
        t0 = time.perf_counter()
        if mode == "trellis":
            du = secant_velocity(origin, trellis_gradient(levels[k - 1]), trellis_gradient(levels[k]), 1.0)
        else:
            du = affine_velocity(origin, mode, levels[k] - levels[k - 1])
        x = x + du
        x[ends, :3] = end_targets(origin[ends, :3], mode, levels[k])
        x2, sinfo = equilibrium(system, static, x.reshape(-1))
        x = np.asarray(x2, float).reshape(nn, 9)
        sinfo["wall_s"] = time.perf_counter() - t0
        info["substeps"].append({"strain": float(levels[k]), "converged": bool(sinfo["converged"]),
                                 "iterations": int(sinfo.get("iterations", 0)), "wall_s": sinfo["wall_s"]})
        if not sinfo["converged"]:
            log.warning("%s step %d: sub-increment %d of %d (strain %g) did not converge", mode, step, k, n,
                        levels[k])
            break
    info["static"] = sinfo
    info["converged"] = bool(sinfo["converged"])
    info["residual_N"] = free_residual(system, x)
    if fr is not None:
        info["friction"] = friction_summary(system, d_start)
    info["wall_s"] = time.perf_counter() - t_start
    if not info["converged"]:
        log.warning("%s step %d: static solve did not reach %.1e N (|F| = %.3e N)", mode, step, sp_.static_atol,
                    info["residual_N"])
    return x, system, info


def _algorithm_step(cfg, fab, mesh, x_prev, origin, mode: str, step: int, eps_prev: float, eps: float,
                    multipliers=None, friction=None, fallback_stall=None):
    """Algorithm 7.1 from ``x_prev`` at strain ``eps_prev`` to ``eps`` (module docstring;
    ``step`` labels the record). The multipliers (``strain_step``) pass from phase to phase;
    the static solve is in the Uzawa loop (``multipliers.equilibrium``). So does the friction
    history (``friction``, that of ``x_prev``): every accepted time step of the two dynamic
    phases commits it (``relax_to_equilibrium``), the static solve solves the residual from it
    (``cell_statics.static_minimize``) and commits the solution."""
    sp_ = cfg.strain
    t_start = time.perf_counter()
    d_eps = float(eps - eps_prev)
    eps = float(eps)
    rate = d_eps / sp_.t_step
    nn = mesh.n_nodes
    origin = np.asarray(origin, float)
    x = np.array(x_prev, float).reshape(nn, 9)
    ends, _, _ = clamped_ends(fab, mesh)
    if mode == "trellis":  # F(theta) is not linear in theta: the secant field of the step
        w_aff = secant_velocity(origin, trellis_gradient(float(eps_prev)), trellis_gradient(eps), sp_.t_step)
    else:
        w_aff = affine_velocity(origin, mode, rate)
    end_vel = w_aff[ends, :3]
    info = {"mode": mode, "step": int(step), "strain": eps, "strain_increment": d_eps}

    # 1. driven phase
    t0 = time.perf_counter()
    sys1 = mech_system(fab, mesh, cfg, sp_.damping, x, end_velocity=end_vel)
    seed_multipliers(sys1, multipliers)
    seed_friction(sys1, friction, x.reshape(-1))
    fr1 = friction_of(sys1)
    d_start = 0.0 if fr1 is None else float(fr1.dissipated)
    s1 = _settings(sp_.t_step, sp_.stretch_steps, sp_.rebuild_every, sp_.newton_rtol, sp_.newton_max_iter,
                   sp_.static_atol, static=False)
    res1 = relax_to_equilibrium(sys1, x.reshape(-1), w_aff.reshape(-1), s1)
    x1 = res1.x.reshape(nn, 9).copy()
    done = res1.t / sp_.t_step if sp_.t_step > 0 else 1.0
    info["driven"] = {"t_reached": float(res1.t), "dynamic_steps": int(res1.dynamic_steps),
                      "newton_iterations": int(res1.dynamic_newton_iterations),
                      "wall_s": time.perf_counter() - t0}
    if done < 1.0 - 1e-9:
        log.warning("driven phase stopped at %.3g of t_step; the rest of the field is applied kinematically", done)
        x1 += (1.0 - done) * sp_.t_step * w_aff
        info["driven"]["kinematic_fraction"] = float(1.0 - done)
    # the ends land exactly on X + eps X1 e_i (the integration puts them there to round-off)
    if mode == "trellis":
        target = end_targets(origin[ends, :3], mode, eps)
    else:  # (the original arithmetic of uniaxial and shear, unchanged)
        d = MODE_DIRECTION[mode]
        target = origin[ends, :3].copy()
        target[:, d] += eps * origin[ends, MODE_SOURCE.get(mode, 0)]
    info["driven"]["end_drift_mm"] = float(np.abs(x1[ends, :3] - target).max())
    x1[ends, :3] = target

    # 2.-3. heavily damped relaxation with the ends held, then the static solve
    t0 = time.perf_counter()
    sys2 = mech_system(fab, mesh, cfg, sp_.relax_damping, x1)
    seed_multipliers(sys2, multiplier_record(sys1))
    seed_friction(sys2, friction_record(sys1), x1.reshape(-1))
    s2 = _settings(sp_.t_relax, sp_.relax_steps, sp_.rebuild_every, sp_.newton_rtol, sp_.newton_max_iter,
                   sp_.static_atol, static=False)
    res2 = relax_to_equilibrium(sys2, x1.reshape(-1), np.zeros(sys2.n), s2)
    info["relax"] = _summary(res2, sys2, res2.x)
    info["relax"]["wall_s_total"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if sp_.static_method == "energy":
        def static(xs):
            return static_minimize(sys2, xs, sp_.static_atol, sp_.static_max_iter, commit=False,
                                   fallback_stall=fallback_stall)
    else:
        def static(xs):
            return static_polish(sys2, xs, sp_.static_atol, sp_.static_rounds, sp_.static_max_iter)
    x2, sinfo = equilibrium(sys2, static, res2.x)
    sinfo["wall_s"] = time.perf_counter() - t0
    info["static"] = sinfo
    x2 = x2.reshape(nn, 9)
    info["converged"] = bool(sinfo["converged"])
    info["residual_N"] = free_residual(sys2, x2)
    if friction_of(sys2) is not None:
        info["friction"] = friction_summary(sys2, d_start)
    info["wall_s"] = time.perf_counter() - t_start
    if not info["converged"]:
        log.warning("%s step %d: static solve did not reach %.1e N (|F| = %.3e N)", mode, step, sp_.static_atol,
                    info["residual_N"])
    return x2, sys2, info
