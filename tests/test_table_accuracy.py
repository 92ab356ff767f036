"""The stated accuracy of a table: a convergence study's accuracy.json, named by
the run spec's `accuracy` key, ends up in the gathered table's attributes — only for the
configuration the study assessed."""
import json
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from rve.homogenisation.sweeps import load_run_config
from rve.tables import open_table
from rve.tables.accuracy import annotate_accuracy, read_accuracy
from rve.tables.jobs import gather_job

ROOT = Path(__file__).parents[1]
DATA = ROOT / "tests" / "data"


def _spec():
    spec = yaml.safe_load((ROOT / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    spec["scene"]["strain"]["modes"] = ["uniaxial", "shear"]
    return spec


def _accuracy(elements, penalty):
    return {"targets": {"reaction_force": 0.02}, "default": {"mesh_elements": elements, "contact_penalty": penalty},
            "mesh": {"reference": 30, "estimated_relative_error": {"reaction_force": 0.013, "probe_resistance": 0.04,
                                                                    "not_a_table_variable": 0.5}},
            "penalty": {"reference": 150, "estimated_relative_error": {"reaction_force": 0.001,
                                                                       "probe_resistance": None}},
            "provenance": {"date": "2026-12-01", "commit": "abc1234"}}


def _gather(tmp_path, spec):
    out = tmp_path / "table.nc"
    gather_job(sorted((DATA / "records_v1_ci").glob("*.json")), out, out.with_suffix(".csv"),
               out.with_suffix(".txt"), None, spec, "ci")
    return out


def test_gathered_table_states_the_study_accuracy(tmp_path):
    spec = _spec()
    cfg = load_run_config(spec)
    acc = tmp_path / "accuracy.json"
    acc.write_text(json.dumps(_accuracy(cfg.mesh.elements, cfg.contact.penalty)))
    spec["accuracy"] = str(acc)
    out = _gather(tmp_path, spec)
    ds = open_table(out)
    a = ds["reaction_force"].attrs
    assert a["estimated_relative_error_mesh"] == pytest.approx(0.013)
    assert a["estimated_relative_error_penalty"] == pytest.approx(0.001)
    assert a["estimated_relative_error"] == pytest.approx(0.014)
    p = ds["probe_resistance"].attrs
    assert p["estimated_relative_error"] == pytest.approx(0.04) and "estimated_relative_error_penalty" not in p
    assert "estimated_relative_error" not in ds["membrane_force"].attrs   # not assessed: not claimed
    assert "abc1234" in ds.attrs["accuracy_source"] and "30 elements" in ds.attrs["accuracy_source"]
    assert "estimated_relative_error" in ds.attrs["comment"]
    text = out.with_suffix(".txt").read_text()
    assert "reaction_force: 1.4 % (mesh 1.3 %, penalty 0.1 %)" in text
    # the CF checker still sees a clean file (the attributes are ordinary variable attributes)
    from cf_checker import cfchecks_command

    exe, env = cfchecks_command(tmp_path)
    if exe is None:
        pytest.skip("cfchecker not installed")
    import netCDF4

    chk = tmp_path / "check.nc"
    shutil.copy(out, chk)
    with netCDF4.Dataset(chk, "a") as f:
        f.Conventions = "CF-1.8"
    cft = DATA / "cf_tables"
    run = subprocess.run([exe, "-v", "1.8", "-s", str(cft / "standard_name_table.xml"), "-a",
                          str(cft / "area_type_table.xml"), "-r", str(cft / "region_names.xml"), str(chk)],
                         capture_output=True, text=True, timeout=300, env=env)
    assert "ERRORS detected: 0" in run.stdout and "WARNINGS given: 0" in run.stdout, run.stdout[-2000:]


def test_accuracy_of_another_mesh_is_not_claimed(tmp_path):
    spec = _spec()
    cfg = load_run_config(spec)
    acc = tmp_path / "accuracy.json"
    acc.write_text(json.dumps(_accuracy(cfg.mesh.elements + 6, cfg.contact.penalty)))
    spec["accuracy"] = str(acc)
    ds = open_table(_gather(tmp_path, spec))
    assert "estimated_relative_error" not in ds["reaction_force"].attrs
    assert "accuracy_source" not in ds.attrs
    # nor of another penalty
    assert annotate_accuracy(ds, _accuracy(cfg.mesh.elements, 2 * cfg.contact.penalty),
                             cfg.mesh.elements, cfg.contact.penalty) == []
    assert "estimated_relative_error" not in ds["reaction_force"].attrs


def test_bad_accuracy_file_names_file_and_key(tmp_path):
    with pytest.raises(ValueError, match="not found"):
        read_accuracy(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"default": {"mesh_elements": 12}, "mesh": {}, "penalty": {}}))
    with pytest.raises(ValueError, match=r"bad.json: default.contact_penalty missing"):
        read_accuracy(bad)
    bad.write_text("{")
    with pytest.raises(ValueError, match="not JSON"):
        read_accuracy(bad)


def test_stated_error_and_per_mode_errors_are_written(tmp_path):
    """A study file with the reference's own error and per-mode maxima: the mesh part is the
    stated error (difference + reference error), and each mode gets its own bound."""
    import xarray as xr

    acc = _accuracy(12, 50.0)
    acc["mesh"].update({"stated_relative_error": {"reaction_force": 0.02}, "reference_error": {"reaction_force": 0.007},
                        "by_mode": {"reaction_force": {"uniaxial": {"max": 0.005, "median": 0.001},
                                                       "shear": {"max": 0.013, "median": 0.004}}}})
    acc["mesh"]["reference_error_by_mode"] = {"reaction_force": {"shear": 0.004}}   # uniaxial: the overall 0.007
    acc["penalty"]["by_mode"] = {"reaction_force": {"uniaxial": {"max": 0.001, "median": 0.0}}}
    ds = xr.Dataset({"reaction_force": ("strain", [1.0, 2.0])})
    assert annotate_accuracy(ds, acc, 12, 50.0) == ["reaction_force"]
    a = ds["reaction_force"].attrs
    assert a["estimated_relative_error_mesh"] == pytest.approx(0.02)
    assert a["estimated_relative_error"] == pytest.approx(0.021)
    assert a["estimated_relative_error_uniaxial"] == pytest.approx(0.005 + 0.007 + 0.001)
    assert a["estimated_relative_error_shear"] == pytest.approx(0.013 + 0.004)
    assert "own estimated error" in ds.attrs["comment"]


def test_shipped_accuracy_file_is_of_the_default_run():
    """configs/rve/plain_weave_accuracy.json states the accuracy of the run that names it:
    the same elements per fibril and penalty as the default config resolves to, references
    finer/stiffer than the default, and an error for every table quantity."""
    pipe = yaml.safe_load((ROOT / "configs/pipeline.yaml").read_text())["rve"]
    for name in pipe["default_runs"]:
        spec = pipe["runs"][name]
        if not spec.get("accuracy"):
            continue
        cfg = load_run_config(spec)
        acc = read_accuracy(ROOT / spec["accuracy"])
        assert int(acc["default"]["mesh_elements"]) == cfg.mesh.elements
        assert float(acc["default"]["contact_penalty"]) == pytest.approx(cfg.contact.penalty)
        assert acc["mesh"]["reference"] > cfg.mesh.elements
        assert acc["penalty"]["reference"] > cfg.contact.penalty
        from rve.studies.table_convergence import QUANTITIES

        for part in ("mesh", "penalty"):
            errs = acc[part]["estimated_relative_error"]
            assert set(errs) == set(QUANTITIES), (part, set(errs))
            assert all(e is not None and e >= 0 for e in errs.values())
