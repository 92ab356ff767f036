"""Fault injection, bad input: every class of bad input the QA pass found is one
clear line naming the key or the file and what is allowed, before anything is computed,
and no traceback on the command line."""
from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from rve.cli import main
from rve.config import ConfigError, load_config

pytestmark = pytest.mark.faults

ROOT = Path(__file__).resolve().parents[1]
WEAVE = "configs/rve/plain_weave.yaml"
DYNAMIC = "configs/scenes/dynamic_wire.yaml"
STATIC = "configs/scenes/static_wire.yaml"


def _one_line(exc: ConfigError, *needles: str) -> str:
    assert len(exc.errors) == 1, exc.errors
    line = exc.errors[0]
    assert "\n" not in line and "Traceback" not in line
    for n in needles:
        assert n in line, (n, line)
    return line


def _preflight(overrides):
    from rve.homogenisation.preflight import preflight

    with pytest.raises(ConfigError) as ei:
        preflight(load_config(WEAVE, overrides))
    return ei.value


# --------------------------------------------------------------------------- geometry
def test_bad_input_overlapping_fibrils_at_the_design_state():
    exc = _preflight(["fabric.fibril_diameter=3 mm"])
    _one_line(exc, "fabric.fibril_diameter = 3 mm", "overlap by", "allowed: <= 50 %", "checks.max_design_overlap")


def test_bad_input_the_default_weave_passes_the_preflight():
    from rve.homogenisation.preflight import design_overlap, preflight

    cfg = load_config(WEAVE)
    fab, mesh = preflight(cfg)
    over, _ = design_overlap(fab, mesh, fab.initial_state(mesh))
    assert 0.0 < over < cfg.checks.max_design_overlap   # the designed stacks overlap a little (~25 %)


@pytest.mark.parametrize("config", [STATIC, DYNAMIC])
def test_bad_input_wire_radius_against_length(config):
    with pytest.raises(ConfigError) as ei:
        load_config(config, ["fibril.radius=5 mm"])
    _one_line(ei.value, "fibril.radius = 5 mm", "must be <= geometry.half_length / 4", "(= 0.25 mm)")


def test_bad_input_empty_stack_row():
    with pytest.raises(ConfigError) as ei:
        load_config(WEAVE, ["fabric.rows=[3, 0, 3]"])
    _one_line(ei.value, "fabric.rows = [3, 0, 3]", "every stack row must hold >= 1 fibril")


def test_bad_input_probe_terminal_matching_no_yarn_end():
    exc = _preflight(['probes=[{name: p, terminals: [{yarn: warp, position: "0.3 mm", end: "x+"}, '
                      '{yarn: warp, position: "-1 mm", end: "x-"}]}]'])
    _one_line(exc, "probes[0].terminals[0]", "warp yarn at 0.3 mm", "matches no yarn end", "yarns: ")


def test_bad_input_probe_terminal_on_a_side_the_yarn_does_not_reach():
    exc = _preflight(['probes=[{name: p, terminals: [{yarn: warp, position: "-1 mm", end: "y+"}, '
                      '{yarn: warp, position: "-1 mm", end: "x-"}]}]'])
    _one_line(exc, "probes[0].terminals[0]", "no fibril end on side y+")


# --------------------------------------------------------------------------- files and keys
def test_bad_input_duplicate_yaml_keys(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text("scene: static_wire\nmesh:\n  order: 2\nmesh:\n  elements: 10\n")
    with pytest.raises(ConfigError) as ei:
        load_config(p)
    _one_line(ei.value, str(p), "line 4: duplicate key 'mesh' (first at line 2)")


def test_bad_input_non_utf8_config(tmp_path):
    p = tmp_path / "latin1.yaml"
    p.write_bytes("scene: static_wire\n# café\n".encode("latin-1"))
    with pytest.raises(ConfigError) as ei:
        load_config(p)
    _one_line(ei.value, str(p), "not UTF-8", "line 2")
    assert main(["validate", str(p)]) == 2


@pytest.mark.slow   # two Snakemake dry runs (~10-30 s on the loaded machine)
def test_bad_input_unknown_run_name_and_top_level_pipeline_key(tmp_path):
    """Through Snakemake (dry runs): a misspelt top-level key and an unknown run name."""
    pytest.importorskip("snakemake")
    from workflow_copy import workflow_copy

    work = workflow_copy(tmp_path)
    cfg = yaml.safe_load((work / "configs/tests/pipeline_ci.yaml").read_text())
    cfg["resourcez"] = {"rve_mem_mb": 10}
    (work / "typo.yaml").write_text(yaml.safe_dump(cfg))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = lambda *a: subprocess.run([sys.executable, "-m", "snakemake", "-n", *a], cwd=work, env=env,  # noqa: E731
                                    capture_output=True, text=True, timeout=300)
    p = run("--configfile", "typo.yaml")
    assert p.returncode != 0
    out = p.stdout + p.stderr
    assert "unknown top-level key(s) 'resourcez' (allowed: " in out
    allowed = out.split("(allowed: ", 1)[1].split(")", 1)[0].split(", ")
    assert {"verification", "default_targets", "rve", "resources"} <= set(allowed) and "resourcez" not in allowed
    p = run("results/rve/nope/table.nc", "--configfile", "configs/tests/pipeline_ci.yaml")
    assert p.returncode != 0
    assert "unknown run 'nope'" in p.stdout + p.stderr and "known: ci, ci_sweep" in p.stdout + p.stderr


def test_bad_input_output_folder_not_writable(tmp_path):
    from rve.homogenisation.preflight import preflight

    if os.geteuid() == 0:
        # root writes anywhere: a path under a regular file cannot be a folder for anyone
        blocker = tmp_path / "file"
        blocker.write_text("x")
        out = blocker / "states" / "initial.nc"
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        out = ro / "states" / "initial.nc"
    with pytest.raises(ConfigError) as ei:
        preflight(load_config(WEAVE), outputs=[out])
    _one_line(ei.value, f"output {out}: cannot be written")


# --------------------------------------------------------------------------- units
@pytest.mark.parametrize("value", ["20 degC", "68 degF", "20 °C"])
def test_bad_input_absolute_temperature_where_a_difference_is_meant(value):
    with pytest.raises(ConfigError) as ei:
        load_config(DYNAMIC, [f"load.end_temperature={value}"])
    _one_line(ei.value, "load.end_temperature", "an absolute temperature", "temperature difference", "'20 K'")


def test_temperature_differences_in_kelvin_are_accepted():
    assert load_config(DYNAMIC, ["load.end_temperature=20 K"]).load.end_temperature == 20.0
    assert load_config(DYNAMIC, ["load.end_temperature=20 delta_degC"]).load.end_temperature == pytest.approx(20.0)


def test_bad_input_bare_angle_is_radians_and_warned_when_it_looks_like_degrees(caplog):
    with caplog.at_level(logging.WARNING, logger="rve.config"):
        cfg = load_config(DYNAMIC, ["load.field_angle=45"])
    assert cfg.load.field_angle == 45.0       # the rule: a bare number is radians
    assert any("field_angle = 45: a bare number is an angle in radians" in r.getMessage() for r in caplog.records)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rve.config"):
        load_config(DYNAMIC, ["load.field_angle=0.785"])
    assert not caplog.records


def test_bad_input_inf_tesla_says_finite():
    with pytest.raises(ConfigError) as ei:
        load_config(DYNAMIC, ["load.field_magnitude=inf T"])
    _one_line(ei.value, "load.field_magnitude = 'inf T': must be a finite number")


def test_bad_input_wrong_unit_in_a_sweep_names_the_sweep_key():
    from rve.homogenisation.sweeps import combos

    with pytest.raises(ConfigError) as ei:
        combos({"sweep": {"fibril_radius": ["0.1 mm", "1 V"]}})
    _one_line(ei.value, "sweep.fibril_radius = '1 V'", "wrong dimension", "length")


# --------------------------------------------------------------------------- memory
@pytest.mark.parametrize("config", [STATIC, DYNAMIC])
def test_bad_input_wire_mesh_against_memory(config):
    with pytest.raises(ConfigError) as ei:
        load_config(config, ["mesh.elements=10000000"])
    _one_line(ei.value, "mesh.elements = 10000000", "the solve would need ~", "MB", "available memory")


def test_bad_input_rve_mesh_against_memory_before_allocating():
    import time

    t0 = time.perf_counter()
    exc = _preflight(["mesh.elements=10000000"])
    assert time.perf_counter() - t0 < 5        # refused from the estimate: nothing was allocated
    _one_line(exc, "mesh.elements = 10000000", "would need ~", "MB")


# --------------------------------------------------------------------------- corrupted tables
def test_bad_input_corrupted_table_names_the_file(tmp_path, capsys):
    from rve.tables import open_table, write_table

    src = write_table(open_table(ROOT / "tests/data/table_v1_ci.nc"), tmp_path / "table.nc")   # sealed
    data = bytearray(src.read_bytes())
    data[len(data) // 3] ^= 0xFF
    bad = tmp_path / "bad_table.nc"
    bad.write_bytes(bytes(data))
    rc = main(["table", "summary", str(bad)])
    err = capsys.readouterr().err
    assert rc != 0 and str(bad) in err and "Traceback" not in err


def test_bad_input_rve_run_output_folder_checked_before_the_run(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc = main(["run", STATIC, "--out", str(blocker / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and f"output folder {blocker / 'out'}: cannot be written" in err and "Traceback" not in err


@pytest.mark.slow   # one Snakemake dry run
def test_bad_input_duplicate_section_in_the_pipeline_config(tmp_path):
    """A pipeline config with a section given twice (Snakemake's loader keeps the last one)."""
    pytest.importorskip("snakemake")
    from workflow_copy import workflow_copy

    work = workflow_copy(tmp_path)
    text = (work / "configs/tests/pipeline_ci.yaml").read_text()
    (work / "dup.yaml").write_text(text + "\nresources:\n  rve_mem_mb: 900\nresources:\n  gather_mem_mb: 400\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--configfile", "dup.yaml"], cwd=work, env=env,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode != 0
    out = p.stdout + p.stderr
    assert "dup.yaml" in out and "duplicate key 'resources'" in out, out[-2000:]
