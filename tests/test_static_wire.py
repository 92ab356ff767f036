"""The static wire on small meshes: quadratic Newton, gauge independence, CLI summary."""
import json

import numpy as np
import pytest

from rve.cli import main
from rve.config.loader import load_config
from rve.scenes import static_wire as sw
from rve.solvers.static import static_solve

CONFIG = "configs/scenes/static_wire.yaml"


@pytest.fixture(scope="module")
def solved():
    cfg = load_config(CONFIG, ["mesh.order=3", "mesh.elements=8", "mesh.disk_points=16"])
    return cfg, sw.solve(cfg)


def test_static_newton_converges_quadratically_near_the_solution():
    # R = 0.08: the twist of the sections (stiffness ~ R^4) is soft enough on thinner wires
    # that the residual history shows a long pre-asymptotic phase (docs/static_solution_path.md)
    cfg = load_config(CONFIG, ["mesh.order=3", "mesh.elements=8", "fibril.radius=0.08 mm"])
    out = sw.solve(cfg)
    model, x = out.model, out.state["x"]
    rng = np.random.default_rng(1)
    xp = x.copy()
    free = np.setdiff1d(np.arange(model.n), model.constraints(0.0)[0])
    xp[free] += 1e-3 * rng.standard_normal(free.size)
    _, _, res = static_solve(model, xp, np.zeros_like(xp), 0.0, sw.newton_options(cfg, model))
    assert res.converged and res.iterations <= 6
    assert max(res.rates) > 1.8, (res.residuals, res.rates)


def test_twist_gauge_does_not_change_the_answer(solved):
    # With the 16-point disk rule the section integral of ln J is close enough to rotation
    # invariant that the uniform twist is a null mode; with the 4-point rule the gauge
    # moves the centre by ~3e-8 (measured), far below the discretisation error.
    cfg, out = solved
    model = sw.setup(cfg, gauge_end=1)
    x = out.state["x"].copy()
    # the other end's gauge value is whatever the first solution has there
    n1 = model.mesh.end_nodes(0)[1]
    model.bcs[2].value = 0.0
    g1z = model.layout.dofs("g1", n1, comp=2)
    x[g1z] = out.state["x"][g1z]
    x2, _, res = static_solve(model, x, np.zeros_like(x), 0.0, sw.newton_options(cfg, model))
    assert res.converged
    c2 = sw.centre_displacement(model, x2, cfg.geometry.half_length)
    assert abs(c2 - out.summary["centre_displacement"]) < 1e-10


def test_summary_has_the_issue_keys_and_matches_the_helix(solved):
    cfg, result = solved
    out = result.summary
    for key in ("centre_displacement", "analytical_centre_displacement", "newton_iterations", "wall_time_s", "dofs"):
        assert key in out
    assert out["fields"] == ["mech"]  # the static wire carries no T or V dofs
    assert out["dofs"] == 9 * (3 * 8 + 1)
    # R = 0.02: bending stiffens the wire; within 1% of the string helix, above it
    assert 0 < out["centre_displacement"] / out["analytical_centre_displacement"] - 1 < 0.01


def test_cli_run_writes_summary(tmp_path):
    code = main(["run", CONFIG, "--set", "mesh.elements=6", "--set", "mesh.order=2", "--out", str(tmp_path)])
    assert code == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["elements"] == 6
    assert abs(summary["analytical_centre_displacement"] - 0.71243) < 1e-5
    assert set(summary["wall_time_s"]) >= {"setup", "relaxation", "static", "total"}
