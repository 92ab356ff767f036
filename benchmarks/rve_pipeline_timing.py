"""Benchmark: wall time of every stage of the RVE pipeline and of the whole job.

Gathers Snakemake's benchmark files ``results/benchmarks/rve/<run>/**.tsv`` (one per job:
wall seconds ``s``, peak RSS ``max_rss`` in MB, ``cpu_time``) into one table per stage
(fabric, relax, strain, probes, gather, report): jobs, median and total wall seconds, total
CPU seconds, max RSS. The whole-job time is the wall time between the first and the last job of the
latest Snakemake log (``.snakemake/log/*.snakemake.log``), or the time measured here with
``--run`` (which runs ``snakemake -j2`` first). Prints the dominant stage (largest total
job time) and the critical path (relax + the longest chain of strain steps).

    python benchmarks/rve_pipeline_timing.py [--run] [--runs plain_weave]
        [--configfile FILE] [--results results] [--csv out.csv]

Run from the repository root after ``snakemake -j2`` (or with ``--run``).
"""
from __future__ import annotations

import argparse
import csv
import re
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import numpy as np

STAGES = ("fabric", "relax", "strain", "probes", "gather", "report")
_STAMP = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]")


def read_benchmarks(root: Path, runs=None) -> list[dict]:
    """One row per benchmark file: run, combo, stage, job, wall s, max RSS (MB), cpu s."""
    rows = []
    for path in sorted(root.glob("**/*.tsv")):
        rel = path.relative_to(root).with_suffix("").parts
        run = rel[0]
        if runs and run not in runs:
            continue
        if len(rel) == 2:  # <run>/gather, <run>/report
            combo, stage, job = "", rel[1], rel[1]
        elif len(rel) == 3:  # <run>/<combo>/fabric|relax
            combo, stage, job = rel[1], rel[2], rel[2]
        else:  # <run>/<combo>/strain|probes/<name>
            combo, stage, job = rel[1], rel[2], rel[3]
        lines = path.read_text().strip().splitlines()
        if len(lines) < 2:
            continue
        head = lines[0].split("\t")
        vals = lines[-1].split("\t")
        rec = dict(zip(head, vals))

        def num(key):
            try:
                return float(rec.get(key, "nan"))
            except ValueError:
                return float("nan")

        rows.append({"run": run, "combo": combo, "stage": stage, "job": job, "s": num("s"),
                     "max_rss_mb": num("max_rss"), "cpu_s": num("cpu_time")})
    return rows


def stage_table(rows: list[dict]) -> list[dict]:
    out = []
    names = [s for s in STAGES if any(r["stage"] == s for r in rows)]
    names += sorted({r["stage"] for r in rows} - set(names))
    for st in names:
        sel = [r for r in rows if r["stage"] == st]
        s = np.array([r["s"] for r in sel])
        rss = np.array([r["max_rss_mb"] for r in sel])
        cpu = np.array([r["cpu_s"] for r in sel])
        out.append({"stage": st, "jobs": len(sel), "median_s": float(np.median(s)), "total_s": float(s.sum()),
                    "max_s": float(s.max()), "total_cpu_s": float(np.nansum(cpu)),
                    "max_rss_mb": float(np.nanmax(rss)) if np.isfinite(rss).any() else np.nan})
    return out


def critical_path(rows: list[dict]) -> float:
    """fabric + relax + the longest strain chain (one mode) + the slowest probe + gather + report,
    per combination (the max over combinations)."""
    best = 0.0
    for combo in {r["combo"] for r in rows if r["combo"]}:
        sel = [r for r in rows if r["combo"] == combo]
        base = sum(r["s"] for r in sel if r["stage"] in ("fabric", "relax"))
        chains: dict = {}
        for r in sel:
            if r["stage"] == "strain":
                mode = r["job"].rsplit("_", 1)[0]
                chains[mode] = chains.get(mode, 0.0) + r["s"]
        probe = max((r["s"] for r in sel if r["stage"] == "probes"), default=0.0)
        best = max(best, base + max(chains.values(), default=0.0) + probe)
    return best + sum(r["s"] for r in rows if r["stage"] in ("gather", "report"))


def log_wall_time(workdir: Path):
    """(first, last job timestamp, seconds) of the latest Snakemake log, or None."""
    logs = sorted((workdir / ".snakemake" / "log").glob("*.snakemake.log"))
    if not logs:
        return None
    stamps = []
    for line in logs[-1].read_text(errors="replace").splitlines():
        m = _STAMP.match(line)
        if m:
            stamps.append(datetime.strptime(m.group(1), "%a %b %d %H:%M:%S %Y"))
    if len(stamps) < 2:
        return None
    return logs[-1].name, (stamps[-1] - stamps[0]).total_seconds()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", default="results", help="results directory (benchmarks/rve/ below it)")
    ap.add_argument("--runs", nargs="*", default=None, help="only these runs (default: all found)")
    ap.add_argument("--run", action="store_true", help="run `snakemake -j2` first and time it")
    ap.add_argument("--configfile", default=None, help="config file for --run")
    ap.add_argument("--targets", nargs="*", default=[], help="targets for --run (default: the default target)")
    ap.add_argument("--csv", default=None, help="also write the per-stage table as CSV")
    args = ap.parse_args(argv)

    measured = None
    if args.run:
        cmd = [sys.executable, "-m", "snakemake", "-j2", *args.targets]
        if args.configfile:
            cmd += ["--configfile", args.configfile]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd)
        measured = time.perf_counter() - t0
        if proc.returncode != 0:
            print(f"snakemake failed ({proc.returncode})", file=sys.stderr)
            return proc.returncode

    root = Path(args.results) / "benchmarks" / "rve"
    rows = read_benchmarks(root, set(args.runs) if args.runs else None)
    if not rows:
        print(f"no benchmark files under {root}", file=sys.stderr)
        return 1
    table = stage_table(rows)
    runs = sorted({r["run"] for r in rows})
    combos = sorted({r["combo"] for r in rows if r["combo"]})
    print(f"RVE pipeline timing: runs {', '.join(runs)}; {len(combos)} combination(s); {len(rows)} jobs")
    print(f"{'stage':8s} {'jobs':>5s} {'median s':>10s} {'max s':>9s} {'total s':>9s} {'total CPU s':>12s} "
          f"{'max RSS MB':>11s}")
    for t in table:
        print(f"{t['stage']:8s} {t['jobs']:5d} {t['median_s']:10.1f} {t['max_s']:9.1f} {t['total_s']:9.1f} "
              f"{t['total_cpu_s']:12.1f} {t['max_rss_mb']:11.0f}")
    total_job_s = sum(t["total_s"] for t in table)
    dom = max(table, key=lambda t: t["total_s"])
    print(f"sum of job times: {total_job_s:.1f} s ({total_job_s / 60:.1f} min); with 2 cores >= "
          f"{total_job_s / 2 / 60:.1f} min")
    print(f"critical path (fabric + relax + longest strain chain + slowest probe + gather + report): "
          f"{critical_path(rows):.1f} s")
    print(f"dominant stage: {dom['stage']} ({dom['total_s']:.1f} s, {100 * dom['total_s'] / total_job_s:.0f} % of "
          "the job time)")
    lw = log_wall_time(Path("."))
    if measured is not None:
        print(f"whole job (measured here, snakemake -j2): {measured:.1f} s ({measured / 60:.1f} min)")
    if lw is not None:
        print(f"whole job (latest Snakemake log {lw[0]}, first to last job stamp): {lw[1]:.0f} s "
              f"({lw[1] / 60:.1f} min)")
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(table[0]))
            w.writeheader()
            w.writerows(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
