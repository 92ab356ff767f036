"""Augmented Lagrangian (Uzawa) loop around an equilibrium solve of a contact system
(docs/contact.md "Augmented Lagrangian").

Contract
--------
The system carries per contact point a multiplier lambda (a line load, N/mm); its penalty
law acts on the shifted overlap ``g + lambda/P*``, so at fixed multipliers a solve is the
penalty problem and its Newton iterations are unchanged. Between solves the multipliers are
updated, ``lambda <- max(0, lambda + P* g)`` (g the true overlap), until the largest true
overlap is below ``tolerance`` times the radius: the converged state is the impenetrable
limit up to that tolerance, whatever P* is.

**Penalty increase** (the method of multipliers' rule): the Uzawa step is P*, and a
contact point much stiffer than P* closes its overlap by only a fraction ~P*/k per update
(linear convergence, or a limit cycle where the solves switch between neighbouring
equilibria). So when an update has not reduced the largest overlap below ``decrease``
(0.25) times the one before, P* is multiplied by ``growth`` (default
``params.al_penalty_growth``, 4), at most up to ``max_growth`` (1e3) times the system's P*
at the start (the last raise ends at that cap); the multipliers are kept (the line load at
zero overlap is unchanged). When the loop ends (converged, exhausted, or stopped by
the caller: ``finish``) P* returns to its starting value with the multipliers re-expressed
so that every point's line load at the final state is unchanged: the state stays the
equilibrium it is, at the configured P*. ``growth=1`` is the plain Uzawa loop.

**Relaxed updates** once the loop cycles: when P* can grow no further and the last
``stall`` (2) checks found no overlap below ``STALL_DECREASE`` (0.75) times the smallest
before them while one of them rose above the check before it (a zigzag), every later update
of the loop is under-relaxed, ``lambda <- w max(0, lambda + P* g) + (1 - w) lambda`` with
``w = relaxation`` (0.5; ``relaxed_from`` the update it started at); where the relaxed
updates zigzag again (the same test on the checks since), ``w`` is multiplied by
``relaxation`` once more, down to ``relaxation ** RELAXATION_HALVINGS`` (0.125). Why: on
the fine periodic cells the loop settled into a two-cycle at the largest P* (overlap 3.0e-4
/ 3.6e-4 R for 14 updates): two sets of points on one fibril take turns, the multipliers of
one set push the fibril off it onto the other, and the full update then drops the first
set's multipliers to zero. The cycle is an eigenvalue of the update near -1, which w = 0.5
takes to about 0: each relaxed update halved the overlap (docs/contact.md "Relaxed updates
when the loop cycles"). ``relaxation=1`` keeps the plain updates; None takes
``RELAXATION`` at construction.

The system needs (the protocol, no model imported here): ``augmented`` (bool),
``max_penetration(x) -> float`` (largest true overlap over min(R+, R-)),
``update_multipliers(x, relaxation)`` (the update's weight, 1 for the plain update),
``penalty`` / ``set_penalty(P, x=None)`` (for the increase), and
``params.al_tolerance`` / ``params.al_max_iter`` for the defaults. A system with
``augmented`` False is converged at once (no update), so a caller can wrap every solve
unconditionally.

* ``AugmentedLagrangian(system, tolerance=None, max_updates=None, growth=None, decrease=0.25,
  max_growth=1e3, relaxation=None, stall=2)``: ``update(x, finish=True) -> bool``
  at a converged solve's state: True when the penetration is below the tolerance (the
  multipliers are left as they are; P* back to its start unless ``finish=False``), else one
  Uzawa update and False (solve again from ``x``). ``history`` lists ``(updates,
  max_penetration)`` of every check;
  ``exhausted`` is True once ``max_updates`` updates were made without convergence;
  ``penalties`` the P* of every solve after an update; ``raised`` whether P* is above its
  start; ``finish(x)`` returns to the starting P* (called by ``update`` when it ends the
  loop; idempotent).
* ``solve_with_multipliers(system, solve, x, tolerance=None, max_updates=None, **options)``: repeats
  ``x = solve(x)`` with updates in between; returns ``(x, loop)``. ``solve`` returns the new
  state (a position vector ``x`` of the system) or a tuple whose first item is it.
"""
from __future__ import annotations

from typing import Callable, Optional

__all__ = ["AugmentedLagrangian", "solve_with_multipliers"]


#: the method of multipliers' penalty increase (module docstring)
PENALTY_GROWTH = 4.0
SUFFICIENT_DECREASE = 0.25
MAX_PENALTY_GROWTH = 1e3
#: the relaxed updates of a cycling loop (module docstring)
RELAXATION = 0.5
STALL_UPDATES = 2
STALL_DECREASE = 0.75
RELAXATION_HALVINGS = 3


class AugmentedLagrangian:
    def __init__(self, system, tolerance: Optional[float] = None, max_updates: Optional[int] = None,
                 growth: Optional[float] = None, decrease: float = SUFFICIENT_DECREASE,
                 max_growth: float = MAX_PENALTY_GROWTH, relaxation: Optional[float] = None,
                 stall: int = STALL_UPDATES):
        self.system = system
        params = getattr(system, "params", None)
        self.tolerance = float(tolerance if tolerance is not None else getattr(params, "al_tolerance", 1e-4))
        self.max_updates = int(max_updates if max_updates is not None else getattr(params, "al_max_iter", 20))
        if not self.tolerance > 0:
            raise ValueError(f"tolerance must be > 0, got {self.tolerance}")
        growth = float(growth if growth is not None else getattr(params, "al_penalty_growth", PENALTY_GROWTH))
        if not (growth >= 1 and 0 < decrease < 1 and max_growth >= 1):
            raise ValueError(f"need growth >= 1, 0 < decrease < 1, max_growth >= 1; got {growth}, {decrease}, "
                             f"{max_growth}")
        self.growth, self.decrease, self.max_growth = float(growth), float(decrease), float(max_growth)
        relaxation = RELAXATION if relaxation is None else relaxation
        if not (0 < relaxation <= 1 and int(stall) >= 1):
            raise ValueError(f"need 0 < relaxation <= 1 and stall >= 1; got {relaxation}, {stall}")
        self.relaxation, self.stall = float(relaxation), int(stall)
        #: the update from which the updates are relaxed (None: plain updates so far)
        self.relaxed_from: Optional[int] = None
        #: the weight of the updates now (1: plain), and the check from which cycling is judged
        self.weight, self._since = 1.0, 0
        self.updates = 0
        self.history: list = []
        self.penalties: list = []
        self.exhausted = False
        self.penalty0 = float(system.penalty) if self.active and hasattr(system, "penalty") else None

    @property
    def active(self) -> bool:
        return bool(getattr(self.system, "augmented", False))

    def update(self, x, finish: bool = True) -> bool:
        """True when the state ``x`` meets the tolerance (or the system has no multipliers);
        otherwise one Uzawa update (and the penalty increase where it is due) and False
        (False with ``exhausted`` when no update is left: the caller stops and reports).
        ``finish=False``: P* is left as it is where the loop ends (the caller solves once
        more at these multipliers and P*, and checks again)."""
        if not self.active:
            return True
        pen = float(self.system.max_penetration(x))
        self.history.append((self.updates, pen))
        if pen <= self.tolerance:
            if finish:
                self.finish(x)
            return True
        if self.updates >= self.max_updates:
            self.exhausted = True
            if finish:
                self.finish(x)
            return False
        if self._cycling():
            if self.relaxed_from is None:
                self.relaxed_from = self.updates
            self.weight = max(self.weight * self.relaxation, self.relaxation ** RELAXATION_HALVINGS)
            self._since = len(self.history) - 1
        self.system.update_multipliers(x, self.weight)
        self.updates += 1
        if (self.penalty0 is not None and self.growth > 1 and len(self.history) > 1
                and pen > self.decrease * self.history[-2][1]):
            P, cap = float(self.system.penalty), self.max_growth * self.penalty0
            if P < cap * (1 - 1e-12):
                # the last raise stops at the cap rather than short of it
                self.system.set_penalty(min(P * self.growth, cap))
        if self.penalty0 is not None:
            self.penalties.append(float(self.system.penalty))
        return False

    def _cycling(self) -> bool:
        """P* can grow no further, and the last ``stall`` checks found no overlap below
        ``STALL_DECREASE`` times the smallest before them, one of them a rise (a zigzag). A
        loop that falls slowly but steadily keeps the plain updates, which relaxing would
        slow."""
        if self.relaxation >= 1.0 or self.penalty0 is None:
            return False
        P = float(self.system.penalty)
        if self.growth > 1 and P < self.max_growth * self.penalty0 * (1 - 1e-12):
            return False
        pens = [p for _, p in self.history[self._since:]]
        if len(pens) <= self.stall:
            return False
        recent = pens[-self.stall - 1:]
        rose = any(b > a for a, b in zip(recent, recent[1:]))
        return rose and min(recent[1:]) > STALL_DECREASE * min(pens[:-self.stall])

    @property
    def raised(self) -> bool:
        """True while P* is above its starting value (the penalty increase)."""
        return self.penalty0 is not None and float(self.system.penalty) != self.penalty0

    def finish(self, x) -> None:
        """P* back to its starting value, the line loads at ``x`` kept (module docstring)."""
        if self.penalty0 is not None and float(self.system.penalty) != self.penalty0:
            self.system.set_penalty(self.penalty0, x)


def solve_with_multipliers(system, solve: Callable, x, tolerance: Optional[float] = None,
                           max_updates: Optional[int] = None, **options):
    """``x = solve(x)`` until the Uzawa loop converges (module docstring); ``(x, loop)``.
    The last item ``solve`` returned is ``loop.last`` (e.g. the Newton result); ``options``:
    ``AugmentedLagrangian``'s other keywords."""
    loop = AugmentedLagrangian(system, tolerance, max_updates, **options)
    while True:
        out = solve(x)
        loop.last = out
        x = out[0] if isinstance(out, tuple) else out
        if loop.update(x) or loop.exhausted:
            return x, loop
