"""The periodic cell through the job bodies of the pipeline (rve.homogenisation.jobs,
rve.tables.jobs): fabric -> relax -> strain steps (uniaxial x and y, shear) -> field probes
-> table -> macro exports, and the CF checker on the table. The whole Snakemake DAG of every
weave: configs/tests/pipeline_periodic.yaml (docs/periodic.md)."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
MODES = ["uniaxial", "uniaxial_y", "shear"]


@pytest.fixture(scope="module")
def periodic_table(tmp_path_factory):
    from rve.homogenisation.jobs import fabric_job, probe_job, relax_job, strain_job
    from rve.tables.jobs import export_job, gather_job

    d = tmp_path_factory.mktemp("periodic")
    spec = {"scene_config": None, "overrides": [],
            "scene": {"scene": "rve", "boundary": "periodic", "fabric": {"kind": "plain", "rows": [1]},
                      "mesh": {"elements": 6}, "output": {"pictures": False},
                      "strain": {"modes": MODES, "total": 0.05, "steps": 1}}}
    fabric_job(d / "initial.nc", None, spec)
    relax_job(d / "initial.nc", d / "relaxed.nc", None, spec)
    states = [d / "relaxed.nc"]
    for mode in MODES:
        strain_job(d / "relaxed.nc", d / f"{mode}_01.nc", None, spec, "base", mode, 1)
        states.append(d / f"{mode}_01.nc")
    records = []
    for st in states:
        records.append(d / f"{st.stem}.json")
        probe_job(st, records[-1], None, spec)
    table = d / "table.nc"
    gather_job(records, table, d / "table.csv", d / "summary.txt", None, spec, "periodic")
    exports = {"abaqus": d / "t.inc", "lsdyna": d / "t.k", "hermite": d / "t.json", "curves": d / "curves"}
    export_job(table, exports, None)
    return table, exports


def test_every_mode_gives_a_converged_table_with_per_width_figures(periodic_table):
    from rve.tables import open_table

    table, exports = periodic_table
    ds = open_table(table)
    assert sorted(ds["mode"].values) == sorted(MODES) and ds.sizes["strain"] == 2
    assert float(ds["equilibrium_residual"].max()) < 1e-8
    assert ds.attrs["boundary"] == "periodic" and "Hill-Mandel" in ds["membrane_force"].attrs["comment"]
    R = ds["probe_resistance"]
    assert np.isfinite(R).all() and (R > 0).all()
    m = ds["membrane_force"]
    # a stretch along x raises the x membrane force, along y the y one (N/mm, per unit width)
    ux, uy = m.sel(mode="uniaxial"), m.sel(mode="uniaxial_y")
    assert float(ux.isel(strain=1, edge=0, component=0)) > float(ux.isel(strain=0, edge=0, component=0)) > 0
    assert float(uy.isel(strain=1, edge=1, component=1)) > float(uy.isel(strain=0, edge=1, component=1)) > 0
    for p in exports.values():
        assert Path(p).exists()


def test_the_periodic_table_passes_the_cf_checker(periodic_table, tmp_path):
    sys.path.insert(0, str(ROOT / "tests"))
    from cf_checker import cfchecks_command

    exe, env = cfchecks_command(tmp_path)
    if exe is None:
        pytest.skip("the CF checker (pip cfchecker) is not installed")
    import netCDF4

    path = tmp_path / "check.nc"
    shutil.copy(periodic_table[0], path)
    with netCDF4.Dataset(path, "a") as f:
        f.Conventions = "CF-1.8"  # the newest the checker knows (as tests/test_tables.py)
    cft = DATA / "cf_tables"
    run = subprocess.run([exe, "-v", "1.8", "-s", str(cft / "standard_name_table.xml"), "-a",
                          str(cft / "area_type_table.xml"), "-r", str(cft / "region_names.xml"), str(path)],
                         capture_output=True, text=True, timeout=300, env=env)
    assert "ERRORS detected: 0" in run.stdout and "WARNINGS given: 0" in run.stdout, run.stdout[-3000:]
