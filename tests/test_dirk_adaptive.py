"""Embedded error estimates of the SDIRK family and the error-controlled steps of ``integrate``
(docs/time_integration.md §4), on a damped oscillator with a closed form."""
import math

import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.dirk import (
    AdaptiveControl, BACKWARD_EULER, SDIRK2, SDIRK3, IntegrationFailure, DirkStepper, integrate, local_error,
    order_conditions, sdirk, stability_function,
)
from rve.solvers.dirk import Tableau

TIGHT = dict(atol=1e-14, rtol=1e-15, max_iter=20)


class Oscillator:
    """x'' + 2 ζ ω x' + ω² x = 0 as M w' + F = 0, dx/dt = w (one mechanical dof)."""

    n = 1
    mech = np.array([True])

    def __init__(self, omega=2.0, zeta=0.1):
        self.k, self.c = omega ** 2, 2 * zeta * omega
        self.omega, self.zeta = omega, zeta

    def mass(self):
        return sp.identity(1, format="csr")

    def evaluate(self, x, w, t, jacobian=True):
        F = np.array([self.k * x[0] + self.c * w[0]])
        if not jacobian:
            return F, None, None
        return F, sp.csr_matrix([[self.k]]), sp.csr_matrix([[self.c]])

    def constraints(self, t):
        return np.array([], dtype=int), np.array([])

    def admissible(self, x):
        return True

    def exact(self, t, x0=1.0, v0=0.0):
        """Closed form (underdamped) -> (x, v)."""
        wd = self.omega * math.sqrt(1 - self.zeta ** 2)
        a = self.zeta * self.omega
        A, B = x0, (v0 + a * x0) / wd
        e = math.exp(-a * t)
        x = e * (A * math.cos(wd * t) + B * math.sin(wd * t))
        v = -a * x + e * (-A * wd * math.sin(wd * t) + B * wd * math.cos(wd * t))
        return x, v


# ----------------------------------------------------------------------------- the embedded weights
@pytest.mark.parametrize("tab", [SDIRK2, SDIRK3])
def test_embedded_order_conditions_hold_to_order_and_fail_above(tab):
    p = tab.embedded_order
    assert p == tab.order - 1
    emb = Tableau("emb", tab.A, tab.b_hat, tab.c, p)
    conds = order_conditions(emb, p)
    assert max(abs(v) for v in conds.values()) < 1e-14, conds
    above = {k: v for k, v in order_conditions(emb, p + 1).items() if k.startswith(f"p{p + 1}")}
    assert max(abs(v) for v in above.values()) > 1e-2   # exactly order p: the estimate is nonzero
    # R̂(∞) = −1: the estimate stays bounded on stiff modes (the scale rule of _embedded_weights)
    assert abs(tab.embedded_stability(-1e12) + 1) < 1e-9


def test_sdirk2_embedded_closed_form():
    """b̂ = (2√2 − 2, 3 − 2√2) (order 1, R̂(∞) = −1), derived by hand from b̂ = b + δ(1, −1)."""
    np.testing.assert_allclose(SDIRK2.b_hat, [2 * math.sqrt(2) - 2, 3 - 2 * math.sqrt(2)], atol=1e-15)
    assert BACKWARD_EULER.b_hat is None


@pytest.mark.parametrize("tab", [SDIRK2, SDIRK3])
def test_error_weights_on_the_linear_test_equation(tab):
    """On y' = λy the stage values are Y = (I − zA)⁻¹ 1 y0, so Σ e_j (Y_j − y0) must equal
    (R(z) − R̂(z)) y0: the stage-value form of the estimate is the b̂ method's."""
    for z in (-0.3, -2.0, 0.5j, -10 + 3j):
        Y = np.linalg.solve(np.eye(tab.stages) - z * tab.A, np.ones(tab.stages, dtype=complex))
        est = tab.error_weights @ (Y - 1.0)
        assert abs(est - (stability_function(tab, z) - tab.embedded_stability(z))) < 1e-13


# ----------------------------------------------------------------------------- the estimate's order
@pytest.mark.parametrize("tab", [SDIRK2, SDIRK3])
def test_estimate_order_and_asymptotic_correctness(tab):
    """One step from the exact state: the estimate y1 − ŷ falls as h^(p̂+1) (p̂ = embedded
    order) and tends to the true local error of the embedded solution, ŷ − y(t0 + h)."""
    osc = Oscillator()
    t0 = 0.3
    x0, v0 = osc.exact(t0)
    ada = AdaptiveControl(rtol=0.0, atol=1.0)   # err = max |e_x| (unscaled)
    hs = [0.1 / 2 ** k for k in range(5)]
    est, rel = [], []
    for h in hs:
        st = DirkStepper(osc, tab, TIGHT)
        x1, w1, info = st.step(np.array([x0]), np.array([v0]), t0, h)
        e = local_error(tab, np.array([x0]), np.array([v0]), info.stage_states, osc.mech, ada)
        ex = sum(tab.error_weights[j] * (xj[0] - x0) for j, (xj, _) in enumerate(info.stage_states))
        assert abs(abs(ex) - e) < 1e-15
        xhat = x1[0] - ex
        true_hat = xhat - osc.exact(t0 + h)[0]
        est.append(e)
        rel.append(abs(-ex - true_hat) / abs(true_hat))
    orders = np.diff(np.log(est)) / np.diff(np.log(hs))
    assert np.all(np.abs(orders - (tab.embedded_order + 1)) < 0.1), orders
    assert rel[-1] < 0.05 and rel[-1] < rel[0] / 4, rel   # the estimate is asymptotically the error


# ----------------------------------------------------------------------------- error-controlled integration
def _run(tol, n_steps, tab_s=2, **kw):
    osc = Oscillator(omega=2.0, zeta=0.3)
    ada = AdaptiveControl(rtol=0.0, atol=tol, **kw)
    res = integrate(osc, [1.0], [0.0], 0.0, 12.0, n_steps, stages=tab_s, newton_opts=TIGHT, adaptive=ada)
    return res, abs(res.x[0] - osc.exact(12.0)[0])


@pytest.mark.parametrize("s", [2, 3])
def test_adaptive_global_error_follows_the_tolerance(s):
    """Tolerance proportionality: the global error at t_end falls with the tolerance, and
    the decay phase (a damped oscillation) takes longer steps than the start."""
    errs, steps = [], []
    for tol in (1e-4, 1e-6):
        res, err = _run(tol, 12, s)   # nominal grid 1.0: the steps land there
        assert res.t == 12.0 and res.steps > 0
        assert max(res.errors) <= 1.0
        errs.append(err)
        steps.append(res.steps)
        hs = [h for _, h, _ in res.history]
        assert np.median(hs[-10:]) > 2 * np.median(hs[:10])   # the slow tail takes longer steps
    assert errs[1] < errs[0] / 10, errs
    assert steps[1] > steps[0]


def test_adaptive_rejects_a_too_long_step_and_retries():
    """A first step far too long for the tolerance is rejected by the estimate (not by Newton)
    and retried shorter from the same state; the run still lands exactly on t_end."""
    res, err = _run(1e-5, 2, 2)          # h0 = 6: the first attempts cannot meet 1e-5
    assert res.error_rejections >= 1 and res.rejected >= res.error_rejections
    assert res.t == 12.0 and max(res.errors) <= 1.0
    first = res.history[0][1]
    assert first < 6.0 * 0.2 + 1e-12      # the accepted first step is far shorter than h0


def test_adaptive_lands_on_the_grid():
    """Steps land on every point of the grid of land_every nominal steps (fixed output times)."""
    res, _ = _run(1e-5, 24, 2, land_every=3)      # grid 1.5
    ts = [t for t, _, _ in res.history]
    for k in range(1, 9):
        assert any(abs(t - 1.5 * k) < 1e-12 for t in ts), k
    assert max(h for _, h, _ in res.history) <= 1.5 + 1e-12


def test_adaptive_needs_an_embedded_method_and_no_fixed_steps():
    with pytest.raises(ValueError, match="embedded"):
        integrate(Oscillator(), [1.0], [0.0], 0.0, 1.0, 4, stages=1, adaptive=AdaptiveControl())
    from rve.solvers.dirk import StepControl
    with pytest.raises(ValueError, match="fixed_step"):
        integrate(Oscillator(), [1.0], [0.0], 0.0, 1.0, 4, stages=2, adaptive=AdaptiveControl(),
                  control=StepControl(fixed_step=True))
    with pytest.raises(ValueError, match="safety"):
        AdaptiveControl(safety=1.5)


def test_adaptive_gives_up_below_the_minimum_step():
    """A tolerance no step can meet ends the run with the last good state, not a loop."""
    with pytest.raises(IntegrationFailure) as exc:
        integrate(Oscillator(), [1.0], [0.0], 0.0, 1.0, 4, stages=2, newton_opts=TIGHT,
                  adaptive=AdaptiveControl(rtol=0.0, atol=1e-300))
    assert exc.value.cause in ("min_step", "rejections")
    assert exc.value.t == 0.0
