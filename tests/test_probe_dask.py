"""rve.probe_executor dask (rve.homogenisation.distributed): the probe records written on a
dask.distributed LocalCluster are the per-state jobs' records bit for bit (every field but
the wall times), on the CI run's relaxed state; the task list is the run's record list.
With a running Slurm cluster (``pytest -m slurm tests/test_probe_dask.py``, after
``workflow/slurm/local-cluster up``) the same on a dask-jobqueue SLURMCluster."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]


def _ci_spec():
    return yaml.safe_load((ROOT / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]


def _without_wall_times(obj):
    if isinstance(obj, dict):
        return {k: _without_wall_times(v) for k, v in obj.items() if k != "wall_s"}
    if isinstance(obj, list):
        return [_without_wall_times(v) for v in obj]
    return obj


def test_probe_tasks_are_the_runs_records_with_their_states():
    from rve.homogenisation import layout as L
    from rve.homogenisation.distributed import probe_tasks

    spec = _ci_spec()
    tasks = probe_tasks(spec, "ci")
    assert [t.record for t in tasks] == L.run_record_paths(spec, "ci")
    for t in tasks:
        name = Path(t.record).stem
        assert t.state == L.state_path("ci", t.combo, name)
        assert t.log == L.log_path("ci", "probes", t.combo, name)


def test_unknown_cluster_kind_is_named():
    from rve.homogenisation.distributed import dask_cluster

    with pytest.raises(ValueError, match="rve.probe_dask.cluster"):
        with dask_cluster("pbs", 1):
            pass


def _records_on(cluster: str, folder: Path):
    """The CI relaxed state's record by probe_job and by a one-worker dask ``cluster``."""
    from rve.homogenisation.distributed import ProbeTask, run_probe_tasks
    from rve.homogenisation.jobs import fabric_job, probe_job, relax_job

    spec = _ci_spec()
    fabric_job(folder / "initial.nc", None, spec, "base")
    relax_job(folder / "initial.nc", folder / "relaxed.nc", None, spec, "base")
    probe_job(folder / "relaxed.nc", folder / "job.json", None, spec, "base")
    task = ProbeTask(str(folder / "relaxed.nc"), str(folder / "dask.json"), str(folder / "dask.log"), "base",
                     str(folder / "tubes.vtp"))
    written = run_probe_tasks([task], spec, cluster, workers=1, mem_mb=1500, runtime_min=10)
    return spec, task, written


@pytest.mark.slurm
def test_slurm_cluster_records_equal_the_per_state_jobs_records(tmp_path):
    pytest.importorskip("dask_jobqueue")
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cluster_sweep as C

    reason = C.cluster_up()
    if reason:
        pytest.skip(f"no Slurm cluster ({reason}); start one with workflow/slurm/local-cluster up")
    _, task, written = _records_on("slurm", tmp_path)
    assert written == [task.record]
    job, dask = (json.loads((tmp_path / f).read_text()) for f in ("job.json", "dask.json"))
    assert _without_wall_times(dask) == _without_wall_times(job)


def test_dask_records_equal_the_per_state_jobs_records(tmp_path):
    pytest.importorskip("dask.distributed")
    from rve.homogenisation.distributed import run_probe_tasks

    spec, task, written = _records_on("local", tmp_path)
    assert written == [task.record]
    job, dask = (json.loads((tmp_path / f).read_text()) for f in ("job.json", "dask.json"))
    assert _without_wall_times(dask) == _without_wall_times(job)
    assert (tmp_path / "dask.log").read_text()  # the task logged to its own file
    assert run_probe_tasks([task], spec, "local", workers=1) == []  # on disk: not solved again
