"""One table against a reference table on the work-precision study's measures
(``rve.studies.work_precision.run_errors``: the stated magnitude measure, and the range
measure beside it; max over labels, strains and modes) with the acceptance targets.

    python benchmarks/table_against_reference.py RUN/table.nc REFERENCE/table.nc

Prints per targeted quantity the two errors, the stated error per mode and whether the target
is met (on the stated measure); the quantities not comparable with their reason.
"""
from __future__ import annotations

import sys

from rve.studies.work_precision import TARGETS, run_errors, stated
from rve.tables import open_table


def main(run_path: str, ref_path: str) -> int:
    e = run_errors(open_table(run_path), open_table(ref_path))
    print(f"{'quantity':22s} {'magnitude':>10s} {'range':>9s} {'target':>7s}  met   magnitude by mode")
    for q, target in TARGETS.items():
        if q not in stated(e):
            continue
        m, r = stated(e)[q], e["range"].get(q, float("nan"))
        modes = ", ".join(f"{k} {100 * v:.3g} %" for k, v in stated(e, by_mode=True).get(q, {}).items())
        print(f"{q:22s} {100 * m:8.3g} % {100 * r:8.3g} % {100 * target:6.3g} %  {'yes' if m <= target else 'no ':3s}   {modes}")
    for q, why in e["not_compared"].items():
        print(f"{q:22s} not compared: {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
