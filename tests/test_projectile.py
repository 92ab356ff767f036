"""The projectile of thesis §8.4: sphere-segment contact forms (FD tangents, analytic force),
the candidate search, the coupled ImpactSystem (FD Jacobian, free flight)."""
import numpy as np
import pytest

from rve.fem.assembly import DofLayout
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel, CircuitBC, ContactParams, ContactSystem, Couplings, DirichletBC
from rve.model.projectile import ImpactSystem, projectile_mesh
from rve.model.terms.projectile_contact import SphereContactTerm, sphere_candidates
from rve.physics.sphere_contact_forms import sphere_segment_energy, sphere_segment_forces, sphere_segment_gaps
from rve.testing import fd_jacobian, rel_err


def _pairs(rng, P=6, interior=True):
    a = rng.normal(size=(P, 3))
    b = a + rng.normal(size=(P, 3))
    s = rng.uniform(0.2, 0.8, P) if interior else rng.choice([-0.5, 1.5], P)
    e = b - a
    perp = np.cross(e, rng.normal(size=(P, 3)))
    perp /= np.linalg.norm(perp, axis=1, keepdims=True)
    p = a + s[:, None] * e + 0.7 * perp
    return p, a, b


@pytest.mark.parametrize("interior", [True, False])
def test_sphere_form_tangent_and_gradient_fd(interior):
    rng = np.random.default_rng(3 if interior else 4)
    p, a, b = _pairs(rng, interior=interior)
    R, k = 1.0 + 0.5 * rng.uniform(size=p.shape[0]), 2.0 + rng.uniform(size=p.shape[0])
    X = np.stack([p, a, b], axis=1)  # (P, 3, 3)
    assert (sphere_segment_gaps(p, a, b, R) > 0).all()
    F, K = sphere_segment_forces(p, a, b, R, k)
    for q in range(p.shape[0]):
        def res(u, q=q):
            Y = u.reshape(3, 3)
            return sphere_segment_forces(Y[0:1], Y[1:2], Y[2:3], R[q:q + 1], k[q:q + 1], False)[0].ravel()

        def en(u, q=q):
            Y = u.reshape(3, 3)
            return np.array([sphere_segment_energy(Y[0:1], Y[1:2], Y[2:3], R[q:q + 1], k[q:q + 1])])

        u0 = X[q].ravel()
        assert rel_err(K[q].reshape(9, 9), fd_jacobian(res, u0)) < 1e-7
        assert rel_err(F[q].ravel(), fd_jacobian(en, u0).ravel()) < 1e-8
        assert np.allclose(K[q].reshape(9, 9), K[q].reshape(9, 9).T, atol=1e-12)
    # equal and opposite: the pair adds no force in total
    assert np.abs(F.sum(axis=1)).max() < 1e-13


def test_sphere_pressed_on_fibril_gives_analytic_force():
    """A sphere of radius R_p centred at height h over a straight fibril (radius R_f) along x:
    the overlap R_p + R_f - h; point penalty k = P* l_e on the element below it."""
    Rp, Rf, Pstar, h = 18.0, 0.4, 20.0, 18.3
    mesh = fibril_mesh([straight_fibril([-5, 0, 0], [5, 0, 0], Rf)], 10, 1)
    term = SphereContactTerm(mesh, Rp, Pstar, margin=0.3)
    centres = np.array([[0.05, 0.0, h], [0.0, 0.0, 100.0]])  # centre over the interior of element 5
    r = mesh.X0[:, :3]
    term.rebuild(centres, r)
    Fc = term.forces_on_centres(centres, r)
    act = term.active_pairs(centres, r)
    # analytic: on each element [x_i, x_i+1] the closest point to the centre is clip(x_c, x_i, x_i+1);
    # distance sqrt(h^2 + (x_c - x*)^2), overlap Rp + Rf - distance, force k g along the normal
    nodes = np.linspace(-5, 5, 11)
    xs = np.clip(0.05, nodes[:-1], nodes[1:])
    dist = np.hypot(h, 0.05 - xs)
    gap = Rp + Rf - dist
    le = 1.0
    expected = float((Pstar * le * np.where(gap > 0, gap, 0) * h / dist).sum())
    expected_x = float((Pstar * le * np.where(gap > 0, gap, 0) * (0.05 - xs) / dist).sum())
    assert abs(Fc[0, 0] - expected_x) < 1e-12 * expected
    assert act.size == int((gap > 0).sum())
    assert act.size >= 1
    assert abs(Fc[0, 2] - expected) < 1e-12 * expected
    assert np.abs(Fc[1]).max() == 0.0


def test_sphere_candidates_bruteforce():
    rng = np.random.default_rng(0)
    A = rng.uniform(-10, 10, (200, 3))
    B = A + rng.normal(size=(200, 3))
    c = rng.uniform(-10, 10, (2, 3))
    i, j = sphere_candidates(c, A, B, 5.0)
    ref = set()
    for ci in range(2):
        for sj in range(200):
            ss = np.linspace(0, 1, 20001)
            d = np.linalg.norm(A[sj] + ss[:, None] * (B[sj] - A[sj]) - c[ci], axis=1).min()
            if d <= 5.0 - 1e-6:
                ref.add((ci, sj))
            elif d <= 5.0 + 1e-6:
                ref.add((ci, sj)) if (ci, sj) in set(zip(i, j)) else None
    assert set(zip(i.tolist(), j.tolist())) == ref


def small_impact_system(height=18.3, B=(0.0, 0.0007071, 0.0007071), with_fabric_contact=True):
    """A warp (along x) and a weft (along y) crossing under the projectile, pinned, with V."""
    Rf = 0.4
    fib = [straight_fibril([-3, 0.2, 0], [3, 0.2, 0], Rf), straight_fibril([0.3, -3, 0.85], [0.3, 3, 0.85], Rf)]
    mesh = fibril_mesh(fib, 4, 1)
    fields = ("mech", "V")
    layout = DofLayout(mesh.n_nodes, fields)
    ends = np.array([mesh.end_nodes(f) for f in range(2)])
    bcs = [DirichletBC(layout.dofs("r", ends.ravel()), 0.0), DirichletBC(layout.dofs("V", [ends[0, 1]]), 0.0)]
    circ = [CircuitBC(int(ends[0, 0]), 100.0, -100.0, np.pi * Rf**2), CircuitBC(int(ends[1, 0]), 1e-3, 0.0, np.pi * Rf**2)]
    mat = BeamMaterial(youngs_modulus=1.26, density=0.00144, damping=1e-4, electrical_conductivity=1e5)
    cpl = Couplings(B=B, lorentz=True, back_emf=True, joule=False, seebeck=False, thermal_softening=False)
    base = BeamModel(mesh, mat, fields=fields, bcs=bcs, couplings=cpl, circuits=circ)
    x0 = np.zeros(base.n)
    base.nodal(x0)[:, :9] = mesh.X0
    fabric = ContactSystem(base, ContactParams(penalty=20.0, n_gp=2, margin=0.3), x0)
    pmesh = projectile_mesh(18.0, 41.5, (0.1, -0.05, height))
    pmat = BeamMaterial(youngs_modulus=1.26, density=0.01, damping=0.0, electrical_conductivity=1.0)
    pcirc = [CircuitBC(n, 1e-3, 0.0, np.pi * 18.0**2) for n in pmesh.end_nodes(0)]
    proj = BeamModel(pmesh, pmat, fields=fields, couplings=cpl, circuits=pcirc)
    xp = np.zeros(proj.n)
    proj.nodal(xp)[:, :9] = pmesh.X0
    sphere = SphereContactTerm(mesh, 18.0, 20.0, 0.3)
    x = np.concatenate([x0, xp])
    return ImpactSystem(fabric, proj, sphere, x), x


def test_impact_system_jacobian_fd():
    sysm, x = small_impact_system()
    rng = np.random.default_rng(1)
    x = x.copy()
    mech = sysm.mech
    x[mech] += 0.01 * rng.normal(size=mech.sum())
    w = 0.3 * rng.normal(size=sysm.n)
    sysm.rebuild(x)
    c, r = sysm.positions(x)
    assert sysm.sphere.active_pairs(c, r).size >= 2  # the sphere presses both fibrils
    F, Fx, Fw = sysm.evaluate(x, w, 0.0)
    M = sysm.mass()
    assert Fx.nnz == Fw.nnz == M.nnz and np.array_equal(Fx.indices, M.indices)
    cols = np.flatnonzero(mech)
    Jx = fd_jacobian(lambda u: sysm.evaluate(u, w, 0.0, False)[0], x, cols, eps=1e-6)
    assert rel_err(Fx.toarray()[:, cols], Jx) < 1e-6
    Jw = fd_jacobian(lambda u: sysm.evaluate(x, u, 0.0, False)[0], w, eps=1e-6)
    assert rel_err(Fw.toarray(), Jw) < 1e-6
    # the sphere contact is internal: its forces sum to zero
    Fs, act, _ = sysm.sphere_terms(x, False)
    assert act.size and np.abs(Fs[sysm.mech].reshape(-1) .sum()) < 1e-12 * np.abs(Fs).max() * Fs.size


def test_free_flight_keeps_velocity():
    """Projectile far from the fabric, B on: v stays -30 mm/ms to round-off over 40 SDIRK2 steps."""
    from rve.model import RowScaledSystem
    from rve.solvers.dirk import consistent_initialization, integrate

    sysm, x = small_impact_system(height=200.0)
    w = np.zeros(sysm.n)
    _, wp = sysm.split(w)
    rz = sysm._r_end[:, 2]
    w[rz] = -30.0
    sysm.rebuild(x)
    assert sysm.sphere.n_pairs == 0
    nopts = {"atol": 1e-10, "rtol": 1e-13, "max_iter": 20}
    scale = sysm.row_scales(5e-4, x, w)
    rs = RowScaledSystem(sysm, scale)
    w, _ = consistent_initialization(rs, x, w, 0.0, nopts)
    res = integrate(rs, x, w, 0.0, 0.02, 40, stages=2, newton_opts=nopts, consistent=False)
    wn = sysm.projectile.nodal(sysm.split(res.w)[1])
    assert np.abs(wn[:, 2] + 30.0).max() < 1e-12 * 30.0
    assert np.abs(wn[:, :2]).max() < 1e-12 * 30.0
    xn = sysm.projectile.nodal(sysm.split(res.x)[1])
    assert abs(xn[0, 2] - (200.0 - 30.0 * 0.02)) < 1e-11 * 200
