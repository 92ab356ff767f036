"""Compare two RVE lookup tables variable by variable: bit-identical, else the largest
relative difference per mode and strain (issue 9's "behaviour preserved" check, issue 10's
"equal within 1e-6").

    python benchmarks/compare_tables.py OLD/table.nc NEW/table.nc

Variables present in only one table (e.g. the macro quantities of format 2) are listed;
variables whose labels differ (a 4th probe) are compared on the shared labels.
"""
from __future__ import annotations

import sys

import numpy as np

from rve.tables import open_table


def main(a_path: str, b_path: str) -> int:
    a, b = open_table(a_path), open_table(b_path)
    same = True
    for name in sorted(set(a.data_vars) | set(b.data_vars)):
        if name not in a.data_vars or name not in b.data_vars:
            print(f"{name:30s} only in {'the first' if name in a.data_vars else 'the second'} table")
            continue
        x, y = a[name], b[name].transpose(*a[name].dims)
        if x.shape != y.shape:
            # e.g. a table with a 4th probe against one with 3: compare the shared labels
            x, y = __import__("xarray").align(x, y, join="inner")
            print(f"{name:30s} (shared labels only: {dict(x.sizes)})")
        if np.array_equal(x.values, y.values, equal_nan=x.dtype.kind in "fc"):
            print(f"{name:30s} identical")
            continue
        same = False
        if x.dtype.kind not in "fc" or "mode" not in x.dims or "strain" not in x.dims:
            print(f"{name:30s} DIFFERENT")
            continue
        for m in x["mode"].values:
            xs = x.sel(mode=m).transpose("strain", ...).values.reshape(x.sizes["strain"], -1)
            ys = y.sel(mode=m).transpose("strain", ...).values.reshape(x.sizes["strain"], -1)
            with np.errstate(all="ignore"):
                scale = np.nanmax(np.abs(xs), axis=1) if np.isfinite(xs).any() else np.ones(len(xs))
            scale[~(scale > 0)] = 1.0
            with np.errstate(all="ignore"), __import__("warnings").catch_warnings():
                __import__("warnings").simplefilter("ignore", RuntimeWarning)
                rel = np.nanmax(np.abs(xs - ys), axis=1) / scale
            print(f"{name:30s} {m:10s} max rel. diff per strain: " + " ".join(f"{r:.0e}" for r in rel))
    print("ALL SHARED VARIABLES IDENTICAL" if same else "DIFFERENCES FOUND")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
