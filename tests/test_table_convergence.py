"""Table convergence study (rve.studies.table_convergence): the errors, rates and
work figures on a synthetic refinement series with a known order, and (slow) the CI study
through Snakemake."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from rve.studies.table_convergence import (NEGLIGIBLE, combo_costs, combo_wall_times, observed_rates,
                                           reference_error, relative_errors, summarize_by_mode, summarize_errors,
                                           table_convergence_job)


def _series(order=2.0, Ns=(6.0, 12.0, 24.0, 48.0), c=0.3):
    """q(N) = q_exact (1 + c (strain + 1) N^-order): the error to the finest run is known."""
    strain = np.linspace(0, 0.2, 5)
    exact = 1.0 + strain
    vals = np.array([[exact * (1 + c * (strain + 1) * N ** -order)] for N in Ns])  # (N, mode, strain)
    side = np.zeros((len(Ns), 1, 5, 2))
    side[..., 0] = vals            # a big component ...
    side[..., 1] = 1e-3 * vals     # ... and a negligible one (left out)
    ds = xr.Dataset({"probe_resistance": (("mesh_elements", "mode", "strain"), vals),
                     "reaction_force": (("mesh_elements", "mode", "strain", "component"), side)},
                    coords={"mesh_elements": list(Ns), "mode": ["uniaxial"], "strain": strain,
                            "component": ["x", "z"]})
    return ds.transpose("mode", "strain", "mesh_elements", ...), vals, exact


def test_errors_to_the_finest_run_are_the_closed_form_differences():
    ds, vals, exact = _series()
    rows = relative_errors(ds, 48.0, "mesh_elements")
    summ = summarize_errors(rows, "mesh_elements")
    ref = vals[-1, 0]
    for k, N in enumerate((6.0, 12.0, 24.0)):
        want = np.max(np.abs(vals[k, 0] - ref) / np.abs(ref).max())
        assert summ["probe_resistance"][N] == pytest.approx(want, rel=1e-12)
        assert summ["reaction_force"][N] == pytest.approx(want, rel=1e-12)
    assert {r["label"] for r in rows if r["quantity"] == "reaction_force"} == {"x"}  # z is < NEGLIGIBLE
    assert NEGLIGIBLE > 1e-3
    # every strain of every run is a row
    assert sum(r["quantity"] == "probe_resistance" for r in rows) == 3 * 5


def test_observed_rate_recovers_the_order_against_an_exact_reference():
    # with the finest run far finer (N = 1e6, i.e. ~exact) the fitted slope is the order
    ds, _, _ = _series(order=2.0, Ns=(6.0, 12.0, 24.0, 1e6))
    rates = observed_rates(summarize_errors(relative_errors(ds, 1e6, "mesh_elements"), "mesh_elements"))
    assert rates["probe_resistance"] == pytest.approx(2.0, abs=0.02)
    ds1, _, _ = _series(order=1.0, Ns=(6.0, 12.0, 24.0, 1e6))
    rates1 = observed_rates(summarize_errors(relative_errors(ds1, 1e6, "mesh_elements"), "mesh_elements"))
    assert rates1["probe_resistance"] == pytest.approx(1.0, abs=0.02)


def test_reference_error_is_the_reference_runs_own_error_for_a_first_order_series():
    # q(N) = exact (1 + c (s+1) / N): Richardson with order 1 from (24, 48) gives the error of
    # the 48-element run against the exact value, which the study itself cannot see
    ds, vals, exact = _series(order=1.0)
    summ = summarize_errors(relative_errors(ds, 48.0, "mesh_elements"), "mesh_elements")
    est = reference_error(summ, 48.0)
    ref = vals[-1, 0]
    true = np.max(np.abs(ref - exact) / np.abs(ref).max())
    assert est["probe_resistance"] == pytest.approx(true, rel=1e-10)
    # a second-order series: the order-1 estimate is conservative (larger than the truth)
    ds2, vals2, exact2 = _series(order=2.0)
    s2 = summarize_errors(relative_errors(ds2, 48.0, "mesh_elements"), "mesh_elements")
    true2 = np.max(np.abs(vals2[-1, 0] - exact2) / np.abs(vals2[-1, 0]).max())
    assert reference_error(s2, 48.0)["probe_resistance"] > true2


def test_errors_by_mode_give_max_and_median_per_mode():
    rows = [{"quantity": "q", "mode": m, "mesh_elements": 12.0, "relative_error": e}
            for m, e in (("uniaxial", 0.1), ("uniaxial", 0.3), ("uniaxial", 0.2), ("shear", 0.5), ("shear", np.nan))]
    by = summarize_by_mode(rows, "mesh_elements")
    assert by["q"]["uniaxial"][12.0] == {"max": 0.3, "median": 0.2}
    assert by["q"]["shear"][12.0] == {"max": 0.5, "median": 0.5}


def test_costs_sum_cpu_and_take_the_largest_rss(tmp_path):
    for k, (s, cpu, rss) in enumerate(((1.5, 1.0, 300.0), (2.5, 2.25, 500.0))):
        p = tmp_path / "run" / "mesh_elements-6" / "strain" / f"u{k}.tsv"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(f"s\th:m:s\tmax_rss\tmean_load\tcpu_time\n{s}\t0:00:01\t{rss}\t90\t{cpu}\n")
    assert combo_costs(tmp_path, "run") == {"mesh_elements-6": {"wall_s": 4.0, "cpu_s": 3.25, "max_rss_mb": 500.0}}


def test_wall_times_sum_the_jobs_of_each_combination(tmp_path):
    for combo, secs in (("mesh_elements-6", (1.5, 2.5)), ("mesh_elements-12", (4.0, 6.0))):
        for k, s in enumerate(secs):
            p = tmp_path / "run" / combo / "strain" / f"u{k}.tsv"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(f"s\th:m:s\tmax_rss\n{s}\t0:00:01\t100\n")
    (tmp_path / "run" / "gather.tsv").write_text("s\th:m:s\n99\t0\n")  # not a combination's job
    assert combo_wall_times(tmp_path, "run") == {"mesh_elements-6": 4.0, "mesh_elements-12": 10.0}


def test_job_writes_report_plot_and_accuracy(tmp_path):
    ds, _, _ = _series()
    pen = ds.rename({"mesh_elements": "contact_penalty"}).assign_coords(contact_penalty=[5.0, 15.0, 50.0, 150.0])
    outs = {k: tmp_path / f"out.{k}" for k in ("csv", "md", "png", "json")}
    acc = table_convergence_job(ds, pen, {"mesh": "m", "penalty": "p"}, outs, None,
                                {"mesh_elements": 12.0, "contact_penalty": 50.0}, bench_root=tmp_path,
                                states_root=tmp_path)
    assert acc["mesh"]["reference"] == 48.0 and acc["penalty"]["reference"] == 150.0
    assert 0 < acc["mesh"]["estimated_relative_error"]["probe_resistance"] < 0.01
    assert json.loads(outs["json"].read_text())["mesh"]["meets_targets"]["probe_resistance"] is True
    m = acc["mesh"]
    # the stated error adds the reference's own (Richardson) error to the difference
    assert m["stated_relative_error"]["probe_resistance"] == pytest.approx(
        m["estimated_relative_error"]["probe_resistance"] + m["reference_error"]["probe_resistance"])
    assert set(m["by_mode"]["probe_resistance"]) == {"uniaxial"}
    assert set(m["runs"]) == {"6", "12", "24", "48"}
    assert m["reference_error_by_mode"]["probe_resistance"]["uniaxial"] == pytest.approx(
        m["reference_error"]["probe_resistance"])   # one mode: the same figure
    assert "| probe resistance |" in outs["md"].read_text()
    assert outs["png"].stat().st_size > 10_000
    assert len(outs["csv"].read_text().splitlines()) > 30


# long: seven CI-size RVE runs (~5-10 min); the study code is tested above on stored tables,
# `pytest -m long` runs the whole study through Snakemake
@pytest.mark.slow
@pytest.mark.long
def test_ci_study_through_snakemake(tmp_path):
    pytest.importorskip("snakemake")
    from workflow_copy import workflow_copy

    work = workflow_copy(tmp_path)
    target = "results/rve/convergence/ci_table_convergence/table_convergence.md"
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-j2", target, "--configfile",
                           "configs/tests/pipeline_ci.yaml"], cwd=work, capture_output=True, text=True, timeout=2400)
    assert proc.returncode == 0, proc.stderr[-4000:]
    acc = json.loads((work / target).with_name("accuracy.json").read_text())
    assert acc["mesh"]["reference"] == 12.0 and acc["penalty"]["reference"] == 150.0
    errs = acc["mesh"]["estimated_relative_error"]
    assert set(errs) >= {"reaction_force", "probe_resistance", "yarn_resistance", "contact_resistance"}
    assert all(np.isfinite(v) and v >= 0 for v in errs.values())
    assert acc["mesh"]["wall_time_ratio_default_to_reference"] is not None
    text = (work / target).read_text()
    assert "wall time" in text and "P*" in text


def _label_series(ref_values, run_values):
    """A one-label reaction force (component x) and a constant big label (component y), two runs."""
    strain = np.linspace(0, 0.2, len(ref_values))
    f = np.zeros((2, 1, len(strain), 2))
    f[0, 0, :, 0], f[1, 0, :, 0] = run_values, ref_values
    f[:, 0, :, 1] = 10.0                         # constant: range 0
    f[0, 0, -1, 1] = 10.1                        # the coarse run off by 0.1 at the last strain
    ds = xr.Dataset({"reaction_force": (("mesh_elements", "mode", "strain", "component"), f)},
                    coords={"mesh_elements": [6.0, 12.0], "mode": ["shear"], "strain": strain, "component": ["x", "y"]})
    return ds


def test_range_measure_of_a_label_crossing_zero():
    """A label from +4 to -4 (crossing zero; max |q| = 4, range 8): a difference of 2 is
    50 % on the magnitude measure and 25 % on the range measure."""
    from rve.studies.table_convergence import RANGE_FLOOR

    ref = np.array([4.0, 2.0, 0.0, -2.0, -4.0])
    run = ref + np.array([0, 0, 0, 2.0, 0])
    rows = relative_errors(_label_series(ref, run), 12.0, "mesh_elements")
    x = [r for r in rows if r["label"] == "x"]
    assert max(r["relative_error"] for r in x) == pytest.approx(2.0 / 4.0)
    assert max(r["range_error"] for r in x) == pytest.approx(2.0 / 8.0)
    # the constant label: range 0, so the floor RANGE_FLOOR x the quantity's scale (the
    # reference's max |q| over every label: 10) divides
    y = [r for r in rows if r["label"] == "y"]
    assert max(r["range_error"] for r in y) == pytest.approx(0.1 / (RANGE_FLOOR * 10.0))
    assert max(r["relative_error"] for r in y) == pytest.approx(0.1 / 10.0)
    s = summarize_errors(rows, "mesh_elements", "range_error")
    assert s["reaction_force"][6.0] == pytest.approx(max(0.25, 0.1 / (RANGE_FLOOR * 10.0)))


def test_range_measure_equals_the_magnitude_measure_for_a_label_from_zero():
    # a label growing from 0 to its maximum: range = max |q|, both measures agree
    ref = np.array([0.0, 1.0, 2.0, 3.0, 5.0])
    rows = relative_errors(_label_series(ref, ref * 1.1), 12.0, "mesh_elements")
    for r in rows:
        if r["label"] == "x":
            assert r["range_error"] == pytest.approx(r["relative_error"], rel=1e-14)
