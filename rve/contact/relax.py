"""Relaxation of a fibril assembly in contact to static equilibrium (thesis §6.3, §7.3).

Contract
--------
``relax_to_equilibrium(system, x, w, settings, on_rebuild=None) -> RelaxResult`` for a
``ContactSystem``; ``settings.method`` picks the path (docs/relaxation.md):

* ``"energy"`` (the fabric scene's default): the static equilibrium as a **local minimum
  of the potential** ``system.energy(x)`` (beam strain energy + penalty energy; the static
  residual is its exact gradient), by ``minimize_energy``: Newton with a Levenberg-Marquardt
  trust region ``(K + sigma M) du = -F``, sigma raised until the factorisation has no
  negative pivot (``factor_inertia``: the tangent of a stack of frictionless fibrils is
  indefinite on the way down), the energy as merit (with ``backtrack`` energy-only step
  halvings), the centroid step capped at half the search margin and the map rebuilt
  before a trial that leaves the guard (no contact jumped over). A continuation in the
  penalty onset (``onset_schedule``, fractions of R, the C² onset of
  ``contact_forms.penalty_law``; the last entry is the law of the result) smooths the
  first stages; the last stage ends with sigma = 0, i.e. plain Newton, quadratically.
  Velocities are zero throughout.
* ``"dynamic"`` (the previous path):

1. **Dynamic relaxation**: backward Euler (``rve.solvers.dirk.integrate``, step control)
   of the heavily damped dynamics over ``duration`` in ``steps`` nominal steps, the contact
   map rebuilt every ``rebuild_every`` steps (Algorithm 5.2, thesis k = 5). ``integrate``
   is called once per chunk of ``rebuild_every`` steps because a rebuild changes the
   sparsity structure the stepper caches (docs/contact.md). A safety rebuild happens after
   any step that moved a centroid more than half the search margin since the last
   rebuild. Stops early when the largest nodal speed falls below ``v_tol``.
2. **Static Newton with a capped step** (``capped_newton``) from the relaxed state with
   velocities zeroed: the Newton step is scaled so that no centroid moves more than
   ``step_cap`` (default half the search margin) in one iteration, halved while it makes
   det F <= 0, and the contact map is rebuilt whenever a centroid has moved more than
   half the margin since the last rebuild. Contacts the map did not hold cannot be skipped
   over this way, and near the solution the full step is taken (quadratic convergence).
   Repeated (``static_rounds``) until a rebuild at the solution finds no active pair the
   previous map missed. If it fails, pseudo-transient continuation takes over.

``RelaxResult``: final ``x``, ``w`` (zero velocities after the static phase), ``t``,
``history`` (one dict per chunk/solve/stage: iterations, factorisations, residuals,
energies, pairs, active pairs, max overlap / R, wall time), ``timings`` (seconds:
dynamic, static, total), iteration counts, and the last static ``NewtonResult``
(``MinimizeResult`` for the energy path).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..solvers.dirk import IntegrationFailure, integrate
from ..solvers.newton import NewtonResult, convergence_rates, sparse_solve
from ..solvers.static import StaticProblem, pseudo_transient_solve

__all__ = ["RelaxSettings", "RelaxResult", "relax_to_equilibrium", "capped_newton", "minimize_energy",
           "MinimizeResult", "factor_inertia"]

log = logging.getLogger("rve.contact.relax")


@dataclass
class RelaxSettings:
    duration: float
    steps: int
    rebuild_every: int = 5
    newton_atol: float = 1e-9
    newton_rtol: float = 1e-6
    newton_max_iter: int = 25
    v_tol: float = 0.0
    static: bool = True
    static_atol: float = 1e-9
    static_rtol: float = 1e-12
    static_rounds: int = 4
    static_max_iter: int = 40
    step_cap: Optional[float] = None
    method: str = "dynamic"
    onset_schedule: tuple = (0.0,)
    energy_max_iter: int = 300
    time_budget: Optional[float] = None
    backtrack: int = 3
    near: float = 0.0
    reuse: int = 0


@dataclass
class RelaxResult:
    x: np.ndarray
    w: np.ndarray
    t: float
    history: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    dynamic_steps: int = 0
    dynamic_newton_iterations: int = 0
    static_newton_iterations: int = 0
    static_converged: bool = False
    static_result: object = None


def _free_residual(system, x, t):
    F, _, _ = system.evaluate(x, np.zeros(system.n), t, jacobian=False)
    idx, _ = system.constraints(t)
    F = np.array(F, copy=True)
    F[np.asarray(idx, dtype=np.int64)] = 0.0
    return float(np.linalg.norm(F))


def relax_to_equilibrium(system, x, w, settings: RelaxSettings, on_rebuild: Optional[Callable] = None,
                         t0: float = 0.0) -> RelaxResult:
    if settings.method == "energy":
        return _relax_energy(system, x, settings, on_rebuild, t0)
    if settings.method != "dynamic":
        raise ValueError(f"unknown relaxation method {settings.method!r} (energy, dynamic)")
    s = settings
    t_start = time.perf_counter()
    x = np.array(x, float, copy=True)
    w = np.array(w, float, copy=True)
    t = float(t0)
    out = RelaxResult(x, w, t)
    h = s.duration / max(1, s.steps)
    nopts = {"atol": s.newton_atol, "rtol": s.newton_rtol, "max_iter": s.newton_max_iter}
    k = max(1, int(s.rebuild_every))
    done = 0
    chunk = 0
    guard = 0.5 * float(system.params.margin)
    extra = [0]

    def on_step(t_, x_, w_, info):
        # safety: fibrils moved more than half the search margin since the last rebuild
        # -> rebuild now (the stepper then assembles through its general path for the
        # rest of the chunk, still exact)
        if guard > 0 and system.max_displacement_since_rebuild(x_) > guard:
            system.rebuild(x_)
            extra[0] += 1

    while done < s.steps and s.duration > 0:
        m = min(k, s.steps - done)
        system.rebuild(x)
        try:
            res = integrate(system, x, w, t, t + m * h, m, stages=1, newton_opts=nopts, consistent=False,
                            on_step=on_step)
        except IntegrationFailure as exc:
            log.warning("dynamic relaxation stopped at t = %.4g: %s", exc.t, exc)
            x, w, t = exc.x, exc.w, exc.t
            break
        x, w, t = res.x, res.w, res.t
        done += m
        chunk += 1
        out.dynamic_steps += res.steps
        out.dynamic_newton_iterations += res.newton_iterations
        st = system.contact_state(x)
        vmax = float(np.abs(w[system.mech]).max()) if np.any(system.mech) else 0.0
        rec = {"phase": "dynamic", "t": t, "steps": res.steps, "rejected": res.rejected, "extra_rebuilds": extra[0],
               "newton_iterations": res.newton_iterations, "pairs": st["pairs"],
               "active_pairs": st["active_pairs"], "max_overlap_over_R": st["max_overlap_over_R"],
               "max_speed": vmax, "wall_s": time.perf_counter() - t_start}
        out.history.append(rec)
        log.info("relax chunk %d: %s", chunk, rec)
        if on_rebuild is not None:
            on_rebuild(chunk, t, x, w)
        if s.v_tol > 0 and vmax < s.v_tol:
            break
    out.timings["dynamic"] = time.perf_counter() - t_start
    t1 = time.perf_counter()
    w = np.zeros_like(w)
    if s.static:
        cap = s.step_cap if s.step_cap is not None else 0.5 * float(system.params.margin)
        for rnd in range(s.static_rounds):
            system.rebuild(x)
            xs, ws, nres = capped_newton(system, x, t, atol=s.static_atol, rtol=s.static_rtol,
                                         max_iter=s.static_max_iter, step_cap=cap)
            how = "capped newton"
            if not nres.converged:
                log.warning("static Newton failed (%s); pseudo-transient continuation", nres.reason)
                system.rebuild(xs)
                xs2, ws2, pres = pseudo_transient_solve(system, xs, w, t, atol=s.static_atol, rtol=s.static_rtol,
                                                        max_iter=200)
                how = "pseudo-transient"
                nres = NewtonResult(pres.u, pres.converged, nres.iterations + pres.iterations,
                                    nres.residuals + pres.residuals, pres.reason)
                xs, ws = xs2, ws2
            out.static_newton_iterations += nres.iterations
            x, w = xs, ws
            out.static_result = nres
            out.static_converged = bool(nres.converged)
            # a rebuild at the solution: did pairs the map missed come into contact?
            before = set(zip(*_active_keys(system, x)))
            system.rebuild(x)
            after = set(zip(*_active_keys(system, x)))
            st = system.contact_state(x)
            rec = {"phase": "static", "round": rnd + 1, "method": how, "converged": bool(nres.converged),
                   "newton_iterations": int(nres.iterations), "residuals": [float(r) for r in nres.residuals],
                   "pairs": st["pairs"], "active_pairs": st["active_pairs"],
                   "max_overlap_over_R": st["max_overlap_over_R"], "wall_s": time.perf_counter() - t_start}
            out.history.append(rec)
            log.info("static round %d: converged=%s its=%d", rnd + 1, nres.converged, nres.iterations)
            if nres.converged and after <= before:
                break
    out.timings["static"] = time.perf_counter() - t1
    out.timings["total"] = time.perf_counter() - t_start
    out.x, out.w, out.t = x, w, t
    return out


def _relax_energy(system, x, s: RelaxSettings, on_rebuild, t0) -> RelaxResult:
    """Continuation in the penalty onset: ``minimize_energy`` with the onset width set to
    each entry of ``s.onset_schedule`` in turn (fractions of R; the last is the law of the
    result), each stage from the previous one's minimum. A map rebuild at the end checks
    that no pair came into contact unseen (cannot happen under the step guard; logged)."""
    t_start = time.perf_counter()
    x = np.array(x, float, copy=True)
    out = RelaxResult(x, np.zeros(system.n), float(t0))
    sched = [float(v) for v in s.onset_schedule] or [float(system.params.onset)]
    system.rebuild(x)
    for k, eps in enumerate(sched):
        system.set_onset(eps)
        budget = None if s.time_budget is None else max(1.0, s.time_budget - (time.perf_counter() - t_start))
        xs, _, res = minimize_energy(system, x, t0, atol=s.static_atol, rtol=s.static_rtol,
                                     max_iter=s.energy_max_iter, step_cap=s.step_cap, label=f"onset={eps:g}R",
                                     time_budget=budget, sigma0=None if k == 0 else 0.0,
                                     backtrack=s.backtrack, near=s.near, reuse=s.reuse)
        x = xs
        st = system.contact_state(x)
        rec = {"phase": "static", "stage": k + 1, "method": "minimize_energy", "onset_over_R": eps,
               "converged": bool(res.converged), "newton_iterations": int(res.iterations),
               "factorizations": int(res.factorizations), "reused_factorization_steps": int(res.reused),
               "rejections": int(res.rejections),
               "map_rebuilds": int(res.rebuilds), "negative_pivots": int(res.negative_pivots),
               "residuals": [float(v) for v in res.residuals], "energies": [float(v) for v in res.energies],
               "sigmas": [float(v) for v in res.sigmas], "steps": [float(v) for v in res.steps],
               "pairs": st["pairs"], "active_pairs": st["active_pairs"],
               "max_overlap_over_R": st["max_overlap_over_R"], "wall_s": time.perf_counter() - t_start,
               "reason": res.reason}
        out.history.append(rec)
        out.static_newton_iterations += res.iterations
        out.static_result = res
        out.static_converged = bool(res.converged)
        log.info("onset stage %d (%gR): converged=%s its=%d factorizations=%d |F|=%.3e Pi=%.10g wall=%.1f s",
                 k + 1, eps, res.converged, res.iterations, res.factorizations, res.residuals[-1],
                 res.energies[-1], rec["wall_s"])
        if on_rebuild is not None:
            on_rebuild(k + 1, float(t0), x, np.zeros(system.n))
        if not res.converged and res.reason.startswith("time budget"):
            break
    before = set(zip(*_active_keys(system, x)))
    system.rebuild(x)
    after = set(zip(*_active_keys(system, x)))
    if not after <= before:
        log.warning("final map rebuild found %d active pairs the map had missed", len(after - before))
        out.static_converged = False
    out.timings["dynamic"] = 0.0
    out.timings["static"] = out.timings["total"] = time.perf_counter() - t_start
    out.x, out.w = x, np.zeros(system.n)
    return out


def capped_newton(system, x, t, atol=1e-9, rtol=1e-12, max_iter=60, step_cap=0.05, max_halvings=20,
                  max_rejections=12):
    """Static Newton on ``F(x, 0, t) = 0`` with the centroid motion per iteration capped
    at ``step_cap``, the contact map rebuilt after ``step_cap`` of motion, and a
    Levenberg-Marquardt safeguard: a step that increases |F| is rejected and retried
    with ``(K + sigma M) du = -F`` (sigma raised 8x per rejection, lowered 4x after an
    accepted step, down to pure Newton). Returns ``(x, w, NewtonResult)``."""
    w0 = np.zeros(system.n)
    lay = system.layout

    def setup(xc):
        prob = StaticProblem(system, xc, w0, t)  # fresh restriction plans for the current structure
        free = prob.free
        cen = np.flatnonzero(prob.free_mech & np.isin(free % lay.block, (0, 1, 2)))
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
        A = J if sigma == 0.0 else (J + sigma * Mff).tocsc()
        try:
            du = -sparse_solve(A, r)
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


def _active_keys(system, x):
    act = system.active_pairs(x)
    return system.map.e_plus[act], system.map.e_minus[act]


# ----------------------------------------------------------------------------- energy minimiser
#: SuperLU as a symmetric factorisation: minimum degree on A^T + A, diagonal pivots only.
#: For a symmetric matrix the diagonal of U is then the D of A = L D L^T (up to rounding),
#: so the number of negative entries is the number of negative eigenvalues (Sylvester).
_SYM = dict(permc_spec="MMD_AT_PLUS_A", options=dict(SymmetricMode=True, DiagPivotThresh=0.0))


def factor_inertia(A):
    """Factorise the symmetric sparse ``A`` (SuperLU, symmetric mode, diagonal pivots) and
    count its negative eigenvalues from the pivots. Returns ``(lu, n_negative)``;
    ``(None, -1)`` when a pivot is exactly zero."""
    try:
        lu = spla.splu(sp.csc_matrix(A), **_SYM)
    except RuntimeError:
        return None, -1
    d = lu.U.diagonal()
    if not np.all(np.isfinite(d)):
        return None, -1
    return lu, int(np.count_nonzero(d < 0.0))


@dataclass
class MinimizeResult(NewtonResult):
    """``NewtonResult`` of ``minimize_energy`` plus its per-iteration record:
    ``energies`` (N mm), ``sigmas`` (regularisation used by each accepted step),
    ``steps`` (step fraction alpha), ``factorizations``, ``rejections``, ``rebuilds``,
    ``negative_pivots`` (inertia of the last unregularised tangent; 0: a local minimum)."""

    energies: list = field(default_factory=list)
    sigmas: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    factorizations: int = 0
    reused: int = 0
    rejections: int = 0
    rebuilds: int = 0
    negative_pivots: int = -1


def minimize_energy(system, x, t=0.0, *, atol=1e-9, rtol=1e-14, max_iter=300, step_cap=None, sigma0=None,
                    label="minimize", time_budget=None, backtrack=0, near=0.0, reuse=0):
    """Static equilibrium of a mechanics-only ``ContactSystem`` as a **local minimum** of its
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
    stiffest mode's; 0 to start with plain Newton from a near solution). Options measured
    without gain on the weave (docs/relaxation.md): ``near`` (mm; while steps are large the
    tangent also holds the normal penalty stiffness of points closer than this,
    ``ContactSystem.tangent_near``) and ``reuse`` (modified-Newton steps with the same
    factorisation while sigma > 0). Converged when ``|F_free| <= atol`` or
    ``<= rtol |F_0|``.

    Returns ``(x, w, MinimizeResult)``; every iteration is logged on ``rve.contact.relax``.
    """
    t0 = time.perf_counter()
    w0 = np.zeros(system.n)
    lay = system.layout
    guard = 0.5 * float(system.params.margin)
    cap = guard if step_cap is None else float(step_cap)
    if cap > guard:
        raise ValueError(f"step_cap {cap} exceeds half the search margin {guard}")

    def setup(xc):
        prob = StaticProblem(system, xc, w0, t)
        cen = np.flatnonzero(prob.free_mech & np.isin(prob.free % lay.block, (0, 1, 2)))
        return prob, cen, prob.fd.matrix(system.mass())

    x = np.array(x, float, copy=True)
    if system.max_displacement_since_rebuild(x) > 0.0:
        system.rebuild(x)
    system.tangent_near = float(near)
    prob, cen, Mff = setup(x)
    u = prob.u0()
    r, J = prob(u)
    rn = float(np.linalg.norm(r))
    Pi = float(system.energy(x))
    out = MinimizeResult(u, False, 0, [rn], energies=[Pi])
    r0 = rn
    dK, dM = np.abs(J.diagonal()).max(), np.abs(Mff.diagonal()).max()
    scale = float(dK / dM) if dM > 0 else 1.0  # sigma of the stiffest mode
    sig_floor = 1e-8 * scale
    sigma = 1e-6 * scale if sigma0 is None else float(sigma0)
    sig_neg = 0.0
    it = 0
    while True:
        if rn <= atol or rn <= rtol * r0:
            out.converged = True
            break
        if it >= max_iter:
            out.reason = f"no convergence in {max_iter} iterations (|F| = {rn:.3e})"
            break
        if time_budget is not None and time.perf_counter() - t0 > time_budget:
            out.reason = f"time budget {time_budget:.0f} s spent (|F| = {rn:.3e})"
            break
        if not np.isfinite(rn):
            out.reason = "non-finite residual"
            break
        # factorise K + sigma M, raising sigma until it is positive definite
        for _ in range(60):
            lu, neg = factor_inertia(J if sigma == 0.0 else J + sigma * Mff)
            out.factorizations += 1
            if sigma == 0.0:
                out.negative_pivots = neg
            if neg == 0:
                break
            sig_neg = max(sig_neg, sigma)
            sigma = max(4.0 * sigma, sig_floor)
        else:
            out.reason = "no positive definite regularisation found"
            break
        du = -lu.solve(r)
        slope = float(r @ du)
        quad = float(du @ (J @ du))
        move = float(np.abs(du[cen]).max()) * np.sqrt(3.0) if cen.size else 0.0
        alpha = min(1.0, cap / move) if move > 0 else 1.0
        x_cur = prob.state(u)[0]
        ut = u + alpha * du
        xt = prob.state(ut)[0]
        rebuilt = False
        if system.max_displacement_since_rebuild(xt) > guard:
            system.rebuild(x_cur)  # same energy at x_cur; the trial is within the guard of it
            out.rebuilds += 1
            rebuilt = True
        Pt = float(system.energy(xt))
        pred = alpha * slope + 0.5 * alpha * alpha * quad
        ratio = (Pt - Pi) / pred if pred < 0 else -1.0
        noise = 1e-12 * max(1.0, abs(Pi))
        accept = Pt < Pi - noise
        backtracked = 0
        while backtrack and not accept and np.isfinite(Pi) and backtracked < backtrack and pred < -noise:
            # a step into contacts the model does not hold (or past a curvature change):
            # shorten it along the same direction, energies only (no new factorisation)
            alpha *= 0.5
            backtracked += 1
            xt = prob.state(u + alpha * du)[0]
            Pt = float(system.energy(xt))
            pred = alpha * slope + 0.5 * alpha * alpha * quad
            ratio = (Pt - Pi) / pred if pred < 0 else -1.0
            accept = Pt < Pi + 1e-4 * alpha * slope
        ut = u + alpha * du
        if rebuilt:
            prob, cen, Mff = setup(x_cur)
            u = prob.u0()
            ut = u + alpha * du
        if accept or (np.isfinite(Pt) and Pt <= Pi + noise):
            rt, Jt = prob(ut)
            rtn = float(np.linalg.norm(rt))
            if not accept:
                accept = rtn < rn  # energy change lost in rounding: the residual decides
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
        out.residuals.append(rn)
        out.energies.append(Pi)
        out.sigmas.append(sigma)
        out.steps.append(alpha)
        sigma_used = sigma
        if reuse and sigma_used > 0.0 and ratio > 0.5 and not backtracked:
            # modified-Newton steps with the same factorisation of K + sigma M (residual +
            # energy + a triangular solve each, no assembly of K): while the regularised
            # model is good, they buy most of a new factorisation's progress at a fraction
            # of its cost. Never in the sigma = 0 phase (quadratic convergence untouched).
            inner = 0
            while inner < reuse and rn > atol and it < max_iter:
                du2 = -lu.solve(r)
                slope2 = float(r @ du2)
                if not slope2 < 0.0:
                    break
                mv2 = float(np.abs(du2[cen]).max()) * np.sqrt(3.0) if cen.size else 0.0
                a2 = min(1.0, cap / mv2) if mv2 > 0 else 1.0
                u2 = u + a2 * du2
                x2 = prob.state(u2)[0]
                if system.max_displacement_since_rebuild(x2) > guard:
                    break
                P2 = float(system.energy(x2))
                if not P2 < Pi + 1e-4 * a2 * slope2:
                    break
                F2, _, _ = system.evaluate(x2, w0, t, jacobian=False)
                r2 = np.asarray(F2, float)[prob.free]
                inner += 1
                it += 1
                u, r, rn, Pi = u2, r2, float(np.linalg.norm(r2)), P2
                out.residuals.append(rn)
                out.energies.append(Pi)
                out.sigmas.append(sigma_used)
                out.steps.append(a2)
                out.reused += 1
                log.info("%s it=%d |F|=%.3e Pi=%.12e step=%.3g (same factorisation)", label, it, rn, Pi, a2)
            if inner:
                r, J = prob(u)
        # lower sigma after a good full step, but not below twice the last sigma at which
        # K + sigma M was indefinite (that memory fades by 4x per iteration): saves the
        # factorisations the inertia check would reject
        if backtracked:
            sigma = max(2.0 * sigma, sig_floor)
        elif ratio > 0.5 and alpha == 1.0:
            sigma = max(sigma / (8.0 if ratio > 0.75 else 4.0), 2.0 * sig_neg)
            if ratio > 0.75:
                # near the solution sigma also follows |F|^2 (Levenberg-Marquardt with
                # sigma ~ |F|^2 keeps Newton's quadratic rate while it is still > 0)
                sigma = min(sigma, sigma_used * (rn / rn_prev) ** 2)
            if sigma <= sig_floor:
                sigma = 0.0
        elif ratio < 0.25:
            sigma = max(4.0 * sigma, sig_floor)
        elif alpha < 1.0:
            sigma = max(2.0 * sigma, sig_floor)
        sig_neg *= 0.25
        if system.tangent_near > 0.0 and not backtracked and alpha == 1.0 and (
                alpha * move < 0.25 * system.tangent_near or rn < 1e-5):
            # the motion is now small against the near band: exact tangent from here on
            system.tangent_near = 0.0
            r, J = prob(u)
            log.info("%s it=%d: near-contact stiffness off (exact Newton from here)", label, it)
        rates = convergence_rates(out.residuals)
        log.info("%s it=%d |F|=%.3e Pi=%.12e dPi=%.2e ratio=%.2f step=%.3g sigma=%.3g pairs=%d rate=%s wall=%.1f",
                 label, it, rn, Pi, dPi, ratio, alpha, out.sigmas[-1], system.map.n_pairs,
                 f"{rates[-1]:.2f}" if rates else "-", time.perf_counter() - t0)
    system.tangent_near = 0.0
    out.u = u
    out.iterations = it
    xs, ws = prob.state(u)
    return xs, ws, out
