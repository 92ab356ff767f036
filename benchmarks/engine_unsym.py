"""The dynamic scenes' unsymmetric stage matrices (saved by ``benchmarks/engine_matrices.py
--only impact_scene impact_scene_reduced induced_B3``) factorised by each candidate path, in
fresh worker processes, interleaved rounds (docs/engine.md "Unsymmetric stage matrices").

    python benchmarks/engine_unsym.py [--only impact_scene_1 ...] [--rounds 2] [--repeats 5] [--json F]

Variants: ``superlu_colamd`` (COLAMD with partial pivoting), ``superlu_symm`` (the
'superlu' backend), ``superlu_pruned`` (the impact scene's, with its Schur border),
``pardiso_unsym[_fresh|_nomatch]`` (PARDISO mtype 11). Printed per matrix and variant: the
median over the rounds of the per-round medians of factorisation and solve, fill, peak RSS,
the residual.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, median_time as _median_time, rss_mib as _rss_mib, run_json, worker_env  # noqa: E402


def _run_variant(path: Path, variant: str, repeats: int) -> dict:
    rec = run_json([sys.executable, __file__, "--worker", str(path), variant, str(repeats)], worker_env())
    return {"variant": variant, **rec} if "error" in rec else rec


#: variants of ``--unsym`` (docs/engine.md "Unsymmetric stage matrices")
UNSYM_VARIANTS = ("superlu_colamd", "superlu_symm", "superlu_pruned", "pardiso_unsym_fresh", "pardiso_unsym",
                  "pardiso_unsym_nomatch")
UNSYM_ORDER = ("impact_scene_1", "impact_scene_reduced_1", "induced_B3_1")


def worker_unsym(path: str, variant: str, repeats: int) -> dict:
    """One variant on one saved (unsymmetric) stage matrix: medians of ``repeats``
    factorisations and solves of a random b, fill, peak RSS, residual against a dense-free
    check |A x - b| / |b|."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    A = sp.load_npz(path).tocsc()
    A.sum_duplicates()
    meta_path = Path(path).with_suffix(".json")
    meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
    n = A.shape[0]
    b = np.random.default_rng(0).standard_normal(n)
    rss0 = _rss_mib()
    rec = {"variant": variant, "n": n, "nnz": int(A.nnz)}
    if variant.startswith("superlu"):
        from rve.solvers.linear import SUPERLU_FALLBACK_PERMC, SUPERLU_SYMMETRIC

        if variant == "superlu_colamd":   # StageFactorisation's route for 'pardiso'/'auto'
            fac = lambda: spla.splu(A, permc_spec=SUPERLU_FALLBACK_PERMC)  # noqa: E731
        elif variant == "superlu_symm":   # the 'superlu' backend (induced scene's default)
            fac = lambda: spla.splu(A, **SUPERLU_SYMMETRIC)  # noqa: E731
        else:                             # the impact scene's backend, projectile border by Schur complement
            from rve.solvers.backends.pruned import PrunedSuperLU

            be = PrunedSuperLU(symmetric=False, border=int(meta.get("border", 0)))
            fac = lambda: be.factorize(A)  # noqa: E731
        tf, lu = _median_time(fac, repeats)
        ts, x = _median_time(lambda: lu.solve(b), max(repeats, 5))
        L = lu.lu if variant == "superlu_pruned" else lu
        rec.update(factor_s=tf, solve_s=ts, factor_nnz=int(L.L.nnz + L.U.nnz))
    else:
        from rve.solvers.backends import pardiso

        if not pardiso.available():
            return {"variant": variant, "skipped": pardiso.unavailable_reason()}
        f = pardiso.PardisoFactorization(symmetric=False, matching=variant != "pardiso_unsym_nomatch")
        t0 = time.perf_counter()
        f.analyse(A)
        rec["analyse_s"] = time.perf_counter() - t0
        if variant == "pardiso_unsym_fresh":
            def run():
                f.analyse(A)
                return f.factorize(A)
        else:
            f.factorize(A)  # warm-up (first phase 22 after the analysis)
            run = lambda: f.factorize(A)  # noqa: E731
        tf, _ = _median_time(run, repeats)
        ts, x = _median_time(lambda: f.solve(b), max(repeats, 5))
        rec.update(factor_s=tf, solve_s=ts, factor_nnz=f.factor_nnz, perturbed=f.perturbed_pivots,
                   refinement=f.refinement_steps, analyses=f.analyses, stored_fast=f.stored_fast,
                   pardiso_mem_mib=f.memory_kb["factorization"] / 1024.0,
                   pardiso_analysis_mib=f.memory_kb["analysis_peak"] / 1024.0)
        f.release()
    rec["residual"] = float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))
    rec["rss_mib"] = _rss_mib()
    rec["rss_growth_mib"] = rec["rss_mib"] - rss0
    return rec


def unsym_table(results: dict, ref_variant: str) -> str:
    head = (f"{'matrix':<24} {'n':>6} {'nnz':>8} {'variant':<22} {'analyse':>8} {'factor':>8} {'ratio':>6} "
            f"{'solve':>8} {'ratio':>6} {'fill':>9} {'RSS':>6} {'+RSS':>6} {'resid':>8} {'pert':>4}")
    lines = [head, "-" * len(head)]
    for name, recs in results.items():
        ref = next((r for r in recs if r.get("variant") == ref_variant.get(name) and "factor_s" in r), None)
        for r in recs:
            if "factor_s" not in r:
                lines.append(f"{name:<24} {'':>6} {'':>8} {r['variant']:<22} {r.get('skipped') or r.get('error')}")
                continue
            rf = ref["factor_s"] / r["factor_s"] if ref else float("nan")
            rs = ref["solve_s"] / r["solve_s"] if ref else float("nan")
            an = f"{r['analyse_s']:.3f}" if "analyse_s" in r else "-"
            lines.append(
                f"{name:<24} {r['n']:>6} {r['nnz']:>8} {r['variant']:<22} {an:>8} {r['factor_s']:>8.3f} {rf:>5.1f}x "
                f"{r['solve_s'] * 1e3:>6.1f}ms {rs:>5.1f}x {r['factor_nnz']:>9} {r['rss_mib']:>6.0f} "
                f"{r['rss_growth_mib']:>6.0f} {r['residual']:>8.1e} {r.get('perturbed', '-'):>4}")
    lines.append("analyse / factor in s: median over the rounds of the medians of the repeats; ratio = the scene's "
                 "current path (* in the variant column) / this; fill: SuperLU L+U, PARDISO L+U (iparm 18); RSS: peak "
                 "MiB of the worker process, +RSS over the loaded matrix; pert: perturbed pivots")
    return "\n".join(lines)


def main_unsym(d: Path, names, variants, repeats: int, rounds: int, json_path=None) -> None:
    """Every variant on every matrix in fresh worker processes, ``rounds`` interleaved rounds
    (variant order the same each round), per-round medians of ``repeats``; the median over
    the rounds is printed."""
    names = names or [n for n in UNSYM_ORDER if (d / f"{n}.npz").exists()]
    ref = {n: ("superlu_pruned" if n.startswith("impact") else "superlu_symm") for n in names}
    results = {}
    for name in names:
        per = {v: [] for v in variants}
        for _ in range(max(1, rounds)):
            for v in variants:
                per[v].append(_run_variant(d / f"{name}.npz", v, max(repeats, 5)))
                r = per[v][-1]
                print(f"  {name} {v}: {r.get('factor_s', r.get('error', r.get('skipped')))}", file=sys.stderr,
                      flush=True)
        recs = []
        for v in variants:
            ok = [r for r in per[v] if "factor_s" in r]
            if not ok:
                recs.append(per[v][-1])
                continue
            r = dict(ok[-1])
            for k in ("factor_s", "solve_s", "analyse_s", "rss_mib", "rss_growth_mib"):
                if k in r:
                    r[k] = float(np.median([o[k] for o in ok]))
            r["rounds"] = len(ok)
            if v == ref[name]:
                r["variant"] = v + " *"
            recs.append(r)
        results[name] = recs
    ref_names = {n: ref[n] + " *" for n in names}
    print(unsym_table(results, ref_names))
    if json_path:
        Path(json_path).write_text(json.dumps(results, indent=1))


def main(argv=None) -> None:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(worker_unsym(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", default=str(ROOT / "results/engine"))
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--variants", nargs="*", default=list(UNSYM_VARIANTS), choices=UNSYM_VARIANTS)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds")
    ap.add_argument("--json", default=None, help="also write the records here")
    a = ap.parse_args(argv)
    main_unsym(Path(a.dir), a.only, a.variants, a.repeats, a.rounds, a.json)


if __name__ == "__main__":
    main()
