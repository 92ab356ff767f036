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
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..threads import run_chunked

#: pairs per thread below which the kernel runs on one thread (``rve.threads.run_chunked``)
MIN_CHUNK = 512

__all__ = ["frozen_potential"]


@njit(cache=True, nogil=True)
def _asinh_part(z, eta):
    r = np.sqrt(z * z + eta * eta)
    return 0.5 * (z * r + eta * eta * np.arcsinh(z / eta))


@njit(cache=True, nogil=True)
def _point(X, cb, anchor, f0, n0, kT, mu, eta, Dw, Jd, p, g, u, e, t, D):
    """The gap, force ``t`` and (in ``D``) the 3 x 3 stiffness of point (p, g); returns psi
    (0 and t = 0, D = 0 for a point without friction)."""
    M = X.shape[1]
    d = np.zeros(3)
    for i in range(3):
        u[i] = anchor[p, g, i]
    for k in range(M):
        c, w = cb[p, g, k], Dw[p, g, k]
        for i in range(3):
            u[i] += c * X[p, k, i]
            d[i] += w * X[p, k, i]
    for i in range(3):
        for j in range(3):
            u[i] += Jd[p, g, i, j] * d[j]
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
    f, m, k_t = f0[p, g], mu[p, g], kT[p, g]
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
    D = np.zeros((3, 3))
    W = np.zeros((M, 3, 3))
    DW = np.zeros((M, 3, 3))
    for p in range(P):
        for g in range(G):
            psi[p, g] = _point(X, cb, anchor, f0, n0, kT, mu, eta, Dw, Jd, p, g, u, e, t, D)
            if t[0] == 0.0 and t[1] == 0.0 and t[2] == 0.0 and not jacobian:
                continue
            for k in range(M):   # W_k = cb_k I + Dw_k Jd
                for i in range(3):
                    for j in range(3):
                        W[k, i, j] = Dw[p, g, k] * Jd[p, g, i, j] + (cb[p, g, k] if i == j else 0.0)
            for k in range(M):   # R_k += W_k^T t
                for j in range(3):
                    R[p, k, j] += W[k, 0, j] * t[0] + W[k, 1, j] * t[1] + W[k, 2, j] * t[2]
            if not jacobian:
                continue
            for l in range(M):
                for i in range(3):
                    for j in range(3):
                        DW[l, i, j] = D[i, 0] * W[l, 0, j] + D[i, 1] * W[l, 1, j] + D[i, 2] * W[l, 2, j]
            for k in range(M):
                for l in range(M):
                    for i in range(3):
                        for j in range(3):
                            K[p, k, i, l, j] += W[k, 0, i] * DW[l, 0, j] + W[k, 1, i] * DW[l, 1, j] \
                                + W[k, 2, i] * DW[l, 2, j]


def frozen_potential(X, cb, anchor, f0, n0, kT, mu, jacobian: bool, eta: float, Dw, Jd):
    """``(psi, R, K)`` of the frozen-load potential (module docstring)."""
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)   # noqa: E731
    X, cb, anchor, f0, n0, kT, Dw, Jd = map(f, (X, cb, anchor, f0, n0, kT, Dw, Jd))
    mu = f(np.broadcast_to(mu, f0.shape))
    P, M = X.shape[0], X.shape[1]
    psi = np.zeros(f0.shape)
    R = np.zeros((P, M, 3))
    jac = bool(jacobian)
    K = np.zeros((P, M, 3, M, 3)) if jac else np.zeros((0, M, 3, M, 3))
    e = float(eta)
    run_chunked(P, lambda a, b: _forms(X[a:b], cb[a:b], anchor[a:b], f0[a:b], n0[a:b], kT[a:b], mu[a:b], e,
                                       Dw[a:b], Jd[a:b], jac, psi[a:b], R[a:b], K[a:b] if jac else K), MIN_CHUNK)
    return psi, R, (K if jac else None)
