"""Compiled Neo-Hookean element kernel of the director beam (docs/kernels.md).

Contract
--------
``neo_hookean_element_forces(D, W, U, mu, lam, want_tangent, want_dmu)`` with the arrays of a
``BeamBasis`` (D (E, nq, 3, naf), W (E, nq)), U (E, naf, 3) and mu, lam (E, nq) (C-contiguous
float64) returns ``(R (E, naf, 3), K (E, naf, 3, naf, 3) or None, dRdmu (E, nq, naf, 3) or
None)``: the same arrays as ``rve.physics.beam_forms.neo_hookean_element_forces`` (the
reference; formulas there) to rounding, in one pass over the quadrature points with the
3x3 algebra in registers: the per-call numpy overhead of the reference (~20 temporaries of
(E, nq, naf, 3)) is what this removes. The tangent is built on its upper triangle and
mirrored (it is symmetric exactly: the mirrored entry is the same products summed in the
same order). The elements are split over ``rve.threads.solver_threads()`` threads (the kernel
releases the GIL; every element's output is its own, so any split gives the same bits).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..threads import run_chunked

__all__ = ["neo_hookean_element_forces", "min_det_F", "MIN_CHUNK"]

#: elements per thread below which the kernel runs on one thread (``rve.threads.run_chunked``)
MIN_CHUNK = 256


@njit(cache=True, fastmath=False, nogil=True)
def _gradient(D, U, e, q, naf, F, Fi):
    """F[i, J] = sum_a D[J, a] U[a, i] and its inverse Fi at quadrature point q of element e
    (cofactors over the determinant); returns det F."""
    for i in range(3):
        for J in range(3):
            s = 0.0
            for a in range(naf):
                s += D[e, q, J, a] * U[e, a, i]
            F[i, J] = s
    fa, fb, fc = F[0, 0], F[0, 1], F[0, 2]
    fd, fe, ff = F[1, 0], F[1, 1], F[1, 2]
    fg, fh, fi = F[2, 0], F[2, 1], F[2, 2]
    cA, cB, cC = fe * fi - ff * fh, ff * fg - fd * fi, fd * fh - fe * fg
    det = fa * cA + fb * cB + fc * cC
    Fi[0, 0] = cA / det
    Fi[0, 1] = (fc * fh - fb * fi) / det
    Fi[0, 2] = (fb * ff - fc * fe) / det
    Fi[1, 0] = cB / det
    Fi[1, 1] = (fa * fi - fc * fg) / det
    Fi[1, 2] = (fc * fd - fa * ff) / det
    Fi[2, 0] = cC / det
    Fi[2, 1] = (fb * fg - fa * fh) / det
    Fi[2, 2] = (fa * fe - fb * fd) / det
    return det


@njit(cache=True, fastmath=False, nogil=True)
def _tangent_point(D, e, q, naf, G, wmu, wl, wc1, DD, Ke):
    """Quadrature point q's share of the element tangent: wmu D^T D into DD, the lam and
    (mu - lam ln J) G G terms into the upper triangle of Ke."""
    for a in range(naf):
        for b in range(naf):
            s = 0.0
            for J in range(3):
                s += D[e, q, J, a] * D[e, q, J, b]
            DD[a, b] += wmu * s
    for a in range(naf):
        for i in range(3):
            A = 3 * a + i
            ga0, ga1, ga2 = wc1 * G[a, 0], wc1 * G[a, 1], wc1 * G[a, 2]
            gai = wl * G[a, i]
            for b in range(a, naf):
                gbi = G[b, i]
                k0 = i if b == a else 0  # upper triangle: B = 3 b + k >= A
                if wl != 0.0:
                    for k in range(k0, 3):
                        gak = ga0 if k == 0 else (ga1 if k == 1 else ga2)
                        Ke[A, 3 * b + k] += gak * gbi + gai * G[b, k]
                else:  # lam = 0 (nu = 0): the reference skips the lam term too
                    for k in range(k0, 3):
                        gak = ga0 if k == 0 else (ga1 if k == 1 else ga2)
                        Ke[A, 3 * b + k] += gak * gbi


@njit(cache=True, fastmath=False, nogil=True)
def _kernel(D, W, U, mu, lam, want_tangent, want_dmu, R, K, dR):
    E, nq, _, naf = D.shape
    nA = naf * 3
    G = np.empty((naf, 3))
    H = np.empty((naf, 3))
    DD = np.empty((naf, naf))
    F = np.empty((3, 3))
    Fi = np.empty((3, 3))
    Ke = np.empty((nA, nA))
    for e in range(E):
        if want_tangent:
            for a in range(naf):
                for b in range(naf):
                    DD[a, b] = 0.0
            for A in range(nA):
                for B in range(nA):
                    Ke[A, B] = 0.0
        for q in range(nq):
            det = _gradient(D, U, e, q, naf, F, Fi)
            lnJ = np.log(det)
            w = W[e, q]
            wmu = w * mu[e, q]
            wl = w * lam[e, q]
            wc1 = w * (mu[e, q] - lam[e, q] * lnJ)
            for a in range(naf):
                for k in range(3):
                    sg = 0.0
                    sh = 0.0
                    for J in range(3):
                        sg += D[e, q, J, a] * Fi[J, k]
                        sh += D[e, q, J, a] * F[k, J]
                    G[a, k] = sg
                    H[a, k] = sh
                    R[e, a, k] += wmu * sh - wc1 * sg
                    if want_dmu:
                        dR[e, q, a, k] = (sh - sg) * w
            if want_tangent:
                _tangent_point(D, e, q, naf, G, wmu, wl, wc1, DD, Ke)
        if want_tangent:
            for a in range(naf):
                for b in range(a, naf):
                    for i in range(3):
                        Ke[a * 3 + i, b * 3 + i] += DD[a, b]
            for A in range(nA):
                K[e, A, A] = Ke[A, A]
                for B in range(A + 1, nA):
                    K[e, A, B] = Ke[A, B]
                    K[e, B, A] = Ke[A, B]


def neo_hookean_element_forces(D, W, U, mu, lam, want_tangent: bool = True, want_dmu: bool = False):
    """Compiled ``rve.physics.beam_forms.neo_hookean_element_forces`` (module docstring)."""
    E, nq, _, naf = D.shape
    D = np.ascontiguousarray(D, dtype=np.float64)
    W = np.ascontiguousarray(W, dtype=np.float64)
    U = np.ascontiguousarray(U, dtype=np.float64)
    mu = np.ascontiguousarray(np.broadcast_to(np.asarray(mu, float), (E, nq)))
    lam = np.ascontiguousarray(np.broadcast_to(np.asarray(lam, float), (E, nq)))
    R = np.zeros((E, naf, 3))
    K = np.empty((E, naf * 3, naf * 3)) if want_tangent else np.zeros((0, 0, 0))
    dR = np.empty((E, nq, naf, 3)) if want_dmu else np.zeros((0, 0, 0, 0))
    wt, wd = bool(want_tangent), bool(want_dmu)

    def chunk(a, b):  # elements a..b (independent outputs: the same bits on any split)
        _kernel(D[a:b], W[a:b], U[a:b], mu[a:b], lam[a:b], wt, wd, R[a:b], K[a:b] if wt else K,
                dR[a:b] if wd else dR)

    with np.errstate(invalid="ignore", divide="ignore"):
        run_chunked(E, chunk, MIN_CHUNK)
    return (R, K.reshape(E, naf, 3, naf, 3) if want_tangent else None, dR if want_dmu else None)


@njit(cache=True, fastmath=False, nogil=True)
def _min_det(D, X, conn, nn):
    """min over elements and quadrature points of det F, F[i, J] = sum_a D[J, a] U[a, i]
    with U[3 k + c, i] = X[conn[e, k], 3 c + i] (``BeamBasis.element_values``)."""
    E, nq = D.shape[0], D.shape[1]
    out = np.inf
    F = np.empty((3, 3))
    for e in range(E):
        for q in range(nq):
            for i in range(3):
                for J in range(3):
                    s = 0.0
                    for k in range(nn):
                        node = conn[e, k]
                        for c in range(3):
                            s += D[e, q, J, 3 * k + c] * X[node, 3 * c + i]
                    F[i, J] = s
            a, b, c_ = F[0, 0], F[0, 1], F[0, 2]
            d, e_, f = F[1, 0], F[1, 1], F[1, 2]
            g, h, i_ = F[2, 0], F[2, 1], F[2, 2]
            det = a * (e_ * i_ - f * h) - b * (d * i_ - f * g) + c_ * (d * h - e_ * g)
            if det < out:
                out = det
    return out


def min_det_F(D, X, conn) -> float:
    """``BeamBasis.min_det_F`` (the reference: ``det3`` of ``deformation_gradient``) in one
    compiled pass over the quadrature points, reading the nodal state ``X`` (n_nodes, >= 9)
    through the connectivity instead of gathering the element arrays: the admissibility test
    of every stage Newton trial point, where the gather, the batched matmul and the
    determinant's temporaries cost about as much as a residual's beam kernel. Equal to the
    reference to rounding (the 3 x 3 products are summed in another order)."""
    return float(_min_det(np.ascontiguousarray(D, dtype=np.float64), np.ascontiguousarray(X, dtype=np.float64),
                          np.ascontiguousarray(conn, dtype=np.int64), int(conn.shape[1])))
