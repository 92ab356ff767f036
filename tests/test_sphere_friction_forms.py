"""Finite-difference checks of the friction at the projectile's sphere contact
(rve.physics.sphere_friction_forms) in stick and in slip, at interior and clamped closest
points, with the projectile's directors among the unknowns; the return map's invariants."""
import numpy as np
import pytest

from rve.physics.sphere_contact_forms import sphere_segment_geometry
from rve.physics.sphere_friction_forms import (sphere_friction_forces, sphere_friction_state, sphere_material_jump,
                                               sphere_start_history)
from rve.testing import fd_nodes

RS, RF = 2.0, 0.2          # sphere and fibril radii
K_N = 30.0                 # normal point penalty (N/mm)


def _frame(rng, P):
    """Director pairs of a rotated, slightly stretched and sheared end section."""
    A = np.linalg.qr(rng.normal(size=(P, 3, 3)))[0]
    d1 = A[:, :, 0] * (1 + 0.05 * rng.normal(size=(P, 1))) + 0.02 * rng.normal(size=(P, 3))
    d2 = A[:, :, 1] * (1 + 0.05 * rng.normal(size=(P, 1)))
    return d1, d2


def _pairs(interior=True, P=6, overlap=0.03, seed=5):
    """P spheres pressed on chords, a history taken at a nearby state (its contact points)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(P, 3))
    e = rng.normal(size=(P, 3))
    b = a + e
    s = rng.uniform(0.25, 0.75, P) if interior else rng.choice([-0.3, 1.3], P)
    perp = np.cross(e, rng.normal(size=(P, 3)))
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    c = a + np.clip(s, 0, 1)[:, None] * e
    if not interior:  # beyond an end: away from the chord's end point along the chord too
        perp = perp + 0.3 * np.sign(s - 0.5)[:, None] * e / np.linalg.norm(e, axis=1, keepdims=True)
        perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    p = c + (RS + RF - overlap) * perp
    d1, d2 = _frame(rng, P)
    X = np.stack([p, d1, d2, a, b], axis=1)
    X0 = X + rng.normal(size=X.shape) * 0.01
    xi, s_bar, anchor = sphere_start_history(X0, RS, np.full(P, RS + RF))
    return X, xi, s_bar, anchor


def _forces(X, xi, s_bar, anchor, mu, ratio, jac=True):
    P = X.shape[0]
    R = np.full(P, RS + RF)
    k = np.full(P, K_N)
    kT = ratio * k
    Rl, K = sphere_friction_forces(X, R, xi, s_bar, anchor, k, kT, mu, jac)
    st = sphere_friction_state(X, RS, R, xi, s_bar, anchor, k, kT, mu)
    return Rl, K, st


@pytest.mark.parametrize("interior", [True, False])
@pytest.mark.parametrize("regime, mu, ratio", [("stick", 1.5, 0.05), ("slip", 0.2, 50.0)])
def test_sphere_friction_tangent_matches_finite_differences(regime, mu, ratio, interior):
    X, xi, s_bar, anchor = _pairs(interior)
    geo = sphere_segment_geometry(X[:, 0], X[:, 3], X[:, 4], RS + RF)
    assert (geo["g"] > 0).all() and geo["interior"].all() == interior and not (geo["interior"].any() and not interior)
    Rl, K, st = _forces(X, xi, s_bar, anchor, mu, ratio)
    P = X.shape[0]
    assert (st.stick if regime == "stick" else st.slip).sum() == P
    assert np.abs(Rl).max() > 1e-3
    Kfd = fd_nodes(lambda Y: _forces(Y, xi, s_bar, anchor, mu, ratio, False)[0], X)
    err = np.abs(K - Kfd).max() / np.abs(K).max()
    assert err < 1e-6, err
    # the director columns carry the spin of the material point
    assert np.abs(K[:, :, :, 1:3]).max() > 1e-2 * np.abs(K).max()
    A = K.reshape(P, 15, 15)
    asym = np.abs(A - np.swapaxes(A, 1, 2)).max() / np.abs(A).max()
    if regime == "slip":
        assert asym > 1e-3
    else:  # stick: unsymmetric as well where the normal rotates (the projection's derivative)
        assert np.isfinite(asym)


def test_sphere_friction_cone_balance_and_power():
    X, xi, s_bar, anchor = _pairs()
    geo = sphere_segment_geometry(X[:, 0], X[:, 3], X[:, 4], RS + RF)
    for mu, ratio in ((0.2, 50.0), (1.5, 0.05), (0.5, 1.0)):
        Rl, _, st = _forces(X, xi, s_bar, anchor, mu, ratio, jac=False)
        tn = np.linalg.norm(st.t, axis=-1)
        assert np.all(tn <= mu * st.normal * (1 + 1e-12))
        np.testing.assert_allclose(tn[st.slip], mu * st.normal[st.slip], rtol=1e-12)
        assert np.abs(np.einsum("pi,pi->p", st.t, geo["n"])).max() <= 1e-12 * tn.max()
        # equal and opposite on the centre and the chord (the directors take a moment)
        np.testing.assert_allclose(Rl[:, 0] + Rl[:, 3] + Rl[:, 4], 0.0, atol=1e-13 * tn.max())
        assert np.all(st.dissipation >= -1e-15) and np.all(st.dissipation[st.stick] == 0.0)
        # R . w is the friction force's power on the material points' relative velocity
        W = np.random.default_rng(2).normal(size=X.shape)
        h = 1e-6
        jdot = (sphere_material_jump(X + h * W, xi, s_bar) - sphere_material_jump(X - h * W, xi, s_bar)) / (2 * h)
        np.testing.assert_allclose(np.einsum("pkj,pkj->p", Rl, W), np.einsum("pi,pi->p", st.t, jdot),
                                   rtol=1e-7, atol=1e-9 * tn.max())


def test_sphere_friction_committed_history():
    """The history committed at a state gives back the force of that state there (its
    elastic gap), with the projectile's material point on its surface at the contact."""
    X, xi, s_bar, anchor = _pairs()
    for mu, ratio in ((0.2, 50.0), (1.5, 0.05)):
        Rl, _, st = _forces(X, xi, s_bar, anchor, mu, ratio, jac=False)
        R2, _, st2 = _forces(X, st.xi, st.s_bar, st.anchor, mu, ratio, jac=False)
        np.testing.assert_allclose(st2.t, st.t, rtol=1e-12, atol=1e-14 * np.abs(st.t).max())
        assert not st2.slip.any() or mu == 0.2
        assert np.all(st2.dissipation <= 1e-12 * np.abs(st.t).max())
        geo = sphere_segment_geometry(X[:, 0], X[:, 3], X[:, 4], RS + RF)
        d1, d2 = X[:, 1], X[:, 2]
        y = X[:, 0] + st.xi[:, :1] * d1 + st.xi[:, 1:2] * d2 + st.xi[:, 2:] * np.cross(d1, d2)
        np.testing.assert_allclose(y, X[:, 0] - RS * geo["n"], atol=1e-12)
    # no elastic gap: no force
    xi0, s0, a0 = sphere_start_history(X, RS, np.full(X.shape[0], RS + RF))
    Rl, _, _ = _forces(X, xi0, s0, a0, 0.3, 1.0, jac=False)
    assert np.abs(Rl).max() <= 1e-13
