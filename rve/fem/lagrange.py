"""Lagrange shape functions of order p = 1..4 on the reference segment [-1, 1].

Contract: ``lagrange_basis(p, t)`` takes the order and evaluation points ``t`` (shape (n,))
and returns ``(N, dN)`` of shape (n, p+1): values and d/dt of the p+1 shape functions whose
nodes are equally spaced from -1 to 1 *in order along the axis* (node 0 at t=-1, node p at
t=+1). This is the same space as scikit-fem's ``ElementLinePp``; we keep our own 12 lines
because the director beam needs the nodes in axial order (node-interleaved global dofs,
shared end nodes between elements), whereas scikit-fem orders vertex dofs first.
"""
from __future__ import annotations

import numpy as np

__all__ = ["lagrange_nodes", "lagrange_basis"]


def lagrange_nodes(p: int) -> np.ndarray:
    if not 1 <= p <= 4:
        raise ValueError(f"element order must be between 1 and 4, got {p}")
    return np.linspace(-1.0, 1.0, p + 1)


def lagrange_basis(p: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    nodes = lagrange_nodes(p)
    t = np.asarray(t, dtype=float)
    n = p + 1
    N = np.ones((t.size, n))
    dN = np.zeros((t.size, n))
    for a in range(n):
        others = [b for b in range(n) if b != a]
        denom = np.prod([nodes[a] - nodes[b] for b in others])
        factors = np.stack([t - nodes[b] for b in others], axis=1)  # (nt, p)
        N[:, a] = np.prod(factors, axis=1) / denom
        # product rule: sum over which factor is differentiated
        for k in range(p):
            dN[:, a] += np.prod(np.delete(factors, k, axis=1), axis=1) / denom
    return N, dN
