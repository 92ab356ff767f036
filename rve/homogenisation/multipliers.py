"""Augmented Lagrangian contact multipliers along the RVE's strain path (``contact.enforcement:
augmented_lagrangian``; docs/contact.md "Augmented Lagrangian in the RVE pipeline").

Contract
--------
A relaxation or strain step builds a new system for each phase (driven dynamics, damped
relaxation, static solve; the periodic cell one per step). The multipliers are per contact
point, keyed by the point (``contact_pairs.point_keys``), so they pass from one system to the
next by key, and from one step to the next through the checkpoint. With the penalty
(``enforcement: penalty``) every function here is a no-op that leaves the solve and its
record untouched, so the penalty path is bit-identical.

* :func:`multiplier_record` ``(system) -> (keys (n, 6) int64, values (n,)) | None``: the
  multipliers of a ``ContactSystem`` or ``PeriodicSystem`` at its current map.
* :func:`seed_multipliers` ``(system, record)``: the system's multipliers from a record (by
  key; points not in it start at 0). No-op for None or a penalty system.
* :func:`equilibrium` ``(system, solve, x) -> (x, info)``: ``solve(x) -> (x, info)`` (a static
  solve) wrapped in the Uzawa loop ``rve.solvers.augmented.solve_with_multipliers`` until the
  largest true overlap is below ``contact.al_tolerance`` R. The info of the last solve, plus
  ``info["augmented_lagrangian"]`` (updates, the overlap history, whether the tolerance was
  met, the P* of every re-solve, ``relaxed_from``, every solve's iterations and wall time);
  with the penalty, one call of ``solve`` and its info as it is. A frictionless loop relaxes
  its updates once it cycles (``AugmentedLagrangian``); a frictional one keeps the plain
  updates. A solve that did not converge ends the loop (the multipliers of an unconverged
  state are not updated). The
  step's ``converged`` stays the solve's (an equilibrium at the current multipliers); an
  overlap still above the tolerance (``al_max_iter`` reached) is ``met: false`` and a warning.

  **Friction** (``rve.solvers.system.friction_of(system)`` not None): ``solve`` must not commit
  the friction history (``cell_statics.static_minimize(..., commit=False)``); ``equilibrium``
  commits it once, at the converged solve's state after the loop (P* back at its configured
  value, the line loads unchanged: the commit changes no force), and records the energy it
  dissipated as ``info["dissipated"]``. So every Uzawa re-solve of a step is the frictional
  solve from the same held history, that of the last committed state (the previous step or
  sub-increment): a multiplier update moves the normal loads, not the load path, and a commit
  inside the loop would turn each update into a backward-Euler step of its own. With the
  penalty the single solve is committed the same way. An unconverged solve is not committed.
  The re-solves (after the first update) run with ``fr.resolving`` set: ``frictional_solve``
  then takes its predictor in rounds of converged minimisations at fixed loads
  (``rve.solvers.frictional.RESOLVE_ROUNDS``) instead of refreezing the loads at every
  accepted iterate, which diverges at the raised P*, the first round at the loads of the
  previous converged solve (kept by ``frictional_solve`` before the update, ``FrictionTerm.
  hold_loads``; docs/contact.md "Friction with the augmented Lagrangian and the periodic
  cell").

  **Provisional solves** (``PROVISIONAL_RESOLVES``, friction only): every solve of the loop
  whose state only feeds a multiplier update is provisional (``FrictionTerm.provisional``:
  ``frictional_solve`` takes its first predictor stage alone and the solve reports
  ``info["provisional"]``): the first solve and the re-solves, until a provisional state
  meets the tolerance (or the updates run out). That state's equilibrium at its multipliers
  and P* (not yet back at the configured one) is then solved in full and checked again; the
  loop goes on with full re-solves where it does not meet the tolerance, and also once the
  provisional solves stall (``provisional_stalled``: ``PROVISIONAL_STALL`` updates at the final
  P* without a smaller overlap; ``info["augmented_lagrangian"]["provisional_stalled"]``). A provisional solve
  that fails is replaced by the full solve from its start. Where the loop had raised P*,
  that full solve runs without the frictional fallback (``FrictionTerm.fallback``), and if
  it fails it is solved again from the same start at the configured P* (the line loads
  kept), with the fallback (``info["augmented_lagrangian"]["retries"]``). A solve that does
  not report ``provisional`` (one that does not call ``frictional_solve``) is a full solve,
  and the loop is the plain one.
  ``info["augmented_lagrangian"]["provisional_solves"]`` counts them (docs/contact.md
  "Provisional re-solves").
"""
from __future__ import annotations

import logging
import time

from ..solvers.augmented import AugmentedLagrangian
from ..solvers.system import friction_of

__all__ = ["multiplier_record", "seed_multipliers", "equilibrium"]

log = logging.getLogger("rve.homogenisation.multipliers")

#: the frictional solves whose state only feeds a multiplier update are provisional: the
#: first predictor stage alone (``FrictionTerm.provisional``); the state that meets the
#: tolerance is then solved in full at its multipliers and checked again (module docstring)
PROVISIONAL_RESOLVES = True

#: provisional solves end, and the loop goes on with full re-solves, once this many
#: consecutive updates at the final P* have not lowered the smallest overlap of the updates
#: at that P*: the provisional states' own error is then the floor of the overlap
PROVISIONAL_STALL = 3


def provisional_stalled(loop, stall: int = PROVISIONAL_STALL) -> bool:
    """True when, of the solves of the Uzawa ``loop`` (``AugmentedLagrangian``) at the P* of
    its next solve, the last ``stall`` have none of their overlaps below the smallest of
    the ones before them at that P*."""
    if not loop.penalties:
        return False
    # the P* each overlap of the history was solved at: P*0, then P* after each update
    solved_at = [loop.penalty0] + list(loop.penalties[:len(loop.history) - 1])
    run = []
    for (_, pen), P in zip(reversed(loop.history), reversed(solved_at)):
        if P != loop.penalties[-1]:
            break
        run.append(pen)
    run.reverse()
    if len(run) <= stall:
        return False
    return min(run[-stall:]) >= min(run[:-stall])


def _term(system):
    full = getattr(system, "full", system)   # a PeriodicSystem holds the ContactSystem as .full
    return full.term


def multiplier_record(system):
    """``(keys, values)`` of the system's contact multipliers, or None (penalty)."""
    if not getattr(system, "augmented", False):
        return None
    return _term(system).multiplier_record()


def seed_multipliers(system, record) -> None:
    """The multipliers of ``system``'s current map from ``record`` (module docstring)."""
    if record is None or not getattr(system, "augmented", False):
        return
    keys, values = record
    _term(system).seed_multipliers(keys, values)


def equilibrium(system, solve, x):
    """``solve`` in the Uzawa loop, then the friction commit (module docstring); ``(x, info)``."""
    if not getattr(system, "augmented", False):
        x, info = solve(x)
        return x, _commit(system, x, info)
    fr = friction_of(system)
    # a frictional loop keeps the plain updates: its overlaps move with the friction's
    # re-solves as well, and relaxed updates stalled it (docs/contact.md "Relaxed updates")
    loop = AugmentedLagrangian(system, relaxation=None if fr is None else 1.0)
    run = _Solves(solve)
    try:
        x, info = _uzawa(loop, fr, run, x)
    finally:
        if fr is not None:
            fr.resolving = fr.provisional = False
            fr.fallback = True
    loop.finish(x)
    pen = float(system.max_penetration(x))
    info = dict(info)
    info["augmented_lagrangian"] = {
        "updates": int(loop.updates), "solves": run.solves, "tolerance": float(loop.tolerance),
        "max_penetration_over_R": pen, "met": bool(pen <= loop.tolerance),
        "penalties": [float(p) for p in loop.penalties], "relaxed_from": loop.relaxed_from,
        "solve_iterations": run.iterations,
        "provisional_solves": run.provisional, "provisional_stalled": run.stalled, "retries": run.retries,
        "solve_wall_s": [float(t) for t in run.walls],
        "history": [[int(k), float(p)] for k, p in loop.history]}
    if pen > loop.tolerance:   # an equilibrium at these multipliers, not yet the impenetrable limit
        log.warning("augmented Lagrangian: largest overlap %.2e R above al_tolerance %.1e R after %d updates%s",
                    pen, loop.tolerance, loop.updates, "" if info.get("converged") else " (the solve did not converge)")
    return x, _commit(system, x, info)


class _Solves:
    """``solve`` counted: solves, provisional ones, retries, iterations and wall time of each."""

    def __init__(self, solve):
        self.solve = solve
        self.solves = self.provisional = self.retries = 0
        self.iterations, self.walls = [], []
        #: True once the provisional solves stalled (``provisional_stalled``)
        self.stalled = False

    def __call__(self, x):
        t0 = time.perf_counter()
        x, info = self.solve(x)
        self.solves += 1
        self.provisional += int(bool(info.get("provisional", False)))
        self.iterations.append(info.get("iterations"))
        self.walls.append(time.perf_counter() - t0)
        return x, info


def _uzawa(loop, fr, run, x):
    """The solves and updates of ``equilibrium`` (module docstring); ``(x, info)`` of the last
    solve."""
    if fr is not None and PROVISIONAL_RESOLVES:
        fr.provisional = True
    retry = None      # the start of a full solve at a raised P*, to solve again at the configured one
    while True:
        if fr is not None:
            # a full solve that is retried at the configured P* goes without the fallback
            fr.fallback = retry is None
        x0 = x
        x, info = run(x)
        if info.get("provisional", False):
            if not info.get("converged", False):
                x, fr.provisional = x0, False       # the full re-solve from the same start
            elif loop.update(x, finish=False) or loop.exhausted:
                # the provisional state met the tolerance (or the updates ran out): the
                # equilibrium at these multipliers and P*, solved in full and checked again (at
                # the configured P* the cell is softer against the friction's change from the
                # provisional loads, and the overlap rises above the tolerance again)
                fr.provisional = False
                retry = x if loop.raised else None
            else:
                fr.resolving = True
                if provisional_stalled(loop):
                    log.info("augmented Lagrangian: %d provisional updates at P* = %g without a smaller overlap "
                             "(%.2e R): full re-solves from here", PROVISIONAL_STALL, loop.system.penalty,
                             loop.history[-1][1])
                    fr.provisional = False
                    run.stalled = True
            continue
        if not info.get("converged", False):
            if retry is None:
                return x, info
            log.info("augmented Lagrangian: the full solve at P* = %g failed (%s); again from the same start at "
                     "the configured P*", loop.system.penalty, info.get("reason", ""))
            loop.finish(retry)
            x, retry = retry, None
            run.retries += 1
            continue
        retry = None
        if loop.update(x) or loop.exhausted:
            return x, info
        if fr is not None:   # the re-solves (module docstring)
            fr.resolving = True


def _commit(system, x, info):
    """The friction history committed at a converged solve's ``x`` (module docstring)."""
    fr = friction_of(system)
    if fr is None or not info.get("converged", False):
        return info
    info = dict(info)
    info["dissipated"] = float(fr.commit(x))
    return info
