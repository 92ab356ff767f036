"""Static solves of a cell state and the macro path's levels, shared by the pinned
(``rve.homogenisation.strain``) and the periodic (``rve.homogenisation.periodic``) steps.

* :func:`strain_levels` -- the strain after step 0..steps of ``cfg.strain``;
* :func:`cycle_levels` -- the strain after step 0..2n of a loading-unloading cycle;
* :func:`static_minimize` -- static equilibrium as a local minimum of the potential
  (trust-region Newton, inertia check, energy as merit), then a map rebuild that must find
  no newly active pair; ``(x, info)``; a system with friction has no potential: its static
  residual is solved from the held friction history (``rve.solvers.frictional.frictional_solve``),
  each round ended by a map rebuild, and the solution committed unless ``commit=False``
  (the Uzawa loop of ``multipliers.equilibrium`` commits once, at its converged state);
* :func:`static_polish` -- bounded capped-step Newton solves, |F| never increases;
* :func:`cut_retries` -- the step cut of both cells: a step solved again from its start in
  twice as many increments where it fails, a try that can still be cut with the frictional
  fallback's stall window (``CUT_STALL_WINDOW``);
* :func:`free_residual` -- |F(x, 0)| on the free dofs (N);
* :func:`trellis_gradient` -- the picture frame's in-plane deformation gradient.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from ..solvers.frictional import friction_of, frictional_solve
from ..solvers.minimize import capped_newton, minimize_energy

__all__ = ["strain_levels", "cycle_levels", "static_minimize", "static_polish", "free_residual", "trellis_gradient"]

log = logging.getLogger("rve.homogenisation.strain")


def strain_levels(cfg) -> np.ndarray:
    """Strain after step 0..steps (step 0 = the relaxed state)."""
    n = int(cfg.strain.steps)
    return np.array([round(i * cfg.strain.total / n, 12) for i in range(n + 1)])


def cycle_levels(cfg) -> np.ndarray:
    """Strain after step 0..2n of a loading-unloading cycle (step 0 = the relaxed state):
    n = ``strain.cycle_steps`` (default ``steps``) steps up to ``strain.cycle_total`` (default
    ``total``), then the same levels back down to 0 (the unloading lands exactly on them)."""
    sp_ = cfg.strain
    n = int(sp_.cycle_steps or sp_.steps)
    top = float(sp_.cycle_total or sp_.total)
    up = [round(i * top / n, 12) for i in range(n + 1)]
    return np.array(up + up[-2::-1])


def static_minimize(system, x, atol: float, max_iter: int, commit: bool = True,
                    fallback_stall: Optional[int] = None) -> tuple:
    """Static equilibrium as a local minimum of the potential (``rve.solvers.minimize.minimize_energy``:
    trust-region Newton with an inertia check, the energy as merit, centroid steps capped,
    map rebuilt as fibrils move; docs/relaxation.md), from a state near it (plain Newton
    first), then a map rebuild that must find no newly active pair. Returns ``(x, info)``.
    With friction: the residual from the held history (``_static_frictional``), the solution
    committed when it converged and ``commit`` (False: the caller commits, e.g.
    ``multipliers.equilibrium`` once after its Uzawa loop); ``fallback_stall``: the stall
    window of the frictional solve's capped-Newton fallback, without the pseudo-transient continuation
    (``frictional_solve``), for a caller that cuts the step where the solve fails."""
    x = np.asarray(x, float).reshape(-1)
    fr = friction_of(system)
    if fr is not None:
        xs, info = _static_frictional(system, x, atol, max_iter, fallback_stall)
        if commit and info["converged"]:
            info["dissipated"] = float(fr.commit(xs))
        return xs, info
    system.rebuild(x)
    before = set(zip(*_active(system, x)))
    xs, _, res = minimize_energy(system, x, 0.0, atol=atol, rtol=1e-14, max_iter=int(max_iter), sigma0=0.0,
                                 backtrack=3, label="strain step")
    system.rebuild(xs)
    after = set(zip(*_active(system, xs)))
    missed = len(after - before)
    info = {"converged": bool(res.converged), "iterations": int(res.iterations),
            "factorizations": int(res.factorizations), "rejections": int(res.rejections),
            "negative_pivots": int(res.negative_pivots), "residuals": [float(v) for v in res.residuals][-6:],
            "reason": res.reason, "method": "energy"}
    if missed:
        log.info("static minimisation: %d active pairs appeared at the final rebuild", missed)
    return xs, info


#: static solves of a frictional step from its held history, each after a map rebuild, until
#: no new pair is active and the state is an equilibrium
FRICTIONAL_ROUNDS = 6


def _static_frictional(system, x, atol: float, max_iter: int, fallback_stall: Optional[int] = None) -> tuple:
    """The static residual of a frictional system from its held history, not committed
    (``static_minimize``): ``rve.solvers.frictional.frictional_solve`` (the
    incremental-potential predictor, then Newton with the unsymmetric tangent on the LU path;
    its own capped-Newton and pseudo-transient fallback, with the stall window
    ``fallback_stall``); where it fails, once more with the
    smoothed predictor stage from the same start. Each round ends with a map rebuild at the
    solution (history carried by key); a residual above ``atol`` at the rebuilt map starts
    another round from the same held history. A pair newly active at the rebuild alone does
    not: its overlap force and its friction (the history the rebuild gave it) are in that
    residual, so a state within ``atol`` is an equilibrium of the rebuilt map as it is.
    ``rounds`` records the stick and slip counts of the return map at every round's
    solution."""
    x = np.asarray(x, float).reshape(-1)
    fr = friction_of(system)
    info = {"converged": False, "iterations": 0, "residuals": [], "reason": "", "method": "friction",
            "rounds": []}
    residual = np.inf
    for k in range(FRICTIONAL_ROUNDS):
        system.rebuild(x)
        before = set(zip(*_active(system, x)))
        # a later round starts next to an equilibrium of the same history: the law's
        # predictor stage alone (the smoothed stage would first move the state off to its
        # own solution, |F| ~ 2e-2 N on the thesis weave, for the law's stage to bring back)
        xs, res = frictional_solve(system, x, 0.0, atol=atol, rtol=1e-14, max_iter=int(max_iter),
                                   smoothing=() if k else (1.0,), fallback_stall=fallback_stall)
        how, its, converged, residuals, reason = "potential", int(res.iterations), bool(res.converged), \
            res.residuals, res.reason
        if not converged and k:
            log.info("frictional static solve: %s; again with the smoothed stage from the same history", res.reason)
            xs, res = frictional_solve(system, x, 0.0, atol=atol, rtol=1e-14, max_iter=int(max_iter),
                                       fallback_stall=fallback_stall)
            how, its, converged = "potential (smoothed)", its + int(res.iterations), bool(res.converged)
            residuals, reason = res.residuals, res.reason
        x = np.asarray(xs, float)
        info["iterations"] += its
        info["residuals"] = [float(v) for v in residuals][-6:]
        info["converged"], info["reason"] = converged, reason
        system.rebuild(x)
        after = set(zip(*_active(system, x)))
        residual = free_residual(system, x)
        st = fr.state(x)
        info["rounds"].append({"method": how, "iterations": its, "converged": converged,
                               "new_active_pairs": len(after - before), "residual_N": residual,
                               "stick": int(st.stick.sum()), "slip": int(st.slip.sum())})
        if fr.provisional:
            # a provisional re-solve: its state only feeds the next multiplier update
            # (``multipliers.equilibrium``), so it is not driven to atol
            info["provisional"] = True
            return x, info
        if not converged or residual <= atol:
            break
    info["converged"] = bool(info["converged"] and residual <= atol)
    return x, info


def static_polish(system, x, atol: float, rounds: int, max_iter: int) -> tuple:
    """Bounded static solve: up to ``rounds`` capped-step Newton solves
    (``rve.solvers.minimize.capped_newton``: centroid moves capped at half the search margin,
    map rebuilt as fibrils move, Levenberg-Marquardt safeguard, |F| never increases), each
    after a contact-map rebuild, until converged with no newly active pair. No
    pseudo-transient fallback: the iteration budget is ``rounds * max_iter``.
    Returns ``(x, info)``."""
    cap = 0.5 * float(system.params.margin)
    x = np.asarray(x, float).reshape(-1)
    info = {"converged": False, "iterations": 0, "residuals": []}
    for _ in range(int(rounds)):
        system.rebuild(x)
        xs, _, res = capped_newton(system, x, 0.0, atol=atol, rtol=1e-14, max_iter=int(max_iter), step_cap=cap)
        x = xs
        info["iterations"] += int(res.iterations)
        info["residuals"] = [float(v) for v in res.residuals][-6:]
        info["converged"] = bool(res.converged)
        before = set(zip(*_active(system, x)))
        system.rebuild(x)
        after = set(zip(*_active(system, x)))
        if res.converged and after <= before:
            break
        if not res.converged:
            log.info("static polish: %s", res.reason)
    return x, info


def _active(system, x):
    act = system.active_pairs(x)
    return system.map.e_plus[act], system.map.e_minus[act]


#: the stall window of the frictional capped-Newton fallback in a try that can still be cut
#: (no pseudo-transient continuation): a fallback that creeps on converges (the AL cell's
#: uniaxial step 2: |F| -5 % an iteration, 104 iterations), one that stalls with no progress
#: is cut (the imperfect cell's step 1: 1000 iterations at |F| = 6.82e-6 N, then converged in
#: two sub-increments; docs/fault_tolerance.md)
CUT_STALL_WINDOW = 20


def cut_retries(attempt, n: int, max_cuts: int, label: str) -> tuple:
    """The step cut shared by the pinned and the periodic cell: ``attempt(n, fallback_stall)
    -> (out, converged, residual_N)`` solves the step from its start in ``n`` increments or
    parts; where it fails, again in twice as many, at most ``max_cuts`` times. A try that can
    still be cut gets ``CUT_STALL_WINDOW`` (its frictional fallback ends where it stalls), the
    last one None (all of it). Returns ``(out of the last try, its n, cuts)``, ``cuts`` the
    failed tries' ``{"substeps": n, "residual_N": |F|}``."""
    cuts = []
    while True:
        last = len(cuts) >= int(max_cuts)
        out, converged, residual = attempt(n, None if last else CUT_STALL_WINDOW)
        if converged or last:
            return out, n, cuts
        cuts.append({"substeps": n, "residual_N": float(residual)})
        log.warning("%s: not converged in %d increment(s) (|F| = %.3e N); cut to %d", label, n, residual, 2 * n)
        n *= 2


def free_residual(system, x) -> float:
    """|F(x, 0)| on the free dofs (N): the equilibrium error of a state."""
    F, _, _ = system.evaluate(np.asarray(x, float).reshape(-1), np.zeros(system.n), 0.0, jacobian=False)
    idx, _ = system.constraints(0.0)
    F = np.array(F, copy=True)
    F[np.asarray(idx, dtype=np.int64)] = 0.0
    return float(np.linalg.norm(F))


def trellis_gradient(theta: float) -> np.ndarray:
    """In-plane deformation gradient (3, 3) of the picture frame at angle drop ``theta``
    (rad): F e1 = (cos t/2, sin t/2), F e2 = (sin t/2, cos t/2), |F e1| = |F e2| = 1."""
    c, s = np.cos(theta / 2.0), np.sin(theta / 2.0)
    return np.array([[c, s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
