"""Factorisation and solve speed of the linear-solver backends on the project's own matrices
(issue 10; first part: single matrices — the lead extends it with whole-run figures).

    python benchmarks/engine_matrices.py          # once: writes results/engine/*.npz
    python benchmarks/engine_speed.py [--repeats 5] [--only NAME ...] [--variants ...]

For every saved matrix and every variant, in a fresh subprocess (so ``ru_maxrss`` is the
peak of that variant alone): median wall time of one numeric factorisation and of one
solve (``--repeats``, at least 5), the ratio against SuperLU measured in the same run,
factor nonzeros, peak RSS (MiB, and its growth over the loaded matrix), the relative
residual |A x - b| / |b| of a random b, negative pivots, and for PARDISO the perturbed
pivots and refinement steps. Variants:

* ``superlu``: today's path (``spla.splu`` with ``rve.solvers.newton._SYMMETRIC``: minimum
  degree on AᵀA + A, symmetric mode, diagonal pivots); fresh ordering every factorisation.
* ``pardiso_fresh``: PARDISO with the analysis (phase 11) redone before every phase 22.
* ``pardiso_reuse``: PARDISO, one analysis, then phase 22 only (what a Newton loop with an
  unchanged contact pattern pays); the analysis time is reported separately.
* ``pardiso_nomatch``: as ``pardiso_reuse`` without weighted matching / scaling.
* ``pardiso_dropzeros``: as ``pardiso_reuse`` with the backend's ``drop_zeros=True`` (the
  explicit zeros of inactive contact pairs dropped in every factorisation, the copy
  included in the time; only for the matrices holding explicit zeros).
* ``pardiso_nomatch_drop``: both (no matching/scaling, zeros dropped).
  The other PARDISO variants run with ``drop_zeros=False`` (the stored pattern).

The machine (2 cores) is usually shared: compare ratios within one run, not across runs.
Threads: MKL_NUM_THREADS / OPENBLAS_NUM_THREADS / OMP_NUM_THREADS are set to 1 in the
workers unless already set.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("superlu", "pardiso_fresh", "pardiso_reuse", "pardiso_nomatch", "pardiso_dropzeros",
            "pardiso_nomatch_drop")
DEFAULT_ORDER = ("min12_first", "min12_first_keep", "min12_K", "min12_pd", "driven12", "min30_first",
                 "min30_first_keep", "min30_pd", "damped30", "impact_stage_mech", "impact_stage")


def _rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _median_time(fn, repeats: int):
    ts, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), out


def worker(path: str, variant: str, repeats: int) -> dict:
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    A = sp.load_npz(path).tocsc()
    A.sum_duplicates()
    n = A.shape[0]
    b = np.random.default_rng(0).standard_normal(n)
    rss0 = _rss_mib()
    rec = {"variant": variant, "n": n, "nnz": int(A.nnz)}
    if variant == "superlu":
        from rve.solvers.newton import _SYMMETRIC

        tf, lu = _median_time(lambda: spla.splu(A, **_SYMMETRIC), repeats)
        ts, x = _median_time(lambda: lu.solve(b), max(repeats, 5))
        rec.update(factor_s=tf, solve_s=ts, factor_nnz=int(lu.L.nnz + lu.U.nnz),
                   negative_pivots=int(np.count_nonzero(lu.U.diagonal() < 0)))
    else:
        from rve.solvers import pardiso

        if not pardiso.available():
            return {"variant": variant, "skipped": pardiso.unavailable_reason()}
        M = A
        drop = variant in ("pardiso_dropzeros", "pardiso_nomatch_drop")
        if drop:
            rec["nnz"] = int(np.count_nonzero(A.data))
        # the backend drops the zeros itself (its factorisation time includes that copy)
        f = pardiso.PardisoFactorization(matching="nomatch" not in variant, drop_zeros=drop)
        t0 = time.perf_counter()
        f.analyse(M)
        rec["analyse_s"] = time.perf_counter() - t0
        if variant == "pardiso_fresh":
            def run():
                f.analyse(M)
                return f.factorize(M)
        else:
            f.factorize(M)  # warm-up (first phase 22 after an analysis)
            run = lambda: f.factorize(M)  # noqa: E731
        tf, _ = _median_time(run, repeats)
        ts, x = _median_time(lambda: f.solve(b), max(repeats, 5))
        rec.update(factor_s=tf, solve_s=ts, factor_nnz=f.factor_nnz, negative_pivots=f.negative_pivots,
                   perturbed=f.perturbed_pivots, refinement=f.refinement_steps, analyses=f.analyses,
                   pardiso_mem_mib=f.memory_kb["factorization"] / 1024.0)
        f.release()
    rec["residual"] = float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))
    rec["rss_mib"] = _rss_mib()
    rec["rss_growth_mib"] = rec["rss_mib"] - rss0
    return rec


def run_variant(path: Path, variant: str, repeats: int) -> dict:
    env = dict(os.environ)
    for k in ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
        env.setdefault(k, "1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, "--worker", str(path), variant, str(repeats)]
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        return {"variant": variant, "error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    return json.loads(p.stdout.strip().splitlines()[-1])


def table(results: dict) -> str:
    head = (f"{'matrix':<18} {'n':>6} {'nnz':>8} {'variant':<18} {'analyse':>8} {'factor':>8} {'ratio':>6} "
            f"{'solve':>8} {'ratio':>6} {'L nnz':>9} {'RSS':>6} {'+RSS':>6} {'resid':>8} {'neg':>5} {'pert':>4}")
    lines = [head, "-" * len(head)]
    for name, recs in results.items():
        ref = next((r for r in recs if r.get("variant") == "superlu" and "factor_s" in r), None)
        for r in recs:
            if "factor_s" not in r:
                lines.append(f"{name:<18} {'':>6} {'':>8} {r['variant']:<18} {r.get('skipped') or r.get('error')}")
                continue
            rf = ref["factor_s"] / r["factor_s"] if ref else float("nan")
            rs = ref["solve_s"] / r["solve_s"] if ref else float("nan")
            an = f"{r['analyse_s']:.3f}" if "analyse_s" in r else "-"
            lines.append(
                f"{name:<18} {r['n']:>6} {r['nnz']:>8} {r['variant']:<18} {an:>8} {r['factor_s']:>8.3f} {rf:>5.1f}x "
                f"{r['solve_s'] * 1e3:>6.1f}ms {rs:>5.1f}x {r['factor_nnz']:>9} {r['rss_mib']:>6.0f} "
                f"{r['rss_growth_mib']:>6.0f} {r['residual']:>8.1e} {r['negative_pivots']:>5} "
                f"{r.get('perturbed', '-'):>4}")
    lines.append("analyse/factor in s (median); ratio = SuperLU time / this time (same run); L nnz: "
                 "SuperLU L+U, PARDISO L; RSS: peak MiB of the worker, +RSS over the loaded matrix; "
                 "neg: negative pivots; pert: perturbed pivots")
    return "\n".join(lines)


def main(argv=None) -> None:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(worker(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", default=str(ROOT / "results/engine"))
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default=None, help="also write the records here")
    a = ap.parse_args(argv)
    d = Path(a.dir)
    names = a.only or [n for n in DEFAULT_ORDER if (d / f"{n}.npz").exists()]
    results = {}
    for name in names:
        meta = json.loads((d / f"{name}.json").read_text()) if (d / f"{name}.json").exists() else {}
        recs = []
        for v in a.variants:
            if v in ("pardiso_dropzeros", "pardiso_nomatch_drop") and not meta.get("explicit_zeros"):
                continue
            r = run_variant(d / f"{name}.npz", v, max(a.repeats, 5))
            recs.append(r)
            print(f"  {name} {v}: {r.get('factor_s', r.get('error', r.get('skipped')))}", file=sys.stderr, flush=True)
        results[name] = recs
    print(table(results))
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
