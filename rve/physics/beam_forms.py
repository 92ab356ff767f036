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
* ``neo_hookean_element_forces(basis, U, mu, lam, want_tangent, want_dmu)``: the same force
  and tangent (and dR/dmu per quadrature point) as a few batched matmuls: the fast path the
  model's elasticity term uses (``rve.model.terms.elasticity``); tested against
  ``internal_force`` to rounding.
* ``internal_force_dmu(basis, U)``: dF_int/dmu per quadrature point (for mu(T)).
* ``mass_matrix(basis, rho)``: consistent mass, returns (E, nn*3, nn*3) (same for each i).
* ``lorentz_force(basis, U, current, B)``: body load from a current ``current`` (A, per
  element) flowing along the centroid, per unit reference length  f = I r' x B.
"""
from __future__ import annotations

import numpy as np

from ..fem.basis import BeamBasis
from ..fem.small_matrix import inv_det3
from .elasticity import neo_hookean_stress, neo_hookean_tangent

__all__ = ["internal_force", "neo_hookean_element_forces", "mass_matrix", "lorentz_force", "levi_civita", "F_from_U"]

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


_DTD = {}


def _DtD_cache(basis: BeamBasis) -> np.ndarray:
    key = id(basis)
    hit = _DTD.get(key)
    if hit is None or hit[0] is not basis:
        if len(_DTD) > 32:
            _DTD.clear()
        DD = np.matmul(np.swapaxes(basis.D, 2, 3), basis.D)  # (E, nq, naf, naf)
        hit = _DTD[key] = (basis, DD)
    return hit[1]


def neo_hookean_element_forces(basis: BeamBasis, U, mu, lam, want_tangent: bool = True, want_dmu: bool = False):
    """Neo-Hookean internal force of all elements with mu per quadrature point, in a form
    that costs a few batched matmuls (the coupled scenes call it thousands of times).

    Same result as ``rve.physics.beam_forms.internal_force`` (tested to rounding), using the
    structure of the tangent: with G = D^T F^-1 ... precisely G[a, k] = sum_J D[J, a] Finv[J, k],
    H[a, i] = sum_J D[J, a] F[i, J]:
        R[a, i]       = sum_q W (mu H + (lam ln J - mu) G)[a, i]
        K[a, i, b, k] = sum_q W (mu delta_ik (D^T D)[a, b] + (mu - lam ln J) G[a,k] G[b,i] + lam G[a,i] G[b,k])
        dR/dmu_q      = W (H - G)  (returned as (E, nq, naf, 3) when ``want_dmu``).
    Returns (R (E, naf, 3), K (E, naf, 3, naf, 3) or None, dRdmu or None)."""
    D, W = basis.D, basis.W  # (E, nq, 3, naf), (E, nq)
    E, nq, _, naf = D.shape
    mu = np.broadcast_to(np.asarray(mu, float), (E, nq))
    lam = np.broadcast_to(np.asarray(lam, float), (E, nq))
    Dt = np.swapaxes(D, 2, 3)  # (E, nq, naf, 3)
    F = np.swapaxes(np.matmul(D, U[:, None, :, :]), -1, -2)  # (E, nq, i, J)
    Finv, det = inv_det3(F)
    lnJ = np.log(det)
    G = np.matmul(Dt, Finv)  # (E, nq, naf, 3)
    H = np.matmul(Dt, np.swapaxes(F, -1, -2))  # (E, nq, naf, 3)
    c1 = mu - lam * lnJ
    R = np.einsum("eqai,eq->eai", H, W * mu) - np.einsum("eqai,eq->eai", G, W * c1)
    dR = (H - G) * W[:, :, None, None] if want_dmu else None
    if not want_tangent:
        return R, None, dR
    Gf = G.reshape(E, nq, naf * 3)
    Gc1 = Gf * (W * c1)[:, :, None]
    # accumulate in the layout [a, k, b, i] (the c1 term is a plain matmul there); the
    # returned [a, i, b, k] is a transposed view (the caller's reshape copies it once)
    Kt = np.matmul(np.swapaxes(Gc1, 1, 2), Gf).reshape(E, naf, 3, naf, 3)
    if np.any(lam != 0):
        Gl = Gf * (W * lam)[:, :, None]
        Kt += np.matmul(np.swapaxes(Gl, 1, 2), Gf).reshape(E, naf, 3, naf, 3).transpose(0, 1, 4, 3, 2)
    DD = _DtD_cache(basis)  # (E, nq, naf, naf): sum_J D[J, a] D[J, b] per quadrature point
    DtD = np.matmul((W * mu)[:, None, :], DD.reshape(E, nq, naf * naf)).reshape(E, naf, naf)
    for i in range(3):
        Kt[:, :, i, :, i] += DtD
    K = Kt.transpose(0, 1, 4, 3, 2)
    return R, K, dR
