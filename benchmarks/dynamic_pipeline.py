"""Whole Snakemake targets of the dynamic scenes on fresh result directories, this tree
against a baseline tree, as fresh runs alternated round by round (docs/engine.md "Dynamic
scenes: the targets").

    python benchmarks/dynamic_pipeline.py impact induced_deformation --baseline /work/wt/base [--runs 1]

Per run: ``snakemake -jJ TARGET`` (``--jobs``, default 2) started in the tree (its
``PYTHONPATH``), after removing the target's results, logs and Snakemake benchmark files
there (``results/<scene>``, ``results/logs/<scene>``, ``results/benchmarks/<scene>``): so
the impact run relaxes again. Printed per run: wall seconds (launch to exit), CPU seconds
of Snakemake and every job it waited for (``os.wait4``: user + system of the whole tree of
processes), peak RSS (the largest single process, from ``wait4`` and the jobs' Snakemake
benchmark files), the jobs' own wall/CPU seconds (benchmark files), and the load average
(``/proc/loadavg``) before and after; then the medians per tree and the ratio this tree /
baseline. The first tree of each round alternates (baseline first in odd rounds).

Not this script's business: the physics of the outputs (``benchmarks/dynamic_compare.py``).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SNAKEMAKE = Path(sys.executable).with_name("snakemake")
SCENE_DIR = {"impact": "impact", "induced_deformation": "induced_deformation"}


def _load() -> str:
    with open("/proc/loadavg") as fh:
        return " ".join(fh.read().split()[:3])


def _fresh(tree: Path, scene: str) -> None:
    for sub in (f"results/{scene}", f"results/logs/{scene}", f"results/benchmarks/{scene}"):
        shutil.rmtree(tree / sub, ignore_errors=True)


def _jobs(tree: Path, scene: str) -> list[dict]:
    out = []
    for p in sorted((tree / "results/benchmarks" / scene).glob("**/*.tsv")):
        with open(p) as fh:
            row = next(csv.DictReader(fh, delimiter="\t"))
        out.append({"job": str(p.relative_to(tree / "results/benchmarks" / scene).with_suffix("")),
                    "wall_s": float(row["s"]), "cpu_s": float(row.get("cpu_time") or "nan"),
                    "max_rss_mb": float(row["max_rss"]) if row.get("max_rss") not in (None, "", "-") else float("nan")})
    return out


def run_target(tree: Path, target: str, jobs: int) -> dict:
    scene = SCENE_DIR[target]
    _fresh(tree, scene)
    env = dict(os.environ, PYTHONPATH=str(tree))
    env["PATH"] = str(SNAKEMAKE.parent) + os.pathsep + env.get("PATH", "")
    load0 = _load()
    with tempfile.TemporaryFile("w+") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(["nice", "-n", "10", str(SNAKEMAKE), f"-j{jobs}", target], cwd=tree, env=env,
                                stdout=out, stderr=subprocess.STDOUT, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        out.seek(0)
        text = out.read()
    code = os.waitstatus_to_exitcode(status)
    jb = _jobs(tree, scene)
    rss = max([usage.ru_maxrss / 1024.0] + [j["max_rss_mb"] for j in jb if np.isfinite(j["max_rss_mb"])])
    rec = {"tree": str(tree), "target": target, "returncode": code, "wall_s": wall,
           "cpu_s": usage.ru_utime + usage.ru_stime, "peak_rss_mb": rss, "load_before": load0,
           "load_after": _load(), "jobs": jb}
    if code != 0:
        rec["error"] = text.strip().splitlines()[-20:]
    return rec


def _line(rec: dict) -> str:
    if rec["returncode"] != 0:
        return f"FAILED ({rec['returncode']}): " + " | ".join(rec.get("error", [])[-3:])
    jobs = ", ".join(f"{j['job']} {j['wall_s']:.0f}/{j['cpu_s']:.0f}" for j in rec["jobs"])
    return (f"wall {rec['wall_s']:.1f} s, CPU {rec['cpu_s']:.1f} s, peak RSS {rec['peak_rss_mb']:.0f} MB, load "
            f"{rec['load_before']} -> {rec['load_after']}; jobs wall/CPU s: {jobs}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("targets", nargs="+", choices=sorted(SCENE_DIR))
    ap.add_argument("--baseline", required=True, help="the other source tree (e.g. a worktree of main)")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--sides", nargs="+", default=["baseline", "this"], choices=["baseline", "this"],
                    help="run only these trees (the ratio needs both)")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    this = Path(__file__).resolve().parents[1]
    trees = {"baseline": Path(a.baseline).resolve(), "this": this}
    recs = {t: {k: [] for k in trees} for t in a.targets}
    for k in range(a.runs):
        order = [n for n in (["baseline", "this"] if k % 2 == 0 else ["this", "baseline"]) if n in a.sides]
        for target in a.targets:
            for name in order:
                rec = run_target(trees[name], target, a.jobs)
                recs[target][name].append(rec)
                print(f"[{target}] run {k + 1} {name} ({trees[name]}): {_line(rec)}", flush=True)
    for target in a.targets:
        med = {}
        for name in a.sides:
            ok = [r for r in recs[target][name] if r["returncode"] == 0]
            med[name] = {key: float(np.median([r[key] for r in ok])) if ok else float("nan")
                         for key in ("wall_s", "cpu_s", "peak_rss_mb")}
            print(f"[{target}] {name}: median of {len(ok)} runs: wall {med[name]['wall_s']:.1f} s, CPU "
                  f"{med[name]['cpu_s']:.1f} s, peak RSS {med[name]['peak_rss_mb']:.0f} MB")
        if len(med) < 2:
            continue
        b, t = med["baseline"], med["this"]
        print(f"[{target}] ratio this / baseline: wall {t['wall_s'] / b['wall_s']:.3f}, CPU "
              f"{t['cpu_s'] / b['cpu_s']:.3f}, peak RSS {t['peak_rss_mb'] / b['peak_rss_mb']:.3f}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(recs, fh, indent=1, default=float)


if __name__ == "__main__":
    main()
