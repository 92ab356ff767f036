"""Yarn pull-out from the RVE (``pullout`` section of the RVE config; docs/rve_pipeline.md
"Yarn pull-out").

From the relaxed state of the pinned cell, one yarn (``pullout.yarn``, ``pullout.position``:
e.g. the warp yarn at y = -1 mm) is pulled out along its axis: the centroids of its fibril
ends on the + side (x+ for a warp yarn, y+ for a weft yarn) are moved by the pull-out
displacement u along the axis, its ends on the - side are **released along the axis** (free
to slide axially; their transverse position stays held, as the fabric beyond the cell holds
the yarn in place: a free end would lift off its crossings and hang), and every other fibril
end stays pinned where the relaxation left it (the twist gauge as on the strain path).
The yarn can slide through the crossings only against the crimp interlock and, with
friction, against mu times the crossings' normal forces.

Contract
--------
* :func:`pullout_levels` ``(cfg)`` -> u after step 0..steps (mm);
* :func:`pullout_system` ``(cfg, fab, mesh, x)`` -> ``(ContactSystem, pulled end nodes,
  released end nodes, axis)``: the mechanics-only system with those supports (friction from
  the config as ``strain.mech_system``);
* :func:`pullout_step` ``(cfg, fab, mesh, x_prev, origin, step, friction=None)`` -> ``(x,
  system, info)``: from u_{step-1} to u_step in ``strain.substeps`` committed sub-increments,
  each the pulled ends moved to their targets (the predictor; the rest of the yarn follows in
  the solve, its contacts starting from stick) and the static solve (``cell_statics.static_minimize``:
  the energy minimiser, with friction the committed residual solve from the history of the
  last sub-increment); a sub-increment that fails is undone and halved, down to
  ``pullout.max_halvings`` (translating the whole yarn as the predictor made every contact
  slip at once and the frictional Newton failed on the CI weave). ``info["pullout"]``: ``displacement``
  (mm), ``force`` (N: the pull, the clamps' force on the pulled ends along the axis),
  ``released_displacement`` (mm: mean axial motion of the released ends, how far the yarn
  slid out), ``energy`` (N mm), ``balance`` (N: the sum of every support's axial force, 0 at
  an equilibrium);
  Step 1 first releases the - ends at u = 0: their clamp force at the relaxed state (the yarn
  is in tension) is applied as a dead load and taken off in ``pullout.release_steps`` equal
  decrements, each a static solve (with friction committed: the yarn retracts through the
  crossings as far as friction lets it); that state is ``info["pullout"]["start"]`` (force,
  balance, energy), the curve's step 0.

The force-displacement table, its figure and their rules: ``rve.tables.pullout``.
"""
from __future__ import annotations

import dataclasses
import logging
import time

import numpy as np

from ..fabrics.setup import clamped_ends, contact_params
from ..fem.assembly import DofLayout
from ..model import BeamMaterial, BeamModel, ContactSystem, DirichletBC
from ..solvers.system import DeadLoad, friction_of
from .cell_statics import free_residual, static_minimize
from .strain import friction_law, friction_summary, seed_friction

__all__ = ["pullout_levels", "pullout_system", "pullout_step", "AXIS"]

log = logging.getLogger("rve.homogenisation.pullout")

#: yarn direction -> (axis component, pulled side, released side)
AXIS = {"warp": (0, "x+", "x-"), "weft": (1, "y+", "y-")}


def pullout_levels(cfg) -> np.ndarray:
    """Pull-out displacement after step 0..steps (mm)."""
    p = cfg.pullout
    n = int(p.steps)
    return np.array([round(i * float(p.displacement) / n, 12) for i in range(n + 1)])


def _ends(fab, mesh, cfg):
    p = cfg.pullout
    comp, plus, minus = AXIS[p.yarn]
    yarn = fab.yarn_at(p.yarn, float(p.position), tol=1e-6)
    pulled = fab.end_nodes(mesh, plus, yarn.index).astype(np.int64)
    released = fab.end_nodes(mesh, minus, yarn.index).astype(np.int64)
    if pulled.size == 0 or released.size == 0:
        raise ValueError(f"pullout: the {p.yarn} yarn at {p.position} mm has no fibril ends on {plus} and {minus}")
    return yarn, pulled, released, comp


def pullout_system(cfg, fab, mesh, x):
    """The pull-out supports (module docstring) as a mechanics-only ``ContactSystem`` at ``x``."""
    yarn, pulled, released, comp = _ends(fab, mesh, cfg)
    layout = DofLayout(mesh.n_nodes, ("mech",))
    ends, pinned, gauge = clamped_ends(fab, mesh, layout)
    # the released ends slide along the axis only: their transverse centroid dofs stay held
    free = np.zeros((ends.size, 3), bool)
    free[np.isin(ends, released), comp] = True
    held = np.asarray(pinned).reshape(-1, 3)[~free]
    m = cfg.material
    mat = BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density, damping=float(cfg.strain.relax_damping))
    base = BeamModel(mesh, mat, disk_points=cfg.mesh.disk_points, axial_points=cfg.mesh.axial_points,
                     bcs=[DirichletBC(held, np.zeros(held.size)), DirichletBC(gauge, 0.0)])
    params = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=False)
    law = friction_law(cfg)
    if law is not None:
        params = dataclasses.replace(params, friction=law)
    system = ContactSystem(base, params, np.asarray(x, float).reshape(-1))
    fr = friction_of(system)
    if fr is not None:
        fr.set_families([fab.yarns[int(y)].direction for y in fab.fibril_yarn])
    return system, pulled, released, comp


def _release(system, x, released, comp, cfg):
    """Take the released ends' clamp force off in ``pullout.release_steps`` equal decrements,
    each a static solve (with friction a committed one); returns ``(x, info)``."""
    n = system.n
    F, _, _ = system.evaluate(np.asarray(x, float).reshape(-1), np.zeros(n), 0.0, jacobian=False)
    dofs = system.layout.dofs("r", np.asarray(released, np.int64), comp=comp)
    load0 = np.zeros(n)
    load0[dofs] = np.asarray(F)[dofs]          # the clamp force there: the relaxed state is in equilibrium
    k = int(cfg.pullout.release_steps)
    sp_ = cfg.strain
    out = {"converged": True, "steps": [], "clamp_force_N": [float(v) for v in load0[dofs]]}
    xs = np.asarray(x, float).reshape(-1)
    for j in range(1, k + 1):
        loaded = DeadLoad(system, (1.0 - j / k) * load0)
        xs, sinfo = static_minimize(loaded, xs, sp_.static_atol, sp_.static_max_iter)
        out["steps"].append({"converged": bool(sinfo["converged"]), "iterations": int(sinfo.get("iterations", 0))})
        if not sinfo["converged"]:
            out["converged"] = False
            break
    out["iterations"] = sum(s["iterations"] for s in out["steps"])
    return xs, out


def _pull(system, x, pulled, comp, origin, subs, sp_, max_halvings: int, info):
    """The pulled ends from ``subs[0]`` to ``subs[-1]`` through the levels ``subs``, each
    sub-increment a static solve from the last committed state with the pulled ends moved to
    their targets as the predictor (the rest of the yarn follows in the solve: its contacts
    start from stick). A sub-increment that fails is undone (the state and, with friction, its
    history restored) and taken in two halves, down to ``max_halvings``; returns ``(x, info of
    the last solve)``."""
    fr = friction_of(system)
    nn = x.shape[0]
    sinfo = {"converged": True}

    def advance(xa, a, b, depth):
        nonlocal sinfo
        snap = None if fr is None else fr.record()
        t0 = time.perf_counter()
        xp = xa.copy()
        xp[pulled, comp] = origin[pulled, comp] + b
        xs, sinfo = static_minimize(system, xp.reshape(-1), sp_.static_atol, sp_.static_max_iter)
        xs = np.asarray(xs, float).reshape(nn, 9)
        info["substeps"].append({"displacement": float(b), "depth": depth, "converged": bool(sinfo["converged"]),
                                 "iterations": int(sinfo.get("iterations", 0)), "wall_s": time.perf_counter() - t0})
        if sinfo["converged"] or depth >= max_halvings:
            return xs, bool(sinfo["converged"])
        system.rebuild(xa.reshape(-1))           # undo: the map and the history of the start
        if snap is not None:
            fr.seed(snap)
        m = 0.5 * (a + b)
        xm, ok = advance(xa, a, m, depth + 1)
        return advance(xm, m, b, depth + 1) if ok else (xm, False)

    for k in range(1, len(subs)):
        x, ok = advance(x, subs[k - 1], subs[k], 0)
        if not ok:
            log.warning("pull-out: the sub-increment to u = %g mm did not converge", subs[k])
            break
    return x, sinfo


def _axial_forces(system, x, nodes, comp) -> np.ndarray:
    F, _, _ = system.evaluate(np.asarray(x, float).reshape(-1), np.zeros(system.n), 0.0, jacobian=False)
    return np.asarray(system.nodal(F))[np.asarray(nodes, np.int64), comp]


def pullout_step(cfg, fab, mesh, x_prev, origin, step: int, friction=None):
    """Pull-out step ``step`` (module docstring); ``friction``: the history of ``x_prev``."""
    levels = pullout_levels(cfg)
    if not 1 <= int(step) < len(levels):
        raise ValueError(f"pullout step must be in 1..{len(levels) - 1}, got {step}")
    t_start = time.perf_counter()
    nn = mesh.n_nodes
    origin = np.asarray(origin, float).reshape(nn, 9)
    x = np.array(x_prev, float).reshape(nn, 9)
    yarn, pulled, released, comp = _ends(fab, mesh, cfg)
    system, _, _, _ = pullout_system(cfg, fab, mesh, x)
    seed_friction(system, friction, x.reshape(-1))
    fr = friction_of(system)
    d_start = 0.0 if fr is None else float(fr.dissipated)
    u0, u1 = float(levels[step - 1]), float(levels[step])
    sp_ = cfg.strain
    n = int(sp_.substeps)
    subs = [u0 + (u1 - u0) * k / n for k in range(n)] + [u1]
    info = {"mode": "pullout", "step": int(step), "substeps": []}
    ends, _, _ = clamped_ends(fab, mesh)
    held = ends[~np.isin(ends, released)]

    def measure(xm):
        return {"force": float(_axial_forces(system, xm, pulled, comp).sum()),
                "balance": float(_axial_forces(system, xm, held, comp).sum()),
                "released_displacement": float((xm[released, comp] - origin[released, comp]).mean()),
                "energy": float(system.energy(xm.reshape(-1))),
                "dissipated": 0.0 if fr is None else float(fr.dissipated)}

    sinfo = {"converged": True}
    if int(step) == 1:   # release the - ends at u = 0 first: the curve's step 0
        xs, rinfo = _release(system, x.reshape(-1), released, comp, cfg)
        x = np.asarray(xs, float).reshape(nn, 9)
        info["release"] = rinfo
        sinfo = {"converged": rinfo["converged"]}
        info["start"] = measure(x)
    if sinfo["converged"]:
        x, sinfo = _pull(system, x, pulled, comp, origin, subs, sp_, int(cfg.pullout.max_halvings), info)
    info.update({"static": sinfo, "converged": bool(sinfo["converged"]), "residual_N": free_residual(system, x),
                 "pullout": {"displacement": u1, **measure(x), "yarn": yarn.name, "steps": len(levels) - 1}})
    if "start" in info:
        info["pullout"]["start"] = info.pop("start")
    if fr is not None:
        info["friction"] = friction_summary(system, d_start)
    info["wall_s"] = time.perf_counter() - t_start
    return x, system, info
