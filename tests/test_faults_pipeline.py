"""Fault injection, pipeline: kills at every stage of the Snakemake DAG resume
bit-identically, and a damaged or truncated state is rebuilt by the next ``snakemake``
call (not "Nothing to be done"). On the CI config plus a tiny run (2 x 2 weave, one strain
step, 6 jobs) so each stage can be hit in a few minutes; the full CI DAG's resume test is
tests/test_rve_pipeline.py::test_killed_run_resumes_with_an_identical_table."""
from __future__ import annotations

import os
import shutil
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

pytestmark = [pytest.mark.faults, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
RUN = "tiny"
TABLE = L.table_outputs(RUN)["table"]
CONFIG = "configs/tests/pipeline_faults.yaml"
TINY = {"scene_config": None, "overrides": [],
        "scene": {"scene": "rve", "fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]},
                  "mesh": {"elements": 6},
                  "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2, "static_atol": 1.0e-9,
                                 "static_max_iter": 40},
                  "strain": {"modes": ["uniaxial"], "total": 0.05, "steps": 1, "static_atol": 1.0e-9,
                             "static_max_iter": 40}}}
#: stage -> the log file whose appearance means a job of that stage is running
STAGES = {
    "fabric": L.log_path(RUN, "fabric", "base"),
    "relax": L.log_path(RUN, "relax", "base"),
    "strain": L.log_path(RUN, "strain", "base", "uniaxial_01"),
    "probes": L.log_path(RUN, "probes", "base", "relaxed"),
    "gather": L.log_path(RUN, "gather"),
}


def _work(dest: Path) -> Path:
    work = workflow_copy(dest)
    cfg = yaml.safe_load((ROOT / "configs/tests/pipeline_ci.yaml").read_text())
    cfg["rve"]["runs"][RUN] = TINY
    cfg["rve"]["default_runs"] = [RUN]
    (work / CONFIG).write_text(yaml.safe_dump(cfg, sort_keys=False))
    return work


def _cmd(*extra):
    return [sys.executable, "-m", "snakemake", "-j2", TABLE, *extra, "--configfile", CONFIG]


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def _run(work: Path, cmd, timeout=900) -> subprocess.CompletedProcess:
    p = subprocess.run(cmd, cwd=work, env=_env(), capture_output=True, text=True, timeout=timeout)
    if p.returncode != 0:
        pytest.fail(f"{' '.join(cmd[2:])} failed ({p.returncode}):\n{p.stderr[-4000:]}")
    return p


def _table(work: Path):
    from rve.tables import open_table

    return open_table(work / TABLE)


def _assert_identical(a, b):
    assert set(a.variables) == set(b.variables)
    for k in a.variables:
        if a[k].dtype.kind == "f":
            np.testing.assert_array_equal(a[k].values, b[k].values, err_msg=k)
        else:
            assert list(a[k].values.ravel()) == list(b[k].values.ravel()), k


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    pytest.importorskip("snakemake")
    work = _work(tmp_path_factory.mktemp("faults_ref"))
    _run(work, _cmd())
    return work, _table(work)


# long: one pipeline run per stage (~1-3 min each); the default test run keeps the CI DAG's kill test
# (tests/test_rve_pipeline.py); `pytest -m long` or benchmarks/fault_injection.py kills runs these
@pytest.mark.long
@pytest.mark.parametrize("stage,sig", [(s, "KILL") for s in STAGES] + [("strain", "TERM")])
def test_kill_at_each_stage_resumes_bit_identically(stage, sig, reference, tmp_path):
    work = _work(tmp_path)
    trigger = work / STAGES[stage]
    proc = subprocess.Popen(_cmd(), cwd=work, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        t0 = time.time()
        while not trigger.exists():
            if proc.poll() is not None or time.time() - t0 > 600:
                pytest.fail(f"snakemake ended ({proc.returncode}) before a {stage} job started")
            time.sleep(0.05)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, getattr(signal, f"SIG{sig}"))
        proc.wait(timeout=120)
    if sig == "KILL":
        _run(work, [sys.executable, "-m", "snakemake", "--unlock", "--configfile", CONFIG], timeout=300)
    _run(work, _cmd("--rerun-incomplete"))
    _assert_identical(reference[1], _table(work))


def test_corrupt_state_is_rebuilt_by_the_next_run_bit_identically(reference, tmp_path):
    """A truncated strain state and a flipped byte in the relaxed state of a finished run:
    the next snakemake call moves them (and what was derived from them) aside and rebuilds;
    never "Nothing to be done"."""
    work = tmp_path / "w"
    shutil.copytree(reference[0], work, symlinks=True)
    states = work / "results" / "rve" / RUN / "base" / "states"
    p = states / "uniaxial_01.nc"
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    proc = _run(work, _cmd())
    out = proc.stdout + proc.stderr
    assert "Nothing to be done" not in out
    assert "uniaxial_01.nc: no SHA-256 trailer" in out
    assert (states / "uniaxial_01.nc.corrupt").exists()
    _assert_identical(reference[1], _table(work))
    q = states / "relaxed.nc"
    data = bytearray(q.read_bytes())
    data[len(data) // 2] ^= 0x10
    q.write_bytes(bytes(data))
    proc = _run(work, _cmd())
    assert "relaxed.nc: SHA-256 mismatch" in proc.stdout + proc.stderr
    _assert_identical(reference[1], _table(work))


def test_unconverged_relax_job_fails_and_the_next_run_is_not_nothing_to_be_done(tmp_path):
    pytest.importorskip("snakemake")
    work = _work(tmp_path)
    cfg = yaml.safe_load((work / CONFIG).read_text())
    cfg["rve"]["runs"][RUN]["scene"]["relaxation"].update({"static_atol": 1.0e-20, "static_max_iter": 3})
    (work / CONFIG).write_text(yaml.safe_dump(cfg, sort_keys=False))
    states = work / "results" / "rve" / RUN / "base" / "states"
    p = subprocess.run(_cmd(), cwd=work, env=_env(), capture_output=True, text=True, timeout=900)
    assert p.returncode != 0
    assert (states / "relaxed.unconverged.nc").exists() and not (states / "relaxed.nc").exists()
    log = (work / STAGES["relax"]).read_text()
    assert "not an equilibrium" in log
    p = subprocess.run([sys.executable, "-m", "snakemake", "-n", TABLE, "--configfile", CONFIG], cwd=work,
                       env=_env(), capture_output=True, text=True, timeout=300)
    assert "Nothing to be done" not in p.stdout + p.stderr and "rve_relax" in p.stdout + p.stderr
