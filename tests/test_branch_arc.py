"""Through the limit points on one path (rve.homogenisation.branch.continue_arc): the toy
snap-through of tests/test_branch.py, whose equilibria u(eps) form an S-curve with folds at
eps = +-LIMIT. The continuation from the left branch passes both folds on the one curve
(the middle branch has one negative eigenvalue), the energy along it is continuous (its
change is the path integral of dPi/deps), and where it ends does not depend on the step
size; two runs are bit-identical."""
import numpy as np
import pytest

from rve.homogenisation.branch import ArcProblem, ArcSettings, BranchSettings, StepSolution, continue_arc, follow_branch

K, WELL = 0.5, -1.0
LIMIT = 2.0 / K * (1 - K) ** 1.5 / (3 * np.sqrt(3))


def _roots(eps):
    r = np.roots([1.0, 0.0, K + WELL, -K * eps])
    return np.sort(r[np.abs(r.imag) < 1e-9].real)


def _problem(rebuilds=None):
    """Pi(u; eps) = u^4/4 + WELL u^2/2 + K (eps - u)^2/2 on a 1-vector."""
    def residual(x, eps):
        u = x[0]
        return np.array([u ** 3 + WELL * u - K * (eps - u)])

    def tangent(x, eps):
        return np.array([[3 * x[0] ** 2 + WELL + K]]), np.array([-K])

    def factor(Km):
        k = float(Km[0, 0])
        return (lambda b: np.asarray(b, float) / k), int(k < 0)

    def energy(x, eps):
        u = x[0]
        return 0.25 * u ** 4 + 0.5 * WELL * u ** 2 + 0.5 * K * (eps - u) ** 2, K * (eps - u)

    def rebuild(x, eps):
        if rebuilds is not None:
            rebuilds.append(float(eps))

    return ArcProblem(residual, tangent, factor, rebuild, energy, atol=1e-13)


def test_the_continuation_passes_both_folds_on_one_curve():
    calls = []
    u0 = np.array([_roots(0.2)[0]])              # the left branch
    x, info = continue_arc(_problem(calls), u0, 0.2, 0.5)
    assert info["converged"] and info["folds"] == 2
    assert x[0] == pytest.approx(_roots(0.5)[0], abs=1e-12)   # the only equilibrium left at 0.5
    path = info["path"]
    eps = np.array([p["eps"] for p in path])
    inertia = [p["inertia"] for p in path]
    # the curve turns back past +LIMIT and forward again past -LIMIT
    assert eps.max() >= LIMIT - 0.05 and eps.min() <= -LIMIT + 0.05
    assert 1 in inertia and inertia[0] == 0 and inertia[-1] == 0
    # the inertia changes only where eps turns (each point is on the branch its inertia says)
    changes = [i for i in range(1, len(path)) if inertia[i] != inertia[i - 1]]
    assert len(changes) == 2
    # one continuous branch: the energy change is the path integral of dPi/deps (to the
    # trapezoid error of the arc steps), far below what the snap at the fold releases
    e = lambda u, ep: 0.25 * u ** 4 + 0.5 * WELL * u ** 2 + 0.5 * K * (ep - u) ** 2
    r = _roots(LIMIT - 1e-9)
    released = e(r[0], LIMIT) - e(r[-1], LIMIT)
    assert released > 0.1
    assert abs(info["energy_mismatch"]) < 0.05 * released
    assert len(calls) == info["arc_steps"]     # the map rebuilt once per accepted arc step


def test_the_end_does_not_depend_on_the_step_size_and_runs_are_bit_identical():
    u0 = np.array([_roots(-0.4)[0]])
    ends = [continue_arc(_problem(), u0, -0.4, 0.35, ArcSettings(steps=n))[0] for n in (3, 7, 12)]
    assert all(e is not None for e in ends)
    assert np.allclose(np.concatenate(ends), _roots(0.35)[-1], atol=1e-12)
    again = continue_arc(_problem(), u0, -0.4, 0.35, ArcSettings(steps=7))[0]
    assert np.array_equal(again, ends[1])


def test_a_step_before_the_fold_stays_on_the_branch():
    u0 = np.array([_roots(-0.4)[0]])
    x, info = continue_arc(_problem(), u0, -0.4, 0.2)
    assert info["converged"] and info["folds"] == 0
    assert x[0] == pytest.approx(_roots(0.2)[0], abs=1e-12)


def _overshoot_solver(overshoot=3.0):
    def solve(start, ea, eb):
        up = start.x + overshoot * (eb - ea)
        r = _roots(eb)
        return StepSolution(float(r[0] if (len(r) == 1 or up < r[1]) else r[-1]))

    def energy(sol, eps):
        u = sol.x
        return 0.25 * u ** 4 + 0.5 * WELL * u ** 2 + 0.5 * K * (eps - u) ** 2, K * (eps - u)

    def inertia(sol):
        return int(3.0 * sol.x ** 2 + WELL + K < 0)

    def arc(start, ea, eb):
        x, info = continue_arc(_problem(), np.array([start.x]), ea, eb)
        return None if x is None else StepSolution(float(x[0]), {"arc": info})

    return solve, energy, inertia, arc


def test_follow_branch_by_continuation():
    """The naive step jumps to the right well while the left branch exists (0.2): the
    continuation keeps the left branch; past the fold (0.5) it ends where the naive step
    ends, which is kept, with the two limit points passed recorded."""
    solve, energy, inertia, arc = _overshoot_solver()
    s = BranchSettings(method="arc_length")
    out, info = follow_branch(solve, StepSolution(float(_roots(-0.4)[0])), -0.4, 0.2, energy, inertia=inertia,
                              settings=s, arc=arc)
    assert info["kept"] == "arc" and info["branch_jumps"] == 1 and info["solves"] == 1
    assert out.x == pytest.approx(_roots(0.2)[0], abs=1e-12)
    naive = solve(out, 0.2, 0.5)
    out2, info2 = follow_branch(solve, out, 0.2, 0.5, energy, inertia=inertia, settings=s, arc=arc)
    assert info2["kept"] == "naive" and out2.x == naive.x
    assert info2["limit_points_passed"] == 2 and info2["arc"]["converged"]


def _ci_periodic_cell():
    from rve.config.rve import RVEConfig
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.strain import relax_fabric

    cfg = RVEConfig(scene="rve", boundary="periodic", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6},
                    contact={"onset": 0.05}, strain={"total": 0.1, "steps": 2, "static_atol": 1e-8,
                                                       "branch_method": "arc_length"})
    fab, mesh = fabric_and_mesh(cfg)
    x0, _, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info["converged"]
    return cfg, fab, mesh, x0


def test_periodic_weave_continuation_is_one_branch_and_reproducible():
    """The CI-size periodic plain cell in shear: the naive step (energy minimisation from
    the affine predictor) drops into a minimum 2e-4 N mm below the branch the relaxed state
    is on, which has negative pivots. The continuation follows that branch: its energy
    change is the path integral of the Hill-Mandel work rate (far below the drop), its
    inertia does not change along it, its end is an equilibrium; being a saddle branch it is
    no table state, so the naive step is kept (a limit point). Two runs are bit-identical."""
    from rve.homogenisation.branch import StepSolution
    from rve.homogenisation.continuation import periodic_arc
    from rve.homogenisation.strain import strain_step

    cfg, fab, mesh, x0 = _ci_periodic_cell()
    arc = periodic_arc(cfg, fab, mesh, "shear")
    sol = arc(StepSolution(x0), 0.0, 0.05)
    a = sol.info["arc"]
    assert a["converged"] and sol.info["converged"] and sol.info["residual_N"] <= cfg.strain.static_atol
    inertia = {p["inertia"] for p in a["path"]}
    assert len(inertia) == 1 and inertia.pop() > 0
    x1, _, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1)
    b = info["branch"]
    assert b["detections"] == 1 and b["kept"] == "naive" and b["limit_points"] == 1 and b["arc"]["unstable"]
    e_arc = a["path"][-1]["energy"]
    assert e_arc - info["energy_mJ"] > 0           # the naive step's minimum is below the branch
    assert abs(a["energy_mismatch"]) < 1e-2 * (e_arc - info["energy_mJ"])
    again = arc(StepSolution(x0), 0.0, 0.05)
    assert np.array_equal(again.x, sol.x)
    x2, _, _ = strain_step(cfg, fab, mesh, x0, x0, "shear", 1)
    assert np.array_equal(x2, x1)


def test_periodic_continuation_with_the_augmented_lagrangian():
    """The same cell and step with the augmented Lagrangian: the curve of the penalty law
    shifted by the relaxed state's multipliers is continued (the same saddle branch, its
    energy change the path integral of the work rate), its end passes the Uzawa loop to
    al_tolerance and is an equilibrium; the branch being a saddle, the step keeps the naive
    state, which is the step without the continuation's state bit for bit."""
    from rve.homogenisation.branch import StepSolution
    from rve.homogenisation.continuation import periodic_arc
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import relax_fabric, strain_step

    cfg, fab, mesh, _ = _ci_periodic_cell()
    cfg = cfg.model_copy(update={"contact": cfg.contact.model_copy(update={"enforcement": "augmented_lagrangian"})})
    x0, sys0, info0 = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    lam = multiplier_record(sys0)
    assert info0["converged"] and lam is not None and np.abs(lam[1]).max() > 0
    sol = periodic_arc(cfg, fab, mesh, "shear", multipliers=lam)(StepSolution(x0), 0.0, 0.05)
    a, al = sol.info["arc"], sol.info["static"]["augmented_lagrangian"]
    assert a["converged"] and sol.info["converged"] and sol.info["residual_N"] <= cfg.strain.static_atol
    assert al["met"] and al["max_penetration_over_R"] <= cfg.contact.al_tolerance
    inertia = {p["inertia"] for p in a["path"]}
    assert len(inertia) == 1 and inertia.pop() > 0
    x1, _, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam)
    b = info["branch"]
    assert b["detections"] == 1 and b["kept"] == "naive" and b["arc"]["unstable"]
    assert abs(a["energy_mismatch"]) < 1e-2 * (a["path"][-1]["energy"] - info["energy_mJ"])
    off = cfg.model_copy(update={"strain": cfg.strain.model_copy(update={"branch_method": "halving",
                                                                          "branch_max_halvings": 0})})
    x2, _, _ = strain_step(off, fab, mesh, x0, x0, "shear", 1, multipliers=lam)
    assert np.array_equal(x2, x1)


def test_pinned_load_derivative_is_the_strain_derivative_of_the_residual():
    """``pinned_arc``'s R_eps (the free rows of the tangent times d(end targets)/d eps) is the
    central difference of the free residual in eps at fixed free dofs (the CI weave)."""
    from pathlib import Path

    import yaml

    from rve.fabrics.setup import clamped_ends, fabric_and_mesh
    from rve.homogenisation.continuation import _free
    from rve.homogenisation.strain import end_targets, mech_system, relax_fabric
    from rve.homogenisation.sweeps import load_run_config

    spec = yaml.safe_load((Path(__file__).parents[1] / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    cfg = load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    x, _, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    ends, pinned, _ = clamped_ends(fab, mesh)
    system = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, x.reshape(-1))
    free = _free(system)
    zero = np.zeros(system.n)
    assert np.intersect1d(free, pinned).size == 0
    for mode in ("uniaxial", "shear", "trellis"):
        def at(eps):
            xe = x.reshape(-1).copy()
            xe[pinned] = end_targets(x[ends, :3], mode, eps).reshape(-1)
            return xe
        eps, h = 0.01, 1e-6
        _, Fx, _ = system.evaluate(at(eps), zero, 0.0, jacobian=True)
        rate = ((end_targets(x[ends, :3], mode, eps + h) - end_targets(x[ends, :3], mode, eps - h)) / (2 * h)).reshape(-1)
        R_eps = Fx.tocsr()[free][:, pinned] @ rate
        fd = (system.evaluate(at(eps + h), zero, 0.0, jacobian=False)[0][free]
              - system.evaluate(at(eps - h), zero, 0.0, jacobian=False)[0][free]) / (2 * h)
        assert np.abs(R_eps).max() > 0
        assert np.abs(R_eps - fd).max() <= 1e-6 * np.abs(fd).max(), mode


def test_table_attributes_count_what_the_path_test_found():
    """The table's branch_* attributes sum the steps' records per mode, the limit points the
    continuation passed included."""
    import json

    from rve.tables.build import build_table

    def rec(mode, strain, **b):
        return {"mode": mode, "strain": strain, "params": {}, "state": {"branch": b}}

    recs = [rec("uniaxial", 0.1, detections=2, limit_points=1, limit_points_passed=2, branch_jumps=1),
            rec("uniaxial", 0.2, detections=1, limit_points_passed=1), rec("shear", 0.1, detections=0)]
    ds = build_table(recs, fabric="plain", config={})
    assert json.loads(ds.attrs["branch_limit_points_passed"]) == {"shear": 0, "uniaxial": 3}
    assert json.loads(ds.attrs["branch_detections"]) == {"shear": 0, "uniaxial": 3}
    assert json.loads(ds.attrs["branch_limit_points"]) == {"shear": 0, "uniaxial": 1}


def test_the_dogleg_corrector_passes_both_folds_to_the_same_end():
    """The trust-region corrector (ArcSettings.corrector = "dogleg") on the toy: the same two
    folds, the same end state; the dogleg step is the Newton step inside the region and on
    its boundary otherwise."""
    from rve.homogenisation.branch import _dogleg

    u0 = np.array([_roots(0.2)[0]])
    x, info = continue_arc(_problem(), u0, 0.2, 0.5, ArcSettings(corrector="dogleg"))
    assert info["converged"] and info["folds"] == 2
    assert x[0] == pytest.approx(_roots(0.5)[0], abs=1e-12)
    rng = np.random.default_rng(3)
    dN, dC = rng.standard_normal(5), 0.1 * rng.standard_normal(5)
    nN = float(np.linalg.norm(dN))
    assert np.array_equal(_dogleg(dN, dC, nN, 2 * nN), dN)
    for radius in (0.05, 0.5 * nN, 0.9 * nN):
        d = _dogleg(dN, dC, nN, radius)
        assert np.linalg.norm(d) == pytest.approx(radius, rel=1e-12)
    with pytest.raises(ValueError, match="corrector"):
        ArcSettings(corrector="lm")


def test_periodic_continuation_at_a_raised_penalty_with_the_dogleg():
    """``strain.arc_penalty`` and ``strain.arc_corrector`` from the config: the CI cell's AL
    continuation at ten times P* (the multipliers re-expressed there) with the dogleg
    corrector converges, its end passes the Uzawa loop back at the configured P* (the system
    it returns is at contact.penalty) and is an equilibrium; a bad corrector is refused,
    naming the key."""
    from rve.config import validate_config
    from rve.homogenisation.branch import StepSolution
    from rve.homogenisation.continuation import arc_settings, periodic_arc
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import relax_fabric

    cfg, fab, mesh, _ = _ci_periodic_cell()
    P = float(cfg.contact.penalty)
    cfg = cfg.model_copy(update={
        "contact": cfg.contact.model_copy(update={"enforcement": "augmented_lagrangian"}),
        "strain": cfg.strain.model_copy(update={"arc_penalty": 10.0 * P, "arc_corrector": "dogleg"})})
    x0, sys0, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    settings = arc_settings(cfg)
    assert settings.corrector == "dogleg"
    sol = periodic_arc(cfg, fab, mesh, "shear", settings, multipliers=multiplier_record(sys0))(StepSolution(x0), 0.0,
                                                                                                0.05)
    a, al = sol.info["arc"], sol.info["static"]["augmented_lagrangian"]
    assert a["converged"] and sol.info["converged"] and sol.info["residual_N"] <= cfg.strain.static_atol
    assert al["met"] and float(sol.extra.penalty) == P
    # the curve ran at the raised P*: the start's potential (its penalty part, at the same
    # line loads) is not the one at the configured P*
    soft = cfg.model_copy(update={"strain": cfg.strain.model_copy(update={"arc_penalty": None})})
    ref = periodic_arc(soft, fab, mesh, "shear", settings, multipliers=multiplier_record(sys0))(StepSolution(x0), 0.0,
                                                                                                  0.05)
    e_soft, e_stiff = ref.info["arc"]["path"][0]["energy"], a["path"][0]["energy"]
    assert abs(e_stiff - e_soft) > 1e-6 * abs(e_soft)
    with pytest.raises(Exception, match="arc_corrector"):
        validate_config({"scene": "rve", "strain": {"arc_corrector": "lm"}})
