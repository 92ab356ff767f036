"""The gather of a large sweep: the eager path (rve_gather) against two lazy ones, on
synthetic sweeps of 200, 2,000 and 20,000 runs (docs/cluster.md "dask").

A synthetic run is one combination of a two-parameter sweep (fibril_radius x
contact_conductance) with the records the pipeline writes for it: the relaxed state and
two uniaxial steps (JSON files, as rve_probes writes them), one probe by default. With one
probe the table has no network fit (R_y, R_c need two probes or more), so the figures are
those of gathering itself: reading, filling, combining, writing. ``--probes 4`` adds the
fits. Three gathers:

* eager (rve_gather): read every record, ``build_table`` over all of them, write the table
  (``write_table``: zlib, chunked by netCDF-4);
* lazy, open_mfdataset: one small netCDF-4 file per run (its values, each variable
  zlib-compressed in one chunk; written by :func:`write_run_file`, a minimal netCDF4
  writer, timed apart as "per-run files": the work per-run jobs would do), then
  ``xr.open_mfdataset(..., parallel=True)`` as a nested 2-D combine and ``to_netcdf`` with
  dask chunks and zlib, computed chunk by chunk; run up to ``--lazy-up-to`` runs, beyond
  that its time is extrapolated from the sizes measured (a power law) and printed;
* lazy, streamed slabs: the same per-run files read one by one into slabs of 64 rows of
  the sweep, each written into the chunked, compressed table: memory bounded by a slab.

Each gather runs in a fresh child process; its wall time and peak RSS (ru_maxrss of the
child) are printed, and both lazy tables are checked to hold every per-run variable of the
eager table with the same bits.

    nice -n 10 python benchmarks/dask_gather.py --runs 100 200 2000 20000 --lazy-up-to 200
    nice -n 10 python benchmarks/dask_gather.py --build --runs 2000 20000   # build_table alone

``--build`` times ``build_table`` alone on the records in memory (no files) for the
near-square two-parameter grid and for a one-parameter sweep of the same size (1 x N), and
prints a digest of the table's bits, to compare two commits.
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
    """rve_gather: every record in memory, one build_table, write_table."""
    from rve.tables.build import build_table
    from rve.tables.io import write_table
    from rve.tables.jobs import gather_records

    ds = build_table(gather_records(record_files, ["uniaxial"]), fabric=FABRIC, config={}, swept=SWEPT)
    write_table(ds, out)


def run_files(record_files: list[Path], folder: Path) -> list[Path]:
    """One small chunked, compressed netCDF file per run (what a per-run job would write):
    the lazy gather's input. The run's values are its slice of one ``build_table`` over
    all records (so both gathers hold the same numbers), written by :func:`write_run_file`
    with netCDF4 directly: no per-run table build, no CF encoding pass."""
    from rve.tables.build import build_table
    from rve.tables.jobs import gather_records

    ds = build_table(gather_records(record_files, ["uniaxial"]), fabric=FABRIC, config={}, swept=SWEPT)
    per_run = [n for n, v in ds.data_vars.items() if set(SWEPT) <= set(v.dims)]
    labels = [d for d in ds.dims if d not in SWEPT and d != "strain"]
    arrays = {n: ds[n].transpose(*SWEPT, ...).values for n in per_run}
    dims = {n: ds[n].transpose(*SWEPT, ...).dims[2:] for n in per_run}
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for i, a in enumerate(ds[SWEPT[0]].values):
        for j, b in enumerate(ds[SWEPT[1]].values):
            out.append(write_run_file(folder / f"r{i:04d}_{j:04d}.nc", {SWEPT[0]: a, SWEPT[1]: b},
                                      {c: ds[c].values for c in ["strain", *labels]},
                                      {n: (dims[n], arrays[n][i, j]) for n in per_run}))
    return out


def write_run_file(path: Path, params: dict, coords: dict, variables: dict) -> Path:
    """A run's values as netCDF-4: the swept parameters as length-1 dimensions, every
    variable zlib-compressed in one chunk, the labels as variable-length strings."""
    import netCDF4

    with netCDF4.Dataset(path, "w") as nc:
        for name, value in params.items():
            nc.createDimension(name, 1)
            nc.createVariable(name, "f8", (name,))[:] = [value]
        for name, values in coords.items():
            nc.createDimension(name, len(values))
            if values.dtype.kind == "f":
                nc.createVariable(name, "f8", (name,))[:] = values
            else:
                var = nc.createVariable(name, str, (name,))
                var[:] = np.asarray([str(v) for v in values], dtype=object)
        for name, (dims, values) in variables.items():
            full = (*params, *dims)
            var = nc.createVariable(name, "f8", full, zlib=True, complevel=4, shuffle=True,
                                    chunksizes=(1,) * len(params) + values.shape, fill_value=np.nan)
            var[:] = values[np.newaxis, np.newaxis]
    return path


def lazy_gather(run_paths: list[Path], out: Path, chunk: int = 64) -> None:
    """open_mfdataset over the per-run files (a nested 2-D combine, parallel open),
    written with dask chunks of ``chunk`` x ``chunk`` runs and zlib, computed chunk by chunk."""
    import xarray as xr

    with xr.open_mfdataset(run_grid(run_paths), combine="nested", concat_dim=SWEPT, parallel=True, data_vars="minimal",
                           coords="minimal", compat="override", join="override", combine_attrs="override") as ds:
        ds = ds.chunk({d: min(chunk, ds.sizes[d]) for d in SWEPT})
        enc = {}
        for name, var in ds.data_vars.items():
            enc[name] = {"zlib": True, "complevel": 4, "shuffle": True,
                         "chunksizes": tuple(min(chunk, n) if d in SWEPT else n for d, n in zip(var.dims, var.shape))}
        ds.to_netcdf(out, encoding=enc)


def run_grid(run_paths: list[Path]) -> list[list[Path]]:
    """The per-run files as the 2-D grid of the sweep (file rIIII_JJJJ at row I, column J)."""
    grid: dict[str, dict[str, Path]] = {}
    for p in sorted(run_paths):
        i, j = p.stem[1:].split("_")
        grid.setdefault(i, {})[j] = p
    return [[row[j] for j in sorted(row)] for _, row in sorted(grid.items())]


def streamed_gather(run_paths: list[Path], out: Path, chunk: int = 64) -> None:
    """The bounded-memory equivalent of open_mfdataset: the per-run files read one by one
    (netCDF4) into a slab of ``chunk`` rows of the sweep, each full slab written into the
    chunked, zlib-compressed table; memory is one slab (chunk x columns runs), not the sweep."""
    import netCDF4

    grid = run_grid(run_paths)
    na, nb = len(grid), len(grid[0])
    with netCDF4.Dataset(grid[0][0]) as first:
        names = [n for n, v in first.variables.items() if v.dimensions[:2] == tuple(SWEPT)]
        tail = {n: (first[n].dimensions[2:], first[n].shape[2:]) for n in names}
        coords = {n: first[n][:] for n in first.variables if n not in names and n not in SWEPT}
        labels = {n: first[n].dtype for n in coords}
    with netCDF4.Dataset(out, "w") as nc:
        for d, n in zip(SWEPT, (na, nb)):
            nc.createDimension(d, n)
            nc.createVariable(d, "f8", (d,))
        for name, values in coords.items():
            nc.createDimension(name, len(values))
            nc.createVariable(name, labels[name] if labels[name] is str else "f8", (name,))[:] = values
        for name, (dims, shape) in tail.items():
            nc.createVariable(name, "f8", (*SWEPT, *dims), zlib=True, complevel=4, shuffle=True,
                              chunksizes=(min(chunk, na), min(chunk, nb), *shape), fill_value=np.nan)
        for r0 in range(0, na, chunk):
            rows = grid[r0:r0 + chunk]
            slab = {n: np.empty((len(rows), nb, *tail[n][1])) for n in names}
            a_vals, b_vals = np.empty(len(rows)), np.empty(nb)
            for i, row in enumerate(rows):
                for j, path in enumerate(row):
                    with netCDF4.Dataset(path) as run:
                        a_vals[i], b_vals[j] = run[SWEPT[0]][0], run[SWEPT[1]][0]
                        for n in names:
                            slab[n][i, j] = run[n][0, 0]
            nc[SWEPT[0]][r0:r0 + len(rows)] = a_vals
            nc[SWEPT[1]][:] = b_vals
            for n in names:
                nc[n][r0:r0 + len(rows)] = slab[n]


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
    {"eager": eager_gather, "lazy": lazy_gather, "streamed": streamed_gather, "run_files": lambda f, o: run_files(f, o)}[kind](files, out)
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


def same_values(eager_path: Path, lazy_path: Path) -> bool:
    """The lazy table holds every per-run variable of the eager one, with the same bits."""
    import xarray as xr

    from rve.tables import open_table

    a = open_table(eager_path)
    with xr.open_dataset(lazy_path) as b:
        per_run = {n for n, v in a.data_vars.items() if set(SWEPT) <= set(v.dims)}
        if per_run != set(b.data_vars):
            return False
        for name in per_run:
            x, y = a[name], b[name].transpose(*a[name].dims)
            if not all(np.array_equal(a[c].values, y[c].values) for c in SWEPT):
                return False
            if np.ascontiguousarray(x.values).tobytes() != np.ascontiguousarray(y.values).tobytes():
                return False
    return True


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, nargs="+", default=[200, 2000])
    parser.add_argument("--lazy-up-to", type=int, default=200,
                        help="run open_mfdataset only up to this many runs (it costs ~0.2-0.5 s per file here, "
                             "growing faster than the runs); larger sizes print its extrapolated time")
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
    print(f"{'runs':>6} {'path':<28} {'wall s':>8} {'peak RSS MB':>12} {'table MB':>9}")
    measured: list[tuple[int, float, float]] = []  # open_mfdataset: (runs, wall, rss)
    for runs in sorted(args.runs):
        work = Path(tempfile.mkdtemp(prefix=f"rve-gather-{runs}-"))
        try:
            files = write_sweep(work / "records", runs)
            rows = {"eager (rve_gather)": measure("eager", files, work / "eager.nc", work) + (work / "eager.nc",),
                    "per-run files (input)": measure("run_files", files, work / "runs", work) + (None,)}
            run_paths = sorted((work / "runs").glob("*.nc"))
            rows["lazy, streamed slabs"] = measure("streamed", run_paths, work / "streamed.nc", work) + \
                (work / "streamed.nc",)
            crashed = None
            if runs <= args.lazy_up_to:
                try:
                    rows["lazy, open_mfdataset"] = measure("lazy", run_paths, work / "lazy.nc", work) + \
                        (work / "lazy.nc",)
                    measured.append((runs, *rows["lazy, open_mfdataset"][:2]))
                except subprocess.CalledProcessError as exc:
                    # the parallel open reads HDF5 from dask's threads; it can die in HDF5
                    crashed = f"exit {exc.returncode}" + (" (SIGSEGV)" if exc.returncode == -11 else "")
            for name, (wall, rss, out) in rows.items():
                size = f"{out.stat().st_size / 1e6:9.2f}" if out else f"{'':9s}"
                print(f"{runs:6d} {name:<28} {wall:8.1f} {rss:12.0f} {size}", flush=True)
            if crashed:
                print(f"{runs:6d} {'lazy, open_mfdataset':<28} crashed: {crashed}", flush=True)
            lazy = [k for k in ("streamed", "lazy") if (work / f"{k}.nc").exists()]
            print(f"{runs:6d} same bits as eager: " + ", ".join(
                f"{k} {same_values(work / 'eager.nc', work / f'{k}.nc')}" for k in lazy), flush=True)
            if runs > args.lazy_up_to:
                print(f"{runs:6d} open_mfdataset not run (--lazy-up-to {args.lazy_up_to}): "
                      f"{extrapolation(measured, runs)}", flush=True)
        finally:
            shutil.rmtree(work)
    return 0


def extrapolation(measured: list[tuple[int, float, float]], runs: int) -> str:
    """The open_mfdataset wall time at ``runs``, from a power law through the sizes measured."""
    if not measured:
        return "no smaller size measured to extrapolate from"
    if len(measured) == 1:
        (n0, t0, _), k = measured[0], 1.0
        how = "linearly from one size"
    else:
        (n0, t0, _), (n1, t1, _) = measured[-2], measured[-1]
        k = math.log(t1 / t0) / math.log(n1 / n0)
        how = f"t ~ runs^{k:.2f} fitted through {n0} and {n1} runs"
        n0, t0 = n1, t1
    est = t0 * (runs / n0) ** k
    return f"~{est:,.0f} s ({est / 3600:.1f} h) extrapolated, {how}"


if __name__ == "__main__":
    sys.exit(main())
