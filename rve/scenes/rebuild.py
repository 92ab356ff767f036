"""The contact-map rebuilds of the dynamic fabric scenes as ``StructureHook`` objects of
``rve.solvers.dirk.integrate`` (called after every accepted step; True restarts the step
control on the changed structure).

Contract
--------
* ``MapRebuild(system, t_end, every, guard)``: rebuild every ``every`` accepted steps and
  at once when a centroid has moved ``guard`` since the last rebuild; restart only when the
  union sparsity pattern changed. Counts ``changes``, ``early``; ``wall`` seconds.
* ``ChunkedRebuild(system, t_end, steps, every, guard, at_boundary=None)``: rebuild at the
  end of every segment of ``every`` nominal steps (``horizon``: the segment the restarted
  step control runs on) and early on the guard; every rebuild restarts.
* ``every=None`` (both): the Verlet-skin rule alone, a rebuild only when a node has moved
  ``guard`` (half the search margin, the skin) since the last one. The candidate lists are
  then still complete: a pair outside the list was farther apart than the contact
  distance plus the margin at the rebuild, and neither of its ends has moved more than
  half the margin since, so it cannot touch yet (linear elements: every point of an
  element moves at most as far as its farthest node). ``ChunkedRebuild`` then runs one
  segment to the next guard rebuild (or ``t_end``).
  ``at_boundary(t, x, w)`` runs before each rebuild and may set ``fresh`` (the restart
  then carries no factorisation or predictor history over: a checkpoint is written there);
  ``rebuild(x)`` is the initial one. Counts ``rebuilds``, ``early``; ``wall`` seconds.

``system``: a contact system with ``rebuild(x)``, ``max_displacement_since_rebuild(x)``
(and, for ``MapRebuild``, ``assembler.reused``).
"""
from __future__ import annotations

import math
import time

__all__ = ["MapRebuild", "ChunkedRebuild"]


class MapRebuild:
    """Rebuilds by accepted steps (the induced deformation): the contact map is rebuilt every
    ``every`` accepted steps (Appendix A) and at once when a centroid has moved
    ``guard`` (half the search margin) since the last rebuild; the step control restarts
    only when the rebuild changed the union sparsity pattern."""

    def __init__(self, sysm, t_end: float, every: int, guard: float):
        self.sysm, self.t_end, self.guard = sysm, float(t_end), float(guard)
        self.every = None if every is None else max(1, int(every))
        self.since, self.early, self.changes, self.wall = 0, 0, 0, 0.0

    def __call__(self, t, x, w) -> bool:
        self.since += 1
        if t >= self.t_end * (1 - 1e-12):
            return False
        early = self.guard > 0 and self.sysm.max_displacement_since_rebuild(x) > self.guard
        due = self.every is not None and self.since >= self.every
        if not (early or due):
            return False
        t0 = time.perf_counter()
        kept = self.sysm.assembler.reused
        self.sysm.rebuild(x)
        changed = self.sysm.assembler.reused == kept
        self.changes += int(changed)
        self.early += int(early and not due)
        self.since = 0
        self.wall += time.perf_counter() - t0
        return changed


class ChunkedRebuild:
    """Rebuilds on the nominal grid (the impact): the contact maps are rebuilt on segments
    of ``every`` nominal steps of the grid ``k h0`` from t = 0, and
    early when a centroid or an end node moved half the margin since the last rebuild;
    every rebuild restarts the step control. ``at_boundary(t, x, w)`` runs at every segment
    boundary before the rebuild (progress, checkpoints)."""

    def __init__(self, sysm, t_end: float, steps: int, every: int, guard: float, at_boundary=None):
        self.sysm, self.t_end, self.steps = sysm, float(t_end), int(steps)
        self.h0 = (self.t_end - 0.0) / self.steps
        self.every = None if every is None else max(1, int(every))
        self.guard, self.at_boundary = float(guard), at_boundary
        self.t_stop = None
        self.fresh = False
        self.rebuilds, self.early, self.wall = 0, 0, 0.0

    def horizon(self, t: float):
        k_cur = int(math.floor(t / self.h0 + 1e-9))
        k_b = self.steps if self.every is None else min(self.steps, k_cur + self.every)
        self.t_stop = self.t_end if k_b >= self.steps else k_b * self.h0
        return self.t_stop, max(1, k_b - k_cur)

    def rebuild(self, x) -> None:
        t0 = time.perf_counter()
        self.sysm.rebuild(x)
        self.wall += time.perf_counter() - t0
        self.rebuilds += 1

    def __call__(self, t, x, w) -> bool:
        if t >= self.t_end * (1 - 1e-12):
            return False
        early = self.guard > 0 and self.sysm.max_displacement_since_rebuild(x) > self.guard
        self.fresh = False
        if not (early or t >= self.t_stop):
            return False
        self.early += int(early)
        if self.at_boundary is not None:
            self.at_boundary(t, x, w)
        self.rebuild(x)
        return True
