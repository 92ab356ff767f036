"""The one-crossing friction scene (configs/scenes/crossing.yaml, small): the tangential
force grows at the regularisation stiffness, saturates at mu N, and the closed cycle
dissipates mu N times the slip; Newton is quadratic in stick and in slip."""
import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import friction_crossing

STEPS = 8


@pytest.fixture(scope="module")
def crossing():
    cfg = load_config("configs/scenes/crossing.yaml", overrides=[f"load.steps_per_leg={STEPS}"])
    return cfg, friction_crossing.solve(cfg).summary


def _arrays(path, *keys):
    return [np.array([p[k] for p in path]) for k in keys]


def test_stick_grows_at_the_regularisation_stiffness_then_saturates(crossing):
    cfg, s = crossing
    F, slip, N, stick, slipping = _arrays(s["path"], "force", "slip", "normal", "stick", "slip_points")
    kT, mu = s["stiffness"], s["mu"]
    assert np.isclose(kT, cfg.geometry.slider_length / cfg.mesh.elements * cfg.friction.stiffness * cfg.contact.penalty)
    first = np.flatnonzero(slipping[:STEPS])
    assert stick[0] == 1 and first.size and first[0] > 0          # stick first, then slip on the first leg
    st = slice(0, first[0])
    np.testing.assert_allclose(F[st], kT * slip[st], rtol=1e-9)    # slope = w eps_T P*
    on = slipping == 1
    assert on.sum() > len(F) / 2
    np.testing.assert_allclose(np.abs(F[on]), mu * N[on], rtol=1e-9)  # |F_T| = mu N
    assert np.all(np.abs(F) <= mu * N * (1 + 1e-12))


def test_closed_cycle_dissipates_mu_n_slip(crossing):
    _, s = crossing
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
    _, s = crossing
    seen = set()
    for p in s["path"]:
        r = np.array(p["newton"])
        assert r[-1] <= 1e-12
        near = (r[:-1] <= 1e-2) & (r[1:] > 1e-13)   # above the rounding floor (~1e-14 N)
        if near.any():
            assert np.all(r[1:][near] <= 10.0 * r[:-1][near] ** 2), (p["stick"], p["slip_points"], p["newton"])
            seen.add("slip" if p["slip_points"] else "stick")
    assert seen == {"stick", "slip"}
