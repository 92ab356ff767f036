"""Relaxation of a fibril assembly in contact to static equilibrium (thesis §6.3, §7.3).

Contract
--------
``relax_to_equilibrium(system, x, w, settings, on_rebuild=None) -> RelaxResult`` for a
``ContactSystem``:

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
``history`` (one dict per chunk/solve: time, Newton iterations, pairs, active pairs, max
overlap / R, max speed, wall time), ``timings`` (seconds: dynamic, static, total),
iteration counts, and the last static ``NewtonResult``.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..solvers.dirk import IntegrationFailure, integrate
from ..solvers.newton import NewtonResult, convergence_rates, sparse_solve
from ..solvers.static import StaticProblem, pseudo_transient_solve

__all__ = ["RelaxSettings", "RelaxResult", "relax_to_equilibrium", "capped_newton"]

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
