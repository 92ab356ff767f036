"""Element forms of the fibril's heat equation and of the thermal couplings (thesis §2.6,
§2.9, §4.2.3, §6.4).

Contract
--------
T = T(xi3) is constant over the section. The heat equation pushed back to the reference
(natural) configuration, per reference volume, is (docs/coupled_fields.md)

    rho0 c_p dT/dt - d/dxi3 (k0 dT/dxi3) = sigma0 e^2,

with e the EMF per reference length of ``rve.physics.electric_forms`` (so sigma0 e^2 =
J calJ . (calE - S grad T) is the Joule heat per reference volume, exactly integrated over
the section by the disk quadrature because e varies across it). In the residual
``M dw/dt + F = 0`` of the model:

* ``capacity_matrix(ops, rho_cp)`` -> (E, nn, nn): rho0 c_p int N_a N_b dV0;
* ``conduction(ops, k0, Te)`` -> (R (E, nn), K (E, nn, nn)): k0 int N_a' T' dV0;
* ``joule_heating(ops, emf, sigma0)`` -> (R (E, nn), J): R = -int N_a sigma0 e^2 dV0 and its
  partial Jacobians 'V', 'T' (E, nn, nn), 'x', 'v' (E, nn, nn*3, 3) (None when zero);
* ``joule_source(ops, emf, sigma0)`` -> (E, nn): the heat input int N_a sigma0 e^2 dV0 (W);
* ``thermal_softening(basis, U, alpha_mu, ops)`` -> (E, nn*3, 3, nn): d R_int / d T_b of the
  Neo-Hookean internal force with mu(T) = mu0 + alpha_mu T (T interpolated at every
  quadrature point).
All functions work on all elements at once.
"""
from __future__ import annotations

import numpy as np

from ..fem.basis import BeamBasis
from .beam_forms import F_from_U
from .electric_forms import EMF, SectionOps, _outer_q, _sig

__all__ = ["capacity_matrix", "conduction", "joule_heating", "joule_source", "thermal_softening",
           "temperature_at_quadrature"]


def capacity_matrix(ops: SectionOps, rho_cp) -> np.ndarray:
    E = ops.W.shape[0]
    c = _sig(rho_cp, E)
    WN = ops.WN * c[:, :, None]
    return np.matmul(np.swapaxes(WN, 1, 2), np.broadcast_to(ops.Nq, WN.shape))


def conduction(ops: SectionOps, k0, Te, want_tangent: bool = True):
    E = ops.W.shape[0]
    k = _sig(k0, E)
    K = np.matmul(np.swapaxes(ops.WdN, 1, 2), ops.dNq) * k[:, :, None]
    R = np.einsum("eab,eb->ea", K, Te)
    return R, (K if want_tangent else None)


def joule_source(ops: SectionOps, m: EMF, sigma0) -> np.ndarray:
    E = m.e.shape[0]
    s = _sig(sigma0, E)
    return np.einsum("eqa,eq->ea", ops.WN, s * m.e * m.e)


def joule_heating(ops: SectionOps, m: EMF, sigma0, want_tangent: bool = True):
    E = m.e.shape[0]
    s = _sig(sigma0, E)
    WN = ops.WN
    R = -np.einsum("eqa,eq->ea", WN, s * m.e * m.e)
    if not want_tangent:
        return R, None
    g = 2.0 * s * m.e  # d(sigma0 e^2)/de
    A = WN * g[:, :, None]  # (E, nq, nn)
    # de/dV_b = -dN_b  ->  dR/dV = + sum_q W N_a g dN_b
    JV = np.matmul(np.swapaxes(A, 1, 2), ops.dNq)
    J = {"V": JV, "T": JV * m.seebeck if m.seebeck else None, "x": None, "v": None}
    if m.back_emf:
        J["x"] = -_outer_q(A, ops.Dx3, m.c)
        J["v"] = -_outer_q(A, ops.Nx, m.Bxa)
    return R, J


def temperature_at_quadrature(ops: SectionOps, Te) -> np.ndarray:
    """T at every quadrature point (E, nq)."""
    return np.einsum("qn,en->eq", ops.Nq, Te)


def thermal_softening(basis: BeamBasis, U, alpha_mu: float, ops: SectionOps, F=None) -> np.ndarray:
    """d R_int / d T_b = alpha_mu sum_q (dR_int/dmu_q) N_b(q): (E, nn*3, 3, nn).

    dR_int/dmu_q[(a,f), i] = W_q sum_j D[j, (a,f)] dP/dmu[i, j] with dP/dmu = F - F^-T (the
    same as ``beam_forms.internal_force_dmu``, done here as batched matmuls)."""
    if F is None:
        F = F_from_U(basis, U)
    dP = F - np.swapaxes(np.linalg.inv(F), -1, -2)  # (E, nq, i, j)
    E, nq, _, naf = basis.D.shape
    # G[e, q, af, i] = sum_j D[e,q,j,af] dP[e,q,i,j]
    G = np.matmul(np.swapaxes(basis.D, 2, 3), np.swapaxes(dP, 2, 3))  # (E, nq, af, i)
    G = G * (alpha_mu * basis.W)[:, :, None, None]
    K = np.matmul(G.reshape(E, nq, naf * 3).transpose(0, 2, 1), np.broadcast_to(ops.Nq, (E, nq, ops.nn)))
    return K.reshape(E, naf, 3, ops.nn)
