"""One equilibrium path (rve.homogenisation.branch): a toy load path with a known
snap-through, where a step solver that overshoots (as the driven phase of Algorithm 7.1
carries the state with inertia) jumps to the other well while the first still exists;
the follower stays on the branch, down to its limit point, and a smooth path raises no
detection."""
import numpy as np
import pytest

from rve.homogenisation.branch import BranchSettings, StepSolution, detect, follow_branch


def _toy(k: float, well: float, overshoot: float = 3.0):
    """Pi(u; eps) = u^4/4 + well u^2/2 + k (eps - u)^2 / 2 (a spring of stiffness k pulls a
    1-dof system with a double well for well = -1 and k < 1: snap-through at the limit
    points eps = +-2/k (1-k)^(3/2)/(3 sqrt 3)). The step solver predicts u + overshoot d and
    descends to the minimum of the basin the prediction lies in (exact: the roots of the cubic)."""

    def roots(eps):
        r = np.roots([1.0, 0.0, k + well, -k * eps])
        return np.sort(r[np.abs(r.imag) < 1e-9].real)

    def solve(start, ea, eb):
        up = start.x + overshoot * (eb - ea)
        r = roots(eb)
        return StepSolution(float(r[0] if (len(r) == 1 or up < r[1]) else r[-1]), {"from": ea, "to": eb})

    def energy(sol, eps):
        u = sol.x
        return 0.25 * u ** 4 + 0.5 * well * u ** 2 + 0.5 * k * (eps - u) ** 2, k * (eps - u)

    def inertia(sol):
        return int(3.0 * sol.x ** 2 + well + k < 0)

    return solve, energy, inertia, roots


K = 0.5
LIMIT = 2.0 / K * (1 - K) ** 1.5 / (3 * np.sqrt(3))   # 0.272: the left branch ends here


def test_naive_step_jumps_and_the_follower_stays_on_the_branch():
    solve, energy, inertia, roots = _toy(K, -1.0)
    u0 = StepSolution(-1.0)                      # the left well at eps = -1
    path = [-1.0, -0.4, 0.2]                     # 0.2 < LIMIT: the left branch still exists there
    naive = u0
    for a, b in zip(path[:-1], path[1:]):
        naive = solve(naive, a, b)
    assert naive.x > roots(0.2)[1]               # the naive path landed in the right well
    s, infos = u0, []
    for a, b in zip(path[:-1], path[1:]):
        s, info = follow_branch(solve, s, a, b, energy, inertia=inertia)
        infos.append(info)
    assert s.x == pytest.approx(roots(0.2)[0], abs=1e-12)     # the left branch
    assert infos[0]["detections"] == 0 and infos[0]["solves"] == 1
    assert infos[1]["branch_jumps"] == 1 and infos[1]["kept"] == "followed" and infos[1]["limit_points"] == 0
    assert infos[1]["solves"] > 1 and all(c["eps"][1] - c["eps"][0] > 0 for c in infos[1]["checks"])
    # every accepted sub-step of the followed path passed the test
    assert infos[1]["checks"][0]["jump"] and infos[1]["checks"][0]["why"] == ["energy"]


def test_past_the_limit_point_the_jump_is_recorded_and_accepted():
    solve, energy, inertia, roots = _toy(K, -1.0)
    s = StepSolution(float(roots(0.2)[0]))       # on the left branch at 0.2
    s, info = follow_branch(solve, s, 0.2, 0.5, energy, inertia=inertia,
                            settings=BranchSettings(max_halvings=4, persist_ratio=0.0))
    assert len(roots(0.5)) == 1 and s.x == pytest.approx(roots(0.5)[0])   # only the right well is left
    assert info["limit_points"] == 1 and info["branch_jumps"] == 0 and info["false_alarms"] == 0
    floor = [c for c in info["checks"] if c["jump"] and c["depth"] == 4]
    assert len(floor) == 1
    lo, hi = floor[0]["eps"]
    assert lo <= LIMIT <= hi and hi - lo == pytest.approx(0.3 / 2 ** 4)   # the floor interval holds the limit point


def test_smooth_path_raises_no_detection():
    solve, energy, inertia, _ = _toy(2.0, +1.0)   # convex: one equilibrium per eps
    s = StepSolution(0.0)
    levels = np.linspace(0.0, 2.0, 9)
    for a, b in zip(levels[:-1], levels[1:]):
        s2, info = follow_branch(solve, s, a, b, energy, inertia=inertia)
        assert info["detections"] == 0 and info["solves"] == 1 and info["kept"] == "naive"
        s = s2


def test_false_alarm_keeps_the_naive_state_itself():
    """A tolerance so tight that the trapezoid error of a smooth step trips it: the
    followed path ends in the same equilibrium, and the naive solution object is returned."""
    solve, energy, inertia, _ = _toy(2.0, +1.0)
    start = StepSolution(0.0)
    naive = solve(start, 0.0, 1.0)
    out, info = follow_branch(solve, start, 0.0, 1.0, energy, settings=BranchSettings(energy_rtol=1e-9))
    assert info["detections"] >= 1 and info["false_alarms"] == 1 and info["kept"] == "naive"
    assert out.x == naive.x and out.info == naive.info


def test_inertia_change_is_a_detection():
    s = BranchSettings()
    v = detect(1.0, 2.0, 1.2, 2.0, 0.1, s, inertia_a=0, inertia_b=1)   # energy balance exact, inertia changed
    assert v["jump"] and v["why"] == ["inertia"]
    assert not detect(1.0, 2.0, 1.2, 2.0, 0.1, s, inertia_a=0, inertia_b=None)["jump"]   # unknown: not judged
    v = detect(1.0, 2.0, 1.0, 2.0, 0.1, s)                                  # no energy change for 0.2 of work
    assert v["jump"] and v["why"] == ["energy"] and v["mismatch"] == pytest.approx(0.2)


def test_pinned_work_rate_is_the_load_derivative_of_the_energy():
    """``pinned_energy``'s dPi/deps (clamp forces times the end velocity per unit strain) is
    the derivative of the potential when the ends move along the mode with the free dofs held:
    central differences on the relaxed CI weave with its ends moved to a strain of 0.02, every
    mode."""
    from pathlib import Path

    import yaml

    from rve.fabrics.setup import clamped_ends, fabric_and_mesh
    from rve.homogenisation.strain import end_targets, mech_system, pinned_energy, relax_fabric
    from rve.homogenisation.sweeps import load_run_config

    spec = yaml.safe_load((Path(__file__).parents[1] / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    cfg = load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    x, _, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    ends, _, _ = clamped_ends(fab, mesh)
    system = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, x.reshape(-1))
    eps = 0.02    # the ends moved along the mode, the free dofs held: a loaded (non-equilibrium) state
    for mode in ("uniaxial", "shear", "uniaxial_y", "trellis"):
        xe = x.copy()
        xe[ends, :3] = end_targets(x[ends, :3], mode, eps)
        Pi, rate = pinned_energy(fab, mesh, system, xe, x, mode, eps)
        assert Pi == pytest.approx(system.energy(xe.reshape(-1)))
        h = 1e-6
        vals = []
        for s in (h, -h):
            xs = x.copy()
            xs[ends, :3] = end_targets(x[ends, :3], mode, eps + s)
            vals.append(system.energy(xs.reshape(-1)))
        fd = (vals[0] - vals[1]) / (2 * h)
        assert abs(rate) > 0
        assert rate == pytest.approx(fd, rel=1e-5), mode


def test_periodic_work_rate_is_the_derivative_of_the_energy_along_the_branch():
    """``periodic_energy``'s dPi/deps (the Hill-Mandel A P : dF/deps) is the derivative of
    the potential along the equilibrium branch: central differences of Pi over equilibria of
    the CI-size periodic cell at eps +- h (uniaxial and shear); a uniaxial strain step
    through the one-path test passes it and keeps the plain step's bits. (This cell's
    shear step is a detection: the small steps stay on a branch with 3 negative pivots, the
    whole step drops 2e-4 N mm below it into a minimum; a limit point, the naive state kept.)"""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.config.rve import RVEConfig
    from rve.homogenisation.periodic import periodic_energy, periodic_strain_step
    from rve.homogenisation.strain import relax_fabric, strain_step

    cfg = RVEConfig(scene="rve", boundary="periodic", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6},
                    contact={"onset": 0.05}, strain={"total": 0.1, "steps": 2, "static_atol": 1e-8})
    fab, mesh = fabric_and_mesh(cfg)
    x0, _, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info["converged"]
    eps, h = 0.03, 1e-3
    for mode in ("uniaxial", "shear"):
        x_eps, _, inf = periodic_strain_step(cfg, fab, mesh, x0, x0, mode, 1, (0.0, eps))
        assert inf["converged"]
        Pi, rate = periodic_energy(cfg, fab, mesh, x_eps, mode, eps)
        ends = [periodic_energy(cfg, fab, mesh, periodic_strain_step(cfg, fab, mesh, x_eps, x0, mode, 1,
                                                                     (eps, eps + s))[0], mode, eps + s)[0]
                for s in (h, -h)]
        fd = (ends[0] - ends[1]) / (2 * h)
        assert abs(rate) > 0
        assert rate == pytest.approx(fd, rel=1e-4), mode
    x_plain, _, _ = periodic_strain_step(cfg, fab, mesh, x0, x0, "uniaxial", 1)
    x_followed, _, inf = strain_step(cfg, fab, mesh, x0, x0, "uniaxial", 1)
    assert inf["branch"]["detections"] == 0 and inf["branch"]["kept"] == "naive"
    assert np.array_equal(x_followed, x_plain)


def test_a_jump_that_keeps_its_parents_mismatch_is_not_halved_further():
    """The same step with the default ``persist_ratio``: the half that holds the jump keeps
    the whole mismatch (the energy the snap releases) and is the limit point; the other
    half passes; 3 solves instead of halving down to the floor, and the same end state."""
    solve, energy, inertia, roots = _toy(K, -1.0)
    start = StepSolution(float(roots(0.2)[0]))
    s, info = follow_branch(solve, start, 0.2, 0.5, energy, inertia=inertia, settings=BranchSettings(max_halvings=4))
    floor, _ = follow_branch(solve, start, 0.2, 0.5, energy, inertia=inertia,
                             settings=BranchSettings(max_halvings=4, persist_ratio=0.0))
    assert info["limit_points"] == 1 and info["solves"] == 3
    held = [c for c in info["checks"] if c.get("persists")]
    assert len(held) == 1 and held[0]["eps"][0] <= LIMIT <= held[0]["eps"][1]
    assert abs(held[0]["mismatch"]) >= 0.5 * abs(info["checks"][0]["mismatch"])
    assert s.x == pytest.approx(floor.x) == pytest.approx(roots(0.5)[0])


def test_a_followed_path_that_does_not_converge_keeps_the_converged_naive_state():
    """The toy's jump step with sub-step solves that report no convergence: the follower
    keeps the naive step's (converged) state, counts a limit point and records why."""
    solve, energy, inertia, roots = _toy(K, -1.0)

    def failing(start, ea, eb):
        sol = solve(start, ea, eb)
        sol.info["converged"] = (ea, eb) == (-0.4, 0.2)       # only the whole step converges
        return sol

    start = solve(StepSolution(-1.0), -1.0, -0.4)
    s, info = follow_branch(failing, start, -0.4, 0.2, energy, inertia=inertia)
    naive = failing(start, -0.4, 0.2)
    assert info["detections"] >= 1 and info.get("followed_unconverged")
    assert s.x == naive.x and info["limit_points"] >= 1 and info["branch_jumps"] == 0
