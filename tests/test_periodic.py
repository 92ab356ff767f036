"""The periodic cell (rve.model.periodic, rve.homogenisation.periodic*): closed forms.

(a) straight parallel fibrils under uniaxial macro strain: the force per fibril is the
    beam model's uniaxial Neo-Hookean force (nu = 0: N = E A (lambda - 1/lambda) / 2) and
    the sheet resistance W / (sigma A n); (b) a rigid rotation F = Q leaves the cell
    stress-free; (c) Hill-Mandel: dPi/dF = A P at an equilibrium of a woven cell with
    contact; the exact reduced tangent (finite differences); (d) a 1 x 1 and a 2 x 2
    periodic plain weave give the same per-width figures.
"""
from __future__ import annotations

import numpy as np
import pytest

from rve.fem.assembly import DofLayout
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel
from rve.model.periodic import PeriodicSystem, fibril_end_ties, in_plane_gradient as in_plane, polar_rotation
from rve.solvers.static import static_solve
from rve.testing import fd_jacobian, rel_err

E_MOD, RADIUS, SIGMA = 1.26, 0.15, 10.0


def _rotation(theta):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _straight_cell(n=3, L=4.0, W=2.0, order=2, elements=5, cross=False):
    """``n`` straight fibrils along x, spaced W/n across y (and, with ``cross``, ``n`` along
    y one layer up, not touching): a periodic cell of L x W (or L x L)."""
    Wc = L if cross else W
    fibs = [straight_fibril([-L / 2, (k + 0.5) * Wc / n - Wc / 2, 0], [L / 2, (k + 0.5) * Wc / n - Wc / 2, 0],
                            RADIUS) for k in range(n)]
    if cross:
        fibs += [straight_fibril([(k + 0.5) * L / n - L / 2, -Wc / 2, 1.0], [(k + 0.5) * L / n - L / 2, Wc / 2, 1.0],
                                 RADIUS) for k in range(n)]
    mesh = fibril_mesh(fibs, elements, order)
    return mesh, fibril_end_ties(mesh, [[L, 0, 0], [0, Wc, 0]])


def _per_fibril_gauge(ties, mesh):
    """Every fibril's first centroid and g1_z held (no contact: each fibril translates alone)."""
    lay = DofLayout(ties.kept_nodes.size, ("mech",))
    first = np.searchsorted(ties.kept_nodes, mesh.node_offsets[:-1])
    return np.concatenate([lay.dofs("r", first), lay.dofs("g1", first, comp=2)])


def _solve(psys, x_red):
    xs, _, res = static_solve(psys, x_red, np.zeros(psys.n), 0.0, {"atol": 1e-13, "rtol": 1e-15, "max_iter": 30})
    assert res.converged, res.reason
    return xs


@pytest.mark.parametrize("eps", [0.1, -0.05])
def test_straight_fibrils_uniaxial_force_is_the_beam_models_closed_form(eps):
    mesh, ties = _straight_cell()
    psys = PeriodicSystem(BeamModel(mesh, BeamMaterial(E_MOD, 0.0, 1e-3)), ties, _per_fibril_gauge(ties, mesh),
                          F=np.diag([1.0 + eps, 1.0]))
    xs = _solve(psys, psys.restrict(mesh.X0.reshape(-1)))
    lam, A = 1.0 + eps, np.pi * RADIUS ** 2
    # Neo-Hookean with nu = 0 (lambda_Lame = 0): P = mu (F - F^-T), lateral stretch 1, E = 2 mu
    force = 0.5 * E_MOD * A * (lam - 1.0 / lam)
    P = psys.macro_stress(xs)
    per_fibril = psys.tie_forces(xs)[:, 0]
    assert np.allclose(per_fibril, force, rtol=1e-8, atol=0)
    assert P[0, 0] * 2.0 / 3 == pytest.approx(force, rel=1e-8)  # P11 = n N / W
    assert np.abs(P[1:, :]).max() < 1e-12 * abs(force)


def test_straight_fibrils_sheet_resistance_is_exact_and_the_joule_power_is_j_dot_e():
    from rve.homogenisation.periodic_probes import field_solve

    n, L, W = 3, 4.0, 2.0
    mesh, ties = _straight_cell(n, L, W, order=1, elements=4)
    mat = BeamMaterial(E_MOD, 0.0, 1e-3, electrical_conductivity=SIGMA, thermal_conductivity=1.0)
    A, E = np.pi * RADIUS ** 2, 0.25
    for stretch in (1.0, 1.2):  # the section 7.4 pull-back: the current does not change with the stretch
        xn = mesh.X0.copy()
        xn[:, 0] *= stretch
        sol = field_solve(mesh, ties, xn, np.diag([stretch, 1.0, 1.0]), mat, None, np.array([E, 0.0, 0.0]))
        j = -sol["tie_currents"].sum() / W  # A per mm of width, leaving through the + face
        assert E / j == pytest.approx(W / (SIGMA * A * n), rel=1e-12)  # sheet resistance
        # per unit width: a strip of length L has the resistance x width L / (sigma A n_w), n_w = n / W
        assert (E / j) * L == pytest.approx(L / (SIGMA * A * (n / W)), rel=1e-12)
        assert sol["joule_power"] / (L * W) == pytest.approx(j * E, rel=1e-12)  # Hill-Mandel of conduction
        assert np.abs(sol["T"]).max() < 1e-12  # uniform Joule heat, uniform sink: no fluctuation


def test_current_across_the_cell_face_through_the_image_contacts_only():
    """One straight fibril along x pressed against its own images across the y face: along
    y it conducts only through the contacts with its images, whose potential is the macro
    jump E W lower (V is uniform on the fibril): j = G E W / L, G the contact conductance
    of one interface; without the images nothing crosses the y face, and along x the
    fibril is a wire (j = sigma A E / W)."""
    from rve.homogenisation.periodic_probes import field_solve
    from rve.model import ContactParams, ContactSystem

    L, W, E0 = 4.0, 0.28, 0.25
    mesh = fibril_mesh([straight_fibril([-L / 2, 0.0, 0.0], [L / 2, 0.0, 0.0], RADIUS)], 6, 1)
    ties = fibril_end_ties(mesh, [[L, 0, 0], [0, W, 0]])
    mat = BeamMaterial(E_MOD, 0.0, 1e-3, electrical_conductivity=SIGMA, thermal_conductivity=1.0)
    cp = ContactParams(penalty=50.0, n_gp=4, margin=0.1, conductance=3.0)
    xn = mesh.X0.copy()
    contact = ContactSystem(BeamModel(mesh, mat), cp, xn.reshape(-1))
    psys = PeriodicSystem(contact, ties, F=np.eye(2), contact_images=True)
    psys.rebuild(psys.restrict(xn.reshape(-1)))
    G = psys.full.term.conductance_by_pair(psys.expand(psys.restrict(xn.reshape(-1))))
    assert list(G) == [(0, 0)]  # one interface per cell: the fibril and its image
    A = np.pi * RADIUS ** 2
    along_y = field_solve(mesh, ties, xn, np.eye(3), mat, cp, np.array([0, E0, 0]), temperature=False)
    assert along_y["macro_current"][1] == pytest.approx(G[(0, 0)] * E0 * W / L, rel=1e-10)
    assert np.abs(along_y["tie_currents"]).max() < 1e-12 * along_y["macro_current"][1]  # no tie crosses y
    off = field_solve(mesh, ties, xn, np.eye(3), mat, cp, np.array([0, E0, 0]), temperature=False,
                      contact_images=False)
    assert abs(off["macro_current"][1]) < 1e-14
    wire = field_solve(mesh, ties, xn, np.eye(3), mat, cp, np.array([E0, 0, 0]), temperature=False,
                       contact_images=False)
    assert wire["macro_current"][0] == pytest.approx(SIGMA * A * E0 / W, rel=1e-12)


def test_rigid_rotation_gives_zero_stress_and_rotates_every_director():
    mesh, ties = _straight_cell(n=2, cross=True)
    Q = _rotation(0.5)
    assert np.allclose(polar_rotation(Q @ np.diag([1.3, 0.9, 1.0])), Q)
    psys = PeriodicSystem(BeamModel(mesh, BeamMaterial(E_MOD, 0.0, 1e-3)), ties, _per_fibril_gauge(ties, mesh),
                          F=Q[:2, :2])
    X = mesh.X0.reshape(-1, 3) @ Q.T
    x0 = X.reshape(mesh.n_nodes, 9)
    # a perturbation of the free centroids (the held dofs keep the rotated values)
    rng = np.random.default_rng(1)
    x_red = psys.restrict(x0.reshape(-1))
    free = np.setdiff1d(psys.layout.dofs("r"), psys.constraints(0.0)[0])
    x_red[free] += 0.01 * rng.standard_normal(free.size)
    xs = _solve(psys, x_red)
    assert np.abs(psys.macro_stress(xs)).max() < 1e-11
    assert np.abs(psys.expand(xs).reshape(mesh.n_nodes, 9) - x0).max() < 1e-10


@pytest.fixture(scope="module")
def woven_cell():
    from rve.fabrics.setup import fabric_and_mesh
    from rve.config.rve import RVEConfig
    from rve.homogenisation.strain import relax_fabric

    cfg = RVEConfig(scene="rve", boundary="periodic", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6},
                    contact={"onset": 0.05}, strain={"total": 0.1, "steps": 2})
    fab, mesh = fabric_and_mesh(cfg)
    x, _, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info["converged"]
    return cfg, fab, mesh, x


def test_reduced_tangent_is_exact(woven_cell):
    from rve.homogenisation.periodic import macro_gradient, periodic_system

    cfg, fab, mesh, x = woven_cell
    F = macro_gradient("shear", 0.05) @ macro_gradient("uniaxial", 0.03)
    psys = periodic_system(cfg, fab, mesh, x, F)
    xr = psys.restrict(x.reshape(-1)) + 1e-3 * np.random.default_rng(2).standard_normal(psys.n)
    psys.rebuild(xr)
    assert len(psys.active_pairs(xr)) > 0
    w = np.zeros(psys.n)
    R, K, _ = psys.evaluate(xr, w, 0.0)
    cols = np.arange(0, psys.n, 7)
    fd = fd_jacobian(lambda u: psys.evaluate(u, w, 0.0, jacobian=False)[0], xr, cols, eps=1e-7)
    assert rel_err(K.toarray()[:, cols], fd) < 1e-6
    # the residual is the gradient of the energy: R_red = T^T R_full
    g = fd_jacobian(lambda u: np.array([psys.energy(u)]), xr, cols, eps=1e-7)[0]
    assert rel_err(R[cols], g) < 1e-6


def test_hill_mandel_macro_work_equals_the_micro_energy_change(woven_cell):
    from rve.homogenisation.periodic import macro_gradient, periodic_system
    from rve.homogenisation.strain import static_minimize

    cfg, fab, mesh, x = woven_cell
    F0 = macro_gradient("uniaxial", 0.04)
    dF = np.array([[0.3, 0.1, 0.0], [0.5, -0.2, 0.0], [0.0, 0.0, 0.0]])

    def equilibrium(t):
        psys = periodic_system(cfg, fab, mesh, x, F0 + t * dF)
        xs, info = static_minimize(psys, psys.restrict(x.reshape(-1)), 1e-12, 200)
        assert info["converged"]
        return psys, xs

    psys, xs = equilibrium(0.0)
    macro = psys.ties.area * float(np.sum(psys.macro_stress(xs) * dF))
    energies = {t: psys_t.energy(xs_t) for t in (-2e-4, -1e-4, 1e-4, 2e-4) for psys_t, xs_t in [equilibrium(t)]}
    d1 = (energies[1e-4] - energies[-1e-4]) / 2e-4
    d2 = (energies[2e-4] - energies[-2e-4]) / 4e-4
    micro = (4.0 * d1 - d2) / 3.0  # Richardson: O(h^4)
    assert abs(macro) > 1e-4
    assert micro == pytest.approx(macro, rel=1e-8)



def test_hill_mandel_with_contact_across_the_cell_face():
    """One straight fibril along x in a cell narrower than its diameter: it is pressed
    against its own periodic images across the y face, so all of the y stress is image
    contact (no pair inside the cell)."""
    from rve.model import ContactParams, ContactSystem

    L, W = 4.0, 0.28  # W < 2 R: an overlap of 0.02 with each image
    mesh = fibril_mesh([straight_fibril([-L / 2, 0.0, 0.0], [L / 2, 0.0, 0.0], RADIUS)], 6, 1)
    ties = fibril_end_ties(mesh, [[L, 0, 0], [0, W, 0]])
    base = BeamModel(mesh, BeamMaterial(E_MOD, 0.0, 1e-3))
    full = ContactSystem(base, ContactParams(penalty=50.0, n_gp=4, margin=0.1, onset=0.05 * RADIUS), mesh.X0.reshape(-1))
    held = _per_fibril_gauge(ties, mesh)
    F0 = np.array([[1.03, 0.0], [0.02, 0.995]])
    dF = np.array([[0.2, 0.0, 0.0], [0.4, 0.7, 0.0], [0.0, 0.0, 0.0]])

    def equilibrium(t):
        F = in_plane(F0) + t * dF
        psys = PeriodicSystem(full, ties, held, 0.0, F=F, contact_images=True)
        x = mesh.X0.reshape(-1, 3) @ F.T
        xr = psys.restrict(x.reshape(-1))
        psys.rebuild(xr)
        return psys, _solve(psys, xr)

    psys, xs = equilibrium(0.0)
    act = psys.active_pairs(xs)
    assert len(act) > 0 and np.all(np.abs(psys.map.shifts[act][:, 1]) > 0)  # every active pair is an image pair
    moment = psys.image_contact_moment(xs)
    assert moment[1, 1] < 0 and abs(moment[1, 1]) > 1e-4  # compression across y, from the images only
    macro = psys.ties.area * float(np.sum(psys.macro_stress(xs) * dF))
    e = {t: p_.energy(x_) for t in (-2e-4, -1e-4, 1e-4, 2e-4) for p_, x_ in [equilibrium(t)]}
    micro = (4.0 * (e[1e-4] - e[-1e-4]) / 2e-4 - (e[2e-4] - e[-2e-4]) / 4e-4) / 3.0
    assert micro == pytest.approx(macro, rel=1e-8)


def _repeat_figures(kind, repeat, mode):
    """Per-width membrane forces P11, P22 (N/mm), sheet resistances (ohm) and the energy per
    pattern cell (mJ) after one strain step of ``mode`` of a periodic ``kind`` cell."""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.config.rve import RVEConfig
    from rve.homogenisation.periodic import macro_gradient, periodic_system
    from rve.homogenisation.probes import solve_probes
    from rve.homogenisation.strain import relax_fabric, strain_step

    per = 6 if kind == "plain" else 8  # elements per pattern period of a fibril (the same element length)
    cfg = RVEConfig(scene="rve", boundary="periodic", cell={"repeat": repeat}, fabric={"kind": kind, "rows": [1]},
                    mesh={"elements": per * repeat}, strain={"total": 0.05, "steps": 1},
                    probe_solver={"temperature": False})
    fab, mesh = fabric_and_mesh(cfg)
    x, _, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info["converged"], info["residual_N"]
    x, _, info = strain_step(cfg, fab, mesh, x, x, mode, 1)
    assert info["converged"], info["residual_N"]
    L = 2.0 * fab.half_widths[:2]
    reac = info["reaction_force"]
    probes = solve_probes(cfg, fab, mesh, x)
    psys = periodic_system(cfg, fab, mesh, x, macro_gradient(mode, 0.05))
    energy = psys.energy(psys.restrict(x.reshape(-1))) / repeat ** 2
    return np.array([reac["x+"][0] / L[1], reac["y+"][1] / L[0], probes["field_x"].resistance,
                     probes["field_y"].resistance]), energy


@pytest.mark.parametrize("kind", ["plain"] + [pytest.param(k, marks=pytest.mark.long)  # 10-40 s each on 2 busy cores
                                              for k in ("twill_2_1", "twill_2_2", "basket_2_2")])
def test_one_and_two_repeats_give_the_same_per_width_figures(kind):
    """Every weave the project ships, uniaxial: the 2 x 2 repeat of the cell (the same
    element length) has the per-width forces and sheet resistances of the 1 x 1 cell."""
    one, e1 = _repeat_figures(kind, 1, "uniaxial")
    two, e2 = _repeat_figures(kind, 2, "uniaxial")
    assert np.allclose(two, one, rtol=1e-6, atol=0)
    assert e2 == pytest.approx(e1, rel=1e-6)


def test_in_shear_the_two_repeat_cell_may_double_the_period():
    """In shear the 2 x 2 plain cell is free to take an equilibrium of twice the period
    (the crossings settle a little differently in z); it is no higher in energy per
    pattern cell than the 1 x 1 cell's, and its per-width figures stay within 0.1 % of
    them (a tenth of the 1 % the table is to meet)."""
    one, e1 = _repeat_figures("plain", 1, "shear")
    two, e2 = _repeat_figures("plain", 2, "shear")
    assert e2 <= e1 * (1.0 + 1e-12)
    assert np.allclose(two, one, rtol=1e-3, atol=0)


def _crossing_cell(repeat, L=2.0, delta=0.05, elements=8, order=1):
    """``repeat`` x ``repeat`` copies of one crossing: a fibril along x at y = 0 (z = 0) under
    one along y at x = L/2 - delta (z = 0.26 < 2 R), in a cell [-L/2, (repeat - 1/2) L]^2 whose
    x faces cut the crossing's contact zone (delta < its half-length)."""
    n, cell = int(repeat), int(repeat) * L
    lo, hi = -L / 2, -L / 2 + cell
    fibs = [straight_fibril([lo, k * L, 0.0], [hi, k * L, 0.0], RADIUS) for k in range(n)]
    fibs += [straight_fibril([L / 2 - delta + k * L, lo, 0.26], [L / 2 - delta + k * L, hi, 0.26], RADIUS)
             for k in range(n)]
    mesh = fibril_mesh(fibs, elements * n, order)
    return mesh, fibril_end_ties(mesh, [[cell, 0, 0], [0, cell, 0]])


@pytest.mark.parametrize("order", [1, 2])
def test_a_crossing_cut_by_the_cell_face_gets_its_contact_force(order):
    """The 1 x 1 cell's crossing straddles its x face; in the 2 x 2 cell the same crossing
    (one of four) lies inside. At the same periodic (bent, sheared) state, every reduced
    node of the 1 x 1 cell has the residual of its copies in the 2 x 2 cell, the energy is a
    quarter and the Hill-Mandel stress is the same; without the images the face crossing
    loses the part of its force beyond the face."""
    from rve.model import ContactParams, ContactSystem

    L, F = 2.0, np.array([[1.02, 0.03], [-0.01, 0.99]])
    params = ContactParams(penalty=50.0, n_gp=4, margin=0.1, onset=0.05 * RADIUS)

    def periodic_state(mesh):
        # the affine map of the reference plus a periodic bend (period L in x and y)
        X = mesh.X0.reshape(mesh.n_nodes, 9)
        x = X.reshape(-1, 3) @ in_plane(F).T
        x = x.reshape(mesh.n_nodes, 9)
        k = 2 * np.pi / L
        x[:, 2] += 0.01 * np.sin(k * X[:, 0] + 0.3) * np.cos(k * X[:, 1]) - 0.008 * np.cos(k * X[:, 1] + 0.5)
        return x.reshape(-1)

    def evaluate(repeat, images):
        mesh, ties = _crossing_cell(repeat, L, order=order)
        x = periodic_state(mesh)
        full = ContactSystem(BeamModel(mesh, BeamMaterial(E_MOD, 0.0, 1e-3)), params, x)
        psys = PeriodicSystem(full, ties, (), 0.0, F=F, contact_images=images)
        xr = psys.restrict(x)
        assert np.allclose(psys.expand(xr), x, atol=1e-13)  # the state is periodic at F
        psys.rebuild(xr)
        R = psys.evaluate(xr, np.zeros(psys.n), 0.0, jacobian=False)[0]
        return mesh, ties, psys, xr, R

    m1, t1, p1, x1, R1 = evaluate(1, True)
    m2, t2, p2, x2, R2 = evaluate(2, True)
    assert len(p1.active_pairs(x1)) > 0 and np.any(p1.map.shifts[p1.active_pairs(x1)][:, 0] != 0)
    # the reduced node of fibril f, node j of the 1 x 1 cell and its copies in the 2 x 2 cell
    per = order * 8  # reduced nodes per fibril of the 1 x 1 cell (the image node dropped)
    R1n, R2n = R1.reshape(-1, 9), R2.reshape(-1, 9)
    for f in range(2):
        for copy in range(2):
            for half in range(2):
                f2 = 2 * f + copy
                rows = f2 * 2 * per + half * per + np.arange(per)
                assert np.allclose(R2n[rows], R1n[f * per + np.arange(per)], rtol=0, atol=1e-12 * np.abs(R1).max())
    assert p2.energy(x2) == pytest.approx(4.0 * p1.energy(x1), rel=1e-12)
    assert np.allclose(p2.macro_stress(x2), p1.macro_stress(x1), rtol=0, atol=1e-12 * np.abs(p1.macro_stress(x1)).max())
    # without the images the crossing cut by the face is not whole
    *_, p0, x0, _ = evaluate(1, False)
    contact = {k: p_.full.contact_energy(p_.expand(x_)) for k, p_, x_ in (("none", p0, x0), ("1x1", p1, x1),
                                                                          ("2x2", p2, x2))}
    assert contact["1x1"] == pytest.approx(contact["2x2"] / 4.0, rel=1e-12)
    assert contact["none"] < 0.9 * contact["1x1"]
    # and its current: the sheet currents of the two cells agree (the contact conducts
    # across the face through the image, at the potential the macro field gives it)
    from rve.homogenisation.periodic_probes import field_solve

    mat = BeamMaterial(E_MOD, 0.0, 1e-3, electrical_conductivity=SIGMA, thermal_conductivity=1.0)
    cp = ContactParams(penalty=50.0, n_gp=4, margin=0.1, onset=0.05 * RADIUS, conductance=3.0)
    for E in ([0.25, 0.0, 0.0], [0.1, -0.2, 0.0]):
        j = [field_solve(m_, t_, p_.expand(x_).reshape(m_.n_nodes, 9), in_plane(F), mat, cp, np.array(E),
                         temperature=False)["macro_current"] for m_, t_, p_, x_ in ((m1, t1, p1, x1), (m2, t2, p2, x2))]
        assert np.allclose(j[0], j[1], rtol=0, atol=1e-10 * np.abs(j[0]).max())
