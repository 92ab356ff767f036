"""Finite-difference checks of the contact forms (rve.physics.contact_forms) and of the
assembled ContactSystem: every block, recomputed and frozen closest points, the onset."""
import numpy as np
import pytest

from rve.testing import fd_nodes

from rve.physics.contact_forms import (
    chord_geometry, hertz_kappa, hertz_width, penalty_forces, scalar_jump,
)

RNG = np.random.default_rng(7)
R2 = 0.3  # R+ + R-


def _pairs(P=6, G=4, overlap=0.05, seed=0):
    """P crossing chord pairs whose centroids are R2 - overlap apart (+ noise)."""
    rng = np.random.default_rng(seed)
    ap = rng.normal(size=(P, 3)) * 0.05 + [-0.3, 0.0, 0.0]
    bp = ap + [0.6, 0.0, 0.0] + rng.normal(size=(P, 3)) * 0.05
    am = rng.normal(size=(P, 3)) * 0.05 + [0.0, -0.3, -(R2 - overlap)]
    bm = am + [0.0, 0.6, 0.0] + rng.normal(size=(P, 3)) * 0.05
    X = np.stack([ap, bp, am, bm], axis=1)  # (P, 4, 3)
    sp = np.broadcast_to((np.arange(G) + 0.5) / G, (P, G)).copy()
    return X, sp


def _energy(X, sp, w, Ps, s_minus=None):
    geo = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(X.shape[0], R2), s_minus)
    gp = np.where(geo.active, geo.g, 0.0)
    return 0.5 * Ps * np.sum(w[:, None] * gp**2, axis=1)  # per pair


def _residual(X, sp, w, Ps, s_minus=None, jac=True):
    geo = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(X.shape[0], R2), s_minus)
    return penalty_forces(geo, w, Ps, jac)




@pytest.mark.parametrize("frozen", [False, True])
def test_penalty_is_energy_gradient_and_tangent_exact(frozen):
    X, sp = _pairs()
    w = np.full(X.shape[0], 0.1)
    Ps = 50.0
    sm = None
    if frozen:
        sm = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(len(X), R2)).s_minus
    R, K = _residual(X, sp, w, Ps, sm)
    assert np.abs(R).max() > 1e-3  # really in contact
    if not frozen:  # recomputed closest points: the residual is the energy gradient
        dE = fd_nodes(lambda Y: _energy(Y, sp, w, Ps, None), X)
        np.testing.assert_allclose(R, dE, rtol=1e-6, atol=1e-9)
    Kfd = fd_nodes(lambda Y: _residual(Y, sp, w, Ps, sm, False)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-7 * np.abs(K).max())
    if not frozen:
        np.testing.assert_allclose(K, np.swapaxes(np.swapaxes(K, 1, 3), 2, 4), atol=1e-10 * np.abs(K).max())


def test_penalty_equal_and_opposite():
    X, sp = _pairs()
    R, _ = _residual(X, sp, np.full(len(X), 0.1), 50.0)
    np.testing.assert_allclose(R[:, 0] + R[:, 1], -(R[:, 2] + R[:, 3]), atol=1e-14)


def test_clamped_closest_point_tangent():
    """Points whose closest point is clamped to the - chord end (ds = 0 there)."""
    X, sp = _pairs(P=3, overlap=0.05)
    X[:, 3] = X[:, 2] + (X[:, 3] - X[:, 2]) * 0.3  # short - chord: end clamps on one side
    X[:, 2:] += [0.0, 0.12, 0.0]
    geo = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(3, R2))
    assert np.any((geo.s_minus == 0) | (geo.s_minus == 1))
    assert geo.active.any()
    w = np.full(3, 0.1)
    R, K = _residual(X, sp, w, 50.0)
    Kfd = fd_nodes(lambda Y: _residual(Y, sp, w, 50.0, None, False)[0], X)
    np.testing.assert_allclose(K, Kfd, rtol=1e-5, atol=1e-7 * np.abs(K).max())


def test_onset_one_sided():
    """g crossing 0: the force is continuous (vanishes at g = 0); the tangent jumps from
    0 (open) to the penalty stiffness (closed); FD on each side matches."""
    X, sp = _pairs(P=1, G=1, overlap=0.0, seed=3)
    X[:] = [[-0.3, 0, 0], [0.3, 0, 0], [0, -0.3, -R2], [0, 0.3, -R2]]
    w, Ps = np.array([0.1]), 50.0
    for dz, closed in ((+1e-4, False), (-1e-4, True)):
        Y = X.copy()
        Y[:, 2:, 2] += -dz  # dz > 0: apart, dz < 0: overlap of 1e-4
        R, K = _residual(Y, sp, w, Ps)
        Kfd = fd_nodes(lambda Z: _residual(Z, sp, w, Ps, None, False)[0], Y, h=1e-6)
        np.testing.assert_allclose(K, Kfd, rtol=1e-4, atol=1e-9)
        if closed:
            assert abs(R[0, 0, 2]) == pytest.approx(0.5 * w[0] * Ps * 1e-4, rel=1e-6)
            assert abs(K[0, 0, 2, 0, 2]) > 0.2 * w[0] * Ps
        else:
            assert np.all(R == 0) and np.all(K == 0)
    # continuity through the onset: |R| <= w P* |g| on both sides
    for g in (1e-9, 1e-12):
        Y = X.copy()
        Y[:, 2:, 2] += g
        R, _ = _residual(Y, sp, w, Ps)
        assert np.abs(R).max() <= w[0] * Ps * g * 1.0001


def test_hertz_regularisation():
    kap = 2.0
    g = np.logspace(-8, -1, 50)
    for eps in (1e-6, 1e-5):
        a, da = hertz_width(g, kap, eps)
        # approaches the exact width with relative error <= eps / (2 g)
        exact = kap * np.sqrt(g)
        big = g > 100 * eps
        assert np.all(np.abs(a[big] / exact[big] - 1) <= eps / (2 * g[big]) * 1.01)
        # finite derivative at the onset: da/dg(0+) = kappa / sqrt(eps)
        a0, da0 = hertz_width(np.array([1e-300]), kap, eps)
        assert da0[0] == pytest.approx(kap / np.sqrt(eps), rel=1e-9)
        # derivative matches FD
        h = 1e-3 * g
        fd = (hertz_width(g + h, kap, eps)[0] - hertz_width(g - h, kap, eps)[0]) / (2 * h)
        np.testing.assert_allclose(da, fd, rtol=1e-5)
    a, da = hertz_width(np.array([-1.0, 0.0]), kap, 1e-6)
    assert np.all(a == 0) and np.all(da == 0)
    assert hertz_kappa(0.075, 5.0, 0.63) == pytest.approx(np.sqrt(4 * 0.075 * 5.0 / (np.pi * 0.63)))


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("frozen", [False, True])
def test_scalar_jump_jacobians(order, frozen):
    X, sp = _pairs(P=5, overlap=0.06, seed=11)
    nn = order + 1
    rng = np.random.default_rng(5)
    up = rng.normal(size=(5, nn))
    um = rng.normal(size=(5, nn))
    w = np.full(5, 0.1)
    kap, coef, eps = 0.7, 3.0, 1e-5
    sm = None
    if frozen:
        sm = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(5, R2)).s_minus

    def res(Y, a=up, b=um):
        geo = chord_geometry(Y[:, 0], Y[:, 1], Y[:, 2], Y[:, 3], sp, np.full(5, R2), sm)
        return scalar_jump(geo, order, a, b, w, coef, kap, eps, jacobian=False)[0]

    geo = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(5, R2), sm)
    R, Ju, JX = scalar_jump(geo, order, up, um, w, coef, kap, eps)
    assert np.abs(R).max() > 1e-3
    # conservation: what leaves + enters - (sum of rows is zero for constant test fns)
    np.testing.assert_allclose(R[:, :nn].sum(1), -R[:, nn:].sum(1), atol=1e-14)
    JXfd = fd_nodes(res, X, h=1e-7)
    np.testing.assert_allclose(JX, JXfd, rtol=1e-5, atol=1e-7 * np.abs(JX).max())
    # linear in u: Ju u = R
    u = np.concatenate([up, um], axis=1)
    np.testing.assert_allclose(np.einsum("pab,pb->pa", Ju, u), R, atol=1e-13)
    np.testing.assert_allclose(Ju, np.swapaxes(Ju, 1, 2), atol=1e-15)


# ---------------------------------------------------------------------------- assembled
def _crossed_system(order=1, fields=("mech", "T", "V"), overlap=0.04, ne=4, recompute=True):
    from rve.model import ContactParams, ContactSystem
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.model import BeamMaterial, BeamModel

    R = 0.15
    fibs = [straight_fibril([-1, 0.03, 0], [1, 0.03, 0], R, "a"),
            straight_fibril([0.05, -1, -(2 * R - overlap)], [0.05, 1, -(2 * R - overlap)], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    mat = BeamMaterial(1.26, density=1e-3, damping=0.01, electrical_conductivity=10.0,
                       heat_capacity=1.0, thermal_conductivity=1.0)
    base = BeamModel(mesh, mat, fields=fields)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0
    params = ContactParams(penalty=50.0, heat_transfer=0.1, conductance=1.0, n_gp=4, margin=0.1,
                           recompute_closest=recompute)
    return ContactSystem(base, params, x), x


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("recompute", [True, False])
def test_contact_system_jacobians(order, recompute):
    sysm, x = _crossed_system(order, recompute=recompute)
    rng = np.random.default_rng(order)
    xn = sysm.nodal(x)
    xn[:, :3] += rng.normal(scale=0.01, size=(xn.shape[0], 3))
    w = np.zeros(sysm.n)
    wn = sysm.nodal(w)
    wn[:, sysm.layout.offset["T"]] = rng.normal(size=xn.shape[0])
    wn[:, sysm.layout.offset["V"]] = rng.normal(size=xn.shape[0])
    F, Fx, Fw = sysm.evaluate(x, w, 0.0)
    Fc, act, _, _ = sysm.contact_terms(x, w, False)
    assert act.size > 0 and np.abs(Fc).max() > 1e-4
    # one CSR structure for Fx, Fw and M
    M = sysm.mass()
    for A in (Fx, Fw):
        assert np.array_equal(A.indices, M.indices) and np.array_equal(A.indptr, M.indptr)
    h = 1e-7
    cols = np.flatnonzero(sysm.mech)
    cols = cols[np.isin(cols % sysm.layout.block, [0, 1, 2])]  # centroid columns (contact)
    Fxd, Fwd = Fx.toarray(), Fw.toarray()
    for c in cols:
        xp, xm = x.copy(), x.copy()
        xp[c] += h
        xm[c] -= h
        fd = (sysm.evaluate(xp, w, 0, False)[0] - sysm.evaluate(xm, w, 0, False)[0]) / (2 * h)
        np.testing.assert_allclose(Fxd[:, c], fd, rtol=1e-5, atol=1e-6 * (1 + np.abs(Fxd).max()))
    for c in np.flatnonzero(~sysm.mech):
        wp, wm = w.copy(), w.copy()
        wp[c] += h
        wm[c] -= h
        fd = (sysm.evaluate(x, wp, 0, False)[0] - sysm.evaluate(x, wm, 0, False)[0]) / (2 * h)
        np.testing.assert_allclose(Fwd[:, c], fd, rtol=1e-5, atol=1e-7 * (1 + np.abs(Fwd).max()))


def test_penalty_law_is_c2_and_linear_beyond_the_onset():
    from rve.physics.contact_forms import penalty_law

    P, eps = 50.0, 0.003
    g = np.array([-1e-3, 0.0, 1e-12, eps * (1 - 1e-9), eps, eps * (1 + 1e-9), 0.02])
    e, f, k = penalty_law(g, P, eps)
    assert e[0] == f[0] == k[0] == 0.0 and e[1] == f[1] == k[1] == 0.0
    np.testing.assert_allclose([e[3], f[3], k[3]], [e[5], f[5], k[5]], rtol=1e-6)  # C2 at g = eps
    np.testing.assert_allclose(f[-1], P * (0.02 - eps / 2))  # linear law shifted by eps/2
    # derivatives by central differences
    gg = np.linspace(1e-4, 3 * eps, 17)
    h = 1e-8
    ep, fp, _ = penalty_law(gg + h, P, eps)
    em, fm, _ = penalty_law(gg - h, P, eps)
    _, f0, k0 = penalty_law(gg, P, eps)
    np.testing.assert_allclose((ep - em) / (2 * h), f0, rtol=1e-6)
    np.testing.assert_allclose((fp - fm) / (2 * h), k0, rtol=1e-5)
    # onset 0 is the linear law
    e0, f0, k0 = penalty_law(g, P, 0.0)
    np.testing.assert_allclose(f0, P * np.maximum(g, 0))


@pytest.mark.parametrize("frozen", [False, True])
def test_penalty_with_onset_gradient_and_tangent(frozen):
    from rve.physics.contact_forms import penalty_energy

    X, sp = _pairs(overlap=0.004)  # overlaps around the onset width
    w = np.full(X.shape[0], 0.1)
    Ps, eps = 50.0, 0.005
    sm = None
    if frozen:
        sm = chord_geometry(X[:, 0], X[:, 1], X[:, 2], X[:, 3], sp, np.full(len(X), R2)).s_minus

    def res(Y, jac=False):
        geo = chord_geometry(Y[:, 0], Y[:, 1], Y[:, 2], Y[:, 3], sp, np.full(Y.shape[0], R2), sm)
        return penalty_forces(geo, w, Ps, jac, eps)

    R, K = res(X, True)
    assert np.abs(R).max() > 1e-5
    Kfd = fd_nodes(lambda Y: res(Y)[0], X)
    np.testing.assert_allclose(K, Kfd, atol=1e-5 * np.abs(K).max())
    if not frozen:
        def energy(Y):
            geo = chord_geometry(Y[:, 0], Y[:, 1], Y[:, 2], Y[:, 3], sp, np.full(Y.shape[0], R2))
            return np.array([penalty_energy(geo.g[p:p + 1], w[p:p + 1], Ps, eps) for p in range(Y.shape[0])])

        np.testing.assert_allclose(R, fd_nodes(energy, X), atol=1e-7)  # residual = dE/dX


def test_contact_system_energy_gradient():
    """ContactSystem.energy (beam strain + penalty energy, with an onset) has the static
    residual as its gradient: directional derivatives by central differences."""
    from rve.model import ContactParams, ContactSystem
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.model import BeamMaterial, BeamModel

    R = 0.15
    fibs = [straight_fibril([-1, 0, 0], [1, 0, 0], R, "a"), straight_fibril([0, -1, 0.27], [0, 1, 0.27], R, "b")]
    mesh = fibril_mesh(fibs, 6, 1)
    base = BeamModel(mesh, BeamMaterial(1.26))
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0 + RNG.normal(size=mesh.X0.shape) * 0.01
    sysm = ContactSystem(base, ContactParams(penalty=50.0, onset=0.1), x)
    assert sysm.contact_state(x)["active_points"] > 0
    F, _, _ = sysm.evaluate(x, np.zeros(base.n), 0.0, jacobian=False)
    for _ in range(3):
        d = RNG.normal(size=base.n) * 1e-2
        h = 1e-6
        fd = (sysm.energy(x + h * d) - sysm.energy(x - h * d)) / (2 * h)
        assert abs(fd - F @ d) <= 1e-6 * max(1.0, abs(F @ d))
