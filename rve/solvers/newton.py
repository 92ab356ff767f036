"""Newton's method for sparse nonlinear systems, with logged residuals; and the adaptive
modified Newton (factorisation reuse) of the SDIRK stage solves.

Contract
--------
``newton(fun, u0, ...)`` solves ``r(u) = 0``. ``fun(u)`` returns ``(r, J)``: the residual
(ndarray, n) and its exact Jacobian (scipy sparse, n x n). Optional ``admissible(u)``
returns False for states that must be rejected (e.g. det F <= 0 at a quadrature point);
the step is then halved (at most ``max_halvings`` times). With ``line_search=True`` a step
that does not reduce ``|r|`` is halved too (backtracking), which is what rescues Newton far
from the solution; near it the full step is always taken, so convergence stays quadratic.
Convergence is decided by the residual alone: ``|r| <= atol`` or ``|r| <= rtol |r_0|``.

With ``residual(u) -> r`` given, trial points (the line search, and the point that turns
out to be converged) are evaluated without the Jacobian, which is then assembled only if
another iteration needs it: for stage solves that converge in one iteration this saves
the Jacobian assembly at the converged point. ``residual`` must return the same ``r`` as
``fun``.

Returns a ``NewtonResult`` (never raises for non-convergence: the caller decides whether
to cut a step or give up). ``linear_solve(J, r) -> du`` (optional, without ``reuse``) replaces ``sparse_solve`` (the
frictional corrector keeps one PARDISO instance, whose LU analysis it reuses). Every
iteration is logged at INFO on the ``rve.newton`` logger
as ``it, |r|, |du|, rate`` where ``rate = log(r_k/r_k-1) / log(r_k-1/r_k-2)`` tends to 2
for quadratic convergence. Without ``reuse`` the linear solves are
``rve.solvers.linear.sparse_solve`` (one factorisation per iteration, docs/engine.md).

Modified Newton (``reuse=JacobianReuse(...)``, docs/time_integration.md "Factorisation
reuse (modified Newton)"): the ``JacobianReuse`` object holds one factorisation
(``StageFactorisation``: a kept banded LU for narrow bands, else a
``rve.solvers.linear.get_backend(...)`` instance) across ``newton`` calls. An iteration
with a held factorisation ``J̃`` is ``u+ = u - J̃⁻¹ r(u)`` (full step, residual only) and
is accepted iff ``u+`` is admissible and its contraction ``θ = |r(u+)| / |r(u)| < 1``;
otherwise it is discarded and the iteration is redone at ``u`` as a Newton step with a
fresh Jacobian and the line search (counted as ``rejected_reuses``). After any accepted
iteration the factorisation is dropped (the next iteration assembles and factorises a
fresh Jacobian) when ``θ > reuse.contraction``, or when at the observed rate the tolerance
would not be reached within ``max_iter`` iterations, or (``reuse.cost_aware``) when the
measured cost of the remaining modified iterations exceeds that of a fresh factorisation
(also checked at a solve's start, predicted from the latest modified contraction).
The residual tolerance decides convergence exactly as without reuse; ``max_iter`` bounds
the fresh-Jacobian (Newton) iterations and, separately, the modified ones, so reuse never
makes a stage fail the iteration limit that Newton alone would meet. The result counts
Jacobian evaluations, factorisations, reused iterations and the contractions; iterations
log ``θ`` and whether the factorisation was fresh (``J``) or reused (``J~``).
"""
from __future__ import annotations

import logging
import math
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack

from .linear import band_of, get_backend, is_symmetric, sparse_solve

__all__ = ["NewtonResult", "newton", "convergence_rates", "JacobianReuse", "StageFactorisation"]

log = logging.getLogger("rve.newton")


@dataclass
class NewtonResult:
    u: np.ndarray
    converged: bool
    iterations: int
    residuals: list = field(default_factory=list)
    reason: str = ""
    jacobians: int = 0             # evaluations of ``fun`` (residual + Jacobian)
    factorizations: int = 0        # numeric factorisations (without reuse: one per linear solve)
    linear_solves: int = 0         # solves with a factorisation (incl. discarded modified steps)
    reuses: int = 0                # accepted iterations done with a factorisation from an earlier point
    rejected_reuses: int = 0       # modified steps discarded (not contracting / inadmissible)
    contractions: list = field(default_factory=list)   # |r_k| / |r_k-1| per accepted iteration

    @property
    def rates(self) -> list:
        return convergence_rates(self.residuals)


def convergence_rates(res) -> list:
    """Observed orders q_k = log(r_k/r_{k-1}) / log(r_{k-1}/r_{k-2})."""
    r = np.asarray(res, float)
    out = []
    for k in range(2, len(r)):
        a, b = r[k - 1] / r[k - 2], r[k] / r[k - 1]
        if 0 < a < 1 and b > 0 and r[k] > 0:
            out.append(float(np.log(b) / np.log(a)))
        else:
            out.append(float("nan"))
    return out


# ----------------------------------------------------------------------------- kept factorisation
class StageFactorisation:
    """One factorisation of a stage Jacobian kept for repeated solves.

    Narrowly banded matrices (``rve.solvers.linear.band_of``: single fibrils) keep LAPACK's
    banded LU (``dgbtrf`` once, ``dgbtrs`` per solve; ``BandedBackend`` refactorises in every
    solve, which would make reuse pointless); others use ``backend`` (a
    ``rve.solvers.linear.get_backend`` instance, kept by the caller so that a backend that
    analyses a sparsity pattern reuses its analysis), with SuperLU's COLAMD + partial
    pivoting as the fallback when the backend meets a zero pivot. An unsymmetric matrix
    (``rve.solvers.linear.is_symmetric``) handed to a symmetric ``"pardiso"`` instance
    (LDLᵀ of one triangle) goes to the instance's mtype-11 companion
    (``PardisoFactorization.unsymmetric()``: LU, its analysis reused across stages; kind
    ``"pardiso_unsym"``), to SuperLU COLAMD if that fails. Raises ``RuntimeError``
    when even the fallback fails."""

    def __init__(self, J, backend):
        J = sp.csc_matrix(J)
        J.sum_duplicates()
        self.n = J.shape[0]
        self.kind = None
        band = band_of(J)
        if band is not None:
            lo, up, ab = band
            ab2 = np.zeros((2 * lo + up + 1, self.n))
            ab2[lo:] = ab
            lu, piv, info = lapack.dgbtrf(ab2, lo, up)
            if info == 0:
                self.kind, self._band = "banded", (lo, up, lu, piv)
                return
        if getattr(backend, "name", "") == "pardiso" and getattr(backend, "symmetric", True) and not is_symmetric(J):
            # a symmetric PARDISO instance is an LDL^T of the upper triangle: an unsymmetric
            # stage matrix (Lorentz / back-EMF couplings) goes to its mtype-11 companion (LU,
            # kept by the instance, so its analysis is reused), SuperLU if that fails
            companion = getattr(backend, "unsymmetric", None)
            if companion is not None:
                try:
                    self._backend = companion().factorize(J)
                    self._owner = backend  # the companion lives (is released) with its owner
                    self.kind = "pardiso_unsym"
                    return
                except RuntimeError:  # PardisoError, SingularFactorError (non-finite entry)
                    pass
            self._backend = get_backend("superlu", symmetric=False).factorize(J)
            self.kind = "superlu-colamd"
            return
        try:
            self._backend = backend.factorize(J)
            self.kind = getattr(backend, "name", "backend")
        except RuntimeError:
            self._backend = get_backend("superlu", symmetric=False).factorize(J)
            self.kind = "superlu-colamd"

    def solve(self, r) -> np.ndarray:
        r = np.asarray(r, float)
        if self.kind == "banded":
            lo, up, lu, piv = self._band
            x, info = lapack.dgbtrs(lu, lo, up, r, piv)
            return x if info == 0 else np.full_like(r, np.nan)
        return np.asarray(self._backend.solve(r), float)


class JacobianReuse:
    """The state of the adaptive modified Newton kept across ``newton`` calls (stages, steps).

    ``contraction``: largest accepted contraction ``|r_k+1| / |r_k|`` for which the
    factorisation is kept (default 0.5). ``cost_aware``: also drop it when the measured
    cost of the modified iterations still needed at the observed rate exceeds that of a
    fresh Jacobian + factorisation (running means of the wall times measured here).
    ``backend``: name for ``rve.solvers.linear.get_backend`` (None: its default) or a
    factory ``() -> backend`` (a backend with constructor arguments, e.g. a Schur border).

    The owner (``rve.solvers.dirk.DirkStepper``) ``invalidate(reason)``s the factorisation
    when the stage matrix changes for a reason the contraction cannot see first (h·a_ii,
    the constraint set, the sparsity pattern, a failed stage); ``key`` is the owner's
    record of what the factorisation was made for. Counts over the whole run:
    ``jacobians``, ``factorizations``, ``reuses``, ``rejected_reuses``, ``linear_solves``,
    ``refactor_reasons`` (Counter of why a factorisation was dropped)."""

    def __init__(self, contraction: float = 0.5, cost_aware: bool = False, backend: Optional[str] = None):
        if not 0.0 < float(contraction) < 1.0:
            raise ValueError(f"reuse contraction threshold must lie in (0, 1), not {contraction}")
        self.contraction = float(contraction)
        self.cost_aware = bool(cost_aware)
        self.backend_name = backend
        self._backend = None
        self.factor: Optional[StageFactorisation] = None
        self.key = None
        self.refactor_reasons: Counter = Counter()
        self.last_theta: Optional[float] = None   # contraction of the latest modified iteration
        self.jacobians = self.factorizations = self.reuses = self.rejected_reuses = self.linear_solves = 0
        # running mean wall times (s): Jacobian part of fun, factorisation, residual, solve
        self.cost = {"jacobian": None, "factorize": None, "residual": None, "solve": None}

    @property
    def usable(self) -> bool:
        return self.factor is not None

    def invalidate(self, reason: str) -> None:
        """Drop the factorisation (counted under ``reason`` if there was one)."""
        if self.factor is not None:
            self.refactor_reasons[reason] += 1
            log.debug("modified Newton: factorisation dropped (%s)", reason)
        self.factor = None

    def release(self) -> None:
        """Free the held factorisation and the backend's memory (a PARDISO instance's MKL
        arrays) for good: the owner is done with this object (a restart that does not carry
        it), but its counts stay readable. Not counted as a refactor."""
        self.factor = None
        backend, self._backend = self._backend, None
        if backend is not None and hasattr(backend, "release"):
            backend.release()

    def _time(self, what: str, dt: float) -> None:
        old = self.cost[what]
        self.cost[what] = dt if old is None else 0.7 * old + 0.3 * dt

    def factorize(self, J) -> None:
        if self._backend is None:
            name = self.backend_name
            self._backend = name() if callable(name) else get_backend(name)
        t0 = time.perf_counter()
        self.factor = None
        self.factor = StageFactorisation(J, self._backend)
        self._time("factorize", time.perf_counter() - t0)
        self.factorizations += 1

    def solve(self, r) -> np.ndarray:
        t0 = time.perf_counter()
        du = self.factor.solve(r)
        self._time("solve", time.perf_counter() - t0)
        self.linear_solves += 1
        return du

    def _costs(self):
        """(one modified iteration, one fresh Jacobian + factorisation) in s, or None."""
        if not self.cost_aware or None in self.cost.values():
            return None
        return self.cost["residual"] + self.cost["solve"], self.cost["jacobian"] + self.cost["factorize"]

    def worth_starting(self, rn: float, target: float) -> bool:
        """``cost_aware``: at a solve's start with ``|r| = rn``, is the held factorisation
        predicted (at the latest modified contraction) to be cheaper than a fresh one?"""
        costs = self._costs()
        if costs is None or self.last_theta is None or rn <= target or not 0.0 < self.last_theta < 1.0:
            return True
        needed = math.ceil(math.log(target / rn) / math.log(self.last_theta))
        return (needed - 1) * costs[0] <= costs[1]

    def drop_reason(self, theta: float, rn: float, target: float, iterations_left: int) -> Optional[str]:
        """After an accepted iteration with contraction ``theta`` ending at ``|r| = rn``:
        why the factorisation should not serve the next iteration (None: keep it)."""
        if not theta <= self.contraction:
            return "contraction"
        if rn <= target:
            return None
        needed = math.ceil(math.log(target / rn) / math.log(max(theta, 1e-300)))
        if needed > iterations_left:
            return "slow"
        costs = self._costs()
        # a fresh factorisation converges (quadratically) in about one iteration
        if costs is not None and (needed - 1) * costs[0] > costs[1]:
            return "cost"
        return None


# ----------------------------------------------------------------------------- Newton
def newton(
    fun,
    u0,
    *,
    atol: float = 1e-10,
    rtol: float = 1e-12,
    max_iter: int = 30,
    admissible=None,
    line_search: bool = True,
    max_halvings: int = 12,
    label: str = "newton",
    divergence_factor: float = 1e8,
    residual=None,
    reuse: Optional[JacobianReuse] = None,
    linear_solve=None,
) -> NewtonResult:
    if reuse is not None:
        return _modified_newton(fun, u0, atol=atol, rtol=rtol, max_iter=max_iter, admissible=admissible,
                                line_search=line_search, max_halvings=max_halvings, label=label,
                                divergence_factor=divergence_factor, residual=residual, reuse=reuse)
    u = np.array(u0, dtype=float, copy=True)
    r, J = fun(u)
    nj, nf = 1, 0
    rn = float(np.linalg.norm(r))
    res = [rn]
    r0 = max(rn, 1e-300)
    log.info("%s it=0 |r|=%.3e", label, rn)

    def result(converged, iterations, reason=""):
        return NewtonResult(u, converged, iterations, res, reason, jacobians=nj, factorizations=nf,
                            linear_solves=nf)

    def evaluate(v):  # (r, J) of a trial point; the residual alone when there is a function for it
        nonlocal nj
        if residual is not None:
            return residual(v), None
        nj += 1
        return fun(v)

    if not np.isfinite(rn):
        return result(False, 0, "non-finite residual at the initial state")
    for it in range(1, max_iter + 1):
        if rn <= atol or rn <= rtol * r0:
            return result(True, it - 1)
        if J is None:  # accepted from a residual-only evaluation: the Jacobian is needed now
            r, J = fun(u)
            nj += 1
        nf += 1
        try:
            du = -(sparse_solve if linear_solve is None else linear_solve)(J, r)
        except RuntimeError as exc:  # singular factor
            return result(False, it - 1, f"linear solve failed: {exc}")
        if not np.all(np.isfinite(du)):
            return result(False, it - 1, "non-finite Newton update (singular Jacobian?)")
        found = _line_search(u, du, rn, evaluate, admissible, line_search, max_halvings)
        if found is None:
            return result(False, it - 1, "no admissible step (det F <= 0 for every trial)")
        u, r, J, rn, step = found
        res.append(rn)
        rates = convergence_rates(res)
        log.info(
            "%s it=%d |r|=%.3e |du|=%.3e step=%.3g rate=%s",
            label, it, rn, step * float(np.linalg.norm(du)), step,
            f"{rates[-1]:.2f}" if rates else "-",
        )
        if not np.isfinite(rn) or rn > divergence_factor * r0:
            return result(False, it, f"diverged (|r| = {rn:.3e})")
    converged = rn <= atol or rn <= rtol * r0
    return result(converged, max_iter, "" if converged else f"no convergence in {max_iter} iterations (|r| = {rn:.3e})")


class _Timed:
    """The Newton functions with the wall times the cost rule of ``JacobianReuse`` weighs:
    ``fun`` (r, J; counted as a Jacobian), ``residual`` (r alone) and ``evaluate`` (the
    residual alone when there is a residual-only function, else ``fun``)."""

    def __init__(self, fun, residual, reuse, counts):
        self._fun, self._residual, self.reuse, self.counts = fun, residual, reuse, counts

    def fun(self, v):
        t0 = time.perf_counter()
        out = self._fun(v)
        dt = time.perf_counter() - t0
        self.counts["jacobians"] += 1
        self.reuse.jacobians += 1
        if self.reuse.cost["residual"] is not None:
            self.reuse._time("jacobian", max(dt - self.reuse.cost["residual"], 0.0))
        return out

    def residual(self, v):
        t0 = time.perf_counter()
        out = self._residual(v)
        self.reuse._time("residual", time.perf_counter() - t0)
        return out

    def evaluate(self, v):
        return (self.residual(v), None) if self._residual is not None else self.fun(v)


def _reject(reuse, counts, why: str) -> None:
    """A modified step discarded: drop the factorisation and count it."""
    reuse.invalidate(why)
    counts["rejected"] += 1
    reuse.rejected_reuses += 1


def _line_search(u, du, rn, evaluate, admissible, line_search: bool, max_halvings: int):
    """Backtracking from the full Newton step: ``(trial, r, J, |r|, step)``, or None when no
    admissible trial was found (det F <= 0 for every one)."""
    step = 1.0
    for _ in range(max_halvings + 1):
        trial = u + step * du
        if admissible is not None and not admissible(trial):
            step *= 0.5
            continue
        rt, Jt = evaluate(trial)
        rtn = float(np.linalg.norm(rt))
        if not line_search or (np.isfinite(rtn) and rtn < rn) or step < 2.0 ** -max_halvings:
            break
        step *= 0.5
    else:
        return None
    if admissible is not None and not admissible(trial):
        return None
    return trial, rt, Jt, rtn, step


def _modified_newton(fun, u0, *, atol, rtol, max_iter, admissible, line_search, max_halvings, label,
                     divergence_factor, residual, reuse: JacobianReuse) -> NewtonResult:
    """``newton`` with the factorisation held by ``reuse`` (module docstring)."""
    st = Counter()                     # this call's counts
    thetas: list = []
    timed = _Timed(fun, residual, reuse, st)
    timed_fun, evaluate = timed.fun, timed.evaluate
    u = np.array(u0, dtype=float, copy=True)
    r, J = evaluate(u) if reuse.usable else timed_fun(u)
    rn = float(np.linalg.norm(r))
    res = [rn]
    r0 = max(rn, 1e-300)
    target = max(atol, rtol * r0)
    log.info("%s it=0 |r|=%.3e (modified Newton, factorisation %s)", label, rn, "held" if reuse.usable else "none")

    def result(converged, iterations, reason=""):
        return NewtonResult(u, converged, iterations, res, reason, jacobians=st["jacobians"],
                            factorizations=st["factorizations"], linear_solves=st["solves"], reuses=st["reuses"],
                            rejected_reuses=st["rejected"], contractions=thetas)

    if not np.isfinite(rn):
        return result(False, 0, "non-finite residual at the initial state")
    if reuse.usable and not reuse.worth_starting(rn, target):
        reuse.invalidate("cost")
    it = 0
    n_fresh = n_modified = 0           # each kind is limited to max_iter iterations
    while n_fresh < max_iter and n_modified < max_iter:
        if rn <= atol or rn <= rtol * r0:
            return result(True, it)
        fresh = not reuse.usable
        if fresh:
            if J is None:
                r, J = timed_fun(u)
            try:
                reuse.factorize(J)
            except RuntimeError as exc:
                return result(False, it, f"linear solve failed: {exc}")
            st["factorizations"] += 1
        du = -reuse.solve(r)
        st["solves"] += 1
        if not np.all(np.isfinite(du)):
            if fresh:
                reuse.invalidate("singular")
                return result(False, it, "non-finite Newton update (singular Jacobian?)")
            _reject(reuse, st, "non-finite update")
            continue
        step = 1.0
        if fresh:  # a Newton step: backtracking line search as in ``newton``
            found = _line_search(u, du, rn, evaluate, admissible, line_search, max_halvings)
            if found is None:
                return result(False, it, "no admissible step (det F <= 0 for every trial)")
            trial, rt, Jt, rtn, step = found
        else:  # a modified step: full step, accepted only if it contracts
            trial = u + du
            if admissible is not None and not admissible(trial):
                rt, Jt, rtn = None, None, math.inf
            else:
                rt, Jt = evaluate(trial)
                rtn = float(np.linalg.norm(rt))
            if not (np.isfinite(rtn) and rtn < rn):
                _reject(reuse, st, "diverged")
                log.info("%s modified step rejected (|r| %.3e -> %.3e): fresh Jacobian", label, rn, rtn)
                continue
            st["reuses"] += 1
            reuse.reuses += 1
            reuse.last_theta = rtn / max(rn, 1e-300)
        it += 1
        n_fresh, n_modified = (n_fresh + 1, n_modified) if fresh else (n_fresh, n_modified + 1)
        theta = rtn / max(rn, 1e-300)
        thetas.append(theta)
        u, r, J, rn = trial, rt, Jt, rtn
        res.append(rn)
        log.info("%s it=%d |r|=%.3e |du|=%.3e step=%.3g theta=%.2e %s", label, it, rn,
                 step * float(np.linalg.norm(du)), step, theta, "J" if fresh else "J~")
        if not np.isfinite(rn) or rn > divergence_factor * r0:
            reuse.invalidate("diverged")
            return result(False, it, f"diverged (|r| = {rn:.3e})")
        why = reuse.drop_reason(theta, rn, target, max_iter - n_modified)
        if why is not None:
            reuse.invalidate(why)
    converged = rn <= atol or rn <= rtol * r0
    return result(converged, it, "" if converged else
                  f"no convergence in {n_fresh} Newton + {n_modified} modified iterations (|r| = {rn:.3e})")
