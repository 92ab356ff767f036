"""One table against a reference table on the work-precision study's measures
(``rve.studies.work_precision.run_errors``: the stated magnitude measure, and the range
measure beside it; max over labels, strains and modes) with the acceptance targets.

    python benchmarks/table_against_reference.py RUN/table.nc REFERENCE/table.nc [--worst N]

Prints per targeted quantity the two errors, the stated error per mode and whether the target
is met (on the stated measure); the quantities not comparable with their reason; with
``--worst N``, per targeted quantity the N rows (mode, strain, label, run and reference
values) with the largest stated error.
"""
from __future__ import annotations

import argparse
import sys

from rve.studies.work_precision import TARGETS, error_rows, run_errors, stated
from rve.tables import open_table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("reference")
    ap.add_argument("--worst", type=int, default=0)
    a = ap.parse_args(argv)
    run, ref = open_table(a.run), open_table(a.reference)
    e = run_errors(run, ref)
    print(f"{'quantity':22s} {'magnitude':>10s} {'range':>9s} {'target':>7s}  met   magnitude by mode")
    for q, target in TARGETS.items():
        if q not in stated(e):
            continue
        m, r = stated(e)[q], e["range"].get(q, float("nan"))
        modes = ", ".join(f"{k} {100 * v:.3g} %" for k, v in stated(e, by_mode=True).get(q, {}).items())
        print(f"{q:22s} {100 * m:8.3g} % {100 * r:8.3g} % {100 * target:6.3g} %  {'yes' if m <= target else 'no ':3s}   {modes}")
    for q, why in e["not_compared"].items():
        print(f"{q:22s} not compared: {why}")
    if a.worst > 0:
        rows = sorted(error_rows(run, ref), key=lambda r: -r["relative_error"])
        for q in TARGETS:
            top = [r for r in rows if r["quantity"] == q][:a.worst]
            for r in top:
                print(f"  {q:22s} {r['mode']:9s} {r['strain']:.4f} {r['label']:14s} run {r['value']:.5g} "
                      f"reference {r['reference']:.5g}: {100 * r['relative_error']:.3g} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
