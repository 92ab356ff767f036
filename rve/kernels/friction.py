"""Compiled frozen-load friction potential: the predictor's forms of the frictional static
step (docs/kernels.md, docs/contact.md "Cost on a weave").

Contract
--------
``frozen_potential(X, cb, anchor, f0, n0, kT, mu, jacobian, eta, Dw, Jd)`` ->
``(psi (P, G), R (P, M, 3), K (P, M, 3, M, 3) or None)``: the same arrays, to rounding, as
``rve.physics.friction_forms.frozen_potential`` with ``turn=(Dw, Jd)`` (the reference;
formulas, the smoothed cone with ``eta > 0`` and the turn's matrix weights ``W_k = cb_k I +
Dw_k Jd`` there), fused in one pass over the points: per point the gap ``u = anchor + sum_k
cb_k X_k + Jd sum_k Dw_k X_k``, ``e = (I - n0 n0^T) u``, the return map (or the smoothed
cone), ``psi``, ``R_k += W_k^T t`` and ``K_kl += W_k^T D W_l``, with no (P, G, M, 3, 3)
temporaries. ``X`` (P, M, 3) local nodes, ``cb``/``Dw`` (P, G, M), ``anchor``/``n0`` (P, G,
3), ``f0``/``kT``/``mu`` (P, G), ``Jd`` (P, G, 3, 3).

``frame_frozen_potential(Y, cb, anchor, f0, n0, kT, mu, jacobian, eta, (Dw, Jd, gw, Jg))``:
the same for the section frame's potential (``friction_forms.frame_frozen_potential``), in
the centroids and g1 of the local nodes ``Y`` (P, M, 6): ``W_k = (cb_k I + Dw_k Jd, gw_k
Jg)`` (3 x 6), ``R`` (P, M, 6), ``K`` (P, M, 6, M, 6).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..threads import run_chunked

#: pairs per thread below which the kernel runs on one thread (``rve.threads.run_chunked``)
MIN_CHUNK = 512

__all__ = ["frozen_potential", "frame_frozen_potential", "friction_forces"]


@njit(cache=True, nogil=True)
def _asinh_part(z, eta):
    r = np.sqrt(z * z + eta * eta)
    return 0.5 * (z * r + eta * eta * np.arcsinh(z / eta))


@njit(cache=True, nogil=True)
def _point(X, cb, anchor, f0, n0, kT, mu, eta, Dw, Jd, p, g, u, e, t, D):
    """The gap, force ``t`` and (in ``D``) the 3 x 3 stiffness of point (p, g); returns psi
    (0 and t = 0, D = 0 for a point without friction)."""
    M = X.shape[1]
    d0, d1, d2 = 0.0, 0.0, 0.0
    for i in range(3):
        u[i] = anchor[p, g, i]
    for k in range(M):
        c, w = cb[p, g, k], Dw[p, g, k]
        for i in range(3):
            u[i] += c * X[p, k, i]
        d0 += w * X[p, k, 0]
        d1 += w * X[p, k, 1]
        d2 += w * X[p, k, 2]
    for i in range(3):
        u[i] += Jd[p, g, i, 0] * d0 + Jd[p, g, i, 1] * d1 + Jd[p, g, i, 2] * d2
    return _cone(u, n0, f0[p, g], mu[p, g], kT[p, g], eta, p, g, e, t, D)


@njit(cache=True, nogil=True)
def _cone(u, n0, f, m, k_t, eta, p, g, e, t, D):
    """The tangential part ``e`` of the gap ``u`` at point (p, g), the return map's (or the
    smoothed cone's) force ``t`` and stiffness ``D``; returns psi."""
    un = n0[p, g, 0] * u[0] + n0[p, g, 1] * u[1] + n0[p, g, 2] * u[2]
    en2 = 0.0
    for i in range(3):
        e[i] = u[i] - un * n0[p, g, i]
        en2 += e[i] * e[i]
    en = np.sqrt(en2)
    for i in range(3):
        t[i] = 0.0
        for j in range(3):
            D[i, j] = 0.0
    if eta > 0.0:
        if not (f > 0.0 and m > 0.0 and k_t > 0.0):
            return 0.0
        L = m * f
        delta = L / k_t
        x = en / delta
        r = np.sqrt((x - 1.0) ** 2 + eta * eta)
        c0 = 0.5 * (1.0 - np.sqrt(1.0 + eta * eta))
        phi = 0.5 * (x + 1.0 - r) - c0
        dphi = 0.5 * (1.0 - (x - 1.0) / r)
        Phi = 0.25 * x * x + 0.5 * x - 0.5 * (_asinh_part(x - 1.0, eta) - _asinh_part(-1.0, eta)) - c0 * x
        over = dphi if x < 1e-8 else phi / x
        inv = 1.0 / en if en > 0 else 1.0
        a, b = k_t * dphi, k_t * over
        for i in range(3):
            t[i] = L * phi * e[i] * inv
        for i in range(3):
            for j in range(3):
                eij = e[i] * e[j] * inv * inv
                pij = (1.0 if i == j else 0.0) - n0[p, g, i] * n0[p, g, j]
                D[i, j] = a * eij + b * (pij - eij)
        return L * delta * Phi
    L = m * f if (f > 0.0 and m > 0.0) else 0.0
    if not L > 0.0:
        return 0.0
    if k_t * en <= L:
        for i in range(3):
            t[i] = k_t * e[i]
            for j in range(3):
                D[i, j] = k_t * ((1.0 if i == j else 0.0) - n0[p, g, i] * n0[p, g, j])
        return 0.5 * k_t * en * en
    inv = 1.0 / en if en > 0 else 1.0
    s = L * inv
    kts = k_t if k_t > 0 else 1.0
    for i in range(3):
        t[i] = s * e[i]
        for j in range(3):
            eij = e[i] * e[j] * inv * inv
            D[i, j] = s * ((1.0 if i == j else 0.0) - n0[p, g, i] * n0[p, g, j] - eij)
    return L * en - 0.5 * L * L / kts


@njit(cache=True, nogil=True)
def _forms(X, cb, anchor, f0, n0, kT, mu, eta, Dw, Jd, jacobian, psi, R, K):
    P, M = X.shape[0], X.shape[1]
    G = cb.shape[1]
    u, e, t = np.zeros(3), np.zeros(3), np.zeros(3)
    D, DJ, JtD, JtDJ = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    for p in range(P):
        for g in range(G):
            if not (f0[p, g] > 0.0 and mu[p, g] > 0.0):
                continue          # no frozen load: no potential, force or stiffness
            psi[p, g] = _point(X, cb, anchor, f0, n0, kT, mu, eta, Dw, Jd, p, g, u, e, t, D)
            # R_k += W_k^T t, W_k = cb_k I + Dw_k Jd
            Jt0 = Jd[p, g, 0, 0] * t[0] + Jd[p, g, 1, 0] * t[1] + Jd[p, g, 2, 0] * t[2]
            Jt1 = Jd[p, g, 0, 1] * t[0] + Jd[p, g, 1, 1] * t[1] + Jd[p, g, 2, 1] * t[2]
            Jt2 = Jd[p, g, 0, 2] * t[0] + Jd[p, g, 1, 2] * t[1] + Jd[p, g, 2, 2] * t[2]
            for k in range(M):
                a, b = cb[p, g, k], Dw[p, g, k]
                R[p, k, 0] += a * t[0] + b * Jt0
                R[p, k, 1] += a * t[1] + b * Jt1
                R[p, k, 2] += a * t[2] + b * Jt2
            if not jacobian:
                continue
            # K_kl = W_k^T D W_l = cb_k cb_l D + cb_k Dw_l D Jd + Dw_k cb_l Jd^T D + Dw_k Dw_l Jd^T D Jd
            for i in range(3):
                for j in range(3):
                    DJ[i, j] = D[i, 0] * Jd[p, g, 0, j] + D[i, 1] * Jd[p, g, 1, j] + D[i, 2] * Jd[p, g, 2, j]
                    JtD[i, j] = Jd[p, g, 0, i] * D[0, j] + Jd[p, g, 1, i] * D[1, j] + Jd[p, g, 2, i] * D[2, j]
            for i in range(3):
                for j in range(3):
                    JtDJ[i, j] = Jd[p, g, 0, i] * DJ[0, j] + Jd[p, g, 1, i] * DJ[1, j] + Jd[p, g, 2, i] * DJ[2, j]
            for k in range(M):
                ak, bk = cb[p, g, k], Dw[p, g, k]
                for l in range(M):
                    al, bl = cb[p, g, l], Dw[p, g, l]
                    c1, c2, c3, c4 = ak * al, ak * bl, bk * al, bk * bl
                    for i in range(3):
                        for j in range(3):
                            K[p, k, i, l, j] += c1 * D[i, j] + c2 * DJ[i, j] + c3 * JtD[i, j] + c4 * JtDJ[i, j]


def _potential(kernel, nc: int, Y, cb, anchor, f0, n0, kT, mu, jacobian: bool, eta: float, turn):
    """``(psi, R (P, M, nc), K or None)``: ``kernel(Y, cb, anchor, f0, n0, kT, mu, eta, *turn,
    jacobian, psi, R, K)`` run over chunks of the pairs (``rve.threads.run_chunked``) on
    contiguous float64 copies of its inputs."""
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)   # noqa: E731
    Y, cb, anchor, f0, n0, kT = map(f, (Y, cb, anchor, f0, n0, kT))
    turn = tuple(map(f, turn))
    mu = f(np.broadcast_to(mu, f0.shape))
    P, M = Y.shape[0], Y.shape[1]
    psi = np.zeros(f0.shape)
    R = np.zeros((P, M, nc))
    jac = bool(jacobian)
    K = np.zeros((P, M, nc, M, nc)) if jac else np.zeros((0, M, nc, M, nc))
    e = float(eta)

    def chunk(a, b):
        kernel(Y[a:b], cb[a:b], anchor[a:b], f0[a:b], n0[a:b], kT[a:b], mu[a:b], e, *(t[a:b] for t in turn), jac,
               psi[a:b], R[a:b], K[a:b] if jac else K)

    run_chunked(P, chunk, MIN_CHUNK)
    return psi, R, (K if jac else None)


def frozen_potential(X, cb, anchor, f0, n0, kT, mu, jacobian: bool, eta: float, Dw, Jd):
    """``(psi, R, K)`` of the frozen-load potential (module docstring)."""
    return _potential(_forms, 3, X, cb, anchor, f0, n0, kT, mu, jacobian, eta, (Dw, Jd))


@njit(cache=True, nogil=True)
def _frame_forms(Y, cb, anchor, f0, n0, kT, mu, eta, Dw, Jd, gw, Jg, jacobian, psi, R, K):
    P, M = Y.shape[0], Y.shape[1]
    G = cb.shape[1]
    u, e, t = np.zeros(3), np.zeros(3), np.zeros(3)
    D = np.zeros((3, 3))
    W = np.zeros((M, 3, 6))
    DW = np.zeros((M, 3, 6))
    for p in range(P):
        for g in range(G):
            if not (f0[p, g] > 0.0 and mu[p, g] > 0.0):
                continue          # no frozen load: no potential, force or stiffness
            # W_k = (cb_k I + Dw_k Jd, gw_k Jg): the gap's weights of node k's centroid and g1
            for k in range(M):
                a, b, c = cb[p, g, k], Dw[p, g, k], gw[p, g, k]
                for i in range(3):
                    for j in range(3):
                        W[k, i, j] = b * Jd[p, g, i, j] + (a if i == j else 0.0)
                        W[k, i, 3 + j] = c * Jg[p, g, i, j]
            for i in range(3):
                u[i] = anchor[p, g, i]
            for k in range(M):
                for i in range(3):
                    acc = 0.0
                    for c in range(6):
                        acc += W[k, i, c] * Y[p, k, c]
                    u[i] += acc
            psi[p, g] = _cone(u, n0, f0[p, g], mu[p, g], kT[p, g], eta, p, g, e, t, D)
            for k in range(M):
                for c in range(6):
                    R[p, k, c] += W[k, 0, c] * t[0] + W[k, 1, c] * t[1] + W[k, 2, c] * t[2]
            if not jacobian:
                continue
            for l in range(M):
                for i in range(3):
                    for c in range(6):
                        DW[l, i, c] = D[i, 0] * W[l, 0, c] + D[i, 1] * W[l, 1, c] + D[i, 2] * W[l, 2, c]
            for k in range(M):
                for c in range(6):
                    for l in range(M):
                        for d in range(6):
                            K[p, k, c, l, d] += (W[k, 0, c] * DW[l, 0, d] + W[k, 1, c] * DW[l, 1, d]
                                                 + W[k, 2, c] * DW[l, 2, d])


def frame_frozen_potential(Y, cb, anchor, f0, n0, kT, mu, jacobian: bool, eta: float, turn):
    """``(psi (P, G), R (P, M, 6), K (P, M, 6, M, 6) or None)`` of the section frame's
    frozen-load potential at local nodes ``Y`` (P, M, 6) (centroids, g1), ``turn = (Dw, Jd, gw,
    Jg)``: the arrays of ``rve.physics.friction_forms.frame_frozen_potential``."""
    return _potential(_frame_forms, 6, Y, cb, anchor, f0, n0, kT, mu, jacobian, eta, turn)


@njit(cache=True, nogil=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True, nogil=True)
def _skew(a, S):
    S[0, 0], S[0, 1], S[0, 2] = 0.0, -a[2], a[1]
    S[1, 0], S[1, 1], S[1, 2] = a[2], 0.0, -a[0]
    S[2, 0], S[2, 1], S[2, 2] = -a[1], a[0], 0.0


@njit(cache=True, nogil=True)
def _mm(A, B, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]


@njit(cache=True, nogil=True)
def _weighted(Wt, X, p, g, out):
    """``out = sum_k Wt[p, g, k] X[p, k]`` (3,): a point's vector from its local nodes."""
    for i in range(3):
        out[i] = 0.0
    for k in range(X.shape[1]):
        for i in range(3):
            out[i] += Wt[p, g, k] * X[p, k, i]


@njit(cache=True, nogil=True)
def _turn(a, r, h, out, J, V, W):
    """``out = R a`` (the smallest rotation from ``r`` to ``h``) and ``J = d(R a)/dh``
    (``rve.physics.friction_forms.turned_anchor``; ``V`` (3, 3), ``W`` (7, 3, 3): work)."""
    v, w, z = V[0], V[1], V[2]
    _cross(r, h, v)
    c1 = 1.0 + r[0] * h[0] + r[1] * h[1] + r[2] * h[2]
    _cross(v, a, w)
    _cross(v, w, z)
    for i in range(3):
        out[i] = a[i] + w[i] + z[i] / c1
    Sr, Sa, Sw, Sv, dw, t1, t2 = W[0], W[1], W[2], W[3], W[4], W[5], W[6]
    _skew(r, Sr)
    _skew(a, Sa)
    _skew(w, Sw)
    _skew(v, Sv)
    _mm(Sa, Sr, dw)
    for i in range(3):
        for j in range(3):
            dw[i, j] = -dw[i, j]
    _mm(Sw, Sr, t1)
    _mm(Sv, dw, t2)
    for i in range(3):
        for j in range(3):
            J[i, j] = dw[i, j] + (t2[i, j] - t1[i, j]) / c1 - z[i] * r[j] / (c1 * c1)


@njit(cache=True, nogil=True)
def _law_point(c, n, rho, gact, cb, D, X, anchor, d_ref, f, kT, mu, turn, p, g, e, t, h, J, Mv, hM, R, V, W):
    """The trial gap ``e``, force ``t`` and the residual ``R[p] += c t + D C`` of point
    (p, g); with the turn also ``h`` (the - side's direction), ``J = d(R anchor)/dh``, ``Mv
    = n x t`` and ``hM = h x Mv``; ``V`` (6, 3) and ``W`` (7+, 3, 3) work space. Returns ``(active, stick, |e|,
    n.u, |d|)``."""
    M = X.shape[1]
    act = gact[p, g] and f[p, g] > 0.0 and mu[p, g] > 0.0
    jb, d, ua = V[0], V[1], V[2]
    TV, TW = V[3:6], W[:7]
    _weighted(cb, X, p, g, jb)
    dnorm = 1.0
    if turn:
        _weighted(D, X, p, g, d)
        dn = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        dnorm = dn if dn > 0 else 1.0
        for i in range(3):
            h[i] = d[i] / dnorm
        _turn(anchor[p, g], d_ref[p, g], h, ua, J, TV, TW)
    else:
        for i in range(3):
            ua[i] = anchor[p, g, i]
    un = n[p, g, 0] * (ua[0] + jb[0]) + n[p, g, 1] * (ua[1] + jb[1]) + n[p, g, 2] * (ua[2] + jb[2])
    en2 = 0.0
    for i in range(3):
        e[i] = ua[i] + jb[i] - un * n[p, g, i]
        en2 += e[i] * e[i]
    en = np.sqrt(en2)
    limit = mu[p, g] * f[p, g]
    stick = act and kT[p, g] * en <= limit
    slip = act and not stick
    scale = kT[p, g] if stick else (limit / (en if en > 0 else 1.0) if slip else 0.0)
    for i in range(3):
        t[i] = scale * e[i]
    for k in range(M):
        for i in range(3):
            R[p, k, i] += c[p, g, k] * t[i]
    if turn:
        r_a = rho[p, g] if act else 0.0
        _cross(n[p, g], t, Mv)
        _cross(h, Mv, hM)
        for k in range(M):
            for i in range(3):
                R[p, k, i] += D[p, g, k] * r_a / dnorm * hM[i]
    return act, stick, en, un, dnorm


@njit(cache=True, nogil=True)
def _law_tangent(c, ds, n, rho, dc_ds, cb, D, Dp, X, f, kN, kT, mu, turn, p, g, stick, en, un, dnorm, e, t, h,
                 J, Q, dT, K, dE, V, W):
    """``K[p] += c_k dt/dX_l + t dc_k/dX_l`` of an active point (p, g); fills ``Q`` (M, 3, 3)
    = dj/dX_l and ``dT`` (M, 3, 3) = dt/dX_l for the couple's tangent, and with the turn
    ``V[4]`` = ``q2 = sum_k Dp_k X_k`` (the direction's derivative in s-; ``dE`` (M, 3, 3),
    ``V`` (5, 3) and ``W`` (5, 3, 3): work space)."""
    M = X.shape[1]
    jd, ehat, w2, q2 = V[0], V[1], V[2], V[4]
    Pn, Ph, Jd, PJd, proj = W[0], W[1], W[2], W[3], W[4]
    rho_s = rho[p, g]
    _weighted(dc_ds, X, p, g, jd)
    for i in range(3):
        for j in range(3):
            Pn[i, j] = (1.0 if i == j else 0.0) - n[p, g, i] * n[p, g, j]
    if turn:
        for i in range(3):
            for j in range(3):
                Ph[i, j] = (1.0 if i == j else 0.0) - h[i] * h[j]
        _mm(J, Ph, Jd)
        for i in range(3):
            for j in range(3):
                Jd[i, j] /= dnorm
        _mm(Pn, Jd, PJd)
        _weighted(Dp, X, p, g, q2)
        for i in range(3):
            w2[i] = PJd[i, 0] * q2[0] + PJd[i, 1] * q2[1] + PJd[i, 2] * q2[2]
    for l in range(M):
        for i in range(3):
            for j in range(3):
                Q[l, i, j] = (c[p, g, l] if i == j else 0.0) + jd[i] * ds[p, g, l, j]
        for j in range(3):
            eq = e[0] * Q[l, 0, j] + e[1] * Q[l, 1, j] + e[2] * Q[l, 2, j]
            for i in range(3):
                pq = Pn[i, 0] * Q[l, 0, j] + Pn[i, 1] * Q[l, 1, j] + Pn[i, 2] * Q[l, 2, j]
                dE[l, i, j] = cb[p, g, l] * Pn[i, j] - (un / rho_s) * pq - n[p, g, i] * eq / rho_s
                if turn:   # dd/dX_l = D_l I + q2 ds_l^T (the direction at the closest point)
                    dE[l, i, j] += D[p, g, l] * PJd[i, j] + w2[i] * ds[p, g, l, j]
    enn = en if en > 0 else 1.0
    for i in range(3):
        ehat[i] = e[i] / enn
    for i in range(3):
        for j in range(3):
            proj[i, j] = (1.0 if i == j else 0.0) - ehat[i] * ehat[j]
    a_slip = mu[p, g] * f[p, g] / enn
    for l in range(M):
        for i in range(3):
            for j in range(3):
                if stick:
                    dT[l, i, j] = kT[p, g] * dE[l, i, j]
                else:   # slip: mu e_hat df + (mu f/|e|)(I - e_hat e_hat^T) dE, df_l = -kN c_l n^T
                    dT[l, i, j] = a_slip * (proj[i, 0] * dE[l, 0, j] + proj[i, 1] * dE[l, 1, j]
                                            + proj[i, 2] * dE[l, 2, j]) \
                        - ehat[i] * kN[p, g] * mu[p, g] * c[p, g, l] * n[p, g, j]
    for k in range(M):
        ck, dk = c[p, g, k], dc_ds[p, g, k]
        for l in range(M):
            for i in range(3):
                for j in range(3):
                    K[p, k, i, l, j] += ck * dT[l, i, j] + dk * t[i] * ds[p, g, l, j]


@njit(cache=True, nogil=True)
def _couple_tangent(n, rho, ds, D, Dp, p, g, dnorm, t, h, Mv, hM, Q, dT, K, V, W):
    """``K[p] += D_k dC/dX_l + Dp_k C ds_l^T`` of an active point (p, g), ``C = rho h x (n x
    t) / |d|`` with ``dd/dX_l = D_l I + q2 ds_l^T`` (``q2`` in ``V[4]``, ``_law_tangent``;
    ``rve.physics.friction_forms._couple_tangent``; ``V`` (5, 3), ``W`` (10, 3, 3): work
    space)."""
    M = Q.shape[0]
    inv_d = 1.0 / dnorm
    r_a = rho[p, g]
    Sh, Sn, St, SM, ShSt, ShSn, dn_l, dh_l, dhM, tmp = W[0], W[1], W[2], W[3], W[4], W[5], W[6], W[7], W[8], W[9]
    drho, pq2, q2 = V[0], V[1], V[4]
    hq2 = h[0] * q2[0] + h[1] * q2[1] + h[2] * q2[2]
    for i in range(3):
        pq2[i] = q2[i] - h[i] * hq2
    _skew(h, Sh)
    _skew(n[p, g], Sn)
    _skew(t, St)
    _skew(Mv, SM)
    _mm(Sh, St, ShSt)
    _mm(Sh, Sn, ShSn)
    for l in range(M):
        for j in range(3):
            drho[j] = n[p, g, 0] * Q[l, 0, j] + n[p, g, 1] * Q[l, 1, j] + n[p, g, 2] * Q[l, 2, j]
            for i in range(3):
                dn_l[i, j] = (Q[l, i, j] - n[p, g, i] * drho[j]) / r_a
                dh_l[i, j] = (D[p, g, l] * ((1.0 if i == j else 0.0) - h[i] * h[j]) + pq2[i] * ds[p, g, l, j]) * inv_d
        # d(h x (n x t)) = -S(M) dh - S(h) S(t) dn + S(h) S(n) dt
        _mm(SM, dh_l, dhM)
        _mm(ShSt, dn_l, tmp)
        for i in range(3):
            for j in range(3):
                dhM[i, j] = -dhM[i, j] - tmp[i, j] + (ShSn[i, 0] * dT[l, 0, j] + ShSn[i, 1] * dT[l, 1, j]
                                                      + ShSn[i, 2] * dT[l, 2, j])
        dlh = D[p, g, l]
        for k in range(M):
            Dk, Dpk = D[p, g, k], Dp[p, g, k]
            if Dk == 0.0 and Dpk == 0.0:
                continue
            for i in range(3):
                for j in range(3):
                    ddn = dlh * h[j] + hq2 * ds[p, g, l, j]
                    dC = inv_d * (hM[i] * drho[j] + r_a * dhM[i, j]) - r_a * inv_d * inv_d * hM[i] * ddn
                    K[p, k, i, l, j] += Dk * dC + Dpk * r_a * inv_d * hM[i] * ds[p, g, l, j]


@njit(cache=True, nogil=True)
def _law_forms(c, ds, n, rho, gact, dc_ds, cb, D, Dp, X, anchor, d_ref, f, kN, kT, mu, jacobian, turn, R, K):
    P, M = X.shape[0], X.shape[1]
    G = c.shape[1]
    e, t, h, Mv, hM = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    J = np.zeros((3, 3))
    Q, dT, dE = np.zeros((M, 3, 3)), np.zeros((M, 3, 3)), np.zeros((M, 3, 3))
    V, W = np.zeros((6, 3)), np.zeros((10, 3, 3))
    for p in range(P):
        for g in range(G):
            act, stick, en, un, dnorm = _law_point(c, n, rho, gact, cb, D, X, anchor, d_ref, f, kT, mu, turn, p, g,
                                                   e, t, h, J, Mv, hM, R, V, W)
            if not jacobian or not act:
                continue
            _law_tangent(c, ds, n, rho, dc_ds, cb, D, Dp, X, f, kN, kT, mu, turn, p, g, stick, en, un, dnorm, e, t,
                         h, J, Q, dT, K, dE, V, W)
            if turn:
                _couple_tangent(n, rho, ds, D, Dp, p, g, dnorm, t, h, Mv, hM, Q, dT, K, V, W)


def friction_forces(c, ds, n, rho, active, dc_ds, cb, X, anchor, f, kN, kT, mu, jacobian: bool, D=None, d_ref=None,
                    Dp=None):
    """``(R (P, M, 3), K (P, M, 3, M, 3) or None)`` of the law: the same arrays, to rounding,
    as ``rve.physics.friction_forms.friction_forces`` (the reference) from the geometry's
    fields ``c``, ``ds``, ``n``, ``rho``, ``active``, ``dc_ds``, the material weights ``cb``
    (P, G, M) at the history's ``s_bar``, the local nodes ``X``, the history's ``anchor`` and,
    with the anchor's turn, ``d_ref`` (P, G, 3), the - side's direction weights ``D`` (P, G,
    M) at the closest point and their derivative ``Dp`` in it (None: zero, the chord's);
    ``f``, ``kN``, ``kT``, ``mu`` (P, G)."""
    g = lambda a: np.ascontiguousarray(a, dtype=np.float64)   # noqa: E731
    c, ds, n, rho, dc_ds, cb, X, anchor, f, kN, kT = map(g, (c, ds, n, rho, dc_ds, cb, X, anchor, f, kN, kT))
    mu = g(np.broadcast_to(mu, f.shape))
    act = np.ascontiguousarray(active, dtype=np.bool_)
    turn = d_ref is not None
    D = g(D) if turn else np.zeros((0, 1, 1))
    Dp = (np.zeros_like(D) if Dp is None else g(Dp)) if turn else D
    d_ref = g(d_ref) if turn else np.zeros((0, 1, 3))
    P, M = X.shape[0], X.shape[1]
    R = np.zeros((P, M, 3))
    jac = bool(jacobian)
    K = np.zeros((P, M, 3, M, 3)) if jac else np.zeros((0, M, 3, M, 3))
    run_chunked(P, lambda a, b: _law_forms(c[a:b], ds[a:b], n[a:b], rho[a:b], act[a:b], dc_ds[a:b], cb[a:b],
                                           D[a:b] if turn else D, Dp[a:b] if turn else Dp, X[a:b], anchor[a:b],
                                           d_ref[a:b] if turn else d_ref, f[a:b], kN[a:b], kT[a:b], mu[a:b], jac,
                                           turn, R[a:b], K[a:b] if jac else K), MIN_CHUNK)
    return R, (K if jac else None)
