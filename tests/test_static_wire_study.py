"""Static-wire verification study: the Snakemake DAG on the CI config, the acceptance of
the radius sweep (thesis Fig. 6.3.2), the order fit on synthetic data, config schema."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from workflow_copy import workflow_copy

from rve.studies import static_wire as study

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "workflow" / "schemas" / "pipeline.schema.yaml"
CI_CONFIG = "configs/tests/pipeline_ci.yaml"
ANALYTICAL = 0.71243  # chapter 3 centre displacement / L (docs/verification_static_wire.md)


def _snakemake(cwd: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def ci_run(tmp_path_factory):
    """Run the static-wire study of the CI config once (7 solves). Only its outputs: the CI
    config's RVE table, which the default target also builds, is tests/test_rve_pipeline.py's."""
    pytest.importorskip("snakemake")
    from rve.studies import layout as study_layout

    work = workflow_copy(tmp_path_factory.mktemp("pipeline_ci"))
    proc = _snakemake(work, "-j2", *study_layout.STATIC_WIRE_OUTPUTS, "--configfile", CI_CONFIG)
    if proc.returncode != 0:
        logs = "\n".join(f"== {p}\n{p.read_text()[-3000:]}" for p in sorted(work.glob("results/logs/**/*.log")))
        pytest.fail(f"snakemake failed ({proc.returncode}):\n{proc.stderr[-5000:]}\n{logs}")
    return work


@pytest.fixture(scope="module")
def ci_dataset(ci_run):
    xr = pytest.importorskip("xarray")
    with xr.open_dataset(ci_run / "results/verification/static_wire.nc") as ds:
        return ds.load()


# --------------------------------------------------------------------------- pipeline
def test_default_target_builds_the_static_wire_study_and_the_rve_table(tmp_path):
    """`snakemake` without a target (the README's main line) plans both groups of the CI
    config's default_targets: the static-wire study's report and the RVE table's."""
    pytest.importorskip("snakemake")
    work = workflow_copy(tmp_path)
    proc = _snakemake(work, "-n", "--configfile", CI_CONFIG, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    jobs = {line.split()[0]: int(line.split()[1]) for line in proc.stdout.splitlines()
            if len(line.split()) == 2 and line.split()[1].isdigit()}
    assert jobs.get("static_wire_point") == 7 and jobs.get("static_wire_report") == 1, jobs
    assert jobs.get("rve_gather") == 1 and jobs.get("rve_report") == 1 and jobs.get("rve_exports") == 1, jobs


def test_pipeline_outputs(ci_run):
    res = ci_run / "results"
    for rel in ("verification/static_wire.nc", "verification/static_wire_radius.png",
                "verification/static_wire_convergence.png", "verification/static_wire_orders.csv",
                "verification/static_wire_orders.md"):
        assert (res / rel).stat().st_size > 0, rel
    for png in ("static_wire_radius.png", "static_wire_convergence.png"):
        assert (res / "verification" / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cfg = yaml.safe_load((ci_run / CI_CONFIG).read_text())["verification"]["static_wire"]
    points = study.study_points(cfg)
    assert len(points) == 7
    for p, n, r in points:
        name = study.point_name(p, n, r)
        rec = json.loads((res / f"verification/static_wire/points/{name}.json").read_text())
        assert rec["converged"] and (rec["order"], rec["elements"]) == (p, n)
        assert (res / f"benchmarks/verification/static_wire/points/{name}.tsv").exists()
        assert (res / f"logs/verification/static_wire/points/{name}.log").exists()
    for rule in ("gather", "report"):
        assert (res / f"benchmarks/verification/static_wire/{rule}.tsv").exists()
    table = (res / "verification/static_wire_orders.csv").read_text().splitlines()
    assert table[0].startswith("order,parity,") and len(table) == 3  # p = 2, odd and even


def test_dataset_dims_units_provenance(ci_dataset):
    ds = ci_dataset
    assert {"order", "elements", "radius", "parity"} <= set(ds.dims)
    assert ds["centre_displacement"].dims == ("order", "elements", "radius")
    assert list(ds["order"].values) == [2]
    assert sorted(ds["radius"].values) == [0.005, 0.02, 0.08]
    for name in list(ds.data_vars) + list(ds.coords):
        attrs = ds[name].attrs
        assert attrs.get("units"), f"{name} has no units"
        assert attrs.get("long_name"), f"{name} has no long_name"
    assert ds["radius"].attrs["units"] == "mm"
    assert ds["wall_time_s"].attrs["units"] == "s"
    for name in ("centre_displacement", "analytical_centre_displacement", "error", "newton_iterations",
                 "wall_time_s", "dofs", "fitted_order"):
        assert name in ds, name
    # NaN where a (p, N, R) was not computed
    assert np.isnan(float(ds["centre_displacement"].sel(order=2, elements=6, radius=0.08)))
    # provenance
    assert ds.attrs["rve_version"] and ds.attrs["rve_version"] != "unknown"
    assert ds.attrs["date_created"][:2] == "20"
    assert json.loads(ds.attrs["study_config"])["radius_sweep"]["radii_mm"] == [0.08, 0.02, 0.005]
    assert json.loads(ds.attrs["scene_config"])["scene"] == "static_wire"
    assert ds.attrs["reference_solution"] == "p=2, N=40, R=0.02 mm"
    assert "N in [6, 11]" in ds["fitted_order"].attrs["fit_range"]
    # error vs the reference: zero there, finite on the convergence series, NaN elsewhere
    err = ds["error"]
    assert float(err.sel(order=2, elements=40, radius=0.02)) == 0.0
    assert np.isfinite(err.sel(order=2, radius=0.02).sel(elements=[6, 7, 10, 11]).values).all()
    assert np.isnan(err.sel(radius=0.08).values).all()
    # p = 2 errors fall at a positive rate over N = 6..11
    q = ds["fitted_order"].sel(order=2).values
    assert np.all(q > 2.0), q


# --------------------------------------------------------------------------- acceptance
def test_radius_sweep_approaches_analytical(ci_dataset):
    """p = 2, N = 40: at R = 0.005 mm the centre displacement is within 0.5% of the
    chapter-3 value, and |c(R) - c_analytical| decreases as R falls (thesis Fig. 6.3.2)."""
    ds = ci_dataset
    c = ds["centre_displacement"].sel(order=2, elements=40)
    ca = float(ds["analytical_centre_displacement"].sel(order=2, elements=40, radius=0.005))
    assert ca == pytest.approx(ANALYTICAL, abs=1e-5)
    c_small = float(c.sel(radius=0.005))
    assert abs(c_small - ANALYTICAL) / ANALYTICAL < 0.005, c_small
    radii = sorted(ds["radius"].values, reverse=True)  # 0.08, 0.02, 0.005
    errors = [abs(float(c.sel(radius=r)) - ca) for r in radii]
    assert all(np.isfinite(errors))
    assert all(a > b for a, b in zip(errors, errors[1:])), dict(zip(radii, errors))


# --------------------------------------------------------------------------- spatial orders
#: The asymptotic O(h^6) of p = 4, odd N shows only between N = 21 and 27; the study's
#: configured range 5-13 is pre-asymptotic (fitted 6.56, docs/verification_static_wire.md).
P4_ODD_ASYMPTOTIC = (21, 27)


def _solve_points(points):
    scene = ROOT / "configs/scenes/static_wire.yaml"
    return [study.convergence_point(scene, p, n, r) for p, n, r in points]


def _fitted_orders(points, reference, ranges):
    recs = _solve_points(points)
    ds = study.build_dataset(recs, convergence_radius=points[0][2], reference=reference)
    return study.fit_orders(ds, ranges)


def _assert_expected_orders(table, parities_checked):
    seen = set()
    for row in table.itertuples(index=False):
        if row.points < 2:
            continue
        seen.add((row.order, row.parity))
        assert abs(row.fitted_order - study.expected_order(row.order, row.parity)) <= 0.3, row
    assert parities_checked <= seen, (parities_checked, seen)


def test_spatial_orders_reduced_plan():
    """Fitted order per p within 0.3 of ``expected_order`` on a reduced plan: two N per
    (p, parity) inside the study's asymptotic ranges (configs/pipeline.yaml), the study's
    reference (p = 4, N = 36) at R = 0.02 mm. ~12 s."""
    cfg = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())["verification"]["static_wire"]
    r = float(cfg["convergence"]["radius_mm"])
    reference = study.study_reference(cfg)
    assert reference == (4, 36)
    plan = {1: [40, 41, 80, 81], 2: [30, 60], 3: [20, 40]}
    ranges = study.study_fit_ranges(cfg)
    for p, ns in plan.items():  # the reduced points lie in the study's ranges
        for n in ns:
            lo, hi = ranges[p]["odd" if n % 2 else "even"]
            assert lo <= n <= hi, (p, n)
    points = [(p, n, r) for p, ns in plan.items() for n in ns] + [(*reference, r)]
    table = _fitted_orders(points, reference, {p: ranges[p] for p in plan})
    _assert_expected_orders(table, {(1, "odd"), (1, "even"), (2, "even"), (3, "even")})


@pytest.mark.slow
def test_spatial_orders_full_study():
    """The whole convergence study of configs/pipeline.yaml (79 solves, ~3 min): every
    (p, parity) within 0.3 of ``expected_order`` over the study's ranges, p = 4 odd over
    its asymptotic range ``P4_ODD_ASYMPTOTIC`` (those points are in the study)."""
    cfg = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())["verification"]["static_wire"]
    r = float(cfg["convergence"]["radius_mm"])
    points = [pt for pt in study.study_points(cfg) if pt[2] == r]
    ranges = study.study_fit_ranges(cfg)
    ranges[4]["odd"] = P4_ODD_ASYMPTOTIC
    table = _fitted_orders(points, study.study_reference(cfg), ranges)
    _assert_expected_orders(table, {(p, par) for p in (1, 2, 3, 4) for par in ("odd", "even")})


# --------------------------------------------------------------------------- fit on synthetic data
def _synthetic_records(slopes, ns, c_ref=0.7, amp=0.3, radius=0.02):
    """c(p, N) = c_ref + amp * s * h^q with q = slopes[(p, parity)], h = 2/N, the sign s
    alternating with p; reference: p = 4, N = 64, c = c_ref exactly."""
    recs = []
    for p, Ns in ns.items():
        for n in Ns:
            q = slopes[(p, "odd" if n % 2 else "even")]
            sign = 1.0 if p % 2 else -1.0
            recs.append({"order": p, "elements": n, "radius": radius, "converged": True,
                         "centre_displacement": c_ref + sign * amp * (2.0 / n) ** q,
                         "analytical_centre_displacement": 0.71243, "newton_iterations": 3,
                         "relaxation_newton_iterations": 10, "dofs": 9 * (p * n + 1),
                         "wall_time_s": {"total": 0.1}})
    recs.append({"order": 4, "elements": 64, "radius": radius, "converged": True, "centre_displacement": c_ref,
                 "analytical_centre_displacement": 0.71243, "newton_iterations": 3,
                 "relaxation_newton_iterations": 10, "dofs": 9 * 257, "wall_time_s": {"total": 1.0}})
    return recs


def test_fit_orders_recovers_known_slopes():
    slopes = {(1, "odd"): 2.0, (1, "even"): 2.0, (2, "odd"): 3.0, (2, "even"): 4.0,
              (3, "odd"): 4.0, (3, "even"): 6.0, (4, "odd"): 6.0, (4, "even"): 8.0}
    ns = {1: [20, 21, 40, 41, 80, 81], 2: [8, 9, 16, 17, 32, 33], 3: [5, 6, 9, 10, 17, 18],
          4: [4, 5, 7, 8, 11, 12]}
    recs = _synthetic_records(slopes, ns)
    # points outside the asymptotic range that a wrong range selection would pick up
    recs.append({**recs[0], "elements": 2, "centre_displacement": 0.9})
    recs.append({**recs[0], "elements": 3, "centre_displacement": 0.3})
    ds = study.build_dataset(recs)
    assert ds.attrs["reference_solution"] == "p=4, N=64, R=0.02 mm"
    ranges = {1: (20, 81), 2: {"min": 8, "max": 33}, 3: {"odd": (5, 17), "even": (6, 18)}, 4: (4, 64)}
    table = study.fit_orders(ds, ranges)
    assert len(table) == 8
    for row in table.itertuples(index=False):
        assert row.points == 3, row
        assert row.fitted_order == pytest.approx(slopes[(row.order, row.parity)], abs=1e-9), row
        assert row.expected_order == study.expected_order(row.order, row.parity)
    fitted = ds["fitted_order"]
    assert fitted.dims == ("order", "parity")
    assert float(fitted.sel(order=2, parity="even")) == pytest.approx(4.0, abs=1e-9)
    assert float(fitted.sel(order=2, parity="odd")) == pytest.approx(3.0, abs=1e-9)
    assert "p=3 odd N in [5, 17]" in fitted.attrs["fit_range"]
    # the reference (p = 4, N = 64) lies in p = 4's range but is excluded
    assert "64" not in table.set_index(["order", "parity"]).loc[(4, "even"), "elements_used"].split()
    # stored table == returned table
    stored = study.orders_table(ds)
    assert np.allclose(stored["fitted_order"].values, table["fitted_order"].values)


def test_fit_orders_mixing_parity_or_range_gives_other_slopes():
    """The fit must see the parity and the range: on data with different odd/even rates, a
    fit over all N or over the pre-asymptotic points is far from both rates."""
    slopes = {(2, "odd"): 3.0, (2, "even"): 4.0}
    ns = {2: [8, 9, 16, 17, 32, 33]}
    recs = _synthetic_records(slopes, ns)
    recs.append({**recs[0], "elements": 4, "centre_displacement": 0.7 - 1e-6})  # off-trend, out of range
    ds = study.build_dataset(recs)
    good = study.fit_orders(ds, {2: (8, 33)}).set_index("parity")["fitted_order"]
    assert good["odd"] == pytest.approx(3.0, abs=1e-9) and good["even"] == pytest.approx(4.0, abs=1e-9)
    wide = study.fit_orders(ds, {2: (4, 33)}).set_index("parity")["fitted_order"]
    assert abs(wide["even"] - 4.0) > 0.5
    # one point in range: no fit
    one = study.fit_orders(ds, {2: (30, 32)}).set_index("parity")
    assert one.loc["even", "points"] == 1 and math.isnan(one.loc["even", "fitted_order"])


def test_expected_orders():
    assert [study.expected_order(p, "even") for p in (1, 2, 3, 4)] == [2, 4, 6, 8]
    assert [study.expected_order(p, "odd") for p in (1, 2, 3, 4)] == [2, 4, 4, 6]


# --------------------------------------------------------------------------- config
def test_study_design_from_config():
    cfg = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())["verification"]["static_wire"]
    points = study.study_points(cfg)
    assert len(points) == len(set(points))
    assert (2, 40, 0.02) in points and (2, 40, 0.005) in points and (4, 36, 0.02) in points
    ranges = study.study_fit_ranges(cfg)
    assert set(ranges) == {1, 2, 3, 4}
    assert study.study_reference(cfg) == (4, 36)
    for p, per in ranges.items():
        series = next(s for s in cfg["convergence"]["series"] if s["order"] == p)
        for parity, (lo, hi) in per.items():
            inside = [n for n in series["elements"] if lo <= n <= hi and n % 2 == (parity == "odd")]
            assert len(inside) >= 2, (p, parity)


def test_pipeline_configs_validate_against_schema():
    from snakemake.exceptions import WorkflowError
    from snakemake.utils import validate

    for rel in ("configs/pipeline.yaml", CI_CONFIG):
        validate(yaml.safe_load((ROOT / rel).read_text()), schema=str(SCHEMA))
    bad = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    bad["verification"]["static_wire"]["convergence"]["series"][0]["order"] = 7
    with pytest.raises(WorkflowError):
        validate(bad, schema=str(SCHEMA))
    bad = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    bad["verification"]["static_wire"]["radius_sweep"]["radii_mm"] = [-0.01]
    with pytest.raises(WorkflowError):
        validate(bad, schema=str(SCHEMA))


def test_snakemake_lint_is_clean(tmp_path):
    pytest.importorskip("snakemake")
    work = workflow_copy(tmp_path)
    proc = _snakemake(work, "--lint", timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Congratulations" in proc.stdout + proc.stderr


def test_dynamic_wire_plan_defaults_come_from_the_schema():
    """The schema's verification.dynamic_wire defaults are the study's DEFAULT_PLAN, a given
    series replaces the default ones and a partial reference keeps the other default; a
    series outside s = 1..3 is refused."""
    from snakemake.exceptions import WorkflowError
    from snakemake.utils import validate

    from rve.studies.dynamic_wire import normalise_plan

    cfg = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    validate(cfg, schema=str(SCHEMA))
    assert normalise_plan(cfg["verification"]["dynamic_wire"]) == normalise_plan(None)
    cfg = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    cfg["verification"]["dynamic_wire"] = {"reference": {"steps": 2000},
                                           "series": {"2": {"steps": [10, 20], "fit": [10, 20]}}}
    validate(cfg, schema=str(SCHEMA))
    plan = normalise_plan(cfg["verification"]["dynamic_wire"])
    assert plan["reference"] == {"stages": 3, "steps": 2000}
    assert plan["series"] == {2: {"steps": [10, 20], "fit": [10, 20]}}
    assert plan["scene_config"] == "configs/scenes/dynamic_wire.yaml"
    cfg["verification"]["dynamic_wire"] = {"series": {"4": {"steps": [10], "fit": [10, 10]}}}
    with pytest.raises(WorkflowError):
        validate(cfg, schema=str(SCHEMA))


def test_rule_files_import_only_layouts_at_parse_time():
    """At parse time the Snakefile and the rule files import rve's layout modules and the
    config reader only; the job bodies are imported inside the rules."""
    allowed = {"rve.scenes.layout", "rve.studies.layout", "rve.homogenisation.layout", "rve.config.loader",
               "rve.scenes", "rve.studies", "rve.homogenisation"}
    for path in [ROOT / "Snakefile", *sorted((ROOT / "workflow/rules").glob("*.smk"))]:
        for line in path.read_text().splitlines():
            if line.startswith(("from rve", "import rve")):
                module = line.split()[1]
                names = line.split(" import ", 1)[1] if " import " in line else ""
                assert module in allowed, f"{path.name}: {line}"
                if module in ("rve.scenes", "rve.studies", "rve.homogenisation"):
                    assert names.split()[0] == "layout", f"{path.name}: {line}"
