"""Unit tests of the energy minimiser and the capped Newton (rve.solvers.minimize) on small
energies with known minimisers, wrapped in the ContactRelaxable protocol of
rve.solvers.system (no contact: an empty map; the map guard is still exercised)."""
import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.minimize import capped_newton, minimize_energy
from rve.solvers.newton import convergence_rates
from rve.solvers.system import ContactRelaxable


class _Layout:
    """Every node has 3 centroid dofs (the ``r`` part) and nothing else."""

    def __init__(self, n):
        self.n = n

    def dofs(self, name, nodes=None, comp=None):
        assert name == "r"
        return np.arange(self.n)


class _Map:
    n_pairs = 0
    e_plus = np.zeros(0, dtype=np.int64)
    e_minus = np.zeros(0, dtype=np.int64)


class _Params:
    def __init__(self, margin):
        self.margin = margin


class EnergySystem:
    """``F(x) = grad E(x)``, ``Fx = hess E(x)``, unit mass, optional fixed dofs. Records
    every state whose energy is evaluated and the guard distance at that moment."""

    def __init__(self, energy, grad, hess, n, fixed=(), margin=10.0):
        self._E, self._g, self._H = energy, grad, hess
        self.n = n
        self.mech = np.ones(n, dtype=bool)
        self.layout = _Layout(n)
        self.params = _Params(margin)
        self.map = _Map()
        self.fixed = np.asarray(fixed, dtype=np.int64)
        self.x_map = None
        self.rebuilds = 0
        self.energy_calls = []  # (x, max displacement since the last rebuild)
        self.jacobian_states = []

    # DynamicSystem
    def mass(self):
        return sp.identity(self.n, format="csr")

    def evaluate(self, x, w, t, jacobian=True):
        F = self._g(x)
        if not jacobian:
            return F, None, None
        self.jacobian_states.append(np.array(x))
        return F, sp.csr_matrix(self._H(x)), sp.csr_matrix((self.n, self.n))

    def constraints(self, t):
        return self.fixed, np.zeros(self.fixed.size)

    def admissible(self, x):
        return True

    # ContactRelaxable
    def rebuild(self, x):
        self.x_map = np.array(x)
        self.rebuilds += 1

    def max_displacement_since_rebuild(self, x):
        if self.x_map is None:
            return np.inf
        return float(np.linalg.norm((np.asarray(x) - self.x_map).reshape(-1, 3), axis=1).max())

    def energy(self, x):
        self.energy_calls.append((np.array(x), self.max_displacement_since_rebuild(x)))
        return float(self._E(x))

    def set_onset(self, fraction):
        pass

    def active_pairs(self, x):
        return np.zeros(0, dtype=np.int64)

    def contact_state(self, x):
        return {"pairs": 0, "active_pairs": 0, "max_overlap_over_R": 0.0}


# ----------------------------------------------------------------------------- energies
C = np.array([0.3, -0.2, 0.5, 1.0, 0.1, -0.4])


def quartic(n=6):
    """Convex separable quartic, minimiser C: E = sum a (x-c)^2/2 + b (x-c)^4/4."""
    a = np.linspace(1.0, 3.0, n)
    b = np.linspace(2.0, 0.5, n)
    c = C[:n]
    return EnergySystem(lambda x: float(np.sum(a * (x - c) ** 2 / 2 + b * (x - c) ** 4 / 4)),
                        lambda x: a * (x - c) + b * (x - c) ** 3,
                        lambda x: np.diag(a + 3 * b * (x - c) ** 2), n), c


def double_well(n=6, k=0.05):
    """Non-convex: E = sum (x^2 - 1)^2 / 4 + k/2 sum (x_i - x_{i+1})^2. Its Hessian is
    indefinite near 0; the minimiser reached from x > 0 is x = 1 (every dof)."""
    D = np.diff(np.eye(n), axis=0)
    L = D.T @ D
    return EnergySystem(lambda x: float(np.sum((x * x - 1) ** 2) / 4 + 0.5 * k * x @ L @ x),
                        lambda x: x * (x * x - 1) + k * L @ x,
                        lambda x: np.diag(3 * x * x - 1) + k * L, n)


def rosenbrock():
    """Rosenbrock in (x0, x1) plus a quadratic well in x2: minimiser (1, 1, 0.5)."""
    def E(x):
        return float((1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2 + (x[2] - 0.5) ** 2)

    def g(x):
        return np.array([-2 * (1 - x[0]) - 400 * x[0] * (x[1] - x[0] ** 2), 200 * (x[1] - x[0] ** 2),
                         2 * (x[2] - 0.5)])

    def H(x):
        return np.array([[2 - 400 * x[1] + 1200 * x[0] ** 2, -400 * x[0], 0.0], [-400 * x[0], 200.0, 0.0],
                         [0.0, 0.0, 2.0]])

    return EnergySystem(E, g, H, 3)


def _quadratic_tail(res, floor=1e-13):
    """The last iterations converge quadratically: some observed rate >= 1.8 among the
    steps whose residual is above round-off."""
    r = [v for v in res if v > floor]
    rates = [q for q in convergence_rates(r)[-3:] if np.isfinite(q)]
    return rates and max(rates) >= 1.8


# ----------------------------------------------------------------------------- minimize_energy
def test_convex_quartic_converges_quadratically():
    sys, c = quartic()
    assert isinstance(sys, ContactRelaxable)
    x, w, res = minimize_energy(sys, np.zeros(6), atol=1e-13)
    assert res.converged and res.reason == ""
    np.testing.assert_allclose(x, c, atol=1e-12)
    assert np.all(w == 0.0)
    assert res.negative_pivots == 0  # a minimum
    assert all(b < a for a, b in zip(res.energies, res.energies[1:]))  # the energy is the merit
    assert res.sigmas[-1] == 0.0  # plain Newton at the end
    assert _quadratic_tail(res.residuals), res.residuals


def test_rosenbrock():
    sys = rosenbrock()
    x, _, res = minimize_energy(sys, np.array([-1.2, 1.0, 0.0]), atol=1e-12, max_iter=200)
    assert res.converged, res.reason
    np.testing.assert_allclose(x, [1.0, 1.0, 0.5], atol=1e-8)
    assert _quadratic_tail(res.residuals), res.residuals


def test_indefinite_first_tangent_gives_a_shifted_descent_step():
    """From x = 0.1 the Hessian 3x^2 - 1 + kL is negative definite: plain Newton would
    climb to the maximum at 0. The inertia check raises sigma until K + sigma M is
    positive definite (several factorisations before the first step), every accepted step
    lowers the energy, and the minimiser ends in the minimum x = 1, a local minimum (0
    negative pivots of the final unshifted tangent)."""
    sys = double_well()
    x0 = np.full(6, 0.1)
    assert np.linalg.eigvalsh(sys._H(x0)).max() < 0
    x, _, res = minimize_energy(sys, x0, atol=1e-12, sigma0=0.0)
    assert res.converged, res.reason
    np.testing.assert_allclose(x, 1.0, atol=1e-10)
    assert res.sigmas[0] > 0.0  # the first step was shifted
    assert res.factorizations > res.iterations
    assert res.negative_pivots == 0
    assert all(b < a for a, b in zip(res.energies, res.energies[1:]))
    assert _quadratic_tail(res.residuals), res.residuals
    # plain Newton from the same point goes to the saddle / maximum at 0 instead
    u = x0.copy()
    for _ in range(30):
        u = u - np.linalg.solve(sys._H(u), sys._g(u))
    assert np.abs(u).max() < 1e-8


def test_step_cap_and_map_guard():
    """Centroid motion per step <= step_cap; the map is rebuilt before a trial would carry
    a centroid more than half the margin from where the map was built, so no energy is
    ever evaluated beyond that guard."""
    margin = 0.4
    sys, c = quartic()
    sys.params.margin = margin
    cap = 0.05
    x0 = np.zeros(6)
    x, _, res = minimize_energy(sys, x0, atol=1e-12, step_cap=cap)
    assert res.converged, res.reason
    np.testing.assert_allclose(x, c, atol=1e-10)
    states = [x0] + [s for s in sys.jacobian_states]
    moves = [np.abs(b - a).max() * np.sqrt(3.0) for a, b in zip(states, states[1:])]
    assert max(moves) <= cap * (1 + 1e-12)
    assert min(res.steps) < 1.0 and res.steps[-1] == 1.0  # capped far away, full steps near
    assert np.abs(c - x0).max() * np.sqrt(3) / cap < res.iterations
    assert res.rebuilds > 0
    assert max(d for _, d in sys.energy_calls) <= 0.5 * margin
    with pytest.raises(ValueError, match="exceeds half the search margin"):
        minimize_energy(sys, x0, step_cap=0.3)


def test_fixed_dofs_stay_put():
    sys, c = quartic()
    sys.fixed = np.array([1, 4])
    x0 = np.full(6, 0.25)
    x, _, res = minimize_energy(sys, x0, atol=1e-12)
    assert res.converged
    free = np.setdiff1d(np.arange(6), sys.fixed)
    np.testing.assert_allclose(x[free], c[free], atol=1e-12)
    assert np.all(x[sys.fixed] == 0.25)


def test_reports_non_convergence():
    sys = rosenbrock()
    x0 = np.array([-1.2, 1.0, 0.0])
    x, _, res = minimize_energy(sys, x0, max_iter=2)
    assert not res.converged and res.iterations == 2
    assert res.reason.startswith("no convergence in 2 iterations")
    assert sys.energy(x) < sys.energy(x0)
    _, _, res = minimize_energy(rosenbrock(), x0, time_budget=0.0)
    assert not res.converged and res.reason.startswith("time budget")


# ----------------------------------------------------------------------------- capped_newton
def test_capped_newton_converges_quadratically_with_capped_steps():
    sys, c = quartic()
    cap = 0.05
    x0 = np.zeros(6)
    x, w, res = capped_newton(sys, x0, 0.0, atol=1e-13, step_cap=cap)
    assert res.converged, res.reason
    np.testing.assert_allclose(x, c, atol=1e-12)
    states = [x0] + sys.jacobian_states
    moves = [np.abs(b - a).max() * np.sqrt(3.0) for a, b in zip(states, states[1:])]
    assert max(moves) <= cap * (1 + 1e-12)
    assert res.iterations > 5  # the cap bound the early steps
    assert all(b <= a for a, b in zip(res.residuals, res.residuals[1:]))
    assert _quadratic_tail(res.residuals), res.residuals


def test_capped_newton_reports_non_convergence():
    sys, _ = quartic()
    _, _, res = capped_newton(sys, np.zeros(6), 0.0, max_iter=3, step_cap=0.05)
    assert not res.converged and res.iterations == 3
    assert res.reason.startswith("no convergence in 3 iterations")


def test_minimiser_freezes_the_old_objects_only_while_it_runs():
    """``_long_lived_objects_frozen``: the garbage collector skips the objects alive before the
    loop while it runs and is back as it was afterwards; a caller's own freeze is left alone."""
    import gc

    from rve.solvers import minimize

    before = gc.get_freeze_count()
    with minimize._long_lived_objects_frozen():
        inside = gc.get_freeze_count()
    assert before == 0 and inside > 1000 and gc.get_freeze_count() == 0
    gc.freeze()
    try:
        frozen = gc.get_freeze_count()
        with minimize._long_lived_objects_frozen():
            assert gc.get_freeze_count() == frozen
        assert gc.get_freeze_count() == frozen
    finally:
        gc.unfreeze()
