"""Benchmark: convergence of the RVE table with the mesh and the contact penalty (issue 14).

Runs (``--run``) or reads the study ``{study}`` of the pipeline (rule
``rve_table_convergence_report``; runs ``{study}_mesh`` over ``mesh.elements`` and
``{study}_penalty`` over ``contact_penalty``, configs/pipeline.yaml) and prints, per table
quantity, the error of every run against the finest/stiffest one (max over labels, modes and
strains; per mode max and median), the observed rate with mesh size, each run's summed job
CPU and wall time and peak memory, the finest mesh's own estimated error, and the default
run's stated accuracy against the targets (docs/table_accuracy.md). ``--docs`` copies the
work-precision plot to docs/img/rve_table_convergence.png. ``--write-accuracy PATH`` copies
the study's accuracy.json (with the date and commit) to PATH, the file a run spec's
``accuracy`` key names (configs/rve/plain_weave_accuracy.json for the default run): the
gather job then writes it into the table's ``estimated_relative_error`` attributes.

``--work-precision [STUDY]`` prints instead the work-precision study's report
(``rve_work_precision_report``, docs/table_accuracy.md) and the acceptance figures: the
default table's stated error per quantity (against the one reference, range measure)
against the targets, and the default job's summed job wall time and peak memory from its
Snakemake benchmark files (``--default-run``, default plain_weave); with ``--run`` it runs
the study first, with ``--write-accuracy PATH`` it copies the study's accuracy file.

    python benchmarks/table_convergence.py --run                 # the default RVE (long: ~1-2 h)
    python benchmarks/table_convergence.py --work-precision --ci --run   # the CI study (minutes)
    python benchmarks/table_convergence.py --run --ci            # the CI study (2 x 2 weave, minutes)
    python benchmarks/table_convergence.py [--study NAME] [--docs]

Run from the repository root; ``--run`` uses ``nice -n 15 snakemake -j2``.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", action="store_true", help="run the study with snakemake -j2 first")
    ap.add_argument("--ci", action="store_true", help="the CI study (configs/tests/pipeline_ci.yaml)")
    ap.add_argument("--study", default=None, help="study name (default: table_convergence, with --ci "
                                                  "ci_table_convergence)")
    ap.add_argument("--docs", action="store_true", help="copy the plot to docs/img/rve_table_convergence.png")
    ap.add_argument("--results", default="results", help="results folder")
    ap.add_argument("--write-accuracy", default=None, metavar="PATH",
                    help="copy accuracy.json (+ date, commit) to PATH (the run spec's `accuracy` file)")
    ap.add_argument("--work-precision", nargs="?", const="", default=None, metavar="STUDY",
                    help="the work-precision study (default work_precision, with --ci ci_work_precision)")
    ap.add_argument("--default-run", default=None, help="run whose job time and memory are printed "
                                                         "(default plain_weave, with --ci ci)")
    a = ap.parse_args(argv)
    if a.work_precision is not None:
        return work_precision(a)
    study = a.study or ("ci_table_convergence" if a.ci else "table_convergence")
    d = Path(a.results) / "rve" / "convergence" / study
    target = str(d / "table_convergence.md")
    if a.run:
        cmd = ["nice", "-n", "15", sys.executable, "-m", "snakemake", "-j2", target]
        if a.ci:
            cmd += ["--configfile", "configs/tests/pipeline_ci.yaml"]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd)
        print(f"snakemake -j2 {target}: exit {proc.returncode}, {time.perf_counter() - t0:.0f} s wall")
        if proc.returncode:
            return proc.returncode
    if not Path(target).exists():
        print(f"{target} does not exist: run with --run (or snakemake -j2 rve_table_convergence)")
        return 1
    print(Path(target).read_text())
    acc = json.loads((d / "accuracy.json").read_text())
    for name in ("mesh", "penalty"):
        st = acc.get(name)
        if not st:
            continue
        dim = "mesh_elements" if name == "mesh" else "contact_penalty"
        print(f"default {dim} = {acc['default'][dim]:g} vs reference {st['reference']:g}:")
        ref_err = st.get("reference_error") or {}
        stated = st.get("stated_relative_error") or st["estimated_relative_error"]
        for q, e in st["estimated_relative_error"].items():
            tgt = acc["targets"].get(q)
            rate = st["observed_rate"].get(q)
            if e is None:
                print(f"  {q:22s} n/a")
                continue
            extra = (f"  + reference's own {100 * ref_err[q]:7.3f} % = stated {100 * stated[q]:8.3f} %"
                     if ref_err.get(q) is not None else "")
            print(f"  {q:22s} error {100 * e:8.3f} %{extra}  target {100 * tgt:4.1f} %  "
                  f"{'met' if st['meets_targets'][q] else 'NOT met':7s}  rate {rate:.2f}")
        by_mode, ref_m = st.get("by_mode") or {}, st.get("reference_error_by_mode") or {}
        for q, modes in by_mode.items():
            for m, e in modes.items():
                if e:
                    own = (ref_m.get(q) or {}).get(m)
                    print(f"  {q:22s} {m:9s} max {100 * e['max']:8.3f} %  median {100 * e['median']:7.3f} %"
                          + (f"  stated (+ reference's own) {100 * (e['max'] + own):8.3f} %" if own is not None else ""))
        runs = st.get("runs") or {}
        if runs:
            print(f"  {'run':>8s} {'CPU s':>8s} {'wall s':>8s} {'peak RSS MB':>12s}")
            for v, r in runs.items():
                print(f"  {v:>8s} {r.get('cpu_s') or float('nan'):8.0f} {r.get('wall_s') or float('nan'):8.0f} "
                      f"{r.get('max_rss_mb') or float('nan'):12.0f}")
        r = st.get("cpu_time_ratio_default_to_reference")
        w = st.get("wall_time_ratio_default_to_reference")
        if r or w:
            print(f"  time default / reference: CPU {r or float('nan'):.3f}, wall (summed jobs) {w or float('nan'):.3f}"
                  " (wall times depend on the machine's load)")
    if a.write_accuracy:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
        stamp = time.strftime("%Y-%m-%d", time.gmtime((d / "accuracy.json").stat().st_mtime))
        acc["provenance"] = {"date": stamp, "commit": commit or "?", "study": study,
                             "command": "snakemake -j2 rve_table_convergence"}
        Path(a.write_accuracy).write_text(json.dumps(acc, indent=1) + "\n")
        print(f"accuracy -> {a.write_accuracy}")
    if a.docs:
        dst = Path("docs/img/rve_table_convergence.png")
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(d / "table_convergence.png", dst)
        print(f"plot -> {dst}")
    return 0


def work_precision(a) -> int:
    """The work-precision study's report and the acceptance figures (module docstring)."""
    study = a.work_precision or ("ci_work_precision" if a.ci else "work_precision")
    d = Path(a.results) / "rve" / "work_precision" / study
    target = str(d / "work_precision.md")
    if a.run:
        cmd = ["nice", "-n", "15", sys.executable, "-m", "snakemake", "-j2"]
        if a.ci:
            cmd += ["--configfile", "configs/tests/pipeline_ci.yaml"]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd + ["--", target])
        print(f"snakemake -j2 {target}: exit {proc.returncode}, {time.perf_counter() - t0:.0f} s wall")
        if proc.returncode:
            return proc.returncode
    if not Path(target).exists():
        print(f"{target} does not exist: run with --run (or snakemake -j2 rve_work_precision)")
        return 1
    print(Path(target).read_text())
    acc = json.loads((d / "accuracy.json").read_text())
    if not acc["stated_relative_error"]:
        print(f"no stated error: study {study} has no default run compared with its reference {acc['reference']}")
    print(f"stated error of the default run ({acc['default']}) against the reference run {acc['reference']} "
          f"({acc['measure']} measure, max over strains, labels and modes):")
    for q, tgt in acc["targets"].items():
        e = acc["stated_relative_error"].get(q)
        if e is None:
            why = (acc.get("not_measured") or {}).get(q, "no error")
            print(f"  {q:22s} {'n/a':>10s}  target {100 * tgt:4.1f} %  NOT measured ({why})")
            continue
        mag = (acc.get("magnitude_relative_error") or {}).get(q)
        verdict = "met" if e <= tgt else f"NOT met ({e / tgt:.2f} x the target)"
        print(f"  {q:22s} {100 * e:8.3f} %  target {100 * tgt:4.1f} %  {verdict}"
              + (f"  (magnitude measure {100 * mag:.3f} %)" if mag is not None else ""))
    if acc.get("front"):
        print("front (CPU time against the worst error / target): " + "; ".join(acc["front"]))
    run = a.default_run or ("ci" if a.ci else "plain_weave")
    print(_job_figures(Path(a.results) / "benchmarks" / "rve" / run, run))
    if a.write_accuracy:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
        stamp = time.strftime("%Y-%m-%d", time.gmtime((d / "accuracy.json").stat().st_mtime))
        acc["provenance"] = {"date": stamp, "commit": commit or "?", "study": study,
                             "command": f"snakemake -j2 {target}"}
        Path(a.write_accuracy).write_text(json.dumps(acc, indent=1) + "\n")
        print(f"accuracy -> {a.write_accuracy}")
    return 0


def _job_figures(root: Path, run: str) -> str:
    """The default job's summed job wall and CPU time and the largest peak RSS of its jobs."""
    import csv

    rows = []
    for p in sorted(root.glob("**/*.tsv")):
        got = list(csv.DictReader(p.open(), delimiter="\t"))
        if got:
            rows.append(got[-1])
    if not rows:
        return f"default job {run}: no benchmark files under {root} (run snakemake -j2 first)"

    def num(v):
        try:
            return float(v)
        except (TypeError, ValueError):
            return 0.0

    wall = sum(num(r["s"]) for r in rows)
    cpu = sum(num(r.get("cpu_time")) for r in rows)
    rss = max(num(r.get("max_rss")) for r in rows)
    return (f"default job {run}: {len(rows)} jobs, summed job wall {wall:.0f} s, CPU {cpu:.0f} s (with -j2 the job's "
            f"wall is about half the CPU sum plus start-up; benchmarks/rve_pipeline_timing.py prints the stamps), "
            f"peak RSS of one job {rss / 1024:.2f} GiB (target: 10 min wall, 4 GiB)")


if __name__ == "__main__":
    sys.exit(main())
