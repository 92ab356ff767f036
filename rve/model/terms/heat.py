"""Heat conduction term: k0 int N_a' T' dV0 on the T field (docs/coupled_fields.md).

Contract
--------
``HeatConduction(ops, k0, n_elements)``: residual block "T" = K_T T_e and tangent
("T", "T", "w") = K_T, K_T the constant element conduction matrices
(``rve.physics.thermal_forms.conduction``). The Joule source is part of the
electromagnetic term; the heat capacity is a mass block of the inertia term.
"""
from __future__ import annotations

import numpy as np

from ...physics.thermal_forms import conduction
from .base import Term

__all__ = ["HeatConduction"]


class HeatConduction(Term):
    name = "heat_conduction"

    def __init__(self, ops, k0: float, n_elements: int):
        self.K = conduction(ops, k0, np.zeros((n_elements, ops.nn)))[1]  # (E, nn, nn)

    def forms(self, state, jacobian: bool):
        R = {"T": np.einsum("eab,eb->ea", self.K, state.T)}
        return R, ({("T", "T", "w"): self.K} if jacobian else {})
