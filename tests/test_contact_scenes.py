"""Acceptance checks of the contact physics on two-fibril cases (docs/contact.md):

(a) two crossed fibrils pressed together by prescribed end displacements: equal and
    opposite contact forces balanced by the clamp reactions, the integrated overlap equals
    force / P*, Newton converges quadratically once the contact set is fixed;
(b) current (and heat) through one contact = 1 V over the series resistance of the two
    fibril halves and the contact 1/(sigma_C a l_c), within 2 %;
(c) weakened insulation (§8.2): a floating fibril solves, at the reference potential.
"""
import numpy as np
import pytest

from rve.model.insulation import pull_down_circuits, unwired_fibrils
from rve.model import ContactParams, ContactSystem
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel, DirichletBC
from rve.solvers.static import static_solve

R = 0.15
PSTAR = 50.0


def _pressed_pair(E=126.0, d=0.08, ne=16, order=1):
    fibs = [straight_fibril([-1, 0, R], [1, 0, R], R, "a"), straight_fibril([0, -1, -R], [0, 1, -R], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    a0, a1 = mesh.end_nodes(0)
    b0, b1 = mesh.end_nodes(1)
    pinned = np.array([n * 9 + k for n in (a0, a1, b0, b1) for k in range(3)])
    gauge = np.array([a0 * 9 + 5, b0 * 9 + 5])  # twist gauge: g1_z at one end of each
    base = BeamModel(mesh, BeamMaterial(E, density=1e-3),
                     bcs=[DirichletBC(pinned, 0.0), DirichletBC(gauge, 0.0)])
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0
    # prescribed end displacements: fibril a moved down by d, b up by d (ends included)
    xn[mesh.fibril_nodes(0), 2] -= d
    xn[mesh.fibril_nodes(1), 2] += d
    return base, x, (a0, a1, b0, b1)


def test_pressed_crossed_fibrils():
    base, x, (a0, a1, b0, b1) = _pressed_pair()
    sysm = ContactSystem(base, ContactParams(penalty=PSTAR), x)
    assert sysm.contact_state(x)["max_overlap"] > 0.1  # starts deeply interpenetrated
    seen = {}  # residual norm of every evaluated iterate -> its active contact set
    evaluate = sysm.evaluate
    free = np.ones(base.n, bool)
    free[base.constraints(0.0)[0]] = False

    def spy(x, w, t, jacobian=True):
        out = evaluate(x, w, t, jacobian)
        seen[float(np.linalg.norm(out[0][free]))] = frozenset(map(tuple, np.argwhere(sysm.geometry(x).active)))
        return out

    sysm.evaluate = spy
    xs, ws, res = static_solve(sysm, x, np.zeros(base.n), 0.0, {"atol": 1e-13, "rtol": 1e-14, "max_iter": 40})
    assert res.converged
    # equal and opposite contact forces, balanced by the clamp reactions
    fc = sysm.fibril_contact_forces(xs)
    assert fc[0, 2] > 1e-3  # a lies above b: pushed up
    np.testing.assert_allclose(fc[0], -fc[1], atol=1e-12)
    F = evaluate(xs, np.zeros(base.n), 0.0, False)[0]
    Fn = base.nodal(F)
    # the residual at a clamp is the force the clamp exerts on the fibril (F = f_int there)
    clamp_a, clamp_b = Fn[[a0, a1], :3].sum(0), Fn[[b0, b1], :3].sum(0)
    np.testing.assert_allclose(clamp_a, -fc[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(clamp_b, -fc[1], rtol=1e-9, atol=1e-12)
    # overlap ~ force / P*: the integrated overlap (mm^2) times P* is the contact force
    geo = sysm.geometry(xs)
    g = np.where(geo.active, geo.g, 0.0)
    int_g = float((sysm.term.weight[:, None] * g).sum())
    assert np.linalg.norm(fc[0]) == pytest.approx(PSTAR * int_g, rel=1e-2)
    assert 0 < g.max() < 0.05 * R
    # quadratic convergence once the active contact set no longer changes
    res_ = np.asarray(res.residuals)
    sets = [seen[float(r)] for r in res_]
    rates = []
    for k in range(2, len(res_)):
        if sets[k] == sets[k - 1] == sets[k - 2] and k < len(res_) - 1:  # last: round-off floor
            rates.append(np.log(res_[k] / res_[k - 1]) / np.log(res_[k - 1] / res_[k - 2]))
    assert len(rates) >= 1 and max(rates) > 1.8, (res_, rates)
    assert sets[-1] == sets[-2] and len(sets[-1]) > 0


def test_pressed_crossed_fibrils_sign():
    base, x, _ = _pressed_pair()
    sysm = ContactSystem(base, ContactParams(penalty=PSTAR), x)
    xs, _, res = static_solve(sysm, x, np.zeros(base.n), 0.0, {"atol": 1e-12})
    fc = sysm.fibril_contact_forces(xs)
    # a lies above b: a is pushed up (+z), b down
    assert res.converged and fc[0, 2] > 0 > fc[1, 2]


def _probe_pair(floating=True, factor=1e6, V_ref=0.25, ov=0.01, ne=16):
    fibs = [straight_fibril([-1, 0, 0], [1, 0, 0], R, "a"),
            straight_fibril([0, -1, -(2 * R - ov)], [0, 1, -(2 * R - ov)], R, "b")]
    if floating:
        fibs.append(straight_fibril([-1, 3, 0], [1, 3, 0], R, "c"))
    mesh = fibril_mesh(fibs, ne, 1)
    mat = BeamMaterial(1.26, density=1e-3, electrical_conductivity=10.0, heat_capacity=1.0,
                       thermal_conductivity=1.0)
    a0, _ = mesh.end_nodes(0)
    _, b1 = mesh.end_nodes(1)
    from rve.fem.assembly import DofLayout

    lay = DofLayout(mesh.n_nodes, ("mech", "T", "V"))
    oT, oV = lay.offset["T"], lay.offset["V"]
    bcs = [DirichletBC(np.flatnonzero(lay.mech), 0.0),  # geometry held: a pure conduction solve
           DirichletBC(np.array([a0 * lay.block + oV, b1 * lay.block + oV]), np.array([1.0, 0.0])),
           DirichletBC(np.array([a0 * lay.block + oT, b1 * lay.block + oT]), np.array([1.0, 0.0]))]
    if floating:  # no thermal pull-down in the model: pin the floating fibril's T
        bcs.append(DirichletBC(np.array([mesh.end_nodes(2)[0] * lay.block + oT]), 0.0))
    circ = pull_down_circuits(mesh, mat.electrical_conductivity, [a0, b1], factor=factor, V_ref=V_ref)
    base = BeamModel(mesh, mat, fields=("mech", "T", "V"), bcs=bcs, circuits=circ)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0
    sysm = ContactSystem(base, ContactParams(penalty=PSTAR, heat_transfer=0.1, conductance=1.0), x)
    return sysm, x, (a0, b1), lay


def test_current_and_heat_through_one_contact():
    sysm, x, (a0, b1), lay = _probe_pair(floating=False)
    xs, ws, res = static_solve(sysm, x, np.zeros(sysm.n), 0.0, {"atol": 1e-12})
    assert res.converged
    F = sysm.base.evaluate(xs, ws, 0.0, False)[0]  # the contact is far from the end node
    I = F[a0 * lay.block + lay.offset["V"]]  # current leaving through the 1 V end (reaction)
    Q = F[a0 * lay.block + lay.offset["T"]]
    A = np.pi * R**2
    Gv = sum(sysm.contact_conductance(xs, "V").values())  # sigma_C a l_c, discrete
    Gt = sum(sysm.contact_conductance(xs, "T").values())
    # halves: 1 mm from each far end to the crossing
    R_series = 2 * 1.0 / (10.0 * A) + 1.0 / Gv
    Rt_series = 2 * 1.0 / (1.0 * A) + 1.0 / Gt
    assert I * R_series == pytest.approx(1.0, rel=0.02)
    assert Q * Rt_series == pytest.approx(1.0, rel=0.02)
    # the contact resistance is the conductance of a width a over a length l_c
    st = sysm.contact_state(xs)
    l_c = Gv / (1.0 * st["max_width"])
    assert 0 < l_c < 0.5 and st["max_width"] > 0.1


def test_floating_fibril_sits_at_reference_potential():
    sysm, x, (a0, b1), lay = _probe_pair(floating=True, V_ref=0.25)
    assert list(unwired_fibrils(sysm.mesh, [a0, b1])) == [2]
    xs, ws, res = static_solve(sysm, x, np.zeros(sysm.n), 0.0, {"atol": 1e-12})
    assert res.converged
    V = sysm.nodal(ws)[:, lay.offset["V"]]
    np.testing.assert_allclose(V[sysm.mesh.fibril_nodes(2)], 0.25, atol=1e-12)
    # the pull-downs barely perturb the wired path (leak ~ 1/factor)
    ref, _, _, _ = _probe_pair(floating=False)
    _, ws0, _ = static_solve(ref, x[: ref.n], np.zeros(ref.n), 0.0, {"atol": 1e-12})
    V0 = ref.nodal(ws0)[:, lay.offset["V"]]
    nab = V0.size
    np.testing.assert_allclose(V[:nab], V0, atol=1e-6)


def test_without_pull_down_the_floating_fibril_is_singular():
    """The reason for §8.2: without the pull-down the V block of the floating fibril has a
    constant null mode (the static Jacobian is singular)."""
    sysm, x, _, lay = _probe_pair(floating=True, factor=1e6)
    base = sysm.base
    base_np = BeamModel(base.mesh, base.material, fields=("mech", "T", "V"), bcs=base.bcs)
    s2 = ContactSystem(base_np, sysm.params, x)
    _, _, Fw = s2.evaluate(x, np.zeros(s2.n), 0.0)
    Vc = s2.layout.field_dofs("V", s2.mesh.fibril_nodes(2))
    block = Fw[Vc][:, Vc].toarray()
    assert np.abs(block @ np.ones(len(Vc))).max() < 1e-12  # constant mode
    _, _, Fw1 = sysm.evaluate(x, np.zeros(sysm.n), 0.0)
    block1 = Fw1[Vc][:, Vc].toarray()
    assert np.abs(block1 @ np.ones(len(Vc))).max() > 0
