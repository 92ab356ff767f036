"""The gather of a large sweep: today's eager path against a lazy dask one, on synthetic
sweeps of 200, 2,000 and 20,000 runs (docs/cluster.md "dask").

A synthetic run is one combination of a two-parameter sweep (fibril_radius x
contact_conductance) with the records the pipeline writes for it: the relaxed state and
two uniaxial steps (JSON files, as rve_probes writes them), one probe by default. With one
probe the table has no network fit (R_y, R_c need two probes or more), so the figures are
those of gathering itself: reading, filling, combining, writing. ``--probes 4`` adds the
fits (two least-squares fits per state, the same work on both paths, wherever it runs).
Two gathers:

* eager (today's rve_gather): read every record, ``build_table`` over all of them, write
  the table (``write_table``: zlib, chunked by netCDF-4);
* lazy: each run's own small table (``build_table`` on that run's records, written as a
  netCDF file: the work a per-run job would do, timed apart as "per-run tables"), then
  ``xr.open_mfdataset(..., parallel=True)`` over those files and ``to_netcdf`` with dask
  chunks and zlib, computed chunk by chunk.

Each gather runs in a fresh child process; its wall time and peak RSS (ru_maxrss of the
child) are printed, and the two tables are checked to hold the same values.

    nice -n 10 python benchmarks/dask_gather.py                  # 200 and 2,000 runs
    nice -n 10 python benchmarks/dask_gather.py --build --runs 2000 20000   # build_table alone

``--build`` times ``build_table`` alone on the records in memory (no files) for the
near-square two-parameter grid and for a one-parameter sweep of the same size (1 x N), and
prints a digest of the table's bits, to compare two commits.
    nice -n 10 python benchmarks/dask_gather.py --runs 200 2000 20000 --lazy-up-to 200
"""
from __future__ import annotations

import argparse
import json
import math
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FABRIC = {"kind": "plain", "n_warp": 2, "n_weft": 2}
SWEPT = ["fibril_radius", "contact_conductance"]
STRAINS = (0.0, 0.025, 0.05)
PROBES = ["probe1", "probe2", "probe3", "probe4"]
SIDES = ("warp-", "warp+", "weft-", "weft+")


def sweep_shape(runs: int) -> tuple[int, int]:
    """A near-square grid of ``runs`` combinations (n_radius x n_conductance = runs)."""
    a = int(math.sqrt(runs))
    while runs % a:
        a -= 1
    return a, runs // a


def synthetic_records(i: int, j: int, rng: np.random.Generator) -> list[dict]:
    """The records of one run: relaxed (mode None) and two uniaxial steps; positive probe
    resistances around 1-10 ohm that grow with strain."""
    params = {"fibril_radius": 0.1 + 0.001 * i, "contact_conductance": 0.5 + 0.01 * j}
    out = []
    for step, strain in enumerate(STRAINS):
        probes = {}
        for k, p in enumerate(PROBES):
            current = 1.0 / ((1 + k) * (1.0 + strain) * (1.0 + 0.1 * rng.random()))
            probes[p] = {"voltage": 1.0, "current": {"+": current, "-": -current},
                         "temperature_max": float(rng.random()), "temperature_mean": float(0.1 * rng.random())}
        out.append({"mode": None if step == 0 else "uniaxial", "strain": strain, "params": params,
                    "reaction_force": {s: rng.normal(size=3).tolist() for s in SIDES},
                    "contact_count": int(rng.integers(10, 100)), "equilibrium_residual": 1e-10,
                    "converged": True, "probes": probes})
    return out


def write_sweep(folder: Path, runs: int, seed: int = 0) -> list[Path]:
    """The records of a synthetic sweep as JSON files, one per state; their paths."""
    rng = np.random.default_rng(seed)
    na, nb = sweep_shape(runs)
    paths = []
    for i in range(na):
        for j in range(nb):
            run = folder / f"r{i:04d}_{j:04d}"
            run.mkdir(parents=True)
            for n, rec in enumerate(synthetic_records(i, j, rng)):
                paths.append(run / f"state{n}.json")
                paths[-1].write_text(json.dumps(rec))
    return paths


def eager_gather(record_files: list[Path], out: Path) -> None:
    """Today's rve_gather: every record in memory, one build_table, write_table."""
    from rve.tables.build import build_table
    from rve.tables.io import write_table
    from rve.tables.jobs import gather_records

    ds = build_table(gather_records(record_files, ["uniaxial"]), fabric=FABRIC, config={}, swept=SWEPT)
    write_table(ds, out)


def run_tables(record_files: list[Path], folder: Path) -> list[Path]:
    """One small table per run (what per-run jobs would write): the lazy gather's input."""
    from rve.tables.build import build_table
    from rve.tables.io import write_table
    from rve.tables.jobs import gather_records

    by_run: dict[Path, list[Path]] = {}
    for p in record_files:
        by_run.setdefault(p.parent, []).append(p)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for run, files in sorted(by_run.items()):
        ds = build_table(gather_records(sorted(files), ["uniaxial"]), fabric=FABRIC, config={}, swept=SWEPT)
        out.append(write_table(ds, folder / f"{run.name}.nc"))
    return out


def lazy_gather(table_files: list[Path], out: Path, chunk: int = 64) -> None:
    """open_mfdataset over the per-run tables (parallel open), written with dask chunks."""
    import xarray as xr

    from rve.tables.io import _encoding

    with xr.open_mfdataset(table_files, combine="by_coords", parallel=True, data_vars="minimal",
                           coords="minimal", compat="override", join="outer",
                           combine_attrs="drop_conflicts") as ds:
        ds = ds.chunk({d: min(chunk, ds.sizes[d]) for d in SWEPT})
        enc = _encoding(ds)
        for name, var in ds.data_vars.items():
            if var.dtype.kind in "fiu":
                enc[name]["chunksizes"] = tuple(min(chunk, n) if d in SWEPT else n for d, n in zip(var.dims, var.shape))
        ds.to_netcdf(out, encoding=enc)


def build_only(runs: int, one_d: bool) -> tuple[float, str]:
    """Seconds of build_table on the in-memory records of ``runs`` runs, and a digest of
    every variable's bytes and the coordinates (one sweep of N values with ``one_d``)."""
    import hashlib

    from rve.tables.build import build_table
    from rve.tables.jobs import gather_records

    rng = np.random.default_rng(0)
    na, nb = (1, runs) if one_d else sweep_shape(runs)
    recs = gather_records([r for i in range(na) for j in range(nb) for r in synthetic_records(i, j, rng)], ["uniaxial"])
    t0 = time.perf_counter()
    ds = build_table(recs, fabric=FABRIC, config={}, swept=SWEPT)
    wall = time.perf_counter() - t0
    digest = hashlib.sha256()
    for name in sorted(ds.variables):
        values = ds[name].values
        # numbers by their bytes; labels (object arrays hold pointers) by their text
        data = np.ascontiguousarray(values).tobytes() if values.dtype.kind in "biufc" else repr(values.tolist()).encode()
        digest.update(name.encode() + data)
    return wall, digest.hexdigest()[:16]


def child(kind: str, inputs: Path, out: Path) -> None:
    files = [Path(p) for p in json.loads(inputs.read_text())]
    {"eager": eager_gather, "lazy": lazy_gather, "run_tables": lambda f, o: run_tables(f, o)}[kind](files, out)
    print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def measure(kind: str, files: list[Path], out: Path, work: Path) -> tuple[float, float]:
    """Wall time (s) and peak RSS (MB) of ``kind`` in a fresh process."""
    listing = work / f"{kind}.inputs.json"
    listing.write_text(json.dumps([str(p) for p in files]))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, __file__, "--probes", str(len(PROBES)), "--child", kind, str(listing), str(out)], check=True,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    # the child's own ru_maxrss (the children's figure of this process is a maximum over all)
    return wall, json.loads(proc.stdout.strip().splitlines()[-1])["peak_rss_mb"]


def same_values(a_path: Path, b_path: Path) -> bool:
    import xarray as xr

    with xr.open_dataset(a_path) as a, xr.open_dataset(b_path) as b:
        for name in a.data_vars:
            x, y = a[name], b[name].transpose(*a[name].dims)
            if a[name].dtype.kind in "fc" and not np.array_equal(x.values, y.values, equal_nan=True):
                return False
    return True


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[200, 2000])
    parser.add_argument("--lazy-up-to", type=int, default=2000,
                        help="run the lazy path only up to this many runs (open_mfdataset costs ~0.1-1 s per file here)")
    parser.add_argument("--probes", type=int, default=1, choices=(1, 4), help="probes per state (4: with the network fits)")
    parser.add_argument("--build", action="store_true", help="time build_table alone (2-D and 1-D sweeps)")
    parser.add_argument("--child", nargs=3, metavar=("KIND", "INPUTS", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    del PROBES[args.probes:]
    if args.child:
        child(args.child[0], Path(args.child[1]), Path(args.child[2]))
        return 0
    print(f"{len(PROBES)} probe(s) per state")
    if args.build:
        print(f"{'runs':>6} {'sweep':<12} {'build_table s':>14} {'digest':>17}")
        for runs in sorted(args.runs):
            for one_d in (False, True):
                wall, digest = build_only(runs, one_d)
                shape = f"1 x {runs}" if one_d else "{} x {}".format(*sweep_shape(runs))
                print(f"{runs:6d} {shape:<12} {wall:14.2f} {digest:>17}", flush=True)
        return 0
    print(f"{'runs':>6} {'path':<24} {'wall s':>8} {'peak RSS MB':>12} {'table MB':>9}")
    for runs in sorted(args.runs):
        work = Path(tempfile.mkdtemp(prefix=f"rve-gather-{runs}-"))
        try:
            files = write_sweep(work / "records", runs)
            rows = {}
            rows["eager (today)"] = measure("eager", files, work / "eager.nc", work) + ((work / "eager.nc"),)
            if runs <= args.lazy_up_to:
                rows["per-run tables"] = measure("run_tables", files, work / "runs", work) + (None,)
                tables = sorted((work / "runs").glob("*.nc"))
                rows["lazy (open_mfdataset)"] = measure("lazy", tables, work / "lazy.nc", work) + ((work / "lazy.nc"),)
            for name, (wall, rss, out) in rows.items():
                size = f"{out.stat().st_size / 1e6:9.2f}" if out else f"{'':9s}"
                print(f"{runs:6d} {name:<24} {wall:8.1f} {rss:12.0f} {size}", flush=True)
            if runs <= args.lazy_up_to:
                print(f"{runs:6d} same values: {same_values(work / 'eager.nc', work / 'lazy.nc')}", flush=True)
            else:
                print(f"{runs:6d} lazy path not run (--lazy-up-to {args.lazy_up_to})", flush=True)
        finally:
            shutil.rmtree(work)
    return 0


if __name__ == "__main__":
    sys.exit(main())
