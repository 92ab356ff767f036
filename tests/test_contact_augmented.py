"""Augmented Lagrangian contact (rve.solvers.augmented, enforcement 'augmented_lagrangian'):
two crossed fibrils pressed together by prescribed end displacements. The Uzawa loop brings
the largest overlap below the tolerance, the contact force is independent of P* (to what that
tolerance allows) and differs from the plain penalty's, the Newton solves stay quadratic, and
the multipliers follow the points across a rebuild of the map."""
import numpy as np
import pytest

from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem, DirichletBC
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.solvers.augmented import AugmentedLagrangian, solve_with_multipliers
from rve.solvers.static import static_solve

R = 0.15
D = 0.08  # each fibril's ends moved by D towards the other


def _pressed(order, penalty, ne=8, **kw):
    fibs = [straight_fibril([-1, 0, R], [1, 0, R], R, "a"), straight_fibril([0.03, -1, -R], [0.03, 1, -R], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    ends = [n for f in (0, 1) for n in mesh.end_nodes(f)]
    pinned = np.array([n * 9 + k for n in ends for k in range(3)])
    gauge = np.array([mesh.end_nodes(0)[0] * 9 + 5, mesh.end_nodes(1)[0] * 9 + 5])
    base = BeamModel(mesh, BeamMaterial(126.0, density=1e-3), bcs=[DirichletBC(pinned, 0.0), DirichletBC(gauge, 0.0)])
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0
    a0, a1 = mesh.end_nodes(0)
    b0, b1 = mesh.end_nodes(1)
    xn[[a0, a1], 2] -= D  # the interior starts at the reference (touching): no pass-through
    xn[[b0, b1], 2] += D
    sysm = ContactSystem(base, ContactParams(penalty=penalty, **kw), x)
    return sysm, x


def _solve(sysm, x, log):
    def solve(y):
        xs, _, res = static_solve(sysm, y, np.zeros(sysm.n), 0.0, {"atol": 1e-11, "rtol": 1e-13, "max_iter": 40})
        assert res.converged
        log.append(res)
        return xs
    return solve_with_multipliers(sysm, solve, x)


@pytest.mark.parametrize("geometry", ["curve", "chord"])
def test_gap_below_tolerance_and_force_independent_of_penalty(geometry):
    forces, pens = [], []
    for P in (50.0, 500.0):
        sysm, x = _pressed(2, P, geometry=geometry, enforcement="augmented_lagrangian")
        log = []
        xs, loop = _solve(sysm, x, log)
        assert not loop.exhausted and loop.updates >= 1
        pen = sysm.max_penetration(xs)
        assert pen <= loop.tolerance == 1e-4
        pens.append(pen)
        forces.append(sysm.fibril_contact_forces(xs)[0, 2])
        # Newton is unchanged by the multipliers: near the solution every step is quadratic,
        # r_k+1 <= C r_k^2 (residuals in N; steps from r_k < 1e-3 N above the round-off
        # floor; a linear rate would need C r_k > its contraction)
        for res in log:
            r = np.asarray(res.residuals)
            near = (r[:-1] < 1e-3) & (r[1:] > 1e-12)
            assert np.all(r[1:][near] <= 1e3 * r[:-1][near] ** 2), res.residuals
            assert len(r) <= 16
    # an overlap below 1e-4 R moves each fibril by < 1.5e-5 mm of its ~0.08 mm deflection
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-3)
    # the plain penalty (P* = 50) is off by far more than that
    sysm, x = _pressed(2, 50.0, geometry=geometry)
    xs, _, res = static_solve(sysm, x, np.zeros(sysm.n), 0.0, {"atol": 1e-11, "rtol": 1e-13, "max_iter": 40})
    assert res.converged and sysm.max_penetration(xs) > 10 * max(pens)
    assert abs(sysm.fibril_contact_forces(xs)[0, 2] / forces[0] - 1) > 1e-2


def test_penalty_system_is_converged_at_once():
    sysm, x = _pressed(1, 50.0)
    loop = AugmentedLagrangian(sysm)
    assert not loop.active and loop.update(x) and loop.updates == 0 and sysm.multipliers is None


def test_multipliers_survive_a_rebuild():
    sysm, x = _pressed(2, 50.0, geometry="curve", enforcement="augmented_lagrangian")
    xs, loop = _solve(sysm, x, [])
    lam = sysm.multipliers.copy()
    F0 = sysm.evaluate(xs, np.zeros(sysm.n), 0.0, False)[0]
    sysm.rebuild(xs)
    np.testing.assert_array_equal(sysm.multipliers, lam)  # same pairs: same points
    F1 = sysm.evaluate(xs, np.zeros(sysm.n), 0.0, False)[0]
    np.testing.assert_allclose(F1, F0, atol=1e-14)
    # a smaller cutoff drops far pairs: the points still in the map keep their multipliers
    term = sysm.term
    keys, old = term._keys.copy(), lam.ravel().copy()
    term.cutoff = 2 * R + 0.01
    sysm.rebuild(xs)
    assert term.map.n_pairs < lam.shape[0] // 2
    new = dict(zip(map(tuple, term._keys), term.multipliers.ravel()))
    for k, v in zip(map(tuple, keys), old):
        if k in new:
            assert new[k] == v
    F2 = sysm.evaluate(xs, np.zeros(sysm.n), 0.0, False)[0]
    np.testing.assert_allclose(F2, F0, atol=1e-12)


@pytest.mark.parametrize("geometry", ["chord", "curve"])
def test_multiplier_tangents_with_the_onset_law(geometry):
    """The width of the line load through the C² onset (p = φ'(g), dp/dg = φ''(g)): every
    tangent block against central differences of the residual."""
    from test_contact_curve_system import _check_tangents, _crossed

    sysm, x, w = _crossed(2, geometry=geometry, enforcement="augmented_lagrangian", onset=0.05)
    sysm.update_multipliers(x)
    assert sysm.multipliers.max() > 0
    _check_tangents(sysm, x, w)


def test_width_is_hertz_width_of_the_line_load():
    """With multipliers the width is sqrt(4 R* p / (pi E*)) of the line load p = φ'(g) (closed
    form, g_eps = 0), for the onset law as well; for the linear law it is the penalty's
    kappa sqrt(g); the same load at another P* gives the same width."""
    from rve.physics.contact_forms import effective_radius, hertz_width, penalty_law

    g = np.linspace(-1e-3, 2e-2, 41)
    widths = {}
    for onset in (0.0, 0.05):
        for P in (50.0, 500.0):
            sysm, _ = _pressed(1, P, enforcement="augmented_lagrangian", onset=onset, g_eps=0.0)
            term = sysm.term
            kap = term.kappa[0]
            a, _ = term.line_load_width(g, kap)
            p = penalty_law(g, P, term.onset)[1]
            Rs = effective_radius(R, R)
            np.testing.assert_allclose(a, np.sqrt(4 * Rs * p / (np.pi * term.E_star)), rtol=1e-12, atol=1e-15)
            if onset == 0.0:
                np.testing.assert_allclose(a, hertz_width(g, kap, 0.0)[0], rtol=1e-12, atol=1e-15)
            # the overlap that carries the load p = 3 N/mm at this P* (past the onset)
            pl = 3.0
            gl = pl / P if onset == 0.0 else pl / P + 0.5 * term.onset
            widths[onset, P] = term.line_load_width(np.array([gl]), kap)[0][0]
    for onset in (0.0, 0.05):
        assert widths[onset, 50.0] == pytest.approx(widths[onset, 500.0], rel=1e-12)


@pytest.mark.parametrize("geometry", ["chord", "curve"])
def test_penalty_increase_takes_fewer_updates_and_ends_at_the_configured_penalty(geometry):
    """P* = 5, far below the pressed beams' contact stiffness: the plain Uzawa loop closes the
    overlap by a small fraction per update; the penalty increase reaches the tolerance in
    fewer updates, every solve Newton-quadratic, and returns to P* = 5 with the line loads
    kept: the final state is an equilibrium of the configured law (residual at the solve
    tolerance) with the same contact force."""
    runs = {}
    for growth in (1.0, 4.0):
        sysm, x = _pressed(2, 5.0, geometry=geometry, enforcement="augmented_lagrangian", al_penalty_growth=growth,
                           al_max_iter=60)
        log = []
        xs, loop = _solve(sysm, x, log)
        assert not loop.exhausted and sysm.max_penetration(xs) <= loop.tolerance
        assert sysm.penalty == 5.0
        F = sysm.evaluate(xs, np.zeros(sysm.n), 0.0, False)[0]
        idx, _ = sysm.constraints(0.0)
        F[np.asarray(idx, np.int64)] = 0.0
        assert np.linalg.norm(F) <= 1e-9
        for res in log:
            r = np.asarray(res.residuals)
            near = (r[:-1] < 1e-3) & (r[1:] > 1e-12)
            assert np.all(r[1:][near] <= 1e3 * r[:-1][near] ** 2), res.residuals
        runs[growth] = loop.updates, sysm.fibril_contact_forces(xs)[0, 2], max(loop.penalties, default=5.0)
    assert runs[4.0][0] < runs[1.0][0] and runs[4.0][2] > 5.0 and runs[1.0][2] == 5.0
    assert runs[4.0][1] == pytest.approx(runs[1.0][1], rel=1e-3)


class _Seesaw:
    """Two contact points on a rocking fibril, linear: a solve at multipliers lam gives the
    overlaps g = C (F - M lam), M = [[1, -m], [-m, 1]] (pushing one point out presses the
    other in), C = diag(a, b) their compliances. The plain update's map lam -> lam + P C (F -
    M lam) has the eigenvalues of I - P C M; with P = 1, m = 0.5, a = 1.6 and b = 1 they are
    -1 (the rocking mode: a two-cycle, whose two overlaps differ) and 0.4."""

    augmented = True

    def __init__(self, F=(1.0, 0.9), m=0.5, a=1.6, b=1.0):
        self.F, self.M = np.asarray(F, float), np.array([[1.0, -m], [-m, 1.0]])
        self.penalty = 1.0
        self.C = np.diag([a, b])
        self.lam = np.zeros(2)
        self.relaxations = []

    def solve(self, _x):
        return self.C @ (self.F - self.M @ self.lam)

    def max_penetration(self, g):
        return float(max(0.0, np.max(g)))

    def update_multipliers(self, g, relaxation=1.0):
        self.relaxations.append(relaxation)
        new = np.maximum(0.0, self.lam + self.penalty * g)
        self.lam = relaxation * new + (1.0 - relaxation) * self.lam

    def set_penalty(self, P, x=None):
        self.penalty = P


@pytest.mark.parametrize("growth", [1.0, 4.0])
def test_a_cycling_loop_converges_with_relaxed_updates(growth):
    """The plain updates of the seesaw cycle for ever (the overlap stays put); the loop's
    relaxed updates, switched on where the overlap stops falling at the largest P*, reach the
    fixed point lam = M^-1 F (with growth 4, P* may not grow: max_growth 1)."""
    plain = _Seesaw()
    _, loop = solve_with_multipliers(plain, plain.solve, None, 1e-6, 60, growth=growth, max_growth=1.0,
                                     relaxation=1.0)
    assert loop.exhausted and loop.relaxed_from is None
    pens = [p for _, p in loop.history]
    assert min(pens[-10:]) > 0.5 * max(pens[-10:]) > 1e-3      # a cycle, not a slow decrease

    relaxed = _Seesaw()
    _, loop = solve_with_multipliers(relaxed, relaxed.solve, None, 1e-6, 60, growth=growth, max_growth=1.0)
    assert not loop.exhausted and loop.history[-1][1] <= 1e-6
    assert loop.relaxed_from is not None
    assert relaxed.relaxations[:loop.relaxed_from] == [1.0] * loop.relaxed_from
    assert relaxed.relaxations[loop.relaxed_from] == 0.5
    assert set(relaxed.relaxations[loop.relaxed_from:]) <= {0.5, 0.25, 0.125}
    np.testing.assert_allclose(relaxed.lam, np.linalg.solve(relaxed.M, relaxed.F), rtol=1e-5)


def test_a_loop_that_converges_keeps_the_plain_updates(geometry="curve"):
    """Where the overlap keeps falling the updates stay plain (``relaxed_from`` None): the
    two crossed fibrils' loop."""
    sysm, x = _pressed(2, 50.0, enforcement="augmented_lagrangian", geometry=geometry, al_tolerance=1e-6)
    _, loop = _solve(sysm, x, [])
    assert not loop.exhausted and loop.updates >= 2 and loop.relaxed_from is None


def test_relaxed_update_is_the_weighted_mean_of_the_plain_one_and_the_old_multipliers():
    sysm, x = _pressed(2, 50.0, enforcement="augmented_lagrangian")
    xs, _, res = static_solve(sysm, x, np.zeros(sysm.n), 0.0, {"atol": 1e-11, "rtol": 1e-13, "max_iter": 40})
    assert res.converged
    sysm.update_multipliers(xs)
    old = np.array(sysm.term.multipliers, copy=True)
    assert old.max() > 0
    xs, _, res = static_solve(sysm, xs, np.zeros(sysm.n), 0.0, {"atol": 1e-11, "rtol": 1e-13, "max_iter": 40})
    sysm.update_multipliers(xs)
    plain = np.array(sysm.term.multipliers, copy=True)
    sysm.term.multipliers = old.copy()
    sysm.update_multipliers(xs, 0.3)
    np.testing.assert_allclose(sysm.term.multipliers, 0.3 * plain + 0.7 * old, rtol=1e-13, atol=1e-15)
    assert np.abs(plain - old).max() > 1e-3 * old.max()
    with pytest.raises(ValueError, match="relaxation"):
        sysm.update_multipliers(xs, 0.0)


class _Slow:
    """An overlap that falls by 1 % an update whatever P* is: every update asks for a raise."""

    augmented = True

    def __init__(self):
        self.penalty, self.g, self.set_to = 1.0, 1.0, []

    def solve(self, _x):
        self.g *= 0.99
        return self.g

    def max_penetration(self, g):
        return float(g)

    def update_multipliers(self, g, relaxation=1.0):
        pass

    def set_penalty(self, P, x=None):
        self.set_to.append(P)
        self.penalty = P


def test_the_last_penalty_raise_ends_at_the_cap():
    """P* grows by ``growth`` at each update that does not reduce the overlap enough, and the
    raise that would pass ``max_growth`` times the starting P* stops at it (4, then 10, not 4
    for ever); the loop's end puts the starting P* back."""
    s = _Slow()
    _, loop = solve_with_multipliers(s, s.solve, None, 1e-6, 5, growth=4.0, max_growth=10.0, relaxation=1.0)
    assert loop.exhausted
    assert loop.penalties == [1.0, 4.0, 10.0, 10.0, 10.0]   # the first update has no overlap before it
    assert s.set_to[-1] == 1.0 and s.penalty == 1.0
