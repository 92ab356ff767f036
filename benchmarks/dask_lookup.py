"""Lookups of many macro points in a large table: the table in memory against the table
opened lazily with dask chunks (docs/cluster.md "dask").

The table is synthetic, in the layout ``write_table`` stores (CF netCDF-4, zlib): one mode,
``--strains`` strain levels, a fibril_radius x contact_conductance sweep of ``--runs``
combinations, the probe, terminal and side dimensions of a real table, and as many
variables as a real one (every variable of ``rve.tables.schema.VARIABLES``). A macro point
is (strain, fibril_radius, contact_conductance), uniformly random inside the table; the
lookup is ``rve.tables.lookup`` (trilinear) of ``probe_resistance`` and two more
variables at every point.

* eager: ``open_table(path)`` (the whole table in memory), then the lookup;
* lazy: ``open_table(path, chunks=...)``: only the variables looked up are read, chunk by
  chunk, as dask computes the result.

Each path runs in a fresh child process: wall time (open + lookup), throughput (points per
second) and peak RSS (ru_maxrss of the child) are printed; the two results are compared.

    nice -n 10 python benchmarks/dask_lookup.py                       # 10^6 points, 20,000 runs
    nice -n 10 python benchmarks/dask_lookup.py --points 1000000 --runs 2000 20000
"""
from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

LOOKED_UP = ("probe_resistance", "reaction_force", "contact_resistance")
SWEPT = ("fibril_radius", "contact_conductance")


def synthetic_table(path: Path, runs: int, strains: int, seed: int = 0) -> Path:
    """A table of ``runs`` sweep combinations x ``strains`` levels with every variable of
    the schema, smooth in strain and the parameters (values do not matter, size does)."""
    import xarray as xr

    from rve.tables.io import write_table
    from rve.tables.schema import COMPONENTS, SIDE_ORDER, TERMINALS, VARIABLES

    import math

    na = int(math.sqrt(runs))
    while runs % na:
        na -= 1
    nb = runs // na
    rng = np.random.default_rng(seed)
    coords = {"mode": ["uniaxial"], "strain": np.linspace(0.0, 0.25, strains),
              "fibril_radius": 0.1 + 0.001 * np.arange(na), "contact_conductance": 0.5 + 0.01 * np.arange(nb),
              "probe": ["probe1", "probe2", "probe3", "probe4"], "side": list(SIDE_ORDER[:4]),
              "component": list(COMPONENTS), "terminal": list(TERMINALS)}
    lead = ("mode", "strain") + SWEPT
    base = (1.0 + coords["strain"][:, None, None]) * (1.0 + coords["fibril_radius"][None, :, None]) \
        * (1.0 + coords["contact_conductance"][None, None, :])
    data = {}
    for name, (dims, units, long_name, _extra) in VARIABLES.items():
        shape = (1,) + base.shape + tuple(len(coords[d]) for d in dims)
        vals = base.reshape((1,) + base.shape + (1,) * len(dims)) * (1.0 + rng.random(shape[len(lead):]))
        data[name] = (lead + dims, np.broadcast_to(vals, shape).copy(), {"units": units, "long_name": long_name})
    return write_table(xr.Dataset(data, coords=coords), path)


def macro_points(path: Path, n: int, seed: int = 1) -> dict[str, np.ndarray]:
    import xarray as xr

    rng = np.random.default_rng(seed)
    with xr.open_dataset(path) as ds:
        return {d: rng.uniform(float(ds[d].min()), float(ds[d].max()), n) for d in ("strain",) + SWEPT}


def child(kind: str, table: Path, points_file: Path, out: Path, chunk: int) -> None:
    from rve.tables import lookup, open_table

    points = dict(np.load(points_file))
    t0 = time.perf_counter()
    chunks = {"strain": -1, SWEPT[0]: chunk, SWEPT[1]: chunk} if kind == "lazy" else None
    ds = open_table(table, chunks=chunks)
    t_open = time.perf_counter() - t0
    res = lookup(ds, "uniaxial", variables=list(LOOKED_UP), **points).compute()
    wall = time.perf_counter() - t0
    np.savez(out, **{k: res[k].values for k in LOOKED_UP})
    print(json.dumps({"open_s": t_open, "wall_s": wall,
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def measure(kind: str, table: Path, points_file: Path, out: Path, chunk: int) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", kind, str(table), str(points_file), str(out),
                           "--chunk", str(chunk)], check=True, capture_output=True, text=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--runs", type=int, nargs="+", default=[20000])
    parser.add_argument("--strains", type=int, default=11)
    parser.add_argument("--chunk", type=int, default=32, help="dask chunk along each swept dimension")
    parser.add_argument("--child", nargs=4, metavar=("KIND", "TABLE", "POINTS", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], Path(args.child[1]), Path(args.child[2]), Path(args.child[3]), args.chunk)
        return 0
    print(f"{args.points} macro points, {args.strains} strain levels, dask chunk {args.chunk} per swept dimension")
    print(f"{'runs':>6} {'table MB':>9} {'in memory MB':>12} {'path':<6} {'open s':>7} {'wall s':>7} "
          f"{'points/s':>10} {'peak RSS MB':>12}")
    for runs in args.runs:
        work = Path(tempfile.mkdtemp(prefix=f"rve-lookup-{runs}-"))
        try:
            table = synthetic_table(work / "table.nc", runs, args.strains)
            import xarray as xr

            with xr.open_dataset(table) as ds:
                in_memory = ds.nbytes / 1e6
            points = work / "points.npz"
            np.savez(points, **macro_points(table, args.points))
            rows = {k: measure(k, table, points, work / f"{k}.npz", args.chunk) for k in ("eager", "lazy")}
            for k, r in rows.items():
                print(f"{runs:6d} {table.stat().st_size / 1e6:9.1f} {in_memory:12.1f} {k:<6} {r['open_s']:7.2f} "
                      f"{r['wall_s']:7.2f} {args.points / r['wall_s']:10.3g} {r['peak_rss_mb']:12.0f}")
            a, b = np.load(work / "eager.npz"), np.load(work / "lazy.npz")
            same = all(np.array_equal(a[k], b[k], equal_nan=True) for k in LOOKED_UP)
            close = all(np.allclose(a[k], b[k], rtol=1e-12, equal_nan=True) for k in LOOKED_UP)
            print(f"{runs:6d} lazy == eager: bit for bit {same}, to 1e-12 {close}")
        finally:
            shutil.rmtree(work)
    return 0


if __name__ == "__main__":
    sys.exit(main())
