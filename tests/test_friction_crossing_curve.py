"""The one-crossing friction scene on the Lagrange centroid curve at p = 2 (and the smooth
curve): the same checks as tests/test_friction_crossing.py on the chord. The slider's point
is a half-pass point (weight l_e / 2); the base's own point is put 0.5 mm from the crossing
(``geometry.base_offset``) so that one point touches, as on the chord. At p = 2 the slider
bends more than at p = 1 (N is ~10 times smaller), so eps_T / P* = 0.01 keeps the stick
length mu N / kT visible on the cycle's 8 steps per quarter."""
import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import friction_crossing

STEPS = 8
CURVE = ["contact.geometry=curve", "mesh.order=2", "geometry.base_offset=0.5 mm", "friction.stiffness=0.01"]


@pytest.fixture(scope="module", params=["curve", "smooth"])
def crossing(request):
    over = [f"load.steps_per_leg={STEPS}"] + CURVE
    if request.param == "smooth":
        over = over + ["contact.geometry=smooth"]
    cfg = load_config("configs/scenes/crossing.yaml", overrides=over)
    return cfg, friction_crossing.solve(cfg).summary


def _arrays(path, *keys):
    return [np.array([p[k] for p in path]) for k in keys]


def test_stick_grows_at_the_regularisation_stiffness_then_saturates(crossing):
    cfg, s = crossing
    F, slip, N, stick, slipping = _arrays(s["path"], "force", "slip", "normal", "stick", "slip_points")
    kT, mu = s["stiffness"], s["mu"]
    # the half pass's weight: l_e W / 2 with the one Gauss weight W = 1
    le = cfg.geometry.slider_length / cfg.mesh.elements
    assert np.isclose(kT, 0.5 * le * cfg.friction.stiffness * cfg.contact.penalty)
    assert np.all(stick + slipping == 1)                              # one point touches
    first = np.flatnonzero(slipping[:STEPS])
    assert stick[0] == 1 and first.size and first[0] > 1
    st = slice(0, first[0])
    np.testing.assert_allclose(F[st], kT * slip[st], rtol=1e-9)      # slope = w eps_T P*
    on = slipping == 1
    assert on.sum() > len(F) / 2
    np.testing.assert_allclose(np.abs(F[on]), mu * N[on], rtol=1e-9)  # |F_T| = mu N
    assert np.all(np.abs(F) <= mu * N * (1 + 1e-12))


def test_closed_cycle_dissipates_mu_n_slip(crossing):
    _, s = crossing
    u, F, slip, N, D = _arrays(s["path"], "u", "force", "slip", "normal", "dissipated")
    kT, mu = s["stiffness"], s["mu"]
    cyc = slice(STEPS - 1, None)
    assert u[STEPS - 1] == u[-1] and np.isclose(slip[STEPS - 1], slip[-1], rtol=1e-9)
    D_cycle = D[STEPS:].sum()
    Nbar = N[cyc].mean()
    assert np.ptp(N[cyc]) <= 1e-3 * Nbar
    S = 0.5 * (slip[cyc].max() - slip[cyc].min())
    plastic = 4.0 * (S - mu * Nbar / kT)
    assert plastic > 0.5 * 4 * S
    np.testing.assert_allclose(D_cycle, mu * Nbar * plastic, rtol=2e-3)
    du, dF = np.diff(u[cyc]), np.diff(F[cyc])
    W = np.sum(0.5 * (F[cyc][1:] + F[cyc][:-1]) * du)
    assert abs(W - D_cycle) <= 4 * 0.5 * np.abs(dF * du).max()


def test_newton_quadratic_in_stick_and_slip(crossing):
    """In the steps that end in the stick/slip state (and slip direction) of the step before
    (where it changes, an iteration changes the set and converges linearly once, as in
    docs/contact.md "Solving with friction"): stick, r_{k+1} <= 10 r_k^2 as on the chord;
    slip, the order log(r_{k+1}/r_k) / log(r_k/r_{k-1}) of three residuals between 1e-2 and
    1e-12 (above the rounding floor) is at least 1.8 (the p = 2 slider is ten times softer than the p = 1
    chord scene's, so its Newton constant in 1/N is larger and not comparable: measured
    r_{k+1}/r_k^2 ~ 100 /N; a Newton with a wrong slip tangent converges at order 1)."""
    _, s = crossing
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
