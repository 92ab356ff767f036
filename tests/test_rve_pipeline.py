"""RVE pipeline (thesis ch. 7): the Snakemake DAG of the CI config (tiny 2 x 2 weave, 2 steps
per mode), the acceptance checks on its table, the checkpoints, resume after a kill with an
identical table, parameter sweeps, config and schema."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from workflow_copy import workflow_copy

from rve.homogenisation import layout as L
from rve.homogenisation import sweeps as S

ROOT = Path(__file__).resolve().parents[1]
CI_CONFIG = "configs/tests/pipeline_ci.yaml"
SCHEMA = ROOT / "workflow" / "schemas" / "pipeline.schema.yaml"
RUN = "ci"
TABLE = f"results/rve/{RUN}/table.nc"
PLOTS = list(L.report_outputs(RUN).values())
EXPORTS = list(L.export_outputs(RUN).values())
MODES = ["uniaxial", "shear", "uniaxial_y", "trellis"]
PROBES = ["probe1", "probe2", "probe3", "probe4"]


def _ci_spec():
    return yaml.safe_load((ROOT / CI_CONFIG).read_text())["rve"]["runs"][RUN]


def _snakemake_cmd(*targets: str, extra=()) -> list[str]:
    # targets before --configfile (which takes several values)
    return [sys.executable, "-m", "snakemake", "-j2", *targets, *extra, "--configfile", CI_CONFIG]


def _run(cwd: Path, cmd: list[str], timeout: float = 600) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        logs = "\n".join(f"== {p}\n{p.read_text()[-3000:]}" for p in sorted(cwd.glob("results/logs/rve/**/*.log")))
        pytest.fail(f"snakemake failed ({proc.returncode}):\n{proc.stderr[-5000:]}\n{logs}")
    return proc


@pytest.fixture(scope="module")
def ci_run(tmp_path_factory):
    """The whole RVE DAG of the CI config, uninterrupted (22 jobs)."""
    pytest.importorskip("snakemake")
    work = workflow_copy(tmp_path_factory.mktemp("rve_ci"))
    t0 = time.perf_counter()
    _run(work, _snakemake_cmd(TABLE, *PLOTS, *EXPORTS))
    work.joinpath("wall_s.txt").write_text(f"{time.perf_counter() - t0:.1f}\n")
    return work


@pytest.fixture(scope="module")
def table(ci_run):
    from rve.tables import open_table

    return open_table(ci_run / TABLE)


# --------------------------------------------------------------------------- DAG outputs
def test_every_stage_wrote_outputs_logs_and_benchmarks(ci_run):
    res = ci_run / "results"
    spec = _ci_spec()
    cfg = S.load_run_config(spec)
    names = L.state_names(cfg)
    assert names == ["relaxed"] + [f"{m}_{k:02d}" for m in MODES for k in (1, 2)]
    base = res / "rve" / RUN / "base"
    for n in ["initial", *names]:
        assert (base / "states" / f"{n}.nc").stat().st_size > 0, n
    for n in names:
        rec = json.loads((base / "probes" / f"{n}.json").read_text())
        assert set(rec["probes"]) == set(PROBES)
        assert (res / f"benchmarks/rve/{RUN}/base/probes/{n}.tsv").exists()
        assert (res / f"logs/rve/{RUN}/base/probes/{n}.log").exists()
    for n in names[1:]:
        assert (res / f"benchmarks/rve/{RUN}/base/strain/{n}.tsv").exists()
    for stage in ("fabric", "relax"):
        assert (res / f"benchmarks/rve/{RUN}/base/{stage}.tsv").exists()
        assert (res / f"logs/rve/{RUN}/base/{stage}.log").exists()
    for stage in ("gather", "exports", "report"):
        assert (res / f"benchmarks/rve/{RUN}/{stage}.tsv").exists()
    for png in PLOTS:
        assert (ci_run / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "probe_resistance" in (res / f"rve/{RUN}/table.csv").read_text()
    assert "probe resistance" in (res / f"rve/{RUN}/summary.txt").read_text()
    # no temporary files of the atomic writers are left behind
    assert not list((res / "rve").rglob("*.tmp"))


def test_checkpoints_are_self_describing_and_land_on_the_strain_path(ci_run):
    from rve.homogenisation.checkpoint import STATE_FORMAT, load_state
    from rve.fabrics.setup import clamped_ends, fabric_and_mesh
    from rve.homogenisation.strain import strain_levels

    spec = _ci_spec()
    cfg = S.load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    ends, _, _ = clamped_ends(fab, mesh)
    levels = strain_levels(cfg)
    base = ci_run / "results" / "rve" / RUN / "base" / "states"
    relaxed = load_state(base / "relaxed.nc")
    assert relaxed.kind == "relaxed" and relaxed.strain == 0.0
    np.testing.assert_array_equal(relaxed.origin, relaxed.x)
    assert relaxed.config["fabric"]["n_warp"] == 2 and relaxed.config["scene"] == "rve"
    from rve.homogenisation.strain import end_targets

    for mode in MODES:
        for step in (1, 2):
            st = load_state(base / f"{mode}_{step:02d}.nc")
            assert (st.kind, st.mode, st.step) == ("strained", mode, step)
            assert st.strain == pytest.approx(levels[step])
            assert st.solver["converged"]
            # ends at F(eps) X exactly (X: the relaxed state; uniaxial X + eps X1 e1, shear X + eps X1 e2,
            # uniaxial_y X + eps X2 e2, trellis the picture frame)
            want = end_targets(relaxed.x[ends, :3], mode, levels[step])
            np.testing.assert_allclose(st.x[ends, :3], want, rtol=0, atol=1e-13)
            assert set(st.reaction_force) == {"x-", "x+", "y-", "y+"}
    import xarray as xr

    with xr.open_dataset(base / "shear_02.nc") as ds:
        assert ds.attrs["rve_state_format"] == STATE_FORMAT
        assert ds["state"].attrs["units"] == "mm" and ds["reaction_force"].attrs["units"] == "N"
        assert ds.sizes["component"] == 9 and ds.sizes["pair"] > 0
        assert int(ds["contact_active_points"].sum()) == ds.attrs["contact_count"] > 0


# --------------------------------------------------------------------------- table acceptance
def test_table_has_both_modes_all_levels_and_probes(table):
    assert list(table["mode"].values) == MODES
    np.testing.assert_allclose(table["strain"].values, [0.0, 0.05, 0.1])
    assert list(table["probe"].values) == PROBES
    for v in ("reaction_force", "probe_current", "probe_resistance", "temperature_rise_max",
              "temperature_rise_mean", "contact_count"):
        assert np.all(np.isfinite(table[v].values)), v
    assert np.all(table["temperature_rise_max"].values > 0)
    # every stored state is a static equilibrium (the CI config's tolerance, 1e-9 N)
    assert table["equilibrium_residual"].attrs["units"] == "N"
    assert float(table["equilibrium_residual"].max()) <= 1e-9
    assert np.all(table["temperature_rise_max"] >= table["temperature_rise_mean"])


def test_relaxed_cell_is_in_tension_at_the_clamps(table):
    rf = table["reaction_force"].sel(strain=0.0)
    for m in table["mode"].values:
        f = rf.sel(mode=m)
        assert float(f.sel(side="x-", component="x")) < 0 < float(f.sel(side="x+", component="x"))
        assert float(f.sel(side="y-", component="y")) < 0 < float(f.sel(side="y+", component="y"))
        # the clamps balance the fabric
        assert np.abs(f.sum("side").values).max() < 1e-8


def test_probe1_has_the_lowest_resistance_at_every_strain(table):
    r = table["probe_resistance"]
    p1 = r.sel(probe="probe1")
    others = r.sel(probe=["probe2", "probe3"]).min("probe")
    assert bool((p1 < others).all())


def test_terminal_currents_are_equal_and_opposite(table):
    i = table["probe_current"]
    ip, im = i.sel(terminal="+"), i.sel(terminal="-")
    assert bool((ip > 0).all())
    assert float(np.abs((ip + im) / ip).max()) < 1e-9  # leak of the weakened insulation ~1e-11
    assert table.attrs["max_charge_conservation_error"] < 1e-9  # I+ + I- + I_leak, solver tolerance


def test_interpolation_at_stored_strains_returns_stored_values(table):
    from rve.tables import interpolate

    s = table["strain"].values
    for m in table["mode"].values:
        out = interpolate(table, s, mode=m)
        for v in ("probe_resistance", "reaction_force", "temperature_rise_max"):
            np.testing.assert_array_equal(out[v].values, table[v].sel(mode=m).values)
    mid = interpolate(table, [0.025], mode="uniaxial")["probe_resistance"].values
    lo, hi = (table["probe_resistance"].sel(mode="uniaxial", strain=v).values for v in (0.0, 0.05))
    np.testing.assert_allclose(mid[0], 0.5 * (lo + hi))


def test_cf_attributes(table):
    assert table.attrs["Conventions"].startswith("CF-")
    for name in list(table.data_vars) + list(table.coords):
        attrs = table[name].attrs
        assert "units" in attrs and "long_name" in attrs, name
    assert table["probe_resistance"].attrs["units"] == "ohm"
    assert table["reaction_force"].attrs["units"] == "N"
    assert "axis" not in table["strain"].attrs  # CF: strain is not a space axis
    assert table.attrs["Conventions"] == "CF-1.11"
    cfg = json.loads(table.attrs["config"])
    assert cfg["run"] == RUN and cfg["scene"]["scene"] == "rve"
    probes = json.loads(table.attrs["probe_definitions"])
    assert [p["name"] for p in probes] == PROBES
    assert list(table["probe_terminals"].values) == ["warp0+ | warp0-", "warp0+ | warp1-", "warp0+ | weft0+",
                                                     "weft0+ | weft0-"]


# --------------------------------------------------------------------------- resume
def _data(ds):
    return {k: ds[k].values for k in list(ds.data_vars) + list(ds.coords)}


def test_killed_run_resumes_with_an_identical_table(ci_run, table, tmp_path):
    """Kill the run (SIGKILL of the whole process group, as a power cut) once the first
    strain step is on disk, unlock, re-run: it resumes from the stored states (the relax
    is not redone) and the table is identical to the uninterrupted run's."""
    from rve.tables import open_table

    work = workflow_copy(tmp_path)
    states = work / "results" / "rve" / RUN / "base" / "states"
    proc = subprocess.Popen(_snakemake_cmd(TABLE), cwd=work, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        t0 = time.time()
        while not list(states.glob("*_01.nc")):
            if proc.poll() is not None or time.time() - t0 > 300:
                pytest.fail(f"snakemake ended ({proc.returncode}) before a strain step was written")
            time.sleep(0.2)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not (work / TABLE).exists()
    relaxed_mtime = (states / "relaxed.nc").stat().st_mtime_ns
    _run(work, [sys.executable, "-m", "snakemake", "--unlock", "--configfile", CI_CONFIG], timeout=120)
    proc = _run(work, _snakemake_cmd(TABLE, extra=("--rerun-incomplete",)))
    assert (states / "relaxed.nc").stat().st_mtime_ns == relaxed_mtime  # resumed, not redone
    assert "rve_relax" not in proc.stdout + proc.stderr.split("Job stats")[-1].split("Reasons")[0]
    resumed = open_table(work / TABLE)
    a, b = _data(table), _data(resumed)
    assert a.keys() == b.keys()
    for k in a:
        # bit for bit: each job's output depends only on its input file (one BLAS thread per
        # job, set by the Snakefile; no wall-time budgets in the solvers)
        if a[k].dtype.kind == "f":
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        else:
            assert list(a[k].ravel()) == list(b[k].ravel()), k


# --------------------------------------------------------------------------- sweeps
def _tiny_spec(**extra):
    spec = {"scene": {"fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]}, "mesh": {"elements": 6},
                      "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2},
                      "strain": {"modes": ["uniaxial"], "total": 0.05, "steps": 1}}}
    spec.update(extra)
    return spec


def test_combos_of_a_sweep():
    spec = {"sweep": {"fibril.radius": [0.12, 0.15], "contact.sigma_c": [0.5, 1.0], "weave": ["plain", "twill_2_2"]}}
    cs = S.combos(spec)
    assert len(cs) == 8
    assert cs[0].id == "fibril_radius-0.12__contact_conductance-0.5__weave-plain"
    assert cs[0].params == {"fibril_radius": 0.12, "contact_conductance": 0.5, "weave": "plain"}
    assert "fabric.fibril_diameter=0.24" in cs[0].overrides
    assert S.swept_dims(spec) == {"fibril_radius": "mm", "contact_conductance": "A mm-2 V-1", "weave": "1"}
    cfg = S.load_run_config({**_tiny_spec(), **spec}, cs[-1].id)
    assert cfg.fabric.fibril_diameter == pytest.approx(0.3) and cfg.contact.conductance == 1.0
    assert cfg.fabric.kind == "twill_2_2"
    assert S.combos({"sweep": {"contact.penalty": ["40 N/mm^2"]}})[0].params == {"contact_penalty": 40.0}
    with pytest.raises(ValueError, match="unknown sweep parameter"):
        S.combos({"sweep": {"colour": [1]}})
    assert S.combo_ids({}) == ["base"]


# --------------------------------------------------------------------------- configs
def test_configs_validate_and_default_target_is_the_plain_weave_table():
    from snakemake.exceptions import WorkflowError
    from snakemake.utils import validate

    from rve.config.rve import RVEConfig

    cfg = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    validate(cfg, schema=str(SCHEMA))
    assert L.default_targets({**cfg, "default_targets": ["rve"]})[0] == "results/rve/plain_weave/table.nc"
    default = S.load_run_config(cfg["rve"]["runs"]["plain_weave"])
    assert isinstance(default, RVEConfig)
    # thesis Table 7.1 and Algorithm 7.1 / §7.4
    assert default.fabric.fibril_diameter == pytest.approx(0.3)
    assert default.material.youngs_modulus == pytest.approx(1.26)
    assert default.material.electrical_conductivity == pytest.approx(10.0)
    assert default.material.thermal_conductivity == pytest.approx(1.0)
    assert default.contact.heat_transfer == pytest.approx(0.1) and default.contact.conductance == pytest.approx(1.0)
    assert default.strain.modes == ["uniaxial", "shear"]
    assert (default.strain.total, default.strain.steps) == (0.25, 10)
    assert [p.name for p in default.probes] == ["probe1", "probe2", "probe3", "probe4"]  # + a weft yarn end to end
    assert len(L.state_names(default)) == 21
    knit = S.load_run_config(cfg["rve"]["runs"]["knit"])
    assert knit.fabric.kind == "knit" and knit.probes[0].terminals[0].yarn == "loop"
    assert len(S.combos(cfg["rve"]["runs"]["weave_sweep"])) == 8
    ci = yaml.safe_load((ROOT / CI_CONFIG).read_text())
    validate(ci, schema=str(SCHEMA))
    bad = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    bad["rve"]["runs"]["plain_weave"]["sweep"] = {"weave": []}
    with pytest.raises(WorkflowError):
        validate(bad, schema=str(SCHEMA))
    bad = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())
    bad["rve"]["runs"]["plain_weave"]["colour"] = 1
    with pytest.raises(WorkflowError):
        validate(bad, schema=str(SCHEMA))


def test_rve_config_rejects_bad_probes_and_modes():
    from rve.config import ConfigError

    with pytest.raises(ConfigError, match="terminals"):
        S.load_run_config({"scene": {"probes": [{"name": "p", "terminals": [{"yarn": "warp", "position": 1,
                                                                              "end": "x+"}]}]}})
    with pytest.raises(ConfigError, match="modes"):
        S.load_run_config({"scene": {"strain": {"modes": ["uniaxial", "uniaxial"]}}})
    with pytest.raises(ConfigError, match="seebeck"):
        S.load_run_config({"scene": {"material": {"seebeck": 1e-6}}})


@pytest.mark.slow
def test_sweep_runs_through_snakemake_with_one_dimension_per_parameter(tmp_path):
    """The CI config's `ci_sweep` (two contact conductances) through Snakemake: every
    combination has its own chain of jobs; the gathered table has a `contact_conductance`
    dimension. The mechanics does not depend on sigma_C, so the two combinations' reaction
    forces are identical (separate jobs, same bits); the contact-dominated probes (2, 3)
    conduct better with the larger sigma_C."""
    from rve.tables import open_table

    work = workflow_copy(tmp_path)
    target = "results/rve/ci_sweep/table.nc"
    _run(work, _snakemake_cmd(target))
    spec = yaml.safe_load((ROOT / CI_CONFIG).read_text())["rve"]["runs"]["ci_sweep"]
    ids = S.combo_ids(spec)
    assert len(ids) == 2
    for cid in ids:
        states = work / "results" / "rve" / "ci_sweep" / cid / "states"
        assert (states / "relaxed.nc").exists() and (states / "uniaxial_01.nc").exists(), cid
        assert (work / f"results/benchmarks/rve/ci_sweep/{cid}/relax.tsv").exists(), cid
    t = open_table(work / target)
    assert t.sizes["contact_conductance"] == 2
    assert t["probe_resistance"].dims == ("mode", "strain", "contact_conductance", "probe")
    np.testing.assert_allclose(t["contact_conductance"].values, [0.5, 2.0])
    assert t["contact_conductance"].attrs["units"] and t["contact_conductance"].attrs["long_name"]
    rf = t["reaction_force"]
    np.testing.assert_array_equal(rf.isel(contact_conductance=0).values, rf.isel(contact_conductance=1).values)
    r = t["probe_resistance"]
    lo, hi = r.isel(contact_conductance=0), r.isel(contact_conductance=1)
    for p in ("probe2", "probe3"):
        assert bool((hi.sel(probe=p) < lo.sel(probe=p)).all()), p


# --------------------------------------------------------------------------- macro quantities and exports
def test_macro_exports_beside_the_table(ci_run, table):
    from rve.tables.formats import read_abaqus_curves, read_lsdyna_curves

    out = {k: ci_run / v for k, v in L.export_outputs(RUN).items()}
    curves = read_abaqus_curves(out["abaqus"])
    assert set(curves) == {"1", "2", "12"}
    text = out["abaqus"].read_text()
    assert "from mode uniaxial_y" in text and "from mode trellis" in text and "symmetric weave" not in text
    N = table["membrane_force"]
    np.testing.assert_array_equal(curves["2"][1], [float(f"{v:.9e}") for v in (
        N.sel(mode="uniaxial_y", edge="y", component="y").values
        - float(table["membrane_force_at_zero_strain"].sel(mode="uniaxial_y", edge="y", component="y")))])
    assert len(read_lsdyna_curves(out["lsdyna"])) == 3
    assert sorted(p.name for p in out["curves"].glob("*.csv")) == ["shear.csv", "warp.csv", "weft.csv"]
    assert json.loads(out["hermite"].read_text())["format"] == "rve-hermite/1"
    # the relaxed cell's pretension is recorded; the areal density is the cell's mass / area
    assert float(table["membrane_force_at_zero_strain"].sel(mode="uniaxial", edge="x", component="x")) > 0
    assert float(table["areal_density"]) == pytest.approx(4 * 4.0 * np.pi * 0.15 ** 2 * 1e-3 / 16.0, rel=1e-12)
    # the 4th probe separates warp and weft; the weave is symmetric at strain 0
    r0 = table.sel(mode="uniaxial", strain=0.0)
    assert float(r0["yarn_resistance_warp"]) == pytest.approx(float(r0["yarn_resistance_weft"]), rel=1e-3)
    assert float(r0["network_fit_residual_warp_weft"]) < 0.05
    assert float(r0["probe_resistance"].sel(probe="probe4")) == pytest.approx(
        float(r0["probe_resistance"].sel(probe="probe1")), rel=1e-3)
    # trellis keeps the yarn lengths; uniaxial_y stretches the weft
    assert float(table["yarn_strain"].sel(mode="trellis", strain=0.1, yarn="warp")) == 0.0
    assert float(table["yarn_strain"].sel(mode="uniaxial_y", strain=0.1, yarn="weft")) == pytest.approx(0.1)


def test_wall_time_per_mode_from_the_benchmarks(ci_run):
    """The benchmarks give the wall time per mode (strain steps + probe jobs); printed for the report."""
    import csv

    bench = ci_run / "results" / "benchmarks" / "rve" / RUN / "base"
    per_mode = {}
    for m in MODES:
        total = 0.0
        for stage in ("strain", "probes"):
            for k in (1, 2):
                with open(bench / stage / f"{m}_{k:02d}.tsv") as fh:
                    total += float(next(csv.DictReader(fh, delimiter="\t"))["s"])
        per_mode[m] = total
    print("wall s per mode (strain steps + probes):", {m: round(v, 1) for m, v in per_mode.items()})
    assert all(v > 0 for v in per_mode.values())


# --------------------------------------------------------------------------- driver modes (no Snakemake)
def test_driver_fields_of_the_new_modes():
    from rve.homogenisation.strain import affine_velocity, end_targets, secant_velocity, trellis_gradient

    rng = np.random.default_rng(3)
    origin = rng.normal(size=(7, 9))
    # uniaxial_y: v = rate X2 e2 on the centroids and (g_a)_2 e2 on the directors
    w = affine_velocity(origin, "uniaxial_y", 2.0)
    for blk in range(3):
        np.testing.assert_array_equal(w[:, 3 * blk + 1], 2.0 * origin[:, 3 * blk + 1])
        assert not w[:, 3 * blk].any() and not w[:, 3 * blk + 2].any()
    # the old modes: unchanged arithmetic (bit for bit)
    w = affine_velocity(origin, "shear", 0.5)
    np.testing.assert_array_equal(w[:, 1], 0.5 * origin[:, 0])
    np.testing.assert_array_equal(w[:, 4], 0.5 * origin[:, 3])
    # trellis: both families keep their length, the angle drops by theta
    F = trellis_gradient(0.3)
    assert np.linalg.norm(F[:, 0]) == pytest.approx(1.0, abs=1e-15)
    assert np.linalg.norm(F[:, 1]) == pytest.approx(1.0, abs=1e-15)
    assert np.arccos(F[:, 0] @ F[:, 1]) == pytest.approx(np.pi / 2 - 0.3, rel=1e-14)
    # the secant field of a step moves F(theta_0) X to F(theta_1) X in t_step exactly
    X = origin[:, :3]
    t_step = 0.01
    w = secant_velocity(origin, trellis_gradient(0.05), trellis_gradient(0.1), t_step)
    np.testing.assert_allclose(end_targets(X, "trellis", 0.05) + t_step * w[:, :3], end_targets(X, "trellis", 0.1),
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(end_targets(X, "uniaxial_y", 0.1)[:, 1], X[:, 1] * 1.1, rtol=1e-15)


def test_config_digest_follows_the_resolved_scene_config(tmp_path):
    """rve_fabric's `config_digest` param: editing the scene config a run spec names changes
    it (so Snakemake reruns the chain), a comment or a reformatting does not, and each
    combination of a sweep has its own."""
    from rve.homogenisation.layout import config_digest

    src = Path(__file__).parents[1] / "configs" / "rve" / "plain_weave.yaml"
    scene = tmp_path / "weave.yaml"
    scene.write_text(src.read_text())
    spec = {"scene_config": str(scene), "overrides": []}
    d0 = config_digest(spec, "base")
    assert len(d0) == 16
    scene.write_text("# a comment\n" + src.read_text().replace("elements: 30 ", "elements:   30 "))
    assert config_digest(dict(spec), "base") == d0
    scene.write_text(src.read_text().replace("elements: 30 ", "elements: 24 "))
    assert config_digest(dict(spec), "base") != d0
    sweep = {**spec, "sweep": {"mesh.elements": [12, 18]}}
    assert config_digest(sweep, "mesh_elements-12") != config_digest(sweep, "mesh_elements-18")
