"""Compressible Neo-Hookean material (SPEC §2): psi = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2.

Contract: pure functions of batched deformation gradients F (..., 3, 3).
``neo_hookean_stress(F, mu, lam)`` -> first Piola-Kirchhoff P (..., 3, 3);
``neo_hookean_tangent(F, mu, lam)`` -> (P, A) with A[..., i, J, k, L] = dP_iJ / dF_kL;
``dP_dmu(F)`` -> dP/dmu (for mu(T) = mu0 + alpha_mu T). ``mu`` and ``lam`` broadcast
against the batch shape. ``lame(E, nu)`` converts Young's modulus and Poisson's ratio.
"""
from __future__ import annotations

import numpy as np

__all__ = ["lame", "neo_hookean_energy", "neo_hookean_stress", "neo_hookean_tangent", "dP_dmu"]


def lame(E, nu):
    E = np.asarray(E, float)
    nu = np.asarray(nu, float)
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam


def det_inv(F):
    """Determinant and inverse of batched 3x3 matrices by cofactors (vectorised; much
    cheaper than np.linalg on many tiny matrices)."""
    a, b, c = F[..., 0, 0], F[..., 0, 1], F[..., 0, 2]
    d, e, f = F[..., 1, 0], F[..., 1, 1], F[..., 1, 2]
    g, h, i = F[..., 2, 0], F[..., 2, 1], F[..., 2, 2]
    A = e * i - f * h
    B = f * g - d * i
    C = d * h - e * g
    det = a * A + b * B + c * C
    inv = np.empty_like(F)
    inv[..., 0, 0] = A
    inv[..., 1, 0] = B
    inv[..., 2, 0] = C
    inv[..., 0, 1] = c * h - b * i
    inv[..., 1, 1] = a * i - c * g
    inv[..., 2, 1] = b * g - a * h
    inv[..., 0, 2] = b * f - c * e
    inv[..., 1, 2] = c * d - a * f
    inv[..., 2, 2] = a * e - b * d
    inv /= det[..., None, None]
    return det, inv


def _b(a, F):
    return np.asarray(a, float)[..., None, None] * np.ones(F.shape[:-2] + (1, 1))


def neo_hookean_energy(F, mu, lam):
    J = det_inv(F)[0]
    lnJ = np.log(J)
    trC = np.einsum("...ij,...ij->...", F, F)
    return 0.5 * mu * (trC - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2


def neo_hookean_stress(F, mu, lam):
    J, Finv = det_inv(F)
    lnJ = np.log(J)
    FinvT = np.swapaxes(Finv, -1, -2)
    mu_ = _b(mu, F)
    lam_ = _b(lam, F)
    return mu_ * (F - FinvT) + lam_ * lnJ[..., None, None] * FinvT


def neo_hookean_tangent(F, mu, lam):
    J, Finv = det_inv(F)
    lnJ = np.log(J)
    FinvT = np.swapaxes(Finv, -1, -2)
    mu_ = _b(mu, F)
    lam_ = _b(lam, F)
    P = mu_ * (F - FinvT) + lam_ * lnJ[..., None, None] * FinvT
    c1 = (mu_ - lam_ * lnJ[..., None, None])[..., None, None]
    # A[i,J,k,L] = mu d_ik d_JL + (mu - lam lnJ) Finv[J,k] Finv[L,i] + lam Finv[J,i] Finv[L,k]
    A = c1 * (FinvT[..., :, :, None, None] * FinvT[..., None, None, :, :]).transpose(
        *range(F.ndim - 2), F.ndim - 2, F.ndim + 1, F.ndim, F.ndim - 1)
    if np.any(lam_ != 0):
        A += lam_[..., None, None] * FinvT[..., :, :, None, None] * FinvT[..., None, None, :, :]
    A += mu_[..., None, None] * _IDENTITY4
    return P, A


def dP_dmu(F):
    return F - np.swapaxes(det_inv(F)[1], -1, -2)


_IDENTITY4 = np.einsum("ik,JL->iJkL", np.eye(3), np.eye(3))
