"""Fibril meshes: many 1D Lagrange meshes (one per fibril) numbered as one global mesh.

Contract
--------
``FibrilMesh`` holds, for all fibrils of a scene at once:

* ``order`` p (1..4), shared by all fibrils so that element kernels vectorise over all
  elements of all fibrils;
* ``conn`` (E, p+1): global node indices of every element, in axial order;
* ``elem_fibril`` (E,), ``node_fibril`` (n_nodes,);
* ``node_offsets`` (n_fibrils+1,): fibril f owns nodes node_offsets[f]:node_offsets[f+1];
* ``elem_length`` (E,): length of each element in the reference parameter xi3;
* ``X0`` (n_nodes, 9): reference centroid r0 and directors G1, G2 at every node (the
  natural, stress-free configuration; straight or curved, SPEC §2);
* ``radius`` (n_fibrils,): the section radius of each fibril.

Build one with ``fibril_mesh([Fibril(...), ...], elements, order)``. A ``Fibril`` is a
reference curve given by a callable ``s -> (r0, G1, G2)`` over ``s in [0, length]``; the
helper ``straight_fibril`` builds the common straight case.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .lagrange import lagrange_nodes

__all__ = ["Fibril", "FibrilMesh", "fibril_mesh", "straight_fibril", "orthonormal_directors"]


@dataclass(frozen=True)
class Fibril:
    """A fibril's natural configuration: ``frame(s)`` returns (r0, G1, G2), each (n, 3)."""

    length: float
    radius: float
    frame: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
    name: str = ""

    def __post_init__(self):
        if not self.length > 0:
            raise ValueError(f"fibril length must be > 0, got {self.length}")
        if not self.radius > 0:
            raise ValueError(f"fibril radius must be > 0, got {self.radius}")


def orthonormal_directors(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit tangent ``t`` (n,3) to a right-handed frame."""
    t = np.atleast_2d(t)
    t = t / np.linalg.norm(t, axis=1, keepdims=True)
    helper = np.where(np.abs(t[:, [2]]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    g1 = np.cross(helper, t)
    g1 /= np.linalg.norm(g1, axis=1, keepdims=True)
    g2 = np.cross(t, g1)
    return g1, g2


def straight_fibril(start, end, radius: float, name: str = "") -> Fibril:
    start = np.asarray(start, float)
    end = np.asarray(end, float)
    length = float(np.linalg.norm(end - start))
    t = (end - start) / length
    g1, g2 = orthonormal_directors(t[None, :])

    def frame(s):
        s = np.asarray(s, float)[:, None]
        r0 = start[None, :] + s * t[None, :]
        return r0, np.repeat(g1, len(s), 0), np.repeat(g2, len(s), 0)

    return Fibril(length=length, radius=float(radius), frame=frame, name=name)


@dataclass(frozen=True)
class FibrilMesh:
    order: int
    conn: np.ndarray
    elem_fibril: np.ndarray
    node_fibril: np.ndarray
    node_offsets: np.ndarray
    elem_offsets: np.ndarray
    elem_length: np.ndarray
    node_s: np.ndarray
    X0: np.ndarray
    radius: np.ndarray
    names: tuple = field(default=())

    @property
    def n_nodes(self) -> int:
        return self.X0.shape[0]

    @property
    def n_elements(self) -> int:
        return self.conn.shape[0]

    @property
    def n_fibrils(self) -> int:
        return self.radius.shape[0]

    def end_nodes(self, fibril: int) -> tuple[int, int]:
        return int(self.node_offsets[fibril]), int(self.node_offsets[fibril + 1] - 1)

    def fibril_nodes(self, fibril: int) -> np.ndarray:
        return np.arange(self.node_offsets[fibril], self.node_offsets[fibril + 1])


def fibril_mesh(fibrils: list[Fibril], elements, order: int) -> FibrilMesh:
    """Mesh every fibril with ``elements`` (int, or one int per fibril) Lagrange elements."""
    if not 1 <= int(order) <= 4:
        raise ValueError(f"mesh order must be between 1 and 4, got {order}")
    nf = len(fibrils)
    if nf == 0:
        raise ValueError("a mesh needs at least one fibril")
    n_el = np.broadcast_to(np.asarray(elements, dtype=int), (nf,))
    if np.any(n_el < 1):
        raise ValueError(f"elements per fibril must be >= 1, got {n_el.min()}")
    p = int(order)
    local = (lagrange_nodes(p) + 1.0) / 2.0  # 0..1 within the element
    conns, efib, nfib, lengths, s_all, X0 = [], [], [], [], [], []
    node_off, elem_off = [0], [0]
    for f, (fib, ne) in enumerate(zip(fibrils, n_el)):
        nn = p * ne + 1
        start = node_off[-1]
        h = fib.length / ne
        s = (np.arange(ne)[:, None] + local[None, :]) * h  # (ne, p+1)
        s_nodes = np.empty(nn)
        idx = p * np.arange(ne)[:, None] + np.arange(p + 1)[None, :]
        s_nodes[idx] = s
        r0, g1, g2 = fib.frame(s_nodes)
        X0.append(np.hstack([r0, g1, g2]))
        s_all.append(s_nodes)
        conns.append(start + idx)
        efib.append(np.full(ne, f))
        nfib.append(np.full(nn, f))
        lengths.append(np.full(ne, h))
        node_off.append(start + nn)
        elem_off.append(elem_off[-1] + ne)
    return FibrilMesh(
        order=p,
        conn=np.vstack(conns),
        elem_fibril=np.concatenate(efib),
        node_fibril=np.concatenate(nfib),
        node_offsets=np.asarray(node_off),
        elem_offsets=np.asarray(elem_off),
        elem_length=np.concatenate(lengths),
        node_s=np.concatenate(s_all),
        X0=np.vstack(X0),
        radius=np.array([f.radius for f in fibrils], float),
        names=tuple(f.name for f in fibrils),
    )
