"""The contact forms on the Lagrange centroid curve (rve.physics.contact_curve): the closest
point against a brute-force search, the residual as the gradient of the penalty energy, the
tangent against central differences (p = 1, 2, 3; interior and clamped closest points), the
p = 1 forms against the chord forms, and the jump terms' tangents."""
import numpy as np
import pytest

from rve.testing import fd_nodes

from rve.physics.contact_curve import (
    curve_basis, curve_geometry, curve_penalty_energy, curve_penalty_forces, curve_scalar_jump,
    gauss_legendre_01, project_to_curve,
)
from rve.physics.contact_forms import chord_geometry, penalty_forces

R2 = 0.3


def _curved_pairs(order, P=5, overlap=0.04, seed=3, shift_b=(0.0, 0.0, 0.0)):
    """P crossing pairs of curved elements (a along x, b along y, bowed), nodes (P, nn, 3)."""
    rng = np.random.default_rng(seed)
    nn = order + 1
    u = np.linspace(0.0, 1.0, nn)
    Xa = np.zeros((P, nn, 3))
    Xb = np.zeros((P, nn, 3))
    Xa[..., 0] = -0.35 + 0.7 * u
    Xa[..., 2] = -0.08 * u * (1 - u) * (order > 1)
    Xb[..., 1] = -0.35 + 0.7 * u
    Xb[..., 2] = -(R2 - overlap) + 0.06 * u * (1 - u) * (order > 1)
    Xa += rng.normal(size=Xa.shape) * 0.02
    Xb += rng.normal(size=Xb.shape) * 0.02 + np.asarray(shift_b)
    return Xa, Xb


def _geo(order, Xa, Xb, G=4, has_next=False, has_prev=False, t_next=None):
    P = Xa.shape[0]
    s, _ = gauss_legendre_01(G)
    tn = np.zeros((P, 3)) if t_next is None else t_next
    return curve_geometry(order, Xa, Xb, s, np.full(P, R2), np.full(P, has_next), tn, np.full(P, has_prev))




@pytest.mark.parametrize("order", [2, 3])
def test_projection_is_the_closest_point(order):
    Xa, Xb = _curved_pairs(order)
    s_a, _ = gauss_legendre_01(4)
    Na, _, _ = curve_basis(order, s_a)
    p = np.einsum("ga,pai->pgi", Na, Xa)
    s = project_to_curve(order, Xb, p)
    grid = np.linspace(0.0, 1.0, 20001)
    Ng, _, _ = curve_basis(order, grid)
    Q = np.einsum("ka,pai->pki", Ng, Xb)  # (P, K, 3)
    d2 = ((p[:, :, None, :] - Q[:, None, :, :]) ** 2).sum(-1)
    best = grid[np.argmin(d2, axis=-1)]
    np.testing.assert_allclose(s, best, atol=1e-4)
    Nb, _, _ = curve_basis(order, s)
    q = np.einsum("pgb,pbi->pgi", Nb, Xb)
    assert np.all(np.linalg.norm(p - q, axis=-1) <= np.sqrt(d2.min(axis=-1)) + 1e-12)


def test_second_derivative_of_the_basis():
    s = np.linspace(0.05, 0.95, 7)
    for order in (1, 2, 3, 4):
        N, dN, d2N = curve_basis(order, s)
        h = 1e-5
        Np, dNp, _ = curve_basis(order, s + h)
        Nm, dNm, _ = curve_basis(order, s - h)
        np.testing.assert_allclose(dN, (Np - Nm) / (2 * h), atol=1e-7)
        np.testing.assert_allclose(d2N, (dNp - dNm) / (2 * h), atol=1e-5 * max(1.0, np.abs(d2N).max()))


@pytest.mark.parametrize("order", [1, 2, 3])
def test_penalty_gradient_and_tangent(order):
    Xa, Xb = _curved_pairs(order)
    w = np.full((Xa.shape[0], 4), 0.05)
    Ps = 50.0
    X = np.concatenate([Xa, Xb], axis=1)
    nn = order + 1

    def energy(Y):
        geo = _geo(order, Y[:, :nn], Y[:, nn:])
        return np.array([curve_penalty_energy(_take(geo, i), w[i], Ps) for i in range(len(Y))])

    def resid(Y):
        return curve_penalty_forces(_geo(order, Y[:, :nn], Y[:, nn:]), w, Ps, False)[0]

    geo = _geo(order, Xa, Xb)
    assert geo.active.sum() > 4 and np.any((geo.s_b > 0) & (geo.s_b < 1) & geo.active)
    R, K = curve_penalty_forces(geo, w, Ps, True)
    np.testing.assert_allclose(R, fd_nodes(energy, X), rtol=1e-6, atol=1e-9)
    Kfd = fd_nodes(resid, X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    M = 2 * nn
    Km = K.reshape(-1, 3 * M, 3 * M)
    np.testing.assert_allclose(Km, np.swapaxes(Km, 1, 2), atol=1e-10 * np.abs(K).max())
    np.testing.assert_allclose(R[:, :nn].sum(1), -R[:, nn:].sum(1), atol=1e-14)  # action = reaction


def _take(geo, i):
    from rve.physics.contact_curve import CurveGeometry

    return CurveGeometry(**{k: (None if v is None else v[i:i + 1]) for k, v in geo.__dict__.items()})


@pytest.mark.parametrize("order", [1, 2])
def test_clamped_closest_points_tangent(order):
    """b shifted so the points near its end clamp (free end: owned, ds = 0)."""
    Xa, Xb = _curved_pairs(order, shift_b=(0.0, -0.4, 0.0))
    w = np.full((Xa.shape[0], 4), 0.05)
    X = np.concatenate([Xa, Xb], axis=1)
    nn = order + 1
    geo = _geo(order, Xa, Xb)
    assert np.any(geo.active & (geo.s_b >= 1.0))
    R, K = curve_penalty_forces(geo, w, 50.0)
    Kfd = fd_nodes(lambda Y: curve_penalty_forces(_geo(order, Y[:, :nn], Y[:, nn:]), w, 50.0, False)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())


def test_ownership_passes_clamped_points_to_the_next_element():
    """A clamped point at s_b = 1 belongs to b only when the next element bends away."""
    Xa, Xb = _curved_pairs(1, shift_b=(0.0, -0.4, 0.0))
    P = Xa.shape[0]
    d = Xb[:, -1] - Xb[:, 0]
    on = _geo(1, Xa, Xb, has_next=True, t_next=d)  # next continues straight: it owns the point
    off = _geo(1, Xa, Xb, has_next=True, t_next=-d)  # next turns back: b keeps its end
    free = _geo(1, Xa, Xb)
    clamped = free.s_b >= 1.0
    assert clamped.any()
    assert not (on.owned & clamped).any()
    assert (off.owned == free.owned).all()


def test_linear_curve_equals_chord_forms():
    Xa, Xb = _curved_pairs(1)
    P = Xa.shape[0]
    sp = np.broadcast_to((np.arange(4) + 0.5) / 4, (P, 4)).copy()
    chord = chord_geometry(Xa[:, 0], Xa[:, 1], Xb[:, 0], Xb[:, 1], sp, np.full(P, R2))
    curve = curve_geometry(1, Xa, Xb, sp, np.full(P, R2), np.zeros(P, bool), np.zeros((P, 3)), np.zeros(P, bool))
    np.testing.assert_allclose(curve.s_b, chord.s_minus, atol=1e-15)
    R0, K0 = penalty_forces(chord, np.full(P, 0.05), 50.0)
    R1, K1 = curve_penalty_forces(curve, 0.05, 50.0)
    np.testing.assert_allclose(R1, R0, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(K1, K0, rtol=1e-10, atol=1e-12 * np.abs(K0).max())


@pytest.mark.parametrize("order", [1, 2])
def test_scalar_jump_tangents(order):
    Xa, Xb = _curved_pairs(order)
    nn = order + 1
    rng = np.random.default_rng(1)
    ua = rng.normal(size=(Xa.shape[0], nn))
    ub = rng.normal(size=(Xa.shape[0], nn))
    X = np.concatenate([Xa, Xb], axis=1)
    kappa, w = 0.8, 0.05

    def law(geo):  # a smooth conductance of the gap: w kappa g^2 (derivative 2 w kappa g)
        g = np.where(geo.active, geo.g, 0.0)
        return w * kappa * g * g, 2.0 * w * kappa * g

    def res(Y, ua=ua, ub=ub):
        geo = _geo(order, Y[:, :nn], Y[:, nn:])
        k, dk = law(geo)
        return curve_scalar_jump(geo, ua, ub, k, dk, False)[0]

    geo = _geo(order, Xa, Xb)
    k, dk = law(geo)
    R, Ju, JX = curve_scalar_jump(geo, ua, ub, k, dk)
    np.testing.assert_allclose(JX, fd_nodes(res, X), rtol=1e-5, atol=1e-7 * np.abs(JX).max())
    U = np.concatenate([ua, ub], axis=1)
    np.testing.assert_allclose(np.einsum("pAB,pB->pA", Ju, U), R, rtol=1e-12, atol=1e-15)  # linear in u
    np.testing.assert_allclose(R.sum(axis=1), 0.0, atol=1e-14)  # conservative
