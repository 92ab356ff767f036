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
while a jump keeps the energy it releases in the half that holds it. The followed end state is compared with the naive one: when both are
the same equilibrium (``distance`` below ``state_tol`` and the energies equal within the
criterion's tolerance) the naive state is kept, so a false alarm changes no bit of the
result; otherwise the followed state replaces it (a branch jump was avoided). A sub-step at
the floor that still fails the test is a **limit point** (the branch ends; the jump is
physical) and is accepted and recorded. Every detection and retry is in the returned info.

Contract
--------
``follow_branch(solve, start, eps_a, eps_b, energy, *, inertia=None, distance=None,
settings=BranchSettings()) -> (StepSolution, info)``, with

* ``solve(start: StepSolution, eps_from, eps_to) -> StepSolution``: one step of the path's
  own algorithm (pinned Algorithm 7.1, or a periodic step) from an equilibrium at
  ``eps_from`` to one at ``eps_to``;
* ``energy(sol: StepSolution, eps) -> (Pi, Pi_eps)``: the potential of an equilibrium state
  and its load derivative;
* ``inertia(sol) -> int | None``: negative-eigenvalue count of its constrained Hessian
  (None: unknown, the inertia test is skipped);
* ``distance(x_a, x_b) -> float``: how far apart two states are (default: max |x_a - x_b|).

``info`` (JSON-ready): ``checks`` (every tested interval: eps, mismatch, tolerance,
inertia, verdict, depth), ``detections`` (tests that failed), ``converging``, ``solves``, ``branch_jumps`` (jumps avoided by
following), ``limit_points`` (jumps left at the floor), ``false_alarms``, ``kept``
(``naive`` / ``followed``). Pure arithmetic on the callables: no model is imported here.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

import numpy as np

__all__ = ["BranchSettings", "StepSolution", "detect", "follow_branch", "BRANCH_COUNTS"]

log = logging.getLogger("rve.homogenisation.branch")


#: the counters of a step's record (``follow_branch``'s info) that a table reports
BRANCH_COUNTS = ("detections", "solves", "branch_jumps", "limit_points", "false_alarms", "converging")


@dataclass(frozen=True)
class BranchSettings:
    """Tolerances of the branch test (module docstring)."""

    energy_rtol: float = 0.05       # mismatch allowed, as a fraction of the step's work
    energy_atol: float = 1e-12      # N mm: floor of the tolerance (a step without work)
    max_halvings: int = 3           # recursion depth: floor d / 2^max_halvings
    state_tol: float = 1e-6         # distance below which naive and followed states are one


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
                     "false_alarms": 0, "converging": 0,
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
                  settings: BranchSettings = BranchSettings()) -> tuple:
    """One step of the path from ``start`` (an equilibrium at ``eps_a``) to ``eps_b`` that
    stays on ``start``'s branch (module docstring). Returns ``(StepSolution, info)``."""
    f = _Follower(solve, energy, inertia, distance or _max_abs, settings)
    e_a = f.evaluate(start, eps_a)
    naive, e_naive, v = f.step(start, e_a, eps_a, eps_b, 0)
    if not v["jump"]:
        return naive, f.info
    if settings.max_halvings < 1:
        f.info["limit_points"] += 1
        return naive, f.info
    followed, e_fol = f.follow(start, e_a, eps_a, eps_b, 1, v["mismatch"])
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
