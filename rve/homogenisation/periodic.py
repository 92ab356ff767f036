"""The periodic cell of the RVE pipeline (``boundary: periodic``; docs/periodic.md).

Contract
--------
The cell is the weave of the config (``RVEConfig`` sets its yarn counts to the pattern's
repeat times ``cell.repeat``): every fibril spans one period, its last node is tied to its
first (``rve.model.periodic``). The mechanics is the reduced system
``PeriodicSystem(ContactSystem(BeamModel without boundary conditions))`` with

* the rigid translation removed by holding the centroid of the first node of fibril 0,
* the twist gauge g1_z at each fibril's first node (the pinned cell's gauge, docs/relaxation.md).

Functions (each returns the **full**, unrolled state (n_nodes, 9), so checkpoints, probes,
pictures and the clamp-force sums of ``rve.fabrics.setup.clamp_reactions`` read it as a
pinned state):

* :func:`macro_gradient` -- the in-plane F of a mode at a strain (uniaxial: diag(1 + e, 1);
  uniaxial_y: diag(1, 1 + e); shear: F21 = e, the pinned cell's v = e X1 e2; trellis:
  ``strain.trellis_gradient``);
* :func:`periodic_relax` -- the relaxed cell at F = I (``rve.solvers.relaxation`` on the
  reduced system, the config's relaxation settings; with ``relaxation.coarse_elements``
  from the coarse cell's relaxed minimum, interpolated);
* :func:`periodic_strain_step` -- one step: F_{n-1} -> F_n, predictor the affine map
  F_n F_{n-1}^-1 of the previous state about the held node, then the static minimisation
  (``cell_statics.static_minimize``), or a part of it (``eps_range``: the step halving of
  ``strain.follow_branch``);
* :func:`periodic_energy` -- the potential of a state and its load derivative, the
  Hill-Mandel work rate (the one-path test of ``rve.homogenisation.branch``);
* :func:`cell_gradient` -- the F a stored full state carries (its tie jumps), and
  :func:`periodic_free_residual` -- |F| on the free reduced dofs of a stored state;
* :func:`gauge_dofs` -- the held reduced dofs above;
* :func:`newton_polish` -- a few Newton steps after an energy minimisation that stopped
  within a factor ``POLISH_FACTOR`` of its tolerance (relaxation and strain steps).

The face forces of a state (``info["reaction_force"]``, :func:`cell_reactions`) are the
Hill-Mandel stress ``PeriodicSystem.macro_stress`` (the tie forces and the contact forces
on the periodic images) times the face lengths, in the layout of the pinned cell's clamp
forces, so the table's ``membrane_force`` (the + side force over the edge length) is the
column P e_j. (The clamp-force sums of the full system alone would miss the contacts
with the images.)
"""
from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..fabrics.setup import contact_params
from ..fem.assembly import DofLayout
from ..model import BeamMaterial, BeamModel, ContactSystem
from ..model.periodic import PeriodicSystem, fibril_end_ties
from ..solvers.system import friction_of
from .cell_statics import cut_retries, free_residual, static_minimize, static_polish, strain_levels, trellis_gradient
from .multipliers import equilibrium, seed_multipliers

__all__ = ["cell_ties", "periodic_system", "macro_gradient", "periodic_relax", "periodic_strain_step",
           "cell_gradient", "periodic_free_residual", "gauge_dofs", "full_state", "cell_reactions", "newton_polish",
           "periodic_energy"]

log = logging.getLogger("rve.homogenisation.periodic")


def cell_ties(fab, mesh):
    """The ties of a periodic weave cell: each fibril's end is its start's image; the
    periods are the box sides (2 hx, 2 hy)."""
    hx, hy = float(fab.half_widths[0]), float(fab.half_widths[1])
    return fibril_end_ties(mesh, [[2.0 * hx, 0.0, 0.0], [0.0, 2.0 * hy, 0.0]])


def gauge_dofs(ties, mesh, fields=("mech",)) -> np.ndarray:
    """Reduced dofs held in the mechanics: the centroid of fibril 0's first node (the rigid
    translation), g1_z at every fibril's first node (the twist gauge)."""
    first = np.searchsorted(ties.kept_nodes, mesh.node_offsets[:-1])
    lay = DofLayout(ties.kept_nodes.size, fields)
    return np.concatenate([lay.dofs("r", first[:1]), lay.dofs("g1", first, comp=2)])


def periodic_system(cfg, fab, mesh, x_full, F, damping: float = 0.0, params=None,
                    friction: bool = False) -> PeriodicSystem:
    """The reduced mechanics system of the cell at macro gradient ``F`` (module docstring),
    its contact map built at the reduced dofs of the full state ``x_full`` (its image nodes
    placed by ``F``). With ``friction`` and a config whose friction is on, the contact term
    carries the friction law (every fibril's family its yarn direction) and a history that
    starts at ``x_full`` with no elastic gap (seed it: ``strain.seed_friction``); the
    relaxation's system has none."""
    from .friction_history import friction_law

    m = cfg.material
    params = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=False) \
        if params is None else params
    law = friction_law(cfg) if friction else None
    if law is not None:
        params = dataclasses.replace(params, friction=law)
    mat = BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density, damping=float(damping))
    base = BeamModel(mesh, mat, disk_points=cfg.mesh.disk_points, axial_points=cfg.mesh.axial_points)
    x_full = np.asarray(x_full, float).reshape(-1)
    full = ContactSystem(base, params, x_full)
    ties = cell_ties(fab, mesh)
    psys = PeriodicSystem(full, ties, gauge_dofs(ties, mesh), 0.0, F=F, contact_images=cfg.cell.contact_images)
    fr = friction_of(psys)
    if fr is not None:   # the plain cell's first map had no wraps: on the C¹ curve its ends differ
        fr.forget()
    # the map at the state the reduced dofs describe (the images where F puts them)
    psys.rebuild(psys.restrict(x_full))
    if fr is not None:
        fr.set_families([fab.yarns[int(y)].direction for y in fab.fibril_yarn])
    return psys


def cell_reactions(fab, psys, x_red) -> dict:
    """The Hill-Mandel stress as forces per cell face (N), the layout of the pinned cell's
    clamp forces: ``x+`` = P e1 L_y (``x-`` minus that), ``y+`` = P e2 L_x; so the table's
    ``membrane_force`` (the + side force over the edge length) is P e_j."""
    P = psys.macro_stress(x_red)
    L = 2.0 * np.asarray(fab.half_widths[:2], float)
    out = {}
    for j, name in ((0, "x"), (1, "y")):
        col = P[:, j] * L[1 - j]
        out[f"{name}-"] = [float(-v) for v in col]
        out[f"{name}+"] = [float(v) for v in col]
    return out


def macro_gradient(mode: str, eps: float) -> np.ndarray:
    """In-plane macro gradient (3, 3), F33 = 1, of ``mode`` at strain ``eps``."""
    F = np.eye(3)
    if mode == "uniaxial":
        F[0, 0] += eps
    elif mode == "uniaxial_y":
        F[1, 1] += eps
    elif mode == "shear":
        F[1, 0] = eps
    elif mode == "trellis":
        F = trellis_gradient(eps)
    else:
        raise ValueError(f"mode must be uniaxial, uniaxial_y, shear or trellis, got {mode!r}")
    return F


def full_state(psys, x_red) -> np.ndarray:
    """The full nodal state (n_nodes, 9) of reduced dofs ``x_red``."""
    return psys.expand(x_red).reshape(psys.ties.n_nodes, -1)[:, :9].copy()


def cell_gradient(fab, mesh, x_full) -> np.ndarray:
    """The macro gradient (3, 3) a full state carries: its tie jumps r(end) - r(start) =
    F dX, solved for F by least squares over the ties (exact for a periodic state)."""
    ties = cell_ties(fab, mesh)
    x = np.asarray(x_full, float).reshape(mesh.n_nodes, -1)
    d = x[ties.image, :3] - x[ties.master, :3]
    F, *_ = np.linalg.lstsq(ties.jump[:, :2], d, rcond=None)
    out = np.eye(3)
    out[:, :2] = F.T
    return out


def periodic_free_residual(cfg, fab, mesh, x_full, F=None, multipliers=None, friction=None) -> float:
    """|F| on the free reduced dofs (N) of a full state (its own gradient unless given), at
    its contact ``multipliers`` (a record, augmented Lagrangian; None: none) and with its
    friction history (``friction``, a record; None with the config's friction on: every
    contact starts at the state with no elastic gap, i.e. no friction force)."""
    from .friction_history import seed_friction

    F = cell_gradient(fab, mesh, x_full) if F is None else F
    psys = periodic_system(cfg, fab, mesh, x_full, F, friction=True)
    xr = psys.restrict(np.asarray(x_full, float).reshape(-1))
    seed_multipliers(psys, multipliers)
    seed_friction(psys, friction, xr)
    return free_residual(psys, xr)


def periodic_friction_start(cfg, fab, mesh, x_full):
    """The friction history of the relaxed cell (at F = I) with no elastic gap anywhere,
    committed there, image pairs included (keyed by their lattice translation); None
    without friction."""
    psys = periodic_system(cfg, fab, mesh, x_full, np.eye(3), friction=True)
    fr = friction_of(psys)
    if fr is None:
        return None
    fr.start(psys.restrict(np.asarray(x_full, float).reshape(-1)))
    return fr.record()


def periodic_relax(cfg, fab, mesh, x0):
    """Relax the designed periodic cell at F = I (the relaxation settings of ``cfg``:
    energy path with onset continuation, or damped dynamics). With
    ``relaxation.coarse_elements`` (energy path, mesh sequencing): the designed cell is
    relaxed first on that many elements per fibril (the whole onset schedule, its own
    Uzawa loop), its minimum interpolated onto ``mesh`` (``rve.fem.transfer``) and relaxed
    there with ``relaxation.fine_onset_continuation`` + ``[contact.onset]``, so that meshes
    sequenced from one coarse mesh start in that mesh's packing. Returns ``(x (n_nodes, 9),
    full system, info)``."""
    from ..fabrics.relaxation import fine_settings, relax_settings, sequenced

    t0 = time.perf_counter()
    coarse, settings = None, relax_settings(cfg)
    if sequenced(cfg):
        x0, coarse = _coarse_relaxation(cfg, mesh)
        settings = fine_settings(cfg)
    x, system, info = _relax_cell(cfg, fab, mesh, x0, settings)
    info["wall_s"] = time.perf_counter() - t0
    if coarse is not None:
        info["coarse_stage"] = coarse
    return x, system, info


def _coarse_relaxation(cfg, mesh):
    """The mesh sequencing's coarse stage of ``periodic_relax``: ``(x0 on mesh, record)``."""
    from ..fabrics.relaxation import coarse_mesh_section
    from ..fabrics.setup import fabric_and_mesh
    from ..fem.transfer import interpolate_nodal

    r = cfg.relaxation
    ccfg = cfg.model_copy(update={"mesh": coarse_mesh_section(cfg),
                                  "relaxation": r.model_copy(update={"coarse_elements": None})})
    cfab, cmesh = fabric_and_mesh(ccfg)
    xc, _, cinfo = periodic_relax(ccfg, cfab, cmesh, cfab.initial_state(cmesh))
    x0 = interpolate_nodal(cmesh, np.asarray(xc, float).reshape(cmesh.n_nodes, -1), mesh)
    record = {"elements_per_fibril": int(r.coarse_elements), "dofs": int(cinfo["dofs"]),
              "converged": bool(cinfo["converged"]), "residual_N": float(cinfo["residual_N"]),
              "max_overlap_over_R": float(cinfo["max_overlap_over_R"]), "wall_s": float(cinfo["wall_s"])}
    log.info("periodic relaxation: coarse stage on %d elements per fibril (converged %s), interpolated onto %d",
             int(r.coarse_elements), record["converged"], int(cfg.mesh.elements))
    return x0, record


def _relax_cell(cfg, fab, mesh, x0, settings):
    """``periodic_relax`` on one mesh from ``x0`` with the relaxation ``settings``."""
    from ..solvers.relaxation import relax_to_equilibrium

    params = contact_params(cfg.contact, rebuild_every=cfg.relaxation.rebuild_every, conduction=False)
    psys = periodic_system(cfg, fab, mesh, x0, np.eye(3), cfg.relaxation.damping, params)
    xr = psys.restrict(np.asarray(x0, float).reshape(-1))
    res = relax_to_equilibrium(psys, xr, np.zeros(psys.n), settings)
    xs, converged, polish = newton_polish(psys, res.x, bool(res.static_converged), cfg.relaxation.static_atol)
    al = None
    if psys.augmented:   # relaxed with the penalty: the multipliers from here
        r = cfg.relaxation
        xs, al = equilibrium(psys, lambda xv: static_minimize(psys, xv, r.static_atol, r.static_max_iter), xs)
        converged = bool(al["converged"])
    st = psys.contact_state(xs)
    info = {"method": cfg.relaxation.method, "boundary": "periodic", "converged": converged, "polish": polish,
            "residual_N": free_residual(psys, xs), "dofs": int(psys.n),
            "static_newton_iterations": int(res.static_newton_iterations),
            "max_overlap_over_R": float(st["max_overlap_over_R"]), "active_pairs": int(st["active_pairs"]),
            "macro_stress_N_per_mm": psys.macro_stress(xs)[:2, :2].tolist(),
            "reaction_force": cell_reactions(fab, psys, xs)}
    if al is not None:
        info["static"] = al
    if not info["converged"]:
        log.warning("periodic relaxation: not converged (|F| = %.3e N)", info["residual_N"])
    return full_state(psys, xs), psys.full, info


#: the Newton polish starts only this close to the tolerance (|F| <= factor x atol): near
#: a minimum, where the energy change of a step is below the rounding of the energy
POLISH_FACTOR = 1e3


def newton_polish(psys, x, converged: bool, atol: float, max_iter: int = 8):
    """``(x, converged, info)``: the energy minimiser's result, and where it stopped short
    of ``atol`` but within ``POLISH_FACTOR`` of it, a few Newton steps more
    (``strain.static_polish``: |F| never increases). There the energy changes of its steps
    are below the rounding of the energy and the minimiser, which takes the energy as
    merit, can no longer tell a descent step; Newton's quadratic rate from that close
    stays on the same minimum."""
    r0 = free_residual(psys, x)
    if converged or not r0 <= POLISH_FACTOR * atol:
        return x, bool(converged), None
    xp, pinfo = static_polish(psys, x, atol, 1, max_iter)
    r1 = free_residual(psys, xp)
    info = {"from_N": float(r0), "to_N": float(r1), "iterations": int(pinfo["iterations"])}
    log.info("Newton polish: |F| %.3e -> %.3e N in %d iterations", r0, r1, pinfo["iterations"])
    if not r1 < r0:
        return x, False, info
    return xp, bool(pinfo["converged"] and r1 <= atol), info


def _affine_predictor(x_prev, dF, centre) -> np.ndarray:
    """The previous full state mapped by dF about ``centre``: r -> centre + dF (r - centre),
    g_a -> dF g_a (the ties stay satisfied at the new F)."""
    x = np.array(x_prev, float).reshape(-1, 9)
    x[:, :3] = centre + (x[:, :3] - centre) @ dF.T
    x[:, 3:6] = x[:, 3:6] @ dF.T
    x[:, 6:9] = x[:, 6:9] @ dF.T
    return x


def periodic_strain_step(cfg, fab, mesh, x_prev, origin, mode: str, step: int, eps_range=None, multipliers=None,
                         friction=None):
    """One strain step of the periodic cell from ``x_prev`` (full, n_nodes x 9) at strain
    eps_{step-1} to eps_step (module docstring), or between the strains ``eps_range = (from,
    to)`` (a part of the step, ``strain.follow_branch``; ``step`` labels the record).
    ``origin`` (the relaxed state) is not used: the cell's strain is its macro gradient,
    exact by construction. ``multipliers``: the contact multipliers of ``x_prev`` (the static
    solve is in the Uzawa loop, ``multipliers.equilibrium``). ``friction``: the friction
    history of ``x_prev`` (with the config's friction on): the static solve is the frictional
    residual from it, committed once at the Uzawa loop's converged state. With ``strain.path:
    quasi_static`` the step is ``strain.substeps`` sub-increments of F, each the affine
    predictor and that static solve (with friction one committed backward-Euler step of the
    slip each), on one system (``set_macro``); otherwise one. A step whose solve fails is cut:
    solved again from ``x_prev`` (its multipliers and friction history) in twice as many
    sub-increments, at most ``strain.max_cuts`` times (``info["cuts"]``); a try that can still
    be cut ends the frictional solve's fallback where it stalls (``cell_statics.cut_retries``),
    the last try has all of it. Returns ``(x
    (n_nodes, 9), full system, info)``."""
    from .friction_history import friction_summary

    del origin
    sp_ = cfg.strain
    if not 1 <= step <= sp_.steps:
        raise ValueError(f"step must be in 1..{sp_.steps}, got {step}")
    t0 = time.perf_counter()
    levels = strain_levels(cfg)
    eps_from, eps_to = (float(levels[step - 1]), float(levels[step])) if eps_range is None else map(float, eps_range)
    n = int(sp_.substeps) if sp_.path == "quasi_static" else 1
    x_prev = np.asarray(x_prev, float).reshape(mesh.n_nodes, 9)

    def attempt(k, stall):
        out = _increments(cfg, fab, mesh, x_prev, mode, step, eps_from, eps_to, k, multipliers, friction, stall)
        return out, out[4]["converged"], free_residual(out[1], out[7])

    out, n, cuts = cut_retries(attempt, n, sp_.max_cuts, f"{mode} step {step} (periodic)")
    x_full, psys, fr, d_start, sinfo, sub_info, F_next, xs = out
    sinfo["wall_s"] = time.perf_counter() - t0
    info = {"mode": mode, "step": int(step), "strain": eps_to,
            "strain_increment": eps_to - eps_from, "boundary": "periodic",
            "macro_gradient": F_next.tolist(), "static": sinfo, "converged": bool(sinfo["converged"]),
            "residual_N": free_residual(psys, xs), "energy_mJ": float(psys.energy(xs)),
            "macro_stress_N_per_mm": psys.macro_stress(xs)[:2, :2].tolist(),
            "reaction_force": cell_reactions(fab, psys, xs), "wall_s": time.perf_counter() - t0}
    if n > 1:
        info.update({"path": "quasi_static", "substeps": sub_info})
    if cuts:
        info["cuts"] = cuts
    if fr is not None:
        info["friction"] = friction_summary(psys, d_start)
    if not info["converged"]:
        log.warning("%s step %d (periodic): static solve did not reach %.1e N (|F| = %.3e N)", mode, step,
                    sp_.static_atol, info["residual_N"])
    return x_full, psys.full, info


def _increments(cfg, fab, mesh, x_prev, mode, step, eps_from, eps_to, n, multipliers, friction,
                fallback_stall=None):
    """``periodic_strain_step``'s solve in ``n`` increments from ``x_prev`` on a new system
    (the multipliers and friction history of ``x_prev`` seeded): ``(x_full, psys, friction
    view, dissipation at the start, static info of the last increment, per-increment records,
    the last macro gradient, the reduced state)``; it stops at the first increment that fails.
    ``fallback_stall``: the stall window of the frictional solves' fallback (``static_minimize``)."""
    from .friction_history import seed_friction

    sp_ = cfg.strain
    subs = [eps_from + (eps_to - eps_from) * k / n for k in range(n)] + [eps_to]
    held = int(mesh.node_offsets[0])
    centre = x_prev[held, :3]

    def static(xv):   # the energy minimiser, then the Newton polish close to the tolerance
        xm, si = static_minimize(psys, xv, sp_.static_atol, sp_.static_max_iter, commit=False,
                                 fallback_stall=fallback_stall)
        xm, si["converged"], si["polish"] = newton_polish(psys, xm, si["converged"], sp_.static_atol)
        return xm, si

    psys, fr, d_start, sub_info, x_full = None, None, 0.0, [], x_prev
    for k in range(1, n + 1):
        t1 = time.perf_counter()
        F_prev, F_next = macro_gradient(mode, subs[k - 1]), macro_gradient(mode, subs[k])
        x_pred = _affine_predictor(x_full, F_next @ np.linalg.inv(F_prev), centre)
        if psys is None:
            psys = periodic_system(cfg, fab, mesh, x_pred, F_next, friction=True)
            xr = psys.restrict(x_pred.reshape(-1))
            seed_multipliers(psys, multipliers)
            seed_friction(psys, friction, xr)
            fr = friction_of(psys)
            d_start = 0.0 if fr is None else float(fr.dissipated)
        else:
            psys.set_macro(F_next)
            xr = psys.restrict(x_pred.reshape(-1))
            psys.rebuild(xr)
        xs, sinfo = equilibrium(psys, static, xr)
        x_full = full_state(psys, xs)
        sinfo["wall_s"] = time.perf_counter() - t1
        if n > 1:
            sub_info.append({"strain": float(subs[k]), "converged": bool(sinfo["converged"]),
                             "iterations": int(sinfo.get("iterations") or 0), "wall_s": sinfo["wall_s"]})
        if not sinfo["converged"]:
            if n > 1:
                log.warning("%s step %d (periodic): sub-increment %d of %d (strain %g) did not converge", mode,
                            step, k, n, subs[k])
            break
    return x_full, psys, fr, d_start, sinfo, sub_info, F_next, xs


def periodic_energy(cfg, fab, mesh, x_full, mode: str, eps: float, multipliers=None, friction=None) -> tuple:
    """``(Pi, dPi/deps)`` of an equilibrium of the cell at strain ``eps`` (the one-path test
    of ``rve.homogenisation.branch``): the potential of the reduced system at the mode's
    macro gradient (N mm) and its load derivative, the Hill-Mandel work rate A P : dF/deps
    (``PeriodicSystem.macro_stress`` is dPi/dF / A at an equilibrium). With the contact
    ``multipliers`` of the state (augmented Lagrangian) the stress includes their line loads,
    while the potential stays that of the true overlaps: the impenetrable limit's contact
    forces do no work, so its potential is the elastic energy (plus the penalty energy of
    the overlap left below al_tolerance), and the multiplier shift's constant terms, which
    differ from state to state, are no part of it. With the ``friction`` history committed at
    the state the stress includes the friction forces (the potential does not: friction has
    none; ``rve.homogenisation.friction_path`` adds the dissipation)."""
    from .friction_history import seed_friction

    F = macro_gradient(mode, eps)
    psys = periodic_system(cfg, fab, mesh, x_full, F, friction=friction is not None)
    xr = psys.restrict(np.asarray(x_full, float).reshape(-1))
    energy = float(psys.energy(xr))
    seed_multipliers(psys, multipliers)
    seed_friction(psys, friction, xr)
    h = 1e-6   # dF/deps: exact for the linear modes, the trellis gradient's central difference
    dF = (macro_gradient(mode, eps + h) - macro_gradient(mode, eps - h)) / (2.0 * h)
    return energy, float(psys.ties.area * np.sum(psys.macro_stress(xr) * dF))

