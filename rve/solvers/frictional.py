"""Static steps of a system with friction: a residual Newton from the history of the last
converged step, then the history committed (docs/contact.md "Friction").

Contract
--------
Friction is path-dependent: its forces are not the gradient of an energy, so a frictional
static step cannot go through the energy minimiser (``rve.solvers.minimize``); it solves
the residual ``F(x, 0, t) = 0`` with Newton (``rve.solvers.static.static_solve``, whose
linear solves send the unsymmetric tangent to the LU path: ``rve.solvers.linear.sparse_solve``
never hands an unsymmetric matrix to a symmetric factorisation) with the friction history
of the last converged step held fixed.

* ``friction_of(system)`` -> the system's friction (an object with ``commit(x)``: the
  ``FrictionTerm`` of a contact system's term), or None for a frictionless system;
* ``frictional_static_step(system, x, w, t, newton_opts=None)`` -> ``(x, w, result,
  dissipated)``: the Newton solve, and on convergence the commit (``dissipated``: the
  energy dissipated by the step, N mm; 0.0 without convergence, the history unchanged).
"""
from __future__ import annotations

from typing import Optional

from .static import static_solve

__all__ = ["friction_of", "frictional_static_step"]


def friction_of(system):
    """The friction of ``system`` (``system.term.friction``), None when it has none."""
    term = getattr(system, "term", None)
    return getattr(term, "friction", None) if term is not None else None


def frictional_static_step(system, x, w, t: float, newton_opts: Optional[dict] = None):
    """One static step from the held friction history; commits it on convergence."""
    xs, ws, res = static_solve(system, x, w, t, newton_opts)
    dissipated = 0.0
    fr = friction_of(system)
    if res.converged and fr is not None:
        dissipated = fr.commit(xs)
    return xs, ws, res, dissipated
