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

The system needs (the protocol, no model imported here): ``augmented`` (bool),
``max_penetration(x) -> float`` (largest true overlap over min(R+, R-)),
``update_multipliers(x)``, and ``params.al_tolerance`` / ``params.al_max_iter`` for the
defaults. A system with ``augmented`` False is converged at once (no update), so a caller
can wrap every solve unconditionally.

* ``AugmentedLagrangian(system, tolerance=None, max_updates=None)``: ``update(x) -> bool``
  at a converged solve's state: True when the penetration is below the tolerance (the
  multipliers are left as they are), else one Uzawa update and False (solve again from
  ``x``). ``history`` lists ``(updates, max_penetration)`` of every check;
  ``exhausted`` is True once ``max_updates`` updates were made without convergence.
* ``solve_with_multipliers(system, solve, x, tolerance=None, max_updates=None)``: repeats
  ``x = solve(x)`` with updates in between; returns ``(x, loop)``. ``solve`` returns the new
  state (a position vector ``x`` of the system) or a tuple whose first item is it.
"""
from __future__ import annotations

from typing import Callable, Optional

__all__ = ["AugmentedLagrangian", "solve_with_multipliers"]


class AugmentedLagrangian:
    def __init__(self, system, tolerance: Optional[float] = None, max_updates: Optional[int] = None):
        self.system = system
        params = getattr(system, "params", None)
        self.tolerance = float(tolerance if tolerance is not None else getattr(params, "al_tolerance", 1e-4))
        self.max_updates = int(max_updates if max_updates is not None else getattr(params, "al_max_iter", 20))
        if not self.tolerance > 0:
            raise ValueError(f"tolerance must be > 0, got {self.tolerance}")
        self.updates = 0
        self.history: list = []
        self.exhausted = False

    @property
    def active(self) -> bool:
        return bool(getattr(self.system, "augmented", False))

    def update(self, x) -> bool:
        """True when the state ``x`` meets the tolerance (or the system has no multipliers);
        otherwise one Uzawa update and False (False with ``exhausted`` when no update is
        left: the caller stops and reports)."""
        if not self.active:
            return True
        pen = float(self.system.max_penetration(x))
        self.history.append((self.updates, pen))
        if pen <= self.tolerance:
            return True
        if self.updates >= self.max_updates:
            self.exhausted = True
            return False
        self.system.update_multipliers(x)
        self.updates += 1
        return False


def solve_with_multipliers(system, solve: Callable, x, tolerance: Optional[float] = None,
                           max_updates: Optional[int] = None):
    """``x = solve(x)`` until the Uzawa loop converges (module docstring); ``(x, loop)``.
    The last item ``solve`` returned is ``loop.last`` (e.g. the Newton result)."""
    loop = AugmentedLagrangian(system, tolerance, max_updates)
    while True:
        out = solve(x)
        loop.last = out
        x = out[0] if isinstance(out, tuple) else out
        if loop.update(x) or loop.exhausted:
            return x, loop
