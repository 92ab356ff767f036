"""Compiled penalty forms of the centroid-curve contact (docs/contact.md "Contact on the
centroid curve", docs/kernels.md).

Contract
--------
``curve_penalty_rows(order, C, Na, end_snap, Xa, Xb, t_next, has_next, has_prev, s_a,
gap_radius, weight, penalty, onset, jacobian)`` -> ``(active (P,) bool, R (P, M, 3), K (P, M,
3, M, 3) or None)`` for the 2P oriented rows of P pairs (row i: points on e+, row P + i:
points on e-; each row's a nodes, then b nodes; M = 2 nn), both rows of a pair added into
the pair's (e+ nodes, e- nodes) layout (``HalfPasses.fold``): the closest point, the
ownership and the penalty residual and tangent of ``rve.physics.contact_curve``
(``curve_geometry`` + ``curve_penalty_forces``, the reference, formulas there), fused in one
pass per point with no (Pr, G, M, 3) temporaries. ``gap_radius`` and ``weight`` are (Pr, G).
The projection stops per point (the reference stops when every point has converged), so
the two agree to rounding (tests/test_kernels_contact_curve.py).

``smooth_penalty_rows(Ha, end_snap, Ya, Sa, Yb, Sb, has_next, t_next, has_prev, gap_radius,
weight, penalty, onset, jacobian)``: the same on the C¹ Hermite contact curves
(``rve.physics.contact_smooth``: ``smooth_geometry`` + ``curve_penalty_forces``): Hermite data
``Y`` (Pr, 4, 3) and stencil matrices ``S`` (Pr, 4, Ms) of each row's two sides, ``Ha`` (G, 4)
the Hermite basis at the points; M = 2 Ms local nodes per pair. It returns ``R``, ``K`` of
the active pairs only (a first pass of overlaps finds them, so no (P, M, 3, M, 3) block is
filled for the inactive candidates). ``smooth_gap_rows(Ha,
end_snap, Ya, Yb, has_next, t_next, has_prev, gap_radius)`` -> (Pr, G): the overlaps alone,
-inf where a point is not owned (``rve.physics.contact_smooth.smooth_gaps``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..threads import run_chunked

__all__ = ["curve_penalty_rows", "smooth_penalty_rows", "smooth_gap_rows"]

#: rows per thread below which the kernel runs on one thread (``rve.threads.run_chunked``)
MIN_CHUNK = 512
_TINY = 1e-300


@njit(cache=True, nogil=True)
def _basis(C, s, N, dN, d2N):
    """Lagrange values and s-derivatives at s from the monomial coefficients C (nn, nn)."""
    nn = C.shape[0]
    xi = 2.0 * s - 1.0
    for a in range(nn):
        v = 0.0
        d = 0.0
        d2 = 0.0
        pw = 1.0  # xi^k
        pw1 = 0.0  # xi^(k-1)
        pw2 = 0.0  # xi^(k-2)
        for k in range(nn):
            v += C[a, k] * pw
            d += k * C[a, k] * pw1
            d2 += k * (k - 1) * C[a, k] * pw2
            pw2 = pw1
            pw1 = pw
            pw = pw * xi
        N[a] = v
        dN[a] = 2.0 * d
        d2N[a] = 4.0 * d2


@njit(cache=True, nogil=True)
def _law(g, P, eps):
    """Line load and stiffness of the penalty law (``penalty_law``)."""
    gp = g if g > 0.0 else 0.0
    if eps <= 0.0:
        return P * gp, (P if g > 0.0 else 0.0)
    if gp < eps:
        return P * gp * gp / (2.0 * eps), (P * gp / eps if g > 0.0 else 0.0)
    return P * (gp - 0.5 * eps), (P if g > 0.0 else 0.0)


@njit(cache=True, nogil=True)
def _project(order, C, end_snap, Xb, r, p, N, dN, d2N):
    nn = C.shape[0]
    d0 = Xb[r, nn - 1, 0] - Xb[r, 0, 0]
    d1 = Xb[r, nn - 1, 1] - Xb[r, 0, 1]
    d2 = Xb[r, nn - 1, 2] - Xb[r, 0, 2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    s = ((p[0] - Xb[r, 0, 0]) * d0 + (p[1] - Xb[r, 0, 1]) * d1 + (p[2] - Xb[r, 0, 2]) * d2) / (dd if dd > 0 else 1.0)
    s = min(max(s, 0.0), 1.0)
    if order == 1:
        return s
    for _ in range(12):
        _basis(C, s, N, dN, d2N)
        f = 0.0
        tt = 0.0
        et2 = 0.0
        for i in range(3):
            q = 0.0
            t = 0.0
            t2 = 0.0
            for b in range(nn):
                q += N[b] * Xb[r, b, i]
                t += dN[b] * Xb[r, b, i]
                t2 += d2N[b] * Xb[r, b, i]
            e = q - p[i]
            f += e * t
            tt += t * t
            et2 += e * t2
        fp = tt + et2
        fp = max(fp, 0.1 * tt)
        step = f / (fp if fp > 0 else 1.0)
        s_new = min(max(s - step, 0.0), 1.0)
        done = abs(s_new - s) <= 1e-15
        s = s_new
        if done:
            break
    if s < end_snap:
        s = 0.0
    elif s > 1.0 - end_snap:
        s = 1.0
    return s


@njit(cache=True, nogil=True)
def _accumulate(Ro, Ko, jacobian, slot, c, m, nv, j, t, t2, rho, interior, f, kk, ds):
    """Add one point's residual ``-f c n`` and tangent (``curve_penalty_forces``) to the
    pair's local arrays, row nodes mapped by ``slot``; ``f``, ``kk`` = w phi', w phi''."""
    M = c.shape[0]
    for k in range(M):
        for ii in range(3):
            Ro[slot[k], ii] -= f * c[k] * nv[ii]
    if not jacobian:
        return
    A = t[0] * t[0] + t[1] * t[1] + t[2] * t[2] - (j[0] * t2[0] + j[1] * t2[1] + j[2] * t2[2])
    Asafe = A if (interior and A > 0) else 1.0
    for k in range(M):
        for ii in range(3):
            ds[k, ii] = (c[k] * t[ii] + m[k] * j[ii]) / Asafe if interior else 0.0
    fr = f / rho
    beta = fr * A
    for k in range(M):
        sk = slot[k]
        for ii in range(3):
            for l in range(M):
                sl = slot[l]
                ckl = c[k] * c[l]
                for jj in range(3):
                    B = (kk + fr) * nv[ii] * nv[jj] - (fr if ii == jj else 0.0)
                    Ko[sk, ii, sl, jj] += ckl * B + beta * ds[k, ii] * ds[l, jj]


@njit(cache=True, nogil=True)
def _pairs(order, C, end_snap, Xa, Xb, t_next, has_next, has_prev, s_a, Na, gr, w, Pstar, eps, jacobian, lo, hi,
           active, R, K):
    """Pairs lo..hi-1: rows i (points on e+) and half + i (points on e-), each folded into
    the pair's (e+ nodes, e- nodes) layout of R[i - lo], K[i - lo]."""
    half = Xa.shape[0] // 2
    nn = C.shape[0]
    M = 2 * nn
    G = s_a.shape[0]
    N = np.empty(nn)
    dN = np.empty(nn)
    d2N = np.empty(nn)
    p = np.empty(3)
    c = np.empty(M)
    m = np.empty(M)
    ds = np.empty((M, 3))
    j = np.empty(3)
    t = np.empty(3)
    t2 = np.empty(3)
    slot = np.empty(M, np.int64)
    for i in range(lo, hi):
        o = i - lo
        for side in range(2):
            r = i + side * half
            for k in range(M):  # the oriented row's (a, b) nodes in the pair's (e+, e-) layout
                slot[k] = k if side == 0 else (k + nn) % M
            for g in range(G):
                for ii in range(3):
                    v = 0.0
                    for a in range(nn):
                        v += Na[g, a] * Xa[r, a, ii]
                    p[ii] = v
                s = _project(order, C, end_snap, Xb, r, p, N, dN, d2N)
                _basis(C, s, N, dN, d2N)
                for ii in range(3):
                    q = 0.0
                    ti = 0.0
                    t2i = 0.0
                    for b in range(nn):
                        q += N[b] * Xb[r, b, ii]
                        ti += dN[b] * Xb[r, b, ii]
                        t2i += d2N[b] * Xb[r, b, ii]
                    j[ii] = p[ii] - q
                    t[ii] = ti
                    t2[ii] = t2i
                rho = np.sqrt(j[0] * j[0] + j[1] * j[1] + j[2] * j[2])
                gap = gr[r, g] - rho
                interior = (s > 0.0) and (s < 1.0)
                tn2 = t_next[r, 0] ** 2 + t_next[r, 1] ** 2 + t_next[r, 2] ** 2
                grow = 0.0
                for ii in range(3):
                    grow += (Xb[r, nn - 1, ii] - p[ii]) * t_next[r, ii]
                grows = grow >= -2.0 * end_snap * tn2
                owned = interior or (s >= 1.0 and ((not has_next[r]) or grows)) or (s <= 0.0 and not has_prev[r])
                if not (owned and gap > 0.0 and rho > _TINY):
                    continue
                active[o] = True
                rr = max(rho, _TINY)
                nv = (j[0] / rr, j[1] / rr, j[2] / rr)
                for a in range(nn):
                    c[a] = Na[g, a]
                    c[nn + a] = -N[a]
                    m[a] = 0.0
                    m[nn + a] = dN[a]
                f1, f2 = _law(gap, Pstar, eps)
                _accumulate(R[o], K[o if jacobian else 0], jacobian, slot, c, m, nv, j, t, t2, rho, interior,
                            w[r, g] * f1, w[r, g] * f2, ds)


def curve_penalty_rows(order: int, C, Na, end_snap: float, Xa, Xb, t_next, has_next, has_prev, s_a, gap_radius,
                       weight, penalty: float, onset: float = 0.0, jacobian: bool = True):
    """``(active, R, K)`` of the oriented rows (module docstring). ``C`` (nn, nn) are the
    basis' monomial coefficients and ``Na`` (G, nn) its values at ``s_a`` (from
    ``rve.physics.contact_curve``: ``lagrange_monomials``, ``curve_basis``), ``end_snap`` its
    ``END_SNAP``."""
    Xa = np.ascontiguousarray(Xa, dtype=np.float64)
    Xb = np.ascontiguousarray(Xb, dtype=np.float64)
    Pr, nn, _ = Xa.shape
    s_a = np.ascontiguousarray(s_a, dtype=np.float64)
    G = s_a.shape[0]
    Na = np.ascontiguousarray(Na, dtype=np.float64).reshape(G, nn)
    C = np.ascontiguousarray(C, dtype=np.float64)
    gr = np.ascontiguousarray(np.broadcast_to(np.asarray(gap_radius, float).reshape(Pr, -1), (Pr, G)))
    w = np.ascontiguousarray(np.broadcast_to(np.asarray(weight, float).reshape(Pr, -1), (Pr, G)))
    tn = np.ascontiguousarray(t_next, dtype=np.float64)
    hn = np.ascontiguousarray(has_next, dtype=np.bool_)
    hp = np.ascontiguousarray(has_prev, dtype=np.bool_)
    M = 2 * nn
    half = Pr // 2
    active = np.zeros(half, np.bool_)
    R = np.zeros((half, M, 3))
    K = np.zeros((half, M, 3, M, 3)) if jacobian else np.zeros((1, M, 3, M, 3))  # one scratch block
    jac, snap = bool(jacobian), float(end_snap)
    run_chunked(half, lambda a, b: _pairs(int(order), C, snap, Xa, Xb, tn, hn, hp, s_a, Na, gr, w, float(penalty),
                                          float(onset), jac, a, b, active[a:b], R[a:b], K[a:b] if jac else K),
                MIN_CHUNK)
    return active, R, (K if jacobian else None)


@njit(cache=True, nogil=True)
def _hermite(s, H, dH, d2H):
    """Cubic Hermite basis (h00, h01, h10, h11) and its s-derivatives at s."""
    s2 = s * s
    s3 = s2 * s
    H[0] = 2 * s3 - 3 * s2 + 1
    H[1] = -2 * s3 + 3 * s2
    H[2] = s3 - 2 * s2 + s
    H[3] = s3 - s2
    dH[0] = 6 * s2 - 6 * s
    dH[1] = -6 * s2 + 6 * s
    dH[2] = 3 * s2 - 4 * s + 1
    dH[3] = 3 * s2 - 2 * s
    d2H[0] = 12 * s - 6
    d2H[1] = -12 * s + 6
    d2H[2] = 6 * s - 4
    d2H[3] = 6 * s - 2


@njit(cache=True, nogil=True)
def _project_hermite(end_snap, Yb, r, p, H, dH, d2H):
    d0 = Yb[r, 1, 0] - Yb[r, 0, 0]
    d1 = Yb[r, 1, 1] - Yb[r, 0, 1]
    d2 = Yb[r, 1, 2] - Yb[r, 0, 2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    s = ((p[0] - Yb[r, 0, 0]) * d0 + (p[1] - Yb[r, 0, 1]) * d1 + (p[2] - Yb[r, 0, 2]) * d2) / (dd if dd > 0 else 1.0)
    s = min(max(s, 0.0), 1.0)
    for _ in range(12):
        _hermite(s, H, dH, d2H)
        f = 0.0
        tt = 0.0
        et2 = 0.0
        for i in range(3):
            q = 0.0
            t = 0.0
            t2 = 0.0
            for b in range(4):
                q += H[b] * Yb[r, b, i]
                t += dH[b] * Yb[r, b, i]
                t2 += d2H[b] * Yb[r, b, i]
            e = q - p[i]
            f += e * t
            tt += t * t
            et2 += e * t2
        fp = max(tt + et2, 0.1 * tt)
        s_new = min(max(s - f / (fp if fp > 0 else 1.0), 0.0), 1.0)
        done = abs(s_new - s) <= 1e-15
        s = s_new
        if done:
            break
    if s < end_snap:
        s = 0.0
    elif s > 1.0 - end_snap:
        s = 1.0
    return s


@njit(cache=True, nogil=True)
def _smooth_point(end_snap, Ya, Sa, Yb, Sb, t_next, has_next, has_prev, Ha, r, g, gr, s_b, H, dH, d2H, p, c, m, j,
                  t, t2):
    """One point of row r on the Hermite curves, its closest point ``s_b[r, g]`` already
    projected (``_smooth_gaps``): fills c, m, j, t, t2; returns ``(gap, rho, free, counted)``
    (counted: owned, overlapping, rho > 0; free: the closest point moves with the nodes, i.e.
    not clamped at a free end)."""
    Ms = Sa.shape[2]
    for ii in range(3):
        v = 0.0
        for a in range(4):
            v += Ha[g, a] * Ya[r, a, ii]
        p[ii] = v
    s = s_b[r, g]
    _hermite(s, H, dH, d2H)
    for ii in range(3):
        q = 0.0
        ti = 0.0
        t2i = 0.0
        for b in range(4):
            q += H[b] * Yb[r, b, ii]
            ti += dH[b] * Yb[r, b, ii]
            t2i += d2H[b] * Yb[r, b, ii]
        j[ii] = p[ii] - q
        t[ii] = ti
        t2[ii] = t2i
    rho = np.sqrt(j[0] * j[0] + j[1] * j[1] + j[2] * j[2])
    gap = gr[r, g] - rho
    interior = (s > 0.0) and (s < 1.0)
    tn2 = t_next[r, 0] ** 2 + t_next[r, 1] ** 2 + t_next[r, 2] ** 2
    grow = 0.0
    for ii in range(3):
        grow += (Yb[r, 1, ii] - p[ii]) * t_next[r, ii]
    grows = grow >= -2.0 * end_snap * tn2
    owned = interior or (s >= 1.0 and ((not has_next[r]) or grows)) or (s <= 0.0 and not has_prev[r])
    counted = owned and gap > 0.0 and rho > _TINY
    free = interior or (s >= 1.0 and has_next[r]) or (s <= 0.0 and has_prev[r])  # ds = 0 only at a free end
    if counted:
        for k in range(Ms):
            ca = 0.0
            cb = 0.0
            mb = 0.0
            for a in range(4):
                ca += Ha[g, a] * Sa[r, a, k]
                cb += H[a] * Sb[r, a, k]
                mb += dH[a] * Sb[r, a, k]
            c[k] = ca
            c[Ms + k] = -cb
            m[k] = 0.0
            m[Ms + k] = mb
    return gap, rho, free, counted


@njit(cache=True, nogil=True)
def _accumulate_point(Ro, Ko, jacobian, slot, c, m, nv, j, t, t2, rho, free, f, kk, ds, B):
    """``_accumulate`` with the point stiffness B (3, 3) formed once per point (the larger
    stencils of the Hermite curve make the (M, M) loop the cost). The point's stiffness
    ``c_k c_l B + beta ds_k ds_l`` is symmetric: only the blocks on and above the diagonal of
    ``Ko`` (in slot order) are added; ``_mirror_blocks`` fills the rest once per pair."""
    M = c.shape[0]
    for k in range(M):
        for ii in range(3):
            Ro[slot[k], ii] -= f * c[k] * nv[ii]
    if not jacobian:
        return
    A = t[0] * t[0] + t[1] * t[1] + t[2] * t[2] - (j[0] * t2[0] + j[1] * t2[1] + j[2] * t2[2])
    Asafe = A if (free and A > 0) else 1.0
    for k in range(M):
        for ii in range(3):
            ds[k, ii] = (c[k] * t[ii] + m[k] * j[ii]) / Asafe if free else 0.0
    fr = f / rho
    beta = fr * A if free else 0.0
    for ii in range(3):
        for jj in range(3):
            B[ii, jj] = (kk + fr) * nv[ii] * nv[jj] - (fr if ii == jj else 0.0)
    for k in range(M):
        sk = slot[k]
        for l in range(k, M):
            sl = slot[l]
            ckl = c[k] * c[l]
            if sk <= sl:
                for ii in range(3):
                    bk = beta * ds[k, ii]
                    for jj in range(3):
                        Ko[sk, ii, sl, jj] += ckl * B[ii, jj] + bk * ds[l, jj]
            else:  # the same entries, transposed into the upper block
                for ii in range(3):
                    bk = beta * ds[k, ii]
                    for jj in range(3):
                        Ko[sl, jj, sk, ii] += ckl * B[ii, jj] + bk * ds[l, jj]


@njit(cache=True, nogil=True)
def _mirror_blocks(Ko):
    """The blocks below the diagonal of a pair's symmetric (M, 3, M, 3) stiffness from those
    above it (``_accumulate_point``)."""
    M = Ko.shape[0]
    for a in range(M):
        for b in range(a + 1, M):
            for ii in range(3):
                for jj in range(3):
                    Ko[b, jj, a, ii] = Ko[a, ii, b, jj]


@njit(cache=True, nogil=True)
def _smooth_pairs(end_snap, Ya, Sa, Yb, Sb, t_next, has_next, has_prev, Ha, gr, s_b, w, Pstar, eps, jacobian, lo,
                  hi, active, R, K):
    """Pairs lo..hi-1 on the Hermite curves (as ``_pairs``), the closest points ``s_b``."""
    half = Ya.shape[0] // 2
    Ms = Sa.shape[2]
    M = 2 * Ms
    G = Ha.shape[0]
    H = np.empty(4)
    dH = np.empty(4)
    d2H = np.empty(4)
    p = np.empty(3)
    c = np.empty(M)
    m = np.empty(M)
    ds = np.empty((M, 3))
    j = np.empty(3)
    t = np.empty(3)
    t2 = np.empty(3)
    slot = np.empty(M, np.int64)
    B = np.empty((3, 3))
    for i in range(lo, hi):
        o = i - lo
        for side in range(2):
            r = i + side * half
            for k in range(M):
                slot[k] = k if side == 0 else (k + Ms) % M
            for g in range(G):
                gap, rho, free, counted = _smooth_point(end_snap, Ya, Sa, Yb, Sb, t_next, has_next, has_prev,
                                                            Ha, r, g, gr, s_b, H, dH, d2H, p, c, m, j, t, t2)
                if not counted:
                    continue
                active[o] = True
                nv = (j[0] / rho, j[1] / rho, j[2] / rho)
                f1, f2 = _law(gap, Pstar, eps)
                _accumulate_point(R[o], K[o if jacobian else 0], jacobian, slot, c, m, nv, j, t, t2, rho, free,
                                  w[r, g] * f1, w[r, g] * f2, ds, B)
        if jacobian and active[o]:
            _mirror_blocks(K[o])


def smooth_penalty_rows(Ha, end_snap: float, Ya, Sa, Yb, Sb, has_next, t_next, has_prev, gap_radius, weight,
                        penalty: float, onset: float = 0.0, jacobian: bool = True):
    """``(active (P,), R, K)`` of the oriented rows on the Hermite curves (module docstring;
    ``R``, ``K`` of the active pairs, in their order); ``Ha`` (G, 4) from
    ``rve.physics.contact_smooth.hermite_basis``, ``end_snap`` its ``END_SNAP``."""
    Ya = np.ascontiguousarray(Ya, dtype=np.float64)
    Yb = np.ascontiguousarray(Yb, dtype=np.float64)
    Sa = np.ascontiguousarray(Sa, dtype=np.float64)
    Sb = np.ascontiguousarray(Sb, dtype=np.float64)
    Pr, _, Ms = Sa.shape
    Ha = np.ascontiguousarray(Ha, dtype=np.float64).reshape(-1, 4)
    G = Ha.shape[0]
    gr = np.ascontiguousarray(np.broadcast_to(np.asarray(gap_radius, float).reshape(Pr, -1), (Pr, G)))
    w = np.ascontiguousarray(np.broadcast_to(np.asarray(weight, float).reshape(Pr, -1), (Pr, G)))
    tn = np.ascontiguousarray(t_next, dtype=np.float64)
    hn = np.ascontiguousarray(has_next, dtype=np.bool_)
    hp = np.ascontiguousarray(has_prev, dtype=np.bool_)
    M = 2 * Ms
    half = Pr // 2
    jac, snap = bool(jacobian), float(end_snap)
    g = np.empty((Pr, G))
    sb = np.empty((Pr, G))  # the closest points, projected once (the pass over the pairs reuses them)
    run_chunked(Pr, lambda a, b: _smooth_gaps(snap, Ya, Yb, tn, hn, hp, Ha, gr, a, b, g[a:b], sb[a:b]), MIN_CHUNK)
    hit = (g > 0.0).any(axis=1)
    sel = np.flatnonzero(hit[:half] | hit[half:])
    rows = np.concatenate([sel, half + sel])
    Ya, Sa, Yb, Sb = Ya[rows], Sa[rows], Yb[rows], Sb[rows]
    tn, hn, hp, gr, w, sb = tn[rows], hn[rows], hp[rows], gr[rows], w[rows], sb[rows]
    n = sel.size
    active = np.zeros(n, np.bool_)
    R = np.zeros((n, M, 3))
    K = np.zeros((n, M, 3, M, 3)) if jacobian else np.zeros((1, M, 3, M, 3))
    run_chunked(n, lambda a, b: _smooth_pairs(snap, Ya, Sa, Yb, Sb, tn, hn, hp, Ha, gr, sb, w, float(penalty),
                                              float(onset), jac, a, b, active[a:b], R[a:b], K[a:b] if jac else K),
                MIN_CHUNK)
    out = np.zeros(half, np.bool_)
    out[sel] = active
    return out, R[active], (K[active] if jacobian else None)


@njit(cache=True, nogil=True)
def _smooth_gaps(end_snap, Ya, Yb, t_next, has_next, has_prev, Ha, gr, lo, hi, out, s_out):
    """Overlaps ``out`` and closest points ``s_out`` of the rows lo..hi-1 (local rows)."""
    G = Ha.shape[0]
    H = np.empty(4)
    dH = np.empty(4)
    d2H = np.empty(4)
    p = np.empty(3)
    for r in range(lo, hi):
        for g in range(G):
            for ii in range(3):
                v = 0.0
                for a in range(4):
                    v += Ha[g, a] * Ya[r, a, ii]
                p[ii] = v
            s = _project_hermite(end_snap, Yb, r, p, H, dH, d2H)
            s_out[r - lo, g] = s
            _hermite(s, H, dH, d2H)
            rr = 0.0
            grow = 0.0
            tn2 = 0.0
            for ii in range(3):
                q = 0.0
                for b in range(4):
                    q += H[b] * Yb[r, b, ii]
                rr += (p[ii] - q) ** 2
                grow += (Yb[r, 1, ii] - p[ii]) * t_next[r, ii]
                tn2 += t_next[r, ii] ** 2
            interior = (s > 0.0) and (s < 1.0)
            grows = grow >= -2.0 * end_snap * tn2
            owned = interior or (s >= 1.0 and ((not has_next[r]) or grows)) or (s <= 0.0 and not has_prev[r])
            out[r - lo, g] = gr[r, g] - np.sqrt(rr) if owned else -np.inf


def smooth_gap_rows(Ha, end_snap: float, Ya, Yb, has_next, t_next, has_prev, gap_radius):
    """Overlaps (Pr, G) of the oriented rows on the Hermite curves, -inf where not owned."""
    Ya = np.ascontiguousarray(Ya, dtype=np.float64)
    Yb = np.ascontiguousarray(Yb, dtype=np.float64)
    Pr = Ya.shape[0]
    Ha = np.ascontiguousarray(Ha, dtype=np.float64).reshape(-1, 4)
    G = Ha.shape[0]
    gr = np.ascontiguousarray(np.broadcast_to(np.asarray(gap_radius, float).reshape(Pr, -1), (Pr, G)))
    tn = np.ascontiguousarray(t_next, dtype=np.float64)
    hn = np.ascontiguousarray(has_next, dtype=np.bool_)
    hp = np.ascontiguousarray(has_prev, dtype=np.bool_)
    out = np.empty((Pr, G))
    s_b = np.empty((Pr, G))
    snap = float(end_snap)
    run_chunked(Pr, lambda a, b: _smooth_gaps(snap, Ya, Yb, tn, hn, hp, Ha, gr, a, b, out[a:b], s_b[a:b]), MIN_CHUNK)
    return out
