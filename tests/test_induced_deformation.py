"""Induced deformation (thesis §8.3) on a reduced case: 2 x 2 single-fibril yarns (span 5 mm,
natural length 6.25 mm: the slack ratio of Table 8.1), 10 elements per fibril, a short
horizon. Checks the physics directions (docs/induced_deformation.md) against each other (B2 lifts, B3 lifts
and pushes to -y, B1 coils, reversing the current reverses the force, B = 0 is the slack
relaxation alone), the weft potential at the weakened reference until contact, the charge
and electrical balances to solver tolerance, the thermal post-solve against the monolithic
solve, and the orders of the mechanical, thermal and total balance errors in the step size."""
import numpy as np
import pytest

from rve.config.induced_deformation import InducedDeformationConfig
from rve.scenes.induced import setup, solve
from rve.fabrics.slack import crimp_amplitude, slack_weave

T_SHORT, N_SHORT = 0.2, 20   # ms, steps (h = 10 us)


def cfg(orientation="B2", **kw):
    d = dict(scene="induced_deformation",
             geometry=dict(n_warp=2, n_weft=2, span="5 mm", natural_length="6.25 mm"),
             mesh=dict(elements=10), field=dict(orientation=orientation),
             output=dict(vtk=False, png=False))
    for k, v in kw.items():
        d.setdefault(k, {})
        d[k] = {**d[k], **v} if isinstance(v, dict) else v
    return InducedDeformationConfig(**d)


_cache = {}


def run(key, c, t_end=T_SHORT, steps=N_SHORT, **kw):
    if key not in _cache:
        _cache[key] = solve(c, t_end=t_end, steps=steps, **kw)
    return _cache[key]


def warp_xyz(res):
    m = res.model
    st = res.summary["history"]["stored"]
    nodes = np.concatenate([m.mesh.fibril_nodes(f) for f in (0, 1)])
    return st["t"], st["x"][:, nodes, :3]


def nonplanarity(res) -> np.ndarray:
    """rms distance of each warp centre line from its best-fit plane, per stored time (mm)."""
    m = res.model
    X = res.summary["history"]["stored"]["x"]
    out = np.zeros(X.shape[0])
    for f in (0, 1):
        P = X[:, m.mesh.fibril_nodes(f), :3]
        P = P - P.mean(axis=1, keepdims=True)
        out += np.linalg.svd(P, compute_uv=False)[:, -1] / np.sqrt(P.shape[1])
    return out / 2


def test_slack_geometry():
    A = crimp_amplitude(10.0, 12.5, 4)
    w = slack_weave(4, 4, 10.0, 12.5, 0.4, 0.6, 200)
    assert w.amplitude_warp == pytest.approx(A)
    r = w.x0[w.mesh.fibril_nodes(0), :3]
    assert np.linalg.norm(np.diff(r, axis=0), axis=1).sum() == pytest.approx(12.5, rel=1e-4)
    assert r[0, 0] == pytest.approx(-5.0) and r[-1, 0] == pytest.approx(5.0)
    assert w.clearance > 0  # the yarns start apart (thesis: first frame, no contact)
    g1, g2 = w.x0[:, 3:6], w.x0[:, 6:9]
    assert np.allclose((g1 * g2).sum(1), 0, atol=1e-12) and np.allclose(np.linalg.norm(g1, axis=1), 1)


def test_setup_circuit_and_dofs():
    p = setup(cfg())
    assert p.model.layout.fields == ("mech", "V")
    assert len(p.circuit_in) == 2 and len(p.circuit_leak) == 2
    assert all(c.J_bar < 0 for c in p.circuit_in)
    assert setup(cfg(), "monolithic").model.layout.fields == ("mech", "T", "V")


def test_B2_lifts_and_balances():
    r = run("B2", cfg("B2"))
    s = r.summary
    d = s["mean_displacement_mm"]
    assert d[2] > 0.05 and abs(d[0]) < 0.05 * d[2] and abs(d[1]) < 0.05 * d[2]
    assert s["charge_balance_error"] <= 1e-8
    assert s["balance_errors"]["electrical"] <= 1e-7
    assert s["terminal_current_A"] > 0
    assert s["max_temperature_K"] > 0


def test_B3_up_and_minus_y():
    d = run("B3", cfg("B3")).summary["mean_displacement_mm"]
    assert d[2] > 0.05 and d[1] < -0.02


def test_B1_coils_the_warp():
    p1 = nonplanarity(run("B1", cfg("B1")))
    p2 = nonplanarity(run("B2", cfg("B2")))
    assert p1[0] < 1e-12 and p1[-1] > 10 * max(p2[-1], 1e-6)
    assert np.all(np.diff(p1[1:]) > 0)  # grows


def test_reversing_current_reverses_force():
    d = np.array(run("B2", cfg("B2")).summary["mean_displacement_mm"])
    rev = cfg("B2", warp={"radius": "0.4 mm", "r_bar": "100 A/(mm^2*V)", "J_bar": "1000 A/mm^2"})
    dr = np.array(run("B2rev", rev).summary["mean_displacement_mm"])
    d0 = np.array(run("B0", cfg("B2", field={"magnitude": "0 kT"})).summary["mean_displacement_mm"])
    assert dr[2] < 0
    # what the field adds is odd in the current: (d - d0) = -(dr - d0) to first order
    assert (dr - d0)[2] == pytest.approx(-(d - d0)[2], rel=0.15)


def test_no_field_only_slack_relaxation():
    r0 = run("B0", cfg("B2", field={"magnitude": "0 kT"}))
    off = cfg("B2", field={"magnitude": "0 kT"},
              warp={"radius": "0.4 mm", "r_bar": "100 A/(mm^2*V)", "J_bar": "0 A/mm^2"})
    rn = run("B0_nocurrent", off)
    x0 = r0.model.nodal(r0.state["x"])[:, :3]
    xn = rn.model.nodal(rn.state["x"])[:, :3]
    assert np.abs(x0 - xn).max() < 1e-8  # the current alone moves nothing
    d0 = r0.summary["mean_displacement_mm"][2]
    d2 = run("B2", cfg("B2")).summary["mean_displacement_mm"][2]
    assert abs(d0) < 0.2 * abs(d2)
    assert rn.summary["terminal_current_A"] == 0.0 or abs(rn.summary["terminal_current_A"]) < 1e-9


def test_weft_potential_weakened_until_contact():
    r = run("B3long", cfg("B3"), t_end=1.0, steps=100)
    h = r.summary["history"]
    b, st = h["balances"], h["stored"]
    m = r.model
    weft_nodes = np.concatenate([m.mesh.fibril_nodes(f) for f in (2, 3)])
    warp_nodes = np.concatenate([m.mesh.fibril_nodes(f) for f in (0, 1)])
    Vw = np.array([m.nodal(w)[weft_nodes, m.oV] for w in st["w"]])
    Vwarp = np.array([m.nodal(w)[warp_nodes, m.oV] for w in st["w"]])
    contact_t = b["t"][np.flatnonzero(b["contact_active_pairs"] > 0)]
    assert contact_t.size, "no contact within the horizon"
    before = st["t"] < contact_t[0]
    assert before.sum() >= 2
    # isolated: at the pull-down reference (0 V) up to the motional EMF, tiny next to the warp
    assert np.abs(Vw[before]).max() < 1e-2 * np.abs(Vwarp).max()
    # in contact: the weft takes the potential of the warp it touches
    last = np.abs(Vw[-1]).max()
    assert last > 0.05 * np.abs(Vwarp[-1]).max() and last <= np.abs(Vwarp[-1]).max() * (1 + 1e-6)
    assert r.summary["charge_balance_error"] <= 1e-8


def test_post_temperature_equals_monolithic():
    rp = run("B2", cfg("B2"))
    rm = run("B2mono", cfg("B2"), mode="monolithic")
    Tp, Tm = rp.state["T"], rm.state["T"]
    assert np.abs(Tp - Tm).max() <= 1e-6 * np.abs(Tm).max()
    assert rm.summary["dofs"]["total"] > rp.summary["dofs"]["total"]


def test_balance_orders():
    """The mechanical, thermal and total energy balances close at the order of the 2-stage
    SDIRK (>= 1.7) as h halves; the charge balance stays at solver tolerance."""
    errs = {k: [] for k in ("mechanical", "thermal", "total", "charge")}
    for n in (10, 20, 40):
        e = solve(cfg("B2"), t_end=0.05, steps=n, record=False).summary["balance_errors"]
        for k in errs:
            errs[k].append(e[k])
    for k in ("mechanical", "thermal", "total"):
        orders = np.log2(np.array(errs[k][:-1]) / np.array(errs[k][1:]))
        assert np.all(orders >= 1.7), (k, errs[k], orders)
    assert max(errs["charge"]) <= 1e-8


def _pressed_state(orientation="B3"):
    """The reduced weave with every z scaled by 0.6 (the crossings overlap), a potential
    linear along each fibril and a velocity field, on the monolithic (mech, T, V) layout."""
    p = setup(cfg(orientation), "monolithic")
    b = p.model
    x = p.x0.copy()
    xn = b.nodal(x)
    xn[:, 2] *= 0.6
    w = np.zeros(b.n)
    wn = b.nodal(w)
    rng = np.random.default_rng(3)
    wn[:, :3] = rng.normal(scale=0.5, size=(b.mesh.n_nodes, 3))
    for f in range(b.mesh.n_fibrils):
        nodes = b.mesh.fibril_nodes(f)
        wn[nodes, b.oV] = np.linspace(0.3, 0.0, nodes.size) * (1 + 0.1 * f)
    p.system.rebuild(x)
    return p, x, w


def test_contact_heat_block_and_joule_match_the_monolithic_terms():
    """The post-solve's operators against the monolithic system's own T rows at a pressed
    state: the contact heat transfer K_c T equals the change of the monolithic contact
    residual's T rows with T (the term is linear in T), heat_transfer_block equals
    scalar_jump's Ju, and the (compiled) Joule heat equals the numpy reference and minus the
    monolithic Joule rows' T-independent part."""
    from rve.physics.contact_forms import scalar_jump
    from rve.model.thermal_post import ThermalOperators, heat_transfer_block

    p, x, w = _pressed_state()
    sysm, b = p.system, p.model
    c = cfg("B3")
    ops = ThermalOperators(sysm, c.contact.heat_transfer, p.fixed_T_nodes)
    act = ops.active_pairs(x)
    assert act.size >= 2
    rng = np.random.default_rng(0)
    T = rng.uniform(0.0, 5.0, b.mesh.n_nodes)
    w1 = w.copy()
    b.nodal(w1)[:, b.oT] = T
    F1 = b.nodal(sysm.contact_terms(x, w1, jacobian=False)[0])[:, b.oT]
    F0 = b.nodal(sysm.contact_terms(x, w, jacobian=False)[0])[:, b.oT]
    KcT = ops.contact_apply(x, T)
    assert np.abs(KcT).max() > 0
    assert np.abs(KcT - (F1 - F0)).max() <= 1e-12 * np.abs(F1 - F0).max()
    assert np.abs(ops.contact(x) @ T - KcT).max() <= 1e-13 * np.abs(KcT).max()
    term = sysm.term
    geo = term.geometry(x, act)
    z = np.zeros((act.size, 2))
    Ju = scalar_jump(geo, 1, z, z, term.weight[act], 0.1, term.kappa[act], term.g_eps, True)[1]
    Jl = heat_transfer_block(geo, 1, term.weight[act], 0.1, term.kappa[act], term.g_eps)
    assert np.abs(Jl - Ju).max() <= 1e-14 * np.abs(Ju).max()
    Q = ops.joule_now(x, w, 0.01)
    Qref = b.joule_power(x, w, 0.01)
    assert Qref.max() > 0 and np.abs(Q - Qref).max() <= 1e-12 * Qref.max()
    # monolithic T rows: conduction + contact + (-Joule); at T = 0 only -Joule is left
    FT0 = b.nodal(sysm.evaluate(x, w, 0.01, jacobian=False)[0])[:, b.oT]
    assert np.abs(-FT0 - Qref).max() <= 1e-12 * Qref.max()


T_CONTACT, N_CONTACT = 0.3, 30   # ms, steps: reduced B3, contact from ~0.11 ms


def test_post_temperature_equals_monolithic_with_contact(monkeypatch):
    """Through the contact phase (the post-solve's refinement path): post vs monolithic to
    1e-6 relative; and, on the same stage states of that run, the post-solve with
    its reuse (kept factor, iterative refinement, compiled Joule, memoised operators) vs the
    plain reference (a fresh direct solve per stage, numpy Joule, scalar_jump) to round-off.
    (Two runs of the mechanics are not bitwise equal: ~1e-11 mm between repeated runs in one
    process, so the reuse is checked on shared stage states, not across runs.)"""
    import rve.scenes.induced.scene as scene
    from rve.scenes.thermal_post import ThermalPostSolver

    twins = []

    class Twin(ThermalPostSolver):
        def __init__(self, ops, tab, T_fixed=0.0, reuse=True):
            super().__init__(ops, tab, T_fixed, reuse=reuse)
            self.fresh = ThermalPostSolver(ops, tab, T_fixed, reuse=False)
            self.T_fresh, self.dev = None, 0.0
            twins.append(self)

        def step(self, T0, stages, t0, h):
            T = super().step(T0, stages, t0, h)
            self.T_fresh = self.fresh.step(T0 if self.T_fresh is None else self.T_fresh, stages, t0, h)
            self.dev = max(self.dev, float(np.abs(T - self.T_fresh).max() / max(np.abs(T).max(), 1e-300)))
            return T

    monkeypatch.setattr(scene, "ThermalPostSolver", Twin)
    rp = solve(cfg("B3"), t_end=T_CONTACT, steps=N_CONTACT, record=True)
    monkeypatch.undo()
    rm = run("B3c_mono", cfg("B3"), t_end=T_CONTACT, steps=N_CONTACT, record=True, mode="monolithic")
    assert max(rp.summary["history"]["balances"]["contact_active_pairs"]) >= 1
    assert rp.summary["thermal_post_refinements"] > 0 and rp.summary["thermal_post_fallbacks"] == 0
    tw = twins[-1]
    assert tw.fresh.refinements == 0 and tw.fresh.solves == rp.summary["steps_accepted"] * 2
    Tp, Tm = rp.state["T"], rm.state["T"]
    assert np.abs(Tp - Tm).max() <= 1e-6 * np.abs(Tm).max()
    assert tw.dev <= 1e-13, tw.dev
    assert np.abs(Tp - tw.T_fresh).max() <= 1e-13 * np.abs(Tp).max()


def _dense_stage_solve(ops, tab, T0, stages, t0, h, T_fixed=0.0):
    """Independent reference: the SDIRK stage equations of M T' + (K + K_c) T = Q on the
    free nodes, dense, with K_c from scalar_jump and Q from BeamModel.joule_power."""
    from rve.physics.contact_forms import scalar_jump

    term, b = ops.system.term, ops.base
    conn = b.mesh.conn
    M, K = ops.M.toarray(), ops.K.toarray()
    fr, fx = ops.free, ops.fixed
    Fs = []
    for i, (x, w) in enumerate(stages):
        act = term.active_pairs(x)
        Kc = np.zeros_like(M)
        if act.size:
            z = np.zeros((act.size, 2))
            Ju = scalar_jump(term.geometry(x, act), 1, z, z, term.weight[act], ops.h_C, term.kappa[act],
                             term.g_eps, True)[1]
            loc = np.concatenate([conn[term.map.e_plus[act]], conn[term.map.e_minus[act]]], axis=1)
            for p_ in range(act.size):
                Kc[np.ix_(loc[p_], loc[p_])] += Ju[p_]
        ha = h * tab.A[i, i]
        Q = b.joule_power(x, w, t0 + tab.c[i] * h)
        rhs = M @ T0 + ha * Q - sum(h * tab.A[i, j] * Fs[j] for j in range(i))
        A = M + ha * (K + Kc)
        T = np.full(ops.n, T_fixed)
        T[fr] = np.linalg.solve(A[np.ix_(fr, fr)], rhs[fr] - A[np.ix_(fr, fx)] @ T[fx])
        Fs.append((K + Kc) @ T - Q)
    return T


@pytest.mark.parametrize("h_C", [0.1, 1.0e4])
def test_post_step_refinement_and_fallback(h_C):
    """One post-solve step with active contact pairs at two stage states: the kept factor +
    iterative refinement (h_C = 0.1, the scene's value) and its direct fallback (h_C = 1e4,
    a contact far stiffer than the capacity: the refinement does not contract) against the
    plain reference and a dense solve of the stage equations, to round-off."""
    from rve.model.thermal_post import ThermalOperators
    from rve.scenes.thermal_post import ThermalPostSolver
    from rve.solvers.dirk import sdirk

    p, x, w = _pressed_state()
    b = p.model
    x1 = x.copy()
    b.nodal(x1)[:, 2] *= 0.98
    ops = ThermalOperators(p.system, h_C, p.fixed_T_nodes)
    assert ops.active_pairs(x1).size and ops.active_pairs(x).size
    T0 = np.random.default_rng(1).uniform(0.0, 5.0, ops.n)
    T0[ops.fixed] = 0.0
    tab, h = sdirk(2), 0.005
    stages = [(x1, w), (x, w)]
    new = ThermalPostSolver(ops, tab)
    T = new.step(T0, stages, 0.1, h)
    Tf = ThermalPostSolver(ops, tab, reuse=False).step(T0, stages, 0.1, h)
    Td = _dense_stage_solve(ops, tab, T0, stages, 0.1, h)
    assert np.abs(T - Td).max() <= 1e-12 * np.abs(Td).max()
    assert np.abs(T - Tf).max() <= 1e-12 * np.abs(Td).max()
    assert np.abs(Td - ThermalPostSolver(ThermalOperators(p.system, 0.0, p.fixed_T_nodes), tab).step(
        T0, stages, 0.1, h)).max() > 1e-9 * np.abs(Td).max()   # the contact term matters here
    if h_C < 1:
        assert new.refinements >= 2 and new.fallbacks == 0
    else:
        assert new.fallbacks == 2

