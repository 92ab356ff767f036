"""The friction law with the anchor carried by the - cross-section's frame
(``rve.physics.friction_forms.frame_friction_forces``, ``framed_anchor``): exact tangents in
the centroid and director components, objectivity under every rigid rotation (the twist
about the - fibril included), the balance of forces and moments, and the twist that the
position-based law cannot tell from sliding."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rve.physics.contact_forms import chord_geometry, penalty_law
from rve.physics.friction_forms import (framed_anchor, frame_friction_forces, frame_friction_state, friction_forces,
                                        minus_direction, section_frame, start_history, turned_anchor)
from rve.testing import fd_nodes
from test_friction_forms import PEN, R2, _forces_turned, _pairs


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _director_weights(s):
    """The chord's - side g1 at s: (0, 0, 1 - s, s), and its s-derivative."""
    s = np.asarray(s, float)
    z = np.zeros_like(s)
    return np.stack([z, z, 1.0 - s, s], -1), np.stack([z, z, -np.ones_like(s), np.ones_like(s)], -1)


def _section_weights(s):
    """The - element's section director: its first node's g1 (the p = 1 choice), at every s."""
    s = np.asarray(s, float)
    z = np.zeros_like(s)
    return np.stack([z, z, np.ones_like(s), z], -1), np.zeros(s.shape + (4,))


def _cell(seed=3):
    """The crossing chord pairs of ``test_friction_forms._pairs`` with the g1 of their four
    nodes, roughly across the chords with a tilt along them."""
    X, sp, _, _ = _pairs(seed=seed)
    Gd = np.array([0.0, 0.2, 1.0]) + np.random.default_rng(seed + 100).normal(size=X.shape) * 0.2
    return np.concatenate([X, Gd], -1), sp


def _history(Y0, sp):
    """The history of points with no elastic gap committed at ``Y0``: material point, anchor,
    and the frame (the - direction and the unit part of g1 across it)."""
    X0, G0 = Y0[..., :3], Y0[..., 3:]
    g0 = chord_geometry(*(X0[:, k] for k in range(4)), sp, np.full(X0.shape[0], R2))
    s_bar, anchor = start_history(X0, sp, g0.s_minus)
    d_ref = minus_direction(X0, g0.direction_weights(g0.s_minus))[0]
    m_ref = section_frame(d_ref, np.einsum("pgk,pki->pgi", _director_weights(g0.s_minus)[0], G0))[0]
    return s_bar, anchor, d_ref, m_ref


def _forces(Y, sp, hist, mu, ratio, jac=True, weights=_director_weights):
    X, G = Y[..., :3], Y[..., 3:]
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    w = np.full(geo.g.shape, 0.05)
    _, p1, p2 = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    f = np.where(geo.active, w * p1, 0.0)
    kN = np.where(geo.active, w * p2, 0.0)
    R, K = frame_friction_forces(geo, X, G, *hist, f, kN, w * ratio * PEN, np.full(X.shape[0], mu), weights, jac)
    return R, K, geo, f


def test_framed_anchor_derivatives_and_rotation():
    rng = np.random.default_rng(1)
    h = _unit(rng.normal(size=(3, 2, 3)))
    g = rng.normal(size=(3, 2, 3))
    r = _unit(rng.normal(size=(3, 2, 3)))
    m = _unit(np.cross(r, rng.normal(size=(3, 2, 3))))
    a = rng.normal(size=(3, 2, 3))
    _, (Jh, Jg) = framed_anchor(a, r, m, h, g, jacobian=True)
    eps = 1e-6
    for J, which in ((Jh, 0), (Jg, 1)):
        fd = np.zeros_like(J)
        for i in range(3):
            dv = np.zeros(3)
            dv[i] = eps
            args_p = (h + dv, g) if which == 0 else (h, g + dv)
            args_m = (h - dv, g) if which == 0 else (h, g - dv)
            fd[..., i] = (framed_anchor(a, r, m, *args_p) - framed_anchor(a, r, m, *args_m)) / (2 * eps)
        np.testing.assert_allclose(J, fd, atol=1e-8 * np.abs(J).max())
    # committed at (r, g0): the identity there, any rotation of (r, g0) turns the anchor with it
    g0 = rng.normal(size=(3, 2, 3))
    m0 = section_frame(r, g0)[0]
    np.testing.assert_allclose(framed_anchor(a, r, m0, r, g0), a, atol=1e-14)
    Q = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    np.testing.assert_allclose(framed_anchor(a, r, m0, r @ Q.T, g0 @ Q.T), a @ Q.T, atol=1e-14)


def test_framed_anchor_is_the_smallest_rotation_without_a_twist():
    """With g1 across the - direction and carried by the smallest rotation from ``d_ref`` to
    ``h`` (no twist), the frame's turn is the position-based law's turn."""
    rng = np.random.default_rng(2)
    r = _unit(rng.normal(size=(4, 2, 3)))
    h = _unit(r + 0.3 * rng.normal(size=(4, 2, 3)))
    m = _unit(np.cross(r, rng.normal(size=(4, 2, 3))))
    a = rng.normal(size=(4, 2, 3))
    g = 2.0 * turned_anchor(m, r, h)
    np.testing.assert_allclose(framed_anchor(a, r, m, h, g), turned_anchor(a, r, h), atol=1e-13)


@pytest.mark.parametrize("weights", [_director_weights, _section_weights])
@pytest.mark.parametrize("regime, mu, ratio", [("stick", 1.5, 0.05), ("slip", 0.2, 50.0), ("mixed", 0.5, 1.0)])
def test_frame_tangent_matches_finite_differences(regime, mu, ratio, weights):
    """g1 interpolated at the closest point, or the element's section node's."""
    Y, sp = _cell()
    rng = np.random.default_rng(5)
    hist = _history(Y + rng.normal(size=Y.shape) * np.r_[0.02, 0.02, 0.02, 0.05, 0.05, 0.05], sp)
    R, K, geo, f = _forces(Y, sp, hist, mu, ratio, weights=weights)
    assert int((f > 0).sum()) >= 5 and np.abs(R).max() > 1e-4
    st = frame_friction_state(geo, Y[..., :3], Y[..., 3:], *hist, f, np.full(f.shape, 0.05 * ratio * PEN),
                              np.full(5, mu), weights)
    n_stick, n_slip = int(st.stick.sum()), int(st.slip.sum())
    assert {"stick": n_slip == 0, "slip": n_stick == 0, "mixed": n_stick > 0 and n_slip > 0}[regime]
    Kfd = fd_nodes(lambda Z: _forces(Z, sp, hist, mu, ratio, False, weights)[0], Y)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-7 * np.abs(K).max())
    # the director blocks are there: the twist's couple on g1 and g1's turn of the gap
    assert np.abs(K[:, :, 3:]).max() > 1e-3 * np.abs(K).max()
    assert np.abs(K[:, :, :3, :, 3:]).max() > 1e-3 * np.abs(K).max()


@pytest.mark.parametrize("mu, ratio", [(0.2, 50.0), (1.5, 0.05)])
def test_frame_forces_balance_forces_and_moments(mu, ratio):
    """No net force and no net moment on a pair: sum R_X = 0 and sum X x R_X + G x R_G = 0 (a
    rigid rotation of a pair does no work against its residual), the twist part included."""
    Y, sp = _cell()
    rng = np.random.default_rng(6)
    hist = _history(Y + rng.normal(size=Y.shape) * 0.03, sp)
    R, _, _, _ = _forces(Y, sp, hist, mu, ratio, jac=False)
    scale = np.abs(R).max()
    assert scale > 1e-4
    np.testing.assert_allclose(R[..., :3].sum(axis=1), 0.0, atol=1e-13 * scale)
    moment = (np.cross(Y[..., :3], R[..., :3]) + np.cross(Y[..., 3:], R[..., 3:])).sum(axis=1)
    np.testing.assert_allclose(moment, 0.0, atol=1e-12 * scale)


def test_frame_makes_every_rigid_rotation_slip_free():
    """History committed with no elastic gap, then every pair (centroids and directors) turned
    rigidly by 0.2 rad about three axes, one of them the - chord's own: no friction force. The
    position-based law reads the rotation about the - chord as a slip."""
    Y, sp = _cell()
    hist = _history(Y, sp)
    s_bar, anchor, d_ref, _ = hist
    h = d_ref[:, 0]
    a1 = _unit(np.cross(h, [0.0, 0.0, 1.0]))
    f_scale = None
    for axis in (a1, np.cross(h, a1), h):
        Rm = Rotation.from_rotvec(0.2 * axis).as_matrix()                     # (P, 3, 3)
        centre = Y[..., :3].mean(axis=1, keepdims=True)
        Xr = np.einsum("pij,pkj->pki", Rm, Y[..., :3] - centre) + centre
        Gr = np.einsum("pij,pkj->pki", Rm, Y[..., 3:])
        R, _, geo, f = _forces(np.concatenate([Xr, Gr], -1), sp, hist, 0.3, 1.0, jac=False)
        f_scale = 0.3 * f.max()
        assert f_scale > 0
        assert np.abs(R).max() <= 1e-12 * f_scale
    R_pos = _forces_turned(Xr, sp, s_bar, anchor, d_ref, 0.3, 1.0, False)[0]
    assert np.abs(R_pos).max() > 0.1 * f_scale


def test_frame_reads_sliding_around_the_fibril_as_slip():
    """The + side carried around the - fibril (about the - chord's axis) with the - fibril's
    directors held: the position-based law and the frame law both read it as a slip, with the
    same force (the frame has not turned)."""
    Y, sp = _cell()
    hist = _history(Y, sp)
    s_bar, anchor, d_ref, _ = hist
    h = d_ref[:, 0]
    Rm = Rotation.from_rotvec(0.05 * h).as_matrix()
    axis_point = Y[:, 2, :3][:, None]
    Xs = Y[..., :3].copy()
    Xs[:, :2] = np.einsum("pij,pkj->pki", Rm, Xs[:, :2] - axis_point) + axis_point
    Ys = np.concatenate([Xs, Y[..., 3:]], -1)
    R, _, geo, f = _forces(Ys, sp, hist, 0.3, 1.0, jac=False)
    assert np.abs(R[:, :2, :3]).max() > 0.1 * 0.3 * f.max()
    w = np.full(geo.g.shape, 0.05)
    R_pos, _ = friction_forces(geo, Xs, s_bar, anchor, f, np.zeros_like(f), w * PEN, np.full(Ys.shape[0], 0.3),
                               False, d_ref=d_ref)
    np.testing.assert_allclose(R[:, :2, :3], R_pos[:, :2], atol=1e-12 * np.abs(R_pos).max())


@pytest.mark.parametrize("mu, ratio", [(0.2, 50.0), (1.5, 0.05), (0.5, 2.0)])
def test_frame_commit_changes_no_force(mu, ratio):
    """The history committed at a state (``frame_friction_state``: the closest point, the
    elastic gap, the frame there) gives the same residual at that state: a converged state
    stays an equilibrium under its own history."""
    Y, sp = _cell()
    rng = np.random.default_rng(8)
    hist = _history(Y + rng.normal(size=Y.shape) * 0.03, sp)
    R0, _, geo, f = _forces(Y, sp, hist, mu, ratio, jac=False)
    kT = np.full(f.shape, 0.05 * ratio * PEN)
    st = frame_friction_state(geo, Y[..., :3], Y[..., 3:], *hist, f, kT, np.full(5, mu), _director_weights)
    R1, _, _, _ = _forces(Y, sp, (st.s_bar, st.anchor, st.d_ref, st.m_ref), mu, ratio, jac=False)
    np.testing.assert_allclose(R1, R0, atol=1e-12 * np.abs(R0).max())
    assert np.abs(R0).max() > 1e-4


def _frozen_setup(mu=0.3, ratio=1.0, seed=9):
    """Loads and point frozen at the state Y itself, from a history committed elsewhere."""
    from rve.physics.friction_forms import frame_frozen_turn, frame_moved_history

    Y, sp = _cell()
    rng = np.random.default_rng(seed)
    hist = _history(Y + rng.normal(size=Y.shape) * 0.03, sp)
    X, G = Y[..., :3], Y[..., 3:]
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    w = np.full(geo.g.shape, 0.05)
    _, p1, _ = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    f = np.where(geo.active, w * p1, 0.0)
    kT = w * ratio * PEN
    sm = geo.s_minus
    s1, a1, _, _ = frame_moved_history(X, G, *hist, sm, geo.material_weights, geo.direction_weights,
                                       lambda s: _director_weights(s)[0])
    Dw, Jd, d, gw, Jg, g = frame_frozen_turn(X, G, geo.direction_weights(sm), _director_weights(sm)[0], geo.n,
                                             geo.rho, geo.active)
    anchor = a1 - np.einsum("pgij,pgj->pgi", Jd, d) - np.einsum("pgij,pgj->pgi", Jg, g)
    frozen = (geo.material_weights(s1), anchor, f, np.where(geo.active[..., None], geo.n, 0.0), kT,
              np.full(f.shape, mu), (Dw, Jd, gw, Jg))
    return Y, sp, hist, frozen, mu, ratio


def test_frame_frozen_potential_is_the_law_at_its_state():
    """At loads, point and frame frozen at the state itself the frozen potential's gradient is
    the frame law's residual there (its couples included)."""
    from rve.physics.friction_forms import frame_frozen_potential

    Y, sp, hist, (cb, anchor, f0, n0, kT, mu, turn), mu_, ratio = _frozen_setup()
    _, Rf, _ = frame_frozen_potential(Y, cb, anchor, f0, n0, kT, mu, False, 0.0, turn)
    R, _, _, _ = _forces(Y, sp, hist, mu_, ratio, jac=False)
    assert np.abs(R).max() > 1e-4
    np.testing.assert_allclose(Rf, R, atol=1e-11 * np.abs(R).max())


@pytest.mark.parametrize("eta", [0.0, 0.5])
def test_frame_frozen_potential_derivatives(eta):
    """R is the gradient of psi and K the (symmetric) derivative of R, centroids and g1."""
    from rve.physics.friction_forms import frame_frozen_potential

    Y, _, _, (cb, anchor, f0, n0, kT, mu, turn), _, _ = _frozen_setup()
    rng = np.random.default_rng(4)
    Y1 = Y + rng.normal(size=Y.shape) * 0.01
    _, R, K = frame_frozen_potential(Y1, cb, anchor, f0, n0, kT, mu, True, eta, turn)
    psi_sum = lambda Z: frame_frozen_potential(Z, cb, anchor, f0, n0, kT, mu, False, eta, turn)[0].sum(axis=1)
    np.testing.assert_allclose(R, fd_nodes(psi_sum, Y1), atol=1e-7 * np.abs(R).max())
    Kfd = fd_nodes(lambda Z: frame_frozen_potential(Z, cb, anchor, f0, n0, kT, mu, False, eta, turn)[1], Y1)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-7 * np.abs(K).max())
    KT = np.swapaxes(np.swapaxes(K, 1, 3), 2, 4)
    np.testing.assert_allclose(K, KT, atol=1e-12 * np.abs(K).max())
