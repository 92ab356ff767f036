"""Finite-difference checks of every mechanical residual term's exact tangent."""
import numpy as np
import pytest

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel, PrescribedCurrent
from rve.testing import fd_jacobian, helix_fibril, rel_err
from rve.physics.elasticity import neo_hookean_energy, neo_hookean_stress, neo_hookean_tangent


def random_state(model, rng, scale=0.01):
    x = np.zeros(model.n)
    X = model.nodal(x)
    X[:, :9] = model.mesh.X0 + scale * rng.standard_normal(model.mesh.X0.shape)
    return x


def test_neo_hookean_tangent_matches_fd():
    rng = np.random.default_rng(0)
    F = np.eye(3) + 0.2 * rng.standard_normal((5, 3, 3))
    mu, lam = 1.3, 0.7
    P, A = neo_hookean_tangent(F, mu, lam)
    # P = dpsi/dF
    eps = 1e-6
    for n in range(5):
        for k in range(3):
            for L in range(3):
                Fp = F[n].copy(); Fp[k, L] += eps
                Fm = F[n].copy(); Fm[k, L] -= eps
                dpsi = (neo_hookean_energy(Fp, mu, lam) - neo_hookean_energy(Fm, mu, lam)) / (2 * eps)
                assert abs(dpsi - P[n, k, L]) < 1e-7 * max(1, abs(P[n, k, L]))
                dP = (neo_hookean_stress(Fp, mu, lam) - neo_hookean_stress(Fm, mu, lam)) / (2 * eps)
                assert rel_err(A[n, :, :, k, L], dP) < 1e-6


@pytest.mark.parametrize("order", [1, 2, 3, 4])
@pytest.mark.parametrize("curved", [False, True])
def test_internal_force_and_lorentz_tangent(order, curved):
    rng = np.random.default_rng(order)
    fib = helix_fibril() if curved else straight_fibril([0, 0, 0], [1.0, 0.2, 0.1], 0.1)
    mesh = fibril_mesh([fib, straight_fibril([0, 1, 0], [1, 1, 0.3], 0.05)], [2, 1], order)
    mat = BeamMaterial(youngs_modulus=3.0, poisson_ratio=0.3, density=1.0)
    model = BeamModel(mesh, mat, disk_points=8,
                      prescribed_current=PrescribedCurrent(np.array([2.0, -1.0]), np.array([0.3, -0.2, 0.5])))
    x = random_state(model, rng)
    assert model.admissible(x)
    w = np.zeros(model.n)
    F, Fx, Fw = model.evaluate(x, w, 0.0)
    J = fd_jacobian(lambda u: model.evaluate(u, w, 0.0, jacobian=False)[0], x)
    assert rel_err(Fx.toarray(), J) < 1e-6


def test_reference_state_is_stress_free():
    fib = helix_fibril()
    mesh = fibril_mesh([fib], 3, 2)
    model = BeamModel(mesh, BeamMaterial(youngs_modulus=2.0, poisson_ratio=0.2))
    x = np.zeros(model.n)
    model.nodal(x)[:, :9] = mesh.X0
    F, _, _ = model.evaluate(x, np.zeros(model.n), 0.0)
    assert np.abs(F).max() < 1e-12


def test_mass_matrix_rigid_translation_and_rotation_inertia():
    R, L, rho = 0.1, 2.0, 1.5
    mesh = fibril_mesh([straight_fibril([0, 0, 0], [L, 0, 0], R)], 3, 2)
    model = BeamModel(mesh, BeamMaterial(youngs_modulus=1.0, density=rho), disk_points=4)
    M = model.mass()
    v = np.zeros(model.n)
    model.nodal(v)[:, 1] = 1.0  # translate in y: kinetic 2*E = m v^2
    assert np.isclose(v @ (M @ v), rho * np.pi * R**2 * L, rtol=1e-12)
    v[:] = 0.0
    model.nodal(v)[:, 3:6] = [1.0, 0.0, 0.0]  # g1 rate e1: integral of xi1^2 over the section
    assert np.isclose(v @ (M @ v), rho * np.pi * R**4 / 4 * L, rtol=1e-12)
