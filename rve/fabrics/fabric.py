"""The ``Fabric`` container shared by the weave and knit generators (docs/fabrics.md).

A fabric is a list of fibrils in their **natural (reference) configuration** plus what a
scene needs to set it up:

* ``fibrils``: ``rve.fem.mesh.Fibril`` objects (straight for weaves, curved for knits);
* yarn membership: ``fibril_yarn[f]`` and ``yarns[y]`` (name, direction ``'warp'``,
  ``'weft'`` or ``'loop'``, its fibrils, its position across the fabric, its designed
  centreline);
* ``half_widths``: the RVE box ``[-hx, hx] x [-hy, hy] x [-hz, hz]`` (mm);
* ``end_tags``: one ``EndTag`` per fibril end (fibril, ``'start'``/``'end'``, yarn, box
  side ``'x-'``, ``'x+'``, ``'y-'``, ``'y+'``), used for clamps and electrical probes;
* ``initial_state(mesh)``: the designed initial positions and directors at the mesh
  nodes, an (n_nodes, 9) array ``[r, g1, g2]``. For weaves it differs from the reference
  (the fibrils start stressed, thesis §5.4 / §7.4); for knits it equals it.

``s`` is always the fibril's own reference parameter ``s in [0, Fibril.length]`` (the one
``fibril_mesh`` stores in ``mesh.node_s``); each generator documents what it means.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from rve.fem.mesh import Fibril, FibrilMesh, fibril_mesh

__all__ = [
    "EndTag",
    "Fabric",
    "Yarn",
    "hex_stack_offsets",
    "minimal_rotation",
    "SIDES",
]

SIDES = ("x-", "x+", "y-", "y+")

Frame = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class EndTag:
    """One fibril end: ``end`` is ``'start'`` (s = 0) or ``'end'`` (s = length)."""

    fibril: int
    end: str
    yarn: int
    side: str

    def node(self, mesh: FibrilMesh) -> int:
        """Global node index of this end in ``mesh``."""
        first, last = mesh.end_nodes(self.fibril)
        return first if self.end == "start" else last


@dataclass(frozen=True)
class Yarn:
    """A yarn: a bundle of fibrils following one designed centreline.

    ``position`` is where the yarn sits across the fabric: the y of a warp yarn, the x of
    a weft yarn, the y of a knit course. ``centreline(s)`` (n, 3) is the designed yarn
    axis at the fibrils' parameter ``s``.
    """

    index: int
    name: str
    direction: str
    fibrils: tuple[int, ...]
    position: float
    centreline: Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Fabric:
    kind: str
    fibrils: list[Fibril]
    fibril_yarn: np.ndarray
    yarns: list[Yarn]
    half_widths: np.ndarray
    end_tags: list[EndTag]
    designed: list[Frame] = field(repr=False)
    params: dict = field(default_factory=dict)

    # ----------------------------------------------------------------- metadata
    @property
    def n_fibrils(self) -> int:
        return len(self.fibrils)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.fibrils)

    @property
    def fibril_direction(self) -> tuple[str, ...]:
        """Yarn direction (``'warp'``, ``'weft'`` or ``'loop'``) of every fibril."""
        return tuple(self.yarns[y].direction for y in self.fibril_yarn)

    def yarn_at(self, direction: str, position: float, tol: float = 1e-9) -> Yarn:
        """The yarn of ``direction`` whose ``position`` is ``position`` (e.g. warp, -1)."""
        for y in self.yarns:
            if y.direction == direction and abs(y.position - position) <= tol:
                return y
        raise KeyError(f"no {direction} yarn at {position}")

    def tags(self, side: str | None = None, yarn: int | None = None) -> list[EndTag]:
        """End tags filtered by box side and/or yarn index."""
        if side is not None and side not in SIDES:
            raise ValueError(f"side must be one of {SIDES}, got {side!r}")
        return [t for t in self.end_tags
                if (side is None or t.side == side) and (yarn is None or t.yarn == yarn)]

    def end_nodes(self, mesh: FibrilMesh, side: str | None = None,
                  yarn: int | None = None) -> np.ndarray:
        """Global node indices of the tagged ends (filtered like ``tags``)."""
        return np.array([t.node(mesh) for t in self.tags(side, yarn)], dtype=int)

    # ----------------------------------------------------------------- states
    def mesh(self, elements, order: int = 1) -> FibrilMesh:
        """``fibril_mesh`` of this fabric's (reference) fibrils."""
        return fibril_mesh(self.fibrils, elements, order)

    def initial_state(self, mesh: FibrilMesh) -> np.ndarray:
        """Designed initial state ``[r, g1, g2]`` (n_nodes, 9) at the nodes of ``mesh``."""
        if mesh.n_fibrils != self.n_fibrils or tuple(mesh.names) != self.names:
            raise ValueError("mesh was not built from this fabric's fibrils")
        x = np.empty((mesh.n_nodes, 9))
        for f, frame in enumerate(self.designed):
            nodes = mesh.fibril_nodes(f)
            r, g1, g2 = frame(mesh.node_s[nodes])
            x[nodes] = np.hstack([r, g1, g2])
        return x


# --------------------------------------------------------------------- helpers
def hex_stack_offsets(rows, diameter: float) -> np.ndarray:
    """Fibril centres of a packed yarn cross-section, (n, 2) = (lateral, vertical).

    ``rows`` lists fibrils per row from bottom to top (3-4-3 for the thesis yarn). Within
    a row the centres are ``diameter`` apart and centred; consecutive rows whose lateral
    positions interleave (counts of different parity) are ``diameter * sqrt(3)/2`` apart
    (hexagonal packing), otherwise ``diameter`` apart, so no two fibrils overlap. The
    whole stack is centred on the yarn axis (mean offset zero).
    """
    rows = [int(n) for n in rows]
    if not rows or min(rows) < 1:
        raise ValueError(f"rows must be positive counts, got {rows}")
    d = float(diameter)
    pts, v = [], 0.0
    for r, n in enumerate(rows):
        if r > 0:
            interleave = (n - rows[r - 1]) % 2 == 1
            v += d * np.sqrt(3.0) / 2.0 if interleave else d
        for k in range(n):
            pts.append(((k - (n - 1) / 2.0) * d, v))
    pts = np.array(pts)
    return pts - pts.mean(axis=0)


def minimal_rotation(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Apply to ``v`` the smallest rotation taking unit ``a`` onto unit ``b`` (row-wise).

    ``a``, ``b``, ``v`` are (n, 3) (or broadcastable); ``a`` and ``b`` must not be
    antiparallel.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    v = np.asarray(v, float)
    c = np.einsum("...i,...i->...", a, b)[..., None]
    if np.any(c <= -1.0 + 1e-12):
        raise ValueError("minimal_rotation: antiparallel tangents")
    k = np.cross(a, b)
    # Rodrigues with axis k/|k|, sin = |k|, cos = c, written without dividing by |k|
    kv = np.cross(k, v)
    return v + kv + np.cross(k, kv) / (1.0 + c)
