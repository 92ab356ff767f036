"""The speed levers of the dynamic scenes (docs/engine.md "Dynamic scenes: profile and
levers"): the held factorisation and the predictor history across step-control restarts
(``reuse_across_restarts``, ``predictor_across_restarts``) and the Verlet-skin rebuild rule
(``rve.scenes.rebuild`` with ``every=None``).

A carried factorisation that no longer contracts on the restarted problem must be
refactorised (logged, counted) rather than fail the step; carrying must not change the
answer beyond the Newton tolerance; the skin rule rebuilds exactly when a node has moved
more than half the skin.
"""
import logging
import math

import numpy as np
import pytest

from rve.scenes.rebuild import ChunkedRebuild, MapRebuild
from rve.solvers.dirk import integrate, integrator_options
from test_dirk import ProtheroRobinson
from test_modified_newton import Chain

TOL = dict(atol=1e-12, rtol=1e-14)


class Restarts:
    """A ``StructureHook`` reporting a structure change after the steps ending at ``times``
    (and calling ``action(t)`` there first)."""

    def __init__(self, times, action=None):
        self.times, self.action, self.calls = list(times), action, 0

    def __call__(self, t, x, w) -> bool:
        if any(abs(t - s) < 1e-9 for s in self.times):
            self.calls += 1
            if self.action is not None:
                self.action(t)
            return True
        return False


class StiffAfterRestart(ProtheroRobinson):
    """Prothero-Robinson (y = sin t exactly) whose stiffness λ jumps to ``lam_on`` when the
    hook restarts the step control at t = 0.5: the factorisation carried over the restart is
    the soft one (1 + 5h) against the stiff stage matrix 1 - h λ_on."""

    def __init__(self, lam_on):
        super().__init__(-5.0)
        self.lam_on = lam_on

    def switch(self, t):
        self.lam = self.lam_on


def _run(sysm, hook, n, stages, **flat):
    x0 = np.zeros(sysm.n) if not hasattr(sysm, "initial") else sysm.initial()[0]
    w0 = np.zeros(sysm.n) if not hasattr(sysm, "initial") else sysm.initial()[1]
    return integrate(sysm, x0, w0, 0.0, 1.0, n, stages=stages, newton_opts=TOL, rebuild=hook,
                     **integrator_options(**flat))


@pytest.mark.parametrize("lam_on, reason", [(-41.0, "contraction"), (-5000.0, "diverged")])
def test_stale_factorisation_carried_over_a_restart_is_refactorised_not_failed(lam_on, reason, caplog):
    """Backward Euler, h = 1/40, a restart at t = 0.5 where λ jumps: the carried factor
    gives θ = |1 - (1 - hλ_on)/(1 + 5h)| = 0.8 (λ_on = -41: a contraction above the
    threshold, dropped after that iteration) or 110 (-5000: the modified step diverges and
    is redone with a fresh Jacobian). No step is rejected and the answer is full Newton's."""
    runs = {}
    for carry in (False, True):
        sysm = StiffAfterRestart(lam_on)
        hook = Restarts([0.5], sysm.switch)
        with caplog.at_level(logging.INFO, logger="rve"):
            runs[carry] = _run(sysm, hook, 40, 1, jacobian_reuse=True, reuse_across_restarts=carry)
        assert hook.calls == 1 and runs[carry].restarts == 1
    ref = StiffAfterRestart(lam_on)
    full = _run(ref, Restarts([0.5], ref.switch), 40, 1)   # full Newton
    mod = runs[True]
    assert mod.rejected == 0 and mod.stage_retries == 0
    assert mod.refactor_reasons.get(reason, 0) >= 1, mod.refactor_reasons
    assert runs[False].refactor_reasons.get(reason, 0) == 0, runs[False].refactor_reasons
    np.testing.assert_allclose(mod.w, full.w, atol=1e-10)
    np.testing.assert_allclose(runs[False].w, full.w, atol=1e-10)
    assert abs(mod.w[0] - math.sin(1.0)) < 0.05
    assert "theta=" in caplog.text


def test_carry_over_a_harmless_restart_saves_factorisations_and_keeps_the_answer():
    """Chain (banded), SDIRK2, restarts every 5 steps that change nothing: the carried
    factorisation and predictor history serve across them; the states agree with the run
    without carry to the Newton tolerance, with fewer factorisations (bought with more
    modified iterations on the older factorisation)."""
    times = [k / 40 for k in range(5, 40, 5)]
    base = _run(Chain(), Restarts(times), 40, 2, jacobian_reuse=True)
    carry = _run(Chain(), Restarts(times), 40, 2, jacobian_reuse=True, reuse_across_restarts=True,
                 predictor_across_restarts=True)
    assert base.restarts == carry.restarts == len(times)
    np.testing.assert_allclose(carry.x, base.x, atol=1e-10)
    np.testing.assert_allclose(carry.w, base.w, atol=1e-10)
    assert carry.factorizations < base.factorizations
    # the exact solution is reached to the discretisation error of both
    x_ex, _ = Chain().exact(1.0)
    assert np.abs(carry.x - x_ex).max() < 1e-3


def test_predictor_across_restarts_only_moves_newtons_start():
    """Full Newton (no reuse): carrying the predictor history changes the iteration counts
    of the first step after each restart, never the states beyond the Newton tolerance."""
    times = [k / 40 for k in range(4, 40, 4)]
    a = _run(Chain(), Restarts(times), 40, 2)
    b = _run(Chain(), Restarts(times), 40, 2, predictor_across_restarts=True)
    np.testing.assert_allclose(b.x, a.x, atol=1e-11)
    assert b.newton_iterations < a.newton_iterations


class Mover:
    """A contact-like system for the rebuild hooks: ``rebuild(x)`` records x, the displacement
    since is the largest |x - x_rebuild|."""

    def __init__(self):
        self.x_rebuild, self.rebuilds = None, 0

    def rebuild(self, x):
        self.x_rebuild, self.rebuilds = np.array(x, float), self.rebuilds + 1

    def max_displacement_since_rebuild(self, x):
        return float(np.abs(np.asarray(x) - self.x_rebuild).max())


def test_skin_rule_rebuilds_exactly_when_a_node_moved_half_the_skin():
    """``ChunkedRebuild(every=None)``: one segment to t_end, a rebuild (and restart) only
    once a node moved more than the guard; ``every=5`` also rebuilds every 5 steps."""
    sysm = Mover()
    hook = ChunkedRebuild(sysm, 1.0, 100, None, 0.15)
    hook.rebuild(np.zeros(1))
    assert hook.horizon(0.0) == (1.0, 100)
    fired = [t for k in range(1, 100) for t in [k / 100] if hook(t, np.array([0.02 * k]), None)]
    # x = 0.02 k: 0.14 < guard 0.15 after 7 steps, 0.16 after 8: a rebuild every 8 steps
    assert fired == pytest.approx([0.08 * m for m in range(1, 13)])
    assert hook.early == len(fired) and sysm.rebuilds == 1 + len(fired)
    periodic = ChunkedRebuild(Mover(), 1.0, 100, 5, 0.15)
    periodic.rebuild(np.zeros(1))
    assert periodic.horizon(0.0) == (pytest.approx(0.05), 5)


def test_skin_rule_of_map_rebuild():
    """``MapRebuild(every=None)``: no rebuild while every node stays within the guard."""

    class Assembler:
        reused = 0

    sysm = Mover()
    sysm.assembler = Assembler()
    sysm.rebuild(np.zeros(1))
    hook = MapRebuild(sysm, 1.0, None, 0.1)
    at = [k for k in range(1, 20) if hook(k / 50, np.array([0.03 * k]), None)]
    # moves 0.03 per step: 0.09 < guard 0.1 after 3 steps, 0.12 after 4: a rebuild every 4 steps
    assert at == [4, 8, 12, 16]
    assert hook.early == sysm.rebuilds - 1 == 4
