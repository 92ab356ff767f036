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


def test_holm_conductance_is_proportional_to_the_contact_force():
    """Holm a-spots: the pair's conductance is 2 sigma0 / (pi H a_s) times the normal force
    (sum of w times the line load), for the chord and the curve; doubling H halves it."""
    for geometry in ("chord", "curve"):
        G = []
        for H in (100.0, 200.0):
            sysm, x, _ = _crossed(2, fields=("mech", "V"), geometry=geometry, conductance_law="holm", hardness=H,
                                  spot_radius=1e-3)
            Fn = sysm.contact_state(x)["total_normal_force"]
            G.append(sum(sysm.contact_conductance(x, "V").values()))
            np.testing.assert_allclose(G[-1], 2 * 10.0 / (np.pi * H * 1e-3) * Fn, rtol=1e-12)
        np.testing.assert_allclose(G[1], G[0] / 2, rtol=1e-12)


def test_active_points_per_pair():
    for geometry in ("chord", "curve"):
        sysm, x, _ = _crossed(2, fields=("mech",), geometry=geometry)
        n = sysm.active_points(x)
        assert n.shape == (sysm.map.n_pairs,) and n.sum() > 0
        assert set(np.flatnonzero(n)) == set(sysm.active_pairs(x))


def test_sliding_force_history_is_continuous():
    """The crossing slid over element ends of both fibrils (rigid, constant approach): the
    curve's largest force change per step halves when the step halves (no jump), and the
    force stays within 6 % of the closed form (n_gp = 4 quadrature ripple); the chord's
    over-count swings it by more than 50 %."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from contact_order import closed_form_force, crossed_force

    F = closed_form_force(0.02)
    h = 0.25
    coarse = np.linspace(0.0, 1.2 * h, 25)
    fine = np.linspace(0.0, 1.2 * h, 49)
    hist = {n: np.array([crossed_force(2, 8, "curve", 0.02, -0.3 + t, -0.3 + t) for t in s])
            for n, s in (("coarse", coarse), ("fine", fine))}
    jc = np.abs(np.diff(hist["coarse"])).max()
    jf = np.abs(np.diff(hist["fine"])).max()
    assert jf < 0.6 * jc
    assert np.abs(hist["fine"] / F - 1).max() < 0.06
    chord = np.array([crossed_force(2, 8, "chord", 0.02, -0.3 + t, -0.3 + t) for t in coarse])
    assert chord.max() / chord.min() > 1.5


def test_config_keys_reach_the_contact_params():
    from rve.config.fabric import FabricContact
    from rve.fabrics.setup import contact_params
    from rve.model import ContactParams

    d = contact_params(FabricContact(), 5)
    ref = ContactParams(penalty=50.0, heat_transfer=0.1, conductance=1.0, rebuild_every=5)
    assert d == ref  # the defaults: chord, penalty, width law
    p = contact_params(FabricContact(geometry="curve", enforcement="augmented_lagrangian", al_tolerance=1e-5,
                                     conductance_law="holm", hardness="0.1 GPa", spot_radius="2 um"), 5)
    assert (p.geometry, p.enforcement, p.al_tolerance, p.conductance_law) == ("curve", "augmented_lagrangian", 1e-5,
                                                                                "holm")
    np.testing.assert_allclose([p.hardness, p.spot_radius], [100.0, 2e-3])
    with pytest.raises(ValueError, match="contact.hardness"):
        FabricContact(conductance_law="holm")
    with pytest.raises(ValueError):
        FabricContact(geometry="spline")


@pytest.mark.parametrize("order", [2, 3])
def test_candidates_hold_every_active_pair(order):
    """The chord-distance prefilter never drops a pair with an active point: on bowed
    elements (nodes pushed off their chords) the full geometry's active pairs are among the
    candidates, and the forms equal those of the full geometry."""
    sysm, x, w = _crossed(order, ne=6, fields=("mech",), geometry="curve", seed=5)
    assert sysm.term.curve_candidates(x).size < sysm.map.n_pairs  # the filter drops far pairs
    xn = sysm.nodal(x)
    rng = np.random.default_rng(9)
    xn[:, :3] += rng.normal(scale=0.03, size=(xn.shape[0], 3))
    term = sysm.term
    full = term.geometry(x)
    act_full = term._pairs_of_rows(full.active)
    cand = term.curve_candidates(x)
    assert act_full.size > 0 and set(act_full) <= set(cand)
    act, R, _, _ = term.forms(x, w, False)
    np.testing.assert_array_equal(np.sort(act), np.sort(act_full))
