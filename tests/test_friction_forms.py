"""Finite-difference checks of the regularised Coulomb friction forms
(rve.physics.friction_forms) in stick and in slip, and the return mapping's invariants."""
import numpy as np
import pytest

from rve.physics.contact_forms import chord_geometry, penalty_law
from rve.physics.friction_forms import friction_forces, friction_state, start_history
from rve.testing import fd_nodes

R2 = 0.3  # R+ + R-
PEN = 50.0


def _pairs(P=5, G=3, overlap=0.04, seed=3):
    """P crossing chord pairs, centroids R2 - overlap apart (+ noise), with a history
    taken at a nearby state (the material points that were in contact there)."""
    rng = np.random.default_rng(seed)
    ap = rng.normal(size=(P, 3)) * 0.03 + [-0.1, 0.0, 0.0]
    bp = ap + [0.2, 0.0, 0.0] + rng.normal(size=(P, 3)) * 0.03
    am = rng.normal(size=(P, 3)) * 0.03 + [0.0, -0.3, -(R2 - overlap)]
    bm = am + [0.0, 0.6, 0.0] + rng.normal(size=(P, 3)) * 0.03
    X = np.stack([ap, bp, am, bm], axis=1)
    sp = np.broadcast_to((np.arange(G) + 0.5) / G, (P, G)).copy()
    X0 = X + rng.normal(size=X.shape) * 0.01
    g0 = chord_geometry(*(X0[:, k] for k in range(4)), sp, np.full(P, R2))
    s_bar, anchor = start_history(X0, sp, g0.s_minus)
    return X, sp, s_bar, anchor


def _forces(X, sp, s_bar, anchor, mu, ratio, jac=True, s_minus=None):
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2), s_minus)
    w = np.full(geo.g.shape, 0.05)
    _, p1, p2 = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    f = np.where(geo.active, w * p1, 0.0)
    kN = np.where(geo.active, w * p2, 0.0)
    kT = w * ratio * PEN
    R, K = friction_forces(geo, X, s_bar, anchor, f, kN, kT, np.full(X.shape[0], mu), jac)
    st = friction_state(geo, X, s_bar, anchor, f, kT, np.full(X.shape[0], mu))
    return R, K, st, f


@pytest.mark.parametrize("regime, mu, ratio", [("stick", 1.5, 0.05), ("slip", 0.2, 50.0)])
@pytest.mark.parametrize("frozen", [False, True])
def test_friction_tangent_matches_finite_differences(regime, mu, ratio, frozen):
    X, sp, s_bar, anchor = _pairs()
    sm = None
    if frozen:
        sm = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2)).s_minus
    R, K, st, f = _forces(X, sp, s_bar, anchor, mu, ratio, s_minus=sm)
    n_active = int((f > 0).sum())
    assert n_active >= 5
    if regime == "stick":
        assert st.stick.sum() == n_active and not st.slip.any()
    else:
        assert st.slip.sum() == n_active and not st.stick.any()
    assert np.abs(R).max() > 1e-4
    Kfd = fd_nodes(lambda Y: _forces(Y, sp, s_bar, anchor, mu, ratio, False, sm)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    if regime == "slip":  # the slip tangent is not symmetric
        KT = np.swapaxes(np.swapaxes(K, 1, 3), 2, 4)
        assert np.abs(K - KT).max() > 1e-3 * np.abs(K).max()


def test_return_mapping_cone_tangency_and_balance():
    X, sp, s_bar, anchor = _pairs()
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    for mu, ratio in ((0.2, 50.0), (1.5, 0.05), (0.5, 2.0)):
        R, _, st, f = _forces(X, sp, s_bar, anchor, mu, ratio, jac=False)
        tn = np.linalg.norm(st.t, axis=-1)
        assert np.all(tn <= mu * f * (1 + 1e-12) + 1e-300)          # inside the cone
        np.testing.assert_allclose(tn[st.slip], mu * f[st.slip], rtol=1e-12)  # on it when slipping
        assert np.abs(np.einsum("pgi,pgi->pg", st.t, geo.n)).max() <= 1e-12 * max(tn.max(), 1e-300)
        np.testing.assert_allclose(R[:, 0] + R[:, 1], -(R[:, 2] + R[:, 3]), atol=1e-14)  # action = reaction
        assert np.all(st.dissipation >= -1e-15) and np.all(st.dissipation[st.stick] == 0.0)


def test_no_gap_history_gives_no_force():
    X, sp, _, _ = _pairs()
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    s_bar, anchor = start_history(X, sp, geo.s_minus)
    R, _, st, _ = _forces(X, sp, s_bar, anchor, 0.3, 1.0, jac=False)
    assert np.abs(R).max() <= 1e-14
