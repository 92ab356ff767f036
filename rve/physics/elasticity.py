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


def _b(a, F):
    return np.asarray(a, float)[..., None, None] * np.ones(F.shape[:-2] + (1, 1))


def neo_hookean_energy(F, mu, lam):
    J = np.linalg.det(F)
    lnJ = np.log(J)
    trC = np.einsum("...ij,...ij->...", F, F)
    return 0.5 * mu * (trC - 3.0) - mu * lnJ + 0.5 * lam * lnJ**2


def neo_hookean_stress(F, mu, lam):
    Finv = np.linalg.inv(F)
    lnJ = np.log(np.linalg.det(F))
    FinvT = np.swapaxes(Finv, -1, -2)
    mu_ = _b(mu, F)
    lam_ = _b(lam, F)
    return mu_ * (F - FinvT) + lam_ * lnJ[..., None, None] * FinvT


def neo_hookean_tangent(F, mu, lam):
    Finv = np.linalg.inv(F)
    lnJ = np.log(np.linalg.det(F))
    FinvT = np.swapaxes(Finv, -1, -2)
    mu_ = _b(mu, F)
    lam_ = _b(lam, F)
    P = mu_ * (F - FinvT) + lam_ * lnJ[..., None, None] * FinvT
    eye = np.eye(3)
    c1 = (mu_ - lam_ * lnJ[..., None, None])[..., None, None]
    A = (
        mu_[..., None, None] * np.einsum("ik,JL->iJkL", eye, eye)
        + c1 * np.einsum("...Jk,...Li->...iJkL", Finv, Finv)
        + lam_[..., None, None] * np.einsum("...Ji,...Lk->...iJkL", Finv, Finv)
    )
    return P, A


def dP_dmu(F):
    return F - np.swapaxes(np.linalg.inv(F), -1, -2)
