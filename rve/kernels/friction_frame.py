"""Compiled refreeze of the section frame's loads: the per-point part of
``FrictionTerm.loads_at`` with ``friction.frame: section`` (docs/kernels.md, docs/contact.md
"Where the section frame's predictor iterations go").

Contract
--------
``frame_refreeze(X, G, s_bar, anchor, d_ref, m_ref, s_star, n, rho, active, weights,
directions, director_weights)`` -> ``(Dw, Jd, gw, Jg, anchor', h, b_hat)``: the arrays of
the numpy reference ``rve.physics.friction_forms.frame_refreeze`` (same arguments: the
weights functions are evaluated here, once each), to rounding (tests/test_kernels_friction.py),
with the frame's turn of ``a = -rho n`` frozen linear in the - direction and g1 (``Jd``,
``Jg``), the history moved to ``s_star`` (``h``, ``b_hat``) and the anchor less the turn's
linear part computed in one pass per point.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..threads import run_chunked
from .friction import MIN_CHUNK, _cross, _mm, _skew, _weighted

__all__ = ["frame_refreeze"]


@njit(cache=True, nogil=True)
def _frame_at(X, G, D, gw, p, g, h, gg, bh, wh):
    """The - direction ``h``, g1 ``gg`` and the section frame ``(h, bh, wh)`` of point
    (p, g); returns ``(|d|, |b|, h . g)``."""
    _weighted(D, X, p, g, h)
    dn = np.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
    s = dn if dn > 0.0 else 1.0
    for i in range(3):
        h[i] /= s
    _weighted(gw, G, p, g, gg)
    hg = h[0] * gg[0] + h[1] * gg[1] + h[2] * gg[2]
    for i in range(3):
        bh[i] = gg[i] - hg * h[i]
    bn = np.sqrt(bh[0] * bh[0] + bh[1] * bh[1] + bh[2] * bh[2])
    s = bn if bn > 0.0 else 1.0
    for i in range(3):
        bh[i] /= s
    _cross(h, bh, wh)
    return dn, bn, hg


@njit(cache=True, nogil=True)
def _turn_jacobians(h, gg, bh, bn, hg, al1, al2, al3, Jh, Jg, W):
    """``Jh = d(Q a)/dh`` and ``Jg = d(Q a)/dg`` at the state's own frame, ``(al1, al2,
    al3)`` the components of ``a`` in it (``friction_forms.framed_anchor``); ``W`` (6, 3, 3)
    work."""
    Pb, A, dbh_dh, dbh_dg, S, T = W[0], W[1], W[2], W[3], W[4], W[5]
    ib = 1.0 / (bn if bn > 0.0 else 1.0)
    for i in range(3):
        for j in range(3):
            Pb[i, j] = ((1.0 if i == j else 0.0) - bh[i] * bh[j]) * ib
            A[i, j] = (hg if i == j else 0.0) + h[i] * gg[j]
            T[i, j] = (1.0 if i == j else 0.0) - h[i] * h[j]
    _mm(Pb, A, dbh_dh)
    for i in range(3):
        for j in range(3):
            dbh_dh[i, j] = -dbh_dh[i, j]
    _mm(Pb, T, dbh_dg)
    _skew(h, S)
    _mm(S, dbh_dh, A)                       # S(h) d b_hat / dh
    _skew(bh, T)
    for i in range(3):
        for j in range(3):
            Jh[i, j] = ((al1 if i == j else 0.0) + al2 * dbh_dh[i, j] + al3 * (A[i, j] - T[i, j]))
            T[i, j] = (al2 if i == j else 0.0) + al3 * S[i, j]
    _mm(T, dbh_dg, Jg)


@njit(cache=True, nogil=True)
def _refreeze(X, G, D, gw, n, rho, active, cb_bar, cb_star, anchor, d_ref, m_ref, Jd, Jg, anchor_out, h_out, bh_out):
    P, Gp = D.shape[0], D.shape[1]
    h, gg, bh, wh = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    jb, js, rm = np.zeros(3), np.zeros(3), np.zeros(3)
    Jh, Jgp = np.zeros((3, 3)), np.zeros((3, 3))
    W = np.zeros((6, 3, 3))
    for p in range(P):
        for g in range(Gp):
            dn, bn, hg = _frame_at(X, G, D, gw, p, g, h, gg, bh, wh)
            r = rho[p, g] if active[p, g] else 0.0
            # a = -rho n in the state's own frame
            al1 = -r * (h[0] * n[p, g, 0] + h[1] * n[p, g, 1] + h[2] * n[p, g, 2])
            al2 = -r * (bh[0] * n[p, g, 0] + bh[1] * n[p, g, 1] + bh[2] * n[p, g, 2])
            al3 = -r * (wh[0] * n[p, g, 0] + wh[1] * n[p, g, 1] + wh[2] * n[p, g, 2])
            _turn_jacobians(h, gg, bh, bn, hg, al1, al2, al3, Jh, Jgp, W)
            s = dn if dn > 0.0 else 1.0
            for i in range(3):                  # Jd = Jh (I - h h^T) / |d|
                hJ = Jh[i, 0] * h[0] + Jh[i, 1] * h[1] + Jh[i, 2] * h[2]
                for j in range(3):
                    Jd[p, g, i, j] = (Jh[i, j] - hJ * h[j]) / s
                    Jg[p, g, i, j] = Jgp[i, j]
            # the held anchor in the committed frame, carried to the frame at s*
            _cross(d_ref[p, g], m_ref[p, g], rm)
            b1 = d_ref[p, g, 0] * anchor[p, g, 0] + d_ref[p, g, 1] * anchor[p, g, 1] + d_ref[p, g, 2] * anchor[p, g, 2]
            b2 = m_ref[p, g, 0] * anchor[p, g, 0] + m_ref[p, g, 1] * anchor[p, g, 1] + m_ref[p, g, 2] * anchor[p, g, 2]
            b3 = rm[0] * anchor[p, g, 0] + rm[1] * anchor[p, g, 1] + rm[2] * anchor[p, g, 2]
            _weighted(cb_bar, X, p, g, jb)
            _weighted(cb_star, X, p, g, js)
            for i in range(3):             # less the frozen turn's linear part, Jd d + Jg g
                off = 0.0
                for j in range(3):
                    off += Jd[p, g, i, j] * h[j] * dn + Jgp[i, j] * gg[j]
                anchor_out[p, g, i] = b1 * h[i] + b2 * bh[i] + b3 * wh[i] + jb[i] - js[i] - off
                h_out[p, g, i] = h[i]
                bh_out[p, g, i] = bh[i]


def frame_refreeze(X, G, s_bar, anchor, d_ref, m_ref, s_star, n, rho, active, weights, directions,
                   director_weights):
    """``(Dw, Jd, gw, Jg, anchor', h, b_hat)`` of the section frame's refreeze (module docstring)."""
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)   # noqa: E731
    D, gw = f(directions(s_star)), f(director_weights(s_star))
    cb_bar, cb_star = f(weights(s_bar)), f(weights(s_star))
    X, G, n, rho, anchor, d_ref, m_ref = map(f, (X, G, n, rho, anchor, d_ref, m_ref))
    active = np.ascontiguousarray(active, dtype=np.bool_)
    P, Gp = D.shape[0], D.shape[1]
    Jd, Jg = np.zeros((P, Gp, 3, 3)), np.zeros((P, Gp, 3, 3))
    out, h, bh = np.zeros((P, Gp, 3)), np.zeros((P, Gp, 3)), np.zeros((P, Gp, 3))

    def chunk(a, b):
        _refreeze(X[a:b], G[a:b], D[a:b], gw[a:b], n[a:b], rho[a:b], active[a:b], cb_bar[a:b], cb_star[a:b],
                  anchor[a:b], d_ref[a:b], m_ref[a:b], Jd[a:b], Jg[a:b], out[a:b], h[a:b], bh[a:b])

    run_chunked(P, chunk, MIN_CHUNK)
    return D, Jd, gw, Jg, out, h, bh
