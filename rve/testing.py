"""Verification helpers shared by the tests: finite-difference Jacobians and test geometry.

Contract: ``fd_jacobian(fun, u, cols=None, eps=1e-6)`` returns the central-difference
Jacobian of ``fun`` (array -> array) at ``u``, restricted to the columns ``cols`` (all by
default); ``rel_err(A, B)`` is max|A - B| / max|B|; ``helix_fibril(radius)`` is a curved
natural configuration (a quarter turn of a helix with a smooth director frame) used to
test curved references.
"""
from __future__ import annotations

import numpy as np

from .fem.mesh import Fibril, orthonormal_directors

__all__ = ["fd_jacobian", "fd_nodes", "rel_err", "helix_fibril"]


def fd_jacobian(fun, u, cols=None, eps: float = 1e-6) -> np.ndarray:
    u = np.asarray(u, float)
    cols = np.arange(u.size) if cols is None else np.asarray(cols)
    out = np.zeros((np.asarray(fun(u)).size, cols.size))
    for j, k in enumerate(cols):
        up = u.copy()
        up[k] += eps
        um = u.copy()
        um[k] -= eps
        out[:, j] = (fun(up) - fun(um)) / (2 * eps)
    return out


def fd_nodes(fun, X, h: float = 1e-7) -> np.ndarray:
    """Central differences of ``fun(X)`` (P, ...) with respect to every node coordinate of
    ``X`` (P, n, c) (c components a node, e.g. 3), batched over P: returns (P, ..., n, c)."""
    f0 = fun(X)
    out = np.zeros(f0.shape + X.shape[1:])
    for k in range(X.shape[1]):
        for i in range(X.shape[2]):
            Xp, Xm = X.copy(), X.copy()
            Xp[:, k, i] += h
            Xm[:, k, i] -= h
            out[..., k, i] = (fun(Xp) - fun(Xm)) / (2 * h)
    return out


def rel_err(A, B) -> float:
    return float(np.abs(A - B).max() / max(np.abs(B).max(), 1e-300))


def helix_fibril(radius: float = 0.1) -> Fibril:
    a, c = 1.0, 0.5

    def frame(s):
        s = np.asarray(s, float)
        r0 = np.stack([a * np.cos(s), a * np.sin(s), c * s], 1)
        t = np.stack([-a * np.sin(s), a * np.cos(s), np.full_like(s, c)], 1)
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        g1, g2 = orthonormal_directors(t)
        return r0, g1, g2

    return Fibril(length=1.5, radius=radius, frame=frame)
