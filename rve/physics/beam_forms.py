"""Element forms of the director beam (mechanics): internal force, mass, Lorentz load.

Contract
--------
All functions take a ``BeamBasis`` and return element arrays for ALL elements at once, on the
element's mechanical dofs ordered (a, f, i): node a, field f in (r, g1, g2), component i,
i.e. local index a*9 + 3*f + i. Residual arrays have shape (E, nn*3, 3); tangents have shape
(E, nn*3, 3, nn*3, 3). Sign convention: the residual is F in  M dw/dt + F(x, w) = 0, i.e.
internal forces minus external loads.

* ``internal_force(basis, U, mu, lam, want_tangent)``: Neo-Hookean strain energy (mu and lam
  per element or per quadrature point, shape broadcastable to (E, nq)).
* ``internal_force_dmu(basis, U)``: dF_int/dmu per quadrature point (for mu(T)).
* ``mass_matrix(basis, rho)``: consistent mass, returns (E, nn*3, nn*3) (same for each i).
* ``lorentz_force(basis, U, current, B)``: body load from a current ``current`` (A, per
  element) flowing along the centroid, per unit reference length  f = I r' x B.
"""
from __future__ import annotations

import numpy as np

from ..fem.basis import BeamBasis
from .elasticity import neo_hookean_stress, neo_hookean_tangent

__all__ = ["internal_force", "mass_matrix", "lorentz_force", "levi_civita", "F_from_U"]

levi_civita = np.zeros((3, 3, 3))
levi_civita[0, 1, 2] = levi_civita[1, 2, 0] = levi_civita[2, 0, 1] = 1.0
levi_civita[0, 2, 1] = levi_civita[2, 1, 0] = levi_civita[1, 0, 2] = -1.0

_CHUNK = 4096  # elements per chunk in the tangent (bounds the temporary memory)


def F_from_U(basis: BeamBasis, U: np.ndarray) -> np.ndarray:
    return np.swapaxes(np.matmul(basis.D, U[:, None, :, :]), -1, -2)


def internal_force(basis: BeamBasis, U: np.ndarray, mu, lam, want_tangent: bool = True):
    E, nq = basis.W.shape
    naf = basis.nn * 3
    mu = np.broadcast_to(np.asarray(mu, float).reshape(E, -1) if np.ndim(mu) else mu, (E, nq))
    lam = np.broadcast_to(np.asarray(lam, float).reshape(E, -1) if np.ndim(lam) else lam, (E, nq))
    F = F_from_U(basis, U)
    if not want_tangent:
        P = neo_hookean_stress(F, mu, lam)
        # R[af, i] = sum_q W sum_j D[j, af] P[i, j]
        R = np.einsum("eqja,eqij,eq->eai", basis.D, P, basis.W)
        return R, None
    R = np.empty((E, naf, 3))
    K = np.empty((E, naf, 3, naf, 3))
    for s in range(0, E, _CHUNK):
        sl = slice(s, min(E, s + _CHUNK))
        D = basis.D[sl]
        W = basis.W[sl]
        P, A = neo_hookean_tangent(F[sl], mu[sl], lam[sl])
        R[sl] = np.einsum("eqja,eqij,eq->eai", D, P, W)
        ne = D.shape[0]
        # X[e,q,(i,j,m), bg] = sum_n A[i,j,m,n] D[n, bg]
        X = np.matmul(A.reshape(ne, nq, 27, 3), D)  # (ne, nq, 27, naf)
        X = X.reshape(ne, nq, 3, 3, 3 * naf).transpose(0, 1, 3, 2, 4)  # (ne, nq, j, i, m*bg)
        X = X.reshape(ne, nq * 3, 9 * naf)
        WD = (D * W[:, :, None, None]).reshape(ne, nq * 3, naf)  # [(q,j), af]
        Kc = np.matmul(WD.transpose(0, 2, 1), X)  # (ne, af, i*m*bg)
        K[sl] = Kc.reshape(ne, naf, 3, 3, naf).transpose(0, 1, 2, 4, 3)
    return R, K


def internal_force_dmu(basis: BeamBasis, U: np.ndarray):
    """d R / d mu at each quadrature point: (E, nq, naf, 3)."""
    from .elasticity import dP_dmu

    F = F_from_U(basis, U)
    dP = dP_dmu(F)
    return np.einsum("eqja,eqij,eq->eqai", basis.D, dP, basis.W)


def mass_matrix(basis: BeamBasis, rho) -> np.ndarray:
    rho = np.broadcast_to(np.asarray(rho, float), (basis.W.shape[0],))
    return np.einsum("eqa,eqb,eq->eab", basis.Nx, basis.Nx, basis.W * rho[:, None])


def lorentz_force(basis: BeamBasis, U: np.ndarray, current, B, want_tangent: bool = True):
    """Load f = I r' x B per reference length on the centroid (residual gets -f)."""
    E = U.shape[0]
    nn = basis.nn
    I = np.broadcast_to(np.asarray(current, float), (E,))
    B = np.asarray(B, float)
    r = U.reshape(E, nn, 3, 3)[:, :, 0, :]  # (E, nn, 3)
    r_p = np.einsum("egn,eni->egi", basis.dN, r)  # (E, ng, 3)
    f = I[:, None, None] * np.cross(r_p, B[None, None, :])  # (E, ng, 3)
    R = np.zeros((E, nn, 3, 3))
    R[:, :, 0, :] = -np.einsum("gn,egi,eg->eni", basis.N, f, basis.Wg)
    R = R.reshape(E, nn * 3, 3)
    if not want_tangent:
        return R, None
    C = np.einsum("imk,k->im", levi_civita, B)  # d(v x B)_i / d v_m
    K = np.zeros((E, nn, 3, 3, nn, 3, 3))
    # dR[a, r, i] / d r[b, m] = - sum_g Wg N_a I dN_b C[i, m]
    blk = -np.einsum("gn,egb,eg,e->enb", basis.N, basis.dN, basis.Wg, I)
    K[:, :, 0, :, :, 0, :] = blk[:, :, None, :, None] * C[None, None, :, None, :]
    return R, K.reshape(E, nn * 3, 3, nn * 3, 3)
