"""The probe solves of a sweep scheduled by Snakemake (-j2) and by dask.distributed (a
LocalCluster of 2 single-threaded worker processes), on the same stored states
(docs/cluster.md "dask.distributed").

The states are those of configs/tests/pipeline_ci.yaml `ci_cluster_sweep` (4 combinations x
3 states = 12 probe jobs of about a second of solving each): the case where scheduling
overhead weighs most. Snakemake: `snakemake -j2 --forcerun rve_probes <the 12 records>`
(each job its own process that parses the workflow); dask: ``client.map(probe_job, ...)`` on
warm workers, timed with and without starting the cluster. The records of both are checked
to hold the same probe results bit for bit.

    nice -n 10 python benchmarks/dask_distributed_probes.py            # runs the sweep first if needed
    nice -n 10 python benchmarks/dask_distributed_probes.py --work DIR # a folder where it ran
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import cluster_sweep as C  # noqa: E402

THREADS = {"RVE_PARDISO_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def probe_tasks(work: Path, out_dir: Path) -> list[tuple[str, str, str]]:
    """(state, record to write, combo) of every stored state but the initial one."""
    from rve.homogenisation import layout as L

    tasks = []
    for state in sorted((work / L.RVE_DIR / C.RUN).glob("*/states/*.nc")):
        if state.stem == "initial":
            continue
        combo = state.parent.parent.name
        tasks.append((str(state), str(out_dir / combo / f"{state.stem}.json"), combo))
    return tasks


def run_probe(state: str, record: str, combo: str, spec: dict) -> float:
    from rve.homogenisation.jobs import probe_job

    t0 = time.perf_counter()
    probe_job(state, record, None, spec, combo)
    return time.perf_counter() - t0


def dask_probes(tasks, spec) -> tuple[float, float, list[float]]:
    """Wall time with the cluster's start, without it, and each task's own time."""
    from dask.distributed import Client, LocalCluster

    os.environ.update(THREADS)  # the workers inherit it: one BLAS thread each, as Snakemake's jobs
    t0 = time.perf_counter()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        client.run(lambda: __import__("rve.homogenisation.jobs"))  # the imports a Snakemake job pays too
        t1 = time.perf_counter()
        futures = [client.submit(run_probe, s, r, c, spec, pure=False) for s, r, c in tasks]
        own = client.gather(futures)
        t2 = time.perf_counter()
    return t2 - t0, t2 - t1, own


def probes_of(record: Path) -> dict:
    rec = json.loads(record.read_text())
    return {name: {k: v for k, v in p.items() if k != "wall_s"} for name, p in rec["probes"].items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, help="a folder where ci_cluster_sweep ran with -j2")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="rve-probes-"))
    if not (work / C.TABLE).exists():
        C.workflow_copy(work)
        code, wall = C.run(work, C.snakemake_cmd(False))
        print(f"sweep -j2 first: exit {code}, {wall:.1f} s")
        if code:
            return 1
    spec = yaml.safe_load((work / C.CONFIG).read_text())["rve"]["runs"][C.RUN]
    out = work / "dask_records"
    tasks = probe_tasks(work, out)
    from rve.homogenisation import layout as L

    rel = [L.record_path(C.RUN, combo, Path(s).stem) for s, _, combo in tasks]
    records = [work / r for r in rel]
    # the targets first: --forcerun and --configfile take several values
    cmd = [sys.executable, "-m", "snakemake", "-j2", *rel, "--forcerun", "rve_probes", "--configfile", C.CONFIG]
    code, wall_sm = C.run(work, cmd)
    ran = (work / "snakemake.log").read_text().split("Job stats:")[-1].split("Select jobs")[0]
    if code or "rve_probes" not in ran:
        print(f"snakemake failed or ran no probe job: {work}/snakemake.log")
        return 1
    bench = [work / L.benchmark_path(C.RUN, "probes", combo, Path(s).stem) for s, _, combo in tasks]
    own_sm = [float(b.read_text().splitlines()[1].split("\t")[0]) for b in bench]
    wall_dask, wall_dask_warm, own_dask = dask_probes(tasks, spec)
    n = len(tasks)
    print(f"{n} probe jobs of ci_cluster_sweep, 2 at a time")
    print(f"  snakemake -j2:            {wall_sm:6.1f} s wall; the jobs' own time {sum(own_sm):6.1f} s "
          f"(Snakemake's benchmark files)")
    print(f"  dask.distributed, 2 proc: {wall_dask:6.1f} s wall with the cluster's start, {wall_dask_warm:6.1f} s "
          f"on warm workers; the tasks' own time {sum(own_dask):6.1f} s")
    same = all(probes_of(r) == probes_of(Path(d)) for r, (_, d, _) in zip(records, tasks))
    print(f"  records equal bit for bit: {same}")
    if not args.work:
        shutil.rmtree(work)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
