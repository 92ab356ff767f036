"""L-stable SDIRK time integration of ``M dw/dt + F(x, w, t) = 0``, ``dx/dt = w`` (mech).

Thesis §6.2 and Appendix C; see ``docs/time_integration.md``.

* ``sdirk(s)`` -- the Butcher tableaus of the singly diagonally implicit, stiffly accurate,
  L-stable family with s = 1 (backward Euler), 2 and 3 stages (orders 1, 2, 3). The
  3-stage last row printed in Appendix C as ``b2 b2 α`` is ``b1 b2 α``.
* ``dirk_step`` -- one step: each stage is ONE monolithic Newton solve for the stage
  value ``w_i`` on the free dofs, the positions being eliminated through
  ``x_i = x̂_i + h a_ii w_i`` (§6.2.2). Stiffly accurate => ``(x1, w1)`` is the last stage.
* ``integrate`` -- the time loop, with step cutting on failure and regrowth after success,
  landing exactly on ``t_end``; or ``fixed_step=True`` (failure raises at once).
* Error-controlled steps (``integrate(adaptive=AdaptiveControl(...))``, default off): SDIRK2 and
  SDIRK3 carry embedded weights ``b_hat`` of order s − 1 from the same stages (R̂(∞) = −1);
  ``local_error`` takes the estimate ``y1 − ŷ = Σ e_j (Y_j − y0)`` from the stage values (no
  M⁻¹) on the mechanical positions (and velocities with ``atol_w``); a PI or elementary
  controller with safety factor, growth limits and a hold band proposes the next step, a step
  with err > 1 is rejected and retried; the steps land on a grid of ``land_every`` nominal
  steps. docs/time_integration.md §4 "Error-controlled steps".
* ``consistent_initialization`` -- solves ``F = 0`` for the massless (algebraic) dofs at
  t0 so that e.g. the potential V(0) is consistent with x(0), w(0).
* Factorisation reuse (``integrate(reuse=ReusePolicy(mode=...))``, default off: one factorisation
  per Newton iteration as before, bit for bit): the stepper keeps one
  ``rve.solvers.newton.JacobianReuse`` for the run, so a factorisation serves Newton
  iterations, stages and steps while the observed contraction stays below
  ``reuse_contraction``; it is dropped when h·a_ii moves by more than ``reuse_h_rtol``
  (relative), when the constraint set or the system's structure (``structure_token``: a
  contact-map rebuild) changes, and after a failed stage; a stage whose modified Newton
  fails is solved again from the same start by full Newton before the step is cut.
  docs/time_integration.md "Factorisation reuse (modified Newton)".
"""
from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Protocol

import numpy as np
import scipy.sparse as sp

from .newton import JacobianReuse, newton
from .system import FreeDofs, massless_dofs, mech_mask

__all__ = [
    "Tableau", "sdirk", "BACKWARD_EULER", "SDIRK2", "SDIRK3", "SDIRK3_ALPHA",
    "order_conditions", "stability_function",
    "StepInfo", "StepFailure", "IntegrationFailure", "IntegrationResult",
    "dirk_step", "integrate", "consistent_initialization", "DirkStepper", "structure_token", "StructureHook",
    "StepControl", "Budgets", "ReusePolicy", "AdaptiveControl", "local_error", "integrator_options",
]

log = logging.getLogger("rve.dirk")


# ----------------------------------------------------------------------------- tableaus
@dataclass(frozen=True)
class Tableau:
    """Butcher tableau ``(A, b, c)`` of a diagonally implicit Runge-Kutta method."""

    name: str
    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    order: int
    #: embedded weights b̂ (same stages, order ``embedded_order``); None: no error estimate
    b_hat: Optional[np.ndarray] = None
    embedded_order: int = 0

    @property
    def stages(self) -> int:
        return int(self.b.size)

    @property
    def stiffly_accurate(self) -> bool:
        return bool(np.allclose(self.A[-1], self.b, rtol=0, atol=1e-15) and abs(self.c[-1] - 1) < 1e-15)

    def check(self, tol: float = 1e-14) -> None:
        """Raise ``ValueError`` unless the tableau is lower triangular with c = A·1,
        stiffly accurate, and satisfies the order conditions up to ``order``."""
        s = self.stages
        if self.A.shape != (s, s) or self.c.shape != (s,):
            raise ValueError(f"{self.name}: inconsistent shapes")
        if np.any(np.triu(self.A, 1) != 0):
            raise ValueError(f"{self.name}: A is not lower triangular")
        if not np.allclose(self.A.sum(axis=1), self.c, rtol=0, atol=tol):
            raise ValueError(f"{self.name}: c != A 1")
        if not self.stiffly_accurate:
            raise ValueError(f"{self.name}: not stiffly accurate (last row of A != b or c_s != 1)")
        bad = {k: v for k, v in order_conditions(self, self.order).items() if abs(v) > tol}
        if bad:
            raise ValueError(f"{self.name}: order conditions violated: {bad}")
        if self.b_hat is not None:
            emb = Tableau(self.name + " embedded", self.A, np.asarray(self.b_hat, float), self.c, self.embedded_order)
            bad = {k: v for k, v in order_conditions(emb, self.embedded_order).items() if abs(v) > tol}
            if bad or self.embedded_order < 1:
                raise ValueError(f"{self.name}: embedded order conditions violated: {bad}")

    @property
    def error_weights(self) -> np.ndarray:
        """``e`` with ``y1 − ŷ = Σ_j e_j (Y_j − y0)``: the embedded estimate from the stage
        VALUES. Since ``Y − y0 = h A K`` (stage slopes K), ``h b̂ᵀK = b̂ᵀA⁻¹(Y − y0)``, and
        stiffly accurate ``bᵀA⁻¹ = e_s``; so ``e = e_s − A⁻ᵀ b̂``. It applies to the positions
        and to the differential rows of ``M ẇ = −F`` alike, with no M⁻¹."""
        if self.b_hat is None:
            raise ValueError(f"{self.name} has no embedded method")
        e = np.zeros(self.stages)
        e[-1] = 1.0
        return e - np.linalg.solve(self.A.T, np.asarray(self.b_hat, float))

    def embedded_stability(self, z: complex) -> complex:
        """R̂(z) of the embedded method (y' = λy, z = hλ)."""
        k = np.linalg.solve(np.eye(self.stages) - z * self.A, np.ones(self.stages, dtype=complex))
        return complex(1 + z * (np.asarray(self.b_hat, float) @ k))


def _order_trees(A, b, c):
    """Residuals of the Runge-Kutta order conditions (rooted trees up to order 4)."""
    Ac = A @ c
    return {
        1: {"sum b = 1": b.sum() - 1.0},
        2: {"b.c = 1/2": b @ c - 1 / 2},
        3: {"b.c^2 = 1/3": b @ c**2 - 1 / 3, "b.A.c = 1/6": b @ Ac - 1 / 6},
        4: {
            "b.c^3 = 1/4": b @ c**3 - 1 / 4,
            "b.(c*A.c) = 1/8": b @ (c * Ac) - 1 / 8,
            "b.A.c^2 = 1/12": b @ (A @ c**2) - 1 / 12,
            "b.A.A.c = 1/24": b @ (A @ Ac) - 1 / 24,
        },
    }


def order_conditions(tableau: Tableau, order: int) -> dict:
    """``{condition: residual}`` for all order conditions of orders 1..``order`` (<= 4)."""
    if not 1 <= order <= 4:
        raise ValueError("order conditions are tabulated for orders 1..4")
    trees = _order_trees(tableau.A, tableau.b, tableau.c)
    out = {}
    for p in range(1, order + 1):
        out.update({f"p{p}: {k}": float(v) for k, v in trees[p].items()})
    return out


def stability_function(tableau: Tableau, z: complex) -> complex:
    """R(z) = 1 + z bᵀ (I − z A)⁻¹ 1 (y' = λy, z = hλ)."""
    s = tableau.stages
    k = np.linalg.solve(np.eye(s) - z * tableau.A, np.ones(s, dtype=complex))
    return complex(1 + z * (tableau.b @ k))


#: α of the 3-stage method: root of α³ − 3α² + 3α/2 − 1/6 = 0 in (1/6, 1/2).
SDIRK3_ALPHA = 0.43586652150845899942


def _embedded_weights(A, b, c) -> np.ndarray:
    """b̂ of order s − 1 from the same s stages with R̂(∞) = −1.

    Order s − 1 leaves one free direction v (Σv = 0, v·c = 0 for s = 3; v = (1, −1) for
    s = 2), b̂ = b + δ v. Every δ ≠ 0 gives the same estimate direction up to its scale; the
    scale is fixed by the embedded method's value at infinity, R̂(∞) = 1 − b̂ᵀA⁻¹1 = −δ vᵀA⁻¹1:
    |R̂(∞)| = 1 is the largest estimate whose embedded method stays bounded on stiff modes
    (R̂(∞) = −1 chosen of the two signs). SDIRK2: b̂ = (2√2 − 2, 3 − 2√2)."""
    s = b.size
    v = np.array([1.0, -1.0]) if s == 2 else np.array([c[1] - c[2], c[2] - c[0], c[0] - c[1]])
    delta = 1.0 / (v @ np.linalg.solve(A, np.ones(s)))
    return b + delta * v


def _make_tableaus():
    be = Tableau("backward Euler (SDIRK1)", np.array([[1.0]]), np.array([1.0]), np.array([1.0]), 1)

    g = 1.0 - math.sqrt(2.0) / 2.0
    A2 = np.array([[g, 0.0], [1.0 - g, g]])
    c2 = np.array([g, 1.0])
    s2 = Tableau("SDIRK2 (γ = 1 − √2/2)", A2, A2[-1].copy(), c2, 2, _embedded_weights(A2, A2[-1], c2), 1)

    a = SDIRK3_ALPHA
    tau = (1.0 + a) / 2.0
    b1 = -(6 * a * a - 16 * a + 1) / 4.0
    b2 = (6 * a * a - 20 * a + 5) / 4.0
    A3 = np.array([[a, 0.0, 0.0], [tau - a, a, 0.0], [b1, b2, a]])
    c3 = np.array([a, tau, 1.0])
    s3 = Tableau("SDIRK3 (α = 0.4358665215...)", A3, A3[-1].copy(), c3, 3, _embedded_weights(A3, A3[-1], c3), 2)
    for t in (be, s2, s3):
        t.check()
    return be, s2, s3


BACKWARD_EULER, SDIRK2, SDIRK3 = _make_tableaus()


def sdirk(stages: int) -> Tableau:
    """The L-stable, stiffly accurate SDIRK method with ``stages`` = 1, 2 or 3 stages."""
    try:
        return {1: BACKWARD_EULER, 2: SDIRK2, 3: SDIRK3}[int(stages)]
    except KeyError:
        raise ValueError(f"SDIRK family has 1, 2 or 3 stages, not {stages}") from None


# ----------------------------------------------------------------------------- results
@dataclass
class StepInfo:
    """What one accepted step cost."""

    t: float                     # start time of the step
    h: float                     # step size
    stage_iterations: list       # Newton iterations per stage
    stage_residuals: list        # Newton residual history per stage
    linear_solves: int = 0
    stage_jacobians: list = field(default_factory=list)       # Jacobian evaluations per stage
    stage_factorizations: list = field(default_factory=list)  # factorisations per stage
    stage_reuses: list = field(default_factory=list)          # iterations on a reused factorisation
    stage_contractions: list = field(default_factory=list)    # |r_k|/|r_k-1| per stage (reuse on)
    stage_retries: int = 0       # stages re-solved by full Newton after the modified Newton failed
    rejected_reuses: int = 0     # modified steps discarded (redone with a fresh Jacobian)
    #: the converged stage states [(x_i, w_i)], in stage order; stiffly accurate, so the
    #: last one is the step's result (a post-solve driven by the stages reads them here)
    stage_states: list = field(default_factory=list)
    rejected_attempts: int = 0   # attempts rejected (step cut) since the previous accepted step
    error: Optional[float] = None  # scaled local error estimate (error-controlled steps)

    @property
    def jacobians(self) -> int:
        return int(sum(self.stage_jacobians))

    @property
    def factorizations(self) -> int:
        return int(sum(self.stage_factorizations))

    @property
    def newton_iterations(self) -> int:
        return int(sum(self.stage_iterations))


class StepFailure(RuntimeError):
    """A stage Newton solve failed (no convergence, NaN, iteration limit, inadmissible)."""

    def __init__(self, stage: int, t: float, h: float, residuals, reason: str, newton_iterations: int = 0,
                 linear_solves: int = 0, counts: Optional[dict] = None):
        self.stage = stage
        self.t = t
        self.h = h
        self.residuals = list(residuals)
        self.reason = reason
        self.newton_iterations = newton_iterations
        self.linear_solves = linear_solves
        self.counts = dict(counts or {})   # jacobians, factorizations, reuses, ... of the attempt
        super().__init__(
            f"stage {stage} of the step from t = {t:.9g} with h = {h:.6g} failed: {reason}; "
            f"residuals {_fmt_res(self.residuals)}"
        )


class IntegrationFailure(RuntimeError):
    """The integration gave up. Carries the last good state ``(x, w, t)``."""

    def __init__(self, message: str, x, w, t, h, residuals, step_failure: Optional[StepFailure] = None,
                 result: "Optional[IntegrationResult]" = None, cause: str = "failure"):
        super().__init__(message)
        #: why the loop ended: "fixed_step", "max_cuts", "min_step", "rejections", "wall_time",
        #: "initialisation" or "failure"
        self.cause = cause
        self.x = x
        self.w = w
        self.t = t
        self.h = h
        self.residuals = list(residuals)
        self.step_failure = step_failure
        self.result = result

    @property
    def last_good_state(self):
        return self.x, self.w, self.t


@dataclass
class IntegrationResult:
    x: np.ndarray
    w: np.ndarray
    t: float
    steps: int = 0                       # accepted steps
    rejected: int = 0                    # failed (cut) attempts
    newton_iterations: int = 0           # all Newton iterations, including failed attempts
    linear_solves: int = 0               # solves with a factorisation (reuse off: one per Newton iteration)
    h_min: float = math.inf
    history: list = field(default_factory=list)   # (t_end_of_step, h, newton its) per accepted step
    jacobian_evaluations: int = 0        # residual + Jacobian evaluations (all attempts)
    factorizations: int = 0              # numeric factorisations (reuse off: = linear_solves)
    reuses: int = 0                      # Newton iterations done on a reused factorisation
    rejected_reuses: int = 0             # modified steps discarded (then redone with a fresh Jacobian)
    stage_retries: int = 0               # stages re-solved by full Newton after a failed modified Newton
    refactor_reasons: dict = field(default_factory=dict)  # why reused factorisations were dropped
    contractions: list = field(default_factory=list)      # all |r_k|/|r_k-1| of accepted steps (reuse on)
    restarts: int = 0                    # step-control restarts after a structure change (``rebuild``)
    error_rejections: int = 0            # attempts rejected by the error estimate (counted in ``rejected`` too)
    errors: list = field(default_factory=list)  # scaled error estimate per accepted step (error control)

    def add(self, counts: dict) -> None:
        """Add the counts of one step attempt (``StepInfo`` / ``StepFailure`` counts)."""
        self.newton_iterations += int(counts.get("newton_iterations", 0))
        self.linear_solves += int(counts.get("linear_solves", 0))
        self.jacobian_evaluations += int(counts.get("jacobians", 0))
        self.factorizations += int(counts.get("factorizations", 0))
        self.reuses += int(counts.get("reuses", 0))
        self.rejected_reuses += int(counts.get("rejected_reuses", 0))
        self.stage_retries += int(counts.get("stage_retries", 0))


def _fmt_res(res) -> str:
    return "[" + ", ".join(f"{r:.3e}" for r in res) + "]"


def _counts(results) -> dict:
    """Summed counts of Newton results."""
    keys = ("jacobians", "factorizations", "linear_solves", "reuses", "rejected_reuses")
    out = {k: int(sum(getattr(r, k) for r in results)) for k in keys}
    out["newton_iterations"] = int(sum(r.iterations for r in results))
    return out


def structure_token(system):
    """What identifies the structure (sparsity pattern) of a system's matrices: the
    system's ``structure_version`` if it has one, else the rebuild count of a contact
    system (``stats["rebuilds"]``: every contact-map rebuild gives the matrices a new
    structure), else None (no pattern changes known)."""
    v = getattr(system, "structure_version", None)
    if v is not None:
        return v
    stats = getattr(system, "stats", None)
    if isinstance(stats, dict) and "rebuilds" in stats:
        return stats["rebuilds"]
    return None


def _newton_kwargs(newton_opts) -> dict:
    opts = dict(newton_opts or {})
    opts.pop("label", None)
    return opts


# ----------------------------------------------------------------------------- stepping
def extrapolate(points, t: float) -> np.ndarray:
    """Lagrange extrapolation to ``t`` of the trajectory through ``points`` [(t_k, w_k)]
    (distinct times; degree len(points) - 1)."""
    ts = [p[0] for p in points]
    out = np.zeros_like(points[0][1])
    for k, (tk, wk) in enumerate(points):
        lk = 1.0
        for j, tj in enumerate(ts):
            if j != k:
                lk *= (t - tj) / (tk - tj)
        out += lk * wk
    return out


class DirkStepper:
    """Holds what is constant over a run (M, mech mask, restriction caches) for a system.

    Stage predictor: the Newton solve of stage i starts from the polynomial extrapolation
    (degree ``predictor_degree``, default 2) of the most recent stage values in time --
    those of this step and of the previous accepted step -- instead of the previous stage
    value (degree 0). For smooth solutions the start is then O(h^3) from the stage value
    rather than O(h), and most stages converge in one Newton iteration (measured in
    docs/time_integration.md). A predictor that is inadmissible (det F <= 0) falls back to
    the previous stage value. The predictor only changes where Newton starts, never the
    converged stage value beyond the Newton tolerance.

    ``lazy_jacobian``: the Newton trial points are evaluated without the Jacobian, which is
    assembled only when another iteration needs it (``newton(residual=...)``); a stage that
    converges in one iteration then costs one Jacobian assembly, not two.

    ``jacobian_reuse`` (False, True or "auto"): adaptive modified Newton with one
    ``JacobianReuse`` (``self.reuse``) for the stepper's life; "auto" adds the measured
    cost rule (``JacobianReuse(cost_aware=True)``). ``reuse_contraction`` is its
    threshold, ``reuse_h_rtol`` the relative change of h·a_ii that drops the
    factorisation, ``linear_backend`` the ``get_backend`` name (module docstring).
    ``watch_structure`` False: the system's ``structure_token`` does not drop the held
    factorisation (``integrate`` with a ``rebuild`` hook: the hook reports structure
    changes and the step control restarts on a fresh stepper).

    ``linear_stages``: the stage solves of a linear system without mechanical dofs
    (``F(w, t) = L_i w - q_i``; e.g. ``rve.model.thermal_post.KeptFactorStages``) instead of
    Newton: ``source(i, t) -> q_i``, ``solve(i, h a_ii, rhs, t) -> w_i`` of
    ``(M + h a_ii L_i) w_i = rhs`` with the constraints, ``apply(i, w, t) -> L_i w``.
    """

    def __init__(self, system, tableau: Tableau, newton_opts: Optional[dict] = None,
                 predictor_degree: int = 2, lazy_jacobian: bool = True, jacobian_reuse=False,
                 reuse_contraction: float = 0.5, reuse_h_rtol: float = 0.1, linear_backend: Optional[str] = None,
                 watch_structure: bool = True, linear_stages=None):
        self.system = system
        self.linear_stages = linear_stages
        self.watch_structure = bool(watch_structure)
        if jacobian_reuse not in (False, True, "auto"):
            raise ValueError(f"jacobian_reuse must be False, True or 'auto', not {jacobian_reuse!r}")
        self.reuse = (JacobianReuse(reuse_contraction, cost_aware=(jacobian_reuse == "auto"), backend=linear_backend)
                      if jacobian_reuse else None)
        self.reuse_h_rtol = float(reuse_h_rtol)
        self.lazy_jacobian = bool(lazy_jacobian)
        self.tableau = tableau
        if predictor_degree not in (0, 1, 2, 3):
            raise ValueError(f"predictor_degree must be 0..3, not {predictor_degree}")
        self.predictor_degree = int(predictor_degree)
        self._points: list = []   # [(t, w)] of the last accepted step, oldest first
        self.n = int(system.n)
        self.mech = mech_mask(system)
        self.mechf = self.mech.astype(float)
        self.M = sp.csr_matrix(system.mass())
        if self.M.shape != (self.n, self.n):
            raise ValueError(f"mass matrix has shape {self.M.shape}, expected ({self.n}, {self.n})")
        # the products M w of every stage residual on M's nonzeros alone: a contact system's
        # mass lies on the union pattern, whose contact-pair entries are stored zeros (most of
        # its entries in a woven fabric); dropping them leaves every product the same sum of
        # the same nonzero terms in the same order. self.M keeps the union structure, which
        # the stage matrix (FreeDofs.combine) needs.
        self.Mv = self.M.copy()
        self.Mv.eliminate_zeros()
        self.newton_opts = _newton_kwargs(newton_opts)
        self._free_cache: dict = {}

    def carry_from(self, other: "DirkStepper", factorisation: bool, predictor: bool) -> None:
        """Continue ``other``'s run after a restart at the state it ended on: its held
        factorisation (``factorisation``; the contraction test of the modified Newton judges
        it on the new structure) and its stage history for the predictor (``predictor``)."""
        if factorisation and self.reuse is not None and other.reuse is not None:
            self.reuse = other.reuse
        if predictor:
            self._points = list(other._points)

    def free_dofs(self, idx) -> FreeDofs:
        return FreeDofs.cached(self._free_cache, self.n, idx)

    def step(self, x0, w0, t0: float, h: float):
        """One step from (x0, w0, t0) of size h -> (x1, w1, StepInfo); raises StepFailure."""
        if self.linear_stages is not None:
            return self._linear_step(np.asarray(x0, float), np.asarray(w0, float), t0, h)
        sysm, tab, M, mechf = self.system, self.tableau, self.Mv, self.mechf
        x0 = np.asarray(x0, float)
        w0 = np.asarray(w0, float)
        s = tab.stages
        Mw0 = M @ w0
        W, Fs, states = [], [], []
        its, ress = [], []
        results = []
        retries = 0
        w_prev = w0
        pts = self._history_at(t0, w0, h)
        for i in range(s):
            ti = t0 + tab.c[i] * h
            haii = h * tab.A[i, i]
            # explicit part of the stage: x̂_i and the constant part of the residual
            xhat = x0.copy()
            rhs = Mw0.copy()
            for j in range(i):
                aij = h * tab.A[i, j]
                if aij != 0.0:
                    xhat += aij * mechf * W[j]
                    rhs -= aij * Fs[j]
            idx, vals = sysm.constraints(ti)
            idx = np.asarray(idx, dtype=np.int64)
            fd = self.free_dofs(idx)
            wi = self._predict(pts, ti, w_prev, xhat, haii)
            wi[idx] = vals
            state, fun, resid, adm, cache = self._stage_functions(ti, haii, xhat, rhs, fd, wi)
            label = f"dirk s{s} stage {i + 1} t={ti:.6g}"
            stage_results = self._solve_stage(fun, wi[fd.free], adm, label, resid, haii, fd.key)
            retries += len(stage_results) - 1
            res = stage_results[-1]
            results.extend(stage_results)
            its.append(int(sum(r.iterations for r in stage_results)))
            ress.append(list(res.residuals))
            xi, wsol = state(res.u)
            reason = _stage_failure(res, sysm, xi)
            if reason is not None:
                if self.reuse is not None:
                    self.reuse.invalidate("failed step")
                counts = _counts(results)
                counts["stage_retries"] = retries
                raise StepFailure(i + 1, t0, h, res.residuals, reason, int(sum(its)), counts["linear_solves"], counts)
            W.append(wsol)
            states.append((xi, wsol))
            if i < s - 1:  # the last stage's F is not needed (stiffly accurate)
                if "u" in cache and np.array_equal(cache["u"], res.u):
                    Fi = cache["F"]
                else:
                    Fi = np.asarray(sysm.evaluate(xi, wsol, ti, jacobian=False)[0], float)
                Fs.append(Fi)
            w_prev = wsol
            pts.append((ti, wsol))
        # stiffly accurate (A[s-1] = b, c_s = 1): the step result is the last stage
        self._points = pts[-(self.predictor_degree + 1):]
        counts = _counts(results)
        info = StepInfo(t0, h, its, ress, counts["linear_solves"], stage_retries=retries, stage_states=states)
        for r in results:   # per stage (a retried stage: both attempts, in order)
            info.stage_jacobians.append(r.jacobians)
            info.stage_factorizations.append(r.factorizations)
            info.stage_reuses.append(r.reuses)
            info.stage_contractions.append(list(r.contractions))
        info.rejected_reuses = counts["rejected_reuses"]
        return xi, W[-1], info

    def _linear_step(self, x0, w0, t0: float, h: float):
        """One step of a linear system without mechanical dofs, ``F(w, t) = L_i w - q_i`` at
        stage i, by ``linear_stages`` (class docstring): stage i solves
        ``(M + h a_ii L_i) w_i = M w0 + h a_ii q_i - sum_j h a_ij F_j`` (summed in that order)."""
        tab, lin = self.tableau, self.linear_stages
        rhs0 = self.Mv @ w0
        Fs, states = [], []
        s = tab.stages
        for i in range(s):
            ti = t0 + tab.c[i] * h
            haii = h * tab.A[i, i]
            q = lin.source(i, ti)
            rhs = rhs0 + haii * q
            for j in range(i):
                rhs = rhs - h * tab.A[i, j] * Fs[j]
            w = lin.solve(i, haii, rhs, ti)
            states.append((x0, w))
            if i < s - 1:  # the last stage's F is not needed (stiffly accurate)
                Fs.append(lin.apply(i, w, ti) - q)
        return x0, w, StepInfo(t0, h, [0] * s, [[] for _ in range(s)], stage_states=states)

    def _stage_functions(self, ti, haii, xhat, rhs, fd, wi):
        """``(state, fun, residual, admissible, cache)`` of one stage: the state of the free
        unknowns u, the stage residual G(u) = M w + h a_ii F(x, w) - rhs on the free dofs with
        its Jacobian J = M + h a_ii Fw + (h a_ii)^2 Fx diag(mech) restricted to them (``fun``)
        or alone (``residual``, None without ``lazy_jacobian``), and the last F in ``cache``."""
        sysm, M, mechf, free = self.system, self.Mv, self.mechf, fd.free
        cache: dict = {}

        def state(u):
            w = wi.copy()
            w[free] = u
            return xhat + haii * mechf * w, w

        def stage_residual(u, jacobian):
            x, w = state(u)
            F, Fx, Fw = sysm.evaluate(x, w, ti, jacobian=jacobian)
            F = np.asarray(F, float)
            cache["u"], cache["F"] = u.copy(), F
            G = (M @ w + haii * F - rhs)[free]
            if not jacobian:
                return G
            return G, fd.combine([(self.M, 1.0, None), (Fw, haii, None), (Fx, haii * haii, mechf)])

        def adm(u):
            return bool(sysm.admissible(state(u)[0]))

        fun = functools.partial(stage_residual, jacobian=True)
        resid = functools.partial(stage_residual, jacobian=False) if self.lazy_jacobian else None
        return state, fun, resid, adm, cache

    def _solve_stage(self, fun, start, adm, label, resid, haii, constraint_key) -> list:
        """The stage's Newton results: one, or (a failed modified Newton) the failed one and
        the full-Newton retry from the same start, the last being the stage's."""
        reuse = self.reuse
        if reuse is None:
            return [newton(fun, start, admissible=adm, label=label, residual=resid, **self.newton_opts)]
        key = self._check_reuse(haii, constraint_key)
        res = newton(fun, start, admissible=adm, label=label, residual=resid, reuse=reuse, **self.newton_opts)
        if res.factorizations:
            reuse.key = key
        stage_results = [res]
        if not res.converged and (res.reuses or res.rejected_reuses):
            # the modified Newton failed: full Newton from the same start before a cut
            reuse.invalidate("failed stage")
            log.info("%s: modified Newton failed (%s); full Newton retry", label, res.reason)
            stage_results.append(newton(fun, start, admissible=adm, label=label + " retry", residual=resid,
                                        **self.newton_opts))
        log.info("%s: its=%d jacobians=%d factorisations=%d reused=%d rejected=%d contraction=%s", label,
                 sum(r.iterations for r in stage_results), sum(r.jacobians for r in stage_results),
                 sum(r.factorizations for r in stage_results), sum(r.reuses for r in stage_results),
                 sum(r.rejected_reuses for r in stage_results),
                 "[" + ", ".join(f"{q:.1e}" for r in stage_results for q in r.contractions) + "]")
        return stage_results

    def _check_reuse(self, haii: float, constraint_key) -> tuple:
        """Drop the held factorisation if the stage matrix changed in a way the contraction
        cannot see first; returns the key of the stage about to be solved."""
        reuse = self.reuse
        key = (haii, constraint_key, structure_token(self.system) if self.watch_structure else None)
        if reuse.usable and reuse.key is not None:
            h_old, c_old, s_old = reuse.key
            if c_old != constraint_key:
                reuse.invalidate("constraints")
            elif s_old != key[2]:
                reuse.invalidate("pattern")
            elif abs(haii - h_old) > self.reuse_h_rtol * abs(h_old):
                reuse.invalidate("h")
        return key

    def _history_at(self, t0: float, w0, h: float) -> list:
        """The remembered stage values if they end at (t0, w0) (the last accepted step),
        else just [(t0, w0)]."""
        pts = self._points
        if pts and abs(pts[-1][0] - t0) <= 1e-12 * max(abs(t0), abs(h)) and np.array_equal(pts[-1][1], w0):
            return list(pts)
        return [(t0, w0)]

    def _predict(self, pts: list, ti: float, w_prev, xhat, haii: float) -> np.ndarray:
        """Newton's start for the stage at ``ti`` (a fresh array)."""
        k = min(self.predictor_degree + 1, len(pts))
        if k <= 1:
            return np.array(w_prev, dtype=float, copy=True)
        w = extrapolate(pts[-k:], ti)
        if not (np.all(np.isfinite(w)) and self.system.admissible(xhat + haii * self.mechf * w)):
            return np.array(w_prev, dtype=float, copy=True)
        return w


def _stage_failure(res, system, xi):
    """Why a stage solution is not accepted (None when it is)."""
    if not res.converged:
        return res.reason or "Newton did not converge"
    if not np.all(np.isfinite(res.u)):
        return "non-finite stage solution"
    if not system.admissible(xi):
        return "inadmissible stage state (det F <= 0)"
    return None


def dirk_step(system, tableau, x0, w0, t0: float, h: float, newton_opts: Optional[dict] = None, **options):
    """One SDIRK step of size ``h`` from ``(x0, w0)`` at ``t0``.

    ``tableau`` is a ``Tableau`` or a stage count (1, 2, 3). Returns ``(x1, w1, StepInfo)``;
    raises ``StepFailure`` if a stage Newton solve fails. ``newton_opts`` are passed to
    ``rve.solvers.newton.newton`` (atol, rtol, max_iter, line_search, max_halvings, ...),
    ``options`` to ``DirkStepper`` (predictor_degree, lazy_jacobian, jacobian_reuse, ...).
    """
    tab = tableau if isinstance(tableau, Tableau) else sdirk(tableau)
    return DirkStepper(system, tab, newton_opts, **options).step(x0, w0, t0, h)


# ----------------------------------------------------------------------------- init
def consistent_initialization(system, x0, w0, t0: float, newton_opts: Optional[dict] = None):
    """Make ``w0`` consistent at ``t0``: apply the constraints at t0 and solve ``F = 0`` for
    the free massless (algebraic) dofs with x and all other w fixed.

    Returns ``(w0_consistent, NewtonResult or None)`` (None when there is nothing to solve).
    Raises ``IntegrationFailure`` when the solve fails.
    """
    n = int(system.n)
    mech = mech_mask(system)
    x0 = np.asarray(x0, float)
    w = np.array(w0, dtype=float, copy=True)
    idx, vals = system.constraints(t0)
    idx = np.asarray(idx, dtype=np.int64)
    w[idx] = vals
    alg = massless_dofs(system.mass()) & ~mech
    alg[idx] = False
    if not alg.any():
        return w, None
    fd = FreeDofs(n, np.flatnonzero(~alg))

    def fun(u):
        ww = w.copy()
        ww[fd.free] = u
        F, _, Fw = system.evaluate(x0, ww, t0, jacobian=True)
        return np.asarray(F, float)[fd.free], fd.matrix(Fw)

    res = newton(fun, w[fd.free], label=f"dirk consistent init t={t0:.6g}", **_newton_kwargs(newton_opts))
    if not res.converged:
        raise IntegrationFailure(
            f"consistent initialisation of the massless dofs at t = {t0:.9g} failed: {res.reason}; "
            f"residuals {_fmt_res(res.residuals)}", x0, np.asarray(w0, float), t0, 0.0, res.residuals)
    w[fd.free] = res.u
    return w, res


# ----------------------------------------------------------------------------- driver
class StructureHook(Protocol):
    """What ``integrate(rebuild=...)`` calls after every accepted step before ``t_end``.

    ``hook(t, x, w) -> bool``: rebuild whatever depends on the state (a contact map) if it
    is due, and say whether the system's structure changed so that the step control must
    restart at ``t``: a fresh stepper (no held factorisation, no stage history), the
    nominal step again. The optional ``hook.horizon(t) -> (t_stop, n_steps)`` gives the
    segment that the restarted step control runs on (grid ``t + k (t_stop - t)/n_steps``,
    landing on ``t_stop``); without it a segment runs to ``t_end`` on
    ``max(1, ceil((t_end - t)/h0 - 1e-6))`` steps of about the run's nominal step h0.
    The optional attribute ``hook.fresh``, read after a call that returned True: the
    restarted segment carries nothing over (``reuse_across_restarts``,
    ``predictor_across_restarts``), as a run resumed from a checkpoint there would start.
    """

    def __call__(self, t: float, x: np.ndarray, w: np.ndarray) -> bool: ...


def _horizon(rebuild, t: float, t_end: float, h0: float) -> tuple:
    if rebuild is not None and hasattr(rebuild, "horizon"):
        t_stop, n = rebuild.horizon(t)
        return float(t_stop), int(n)
    return float(t_end), max(1, int(math.ceil((t_end - t) / h0 - 1e-6)))


@dataclass(frozen=True)
class StepControl:
    """How ``integrate`` steps (its docstring): ``fixed_step`` (every step h0, the first
    failure ends the run) or halve-and-retry, at most ``max_cuts`` consecutive cuts, the
    step doubled again after ``grow_after`` successes, never below
    ``max(min_step_rel h0, min_step_t_rel |t|)``."""

    fixed_step: bool = False
    max_cuts: int = 8
    grow_after: int = 2
    min_step_rel: float = 1e-6
    min_step_t_rel: float = 1e-12


@dataclass(frozen=True)
class Budgets:
    """What ends a run that still makes progress: ``max_rejections`` rejected attempts in a
    segment (None: ``max(64, 2 n)`` for a segment of n nominal steps) and the wall time
    ``wall_budget_s`` (None: off, so results depend on the input only)."""

    max_rejections: Optional[int] = None
    wall_budget_s: Optional[float] = None


@dataclass(frozen=True)
class AdaptiveControl:
    """Error-controlled steps (``integrate(adaptive=...)``; docs/time_integration.md §4).

    The local error of a step is estimated from its stage values by the tableau's embedded
    method (``Tableau.error_weights``: ``y1 − ŷ``, order p̂ = ``embedded_order``) on the
    positions of the mechanical dofs and, with ``atol_w`` set, on their velocities (the
    massless rows are algebraic: they follow the state and carry no error of their own);
    ``err = max_i |e_i| / (atol + rtol max(|y0_i|, |y1_i|))`` (``atol`` for positions,
    ``atol_w`` for velocities). A step with ``err > 1`` is rejected and retried from the same
    state. The next step is ``h · clip(safety · err^(−β1) · err_prev^(β2), min_factor,
    max_factor)`` (``controller`` "pi": Gustafsson's β1 = 0.7/k, β2 = 0.4/k; "elementary":
    β1 = 1/k, β2 = 0; k = p̂ + 1), no growth after a rejection, and h kept when the factor is in
    [1, ``hold_band``] (a held factorisation of the modified Newton depends on h).
    ``h_max`` (absolute; None: no cap) bounds the step; steps land on the grid of
    ``land_every`` nominal steps from t0 (outputs on a fixed time grid) and on ``t_end``.
    """

    rtol: float = 1e-3
    atol: float = 1e-3
    atol_w: Optional[float] = None
    safety: float = 0.9
    min_factor: float = 0.2
    max_factor: float = 4.0
    hold_band: float = 1.2
    controller: str = "pi"
    h_max: Optional[float] = None
    land_every: int = 1

    def __post_init__(self):
        checks = [("rtol", self.rtol >= 0), ("atol", self.atol > 0),
                  ("atol_w", self.atol_w is None or self.atol_w > 0), ("safety", 0 < self.safety <= 1),
                  ("min_factor", 0 < self.min_factor < 1), ("max_factor", self.max_factor > 1),
                  ("hold_band", self.hold_band >= 1), ("controller", self.controller in ("pi", "elementary")),
                  ("h_max", self.h_max is None or self.h_max > 0), ("land_every", int(self.land_every) >= 1)]
        bad = [k for k, ok in checks if not ok]
        if bad:
            raise ValueError(f"AdaptiveControl: invalid {', '.join(f'{k} = {getattr(self, k)!r}' for k in bad)}")

    def exponents(self, tableau: "Tableau") -> tuple:
        k = float(tableau.embedded_order + 1)
        return (1.0 / k, 0.0) if self.controller == "elementary" else (0.7 / k, 0.4 / k)


def local_error(tableau: Tableau, x0, w0, states, mech, ada: AdaptiveControl) -> float:
    """The scaled local error ``err`` of one step (``AdaptiveControl``) from its stage states
    ``[(x_i, w_i)]`` (the last is the step's result)."""
    e = tableau.error_weights
    x1, w1 = states[-1]
    ex = sum(e[j] * (xj[mech] - x0[mech]) for j, (xj, _) in enumerate(states))
    err = float(np.max(np.abs(ex) / (ada.atol + ada.rtol * np.maximum(np.abs(x0[mech]), np.abs(x1[mech])))))
    if ada.atol_w is not None:
        ew = sum(e[j] * (wj[mech] - w0[mech]) for j, (_, wj) in enumerate(states))
        sc = ada.atol_w + ada.rtol * np.maximum(np.abs(w0[mech]), np.abs(w1[mech]))
        err = max(err, float(np.max(np.abs(ew) / sc)))
    return err


@dataclass
class _StepSize:
    """What the error control carries across segments (restarts): the step size and the
    previous accepted error."""

    h: float
    err_prev: Optional[float] = None
    rejected_last: bool = False


@dataclass(frozen=True)
class ReusePolicy:
    """Factorisation reuse of the stage Newton solves (modified Newton,
    ``rve.solvers.newton.JacobianReuse``; docs/time_integration.md): ``mode`` False (one
    factorisation per Newton iteration), True (keep one while the contraction stays <=
    ``contraction``) or "auto" (also weigh the measured costs); ``h_rtol``: the relative
    change of h a_ii that drops it; ``backend``: a ``rve.solvers.linear.get_backend`` name or
    a factory ``() -> backend``; ``across_restarts``: the held factorisation (and its
    backend's analysis) survives a step-control restart after a structure change
    (``integrate(rebuild=...)``), judged by the contraction test like any reused one,
    instead of being dropped with the stepper."""

    mode: object = False
    contraction: float = 0.5
    h_rtol: float = 0.1
    backend: object = None
    across_restarts: bool = False


_GROUPS = {StepControl: ("fixed_step", "max_cuts", "grow_after", "min_step_rel", "min_step_t_rel"),
           Budgets: ("max_rejections", "wall_budget_s")}
_REUSE_KEYS = {"jacobian_reuse": "mode", "reuse_contraction": "contraction", "reuse_h_rtol": "h_rtol",
               "linear_backend": "backend", "reuse_across_restarts": "across_restarts"}


def integrator_options(**flat) -> dict:
    """``integrate`` keywords from a flat mapping of option names (a scene's or a study's
    ``integrator_options``): the ``StepControl`` fields (``fixed_step``, ``max_cuts``, ...),
    the ``Budgets`` fields and ``jacobian_reuse``, ``reuse_contraction``, ``reuse_h_rtol``,
    ``linear_backend``, ``reuse_across_restarts`` become ``control``, ``budgets`` and ``reuse`` objects; every other
    key (``predictor_degree``, ``lazy_jacobian``, ...) is passed through."""
    out = {}
    for cls, keys in _GROUPS.items():
        given = {k: flat.pop(k) for k in keys if k in flat}
        if given:
            out["control" if cls is StepControl else "budgets"] = cls(**given)
    reuse = {_REUSE_KEYS[k]: flat.pop(k) for k in list(_REUSE_KEYS) if k in flat}
    if reuse:
        out["reuse"] = ReusePolicy(**reuse)
    return {**out, **flat}


def _give_up(fail: StepFailure, ctl: StepControl, bud: Budgets, t: float, h_try: float, h0: float, cuts: int,
             rejected: int, budget: int, wall0: float):
    """(cause, why) when a rejected step ends the run, else None."""
    h_floor = max(float(ctl.min_step_rel) * h0, float(ctl.min_step_t_rel) * abs(t))
    if ctl.fixed_step:
        return "fixed_step", "fixed-step mode"
    if cuts >= ctl.max_cuts:
        return "max_cuts", f"{cuts} consecutive step cuts (max_cuts = {ctl.max_cuts})"
    if h_try / 2.0 < h_floor:
        return "min_step", (f"the next step h/2 = {h_try / 2.0:.3g} would be below the minimum step {h_floor:.3g} "
                            f"(max(min_step_rel {ctl.min_step_rel:g} x h0 {h0:.3g}, min_step_t_rel "
                            f"{ctl.min_step_t_rel:g} x t))")
    if rejected >= budget:
        return "rejections", f"{rejected} rejected steps in total (max_rejections = {budget})"
    if bud.wall_budget_s is not None and time.perf_counter() - wall0 > bud.wall_budget_s:
        return "wall_time", f"the wall-time budget of {bud.wall_budget_s:g} s"
    return None


def _accept(out: IntegrationResult, info: StepInfo, t: float, h_try: float, bar, t0: float) -> None:
    out.steps += 1
    out.add({"newton_iterations": info.newton_iterations, "linear_solves": info.linear_solves,
             "jacobians": info.jacobians, "factorizations": info.factorizations,
             "reuses": sum(info.stage_reuses), "rejected_reuses": info.rejected_reuses,
             "stage_retries": info.stage_retries})
    for c in info.stage_contractions:
        out.contractions.extend(c)
    out.h_min = min(out.h_min, h_try)
    out.history.append((t, h_try, info.newton_iterations))
    rates = [q for c in info.stage_contractions for q in c]
    log.info("step %d t=%.6g h=%.3e newton its=%s factorisations=%d reused=%d max contraction=%s", out.steps, t,
             h_try, info.stage_iterations, info.factorizations, sum(info.stage_reuses),
             f"{max(rates):.2e}" if rates else "-")
    if bar is not None:
        bar.n = t - float(t0)
        bar.set_postfix(h=f"{h_try:.2e}", its=info.newton_iterations, refresh=False)
        bar.refresh()


def _segment(stepper, out, x, w, t, t_stop, n, ctl: StepControl, bud: Budgets, on_step, rebuild, final: bool, bar,
             t0):
    """Step from ``t`` to ``t_stop`` on ``n`` nominal steps with one stepper; returns
    ``(x, w, t)`` where the segment ended: at ``t_stop`` or where ``rebuild`` restarted."""
    h0 = (float(t_stop) - float(t)) / int(n)
    t_start, h = float(t), h0
    budget = max(64, 2 * int(n)) if bud.max_rejections is None else int(bud.max_rejections)
    rejected0, wall0 = out.rejected, time.perf_counter()
    k_next, cuts, successes = 1, 0, 0   # next grid point, consecutive cuts, successes since the last cut
    pending = 0                         # rejected attempts since the last accepted step
    while k_next <= n:
        t_target = float(t_stop) if k_next >= n else t_start + k_next * h0
        h_try = min(h, t_target - t)
        lands = h_try >= (t_target - t) * (1 - 1e-9) or (t_target - t - h_try) < 1e-9 * h0
        if lands:
            h_try = t_target - t
        try:
            x1, w1, info = stepper.step(x, w, t, h_try)
        except StepFailure as fail:
            _newton_rejection(out, fail, ctl, bud, t, h_try, h0, cuts, rejected0, budget, wall0, x, w)
            cuts, successes, h = cuts + 1, 0, h_try / 2.0
            pending += 1
            continue
        t = t_target if lands else t + h_try
        if lands:
            k_next += 1
        x, w = x1, w1
        info.rejected_attempts, pending = pending, 0
        cuts = 0
        successes += 1
        _accept(out, info, t, h_try, bar, t0)
        if on_step is not None:
            on_step(t, x, w, info)
        if rebuild is not None and not (final and k_next > n) and rebuild(t, x, w):
            return x, w, t
        if not ctl.fixed_step and h < h0 and successes >= ctl.grow_after:
            h = min(2.0 * h, h0)
            successes = 0
        if bud.wall_budget_s is not None and k_next <= n and time.perf_counter() - wall0 > bud.wall_budget_s:
            raise IntegrationFailure(
                f"time integration stopped at t = {t:.9g} (step size h = {h_try:.6g}) after the wall-time "
                f"budget of {bud.wall_budget_s:g} s; {out.steps} steps accepted, {out.rejected} rejected; "
                f"last good state at t = {t:.9g}", x.copy(), w.copy(), t, h_try, info.stage_residuals[-1],
                None, out, cause="wall_time")
    return x, w, t


def _newton_rejection(out, fail: StepFailure, ctl: StepControl, bud: Budgets, t: float, h_try: float, h0: float,
                      cuts: int, rejected0: int, budget: int, wall0: float, x, w) -> None:
    """Count a step whose stage Newton failed and log it; an ``IntegrationFailure`` with the
    last good state ``(x, w, t)`` when ``_give_up`` says the step cannot be cut again."""
    out.rejected += 1
    out.add(fail.counts)
    log.info("step %d t=%.6g h=%.3e REJECTED (stage %d: %s)", out.steps + 1, t, h_try, fail.stage, fail.reason)
    stop = _give_up(fail, ctl, bud, t, h_try, h0, cuts, out.rejected - rejected0, budget, wall0)
    if stop is not None:
        raise IntegrationFailure(
            f"time integration failed at t = {t:.9g} with step size h = {h_try:.6g} "
            f"after {stop[1]}: stage {fail.stage}: {fail.reason}; Newton residuals "
            f"{_fmt_res(fail.residuals)}; {out.steps} steps accepted, {out.rejected} rejected; "
            f"last good state at t = {t:.9g}",
            x.copy(), w.copy(), t, h_try, fail.residuals, fail, out, cause=stop[0]) from fail


def _landing(t: float, t0: float, t_end: float, grid: float) -> float:
    """The next landing point after ``t`` on the grid ``t0 + k grid``, or ``t_end``."""
    k = math.floor((t - t0) / grid + 1e-9) + 1
    return min(float(t_end), t0 + k * grid)


def _error_rejection(out, info, tab, ada: AdaptiveControl, err: float, h_try: float, t: float, x, w,
                     h_floor: float, rejected0: int, budget: int) -> float:
    """Count a step whose error estimate ``err`` exceeds 1 and return the shorter step (the
    elementary controller: the PI memory is of accepted steps); an ``IntegrationFailure`` with
    the last good state when that step is below ``h_floor`` or the rejections exceed ``budget``."""
    out.rejected += 1
    out.error_rejections += 1
    out.add({"newton_iterations": info.newton_iterations, "linear_solves": info.linear_solves,
             "jacobians": info.jacobians, "factorizations": info.factorizations,
             "reuses": sum(info.stage_reuses), "rejected_reuses": info.rejected_reuses,
             "stage_retries": info.stage_retries})
    factor = (ada.min_factor if not math.isfinite(err)
              else max(ada.min_factor, ada.safety * err ** (-1.0 / (tab.embedded_order + 1))))
    h_new = h_try * min(factor, 1.0)
    log.info("step %d t=%.6g h=%.3e REJECTED (error estimate %.3g > 1): h -> %.3e", out.steps + 1, t, h_try,
             err, h_new)
    if h_new < h_floor:
        raise IntegrationFailure(
            f"time integration failed at t = {t:.9g}: the error-controlled step h = {h_new:.6g} would be "
            f"below the minimum step {h_floor:.3g} (error estimate {err:.3g}); {out.steps} steps "
            f"accepted, {out.rejected} rejected; last good state at t = {t:.9g}",
            x.copy(), w.copy(), t, h_try, info.stage_residuals[-1], None, out, cause="min_step")
    if out.rejected - rejected0 >= budget:
        raise IntegrationFailure(
            f"time integration failed at t = {t:.9g} after {out.rejected - rejected0} rejected steps "
            f"(max_rejections = {budget}; last error estimate {err:.3g}); last good state at t = {t:.9g}",
            x.copy(), w.copy(), t, h_try, info.stage_residuals[-1], None, out, cause="rejections")
    return h_new


def _next_step_size(ada: AdaptiveControl, hs, err: float, h_try: float, beta1: float, beta2: float) -> float:
    """The step after an accepted one of size ``h_try`` and error estimate ``err`` (the PI or
    elementary controller, clipped to the growth limits; no growth right after a rejection;
    growths inside the hold band keep h, and with it the held factorisation)."""
    factor = ada.safety * max(err, 1e-10) ** (-beta1)
    if hs.err_prev is not None and beta2:
        factor *= max(hs.err_prev, 1e-10) ** beta2
    factor = min(ada.max_factor, max(ada.min_factor, factor))
    if hs.rejected_last:
        factor = min(factor, 1.0)
    if 1.0 <= factor <= ada.hold_band:
        factor = 1.0
    base = hs.h if (factor >= 1.0 and h_try < hs.h) else h_try   # a step shortened to land does not shrink h
    return base * factor


def _segment_adaptive(stepper, out, x, w, t, t_end, ctl: StepControl, bud: Budgets, ada: AdaptiveControl,
                      hs: _StepSize, on_step, rebuild, bar, t0, h0):
    """Error-controlled steps (``AdaptiveControl``) from ``t`` to ``t_end`` with one stepper;
    returns ``(x, w, t)`` at ``t_end`` or where ``rebuild`` restarted. ``hs`` carries the step
    size and the previous error over restarts; a Newton failure halves the step as in
    ``_segment`` (``max_cuts``, ``min_step_rel``), an error rejection shrinks it by the
    controller's factor."""
    tab = stepper.tableau
    beta1, beta2 = ada.exponents(tab)
    mech = stepper.mech
    grid = int(ada.land_every) * h0
    n_est = max(1, int(math.ceil((t_end - t) / h0 - 1e-6)))
    budget = max(64, 2 * n_est) if bud.max_rejections is None else int(bud.max_rejections)
    rejected0, wall0 = out.rejected, time.perf_counter()
    cuts, pending = 0, 0

    def h_floor(tt: float) -> float:
        return max(float(ctl.min_step_rel) * h0, float(ctl.min_step_t_rel) * abs(tt))

    while t < t_end - 1e-12 * max(1.0, abs(t_end)):
        t_target = _landing(t, t0, t_end, grid)
        h_want = min(hs.h, ada.h_max if ada.h_max is not None else math.inf)
        n_left = max(1, int(math.ceil((t_target - t) / h_want - 1e-9)))
        h_try = (t_target - t) / n_left   # equal steps to the landing point: no sliver step
        lands = n_left == 1
        saved = stepper._points
        try:
            x1, w1, info = stepper.step(x, w, t, h_try)
        except StepFailure as fail:
            _newton_rejection(out, fail, ctl, bud, t, h_try, h0, cuts, rejected0, budget, wall0, x, w)
            cuts, pending = cuts + 1, pending + 1
            hs.h, hs.rejected_last = h_try / 2.0, True
            continue
        err = local_error(tab, x, w, info.stage_states, mech, ada)
        if not math.isfinite(err) or err > 1.0:
            stepper._points = saved   # the rejected step's stages must not feed the predictor
            pending += 1
            hs.h = _error_rejection(out, info, tab, ada, err, h_try, t, x, w, h_floor(t), rejected0, budget)
            hs.rejected_last = True
            continue
        hs.h, hs.err_prev, hs.rejected_last = _next_step_size(ada, hs, err, h_try, beta1, beta2), err, False
        t = t_target if lands else t + h_try
        x, w = x1, w1
        info.rejected_attempts, pending, cuts = pending, 0, 0
        info.error = err
        out.errors.append(err)
        _accept(out, info, t, h_try, bar, t0)
        log.info("step %d error estimate %.3g: next h=%.3e", out.steps, err, hs.h)
        if on_step is not None:
            on_step(t, x, w, info)
        if rebuild is not None and t < t_end and rebuild(t, x, w):
            return x, w, t
        if bud.wall_budget_s is not None and t < t_end and time.perf_counter() - wall0 > bud.wall_budget_s:
            raise IntegrationFailure(
                f"time integration stopped at t = {t:.9g} (step size h = {h_try:.6g}) after the wall-time "
                f"budget of {bud.wall_budget_s:g} s; {out.steps} steps accepted, {out.rejected} rejected; "
                f"last good state at t = {t:.9g}", x.copy(), w.copy(), t, h_try, info.stage_residuals[-1],
                None, out, cause="wall_time")
    return x, w, float(t_end) if abs(t - t_end) <= 1e-12 * max(1.0, abs(t_end)) else t


def integrate(
    system,
    x0,
    w0,
    t0: float,
    t_end: float,
    n_steps: int,
    stages: int = 1,
    newton_opts: Optional[dict] = None,
    *,
    control: StepControl = StepControl(),
    reuse: ReusePolicy = ReusePolicy(),
    budgets: Budgets = Budgets(),
    on_step: Optional[Callable] = None,
    rebuild: Optional[StructureHook] = None,
    consistent: bool = True,
    progress: bool = False,
    tableau: Optional[Tableau] = None,
    predictor_degree: int = 2,
    lazy_jacobian: bool = True,
    predictor_across_restarts: bool = False,
    adaptive: Optional[AdaptiveControl] = None,
) -> IntegrationResult:
    """Integrate from ``t0`` to ``t_end`` with nominal step ``h0 = (t_end − t0)/n_steps``.

    Step control (``control``, a ``StepControl``; ``fixed_step=False``): a failed step
    (``StepFailure``) is discarded and retried from the last good state with half the
    step; after ``grow_after`` consecutive
    successes the step doubles again, never beyond ``h0``. Steps are clipped to the
    nominal grid ``t0 + k h0`` so a run always lands exactly on ``t_end`` (and on every
    grid point). After ``max_cuts`` consecutive cuts the next failure raises
    ``IntegrationFailure`` (message: time, step size, residual history; attributes: last
    good ``x, w, t``). With ``fixed_step=True`` every step is ``h0`` and the first failure
    raises ``IntegrationFailure`` at once.

    Every loop ends (docs/fault_tolerance.md; ``budgets``, a ``Budgets``): besides
    ``max_cuts`` (consecutive cuts, reset by every accepted step, however small), the run
    raises the same
    ``IntegrationFailure`` (``cause`` names which budget) when a cut would take the step
    below ``h_min = max(min_step_rel * h0, min_step_t_rel * |t|)`` (``"min_step"``: the
    step no longer advances t in any useful way; with ``min_step_t_rel`` >= 1e-12, t + h
    is always > t), after ``max_rejections`` rejected attempts in a segment
    (``"rejections"``; default ``max(64, 2 n)`` for a segment of n nominal steps) and, if
    ``wall_budget_s`` is set, when a segment has run that long (``"wall_time"``; off by
    default so results depend on the input only).

    ``on_step(t, x, w, info)`` is called after every accepted step (``info.stage_states``:
    the converged stage states). ``rebuild`` (a ``StructureHook``) is called next, except
    after the last step; when it reports a changed structure the step control restarts at
    that t on a new segment (``StructureHook``; ``IntegrationResult.restarts`` counts them);
    a rebuild the hook reports as unchanged keeps the held factorisation (the contraction
    test of the modified Newton sees the changed values).
    With ``consistent`` the massless dofs are first solved for at t0
    (``consistent_initialization``). ``predictor_degree`` sets the stage predictor
    (``DirkStepper``; 0 = previous stage value) and ``lazy_jacobian`` skips the Jacobian at
    converged points (``DirkStepper``). ``predictor_across_restarts``: the stage values the
    predictor extrapolates survive a restart (the state is continuous there; off: the first
    step after a restart starts its stages from the previous stage value).

    Factorisation reuse (modified Newton; docs/time_integration.md; ``reuse``, a
    ``ReusePolicy``): ``mode`` False (default: one factorisation per Newton iteration), True
    (keep a factorisation across iterations, stages and steps while the contraction stays
    <= ``contraction``) or "auto" (also weigh the measured cost of the extra iterations
    against a fresh factorisation); ``h_rtol``: relative change of h·a_ii that drops the
    factorisation; ``backend``: its ``rve.solvers.linear.get_backend`` name or factory.
    ``integrator_options(**flat)`` makes these objects from flat option names. The result
    counts Jacobian evaluations, factorisations, reused iterations, rejected modified
    steps, full-Newton stage retries and why factorisations were dropped
    (``refactor_reasons``).

    Error-controlled steps (``adaptive``, an ``AdaptiveControl``; None: the steps above):
    the first step is ``h0``, the later ones follow the embedded error estimate of the
    tableau (``Tableau.b_hat``; SDIRK2 and SDIRK3), landing on the grid of
    ``adaptive.land_every`` nominal steps and on ``t_end``; a Newton failure still halves
    the step. The step size and the controller's memory survive the restarts of ``rebuild``
    (which must not have a ``horizon``). The result adds ``error_rejections`` and the
    accepted ``errors``.
    """
    tab = tableau if tableau is not None else sdirk(stages)
    if n_steps < 1 or not t_end > t0:
        raise ValueError("need n_steps >= 1 and t_end > t0")
    if adaptive is not None:
        if tab.b_hat is None:
            raise ValueError(f"error-controlled steps need an embedded method; {tab.name} has none (use 2 or 3 stages)")
        if control.fixed_step:
            raise ValueError("error-controlled steps (adaptive) and fixed_step exclude each other")
        if rebuild is not None and hasattr(rebuild, "horizon"):
            raise ValueError("error-controlled steps do not follow a rebuild hook's horizon "
                             "(segments of nominal steps)")
    x = np.array(x0, dtype=float, copy=True)
    w = np.array(w0, dtype=float, copy=True)
    t = float(t0)
    out = IntegrationResult(x, w, t)
    if consistent:
        w, res0 = consistent_initialization(system, x, w, t, newton_opts)
        if res0 is not None:
            out.add(_counts([res0]))
    h0 = (float(t_end) - float(t0)) / int(n_steps)
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=float(t_end) - float(t0), desc=f"SDIRK{tab.stages}",
                   bar_format="{l_bar}{bar}| t-t0 = {n:.6g}/{total:.6g} [{elapsed}<{remaining}{postfix}]")
    reusers: list = []   # the JacobianReuse objects of the run (one per segment unless carried)
    stepper = None
    hs = _StepSize(h0)
    try:
        t_stop, n = (float(t_end), int(n_steps)) if rebuild is None else _horizon(rebuild, t, t_end, h0)
        while True:
            previous = stepper
            stepper = DirkStepper(system, tab, newton_opts, predictor_degree, lazy_jacobian, reuse.mode,
                                  reuse.contraction, reuse.h_rtol, reuse.backend, watch_structure=rebuild is None)
            if previous is not None and not getattr(rebuild, "fresh", False):
                stepper.carry_from(previous, factorisation=reuse.across_restarts,
                                   predictor=predictor_across_restarts)
            if previous is not None and previous.reuse is not None and previous.reuse is not stepper.reuse:
                # the previous segment's factorisation is not carried: free it now (``reusers``
                # keeps the object for the run's counts; with its factor and PARDISO instance it
                # held the memory of one full-size factorisation per checkpoint boundary of the
                # impact, ~0.2 GB each, to the end of the run)
                previous.reuse.release()
            if stepper.reuse is not None and all(r is not stepper.reuse for r in reusers):
                reusers.append(stepper.reuse)
            final = t_stop >= float(t_end)
            if adaptive is not None:
                x, w, t = _segment_adaptive(stepper, out, x, w, t, float(t_end), control, budgets, adaptive, hs,
                                            on_step, rebuild, bar, float(t0), h0)
            else:
                x, w, t = _segment(stepper, out, x, w, t, t_stop, n, control, budgets, on_step, rebuild, final, bar,
                                   t0)
            if t >= float(t_end):
                break
            out.restarts += 1
            t_stop, n = _horizon(rebuild, t, t_end, h0)
    finally:
        if bar is not None:
            bar.close()
        if reuse.mode:
            reasons: dict = {}
            for r in reusers:
                for k, v in r.refactor_reasons.items():
                    reasons[k] = reasons.get(k, 0) + v
            out.refactor_reasons = reasons
    out.x, out.w, out.t = x, w, t
    return out
