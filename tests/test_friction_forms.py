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


def _turned_history(X, sp):
    """A history committed at a nearby state X0 with its - chord direction there, and X0."""
    from rve.physics.friction_forms import minus_direction

    rng = np.random.default_rng(7)
    X0 = X + rng.normal(size=X.shape) * 0.02
    g0 = chord_geometry(*(X0[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    s_bar, anchor = start_history(X0, sp, g0.s_minus)
    d_ref = minus_direction(X0, g0.direction_weights(g0.s_minus))[0]
    return s_bar, anchor, d_ref


def _forces_turned(X, sp, s_bar, anchor, d_ref, mu, ratio, jac=True):
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    w = np.full(geo.g.shape, 0.05)
    _, p1, p2 = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    f = np.where(geo.active, w * p1, 0.0)
    kN = np.where(geo.active, w * p2, 0.0)
    R, K = friction_forces(geo, X, s_bar, anchor, f, kN, w * ratio * PEN, np.full(X.shape[0], mu), jac,
                           d_ref=d_ref)
    st = friction_state(geo, X, s_bar, anchor, f, w * ratio * PEN, np.full(X.shape[0], mu), d_ref=d_ref)
    return R, K, st, f


@pytest.mark.parametrize("mu, ratio", [(1.5, 0.05), (0.2, 50.0), (0.5, 2.0)])
def test_turned_anchor_tangent_matches_finite_differences(mu, ratio):
    """With the anchor turned with the - chord (``d_ref`` of another state) the tangent,
    the turn's derivative included, matches differences of the residual."""
    X, sp, _, _ = _pairs()
    s_bar, anchor, d_ref = _turned_history(X, sp)
    R, K, st, f = _forces_turned(X, sp, s_bar, anchor, d_ref, mu, ratio)
    assert int((f > 0).sum()) >= 5 and np.abs(R).max() > 1e-4
    Kfd = fd_nodes(lambda Y: _forces_turned(Y, sp, s_bar, anchor, d_ref, mu, ratio, False)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())


def test_turned_anchor_makes_a_rigid_rotation_slip_free():
    """History committed with no elastic gap, then every pair rotated rigidly by 0.2 rad about
    an axis across its - chord (two such axes): with the anchor turned with the chord the
    friction force is zero (no slip happened); left unturned it is not (the stored -j_n, the
    length of the radii, reads as a tangential gap). A rotation about the - chord's own axis,
    which positions cannot tell from the + side sliding around it, still reads as a slip."""
    from rve.physics.friction_forms import minus_direction
    from scipy.spatial.transform import Rotation

    X, sp, _, _ = _pairs()
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    s_bar, anchor = start_history(X, sp, geo.s_minus)
    d_ref = minus_direction(X, geo.direction_weights(geo.s_minus))[0]
    h = d_ref[:, 0]                                    # (P, 3): one - chord per pair
    a1 = np.cross(h, [0.0, 0.0, 1.0])
    a1 /= np.linalg.norm(a1, axis=1)[:, None]
    a2 = np.cross(h, a1)
    f_scale = np.abs(geo.g).max() * 0.05 * PEN
    for axes, objective in ((a1, True), (a2, True), (h, False)):
        Rm = Rotation.from_rotvec(0.2 * axes).as_matrix()            # (P, 3, 3)
        centre = X.mean(axis=1, keepdims=True)
        Xr = np.einsum("pij,pkj->pki", Rm, X - centre) + centre
        R_turn = _forces_turned(Xr, sp, s_bar, anchor, d_ref, 0.3, 1.0, False)[0]
        R_fixed = _forces_turned(Xr, sp, s_bar, anchor, None, 0.3, 1.0, False)[0]
        assert np.abs(R_fixed).max() > 0.1 * 0.3 * f_scale
        if objective:
            assert np.abs(R_turn).max() <= 1e-12 * f_scale
        else:
            assert np.abs(R_turn).max() > 0.1 * 0.3 * f_scale


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


@pytest.mark.parametrize("mu, ratio", [(1.5, 0.05), (0.2, 50.0), (0.5, 2.0)])
def test_commit_changes_no_force(mu, ratio):
    """The history committed at a state (material point moved to the closest point, the
    elastic gap kept) gives that state the same friction forces, in stick, slip and a mix:
    a converged state stays an equilibrium after its commit."""
    X, sp, s_bar, anchor = _pairs()
    R, _, st, f = _forces(X, sp, s_bar, anchor, mu, ratio, jac=False)
    assert np.abs(st.s_bar - s_bar).max() > 1e-3                 # the material points do move
    R2_, _, st2, _ = _forces(X, sp, st.s_bar, st.anchor, mu, ratio, jac=False)
    # (the anchor is a difference of positions: its rounding is |X| eps kT ~ 1e-14 N)
    np.testing.assert_allclose(R2_, R, rtol=0, atol=1e-12 * np.abs(R).max())
    assert np.abs(st2.dissipation).max() <= 1e-14 * max(np.abs(st.dissipation).max(), 1e-300) + 1e-300


def test_no_gap_history_gives_no_force():
    X, sp, _, _ = _pairs()
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    s_bar, anchor = start_history(X, sp, geo.s_minus)
    R, _, st, _ = _forces(X, sp, s_bar, anchor, 0.3, 1.0, jac=False)
    assert np.abs(R).max() <= 1e-14


def _frozen(X, sp, s_bar, anchor, mu, ratio, f0, n0, jac=True):
    from rve.physics.friction_forms import frozen_potential

    kT = np.full(f0.shape, 0.05 * ratio * PEN)
    return frozen_potential(X, sp, s_bar, anchor, f0, n0, kT, np.full(X.shape[0], mu), jac)


def _loads_at(X, sp):
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    _, p1, _ = penalty_law(np.where(geo.active, geo.g, 0.0), PEN)
    return np.where(geo.active, 0.05 * p1, 0.0), geo.n


@pytest.mark.parametrize("regime, mu, ratio", [("stick", 1.5, 0.05), ("slip", 0.2, 50.0), ("mixed", 0.5, 2.0)])
def test_frozen_potential_gradient_and_hessian(regime, mu, ratio):
    """At frozen loads the friction forces are the gradient of sum psi and the tangent its
    Hessian (finite differences of the potential and of the forces); the Hessian is
    symmetric positive semi-definite (the minimiser's model is convex)."""
    X, sp, s_bar, anchor = _pairs()
    f0, n0 = _loads_at(X + 0.003, sp)              # loads frozen at another state
    psi, R, K = _frozen(X, sp, s_bar, anchor, mu, ratio, f0, n0)
    st = _forces(X, sp, s_bar, anchor, mu, ratio, jac=False)[2]
    if regime == "stick":
        assert st.stick.sum() >= 5 and not st.slip.any()
    elif regime == "slip":
        assert st.slip.sum() >= 5 and not st.stick.any()
    Rfd = fd_nodes(lambda Y: _frozen(Y, sp, s_bar, anchor, mu, ratio, f0, n0, False)[0].sum(axis=1), X)
    np.testing.assert_allclose(R, Rfd, rtol=1e-6, atol=1e-7 * np.abs(R).max())
    Kfd = fd_nodes(lambda Y: _frozen(Y, sp, s_bar, anchor, mu, ratio, f0, n0, False)[1], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    A = K.reshape(K.shape[0], 12, 12)
    np.testing.assert_allclose(A, np.swapaxes(A, 1, 2), atol=1e-14 * np.abs(A).max())
    assert np.linalg.eigvalsh(A).min() >= -1e-12 * np.abs(A).max()


def test_frozen_potential_at_its_own_loads_is_the_law():
    """With the loads and the material point frozen at the state itself (``moved_history``
    to the closest points) the potential's forces are the return map's (friction_forces),
    in stick and in slip; with the material point left where the history has it they are
    not (the law applies the force at the current closest point); psi is continuous at the
    cone."""
    from rve.physics.friction_forms import moved_history

    X, sp, s_bar, anchor = _pairs()
    f0, n0 = _loads_at(X, sp)
    sm = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2)).s_minus
    s_star, a_star = moved_history(X, sp, s_bar, anchor, sm)
    for mu, ratio in ((1.5, 0.05), (0.2, 50.0), (0.5, 2.0)):
        R_law = _forces(X, sp, s_bar, anchor, mu, ratio, jac=False)[0]
        _, R, _ = _frozen(X, sp, s_star, a_star, mu, ratio, f0, n0, jac=False)
        np.testing.assert_allclose(R, R_law, rtol=0, atol=1e-14 * np.abs(R_law).max())
        _, R_old, _ = _frozen(X, sp, s_bar, anchor, mu, ratio, f0, n0, jac=False)
        assert np.abs(R_old - R_law).max() > 1e-6 * np.abs(R_law).max()
    # psi on both sides of the stick limit |e| = mu f0 / kT (one point, the gap scaled)
    from rve.physics.friction_forms import tangential_gap

    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    e = tangential_gap(geo, X, s_bar, anchor)
    kT = 0.05 * 2.0 * PEN
    p, g = np.unravel_index(np.argmax(f0), f0.shape)
    limit = 0.5 * f0[p, g]
    en = np.linalg.norm(e[p, g])
    # the anchor moved so that |e| sits just below / above the limit of that point
    for side in (1 - 1e-9, 1 + 1e-9):
        a2 = anchor.copy()
        a2[p, g] += e[p, g] * (side * limit / kT / en - 1.0)
        psi, _, _ = _frozen(X, sp, s_bar, a2, 0.5, 2.0, f0, n0, jac=False)
        np.testing.assert_allclose(psi[p, g], 0.5 * limit * limit / kT, rtol=1e-8)


@pytest.mark.parametrize("eta", [0.5, 0.05])
def test_smoothed_potential_gradient_hessian_and_limit(eta):
    """The predictor's rounded cone (eta > 0): forces the gradient of the potential, tangent
    its Hessian (finite differences), convex; the force never above (1 + eta^2/4) mu f0,
    and tending to the law's as eta -> 0."""
    from rve.physics.friction_forms import frozen_potential

    X, sp, s_bar, anchor = _pairs()
    f0, n0 = _loads_at(X + 0.003, sp)
    mu, ratio = 0.5, 2.0
    kT = np.full(f0.shape, 0.05 * ratio * PEN)
    mus = np.full(X.shape[0], mu)

    def fp(Y, jac=False, e=eta):
        return frozen_potential(Y, sp, s_bar, anchor, f0, n0, kT, mus, jac, e)

    psi, R, K = fp(X, True)
    Rfd = fd_nodes(lambda Y: fp(Y)[0].sum(axis=1), X)
    np.testing.assert_allclose(R, Rfd, rtol=1e-6, atol=1e-7 * np.abs(R).max())
    Kfd = fd_nodes(lambda Y: fp(Y)[1], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    A = K.reshape(K.shape[0], 12, 12)
    assert np.linalg.eigvalsh(A).min() >= -1e-12 * np.abs(A).max()
    # the point forces: R_k = cb_k t, so t = R[:, 0] / cb_0 for one point per pair (G = 3 here:
    # compare the pair sums with the law's bound instead)
    bound = (1 + eta * eta / 4) * mu * f0.sum(axis=1)
    assert np.all(np.linalg.norm(R[:, 0] + R[:, 1], axis=-1) <= bound * (1 + 1e-12) + 1e-300)
    R_law = fp(X, e=0.0)[1]
    R_tiny = fp(X, e=1e-7)[1]
    np.testing.assert_allclose(R_tiny, R_law, rtol=0, atol=1e-5 * np.abs(R_law).max())


def _frozen_turned(X, sp, s_bar, anchor, f0, n0, mu, ratio, turn, jac=True, eta=0.0):
    from rve.physics.friction_forms import frozen_potential

    kT = np.full(f0.shape, 0.05 * ratio * PEN)
    return frozen_potential(X, sp, s_bar, anchor, f0, n0, kT, np.full(X.shape[0], mu), jac, eta, turn=turn)


@pytest.mark.parametrize("eta", [0.0, 0.5])
@pytest.mark.parametrize("mu, ratio", [(1.5, 0.05), (0.2, 50.0), (0.5, 2.0)])
def test_frozen_turn_is_a_potential_and_at_its_own_state_the_law(mu, ratio, eta):
    """The frozen potential with the anchor's turn (matrix weights ``cb I + Dw Jd``): its
    forces are its gradient and its tangent its Hessian (symmetric, positive semi-definite);
    frozen at the state itself (loads, point, turn: ``moved_history`` with ``d_ref``,
    ``frozen_turn``) its forces are the law's, the couple included."""
    from rve.physics.friction_forms import frozen_turn, moved_history

    X, sp, _, _ = _pairs()
    s_bar, anchor, d_ref = _turned_history(X, sp)
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    f0, n0 = _loads_at(X, sp)
    s_star, a_star, _ = moved_history(X, sp, s_bar, anchor, geo.s_minus, d_ref=d_ref)
    Dw, Jd, d = frozen_turn(X, geo.direction_weights(geo.s_minus), geo.n, geo.rho, geo.active)
    a_f = a_star - np.einsum("pgij,pgj->pgi", Jd, d)
    turn = (Dw, Jd)
    if eta == 0.0:
        R_law = _forces_turned(X, sp, s_bar, anchor, d_ref, mu, ratio, jac=False)[0]
        R_fz = _frozen_turned(X, sp, s_star, a_f, f0, n0, mu, ratio, turn, jac=False)[1]
        np.testing.assert_allclose(R_fz, R_law, rtol=0, atol=1e-12 * np.abs(R_law).max())
    # away from the freeze state: gradient and Hessian by differences
    Y = X + 0.002
    psi, R, K = _frozen_turned(Y, sp, s_star, a_f, f0, n0, mu, ratio, turn, eta=eta)
    Rfd = fd_nodes(lambda Z: _frozen_turned(Z, sp, s_star, a_f, f0, n0, mu, ratio, turn, False, eta)[0].sum(axis=1), Y)
    np.testing.assert_allclose(R, Rfd, rtol=1e-6, atol=1e-7 * np.abs(R).max())
    Kfd = fd_nodes(lambda Z: _frozen_turned(Z, sp, s_star, a_f, f0, n0, mu, ratio, turn, False, eta)[1], Y)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-6 * np.abs(K).max())
    A = K.reshape(K.shape[0], 12, 12)
    np.testing.assert_allclose(A, np.swapaxes(A, 1, 2), atol=1e-13 * np.abs(A).max())
    assert np.linalg.eigvalsh(A).min() >= -1e-12 * np.abs(A).max()


@pytest.mark.parametrize("mu, ratio", [(1.5, 0.05), (0.2, 50.0), (0.5, 2.0)])
def test_commit_with_the_turn_changes_no_force(mu, ratio):
    """With the anchor turning with the chord, the history committed at a state (material
    point, anchor and chord direction there) gives that state the same forces, the couple
    included."""
    X, sp, _, _ = _pairs()
    s_bar, anchor, d_ref = _turned_history(X, sp)
    R, _, st, _ = _forces_turned(X, sp, s_bar, anchor, d_ref, mu, ratio, jac=False)
    R2_, _, _, _ = _forces_turned(X, sp, st.s_bar, st.anchor, st.d_ref, mu, ratio, jac=False)
    np.testing.assert_allclose(R2_, R, rtol=0, atol=1e-12 * np.abs(R).max())


def test_couple_balances_the_moment_of_the_friction_forces():
    """The friction forces of a point on the pair's nodes sum to zero, and with the couple their
    moment has no part across the - chord (only the twist about it, which a position-only
    chord cannot carry); without the couple the pair of forces, rho n apart, leaves a net
    moment."""
    from rve.physics.friction_forms import minus_direction

    X, sp, _, _ = _pairs()
    s_bar, anchor, d_ref = _turned_history(X, sp)
    R = _forces_turned(X, sp, s_bar, anchor, d_ref, 0.3, 1.0, jac=False)[0]
    R0 = _forces(X, sp, s_bar, anchor, 0.3, 1.0, jac=False)[0]
    geo = chord_geometry(*(X[:, k] for k in range(4)), sp, np.full(X.shape[0], R2))
    h = minus_direction(X, geo.direction_weights(geo.s_minus))[0][:, 0]
    for forces, balanced in ((R, True), (R0, False)):
        assert np.abs(forces.sum(axis=1)).max() <= 1e-15
        M = np.cross(X, -forces).sum(axis=1)
        across = M - np.einsum("pi,pi->p", M, h)[:, None] * h
        scale = np.abs(forces).max() * np.abs(X).max()
        if balanced:
            assert np.abs(across).max() <= 1e-12 * scale
        else:
            assert np.abs(across).max() > 1e-2 * scale
