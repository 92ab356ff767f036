"""Newton's method for sparse nonlinear systems, with logged residuals.

Contract
--------
``newton(fun, u0, ...)`` solves ``r(u) = 0``. ``fun(u)`` returns ``(r, J)``: the residual
(ndarray, n) and its exact Jacobian (scipy sparse, n x n). Optional ``admissible(u)``
returns False for states that must be rejected (e.g. det F <= 0 at a quadrature point);
the step is then halved (at most ``max_halvings`` times). With ``line_search=True`` a step
that does not reduce ``|r|`` is halved too (backtracking), which is what rescues Newton far
from the solution; near it the full step is always taken, so convergence stays quadratic.

With ``residual(u) -> r`` given, trial points (the line search, and the point that turns
out to be converged) are evaluated without the Jacobian, which is then assembled only if
another iteration needs it: for stage solves that converge in one iteration this saves
the Jacobian assembly at the converged point. ``residual`` must return the same ``r`` as
``fun``.

Returns a ``NewtonResult`` (never raises for non-convergence: the caller decides whether
to cut a step or give up). Every iteration is logged at INFO on the ``rve.newton`` logger
as ``it, |r|, |du|, rate`` where ``rate = log(r_k/r_k-1) / log(r_k-1/r_k-2)`` tends to 2
for quadratic convergence. The linear solves are ``rve.solvers.linear.sparse_solve``
(docs/engine.md).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from .linear import sparse_solve

__all__ = ["NewtonResult", "newton", "convergence_rates"]

log = logging.getLogger("rve.newton")


@dataclass
class NewtonResult:
    u: np.ndarray
    converged: bool
    iterations: int
    residuals: list = field(default_factory=list)
    reason: str = ""

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
) -> NewtonResult:
    u = np.array(u0, dtype=float, copy=True)
    r, J = fun(u)
    rn = float(np.linalg.norm(r))
    res = [rn]
    r0 = max(rn, 1e-300)
    log.info("%s it=0 |r|=%.3e", label, rn)
    if not np.isfinite(rn):
        return NewtonResult(u, False, 0, res, "non-finite residual at the initial state")
    for it in range(1, max_iter + 1):
        if rn <= atol or rn <= rtol * r0:
            return NewtonResult(u, True, it - 1, res)
        if J is None:  # accepted from a residual-only evaluation: the Jacobian is needed now
            r, J = fun(u)
        try:
            du = -sparse_solve(J, r)
        except RuntimeError as exc:  # singular factor
            return NewtonResult(u, False, it - 1, res, f"linear solve failed: {exc}")
        if not np.all(np.isfinite(du)):
            return NewtonResult(u, False, it - 1, res, "non-finite Newton update (singular Jacobian?)")
        step = 1.0
        for _ in range(max_halvings + 1):
            trial = u + step * du
            if admissible is not None and not admissible(trial):
                step *= 0.5
                continue
            if residual is not None:
                rt, Jt = residual(trial), None
            else:
                rt, Jt = fun(trial)
            rtn = float(np.linalg.norm(rt))
            if not line_search or (np.isfinite(rtn) and rtn < rn) or step < 2.0 ** -max_halvings:
                break
            step *= 0.5
        else:
            return NewtonResult(u, False, it - 1, res, "no admissible step (det F <= 0 for every trial)")
        if admissible is not None and not admissible(trial):
            return NewtonResult(u, False, it - 1, res, "no admissible step (det F <= 0 for every trial)")
        u, r, J, rn = trial, rt, Jt, rtn
        res.append(rn)
        rates = convergence_rates(res)
        log.info(
            "%s it=%d |r|=%.3e |du|=%.3e step=%.3g rate=%s",
            label, it, rn, step * float(np.linalg.norm(du)), step,
            f"{rates[-1]:.2f}" if rates else "-",
        )
        if not np.isfinite(rn) or rn > divergence_factor * r0:
            return NewtonResult(u, False, it, res, f"diverged (|r| = {rn:.3e})")
    converged = rn <= atol or rn <= rtol * r0
    return NewtonResult(u, converged, max_iter, res, "" if converged else f"no convergence in {max_iter} iterations (|r| = {rn:.3e})")
