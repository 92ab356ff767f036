"""Transfer of nodal fields between two meshes of the same fibrils (mesh sequencing).

Contract: ``interpolate_nodal(src_mesh, src_values, dst_mesh)`` evaluates the Lagrange
interpolant of ``src_values`` (src n_nodes, k) at every node of ``dst_mesh`` (same fibrils,
same reference lengths, any order and element count) and returns (dst n_nodes, k).
Vectorised over all destination nodes.
"""
from __future__ import annotations

import numpy as np

from .lagrange import lagrange_basis
from .mesh import FibrilMesh

__all__ = ["interpolate_nodal"]


def interpolate_nodal(src: FibrilMesh, values: np.ndarray, dst: FibrilMesh) -> np.ndarray:
    if src.n_fibrils != dst.n_fibrils:
        raise ValueError(f"meshes differ in fibril count ({src.n_fibrils} vs {dst.n_fibrils})")
    values = np.asarray(values, float)
    out = np.empty((dst.n_nodes, values.shape[1]))
    p = src.order
    for f in range(src.n_fibrils):  # loop over fibrils only; nodes are vectorised
        e0, e1 = src.elem_offsets[f], src.elem_offsets[f + 1]
        h = src.elem_length[e0:e1]
        edges = np.concatenate([[0.0], np.cumsum(h)])
        nodes = dst.fibril_nodes(f)
        s = dst.node_s[nodes]
        e_loc = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, e1 - e0 - 1)
        t = 2.0 * (s - edges[e_loc]) / h[e_loc] - 1.0
        N, _ = lagrange_basis(p, t)  # (n, p+1)
        conn = src.conn[e0 + e_loc]  # (n, p+1)
        out[nodes] = np.einsum("na,nak->nk", N, values[conn])
    return out
