"""Fault injection, solvers: every time loop ends. Toy systems with a known
exact solution whose stage solves fail in a controlled way: a Zeno system whose admissible
step shrinks to zero (the livelock of the dynamic wire: tiny accepted steps reset the cut
counter), the rejection and wall-time budgets, and the minimiser's budgets. The real
livelocks (dynamic wire at +-200 V and alpha_mu = -100 MPa/K) are in
tests/test_faults_livelock.py."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.dirk import Budgets, IntegrationFailure, StepControl, integrate
from rve.solvers.minimize import minimize_energy

pytestmark = pytest.mark.faults


class Zeno:
    """y' = 1 (exact y = t) whose stage residual is NaN when the Newton start is more than
    the remaining distance to ``t_star`` from the stage time: accepted steps shrink
    geometrically towards t_star, each resetting the consecutive-cut counter; without a
    minimum step the loop never reaches t_end (t + h == t eventually)."""

    n = 1
    mech = np.array([False])

    def __init__(self, t_on=0.5, t_star=0.55):
        self.t_on, self.t_star = t_on, t_star

    def mass(self):
        return sp.identity(1, format="csr")

    def evaluate(self, x, w, t, jacobian=True):
        F = np.array([2.0 * (w[0] - t) - 1.0])   # w' = 1 - 2 (w - t): exact w = t
        allowed = 0.5 * (self.t_star - t) if t < self.t_star else 0.0
        if t > self.t_on and abs(w[0] - t) > allowed:
            F[:] = np.nan
        return F, (sp.csr_matrix((1, 1)) if jacobian else None), (sp.csr_matrix([[2.0]]) if jacobian else None)

    def constraints(self, t):
        return np.array([], dtype=int), np.array([])

    def admissible(self, x):
        return True


def test_zeno_livelock_stops_at_the_minimum_step_with_the_last_good_state():
    t0 = time.perf_counter()
    with pytest.raises(IntegrationFailure) as ei:
        integrate(Zeno(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, predictor_degree=0,
                  control=StepControl(max_cuts=8))
    wall = time.perf_counter() - t0
    e = ei.value
    assert e.cause in ("min_step", "rejections"), str(e)
    assert e.cause == "min_step"
    assert 0.5 <= e.t < 0.55                       # stuck before t_star, never past it
    x, w, t = e.last_good_state
    assert w[0] == pytest.approx(t, abs=1e-9)     # the exact solution y = t: a good state
    assert e.h >= 1e-7 - 1e-18                     # never below max(1e-6 h0, 1e-12 t)
    assert "minimum step" in str(e) and f"t = {e.t:.9g}" in str(e) and "residuals [" in str(e)
    assert e.result.steps > 5                      # tiny steps were accepted on the way
    assert wall < 10


def test_without_the_new_budgets_the_zeno_system_livelocks():
    """The same run with the minimum step and the rejection budget switched off does not end
    within 2000 attempts: what the budgets are for (the failure mode without them)."""
    attempts, accepted = [], []

    class Counting(Zeno):
        def evaluate(self, x, w, t, jacobian=True):
            attempts.append(t)
            if len(attempts) > 2500:
                raise KeyboardInterrupt  # stop the livelock
            return super().evaluate(x, w, t, jacobian)

    with pytest.raises((KeyboardInterrupt, IntegrationFailure)) as ei:
        integrate(Counting(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, predictor_degree=0,
                  on_step=lambda t, x, w, info: accepted.append(t),
                  control=StepControl(max_cuts=8, min_step_rel=0.0, min_step_t_rel=0.0),
                  budgets=Budgets(max_rejections=10**9))
    assert ei.type is KeyboardInterrupt or ei.value.cause != "min_step"
    assert len(attempts) > 2000
    assert 0.5 < max(accepted) < 0.55


class AlwaysFails(Zeno):
    def evaluate(self, x, w, t, jacobian=True):
        F, Fx, Fw = super().evaluate(x, w, t, jacobian)
        if t > self.t_on:
            F[:] = np.nan
        return F, Fx, Fw


def test_total_rejection_budget():
    with pytest.raises(IntegrationFailure) as ei:
        integrate(Zeno(t_star=0.9), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, predictor_degree=0,
                  control=StepControl(max_cuts=100), budgets=Budgets(max_rejections=3))
    e = ei.value
    assert e.cause == "rejections" and e.result.rejected == 3
    assert "max_rejections = 3" in str(e)


def test_wall_time_budget_stops_after_an_accepted_step():
    with pytest.raises(IntegrationFailure) as ei:
        integrate(Zeno(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, predictor_degree=0,
                  budgets=Budgets(wall_budget_s=0.0))
    e = ei.value
    assert e.cause == "wall_time" and e.t == pytest.approx(0.1)
    assert e.w[0] == pytest.approx(0.1, abs=1e-12)


def test_defaults_leave_a_healthy_run_unchanged():
    """A run that never hits a budget gives the same bits with and without them."""
    a = integrate(Zeno(t_on=2.0), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=3)
    b = integrate(Zeno(t_on=2.0), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=3,
                  control=StepControl(min_step_rel=0.0, min_step_t_rel=0.0),
                  budgets=Budgets(max_rejections=10**9))
    assert a.t == b.t == 1.0
    np.testing.assert_array_equal(a.w, b.w)


# ----------------------------------------------------------------------------- minimiser
class NaNAway:
    """A ContactRelaxable-like quadratic bowl whose energy is NaN away from the start: every
    trial is rejected, sigma grows x4 each time."""

    def __init__(self):
        from test_minimize import rosenbrock

        self.inner = rosenbrock()
        self.x0 = None

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def energy(self, x):
        if self.x0 is None:
            self.x0 = np.array(x, copy=True)
        return self.inner.energy(x) if np.array_equal(x, self.x0) else math.nan


def test_minimiser_rejection_budget_and_minimum_step():
    x0 = np.array([-1.2, 1.0, 0.0])
    x, _, res = minimize_energy(NaNAway(), x0, max_iter=50, max_rejections=7)
    assert not res.converged and res.rejections == 7 and "max_rejections = 7" in res.reason
    np.testing.assert_array_equal(x, x0)            # the last accepted iterate
    x, _, res = minimize_energy(NaNAway(), x0, max_iter=50)   # default budget: the sigma cap ends it first
    assert not res.converged and "no descent step" in res.reason, res.reason
    assert res.rejections < 200
