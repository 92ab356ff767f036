"""Inertia and damping terms: consistent mass rho, heat capacity rho c_p, volumetric damping
-gamma v (docs/coupled_fields.md).

Contract
--------
``Inertia(Mm, capacity=None)``: mass blocks ("mech", "mech") = ``Mm`` (E, nn*3, 3, nn*3, 3),
the consistent mass with density, and ("T", "T") = ``capacity`` (E, nn, nn) (none for V: a DAE).

``Damping(Mm, factor, assembled)``: the force density -gamma v as C = (gamma / rho) M_mech.
``assembled=True``: a constant operator (``F += C w``, ``Fw = C``, C = the assembled mass
times gamma/rho: the mechanics-only path, where Fw is then one constant matrix);
``assembled=False``: element blocks ``Ce = Mm gamma/rho`` (residual Ce Uv, tangent
("mech", "mech", "w") = Ce), so that Fw keeps the element pattern with the other
w-blocks (the coupled path). The two differ by rounding only (which product is assembled).
"""
from __future__ import annotations

import numpy as np

from .base import Term

__all__ = ["Inertia", "Damping"]


class Inertia(Term):
    name = "inertia"

    def __init__(self, Mm, capacity=None):
        self.Mm = Mm
        self.capacity = capacity

    def mass_blocks(self) -> dict:
        out = {("mech", "mech"): self.Mm}
        if self.capacity is not None:
            out["T", "T"] = self.capacity
        return out


class Damping(Term):
    name = "damping"

    def __init__(self, Mm, factor: float, assembled: bool):
        if not factor > 0:
            raise ValueError(f"damping factor gamma/rho must be > 0, got {factor}")
        self.Mm, self.factor, self.assembled = Mm, float(factor), bool(assembled)
        E = Mm.shape[0]
        nn = Mm.shape[1] // 3
        self.Ce = None if assembled else (Mm * self.factor).reshape(E, nn, 9, nn, 9)
        self.C = None

    def bind(self, pattern) -> None:
        if not self.assembled:
            return
        E, b = self.Mm.shape[0], pattern.block
        nn = self.Mm.shape[1] // 3
        Mm = self.Mm.reshape(E, nn * 9, nn * 9)
        if b != 9:
            out = np.zeros((E, nn, b, nn, b))
            out[:, :, :9, :, :9] = Mm.reshape(E, nn, 9, nn, 9)
            Mm = out
        self.C = (pattern.assemble_matrix(Mm) * self.factor).tocsr()

    def operator(self):
        return self.C

    def forms(self, state, jacobian: bool):
        if self.assembled:
            return {}, {}
        E, nn9 = self.Ce.shape[0], self.Ce.shape[1] * 9
        R = np.matmul(self.Ce.reshape(E, nn9, nn9), state.Uv.reshape(E, nn9, 1))
        return {"mech": R}, ({("mech", "mech", "w"): self.Ce} if jacobian else {})
