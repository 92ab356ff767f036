"""SDIRK tableaus, observed convergence orders, DAE/mechanical paths and step control."""
import math

import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.dirk import (
    StepControl,
    BACKWARD_EULER, SDIRK2, SDIRK3, SDIRK3_ALPHA, IntegrationFailure, StepFailure,
    consistent_initialization, dirk_step, integrate, order_conditions, sdirk, stability_function,
)
from rve.solvers.system import DynamicSystem

TIGHT = dict(atol=1e-13, rtol=1e-14, max_iter=20)


# ----------------------------------------------------------------------------- tableaus
@pytest.mark.parametrize("s", [1, 2, 3])
def test_order_conditions_hold_up_to_s_and_fail_at_s_plus_1(s):
    tab = sdirk(s)
    assert tab.stages == s and tab.order == s
    conds = order_conditions(tab, s)
    assert max(abs(v) for v in conds.values()) < 1e-14, conds
    higher = {k: v for k, v in order_conditions(tab, s + 1).items() if k.startswith(f"p{s + 1}")}
    assert max(abs(v) for v in higher.values()) > 1e-3  # the order is exactly s
    # singly diagonal, lower triangular, c = A 1, stiffly accurate, c_s = 1
    assert np.allclose(np.diag(tab.A), tab.A[0, 0])
    assert np.all(np.triu(tab.A, 1) == 0)
    np.testing.assert_allclose(tab.A.sum(axis=1), tab.c, atol=1e-15)
    np.testing.assert_array_equal(tab.A[-1], tab.b)
    assert tab.c[-1] == 1.0 and tab.stiffly_accurate


@pytest.mark.parametrize("s", [1, 2, 3])
def test_l_stability(s):
    tab = sdirk(s)
    assert abs(stability_function(tab, -1e10)) < 1e-8            # R(-inf) = 0
    for y in np.logspace(-3, 4, 60):                               # |R(iy)| <= 1 (A-stable)
        assert abs(stability_function(tab, 1j * y)) <= 1 + 1e-12
    for z in -np.logspace(-3, 6, 60):
        assert abs(stability_function(tab, z)) < 1.0


def test_tableau_constants():
    a = SDIRK3_ALPHA
    assert abs(a**3 - 3 * a**2 + 1.5 * a - 1 / 6) < 1e-15
    assert 1 / 6 < a < 1 / 2
    g = 1 - math.sqrt(2) / 2
    np.testing.assert_allclose(SDIRK2.A, [[g, 0], [math.sqrt(2) / 2, g]], atol=1e-16)
    # Appendix C prints the 3-stage last row as "b2 b2 α": the correct row is b1 b2 α
    b1 = -(6 * a * a - 16 * a + 1) / 4
    b2 = (6 * a * a - 20 * a + 5) / 4
    np.testing.assert_allclose(SDIRK3.A[2], [b1, b2, a], atol=1e-16)
    assert b1 != b2
    assert BACKWARD_EULER.A[0, 0] == 1.0


# ----------------------------------------------------------------------------- test systems
def fd_check(system, x, w, t, eps=1e-7):
    """Finite-difference check of Fx (mech columns) and Fw."""
    F, Fx, Fw = system.evaluate(x, w, t)
    Fx, Fw = Fx.toarray(), Fw.toarray()
    for k in range(system.n):
        e = np.zeros(system.n)
        e[k] = eps
        dw = (system.evaluate(x, w + e, t, False)[0] - system.evaluate(x, w - e, t, False)[0]) / (2 * eps)
        np.testing.assert_allclose(Fw[:, k], dw, atol=1e-6)
        if system.mech[k]:
            dx = (system.evaluate(x + e, w, t, False)[0] - system.evaluate(x - e, w, t, False)[0]) / (2 * eps)
            np.testing.assert_allclose(Fx[:, k], dx, atol=1e-6)


class ProtheroRobinson:
    """y' = λ(y − g) + g', g = sin t  as  M w' + F = 0 with one non-mech dof."""

    n = 1
    mech = np.array([False])

    def __init__(self, lam=-5.0):
        self.lam = lam

    def mass(self):
        return sp.identity(1, format="csr")

    def evaluate(self, x, w, t, jacobian=True):
        F = np.array([-self.lam * (w[0] - math.sin(t)) - math.cos(t)])
        if not jacobian:
            return F, None, None
        return F, sp.csr_matrix((1, 1)), sp.csr_matrix([[-self.lam]])

    def constraints(self, t):
        return np.array([], dtype=int), np.array([])

    def admissible(self, x):
        return True


# manufactured solution of the mechanical + thermal + algebraic system
def X(t):
    return np.array([0.5 * np.sin(1.3 * t), 0.3 * np.cos(0.7 * t) + 0.1 * t, 0.2 * np.sin(2 * t)])


def dX(t):
    return np.array([0.65 * np.cos(1.3 * t), -0.21 * np.sin(0.7 * t) + 0.1, 0.4 * np.cos(2 * t)])


def ddX(t):
    return np.array([-0.845 * np.sin(1.3 * t), -0.147 * np.cos(0.7 * t), -0.8 * np.sin(2 * t)])


def Tex(t):
    return 1 + 0.5 * np.sin(t)


def dTex(t):
    return 0.5 * np.cos(t)


def Vex(t):
    return np.exp(-t / 2)


class Manufactured:
    """dofs 0,1: free masses (non-diagonal mass), 2: mass with prescribed velocity,
    3: temperature (mass cT), 4: massless potential (index-1 algebraic). Nonlinear and
    fully coupled; forcing chosen so that X, T, V above are the exact solution."""

    n = 5
    mech = np.array([True, True, True, False, False])
    c, k, k3, beta, kappa, eta, cT = 0.5, 4.0, 2.0, 0.7, 2.0, 0.3, 3.0

    def mass(self):
        M = np.zeros((5, 5))
        M[:2, :2] = [[2, 1], [1, 2]]
        M[2, 2] = 1.0
        M[3, 3] = self.cT
        return sp.csr_matrix(M)

    def forcing(self, t):
        c, k, k3, b, kap, eta, cT = self.c, self.k, self.k3, self.beta, self.kappa, self.eta, self.cT
        x, v, a = X(t), dX(t), ddX(t)
        T, V = Tex(t), Vex(t)
        f0 = 2 * a[0] + a[1] + c * v[0] + k * (x[0] - x[2]) + k3 * x[0] ** 3 + b * V * x[0]
        f1 = a[0] + 2 * a[1] + c * v[1] + k * (x[1] - x[0]) + k * x[1] + 0.1 * T * x[1]
        fT = cT * dTex(t) + kap * T - eta * (v[0] ** 2 + v[1] ** 2) - 0.2 * V**2
        q = (1 + x[0] ** 2 + 0.1 * T) * V
        return f0, f1, fT, q

    def evaluate(self, x, w, t, jacobian=True):
        c, k, k3, b, kap, eta = self.c, self.k, self.k3, self.beta, self.kappa, self.eta
        f0, f1, fT, q = self.forcing(t)
        T, V = w[3], w[4]
        F = np.array([
            c * w[0] + k * (x[0] - x[2]) + k3 * x[0] ** 3 + b * V * x[0] - f0,
            c * w[1] + k * (x[1] - x[0]) + k * x[1] + 0.1 * T * x[1] - f1,
            c * w[2],
            kap * T - eta * (w[0] ** 2 + w[1] ** 2) - 0.2 * V**2 - fT,
            (1 + x[0] ** 2 + 0.1 * T) * V - q,
        ])
        if not jacobian:
            return F, None, None
        Fx = np.zeros((5, 5))
        Fx[0, 0] = k + 3 * k3 * x[0] ** 2 + b * V
        Fx[0, 2] = -k
        Fx[1, 0] = -k
        Fx[1, 1] = 2 * k + 0.1 * T
        Fx[4, 0] = 2 * x[0] * V
        Fw = np.zeros((5, 5))
        Fw[0, 0] = c
        Fw[0, 4] = b * x[0]
        Fw[1, 1] = c
        Fw[1, 3] = 0.1 * x[1]
        Fw[2, 2] = c
        Fw[3, 0] = -2 * eta * w[0]
        Fw[3, 1] = -2 * eta * w[1]
        Fw[3, 3] = kap
        Fw[3, 4] = -0.4 * V
        Fw[4, 3] = 0.1 * V
        Fw[4, 4] = 1 + x[0] ** 2 + 0.1 * T
        return F, sp.csr_matrix(Fx), sp.csr_matrix(Fw)

    def constraints(self, t):
        return np.array([2]), np.array([dX(t)[2]])

    def admissible(self, x):
        return True


def manufactured_initial():
    x0 = np.zeros(5)
    x0[:3] = X(0.0)
    w0 = np.zeros(5)
    w0[:3] = dX(0.0)
    w0[3] = Tex(0.0)
    w0[4] = 0.0  # deliberately inconsistent: integrate() must solve for V(0)
    return x0, w0


def test_test_systems_satisfy_protocol_and_have_exact_jacobians():
    sysm = Manufactured()
    assert isinstance(sysm, DynamicSystem) and isinstance(ProtheroRobinson(), DynamicSystem)
    rng = np.random.default_rng(0)
    fd_check(sysm, rng.normal(size=5) * sysm.mech, rng.normal(size=5), 0.37)
    # the exact solution satisfies M w' + F = 0
    t = 0.81
    x = np.r_[X(t), 0, 0]
    w = np.r_[dX(t), Tex(t), Vex(t)]
    wdot = np.r_[ddX(t), dTex(t), 0.0]
    r = sysm.mass() @ wdot + sysm.evaluate(x, w, t, False)[0]
    np.testing.assert_allclose(r[[0, 1, 3, 4]], 0, atol=1e-13)


def observed_order(errs, ns):
    h = 1.0 / np.asarray(ns, float)
    return np.polyfit(np.log(h), np.log(errs), 1)[0]


PR_STEPS = {1: [20, 40, 80], 2: [10, 20, 40], 3: [20, 40, 80]}


@pytest.mark.parametrize("s", [1, 2, 3])
def test_order_prothero_robinson(s):
    sysm = ProtheroRobinson(lam=-5.0)
    t_end = 1.0
    y0 = np.array([math.sin(0.0) + 0.0])
    errs = []
    for n in PR_STEPS[s]:
        out = integrate(sysm, np.zeros(1), y0, 0.0, t_end, n, stages=s, newton_opts=TIGHT)
        assert out.t == t_end and out.steps == n and out.rejected == 0
        errs.append(abs(out.w[0] - math.sin(t_end)))
    p = observed_order(errs, PR_STEPS[s])
    assert abs(p - s) < 0.3, (s, p, errs)


MF_STEPS = {1: [20, 40, 80], 2: [10, 20, 40], 3: [8, 16, 32]}


@pytest.mark.parametrize("s", [1, 2, 3])
def test_order_mechanical_dae(s):
    """Damped nonlinear 2-mass oscillator with a consistent (non-diagonal) mass matrix, a
    velocity-driven mass, a temperature and a massless potential: order s in every field."""
    sysm = Manufactured()
    t_end = 1.0
    errs = {"x": [], "w": [], "x_driven": [], "T": [], "V": []}
    for n in MF_STEPS[s]:
        x0, w0 = manufactured_initial()
        out = integrate(sysm, x0, w0, 0.0, t_end, n, stages=s, newton_opts=TIGHT)
        assert out.t == t_end and out.steps == n
        assert out.newton_iterations >= n * s and out.linear_solves >= out.newton_iterations
        np.testing.assert_array_equal(out.x[3:], 0.0)                  # placeholders stay 0
        assert out.w[2] == pytest.approx(dX(t_end)[2], abs=1e-14)      # prescribed velocity
        errs["x"].append(np.abs(out.x[:2] - X(t_end)[:2]).max())
        errs["w"].append(np.abs(out.w[:2] - dX(t_end)[:2]).max())
        errs["x_driven"].append(abs(out.x[2] - X(t_end)[2]))
        errs["T"].append(abs(out.w[3] - Tex(t_end)))
        errs["V"].append(abs(out.w[4] - Vex(t_end)))
    for field, e in errs.items():
        p = observed_order(e, MF_STEPS[s])
        assert abs(p - s) < 0.3, (s, field, p, e)


def test_consistent_initialization_solves_the_potential():
    sysm = Manufactured()
    x0, w0 = manufactured_initial()
    w, res = consistent_initialization(sysm, x0, w0, 0.0, TIGHT)
    assert res.converged
    assert w[4] == pytest.approx(Vex(0.0), abs=1e-13)
    np.testing.assert_array_equal(w[:4], w0[:4])
    # nothing to solve for a system without massless dofs
    w2, res2 = consistent_initialization(ProtheroRobinson(), np.zeros(1), np.ones(1), 0.0)
    assert res2 is None and w2[0] == 1.0


def test_dirk_step_matches_integrate_single_step():
    sysm = Manufactured()
    x0, w0 = manufactured_initial()
    w0, _ = consistent_initialization(sysm, x0, w0, 0.0, TIGHT)
    x1, w1, info = dirk_step(sysm, 3, x0, w0, 0.0, 0.1, TIGHT)
    out = integrate(sysm, x0, w0, 0.0, 0.1, 1, stages=3, newton_opts=TIGHT)
    np.testing.assert_allclose(x1, out.x, atol=1e-14)
    np.testing.assert_allclose(w1, out.w, atol=1e-14)
    assert len(info.stage_iterations) == 3 and info.newton_iterations == sum(info.stage_iterations)


# ----------------------------------------------------------------------------- step control
class Rigged:
    """y' = λ(y − t) + 1 (exact y = t). For stage times in (t_on, t_off] the residual is NaN
    whenever |w − t| > δ: a stage whose Newton starts from the previous step value fails
    iff the step h exceeds δ (backward Euler), i.e. Newton 'fails for large h'. The runs use
    ``predictor_degree=0`` (start from the previous value): the extrapolating predictor
    would hit the linear exact solution and never fail."""

    n = 1
    mech = np.array([False])

    def __init__(self, delta=0.03, t_on=0.5, t_off=0.7, lam=-2.0):
        self.delta, self.t_on, self.t_off, self.lam = delta, t_on, t_off, lam

    def mass(self):
        return sp.identity(1, format="csr")

    def evaluate(self, x, w, t, jacobian=True):
        F = np.array([-self.lam * (w[0] - t) - 1.0])
        if self.t_on < t <= self.t_off + 1e-12 and abs(w[0] - t) > self.delta:
            F[:] = np.nan
        return F, (sp.csr_matrix((1, 1)) if jacobian else None), (sp.csr_matrix([[-self.lam]]) if jacobian else None)

    def constraints(self, t):
        return np.array([], dtype=int), np.array([])

    def admissible(self, x):
        return True


def test_step_is_cut_and_run_finishes_exactly_at_t_end():
    calls = []
    out = integrate(Rigged(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, progress=True, predictor_degree=0,
                    on_step=lambda t, x, w, info: calls.append((t, w[0], info.h)),
                    control=StepControl(max_cuts=3))
    assert out.t == 1.0 and calls[-1][0] == 1.0
    assert out.rejected >= 2 and out.steps > 10
    assert out.h_min == pytest.approx(0.025)
    hs = [h for _, h, _ in out.history]
    assert hs[-1] == pytest.approx(0.1)               # grew back to the nominal step
    ts = [c[0] for c in calls]
    assert all(b > a for a, b in zip(ts, ts[1:]))
    assert len(calls) == out.steps
    np.testing.assert_allclose([c[1] for c in calls], ts, atol=1e-12)   # y = t exactly
    # each step lands on the nominal grid points too
    for tk in np.arange(1, 11) * 0.1:
        assert np.min(np.abs(np.array(ts) - tk)) < 1e-12


def test_fixed_step_raises_immediately():
    with pytest.raises(IntegrationFailure) as ei:
        integrate(Rigged(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, predictor_degree=0,
                  control=StepControl(fixed_step=True))
    e = ei.value
    assert e.t == pytest.approx(0.5) and e.h == pytest.approx(0.1)
    assert e.result.rejected == 1 and e.result.steps == 5
    assert isinstance(e.step_failure, StepFailure)


def test_integration_failure_after_max_cuts_reports_time_step_and_state():
    with pytest.raises(IntegrationFailure) as ei:
        integrate(Rigged(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, stages=1, predictor_degree=0,
                  control=StepControl(max_cuts=1))
    e = ei.value
    msg = str(e)
    assert "t = 0.5" in msg and "h = 0.05" in msg and "residuals [" in msg and "nan" in msg
    x, w, t = e.last_good_state
    assert t == pytest.approx(0.5) and w[0] == pytest.approx(0.5, abs=1e-12)
    assert e.step_failure.stage == 1


def test_step_failure_on_inadmissible_state_and_iteration_limit():
    class NoGo(Manufactured):
        def admissible(self, x):
            return False

    sysm = NoGo()
    x0, w0 = manufactured_initial()
    with pytest.raises(StepFailure) as ei:
        dirk_step(sysm, 2, x0, w0, 0.0, 0.1)
    assert "admissible" in ei.value.reason and ei.value.stage == 1 and ei.value.h == 0.1
    with pytest.raises(StepFailure) as ei:
        dirk_step(Manufactured(), 2, x0, w0, 0.0, 0.1, dict(max_iter=1, atol=1e-14, rtol=1e-16))
    assert "no convergence in 1 iterations" in ei.value.reason
    assert "t = 0" in str(ei.value) and "h = 0.1" in str(ei.value)


@pytest.mark.parametrize("s", [2, 3])
def test_stage_newton_converges_quadratically(s):
    """The stage Jacobian M + h a_ii Fw + (h a_ii)^2 Fx is exact: quadratic convergence."""
    sysm = Manufactured()
    x0, w0 = manufactured_initial()
    w0, _ = consistent_initialization(sysm, x0, w0, 0.0, TIGHT)
    w0[:2] += 3.0          # start each stage far from its solution, with a large step
    _, _, info = dirk_step(sysm, s, x0, w0, 0.0, 1.0, dict(atol=1e-14, rtol=1e-16))
    from rve.solvers.newton import convergence_rates
    assert len(info.stage_residuals) == s
    for res in info.stage_residuals:
        rates = [q for q, r in zip(convergence_rates(res), res[2:]) if r > 1e-10]
        assert len(res) <= 7 and rates and max(rates) > 1.8, (res, rates)


# ----------------------------------------------------------------------------- predictor, lazy Jacobian
def test_extrapolate_is_exact_for_polynomials_of_its_degree():
    from rve.solvers.dirk import extrapolate

    ts = [0.0, 0.3, 0.7]
    p = lambda t: np.array([1.0 - 2.0 * t + 3.0 * t * t, 5.0 * t])  # noqa: E731
    np.testing.assert_allclose(extrapolate([(t, p(t)) for t in ts], 1.4), p(1.4), rtol=1e-13)
    # degree 1 through the last two points misses the curvature by 3 (1.4-0.3)(1.4-0.7)
    lin = extrapolate([(t, p(t)) for t in ts[1:]], 1.4)
    assert lin[0] == pytest.approx(p(1.4)[0] - 3.0 * 1.1 * 0.7, rel=1e-13)


@pytest.mark.parametrize("s", [1, 2, 3])
def test_stage_predictor_saves_newton_iterations_without_changing_the_solution(s):
    """Extrapolating the stage values in time (degree 2) instead of starting from the previous
    stage value: the same solution to the Newton tolerance, fewer iterations."""
    sysm = Manufactured()
    runs = {}
    for deg in (0, 2):
        x0, w0 = manufactured_initial()
        runs[deg] = integrate(sysm, x0, w0, 0.0, 1.0, 40, stages=s, newton_opts=dict(atol=1e-10, rtol=1e-14),
                              predictor_degree=deg)
    np.testing.assert_allclose(runs[2].w, runs[0].w, atol=1e-9)
    np.testing.assert_allclose(runs[2].x, runs[0].x, atol=1e-9)
    assert runs[2].newton_iterations < 0.8 * runs[0].newton_iterations, (
        runs[2].newton_iterations, runs[0].newton_iterations)


def test_lazy_jacobian_skips_assembly_at_converged_points_only():
    """newton(residual=...) assembles the Jacobian only where another iteration needs it:
    same iterates, one Jacobian assembly fewer per solve (the converged point)."""
    from rve.solvers.newton import newton

    calls = {"full": 0, "residual": 0}

    def r(u):
        return np.array([u[0] ** 3 + u[0] - 2.0, u[1] - np.sin(u[0])])

    def fun(u):
        calls["full"] += 1
        J = sp.csr_matrix(np.array([[3 * u[0] ** 2 + 1, 0.0], [-np.cos(u[0]), 1.0]]))
        return r(u), J

    def resid(u):
        calls["residual"] += 1
        return r(u)

    eager = newton(fun, np.array([2.0, 0.0]), atol=1e-13)
    n_eager = calls["full"]
    calls.update(full=0, residual=0)
    lazy = newton(fun, np.array([2.0, 0.0]), atol=1e-13, residual=resid)
    assert eager.converged and lazy.converged
    np.testing.assert_array_equal(lazy.u, eager.u)
    assert lazy.residuals == eager.residuals
    assert calls["full"] == n_eager - 1 == eager.iterations
    assert calls["residual"] == eager.iterations


def test_linear_stages_equal_the_newton_stages():
    """DirkStepper(linear_stages=...) on M w' + L_i w - q(t) = 0 (no mechanical dofs, one
    constrained dof): the stage solves by the linear-stage object give the step that the
    stage Newton gives on the same system, to round-off, for s = 1, 2, 3."""
    import scipy.sparse as sp_

    from rve.solvers.dirk import DirkStepper, sdirk

    rng = np.random.default_rng(3)
    n = 6
    B = rng.normal(size=(n, n))
    L = sp_.csr_matrix(B @ B.T + n * np.eye(n))
    M = sp_.csr_matrix(np.diag(rng.uniform(1.0, 2.0, n)))
    fixed, value = np.array([0]), np.array([0.5])

    def q(t):
        return np.sin(np.arange(1, n + 1) * t)

    class Linear:
        n_ = n
        mech = np.zeros(n, bool)

        def __init__(self):
            self.n = n

        def mass(self):
            return M

        def constraints(self, t):
            return fixed, value

        def admissible(self, x):
            return True

        def evaluate(self, x, w, t, jacobian=True):
            F = L @ w - q(t)
            return (F, None, None) if not jacobian else (F, sp_.csr_matrix((n, n)), L)

    class Stages:
        def source(self, i, t):
            return q(t)

        def apply(self, i, w, t):
            return L @ w

        def solve(self, i, haii, rhs, t):
            A = (M + haii * L).toarray()
            w = np.empty(n)
            w[fixed] = value
            free = np.arange(1, n)
            w[free] = np.linalg.solve(A[np.ix_(free, free)], rhs[free] - A[np.ix_(free, fixed)] @ value)
            return w

    w0 = rng.normal(size=n)
    w0[fixed] = value
    for s in (1, 2, 3):
        tab = sdirk(s)
        ref = DirkStepper(Linear(), tab, {"atol": 0.0, "rtol": 1e-14, "max_iter": 10}).step(w0, w0, 0.2, 0.05)
        lin = DirkStepper(Linear(), tab, linear_stages=Stages()).step(w0, w0, 0.2, 0.05)
        assert np.abs(lin[1] - ref[1]).max() <= 1e-12 * np.abs(ref[1]).max()
        assert len(lin[2].stage_states) == s and lin[1][0] == value[0]
        assert np.abs(lin[1] - w0).max() > 1e-3   # the step moved
