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
* ``temperature_at_quadrature(ops, Te)`` -> (E, nq). (The tangent of the thermal softening
  mu(T) comes from ``beam_forms.neo_hookean_element_forces(..., want_dmu=True)``.)
All functions work on all elements at once.
"""
from __future__ import annotations

import numpy as np

from .electric_forms import EMF, SectionOps, _outer_q, _sig

__all__ = ["capacity_matrix", "conduction", "joule_heating", "joule_source",
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
