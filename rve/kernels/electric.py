"""Compiled EMF / Lorentz / Joule kernel of the conduction terms (docs/kernels.md).

Contract
--------
``coupled_forms(ops, U, Uv, Te, Ve, B, sigma0, seebeck, back_emf, lorentz, joule,
want_tangent)`` returns ``(R, J)`` with exactly the keys, shapes and meaning of
``rve.physics.electric_forms.coupled_forms(ops, emf(ops, U, Uv, Te, Ve, B, seebeck,
back_emf), sigma0, B, lorentz, joule, want_tangent)`` (the reference; formulas and
layouts there), to rounding: the EMF e = -V' - S T' + (v x B) . a at every quadrature point
and every residual and Jacobian block in one pass over the points. ``sigma0`` scalar or
per element. The reference costs ~40 numpy calls on arrays of a few hundred points (a
single fibril of 40 elements): per-call overhead, which is what this removes.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["coupled_forms"]


@njit(cache=True, nogil=True)
def _tangent_point(el, q, nn, naf, r, Nx, Dx3, dNq, rho, rhoM, c, bxa, L, C, e, X, Y, back_emf, lorentz,
                   SV, Sx, Sv, LV, Lx, Lv):
    """Quadrature point q's share of the V, x and v columns of the current, Joule and Lorentz
    rows (rho, rhoM, c, bxa, L and e of the point from ``_kernel``)."""
    # V columns: d e / d V_b = -dN_b
    for k in range(r):
        for n in range(nn):
            SV[el, k, n] += rho[k] * (-dNq[el, q, n])
    if back_emf:
        for k in range(r):
            for A in range(naf):
                pd = rho[k] * Dx3[el, q, A]
                pn = rho[k] * Nx[el, q, A]
                for m in range(3):
                    Sx[el, k, A, m] += pd * c[m]
                    Sv[el, k, A, m] += pn * bxa[m]
    if lorentz:
        for A in range(naf):
            for i in range(3):
                for n in range(nn):
                    LV[el, A, i, n] += rhoM[A] * (-L[i] * dNq[el, q, n])
        for i in range(3):
            for m in range(3):
                X[i, m] = e * C[i, m]
                if back_emf:
                    X[i, m] = X[i, m] + L[i] * c[m]
                    Y[i, m] = L[i] * bxa[m]
        for A in range(naf):
            for Bb in range(naf):
                pd = rhoM[A] * Dx3[el, q, Bb]
                pn = rhoM[A] * Nx[el, q, Bb]
                for i in range(3):
                    for m in range(3):
                        Lx[el, A, i, Bb, m] += pd * X[i, m]
                        if back_emf:
                            Lv[el, A, i, Bb, m] += pn * Y[i, m]


@njit(cache=True, nogil=True)
def _kernel(Nq, dNq, Nx, Dx3, W, U, Uv, Te, Ve, B, sig, S, back_emf, lorentz, joule, tangent,
            RV, RT, RL, SV, Sx, Sv, LV, Lx, Lv):
    E, nq, nn = dNq.shape
    naf = Nx.shape[2]
    r = 2 * nn if joule else nn
    B0, B1, B2 = B[0], B[1], B[2]
    rho = np.empty(r)
    rhoM = np.empty(naf)
    a = np.empty(3)
    c = np.zeros(3)
    bxa = np.zeros(3)
    L = np.empty(3)
    X = np.empty((3, 3))
    Y = np.empty((3, 3))
    C = np.array([[0.0, B2, -B1], [-B2, 0.0, B0], [B1, -B0, 0.0]])  # (a x B)_i = C[i, m] a_m
    for el in range(E):
        for q in range(nq):
            # EMF (rve.physics.electric_forms.emf)
            for i in range(3):
                s_ = 0.0
                for A in range(naf):
                    s_ += Dx3[el, q, A] * U[el, A, i]
                a[i] = s_
            Vp = 0.0
            Tp = 0.0
            for n in range(nn):
                Vp += dNq[el, q, n] * Ve[el, n]
                Tp += dNq[el, q, n] * Te[el, n]
            e = -Vp
            if S != 0.0:
                e = e - S * Tp
            if back_emf:
                v0 = 0.0
                v1 = 0.0
                v2 = 0.0
                for A in range(naf):
                    v0 += Nx[el, q, A] * Uv[el, A, 0]
                    v1 += Nx[el, q, A] * Uv[el, A, 1]
                    v2 += Nx[el, q, A] * Uv[el, A, 2]
                c[0], c[1], c[2] = v1 * B2 - v2 * B1, v2 * B0 - v0 * B2, v0 * B1 - v1 * B0
                e = e + (c[0] * a[0] + c[1] * a[1] + c[2] * a[2])
                bxa[0], bxa[1], bxa[2] = B1 * a[2] - B2 * a[1], B2 * a[0] - B0 * a[2], B0 * a[1] - B1 * a[0]
            sW = sig[el] * W[el, q]
            for n in range(nn):
                rho[n] = -sW * dNq[el, q, n]
                RV[el, n] += rho[n] * e
                if joule:
                    rho[nn + n] = -2.0 * (sW * e) * Nq[q, n]
                    RT[el, n] -= Nq[q, n] * (sW * e * e)
            if lorentz:
                L[0], L[1], L[2] = a[1] * B2 - a[2] * B1, a[2] * B0 - a[0] * B2, a[0] * B1 - a[1] * B0
                for A in range(naf):
                    rhoM[A] = -sW * Nx[el, q, A]
                    for i in range(3):
                        RL[el, A, i] += rhoM[A] * (e * L[i])
            if not tangent:
                continue
            _tangent_point(el, q, nn, naf, r, Nx, Dx3, dNq, rho, rhoM, c, bxa, L, C, e, X, Y, back_emf, lorentz,
                           SV, Sx, Sv, LV, Lx, Lv)


def coupled_forms(ops, U, Uv, Te, Ve, B, sigma0, seebeck: float = 0.0, back_emf: bool = True,
                  lorentz: bool = True, joule: bool = True, want_tangent: bool = True):
    """Compiled EMF + ``coupled_forms`` (module docstring)."""
    E, nq, nn = ops.dNq.shape
    naf = ops.Nx.shape[2]
    f = lambda v: np.ascontiguousarray(v, dtype=np.float64)  # noqa: E731
    Ve = f(Ve)
    Te = f(np.zeros_like(Ve) if Te is None else Te)
    Uv = f(np.zeros_like(U) if Uv is None else Uv)
    sig = f(np.broadcast_to(np.asarray(sigma0, float).reshape(-1), (E,)))
    r = 2 * nn if joule else nn
    tan = bool(want_tangent)
    z = lambda *shape: np.zeros(shape)  # noqa: E731
    RV, RT, RL = z(E, nn), z(E, nn) if joule else z(1, 1), z(E, naf, 3) if lorentz else z(1, 1, 1)
    SV = z(E, r, nn) if tan else z(1, 1, 1)
    Sx = z(E, r, naf, 3) if tan and back_emf else z(1, 1, 1, 1)
    Sv = z(E, r, naf, 3) if tan and back_emf else z(1, 1, 1, 1)
    LV = z(E, naf, 3, nn) if tan and lorentz else z(1, 1, 1, 1)
    Lx = z(E, naf, 3, naf, 3) if tan and lorentz else z(1, 1, 1, 1, 1)
    Lv = z(E, naf, 3, naf, 3) if tan and lorentz and back_emf else z(1, 1, 1, 1, 1)
    _kernel(f(ops.Nq), f(ops.dNq), f(ops.Nx), f(ops.Dx3), f(ops.W), f(U), Uv, Te, Ve, f(B), sig,
            float(seebeck), bool(back_emf), bool(lorentz), bool(joule), tan, RV, RT, RL, SV, Sx, Sv, LV, Lx, Lv)
    R = {"V": RV, "T": RT if joule else None, "L": RL if lorentz else None}
    if not tan:
        return R, None
    J = {"Sx": Sx if back_emf else None, "Sv": Sv if back_emf else None, "SV": SV,
         "Lx": Lx if lorentz else None, "Lv": Lv if lorentz and back_emf else None,
         "LV": LV if lorentz else None}
    return R, J
