"""Static equilibrium of a ``DynamicSystem``: ``F(x, w*, t) = 0`` with zero velocities.

Thesis §6.3: after dynamic relaxation the velocities are zeroed and a static Newton solve
finalises the equilibrium. See ``docs/time_integration.md``.

Unknowns (one index space, the free dofs of the system's layout):

* at free mechanical dofs: the positions ``x`` (the velocity ``w`` there is set to 0);
* at free non-mechanical dofs (T, V): the values ``w``.

Constrained mechanical dofs keep their current ``x`` (move them before calling to impose a
displacement); constrained T/V dofs take their prescribed values ``constraints(t)``.
The Jacobian is ``dF/dx`` on the mechanical columns and ``dF/dw`` on the others.

Two paths to equilibrium:

Linear solves: ``rve.solvers.linear.sparse_solve`` (PARDISO when available, SuperLU
otherwise; docs/engine.md); ``pseudo_transient_solve`` keeps one backend instance per run.

* ``static_solve`` -- Newton (with the backtracking line search and det F guard of
  ``rve.solvers.newton``); quadratic near the solution.
* ``pseudo_transient_solve`` -- pseudo-transient continuation
  ``(K + σ_k M) Δu = −F(u_k)``, with σ_k set by switched evolution relaxation
  ``σ_k = σ_0 · β_k · |F_k| / |F_0|``: a heavily regularised (damped, gradient-like) step
  far from equilibrium, turning into Newton (σ → 0) as the residual falls. A step that
  gives a non-finite residual, an inadmissible state or a residual growth above
  ``reject_factor`` is rejected and retried with β multiplied by ``sigma_boost``; β relaxes
  back toward 1 after accepted steps.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np
import scipy.sparse as sp

from .backends.registry import run_backend
from .linear import shifted, sparse_solve
from .newton import NewtonResult, convergence_rates, newton
from .system import FreeDofs, mech_mask

__all__ = ["static_solve", "pseudo_transient_solve", "StaticProblem"]

log = logging.getLogger("rve.static")


class StaticProblem:
    """The static residual of a system at time ``t`` as a function of the free unknowns."""

    def __init__(self, system, x, w, t: float, fmt: str = "csc"):
        self.system = system
        self.fmt = fmt  # of the restricted Jacobian (``FreeDofs.matrix``)
        self.t = float(t)
        self.n = int(system.n)
        self.mech = mech_mask(system)
        idx, vals = system.constraints(self.t)
        idx = np.asarray(idx, dtype=np.int64)
        self.x = np.array(x, dtype=float, copy=True)
        self.w = np.array(w, dtype=float, copy=True)
        self.w[self.mech] = 0.0
        self.x[~self.mech] = 0.0
        nonmech_idx = idx[~self.mech[idx]]
        self.w[nonmech_idx] = np.asarray(vals, float)[~self.mech[idx]]
        self.fd = FreeDofs(self.n, idx)
        self._mechf = self.mech.astype(float)
        self.free = self.fd.free
        self.free_mech = self.mech[self.free]

    def u0(self) -> np.ndarray:
        return np.where(self.free_mech, self.x[self.free], self.w[self.free])

    def state(self, u):
        x = self.x.copy()
        w = self.w.copy()
        fm = self.free_mech
        x[self.free[fm]] = u[fm]
        w[self.free[~fm]] = u[~fm]
        return x, w

    def __call__(self, u):
        x, w = self.state(u)
        F, Fx, Fw = self.system.evaluate(x, w, self.t, jacobian=True)
        fd = self.fd
        J = fd.combine([(Fx, 1.0, self._mechf), (Fw, 1.0, 1.0 - self._mechf)], fmt=self.fmt)
        return np.asarray(F, float)[self.free], J

    def admissible(self, u) -> bool:
        return bool(self.system.admissible(self.state(u)[0]))


def static_solve(system, x, w, t: float, newton_opts: Optional[dict] = None):
    """Solve the static problem ``F(x, w*, t) = 0`` (mechanical velocities zeroed).

    Returns ``(x, w, NewtonResult)``; ``x, w`` are the full vectors at the last Newton
    iterate (check ``result.converged``). ``newton_opts`` go to ``rve.solvers.newton``.
    """
    prob = StaticProblem(system, x, w, t)
    opts = dict(newton_opts or {})
    opts.setdefault("label", f"static t={prob.t:.6g}")
    res = newton(prob, prob.u0(), admissible=prob.admissible, **opts)
    xs, ws = prob.state(res.u)
    return xs, ws, res


def pseudo_transient_solve(
    system,
    x,
    w,
    t: float,
    *,
    sigma0: Optional[float] = None,
    atol: float = 1e-10,
    rtol: float = 1e-12,
    max_iter: int = 500,
    reject_factor: float = 10.0,
    sigma_boost: float = 10.0,
    max_rejections: int = 30,
    label: Optional[str] = None,
    backend=None,
):
    """Pseudo-transient continuation to the static equilibrium ``F(x, w*, t) = 0``.

    Iterates ``(K + σ_k M_ff) Δu = −F_k`` on the free unknowns (K the static Jacobian of
    ``static_solve``, M the system's mass matrix restricted to the free dofs, zero on
    massless rows) with ``σ_k = σ_0 β_k |F_k|/|F_0|`` (switched evolution relaxation).
    Default ``σ_0 = max|diag K| / max|diag M|`` (the stiffest mode critically regularised);
    with no mass on any unknown, M is replaced by the identity.
    Convergence when ``|F| <= atol`` or ``|F| <= rtol |F_0|``.

    ``backend``: the linear solver (``rve.solvers.linear``; one instance kept for the run,
    so PARDISO's analysis is reused while the pattern is unchanged).

    Returns ``(x, w, NewtonResult)`` (``iterations`` counts accepted steps, each one linear
    solve; rejected trials are logged).
    """
    with run_backend(backend) as solver:
        return _pseudo_transient(system, x, w, t, sigma0, atol, rtol, max_iter, reject_factor, sigma_boost,
                                 max_rejections, label, solver)


def _pseudo_transient(system, x, w, t, sigma0, atol, rtol, max_iter, reject_factor, sigma_boost, max_rejections,
                      label, solver):
    prob = StaticProblem(system, x, w, t)
    label = label or f"pseudo-transient t={prob.t:.6g}"
    Mff = prob.fd.matrix(sp.csr_matrix(system.mass()))
    u = prob.u0()
    r, K = prob(u)
    rn = float(np.linalg.norm(r))
    r0 = max(rn, 1e-300)
    res = [rn]
    if not np.isfinite(rn):
        return (*prob.state(u), NewtonResult(u, False, 0, res, "non-finite residual at the initial state"))
    dM = np.abs(Mff.diagonal())
    if not (dM.size and dM.max() > 0):  # no mass on the unknowns: regularise with the identity
        Mff = sp.identity(u.size, format="csc")
        dM = np.ones(u.size)
    if sigma0 is None:
        dK = np.abs(K.diagonal())
        sigma0 = float(dK.max() / dM.max()) if dK.size and dK.max() > 0 else 1.0
    beta = 1.0
    rejections = 0
    log.info("%s it=0 |F|=%.3e sigma0=%.3e", label, rn, sigma0)
    for it in range(1, max_iter + 1):
        if rn <= atol or rn <= rtol * r0:
            return (*prob.state(u), NewtonResult(u, True, it - 1, res))
        sigma = sigma0 * beta * rn / r0
        while True:
            A = shifted(K, Mff, sigma) if sigma > 0 else K
            try:
                du = -sparse_solve(A, r, backend=solver)
            except RuntimeError:
                du = np.full_like(u, np.nan)
            trial = u + du
            ok = np.all(np.isfinite(du)) and prob.admissible(trial)
            if ok:
                rt, Kt = prob(trial)
                rtn = float(np.linalg.norm(rt))
                ok = np.isfinite(rtn) and rtn <= reject_factor * rn
            if ok:
                break
            rejections += 1
            if rejections > max_rejections:
                return (*prob.state(u), NewtonResult(
                    u, False, it - 1, res, f"pseudo-transient: {rejections} rejected steps (sigma = {sigma:.3e})"))
            beta *= sigma_boost
            sigma = max(sigma * sigma_boost, sigma0 * beta * rn / r0, 1e-300)
            log.info("%s it=%d step rejected, sigma -> %.3e", label, it, sigma)
        u, r, K, rn = trial, rt, Kt, rtn
        res.append(rn)
        beta = max(1.0, beta / sigma_boost ** 0.5)
        rates = convergence_rates(res)
        log.info("%s it=%d |F|=%.3e sigma=%.3e rate=%s", label, it, rn, sigma,
                 f"{rates[-1]:.2f}" if rates else "-")
    converged = rn <= atol or rn <= rtol * r0
    return (*prob.state(u), NewtonResult(
        u, converged, max_iter, res,
        "" if converged else f"pseudo-transient: no convergence in {max_iter} steps (|F| = {rn:.3e})"))
