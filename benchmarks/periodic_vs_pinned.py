"""The pinned (thesis) table and the periodic table side by side (docs/periodic.md "Measured").

Reads two tables of the same weave (default: the pinned default ``results/rve/plain_weave``
and the periodic ``results/rve/plain_weave_periodic``) and the Snakemake benchmark files of
their jobs, and prints:

* the cost of each run: jobs, the sum of the jobs' CPU seconds and wall seconds, the
  largest job's peak RSS (``results/benchmarks/rve/<run>/**.tsv``);
* the membrane forces per unit reference width (N/mm) of both cells at chosen strains:
  N_xx and N_yy in uniaxial x, N_yy in uniaxial y (periodic only), the shear resultant
  N_yx in shear; the pinned cell's face forces are clamp forces, the periodic cell's the
  Hill-Mandel stress (the pretension of the relaxed cell included in both);
* the electrical figures per square: the periodic cell's sheet resistances (field along x
  and y) and the pinned table's bus-bar sheet resistance of each yarn layer (1 / (1/R_y +
  1/R_c), docs/macro_export.md), with the pinned probe resistances and R_y, R_c;
* the largest Joule temperature rise of each probe at 1 V;
* the contacts across the faces of the periodic relaxed state: the active pairs with a
  periodic image and their part of the Hill-Mandel stress.

    python benchmarks/periodic_vs_pinned.py [--pinned results/rve/plain_weave]
        [--periodic results/rve/plain_weave_periodic] [--strains 0 0.1 0.25]
"""
from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np


def run_cost(bench_dir: Path) -> dict:
    """Jobs, sum of CPU and wall seconds, largest peak RSS (MB) of a run's benchmark files."""
    cpu = wall = rss = 0.0
    n = 0
    for path in sorted(bench_dir.glob("**/*.tsv")):
        with open(path) as f:
            rows = list(csv.DictReader(f, delimiter="\t"))
        if not rows:
            continue
        r = rows[-1]
        n += 1
        wall += float(r["s"])
        cpu += float(r.get("cpu_time") or 0.0)
        rss = max(rss, float(r["max_rss"]) if r["max_rss"] not in ("", "NA", "-") else 0.0)
    return {"jobs": n, "cpu_s": cpu, "wall_s": wall, "max_rss_mb": rss}


def _at(da, **sel):
    """The value of ``da`` at the labels ``sel`` (strain: nearest), NaN where absent."""
    try:
        for k, v in sel.items():
            if k == "strain":
                da = da.sel(strain=v, method="nearest")
            elif k in da.dims:
                da = da.sel({k: v})
            else:
                return float("nan")
        return float(da)
    except KeyError:
        return float("nan")


def membrane_rows(ds, strains):
    """(label, [values at strains]) of the membrane forces."""
    m = ds["membrane_force"]
    picks = [("N_xx uniaxial x", "uniaxial", "x", "x"), ("N_yy uniaxial x", "uniaxial", "y", "y"),
             ("N_yy uniaxial y", "uniaxial_y", "y", "y"), ("N_yx shear", "shear", "x", "y")]
    out = []
    for label, mode, edge, comp in picks:
        if mode not in [str(v) for v in ds["mode"].values]:
            out.append((label, [float("nan")] * len(strains)))
            continue
        out.append((label, [_at(m, mode=mode, strain=s, edge=edge, component=comp) for s in strains]))
    return out


def electrical_rows(ds, strains, modes):
    out = []
    probes = [str(p) for p in ds["probe"].values]
    for mode in modes:
        if mode not in [str(v) for v in ds["mode"].values]:
            continue
        for p in probes:
            out.append((f"R {p} ({mode})", [_at(ds["probe_resistance"], mode=mode, strain=s, probe=p) for s in strains]))
        if "busbar_sheet_resistance" in ds and np.isfinite(ds["busbar_sheet_resistance"]).any():
            for y in [str(v) for v in ds["yarn"].values]:
                out.append((f"bus-bar sheet R {y} ({mode})",
                            [_at(ds["busbar_sheet_resistance"], mode=mode, strain=s, yarn=y) for s in strains]))
        for name, var in (("R_y", "yarn_resistance"), ("R_c", "contact_resistance")):
            if var in ds and np.isfinite(ds[var]).any():
                out.append((f"{name} ({mode})", [_at(ds[var], mode=mode, strain=s) for s in strains]))
        for p in probes:
            out.append((f"T max {p} ({mode})",
                        [_at(ds["temperature_rise_max"], mode=mode, strain=s, probe=p) for s in strains]))
    return out


def _print_rows(title, rows, strains):
    print(f"{title:<34}" + "".join(f"{'eps=' + format(s, 'g'):>13}" for s in strains))
    for label, vals in rows:
        print(f"  {label:<32}" + "".join(f"{v:13.5g}" for v in vals))


def image_contact_share(run_dir: Path, spec: dict, state: str = "relaxed") -> None:
    """The contacts across the cell faces of a stored periodic state: active pairs with a
    periodic image and their part of the Hill-Mandel stress."""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.periodic import cell_gradient, periodic_system
    from rve.homogenisation.sweeps import load_run_config

    cfg = load_run_config(spec, "base")
    fab, mesh = fabric_and_mesh(cfg)
    st = load_state(run_dir / "base" / "states" / f"{state}.nc")
    psys = periodic_system(cfg, fab, mesh, st.x, cell_gradient(fab, mesh, st.x))
    xr = psys.restrict(st.x.reshape(-1))
    act = psys.active_pairs(xr)
    n_img = int((np.abs(psys.map.shifts[act]).sum(axis=1) > 0).sum())
    P = psys.macro_stress(xr)[:2, :2]
    M = psys.image_contact_moment(xr)[:2, :2] / psys.ties.area
    print(f"\ncontacts across the faces ({state}): {n_img} of {act.size} active pairs with a periodic image;")
    print(f"  Hill-Mandel P [N/mm] = {np.round(P, 6).tolist()}, of it the image contacts' {np.round(M, 6).tolist()}")


def main(argv=None):
    from rve.tables import open_table

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pinned", default="results/rve/plain_weave", help="the pinned run's directory")
    ap.add_argument("--periodic", default="results/rve/plain_weave_periodic", help="the periodic run's directory")
    ap.add_argument("--benchmarks", default="results/benchmarks/rve", help="Snakemake benchmark files per run")
    ap.add_argument("--strains", nargs="*", type=float, default=[0.0, 0.1, 0.25])
    ap.add_argument("--periodic-config", default="configs/rve/plain_weave_periodic_p1.yaml",
                    help="the periodic run's scene config (for the contacts across the faces)")
    ap.add_argument("--names", nargs=2, default=["pinned", "periodic"],
                    help="labels of the two runs (e.g. 1x1 2x2 for two periodic cells)")
    args = ap.parse_args(argv)
    runs = dict(zip(args.names, (Path(args.pinned), Path(args.periodic))))
    tables = {k: open_table(p / "table.nc") for k, p in runs.items() if (p / "table.nc").exists()}
    print("cost (Snakemake benchmark files):")
    print(f"  {'run':<10}{'jobs':>6}{'CPU s':>10}{'job wall s':>12}{'max RSS MB':>12}")
    for k, p in runs.items():
        c = run_cost(Path(args.benchmarks) / p.name)
        print(f"  {k:<10}{c['jobs']:6d}{c['cpu_s']:10.1f}{c['wall_s']:12.1f}{c['max_rss_mb']:12.0f}")
    for k, ds in tables.items():
        fab = ds.attrs.get("boundary", "pinned")
        print(f"\n{k} ({fab}): {runs[k] / 'table.nc'}, dims {dict(ds.sizes)}")
        _print_rows("membrane force [N/mm]", membrane_rows(ds, args.strains), args.strains)
        _print_rows("electrical [ohm, K]", electrical_rows(ds, args.strains, ["uniaxial", "shear"]), args.strains)
        mz = float(np.abs(ds["membrane_force"].sel(component="z")).max())
        print(f"  out of plane: max |membrane force z| {mz:.2e} N/mm over every mode and strain")
        res = ds["equilibrium_residual"]
        print(f"  equilibrium residual: max {float(res.max()):.2e} N; converged: "
              f"{int(ds['converged'].sum())} of {ds['converged'].size}")
    second = runs[args.names[1]]
    if tables.get(args.names[1]) is not None and tables[args.names[1]].attrs.get("boundary") == "periodic" \
            and Path(args.periodic_config).exists() and (second / "base" / "states" / "relaxed.nc").exists():
        image_contact_share(second, {"scene_config": args.periodic_config, "overrides": []})


if __name__ == "__main__":
    main()
