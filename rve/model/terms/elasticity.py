"""Elasticity term: the Neo-Hookean internal force of the director beams, with the thermal
softening mu(T) = mu0 + alpha_mu T when declared (docs/coupled_fields.md).

Contract
--------
``Elasticity(basis, mu, lam, alpha_mu=0.0, ops=None)``: residual block "mech", tangent
blocks ("mech", "mech", "x") and, with softening (alpha_mu != 0, needs the T field and
``ops``), ("mech", "T", "w") = alpha_mu sum_q dR/dmu_q N_b(q). Kernel:
``rve.physics.beam_forms.neo_hookean_element_forces`` (exact tangent; the reference), or its
compiled twin ``rve.kernels.beam`` when ``rve.kernels.use_numba()`` (docs/kernels.md).

``beam_strain_energy(model, x)``: the strain energy sum_q W psi(F) (N mm) whose gradient is
the elasticity residual; +inf where det F <= 0 (psi: ``rve.physics.elasticity.neo_hookean_energy``).
"""
from __future__ import annotations

import numpy as np

from ...fem.small_matrix import det3
from ...kernels import use_numba
from ...physics.beam_forms import neo_hookean_element_forces
from ...physics.elasticity import neo_hookean_energy
from ...physics.thermal_forms import temperature_at_quadrature
from .base import Term

__all__ = ["Elasticity", "beam_strain_energy"]


class Elasticity(Term):
    name = "elasticity"

    def __init__(self, basis, mu: float, lam: float, alpha_mu: float = 0.0, ops=None):
        if alpha_mu != 0.0 and ops is None:
            raise ValueError("thermal softening (alpha_mu != 0) needs the section operators of the T field")
        self.basis, self.mu, self.lam = basis, float(mu), float(lam)
        self.alpha_mu = float(alpha_mu)
        self.ops = ops

    def forms(self, state, jacobian: bool):
        soft = self.alpha_mu != 0.0
        mu = self.mu + self.alpha_mu * temperature_at_quadrature(self.ops, state.T) if soft else self.mu
        if use_numba():
            from ...kernels.beam import neo_hookean_element_forces as compiled

            Rm, Km, dRdmu = compiled(self.basis.D, self.basis.W, state.U, mu, self.lam, jacobian, soft and jacobian)
        else:
            Rm, Km, dRdmu = neo_hookean_element_forces(self.basis, state.U, mu, self.lam, jacobian, soft and jacobian)
        if not jacobian:
            return {"mech": Rm}, {}
        K = {("mech", "mech", "x"): Km}
        if soft:
            # d R_int / d T_b = alpha_mu sum_q (dR/dmu_q) N_b(q)
            E, nn = state.U.shape[0], self.basis.nn
            G = dRdmu.reshape(E, -1, nn * 9).transpose(0, 2, 1)  # (E, af*i, q)
            K["mech", "T", "w"] = self.alpha_mu * np.matmul(G, self.ops.Nq)
        return {"mech": Rm}, K


def beam_strain_energy(base, x) -> float:
    """Neo-Hookean strain energy ``sum_q W psi(F)`` (N mm) of a ``BeamModel`` at state ``x``,
    ``psi = mu/2 (tr C - 3) - mu ln J + lam/2 (ln J)^2`` (the energy whose gradient is the model's
    mechanical residual); +inf where det F <= 0. Mechanics only: a model with a prescribed
    current (Lorentz force) or temperature-dependent mu has no such potential."""
    if getattr(base, "prescribed_current", None) is not None:
        raise ValueError("beam_strain_energy: the Lorentz load of a prescribed current has no potential")
    basis = base.basis
    Fg = basis.deformation_gradient(base.nodal(np.asarray(x, float)))
    det = det3(Fg)
    if not det.min() > 0.0:
        return float("inf")
    psi = neo_hookean_energy(Fg, float(base.mu), float(base.lam), det=det)
    return float((basis.W * psi).sum())
