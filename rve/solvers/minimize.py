"""Energy minimiser and capped Newton for static equilibria under contact (docs/relaxation.md).

Contract
--------
Both work on a mechanics-only ``ContactRelaxable`` system (``rve.solvers.system``: a
``DynamicSystem`` with a rebuildable contact map, ``energy(x)``, ``layout``,
``params.margin``; e.g. ``rve.model.ContactSystem``) at zero velocities, on the
free dofs of ``rve.solvers.static.StaticProblem``, and rebuild the system's contact map
themselves (their one side effect on the system).

* ``minimize_energy(system, x, t=0, ...) -> (x, w, MinimizeResult)``: the static
  equilibrium as a **local minimum** of ``system.energy(x)``: Newton with a
  Levenberg-Marquardt shift ``(K + sigma M) du = -F``, sigma raised until the
  factorisation has no negative pivot (the inertia check,
  ``rve.solvers.linear.factor_inertia``), the energy as merit, the centroid step capped
  at half the search margin and the contact map rebuilt before a trial that leaves that
  guard. Ends with sigma = 0 (plain Newton, quadratic convergence).
* ``capped_newton(system, x, t, ...) -> (x, w, NewtonResult)``: Newton on
  ``F(x, 0, t) = 0`` with the centroid motion per iteration capped, the map rebuilt after
  ``step_cap`` of motion and a Levenberg-Marquardt safeguard on rejected steps.
* ``active_pair_keys(system, x) -> (e_plus, e_minus)``: the element pairs in contact.
* Linear solves: both take ``backend=`` (a name, or an instance that is used as is); a
  run keeps ONE backend instance (``run_backend``) for all its factorisations, so
  PARDISO's symbolic analysis is reused while the pattern is unchanged (docs/engine.md).

Neither solver raises for non-convergence: the result says ``converged`` and why not
(``reason``).
"""
from __future__ import annotations

import contextlib
import gc
import logging
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .backends.registry import run_backend
from .linear import factor_inertia, factor_positive_definite, shifted, sparse_solve
from .system import friction_of
from .newton import NewtonResult, convergence_rates
from .static import StaticProblem

__all__ = ["minimize_energy", "MinimizeResult", "MinimizeOptions", "capped_newton", "active_pair_keys"]

log = logging.getLogger("rve.solvers.minimize")

@dataclass(frozen=True)
class MinimizeOptions:
    """The linear-algebra policy of one minimiser run (``minimize_energy``, ``capped_newton``).

    ``keep_stored_pattern``: True (default) factorises K + sigma M on the contact map's
    stored pattern (explicit zeros of inactive candidate pairs kept, ``shifted(...,
    keep_pattern=True)``), which PARDISO analyses when the nonzero pattern leaves the
    analysed one (docs/engine.md, "Backend choice": 30 analyses instead of 283 on the
    30-element weave); False: the nonzero pattern of scipy's sum. ``pardiso_options``:
    ``PardisoFactorization`` keywords of the run's instance (None:
    ``rve.solvers.backends.registry.PARDISO_RUN_OPTIONS``). ``cholesky_test``: the
    definiteness test of K + sigma M is PARDISO's Cholesky (True; it stops at the first
    pivot <= 0) or the LDL^T inertia count (False); the same verdicts and sigma ladder
    (tests/test_pardiso.py; docs/engine.md "Cholesky as the definiteness test").
    """

    keep_stored_pattern: bool = True
    pardiso_options: Optional[dict] = None
    cholesky_test: bool = True

    def run_backend(self, backend=None):
        """The run's backend instance (``rve.solvers.backends.run_backend``)."""
        return run_backend(backend, keep_pattern=self.keep_stored_pattern, pardiso_options=self.pardiso_options)


DEFAULT_OPTIONS = MinimizeOptions()


def _analyses(solver) -> int:
    """Symbolic analyses of a run's backend so far (its companions' included)."""
    return int(getattr(solver, "total_analyses", getattr(solver, "analyses", 0)))


def _free_centroids(prob, layout) -> np.ndarray:
    """Positions in the free-dof vector of ``prob`` of the free centroid dofs (``r``)."""
    is_r = np.zeros(prob.n, dtype=bool)
    is_r[layout.dofs("r")] = True
    return np.flatnonzero(prob.free_mech & is_r[prob.free])


def capped_newton(system, x, t, atol=1e-9, rtol=1e-12, max_iter=60, step_cap=0.05, max_halvings=20,
                  max_rejections=12, backend=None, options: MinimizeOptions = DEFAULT_OPTIONS,
                  stall_window: Optional[int] = None):
    """Static Newton on ``F(x, 0, t) = 0`` with the centroid motion per iteration capped
    at ``step_cap``, the contact map rebuilt after ``step_cap`` of motion, and a
    Levenberg-Marquardt safeguard: a step that increases |F| is rejected and retried
    with ``(K + sigma M) du = -F`` (sigma raised 8x per rejection, lowered 4x after an
    accepted step, down to pure Newton). ``backend``: the linear solver (one instance for
    the run, ``options.run_backend``). ``stall_window``: stop, not converged, where |F| fell
    by less than ``STALL_DROP`` over that many accepted iterations, or where at that
    window's rate the tolerance is out of reach within the iterations left. Returns ``(x, w,
    NewtonResult)``."""
    with options.run_backend(backend) as solver:
        return _capped_newton(system, x, t, atol, rtol, max_iter, step_cap, max_halvings, max_rejections, solver,
                              options.keep_stored_pattern, stall_window)


#: the least relative fall of |F| over ``capped_newton``'s ``stall_window`` iterations
STALL_DROP = 0.01


def _stalled(residuals, window, tol: Optional[float] = None, left: Optional[int] = None) -> bool:
    """|F| (``residuals``: the start, then every accepted iterate) fell by less than
    ``STALL_DROP`` over the last ``window`` iterations, or (``tol``, ``left`` given) at the
    window's mean rate it would take more than the ``left`` iterations of the budget to
    reach ``tol``: a creep that cannot converge in time."""
    if not window or len(residuals) <= window:
        return False
    drop = residuals[-1] / residuals[-1 - window]
    if drop > 1.0 - STALL_DROP:
        return True
    if tol is None or left is None or residuals[-1] <= tol:
        return False
    return window * np.log(tol / residuals[-1]) / np.log(drop) > left


def _capped_newton(system, x, t, atol, rtol, max_iter, step_cap, max_halvings, max_rejections, solver, keep_stored,
                   stall_window=None):
    w0 = np.zeros(system.n)
    lay = system.layout

    def setup(xc):
        prob = StaticProblem(system, xc, w0, t)  # fresh restriction plans for the current structure
        cen = _free_centroids(prob, lay)
        return prob, cen, prob.fd.matrix(system.mass())

    prob, cen_idx, Mff = setup(np.asarray(x, float))
    u = prob.u0()
    r, J = prob(u)
    rn = float(np.linalg.norm(r))
    res = [rn]
    r0 = rn
    sigma, sig_min = 0.0, None
    rejections = 0
    it = 0
    while it < max_iter:
        if not np.isfinite(rn):
            return (*prob.state(u), NewtonResult(u, False, it, res, "non-finite residual"))
        if rn <= atol or rn <= rtol * r0:
            return (*prob.state(u), NewtonResult(u, True, it, res))
        A = shifted(J, Mff, sigma, keep_pattern=keep_stored and solver.name == "pardiso")
        try:
            du = -sparse_solve(A, r, backend=solver)
        except RuntimeError as exc:
            return (*prob.state(u), NewtonResult(u, False, it, res, f"linear solve failed: {exc}"))
        if not np.all(np.isfinite(du)):
            return (*prob.state(u), NewtonResult(u, False, it, res, "non-finite Newton update"))
        move = np.abs(du[cen_idx]).max() * np.sqrt(3.0) if cen_idx.size else 0.0
        step = min(1.0, step_cap / move) if move > 0 else 1.0
        for _ in range(max_halvings):
            if prob.admissible(u + step * du):
                break
            step *= 0.5
        else:
            return (*prob.state(u), NewtonResult(u, False, it, res, "no admissible step (det F <= 0)"))
        x_cur, _ = prob.state(u)
        ut = u + step * du
        xt, _ = prob.state(ut)
        rebuilt = system.max_displacement_since_rebuild(xt) > step_cap
        if rebuilt:
            system.rebuild(xt)
            prob, cen_idx, Mff = setup(xt)
            ut = prob.u0()
        rt, Jt = prob(ut)
        rtn = float(np.linalg.norm(rt))
        if np.isfinite(rtn) and (rtn <= rn or rejections >= max_rejections):
            it += 1
            u, r, J, rn = ut, rt, Jt, rtn
            res.append(rn)
            rejections = 0
            sigma = 0.0 if sigma <= (sig_min or 0.0) else sigma / 4.0
            rates = convergence_rates(res)
            log.info("capped newton it=%d |r|=%.3e step=%.3g sigma=%.3g rate=%s pairs=%d", it, rn, step, sigma,
                     f"{rates[-1]:.2f}" if rates else "-", system.map.n_pairs)
            if _stalled(res, stall_window, max(atol, rtol * r0), max_iter - it):
                return (*prob.state(u), NewtonResult(u, False, it, res, f"stalled: |r| {res[-1 - stall_window]:.3e} -> "
                                                     f"{rn:.3e} in the last {stall_window} iterations"))
            continue
        # reject: back to the current iterate, more regularisation
        rejections += 1
        if sig_min is None:
            dK = np.abs(J.diagonal())
            dM = np.abs(Mff.diagonal())
            sig_min = 1e-3 * float(dK.max() / dM.max()) if dM.max() > 0 else 1.0
        sigma = max(8.0 * sigma, sig_min)
        log.info("capped newton step rejected (|r| %.3e -> %.3e), sigma -> %.3g", rn, rtn, sigma)
        if rebuilt:  # the map and structure moved with the trial: re-evaluate the iterate on them
            prob, cen_idx, Mff = setup(x_cur)
            u = prob.u0()
            r, J = prob(u)
            rn = float(np.linalg.norm(r))
    return (*prob.state(u), NewtonResult(u, False, max_iter, res,
                                         f"no convergence in {max_iter} iterations (|r| = {res[-1]:.3e})"))


def active_pair_keys(system, x):
    """``(e_plus, e_minus)``: the element pairs of the current map in contact at ``x``."""
    act = system.active_pairs(x)
    return system.map.e_plus[act], system.map.e_minus[act]


@dataclass
class MinimizeResult(NewtonResult):
    """``NewtonResult`` of ``minimize_energy`` plus its per-iteration record:
    ``energies`` (N mm), ``sigmas`` (regularisation used by each accepted step),
    ``steps`` (step fraction alpha), ``factorizations`` (all numeric factorisations, the
    definiteness tests included), ``indefinite`` (tests that found K + sigma M not positive
    definite: with PARDISO a Cholesky stopped at its first pivot <= 0), ``rejections``, ``rebuilds``,
    ``negative_pivots`` (inertia of the last unregularised tangent; 0: a local minimum),
    ``backend`` (the linear
    solver's name) and ``analyses`` (its symbolic analyses in this run; 0 for SuperLU,
    which orders every factorisation afresh)."""

    energies: list = field(default_factory=list)
    sigmas: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    factorizations: int = 0
    indefinite: int = 0
    rejections: int = 0
    rebuilds: int = 0
    negative_pivots: int = -1
    backend: str = ""
    analyses: int = 0

    def accepted(self, residual: float, energy: float, sigma: float, alpha: float) -> None:
        """Record an accepted step."""
        self.residuals.append(residual)
        self.energies.append(energy)
        self.sigmas.append(sigma)
        self.steps.append(alpha)


def minimize_energy(system, x, t=0.0, *, atol=1e-9, rtol=1e-14, max_iter=300, step_cap=None, sigma0=None,
                    label="minimize", time_budget=None, backtrack=0, backend=None, max_rejections=None,
                    max_sigma_rel=1e16, options: MinimizeOptions = DEFAULT_OPTIONS, on_accept=None):
    """Static equilibrium of a mechanics-only ``ContactRelaxable`` system (e.g. a
    ``ContactSystem``) as a **local minimum** of its
    potential ``system.energy(x)`` (beam strain energy + penalty energy), by Newton's method
    with a Levenberg-Marquardt trust region, an inertia check and the energy as merit.

    Each iteration solves ``(K + sigma M) du = -F`` on the free dofs (K the exact tangent,
    M the mass matrix as the metric), after raising sigma until the factorised matrix has no
    negative pivot (so du is a descent direction even where K is indefinite: the stacks of
    frictionless fibrils pass saddles on their way down); the centroid motion of a step is
    capped at ``step_cap`` (default half the search margin) and the contact map is rebuilt
    before a trial that would carry a centroid more than half the margin from where the map
    was built (no contact is jumped over; the energy does not depend on the map under that
    guard). A trial is accepted when the energy decreases (within rounding, the residual
    must decrease); before a rejection the step is halved up to ``backtrack`` times
    (energy evaluations only). sigma follows the agreement ``ratio`` of the actual and the
    predicted (quadratic model) energy change: /8 (/4) after a very good (good) full step,
    and then at most sigma |F_new / F_old|^2, but not below twice the last sigma at which
    the factor was indefinite (a memory fading x1/4 per iteration); x2 after a shortened
    step, x4 after a poor or rejected one; below 1e-8 of the stiffest mode's sigma it is 0:
    plain Newton, quadratic convergence. ``sigma0`` is the first sigma (default 1e-6 of the
    stiffest mode's; 0 to start with plain Newton from a near solution). Converged when
    ``|F_free| <= atol`` or ``<= rtol |F_0|``. ``backend``: the linear solver of the
    definiteness test (one instance for the whole run, ``options.run_backend``, so PARDISO's
    analysis is reused while the pattern is unchanged; default
    ``rve.solvers.linear.resolve_backend()``); ``options``: ``MinimizeOptions``.

    Every loop ends (docs/fault_tolerance.md): ``max_iter`` accepted iterations,
    ``max_rejections`` rejected trials in total (default ``max(200, 2 max_iter)``), a
    regularisation above ``max_sigma_rel`` x the stiffest mode's sigma (the trial steps
    have shrunk to nothing: the minimum step) and the optional wall-time budget
    ``time_budget`` (s; off by default so results depend on the input only). On
    exhaustion the result is not converged, ``reason`` says which budget, ``residuals``
    is the history and ``x`` the last accepted iterate.

    ``on_accept(x) -> bool`` (optional) is called with every trial state the energy test
    accepts, before its residual is evaluated; True says the caller changed the potential
    there (``rve.solvers.frictional`` refreezes the friction loads), whose energy is then
    the merit of the next iteration. None (default): the potential is fixed.

    Returns ``(x, w, MinimizeResult)``; every iteration is logged on ``rve.solvers.minimize``.
    A system with friction (``rve.solvers.frictional.friction_of``) is a ValueError: it has
    no potential; unless its loads are frozen (``FrictionTerm.freeze``), when the friction
    is the convex incremental potential of those loads (``rve.solvers.frictional``).
    """
    fr = friction_of(system)
    if fr is not None and not fr.frozen:
        raise ValueError("minimize_energy: the system has friction, which has no potential; solve its residual "
                         "(rve.solvers.frictional.frictional_static_step, or relax_to_equilibrium)")
    budget = max(200, 2 * int(max_iter)) if max_rejections is None else int(max_rejections)
    with options.run_backend(backend) as solver, _long_lived_objects_frozen():
        return _minimize_energy(system, x, t, atol, rtol, max_iter, step_cap, sigma0, label, time_budget,
                                backtrack, solver, budget, float(max_sigma_rel), options, on_accept)


@contextlib.contextmanager
def _long_lived_objects_frozen():
    """Python's cyclic garbage collector skips the objects alive before the loop (``gc.freeze``;
    thawed after it): the loop makes arrays and sparse matrices, no reference cycles of note,
    but every full collection it triggered traversed the ~10^5 objects of the imported modules
    (numba's type system, pint's registry): 3 collections of ~60 ms in a 12-element relaxation
    (docs/engine.md, "the fixed costs of a process"). Nothing is frozen when a caller has already frozen objects."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _budget_spent(out, rn, it, max_iter, time_budget, t0, max_rejections, sigma, sigma_max, max_sigma_rel) -> str:
    """Why the minimiser stops before its next iteration ('' when it goes on)."""
    if it >= max_iter:
        return f"no convergence in {max_iter} iterations (|F| = {rn:.3e})"
    if time_budget is not None and time.perf_counter() - t0 > time_budget:
        return f"time budget {time_budget:g} s (wall time) spent after {it} iterations (|F| = {rn:.3e})"
    if not np.isfinite(rn):
        return "non-finite residual"
    if max_rejections is not None and out.rejections >= max_rejections:
        return (f"{out.rejections} rejected trials in total (max_rejections = {max_rejections}) after "
                f"{it} iterations (|F| = {rn:.3e})")
    if sigma > sigma_max:
        return (f"no descent step: the regularisation sigma = {sigma:.3g} exceeds {max_sigma_rel:g} x the "
                f"stiffest mode's (the trial steps shrank below the minimum step; |F| = {rn:.3e})")
    return ""


def _definite_factor(J, Mff, sigma, sig_neg, sig_floor, keep, solver, options, out, unregularised):
    """Factorise K + sigma M, raising sigma until it is positive definite (the test is a
    Cholesky where PARDISO is there: it stops at the first pivot <= 0, docs/engine.md);
    ``(factor or None, sigma, the largest sigma found indefinite, the unregularised tangent
    still to count)``."""
    for _ in range(60):
        A = shifted(J, Mff, sigma, keep_pattern=keep)
        lu = factor_positive_definite(A, backend=solver, cholesky=options.cholesky_test)
        out.factorizations += 1
        if sigma == 0.0:
            # inertia of the unregularised tangent: 0 when definite; otherwise counted
            # (an LDL^T) only if it is still the last unregularised tangent at the end
            out.negative_pivots, unregularised = (0, None) if lu is not None else (-1, A)
        if lu is not None:
            return lu, sigma, sig_neg, unregularised
        out.indefinite += 1
        sig_neg = max(sig_neg, sigma)
        sigma = max(4.0 * sigma, sig_floor)
    return None, sigma, sig_neg, unregularised


def _rebuild_for(system, x_trial, x_cur, guard: float, out) -> bool:
    """Rebuild the contact map at ``x_cur`` when the trial carries a centroid more than
    ``guard`` from where the map was built (the energy at x_cur does not change; the trial
    is then within the guard of the new map); says whether it did."""
    if system.max_displacement_since_rebuild(x_trial) <= guard:
        return False
    system.rebuild(x_cur)
    out.rebuilds += 1
    return True


def _trial_energy(system, prob, u, du, alpha, slope, quad, Pi):
    """``(energy, predicted change, agreement ratio)`` of the step ``alpha du``."""
    Pt = float(system.energy(prob.state(u + alpha * du)[0]))
    pred = alpha * slope + 0.5 * alpha * alpha * quad
    return Pt, pred, (Pt - Pi) / pred if pred < 0 else -1.0


def _next_sigma(sigma, backtracked, ratio, alpha, sig_floor, sig_neg, contraction):
    """The regularisation after an accepted step: lower after a good full step, but not
    below twice the last sigma at which K + sigma M was indefinite (that memory fades by 4x
    per iteration): saves the factorisations the inertia check would reject."""
    sigma_used = sigma
    if backtracked:
        return max(2.0 * sigma, sig_floor)
    if ratio > 0.5 and alpha == 1.0:
        sigma = max(sigma / (8.0 if ratio > 0.75 else 4.0), 2.0 * sig_neg)
        if ratio > 0.75:
            # near the solution sigma also follows |F|^2 (Levenberg-Marquardt with
            # sigma ~ |F|^2 keeps Newton's quadratic rate while it is still > 0)
            sigma = min(sigma, sigma_used * contraction ** 2)
        return 0.0 if sigma <= sig_floor else sigma
    if ratio < 0.25:
        return max(4.0 * sigma, sig_floor)
    if alpha < 1.0:
        return max(2.0 * sigma, sig_floor)
    return sigma


def _minimize_energy(system, x, t, atol, rtol, max_iter, step_cap, sigma0, label, time_budget, backtrack, solver,
                     max_rejections, max_sigma_rel, options: MinimizeOptions, on_accept=None):
    t0 = time.perf_counter()
    keep = options.keep_stored_pattern and solver.name == "pardiso"
    analyses0 = _analyses(solver)
    guard, cap = _guard_and_cap(system, step_cap)
    fmt = "csr" if keep else "csc"  # PARDISO reads CSR as well: the restriction is then a row filter
    x = np.array(x, float, copy=True)
    if system.max_displacement_since_rebuild(x) > 0.0:
        system.rebuild(x)
    prob, cen, Mff = _restricted(system, x, t, fmt)
    u = prob.u0()
    r, J = prob(u)
    r0 = rn = float(np.linalg.norm(r))
    Pi = float(system.energy(x))
    out = MinimizeResult(u, False, 0, [rn], energies=[Pi])
    scale = _stiffest_sigma(J, Mff)
    sig_floor = 1e-8 * scale
    sigma = 1e-6 * scale if sigma0 is None else float(sigma0)
    sig_neg, it = 0.0, 0
    unregularised = None  # the last K (sigma = 0) found indefinite, its count still to take
    while True:
        if rn <= atol or rn <= rtol * r0:
            out.converged = True
            break
        out.reason = _budget_spent(out, rn, it, max_iter, time_budget, t0, max_rejections, sigma,
                                   max_sigma_rel * scale, max_sigma_rel)
        if out.reason:
            break
        lu, sigma, sig_neg, unregularised = _definite_factor(J, Mff, sigma, sig_neg, sig_floor, keep, solver,
                                                             options, out, unregularised)
        if lu is None:
            out.reason = "no positive definite regularisation found"
            break
        du, slope, quad, alpha = _direction(lu, r, J, cen, cap)
        x_cur = prob.state(u)[0]
        rebuilt = _rebuild_for(system, prob.state(u + alpha * du)[0], x_cur, guard, out)
        Pt, pred, ratio = _trial_energy(system, prob, u, du, alpha, slope, quad, Pi)
        noise = 1e-12 * max(1.0, abs(Pi))
        accept = Pt < Pi - noise
        backtracked = 0
        while backtrack and not accept and np.isfinite(Pi) and backtracked < backtrack and pred < -noise:
            # a step into contacts the model does not hold (or past a curvature change):
            # shorten it along the same direction, energies only (no new factorisation)
            alpha *= 0.5
            backtracked += 1
            Pt, pred, ratio = _trial_energy(system, prob, u, du, alpha, slope, quad, Pi)
            accept = Pt < Pi + 1e-4 * alpha * slope
        if rebuilt:
            prob, cen, Mff = _restricted(system, x_cur, t, fmt)
            u = prob.u0()
        ut = u + alpha * du
        if accept and on_accept is not None and on_accept(prob.state(ut)[0]):
            # the caller changed the potential at the accepted state (frozen friction loads
            # refreshed): the merit of the next iteration is the new potential's
            Pt = float(system.energy(prob.state(ut)[0]))
        if accept or (np.isfinite(Pt) and Pt <= Pi + noise):
            rt, Jt = prob(ut)
            rtn = float(np.linalg.norm(rt))
            accept = accept or rtn < rn  # energy change lost in rounding: the residual decides
        if not accept:
            out.rejections += 1
            sigma = max(4.0 * sigma, sig_floor)
            log.info("%s it=%d rejected: dPi=%.3e predicted %.3e, sigma -> %.3g", label, it + 1, Pt - Pi, pred,
                     sigma)
            if rebuilt:
                r, J = prob(u)  # same values, new structure
            continue
        it += 1
        dPi = Pt - Pi
        rn_prev = rn
        u, r, J, rn, Pi = ut, rt, Jt, rtn, Pt
        out.accepted(rn, Pi, sigma, alpha)
        sigma = _next_sigma(sigma, backtracked, ratio, alpha, sig_floor, sig_neg, rn / rn_prev)
        sig_neg *= 0.25
        _log_iteration(label, it, rn, Pi, dPi, ratio, alpha, out, system, t0)
    if unregularised is not None:
        out.negative_pivots = factor_inertia(unregularised, backend=solver)[1]
    out.u, out.iterations, out.backend, out.analyses = u, it, solver.name, _analyses(solver) - analyses0
    xs, ws = prob.state(u)
    return xs, ws, out


def _restricted(system, xc, t, fmt: str):
    """The static problem at ``xc``, its free centroid positions and its restricted mass."""
    prob = StaticProblem(system, xc, np.zeros(system.n), t, fmt=fmt)
    return prob, _free_centroids(prob, system.layout), prob.fd.matrix(system.mass(), fmt=fmt)


def _guard_and_cap(system, step_cap):
    """Half the search margin (the rebuild guard) and the centroid step cap (default: it)."""
    guard = 0.5 * float(system.params.margin)
    cap = guard if step_cap is None else float(step_cap)
    if cap > guard:
        raise ValueError(f"step_cap {cap} exceeds half the search margin {guard}")
    return guard, cap


def _stiffest_sigma(J, Mff) -> float:
    """max|diag K| / max|diag M|: the sigma of the stiffest mode (1 without mass)."""
    dK, dM = np.abs(J.diagonal()).max(), np.abs(Mff.diagonal()).max()
    return float(dK / dM) if dM > 0 else 1.0


def _direction(lu, r, J, cen, cap):
    """``(du, slope, curvature, alpha)``: the regularised Newton step, the model's slope
    and curvature along it, and the step fraction that caps the centroid motion."""
    du = -lu.solve(r)
    slope = float(r @ du)
    quad = float(du @ (J @ du))
    move = float(np.abs(du[cen]).max()) * np.sqrt(3.0) if cen.size else 0.0
    return du, slope, quad, min(1.0, cap / move) if move > 0 else 1.0


def _log_iteration(label, it, rn, Pi, dPi, ratio, alpha, out, system, t0) -> None:
    rates = convergence_rates(out.residuals)
    log.info("%s it=%d |F|=%.3e Pi=%.12e dPi=%.2e ratio=%.2f step=%.3g sigma=%.3g pairs=%d rate=%s wall=%.1f",
             label, it, rn, Pi, dPi, ratio, alpha, out.sigmas[-1], system.map.n_pairs,
             f"{rates[-1]:.2f}" if rates else "-", time.perf_counter() - t0)
