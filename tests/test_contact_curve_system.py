"""The assembled ContactSystem with the centroid-curve geometry, the Holm conductance law and
augmented Lagrangian multipliers: every tangent block against central differences of the full
residual (p = 1, 2, 3), the energy as the potential of the residual, action = reaction, and
the default options giving the chord system unchanged."""
import numpy as np
import pytest

from rve.testing import fd_jacobian, rel_err

R = 0.15


def _crossed(order, ne=4, overlap=0.04, fields=("mech", "T", "V"), seed=0, **kw):
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem

    fibs = [straight_fibril([-1, 0.03, 0], [1, 0.03, 0], R, "a"),
            straight_fibril([0.05, -1, -(2 * R - overlap)], [0.05, 1, -(2 * R - overlap)], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    mat = BeamMaterial(1.26, density=1e-3, damping=0.01, electrical_conductivity=10.0,
                       heat_capacity=1.0, thermal_conductivity=1.0)
    base = BeamModel(mesh, mat, fields=fields)
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0
    rng = np.random.default_rng(seed)
    xn[:, :3] += rng.normal(scale=0.01, size=(xn.shape[0], 3))
    args = dict(penalty=50.0, heat_transfer=0.1, conductance=1.0, n_gp=4, margin=0.1)
    args.update(kw)
    sysm = ContactSystem(base, ContactParams(**args), x)
    w = np.zeros(base.n)
    if "T" in fields:
        wn = sysm.nodal(w)
        wn[:, sysm.layout.offset["T"]] = rng.normal(size=xn.shape[0])
        wn[:, sysm.layout.offset["V"]] = rng.normal(size=xn.shape[0])
    return sysm, x, w


def _check_tangents(sysm, x, w):
    F, Fx, Fw = sysm.evaluate(x, w, 0.0)
    Fc, act, _, _ = sysm.contact_terms(x, w, False)
    assert act.size > 0 and np.abs(Fc).max() > 1e-4
    M = sysm.mass()
    for A in (Fx, Fw):
        assert np.array_equal(A.indices, M.indices) and np.array_equal(A.indptr, M.indptr)
    cols = np.flatnonzero(sysm.mech)
    cols = cols[np.isin(cols % sysm.layout.block, [0, 1, 2])]  # centroid columns (contact)
    Jx = fd_jacobian(lambda y: sysm.evaluate(y, w, 0.0, False)[0], x, cols, eps=1e-7)
    assert rel_err(Fx.toarray()[:, cols], Jx) < 1e-6
    sc = np.flatnonzero(~sysm.mech)
    if sc.size:
        Jw = fd_jacobian(lambda v: sysm.evaluate(x, v, 0.0, False)[0], w, sc, eps=1e-7)
        assert rel_err(Fw.toarray()[:, sc], Jw) < 1e-6
    # the contact forces on the two fibrils are equal and opposite
    f = sysm.fibril_contact_forces(x)
    np.testing.assert_allclose(f[0], -f[1], atol=1e-12 * np.abs(f).max())


@pytest.mark.parametrize("order", [1, 2, 3])
def test_curve_system_tangents(order):
    sysm, x, w = _crossed(order, geometry="curve")
    assert sysm.term.passes is not None
    _check_tangents(sysm, x, w)


@pytest.mark.parametrize("geometry", ["chord", "curve"])
def test_holm_law_tangents(geometry):
    sysm, x, w = _crossed(2, geometry=geometry, conductance_law="holm", hardness=200.0, spot_radius=1e-3)
    assert sysm.term.holm and sysm.term.scalar == ["T", "V"]
    _check_tangents(sysm, x, w)


@pytest.mark.parametrize("geometry", ["chord", "curve"])
def test_multiplier_tangents(geometry):
    sysm, x, w = _crossed(2, geometry=geometry, enforcement="augmented_lagrangian")
    sysm.update_multipliers(x)
    lam = sysm.multipliers
    assert lam is not None and lam.max() > 0
    _check_tangents(sysm, x, w)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_curve_energy_is_the_potential(order):
    sysm, x, _ = _crossed(order, fields=("mech",), geometry="curve")
    F, _, _ = sysm.evaluate(x, np.zeros(sysm.n), 0.0, jacobian=False)
    rng = np.random.default_rng(4)
    for _ in range(3):
        d = rng.normal(size=sysm.n) * 1e-2
        h = 1e-6
        fd = (sysm.energy(x + h * d) - sysm.energy(x - h * d)) / (2 * h)
        assert abs(fd - F @ d) <= 1e-6 * max(1.0, abs(F @ d))


def test_curve_mechanics_only_tangent():
    sysm, x, w = _crossed(3, fields=("mech",), geometry="curve")
    _check_tangents(sysm, x, w)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_crossed_fibrils_closed_form(order):
    """Rigid straight crossed fibrils at approach delta: the force is the integral of P* g n_z
    along either fibril, F = 2 P* d (Rs asinh(L/d) - L) (d = Rs - delta, L = sqrt(Rs^2 - d^2)).
    The curve's two half passes reach it to the quadrature error of the kinked integrand
    (< 0.5 % at 32 elements, n_gp = 4, crossing inside or at an element end); the chord's
    one-sided pass counts a point once more for every - element whose clamped end is within
    reach (here about twice the force)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from contact_order import closed_form_force, crossed_force

    F = closed_form_force(0.02)
    for x0, y0 in ((0.0137, 0.0291), (0.0, 0.0)):
        assert abs(crossed_force(order, 32, "curve", 0.02, x0, y0) / F - 1) < 5e-3
    assert crossed_force(order, 16, "chord", 0.02, 0.0137, 0.0291) / F - 1 > 0.5
