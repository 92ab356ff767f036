"""The compiled frozen-load friction potential (``rve.kernels.friction``) against the numpy
reference (``rve.physics.friction_forms.frozen_potential`` with the turn), on random points
in stick, slip, out of contact and at the smoothed cone, for the chord (M = 4) and the
curves' local node counts (M = 6, 8), and the term's two paths on the same system."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

from rve.kernels.friction import frozen_potential as compiled  # noqa: E402
from rve.physics.friction_forms import frozen_potential as reference  # noqa: E402


def _points(M, seed=0, P=300, G=4):
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(P, M, 3))
    cb = rng.normal(size=(P, G, M))
    anchor = 0.1 * rng.normal(size=(P, G, 3))
    n0 = rng.normal(size=(P, G, 3))
    n0 /= np.linalg.norm(n0, axis=-1)[..., None]
    f0 = np.abs(rng.normal(size=(P, G)))
    f0[rng.random((P, G)) < 0.3] = 0.0                      # points without a frozen load
    # tangential stiffness over three decades: stick (small |e| kT) and slip both occur
    kT = np.abs(rng.normal(size=(P, G))) * rng.choice([0.1, 10.0, 1000.0], size=(P, G))
    mu = np.where(rng.random((P, G)) < 0.1, 0.0, 0.2)
    Dw = rng.normal(size=(P, G, M))
    Jd = 0.1 * rng.normal(size=(P, G, 3, 3))
    return X, cb, anchor, f0, n0, kT, mu, Dw, Jd


def _assert_same(ref, out, tol):
    """The kernel's ``(psi, R, K)`` equal the reference's to ``tol`` of each one's largest entry."""
    for a, b in zip(ref, out):
        if a is None:
            assert b is None
            continue
        assert a.shape == b.shape
        assert np.abs(a - b).max() <= tol * np.abs(a).max()


def _stick_and_slip(u, n0, f0, mu, kT):
    """``(stick, slip)`` point counts of the gaps ``u`` at the frozen loads."""
    e = u - np.einsum("pgi,pgi->pg", n0, u)[..., None] * n0
    on = (f0 > 0) & (mu > 0)
    stick = on & (kT * np.linalg.norm(e, axis=-1) <= mu * f0)
    return int(stick.sum()), int((on & ~stick).sum())


@pytest.mark.parametrize("M", [4, 6, 8])
@pytest.mark.parametrize("eta", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("jacobian", [True, False])
def test_frozen_potential_kernel_matches_numpy(M, eta, jacobian):
    X, cb, anchor, f0, n0, kT, mu, Dw, Jd = _points(M)
    ref = reference(X, None, None, anchor, f0, n0, kT, mu, jacobian, eta, weights=lambda s: cb, turn=(Dw, Jd))
    out = compiled(X, cb, anchor, f0, n0, kT, mu, jacobian, eta, Dw, Jd)
    # the smoothed cone's potential is a difference of terms ~x^2 for x = |e|/delta up to 1e4
    # here: the two arcsinh implementations' last bits, amplified by that cancellation, give
    # ~x^2 eps relative to the largest entry; the law (eta = 0) agrees to a few ulps
    tol = 1e-13 if eta == 0.0 else 1e-11
    _assert_same(ref, out, tol)


def test_frozen_potential_kernel_sees_stick_and_slip():
    """The random points of the comparison have both stick and slip points (else the test
    above would not compare both branches)."""
    X, cb, anchor, f0, n0, kT, mu, Dw, Jd = _points(4)
    u = anchor + np.einsum("pgk,pki->pgi", cb, X) + np.einsum("pgij,pgj->pgi", Jd, np.einsum("pgk,pki->pgi", Dw, X))
    stick, slip = _stick_and_slip(u, n0, f0, mu, kT)
    assert stick > 10 and slip > 10


@pytest.mark.parametrize("eta", [0.0, 1.0])
@pytest.mark.parametrize("shift", [-0.002, 0.002])
def test_frozen_term_forms_equal_on_both_paths(monkeypatch, eta, shift):
    """``FrictionTerm`` at frozen loads on the sliding crossing of tests/test_friction_term.py
    (stick for one sign of the shift, slip for the other): residual, tangent and potential of
    the compiled path equal the numpy path's."""
    from test_friction_term import _slid

    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        cfg, system, parts, x = _slid(cycle_steps=2, u=0.04)
        fr = system.term.friction
        fr.freeze(None)
        fr.smoothing = eta
        y = x.copy()
        y[parts["contact_x"]] += shift
        F, J, _ = system.evaluate(y, np.zeros(system.n), 0.0)
        out[path] = (np.asarray(F, float), J.toarray(), fr.potential(y))
    a, b = out["numpy"], out["numba"]
    assert a[2] > 0
    assert np.abs(a[0] - b[0]).max() <= 1e-12 * np.abs(a[0]).max()
    assert np.abs(a[1] - b[1]).max() <= 1e-12 * np.abs(a[1]).max()
    assert abs(a[2] - b[2]) <= 1e-12 * abs(a[2])


def _law_inputs(M, turn, seed=1, P=250, G=4):
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    X = rng.normal(size=(P, M, 3))
    n = rng.normal(size=(P, G, 3))
    n /= np.linalg.norm(n, axis=-1)[..., None]
    cb = rng.normal(size=(P, G, M))
    D = rng.normal(size=(P, G, M)) if turn else None
    d_ref = None
    if turn:
        d_ref = rng.normal(size=(P, G, 3))
        d_ref /= np.linalg.norm(d_ref, axis=-1)[..., None]
    geo = SimpleNamespace(c=rng.normal(size=(P, G, M)), ds=rng.normal(size=(P, G, M, 3)), n=n,
                          rho=0.1 + rng.random((P, G)), active=rng.random((P, G)) < 0.85,
                          dc_ds=rng.normal(size=(P, G, M)), material_weights=lambda s: cb)
    f = np.abs(rng.normal(size=(P, G)))
    f[~geo.active] = 0.0
    kN = np.abs(rng.normal(size=(P, G)))
    kT = np.abs(rng.normal(size=(P, G))) * rng.choice([0.1, 10.0, 1000.0], size=(P, G))
    mu = np.where(rng.random((P, G)) < 0.1, 0.0, 0.3)
    anchor = 0.3 * rng.normal(size=(P, G, 3))
    return geo, X, anchor, f, kN, kT, mu, cb, D, d_ref


@pytest.mark.parametrize("M", [4, 6, 8])
@pytest.mark.parametrize("turn", [False, True])
@pytest.mark.parametrize("jacobian", [True, False])
def test_law_kernel_matches_numpy(M, turn, jacobian):
    """``rve.kernels.friction.friction_forces`` against ``friction_forms.friction_forces``
    (stick, slip and inactive points; with and without the anchor's turn and its couple)."""
    from rve.kernels.friction import friction_forces as compiled_law
    from rve.physics.friction_forms import friction_forces

    geo, X, anchor, f, kN, kT, mu, cb, D, d_ref = _law_inputs(M, turn)
    Dp = None
    if turn:   # the direction weights at the closest point and their derivative in it
        Dp = np.random.default_rng(3).normal(size=D.shape)
        geo.s_minus = np.full(f.shape, 0.25)
        geo.direction_weights = lambda s: D
        geo.direction_weights_ds = lambda s: Dp
    ref = friction_forces(geo, X, np.full(f.shape, 0.5), anchor, f, kN, kT, mu, jacobian, d_ref=d_ref)
    out = compiled_law(geo.c, geo.ds, geo.n, geo.rho, geo.active, geo.dc_ds, cb, X, anchor, f, kN, kT, mu,
                       jacobian, D=D, d_ref=d_ref, Dp=Dp)
    for a, b in zip(ref, out):
        if a is None:
            assert b is None
            continue
        assert np.abs(a - b).max() <= 1e-12 * np.abs(a).max()


@pytest.mark.parametrize("shift", [-0.002, 0.002])
def test_law_term_forms_equal_on_both_paths(monkeypatch, shift):
    """``FrictionTerm`` with the exact law (no frozen loads) on the sliding crossing:
    residual and tangent of the compiled path equal the numpy path's."""
    from test_friction_term import _slid

    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        cfg, system, parts, x = _slid(cycle_steps=2, u=0.04)
        y = x.copy()
        y[parts["contact_x"]] += shift
        F, J, _ = system.evaluate(y, np.zeros(system.n), 0.0)
        assert system.term.friction.state(y).t.any()
        out[path] = (np.asarray(F, float), J.toarray())
    a, b = out["numpy"], out["numba"]
    assert np.abs(a[0] - b[0]).max() <= 1e-12 * np.abs(a[0]).max()
    assert np.abs(a[1] - b[1]).max() <= 1e-12 * np.abs(a[1]).max()


def _frame_points(seed=2, P=300, G=4, M=4):
    rng = np.random.default_rng(seed)
    X, cb, anchor, f0, n0, kT, mu, Dw, Jd = _points(M, seed, P, G)
    Y = np.concatenate([X, rng.normal(size=(P, M, 3))], axis=-1)
    gw = np.zeros((P, G, M))
    gw[..., 2] = 1.0                          # the section node: the - element's first
    gw[::3] = rng.normal(size=gw[::3].shape)  # and arbitrary weights on a third of the pairs
    Jg = 0.1 * rng.normal(size=(P, G, 3, 3))
    return Y, cb, anchor, f0, n0, kT, mu, (Dw, Jd, gw, Jg)


@pytest.mark.parametrize("eta", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("jacobian", [True, False])
def test_frame_frozen_potential_kernel_matches_numpy(eta, jacobian):
    """``rve.kernels.friction.frame_frozen_potential`` against the numpy reference
    (``friction_forms.frame_frozen_potential``) on random points in stick and slip, without a
    load and at the smoothed cone, with the frame's turn in the centroids and g1."""
    from rve.kernels.friction import frame_frozen_potential as compiled_frame
    from rve.physics.friction_forms import frame_frozen_potential

    args = _frame_points()
    ref = frame_frozen_potential(*args[:7], jacobian, eta, args[7])
    out = compiled_frame(*args[:7], jacobian, eta, args[7])
    tol = 1e-13 if eta == 0.0 else 1e-11      # as for the chord's kernel above
    _assert_same(ref, out, tol)
    Y, cb, anchor, f0, n0, kT, mu, (Dw, Jd, gw, Jg) = args
    u = (anchor + np.einsum("pgk,pki->pgi", cb, Y[..., :3])
         + np.einsum("pgij,pgj->pgi", Jd, np.einsum("pgk,pki->pgi", Dw, Y[..., :3]))
         + np.einsum("pgij,pgj->pgi", Jg, np.einsum("pgk,pki->pgi", gw, Y[..., 3:])))
    stick, slip = _stick_and_slip(u, n0, f0, mu, kT)
    assert stick > 10 and slip > 10
    assert np.abs(ref[1][..., 3:]).max() > 0        # g1 carries a force


@pytest.mark.parametrize("eta", [0.0, 1.0])
def test_frame_frozen_term_forms_equal_on_both_paths(monkeypatch, eta):
    """The pinned cell's system with ``friction.frame: section`` after a frictional step, its
    loads frozen at a trial state off it: residual, tangent and potential of the compiled path
    equal the numpy path's."""
    from test_rve_friction_al_periodic import _cfg, _relaxed

    from rve.homogenisation.strain import strain_step

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=1, frame="section")
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x1, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    assert info["converged"]
    x = np.asarray(x1, float).reshape(-1)
    y = x + np.random.default_rng(4).normal(size=system.n) * 3e-5
    fr = system.term.friction
    system.rebuild(x)
    fr.freeze(x)
    fr.smoothing = eta
    w = np.zeros(system.n)
    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        F, J, _ = system.evaluate(y, w, 0.0)
        out[path] = (np.asarray(F, float), J.toarray(), fr.potential(y))
    a, b = out["numpy"], out["numba"]
    # the gap u = anchor + sum W_k Y_k is mm-sized terms cancelling to a micron-sized gap, summed
    # in another order by each path: its rounding, ~eps |anchor|, times kT bounds the forces'
    rows, arrays = fr._frozen_inputs(fr._frozen_pairs())
    anchor, kT = arrays[1], arrays[4]
    bound = 64 * np.finfo(float).eps * np.abs(anchor).max() * kT.max()
    assert a[2] > 0
    assert np.abs(a[0] - b[0]).max() <= bound
    # a slip point's stiffness (mu f/|e|)(P - e_hat e_hat^T) turns that rounding of e by
    # |anchor|/|e| more (a few 1e-12 of the largest entry here); a wrong layout or term would
    # differ by O(1)
    assert np.abs(a[1] - b[1]).max() <= 1e-9 * np.abs(a[1]).max()
    # the potential's rounding: that of the gap times the forces it is the work of
    _, Rf, _ = fr._frozen_forms(y, fr._frozen_pairs(), False)
    assert abs(a[2] - b[2]) <= 64 * np.finfo(float).eps * np.abs(anchor).max() * np.abs(Rf).sum()


def _refreeze_points(seed=5, P=300, G=4, M=6):
    """Random inputs of the section frame's refreeze: nodes, directors, held and closest
    material points, weights functions linear in ``s``, normals, distances, a quarter of the
    points inactive, and a held history with an orthonormal committed frame."""
    rng = np.random.default_rng(seed)
    X, Gn = rng.normal(size=(P, M, 3)), rng.normal(size=(P, M, 3))
    s_bar, s_star = rng.random((P, G)), rng.random((P, G))

    def linear_in_s():
        a, b = rng.normal(size=(P, G, M)), rng.normal(size=(P, G, M))
        return lambda s: a + np.asarray(s)[..., None] * b

    weights, directions, director_weights = linear_in_s(), linear_in_s(), linear_in_s()
    n = rng.normal(size=(P, G, 3))
    n /= np.linalg.norm(n, axis=-1)[..., None]
    rho = 0.3 + rng.random((P, G))
    active = rng.random((P, G)) > 0.25
    anchor = 0.1 * rng.normal(size=(P, G, 3))
    d_ref = rng.normal(size=(P, G, 3))
    d_ref /= np.linalg.norm(d_ref, axis=-1)[..., None]
    m_ref = rng.normal(size=(P, G, 3))
    m_ref -= np.einsum("pgi,pgi->pg", m_ref, d_ref)[..., None] * d_ref
    m_ref /= np.linalg.norm(m_ref, axis=-1)[..., None]
    return (X, Gn, s_bar, anchor, d_ref, m_ref, s_star, n, rho, active, weights, directions, director_weights)


def test_frame_refreeze_kernel_matches_numpy():
    """``rve.kernels.friction_frame.frame_refreeze`` against the numpy reference
    (``friction_forms.frame_refreeze``) on random points, inactive ones included."""
    from rve.kernels.friction_frame import frame_refreeze
    from rve.physics.friction_forms import frame_refreeze as reference

    args = _refreeze_points()
    active = args[9]
    ref, out = reference(*args), frame_refreeze(*args)
    Jd = ref[1]
    assert np.abs(Jd[~active]).max() == 0.0 and np.abs(Jd[active]).max() > 0.1
    for a, b in zip(ref, out):
        assert a.shape == b.shape
        assert np.abs(a - b).max() <= 1e-13 * np.abs(a).max()


def test_section_frame_loads_equal_on_both_paths(monkeypatch):
    """The pinned cell's frictional system with the section frame after a frictional step:
    its loads at a state off it (``FrictionTerm.loads_at``, the predictor's refreeze) equal
    on the compiled and the numpy path."""
    from test_rve_friction_al_periodic import section_frame_cell_off_its_step

    system, y = section_frame_cell_off_its_step(6)
    fr = system.term.friction
    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        out[path] = fr.loads_at(y)
    a, b = out["numpy"], out["numba"]
    assert a.keys() == b.keys()
    assert np.abs(a["Jg"]).max() > 0 and (a["f0"] > 0).sum() > 10
    for k in a:
        scale = max(np.abs(a[k]).max(), 1e-300)
        assert np.abs(a[k] - b[k]).max() <= 1e-12 * scale, k
