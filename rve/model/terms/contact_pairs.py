"""The two half passes of the centroid-curve contact and the keys of the contact multipliers
(docs/contact.md "Contact on the centroid curve", "Augmented Lagrangian").

Contract
--------
``HalfPasses.build(cmap, mesh, n_gp, neighbours)``: every pair i of a ``ContactMap``
(e+, e-, shift S on the - side) gives two *oriented* pairs, stacked as 2P rows: row i has its
points on e+ and their closest points on e- + S, row P + i its points on e- + S and their
closest points on e+. Each row has the ``n_gp`` Gauss-Legendre points of its own element
with the weight ``l_a W_k / 2`` (``l_a`` the element's length in the reference parameter,
``W_k`` the Gauss weights on [0, 1]): the two half passes integrate both sides and average
them, so no side is the master. ``rows(sel)`` are the oriented rows of the map pairs ``sel``;
``geometry(order, conn, r, gap_radius, rows)`` the ``CurveGeometry`` of those rows at positions
``r`` (n_nodes, 3); ``fold`` adds a pair's two rows into the pair's
local layout (e+ nodes, then e- nodes). With a ``SmoothStencil`` (``geometry: smooth``,
``rve.physics.contact_smooth``) the rows are on the elements' C¹ Hermite curves and a side's
local nodes are its element's stencil (prev's, own, next's nodes): ``width`` slots per side.

``point_keys(...)`` names every contact point by what it is physically: (the element that
carries the point, the point's index, the fibril it touches, the translation of that fibril
relative to the element). Pairs (a, b) and (a, next b) give a point the same key, so a
multiplier carried by key follows the point when its closest point moves on to the
neighbour element, and survives a rebuild of the map.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ...physics.contact_curve import END_SNAP, CurveGeometry, curve_basis, curve_geometry, gauss_legendre_01
from ...physics.contact_smooth import SmoothStencil, hermite_basis, smooth_gaps, smooth_geometry

__all__ = ["HalfPasses", "point_keys", "lattice_translation", "gather_by_key"]

#: resolution of the translations in a point key (mm): lattice vectors are rounded to it
_SHIFT_RESOLUTION = 1e-6


@dataclass(frozen=True)
class HalfPasses:
    """The 2P oriented rows of a map (module docstring). Per row: ``a_elem``, ``b_elem``
    (2P,); ``a_shift``, ``b_shift`` (2P, 3); ``next_elem`` (2P,) (b's next element, -1 at a
    free end); ``has_prev`` (2P,); ``weight`` (2P, G); ``s`` (G,) the Gauss points."""

    n_pairs: int
    a_elem: np.ndarray
    b_elem: np.ndarray
    a_shift: np.ndarray
    b_shift: np.ndarray
    next_elem: np.ndarray
    has_prev: np.ndarray
    weight: np.ndarray
    s: np.ndarray
    #: the C¹ contact curve's stencils (None: the elements' Lagrange curves)
    stencil: Optional[SmoothStencil] = None

    @classmethod
    def build(cls, cmap, mesh, n_gp: int, neighbours, stencil: Optional[SmoothStencil] = None) -> "HalfPasses":
        P = cmap.n_pairs
        S = cmap.shifts
        zero = np.zeros((P, 3))
        a_elem = np.concatenate([cmap.e_plus, cmap.e_minus]).astype(np.int64)
        b_elem = np.concatenate([cmap.e_minus, cmap.e_plus]).astype(np.int64)
        s, W = gauss_legendre_01(n_gp)
        weight = 0.5 * np.asarray(mesh.elem_length, float)[a_elem][:, None] * W[None, :]
        return cls(n_pairs=P, a_elem=a_elem, b_elem=b_elem, a_shift=np.concatenate([zero, S]),
                   b_shift=np.concatenate([S, zero]), next_elem=np.asarray(neighbours.next)[b_elem],
                   has_prev=np.asarray(neighbours.prev)[b_elem] >= 0, weight=weight, s=s, stencil=stencil)

    def width(self, nn: int) -> int:
        """Local nodes per side of a row: the element's nn, or its stencil's."""
        return nn if self.stencil is None else self.stencil.width

    def side_nodes(self, conn, elems) -> np.ndarray:
        """Local nodes (n, width) of the sides on elements ``elems``."""
        return conn[elems] if self.stencil is None else self.stencil.nodes[elems]

    def rows(self, sel=None) -> np.ndarray:
        """Oriented rows of the map pairs ``sel`` (all by default): ``sel`` then ``P + sel``."""
        sel = np.arange(self.n_pairs) if sel is None else np.asarray(sel, np.int64)
        return np.concatenate([sel, self.n_pairs + sel])

    def inputs(self, order: int, conn, r, rows):
        """``(Xa, Xb, has_next, t_next, has_prev)`` of the oriented ``rows`` at positions ``r``
        (n_nodes, 3): the element curves (shifts applied), whether b has a next element and
        that element's tangent at its first node (shifts drop out), whether b has a previous."""
        ea, eb, nx = self.a_elem[rows], self.b_elem[rows], self.next_elem[rows]
        Xa = r[conn[ea]] + self.a_shift[rows][:, None, :]
        Xb = r[conn[eb]] + self.b_shift[rows][:, None, :]
        has_next = nx >= 0
        _, dN0, _ = curve_basis(order, np.zeros(1))
        t_next = np.einsum("b,pbi->pi", dN0[0], r[conn[np.where(has_next, nx, 0)]])
        return Xa, Xb, has_next, t_next, self.has_prev[rows]

    def smooth_inputs(self, r, rows, Y=None):
        """``(Ya, Sa, Yb, Sb, has_next, t_next, has_prev)`` of the oriented ``rows`` on the
        Hermite curves (``SmoothStencil``): their data (shifts applied) and stencil matrices,
        and b's next element's start tangent m_0. ``Y``: the elements' Hermite data at ``r``
        if the caller has them (``SmoothStencil.control(r)``)."""
        st = self.stencil
        ea, eb, nx = self.a_elem[rows], self.b_elem[rows], self.next_elem[rows]
        Y = st.control(r) if Y is None else Y
        Ya, Yb = Y[ea], Y[eb]
        Ya[:, :2] += self.a_shift[rows][:, None, :]
        Yb[:, :2] += self.b_shift[rows][:, None, :]
        has_next = nx >= 0
        return Ya, st.S[ea], Yb, st.S[eb], has_next, Y[np.where(has_next, nx, 0), 2], self.has_prev[rows]

    def smooth_gaps(self, r, gap_radius, rows, compiled: bool = False, Y=None) -> np.ndarray:
        """Overlaps (len(rows), G) on the Hermite curves, -inf where a point is not owned
        (``contact_smooth.smooth_gaps``, or its compiled kernel); ``Y`` as ``smooth_inputs``."""
        Ya, _, Yb, _, has_next, t_next, has_prev = self.smooth_inputs(r, rows, Y)
        if compiled:
            from ...kernels.contact_curve import smooth_gap_rows

            return smooth_gap_rows(hermite_basis(self.s)[0], END_SNAP, Ya, Yb, has_next, t_next, has_prev, gap_radius)
        return smooth_gaps(Ya, Yb, self.s, gap_radius, has_next, t_next, has_prev)

    def geometry(self, order: int, conn, r, gap_radius, rows) -> CurveGeometry:
        """``CurveGeometry`` of the oriented ``rows`` at positions ``r`` (n_nodes, 3);
        ``gap_radius`` (len(rows),) or (len(rows), G)."""
        if self.stencil is not None:
            Ya, Sa, Yb, Sb, has_next, t_next, has_prev = self.smooth_inputs(r, rows)
            own = self.stencil.own
            return smooth_geometry(order, Ya, Sa, Yb, Sb, self.s, gap_radius, has_next, t_next, has_prev,
                                   own[self.a_elem[rows]], own[self.b_elem[rows]])
        Xa, Xb, has_next, t_next, has_prev = self.inputs(order, conn, r, rows)
        return curve_geometry(order, Xa, Xb, self.s, gap_radius, has_next, t_next, has_prev)

    @staticmethod
    def fold(R, nn: int, axes=(1,)) -> np.ndarray:
        """(2Ps, ...) oriented local arrays -> (Ps, ...) in the pairs' (e+ nodes, e- nodes)
        layout: the second half's node ``axes`` (each of length 2 nn; nn the local nodes
        per side) are swapped."""
        half = R.shape[0] // 2
        perm = np.r_[nn:2 * nn, 0:nn]
        B = R[half:]
        for ax in axes:
            B = np.take(B, perm, axis=ax)
        return R[:half] + B

    @staticmethod
    def take(geo: CurveGeometry, rows) -> CurveGeometry:
        """The geometry of a subset of its rows."""
        return CurveGeometry(**{k: (None if v is None else np.asarray(v)[rows]) for k, v in geo.__dict__.items()})


def point_keys(a_elem, fibril_b, relative_shift, n_gp: int, translation=None) -> np.ndarray:
    """(rows * n_gp, 6) int64 keys of the points of oriented rows: (element a, point index,
    fibril of b, translation of b relative to a in units of 1e-6 mm, or ``translation``
    (rows, 3) int64 when given: the lattice coordinates of ``lattice_translation``). (The
    chord geometry, whose closest point stays on its element, passes the element of b as
    ``fibril_b``.)"""
    rows = np.asarray(a_elem).size
    if translation is not None:
        t = np.asarray(translation, np.int64).reshape(rows, 3)
    else:
        t = np.round(np.asarray(relative_shift, float) / _SHIFT_RESOLUTION).astype(np.int64)
    k = np.arange(int(n_gp), dtype=np.int64)
    return np.column_stack([
        np.repeat(np.asarray(a_elem, np.int64), n_gp), np.tile(k, rows),
        np.repeat(np.asarray(fibril_b, np.int64), n_gp), np.repeat(t, n_gp, axis=0),
    ])


def lattice_translation(shift, lattice, period=None) -> np.ndarray:
    """(rows, 3) int64 names of the translations ``shift`` (rows, 3) of a periodic cell's
    contact pairs: their integer coordinates (i, j, 0) on the deformed ``lattice`` (2, 3),
    reduced modulo ``period`` (rows, 3), the lattice vector over which the touched fibril
    continues into its own image (NaN or zero rows: it does not wrap).

    Why lattice coordinates and not millimetres: the lattice turns with the macro gradient
    from one strain step to the next, and a point keeps its name (and its multiplier) when
    it does. Why modulo the wrap: a point next to the seam of a fibril that wraps touches the
    same place of the same infinite periodic fibril from the pair with its last element and
    from the pair with the image of its first; both must carry one multiplier, or the
    shifted overlap, and so the energy, jumps where the closest point passes the seam."""
    A = np.asarray(lattice, float).reshape(2, 3)[:, :2].T
    c = np.rint(np.linalg.solve(A, np.asarray(shift, float).reshape(-1, 3)[:, :2].T).T).astype(np.int64)
    if period is not None:
        w = np.asarray(period, float).reshape(-1, 3)
        wraps = np.all(np.isfinite(w), axis=1) & np.any(w != 0.0, axis=1)
        cp = np.zeros_like(c)
        if wraps.any():
            cp[wraps] = np.rint(np.linalg.solve(A, w[wraps][:, :2].T).T).astype(np.int64)
        # the first nonzero coordinate of the period sets how many periods to take off
        lead = np.where(cp[:, 0] != 0, 0, 1)
        num = c[np.arange(c.shape[0]), lead]
        den = cp[np.arange(c.shape[0]), lead]
        k = np.where(den != 0, np.floor_divide(num, np.where(den != 0, den, 1)), 0)
        c = c - k[:, None] * cp
    return np.column_stack([c, np.zeros(c.shape[0], np.int64)])


def gather_by_key(keys_to, keys_from, values_from) -> np.ndarray:
    """Values at ``keys_to`` (n, 6): the largest of ``values_from`` with the same key
    (0 where no key matches). Used to share a multiplier between the pairs that hold the
    same physical point and to carry the multipliers over a rebuild."""
    keys_to = np.asarray(keys_to, np.int64)
    keys_from = np.asarray(keys_from, np.int64)
    if keys_to.shape[0] == 0:
        return np.zeros(0)
    both = np.concatenate([keys_to, keys_from])
    _, inv = np.unique(both, axis=0, return_inverse=True)
    inv = inv.ravel()
    best = np.zeros(inv.max() + 1)
    np.maximum.at(best, inv[keys_to.shape[0]:], np.asarray(values_from, float).ravel())
    return best[inv[:keys_to.shape[0]]]
