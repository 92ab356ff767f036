"""Friction in the dynamic scenes (rve.scenes.dynamic_friction; docs/impact.md "Friction",
docs/induced_deformation.md "Friction"): the config section, mu = 0 builds no friction term,
the unsymmetric frictional stage matrix through the kept stage factorisations, kill and
resume of the impact with friction bit for bit, and the energy balance that closes with
the friction terms and not without them; the same for the friction at the projectile's
sphere contact (rve.scenes.impact.friction; docs/impact.md "Friction at the projectile"),
with its FD tangent in the whole system and the stage Newton's quadratic rate."""
import numpy as np
import pytest
import scipy.sparse as sp

from rve.config import ConfigError
from rve.config.loader import load_config
from rve.scenes import friction_crossing, impact
from rve.scenes.dynamic_friction import DynamicFriction
from rve.scenes.frictional import initial_state, step
from rve.scenes.induced import scene as induced
from rve.scenes.protocol import SceneFailure
from rve.solvers.linear import get_backend, is_symmetric
from rve.testing import fd_jacobian
from rve.solvers.newton import StageFactorisation
from rve.solvers.backends.pruned import PardisoOrPruned, PrunedSuperLU

IMPACT = "configs/scenes/impact.yaml"
INDUCED = "configs/scenes/induced_deformation.yaml"
TINY = ["geometry.n_warp=4", "geometry.n_weft=4", "geometry.span=6.35 mm", "mesh.elements=8",
        "projectile.radius=2 mm", "time.t_end=0.02 ms", "time.steps=40", "relaxation.steps=5",
        "relaxation.t_end=0.2 ms", "newton.jacobian_reuse=false", "time.checkpoint_every=10"]


@pytest.mark.parametrize("path", [IMPACT, INDUCED])
def test_friction_section_default_off_and_validated(path):
    cfg = load_config(path)
    assert cfg.friction.coefficient == 0.0 and cfg.friction.pairs == {}
    with pytest.raises(ConfigError, match=r"friction.coefficient = 2.5: must be >= 0 and <= 2"):
        load_config(path, ["friction.coefficient=2.5"])
    with pytest.raises(ConfigError, match="friction"):
        load_config(path, ["friction.stiffness=0"])


def test_zero_coefficient_builds_no_friction_term():
    cfg = load_config(IMPACT, TINY)
    p = impact.setup(cfg)
    assert p.friction is None and p.fabric.term.friction is None and p.fabric.params.friction is None
    cfg = load_config(INDUCED, ["mesh.elements=8"])
    p = induced.setup(cfg)
    assert p.friction is None and p.system.term.friction is None


def test_families_and_relaxation_without_friction():
    cfg = load_config(IMPACT, TINY + ["friction.coefficient=0.2", "friction.pairs={warp-warp: 0.5}"])
    p = impact.setup(cfg)
    fr = p.friction.term
    assert set(fr.family_names) == {"warp", "weft"}
    M = fr._mu_matrix
    w, f = fr.family_names.index("warp"), fr.family_names.index("weft")
    assert M[w, w] == 0.5 and M[w, f] == 0.2 and M[f, f] == 0.2
    # the relaxation (B off, the projectile held) stays frictionless: its start is at rest
    assert impact.setup(cfg, "relax").friction is None


def _stage_matrix():
    """A stage matrix M + c Fw + c^2 Fx of the crossing committed in slip (the state moved on)."""
    cfg = load_config("configs/scenes/crossing.yaml")
    system, parts = friction_crossing.setup(cfg)
    x = initial_state(system.mesh, system.layout)
    z0 = x[parts["z"]].copy()
    for k in (1, 2):
        x[parts["z"]] = z0 - cfg.geometry.indentation * k / 2
        x, _, _ = step(system, x, 0.0, cfg.newton, "t", "indent", k)
    for k in (1, 2):
        x[parts["x"]] = 0.04 * k / 2
        x, _, _ = step(system, x, 0.0, cfg.newton, "t", "cycle", k)
    x[parts["contact_x"]] += 0.002
    assert system.term.friction.state(x).slip.sum() == 1
    w = np.zeros(system.n)
    _, Fx, Fw = system.evaluate(x, w, 0.0)
    M = system.base.assembler.mass()
    c = 1e-3
    A = (M + c * Fw + c * c * Fx).tocsr()
    free = np.setdiff1d(np.arange(system.n), system.constraints(0.0)[0])
    return A[free][:, free]


@pytest.mark.parametrize("backend", ["superlu", "pruned", "auto_pruned"])
def test_kept_stage_factorisation_solves_the_unsymmetric_frictional_matrix(backend):
    """The DIRK's kept factorisation (StageFactorisation, the scenes' backends: SuperLU's
    symmetric mode is an LU of the whole matrix with a symmetric ordering) does not assume
    a symmetric matrix: the slip tangent's stage matrix is solved to rounding."""
    A = _stage_matrix()
    assert not is_symmetric(A)
    # four copies, symmetrically permuted: no narrow band (a weave's matrices have none), so
    # the factorisation is the backend's and not LAPACK's banded LU
    A = sp.block_diag([A] * 4, format="csr")
    perm = np.random.default_rng(0).permutation(A.shape[0])
    A = A[perm][:, perm]
    inst = {"superlu": lambda: get_backend("superlu"), "pruned": lambda: PrunedSuperLU(symmetric=False, border=3),
            "auto_pruned": lambda: PardisoOrPruned(symmetric=False, border=3)}[backend]()
    fac = StageFactorisation(A, inst)
    assert fac.kind == inst.name
    b = np.random.default_rng(1).normal(size=A.shape[0])
    du = fac.solve(b)
    assert np.linalg.norm(A @ du - b) <= 1e-10 * np.linalg.norm(b)
    # the symmetric part alone is a different matrix: its solution misses
    S = 0.5 * (A + A.T)
    assert np.linalg.norm(S @ du - b) > 1e-8 * np.linalg.norm(b)


#: the fabric's crossings start sliding at step 38 of the tiny impact: resumed at step 50, mid-slide
FRICTIONAL = TINY + ["friction.coefficient=0.3", "time.t_end=0.03 ms", "time.steps=60"]


@pytest.fixture(scope="module")
def frictional_impact():
    cfg = load_config(IMPACT, FRICTIONAL)
    x, info = impact.relax(cfg)
    return cfg, x, info, impact.solve(cfg, x_start=x, relax_info=info, record=True)


@pytest.mark.slow
def test_impact_with_friction_resumes_bit_for_bit(tmp_path, monkeypatch, frictional_impact):
    cfg, x, info, ref = frictional_impact
    D = ref.summary["energies_mJ"]["friction_dissipated_mJ"]
    assert D > 0
    ck = tmp_path / "checkpoint.npz"
    with pytest.raises(SceneFailure):
        impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck, stop_after_steps=50)
    with np.load(ck) as d:
        assert float(d["friction/dissipated"]) > 0   # the history is in the checkpoint
    saved = ck.read_bytes()
    res = impact.solve(cfg, x_start=x, relax_info=info, record=True, checkpoint=ck)
    assert res.summary["resumed_from_ms"] > 0
    for k in ("x", "w", "T"):
        assert np.array_equal(res.state[k], ref.state[k])
    assert res.summary["energies_mJ"]["friction_dissipated_mJ"] == D
    # resumed without the friction history (every stick point starting afresh) it differs
    ck.write_bytes(saved)
    monkeypatch.setattr(DynamicFriction, "restore", lambda self, x_, arrays: None)
    bad = impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck)
    assert not np.array_equal(bad.state["x"], ref.state["x"])


@pytest.mark.slow
def test_impact_system_jacobian_with_friction_fd(frictional_impact):
    """The whole ImpactSystem's tangent (fabric with friction + projectile + spheres, on its
    union pattern) against central differences at a trial state moved on from the last
    committed one along the velocity (the sliding crossings slip there), in the centroids
    and first directors of the slipping pairs' nodes (the section frame's law acts on g1)."""
    _, _, _, ref = frictional_impact
    sysm, x, w = ref.model, ref.state["x"], ref.state["w"]
    fr = sysm.fabric.term.friction
    xt = x + 2e-4 * w                       # 0.2 us further on, the history held
    st = fr.state(sysm.split(xt)[0])
    assert st.slip.sum() > 0
    F, Fx, _ = sysm.evaluate(xt, w, 0.03)
    assert not is_symmetric(Fx)
    pairs = np.flatnonzero(st.slip.any(axis=1))[:3]
    c = sysm.fabric.term
    nodes = np.unique(np.concatenate([np.ravel(c.map.nodes_plus[pairs]), np.ravel(c.map.nodes_minus[pairs])]))
    assert fr.frame
    cols = np.concatenate([sysm.fabric.layout.dofs("r", nodes), sysm.fabric.layout.dofs("g1", nodes)])
    J = fd_jacobian(lambda v: sysm.evaluate(v, w, 0.03, jacobian=False)[0], xt, cols, eps=1e-7)
    A = Fx.toarray()[:, cols]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())


@pytest.mark.slow
def test_impact_energy_balance_closes_with_the_friction_work(frictional_impact):
    """The tiny impact with mu = 0.3 (the crossings slide over the last 22 of 60 steps):
    the mechanical balance's residual is a small part of the friction work with it and most
    of it without it; the work W_f (trapezoid of the friction power) and the return maps'
    dissipated energy plus the springs' energy agree to first order in h."""
    from rve.model.balances import impact_balance_errors

    _, _, _, ref = frictional_impact
    bal = {k: np.asarray(v) for k, v in ref.summary["history"]["balances"].items()}
    e = impact_balance_errors(bal)
    W_f, D, E_T = e["friction_work_mJ"], e["friction_dissipated_mJ"], e["friction_elastic_energy_mJ"]
    assert W_f > 0.5 * abs(e["delta_mechanical_energy_mJ"])       # friction matters here
    res = np.abs(e["series"]["mechanical_residual"]).max()
    assert res <= 0.02 * W_f
    off = impact_balance_errors({k: v for k, v in bal.items()
                                 if k not in ("friction_dissipated", "energy_friction", "power_friction")})
    assert np.abs(off["series"]["mechanical_residual"]).max() >= 0.5 * W_f
    assert abs(W_f - (D + E_T)) <= 0.1 * W_f


def _errors_without_friction(history_balances):
    from rve.model.balances import balance_errors

    s = {k: v for k, v in history_balances.items()
         if k not in ("friction_dissipated", "energy_friction", "power_friction")}
    return balance_errors(s)


@pytest.mark.slow
@pytest.mark.parametrize("frame, steps", [("section", 200), ("chord", 100)])
def test_induced_energy_balance_closes_with_the_friction_terms(frame, steps):
    """B3 on the induced weave at 12 elements per fibril, 0.5 ms into contact: with mu = 0.5
    the crossings slide and friction dissipates a large part of the Lorentz work. The
    mechanical and total balances close as they do without friction (the same scheme's
    numerical dissipation at the same fixed step, within 1.5x) only with the friction terms;
    without them the error is 2.5x that or more. The position-based law at the thesis's
    fixed step (the shipped config's error control off), where the balances were measured;
    the section frame at half of it: its friction also spins the fibrils (the directors turn
    by ~0.06 rad a step at 5 µs), which the thesis's step does not resolve (mechanical error
    3.5x the frictionless one there, docs/induced_deformation.md "Friction between
    fibrils")."""
    sets = ["mesh.elements=12", "field.orientation=B3", "time.t_end=0.5 ms", f"time.steps={steps}",
            "newton.jacobian_reuse=false", "time.adaptive.enabled=false"]
    e0 = induced.solve(load_config(INDUCED, sets), record=True).summary["balance_errors"]
    res = induced.solve(load_config(INDUCED, sets + ["friction.coefficient=0.5", f"friction.frame={frame}"]),
                        record=True)
    s = res.summary
    D = s["energies_mJ"]["friction_dissipated_mJ"]
    assert D > 0.2 * s["energies_mJ"]["work_lorentz_mJ"]   # friction matters here
    e = s["balance_errors"]
    off = _errors_without_friction(s["history"]["balances"])
    for k in ("mechanical", "total"):
        assert e[k] <= 1.5 * e0[k]
        assert off[k] >= 2.5 * e0[k]


# ----------------------------------------------------------------------------- friction at the projectile
#: both frictions: the fibrils over the last 22 of the 60 steps, the projectile's nose from step 33
SPHERE = FRICTIONAL + ["friction.projectile=0.3"]


def test_projectile_friction_key_default_off_and_validated():
    cfg = load_config(IMPACT)
    assert cfg.friction.projectile == 0.0
    with pytest.raises(ConfigError, match=r"friction.projectile = 2.5: must be >= 0 and <= 2"):
        load_config(IMPACT, ["friction.projectile=2.5"])
    with pytest.raises(ConfigError, match=r"friction.projectile"):
        load_config(IMPACT, ["friction.projectile=-0.1"])
    # mu_p = 0 (with or without friction between the fibrils): no sphere friction term, the
    # frictionless 9 x 9 pair blocks
    for sets in (TINY, TINY + ["friction.coefficient=0.2"]):
        p = impact.setup(load_config(IMPACT, sets))
        assert p.system.sphere.friction is None and p.system.sphere.n_local == 3
        assert p.friction is None or isinstance(p.friction, DynamicFriction)
    # mu_p > 0 alone: the sphere driver, no fibril friction; the relaxation stays frictionless
    cfg = load_config(IMPACT, TINY + ["friction.projectile=0.3"])
    p = impact.setup(cfg)
    assert p.system.sphere.friction.mu == 0.3 and p.system.sphere.n_local == 5
    assert p.friction.term is None and p.friction.sphere is not None and p.fabric.term.friction is None
    assert impact.setup(cfg, "relax").system.sphere.friction is None


@pytest.fixture(scope="module")
def sphere_frictional_impact(frictional_impact):
    _, x, info, _ = frictional_impact          # the same (frictionless) relaxation
    cfg = load_config(IMPACT, SPHERE)
    return cfg, x, info, impact.solve(cfg, x_start=x, relax_info=info, record=True)


@pytest.mark.slow
@pytest.mark.parametrize("regime", ["stick", "slip"])
def test_impact_system_jacobian_with_sphere_friction_fd(sphere_frictional_impact, regime):
    """The whole ImpactSystem's tangent with friction at the sphere contact, in the columns of
    the projectile's end nodes (centre and directors) and of the chords its pairs touch,
    against central differences at a trial state from the last committed history: moved on
    along the velocity (the pairs slip further) or back against it (they stick, unloading)."""
    _, _, _, ref = sphere_frictional_impact
    sysm, x, w = ref.model, ref.state["x"], ref.state["w"]
    fr = sysm.sphere.friction
    xt = x + (2e-4 if regime == "slip" else -1e-4) * w
    st = fr.state(sysm.sphere_local(xt))
    on = st.normal > 0
    assert on.sum() >= 4
    assert (st.slip[on].all() if regime == "slip" else st.stick[on].all())
    F, Fx, _ = sysm.evaluate(xt, w, 0.03)
    pairs = np.flatnonzero(on)
    fab = sysm.fabric.layout.dofs("r", np.unique(np.r_[sysm.sphere.node_a[pairs], sysm.sphere.node_b[pairs]]))
    ends = sysm.nf + sysm.projectile.layout.dofs("mech", sysm.ends)
    cols = np.r_[ends, fab]
    J = fd_jacobian(lambda v: sysm.evaluate(v, w, 0.03, jacobian=False)[0], xt, cols, eps=1e-7)
    A = Fx.toarray()[:, cols]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())
    # the friction couples the chords to the projectile's directors
    assert np.abs(Fx.toarray()[np.ix_(fab, sysm._g_end.ravel())]).max() > 0
    if regime == "slip":
        assert not is_symmetric(Fx)


@pytest.mark.slow
def test_stage_newton_is_quadratic_with_sphere_friction(sphere_frictional_impact):
    """A full-Newton SDIRK2 step (8 nominal steps long, so that Newton has something to do
    and more than one of its steps ends above round-off) of the tiny impact from its last
    state, the nose's pairs slipping: every stage converges quadratically (measured orders
    1.87, 1.88 and 1.98, 1.92 above round-off with the section frame, 1.65, 1.88 and 1.94,
    1.86 with the position-based law; at 4 nominal steps a stage has one order above
    round-off, 1.71 to 2.3)."""
    from rve.model import RowScaledSystem
    from rve.solvers.dirk import dirk_step
    from rve.solvers.newton import convergence_rates

    _, _, _, ref = sphere_frictional_impact
    sysm, x, w = ref.model, ref.state["x"], ref.state["w"]
    h = 4e-3
    rs = RowScaledSystem(sysm, sysm.row_scales(h, x, w))
    x1, _, info = dirk_step(rs, 2, x, w, 0.03, h, dict(atol=1e-300, rtol=1e-13, max_iter=20), jacobian_reuse=False)
    assert sysm.sphere.friction.state(sysm.sphere_local(x1)).slip.sum() >= 4
    for res in info.stage_residuals:
        # the orders of the steps that end above the round-off floor (~1e-14 here)
        rates = [q for q, r in zip(convergence_rates(res), res[2:]) if r > 1e-12 * res[0]]
        assert res[-1] <= 1e-13 * res[0] and len(res) <= 5 and rates and max(rates) > 1.8, (res, rates)


@pytest.mark.slow
def test_impact_energy_balance_closes_with_the_sphere_friction_work(sphere_frictional_impact):
    """With friction at the fibrils and at the projectile (mu = mu_p = 0.3): the mechanical
    balance's residual is a small part of the friction work with the sphere's work in it,
    and most of the sphere's work without it; its work and the return maps' estimate agree
    to first order in h; the projectile's momentum balance (the friction force on the centre
    in the sphere force) closes as it does without."""
    from rve.model.balances import impact_balance_errors

    _, _, _, ref = sphere_frictional_impact
    bal = {k: np.asarray(v) for k, v in ref.summary["history"]["balances"].items()}
    e = impact_balance_errors(bal)
    W_f, W_s = e["friction_work_mJ"], e["friction_work_sphere_mJ"]
    D_s, E_s = e["friction_dissipated_sphere_mJ"], e["friction_elastic_energy_sphere_mJ"]
    assert W_s > 0.3 * W_f and W_s > 0.3 * abs(e["delta_mechanical_energy_mJ"])   # the sphere's friction matters
    res = np.abs(e["series"]["mechanical_residual"]).max()
    assert res <= 0.02 * W_f
    off = impact_balance_errors({k: v for k, v in bal.items() if not k.endswith("_friction_sphere")
                                 and k not in ("friction_dissipated_sphere", "energy_friction_sphere")})
    assert "friction_work_sphere_mJ" not in off
    assert np.abs(off["series"]["mechanical_residual"]).max() >= 0.5 * W_s
    assert abs(W_s - (D_s + E_s)) <= 0.1 * W_s
    assert e["momentum_projectile"] <= 5e-3


@pytest.mark.slow
def test_impact_with_sphere_friction_resumes_bit_for_bit(tmp_path, monkeypatch, sphere_frictional_impact):
    """Killed at step 50 (the nose's pairs slipping) and resumed from the checkpoint: the
    same state and friction work bit for bit; without the sphere's history it differs."""
    from rve.scenes.impact.friction import SphereFriction

    cfg, x, info, ref = sphere_frictional_impact
    ck = tmp_path / "checkpoint.npz"
    with pytest.raises(SceneFailure):
        impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck, stop_after_steps=50)
    with np.load(ck) as d:
        assert float(d["friction/sphere/dissipated"]) > 0 and d["friction/sphere/keys"].shape[0] > 0
    saved = ck.read_bytes()
    res = impact.solve(cfg, x_start=x, relax_info=info, record=True, checkpoint=ck)
    assert res.summary["resumed_from_ms"] > 0
    for k in ("x", "w", "T"):
        assert np.array_equal(res.state[k], ref.state[k])
    for k in ("friction_work_sphere_mJ", "friction_dissipated_sphere_mJ", "friction_work_mJ"):
        assert res.summary["energies_mJ"][k] == ref.summary["energies_mJ"][k]
    ck.write_bytes(saved)
    monkeypatch.setattr(SphereFriction, "restore", lambda self, x_, arrays: None)
    bad = impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck)
    assert not np.array_equal(bad.state["x"], ref.state["x"])


@pytest.mark.slow
def test_impact_with_projectile_friction_alone_resumes_bit_for_bit(tmp_path, frictional_impact):
    """mu = 0, mu_p = 0.3 (the sphere's driver alone, no fibril friction term): killed at
    step 50 and resumed, the same state and sphere friction work bit for bit."""
    _, x, info, _ = frictional_impact
    cfg = load_config(IMPACT, TINY + ["time.t_end=0.03 ms", "time.steps=60", "friction.projectile=0.3"])
    ref = impact.solve(cfg, x_start=x, relax_info=info, record=True)
    assert ref.model.fabric.term.friction is None
    assert "friction_work_mJ" in ref.summary["energies_mJ"] and ref.summary["energies_mJ"]["friction_work_sphere_mJ"] > 0
    ck = tmp_path / "checkpoint.npz"
    with pytest.raises(SceneFailure):
        impact.solve(cfg, x_start=x, relax_info=info, record=False, checkpoint=ck, stop_after_steps=50)
    with np.load(ck) as d:
        assert not any(k.startswith("friction/") and not k.startswith("friction/sphere/") for k in d.files)
    res = impact.solve(cfg, x_start=x, relax_info=info, record=True, checkpoint=ck)
    assert res.summary["resumed_from_ms"] > 0
    for k in ("x", "w", "T"):
        assert np.array_equal(res.state[k], ref.state[k])
    assert res.summary["energies_mJ"] == ref.summary["energies_mJ"]
