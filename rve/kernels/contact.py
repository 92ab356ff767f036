"""Compiled penalty-contact kernels of the mechanics-only contact term (docs/kernels.md,
docs/contact.md "Compiled kernels").

Contract
--------
Arrays as in ``rve.model.terms.contact.ContactTerm``: ``r`` (n_nodes, 3) centroid positions,
``npl``/``nmi`` (P, 2) chord end nodes of the + and - elements, ``s_plus`` (P, G),
``gap_radius`` (P,), ``s_minus`` (P, G) (used only when ``recompute`` is False: the frozen
table), ``weight`` (P,).

* ``chord_gaps(r, npl, nmi, s_plus, gap_radius, s_minus, recompute)`` -> g (P, G): the
  overlaps, with the formulas of ``rve.physics.contact_forms.chord_gaps``.
* ``penalty_forms(r, npl, nmi, s_plus, gap_radius, s_minus, recompute, weight, penalty,
  onset, jacobian)`` -> ``(act, R (Pa, 4, 3), K (Pa, 4, 3, 4, 3) or None)``: the pairs
  with a point of g > 0 and their penalty residual and tangent: ``chord_geometry`` +
  ``penalty_forces`` of ``rve.physics.contact_forms`` (the reference, formulas there),
  fused in one pass over the points (no (P, G, 4, 3) temporaries).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..threads import run_chunked

#: pairs per thread below which a kernel runs on one thread (``rve.threads.run_chunked``)
MIN_CHUNK = 512

__all__ = ["chord_gaps", "penalty_forms"]

_TINY = 1e-300


@njit(cache=True, nogil=True)
def _gap_point(r, npl, nmi, sp, gr, sm, recompute, p, k):
    ap0, ap1, ap2 = r[npl[p, 0], 0], r[npl[p, 0], 1], r[npl[p, 0], 2]
    am0, am1, am2 = r[nmi[p, 0], 0], r[nmi[p, 0], 1], r[nmi[p, 0], 2]
    e0, e1, e2 = r[npl[p, 1], 0] - ap0, r[npl[p, 1], 1] - ap1, r[npl[p, 1], 2] - ap2
    d0, d1, d2 = r[nmi[p, 1], 0] - am0, r[nmi[p, 1], 1] - am1, r[nmi[p, 1], 2] - am2
    h0, h1, h2 = ap0 - am0, ap1 - am1, ap2 - am2
    t = sp[p, k]
    if recompute:
        dd = d0 * d0 + d1 * d1 + d2 * d2
        if dd > 0:
            hd = h0 * d0 + h1 * d1 + h2 * d2
            ed = e0 * d0 + e1 * d1 + e2 * d2
            s = (hd + t * ed) / dd
            s = min(max(s, 0.0), 1.0)
        else:
            s = 0.0
    else:
        s = sm[p, k]
    j0 = h0 + t * e0 - s * d0
    j1 = h1 + t * e1 - s * d1
    j2 = h2 + t * e2 - s * d2
    return gr[p] - np.sqrt(j0 * j0 + j1 * j1 + j2 * j2)


@njit(cache=True, nogil=True)
def _gaps(r, npl, nmi, sp, gr, sm, recompute, out):
    P, Gn = sp.shape
    for p in range(P):
        for k in range(Gn):
            out[p, k] = _gap_point(r, npl, nmi, sp, gr, sm, recompute, p, k)


@njit(cache=True, nogil=True)
def _select(r, npl, nmi, sp, gr, sm, recompute, thr, mark):
    P, Gn = sp.shape
    n = 0
    for p in range(P):
        hit = False
        for k in range(Gn):
            if _gap_point(r, npl, nmi, sp, gr, sm, recompute, p, k) > thr:
                hit = True
                break
        mark[p] = hit
        if hit:
            n += 1
    return n


@njit(cache=True, nogil=True)
def _forms(r, npl, nmi, sp, gr, sm, recompute, weight, act, Pstar, onset, jacobian, R, K):
    Gn = sp.shape[1]
    c = np.empty(4)
    ds = np.empty((4, 3))
    n = np.empty(3)
    A = np.empty((3, 3))
    cm = (0.0, 0.0, 1.0, -1.0)
    for ia in range(act.size):
        p = act[ia]
        w = weight[p]
        ap0, ap1, ap2 = r[npl[p, 0], 0], r[npl[p, 0], 1], r[npl[p, 0], 2]
        bp0, bp1, bp2 = r[npl[p, 1], 0], r[npl[p, 1], 1], r[npl[p, 1], 2]
        am0, am1, am2 = r[nmi[p, 0], 0], r[nmi[p, 0], 1], r[nmi[p, 0], 2]
        d0, d1, d2 = r[nmi[p, 1], 0] - am0, r[nmi[p, 1], 1] - am1, r[nmi[p, 1], 2] - am2
        dd = d0 * d0 + d1 * d1 + d2 * d2
        ddsafe = dd if dd > 0 else 1.0
        for k in range(Gn):
            t = sp[p, k]
            p0 = ap0 + t * (bp0 - ap0)
            p1 = ap1 + t * (bp1 - ap1)
            p2 = ap2 + t * (bp2 - ap2)
            if recompute:
                st = ((p0 - am0) * d0 + (p1 - am1) * d1 + (p2 - am2) * d2) / ddsafe
                if not dd > 0:
                    st = 0.0
                s = min(max(st, 0.0), 1.0)
                free = (st > 0.0) and (st < 1.0)
            else:
                s = sm[p, k]
                free = False
            j0 = p0 - (am0 + s * d0)
            j1 = p1 - (am1 + s * d1)
            j2 = p2 - (am2 + s * d2)
            rho = np.sqrt(j0 * j0 + j1 * j1 + j2 * j2)
            rs = max(rho, _TINY)
            n[0], n[1], n[2] = j0 / rs, j1 / rs, j2 / rs
            g = gr[p] - rho
            c[0], c[1], c[2], c[3] = 1.0 - t, t, -(1.0 - s), -s
            active = (g > 0.0) and (rho > _TINY)
            if active:
                # penalty law phi'(g), phi''(g) (rve.physics.contact_forms.penalty_law)
                if onset <= 0.0:
                    phi1 = Pstar * g
                    phi2 = Pstar
                elif g < onset:
                    phi1 = Pstar * g * g / (2.0 * onset)
                    phi2 = Pstar * g / onset
                else:
                    phi1 = Pstar * (g - 0.5 * onset)
                    phi2 = Pstar
                f = w * phi1
                for a in range(4):
                    for i in range(3):
                        R[ia, a, i] -= f * c[a] * n[i]
                if not jacobian:
                    continue
                kk = w * phi2
                fr = f / rho
                for i in range(3):
                    for jj in range(3):
                        A[i, jj] = (kk + fr) * (n[i] * n[jj])
                    A[i, i] -= fr
                for a in range(4):
                    for b in range(4):
                        cc = c[a] * c[b]
                        for i in range(3):
                            for jj in range(3):
                                K[ia, a, i, b, jj] += cc * A[i, jj]
                beta = fr * dd
                if free and beta != 0.0:
                    jv = (j0, j1, j2)
                    dv = (d0, d1, d2)
                    for a in range(4):
                        for i in range(3):
                            ds[a, i] = (c[a] * dv[i] - cm[a] * jv[i]) / ddsafe
                    for a in range(4):
                        for i in range(3):
                            bdi = beta * ds[a, i]
                            for b in range(4):
                                for jj in range(3):
                                    K[ia, a, i, b, jj] += bdi * ds[b, jj]


def _prep(r, npl, nmi, s_plus, gap_radius, s_minus):
    r = np.ascontiguousarray(r, dtype=np.float64)
    npl = np.ascontiguousarray(npl, dtype=np.int64)
    nmi = np.ascontiguousarray(nmi, dtype=np.int64)
    sp = np.ascontiguousarray(s_plus, dtype=np.float64)
    gr = np.ascontiguousarray(gap_radius, dtype=np.float64)
    sm = sp if s_minus is None else np.ascontiguousarray(s_minus, dtype=np.float64)
    return r, npl, nmi, sp, gr, sm


def chord_gaps(r, npl, nmi, s_plus, gap_radius, s_minus=None, recompute: bool = True) -> np.ndarray:
    """Overlaps g (P, G) of every point (module docstring)."""
    r, npl, nmi, sp, gr, sm = _prep(r, npl, nmi, s_plus, gap_radius, s_minus)
    out = np.empty(sp.shape)
    rc = bool(recompute)
    run_chunked(sp.shape[0], lambda a, b: _gaps(r, npl[a:b], nmi[a:b], sp[a:b], gr[a:b], sm[a:b], rc, out[a:b]),
                MIN_CHUNK)
    return out


def penalty_forms(r, npl, nmi, s_plus, gap_radius, s_minus, recompute: bool, weight, penalty: float,
                  onset: float = 0.0, jacobian: bool = True):
    """``(act, R, K)`` of the active pairs (module docstring)."""
    r, npl, nmi, sp, gr, sm = _prep(r, npl, nmi, s_plus, gap_radius, s_minus)
    w = np.ascontiguousarray(weight, dtype=np.float64)
    P = sp.shape[0]
    mark = np.zeros(P, np.bool_)
    rc, jac = bool(recompute), bool(jacobian)
    run_chunked(P, lambda a, b: _select(r, npl[a:b], nmi[a:b], sp[a:b], gr[a:b], sm[a:b], rc, 0.0, mark[a:b]),
                MIN_CHUNK)
    act = np.flatnonzero(mark)
    Pa = act.size
    R = np.zeros((Pa, 4, 3))
    K = np.zeros((Pa, 4, 3, 4, 3)) if jacobian else np.zeros((0, 4, 3, 4, 3))
    if Pa:
        run_chunked(Pa, lambda a, b: _forms(r, npl, nmi, sp, gr, sm, rc, w, act[a:b], float(penalty), float(onset),
                                            jac, R[a:b], K[a:b] if jac else K), MIN_CHUNK)
    return act, R, (K if jacobian else None)
