"""Finite-difference checks of the exact tangents of every coupled (T, V) term.

Each coupling is switched on alone (and then all together) on straight and curved fibrils
with p = 1..3; Fx is checked column by column on the mechanical dofs and Fw on the
velocity, T and V dofs (relative error <= 1e-6 against central differences).
"""
import numpy as np
import pytest
import scipy.sparse as sp

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.testing import fd_jacobian, helix_fibril, rel_err
from rve.model import BeamMaterial, BeamModel, CircuitBC, Couplings, feedback_from_temperature


MAT = BeamMaterial(youngs_modulus=3.0, poisson_ratio=0.2, density=1.0, damping=0.3,
                   electrical_conductivity=2.0, seebeck=0.4, heat_capacity=1.5,
                   thermal_conductivity=0.7, alpha_mu=-0.2)
B = (0.3, -0.2, 0.5)

ALL_OFF = dict(lorentz=False, back_emf=False, joule=False, seebeck=False, thermal_softening=False)
CASES = {
    "conduction_only": {},
    "lorentz": dict(lorentz=True),
    "back_emf": dict(back_emf=True),
    "joule": dict(joule=True),
    "seebeck": dict(seebeck=True),
    "thermal_softening": dict(thermal_softening=True),
    "all": dict(lorentz=True, back_emf=True, joule=True, seebeck=True, thermal_softening=True),
}


def make_model(order, curved, couplings, fields=("mech", "T", "V"), circuits=True):
    fib = helix_fibril() if curved else straight_fibril([0, 0, 0], [1.0, 0.2, 0.1], 0.1)
    mesh = fibril_mesh([fib, straight_fibril([0, 1, 0], [1, 1, 0.3], 0.05)], [2, 1], order)
    circ = []
    if circuits and "V" in fields:
        n0, n1 = mesh.end_nodes(1)
        circ = [CircuitBC.resistor(n1, 3.0, 0.25, np.pi * 0.05**2), CircuitBC(n0, -0.7, 0.2, 0.01)]
    c = Couplings(B=B, **{**ALL_OFF, **couplings})
    return BeamModel(mesh, MAT, disk_points=8, fields=fields, couplings=c, circuits=circ)


def random_state(model, rng, scale=0.02):
    x = np.zeros(model.n)
    w = np.zeros(model.n)
    X = model.nodal(x)
    X[:, :9] = model.mesh.X0 + scale * rng.standard_normal(model.mesh.X0.shape)
    Wn = model.nodal(w)
    Wn[:, :9] = rng.standard_normal(Wn[:, :9].shape)
    if model.has_T:
        Wn[:, model.oT] = rng.standard_normal(model.mesh.n_nodes)
    if model.has_V:
        Wn[:, model.oV] = rng.standard_normal(model.mesh.n_nodes)
    return x, w


def check_jacobians(model, x, w, tol=1e-6):
    F, Fx, Fw = model.evaluate(x, w, 0.0)
    Fx, Fw = Fx.toarray(), Fw.toarray()
    mech = np.flatnonzero(model.mech)
    Jx = fd_jacobian(lambda u: model.evaluate(u, w, 0.0, jacobian=False)[0], x, mech)
    Jw = fd_jacobian(lambda u: model.evaluate(x, u, 0.0, jacobian=False)[0], w, np.arange(model.n))
    assert rel_err(Fx[:, mech], Jx) < tol, rel_err(Fx[:, mech], Jx)
    assert rel_err(Fw, Jw) < tol, rel_err(Fw, Jw)
    # and per field block (so that a small block cannot hide behind a large one)
    for f in model.layout.fields:
        cols = model.field_dofs(f)
        blk = Jw[:, cols]
        if np.abs(blk).max() > 0:
            assert rel_err(Fw[:, cols], blk) < tol, (f, rel_err(Fw[:, cols], blk))
        rows = model.field_dofs(f)
        blk = Jx[rows]
        if np.abs(blk).max() > 0:
            assert rel_err(Fx[rows][:, mech], blk) < tol, (f, rel_err(Fx[rows][:, mech], blk))
    return F, Fx, Fw


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("curved", [False, True])
def test_coupled_tangents_match_fd(case, order, curved):
    rng = np.random.default_rng(order + 10 * curved)
    model = make_model(order, curved, CASES[case])
    x, w = random_state(model, rng)
    assert model.admissible(x)
    for name, on in CASES[case].items():
        assert model.active[name] == on
    check_jacobians(model, x, w)


@pytest.mark.parametrize("fields,couplings", [
    (("mech", "V"), dict(lorentz=True, back_emf=True)),
    (("mech", "T"), dict(thermal_softening=True)),
])
def test_reduced_field_sets_match_fd(fields, couplings):
    rng = np.random.default_rng(7)
    model = make_model(2, True, couplings, fields=fields)
    assert model.n == model.mesh.n_nodes * (9 + len(fields) - 1)
    x, w = random_state(model, rng)
    check_jacobians(model, x, w)


def test_undeclared_field_is_an_error():
    with pytest.raises(ValueError, match="joule.*T"):
        make_model(1, False, dict(joule=True), fields=("mech", "V"))
    with pytest.raises(ValueError, match="lorentz.*V"):
        make_model(1, False, dict(lorentz=True), fields=("mech", "T"))


def test_feedback_from_temperature():
    c = Couplings(B=B)
    assert feedback_from_temperature(MAT, c)
    mat0 = BeamMaterial(youngs_modulus=1.0, electrical_conductivity=1.0, seebeck=0.0, alpha_mu=0.0)
    assert not feedback_from_temperature(mat0, c)


def test_mass_matrix_blocks():
    model = make_model(2, False, CASES["all"])
    M = model.mass().tocsr()
    V = model.field_dofs("V")
    T = model.field_dofs("T")
    assert abs(M[V]).sum() == 0 and abs(M[:, V]).sum() == 0  # V is massless (DAE)
    # heat capacity: 1^T M_T 1 = rho c_p * volume
    vol = sum(f_len * np.pi * r**2 for f_len, r in [(np.linalg.norm([1.0, 0.2, 0.1]), 0.1),
                                                     (np.linalg.norm([1, 0, 0.3]), 0.05)])
    assert np.isclose(M[T][:, T].sum(), MAT.density * MAT.heat_capacity * vol, rtol=1e-12)
    assert sp.issparse(model.evaluate(*random_state(model, np.random.default_rng(0)), 0.0)[1])


def test_conduction_current_of_a_uniform_field_is_sigma_A_E():
    """Straight fibril at rest, V linear: I = sigma0 A dV/ds, everywhere, with no motion terms."""
    L, R = 2.0, 0.1
    mesh = fibril_mesh([straight_fibril([0, 0, 0], [L, 0, 0], R)], 5, 2)
    model = BeamModel(mesh, MAT, fields=("mech", "T", "V"), couplings=Couplings(B=B))
    x = np.zeros(model.n); w = np.zeros(model.n)
    model.nodal(x)[:, :9] = mesh.X0
    model.nodal(w)[:, model.oV] = 0.3 - 0.1 * mesh.node_s
    I = model.axial_current(x, w)
    assert np.allclose(I, MAT.electrical_conductivity * np.pi * R**2 * 0.1, rtol=1e-12)
    ends = model.end_currents(x, w)
    assert np.allclose(ends[0], [-I[0, 0], I[0, 0]], rtol=1e-12)


def test_row_scaled_model_is_the_scaled_system():
    """with_row_scale (in-kernel) == RowScaledSystem (generic wrapper) == S * model."""
    from rve.model import RowScaledSystem

    rng = np.random.default_rng(3)
    model = make_model(2, True, CASES["all"])
    x, w = random_state(model, rng)
    s = rng.uniform(0.5, 2.0, model.n)
    a = model.with_row_scale(s)
    b = RowScaledSystem(model, s)
    F0, Fx0, Fw0 = model.evaluate(x, w, 0.0)
    for sysm in (a, b):
        F, Fx, Fw = sysm.evaluate(x, w, 0.0)
        assert np.allclose(F, s * F0, rtol=1e-14, atol=0)
        assert np.allclose(Fx.toarray(), s[:, None] * Fx0.toarray(), rtol=1e-14, atol=0)
        assert np.allclose(Fw.toarray(), s[:, None] * Fw0.toarray(), rtol=1e-14, atol=0)
        assert np.allclose(sysm.mass().toarray(), s[:, None] * model.mass().toarray(), rtol=1e-14, atol=0)
    # the original model is untouched
    assert np.array_equal(model.evaluate(x, w, 0.0)[0], F0)


def test_fast_neo_hookean_matches_beam_forms():
    from rve.physics.beam_forms import neo_hookean_element_forces
    from rve.physics.beam_forms import internal_force, internal_force_dmu

    rng = np.random.default_rng(5)
    for order, curved in [(1, False), (2, True), (3, True)]:
        model = make_model(order, curved, CASES["all"])
        x, _ = random_state(model, rng, scale=0.05)
        U = model.basis.element_values(model.nodal(x))
        mu = 2.0 + rng.uniform(size=model.basis.W.shape)
        R0, K0 = internal_force(model.basis, U, mu, 0.4, True)
        R1, K1, dR = neo_hookean_element_forces(model.basis, U, mu, 0.4, True, True)
        assert rel_err(R1, R0) < 1e-12 and rel_err(K1, K0) < 1e-12
        assert rel_err(dR, internal_force_dmu(model.basis, U)) < 1e-12


@pytest.mark.parametrize("back_emf", [True, False])
def test_fused_kernel_equals_the_separate_forms(back_emf):
    """coupled_forms (used by the model) == potential_equation + lorentz_force_field +
    joule_heating (the readable per-term forms), residuals and Jacobians."""
    from rve.physics.electric_forms import coupled_forms, emf, lorentz_force_field, potential_equation
    from rve.physics.thermal_forms import joule_heating

    rng = np.random.default_rng(11)
    model = make_model(2, True, CASES["all"])
    x, w = random_state(model, rng)
    U, Uv, Te, Ve = model.element_fields(x, w)
    m = emf(model.ops, U, Uv, Te, Ve, B, seebeck=0.4, back_emf=back_emf)
    R, J = coupled_forms(model.ops, m, 2.0, B)
    RV, JV = potential_equation(model.ops, m, 2.0)
    RL, JL = lorentz_force_field(model.ops, m, 2.0, B)
    RJ, JJ = joule_heating(model.ops, m, 2.0)
    assert rel_err(R["V"], RV) < 1e-13 and rel_err(R["L"], RL) < 1e-13 and rel_err(R["T"], RJ) < 1e-13
    E, nn = RV.shape
    assert rel_err(J["SV"][:, :nn], JV["V"]) < 1e-13 and rel_err(J["SV"][:, nn:], JJ["V"]) < 1e-13
    assert rel_err(J["Lx"], JL["x"]) < 1e-13 and rel_err(J["LV"], JL["V"]) < 1e-13
    if back_emf:
        assert rel_err(J["Sx"][:, :nn], JV["x"]) < 1e-13 and rel_err(J["Sv"][:, :nn], JV["v"]) < 1e-13
        assert rel_err(J["Sx"][:, nn:], JJ["x"]) < 1e-13 and rel_err(J["Sv"][:, nn:], JJ["v"]) < 1e-13
        assert rel_err(J["Lv"], JL["v"]) < 1e-13
    else:
        assert J["Sx"] is None and J["Lv"] is None and JL["v"] is None
