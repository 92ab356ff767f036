"""Electromagnetic term: current conservation (V) with back-EMF and Seebeck EMF, the Lorentz
force of the conduction current (mech) and its Joule heat (T), from ONE fused kernel
(``rve.physics.electric_forms.coupled_forms``, the reference; its compiled twin
``rve.kernels.electric`` when ``rve.kernels.use_numba()``, docs/kernels.md; derivation and
tangents: docs/coupled_fields.md).

Contract
--------
``Electromagnetic(ops, sigma0, B, active, seebeck, field_ramp=None)``: ``active`` the
resolved coupling flags (``rve.model.materials.resolve_couplings``: lorentz, back_emf,
joule, seebeck). The EMF is e = -V' (+ v x B . r' with back_emf) (- S T' with seebeck);
B(t) = B * field_ramp(t) (B when there is no ramp).

Blocks: residual "V" (always), "T" (joule), "mech" (lorentz); tangents, for each of the
rows "V" and (joule) "T": (row, "mech", "x") and (row, "mech", "w") when the EMF depends on
the motion, (row, "V", "w"), and (row, "T", "w") = S (row, "V", "w") with Seebeck; with
lorentz: ("mech", "mech", "x"), ("mech", "mech", "w") (back-EMF), ("mech", "V", "w") and
(Seebeck) ("mech", "T", "w"). ``emf(state, B)`` and ``field(t)`` serve the model's
post-processing (axial current, end currents, Joule power).
"""
from __future__ import annotations

import numpy as np

from ...kernels import use_numba
from ...physics.electric_forms import coupled_forms, emf
from .base import Term

__all__ = ["Electromagnetic", "field_at"]


def field_at(B, field_ramp, t):
    """B at time t (the full B when t is None or there is no ramp)."""
    if field_ramp is None or t is None:
        return B
    return B * float(field_ramp(t))


class Electromagnetic(Term):
    name = "electromagnetic"

    def __init__(self, ops, sigma0: float, B, active: dict, seebeck: float = 0.0, field_ramp=None):
        if not sigma0 > 0:
            raise ValueError("the 'V' field needs electrical_conductivity > 0")
        self.ops, self.sigma0 = ops, float(sigma0)
        self.B = np.asarray(B, float)
        self.active = dict(active)
        self.seebeck = float(seebeck)
        self.field_ramp = field_ramp

    def field(self, t=None):
        return field_at(self.B, self.field_ramp, t)

    def emf(self, state, B=None):
        a = self.active
        T = state.T if state.T is not None else np.zeros_like(state.V)
        return emf(self.ops, state.U, state.Uv, T, state.V, self.B if B is None else B,
                   seebeck=self.seebeck if a["seebeck"] else 0.0, back_emf=a["back_emf"])

    def forms(self, state, jacobian: bool):
        a = self.active
        Bt = self.field(state.t)
        if use_numba():
            from ...kernels.electric import coupled_forms as compiled

            S = self.seebeck if a["seebeck"] else 0.0
            R, J = compiled(self.ops, state.U, state.Uv if a["back_emf"] else None, state.T, state.V, Bt,
                            self.sigma0, S, a["back_emf"], a["lorentz"], a["joule"], jacobian)
        else:
            m = self.emf(state, Bt)
            S = m.seebeck
            R, J = coupled_forms(self.ops, m, self.sigma0, Bt, lorentz=a["lorentz"], joule=a["joule"],
                                 want_tangent=jacobian)
        res = {"V": R["V"]}
        if a["joule"]:
            res["T"] = R["T"]
        if a["lorentz"]:
            res["mech"] = R["L"]
        if not jacobian:
            return res, {}
        nn = self.ops.nn
        K = {}
        rows = [("V", slice(0, nn))]
        if a["joule"]:
            rows.append(("T", slice(nn, 2 * nn)))
        for f, sl in rows:
            if J["Sx"] is not None:
                K[f, "mech", "x"] = J["Sx"][:, sl]
                K[f, "mech", "w"] = J["Sv"][:, sl]
            bV = J["SV"][:, sl]
            K[f, "V", "w"] = bV
            if S:
                K[f, "T", "w"] = S * bV
        if a["lorentz"]:
            K["mech", "mech", "x"] = J["Lx"]
            if J["Lv"] is not None:
                K["mech", "mech", "w"] = J["Lv"]
            K["mech", "V", "w"] = J["LV"]
            if S:
                K["mech", "T", "w"] = S * J["LV"]
        return res, K
