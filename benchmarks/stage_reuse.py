"""Modified Newton in the SDIRK stage solves: how many iterations does a stage need when
the factorisation is reused (from the stage start, or carried over from earlier stages and
steps) instead of refactorised every iteration? (issue 10, item 2; the measurement only.)

    python benchmarks/stage_reuse.py [--n 8] [--elements 20] [--steps 40] [--h 5e-4] [--v0 10]

A real dynamic run: an n × n plain weave of single-fibril yarns (d = 0.3 mm, spacing 1 mm,
crimp amplitude R, the RVE material of configs/rve/plain_weave.yaml, no damping), linear
elements, fibril ends pinned, directors free with a twist gauge, contact on; initial
velocity -v0 e_z (mm/ms) on the centroids of the warp fibrils' nodes within 2 mm of the
centre (|x|, |y| < 2), which drives them into the weft fibrils under them; SDIRK2 (rve.solvers.dirk.integrate, fixed step h, ms).

The integration itself runs with today's Newton (one factorisation per iteration). Each
stage Newton call is intercepted (``rve.solvers.dirk.newton`` is wrapped *in this process
only*; dirk.py and newton.py are not edited) and, from the same starting point and with the
same tolerances (the residual decides: ``|G| <= atol`` or ``<= rtol |G_0|``), the stage is
solved again by:

* ``stage``: modified Newton with the Jacobian factorised once at the stage start;
* ``carried``: modified Newton with a factorisation carried across stages and steps (SDIRK2
  has one diagonal coefficient, so every stage matrix is M + h a C + (h a)² K), refactorised
  only when the observed contraction |G_k+1| / |G_k| exceeds ``--kappa`` (default 0.5) or
  the stage does not converge in ``--max-reuse`` iterations (then restarted from the stage
  start with a fresh factorisation);

and the iteration counts, contraction rates, factorisations and the distance of the
modified-Newton stage value from the full-Newton one are printed. It also counts how often
the stage matrix's stored pattern (explicit zeros kept) and its nonzero pattern (zeros
dropped) change from one stage to the next, which decides how often a reused analysis
(rve/solvers/pardiso.py) must be redone.
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def build(n: int, elements: int, v0: float):
    import rve.homogenisation.config  # noqa: F401  (registers the "rve" scene)
    from rve.config.loader import load_config
    from rve.contact.system import ContactParams, ContactSystem
    from rve.fabrics import weave
    from rve.model import BeamMaterial, BeamModel, DirichletBC

    cfg = load_config(ROOT / "configs/rve/plain_weave.yaml")
    m, c = cfg.material, cfg.contact
    d = 0.3
    fab = weave("plain", n, n, spacing=1.0, amplitude=d / 2, fibril_diameter=d, rows=(1,))
    mesh = fab.mesh(elements, 1)
    ends = np.array([tg.node(mesh) for tg in fab.end_tags], dtype=np.int64)
    first = mesh.node_offsets[:-1].astype(np.int64)
    mat = BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density)
    lay0 = BeamModel(mesh, mat).layout
    bcs = [DirichletBC(lay0.dofs("r", ends), 0.0), DirichletBC(lay0.dofs("g1", first, comp=2), 0.0)]
    base = BeamModel(mesh, mat, disk_points=4, bcs=bcs)
    params = ContactParams(penalty=c.penalty, heat_transfer=0.0, conductance=0.0, n_gp=c.n_gp, margin=c.margin,
                           g_eps=c.g_eps, recompute_closest=c.recompute_closest, rebuild_every=1)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = fab.initial_state(mesh)
    system = ContactSystem(base, params, x)
    w = np.zeros(base.n)
    X = base.nodal(x)
    warp = np.zeros(mesh.n_nodes, dtype=bool)
    for y in fab.yarns:
        if y.direction == "warp":
            for f in y.fibrils:
                warp[mesh.fibril_nodes(f)] = True
    mid = np.flatnonzero((np.abs(X[:, 0]) < 2.0) & (np.abs(X[:, 1]) < 2.0) & warp)
    w[base.layout.dofs("r", mid, comp=2)] = -float(v0)
    return system, x, w


class Factor:
    """SuperLU as today (symmetric mode) — the backend does not change iteration counts."""

    def __init__(self, J):
        from rve.solvers.newton import _SYMMETRIC

        self.lu = spla.splu(sp.csc_matrix(J), **_SYMMETRIC)

    def solve(self, r):
        return self.lu.solve(r)


def modified_newton(residual, u0, lu, atol, rtol, max_iter):
    """u_k+1 = u_k - LU⁻¹ G(u_k) with a fixed factorisation; returns (u, converged, norms)."""
    u = np.array(u0, float, copy=True)
    G = residual(u)
    res = [float(np.linalg.norm(G))]
    r0 = max(res[0], 1e-300)
    for _ in range(max_iter):
        if res[-1] <= atol or res[-1] <= rtol * r0:
            return u, True, res
        u = u - lu.solve(G)
        G = residual(u)
        res.append(float(np.linalg.norm(G)))
        if not np.isfinite(res[-1]) or res[-1] > 1e3 * r0:
            break
    return u, bool(res[-1] <= atol or res[-1] <= rtol * r0), res


def _key(A, drop: bool) -> str:
    A = sp.csc_matrix(A)
    if drop:
        A = A.copy()
        A.eliminate_zeros()
    return hashlib.sha1(A.indptr.tobytes() + A.indices.tobytes()).hexdigest()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--elements", type=int, default=20)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--h", type=float, default=5e-4)
    ap.add_argument("--v0", type=float, default=10.0)
    ap.add_argument("--kappa", type=float, default=0.5)
    ap.add_argument("--max-reuse", type=int, default=8)
    a = ap.parse_args(argv)

    import rve.solvers.dirk as dirk

    system, x0, w0 = build(a.n, a.elements, a.v0)
    real_newton = dirk.newton
    rec = []
    carried = {"lu": None, "factorizations": 0}
    last_keys = {"kept": None, "dropped": None, "kept_changes": 0, "dropped_changes": 0}

    def wrapped(fun, u0, *, atol=1e-10, rtol=1e-12, max_iter=30, label="", residual=None, **kw):
        t0 = time.perf_counter()
        ref = real_newton(fun, u0, atol=atol, rtol=rtol, max_iter=max_iter, label=label, residual=residual, **kw)
        t_ref = time.perf_counter() - t0
        if residual is None:
            residual_ = lambda u: fun(u)[0]  # noqa: E731
        else:
            residual_ = residual
        _, J0 = fun(u0)
        for kind, drop in (("kept", False), ("dropped", True)):
            k = _key(J0, drop)
            if last_keys[kind] is not None and k != last_keys[kind]:
                last_keys[kind + "_changes"] += 1
            last_keys[kind] = k
        # (i) factorised at the stage start
        us, cs, rs = modified_newton(residual_, u0, Factor(J0), atol, rtol, 50)
        # (ii) carried across stages and steps, adaptive refactorisation
        nfac = 0
        if carried["lu"] is None:
            carried["lu"], nfac = Factor(J0), 1
        uc, cc, rc = modified_newton(residual_, u0, carried["lu"], atol, rtol, a.max_reuse)
        rates = [rc[k + 1] / rc[k] for k in range(len(rc) - 1) if rc[k] > 0]
        if not cc or (rates and max(rates) > a.kappa):
            carried["lu"] = Factor(J0)
            nfac += 1
            uc2, cc, rc2 = modified_newton(residual_, u0, carried["lu"], atol, rtol, 50)
            its_c = (len(rc) - 1) + (len(rc2) - 1)
            uc = uc2
        else:
            its_c = len(rc) - 1
        carried["factorizations"] += nfac
        scale = max(float(np.linalg.norm(ref.u)), 1e-300)
        rec.append({
            "label": label, "ref_its": ref.iterations, "ref_res": list(ref.residuals), "ref_s": t_ref,
            "stage_its": len(rs) - 1, "stage_conv": cs, "stage_rates": [rs[k + 1] / rs[k] for k in range(len(rs) - 1)],
            "carried_its": its_c, "carried_conv": cc, "carried_fac": nfac,
            "carried_rates": rates,
            "d_stage": float(np.linalg.norm(us - ref.u) / scale), "d_carried": float(np.linalg.norm(uc - ref.u) / scale),
        })
        return ref

    dirk.newton = wrapped
    try:
        t0 = time.perf_counter()
        res = dirk.integrate(system, x0, w0, 0.0, a.steps * a.h, a.steps, stages=2, fixed_step=True,
                             consistent=False)
        wall = time.perf_counter() - t0
    finally:
        dirk.newton = real_newton

    nst = len(rec)
    ref_its = np.array([r["ref_its"] for r in rec])
    st_its = np.array([r["stage_its"] for r in rec])
    ca_its = np.array([r["carried_its"] for r in rec])
    st_rates = np.concatenate([r["stage_rates"] for r in rec if r["stage_rates"]] or [np.zeros(0)])
    ca_rates = np.concatenate([r["carried_rates"] for r in rec if r["carried_rates"]] or [np.zeros(0)])
    print(f"# {a.n}x{a.n} single-fibril plain weave, {a.elements} el/fibril, n={system.n} dofs, SDIRK2, "
          f"h={a.h:g} ms, {a.steps} steps, v0={a.v0:g} mm/ms; run wall {wall:.1f} s (incl. the measurement)")
    print(f"# max |w_z| at the end {np.abs(system.nodal(res.w)[:, 2]).max():.3g} mm/ms, "
          f"active contact pairs at the end: {int(np.count_nonzero(system.active_pairs(res.x)))}"
          if hasattr(system, "active_pairs") else "")
    print(f"stage solves: {nst}")
    print(f"full Newton (today, 1 factorisation/iteration): iterations {ref_its.sum()} "
          f"(per stage: mean {ref_its.mean():.2f}, max {ref_its.max()}), factorisations = iterations = {ref_its.sum()}")
    print(f"modified Newton, factorised at each stage start: iterations {st_its.sum()} (mean {st_its.mean():.2f}, "
          f"max {st_its.max()}), factorisations {nst}, all converged: {all(r['stage_conv'] for r in rec)}")
    print(f"   contraction |G_k+1|/|G_k|: median {np.median(st_rates):.2e}, max {st_rates.max():.2e}")
    print(f"modified Newton, carried across stages/steps (refactorise when rate > {a.kappa}): iterations "
          f"{ca_its.sum()} (mean {ca_its.mean():.2f}, max {ca_its.max()}), factorisations "
          f"{carried['factorizations']}, all converged: {all(r['carried_conv'] for r in rec)}")
    if ca_rates.size:
        print(f"   contraction: median {np.median(ca_rates):.2e}, 90% {np.quantile(ca_rates, 0.9):.2e}, "
              f"max {ca_rates.max():.2e}")
    print(f"distance from the full-Newton stage value (relative): stage-start max "
          f"{max(r['d_stage'] for r in rec):.1e}, carried max {max(r['d_carried'] for r in rec):.1e}")
    print(f"stored pattern changes between stage starts: {last_keys['kept_changes']} of {nst - 1}; "
          f"nonzero pattern (zeros dropped) changes: {last_keys['dropped_changes']} of {nst - 1}")
    print("first stages (full its | stage-start its | carried its, contraction rates of the carried factor):")
    for r in rec[:6] + rec[-4:]:
        print(f"  {r['label']:<34} {r['ref_its']} | {r['stage_its']} | {r['carried_its']} "
              f"{['%.1e' % v for v in r['carried_rates']]}")


if __name__ == "__main__":
    main()
