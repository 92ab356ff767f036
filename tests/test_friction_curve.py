"""Regularised Coulomb friction on the centroid curves (rve.physics.friction_forms with the
``CurveGeometry`` of rve.physics.contact_curve, p = 1, 2, 3, and of the smooth Hermite curve,
rve.physics.contact_smooth): what the geometry supplies (material weights, dc/ds), the exact
tangent in stick and in slip against central differences, the frozen potential's gradient
and Hessian, the potential at its own loads is the law, and a commit changes no force."""
import sys
from pathlib import Path

import numpy as np
import pytest

from rve.physics.contact_curve import curve_geometry, gauss_legendre_01
from rve.physics.contact_forms import penalty_law
from rve.physics.contact_smooth import smooth_geometry
from rve.physics.friction_forms import (friction_forces, friction_state, frozen_potential, moved_history,
                                        start_history, tangential_gap)
from rve.testing import fd_nodes

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_contact_curve import _curved_pairs  # noqa: E402
from test_contact_curve_smooth import _rows  # noqa: E402

R2 = 0.3     # R+ + R- of both fixtures
PEN = 50.0
W = 0.05     # point weight
G = 4

#: (geometry, order) of every case
CASES = [("curve", 1), ("curve", 2), ("curve", 3), ("smooth", 1), ("smooth", 2), ("smooth", 3)]


def _case(kind, order, seed=3):
    """``(X (P, M, 3), geo(X))``: crossing rows of curved elements on the Lagrange curve,
    or on the Hermite curve (a and b the middle elements of 3-element fibrils)."""
    s, _ = gauss_legendre_01(G)
    if kind == "curve":
        Xa, Xb = _curved_pairs(order, P=6, seed=seed)
        nn = order + 1
        P = Xa.shape[0]

        def geo(X):
            return curve_geometry(order, X[:, :nn], X[:, nn:], s, np.full(P, R2), np.zeros(P, bool),
                                  np.zeros((P, 3)), np.zeros(P, bool))
        return np.concatenate([Xa, Xb], axis=1), geo
    Xa, Xb, Sa, Sb, hn, hp, oa, ob = _rows(order, P=6, seed=seed, kinds=("mid",))
    Ms = Sa.shape[-1]

    def geo(X):
        Ya, Yb = np.matmul(Sa, X[:, :Ms]), np.matmul(Sb, X[:, Ms:])
        return smooth_geometry(order, Ya, Sa, Yb, Sb, s, np.full(X.shape[0], R2), hn, Yb[:, 3], hp, oa, ob)
    return np.concatenate([Xa, Xb], axis=1), geo


def _history(X, geo, seed=5, scale=0.01, turned=False):
    """A history taken at a nearby state: the material points in contact there, no gap
    (``turned``: with the - side's direction at the closest points there, ``d_ref``, so that
    the anchor turns between that state and ``X``)."""
    from rve.physics.friction_forms import minus_direction

    X0 = X + np.random.default_rng(seed).normal(size=X.shape) * scale
    g0 = geo(X0)
    s_bar, anchor = start_history(X0, None, g0.s_minus, weights=g0.material_weights)
    if not turned:
        return s_bar, anchor
    return s_bar, anchor, minus_direction(X0, g0.direction_weights(g0.s_minus))[0]


def _forces(geo_fn, X, s_bar, anchor, mu, ratio, jac=True, d_ref=None):
    """Friction forms of the points at ``X``; ``d_ref``: the anchor turns (its direction then)."""
    geo = geo_fn(X)
    w = np.full(geo.g.shape, W)
    _, p1, p2 = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    f = np.where(geo.active, w * p1, 0.0)
    kN = np.where(geo.active, w * p2, 0.0)
    kT = w * ratio * PEN
    mus = np.full(X.shape[0], mu)
    R, K = friction_forces(geo, X, s_bar, anchor, f, kN, kT, mus, jac, d_ref=d_ref)
    return R, K, friction_state(geo, X, s_bar, anchor, f, kT, mus, d_ref=d_ref), f


@pytest.mark.parametrize("kind, order", CASES)
def test_geometry_supplies_the_material_weights_and_their_derivative(kind, order):
    """``material_weights(s_b)`` is ``c`` (bit for bit: a commit moves no force), its
    s-derivative is ``dc_ds`` (central differences), and ``sum dc_ds X = -dq/ds``."""
    X, geo_fn = _case(kind, order)
    geo = geo_fn(X)
    assert np.array_equal(geo.material_weights(geo.s_minus), geo.c)
    h = 1e-6
    s = geo.s_minus + 0.1
    fd = (geo.material_weights(s + h) - geo.material_weights(s - h)) / (2 * h)
    geo_s = geo.material_weights(s)
    assert np.abs(geo_s[..., :geo_s.shape[-1] // 2] - geo.c[..., :geo.c.shape[-1] // 2]).max() == 0.0
    # dc_ds at s_b against the difference quotient at s_b
    fd0 = (geo.material_weights(geo.s_minus + h) - geo.material_weights(geo.s_minus - h)) / (2 * h)
    np.testing.assert_allclose(geo.dc_ds, fd0, rtol=1e-7, atol=1e-7)
    assert np.abs(fd).max() > 0.5
    # the jump at the current closest point: j = c X
    np.testing.assert_allclose(np.einsum("pgk,pki->pgi", geo.c, X), geo.j, atol=1e-14)


@pytest.mark.parametrize("kind, order", CASES)
@pytest.mark.parametrize("regime, mu, ratio", [("stick", 1.5, 0.05), ("slip", 0.2, 50.0)])
def test_friction_tangent_matches_finite_differences(kind, order, regime, mu, ratio):
    X, geo_fn = _case(kind, order)
    s_bar, anchor = _history(X, geo_fn)
    R, K, st, f = _forces(geo_fn, X, s_bar, anchor, mu, ratio)
    n_active = int((f > 0).sum())
    assert n_active >= 6
    if regime == "stick":
        assert st.stick.sum() == n_active and not st.slip.any()
    else:
        assert st.slip.sum() == n_active and not st.stick.any()
    # the closest points move with the nodes: the dc/dX term of the tangent is exercised
    assert np.abs(geo_fn(X).ds).max() > 0.1
    assert np.abs(R).max() > 1e-4
    Kfd = fd_nodes(lambda Y: _forces(geo_fn, Y, s_bar, anchor, mu, ratio, False)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    M = X.shape[1]
    A = K.reshape(K.shape[0], 3 * M, 3 * M)
    if regime == "slip":   # the slip tangent is not symmetric
        assert np.abs(A - np.swapaxes(A, 1, 2)).max() > 1e-3 * np.abs(A).max()
    # action = reaction: the forces on a's nodes balance those on b's
    half = M // 2
    np.testing.assert_allclose(R[:, :half].sum(1), -R[:, half:].sum(1), atol=1e-14)


@pytest.mark.parametrize("kind, order", CASES)
def test_return_map_on_the_cone_and_tangent_to_the_contact(kind, order):
    X, geo_fn = _case(kind, order)
    s_bar, anchor = _history(X, geo_fn)
    geo = geo_fn(X)
    for mu, ratio in ((0.2, 50.0), (1.5, 0.05), (0.5, 2.0)):
        _, _, st, f = _forces(geo_fn, X, s_bar, anchor, mu, ratio, jac=False)
        tn = np.linalg.norm(st.t, axis=-1)
        assert np.all(tn <= mu * f * (1 + 1e-12) + 1e-300)
        np.testing.assert_allclose(tn[st.slip], mu * f[st.slip], rtol=1e-12)
        assert np.abs(np.einsum("pgi,pgi->pg", st.t, geo.n)).max() <= 1e-12 * max(tn.max(), 1e-300)


@pytest.mark.parametrize("kind, order", CASES)
@pytest.mark.parametrize("mu, ratio", [(1.5, 0.05), (0.2, 50.0), (0.5, 2.0)])
def test_commit_changes_no_force(kind, order, mu, ratio):
    X, geo_fn = _case(kind, order)
    s_bar, anchor = _history(X, geo_fn)
    R, _, st, _ = _forces(geo_fn, X, s_bar, anchor, mu, ratio, jac=False)
    assert np.abs(st.s_bar - s_bar)[st.stick | st.slip].max() > 1e-3      # the material points do move
    R2_, _, st2, _ = _forces(geo_fn, X, st.s_bar, st.anchor, mu, ratio, jac=False)
    np.testing.assert_allclose(R2_, R, rtol=0, atol=1e-12 * np.abs(R).max())
    assert np.abs(st2.dissipation).max() <= 1e-14 * max(np.abs(st.dissipation).max(), 1e-300) + 1e-300


def _loads_at(geo):
    _, p1, _ = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    return np.where(geo.active, W * p1, 0.0), geo.n


def _frozen(X, s_bar, anchor, mu, ratio, f0, n0, weights, jac=True, eta=0.0):
    kT = np.full(f0.shape, W * ratio * PEN)
    return frozen_potential(X, None, s_bar, anchor, f0, n0, kT, np.full(X.shape[0], mu), jac, eta, weights=weights)


@pytest.mark.parametrize("kind, order", CASES)
@pytest.mark.parametrize("regime, mu, ratio, eta", [("stick", 1.5, 0.05, 0.0), ("slip", 0.2, 50.0, 0.0),
                                                    ("mixed", 0.5, 2.0, 0.0), ("smoothed", 0.5, 2.0, 0.3)])
def test_frozen_potential_gradient_and_hessian(kind, order, regime, mu, ratio, eta):
    """At frozen loads (taken at another state) the forces are the gradient of sum psi and
    the tangent its Hessian (central differences), symmetric positive semi-definite, on
    the curves' M local nodes; with the cone's corner rounded (eta > 0) too."""
    X, geo_fn = _case(kind, order)
    s_bar, anchor = _history(X, geo_fn)
    f0, n0 = _loads_at(geo_fn(X + 0.003))
    wts = geo_fn(X + 0.003).material_weights          # the weights depend on s only
    psi, R, K = _frozen(X, s_bar, anchor, mu, ratio, f0, n0, wts, eta=eta)
    st = _forces(geo_fn, X, s_bar, anchor, mu, ratio, jac=False)[2]
    if regime == "stick":
        assert st.stick.sum() >= 6 and not st.slip.any()
    elif regime == "slip":
        assert st.slip.sum() >= 6 and not st.stick.any()
    Rfd = fd_nodes(lambda Y: _frozen(Y, s_bar, anchor, mu, ratio, f0, n0, wts, False, eta)[0].sum(axis=1), X)
    np.testing.assert_allclose(R, Rfd, rtol=1e-6, atol=1e-7 * np.abs(R).max())
    Kfd = fd_nodes(lambda Y: _frozen(Y, s_bar, anchor, mu, ratio, f0, n0, wts, False, eta)[1], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    M = X.shape[1]
    A = K.reshape(K.shape[0], 3 * M, 3 * M)
    np.testing.assert_allclose(A, np.swapaxes(A, 1, 2), atol=1e-14 * np.abs(A).max())
    assert np.linalg.eigvalsh(A).min() >= -1e-12 * np.abs(A).max()


@pytest.mark.parametrize("kind, order", CASES)
def test_frozen_potential_at_its_own_loads_is_the_law(kind, order):
    """Loads and material point frozen at the state itself (``moved_history`` to the closest
    points): the potential's forces are the return map's; with the material point where the
    history has it they are not (the law applies the force at the current closest point)."""
    X, geo_fn = _case(kind, order)
    s_bar, anchor = _history(X, geo_fn)
    geo = geo_fn(X)
    f0, n0 = _loads_at(geo)
    s_star, a_star = moved_history(X, None, s_bar, anchor, geo.s_minus, weights=geo.material_weights)
    np.testing.assert_allclose(tangential_gap(geo, X, s_star, a_star), tangential_gap(geo, X, s_bar, anchor),
                               rtol=0, atol=1e-15)
    for mu, ratio in ((1.5, 0.05), (0.2, 50.0), (0.5, 2.0)):
        R_law = _forces(geo_fn, X, s_bar, anchor, mu, ratio, jac=False)[0]
        _, R, _ = _frozen(X, s_star, a_star, mu, ratio, f0, n0, geo.material_weights, jac=False)
        np.testing.assert_allclose(R, R_law, rtol=0, atol=1e-14 * np.abs(R_law).max())
        _, R_old, _ = _frozen(X, s_bar, anchor, mu, ratio, f0, n0, geo.material_weights, jac=False)
        assert np.abs(R_old - R_law).max() > 1e-6 * np.abs(R_law).max()


# --------------------------------------------------------------------------- the turned anchor
@pytest.mark.parametrize("kind, order", CASES)
def test_direction_weights_are_the_tangent_at_a_point_and_its_derivative(kind, order):
    """``direction_weights(s) X = dq/ds`` (the - side's tangent, against differences of the
    material weights) and ``direction_weights_ds`` its derivative in s (differences)."""
    X, geo_fn = _case(kind, order)
    geo = geo_fn(X)
    h = 1e-6
    s = geo.s_minus + 0.1
    half = X.shape[1] // 2
    q = lambda v: -np.einsum("pgk,pki->pgi", geo.material_weights(v)[..., half:], X[:, half:])  # noqa: E731
    d = np.einsum("pgk,pki->pgi", geo.direction_weights(s), X)
    np.testing.assert_allclose(d, (q(s + h) - q(s - h)) / (2 * h), rtol=1e-7, atol=1e-8)
    assert np.abs(geo.direction_weights(s)[..., :half]).max() == 0.0
    fd = (geo.direction_weights(s + h) - geo.direction_weights(s - h)) / (2 * h)
    np.testing.assert_allclose(geo.direction_weights_ds(s), fd, rtol=1e-6, atol=1e-6)
    straight = kind == "curve" and order == 1       # a straight element: one direction
    assert (np.abs(geo.direction_weights_ds(s)).max() == 0.0) if straight else \
        (np.abs(geo.direction_weights_ds(s)).max() > 0.1)


@pytest.mark.parametrize("kind, order", CASES)
@pytest.mark.parametrize("regime, mu, ratio", [("stick", 1.5, 0.05), ("slip", 0.2, 50.0)])
def test_turned_friction_tangent_matches_finite_differences(kind, order, regime, mu, ratio):
    """With the anchor turned to the - side's direction at the current closest point (a
    direction that moves with that point along the curve) the tangent, the turn's derivative,
    the couple's and the moving weights of the couple included, matches central differences."""
    X, geo_fn = _case(kind, order)
    s_bar, anchor, d_ref = _history(X, geo_fn, turned=True)
    R, K, st, f = _forces(geo_fn, X, s_bar, anchor, mu, ratio, d_ref=d_ref)
    n_active = int((f > 0).sum())
    assert n_active >= 6
    if regime == "stick":
        assert st.stick.sum() == n_active
    else:
        assert st.slip.sum() == n_active
    # the direction moves with the closest point: its derivative terms are exercised
    geo = geo_fn(X)
    q2 = np.einsum("pgk,pki->pgi", geo.direction_weights_ds(geo.s_minus), X)
    assert np.abs(geo.ds).max() > 0.1
    if not (kind == "curve" and order == 1):
        assert np.abs(q2[f > 0]).max() > 0.05
    Kfd = fd_nodes(lambda Y: _forces(geo_fn, Y, s_bar, anchor, mu, ratio, False, d_ref=d_ref)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())


@pytest.mark.parametrize("kind, order", CASES)
@pytest.mark.parametrize("mu, ratio", [(1.5, 0.05), (0.2, 50.0)])
def test_turned_commit_changes_no_force(kind, order, mu, ratio):
    """The history committed at a state (material point, anchor and direction at the
    closest point) gives that state the same forces, the couple included: the direction of
    the turn is taken at the closest point, which a commit does not move."""
    X, geo_fn = _case(kind, order)
    s_bar, anchor, d_ref = _history(X, geo_fn, turned=True)
    R, _, st, _ = _forces(geo_fn, X, s_bar, anchor, mu, ratio, jac=False, d_ref=d_ref)
    assert np.abs(st.s_bar - s_bar)[st.stick | st.slip].max() > 1e-3      # the material points do move
    R2_, _, _, _ = _forces(geo_fn, X, st.s_bar, st.anchor, mu, ratio, jac=False, d_ref=st.d_ref)
    np.testing.assert_allclose(R2_, R, rtol=0, atol=1e-12 * np.abs(R).max())
