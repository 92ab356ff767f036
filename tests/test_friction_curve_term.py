"""The friction term on the curve and smooth contact geometries in the assembled contact
system (the crossing scene with ``contact.geometry`` curve / smooth): the assembled tangent
against central differences in stick and in slip (both half passes, the slider's and the
base's points), unsymmetric in slip and solved on the LU path; a commit changes no force;
the history follows rebuilds and records by point key; the frozen loads are a potential of
the assembled system."""
import sys
from pathlib import Path

import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import friction_crossing
from rve.solvers.linear import is_symmetric, sparse_solve
from rve.testing import fd_jacobian

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_friction_term import _slid, check_history_survives_rebuilds_and_records  # noqa: E402

CASES = [("curve", 1), ("curve", 2), ("curve", 3), ("smooth", 1), ("smooth", 2)]


def _case(geometry, order, cycle_steps=2, u=0.006, extra=()):
    """The crossing on the curve geometry, slid to ``u``: with the base's element centred
    under the crossing both half passes touch (the slider's point pressed on the base, the
    base's point pressed on the slider)."""
    return _slid([f"contact.geometry={geometry}", f"mesh.order={order}", "friction.stiffness=0.2", *extra],
                 cycle_steps=cycle_steps, u=u)


def _cols(system, cfg):
    """The mechanical dofs of the slider's middle element and of the base's element."""
    mesh, lay = system.mesh, system.layout
    nodes = np.concatenate([mesh.conn[cfg.mesh.elements // 2], mesh.conn[cfg.mesh.elements]])
    return lay.dofs("mech", nodes)


#: the slider's contact element moved back (both points stick) or on (both slip; p = 1 is
#: stiffer, its normal forces and so its stick lengths mu f / kT ten times those of p >= 2)
SHIFT = {"stick": -0.0002, "slip": 0.002}
SLIP_P1 = 0.01


def _trial(parts, x, regime, order=2):
    y = x.copy()
    y[parts["point_x"]] += SLIP_P1 if (regime == "slip" and order == 1) else SHIFT[regime]
    return y


@pytest.mark.parametrize("geometry, order", CASES)
@pytest.mark.parametrize("regime", ["stick", "slip"])
def test_assembled_tangent_exact(geometry, order, regime):
    cfg, system, parts, x = _case(geometry, order)
    fr = system.term.friction
    assert fr.last.normal.shape == (2, 1) and np.all(fr.last.normal > 0)   # both half passes touch
    y = _trial(parts, x, regime, order)
    st = fr.state(y)
    assert getattr(st, regime).sum() == 2, (st.stick, st.slip)
    w = np.zeros(system.n)
    F, Fx, _ = system.evaluate(y, w, 0.0)
    cols = _cols(system, cfg)
    J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], y, cols, eps=1e-7)
    A = Fx.toarray()[:, cols]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())
    if regime == "slip":
        assert not is_symmetric(Fx)
        b = np.random.default_rng(0).normal(size=system.n)
        free = np.setdiff1d(np.arange(system.n), system.constraints(0.0)[0])
        K = Fx[free][:, free]
        du = sparse_solve(K, b[free])
        assert np.linalg.norm(K @ du - b[free]) <= 1e-8 * np.linalg.norm(b[free])


@pytest.mark.parametrize("geometry, order", [("curve", 2), ("smooth", 2)])
def test_commit_changes_no_force(geometry, order):
    """A commit at a state (the history moved to the current closest points, the elastic
    gap kept) leaves the residual there as it was, in slip and in stick."""
    for regime in ("slip", "stick"):
        cfg, system, parts, x = _case(geometry, order)
        fr = system.term.friction
        y = _trial(parts, x, regime, order)
        assert getattr(fr.state(y), regime).sum() == 2
        w = np.zeros(system.n)
        F0 = system.evaluate(y, w, 0.0, jacobian=False)[0]
        s0 = fr.s_bar.copy()
        fr.commit(y)
        assert np.abs(fr.s_bar - s0).max() > 1e-5
        F1 = system.evaluate(y, w, 0.0, jacobian=False)[0]
        np.testing.assert_allclose(F1, F0, rtol=0, atol=1e-12 * np.abs(F0).max())


@pytest.mark.parametrize("geometry, order", [("curve", 2), ("smooth", 2)])
def test_history_survives_rebuilds_and_records(geometry, order):
    cfg, system, parts, x = _case(geometry, order, cycle_steps=1, u=0.001)
    fr = system.term.friction
    assert fr.last.stick.sum() == 2 and np.abs(fr.last.t).max() > 0
    assert fr.keys.shape == (2 * system.term.map.n_pairs * cfg.contact.n_gp, 6)
    assert np.unique(fr.keys, axis=0).shape[0] == fr.keys.shape[0]     # one key per row and point
    check_history_survives_rebuilds_and_records(cfg, system, parts, x, 0.0002)


def test_history_carried_to_the_next_element_of_the_base():
    """The base in two elements with its node under the crossing: the slider's point
    changes element pair as it slides; at every commit the row of the neighbouring base
    element takes the same material point (by its fibril parameter) and elastic gap, so the
    contact keeps its stick state across the node: the cycle's forces and dissipation are
    those of the one-element base (its point away from the crossing in both)."""
    steps = 6
    out = []
    for base in (["geometry.base_elements=2"], ["geometry.base_offset=0.5 mm"]):
        cfg = load_config("configs/scenes/crossing.yaml",
                          [f"load.steps_per_leg={steps}", "contact.geometry=curve", "mesh.order=2",
                           "friction.stiffness=0.01", *base])
        out.append(friction_crossing.solve(cfg).summary["path"])
    two, one = out
    F2, F1 = np.array([p["force"] for p in two]), np.array([p["force"] for p in one])
    assert min(p["stick"] for p in two[:2]) == 1 and max(p["slip_points"] for p in two) == 1
    np.testing.assert_allclose(F2, F1, rtol=0, atol=1e-9 * np.abs(F1).max())
    D2, D1 = sum(p["dissipated"] for p in two), sum(p["dissipated"] for p in one)
    assert D1 > 0
    assert D2 == pytest.approx(D1, rel=1e-9)


@pytest.mark.parametrize("geometry, order", [("curve", 2), ("smooth", 2)])
@pytest.mark.parametrize("case", ["stick", "slip", "separated"])
def test_frozen_loads_are_a_potential_of_the_assembled_system(geometry, order, case):
    """With the loads frozen (FrictionTerm.freeze) the assembled residual is the gradient of
    system.energy and its tangent the exact Hessian on the curves' local nodes, also where
    the fibrils have separated; a rebuild carries the frozen loads by point key."""
    cfg, system, parts, x = _case(geometry, order)
    fr = system.term.friction
    fr.freeze(None)
    f0 = fr.frozen_loads()["f0"]
    assert (f0 > 0).sum() == 2
    y = _trial(parts, x, "slip" if case == "separated" else case, order)
    if case == "separated":
        lay, mesh = system.layout, system.mesh
        y.reshape(-1, lay.block)[mesh.fibril_nodes(0), 2] += 0.03
        assert system.active_pairs(y).size == 0
    w = np.zeros(system.n)
    F, Fx, _ = system.evaluate(y, w, 0.0)
    cols = _cols(system, cfg)
    assert np.abs(F[cols]).max() > 1e-6
    # (eps 1e-5: at 1e-7 the rounding of the beams' energy alone gives 1e-6 of the largest
    # entry at p = 2, with or without friction)
    g = fd_jacobian(lambda v: np.array([system.energy(v)]), y, cols, eps=1e-5)[0]
    np.testing.assert_allclose(F[cols], g, rtol=1e-5, atol=1e-6 * np.abs(F[cols]).max())
    J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], y, cols, eps=1e-7)
    A = Fx.toarray()[:, cols]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())
    e0 = system.energy(y)
    system.rebuild(y)
    assert system.energy(y) == pytest.approx(e0, rel=1e-12)
    np.testing.assert_array_equal(fr.frozen_loads()["f0"], f0)


@pytest.mark.parametrize("geometry, order", [("curve", 2), ("smooth", 1)])
def test_frozen_at_its_own_loads_is_the_law(geometry, order):
    """Loads frozen at the state itself (``freeze(x)``, the material point moved to the
    closest points with the loads): the assembled residual is the law's."""
    cfg, system, parts, x = _case(geometry, order)
    fr = system.term.friction
    w = np.zeros(system.n)
    for regime in ("stick", "slip"):
        y = _trial(parts, x, regime, order)
        assert getattr(fr.state(y), regime).sum() == 2
        F_law = system.evaluate(y, w, 0.0, jacobian=False)[0]
        fr.freeze(y)
        F_fz = system.evaluate(y, w, 0.0, jacobian=False)[0]
        fr.unfreeze()
        np.testing.assert_allclose(F_fz, F_law, rtol=0, atol=1e-12 * np.abs(F_law).max())
        fr.freeze(None)
        assert np.abs(system.evaluate(y, w, 0.0, jacobian=False)[0] - F_law).max() > 1e-6 * np.abs(F_law).max()
        fr.unfreeze()


def _two_fibrils(fibs, geometry):
    """``(mesh, base, system, x)``: fibrils ``fibs`` (6 elements, p = 2) in one contact system
    with friction (mu 0.3, eps_T / P* 0.2) at their natural state."""
    from rve.fem.mesh import fibril_mesh
    from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem
    from rve.model.terms.friction import FrictionLaw

    mesh = fibril_mesh(fibs, 6, 2)
    base = BeamModel(mesh, BeamMaterial(1.26, density=1e-3))
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0
    params = ContactParams(penalty=50.0, geometry=geometry, friction=FrictionLaw(0.3, 0.2))
    return mesh, base, ContactSystem(base, params, x), x


def _seam_slide(a_start, geometry, slide, steps=10, L=2.0):
    """Fibril b pressed across fibril a (along x over [a_start, a_start + L], wrapping into its
    image one period L on) and slid along x by ``slide`` in ``steps`` prescribed positions,
    the friction history committed at each: the total contact force on b at each position."""
    from rve.fem.mesh import straight_fibril

    R = 0.15
    fibs = [straight_fibril([a_start, 0.013, 0], [a_start + L, 0.013, 0], R, "a"),
            straight_fibril([-slide / 2, -1, -(2 * R - 0.01)], [-slide / 2, 1, -(2 * R - 0.01)], R, "b")]
    mesh, base, system, x = _two_fibrils(fibs, geometry)
    T = np.array([L, 0.0, 0.0])
    system.set_periodic(images=[T, -T], wrap={0: T}, x=x, lattice=[T, [0.0, 4.0, 0.0]])
    fr = system.term.friction
    fr.commit(x)
    on_b = mesh.node_fibril == 1
    b_dofs = base.layout.dofs("r", np.flatnonzero(on_b)).reshape(-1, 3)
    forces = []
    for k in range(1, steps + 1):
        y = x.copy()
        base.nodal(y)[on_b, 0] += k * slide / steps
        system.rebuild(y)
        forces.append(system.evaluate(y, np.zeros(system.n), 0.0, False)[0][b_dofs].sum(axis=0))
        fr.commit(y)
    return np.array(forces)


@pytest.mark.parametrize("geometry", ["curve", "smooth"])
@pytest.mark.parametrize("slide", [0.004, 0.04, -0.04])
def test_history_carried_across_the_periodic_seam(geometry, slide):
    """A contact sliding across the seam of a fibril that wraps into its own image (its last
    element continues into the image of its first) carries its stick state over the seam
    as over any element end: the same slide with the seam half a period away (the
    same nodes, numbered from the other end) gives the same forces at every position, in
    stick (0.004 mm) and into slip (0.04 mm, both ways). Without the wrap in the neighbour
    relation the point restarted with no elastic gap at the seam (a third of the force lost)."""
    across = _seam_slide(0.0, geometry, slide)
    away = _seam_slide(-1.0, geometry, slide)
    assert np.abs(away[:, 0]).min() > 0.1 * np.abs(away[:, 0]).max()   # friction carries load all along
    np.testing.assert_allclose(across, away, rtol=0, atol=1e-12 * np.abs(away).max())


def _node_slide(geometry, bend, positions):
    """Fibril b pressed across fibril a (6 elements along x) next to a's node at x = 2/3,
    the history committed there (b's point inside a's element, the row of that point on
    a's next element sharing it), then a bent by ``bend`` about that node (its elements turn
    against each other) and b slid along x through ``positions`` across the node, on a, the
    history held: the total contact force on b at each position."""
    from rve.fem.mesh import straight_fibril

    R = 0.15
    x0 = positions[0]
    fibs = [straight_fibril([0.0, 0.013, 0.0], [2.0, 0.013, 0.0], R, "a"),
            straight_fibril([x0, -1, -(2 * R - 0.01)], [x0, 1, -(2 * R - 0.01)], R, "b")]
    mesh, base, system, x = _two_fibrils(fibs, geometry)
    fr = system.term.friction
    fr.commit(x)
    on_a, on_b = mesh.node_fibril == 0, mesh.node_fibril == 1
    b_dofs = base.layout.dofs("r", np.flatnonzero(on_b)).reshape(-1, 3)
    ra = base.nodal(x)[on_a, :3]
    y0 = x.copy()
    base.nodal(y0)[on_a, 2] += bend * (ra[:, 0] - 2.0 / 3.0) ** 2     # a's elements turn about its node
    forces = []
    for p in positions:
        y = y0.copy()
        base.nodal(y)[on_b, 0] += p - x0
        base.nodal(y)[on_b, 2] += bend * (p - 2.0 / 3.0) ** 2
        system.rebuild(y)
        forces.append(system.evaluate(y, np.zeros(system.n), 0.0, False)[0][b_dofs].sum(axis=0))
    return np.array(forces)


@pytest.mark.parametrize("geometry", ["curve", "smooth"])
def test_friction_force_continuous_across_an_element_end(geometry):
    """The anchor turns with the - fibril's tangent at the contact point, and a row that takes
    a neighbour's history takes its direction, so a contact sliding across an element end of
    a - fibril bent since the history keeps a continuous friction force: no change between
    neighbouring positions stands out from its neighbours' (a jump is one change many times
    both neighbours; with the turn by each element's own chord it was 162 times at the node,
    the two elements having turned against each other by the bend)."""
    positions = np.linspace(2.0 / 3.0 - 0.02, 2.0 / 3.0 + 0.02, 41)
    F = _node_slide(geometry, 0.6, positions)
    steps = np.linalg.norm(np.diff(F, axis=0), axis=1)
    assert steps.min() > 0
    spike = steps[1:-1] / np.maximum(steps[:-2], steps[2:])
    assert spike.max() <= 2.0, (spike.max(), int(np.argmax(spike)) + 1)
