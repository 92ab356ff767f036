"""The stop rules of the frictional predictor's rounds (``rve.solvers.frictional._predictor``
with ``refreeze=False``; docs/contact.md "When a re-solve's rounds hand over to the
corrector"), on a scripted friction and minimiser: the rounds end where the loads change by
at most ``load_rtol``, where the exact |F| meets the stage's tolerance, where a round's load
change jumps to more than ``LOAD_JUMP`` times the round before's (a point flipped, and more
rounds cycle), or at ``max_rounds``; a re-solve of the Uzawa loop hands over at
``RESOLVE_LOAD_RTOL`` and lets its retry's rounds settle the loads to
``RESOLVE_RETRY_LOAD_RTOL``."""
from __future__ import annotations

import numpy as np
import pytest

import rve.solvers.frictional as frictional
import rve.solvers.minimize as minimize


class _Friction:
    """What ``_predictor`` asks of a friction term: one point, its loads fixed (the rounds'
    load changes are scripted through ``_load_change``)."""

    def __init__(self):
        self.keys = np.zeros((1, 6), np.int64)
        self.smoothing = 0.0

    def freeze(self, x):
        pass

    def freeze_held(self):
        return False

    def blend_frozen(self, keys, f0, weight):
        pass

    def frozen_loads(self):
        return {"f0": np.ones((1, 1))}

    def unfreeze(self):
        pass


class _System:
    def rebuild(self, x):
        pass


class _Result:
    converged, iterations = True, 2


def _rounds(monkeypatch, changes, residuals=None, load_rtol=0.01, max_rounds=8, ptol=1e-9):
    """Runs ``_predictor`` in rounds with each round's load change (and exact |F|) scripted;
    returns the number of rounds taken."""
    changes = list(changes)
    residuals = list(residuals) if residuals is not None else [1.0] * len(changes)
    calls = {"n": 0}

    def fake_minimize(system, x, t, **kw):
        calls["n"] += 1
        return x + 1.0, None, _Result()

    monkeypatch.setattr(minimize, "minimize_energy", fake_minimize)
    monkeypatch.setattr(frictional, "_load_change", lambda fr, x: changes[calls["n"] - 1])
    monkeypatch.setattr(frictional, "_exact_residual", lambda system, x, t: residuals[calls["n"] - 1])
    out = frictional.FrictionalResult(None, False, 0, [1.0])
    frictional._predictor(_System(), _Friction(), 0.0, 0.0, out, ptol, 1e-14, 50, False, max_rounds, load_rtol,
                          None, None, None, 0.0, 0.5)
    assert out.rounds == calls["n"] and out.load_changes == changes[:out.rounds]
    return out.rounds


def test_rounds_end_where_the_loads_settle_below_load_rtol(monkeypatch):
    # the uniaxial step's final solve: 4.3 %, 5.7 % (no jump: < 2 x), 2.1 %, 1 %
    assert _rounds(monkeypatch, [0.043, 0.057, 0.021, 0.01, 0.005]) == 4
    assert _rounds(monkeypatch, [0.043, 0.057, 0.021, 0.01, 0.005], load_rtol=0.05) == 1


def test_rounds_end_where_the_exact_residual_meets_the_tolerance(monkeypatch):
    assert _rounds(monkeypatch, [0.2, 0.15, 0.12, 0.1], residuals=[1e-3, 1e-6, 1e-12, 1e-12], ptol=1e-9) == 3


def test_a_jump_of_the_load_change_ends_the_rounds(monkeypatch):
    # a point flipping on and off: the change halves with the blend, then jumps back
    assert _rounds(monkeypatch, [0.071, 0.049, 0.30, 0.15, 0.075, 0.037]) == 3
    # exactly twice the round before's is not yet a jump
    assert _rounds(monkeypatch, [0.1, 0.2, 0.005]) == 3
    monkeypatch.setattr(frictional, "LOAD_JUMP", np.inf)
    assert _rounds(monkeypatch, [0.071, 0.049, 0.30, 0.15, 0.075, 0.037, 0.009]) == 7


def test_rounds_stop_at_max_rounds(monkeypatch):
    assert _rounds(monkeypatch, [0.1, 0.09, 0.08, 0.07, 0.06, 0.055], max_rounds=4) == 4


@pytest.mark.parametrize("resolve", [True, False])
def test_a_re_solve_hands_over_at_its_load_tolerance_and_its_retry_rounds_settle_the_loads(monkeypatch, resolve):
    """A re-solve's rounds hand over to the corrector at ``RESOLVE_LOAD_RTOL`` and, after that
    corrector failed, the retry's rounds go on to ``RESOLVE_RETRY_LOAD_RTOL``. Any other solve:
    ``LOAD_RTOL`` in both passes."""
    predictors, correctors = [], []

    def spied_predictor(system, fr, x, t, out, ptol, rtol, max_iter, refreeze, max_rounds, load_rtol, *rest):
        predictors.append(load_rtol)
        return x

    def spied_corrector(system, x, t, out, atol, rtol, corrector_iter, backend, *rest, **kw):
        correctors.append(x)
        ok = len(correctors) == 2
        return x, frictional.NewtonResult(x if ok else None, ok, 1, [1.0, 0.5], "" if ok else "stalled")

    fr = _Friction()
    fr.resolving, fr.provisional, fr._committed_loads = resolve, False, None
    system = _System()
    system.augmented = False
    monkeypatch.setattr(frictional, "friction_of", lambda s: fr)
    monkeypatch.setattr(frictional, "_predictor", spied_predictor)
    monkeypatch.setattr(frictional, "_corrector", spied_corrector)
    monkeypatch.setattr(frictional, "_exact_residual", lambda system, x, t: 1.0)
    monkeypatch.setattr(frictional, "RESOLVE_SMOOTHING", None)
    xs, out = frictional.frictional_solve(system, 0.0, smoothing=())
    assert out.converged and len(predictors) == 2 and len(correctors) == 2
    if resolve:
        assert predictors == [frictional.RESOLVE_LOAD_RTOL, frictional.RESOLVE_RETRY_LOAD_RTOL]
        assert frictional.RESOLVE_RETRY_LOAD_RTOL < frictional.RESOLVE_LOAD_RTOL < frictional.LOAD_RTOL
    else:
        assert predictors == [frictional.LOAD_RTOL] * 2
