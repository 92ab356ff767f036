"""Lorentz force of a prescribed current (the static wire: no V field; docs/coupled_fields.md).

Contract
--------
``PrescribedLorentz(basis, current, B)``: ``current`` (E,) A per element flowing along the
centroid, ``B`` (3,) kT; residual block "mech" (the load f = I r' x B per unit reference
length, with the sign of F = internal - external) and its exact tangent ("mech", "mech", "x").
Kernel: ``rve.physics.beam_forms.lorentz_force``. (The force of the *conduction* current is
part of the electromagnetic term.)
"""
from __future__ import annotations

import numpy as np

from ...physics.beam_forms import lorentz_force
from .base import Term

__all__ = ["PrescribedLorentz"]


class PrescribedLorentz(Term):
    name = "prescribed_lorentz"

    def __init__(self, basis, current, B):
        self.basis = basis
        self.current = np.asarray(current, float)
        self.B = B

    def forms(self, state, jacobian: bool):
        Rl, Kl = lorentz_force(self.basis, state.U, self.current, self.B, jacobian)
        return {"mech": Rl}, ({("mech", "mech", "x"): Kl} if jacobian else {})
