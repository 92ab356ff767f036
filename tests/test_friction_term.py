"""The friction term in the assembled contact system: mu = 0 adds nothing, the assembled
tangent is exact and unsymmetric (the LU path), the history follows map rebuilds and
records by point key, per-family coefficients, and the config's checks."""
import numpy as np
import pytest

from rve.config import ConfigError
from rve.config.loader import load_config
from rve.model.contact_model import ContactSystem
from rve.model.terms.contact import ContactParams
from rve.model.terms.friction import FrictionLaw, match_rows
from rve.scenes import friction_crossing
from rve.scenes.frictional import initial_state, step
from rve.solvers.linear import is_symmetric, sparse_solve
from rve.testing import fd_jacobian

CFG = "configs/scenes/crossing.yaml"


def _slid(overrides=(), cycle_steps=3, u=0.05):
    """The crossing indented and its slider's ends moved to ``u`` (slip at u = 0.05)."""
    cfg = load_config(CFG, list(overrides))
    system, parts = friction_crossing.setup(cfg)
    x = initial_state(system.mesh, system.layout)
    z0 = x[parts["z"]].copy()
    for k in (1, 2):
        x[parts["z"]] = z0 - cfg.geometry.indentation * k / 2
        x, _, _ = step(system, x, 0.0, cfg.newton, "t", "indent", k)
    for k in range(1, cycle_steps + 1):
        x[parts["x"]] = u * k / cycle_steps
        x, _, _ = step(system, x, 0.0, cfg.newton, "t", "cycle", k)
    return cfg, system, parts, x


@pytest.mark.parametrize("regime, shift", [("stick", -0.002), ("slip", 0.002)])
def test_assembled_tangent_exact_and_unsymmetric(regime, shift):
    cfg, system, parts, x = _slid(cycle_steps=2, u=0.04)   # committed in slip
    x[parts["contact_x"]] += shift   # a trial state: the contact point moved back (stick) or on (slip)
    fr = system.term.friction
    st = fr.state(x)
    assert (st.stick.sum() if regime == "stick" else st.slip.sum()) == 1
    w = np.zeros(system.n)
    F, Fx, _ = system.evaluate(x, w, 0.0)
    mid = cfg.mesh.elements // 2
    cols = system.layout.dofs("mech", system.mesh.conn[mid])
    J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], x, cols, eps=1e-7)
    A = Fx.toarray()[:, cols]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())
    if regime == "slip":
        assert not is_symmetric(Fx)
        b = np.random.default_rng(0).normal(size=system.n)
        free = np.setdiff1d(np.arange(system.n), system.constraints(0.0)[0])
        K = Fx[free][:, free]
        du = sparse_solve(K, b[free])
        assert np.linalg.norm(K @ du - b[free]) <= 1e-8 * np.linalg.norm(b[free])


def test_zero_coefficient_adds_nothing():
    assert not FrictionLaw(0.0).enabled and not FrictionLaw(0.0, 1.0, (("warp", "weft", 0.0),)).enabled
    cfg, system, parts, x = _slid(["friction.coefficient=0.0"])
    assert system.term.friction is None
    w = np.zeros(system.n)
    F, Fx, _ = system.evaluate(x, w, 0.0)
    plain = ContactSystem(system.base, ContactParams(penalty=cfg.contact.penalty, n_gp=cfg.contact.n_gp,
                                                     margin=0.5 * cfg.geometry.radius), x)
    system.rebuild(x)
    F1, Fx1, _ = system.evaluate(x, w, 0.0)
    F2, Fx2, _ = plain.evaluate(x, w, 0.0)
    assert np.array_equal(F1, F2) and np.array_equal(Fx1.data, Fx2.data) and np.array_equal(Fx1.indices, Fx2.indices)


def check_history_survives_rebuilds_and_records(cfg, system, parts, x, du: float) -> None:
    """With a committed stick history at ``x`` and the slider moved by ``du``: a rebuild at
    ``x`` keeps every force (history by key); a fresh system differs until seeded with the
    record, then equals it; a map without the pair forgets it, and the pair's return starts
    with no elastic gap."""
    fr = system.term.friction
    w = np.zeros(system.n)
    x2 = x.copy()
    x2[parts["x"]] += du
    F_before = system.evaluate(x2, w, 0.0, jacobian=False)[0]
    system.rebuild(x)                               # same pairs, history by key
    assert np.array_equal(system.evaluate(x2, w, 0.0, jacobian=False)[0], F_before)
    rec = fr.record()
    other = friction_crossing.setup(cfg)[0]
    other.rebuild(x)
    assert not np.array_equal(other.evaluate(x2, w, 0.0, jacobian=False)[0], F_before)
    other.term.friction.seed(rec)
    assert np.array_equal(other.evaluate(x2, w, 0.0, jacobian=False)[0], F_before)
    far = x.copy()
    far.reshape(-1, system.layout.block)[system.mesh.fibril_nodes(0), 2] += 1.0
    system.rebuild(far)
    assert system.term.map.n_pairs == 0 and system.term.friction.keys.shape[0] == 0
    system.rebuild(x)
    assert np.abs(system.term.friction.state(x).t).max() == 0.0


def test_history_survives_rebuilds_and_records():
    cfg, system, parts, x = _slid(cycle_steps=1, u=0.004)   # stick with an elastic gap
    fr = system.term.friction
    assert fr.last.stick.sum() == 1 and np.abs(fr.last.t).max() > 0
    check_history_survives_rebuilds_and_records(cfg, system, parts, x, 0.002)


def test_family_coefficients():
    cfg, system, parts, x = _slid(["friction.coefficient=0.3"], cycle_steps=1, u=0.004)
    fr = system.term.friction
    assert np.allclose(fr.mu_pair, 0.3)
    fr.law = FrictionLaw(0.3, 1.0, (("weft", "warp", 0.05),))
    fr.set_families(["warp", "weft"])
    assert np.allclose(fr.mu_pair, 0.05)
    fr.set_families(["warp", "warp"])
    assert np.allclose(fr.mu_pair, 0.3)
    with pytest.raises(ValueError, match="one label per fibril"):
        fr.set_families(["warp"])


def test_match_rows():
    a = np.array([[1, 2], [3, 4], [5, 6]])
    b = np.array([[5, 6], [1, 2]])
    assert list(match_rows(a, b)) == [1, -1, 0]


@pytest.mark.parametrize("override, text", [
    ("friction.coefficient=2.5", "friction.coefficient"),
    ("friction.coefficient=-0.1", "friction.coefficient"),
    ("friction.stiffness=0", "friction.stiffness"),
    ("friction.pairs={warp-wool: 0.2}", "must be 'a-b' with a, b in ('warp', 'weft', 'loop')"),
    ("friction.pairs={warp-weft: 3.0}", "must be in [0, 2.0]"),
    ("friction.pairs={warp-weft: 0.2, weft-warp: 0.3}", "name the same pair"),
])
def test_config_errors_name_the_key_and_range(override, text):
    with pytest.raises(ConfigError) as err:
        load_config(CFG, [override])
    assert text in str(err.value), str(err.value)
    with pytest.raises(ValueError):
        FrictionLaw(2.5)


def test_relaxation_of_a_frictional_system_solves_the_residual():
    from rve.solvers.frictional import frictional_static_step
    from rve.solvers.minimize import minimize_energy
    from rve.solvers.relaxation import RelaxSettings, relax_to_equilibrium

    cfg, system, parts, x = _slid(cycle_steps=1, u=0.004)
    x[parts["x"]] = 0.03                        # the ends moved on: stick turns into slip
    with pytest.raises(ValueError, match="friction"):
        minimize_energy(system, x)
    rec = system.term.friction.record()
    ref, _, res, d = frictional_static_step(system, x, np.zeros(system.n), 0.0, {"atol": 1e-11, "max_iter": 30})
    assert res.converged and d > 0
    system.term.friction.seed(rec)              # back to the history of the last converged state
    out = relax_to_equilibrium(system, x, np.zeros(system.n),
                               RelaxSettings(duration=1.0, steps=1, method="energy", static_atol=1e-11))
    assert out.static_converged and out.history[0]["method"] == "potential predictor + newton"
    np.testing.assert_allclose(out.x, ref, rtol=0, atol=1e-9)
    assert system.term.friction.dissipated == pytest.approx(rec["dissipated"] + d, rel=1e-6)


def test_history_shared_with_the_neighbouring_element():
    """A point out of contact takes the stick state of the same + point on the neighbouring
    element of the - fibril: the same material point (collinear chords) and the same
    elastic gap, so the contact carries it on to the next element."""
    cfg, system, parts, x = _slid(["geometry.base_elements=2", "geometry.base_offset=0.1 mm"], cycle_steps=2,
                                  u=0.012)   # stick, elastic gap ~0.01 mm; the base node at x = 0.1
    fr, term = system.term.friction, system.term
    geo = term.geometry(x)
    on = geo.active.ravel()
    assert on.sum() == 1 and fr.last.stick.sum() == 1
    keys = fr.keys
    d = np.flatnonzero(on)[0]
    r = np.flatnonzero((keys[:, 0] == keys[d, 0]) & (keys[:, 1] == keys[d, 1]) & (np.abs(keys[:, 2] - keys[d, 2]) == 1))
    assert r.size == 1
    r = r[0]
    G = cfg.contact.n_gp
    X = np.stack(term.ends(x), 1)
    def q(i):                       # position of the - material point of point i
        s = fr.s_bar.ravel()[i]
        return (1 - s) * X[i // G, 2] + s * X[i // G, 3]
    np.testing.assert_allclose(q(r), q(d), atol=1e-12)
    from rve.physics.friction_forms import tangential_gap
    e = tangential_gap(geo, X, fr.s_bar, fr.anchor).reshape(-1, 3)
    assert np.linalg.norm(e[d]) > 5e-3
    p = X[r // G, 0] + geo.s_plus.ravel()[r] * (X[r // G, 1] - X[r // G, 0])
    u_r = fr.anchor.reshape(-1, 3)[r] + p - q(r)   # the receiver's gap before its own projection
    np.testing.assert_allclose(u_r, e[d], atol=1e-12)


def test_tangent_exact_with_temperature_and_potential_fields():
    """With T and V on the pairs (local layout: both elements' nodes x (r, T, V)) the friction
    blocks land on the chord ends' r rows and columns: the assembled Fx against differences."""
    from rve.model import BeamMaterial, BeamModel, DirichletBC

    cfg, mech, parts, x_m = _slid(cycle_steps=2, u=0.04)
    mesh = mech.mesh
    mat = BeamMaterial(youngs_modulus=cfg.material.youngs_modulus, electrical_conductivity=10.0,
                       thermal_conductivity=1.0)
    probe = BeamModel(mesh, mat, fields=("mech", "T", "V"))
    lay = probe.layout
    a, b = mesh.end_nodes(0)
    held = np.concatenate([lay.dofs("mech", [a, b]), lay.dofs("mech", mesh.fibril_nodes(1)),
                           lay.dofs("T", [a]), lay.dofs("V", [a])])
    base = BeamModel(mesh, mat, fields=("mech", "T", "V"), bcs=[DirichletBC(held, 0.0)])
    params = ContactParams(penalty=cfg.contact.penalty, n_gp=1, margin=0.05, heat_transfer=0.1, conductance=1.0,
                           friction=FrictionLaw(0.3, 0.1))
    x = np.zeros(lay.n)
    lay.as_nodal(x)[:, :9] = mech.layout.as_nodal(x_m)
    system = ContactSystem(base, params, x)
    assert system.term.m == 4 and system.term.nC == 5
    system.term.friction.seed(mech.term.friction.record())
    w = np.zeros(lay.n)
    lay.as_nodal(w)[:, lay.offset["T"]] = np.linspace(0.0, 1.0, mesh.n_nodes)
    lay.as_nodal(w)[:, lay.offset["V"]] = np.linspace(1.0, 0.0, mesh.n_nodes)
    x[lay.dofs("r", mesh.conn[cfg.mesh.elements // 2], comp=0)] += 0.002      # slip on
    assert system.term.friction.state(x).slip.sum() == 1
    F, Fx, Fw = system.evaluate(x, w, 0.0)
    cols = lay.dofs("mech", mesh.conn[cfg.mesh.elements // 2])
    J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], x, cols, eps=1e-7)
    A = Fx.toarray()[:, cols]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())
    rows = lay.dofs("r", mesh.conn[cfg.mesh.elements // 2], comp=0)
    fx_plain = ContactSystem(base, ContactParams(penalty=cfg.contact.penalty, n_gp=1, margin=0.05, heat_transfer=0.1,
                                                 conductance=1.0), x).evaluate(x, w, 0.0)[0]
    assert np.abs(F[rows] - fx_plain[rows]).max() > 1e-3      # the friction force is in the r rows


def test_dynamic_relaxation_commits_every_step():
    """The damped dynamic relaxation of a frictional system commits the history after every
    accepted step: pushed on from a slipping state, it dissipates, and the static round
    ends on the Coulomb limit (the supports' tangential force = mu N)."""
    from rve.model import BeamMaterial, BeamModel
    from rve.scenes.frictional import reaction
    from rve.solvers.relaxation import RelaxSettings, relax_to_equilibrium

    cfg, system, parts, x = _slid(cycle_steps=2, u=0.04)
    base = BeamModel(system.mesh, BeamMaterial(youngs_modulus=cfg.material.youngs_modulus, damping=50.0),
                     bcs=system.base.bcs)
    damped = ContactSystem(base, system.params, x)
    damped.term.friction.seed(system.term.friction.record())
    d0 = damped.term.friction.dissipated
    x[parts["x"]] = 0.06
    commits = []
    fr = damped.term.friction
    original = fr.commit
    fr.commit = lambda xx: commits.append(1) or original(xx)
    out = relax_to_equilibrium(damped, x, np.zeros(damped.n), RelaxSettings(
        duration=2.0, steps=10, rebuild_every=5, static_atol=1e-11, static_max_iter=40))
    assert out.static_converged and len(commits) >= out.dynamic_steps + 1
    assert fr.dissipated > d0
    pts = fr.points()
    F = reaction(damped, out.x, parts["x"]).sum()
    assert pts["slip"] == 1
    np.testing.assert_allclose(F, cfg.friction.coefficient * pts["normal_force"], rtol=1e-6)


def test_cell_static_step_of_a_frictional_system():
    from rve.homogenisation.cell_statics import static_minimize
    from rve.solvers.frictional import frictional_static_step

    cfg, system, parts, x = _slid(cycle_steps=1, u=0.004)
    x[parts["x"]] = 0.03
    rec = system.term.friction.record()
    ref, _, res, _ = frictional_static_step(system, x, np.zeros(system.n), 0.0, {"atol": 1e-11, "max_iter": 30})
    system.term.friction.seed(rec)
    xs, info = static_minimize(system, x, 1e-11, 40)
    assert info["converged"] and info["method"] == "friction"
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("case", ["stick", "slip", "separated"])
def test_frozen_loads_are_a_potential_of_the_assembled_system(case):
    """With the loads frozen (FrictionTerm.freeze) the assembled residual is the gradient of
    system.energy (penalty + beams + the incremental potential) and its tangent the exact
    Hessian, also where the pair has separated (the frozen load still acts: the potential
    is smooth); a rebuild carries the frozen loads by point key (the energy unchanged);
    the energy minimiser accepts the system only while its loads are frozen."""
    from rve.solvers.minimize import minimize_energy

    cfg, system, parts, x = _slid(cycle_steps=2, u=0.04)
    fr = system.term.friction
    fr.freeze(None)                                     # the loads of the committed state
    f0 = fr.frozen_loads()["f0"]
    assert f0.max() > 0
    y = x.copy()
    y[parts["contact_x"]] += {"stick": -0.002, "slip": 0.002, "separated": 0.002}[case]
    if case == "separated":
        lay, mesh = system.layout, system.mesh
        node = parts["contact_x"][0] // lay.block
        slider = next(f for f in range(mesh.n_fibrils) if node in mesh.fibril_nodes(f))
        y.reshape(-1, lay.block)[mesh.fibril_nodes(slider), 2] += 0.03    # the slider lifted off
        assert system.term.map.n_pairs == 1
        assert system.active_pairs(y).size == 0
    w = np.zeros(system.n)
    F, Fx, _ = system.evaluate(y, w, 0.0)
    mech = system.layout.dofs("mech", system.mesh.conn[cfg.mesh.elements // 2])
    assert np.abs(F[mech]).max() > 1e-6
    g = fd_jacobian(lambda v: np.array([system.energy(v)]), y, mech, eps=1e-7)[0]
    np.testing.assert_allclose(F[mech], g, rtol=1e-5, atol=1e-6 * np.abs(F[mech]).max())
    J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], y, mech, eps=1e-7)
    A = Fx.toarray()[:, mech]
    np.testing.assert_allclose(A, J, rtol=1e-5, atol=1e-6 * np.abs(A).max())
    e0 = system.energy(y)
    system.rebuild(y)
    assert system.energy(y) == pytest.approx(e0, rel=1e-12)
    np.testing.assert_array_equal(fr.frozen_loads()["f0"], f0)
    minimize_energy(system, y, max_iter=1)              # accepted while frozen
    fr.unfreeze()
    with pytest.raises(ValueError, match="friction"):
        minimize_energy(system, y, max_iter=1)
