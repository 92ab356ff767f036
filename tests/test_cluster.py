"""Sweeps on a Slurm cluster (docs/cluster.md): the local cluster script names what is
missing, and the 4-run sweep of configs/tests/pipeline_ci.yaml (ci_cluster_sweep) run
through workflow/profiles/slurm gives the bits of the same sweep run with -j2.

The cluster test needs a running cluster and the `cluster` extra; it is skipped, with the
reason, otherwise. It takes minutes, so it is marked `long` too:

    workflow/slurm/local-cluster up && pytest -m slurm tests/test_cluster.py
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import cluster_sweep as C  # noqa: E402

SCRIPT = ROOT / "workflow" / "slurm" / "local-cluster"


def test_local_cluster_names_the_missing_packages(tmp_path):
    """With Slurm's and MariaDB's commands off PATH (the daemons in /usr/sbin stay found),
    `up` refuses before starting anything and names the Debian packages to install."""
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    for tool in ("bash", "dirname", "sort", "tr", "cat", "sed", "awk", "head", "mkdir", "nproc", "hostname", "id"):
        found = subprocess.run(["bash", "-c", f"command -v {tool}"], capture_output=True, text=True).stdout.strip()
        if found:
            (bin_ / tool).symlink_to(found)
    env = {"PATH": str(bin_), "RVE_SLURM_STATE": str(tmp_path / "state")}
    proc = subprocess.run(["bash", str(SCRIPT), "up"], capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == 1
    assert "packages missing:" in proc.stderr and "slurm-client" in proc.stderr, proc.stderr
    assert "apt-get install" in proc.stderr
    assert not (tmp_path / "state").exists()  # nothing started, nothing written


def test_table_comparison_sees_one_flipped_bit(tmp_path):
    """The comparison the cluster test relies on: the same table is identical, a table
    with one value changed in its last bit is not, and the write time does not count."""
    import numpy as np
    import xarray as xr

    ds = xr.Dataset({"r": (("strain",), np.array([1.0, 2.0, 3.0]))}, attrs={"date_created": "a", "title": "t"})
    ds.to_netcdf(tmp_path / "a.nc")
    ds.assign_attrs(date_created="b").to_netcdf(tmp_path / "b.nc")
    flipped = ds.copy(deep=True)
    flipped["r"].values[1] = np.nextafter(2.0, 3.0)
    flipped.to_netcdf(tmp_path / "c.nc")
    assert C.table_differences(tmp_path / "a.nc", tmp_path / "b.nc") == []
    assert C.table_differences(tmp_path / "a.nc", tmp_path / "c.nc") == ["r"]


@pytest.mark.slurm
@pytest.mark.long
def test_sweep_on_slurm_is_bit_identical_to_local(tmp_path):
    """ci_cluster_sweep (2 x 2 combinations, 29 jobs) on Slurm through the shipped profile:
    every job a Slurm job with the rule's resources, the table bit-identical to -j2's."""
    pytest.importorskip("snakemake_executor_plugin_slurm", reason="the cluster extra is not installed")
    reason = C.cluster_up()
    if reason:
        pytest.skip(f"no Slurm cluster ({reason}); start one with workflow/slurm/local-cluster up")
    local, slurm = C.workflow_copy(tmp_path / "local"), C.workflow_copy(tmp_path / "slurm")
    since = C.sacct_now()
    code, _ = C.run(local, C.snakemake_cmd(False))
    assert code == 0, (local / "snakemake.log").read_text()[-3000:]
    code, _ = C.run(slurm, C.snakemake_cmd(True))
    assert code == 0, (slurm / "snakemake.log").read_text()[-3000:]
    jobs = C.sacct_jobs(since)
    assert len(jobs) == 29 and {j["state"] for j in jobs} == {"COMPLETED"}, jobs
    # the resources of configs/pipeline.yaml and the rules' threads, as Slurm was asked
    import yaml

    res = yaml.safe_load((ROOT / "configs" / "pipeline.yaml").read_text())["resources"]
    by_rule = {}
    for j in jobs:
        by_rule.setdefault(j["rule"], set()).add((j["cpus"], j["mem_mb"], j["limit_min"]))
    assert by_rule["rve_relax"] == {(2, res["rve_mem_mb"], res["rve_runtime_min"])}
    assert by_rule["rve_strain_step"] == {(1, res["rve_mem_mb"], res["rve_runtime_min"])}
    assert by_rule["rve_gather"] == {(1, res["gather_mem_mb"], res["gather_runtime_min"])}
    assert C.table_differences(local / C.TABLE, slurm / C.TABLE) == []
    assert os.path.getsize(slurm / C.TABLE) > 0
