"""The sweep of configs/tests/pipeline_ci.yaml `ci_cluster_sweep` (2 x 2 combinations, 29
jobs) run three ways, the gathered tables compared bit for bit (docs/cluster.md):

1. locally, `snakemake -j2`;
2. on Slurm through the shipped profile, `snakemake --profile workflow/profiles/slurm`;
3. on Slurm with one strain-step job cancelled by `scancel` while it runs (the run fails,
   every other job finishes), then the same command again, which runs what is missing.

Needs a running cluster (`workflow/slurm/local-cluster up`) and the `cluster` extra:

    nice -n 10 python benchmarks/cluster_sweep.py            # all three, prints the figures
    python benchmarks/cluster_sweep.py --keep DIR            # keep the three work folders in DIR

Each run works in its own copy of the Snakefile, workflow/ and configs/ (its own results/ and
.snakemake/). Prints the wall time of each run, the Slurm jobs' elapsed times from sacct,
the cancelled job and, per table variable, whether the bits agree. Exit code 0 when all
tables agree, 1 when one differs, 2 when no cluster is up.
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = "configs/tests/pipeline_ci.yaml"
RUN = "ci_cluster_sweep"
TABLE = f"results/rve/{RUN}/table.nc"
PROFILE = "workflow/profiles/slurm"
# The executor's first status check waits 40 s by default (and 10 s longer after every
# check that found nothing finished): right for a busy site, slow for jobs of seconds.
LOCAL_POLL = ("--slurm-init-seconds-before-status-checks", "2")
# attributes that record when the table was written, not what it holds
TIME_ATTRS = ("date_created", "history")


def cluster_up() -> str | None:
    """None when `sinfo` answers with a node that takes jobs, else the reason it does not."""
    if shutil.which("sinfo") is None:
        return "no sinfo on PATH (Slurm's client commands are not installed)"
    try:
        proc = subprocess.run(["sinfo", "-h", "-N", "-o", "%T"], capture_output=True, text=True, timeout=20)
    except subprocess.TimeoutExpired:
        return "sinfo did not answer in 20 s (slurmctld not running?)"
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        return f"sinfo failed: {last}"
    states = proc.stdout.split()
    if not any(s.rstrip("*") in ("idle", "mixed", "allocated") for s in states):
        return f"no Slurm node takes jobs (node states: {' '.join(states) or 'none'})"
    return None


def workflow_copy(dest: Path) -> Path:
    """The Snakefile, workflow/ and configs/ copied into ``dest`` (its own results and state)."""
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copy2(ROOT / "Snakefile", dest / "Snakefile")
    shutil.copytree(ROOT / "workflow", dest / "workflow")
    shutil.copytree(ROOT / "configs", dest / "configs")
    return dest


def snakemake_cmd(slurm: bool, *extra: str) -> list[str]:
    how = ["--profile", PROFILE, *LOCAL_POLL] if slurm else ["-j2"]
    # the target before --configfile, which takes several values
    return [sys.executable, "-m", "snakemake", *how, TABLE, *extra, "--configfile", CONFIG]


def _env() -> dict[str, str]:
    # the jobs import this tree's rve (Slurm passes the submitting environment on)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH", "")) if p)
    return env


def run(work: Path, cmd: list[str], timeout: float = 1800) -> tuple[int, float]:
    """Run ``cmd`` in ``work`` (output in work/snakemake.log): exit code and wall time."""
    t0 = time.perf_counter()
    with open(work / "snakemake.log", "a") as log:
        proc = subprocess.run(cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT, env=_env(), timeout=timeout)
    return proc.returncode, time.perf_counter() - t0


def running_job(rule: str, timeout: float = 600, proc: subprocess.Popen | None = None) -> tuple[str, str]:
    """(job id, comment) of the first RUNNING Slurm job of ``rule`` (the executor's comment
    names the rule and its wildcards)."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"snakemake ended ({proc.returncode}) before a {rule} job ran")
        out = subprocess.run(["squeue", "-h", "-t", "RUNNING", "-o", "%i|%k"], capture_output=True, text=True).stdout
        for line in out.splitlines():
            job, _, comment = line.partition("|")
            if comment.startswith(f"rule_{rule}_"):
                return job.strip(), comment
        time.sleep(0.3)
    raise RuntimeError(f"no {rule} job ran within {timeout:.0f} s")


def cancelled_run(work: Path, rule: str = "rve_strain_step") -> dict:
    """The profile's run with no retries; one running ``rule`` job cancelled by scancel."""
    cmd = snakemake_cmd(True, "--retries", "0")
    t0 = time.perf_counter()
    with open(work / "snakemake.log", "a") as log:
        proc = subprocess.Popen(cmd, cwd=work, stdout=log, stderr=subprocess.STDOUT, env=_env(),
                                start_new_session=True)
        try:
            job, comment = running_job(rule, proc=proc)
            subprocess.run(["scancel", job], check=True)
            try:
                code = proc.wait(timeout=900)
            except subprocess.TimeoutExpired:
                # the executor never saw the cancel: stop the run as a user would have to
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                subprocess.run(snakemake_cmd(False, "--unlock"), cwd=work, env=_env(), capture_output=True)
                code = "none: snakemake did not notice the cancel in 900 s and was killed"
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait()
    return {"job": job, "comment": comment, "code": code, "wall_s": time.perf_counter() - t0,
            "table_written": (work / TABLE).exists()}


def sacct_now() -> str:
    """The current time as sacct's -S takes it."""
    return time.strftime("%Y-%m-%dT%H:%M:%S")


def sacct_jobs(since: str) -> list[dict]:
    """This user's Slurm jobs since ``since``: id, state, elapsed s, the rule (from the
    executor's job comment), allocated CPUs, requested MB and time limit in minutes."""
    fields = "JobID,State,ElapsedRaw,AllocCPUS,ReqMem,TimelimitRaw,Comment"
    out = subprocess.run(["sacct", "-X", "-n", "-P", "-S", since, "-o", fields],
                         capture_output=True, text=True).stdout
    jobs = []
    for line in out.splitlines():
        job, state, elapsed, cpus, mem, limit, comment = line.split("|", 6)
        rule = comment[len("rule_"):].split("_wildcards_")[0] if comment.startswith("rule_") else ""
        mem_mb = float(mem.rstrip("MGn")) * (1024 if mem.rstrip("n").endswith("G") else 1) if mem else 0.0
        jobs.append({"id": job, "state": state.split()[0], "elapsed_s": float(elapsed or 0), "rule": rule,
                     "cpus": int(cpus or 0), "mem_mb": int(mem_mb), "limit_min": int(limit) if limit.isdigit() else 0})
    return jobs


def table_differences(a_path: Path, b_path: Path) -> list[str]:
    """Names of the variables, coordinates and attributes whose bits differ (the write
    time attributes aside); empty when the tables are bit-identical."""
    import xarray as xr

    with xr.open_dataset(a_path) as a, xr.open_dataset(b_path) as b:
        names = set(a.variables) | set(b.variables)
        diff = sorted(n for n in names if n not in a.variables or n not in b.variables
                      or not _same_bits(a[n].values, b[n].values) or a[n].attrs != b[n].attrs)
        for key in (set(a.attrs) | set(b.attrs)) - set(TIME_ATTRS):
            if not _same_bits(np.asarray(a.attrs.get(key)), np.asarray(b.attrs.get(key))):
                diff.append(f"attribute {key}")
    return diff


def _same_bits(x: np.ndarray, y: np.ndarray) -> bool:
    if x.dtype != y.dtype or x.shape != y.shape:
        return False
    if x.dtype.kind in "biufc":
        # bytes, not values: -0.0 against 0.0 and NaN payloads count
        return np.ascontiguousarray(x).tobytes() == np.ascontiguousarray(y).tobytes()
    return [str(v) for v in x.ravel()] == [str(v) for v in y.ravel()]


def _report(name: str, diff: list[str]) -> bool:
    print(f"  {name}: {'bit-identical' if not diff else 'DIFFERENT: ' + ', '.join(diff)}")
    return not diff


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keep", type=Path, help="keep the work folders in this folder")
    args = parser.parse_args()
    reason = cluster_up()
    if reason:
        print(f"no cluster: {reason}; start one with  workflow/slurm/local-cluster up")
        return 2
    base = args.keep or Path(tempfile.mkdtemp(prefix="rve-cluster-sweep-"))
    local, slurm, cancel = (workflow_copy(base / n) for n in ("local", "slurm", "cancelled"))
    since = sacct_now()

    code, wall = run(local, snakemake_cmd(False))
    print(f"local -j2:         exit {code}, {wall:.1f} s wall")
    code_s, wall_s = run(slurm, snakemake_cmd(True))
    jobs = sacct_jobs(since)
    print(f"slurm profile:     exit {code_s}, {wall_s:.1f} s wall; {len(jobs)} Slurm jobs, "
          f"{sum(j['elapsed_s'] for j in jobs):.0f} s summed elapsed, states {sorted({j['state'] for j in jobs})}")
    asked = sorted({(j["rule"], j["cpus"], j["mem_mb"], j["limit_min"]) for j in jobs})
    print("  rule, CPUs, MB, minutes asked of Slurm: " + "; ".join(" ".join(map(str, a)) for a in asked))
    c = cancelled_run(cancel)
    print(f"scancel:           job {c['job']} ({c['comment']}) cancelled while running; "
          f"snakemake exit {c['code']} after {c['wall_s']:.1f} s, table written: {c['table_written']}")
    code_r, wall_r = run(cancel, snakemake_cmd(True))
    print(f"rerun:             exit {code_r}, {wall_r:.1f} s wall")
    if code or code_s or code_r or c["code"] == 0:
        print(f"a run failed or the cancelled run did not: see {base}/*/snakemake.log")
        return 1
    print("tables against the local -j2 table:")
    ok = _report("slurm profile", table_differences(local / TABLE, slurm / TABLE))
    ok = _report("scancel + rerun", table_differences(local / TABLE, cancel / TABLE)) and ok
    if not args.keep:
        shutil.rmtree(base)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
