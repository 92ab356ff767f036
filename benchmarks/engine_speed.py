"""Speed of the linear-solver backends on the project's own saved matrices: single
factorisations per variant in fresh processes, and PARDISO's threads / CNR check
(docs/engine.md "Supernodal backend (measured)", "Two threads"). The other questions have
their own scripts: ``engine_whole.py`` (whole relaxation and strain-step runs per
backend), ``engine_wire.py`` (the dynamic-wire study), ``engine_unsym.py`` (the dynamic
scenes' unsymmetric stage matrices), ``engine_scene_ab.py`` (whole-scene A/B of the
stage-matrix backend); ``_harness.py`` is their shared process machinery.

    python benchmarks/engine_matrices.py          # once: writes results/engine/*.npz
    python benchmarks/engine_speed.py [--repeats 5] [--only NAME ...] [--variants ...]
    python benchmarks/engine_speed.py --threads-check [--only min30_first_keep ...]
        # PARDISO on 1 and 2 threads, CNR off / on (iparm(34) = 2): factorisation medians and
        # max |x - x_ref| of repeated solves (bitwise reproducibility)

For every saved matrix and every variant, in a fresh subprocess (so ``ru_maxrss`` is the
peak of that variant alone): median wall time of one numeric factorisation and of one
solve (``--repeats``, at least 5), the ratio against SuperLU measured in the same run,
factor nonzeros, peak RSS (MiB, and its growth over the loaded matrix), the relative
residual |A x - b| / |b| of a random b, negative pivots, and for PARDISO the perturbed
pivots and refinement steps. Variants:

* ``superlu``: SuperLU's symmetric mode (``spla.splu`` with ``rve.solvers.linear.SUPERLU_SYMMETRIC``: minimum
  degree on AᵀA + A, symmetric mode, diagonal pivots); fresh ordering every factorisation.
* ``pardiso_fresh``: PARDISO with the analysis (phase 11) redone before every phase 22.
* ``pardiso_reuse``: PARDISO, one analysis, then phase 22 only (what a Newton loop with an
  unchanged contact pattern pays); the analysis time is reported separately.
* ``pardiso_nomatch``: as ``pardiso_reuse`` without weighted matching / scaling.
* ``pardiso_dropzeros``: as ``pardiso_reuse`` with the backend's ``drop_zeros=True`` (the
  explicit zeros of inactive contact pairs dropped in every factorisation, the copy
  included in the time; only for the matrices holding explicit zeros).
* ``pardiso_nomatch_drop``: both (no matching/scaling, zeros dropped).
* ``pardiso_drop_cnr`` / ``pardiso_drop_t2``: as ``pardiso_dropzeros`` in MKL's conditional
  numerical reproducibility mode for up to two threads (iparm(34) = 2), on one / two
  threads (the two give bitwise the same factor; docs/engine.md "Two threads").
* ``pardiso_chol_t2``: the energy minimiser's definiteness test, PARDISO's Cholesky (mtype 2,
  ``PardisoFactorization(positive_definite=True)``) as ``pardiso_drop_t2`` otherwise; on an
  indefinite matrix the time until it stops at the first pivot <= 0 (``neg`` is then
  printed as ``>0``, the residual as nan), on a definite one a whole factorisation and its
  solve (docs/engine.md "Cholesky as the definiteness test").
  The other PARDISO variants run with ``drop_zeros=False`` (the stored pattern).

The machine (2 cores) is usually shared: compare ratios within one run, not across runs.
Threads: MKL_NUM_THREADS / OPENBLAS_NUM_THREADS / OMP_NUM_THREADS are set to 1 in the
workers unless already set.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, median_time as _median_time, rss_mib as _rss_mib, run_json, worker_env  # noqa: E402

VARIANTS = ("superlu", "pardiso_fresh", "pardiso_reuse", "pardiso_nomatch", "pardiso_dropzeros",
            "pardiso_nomatch_drop", "pardiso_drop_cnr", "pardiso_drop_t2", "pardiso_chol_t2")
DEFAULT_ORDER = ("min12_first", "min12_first_keep", "min12_K", "min12_pd", "driven12", "min30_first",
                 "min30_first_keep", "min30_pd", "damped30", "impact_stage_mech", "impact_stage")


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
        from rve.solvers.linear import SUPERLU_SYMMETRIC as _SYMMETRIC

        tf, lu = _median_time(lambda: spla.splu(A, **_SYMMETRIC), repeats)
        ts, x = _median_time(lambda: lu.solve(b), max(repeats, 5))
        rec.update(factor_s=tf, solve_s=ts, factor_nnz=int(lu.L.nnz + lu.U.nnz),
                   negative_pivots=int(np.count_nonzero(lu.U.diagonal() < 0)))
    else:
        from rve.solvers.backends import pardiso

        if not pardiso.available():
            return {"variant": variant, "skipped": pardiso.unavailable_reason()}
        M = A
        if variant == "pardiso_chol_t2":
            return _cholesky_record(A, b, rec, repeats, rss0)
        drop = variant in ("pardiso_dropzeros", "pardiso_nomatch_drop", "pardiso_drop_cnr", "pardiso_drop_t2")
        if drop:
            rec["nnz"] = int(np.count_nonzero(A.data))
        # CNR mode for up to 2 threads (iparm(34) = 2), on one or two threads
        extra = {"cnr": 2, "threads": 2 if variant.endswith("_t2") else 1} if "_drop_" in variant else {}
        # the backend drops the zeros itself (its factorisation time includes that copy)
        f = pardiso.PardisoFactorization(matching="nomatch" not in variant, drop_zeros=drop, **extra)
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


def _cholesky_record(A, b, rec: dict, repeats: int, rss0: float) -> dict:
    """``pardiso_chol_t2``: the Cholesky companion on two threads (CNR), zeros dropped."""
    from rve.solvers.backends import pardiso
    from rve.solvers.linear import NotPositiveDefiniteError

    f = pardiso.PardisoFactorization(positive_definite=True, drop_zeros=True, cnr=2, threads=2)
    t0 = time.perf_counter()
    f.analyse(A)
    rec["analyse_s"] = time.perf_counter() - t0
    rec["nnz"] = int(np.count_nonzero(A.data))

    def run():
        try:
            return f.factorize(A)
        except NotPositiveDefiniteError:
            return None

    definite = run() is not None  # warm-up
    tf, _ = _median_time(run, repeats)
    if definite:
        ts, x = _median_time(lambda: f.solve(b), max(repeats, 5))
        rec["residual"] = float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))
    else:
        ts, rec["residual"] = float("nan"), float("nan")
    rec.update(factor_s=tf, solve_s=ts, factor_nnz=f.factor_nnz if definite else -1,
               negative_pivots=0 if definite else ">0", perturbed=0, refinement=0, analyses=f.analyses)
    f.release()
    rec["rss_mib"] = _rss_mib()
    rec["rss_growth_mib"] = rec["rss_mib"] - rss0
    return rec


def threads_check(path: Path, repeats: int) -> None:
    """Factorise and solve one matrix on 1 and 2 PARDISO threads, CNR off and on, each
    twice with a fresh instance; print the median factorisation time and the largest
    difference of every solution to the first one of its CNR mode."""
    import scipy.sparse as sp

    from rve.solvers.backends import pardiso

    A = sp.load_npz(path).tocsc()
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    print(f"{path.stem}: n = {A.shape[0]}, nnz = {A.nnz}")
    for cnr in (0, 2):
        ref = None
        for threads in (1, 2, 2, 1):
            f = pardiso.PardisoFactorization(threads=threads, cnr=cnr)
            f.factorize(A)
            tf, _ = _median_time(lambda: f.factorize(A), repeats)
            x = f.solve(b)
            f.release()
            ref = x if ref is None else ref
            d = float(np.abs(x - ref).max())
            print(f"  cnr={cnr} threads={threads}: factorisation {tf:.3f} s, max|x - x(first, 1 thread)| = "
                  f"{'0 (bitwise)' if d == 0.0 else f'{d:.2e}'}", flush=True)


def run_variant(path: Path, variant: str, repeats: int) -> dict:
    rec = run_json([sys.executable, __file__, "--worker", str(path), variant, str(repeats)], worker_env())
    return {"variant": variant, **rec} if "error" in rec else rec


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
    ap.add_argument("--threads-check", action="store_true",
                    help="1 vs 2 PARDISO threads, CNR off/on, on the --only matrices (default min30_first_keep)")
    a = ap.parse_args(argv)
    if a.threads_check:
        for name in a.only or ["min30_first_keep"]:
            threads_check(Path(a.dir) / f"{name}.npz", a.repeats)
        return
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
