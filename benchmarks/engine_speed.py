"""Speed of the linear-solver backends (issue 10): single factorisations of the project's
own matrices, and whole runs (relaxation, strain step) as whole processes per backend.

    python benchmarks/engine_matrices.py          # once: writes results/engine/*.npz
    python benchmarks/engine_speed.py [--repeats 5] [--only NAME ...] [--variants ...]
    python benchmarks/engine_speed.py --relax 12 [--runs 3] [--backends superlu pardiso ...]
    python benchmarks/engine_speed.py --relax 30 --runs 1
    python benchmarks/engine_speed.py --strain-step [--state FILE] [--runs 3]
    python benchmarks/engine_speed.py --wire [--runs 3] [--backends superlu pardiso]
        [--baseline /work/baseline --baseline-python /work/baseline/.venv/bin/python]
        # the dynamic-wire study (benchmarks/dynamic_wire_study_time.py) as fresh processes
    python benchmarks/engine_speed.py --threads-check [--only min30_first_keep ...]
        # PARDISO on 1 and 2 threads, CNR off / on (iparm(34) = 2): factorisation medians and
        # max |x - x_ref| of repeated solves (bitwise reproducibility; docs/engine.md "Two threads")
    python benchmarks/engine_speed.py --unsym [--only impact_scene_1 ...] [--rounds 2]
        # the dynamic scenes' unsymmetric stage matrices (engine_matrices.py --only
        # impact_scene impact_scene_reduced induced_B3): superlu_colamd (StageFactorisation's
        # route for pardiso/auto before round 4), superlu_symm (the 'superlu' backend),
        # superlu_pruned (the impact scene's), pardiso_unsym[_fresh|_nomatch] (mtype 11)
    python benchmarks/engine_speed.py --scene-ab impact [--start 60 --steps 20 --rounds 2] [--reduced]
    python benchmarks/engine_speed.py --scene-ab induced [--steps 100 --rounds 3]
        # interleaved whole-scene A/B of the stage-matrix backend (main_scene_ab)

Whole runs (``--relax N``: the shipped 80-fibril plain weave, configs/scenes/
plain_weave_relax.yaml with ``mesh.elements = N``; at N = 12 its coarse stage is the run
itself, at 30 the shipped mesh sequencing 12 -> 30; ``--strain-step``: one RVE strain
step, ``rve.homogenisation.strain.strain_step``, of configs/rve/plain_weave.yaml (12
el/fibril, the default job's), uniaxial step 1 from a relaxed state file): every run is a
fresh ``python`` process with ``RVE_LINEAR_BACKEND`` set to the backend, the runs
interleaved (superlu, pardiso, ..., superlu, pardiso, ...). Printed per backend: median
process wall time (launch to exit, imports included) and of the solve alone, the ratio
superlu / this (same invocation), peak RSS, Newton iterations, factorisations and
analyses, final energy and its relative difference to superlu's, max overlap / R,
negative pivots of the final tangent (stable), |x - x_superlu|_max, and the split of the
solve time measured by wrapping (factorisation + solve, assembly, contact rebuild,
energy, other). Backends: ``superlu`` (scipy's SuperLU) and ``pardiso`` (the default
"auto" where MKL is present, with the minimiser's ``MinimizeOptions`` defaults). The
PARDISO variants measured against them (nonzero vs stored pattern, analysis growth,
orderings, CNR, two threads, the LDL^T test) are decided; their figures stay in
docs/engine.md and in git. Whole runs get ``RVE_PARDISO_THREADS=1`` unless it is set.

For every saved matrix and every variant, in a fresh subprocess (so ``ru_maxrss`` is the
peak of that variant alone): median wall time of one numeric factorisation and of one
solve (``--repeats``, at least 5), the ratio against SuperLU measured in the same run,
factor nonzeros, peak RSS (MiB, and its growth over the loaded matrix), the relative
residual |A x - b| / |b| of a random b, negative pivots, and for PARDISO the perturbed
pivots and refinement steps. Variants:

* ``superlu``: today's path (``spla.splu`` with ``rve.solvers.linear.SUPERLU_SYMMETRIC``: minimum
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
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = ("superlu", "pardiso_fresh", "pardiso_reuse", "pardiso_nomatch", "pardiso_dropzeros",
            "pardiso_nomatch_drop", "pardiso_drop_cnr", "pardiso_drop_t2", "pardiso_chol_t2")
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


def run_variant(path: Path, variant: str, repeats: int, worker: str = "--worker") -> dict:
    env = dict(os.environ)
    for k in ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
        env.setdefault(k, "1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, worker, str(path), variant, str(repeats)]
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


# ----------------------------------------------------------------------------- unsymmetric stage matrices
#: variants of ``--unsym`` (docs/engine.md "Unsymmetric stage matrices (round 4)")
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

        if variant == "superlu_colamd":   # StageFactorisation's route for 'pardiso'/'auto' before round 4
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
                per[v].append(run_variant(d / f"{name}.npz", v, max(repeats, 5), worker="--worker-unsym"))
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


# ----------------------------------------------------------------------------- scene A/B (round 4)
def _state_diff(a: dict, b: dict) -> dict:
    """max |a - b| / max |a| of the final states' arrays (x, w, T)."""
    out = {}
    for k in ("x", "w", "T"):
        if k in a and k in b:
            va, vb = np.asarray(a[k], float), np.asarray(b[k], float)
            out[k] = float(np.abs(va - vb).max() / max(np.abs(va).max(), 1e-300))
    return out


class _Timers:
    """Calls and wall time of the factorisation backends' phases (wrapped methods), reset per run."""

    def __init__(self):
        from rve.solvers.backends.pruned import PrunedSuperLU
        from rve.solvers import linear
        from rve.solvers.backends import pardiso

        self.t, self.n = {}, {}
        targets = [(pardiso.PardisoFactorization, "analyse", "pardiso_analyse"),
                   (pardiso.PardisoFactorization, "factorize", "pardiso_factorize"),
                   (pardiso.PardisoFactorization, "solve", "pardiso_solve"),
                   (PrunedSuperLU, "_factorize", "superlu_pruned_factorize"),
                   (PrunedSuperLU, "solve", "superlu_pruned_solve"),
                   (linear.SuperLUBackend, "_factorize", "superlu_factorize"),
                   (linear.SuperLUBackend, "solve", "superlu_solve")]
        for owner, attr, key in targets:
            self._wrap(owner, attr, key)

    def _wrap(self, owner, attr, key):
        fn = owner.__dict__[attr]
        timers = self

        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                timers.t[key] = timers.t.get(key, 0.0) + time.perf_counter() - t0
                timers.n[key] = timers.n.get(key, 0) + 1

        setattr(owner, attr, timed)

    def reset(self):
        self.t, self.n = {}, {}

    def summary(self) -> str:
        # pardiso_factorize includes the analyses it triggers; printed as is
        return ", ".join(f"{k} {self.n[k]}x {self.t[k]:.1f} s" for k in sorted(self.t))


def main_scene_ab(scene: str, backends, rounds: int, steps: int, start: int, reduced: bool, json_path=None) -> None:
    """Interleaved whole-scene runs in this process, one per backend and round (the backend
    through ``integrator_options={'linear_backend': ...}``): CPU and wall time medians, the
    ratio to the first backend, factorisations, Newton iterations per stage, balance errors,
    and the final states' max differences to the first backend's.

    ``impact``: configs/scenes/impact.yaml (full size unless ``reduced``); the relaxed state of
    engine_matrices.py (``impact_scene[_reduced]_relaxed.npz``, relaxed here if absent), then
    ``start`` steps of 0.5 us once (pardiso_unsym) to a checkpoint, from which every timed run
    resumes for ``steps`` more (the segment in sphere + fabric contact); the last two stage
    matrices of the preparation are saved as ``impact_deep[_reduced]_<k>``.
    ``induced``: configs/scenes/induced_deformation.yaml B3 full size, ``steps`` steps of 5 us
    from t = 0 (contact from about 0.3 ms)."""
    import shutil
    import tempfile

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from rve.config.loader import load_config

    from rve.solvers import linear
    from rve.solvers.backends import pardiso as _pardiso

    # a benchmark-only variant: mtype 11 analysing the stored pattern (candidate contact pairs
    # included), so that later nonzero patterns of the same contact map lie in it
    linear.register_backend("pardiso_unsym_stored", lambda symmetric=True: _pardiso.PardisoFactorization(
        symmetric=False, analyse_stored=True))
    d = ROOT / "results/engine"
    ov = ["output.vtk=false", "output.png=false"]
    runs = {b: [] for b in backends}
    tmp = Path(tempfile.mkdtemp(prefix="rve_ab_"))
    if scene == "impact":
        from engine_matrices import _hook_stage_matrices, _save

        from rve.scenes import impact
        from rve.scenes.impact.scene import schur_border

        if reduced:
            ov += ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
                   "projectile.radius=4.5 mm"]
        tag = "impact_scene_reduced" if reduced else "impact_scene"
        cfg = load_config(ROOT / "configs/scenes/impact.yaml", ov + [f"time.checkpoint_every={start}"])
        state = d / f"{tag}_relaxed.npz"
        if state.exists():
            x0 = np.load(state)["x"]
        else:
            x0, _ = impact.relax(cfg)
            d.mkdir(parents=True, exist_ok=True)
            np.savez(state, x=x0)
        total = start + steps
        t_end = 5e-4 * total
        ck = tmp / "start.npz"
        seen, undo = _hook_stage_matrices(2)
        t0 = time.perf_counter()
        try:
            impact.solve(cfg, x_start=x0, record=False, t_end=t_end, steps=total, checkpoint=ck,
                         stop_after_steps=start, integrator_options={"linear_backend": "pardiso_unsym"})
        except Exception as exc:  # SceneFailure: stopped after `start` steps (the checkpoint is written)
            print(f"  preparation: {exc} ({time.perf_counter() - t0:.0f} s)", flush=True)
        finally:
            undo()
        deep = "impact_deep_reduced" if reduced else "impact_deep"
        for k, (seq, A) in enumerate(seen["last"]):
            _save(d, f"{deep}_{k}", A, {"source": f"impact scene {'reduced' if reduced else 'full size'}, the "
                                                  f"{seq}-th of {seen['count']} stage factorisations of the first "
                                                  f"{start} steps of 0.5 us (row-scaled, restricted)",
                                        "border": schur_border(impact.setup(cfg).system),
                                        "note": f"factorisation {seq}/{seen['count']}"})

        def one(backend):
            c = tmp / f"run_{backend}.npz"
            shutil.copy(ck, c)
            return impact.solve(cfg, x_start=x0, record=False, t_end=t_end, steps=total, checkpoint=c,
                                integrator_options={"linear_backend": backend})
    else:
        from rve.scenes.induced import solve as induced_solve

        cfg = load_config(ROOT / "configs/scenes/induced_deformation.yaml", ov + ["field.orientation=B3"])

        def one(backend):
            return induced_solve(cfg, t_end=5e-3 * steps, steps=steps, record=False,
                                 integrator_options={"linear_backend": backend})
    timers = _Timers()
    phases = {}
    for _ in range(max(1, rounds)):
        for b in backends:
            timers.reset()
            c0, w0 = time.process_time(), time.perf_counter()
            r = one(b)
            runs[b].append((r, time.process_time() - c0, time.perf_counter() - w0))
            phases[b] = timers.summary()
            print(f"  {scene} {b}: CPU {runs[b][-1][1]:.1f} s wall {runs[b][-1][2]:.1f} s "
                  f"(load {os.getloadavg()[0]:.1f}); {phases[b]}", flush=True)
    ref = runs[backends[0]][-1][0]
    rec = {}
    cpu0 = float(np.median([c for _, c, _ in runs[backends[0]]]))
    for b in backends:
        r = runs[b][-1][0]
        s = r.summary
        cpu = float(np.median([c for _, c, _ in runs[b]]))
        wall = float(np.median([w for _, _, w in runs[b]]))
        diff = _state_diff(ref.state, r.state)
        rec[b] = {"cpu_s": cpu, "wall_s": wall, "cpu_ratio": cpu0 / cpu, "runs": len(runs[b]),
                  "factorizations": s.get("factorizations"), "newton_per_stage": s.get("newton_iterations_per_stage"),
                  "steps_accepted": s.get("steps_accepted"), "steps_rejected": s.get("steps_rejected"),
                  "balance_errors": s.get("balance_errors"), "state_diff_to_first": diff, "phases": phases.get(b)}
        print(f"[{scene}] {b:<16} CPU {cpu:7.1f} s (ratio {cpu0 / cpu:4.2f})  wall {wall:7.1f} s  "
              f"steps {s.get('steps_accepted')}/{s.get('steps_rejected')} rejected  factorisations "
              f"{s.get('factorizations')}  Newton/stage {s.get('newton_iterations_per_stage'):.2f}  "
              f"max|diff|/max to {backends[0]}: " + " ".join(f"{k} {v:.1e}" for k, v in diff.items()), flush=True)
        print(f"[{scene}] {b:<16} balance errors "
              + json.dumps({k: float(f"{v:.4g}") for k, v in s.get("balance_errors", {}).items()}), flush=True)
    shutil.rmtree(tmp, ignore_errors=True)
    if json_path:
        Path(json_path).write_text(json.dumps(rec, indent=1, default=float))


# ----------------------------------------------------------------------------- whole runs
RUN_BACKENDS = ("superlu", "pardiso")
RELAX_CONFIG = ROOT / "configs/scenes/plain_weave_relax.yaml"
STRAIN_CONFIG = ROOT / "configs/rve/plain_weave.yaml"


class _Split:
    """Wall-time accumulators around the hot calls (wrapping costs ~1 us per call)."""

    def __init__(self):
        self.t = {"factorisation": 0.0, "assembly": 0.0, "contact_rebuild": 0.0, "energy": 0.0}
        self.n = {k: 0 for k in self.t}

    def wrap(self, owner, attr, key):
        fn = getattr(owner, attr)

        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.t[key] += time.perf_counter() - t0
                self.n[key] += 1

        setattr(owner, attr, timed)


def _instrument() -> _Split:
    from rve.model import contact_model
    from rve.solvers import minimize, newton, static

    sp_ = _Split()
    cs = contact_model.ContactSystem
    sp_.wrap(cs, "evaluate", "assembly")
    sp_.wrap(cs, "rebuild", "contact_rebuild")
    sp_.wrap(cs, "energy", "energy")
    for mod in (minimize, newton, static):
        for name in ("factor_inertia", "factor_positive_definite", "sparse_solve"):
            if hasattr(mod, name):
                sp_.wrap(mod, name, "factorisation")
    from rve.fabrics import relaxation as fabric_relaxation

    # the stability check (its own reference; wrapping linear's would count the LDL^T of
    # factor_positive_definite twice)
    sp_.wrap(fabric_relaxation, "factor_inertia", "factorisation")
    return sp_


def run_worker(kind: str, arg: str, backend: str, out_npz: str) -> dict:
    """One whole run in this process (``RVE_LINEAR_BACKEND`` is already set by the parent)."""
    t_import = time.perf_counter()
    import rve.scenes  # noqa: F401
    split = _instrument()
    rec = {"kind": kind, "arg": arg, "backend": backend, "env": os.environ.get("RVE_LINEAR_BACKEND", "")}
    t0 = time.perf_counter()
    if kind == "relax":
        from rve.config import load_config
        from rve.scenes import fabric_relax

        cfg = load_config(str(RELAX_CONFIG), [f"mesh.elements={int(arg)}"])
        res = fabric_relax.solve(cfg)
        s = res.summary
        x = np.asarray(res.state["x"], float)
        stages = [h for h in s["history"] if h.get("method") == "minimize_energy"]
        rec.update(iterations=int(s["static_newton_iterations"]), converged=bool(s["static_converged"]),
                   factorizations=int(sum(h.get("factorizations", 0) for h in stages)),
                   analyses=int(sum(h.get("analyses", 0) for h in stages)),
                   energy_mJ=float(s["energy_mJ"]), max_overlap_over_R=float(s["max_overlap_over_R"]),
                   negative_pivots=int(s["negative_pivots"]), stable=bool(s["stable"]),
                   stages=[{k: h.get(k) for k in ("mesh_elements", "onset_over_R", "newton_iterations",
                                                  "factorizations", "analyses", "wall_s")} for h in stages])
    else:
        from rve.config import load_config
        from rve.fabrics.setup import fabric_and_mesh
        from rve.homogenisation.checkpoint import load_state
        from rve.homogenisation.strain import strain_step
        from rve.solvers.linear import factor_inertia
        from rve.solvers.static import StaticProblem

        cfg = load_config(str(STRAIN_CONFIG), ["mesh.elements=12"])  # the 12-element step measured since round 3
        fab, mesh = fabric_and_mesh(cfg)
        st = load_state(arg)
        xs, system, info = strain_step(cfg, fab, mesh, st.x, st.origin, "uniaxial", 1)
        x = np.asarray(xs, float).reshape(-1)
        prob = StaticProblem(system, x, np.zeros(system.n), 0.0)
        _, J = prob(prob.u0())
        _, neg = factor_inertia(J)
        cst = system.contact_state(x)
        rec.update(converged=bool(info.get("converged")), residual_N=float(info.get("residual_N", np.nan)),
                   energy_mJ=float(system.energy(x)), max_overlap_over_R=float(cst["max_overlap_over_R"]),
                   negative_pivots=int(neg), stable=bool(neg == 0),
                   iterations=int(_count(info, "newton_iterations")),
                   factorizations=int(_count(info, "factorizations")),
                   analyses=int(_count(info, "analyses")))
    rec["solve_s"] = time.perf_counter() - t0
    rec["import_s"] = t0 - t_import
    rec["split_s"] = {k: float(v) for k, v in split.t.items()}
    rec["split_s"]["other"] = rec["solve_s"] - sum(split.t.values())
    rec["calls"] = dict(split.n)
    rec["rss_mib"] = _rss_mib()
    np.save(out_npz, x)
    return rec


def _count(info, key) -> int:
    """Sum of ``key`` over a nested info dict."""
    if isinstance(info, dict):
        return sum((v if k == key and isinstance(v, (int, np.integer)) else _count(v, key)) for k, v in info.items())
    if isinstance(info, (list, tuple)):
        return sum(_count(v, key) for v in info)
    return 0


def run_whole(kind: str, arg: str, backend: str, out_npz: Path) -> dict:
    env = dict(os.environ)
    for k in ("MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "RVE_PARDISO_THREADS"):
        env.setdefault(k, "1")
    env["RVE_LINEAR_BACKEND"] = "superlu" if backend == "superlu" else "pardiso"
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, "--run-worker", kind, str(arg), backend, str(out_npz)]
    t0 = time.perf_counter()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    if p.returncode != 0:
        return {"backend": backend, "error": (p.stderr.strip().splitlines() or ["?"])[-1], "wall_s": wall}
    rec = json.loads(p.stdout.strip().splitlines()[-1])
    rec["wall_s"] = wall
    rec["cpu_s"] = cpu
    return rec


def whole_table(title: str, runs: list, xs: dict) -> str:
    by = {}
    for r in runs:
        by.setdefault(r["backend"], []).append(r)
    ok = lambda b: [r for r in by.get(b, []) if "error" not in r]  # noqa: E731
    ref = ok("superlu")
    ref_wall = float(np.median([r["wall_s"] for r in ref])) if ref else float("nan")
    ref_cpu = float(np.median([r["cpu_s"] for r in ref])) if ref else float("nan")
    ref_E = ref[0]["energy_mJ"] if ref else float("nan")
    x_ref = xs.get(("superlu", 0))
    head = (f"{'backend':<13} {'runs':>4} {'wall(med)':>9} {'ratio':>6} {'cpu(med)':>8} {'ratio':>6} {'solve':>8} "
            f"{'RSS MiB':>8} {'its':>5} "
            f"{'fact':>5} {'anal':>5} {'energy mJ':>16} {'dE/E':>8} {'ovl/R':>7} {'neg':>4} {'|dx|max':>8}  "
            f"split of the solve: fact / asm / rebuild / energy / other (s)")
    lines = [title, head, "-" * len(head)]
    for b, recs in by.items():
        good = ok(b)
        for r in recs:
            if "error" in r:
                lines.append(f"{b:<13} error: {r['error']}")
        if not good:
            continue
        wall = float(np.median([r["wall_s"] for r in good]))
        cpu = float(np.median([r["cpu_s"] for r in good]))
        r0 = good[0]
        walls = ", ".join(f"{r['wall_s']:.1f}" for r in good)
        x0 = xs.get((b, 0))
        dx = float(np.abs(x0 - x_ref).max()) if x0 is not None and x_ref is not None else float("nan")
        sp_ = {k: float(np.median([r["split_s"][k] for r in good])) for k in r0["split_s"]}
        lines.append(
            f"{b:<13} {len(good):>4} {wall:>9.1f} {ref_wall / wall:>5.2f}x {cpu:>8.1f} {ref_cpu / cpu:>5.2f}x "
            f"{np.median([r['solve_s'] for r in good]):>8.1f} {max(r['rss_mib'] for r in good):>8.0f} "
            f"{r0['iterations']:>5} {r0['factorizations']:>5} {r0['analyses']:>5} {r0['energy_mJ']:>16.12f} "
            f"{abs(r0['energy_mJ'] - ref_E) / abs(ref_E):>8.1e} {r0['max_overlap_over_R']:>7.4f} "
            f"{r0['negative_pivots']:>4} {dx:>8.1e}  "
            + " / ".join(f"{sp_[k]:.1f}" for k in ("factorisation", "assembly", "contact_rebuild", "energy", "other"))
            + f"   (walls: {walls})")
    lines.append("wall = whole process (launch to exit), median; cpu = its user + system CPU time (the fairer "
                 "figure on a loaded machine); ratio = superlu median / this median (same "
                 "invocation, interleaved); solve = the solve alone (wall); its/fact/anal: Newton iterations, "
                 "factorisations, symbolic analyses of the first run; neg: negative pivots of the final tangent (0 = stable)")
    return "\n".join(lines)


def main_whole(kind: str, arg: str, runs: int, backends, json_path=None, outdir=None) -> None:
    outdir = Path(outdir or ROOT / "results/engine/runs")
    outdir.mkdir(parents=True, exist_ok=True)
    recs, xs = [], {}
    for k in range(runs):
        for b in backends:
            npz = outdir / f"{kind}_{Path(str(arg)).stem}_{b}_{k}.npy"
            r = run_whole(kind, arg, b, npz)
            r["rep"] = k
            recs.append(r)
            if "error" not in r:
                xs[(b, k)] = np.load(npz)
            print(f"  {kind} {arg} {b} run {k + 1}: " + (f"{r['wall_s']:.1f} s (cpu {r['cpu_s']:.1f} s), "
                  f"E = {r['energy_mJ']:.12f} mJ, "
                  f"its {r['iterations']}, fact {r['factorizations']}, anal {r['analyses']}, split "
                  + ", ".join(f"{kk} {v:.1f}" for kk, v in r["split_s"].items()) if "error" not in r
                  else f"error {r['error']}"), file=sys.stderr, flush=True)
    title = (f"relaxation, 80-fibril plain weave, {arg} el/fibril" if kind == "relax" else
             f"strain step (uniaxial 1) of {STRAIN_CONFIG.relative_to(ROOT)} from {arg}")
    print(whole_table(title, recs, xs))
    if json_path:
        Path(json_path).write_text(json.dumps(recs, indent=1, default=float))


def _wire_process(python: str, tree: Path, env: dict) -> dict:
    """One fresh process of ``benchmarks/dynamic_wire_study_time.py`` (the default plan) in
    ``tree`` with ``python``: study wall time as the script prints it, the process's wall time
    and peak RSS (``os.wait4``: the parent process; the study's two worker processes are
    not included), and its fitted-orders table (the lines after "fitted orders")."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([python, "benchmarks/dynamic_wire_study_time.py"], cwd=tree, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"dynamic_wire_study_time.py failed in {tree}:\n{out[-2000:]}")
    study = float(next(ln for ln in out.splitlines() if ln.startswith("study wall time")).split(":")[1].split()[0])
    orders = out.split("fitted orders:", 1)[1].strip() if "fitted orders:" in out else ""
    return {"study_s": study, "process_s": wall, "rss_mib": usage.ru_maxrss / 1024.0, "orders": orders}


def main_wire(runs: int, backends, baseline: str | None, baseline_python: str | None) -> None:
    """The dynamic-wire study (``--wire``): interleaved fresh processes, per side the median
    study wall time, its ratio against the first side (today's main when ``--baseline`` is
    given, else the first backend) and peak RSS; the orders tables must be equal across sides
    (the wire is one fibril: its stage matrices take the kept banded LU whatever
    ``RVE_LINEAR_BACKEND`` says, so the backends should not change a digit)."""
    sides = []
    if baseline:
        sides.append(("today's main", baseline_python or sys.executable, Path(baseline), {}))
    for b in backends:
        sides.append((f"this tree, {b}", sys.executable, ROOT, {"RVE_LINEAR_BACKEND": b}))
    recs = {name: [] for name, *_ in sides}
    for k in range(runs):
        for name, py, tree, extra in sides:
            env = {**os.environ, **extra}
            r = _wire_process(py, tree, env)
            recs[name].append(r)
            print(f"  run {k + 1} {name}: study {r['study_s']:.2f} s, process {r['process_s']:.2f} s, "
                  f"peak RSS {r['rss_mib']:.0f} MiB", file=sys.stderr, flush=True)
    ref = sides[0][0]
    ref_t = float(np.median([r["study_s"] for r in recs[ref]]))
    print(f"dynamic-wire study: medians of {runs} interleaved runs (ratio = {ref} / side)")
    for name, *_ in sides:
        t = float(np.median([r["study_s"] for r in recs[name]]))
        pt = float(np.median([r["process_s"] for r in recs[name]]))
        rss = max(r["rss_mib"] for r in recs[name])
        same = all(r["orders"] == recs[ref][0]["orders"] for r in recs[name])
        print(f"{name:24s} study {t:7.2f} s ({ref_t / t:.2f}x)  process {pt:7.2f} s  peak RSS {rss:5.0f} MiB  "
              f"orders {'identical to ' + ref if same else 'DIFFERENT'}")
    print("fitted orders (" + ref + "):\n" + recs[ref][0]["orders"])


def main(argv=None) -> None:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--worker":
        print(json.dumps(worker(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        return
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--worker-unsym":
        print(json.dumps(worker_unsym(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        return
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--run-worker":
        print(json.dumps(run_worker(sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5]), default=float))
        return
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dir", default=str(ROOT / "results/engine"))
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", default=None, help="also write the records here")
    ap.add_argument("--relax", type=int, default=None, metavar="ELEMENTS",
                    help="whole relaxation runs of the 80-fibril weave at this mesh (12 or 30)")
    ap.add_argument("--strain-step", action="store_true", help="whole runs of one RVE strain step")
    ap.add_argument("--state", default=str(ROOT / "results/engine/relaxed12.nc"),
                    help="relaxed state of configs/rve/plain_weave.yaml for --strain-step")
    ap.add_argument("--runs", type=int, default=3, help="interleaved runs per backend (whole runs)")
    ap.add_argument("--backends", nargs="*", default=["superlu", "pardiso"], choices=RUN_BACKENDS)
    ap.add_argument("--threads-check", action="store_true",
                    help="1 vs 2 PARDISO threads, CNR off/on, on the --only matrices (default min30_first_keep)")
    ap.add_argument("--unsym", action="store_true",
                    help="the unsymmetric stage matrices of the dynamic scenes (engine_matrices.py --only "
                         "impact_scene induced_B3): SuperLU paths vs PARDISO mtype 11")
    ap.add_argument("--unsym-variants", nargs="*", default=list(UNSYM_VARIANTS), choices=UNSYM_VARIANTS)
    ap.add_argument("--rounds", type=int, default=2, help="interleaved rounds of the --unsym variants")
    ap.add_argument("--scene-ab", choices=("impact", "induced"), default=None,
                    help="interleaved whole-scene runs per backend (--scene-backends) in this process")
    ap.add_argument("--scene-backends", nargs="*", default=None,
                    help="default: impact superlu_pruned pardiso_unsym; induced superlu pardiso")
    ap.add_argument("--steps", type=int, default=20, help="--scene-ab: timed steps")
    ap.add_argument("--start", type=int, default=60, help="--scene-ab impact: steps before the timed segment")
    ap.add_argument("--reduced", action="store_true", help="--scene-ab impact: the config header's small version")
    ap.add_argument("--wire", action="store_true",
                    help="the dynamic-wire study as whole processes (--runs, --backends, --baseline)")
    ap.add_argument("--baseline", default=None, help="--wire: today's main tree to compare against")
    ap.add_argument("--baseline-python", default=None, help="--wire: the baseline tree's interpreter")
    a = ap.parse_args(argv)
    if a.wire:
        main_wire(a.runs, a.backends, a.baseline, a.baseline_python)
        return
    if a.scene_ab:
        be = a.scene_backends or (["superlu_pruned", "pardiso_unsym"] if a.scene_ab == "impact"
                                  else ["superlu", "pardiso"])
        main_scene_ab(a.scene_ab, be, a.rounds, a.steps, a.start, a.reduced, a.json)
        return
    if a.threads_check:
        for name in a.only or ["min30_first_keep"]:
            threads_check(Path(a.dir) / f"{name}.npz", a.repeats)
        return
    if a.unsym:
        main_unsym(Path(a.dir), a.only, a.unsym_variants, a.repeats, a.rounds, a.json)
        return
    if a.relax is not None or a.strain_step:
        kind, arg = ("relax", str(a.relax)) if a.relax is not None else ("strain", a.state)
        main_whole(kind, arg, a.runs, a.backends, a.json)
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
