"""Adaptive factorisation reuse (modified Newton) in the SDIRK stage solves.

docs/time_integration.md "Factorisation reuse (modified Newton)". On the manufactured
problems of tests/test_dirk.py: reuse gives the full-Newton solution to the Newton
tolerance with fewer factorisations and the same convergence orders; a stiff term switching
on, a pattern change, a constraint change and a failed step each drop the factorisation
(counted); reuse off is bit for bit the code before reuse existed (commit 9569e2a).
"""
import importlib.util
import logging
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.dirk import ReusePolicy, integrate, integrator_options
from rve.solvers.newton import JacobianReuse, newton
from rve.solvers.system import DynamicSystem
from test_dirk import (MF_STEPS, PR_STEPS, TIGHT, Manufactured, ProtheroRobinson, Rigged, X, dX, fd_check,
                       manufactured_initial, observed_order)

ROOT = Path(__file__).resolve().parents[1]
#: the commit before factorisation reuse: default-off must reproduce it bit for bit
BEFORE_REUSE = "9569e2a"


# ----------------------------------------------------------------------------- test systems
class Chain:
    """n masses on a line, nonlinear springs (k x + k3 x^3 between neighbours), damping c,
    pinned ends (velocity 0), forced so that x_j(t) = a_j sin(omega t) exactly. Narrowly
    banded (the kept banded LU). ``structure_version`` / ``extra_zeros``: a different stored
    sparsity pattern (explicit zeros coupling dof 1 to every other dof) and its token; with
    ``hold_from`` the dof ``hold_dof`` becomes velocity-driven (exactly) from that time on."""

    def __init__(self, n=12, k=40.0, k3=200.0, c=0.3, omega=2.0, hold_from=None, hold_dof=3):
        self.n, self.k, self.k3, self.c, self.omega = n, k, k3, c, omega
        self.mech = np.ones(n, dtype=bool)
        self.amp = 0.1 * np.sin(np.pi * np.arange(n) / (n - 1))
        self.structure_version = 0
        self.extra_zeros = False
        self.hold_from, self.hold_dof = hold_from, hold_dof

    def mass(self):
        return sp.identity(self.n, format="csr")

    def exact(self, t):
        return self.amp * np.sin(self.omega * t), self.amp * self.omega * np.cos(self.omega * t)

    def _springs(self, x):
        d = np.diff(x)
        f = self.k * d + self.k3 * d**3
        out = np.zeros(self.n)
        out[:-1] -= f
        out[1:] += f
        kd = self.k + 3 * self.k3 * d**2
        main = np.zeros(self.n)
        main[:-1] += kd
        main[1:] += kd
        K = sp.diags([main, -kd, -kd], [0, 1, -1], format="csr")
        return out, K

    def forcing(self, t):
        x, v = self.exact(t)
        a = -self.omega**2 * x
        return a + self.c * v + self._springs(x)[0]

    def evaluate(self, x, w, t, jacobian=True):
        fs, K = self._springs(x)
        F = self.c * w + fs - self.forcing(t)
        if not jacobian:
            return F, None, None
        Fw = self.c * sp.identity(self.n, format="csr")
        if self.extra_zeros:
            Z = sp.csr_matrix((np.zeros(self.n - 1), (np.ones(self.n - 1, int), np.r_[0, 2:self.n])),
                              shape=(self.n, self.n))
            K = (K + Z).tocsr()
            K.data[K.data == 0] = 0.0  # keep them stored
        return F, K, Fw

    def constraints(self, t):
        idx = [0, self.n - 1]
        vals = [0.0, 0.0]
        if self.hold_from is not None and t >= self.hold_from - 1e-12:
            idx.append(self.hold_dof)
            vals.append(self.exact(t)[1][self.hold_dof])
        return np.array(idx), np.array(vals)

    def admissible(self, x):
        return True

    def initial(self):
        x, v = self.exact(0.0)
        return x.copy(), v.copy()


class SwitchingPR(ProtheroRobinson):
    """Prothero-Robinson whose stiffness λ jumps from ``lam`` to ``lam_on`` at ``t_on``
    (the exact solution stays y = sin t): a held factorisation of the soft stage matrix
    no longer contracts once the stiff term is on."""

    def __init__(self, lam=-5.0, lam_on=-5000.0, t_on=0.5):
        super().__init__(lam)
        self.lam0, self.lam_on, self.t_on = lam, lam_on, t_on

    def evaluate(self, x, w, t, jacobian=True):
        self.lam = self.lam_on if t > self.t_on else self.lam0
        return super().evaluate(x, w, t, jacobian)


def _load_before_reuse():
    """newton.py and dirk.py of commit BEFORE_REUSE as modules (linear.py and system.py are
    the current ones: only the files reuse touched are swapped)."""
    mods = {}
    for name in ("newton", "dirk"):
        try:
            src = subprocess.run(["git", "-C", str(ROOT), "show", f"{BEFORE_REUSE}:rve/solvers/{name}.py"],
                                 capture_output=True, text=True, check=True).stdout
        except (OSError, subprocess.CalledProcessError):
            pytest.skip(f"git history with commit {BEFORE_REUSE} not available")
        src = (src.replace("from .linear import", "from rve.solvers.linear import")
               .replace("from .system import", "from rve.solvers.system import")
               .replace("from .newton import", "from _before_reuse_newton import"))
        modname = f"_before_reuse_{name}"
        spec = importlib.util.spec_from_loader(modname, loader=None)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[modname] = mod
        exec(compile(src, f"{BEFORE_REUSE}:rve/solvers/{name}.py", "exec"), mod.__dict__)
        mods[name] = mod
    return mods


def test_chain_protocol_and_exact_jacobians():
    sysm = Chain()
    assert isinstance(sysm, DynamicSystem)
    rng = np.random.default_rng(1)
    fd_check(sysm, 0.2 * rng.normal(size=sysm.n), rng.normal(size=sysm.n), 0.3)
    # the exact solution satisfies M w' + F = 0
    t = 0.7
    x, v = sysm.exact(t)
    a = -sysm.omega**2 * x
    np.testing.assert_allclose(a + sysm.evaluate(x, v, t, False)[0], 0.0, atol=1e-13)


# ----------------------------------------------------------------------------- default off
@pytest.mark.parametrize("s", [1, 2, 3])
def test_default_off_is_bit_identical_to_the_code_before_reuse(s):
    old = _load_before_reuse()["dirk"]
    zeros = lambda: (np.zeros(1), np.zeros(1))  # noqa: E731
    cases = [(Manufactured, manufactured_initial, 16), (lambda: ProtheroRobinson(-5.0), zeros, 20),
             (Chain, lambda: Chain().initial(), 20), (Rigged, zeros, 10)]
    for make, init, n in cases:
        kw = dict(stages=s, newton_opts=dict(atol=1e-12, rtol=1e-14), max_cuts=4)
        if make is Rigged:
            kw.update(stages=1, predictor_degree=0, newton_opts=None)
        a = old.integrate(make(), *init(), 0.0, 1.0, n, **kw)
        for opts in ({}, {"jacobian_reuse": False}):
            b = integrate(make(), *init(), 0.0, 1.0, n, **integrator_options(**kw, **opts))
            assert np.array_equal(a.x, b.x) and np.array_equal(a.w, b.w)
            assert (a.steps, a.rejected, a.newton_iterations, a.linear_solves, a.history) == \
                (b.steps, b.rejected, b.newton_iterations, b.linear_solves, b.history)
            # reuse off: one factorisation per linear solve, nothing reused
            assert b.factorizations == b.linear_solves and b.reuses == 0 and b.refactor_reasons == {}
            assert b.jacobian_evaluations >= b.newton_iterations - b.steps * s


def test_default_newton_counts_match_its_work():
    calls = {"fun": 0}

    def fun(u):
        calls["fun"] += 1
        return np.array([u[0] ** 3 - 8.0]), sp.csr_matrix([[3 * u[0] ** 2]])

    res = newton(fun, np.array([3.0]), atol=1e-13)
    assert res.converged and res.jacobians == calls["fun"] == res.iterations + 1
    assert res.factorizations == res.linear_solves == res.iterations and res.reuses == 0


# ----------------------------------------------------------------------------- same answers
def _runs(make, init, n, s, reuse, **kw):
    out = {}
    for mode in (False, reuse):
        out[mode] = integrate(make(), *init(), 0.0, 1.0, n, stages=s, newton_opts=dict(atol=1e-12, rtol=1e-14),
                              **integrator_options(jacobian_reuse=mode, **kw))
    return out[False], out[reuse]


CASES = {
    "manufactured": (Manufactured, manufactured_initial, 40),
    "prothero-robinson": (lambda: ProtheroRobinson(-5.0), lambda: (np.zeros(1), np.zeros(1)), 40),
    "chain (banded)": (Chain, lambda: Chain().initial(), 40),
}


@pytest.mark.parametrize("reuse", [True, "auto"])
@pytest.mark.parametrize("s", [1, 2, 3])
@pytest.mark.parametrize("case", sorted(CASES))
def test_reuse_gives_the_newton_solution_with_fewer_factorisations(case, s, reuse):
    make, init, n = CASES[case]
    full, mod = _runs(make, init, n, s, reuse)
    assert mod.steps == full.steps == n and mod.rejected == 0 and mod.t == 1.0
    # the residual tolerance (1e-12) decides: the stage values agree to it
    np.testing.assert_allclose(mod.w, full.w, rtol=0, atol=1e-10)
    np.testing.assert_allclose(mod.x, full.x, rtol=0, atol=1e-10)
    assert mod.factorizations < full.factorizations, (mod.factorizations, full.factorizations)
    assert mod.reuses > 0 and mod.contractions and max(mod.contractions) < 1.0
    assert full.factorizations == full.linear_solves == full.newton_iterations - 0  # one per iteration
    # every factorisation but the first was preceded by a dropped one
    assert sum(mod.refactor_reasons.values()) >= mod.factorizations - 1 - (1 if case == "manufactured" else 0)


def test_linear_stage_matrix_is_factorised_once_and_the_jacobian_assembled_once():
    """Prothero-Robinson: the stage matrix 1 + h a λ is constant, so one factorisation and
    (lazy Jacobian) one Jacobian evaluation serve the whole run."""
    full, mod = _runs(lambda: ProtheroRobinson(-5.0), lambda: (np.zeros(1), np.zeros(1)), 40, 2, True)
    assert mod.factorizations == 1 and mod.jacobian_evaluations == 1
    assert full.factorizations == full.newton_iterations > 40
    # without the lazy Jacobian the trial points are evaluated with it: more evaluations, same answer
    eager = integrate(ProtheroRobinson(-5.0), np.zeros(1), np.zeros(1), 0.0, 1.0, 40, stages=2,
                      newton_opts=dict(atol=1e-12, rtol=1e-14), lazy_jacobian=False,
                      reuse=ReusePolicy(mode=True))
    assert eager.factorizations == 1 and eager.jacobian_evaluations > 1
    np.testing.assert_allclose(eager.w, mod.w, atol=1e-12)


@pytest.mark.parametrize("backend", ["superlu", None])
def test_backend_path_and_predictor_off(backend):
    """The manufactured system (5 dofs: not banded) goes through the get_backend instance;
    with the predictor off (degree 0) the answers still agree."""
    full, mod = _runs(Manufactured, manufactured_initial, 40, 2, True, linear_backend=backend, predictor_degree=0)
    np.testing.assert_allclose(mod.w, full.w, atol=1e-10)
    assert mod.factorizations < full.factorizations


# ----------------------------------------------------------------------------- orders
@pytest.mark.parametrize("s", [1, 2, 3])
def test_orders_unchanged_with_reuse(s):
    sysm = Manufactured()
    errs = {"x": [], "w": [], "T": [], "V": []}
    for n in MF_STEPS[s]:
        x0, w0 = manufactured_initial()
        out = integrate(sysm, x0, w0, 0.0, 1.0, n, stages=s, newton_opts=TIGHT, reuse=ReusePolicy(mode=True))
        assert out.reuses > 0
        errs["x"].append(np.abs(out.x[:2] - X(1.0)[:2]).max())
        errs["w"].append(np.abs(out.w[:2] - dX(1.0)[:2]).max())
        errs["T"].append(abs(out.w[3] - (1 + 0.5 * np.sin(1.0))))
        errs["V"].append(abs(out.w[4] - np.exp(-0.5)))
    for field, e in errs.items():
        p = observed_order(e, MF_STEPS[s])
        assert abs(p - s) < 0.3, (s, field, p, e)
    e_pr = []
    for n in PR_STEPS[s]:
        out = integrate(ProtheroRobinson(-5.0), np.zeros(1), np.zeros(1), 0.0, 1.0, n, stages=s, newton_opts=TIGHT,
                        reuse=ReusePolicy(mode=True))
        e_pr.append(abs(out.w[0] - math.sin(1.0)))
    assert abs(observed_order(e_pr, PR_STEPS[s]) - s) < 0.3, e_pr


# ----------------------------------------------------------------------------- triggers
@pytest.mark.parametrize("lam_on, reason", [(-41.0, "contraction"), (-5000.0, "diverged")])
def test_stiff_term_switching_on_forces_a_refactorisation(lam_on, reason, caplog):
    """Backward Euler, h = 1/40: the held factor 1 + 5h of the soft phase against the stiff
    stage matrix 1 - h λ_on gives θ = |1 - (1 - hλ_on)/(1 + 5h)|: 0.8 for λ_on = -41 (a
    contraction above 0.5: kept for that step, dropped after it) and 110 for -5000 (the
    modified step diverges: discarded and redone with a fresh Jacobian)."""
    def make():
        return SwitchingPR(lam_on=lam_on)

    with caplog.at_level(logging.INFO, logger="rve"):
        full, mod = _runs(make, lambda: (np.zeros(1), np.zeros(1)), 40, 1, True)
    np.testing.assert_allclose(mod.w, full.w, atol=1e-10)
    assert abs(mod.w[0] - math.sin(1.0)) < 0.05
    assert mod.refactor_reasons.get(reason, 0) >= 1, mod.refactor_reasons
    assert mod.factorizations == 2 and mod.rejected == 0, (mod.factorizations, mod.refactor_reasons)
    if reason == "diverged":
        assert mod.rejected_reuses == 1
        assert "modified step rejected" in caplog.text
    else:
        assert mod.rejected_reuses == 0 and any(0.5 < q < 1.0 for q in mod.contractions)
    assert "theta=" in caplog.text and "factorisations=" in caplog.text


def test_pattern_and_constraint_changes_force_a_refactorisation():
    """Chain: a structure change (new ``structure_version``: matrices with another stored
    pattern) at t = 0.3 and a dof becoming velocity-driven at t = 0.6 each drop the held
    factorisation once; the answers stay those of full Newton."""
    def make():
        return Chain(hold_from=0.6)

    def on_step(t, x, w, info, box):
        if abs(t - 0.3) < 1e-9:
            box[0].extra_zeros = True
            box[0].structure_version += 1

    res = {}
    for mode in (False, True):
        sysm = make()
        box = [sysm]
        res[mode] = integrate(sysm, *sysm.initial(), 0.0, 1.0, 40, stages=2,
                              newton_opts=dict(atol=1e-12, rtol=1e-14),
                              on_step=lambda t, x, w, info, box=box: on_step(t, x, w, info, box),
                              reuse=ReusePolicy(mode=mode))
    full, mod = res[False], res[True]
    np.testing.assert_allclose(mod.w, full.w, atol=1e-10)
    np.testing.assert_allclose(mod.x, full.x, atol=1e-10)
    assert mod.refactor_reasons.get("pattern") == 1, mod.refactor_reasons
    assert mod.refactor_reasons.get("constraints") == 1, mod.refactor_reasons
    assert mod.factorizations < full.factorizations / 3


def test_failed_step_and_step_size_change_drop_the_factorisation():
    """Rigged (test_dirk): stages fail for h > δ in (0.5, 0.7]; the cut step (and the new
    h·a) must not run on the old factorisation; the run is the full-Newton run."""
    kw = dict(stages=1, max_cuts=3, predictor_degree=0)
    full = integrate(Rigged(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10, **integrator_options(**kw))
    mod = integrate(Rigged(), np.zeros(1), np.zeros(1), 0.0, 1.0, 10,
                    **integrator_options(jacobian_reuse=True, **kw))
    assert (mod.steps, mod.rejected, mod.h_min) == (full.steps, full.rejected, full.h_min)
    assert [h for _, h, _ in mod.history] == pytest.approx([h for _, h, _ in full.history])
    np.testing.assert_allclose(mod.w, full.w, atol=1e-12)
    assert mod.refactor_reasons.get("failed step", 0) >= 1 and mod.refactor_reasons.get("h", 0) >= 1, \
        mod.refactor_reasons
    assert mod.factorizations < full.factorizations


def test_modified_iteration_that_diverges_is_redone_with_a_fresh_jacobian():
    """newton() directly: a factorisation held from another problem (slope 1 against 3u^2 =
    12 at the root 2) does not contract; the step is discarded, Newton refactorises, and
    converges quadratically afterwards; the answer is the root to the tolerance."""
    reuse = JacobianReuse(0.5)
    reuse.factorize(sp.csr_matrix([[1.0]]))

    def fun(u):
        return np.array([u[0] ** 3 - 8.0]), sp.csr_matrix([[3 * u[0] ** 2]])

    res = newton(fun, np.array([2.2]), atol=1e-13, residual=lambda u: fun(u)[0], reuse=reuse)
    assert res.converged and abs(res.u[0] - 2.0) < 1e-13
    assert res.rejected_reuses == 1 and reuse.refactor_reasons["diverged"] == 1
    assert res.factorizations >= 1 and res.contractions[0] < 0.1
    # the factorisation is kept for the next call at a nearby problem: no Jacobian needed
    nj = reuse.jacobians

    def fun2(u):
        return np.array([u[0] ** 3 - 8.1]), sp.csr_matrix([[3 * u[0] ** 2]])

    res2 = newton(fun2, np.array([2.0]), atol=1e-13, residual=lambda u: fun2(u)[0], reuse=reuse)
    assert res2.converged and res2.factorizations == 0 and reuse.jacobians == nj and res2.reuses == res2.iterations
    assert abs(res2.u[0] - 8.1 ** (1 / 3)) < 1e-13
    assert all(q < 0.5 for q in res2.contractions)


def test_slow_contraction_is_refactorised_before_the_iteration_limit():
    """A held factorisation with θ ≈ 0.45 (< 0.5) would need ~35 iterations for 1e-12; with
    max_iter = 10 the projection drops it ('slow') and Newton finishes in time."""
    reuse = JacobianReuse(0.5)
    reuse.factorize(sp.csr_matrix([[1.0 / 0.55]]))   # J~ = J / 0.55: θ = 1 - 0.55 = 0.45

    def fun(u):
        return np.array([u[0] - 1.0]), sp.csr_matrix([[1.0]])

    res = newton(fun, np.array([2.0]), atol=1e-12, rtol=0.0, max_iter=10, residual=lambda u: fun(u)[0], reuse=reuse)
    assert res.converged and res.iterations <= 3
    assert reuse.refactor_reasons["slow"] == 1
    np.testing.assert_allclose(res.u, 1.0, atol=1e-12)


def test_option_validation():
    with pytest.raises(ValueError):
        integrate(ProtheroRobinson(), np.zeros(1), np.zeros(1), 0.0, 1.0, 4, reuse=ReusePolicy(mode="always"))
    with pytest.raises(ValueError):
        JacobianReuse(1.5)
