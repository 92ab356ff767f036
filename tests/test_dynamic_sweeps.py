"""The dynamic scenes' sweeps (workflow/rules/impact.smk ``impact_velocity_sweep``,
induced_deformation.smk ``induced_current_sweep``): the Snakemake plumbing by a dry run, and
the current sweep's job and figure on a tiny induced case, checked against the scalings the
physics fixes (Lorentz force and early deflection ∝ J, Joule heat and temperature ∝ J²)."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from rve.scenes.induced.jobs import current_sweep_curve, orientation_job

ROOT = Path(__file__).resolve().parents[1]
TINY_INDUCED = ["geometry.n_warp=2", "geometry.n_weft=2", "geometry.span=5 mm", "geometry.natural_length=6.25 mm",
                "mesh.elements=10", "time.t_end=0.03 ms", "time.steps=3", "time.store_every=1", "output.png=false",
                "output.vtk=false"]


@pytest.mark.parametrize("target, point_rule", [("impact_velocity_sweep", "impact_velocity_point"),
                                                ("induced_current_sweep", "induced_current_point")])
def test_sweep_dry_run_has_one_job_per_point(target, point_rule, tmp_path):
    """--forceall: the DAG of the config, whatever results/ already holds."""
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--forceall", "--directory", str(ROOT), target,
                          "--config", "impact={\"velocities\": [10, 20.5, 30]}",
                          "induced_deformation={\"currents\": [250, 750, 1500]}"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    text = out.stdout + out.stderr
    counts = {line.split()[0]: line.split()[1] for line in text.splitlines()
              if len(line.split()) == 2 and line.split()[1].isdigit()}
    assert counts.get(point_rule) == "3", text[-2000:]
    assert counts.get(target) == "1"
    points = ("v10", "v20.5", "v30") if target.startswith("impact") else ("J250", "J750", "J1500")
    for p in points:
        assert f"/{p}/summary.json" in text


def test_current_sweep_jobs_and_figure_follow_the_scalings(tmp_path):
    scene = ROOT / "configs/scenes/induced_deformation.yaml"
    dirs, currents = [], [500, 1000]
    for J in currents:
        d = tmp_path / f"J{J}"
        orientation_job(scene, "B2", d, d / "summary.json", tmp_path / f"J{J}.log",
                        TINY_INDUCED + [f"warp.J_bar=-{J} A/mm^2"])
        dirs.append(d)
    out = current_sweep_curve(dirs, currents, tmp_path / "sweep.png", tmp_path / "sweep.json")
    assert (tmp_path / "sweep.png").stat().st_size > 10_000
    rows = json.loads((tmp_path / "sweep.json").read_text())
    assert [r["J_A_per_mm2"] for r in rows] == currents and rows == json.loads(json.dumps(out["rows"], default=float))
    a, b = rows
    # the force is I x B: the early lift doubles with the current (back-EMF and the geometry: a few %)
    assert b["mean_displacement_mm"][2] / a["mean_displacement_mm"][2] == pytest.approx(2.0, rel=0.03)
    # Joule heat I^2 R in a linear heat equation (S = 0): the temperature quadruples
    assert b["max_temperature_K"] / a["max_temperature_K"] == pytest.approx(4.0, rel=0.03)
    assert b["terminal_current_A"] / a["terminal_current_A"] == pytest.approx(2.0, rel=0.03)
