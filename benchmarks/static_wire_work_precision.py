"""Work-precision benchmark of the static wire (thesis §6.3) at R = 0.02 mm.

For each solver path (``solver.path = dynamic_relaxation`` and ``continuation``, whichever
the scene accepts), each order p and number of elements N it solves the wire ``--repeats``
times and prints: dofs, the median wall time of ``solve``, the Newton iterations (static
phase, path to it, total), and the error of the centre displacement against the finest
solution (p = 4, N = 36 by default, solved once with the first path that works). It writes
the work-precision plot (error vs wall time, one line per p and path) and a CSV next to it,
prints the cheapest configuration reaching error <= --tol (target: < 0.5 s) and the peak
memory (ru_maxrss). Speed targets are reported, never asserted (docs/verification_static_wire.md).

    python benchmarks/static_wire_work_precision.py            # full grid, ~5-10 min
    python benchmarks/static_wire_work_precision.py --quick    # a few points, 1 run each
"""
from __future__ import annotations

import argparse
import math
import resource
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rve.config.loader import ConfigError, load_config  # noqa: E402
from rve.io.atomic import atomic_path, atomic_write_text  # noqa: E402
from rve.scenes.static_wire import solve  # noqa: E402
from rve.studies.static_wire import point_overrides, total_newton_iterations  # noqa: E402

SCENE = ROOT / "configs" / "scenes" / "static_wire.yaml"
PATHS = ("dynamic_relaxation", "continuation")
GRID = {
    1: [10, 20, 40, 80],
    2: [5, 8, 10, 16, 20, 40],
    3: [3, 4, 5, 6, 7, 8, 12, 16],
    4: [3, 4, 5, 6, 8, 12],
}
QUICK_GRID = {2: [10, 20], 3: [5, 7], 4: [5]}


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=str(SCENE), help="scene config (default: %(default)s)")
    ap.add_argument("--radius", type=float, default=0.02, help="fibril radius in mm (default: %(default)s)")
    ap.add_argument("--repeats", type=int, default=3, help="solves per point; the median is reported")
    ap.add_argument("--paths", nargs="+", default=list(PATHS), help="solver paths to compare")
    ap.add_argument("--reference", default="4,36", help="finest solution p,N (default: %(default)s)")
    ap.add_argument("--tol", type=float, default=1e-4, help="error target (default: %(default)s)")
    ap.add_argument("--target-time", type=float, default=0.5, help="wall-time target in s for --tol")
    ap.add_argument("--quick", action="store_true", help="a few points, one run each")
    ap.add_argument("--out", default=str(ROOT / "results" / "benchmarks" / "static_wire_work_precision.png"),
                    help="plot path; the table goes to the same stem with .csv")
    return ap.parse_args(argv)


def config(scene, path, p, n, radius):
    return load_config(scene, overrides=point_overrides(p, n, radius, [f"solver.path={path}"]))


def run_point(scene, path, p, n, radius, repeats):
    """(median wall time, minimum wall time, last result) of ``repeats`` solves; raises
    on failure."""
    cfg = config(scene, path, p, n, radius)
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = solve(cfg).summary
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times), result


def main(argv=None) -> int:
    args = parse_args(argv)
    grid = QUICK_GRID if args.quick else GRID
    repeats = 1 if args.quick else args.repeats
    ref_p, ref_n = (int(v) for v in args.reference.split(","))

    paths = []
    for path in args.paths:
        try:
            config(args.scene, path, 2, 4, args.radius)
        except ConfigError as exc:
            print(f"solver.path={path}: not available ({exc})")
            continue
        paths.append(path)
    if not paths:
        print("no solver path available")
        return 1

    reference = None
    for path in paths:
        try:
            t0 = time.perf_counter()
            res = solve(config(args.scene, path, ref_p, ref_n, args.radius))
            reference = res["centre_displacement"]
            print(f"reference p={ref_p} N={ref_n} R={args.radius} mm ({path}): "
                  f"centre displacement {reference:.12f} L in {time.perf_counter() - t0:.2f} s")
            break
        except Exception as exc:  # noqa: BLE001 - try the next path
            print(f"reference with {path} failed: {exc}")
    if reference is None:
        return 1

    rows = []
    header = (f"{'path':<19} {'p':>2} {'N':>4} {'dofs':>6} {'wall[s]':>8} {'newton':>6} {'path_it':>7} "
              f"{'total':>6} {'error':>10}  status")
    print(f"\nmedian of {repeats} run(s) of solve; error = |c - c_ref| / L\n{header}\n{'-' * len(header)}")
    for path in paths:
        for p, Ns in grid.items():
            for n in Ns:
                row = {"path": path, "order": p, "elements": n}
                try:
                    wall, wall_min, res = run_point(args.scene, path, p, n, args.radius, repeats)
                except Exception as exc:  # noqa: BLE001 - reported in the table
                    row.update(status=f"failed: {type(exc).__name__}: {str(exc)[:80]}", dofs=math.nan,
                               wall_s=math.nan, wall_min_s=math.nan, newton=math.nan, path_newton=math.nan, total_newton=math.nan,
                               error=math.nan)
                else:
                    row.update(status="ok", dofs=res["dofs"], wall_s=wall, wall_min_s=wall_min, newton=res["newton_iterations"],
                               path_newton=res.get("relaxation_newton_iterations", 0),
                               total_newton=total_newton_iterations(res),
                               error=abs(res["centre_displacement"] - reference))
                rows.append(row)
                print(f"{path:<19} {p:>2} {n:>4} {row['dofs']:>6} {row['wall_s']:>8.3f} {row['newton']:>6} "
                      f"{row['path_newton']:>7} {row['total_newton']:>6} {row['error']:>10.3e}  {row['status']}",
                      flush=True)

    # cheapest configuration reaching the tolerance
    ok = [r for r in rows if r["status"] == "ok" and r["error"] <= args.tol]
    print()
    for path in paths:
        best = min((r for r in ok if r["path"] == path), key=lambda r: r["wall_s"], default=None)
        if best is None:
            print(f"{path}: no configuration reaches error <= {args.tol:g}")
        else:
            print(f"{path}: cheapest with error <= {args.tol:g}: p={best['order']} N={best['elements']} "
                  f"({best['dofs']} dofs) error {best['error']:.2e} in {best['wall_s']:.3f} s")
    best = min(ok, key=lambda r: r["wall_s"], default=None)
    if best is not None:
        met = "met" if best["wall_s"] < args.target_time else "NOT met"
        print(f"cheapest overall: {best['path']} p={best['order']} N={best['elements']}: "
              f"{best['wall_s']:.3f} s for error {best['error']:.2e} "
              f"(target < {args.target_time:g} s: {met})")

    # table and plot
    out = Path(args.out)
    cols = ["path", "order", "elements", "dofs", "wall_s", "wall_min_s", "newton", "path_newton", "total_newton", "error", "status"]
    lines = [",".join(cols)] + [",".join(str(r[c]).replace(",", ";") for c in cols) for r in rows]
    atomic_write_text(out.with_suffix(".csv"), "\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    styles = {path: ls for path, ls in zip(paths, ["-", "--", ":", "-."])}
    markers = {path: m for path, m in zip(paths, ["o", "s", "^", "v"])}
    for i, p in enumerate(grid):
        for path in paths:
            # in order of N: the refinement path of each p
            pts = [(r["wall_s"], r["error"]) for r in sorted(rows, key=lambda r: r["elements"])
                   if r["path"] == path and r["order"] == p and r["status"] == "ok" and r["error"] > 0]
            if pts:
                ax.loglog(*zip(*pts), styles[path], marker=markers[path], color=f"C{i}", label=f"p={p}, {path}")
    ax.axhline(args.tol, color="k", lw=0.8, ls=":", label=f"error {args.tol:g}")
    ax.axvline(args.target_time, color="grey", lw=0.8, ls=":", label=f"{args.target_time:g} s")
    ax.set_xlabel(f"wall time of solve [s] (median of {repeats})")
    ax.set_ylabel(f"|c - c_ref| / L  (ref p={ref_p}, N={ref_n})")
    ax.set_title(f"Static wire work-precision, R = {args.radius:g} mm")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=150, bbox_inches="tight")
    plt.close(fig)
    print(f"wrote {out} and {out.with_suffix('.csv')}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    scale = 1.0 / 1024 if sys.platform != "darwin" else 1.0 / 1024**2  # KiB on Linux, bytes on macOS
    print(f"peak memory (ru_maxrss): {peak * scale:.0f} MiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
