"""The frictional static step by the incremental potential at frozen loads and the Newton
corrector (rve.solvers.frictional.frictional_solve): the same equilibrium as the residual
Newton where that converges, a root of the exact residual where it does not, a corrector
that converges faster than linearly, and a system without friction refused."""
import dataclasses

import numpy as np
import pytest

from rve.solvers.frictional import frictional_solve, frictional_static_step
from rve.solvers.static import StaticProblem


def _free_residual(system, x):
    prob = StaticProblem(system, x, np.zeros(system.n), 0.0)
    F, _, _ = system.evaluate(prob.x, prob.w, 0.0, jacobian=False)
    return float(np.linalg.norm(np.asarray(F)[prob.free]))


@pytest.fixture(scope="module")
def weave():
    """A relaxed 4x4 plain weave (one fibril per yarn, 12 el/fibril) and the affine field
    of its first shear increment (benchmarks/friction_cost.py --small)."""
    from rve.config.rve import RVEConfig
    from rve.fabrics.relaxation import relax
    from rve.fabrics.setup import clamped_ends, contact_params, fabric_and_mesh
    from rve.homogenisation.strain import affine_velocity, end_targets

    cfg = RVEConfig(scene="rve", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 12})
    fab, mesh = fabric_and_mesh(cfg)
    xr = relax(cfg).x.reshape(-1, 9)
    ends, _, _ = clamped_ends(fab, mesh)
    eps = cfg.strain.total / cfg.strain.steps

    def target(x_prev, k, n):
        """Sub-increment k of n from the state ``x_prev`` (the driven phase's field)."""
        x = x_prev.reshape(-1, 9) + affine_velocity(xr, "shear", eps / n)
        x[ends, :3] = end_targets(xr[ends, :3], "shear", eps * k / n)
        return x.reshape(-1)

    base = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=False)
    return cfg, fab, mesh, xr.reshape(-1), base, target


def _system(weave, mu=0.2):
    from rve.fabrics.setup import mechanics_system
    from rve.model.terms.friction import FrictionLaw

    cfg, fab, mesh, x0, base, _ = weave
    s = mechanics_system(fab, mesh, cfg, dataclasses.replace(base, friction=FrictionLaw(mu)), 0.0, x0)
    s.term.friction.set_families(fab.fibril_direction)
    s.term.friction.commit(x0)
    return s


def test_same_equilibrium_as_the_residual_newton_in_two_sub_increments(weave):
    """Where the capped residual Newton converges (two committed sub-increments of the shear
    increment), the potential predictor + corrector finds its equilibrium (to 1e-8 mm) and
    the same dissipation."""
    from rve.solvers.minimize import capped_newton

    _, _, _, _, _, target = weave
    # both solved far below the pipeline's 1e-9 N: the tangent's soft mode (|eigenvalue| ~
    # 6e-6) turns a residual of 1e-9 N into ~1e-8 mm
    atol = 1e-12
    a, b = _system(weave), _system(weave)
    xa = xb = weave[3]
    for k in (1, 2):
        y = target(xa, k, 2)
        a.rebuild(y)
        xa, res = frictional_solve(a, y, 0.0, atol=atol, rtol=1e-12)
        assert res.converged and res.method == "potential predictor + newton" and res.fallback_iterations == 0
        a.term.friction.commit(xa)
        y = target(xb, k, 2)
        b.rebuild(y)
        xb, _, rb = capped_newton(b, y, 0.0, atol=atol, rtol=1e-12, max_iter=100, step_cap=0.5 * b.params.margin)
        assert rb.converged
        b.term.friction.commit(xb)
        assert np.abs(xa - xb).max() <= 1e-8
    assert a.term.friction.dissipated > 0
    assert a.term.friction.dissipated == pytest.approx(b.term.friction.dissipated, rel=1e-6)


def test_whole_increment_converges_to_a_root_of_the_exact_residual(weave):
    """The whole increment at once (where the residual Newton does not converge, docs): the
    result is a root of the exact frictional residual (evaluated afresh), found by the
    predictor and a corrector whose last step contracts by > 1e3 (Newton's rate, not a
    linear one); the friction is active (slipping points)."""
    cfg, _, _, _, _, target = weave
    atol = 1e-11
    s = _system(weave)
    y = target(weave[3], 1, 1)
    s.rebuild(y)
    r0 = _free_residual(s, y)
    xs, res = frictional_solve(s, y, 0.0, atol=atol, rtol=1e-14)
    assert res.converged and res.fallback_iterations == 0 and res.corrector_iterations >= 1
    assert _free_residual(s, xs) <= atol < 1e-6 * r0
    r = res.residuals
    assert r[-1] <= 1e-3 * r[-2]
    st = s.term.friction.state(xs)
    assert st.slip.sum() > 0


def test_potential_step_of_the_crossing_equals_newton():
    """The single crossing in slip (tests/test_friction_term.py): frictional_static_step by
    the potential method and by Newton give the same state and dissipation."""
    from test_friction_term import _slid

    _, system, parts, x = _slid(cycle_steps=1, u=0.004)
    x[parts["x"]] = 0.03
    fr = system.term.friction
    rec = fr.record()
    ref, _, res, d = frictional_static_step(system, x, np.zeros(system.n), 0.0, {"atol": 1e-11, "max_iter": 30})
    assert res.converged and d > 0
    fr.seed(rec)
    xs, _, res2, d2 = frictional_static_step(system, x, np.zeros(system.n), 0.0, {"atol": 1e-11, "max_iter": 30},
                                             method="potential")
    assert res2.converged
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-9)
    assert d2 == pytest.approx(d, rel=1e-6)


def test_frictionless_system_is_refused(weave):
    from rve.fabrics.setup import mechanics_system

    cfg, fab, mesh, x0, base, _ = weave
    s = mechanics_system(fab, mesh, cfg, base, 0.0, x0)
    with pytest.raises(ValueError, match="no friction"):
        frictional_solve(s, x0)


def test_commit_keeps_the_equilibrium_and_a_near_start_is_newton_alone(weave):
    """The commit moves every point's material point to its closest point without changing a
    force, so the committed state is still an equilibrium (after a map rebuild too). A
    solve from a start within ``direct_atol`` of it is Newton alone: no predictor iteration,
    and it ends on a root of the exact residual."""
    cfg, _, _, _, _, target = weave
    atol = cfg.strain.static_atol
    s = _system(weave)
    y = target(weave[3], 1, 2)
    s.rebuild(y)
    x1, res = frictional_solve(s, y, 0.0, atol=atol, rtol=1e-12)
    assert res.converged and res.predictor_iterations > 0
    r1 = _free_residual(s, x1)
    s_bar = s.term.friction.s_bar.copy()
    s.term.friction.commit(x1)
    assert np.abs(s.term.friction.s_bar - s_bar).max() > 1e-4      # the material points moved
    s.rebuild(x1)
    assert _free_residual(s, x1) <= max(2.0 * r1, 1e-12)
    prob = StaticProblem(s, x1, np.zeros(s.n), 0.0)
    xp = x1.copy()
    xp[prob.free] += 1e-9 * np.random.default_rng(0).standard_normal(prob.free.size)
    r0 = _free_residual(s, xp)
    assert atol < r0 <= 1e4 * atol          # off balance, within direct_atol
    x2, res = frictional_solve(s, xp, 0.0, atol=atol, rtol=1e-12)
    assert res.converged and res.method == "newton" and res.predictor_iterations == 0 and res.rounds == 0
    assert _free_residual(s, x2) <= atol


def test_a_re_solve_takes_the_law_stage_alone_and_the_smoothed_stage_where_it_fails(monkeypatch):
    """An augmented-Lagrangian re-solve (``fr.resolving``) first takes the law's predictor
    stage alone without the fallback; where that fails, the caller's smoothed stages from the
    same start, with the fallback; the iterations of both passes are counted and the loads of
    the converged solve are held for the next re-solve."""
    from types import SimpleNamespace

    import rve.solvers.frictional as frictional

    held, calls = [], []
    fr = SimpleNamespace(resolving=True, hold_loads=lambda x: held.append(x))
    system = SimpleNamespace(term=SimpleNamespace(friction=fr), augmented=True)
    x0 = np.zeros(3)

    def fake(system, fr, x, t, *args):
        fallback, smoothing = args[10], args[13]
        calls.append((tuple(smoothing), bool(fallback), np.array(x)))
        ok = tuple(smoothing) != ()
        out = frictional.FrictionalResult(None, ok, 7, [1.0], "" if ok else "stalled")
        out.predictor_iterations, out.corrector_iterations, out.rounds = 5, 2, 1
        return x + (1.0 if ok else 2.0), out

    monkeypatch.setattr(frictional, "_solve", fake)
    xs, out = frictional.frictional_solve(system, x0)
    assert [(c[0], c[1]) for c in calls] == [((), False), ((1.0,), True)]
    assert np.array_equal(calls[1][2], x0)                 # the second pass from the same start
    assert out.converged and np.array_equal(xs, x0 + 1.0)
    assert out.iterations == 14 and out.predictor_iterations == 10 and out.rounds == 2
    assert len(held) == 1 and np.array_equal(held[0], xs)
    calls.clear()
    fr.resolving = False                                    # a first solve: the caller's stages only
    frictional.frictional_solve(system, x0)
    assert [(c[0], c[1]) for c in calls] == [((1.0,), True)]


def test_a_fallback_with_a_stall_window_skips_the_continuation(monkeypatch):
    """``fallback_stall`` (a try its caller can still cut): the capped Newton gets the stall
    window and a failure ends there; without it, a failure of the capped Newton goes on to the
    pseudo-transient continuation."""
    from types import SimpleNamespace

    import rve.solvers.frictional as frictional
    import rve.solvers.minimize as minimize
    import rve.solvers.static as static
    from rve.solvers.newton import NewtonResult

    capped, continued = [], []

    def fake_capped(system, x, t, *, max_iter, stall_window, **k):
        capped.append((max_iter, stall_window))
        return x, None, NewtonResult(None, False, 17, [1.0, 0.5], "stalled")

    def fake_continuation(system, x, w, t, **k):
        continued.append(k["max_iter"])
        return x, None, NewtonResult(None, False, 3, [0.5, 0.4], "stalled")

    monkeypatch.setattr(minimize, "capped_newton", fake_capped)
    monkeypatch.setattr(static, "pseudo_transient_solve", fake_continuation)
    system = SimpleNamespace(rebuild=lambda x: None, params=SimpleNamespace(margin=0.1), n=3)
    for stall, cont in ((20, []), (None, [200])):
        capped.clear()
        continued.clear()
        out = frictional.FrictionalResult(None, False, 0, [1.0])
        frictional._fallback(system, np.zeros(3), 0.0, out, 1e-9, 1e-14, 1000, None, None, stall)
        assert capped == [(1000, stall)] and continued == cont and not out.converged
        assert out.fallback_iterations == 17 + (3 if cont else 0)


def test_capped_newton_stall_test():
    """``capped_newton``'s stall test: |F| that fell by less than 1 % over the window's
    accepted iterations is a stall; a steady 5 % an iteration (the fallback that converges in
    ~100 iterations) is not, nor is a history shorter than the window, nor no window; a
    creep whose rate over the window would need more iterations than are left to reach the
    tolerance is a stall."""
    from rve.solvers.minimize import _stalled

    flat = [5.2e-5, 1.1e-5] + [6.82e-6 * (1 - 1e-5 * k) for k in range(25)]
    creep = [2.7e-5 * 0.95 ** k for k in range(40)]
    assert _stalled(flat, 20) and not _stalled(flat[:21], 20)
    assert not _stalled(creep, 20)
    assert not _stalled(flat, None) and not _stalled(flat, 0)
    # with the tolerance and the budget left: the AL cell's creep (|F| -0.07 % an iteration
    # at 4.9e-7 N, 1e-9 N about 9000 iterations away) is a stall with 900 iterations left;
    # the 5 % creep from 2.7e-5 N (about 200 iterations to 1e-9 N) is not, and is with 100
    slow = [4.9e-7 * (1 - 7e-4) ** k for k in range(25)]
    assert not _stalled(slow, 20) and _stalled(slow, 20, 1e-9, 900) and not _stalled(slow, 20, 1e-9, 10 ** 5)
    assert not _stalled(creep, 20, 1e-9, 900) and _stalled(creep, 20, 1e-9, 100)
    assert not _stalled([1e-8] * 5 + [5e-10], 3, 1e-9, 1)     # converged: no stall


class _ScriptedProblem:
    """A ``StaticProblem`` stand-in whose residuals at successive evaluations are scripted
    (the Jacobian the identity), for the corrector's full-step watchdog."""

    def __init__(self, residuals):
        self.residuals = list(residuals)
        self.calls = 0

    def u0(self):
        return np.zeros(1)

    def __call__(self, u):
        import scipy.sparse as sp
        r = self.residuals[min(self.calls, len(self.residuals) - 1)]
        self.calls += 1
        return np.array([r]), sp.identity(1, format="csr")

    def admissible(self, u):
        return True

    def state(self, u):
        return np.array(u, copy=True), None


@pytest.mark.parametrize("residuals, steps, converged, best", [
    # a step across a stick/slip change raises |F| once, then quadratic convergence
    ([1.1e-4, 8.5e-4, 6.2e-7, 1.4e-9, 7.3e-13], 4, True, 4),
    ([1.1e-4, 2.0e-2, 1e-12], 1, False, 0),          # growth beyond FULL_STEP_GROWTH: stop
    ([1.1e-4, 5.0e-4, 2.0e-4, 1e-12], 2, False, 0),  # not below the start from the second step
    ([1.1e-4, 5.0e-5, 6.0e-5, 7.0e-5, 8.0e-5, 9.0e-5, 1.0e-4, 1e-12], 6, False, 1),  # FULL_STEPS
])
def test_full_steps_let_the_residual_rise_and_keep_the_lowest(monkeypatch, residuals, steps, converged, best):
    """The corrector's watchdog (``_full_steps``): full Newton steps, |F| allowed to rise up to
    ``FULL_STEP_GROWTH`` times the start's and, from the second step on, not above the start;
    at most ``FULL_STEPS``; it returns the iterate of the lowest |F| and converges only at
    ``atol``."""
    import rve.solvers.frictional as frictional

    prob = _ScriptedProblem(residuals)
    monkeypatch.setattr(frictional, "StaticProblem", lambda *a: prob)
    system = type("S", (), {"n": 1})()
    xs, res, nres = frictional._full_steps(system, None, 0.0, 1e-9, lambda J, r: J @ r)
    assert len(res) - 1 == steps and res == residuals[:steps + 1]
    assert nres.converged is converged and nres.iterations == steps
    # the iterates are u_k = -(r_0 + ... + r_{k-1}) (J = I): the one kept is that of the lowest |F|
    assert xs[0] == pytest.approx(-sum(residuals[:best]))


def test_the_corrector_keeps_converged_full_steps_else_searches_from_the_best(monkeypatch):
    """``_corrector``: full steps that converge are the result (no line-search Newton); full
    steps that do not hand their lowest-|F| iterate to the line-search Newton, and the
    record counts both."""
    from types import SimpleNamespace

    import rve.solvers.frictional as frictional
    from rve.solvers.newton import NewtonResult

    searched = []

    def fake_static(system, x, w, t, opts):
        searched.append(np.array(x))
        return x + 1.0, None, NewtonResult(None, True, 2, [5e-5, 1e-7, 1e-12])

    monkeypatch.setattr(frictional, "static_solve", fake_static)
    system = SimpleNamespace(rebuild=lambda x: None, n=1)
    for res, ok in (([1e-4, 8e-4, 1e-7, 1e-12], True), ([1e-4, 5e-5, 2e-4], False)):
        searched.clear()
        done = (np.array([7.0]), res, NewtonResult(None, ok, len(res) - 1, res))
        monkeypatch.setattr(frictional, "_full_steps", lambda *a, done=done: done)
        out = frictional.FrictionalResult(None, False, 0, [1e-4])
        xs, nres = frictional._corrector(system, np.zeros(1), 0.0, out, 1e-9, 1e-14, 12, None)
        assert nres.converged
        if ok:
            assert not searched and xs[0] == 7.0 and nres.iterations == 3 and out.residuals[1:] == res[1:]
        else:   # the search starts from the full steps' best state, its residual 5e-5 after the start's
            assert len(searched) == 1 and searched[0][0] == 7.0 and xs[0] == 8.0
            assert nres.iterations == 2 + 2 and nres.residuals == [1e-4, 5e-5, 1e-7, 1e-12]
