"""Compressible Neo-Hookean material (docs/coupled_fields.md): psi = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2.

Contract: pure functions of batched deformation gradients F (..., 3, 3).
``neo_hookean_stress(F, mu, lam)`` -> first Piola-Kirchhoff P (..., 3, 3);
``neo_hookean_tangent(F, mu, lam)`` -> (P, A) with A[..., i, J, k, L] = dP_iJ / dF_kL;
``dP_dmu(F)`` -> dP/dmu (for mu(T) = mu0 + alpha_mu T). ``mu`` and ``lam`` broadcast
against the batch shape. ``lame(E, nu)`` converts Young's modulus and Poisson's ratio; ``neo_hookean_energy(F, mu,
lam)`` -> psi (...,). Batched det / inverse: ``rve.fem.small_matrix``.
"""
from __future__ import annotations

import numpy as np

from ..fem.small_matrix import det3, inv_det3

__all__ = ["lame", "neo_hookean_energy", "neo_hookean_stress", "neo_hookean_tangent", "dP_dmu"]


def lame(E, nu):
    E = np.asarray(E, float)
    nu = np.asarray(nu, float)
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam


def _b(a, F):
    return np.asarray(a, float)[..., None, None] * np.ones(F.shape[:-2] + (1, 1))


def neo_hookean_energy(F, mu, lam, det=None):
    """Strain energy density psi (...,) of F (..., 3, 3); ``det`` = det F if already known.
    The one Neo-Hookean energy of the package (``rve.model.beam_strain_energy`` sums it)."""
    a = F.reshape(F.shape[:-2] + (9,))
    lnJ = np.log(det3(F) if det is None else det)
    return 0.5 * mu * ((a * a).sum(axis=-1) - 3.0) - mu * lnJ + 0.5 * lam * lnJ * lnJ


def _stress_parts(F, mu, lam):
    """(P, F^-T, ln J, mu and lam broadcast to F's batch shape) of the compressible neo-Hookean law."""
    Finv, J = inv_det3(F)
    lnJ = np.log(J)
    FinvT = np.swapaxes(Finv, -1, -2)
    mu_ = _b(mu, F)
    lam_ = _b(lam, F)
    return mu_ * (F - FinvT) + lam_ * lnJ[..., None, None] * FinvT, FinvT, lnJ, mu_, lam_


def neo_hookean_stress(F, mu, lam):
    return _stress_parts(F, mu, lam)[0]


def neo_hookean_tangent(F, mu, lam):
    P, FinvT, lnJ, mu_, lam_ = _stress_parts(F, mu, lam)
    c1 = (mu_ - lam_ * lnJ[..., None, None])[..., None, None]
    # A[i,J,k,L] = mu d_ik d_JL + (mu - lam lnJ) Finv[J,k] Finv[L,i] + lam Finv[J,i] Finv[L,k]
    A = c1 * (FinvT[..., :, :, None, None] * FinvT[..., None, None, :, :]).transpose(
        *range(F.ndim - 2), F.ndim - 2, F.ndim + 1, F.ndim, F.ndim - 1)
    if np.any(lam_ != 0):
        A += lam_[..., None, None] * FinvT[..., :, :, None, None] * FinvT[..., None, None, :, :]
    A += mu_[..., None, None] * _IDENTITY4
    return P, A


def dP_dmu(F):
    return F - np.swapaxes(inv_det3(F)[0], -1, -2)


_IDENTITY4 = np.einsum("ik,JL->iJkL", np.eye(3), np.eye(3))
