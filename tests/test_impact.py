"""The impact scene (thesis §8.4) on reduced runs: set-up, balances, the B = 0 symmetry, the
B-on tilt and current asymmetry, checkpoint/resume (docs/impact.md)."""
import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import impact
from rve.scenes.protocol import SceneFailure

REDUCED = ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
           "projectile.radius=4.5 mm", "time.t_end=0.05 ms", "time.steps=100"]
TINY = ["geometry.n_warp=4", "geometry.n_weft=4", "geometry.span=6.35 mm", "mesh.elements=8",
        "projectile.radius=2 mm", "time.t_end=0.02 ms", "time.steps=40", "relaxation.steps=5",
        "relaxation.t_end=0.2 ms", "newton.jacobian_reuse=false", "time.checkpoint_every=10"]


def _cfg(extra=()):
    return load_config("configs/scenes/impact.yaml", REDUCED + list(extra))


def test_setup_full_size_counts_and_rule():
    cfg = load_config("configs/scenes/impact.yaml")
    assert impact.nominal_steps(cfg) == 1000
    assert impact.time_step_rule(cfg) == pytest.approx(0.4 / (20 * 30.0))
    c2 = load_config("configs/scenes/impact.yaml", ["time.steps=auto"])
    assert impact.nominal_steps(c2) == 750  # ceil(0.5 / (0.4 / 600))


def test_setup_reduced_geometry():
    cfg = load_config("configs/scenes/impact.yaml", TINY)
    p = impact.setup(cfg)
    sysm = p.system
    assert sysm.projectile.mesh.n_elements == 1 and sysm.projectile.mesh.n_nodes == 2
    L = p.info["projectile_length_mm"]
    assert L == pytest.approx(5.5 + 2 * 2.0)
    xp = sysm.projectile.nodal(sysm.split(p.x0)[1])
    assert xp[1, 2] - xp[0, 2] == pytest.approx(L)
    # the lower hemisphere starts `gap` above the fabric's top surface
    top = sysm.fabric.nodal(sysm.split(p.x0)[0])[:, 2].max() + 0.4
    assert xp[0, 2] - 2.0 - top == pytest.approx(0.2)
    assert p.info["initial_chord_clearance_mm"] == pytest.approx(0.01, abs=1e-5)
    assert sysm.n == sysm.fabric.n + 20
    # mass of the projectile = rho pi R^2 L (the element's consistent mass, translation rows)
    M = sysm.projectile.mass()
    r = sysm.projectile.layout.dofs("r").reshape(-1, 3)
    ones = np.zeros(sysm.projectile.n)
    ones[r[:, 2]] = 1.0
    assert (M @ ones)[r[:, 2]].sum() == pytest.approx(0.01 * np.pi * 4.0 * L, rel=1e-12)


def test_angular_velocity_formula_rigid_rotation():
    """A rigid rotation omega e_x of the end nodes about the centre gives omega back."""
    L, om = 10.0, 0.3
    q_top, q_bot = np.zeros(3), np.zeros(3)
    r = np.array([0.0, 0.0, L / 2])
    v_top = np.cross([om, 0, 0], r)
    v_bot = -v_top
    w = impact.angular_velocity(q_top, q_bot, v_top, v_bot, L)
    assert np.allclose(w, [om, 0, 0], atol=1e-15)


@pytest.fixture(scope="module")
def relaxed():
    cfg = _cfg()
    x, info = impact.relax(cfg)
    return x, info


@pytest.fixture(scope="module")
def runs(relaxed):
    x, info = relaxed
    out = {}
    for name, B in (("B_on", "0.001 kT"), ("B_off", "0 kT")):
        out[name] = impact.solve(_cfg([f"field.magnitude={B}"]), x_start=x, relax_info=info).summary
    return out


@pytest.mark.slow
def test_relaxation_settles(relaxed):
    x, info = relaxed
    assert info["max_velocity_mm_per_ms"] < 1e-3
    assert info["max_displacement_mm"] < 1e-9  # the crimped, apart start is an equilibrium


@pytest.mark.slow
def test_balances_on_the_reduced_run(runs):
    s = runs["B_on"]
    e = s["balance_errors"]
    assert s["steps_accepted"] == 100
    assert e["momentum_projectile"] < 1e-2 and e["momentum_total"] < 1e-2
    assert e["charge"] < 1e-8 and e["electrical"] < 1e-6
    assert e["mechanical"] < 1e-2 and e["thermal"] < 1e-2
    assert s["sphere_pairs_active_max"] > 0
    # the fabric slows the projectile (the impulse on it points up) and momentum is exchanged
    assert s["projectile_velocity_mm_per_ms"][2] > -30.0
    assert s["impulses_Nms"]["impulse_sphere_on_projectile_Nms"][2] > 0


@pytest.mark.slow
def test_B_off_symmetric_and_B_on_tilts(runs):
    on, off = runs["B_on"], runs["B_off"]
    w_on = on["projectile_angular_velocity_x_rad_per_ms"]
    w_off = off["projectile_angular_velocity_x_rad_per_ms"]
    assert w_on < 0
    assert abs(w_off) < 0.01 * abs(w_on)
    c_off, c_on = off["yarn_current_A"], on["yarn_current_A"]
    assert abs(c_off["plus_y"] - c_off["minus_y"]) < 1e-6 * abs(c_off["plus_y"])
    assert c_on["plus_y"] > c_on["minus_y"]


@pytest.mark.slow
def test_checkpoint_resume_gives_the_same_result(tmp_path):
    cfg = load_config("configs/scenes/impact.yaml", TINY)
    x, info = impact.relax(cfg)
    ref = impact.solve(cfg, x_start=x, relax_info=info, record=False)
    ck = tmp_path / "checkpoint.npz"
    with pytest.raises(SceneFailure):
        impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck, stop_after_steps=20)
    assert ck.exists()
    res = impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck)
    assert res.summary["resumed_from_ms"] == pytest.approx(0.01)
    assert res.summary["steps_accepted"] == ref.summary["steps_accepted"]
    assert np.array_equal(res.state["x"], ref.state["x"]) and np.array_equal(res.state["w"], ref.state["w"])
    assert np.array_equal(res.state["T"], ref.state["T"])


def test_relaxed_state_is_saved_and_reused(tmp_path, monkeypatch):
    cfg = load_config("configs/scenes/impact.yaml", TINY)
    from rve.scenes.impact import scene

    calls = []
    real = scene.relax

    def counting(c, progress=False):
        calls.append(1)
        return real(c, progress)

    monkeypatch.setattr(scene, "relax", counting)
    f = tmp_path / "relaxed.npz"
    x1, _ = impact.load_or_relax(cfg, f)
    x2, info2 = impact.load_or_relax(cfg, f)
    assert len(calls) == 1 and np.array_equal(x1, x2) and info2["loaded_from"] == str(f)
    # the impact speed does not invalidate the relaxed state; the mesh does
    x3, _ = impact.load_or_relax(load_config("configs/scenes/impact.yaml", TINY + ["projectile.speed=10 mm/ms"]), f)
    assert len(calls) == 1
    impact.load_or_relax(load_config("configs/scenes/impact.yaml", TINY + ["mesh.elements=10"]), f)
    assert len(calls) == 2


def test_projectile_heat_sink_matrix():
    """Sphere pairs in contact conduct h_C a(g) l_e to the projectile (T = 0): the sink matrix
    is G beta beta^T per pair and the heat into the projectile is sum G T(closest point)."""
    from rve.physics.contact_forms import effective_radius, hertz_kappa, hertz_width
    from rve.physics.sphere_contact_forms import sphere_segment_geometry
    from rve.scenes.impact.thermal import ImpactThermal

    cfg = load_config("configs/scenes/impact.yaml", TINY)
    p = impact.setup(cfg)
    sysm = p.system
    x = p.x0.copy()
    x[sysm._r_end[:, 2]] -= 0.5  # press the lower hemisphere 0.3 mm into the fabric
    sysm.rebuild(x)
    th = ImpactThermal(sysm, 0.1, p.fixed_T_nodes)
    xf = sysm.split(x)[0]
    th.set_state(x)
    K = th.sink_matrix(xf).toarray()
    c, r = sysm.positions(x)
    term = sysm.sphere
    geo = sphere_segment_geometry(c[term.centre], r[term.node_a], r[term.node_b], term.gap_radius)
    act = np.flatnonzero(geo["g"] > 0)
    assert act.size > 0
    ref = np.zeros_like(K)
    for q in act:
        kap = hertz_kappa(effective_radius(0.4, 2.0), term.penalty, sysm.fabric.E_star)
        a, _ = hertz_width(geo["g"][q], kap, sysm.fabric.g_eps)
        G = 0.1 * a * sysm.mesh.elem_length[term.element[q]]
        s = geo["s"][q]
        na, nb = term.node_a[q], term.node_b[q]
        ref[np.ix_([na, nb], [na, nb])] += G * np.outer([1 - s, s], [1 - s, s])
    assert np.abs(K - ref).max() <= 1e-14 * np.abs(ref).max()
    T = np.random.default_rng(0).uniform(size=K.shape[0])
    assert th.sink_heat(T, xf) == pytest.approx(float((ref @ T).sum()), rel=1e-13)
    # the full state gives the same operator as the fabric part with the remembered centres
    assert np.abs(th.contact(x).toarray() - th.contact(xf).toarray()).max() == 0.0


def test_bordered_backend_solves_like_a_direct_solve():
    """superlu_pruned with the projectile's dofs as a Schur-complement border gives the
    direct solution of a stage-like matrix of the impact system."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from rve.solvers.backends.pruned import PrunedSuperLU
    from rve.solvers.system import FreeDofs

    cfg = load_config("configs/scenes/impact.yaml", TINY)
    p = impact.setup(cfg)
    sysm = p.system
    x = p.x0.copy()
    x[sysm._r_end[:, 2]] -= 0.5
    sysm.rebuild(x)
    w = np.zeros(sysm.n)
    w[sysm._r_end[:, 2]] = -30.0
    F, Fx, Fw = sysm.evaluate(x, w, 0.0)
    ha = 5e-4 * (1 - 2**-0.5)
    idx, _ = sysm.constraints(0.0)
    fd = FreeDofs(sysm.n, idx)
    J = fd.combine([(sysm.mass(), 1.0, None), (Fw, ha, None), (Fx, ha * ha, sysm.mech.astype(float))])
    b = np.random.default_rng(2).normal(size=J.shape[0])
    ref = spla.spsolve(sp.csc_matrix(J), b)
    for border in (0, 20):
        be = PrunedSuperLU(symmetric=False, border=border)
        be.factorize(J)
        u = be.solve(b)
        # backward error at round-off (the unscaled stage matrix is ill-conditioned: the
        # forward difference to SuperLU's COLAMD solve is the conditioning times round-off)
        Jn = abs(J).sum(axis=1).max()
        assert np.abs(J @ u - b).max() <= 1e-12 * (Jn * np.abs(u).max() + np.abs(b).max())
        assert np.abs(u - ref).max() <= 1e-6 * np.abs(ref).max()
