"""Every term of the model (rve/model/terms/*) on its own: its tangent blocks against
central finite differences of its residual, assembled by the one assembler; and the
mechanics-only model is the same assembler with fewer terms."""
import numpy as np
import pytest

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel, CircuitBC, ContactParams, ContactSystem, Couplings, PrescribedCurrent
from rve.model.assembler import Assembler
from rve.testing import fd_jacobian, rel_err

B = (0.4, -0.3, 0.6)
MAT = BeamMaterial(youngs_modulus=10.0, poisson_ratio=0.3, density=1e-3, damping=2e-3, electrical_conductivity=2.0,
                   seebeck=0.3, heat_capacity=0.5, thermal_conductivity=0.7, alpha_mu=-0.4)


def _model(order=2, fields=("mech", "T", "V"), **kw):
    mesh = fibril_mesh([straight_fibril([0, 0, 0], [1.0, 0.2, 0.1], 0.08, "f")], 3, order)
    return BeamModel(mesh, MAT, fields=fields, couplings=kw.pop("couplings", Couplings(B=B)), **kw)


def _state(model, seed=0):
    rng = np.random.default_rng(seed)
    x = np.zeros(model.n)
    w = np.zeros(model.n)
    model.nodal(x)[:, :9] = model.mesh.X0 + 0.03 * rng.standard_normal(model.mesh.X0.shape)
    model.nodal(w)[:, :9] = 0.2 * rng.standard_normal((model.mesh.n_nodes, 9))
    if model.has_T:
        model.nodal(w)[:, model.oT] = rng.standard_normal(model.mesh.n_nodes)
    if model.has_V:
        model.nodal(w)[:, model.oV] = rng.standard_normal(model.mesh.n_nodes)
    return x, w


def _check(asm, x, w, t=0.3, tol=1e-6):
    ev = asm.evaluate(x, w, t, True)
    mech = np.flatnonzero(asm.layout.mech)
    Jx = fd_jacobian(lambda xx: asm.evaluate(xx, w, t, False).F, x, cols=mech)
    Jw = fd_jacobian(lambda ww: asm.evaluate(x, ww, t, False).F, w)
    scale = max(np.abs(Jx).max(), np.abs(Jw).max(), 1e-300)
    assert np.abs(ev.Fx.toarray()[:, mech] - Jx).max() / scale < tol
    assert np.abs(ev.Fw.toarray() - Jw).max() / scale < tol
    assert np.abs(ev.F).max() > 0  # the term does something


def _alone(model, *names):
    return Assembler(model.layout, model.pattern, model.basis, [model.assembler.term(n) for n in names])


@pytest.mark.parametrize("order", [1, 2])
def test_elasticity_with_softening(order):
    m = _model(order)
    _check(_alone(m, "elasticity"), *_state(m))
    assert m.assembler.term("elasticity").alpha_mu == MAT.alpha_mu


def test_prescribed_lorentz():
    m = _model(2, fields=("mech",), couplings=Couplings(lorentz=False, back_emf=False, joule=False, seebeck=False,
                                                          thermal_softening=False),
               prescribed_current=PrescribedCurrent(np.array([1.5]), np.array(B)))
    _check(_alone(m, "prescribed_lorentz"), *_state(m))


def test_heat_conduction():
    m = _model(2)
    _check(_alone(m, "heat_conduction"), *_state(m))


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("couplings", [Couplings(B=B), Couplings(B=B, back_emf=False),
                                       Couplings(B=B, seebeck=False, joule=False)])
def test_electromagnetic(order, couplings):
    m = _model(order, couplings=couplings, field_ramp=lambda t: 0.5 + t)
    _check(_alone(m, "electromagnetic"), *_state(m))


@pytest.mark.parametrize("fields", [("mech",), ("mech", "V")])
def test_damping(fields):
    c = Couplings(B=B, joule=False, seebeck=False, thermal_softening=False) if "V" in fields else None
    m = _model(2, fields=fields, couplings=c)
    d = m.assembler.term("damping")
    assert d.assembled == (fields == ("mech",))  # constant operator on the mechanics-only path
    _check(_alone(m, "damping"), *_state(m))


def test_circuits():
    m = _model(1)
    n1 = m.mesh.end_nodes(0)[1]
    m = _model(1, circuits=[CircuitBC.resistor(n1, 5.0, 0.3, np.pi * 0.08**2)])
    asm = _alone(m, "electromagnetic", "circuits")
    _check(asm, *_state(m))
    x, w = _state(m)
    a = asm.evaluate(x, w, 0.3).F - _alone(m, "electromagnetic").evaluate(x, w, 0.3).F
    c = m.circuits[0]
    i = m.layout.dofs("V", [n1])[0]
    assert np.isclose(a[i], c.area * (c.r_bar * w[i] + c.J_bar), rtol=1e-12)


def test_inertia_mass():
    m = _model(2)
    M = m.mass()
    assert abs(M - M.T).max() < 1e-15 * abs(M).max()
    r = m.layout.dofs("r", comp=0)
    vol = np.pi * 0.08**2 * np.linalg.norm([1.0, 0.2, 0.1])
    assert np.isclose(M[np.ix_(r, r)].sum(), MAT.density * vol, rtol=1e-12)  # rho |V| in the r_x block
    T = m.layout.dofs("T")
    assert np.isclose(M[np.ix_(T, T)].sum(), MAT.density * MAT.heat_capacity * vol, rtol=1e-12)
    assert abs(M[np.ix_(m.layout.dofs("V"), m.layout.dofs("V"))]).max() == 0.0  # V: no mass (a DAE)


@pytest.mark.parametrize("fields", [("mech",), ("mech", "T", "V")])
def test_contact_term(fields):
    """The contact term (pair elements) alone on the union pattern: its residual and tangents."""
    mesh = fibril_mesh([straight_fibril([-0.5, 0.07, 0], [0.5, 0.07, 0], 0.1, "a"),
                        straight_fibril([0.1, -0.5, 0.17], [0.1, 0.5, 0.17], 0.1, "b")], 4, 1)
    c = Couplings(joule=False, lorentz=False, back_emf=False, seebeck=False, thermal_softening=False)
    base = BeamModel(mesh, MAT, fields=fields, couplings=c if "V" in fields else None)
    x, w = _state(base, 2)
    base.nodal(x)[:, :9] = mesh.X0
    sysm = ContactSystem(base, ContactParams(penalty=20.0, heat_transfer=0.3, conductance=0.5), x)
    assert sysm.active_pairs(x).size > 0

    def contact_F(xx, ww):
        return sysm.evaluate(xx, ww, 0.0, False)[0] - base.evaluate(xx, ww, 0.0, False)[0]

    F, Fx, Fw = sysm.evaluate(x, w, 0.0)
    _, Bx, Bw = base.evaluate(x, w, 0.0)
    r = base.layout.dofs("r")
    Jx = fd_jacobian(lambda xx: contact_F(xx, w), x, cols=r)
    assert rel_err((Fx - sysm.assembler.union.csr(sysm.assembler.union.data_of(Bx))).toarray()[:, r], Jx) < 1e-6
    if len(fields) > 1:
        s = np.concatenate([base.layout.dofs("T"), base.layout.dofs("V")])
        Jw = fd_jacobian(lambda ww: contact_F(x, ww), w, cols=s)
        assert rel_err((Fw - sysm.assembler.union.csr(sysm.assembler.union.data_of(Bw))).toarray()[:, s], Jw) < 1e-6


@pytest.mark.parametrize("damping", [0.0, 2e-3])
def test_mechanics_only_is_the_full_assembler_with_fewer_terms(damping):
    """The mechanics-only model equals the full (mech, T, V) assembler with the
    non-mechanical terms removed, on the mechanical dofs: bit for bit without damping, to
    rounding with it (the mechanics-only path assembles C, the coupled one C's element blocks)."""
    import dataclasses

    mat = dataclasses.replace(MAT, alpha_mu=0.0, damping=damping)
    mesh = fibril_mesh([straight_fibril([0, 0, 0], [1.0, 0.2, 0.1], 0.08, "f")], 3, 2)
    mech = BeamModel(mesh, mat)
    full = BeamModel(mesh, mat, fields=("mech", "T", "V"), couplings=Couplings(B=B))
    names = [t.name for t in full.terms if t.name in ("elasticity", "damping", "inertia")]
    asm = _alone(full, *names)
    xm, wm = _state(mech)
    xf, wf = np.zeros(full.n), np.zeros(full.n)
    full.nodal(xf)[:, :9], full.nodal(wf)[:, :9] = mech.nodal(xm)[:, :9], mech.nodal(wm)[:, :9]
    F1, Fx1, Fw1 = mech.evaluate(xm, wm, 0.0)
    ev = asm.evaluate(xf, wf, 0.0)
    md = np.flatnonzero(full.layout.mech)
    sub = lambda A: A.toarray()[np.ix_(md, md)]  # noqa: E731
    exact = damping == 0.0
    for a, b in ((F1, ev.F[md]), (Fx1.toarray(), sub(ev.Fx)), (Fw1.toarray(), sub(ev.Fw)),
                 (mech.mass().toarray(), sub(asm.mass()))):
        assert np.array_equal(a, b) if exact else np.allclose(a, b, rtol=0, atol=1e-13 * np.abs(b).max())
    assert [t.name for t in mech.terms] == ["elasticity"] + (["damping"] if damping else []) + ["inertia"]
