"""The one-crossing friction scene (configs/scenes/crossing.yaml, small), on the chord and
(p = 2) on the Lagrange centroid curve and the smooth curve: the tangential force grows at the
regularisation stiffness, saturates at mu N, and the closed cycle dissipates mu N times the
slip; Newton converges quadratically in stick and in slip. On the curves the slider's point is
a half-pass point (weight l_e / 2); the base's own point is put 0.5 mm from the crossing
(``geometry.base_offset``) so that one point touches, as on the chord; the p = 2 slider bends
more (N is ~10 times smaller), so eps_T / P* = 0.01 keeps the stick length mu N / kT visible on
the cycle's 8 steps per quarter."""
import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import friction_crossing

STEPS = 8
CURVE = ["mesh.order=2", "geometry.base_offset=0.5 mm", "friction.stiffness=0.01"]


@pytest.fixture(scope="module", params=["chord", "curve", "smooth"])
def crossing(request):
    over = [f"load.steps_per_leg={STEPS}"]
    if request.param != "chord":
        over += CURVE + [f"contact.geometry={request.param}"]
    cfg = load_config("configs/scenes/crossing.yaml", overrides=over)
    return request.param, cfg, friction_crossing.solve(cfg).summary


def _arrays(path, *keys):
    return [np.array([p[k] for p in path]) for k in keys]


def test_stick_grows_at_the_regularisation_stiffness_then_saturates(crossing):
    geometry, cfg, s = crossing
    F, slip, N, stick, slipping = _arrays(s["path"], "force", "slip", "normal", "stick", "slip_points")
    kT, mu = s["stiffness"], s["mu"]
    # the point's weight: l_e on the chord; on the curves the half pass's l_e W / 2, W = 1
    le = cfg.geometry.slider_length / cfg.mesh.elements
    assert np.isclose(kT, (1.0 if geometry == "chord" else 0.5) * le * cfg.friction.stiffness * cfg.contact.penalty)
    if geometry != "chord":
        assert np.all(stick + slipping == 1)                          # one point touches
    first = np.flatnonzero(slipping[:STEPS])
    assert stick[0] == 1 and first.size and first[0] > (0 if geometry == "chord" else 1)   # stick, then slip
    st = slice(0, first[0])
    np.testing.assert_allclose(F[st], kT * slip[st], rtol=1e-9)    # slope = w eps_T P*
    on = slipping == 1
    assert on.sum() > len(F) / 2
    np.testing.assert_allclose(np.abs(F[on]), mu * N[on], rtol=1e-9)  # |F_T| = mu N
    assert np.all(np.abs(F) <= mu * N * (1 + 1e-12))


def test_closed_cycle_dissipates_mu_n_slip(crossing):
    _, _, s = crossing
    u, F, slip, N, D = _arrays(s["path"], "u", "force", "slip", "normal", "dissipated")
    kT, mu = s["stiffness"], s["mu"]
    cyc = slice(STEPS - 1, None)            # u = U -> -U -> U: a closed loop
    assert u[STEPS - 1] == u[-1] and np.isclose(slip[STEPS - 1], slip[-1], rtol=1e-9)
    D_cycle = D[STEPS:].sum()
    Nbar = N[cyc].mean()
    assert np.ptp(N[cyc]) <= 1e-3 * Nbar    # the normal force is (nearly) constant
    S = 0.5 * (slip[cyc].max() - slip[cyc].min())
    plastic = 4.0 * (S - mu * Nbar / kT)    # slip of the loop: amplitude minus the elastic part
    assert plastic > 0.5 * 4 * S
    np.testing.assert_allclose(D_cycle, mu * Nbar * plastic, rtol=2e-3)
    # the supports' work over the loop (trapezoid) is the dissipation; the rule errs only in
    # the steps where stick turns into slip (4 per loop), by at most |dF| du / 2 each
    du, dF = np.diff(u[cyc]), np.diff(F[cyc])
    W = np.sum(0.5 * (F[cyc][1:] + F[cyc][:-1]) * du)
    assert abs(W - D_cycle) <= 4 * 0.5 * np.abs(dF * du).max()


def test_newton_quadratic_in_stick_and_slip(crossing):
    """Near the solution every iteration squares the residual: r_{k+1} <= C r_k^2 with
    C = 10 /N (a linearly converging Newton, e.g. with a symmetrised tangent, fails this
    as soon as r_k is small). The logged rates are in the solver log (rve.newton)."""
    geometry, _, s = crossing
    if geometry != "chord":
        return _newton_order_two_on_the_curves(s)
    seen = set()
    for p in s["path"]:
        r = np.array(p["newton"])
        assert r[-1] <= 1e-12
        near = (r[:-1] <= 1e-2) & (r[1:] > 1e-13)   # above the rounding floor (~1e-14 N)
        if near.any():
            assert np.all(r[1:][near] <= 10.0 * r[:-1][near] ** 2), (p["stick"], p["slip_points"], p["newton"])
            seen.add("slip" if p["slip_points"] else "stick")
    assert seen == {"stick", "slip"}


def _newton_order_two_on_the_curves(s):
    """In the steps that end in the stick/slip state (and slip direction) of the step before
    (where it changes, an iteration changes the set and converges linearly once, as in
    docs/contact.md "Solving with friction"): stick, r_{k+1} <= 10 r_k^2 as on the chord;
    slip, the order log(r_{k+1}/r_k) / log(r_k/r_{k-1}) of three residuals between 1e-2 and
    1e-12 (above the rounding floor) is at least 1.8 (the p = 2 slider is ten times softer than the p = 1
    chord scene's, so its Newton constant in 1/N is larger and not comparable: measured
    r_{k+1}/r_k^2 ~ 100 /N; a Newton with a wrong slip tangent converges at order 1)."""
    seen = set()
    prev = None
    for p in s["path"]:
        r = np.array(p["newton"])
        assert r[-1] <= 1e-12
        state = ("slip", np.sign(p["force"])) if p["slip_points"] else ("stick", 0.0)
        near = (r[:-1] <= 1e-2) & (r[1:] > 1e-13)
        if state == prev and state[0] == "stick" and near.any():
            assert np.all(r[1:][near] <= 10.0 * r[:-1][near] ** 2), (p["stick"], p["slip_points"], p["newton"])
            seen.add("stick")
        mid = r[(r <= 1e-2) & (r > 1e-12)]       # above the rounding floor (final residuals 2e-14..1e-13)
        if state == prev and state[0] == "slip" and mid.size >= 3:
            q = np.log(mid[2:] / mid[1:-1]) / np.log(mid[1:-1] / mid[:-2])
            assert np.all(q >= 1.8), (p["newton"], q)
            seen.add("slip")
        prev = state
    assert seen == {"stick", "slip"}
