"""Static steps of a system with friction: the equilibrium from the history of the last
converged step, then the history committed (docs/contact.md "Friction", "Solving with
friction" and "Cost on a weave").

Contract
--------
Friction is path-dependent: its forces are not the gradient of an energy, so the exact
frictional equilibrium is a root of the residual ``F(x, 0, t) = 0`` (the friction history
of the last converged step held fixed), whose tangent is unsymmetric (the linear solves
send it to the LU path: ``rve.solvers.linear.sparse_solve`` never hands an unsymmetric
matrix to a symmetric factorisation).

* ``friction_of(system)`` -> the system's friction (an object with ``commit(x)``: the
  ``FrictionTerm`` of a contact system's term), or None for a frictionless system;
* ``frictional_static_step(system, x, w, t, newton_opts=None, method="newton")`` ->
  ``(x, w, result, dissipated)``: the solve, and on convergence the commit
  (``dissipated``: the energy dissipated by the step, N mm; 0.0 without convergence, the
  history unchanged). ``method="newton"``: Newton on the residual from ``x``
  (``rve.solvers.static.static_solve``; the single-fibril scenes); ``"potential"``:
  ``frictional_solve`` below.
* ``frictional_solve(system, x, t, atol, rtol=1e-14, max_iter=200, ...)`` -> ``(x,
  FrictionalResult)`` (no commit): the globalised solve of a step that moves many contacts
  (the weave's strain steps; docs/contact.md "Cost on a weave"):

  1. **predictor**: with the loads (normal force and normal of every contact point) frozen,
     the friction is the gradient of a convex incremental potential
     (``rve.physics.friction_forms.frozen_potential``), so the step is a minimisation of
     ``Pi(x) + sum psi`` by the energy minimiser (``minimize_energy``: trust region,
     inertia check, the map rebuilt as fibrils move, the frozen loads carried by point
     key). The loads are frozen first at the last committed state (``freeze="committed"``;
     ``"current"``: at ``x``) and, ``refreeze=True`` (default), refrozen at every accepted
     iterate (``minimize_energy(on_accept=...)``), so the minimiser's fixed point is the
     exact equilibrium (at loads frozen at the state itself the potential's forces are the
     law's). ``smoothing`` (default ``(1.0,)``): stages with the cone's corner rounded by
     these ``eta`` first (each to ten times the next stage's tolerance), then the law
     (``eta = 0``) to ``predictor_rtol`` (default 1e-4) of the step's initial |F|.
     ``refreeze=False``: rounds of converged minimisations at fixed loads, refrozen between
     rounds until the loads change by at most ``load_rtol`` (default ``LOAD_RTOL``, 5 %; at
     most ``max_rounds``, default 4), or until a round's load change exceeds ``LOAD_JUMP``
     times the round before's (a point flipped between contact or stick and slip, and more
     rounds cycle). ``refreeze=None`` (default): False, with ``max_rounds`` default
     ``RESOLVE_ROUNDS`` (8), when the friction is ``resolving`` (the re-solves of
     ``multipliers.equilibrium``'s Uzawa loop at updated multipliers and raised P*), else
     True. A re-solve's rounds hand over to the corrector at ``RESOLVE_LOAD_RTOL`` (3 %) and,
     where that corrector fails, its retry's rounds go on to ``RESOLVE_RETRY_LOAD_RTOL``
     (1 %): on the periodic cell's uniaxial steps a corrector from loads still changing by
     2-4 % failed, one from below 1 % converged, while in its shear steps one from 2.6 %
     converged and the rounds to 1 % took twice the iterations (docs/contact.md "When a
     re-solve's rounds hand over to the corrector"). Measured on the periodic 2 x 2 weave's
     shear step (docs/contact.md "Friction with the augmented Lagrangian and the periodic
     cell"): at a re-solve's start the normal loads jump with the raised P*, and refreezing
     them at every accepted iterate makes the minimiser's merit jump at each refreeze and the
     iterates oscillate (P* = 600: 922 iterations; 2400: |F| 0.09 -> 1.1 and no convergence),
     where rounds take 114 + 3 and 116 + 5 iterations; the first solve of a step keeps the
     refreezing (56 iterations there, rounds stall). A re-solve's first round freezes the
     loads of the last converged solve, before the multiplier update (``RESOLVE_HELD``:
     ``FrictionTerm.hold_loads`` at the end of every converged solve of an augmented system,
     ``freeze_held``; those at the re-solve's start have jumped with the updated multipliers),
     and every later round freezes normal forces halfway between those at its start and the
     round before's (``RESOLVE_BLEND`` = 0.5, by point key): the loads of plain rounds settle
     into a two-set cycle (load change 13 % or 58 % round after round, |F| ~1e-3 N) that the
     mean breaks. A re-solve takes the law's stage alone first (``RESOLVE_SMOOTHING``: no
     smoothed stage; it starts next to the last solve's equilibrium), without the fallback;
     where that fails, the caller's stages from the same start, with it;
  2. **corrector**: Newton on the exact residual with its exact unsymmetric tangent from
     the predictor's state (``static_solve``, line search on |F|; the linear solves on the
     LU companion of the run's PARDISO instance, checked by their residual, else
     ``sparse_solve``; quadratic once the stick/slip set is settled; logged on
     ``rve.newton``), at most ``corrector_iter`` iterations. It first takes up to
     ``FULL_STEPS`` full steps with |F| allowed to rise (a watchdog, ``_full_steps``: a step
     across a stick/slip or contact change raises |F| once, and the next converge
     quadratically, where the line search on |F| cut every step and crept), kept where they
     converge; else the line-search Newton goes on from their lowest |F|, in chunks of 3
     iterations; a chunk that does not reduce |F| tenfold is a stall (Newton heading for
     another root of the non-unique frictional equilibrium, its line search creeping) and
     ends it;
  3. if the corrector fails: the predictor again (the law, no smoothing stage) to
     ``retry_rtol`` (1e-6) and the corrector;
     then (``fallback=True``) the residual path of before from the better state: the capped
     Newton (``rve.solvers.minimize.capped_newton``), then pseudo-transient continuation;
     ``fallback_stall``: the capped Newton stops where |F| fell by less than 1 % over that
     many iterations (``capped_newton(stall_window=...)``), and no continuation follows (a
     caller that cuts the step where the solve fails).

  **Provisional solves** (``fr.provisional``, set by ``multipliers.equilibrium`` while a
  solve's state only feeds the next multiplier update): the first predictor stage alone, no
  corrector and no fallback, ``converged`` the stage's minimisation's, ``method``
  "provisional" (``_provisional``). A re-solve's stage is one round of the law at the held
  loads (to ``predictor_rtol``); a step's first solve its first stage (the smoothed one, ten
  times looser, where ``smoothing`` has one) with the loads refrozen at every accepted
  iterate. The held loads are then those at its state.

  A start already within ``direct_atol`` (N; default 1e4 atol) of equilibrium (the re-solve after a commit)
  goes to the corrector first, and to the predictor only if it stalls. The first pass's
  predictor stages stop after ``predictor_iter`` iterations each (the trust region crawls on
  the law's corner, while Newton converges from |F| ~ 1e-4 in 3 iterations); the retry's
  predictor has ``max_iter``.

  ``FrictionalResult`` (a ``NewtonResult``): ``iterations`` all linear-solve iterations
  (predictor + corrector + fallback), ``residuals`` the exact |F| at the start, after every
  predictor stage and after every corrector iteration, ``rounds`` (predictor stages),
  ``predictor_iterations``, ``corrector_iterations``, ``fallback_iterations``,
  ``load_changes`` (per stage), ``walls`` (s, per phase), ``method`` (the path that
  converged).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .backends.registry import run_backend
from .linear import sparse_solve
from .newton import NewtonResult, StageFactorisation, convergence_rates
from .system import friction_of
from .static import StaticProblem, static_solve

__all__ = ["friction_of", "frictional_static_step", "frictional_solve", "FrictionalResult"]

log = logging.getLogger("rve.solvers.frictional")


def frictional_static_step(system, x, w, t: float, newton_opts: Optional[dict] = None, method: str = "newton"):
    """One static step from the held friction history; commits it on convergence.
    ``newton_opts`` (``method="potential"``): ``atol``, ``rtol``, ``max_iter``,
    ``direct_atol`` and ``smoothing`` of ``frictional_solve``."""
    if method == "potential":
        opts = dict(newton_opts or {})
        xs, res = frictional_solve(system, x, t, atol=opts.get("atol", 1e-9), rtol=opts.get("rtol", 1e-14),
                                   max_iter=opts.get("max_iter", 200), direct_atol=opts.get("direct_atol"),
                                   smoothing=opts.get("smoothing", (1.0,)))
        ws = np.zeros(system.n)
    elif method == "newton":
        xs, ws, res = static_solve(system, x, w, t, newton_opts)
    else:
        raise ValueError(f"unknown frictional step method {method!r} (newton, potential)")
    dissipated = 0.0
    fr = friction_of(system)
    if res.converged and fr is not None:
        dissipated = fr.commit(xs)
    return xs, ws, res, dissipated


@dataclass
class FrictionalResult(NewtonResult):
    """``NewtonResult`` of ``frictional_solve`` with its phases (module docstring)."""

    rounds: int = 0
    predictor_iterations: int = 0
    corrector_iterations: int = 0
    fallback_iterations: int = 0
    load_changes: list = field(default_factory=list)
    method: str = ""
    #: whether the last predictor round's minimisation converged
    round_converged: bool = False
    #: wall time (s) of every predictor round, then of the corrector, then of the fallback
    walls: list = field(default_factory=list)


def _exact_residual(system, x, t) -> float:
    prob = StaticProblem(system, x, np.zeros(system.n), t)
    F, _, _ = system.evaluate(prob.x, prob.w, t, jacobian=False)
    return float(np.linalg.norm(np.asarray(F, float)[prob.free]))


def _load_change(fr, x) -> float:
    """max |f(x) - f0| / max f0 over the map's points (the frozen loads f0 against those at x)."""
    f0 = fr.frozen_loads()["f0"]
    f = fr.loads_at(x)["f0"]
    scale = max(float(f0.max(initial=0.0)), float(np.max(f, initial=0.0)), 1e-300)
    return float(np.abs(f - f0).max(initial=0.0)) / scale


def _unsymmetric_solver(solver):
    """``linear_solve`` of the corrector: the unsymmetric tangent by the run's instance
    (``StageFactorisation``: a symmetric PARDISO instance hands it to its LU companion,
    whose analysis is reused while the pattern holds), checked by its residual, else
    ``sparse_solve``."""

    def solve(J, r):
        try:
            du = StageFactorisation(J, solver).solve(r)
            if np.all(np.isfinite(du)) and np.linalg.norm(J @ du - r) <= 1e-8 * max(np.linalg.norm(r), 1e-300):
                return du
        except RuntimeError:
            pass
        return sparse_solve(J, r)

    return solve


def _refreezer(fr):
    """``on_accept`` of the minimiser: the loads refrozen at every accepted iterate."""

    def on_accept(x):
        fr.freeze(x)
        return True

    return on_accept


#: predictor rounds per stage of an augmented-Lagrangian re-solve (``fr.resolving``; module docstring)
RESOLVE_ROUNDS = 8

#: a re-solve's first round freezes the loads of the last converged solve (``hold_loads``)
RESOLVE_HELD = True
#: weight of the loads at the round's start in a re-solve round's frozen normal forces, the
#: rest the last round's (1: the loads at the start alone)
RESOLVE_BLEND = 0.5
#: the load change at which the predictor's rounds hand over to the corrector
LOAD_RTOL = 0.05
#: the same for a re-solve, and the one to which its retry's rounds go on after that
#: corrector failed
RESOLVE_LOAD_RTOL, RESOLVE_RETRY_LOAD_RTOL = 0.03, 0.01
#: a round whose load change exceeds this many times the round before's ends the rounds
LOAD_JUMP = 2.0
#: the predictor stages of an augmented-Lagrangian re-solve (None: the caller's
#: ``smoothing``): the law's stage alone, since a re-solve starts next to the last solve's
#: equilibrium and the smoothed stage would first move it off to its own solution
RESOLVE_SMOOTHING = ()


def frictional_solve(system, x, t: float = 0.0, *, atol: float = 1e-9, rtol: float = 1e-14, max_iter: int = 200,
                     refreeze: Optional[bool] = None, predictor_rtol: float = 1e-4, retry_rtol: float = 1e-6,
                     max_rounds: Optional[int] = None, load_rtol: Optional[float] = None, corrector_iter: int = 12,
                     freeze: str = "committed", fallback: bool = True, step_cap=None, backend=None,
                     smoothing=(1.0,), predictor_iter: int = 150, direct_atol: Optional[float] = None,
                     fallback_stall: Optional[int] = None):
    """The frictional equilibrium from the held history (module docstring); ``(x, result)``."""
    fr = friction_of(system)
    if fr is None:
        raise ValueError("frictional_solve: the system has no friction")
    resolve = refreeze is None and bool(getattr(fr, "resolving", False))
    fallback = fallback and bool(getattr(fr, "fallback", True))
    if refreeze is None:   # an augmented-Lagrangian re-solve: rounds (module docstring)
        refreeze = not resolve
    if max_rounds is None:
        max_rounds = RESOLVE_ROUNDS if resolve else 4
    if load_rtol is None:
        load_rtol = RESOLVE_LOAD_RTOL if resolve else LOAD_RTOL
    if getattr(fr, "provisional", False):
        xs, out = _provisional(system, fr, x, t, atol, rtol, min(max_iter, predictor_iter), predictor_rtol, step_cap,
                               backend, resolve, smoothing, freeze)
        if out.converged:
            fr.hold_loads(xs)
        return xs, out
    # (stages, fallback) of each pass: a re-solve takes the law's stage alone first and, where
    # that fails, the caller's stages from the same start (module docstring)
    passes = [(smoothing, fallback)]
    if resolve and RESOLVE_SMOOTHING is not None and tuple(RESOLVE_SMOOTHING) != tuple(smoothing):
        passes.insert(0, (RESOLVE_SMOOTHING, False))
    done = None
    for stages, fb in passes:
        xs, out = _solve(system, fr, x, t, atol, rtol, max_iter, refreeze, predictor_rtol, retry_rtol, max_rounds,
                         load_rtol, corrector_iter, freeze, fb, step_cap, backend, stages, predictor_iter,
                         direct_atol, resolve, fallback_stall)
        if done is not None:
            for k in ("iterations", "predictor_iterations", "corrector_iterations", "rounds"):
                setattr(out, k, getattr(out, k) + getattr(done, k))
        if out.converged:
            break
        if (stages, fb) != passes[-1]:
            log.info("friction re-solve: the law's stage alone did not converge (%s); again with the smoothed "
                     "stage", out.reason)
        done = out
    if getattr(system, "augmented", False) and hasattr(fr, "hold_loads"):
        # the loads the next re-solve of the Uzawa loop freezes first (module docstring)
        fr.hold_loads(xs if out.converged else None)
    return xs, out


def _solve(system, fr, x, t, atol, rtol, max_iter, refreeze, predictor_rtol, retry_rtol, max_rounds, load_rtol,
           corrector_iter, freeze, fallback, step_cap, backend, smoothing, predictor_iter, direct_atol, resolve,
           fallback_stall=None):
    """``frictional_solve`` once the re-solve is told apart (module docstring)."""
    x = np.array(x, float, copy=True)
    system.rebuild(x)
    out = FrictionalResult(None, False, 0, [_exact_residual(system, x, t)])
    if out.residuals[0] <= (1e4 * atol if direct_atol is None else direct_atol):
        # a start next to an equilibrium (the re-solve after a commit): Newton alone, since
        # the smoothed predictor stage would first move the state off to its own solution
        xs, nres = _corrector(system, x, t, out, atol, rtol, corrector_iter, backend)
        if nres.converged:
            out.u, out.converged, out.method = nres.u, True, "newton"
            return xs, out
        if np.isfinite(nres.residuals[-1]) and nres.residuals[-1] < nres.residuals[0]:
            x = xs
    first = _first_loads(fr, freeze, resolve)
    for ptol in (predictor_rtol, retry_rtol):
        # the retry goes on from the corrector's start with the law itself; a re-solve's
        # retry rounds go on until the loads have settled (module docstring)
        etas = (tuple(float(v) for v in smoothing if v > 0) if ptol == predictor_rtol else ()) + (0.0,)
        lr = min(load_rtol, RESOLVE_RETRY_LOAD_RTOL) if resolve and ptol != predictor_rtol else load_rtol
        for i, eta in enumerate(etas):
            tol = ptol * 10.0 ** (len(etas) - 1 - i)      # a decade looser per smoother stage
            # the first pass hands over to Newton after predictor_iter iterations: the law's
            # corner makes the trust region crawl, while Newton converges from far less close
            its = min(max_iter, predictor_iter) if ptol == predictor_rtol else max_iter
            x = _predictor(system, fr, x, t, out, max(atol, tol * out.residuals[0]), rtol, its, refreeze,
                           max_rounds, lr, first, step_cap, backend, eta, RESOLVE_BLEND if resolve else 1.0)
            first = None
        first = None
        xs, nres = _corrector(system, x, t, out, atol, rtol, corrector_iter, backend)
        if nres.converged:
            out.u, out.converged, out.method = nres.u, True, "potential predictor + newton"
            return xs, out
        log.warning("friction corrector did not converge (%s)", nres.reason)
        if np.isfinite(nres.residuals[-1]) and nres.residuals[-1] < nres.residuals[0]:
            x = xs
    if not fallback:
        out.u, out.reason = None, f"corrector: {nres.reason}"
        return x, out
    return _fallback(system, x, t, out, atol, rtol, max_iter, step_cap, backend, fallback_stall)


def _first_loads(fr, freeze, resolve):
    """The loads the first predictor round freezes (``_predictor``'s ``start``): a re-solve's
    held ones (``RESOLVE_HELD``), else the committed ones where kept and asked for, else
    those at the start."""
    if resolve and RESOLVE_HELD:
        return "held"
    return "committed" if fr._committed_loads is not None and freeze == "committed" else None


def _provisional(system, fr, x, t, atol, rtol, max_iter, predictor_rtol, step_cap, backend, resolve, smoothing,
                 freeze):
    """A provisional solve (``fr.provisional``): the first predictor stage alone, no corrector;
    ``converged`` is the stage's (module docstring). The first stage of ``_solve``'s first
    pass: a re-solve's is the law at its first loads (``_first_loads``: the held ones), to
    ``predictor_rtol`` of the start's |F|; a step's first solve's is its first stage (the
    smoothed one where ``smoothing`` has one, a decade looser per later stage) with the loads
    refrozen at every accepted iterate."""
    x = np.array(x, float, copy=True)
    system.rebuild(x)
    out = FrictionalResult(None, False, 0, [_exact_residual(system, x, t)])
    # the first stage of ``_solve``'s first pass, with its loads and tolerance
    etas = (0.0,) if resolve else tuple(float(v) for v in smoothing if v > 0) + (0.0,)
    tol = predictor_rtol * 10.0 ** (len(etas) - 1)
    xs = _predictor(system, fr, x, t, out, max(atol, tol * out.residuals[0]), rtol, max_iter, not resolve, 1, 0.0,
                    _first_loads(fr, freeze, resolve), step_cap, backend, etas[0])
    out.converged = bool(out.round_converged)
    out.u = xs if out.converged else None
    out.method = "provisional"
    out.reason = "" if out.converged else "the provisional stage did not converge"
    return xs, out


def _predictor(system, fr, x, t, out, ptol, rtol, max_iter, refreeze, max_rounds, load_rtol, start, step_cap,
               backend, eta=0.0, blend=1.0):
    """The predictor rounds from ``x`` (module docstring); returns the last round's state.
    ``start``: the first round's loads, "committed", "held" (``freeze_held``, where kept) or None (at
    ``x``); ``blend`` < 1: a later round's normal forces ``blend`` f(x) + (1 - blend) those of
    the previous round, by point key."""
    from .minimize import minimize_energy

    for k in range(1 if refreeze else max_rounds):
        t0 = time.perf_counter()
        if not (k == 0 and start == "held" and fr.freeze_held()):
            fr.freeze(None if (k == 0 and start == "committed") else x)
        if k and blend < 1.0:
            # the rounds' loads cycle between two sets where a point flips (contact, slip):
            # the mean of the two breaks the cycle
            fr.blend_frozen(prev[0], prev[1], blend)
        fr.smoothing = eta
        try:
            xs, _, mres = minimize_energy(system, x, t, atol=ptol, rtol=rtol, max_iter=max_iter, sigma0=0.0,
                                          backtrack=3, step_cap=step_cap, label=f"friction predictor {out.rounds + 1}",
                                          backend=backend, on_accept=_refreezer(fr) if refreeze else None)
            change = _load_change(fr, xs)
            prev = (np.array(fr.keys, copy=True), fr.frozen_loads()["f0"].reshape(-1))
        finally:
            fr.unfreeze()
        out.rounds += 1
        out.round_converged = bool(mres.converged)
        out.walls.append(time.perf_counter() - t0)
        out.predictor_iterations += int(mres.iterations)
        out.iterations += int(mres.iterations)
        out.load_changes.append(change)
        rn = _exact_residual(system, xs, t)
        out.residuals.append(rn)
        log.info("friction predictor round %d (smoothing %g): %s in %d iterations, load change %.3e, exact |F| = %.3e",
                 out.rounds, eta, "converged" if mres.converged else f"not converged ({mres.reason})", mres.iterations,
                 change, rn)
        if not np.isfinite(rn):
            break
        x = xs
        if change <= load_rtol or rn <= ptol:
            break
        if k and change > LOAD_JUMP * out.load_changes[-2]:
            # a point flipped (contact, stick/slip): the loads do not settle by more rounds
            break
    return x


def _corrector(system, x, t, out, atol, rtol, corrector_iter, backend, chunk: int = 3):
    """Newton on the exact residual from ``x``, its unsymmetric solves on the run's backend:
    first full steps (``_full_steps``), kept where they converge; else, from the best of them,
    in chunks of ``chunk`` iterations with the line search on |F|: a chunk that does not reduce
    |F| tenfold ends it (a stall: Newton heading for another root past a stick/slip change,
    its line search creeping; the caller then predicts again, more tightly)."""
    t0 = time.perf_counter()
    system.rebuild(x)
    with run_backend(backend) as solver:
        lin = _unsymmetric_solver(solver)
        xs, res, nres = _full_steps(system, x, t, atol, lin)
        done = len(res) - 1
        if not nres.converged:
            res = [res[0]] + ([min(res)] if min(res) < res[0] else [])   # the start, then the best
            while done < corrector_iter:
                n = min(chunk, corrector_iter - done)
                xs, _, nres = static_solve(system, xs, np.zeros(system.n), t, {
                    "atol": atol, "rtol": 0.0, "max_iter": n, "label": "friction corrector", "linear_solve": lin})
                done += int(nres.iterations)
                res = res + [float(v) for v in nres.residuals[1:]]
                if nres.converged or not (nres.residuals[-1] <= 0.1 * nres.residuals[0]) or nres.iterations < n:
                    break
    if not nres.converged and not res[-1] <= atol:
        nres.reason = nres.reason or f"stalled (|F| {res[0]:.3e} -> {res[-1]:.3e})"
    nres = NewtonResult(nres.u, bool(nres.converged), done, res, nres.reason)
    out.corrector_iterations += done
    out.iterations += done
    out.walls.append(time.perf_counter() - t0)
    out.residuals.extend(res[1:])
    return xs, nres


#: full Newton steps the corrector takes before its line search (``_full_steps``), and the
#: growth of |F| over the start's at which they stop
FULL_STEPS, FULL_STEP_GROWTH = 6, 100.0


def _full_steps(system, x, t, atol, lin):
    """Up to ``FULL_STEPS`` full Newton steps from ``x`` with |F| allowed to rise (a watchdog):
    a step across a stick/slip or contact change can raise |F| once and the next ones converge
    quadratically (the periodic cell's re-solves: |F| 1.1e-4 -> 8.5e-4 -> 6.2e-7 -> 1.4e-9 ->
    7.3e-13 N, where the line search on |F| cut every step and crept, -5 % an iteration). They
    stop where |F| exceeds ``FULL_STEP_GROWTH`` times the start's, or is not below it from the
    second step on. Returns ``(x of the lowest |F|, residuals of the iterates, start first,
    NewtonResult)``."""
    prob = StaticProblem(system, x, np.zeros(system.n), t)
    u = prob.u0()
    r, J = prob(u)
    res = [float(np.linalg.norm(r))]
    best = (res[0], u)
    for k in range(1, FULL_STEPS + 1):
        if res[-1] <= atol:
            break
        try:
            du = -lin(J, r)
        except RuntimeError:
            break
        if not np.all(np.isfinite(du)) or not prob.admissible(u + du):
            break
        u = u + du
        r, J = prob(u)
        res.append(float(np.linalg.norm(r)))
        rates = convergence_rates(res)
        log.info("friction corrector (full steps) it=%d |r|=%.3e rate=%s", k, res[-1],
                 f"{rates[-1]:.2f}" if rates else "-")
        if not np.isfinite(res[-1]):
            res.pop()
            break
        if res[-1] < best[0]:
            best = (res[-1], u)
        if res[-1] > FULL_STEP_GROWTH * res[0] or (k >= 2 and res[-1] >= res[0]):
            break
    ok = best[0] <= atol
    xs, _ = prob.state(best[1])
    return xs, res, NewtonResult(best[1], ok, len(res) - 1, res, "" if ok else "full steps did not converge")


def _fallback(system, x, t, out, atol, rtol, max_iter, step_cap, backend, stall=None):
    """The residual path of before from ``x``: the capped Newton, then pseudo-transient
    continuation; ``stall``: the capped Newton's stall window, and no continuation."""
    from .minimize import capped_newton
    from .static import pseudo_transient_solve

    t0 = time.perf_counter()
    system.rebuild(x)
    cap = 0.5 * float(system.params.margin) if step_cap is None else float(step_cap)
    xc, _, cres = capped_newton(system, x, t, atol=atol, rtol=rtol, max_iter=max_iter, step_cap=cap, backend=backend,
                                stall_window=stall)
    its = int(cres.iterations)
    if not cres.converged and stall is None:
        log.warning("frictional capped Newton failed (%s); pseudo-transient continuation", cres.reason)
        system.rebuild(xc)
        xc, _, pres = pseudo_transient_solve(system, xc, np.zeros(system.n), t, atol=atol, rtol=rtol, max_iter=200,
                                             backend=backend)
        its += int(pres.iterations)
        cres = NewtonResult(pres.u, pres.converged, its, cres.residuals + pres.residuals, pres.reason)
    out.fallback_iterations = its
    out.iterations += its
    out.walls.append(time.perf_counter() - t0)
    out.residuals.extend(float(v) for v in cres.residuals[1:])
    out.u, out.converged, out.reason = cres.u, bool(cres.converged), cres.reason
    out.method = "capped newton (friction)" if cres.converged else ""
    return xc, out
