"""Circuit term: mixed end conditions of the V field, acting on the assembled arrays
(thesis eq. 2.8.2, outward normal; docs/coupled_fields.md).

Contract
--------
``Circuits(layout, circuits)`` (a list of ``CircuitBC``): after the element sum,
``F[V dof of the end] += area (r_bar V + J_bar)`` (the current leaving through the end) and
``Fw[that dof, that dof] += area r_bar`` (in place, in the pattern's data slot found at
``bind``). Needs the V field.
"""
from __future__ import annotations

import numpy as np

from .base import Term

__all__ = ["Circuits"]


class Circuits(Term):
    name = "circuits"

    def __init__(self, layout, circuits):
        if not layout.has("V"):
            raise ValueError("circuit boundary conditions need the 'V' field")
        self.circuits = list(circuits)
        self.idx = np.concatenate([layout.dofs("V", [c.node]) for c in self.circuits])
        self.r = np.array([c.area * c.r_bar for c in self.circuits])
        self.J = np.array([c.area * c.J_bar for c in self.circuits])
        self.slot = None

    def bind(self, pattern) -> None:
        ip, ind = pattern.indptr, pattern.indices
        self.slot = np.array([ip[i] + int(np.flatnonzero(ind[ip[i]:ip[i + 1]] == i)[0]) for i in self.idx])
        self._nnz = pattern.nnz

    def add_to_residual(self, F, w) -> None:
        F[self.idx] += self.r * w[self.idx] + self.J

    def add_to_tangent(self, Fx, Fw) -> None:
        if Fw.nnz != self._nnz:  # pragma: no cover - the V field always has element w-blocks
            raise ValueError("circuits need Fw on the element pattern")
        Fw.data[self.slot] += self.r
