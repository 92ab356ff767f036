"""Node-interleaved dof layout and fast sparse assembly of element arrays.

Contract
--------
``DofLayout(n_nodes, fields)``: every node carries the same block of components, in the
order given by ``fields`` (a subset of ``("mech", "T", "V")``; "mech" is the 9 components
r, g1, g2). Global dof of (node, comp) = node * block + comp (SPEC §4: node-interleaved
ordering keeps the bandwidth of the beam systems small).

Dof indices are asked of the layout, never computed by hand: ``layout.dofs(name, nodes,
comp)`` with ``name`` a field ("mech", "T", "V") or a part of the mechanical block ("r"
the centroid, "g1", "g2" the directors), ``comp`` one component of it (0, 1, 2 = x, y, z)
or all; ``layout.offset_of(name)`` is the position of that part within the node block.

``ElementPattern(layout, conn)`` precomputes, for element connectivity ``conn`` (E, nn),
the CSR structure of the global matrix and the position of every element-matrix entry in
its ``data`` array. ``assemble_matrix(Ke)`` with Ke (E, nn*block, nn*block) is then one
``np.bincount``; ``assemble_vector(Re)`` likewise. Entries of several patterns (beam
elements, contact pairs) are combined by ``add_matrices``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["DofLayout", "ElementPattern"]

_FIELD_SIZE = {"mech": 9, "T": 1, "V": 1}
#: parts of the mechanical block: (offset within the block, size)
_MECH_PARTS = {"r": (0, 3), "g1": (3, 3), "g2": (6, 3)}


class DofLayout:
    def __init__(self, n_nodes: int, fields=("mech",)):
        fields = tuple(fields)
        for f in fields:
            if f not in _FIELD_SIZE:
                raise ValueError(f"unknown field {f!r}; allowed: {sorted(_FIELD_SIZE)}")
        if "mech" not in fields or fields[0] != "mech":
            raise ValueError("the mechanical field must come first in the dof layout")
        self.n_nodes = int(n_nodes)
        self.fields = fields
        self.offset = {}
        o = 0
        for f in fields:
            self.offset[f] = o
            o += _FIELD_SIZE[f]
        self.block = o
        self.n = self.n_nodes * self.block
        mech = np.zeros(self.block, bool)
        mech[:9] = True
        self.mech = np.tile(mech, self.n_nodes)

    def has(self, field: str) -> bool:
        return field in self.offset

    def dof(self, nodes, comp) -> np.ndarray:
        """Global dof index of component ``comp`` (int within the block) at ``nodes``."""
        return np.asarray(nodes) * self.block + comp

    def field_dofs(self, field: str, nodes=None) -> np.ndarray:
        nodes = np.arange(self.n_nodes) if nodes is None else np.asarray(nodes)
        o = self.offset[field]
        k = _FIELD_SIZE[field]
        return (nodes[:, None] * self.block + o + np.arange(k)[None, :]).ravel()

    def offset_of(self, name: str) -> int:
        """Position of field or mechanical part ``name`` within the node block."""
        if name in _MECH_PARTS:
            return _MECH_PARTS[name][0]
        if name not in self.offset:
            raise ValueError(f"the layout has no {name!r} dofs (fields {self.fields}; parts {sorted(_MECH_PARTS)})")
        return self.offset[name]

    def dofs(self, name: str, nodes=None, comp=None) -> np.ndarray:
        """Global dofs of field or mechanical part ``name`` ("mech", "T", "V", "r", "g1",
        "g2") at ``nodes`` (all nodes if None), node-major: all components of a node, or
        only component ``comp`` (an int or a sequence of ints within the part)."""
        o = self.offset_of(name)
        size = _MECH_PARTS[name][1] if name in _MECH_PARTS else _FIELD_SIZE[name]
        comps = np.arange(size) if comp is None else np.atleast_1d(np.asarray(comp, dtype=np.int64))
        if comps.size and (comps.min() < 0 or comps.max() >= size):
            raise ValueError(f"component {comp!r} out of range for {name!r} (0..{size - 1})")
        nodes = np.arange(self.n_nodes) if nodes is None else np.atleast_1d(np.asarray(nodes, dtype=np.int64))
        return (nodes[:, None] * self.block + o + comps[None, :]).ravel()

    def as_nodal(self, u: np.ndarray) -> np.ndarray:
        return u.reshape(self.n_nodes, self.block)


class ElementPattern:
    def __init__(self, layout: DofLayout, conn: np.ndarray):
        conn = np.asarray(conn)
        E, nn = conn.shape
        b = layout.block
        self.n = layout.n
        self.nloc = nn * b
        edofs = (conn[:, :, None] * b + np.arange(b)[None, None, :]).reshape(E, nn * b)
        self.edofs = edofs
        rows = np.repeat(edofs, self.nloc, axis=1).ravel()
        cols = np.tile(edofs, (1, self.nloc)).ravel()
        # unique (row, col) pairs in CSR order
        key = rows.astype(np.int64) * self.n + cols
        uniq, inv = np.unique(key, return_inverse=True)
        self.slot = inv
        self.nnz = uniq.size
        ur = uniq // self.n
        self.indices = (uniq % self.n).astype(np.int32)
        self.indptr = np.zeros(self.n + 1, np.int64)
        np.add.at(self.indptr, ur + 1, 1)
        self.indptr = np.cumsum(self.indptr)

    def assemble_vector(self, Re: np.ndarray) -> np.ndarray:
        return np.bincount(self.edofs.ravel(), weights=Re.reshape(-1), minlength=self.n)

    def assemble_matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        data = np.bincount(self.slot, weights=Ke.reshape(-1), minlength=self.nnz)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
