"""The machinery every benchmark script shares: fresh processes, interleaved sides, medians,
peak RSS, JSON records.

Contract
--------
* ``worker_env(**extra) -> dict``: the environment of a measured process: this tree first on
  ``PYTHONPATH``, one BLAS/OpenMP/MKL thread unless the caller's environment sets them, and
  ``extra`` on top.
* ``run_process(argv, env=None, cwd=None) -> Run``: one fresh process to its end; ``Run``
  holds its exit code, wall time (launch to exit), user + system CPU time and peak RSS
  (``os.wait4``: that process alone, not its children), and its output.
* ``run_json(argv, env=None, cwd=None) -> dict``: ``run_process`` whose last stdout line is a
  JSON record, returned with ``wall_s``, ``cpu_s``, ``process_rss_mib`` added (``error``: the
  last stderr line when the process failed).
* ``interleave(sides, runs) -> {name: [record, ...]}``: ``sides`` maps a name to a callable
  ``run(k) -> dict``; round k runs every side once, in order (so a slow period of a shared
  machine falls on every side alike).
* ``median(records, key)``, ``peak(records, key)`` over the records without ``error``;
  ``median_time(fn, repeats) -> (median seconds, last result)`` inside one process;
  ``rss_mib()`` the peak RSS of this process.
* ``write_json(path, obj)``: the records, numbers as floats.
* ``pipeline_spec(run, overrides=()) -> dict``: a copy of the run spec ``run`` of
  configs/pipeline.yaml without its ``sweep`` and ``accuracy``, ``overrides`` appended (one
  combination, the spec the job functions of ``rve.homogenisation.jobs`` take).
* ``relaxed_state(spec, combo, directory) -> Path``: ``directory/relaxed.nc`` of the spec's
  combination (``fabric_job`` and ``relax_job`` of the pipeline), built once.

The machine (2 cores) is usually shared: compare ratios within one invocation, not across.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

__all__ = ["ROOT", "Run", "worker_env", "run_process", "run_json", "interleave", "median", "peak", "median_time",
           "rss_mib", "write_json", "pipeline_spec", "relaxed_state"]

ROOT = Path(__file__).resolve().parents[1]
_ONE_THREAD = ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")


@dataclass
class Run:
    returncode: int
    wall_s: float
    cpu_s: float
    rss_mib: float
    stdout: str
    stderr: str


def worker_env(**extra) -> dict:
    env = dict(os.environ)
    for k in _ONE_THREAD:
        env.setdefault(k, "1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.update({k: str(v) for k, v in extra.items()})
    return env


def run_process(argv, env: Mapping | None = None, cwd=None) -> Run:
    # output to temporary files, not pipes: the process is then reaped by os.wait4 alone,
    # which gives its own resource usage (peak RSS, CPU time)
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen([str(a) for a in argv], cwd=cwd, env=dict(env) if env is not None else None,
                                stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        return Run(proc.returncode, wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, out.read(),
                   err.read())


def run_json(argv, env: Mapping | None = None, cwd=None) -> dict:
    r = run_process(argv, env, cwd)
    if r.returncode != 0:
        return {"error": (r.stderr.strip().splitlines() or ["?"])[-1], "wall_s": r.wall_s}
    rec = json.loads(r.stdout.strip().splitlines()[-1])
    rec.update(wall_s=r.wall_s, cpu_s=r.cpu_s, process_rss_mib=r.rss_mib)
    return rec


def interleave(sides: Mapping[str, Callable[[int], dict]], runs: int, log=sys.stderr) -> dict:
    recs = {name: [] for name in sides}
    for k in range(int(runs)):
        for name, run in sides.items():
            rec = run(k)
            recs[name].append(rec)
            if log is not None:
                print(f"  run {k + 1} {name}: " + ("error " + rec["error"] if "error" in rec else
                      f"{rec.get('wall_s', float('nan')):.2f} s"), file=log, flush=True)
    return recs


def _ok(records):
    return [r for r in records if "error" not in r]


def median(records, key: str) -> float:
    vals = [r[key] for r in _ok(records)]
    return float(np.median(vals)) if vals else float("nan")


def peak(records, key: str) -> float:
    vals = [r[key] for r in _ok(records)]
    return float(max(vals)) if vals else float("nan")


def median_time(fn, repeats: int):
    ts, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), out


def rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def write_json(path, obj) -> None:
    Path(path).write_text(json.dumps(obj, indent=1, default=float))


def pipeline_spec(run: str, overrides=()) -> dict:
    """One combination's spec of a configs/pipeline.yaml run (module docstring)."""
    import copy

    import yaml

    spec = copy.deepcopy(yaml.safe_load((ROOT / "configs" / "pipeline.yaml").read_text())["rve"]["runs"][run])
    spec.pop("sweep", None)
    spec.pop("accuracy", None)
    spec["overrides"] = list(spec.get("overrides") or []) + list(overrides)
    return spec


def relaxed_state(spec: Mapping, combo: str, directory) -> Path:
    """The relaxed state of ``spec``'s ``combo`` under ``directory`` (module docstring)."""
    from rve.homogenisation.jobs import fabric_job, relax_job

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    out = d / "relaxed.nc"
    if not out.exists():
        c0 = time.process_time()
        fabric_job(d / "initial.nc", d / "fabric.log", spec, combo)
        relax_job(d / "initial.nc", out, d / "relax.log", spec, combo)
        print(f"relaxed {d.name}: {time.process_time() - c0:.1f} s CPU -> {out}", file=sys.stderr, flush=True)
    return out
