"""Static Newton and pseudo-transient continuation on a small coupled nonlinear system."""
import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.static import pseudo_transient_solve, static_solve

K1, K3, ALPHA, KAPPA, Q, C = 3.0, 5.0, 0.8, 2.0, 0.25, 0.7
XSTAR = np.array([0.0, 1.2, 2.7])   # equilibrium positions for the loads below (x0 fixed)
V5 = 1.0                            # prescribed potential


def spring(e):
    return K1 * e + K3 * e**3


def dspring(e):
    return K1 + 3 * K3 * e**2


def exact():
    e01, e12 = XSTAR[1] - XSTAR[0] - 1, XSTAR[2] - XSTAR[1] - 1
    G = 1 / (XSTAR[2] - XSTAR[1])
    V4 = G * V5 / (G + 1)                              # voltage divider with a unit pull-down
    P1 = spring(e01) - spring(e12)
    P2 = spring(e12) + ALPHA * V4**2
    T = (G * (V4 - V5) ** 2 + Q) / KAPPA               # Joule heat + source, conduction to 0
    return P1, P2, T, V4


class SpringChain:
    """dofs 0,1,2: positions of a chain of cubic springs (rest length 1, dof 0 pinned),
    3: temperature, 4: potential of the right node (massless), 5: prescribed potential.
    A force α V4² acts on node 2, the conductance between nodes 1 and 2 is 1/(x2 − x1)."""

    n = 6
    mech = np.array([True, True, True, False, False, False])

    def __init__(self):
        self.P1, self.P2, _, _ = exact()

    def mass(self):
        return sp.diags([1.0, 1.0, 1.0, 2.0, 0.0, 0.0]).tocsr()

    def evaluate(self, x, w, t, jacobian=True):
        e01, e12 = x[1] - x[0] - 1, x[2] - x[1] - 1
        L = x[2] - x[1]
        G = 1 / L
        T, V4, V5 = w[3], w[4], w[5]
        F = np.array([
            C * w[0] - spring(e01),
            C * w[1] + spring(e01) - spring(e12) - self.P1,
            C * w[2] + spring(e12) + ALPHA * V4**2 - self.P2,
            KAPPA * T - G * (V4 - V5) ** 2 - Q,
            G * (V4 - V5) + V4,
            V5,
        ])
        if not jacobian:
            return F, None, None
        Fx = np.zeros((6, 6))
        d01, d12 = dspring(e01), dspring(e12)
        Fx[0, :2] = [d01, -d01]
        Fx[1, :3] = [-d01, d01 + d12, -d12]
        Fx[2, 1:3] = [-d12, d12]
        dG = np.array([0, 1 / L**2, -1 / L**2])  # dG/dx
        Fx[3, :3] = -dG * (V4 - V5) ** 2
        Fx[4, :3] = dG * (V4 - V5)
        Fw = np.diag([C, C, C, KAPPA, G + 1, 1.0])
        Fw[2, 4] = 2 * ALPHA * V4
        Fw[3, 4] = -2 * G * (V4 - V5)
        Fw[3, 5] = 2 * G * (V4 - V5)
        Fw[4, 5] = -G
        return F, sp.csr_matrix(Fx), sp.csr_matrix(Fw)

    def constraints(self, t):
        return np.array([0, 5]), np.array([0.0, V5])

    def admissible(self, x):
        return bool(x[2] - x[1] > 0 and x[1] - x[0] > 0)


def start():
    x = np.array([0.0, 1.0, 2.0, 0.0, 0.0, 0.0])
    w = np.array([0.3, -0.2, 0.5, 0.0, 0.0, 0.0])   # velocities are zeroed by the solver
    return x, w


def test_jacobian_matches_finite_differences():
    s = SpringChain()
    rng = np.random.default_rng(1)
    x = np.r_[XSTAR + 0.1 * rng.normal(size=3), 0, 0, 0]
    w = rng.normal(size=6)
    _, Fx, Fw = s.evaluate(x, w, 0.0)
    eps = 1e-7
    for k in range(6):
        e = np.zeros(6)
        e[k] = eps
        np.testing.assert_allclose(
            Fw.toarray()[:, k], (s.evaluate(x, w + e, 0, False)[0] - s.evaluate(x, w - e, 0, False)[0]) / (2 * eps),
            atol=1e-6)
        if k < 3:
            np.testing.assert_allclose(
                Fx.toarray()[:, k],
                (s.evaluate(x + e, w, 0, False)[0] - s.evaluate(x - e, w, 0, False)[0]) / (2 * eps), atol=1e-6)


def test_static_solve_reaches_known_equilibrium_quadratically():
    _, _, T, V4 = exact()
    x, w = start()
    xs, ws, res = static_solve(SpringChain(), x, w, 0.0, dict(atol=1e-12, rtol=1e-14))
    assert res.converged and res.iterations >= 4
    np.testing.assert_allclose(xs[:3], XSTAR, atol=1e-11)
    np.testing.assert_array_equal(xs[3:], 0.0)
    np.testing.assert_array_equal(ws[:3], 0.0)            # velocities zeroed
    assert ws[3] == pytest.approx(T, abs=1e-11)
    assert ws[4] == pytest.approx(V4, abs=1e-11)
    assert ws[5] == V5                                    # prescribed value imposed
    # quadratic convergence: the rates of the last iterations (those above round-off)
    r = np.array(res.residuals)
    rates = [q for q, rk in zip(res.rates, r[2:]) if rk > 1e-13]
    assert len(rates) >= 2 and 1.7 < rates[-1] < 2.5, (res.residuals, res.rates)


def test_constrained_mech_dof_keeps_its_position():
    x, w = start()
    x[0] = 0.1  # move the pinned end: the whole chain shifts rigidly at equilibrium
    x[1:3] += 0.1
    xs, _, res = static_solve(SpringChain(), x, w, 0.0, dict(atol=1e-12))
    assert res.converged and xs[0] == 0.1
    np.testing.assert_allclose(xs[:3], XSTAR + 0.1, atol=1e-11)


def test_pseudo_transient_reaches_the_same_equilibrium():
    _, _, T, V4 = exact()
    x, w = start()
    xn, wn, rn = static_solve(SpringChain(), x, w, 0.0, dict(atol=1e-12))
    xp, wp, rp = pseudo_transient_solve(SpringChain(), x, w, 0.0, atol=1e-12)
    assert rp.converged, rp.reason
    np.testing.assert_allclose(xp, xn, atol=1e-10)
    np.testing.assert_allclose(wp, wn, atol=1e-10)
    assert wp[4] == pytest.approx(V4, abs=1e-10) and wp[3] == pytest.approx(T, abs=1e-10)
    # the regularisation fades as |F| falls: the final steps are Newton-like (superlinear)
    assert rp.residuals[-1] < 1e-12 and rp.iterations < 60
    assert rp.iterations > rn.iterations                 # and it did regularise early on


def test_pseudo_transient_from_far_start_with_large_sigma():
    x = np.array([0.0, 0.5, 3.5, 0, 0, 0])
    w = np.zeros(6)
    xp, wp, rp = pseudo_transient_solve(SpringChain(), x, w, 0.0, atol=1e-12, sigma0=100.0)
    assert rp.converged, rp.reason
    np.testing.assert_allclose(xp[:3], XSTAR, atol=1e-10)
