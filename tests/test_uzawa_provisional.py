"""The Uzawa loop of ``rve.homogenisation.multipliers.equilibrium`` with provisional frictional
re-solves (docs/contact.md "Provisional re-solves"), on a scripted system: the re-solves whose
state only feeds a multiplier update are provisional; the state that meets the tolerance is
solved in full at its multipliers and checked again; a provisional solve that fails is
replaced by the full solve from the same start; the flags are cleared at the end; a
frictionless system never sees them."""
from __future__ import annotations

import pytest


class _Params:
    al_tolerance = 1e-4
    al_max_iter = 20
    al_penalty_growth = 1.0


class _Friction:
    def __init__(self):
        self.resolving = False
        self.provisional = False
        self.commits = []

    def commit(self, x):
        self.commits.append(x)
        return 0.0


class _System:
    """A scalar 'state' whose overlap is scripted per solve; records every update."""

    augmented = True
    params = _Params()

    def __init__(self, friction=True):
        self._friction = _Friction() if friction else None
        self.updates = []
        self.penalty = 1.0

    @property
    def friction_view(self):   # how ``friction_of`` finds a cell's friction
        return self._friction

    def max_penetration(self, x):
        return x["overlap"]

    def update_multipliers(self, x, relaxation=1.0):
        self.updates.append(x["n"])

    def set_penalty(self, P, x=None):
        self.penalty = P


class _Script:
    """``solve(x)``: the next scripted (overlap, converged); records the flags it saw."""

    def __init__(self, system, script, honours=True):
        self.system, self.script, self.honours = system, list(script), honours
        self.seen, self.starts, self.penalties, self.fallbacks = [], [], [], []

    def __call__(self, x):
        fr = self.system.friction_view
        flags = (False, False) if fr is None else (fr.resolving, fr.provisional)
        self.seen.append(flags)
        self.penalties.append(self.system.penalty)
        self.fallbacks.append(None if fr is None else getattr(fr, "fallback", True))
        self.starts.append(x["n"])
        overlap, ok = self.script.pop(0)
        info = {"converged": ok, "iterations": 1}
        if fr is not None and fr.provisional and self.honours:
            info["provisional"] = True
        return {"n": len(self.seen), "overlap": overlap}, info


def _run(system, script, honours=True):
    from rve.homogenisation.multipliers import equilibrium

    solve = _Script(system, script, honours)
    x, info = equilibrium(system, solve, {"n": 0, "overlap": 1.0})
    return x, info, solve


def test_provisional_until_the_tolerance_then_the_full_solve_checked_again():
    sysm = _System()
    x, info, solve = _run(sysm, [(1e-2, True), (1e-3, True), (5e-5, True), (2e-4, True), (1e-5, True)])
    # first solve and two re-solves provisional; the third provisional state met the
    # tolerance: the full solve at its multipliers (no update in between), whose overlap is
    # above it, so one more update and a full re-solve
    assert solve.seen == [(False, True), (True, True), (True, True), (True, False), (True, False)]
    assert sysm.updates == [1, 2, 4]
    al = info["augmented_lagrangian"]
    assert al["solves"] == 5 and al["provisional_solves"] == 3 and al["updates"] == 3 and al["met"]
    assert al["solves"] == al["updates"] + 2
    assert x["n"] == 5 and sysm.friction_view.commits == [x]
    assert sysm.friction_view.resolving is False and sysm.friction_view.provisional is False


def test_provisional_solves_that_stall_give_way_to_full_re_solves():
    """Three provisional states after the smallest overlap without a smaller one (their own
    error is the floor): the next re-solves are full, and the loop ends at the tolerance."""
    sysm = _System()
    script = [(1e-2, True), (2e-3, True), (3e-4, True), (8e-4, True), (5e-4, True), (4e-4, True),
              (2e-4, True), (5e-5, True)]
    x, info, solve = _run(sysm, script)
    assert solve.seen == [(False, True)] + [(True, True)] * 5 + [(True, False)] * 2
    al = info["augmented_lagrangian"]
    assert al["provisional_stalled"] and al["provisional_solves"] == 6 and al["met"] and x["n"] == 8
    assert sysm.friction_view.provisional is False


def test_the_full_solve_keeps_the_raised_penalty_until_the_loop_ends(monkeypatch):
    """The loop raises P* where an update leaves more than a quarter of the overlap; the full
    solve after the provisional state that met the tolerance runs at that P*, and P* is back
    at its start after the loop."""
    sysm = _System()
    monkeypatch.setattr(_Params, "al_penalty_growth", 4.0)
    x, info, solve = _run(sysm, [(1e-2, True), (8e-3, True), (5e-5, True), (6e-5, True)])
    assert solve.seen == [(False, True), (True, True), (True, True), (True, False)]
    assert solve.penalties == [1.0, 1.0, 4.0, 4.0] and sysm.penalty == 1.0


def test_a_failed_full_solve_at_a_raised_penalty_is_solved_again_at_the_configured_one(monkeypatch):
    """The full solve at the raised P* runs without the frictional fallback; where it fails,
    the same start (the provisional state) is solved again at the configured P* with it."""
    sysm = _System()
    monkeypatch.setattr(_Params, "al_penalty_growth", 4.0)
    x, info, solve = _run(sysm, [(1e-2, True), (8e-3, True), (5e-5, True), (1.0, False), (6e-5, True)])
    assert solve.seen == [(False, True), (True, True), (True, True), (True, False), (True, False)]
    assert solve.penalties == [1.0, 1.0, 4.0, 4.0, 1.0] and sysm.penalty == 1.0
    assert solve.fallbacks == [True, True, True, False, True]
    assert solve.starts[-2:] == [3, 3] and x["n"] == 5
    al = info["augmented_lagrangian"]
    assert al["retries"] == 1 and al["met"] and info["converged"]
    assert sysm.friction_view.fallback is True


def test_a_first_solve_that_meets_the_tolerance_is_solved_in_full_once():
    sysm = _System()
    x, info, solve = _run(sysm, [(1e-5, True), (2e-5, True)])
    assert solve.seen == [(False, True), (False, False)] and sysm.updates == []
    assert info["augmented_lagrangian"]["updates"] == 0 and x["n"] == 2


def test_a_failed_provisional_solve_is_replaced_by_the_full_solve_from_its_start():
    sysm = _System()
    x, info, solve = _run(sysm, [(1e-2, True), (1e-3, False), (1e-5, True)])
    assert solve.seen == [(False, True), (True, True), (True, False)]
    assert solve.starts == [0, 1, 1]          # the full re-solve from the provisional one's start
    assert sysm.updates == [1] and info["converged"] and x["n"] == 3


def test_a_solve_that_ignores_the_flag_is_a_full_solve():
    """A solve that does not report ``provisional`` (e.g. the capped-Newton polish) is taken
    as the full solve: the loop is the plain Uzawa loop."""
    sysm = _System()
    x, info, solve = _run(sysm, [(1e-2, True), (1e-5, True)], honours=False)
    assert len(solve.seen) == 2 and sysm.updates == [1] and info["augmented_lagrangian"]["provisional_solves"] == 0


def test_without_friction_or_with_the_switch_off_no_provisional_solve(monkeypatch):
    import rve.homogenisation.multipliers as multipliers

    sysm = _System(friction=False)
    x, info, solve = _run(sysm, [(1e-2, True), (1e-5, True)])
    assert solve.seen == [(False, False), (False, False)]
    monkeypatch.setattr(multipliers, "PROVISIONAL_RESOLVES", False)
    sysm = _System()
    x, info, solve = _run(sysm, [(1e-2, True), (1e-5, True)])
    assert solve.seen == [(False, False), (True, False)] and info["augmented_lagrangian"]["solves"] == 2


@pytest.mark.parametrize("last_ok", [True, False])
def test_updates_run_out_in_provisional_solves(monkeypatch, last_ok):
    """The updates exhausted by provisional solves: the full solve at the last multipliers
    still runs, and ends the loop (met: false)."""
    sysm = _System()
    monkeypatch.setattr(_Params, "al_max_iter", 2)
    x, info, solve = _run(sysm, [(1e-2, True), (1e-2, True), (1e-2, True), (1e-2, last_ok)])
    assert solve.seen[-1] == (True, False) and len(solve.seen) == 4 and sysm.updates == [1, 2]
    assert info["augmented_lagrangian"]["met"] is False and info["converged"] is last_ok
