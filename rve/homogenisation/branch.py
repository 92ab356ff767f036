"""One equilibrium path: detect that a load step jumped to another equilibrium, and follow
the branch from the previous state with smaller steps (docs/table_accuracy.md, "One
equilibrium path").

A quasi-static path is a sequence of equilibria x(eps) of a potential Pi(x; eps) under a
load parameter eps (the macro strain: the prescribed end positions of the pinned cell, the
macro deformation gradient of a periodic one). Along one smooth branch the total derivative
of the energy is the load derivative at fixed free dofs (the free residual vanishes):

    dPi/deps = Pi_eps(x(eps); eps)      (the work-conjugate macro force)

so the energy change of a step is the work of the macro force, and the trapezoid rule
predicts it to O(d^3) in the step d = eps_b - eps_a:

    W = (Pi_eps(a) + Pi_eps(b)) d / 2,      mismatch m = W - (Pi(b) - Pi(a)).

A step whose solver landed in another local minimum (the driven phase carried the state over
a barrier that still exists) has a mismatch of the order of the energy released at the jump,
which does not shrink with d. The **criterion** (``detect``): a jump when

    |m| > energy_rtol * |d| max(|Pi_eps(a)|, |Pi_eps(b)|) + energy_atol,

or when the inertia of the constrained Hessian (its negative-eigenvalue count; 0 for a local
minimum, the definiteness verdict the energy minimiser computes) differs between the two
states (where both are known).

On detection (``follow_branch``) the step is split in two halves, each solved from the state
before it and checked the same way, recursively down to ``max_halvings`` (the floor
d / 2^max_halvings). A half whose mismatch is at most a quarter of its parent's is resolved
(``converging``): the trapezoid error of a smooth branch falls as d^3 (1/8 per halving),
while a jump keeps the energy it releases in the half that holds it: a failing half whose
mismatch is at least ``persist_ratio`` (0.5) of its parent's holds the jump itself and is
accepted as a limit point without halving further (each level would cost two more step
solves and only narrow where the jump happens; ``persist_ratio = 0``: down to the floor). The followed end state is compared with the naive one: when both are
the same equilibrium (``distance`` below ``state_tol`` and the energies equal within the
criterion's tolerance) the naive state is kept, so a false alarm changes no bit of the
result; otherwise the followed state replaces it (a branch jump was avoided), unless the
followed path's last solve did not converge (its ``info["converged"]`` False): then the
converged naive state is kept as a limit point (``followed_unconverged``). A sub-step at
the floor that still fails the test is a **limit point** (the branch ends; the jump is
physical) and is accepted and recorded. Every detection and retry is in the returned info.

**Through a limit point** (``settings.method == "arc_length"`` with an ``arc`` callable):
a detected step is followed by pseudo-arclength continuation instead (``continue_arc``):
the equilibria R(x, eps) = 0 as one curve in (x, eps), parametrised by its arc length
s with ds^2 = |dx|^2 + xi^2 deps^2 (xi = |dx/deps| at the start, so that both parts weigh
alike there). Each arc step predicts along the unit tangent t and corrects by Newton on

    R(x, eps) = 0,     t_x . (x - x_p) + xi^2 t_eps (eps - eps_p) = 0

(the bordered system [[K, R_eps], [t_x^T, xi^2 t_eps]], solved with the one factorisation
of K per iteration, two back-substitutions; it stays regular where K is singular, at a
fold). The tangent of the next step is the bordered system's solution for the right-hand
side (0, 1), oriented along the previous one; a step over which the tangent turns by more
than ``min_turn_cos`` is halved (it could cut across a fold); a sign change of t_eps is a fold passed (a
limit point in eps: the path turns back, on the branch whose inertia the factorisation
counts, and turns forward again at the next). The continuation stops at the first point
past eps_b with eps increasing and ends by Newton at eps = eps_b from the chord between the
last two points. ``ArcSettings(corrector="dogleg")`` corrects by Powell's dogleg on |R|^2 / 2
within the hyperplane instead (the bordered Newton step inside a trust region, the projected
Cauchy step towards it outside), for residuals too nonlinear on the scale of an arc step for
Newton with backtracking. A sharp turn over a step shorter than ``kink_fraction`` of the first is a
corner of the curve (the contact law is piecewise smooth), accepted and counted (``kinks``).
The end is the state on the one continuous branch from ``start``: it
depends on the curve of equilibria, not on a step size (tested: two step sizes land on the
same equilibrium; two runs are bit-identical). The naive state is kept when it is that
state (as above), and when the continued branch is not a local minimum at its start or its
end (a negative pivot: a saddle branch is no state of the table; the naive step's
minimisation is then the physical exit, a limit point); otherwise the arc's. A continuation that fails (its step floor, or
``max_steps``) falls back to the halving.

Contract
--------
``follow_branch(solve, start, eps_a, eps_b, energy, *, inertia=None, distance=None,
settings=BranchSettings(), arc=None) -> (StepSolution, info)``, with

* ``solve(start: StepSolution, eps_from, eps_to) -> StepSolution``: one step of the path's
  own algorithm (pinned Algorithm 7.1, or a periodic step) from an equilibrium at
  ``eps_from`` to one at ``eps_to``;
* ``energy(sol: StepSolution, eps) -> (Pi, Pi_eps)``: the potential of an equilibrium state
  and its load derivative;
* ``inertia(sol) -> int | None``: negative-eigenvalue count of its constrained Hessian
  (None: unknown, the inertia test is skipped);
* ``distance(x_a, x_b) -> float``: how far apart two states are (default: max |x_a - x_b|);
* ``arc(start, eps_from, eps_to) -> StepSolution | None``: the continuation of the caller's
  problem from ``start`` (``continue_arc`` on an ``ArcProblem``; None: it failed).

``continue_arc(problem, x0, eps0, eps1, settings=ArcSettings()) -> (x, info)`` with an
``ArcProblem`` of callables: ``residual(x, eps)``, ``tangent(x, eps) -> (K, R_eps)``,
``factor(K) -> (solve, negative_count)``, ``rebuild(x, eps)`` (between arc steps: the
contact map), ``energy(x, eps) -> (Pi, Pi_eps)``, and ``atol`` (|R|_inf of an equilibrium).
Its info: ``converged``, ``arc_steps``, ``folds`` (limit points passed), ``kinks``, ``rejected``,
``factorizations``, ``path`` (eps, negative count, Pi, Pi_eps of every accepted point),
``end_inertia`` and ``energy_mismatch`` (the energy change along the path minus the
trapezoid work of Pi_eps over it: ~0 on one continuous branch).

``info`` (JSON-ready): ``checks`` (every tested interval: eps, mismatch, tolerance,
inertia, verdict, depth), ``detections`` (tests that failed), ``converging``, ``solves``, ``branch_jumps`` (jumps avoided by
following), ``limit_points`` (jumps left at the floor), ``false_alarms``, ``kept``
(``naive`` / ``followed`` / ``arc``), ``limit_points_passed`` and ``arc`` (the continuation's
info) where one ran. Pure arithmetic on the callables: no model is imported here.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

import numpy as np

__all__ = ["BranchSettings", "StepSolution", "detect", "follow_branch", "BRANCH_COUNTS", "ArcSettings", "ArcProblem",
           "continue_arc"]

log = logging.getLogger("rve.homogenisation.branch")


#: the counters of a step's record (``follow_branch``'s info) that a table reports
BRANCH_COUNTS = ("detections", "solves", "branch_jumps", "limit_points", "false_alarms", "converging",
                 "limit_points_passed")


@dataclass(frozen=True)
class BranchSettings:
    """Tolerances of the branch test (module docstring)."""

    energy_rtol: float = 0.05       # mismatch allowed, as a fraction of the step's work
    energy_atol: float = 1e-12      # N mm: floor of the tolerance (a step without work)
    max_halvings: int = 3           # recursion depth: floor d / 2^max_halvings
    state_tol: float = 1e-6         # distance below which naive and followed states are one
    method: str = "halving"         # "arc_length": a detected step by continuation (with ``arc``)
    persist_ratio: float = 0.5      # a failing half with this share of its parent's mismatch is the jump


@dataclass(frozen=True)
class ArcSettings:
    """Step control of ``continue_arc``."""

    steps: int = 4                  # first arc step: the interval's scaled length / steps
    max_steps: int = 60             # accepted arc steps at most
    newton_max_iter: int = 20       # corrector iterations per arc step
    backtracks: int = 4             # halvings of a corrector step that does not lower |R|
    path_atol_factor: float = 1.0   # the path's points are equilibria to this x the problem's atol
    grow: float = 1.5               # step growth after an easy corrector (<= 3 iterations)
    min_step_fraction: float = 1e-3  # floor of the arc step, of the first one
    min_turn_cos: float = 0.95      # a step whose tangent turns further (cos below) is halved,
    kink_fraction: float = 0.02     # unless it is this short (of the first): a corner, accepted
    corrector: str = "newton"       # "dogleg": a trust region on |R|^2 in the hyperplane
    dogleg_max_iter: int = 40       # iterations of the dogleg corrector per arc step

    def __post_init__(self):
        if self.corrector not in ("newton", "dogleg"):
            raise ValueError(f"ArcSettings.corrector must be 'newton' or 'dogleg', got {self.corrector!r}")


@dataclass
class ArcProblem:
    """The equilibrium curve R(x, eps) = 0 of ``continue_arc`` (module docstring)."""

    residual: Callable
    tangent: Callable
    factor: Callable
    rebuild: Callable
    energy: Callable
    atol: float


@dataclass
class StepSolution:
    """An equilibrium state of the path: ``x`` (the state vector or array), ``info`` (its
    solver record), ``extra`` (anything the callables need, e.g. the system built at x)."""

    x: Any
    info: dict = field(default_factory=dict)
    extra: Any = None


def _max_abs(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))))


def detect(Pi_a: float, dPi_a: float, Pi_b: float, dPi_b: float, d_eps: float, settings: BranchSettings,
           inertia_a: Optional[int] = None, inertia_b: Optional[int] = None) -> dict:
    """The branch test of one interval (module docstring): ``{"mismatch", "tolerance",
    "work", "energy_change", "inertia", "jump", "why"}``."""
    work = 0.5 * (dPi_a + dPi_b) * d_eps
    change = Pi_b - Pi_a
    mismatch = work - change
    # the scale is the larger end force: a step that starts from an unloaded state (Pi_eps(a)
    # = 0) is judged against the work the loaded end would do
    tol = settings.energy_rtol * abs(d_eps) * max(abs(dPi_a), abs(dPi_b)) + settings.energy_atol
    why = []
    if not np.isfinite(mismatch) or abs(mismatch) > tol:
        why.append("energy")
    if inertia_a is not None and inertia_b is not None and int(inertia_a) != int(inertia_b):
        why.append("inertia")
    return {"work": float(work), "energy_change": float(change), "mismatch": float(mismatch),
            "tolerance": float(tol), "inertia": [inertia_a, inertia_b], "jump": bool(why), "why": why}


class _Follower:
    """The recursion of ``follow_branch`` and its record."""

    def __init__(self, solve, energy, inertia, distance, settings):
        self.solve, self.energy, self.inertia, self.distance = solve, energy, inertia, distance
        self.s = settings
        self.info = {"checks": [], "detections": 0, "solves": 0, "branch_jumps": 0, "limit_points": 0,
                     "false_alarms": 0, "converging": 0, "limit_points_passed": 0,
                     "kept": "naive"}

    def evaluate(self, sol, eps):
        Pi, dPi = self.energy(sol, eps)
        k = self.inertia(sol) if self.inertia is not None else None
        return float(Pi), float(dPi), (None if k is None else int(k))

    def step(self, start, e_a, eps_a, eps_b, depth):
        """Solve [eps_a, eps_b] from ``start`` (energy record ``e_a``) and test it:
        ``(solution, its energy record, verdict)``."""
        sol = self.solve(start, eps_a, eps_b)
        self.info["solves"] += 1
        e_b = self.evaluate(sol, eps_b)
        v = detect(e_a[0], e_a[1], e_b[0], e_b[1], eps_b - eps_a, self.s, e_a[2], e_b[2])
        self.info["checks"].append({"eps": [float(eps_a), float(eps_b)], "depth": int(depth),
                                    **{k: v[k] for k in ("work", "energy_change", "mismatch", "tolerance",
                                                         "inertia", "jump", "why")}})
        if v["jump"]:
            self.info["detections"] += 1
            log.info("branch test [%g, %g] (depth %d): jump (%s; mismatch %.3e N mm, tolerance %.3e)", eps_a, eps_b,
                     depth, "+".join(v["why"]), v["mismatch"], v["tolerance"])
        return sol, e_b, v

    def follow(self, start, e_a, eps_a, eps_b, depth, parent_mismatch):
        """Follow the branch over [eps_a, eps_b] by halves; returns ``(solution, energy record)``."""
        mid = 0.5 * (eps_a + eps_b)
        out, e_out = start, e_a
        for lo, hi in ((eps_a, mid), (mid, eps_b)):
            sol, e_sol, v = self.step(out, e_out, lo, hi, depth)
            if v["jump"] and v["why"] == ["energy"] and abs(v["mismatch"]) <= 0.25 * abs(parent_mismatch):
                # the mismatch falls at the trapezoid's rate (a smooth branch: d^3, 1/8 per
                # halving; a jump keeps its released energy in the half that holds it)
                self.info["converging"] += 1
                self.info["checks"][-1]["converging"] = True
            elif (v["jump"] and self.s.persist_ratio > 0 and "energy" in v["why"]
                  and abs(v["mismatch"]) >= self.s.persist_ratio * abs(parent_mismatch)):
                # the half holds the parent's whole mismatch: the energy a jump releases, which
                # no shorter step removes; halving further would only narrow where it happens
                self.info["limit_points"] += 1
                self.info["checks"][-1]["persists"] = True
                log.warning("branch: the jump over [%g, %g] keeps its parent's mismatch (%.3e of %.3e N mm): a limit "
                            "point of the branch (accepted)", lo, hi, v["mismatch"], parent_mismatch)
            elif v["jump"]:
                if depth < self.s.max_halvings:
                    sol, e_sol = self.follow(out, e_out, lo, hi, depth + 1, v["mismatch"])
                else:
                    self.info["limit_points"] += 1
                    log.warning("branch: a jump over [%g, %g] remains at the step floor %g: a limit point of the "
                                "branch (accepted)", lo, hi, hi - lo)
            out, e_out = sol, e_sol
        return out, e_out


def follow_branch(solve: Callable, start: StepSolution, eps_a: float, eps_b: float, energy: Callable, *,
                  inertia: Optional[Callable] = None, distance: Optional[Callable] = None,
                  settings: BranchSettings = BranchSettings(), arc: Optional[Callable] = None) -> tuple:
    """One step of the path from ``start`` (an equilibrium at ``eps_a``) to ``eps_b`` that
    stays on ``start``'s branch (module docstring). Returns ``(StepSolution, info)``."""
    f = _Follower(solve, energy, inertia, distance or _max_abs, settings)
    e_a = f.evaluate(start, eps_a)
    naive, e_naive, v = f.step(start, e_a, eps_a, eps_b, 0)
    if not v["jump"]:
        return naive, f.info
    if settings.method == "arc_length" and arc is not None:
        out = _by_arc(f, arc, start, naive, e_naive, v, eps_a, eps_b)
        if out is not None:
            return out, f.info
    if settings.max_halvings < 1:
        f.info["limit_points"] += 1
        return naive, f.info
    followed, e_fol = f.follow(start, e_a, eps_a, eps_b, 1, v["mismatch"])
    if followed.info.get("converged") is False and naive.info.get("converged") is not False:
        # a followed path whose sub-steps did not reach equilibrium is no state of the table:
        # the converged naive state is kept, and the record says so
        f.info["followed_unconverged"] = True
        f.info["limit_points"] += 1
        log.warning("branch [%g, %g]: the followed path did not converge; the naive step's state is kept",
                    eps_a, eps_b)
        return naive, f.info
    gap = float(f.distance(naive.x, followed.x))
    energy_gap = abs(e_fol[0] - e_naive[0])
    same = gap <= settings.state_tol and energy_gap <= max(v["tolerance"], settings.energy_atol)
    f.info.update({"naive_to_followed_distance": gap, "naive_to_followed_energy": float(e_fol[0] - e_naive[0])})
    if same:
        # the naive step's state is the end of the branch it left from: a false alarm, or
        # a limit point the naive step passed the same way
        f.info["false_alarms"] += 0 if f.info["limit_points"] else 1
        log.info("branch [%g, %g]: the followed path ends in the naive step's state (distance %.3e): kept it",
                 eps_a, eps_b, gap)
        return naive, f.info
    f.info["branch_jumps"] += 1
    f.info["kept"] = "followed"
    log.warning("branch [%g, %g]: the naive step jumped to another equilibrium (distance %.3e, energy %+.3e N mm); "
                "the followed branch is kept", eps_a, eps_b, gap, e_fol[0] - e_naive[0])
    return followed, f.info


class _Arc:
    """The state of ``continue_arc``: the scaled metric, the current point and tangent."""

    def __init__(self, problem: ArcProblem, settings: ArcSettings):
        self.p, self.s = problem, settings
        self.info = {"converged": False, "arc_steps": 0, "folds": 0, "kinks": 0, "rejected": 0, "factorizations": 0,
                     "newton_iterations": 0, "path": []}

    def factor(self, x, eps):
        solve, R_eps, neg, _ = self.factor_with_tangent(x, eps)
        return solve, R_eps, neg

    def factor_with_tangent(self, x, eps):
        """``factor``'s ``(solve, R_eps, negative pivots)`` and the tangent K itself."""
        K, R_eps = self.p.tangent(x, eps)
        solve, neg = self.p.factor(K)
        self.info["factorizations"] += 1
        return solve, np.asarray(R_eps, float), (None if neg is None else int(neg)), K

    def tangent(self, solve, R_eps, t_prev):
        """The unit tangent (t_x, t_eps) from the bordered system with right-hand side (0, 1)
        (the start: dx/deps = -K^-1 R_eps, eps increasing)."""
        a = solve(R_eps)
        if t_prev is None:
            tx, te = -a, 1.0
        else:
            px, pe = t_prev
            te = 1.0 / (self.xi2 * pe - float(px @ a))
            tx = -te * a
        n = np.sqrt(float(tx @ tx) + self.xi2 * te * te)
        tx, te = tx / n, te / n
        if t_prev is not None and float(tx @ t_prev[0]) + self.xi2 * te * t_prev[1] < 0.0:
            tx, te = -tx, -te
        return tx, float(te)

    def record(self, x, eps, neg):
        Pi, dPi = self.p.energy(x, eps)
        self.info["path"].append({"eps": float(eps), "inertia": neg, "energy": float(Pi), "energy_rate": float(dPi)})

    def correct(self, xp, ep, t):
        """The corrector on the residual and the hyperplane through the predictor normal to
        ``t`` (``settings.corrector``): ``(x, eps, iterations)`` or None."""
        if self.s.corrector == "dogleg":
            return self.correct_dogleg(xp, ep, t)
        return self.correct_newton(xp, ep, t)

    def correct_dogleg(self, xp, ep, t):
        """Powell's dogleg on |R|^2 / 2 within the hyperplane (module docstring), in the
        scaled coordinates y = (x, xi eps) where the arc metric is Euclidean: the step is the
        bordered Newton step where it lies in the trust region, else the path from the
        hyperplane-projected Cauchy point towards it; the region grows after good agreement
        of the linear model and shrinks after poor. Every step keeps the hyperplane (the
        predictor lies in it and the steps are tangent to it)."""
        tx, te = t
        xi = float(np.sqrt(self.xi2))
        ty = np.concatenate([tx, [xi * te]])
        x, eps = xp.copy(), float(ep)
        atol = self.s.path_atol_factor * self.p.atol
        R = np.asarray(self.p.residual(x, eps), float)
        radius = None
        for it in range(self.s.dogleg_max_iter + 1):
            if not np.all(np.isfinite(R)):
                return None
            r = float(np.max(np.abs(R)))
            log.debug("arc dogleg it=%d |R|=%.3e eps=%.6g radius=%s", it, r, eps, radius)
            if r <= atol:
                return x, eps, it
            if it == self.s.dogleg_max_iter:
                return None
            solve, R_eps, _, K = self.factor_with_tangent(x, eps)
            a, b = solve(R), solve(R_eps)
            d_eps = float(tx @ a) / (self.xi2 * te - float(tx @ b))
            dN = np.concatenate([-a - d_eps * b, [xi * d_eps]])
            J = lambda v: K @ v[:-1] + R_eps * (v[-1] / xi)  # noqa: E731
            G = np.concatenate([K.T @ R, [float(R_eps @ R) / xi]])
            G -= float(ty @ G) * ty
            JG = J(G)
            alpha = float(G @ G) / max(float(JG @ JG), 1e-300)
            dC = -alpha * G
            nN = float(np.linalg.norm(dN))
            radius = nN if radius is None else radius
            f0 = float(R @ R)
            while True:
                d = _dogleg(dN, dC, nN, radius)
                x1, e1 = x + d[:-1], eps + d[-1] / xi
                R1 = np.asarray(self.p.residual(x1, e1), float)
                lin = R + J(d)
                pred = f0 - float(lin @ lin)
                act = f0 - float(R1 @ R1) if np.all(np.isfinite(R1)) else -np.inf
                rho = act / pred if pred > 0 else -np.inf
                nd = float(np.linalg.norm(d))
                if rho < 0.25:
                    radius = 0.25 * nd
                elif rho > 0.75 and nd >= 0.99 * radius:
                    radius = 2.0 * radius
                if rho > 0.1:
                    x, eps, R = x1, e1, R1
                    break
                if radius < 1e-12 * max(1.0, nN):
                    return None
            self.info["newton_iterations"] += 1
        return None

    def correct_newton(self, xp, ep, t):
        """Newton on the residual and the hyperplane through the predictor normal to ``t``:
        ``(x, eps, iterations)`` or None."""
        tx, te = t
        x, eps = xp.copy(), float(ep)
        atol = self.s.path_atol_factor * self.p.atol
        history = []
        for it in range(self.s.newton_max_iter + 1):
            R = np.asarray(self.p.residual(x, eps), float)
            g = float(tx @ (x - xp)) + self.xi2 * te * (eps - ep)
            if not np.all(np.isfinite(R)):
                return None
            r = float(np.max(np.abs(R)))
            log.debug("arc corrector it=%d |R|=%.3e g=%.3e eps=%.6g", it, r, g, eps)
            if r <= atol and abs(g) <= 1e-12 * max(1.0, self.scale):
                return x, eps, it
            history.append(r)
            # no progress over 4 iterations: the residual is not smooth here (a contact
            # point crossing an element end); a shorter arc step may pass it
            if it == self.s.newton_max_iter or (len(history) > 4 and r > 0.5 * history[-5]):
                return None
            solve, R_eps, _ = self.factor(x, eps)
            a, b = solve(R), solve(R_eps)
            d_eps = (float(tx @ a) - g) / (self.xi2 * te - float(tx @ b))
            dx = -a - d_eps * b
            x, eps = self.backtrack(x, eps, dx, d_eps, float(np.linalg.norm(R)), xp, ep, t)
            self.info["newton_iterations"] += 1
        return None

    def backtrack(self, x, eps, dx, d_eps, r0, xp, ep, t):
        """The Newton step, halved (up to ``backtracks`` times) until |R| decreases: the
        contact law is only piecewise smooth, where a full step can overshoot. The
        hyperplane is linear, so every fraction of the step keeps its residual as Newton
        made it."""
        for k in range(self.s.backtracks + 1):
            lam = 0.5 ** k
            xt, et = x + lam * dx, eps + lam * d_eps
            R = np.asarray(self.p.residual(xt, et), float)
            if np.all(np.isfinite(R)) and float(np.linalg.norm(R)) < r0:
                return xt, et
        return xt, et

    def newton_at(self, x, eps):
        """Newton at fixed eps (the end of the path, to the path's tolerance): x or None."""
        for _ in range(self.s.newton_max_iter + 1):
            R = np.asarray(self.p.residual(x, eps), float)
            if not np.all(np.isfinite(R)):
                return None
            if np.max(np.abs(R)) <= self.s.path_atol_factor * self.p.atol:
                return x
            solve, _, _ = self.factor(x, eps)
            x = x - solve(R)
            self.info["newton_iterations"] += 1
        return None


def _dogleg(dN, dC, nN: float, radius: float) -> np.ndarray:
    """The dogleg step in a region of ``radius``: the Newton step ``dN`` where it fits,
    else the Cauchy step ``dC`` cut at the boundary, else the path from ``dC`` to ``dN``
    to the boundary."""
    if nN <= radius:
        return dN
    nC = float(np.linalg.norm(dC))
    if nC >= radius:
        return dC * (radius / nC)
    p = dN - dC
    a, b, c = float(p @ p), 2.0 * float(dC @ p), nC * nC - radius * radius
    tau = (-b + np.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
    return dC + tau * p


def _path_mismatch(path) -> float:
    """Energy change along the path minus the trapezoid work of Pi_eps over it."""
    work = sum(0.5 * (a["energy_rate"] + b["energy_rate"]) * (b["eps"] - a["eps"]) for a, b in zip(path, path[1:]))
    return float(path[-1]["energy"] - path[0]["energy"] - work)


def continue_arc(problem: ArcProblem, x0, eps0: float, eps1: float, settings: ArcSettings = ArcSettings()):
    """Pseudo-arclength continuation of the equilibrium ``x0`` at ``eps0`` to ``eps1``
    (module docstring). Returns ``(x at eps1, info)``; ``x`` is None if it failed."""
    arc = _Arc(problem, settings)
    x, eps = np.array(x0, float), float(eps0)
    solve, R_eps, neg = arc.factor(x, eps)
    dx = solve(R_eps)
    arc.xi2 = max(float(dx @ dx), 1e-300)
    arc.scale = float(np.sqrt(arc.xi2)) * abs(eps1 - eps0)
    arc.record(x, eps, neg)
    t = arc.tangent(solve, R_eps, None)
    ds = float(np.sqrt(2.0 * arc.xi2)) * (eps1 - eps0) / settings.steps
    ds_first = ds
    ds_min = settings.min_step_fraction * ds
    info = arc.info
    while info["arc_steps"] < settings.max_steps:
        got = arc.correct(x + ds * t[0], eps + ds * t[1], t)
        if got is None:
            info["rejected"] += 1
            log.info("arc-length: corrector failed from eps %g (ds %.3e): halved", eps, ds)
            ds *= 0.5
            if ds < ds_min:
                log.warning("arc-length: step floor reached at eps %g", eps)
                break
            continue
        xc, ec, iters = got
        solve, R_eps, neg = arc.factor(xc, ec)
        t_new = arc.tangent(solve, R_eps, t)
        turn = float(t_new[0] @ t[0]) + arc.xi2 * t_new[1] * t[1]
        if turn < settings.min_turn_cos and ds <= settings.kink_fraction * ds_first:
            # a sharp turn over a short step: a corner of the curve (the contact law is only
            # piecewise smooth), not a fold cut across: accepted
            info["kinks"] += 1
        elif turn < settings.min_turn_cos:
            # the tangent turned too far in one step: it may have cut across a fold onto
            # another part of the curve
            info["rejected"] += 1
            log.info("arc-length: the tangent turned too far from eps %g (ds %.3e): halved", eps, ds)
            ds *= 0.5
            if ds < ds_min:
                log.warning("arc-length: step floor reached at eps %g (the curve turns sharply)", eps)
                break
            continue
        if np.sign(t_new[1]) != np.sign(t[1]):
            info["folds"] += 1
            log.info("arc-length: a limit point passed near eps %g (inertia %s)", ec, neg)
        info["arc_steps"] += 1
        problem.rebuild(xc, ec)
        arc.record(xc, ec, neg)
        if ec >= eps1 and t_new[1] > 0.0:
            w = (eps1 - eps) / (ec - eps)
            xe = arc.newton_at(x + w * (xc - x), eps1)
            if xe is None:
                break
            _, _, neg_end = arc.factor(xe, eps1)
            arc.record(xe, eps1, neg_end)
            info.update({"converged": True, "end_inertia": neg_end, "energy_mismatch": _path_mismatch(info["path"])})
            return xe, info
        x, eps, t = xc, ec, t_new
        if iters <= 3:
            ds *= settings.grow
    info["energy_mismatch"] = _path_mismatch(info["path"])
    return None, info


def _by_arc(f: _Follower, arc: Callable, start, naive, e_naive, v, eps_a: float, eps_b: float):
    """The detected step by continuation (module docstring): the naive state where it is the
    continuation's end, else the continuation's; None when the continuation failed."""
    sol = arc(start, eps_a, eps_b)
    ainfo = (sol.info.get("arc") if sol is not None else None) or {}
    f.info["arc"] = {k: ainfo.get(k) for k in ("converged", "arc_steps", "folds", "kinks", "rejected", "factorizations",
                                               "newton_iterations", "end_inertia", "energy_mismatch", "path")}
    if sol is None or not ainfo.get("converged"):
        log.warning("branch [%g, %g]: the continuation failed; the step is followed by halving", eps_a, eps_b)
        return None
    f.info["limit_points_passed"] = int(ainfo.get("folds") or 0)
    path = ainfo.get("path") or [{}]
    unstable = [k for k in (path[0].get("inertia"), ainfo.get("end_inertia")) if k]
    if unstable:
        # the branch from the start is not a local minimum there (or no longer at eps_b): no
        # stable state to follow; the naive step's is the physical one (a limit point)
        f.info["limit_points"] += 1
        f.info["arc"]["unstable"] = True
        log.warning("branch [%g, %g]: the continued branch is unstable (negative pivots %s at its ends); the naive "
                    "step's state is kept (a limit point)", eps_a, eps_b,
                    [path[0].get("inertia"), ainfo.get("end_inertia")])
        return naive
    e_arc = f.evaluate(sol, eps_b)
    gap = float(f.distance(naive.x, sol.x))
    f.info.update({"naive_to_followed_distance": gap, "naive_to_followed_energy": float(e_arc[0] - e_naive[0])})
    if gap <= f.s.state_tol and abs(e_arc[0] - e_naive[0]) <= max(v["tolerance"], f.s.energy_atol):
        f.info["false_alarms"] += 0 if f.info["limit_points_passed"] else 1
        log.info("branch [%g, %g]: the continuation ends in the naive step's state (distance %.3e): kept it",
                 eps_a, eps_b, gap)
        return naive
    f.info["branch_jumps"] += 1
    f.info["kept"] = "arc"
    log.warning("branch [%g, %g]: the naive step left the branch (distance %.3e, energy %+.3e N mm); the "
                "continuation's state is kept (%d limit points passed)", eps_a, eps_b, gap, e_arc[0] - e_naive[0],
                f.info["limit_points_passed"])
    return sol
