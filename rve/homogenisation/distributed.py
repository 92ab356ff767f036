"""The probe solves of a run on a dask.distributed cluster (``rve.probe_executor: dask``).

Contract: ``layout.probe_tasks`` lists every probe job of a run (each stored state but the
initial one, across all sweep combinations) with the paths the per-state rule
``rve_probes`` would use; :func:`run_probe_tasks` runs them as ``probe_job`` calls on a
dask cluster and returns once every record is on disk. Each task is exactly the body of
one ``rve_probes`` job (same inputs, same per-state log, same atomic record), so the
records are the same bits as Snakemake's: a probe job's output depends on its input file
only when each worker runs one BLAS/PARDISO thread, which the workers inherit from the
Snakefile's environment (and :data:`ONE_THREAD` enforces where it is unset).

Why: a probe job solves for about a second on the CI weave, and as a Snakemake job it
pays a fresh process (imports, workflow parse, first calls of the kernels) each time; a
dask worker pays that once for all the run's probes (docs/cluster.md "dask.distributed").
What it gives up: one Slurm job per state, and resuming inside the run's probes (the one
job writes every record of the run: Snakemake reruns it whole after a kill, while
:func:`run_probe_tasks` called by hand skips the records already on disk).

Clusters (``rve.probe_dask``): ``local``, a ``LocalCluster`` of ``workers`` one-thread
worker processes (the rule's ``threads``); ``slurm``, a dask-jobqueue ``SLURMCluster`` of
``workers`` one-core Slurm jobs with the run's ``rve_mem_mb`` and ``rve_runtime_min``
(the ``cluster`` extra; e.g. the cluster of ``workflow/slurm/local-cluster``).
"""
from __future__ import annotations

import contextlib
import logging
import os
import tempfile
from pathlib import Path
from typing import Iterator, Mapping, Optional, Sequence

from . import layout as L
from .layout import ProbeTask, probe_tasks

log = logging.getLogger(__name__)

#: one BLAS/OpenMP/PARDISO thread per worker: the records are then those of the per-state jobs
ONE_THREAD = {"RVE_PARDISO_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1"}


def _probe(task: ProbeTask, spec: Mapping) -> str:
    """A worker's task: the body of one ``rve_probes`` job."""
    from .jobs import probe_job

    probe_job(task.state, task.record, task.log, spec, task.combo, task.tubes)
    return task.record


@contextlib.contextmanager
def dask_cluster(kind: str, workers: int, mem_mb: int = 1500, runtime_min: int = 60,
                 log_directory: Optional[str] = None) -> Iterator:
    """A running cluster of ``workers`` single-threaded workers, closed on exit; on Slurm the
    worker jobs' output files go to ``log_directory`` (default: a temporary folder)."""
    for key, value in ONE_THREAD.items():
        os.environ.setdefault(key, value)  # workers (processes or Slurm jobs) inherit it
    if kind == "local":
        try:
            from dask.distributed import LocalCluster
        except ImportError as exc:
            raise ImportError("rve.probe_executor dask needs dask.distributed: pip install -e '.[cluster]'") from exc

        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    elif kind == "slurm":
        try:
            from dask_jobqueue import SLURMCluster
        except ImportError as exc:
            raise ImportError("rve.probe_dask.cluster 'slurm' needs dask-jobqueue: pip install -e '.[cluster]'") from exc
        hours, minutes = divmod(int(runtime_min), 60)
        log_directory = log_directory or tempfile.mkdtemp(prefix="rve-dask-workers-")
        cluster = SLURMCluster(log_directory=log_directory, cores=1, processes=1, memory=f"{int(mem_mb)}MB", walltime=f"{hours:02d}:{minutes:02d}:00",
                               job_name="rve_probes_dask", scheduler_options={"dashboard_address": None})
        cluster.scale(jobs=workers)
    else:
        raise ValueError(f"rve.probe_dask.cluster must be 'local' or 'slurm', got {kind!r}")
    with cluster:
        yield cluster


def run_probe_tasks(tasks: Sequence[ProbeTask], spec: Mapping, cluster: str = "local", workers: int = 2,
                    mem_mb: int = 1500, runtime_min: int = 60, log_directory: Optional[str] = None) -> list[str]:
    """Run the tasks whose record is missing on a ``cluster`` of ``workers``; the records written.

    A failing task raises its own exception here (after the others finished or were
    cancelled), as the per-state job would fail."""
    from dask.distributed import Client, wait

    todo = [t for t in tasks if not Path(t.record).exists()]
    if not todo:
        return []
    with dask_cluster(cluster, workers, mem_mb, runtime_min, log_directory) as c, Client(c) as client:
        futures = [client.submit(_probe, t, spec, pure=False, key=f"probe-{t.combo}-{Path(t.state).stem}")
                   for t in todo]
        wait(futures)
        failed = [f for f in futures if f.status != "finished"]
        if failed:
            failed[0].result()  # re-raises the task's exception
        done = client.gather(futures)
    log.info("%d probe jobs on a dask %s cluster of %d workers", len(done), cluster, workers)
    return done


def probes_dask_job(spec: Mapping, run: str, log_path: Optional[str], dask_cfg: Mapping, resources: Mapping,
                    threads: int, root: str = L.RVE_DIR, log_root: str = L.LOG_DIR) -> list[str]:
    """The body of ``rve_probes_dask``: every probe job of ``run`` on the configured cluster.

    ``threads`` (the rule's, as Snakemake scaled it) is the number of local workers; on
    Slurm the workers are ``dask_cfg['workers']`` jobs of their own."""
    from ..io.provenance import logging_to

    kind = dask_cfg.get("cluster", "local")
    workers = int(threads) if kind == "local" else int(dask_cfg.get("workers", 2))
    with logging_to(log_path):
        return run_probe_tasks(probe_tasks(spec, run, root, log_root), spec, kind, workers,
                               resources.get("rve_mem_mb", 1500), resources.get("rve_runtime_min", 60),
                               log_directory=str(Path(log_path).parent / "dask_workers") if log_path else None)
