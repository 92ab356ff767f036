"""The strain path of a cell as an equilibrium curve for ``branch.continue_arc`` (through the
limit points on one path; docs/table_accuracy.md "One equilibrium path").

The load parameter is the macro strain eps of the mode; the unknowns are the free dofs:

* **pinned cell**: every dof but the pinned end centroids (at ``end_targets(eps)``) and the
  twist gauge (held); R = the residual on the free dofs, K its block of the tangent, and
  R_eps = K_free,pinned d(end targets)/d eps (exact: the ends enter only through their
  positions);
* **periodic cell**: the reduced dofs but the gauges, at the macro gradient F(eps) of the
  mode (``PeriodicSystem.set_macro``); R_eps is the central difference of R in eps at fixed
  dofs and contact map (step 1e-7: its error is below the corrector's tolerance, and R_eps
  only steers the corrector, whose converged point is R = 0 whatever R_eps is).

Between arc steps the contact map is rebuilt at the accepted point. The path's points are
equilibria to ``ARC_SETTINGS.path_atol_factor`` x the static tolerance (the chord contact's
force jumps where a contact point crosses an element end); the end state goes
through the cell's static polish (capped Newton with map rebuilds, ``cell_statics.static_polish``:
the nearest equilibrium, stable or not) so that it is an equilibrium of the map built at
it. The negative-pivot count of every factorisation is the inertia of the path's points
(``rve.solvers.linear.factor_inertia``: PARDISO's LDL^T, SuperLU where that perturbs a pivot).

Contract
--------
``pinned_arc(cfg, fab, mesh, origin, mode, cell)`` (``cell``: the strain path's system,
end targets and energy) and ``periodic_arc(cfg, fab, mesh, mode)``
return ``arc(start, eps_from, eps_to) -> StepSolution | None`` (``branch.follow_branch``'s
``arc``): ``start.x`` the full nodal state (n_nodes, 9); the solution's ``x`` likewise,
``extra`` its system (pinned: the mechanics system with the clamps; periodic: the full
system), ``info`` a step record (``converged``, ``residual_N``, ``static``, ``arc``); a failed
continuation gives ``x`` None and only ``info["arc"]``. The pinned cell's arc returns None
when the contact law is the augmented Lagrangian (the caller falls back to halving).

**The periodic cell with the augmented Lagrangian** (``periodic_arc(..., multipliers=)``): the
curve is that of the penalty law shifted by the start's multipliers (those of ``start.extra``,
else ``multipliers``: the step's), held along the path, carried by point key through the map
rebuilds. The start is an equilibrium of that law (its multipliers are expressed at the
configured P*), and the shift only moves the fold's strain by the overlap the soft P* lets
between two Uzawa loops. ``strain.arc_penalty`` runs the curve at another P* instead, the
start's multipliers re-expressed there (``set_penalty(P, x)``: every line load kept), as the
Uzawa loop's raised P* would see it: the stacks' contacts are then stiff enough for the
inertia along the path to be that of the impenetrable limit; the multipliers go back to
the configured P* before the end's loop. The corrector is the caller's ``settings``
(``strain.arc_corrector`` in the strain path: ``arc_settings(cfg)``). The end at eps_to is
the cell's Uzawa loop (``multipliers.equilibrium``)
around the static polish, from the continuation's end state: the nearest equilibrium of the
impenetrable limit to ``al_tolerance``, whose inertia is the continuation's at its end.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..fabrics.setup import clamped_ends
from ..solvers.linear import factor_inertia, factorize
from .branch import ArcProblem, ArcSettings, StepSolution, continue_arc
from .cell_statics import free_residual, static_polish

__all__ = ["pinned_arc", "periodic_arc", "ARC_SETTINGS", "arc_settings"]

#: the cells' continuation: the path's points equilibria to 1e5 x the static tolerance (1e-4 N
#: at the default 1e-9 N: the chord contact's force jumps where a contact point crosses an
#: element end, and Newton stalls there at 1e-6 to 1e-4 N on the default weave), the end
#: polished to the static tolerance
ARC_SETTINGS = ArcSettings(path_atol_factor=1e5)


def arc_settings(cfg) -> ArcSettings:
    """``ARC_SETTINGS`` with the config's corrector (``strain.arc_corrector``)."""
    return dataclasses.replace(ARC_SETTINGS, corrector=str(cfg.strain.arc_corrector))


def _factor(K):
    """``(solve, negative pivots)`` of the symmetric ``K`` (None: unknown inertia)."""
    lu, neg = factor_inertia(K)
    if lu is None:
        lu, neg = factorize(K, symmetric=False), None
    return lu.solve, (None if neg is None or neg < 0 else int(neg))


def _free(system) -> np.ndarray:
    idx, _ = system.constraints(0.0)
    keep = np.ones(system.n, bool)
    keep[np.asarray(idx, dtype=np.int64)] = False
    return np.flatnonzero(keep)


def _finish(system, x, sp_, info, t0, arc_info, penalty=None):
    """The polish of the continuation's end (the nearest equilibrium, stable or not) and its
    step record. With the augmented Lagrangian the polish runs in the Uzawa loop, from the
    configured P* ``penalty`` (the multipliers re-expressed at ``x`` where the curve ran at
    another; module docstring); with the penalty ``equilibrium`` is the polish alone."""
    from .multipliers import equilibrium

    if penalty is not None and float(system.penalty) != float(penalty):
        system.set_penalty(float(penalty), x)
    xs, pinfo = equilibrium(system, lambda xv: static_polish(system, xv, sp_.static_atol, sp_.static_rounds,
                                                              sp_.static_max_iter), x)
    pinfo["negative_pivots"] = arc_info.get("end_inertia")
    pinfo["method"] = "arc_length"
    info.update({"static": pinfo, "converged": bool(pinfo["converged"]), "residual_N": free_residual(system, xs),
                 "arc": arc_info, "wall_s": time.perf_counter() - t0})
    return xs


def pinned_arc(cfg, fab, mesh, origin, mode: str, cell, settings: ArcSettings = ARC_SETTINGS):
    """The pinned cell's continuation (module docstring). ``cell``: the strain path's
    ``system(x)`` (the mechanics system with the clamps at the flat state x),
    ``targets(origin_ends, mode, eps)`` (the pinned end positions) and ``energy(system, x,
    eps)`` (``(Pi, dPi/deps)``), i.e. ``strain.mech_system``, ``end_targets`` and
    ``pinned_energy``."""
    sp_ = cfg.strain
    origin = np.asarray(origin, float)
    ends, pinned, _ = clamped_ends(fab, mesh)
    origin_ends = origin[ends, :3]
    end_targets = cell.targets

    def arc(start, e_from, e_to):
        t0 = time.perf_counter()
        x0 = np.asarray(start.x, float).reshape(-1)
        system = cell.system(x0)
        if system.augmented:
            return None
        free = _free(system)
        base = x0.copy()
        zero = np.zeros(system.n)

        def full(xf, eps):
            x = base.copy()
            x[pinned] = end_targets(origin_ends, mode, eps).reshape(-1)
            x[free] = xf
            return x

        def rate(eps, h=1e-6):
            return ((end_targets(origin_ends, mode, eps + h) - end_targets(origin_ends, mode, eps - h))
                    / (2.0 * h)).reshape(-1)

        def residual(xf, eps):
            return system.evaluate(full(xf, eps), zero, 0.0, jacobian=False)[0][free]

        def tangent(xf, eps):
            _, Fx, _ = system.evaluate(full(xf, eps), zero, 0.0, jacobian=True)
            rows = Fx.tocsr()[free]
            return rows[:, free], rows[:, pinned] @ rate(eps)

        problem = ArcProblem(residual, tangent, _factor, lambda xf, eps: system.rebuild(full(xf, eps)),
                             lambda xf, eps: cell.energy(system, full(xf, eps), eps),
                             atol=float(sp_.static_atol))
        system.rebuild(x0)
        xf, ainfo = continue_arc(problem, x0[free], float(e_from), float(e_to), settings)
        if xf is None:   # failed: its record only
            return StepSolution(None, {"arc": ainfo})
        info = {"mode": mode, "strain": float(e_to), "strain_increment": float(e_to - e_from)}
        xs = _finish(system, full(xf, float(e_to)), sp_, info, t0, ainfo)
        return StepSolution(xs.reshape(mesh.n_nodes, 9), info, system)

    return arc


def periodic_arc(cfg, fab, mesh, mode: str, settings: ArcSettings = ARC_SETTINGS, multipliers=None):
    """The periodic cell's continuation (module docstring). ``multipliers``: the contact
    multipliers of a start without a system (the step's start; augmented Lagrangian)."""
    from .multipliers import multiplier_record, seed_multipliers
    from .periodic import cell_reactions, full_state, macro_gradient, periodic_system

    sp_ = cfg.strain

    def arc(start, e_from, e_to):
        t0 = time.perf_counter()
        x0 = np.asarray(start.x, float).reshape(-1)
        psys = periodic_system(cfg, fab, mesh, x0, macro_gradient(mode, float(e_from)))
        seed_multipliers(psys, multipliers if start.extra is None else multiplier_record(start.extra))
        free = _free(psys)
        base = psys.restrict(x0)
        configured = float(psys.penalty) if psys.augmented else None
        if psys.augmented and sp_.arc_penalty is not None:
            psys.set_penalty(float(sp_.arc_penalty), base)
        zero = np.zeros(psys.n)
        at = {"eps": float(e_from)}

        def load(eps):   # the macro gradient of eps (its images take effect at the next rebuild)
            if eps != at["eps"]:
                psys.set_macro(macro_gradient(mode, eps))
                at["eps"] = eps

        def red(xf):
            x = base.copy()
            x[free] = xf
            return x

        def residual(xf, eps):
            load(eps)
            return psys.evaluate(red(xf), zero, 0.0, jacobian=False)[0][free]

        def tangent(xf, eps, h=1e-7):
            load(eps)
            _, Fx, _ = psys.evaluate(red(xf), zero, 0.0, jacobian=True)
            K = Fx.tocsr()[free][:, free]
            R_eps = (residual(xf, eps + h) - residual(xf, eps - h)) / (2.0 * h)
            load(eps)
            return K, R_eps

        def energy(xf, eps):
            load(eps)
            h = 1e-6
            dF = (macro_gradient(mode, eps + h) - macro_gradient(mode, eps - h)) / (2.0 * h)
            return float(psys.energy(red(xf))), float(psys.ties.area * np.sum(psys.macro_stress(red(xf)) * dF))

        def rebuild(xf, eps):
            load(eps)
            psys.rebuild(red(xf))

        problem = ArcProblem(residual, tangent, _factor, rebuild, energy, atol=float(sp_.static_atol))
        xf, ainfo = continue_arc(problem, base[free], float(e_from), float(e_to), settings)
        if xf is None:   # failed: its record only
            return StepSolution(None, {"arc": ainfo})
        load(float(e_to))
        psys.rebuild(red(xf))
        F_end = macro_gradient(mode, float(e_to))
        info = {"mode": mode, "strain": float(e_to), "strain_increment": float(e_to - e_from), "boundary": "periodic",
                "macro_gradient": F_end.tolist()}
        xs = _finish(psys, red(xf), sp_, info, t0, ainfo, configured)
        info.update({"energy_mJ": float(psys.energy(xs)), "macro_stress_N_per_mm": psys.macro_stress(xs)[:2, :2].tolist(),
                     "reaction_force": cell_reactions(fab, psys, xs)})
        return StepSolution(full_state(psys, xs), info, psys.full)

    return arc
