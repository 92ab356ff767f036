"""The probe solves of a sweep scheduled by Snakemake (one job per state, -j2) and by the
shipped dask path (``rve.probe_executor: dask``: one job that runs them all on a
dask.distributed LocalCluster of 2 one-thread workers), on the same stored states
(docs/cluster.md "dask.distributed").

The states are those of configs/tests/pipeline_ci.yaml `ci_cluster_sweep` (4 combinations x
3 states = 12 probe jobs of about a second of solving each): the case where scheduling
overhead weighs most. Both are whole Snakemake calls on the 12 records:
`snakemake -j2 <records> --forcerun rve_probes` against the same with
`--forcerun rve_probes_dask_ci_cluster_sweep --config 'rve={probe_executor: dask}'`; then
the gather of the dask records. The records (every field but the wall times) and the
tables are compared bit for bit, and the ratio of the wall times is the win.

    nice -n 10 python benchmarks/dask_distributed_probes.py            # runs the sweep first if needed
    nice -n 10 python benchmarks/dask_distributed_probes.py --work DIR # a folder where it ran
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import cluster_sweep as C  # noqa: E402

def without_wall_times(obj):
    """A record with every ``wall_s`` left out (the one field that is a time, not a result)."""
    if isinstance(obj, dict):
        return {k: without_wall_times(v) for k, v in obj.items() if k != "wall_s"}
    if isinstance(obj, list):
        return [without_wall_times(v) for v in obj]
    return obj


def records_of(paths: list[Path]) -> list[dict]:
    return [without_wall_times(json.loads(p.read_text())) for p in paths]


def job_stats(work: Path) -> str:
    """The job table of the last Snakemake call in work/snakemake.log."""
    return (work / "snakemake.log").read_text().split("Job stats:")[-1].split("Select jobs")[0]


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
    from rve.homogenisation import layout as L
    from rve.homogenisation.distributed import probe_tasks

    spec = yaml.safe_load((work / C.CONFIG).read_text())["rve"]["runs"][C.RUN]
    rel = [t.record for t in probe_tasks(spec, C.RUN)]
    records = [work / r for r in rel]
    sm = [sys.executable, "-m", "snakemake", "-j2", *rel]  # the targets first: the options below take several values
    code, wall_sm = C.run(work, [*sm, "--forcerun", "rve_probes", "--configfile", C.CONFIG])
    if code or "rve_probes " not in job_stats(work):
        print(f"snakemake failed or ran no probe job: {work}/snakemake.log")
        return 1
    bench = [work / L.benchmark_path(C.RUN, "probes", r.parent.parent.name, r.stem) for r in records]
    own_sm = sum(float(b.read_text().splitlines()[1].split("\t")[0]) for b in bench)
    by_job = records_of(records)
    shutil.copy(work / C.TABLE, work / "table_per_state_jobs.nc")
    dask_rule = f"rve_probes_dask_{C.RUN}"
    dask = ["--configfile", C.CONFIG, "--config", "rve={probe_executor: dask}"]
    code, wall_dask = C.run(work, [*sm, "--forcerun", dask_rule, *dask])
    if code or dask_rule not in job_stats(work):
        print(f"snakemake with probe_executor dask failed or ran no {dask_rule} job: {work}/snakemake.log")
        return 1
    own_dask = float((work / L.benchmark_path(C.RUN, "probes_dask")).read_text().splitlines()[1].split("\t")[0])
    same = records_of(records) == by_job
    code_g, _ = C.run(work, [sys.executable, "-m", "snakemake", "-j2", C.TABLE, "--forcerun", "rve_gather", *dask])
    table_diff = C.table_differences(work / "table_per_state_jobs.nc", work / C.TABLE) if not code_g else ["gather failed"]
    print(f"{len(records)} probe jobs of {C.RUN}, 2 at a time")
    print(f"  snakemake -j2, one job per state:        {wall_sm:6.1f} s wall; the jobs' own time {own_sm:6.1f} s")
    print(f"  probe_executor dask, LocalCluster of 2:  {wall_dask:6.1f} s wall; the one job's own time {own_dask:6.1f} s")
    print(f"  win: {wall_sm / wall_dask:.2f}x in wall time")
    print(f"  records equal bit for bit (but wall_s): {same}")
    print(f"  table of the dask records: {'bit-identical' if not table_diff else 'DIFFERENT: ' + ', '.join(table_diff)}")
    if not args.work:
        shutil.rmtree(work)
    return 0 if same and not table_diff else 1


if __name__ == "__main__":
    sys.exit(main())
