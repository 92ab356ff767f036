"""Contact map geometry: candidate element pairs and the quadrature-point table.

Thesis §4.3.3-4.3.4 and §5.5 (Algorithm 5.2); SPEC §3.

Geometry conventions
--------------------
* Contact is evaluated on the **centroid polyline**: the centroid of element ``e`` is the
  straight segment (the *chord*) from node ``conn[e, 0]`` to node ``conn[e, -1]``, even for
  higher-order elements (thesis §4.3.3, simplification 1).
* A point on a chord is named by ``s in [0, 1]``: ``r(s) = (1 - s) r_a + s r_b`` with
  ``r_a = r[conn[e, 0]]`` and ``r_b = r[conn[e, -1]]``. For an element of order p whose
  reference coordinate is ``xi in [-1, 1]`` this is ``xi = 2 s - 1`` along the chord.
  (The thesis writes the - element as ``s r1 + (1 - s) r2``; that is this convention with
  ``s -> 1 - s``. Its eq. 4.3.2 also has a sign slip; the closest point used here is the
  exact minimiser ``s = clamp((p - r_a).(r_b - r_a) / |r_b - r_a|^2, 0, 1)``.)
* Each unordered element pair appears once; the element with the **lower global element
  index is +**, the other is -.
* ``s_plus`` holds ``n_gp`` equally spaced points on the + chord: the midpoints of
  ``n_gp`` equal sub-intervals, ``s_k = (k + 1/2) / n_gp`` (so no point sits on a node
  shared by two elements and each point carries the weight ``1 / n_gp`` of the chord).
* ``s_minus`` holds, for every + point, the closest point on the - chord, computed at the
  state the map was built from.

Frozen or recomputed ``s_minus``
--------------------------------
The thesis builds the table (pairs *and* the ``(s+, s-)`` points) every k steps (k = 5)
and keeps it fixed in between. ``build_contact_map`` follows that: ``ContactMap.s_minus``
is **frozen** at the build state, so between rebuilds the contact terms are functions of
the nodal positions only (no ``ds-/dx`` terms in the tangent). A mechanics kernel that
prefers the closest point to follow the current state calls
``ContactMap.recompute_s_minus(x)`` (same pairs, same ``s_plus``, new ``s_minus``) or
``ContactMap.refreshed(x)`` (a new map with those values) at every evaluation; with a
recomputed clamped closest point the gap is still exact, but its tangent gains the
``ds-/dx`` term wherever ``0 < s- < 1``.

Cutoff
------
``cutoff`` is a distance between centroid chords. Pairs farther apart cannot touch until
they move; a sensible value is ``R+ + R- + margin`` where the margin covers how far
fibrils move between two rebuilds.

Same-fibril pairs
-----------------
``exclude_neighbours=None`` (the default) drops every pair of elements on the same fibril
(the thesis only pairs different meshes). An integer ``k`` keeps self-contact but drops
same-fibril pairs whose element indices along the fibril differ by at most ``k``
(``k = 0`` drops only an element with itself, which is always dropped). Adjacent elements
share a node, so for self-contact ``k`` must be at least ``ceil((R+ + R- + margin) / h)``.

Search cost
-----------
A ``scipy.spatial.cKDTree`` over chord midpoints returns the midpoint pairs within
``cutoff + L_max`` (two chords of half-lengths h1, h2 whose midpoints are farther apart than
``cutoff + h1 + h2`` are farther apart than ``cutoff``, and h1 + h2 <= L_max); a cheaper
per-pair bound and then the exact, vectorised segment-segment distance filter the
candidates. Chords much longer than the median are cut into pieces for the tree so that one
long chord does not inflate the search radius for all. The cost is O(S log S + P) in the
number of chords S and nearby pairs P; ``candidate_pairs_bruteforce`` is the O(S^2)
reference (benchmarks/contact_search_scaling.py compares both).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "ContactMap",
    "ElementNeighbours",
    "build_contact_map",
    "element_neighbours",
    "wrap_vectors",
    "candidate_pairs",
    "candidate_pairs_bruteforce",
    "closest_points",
    "element_segments",
    "gauss_fractions",
    "segment_distance",
]


# --------------------------------------------------------------------------- geometry
def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", u, v)


def closest_points(r_plus_points, seg_minus_a, seg_minus_b) -> np.ndarray:
    """Closest point parameter ``s`` on the chord ``a -> b`` for every point (eq. 4.3.2).

    ``r_plus_points`` (..., 3); ``seg_minus_a``/``seg_minus_b`` broadcastable to it, e.g.
    points (P, n_gp, 3) with chords (P, 1, 3). Returns ``s`` (...) clamped to [0, 1] with
    ``r(s) = (1 - s) a + s b``; a zero-length chord gives ``s = 0``.
    """
    p = np.asarray(r_plus_points, float)
    a = np.asarray(seg_minus_a, float)
    b = np.asarray(seg_minus_b, float)
    d = b - a
    dd = _dot(d, d)
    num = _dot(p - a, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(dd > 0.0, num / np.where(dd > 0.0, dd, 1.0), 0.0)
    return np.clip(s, 0.0, 1.0)


def segment_distance(p0, p1, q0, q1):
    """Distance between segments ``p0 -> p1`` and ``q0 -> q1`` (vectorised over rows).

    Returns ``(d, s, t)``: the distance and the parameters of one pair of closest points
    ``p0 + s (p1 - p0)`` and ``q0 + t (q1 - q0)``, each in [0, 1]. Handles parallel and
    zero-length segments.
    """
    p0, p1, q0, q1 = (np.asarray(v, float) for v in (p0, p1, q0, q1))
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = _dot(d1, d1)
    e = _dot(d2, d2)
    b = _dot(d1, d2)
    c = _dot(d1, r)
    f = _dot(d2, r)
    tiny = np.finfo(float).tiny
    a_ok = a > tiny
    e_ok = e > tiny
    a_s = np.where(a_ok, a, 1.0)
    e_s = np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    # not parallel: unconstrained minimiser in s, clamped; parallel: any s, take 0
    gen = denom > 1e-14 * a_s * e_s
    s = np.where(gen, np.clip((b * f - c * e) / np.where(gen, denom, 1.0), 0.0, 1.0), 0.0)
    s = np.where(a_ok, s, 0.0)
    # best t for that s, clamped; if clamped, best s for that t
    t = np.where(e_ok, (b * s + f) / e_s, 0.0)
    t_lo = t < 0.0
    t_hi = t > 1.0
    t = np.clip(t, 0.0, 1.0)
    s_lo = np.clip(-c / a_s, 0.0, 1.0)
    s_hi = np.clip((b - c) / a_s, 0.0, 1.0)
    s = np.where(a_ok & (t_lo | ~e_ok), s_lo, np.where(a_ok & t_hi, s_hi, s))
    gap = (p0 + s[..., None] * d1) - (q0 + t[..., None] * d2)
    return np.sqrt(_dot(gap, gap)), s, t


def gauss_fractions(n_gp: int) -> np.ndarray:
    """``n_gp`` equally spaced points on [0, 1]: midpoints of equal sub-intervals."""
    if int(n_gp) < 1:
        raise ValueError(f"n_gp must be >= 1, got {n_gp}")
    n = int(n_gp)
    return (np.arange(n) + 0.5) / n


def element_segments(x_nodes, mesh) -> tuple[np.ndarray, np.ndarray]:
    """Chord end points ``(a, b)``, each (E, 3), of every element for nodal state ``x``.

    ``x_nodes`` is (n_nodes, 3) centroid positions or the full state (n_nodes, 9).
    """
    r = _positions(x_nodes, mesh.n_nodes)
    return r[mesh.conn[:, 0]], r[mesh.conn[:, -1]]


def _positions(x_nodes, n_nodes: int) -> np.ndarray:
    x = np.asarray(x_nodes, float)
    if x.ndim != 2 or x.shape[0] != n_nodes or x.shape[1] < 3:
        raise ValueError(f"expected nodal state of shape ({n_nodes}, 3 or 9), got {x.shape}")
    return x[:, :3]


# --------------------------------------------------------------------------- search
def _exclusion_mask(i, j, fibril_of_segment, index_in_fibril, exclude_neighbours):
    """True for pairs (i, j) that stay candidates."""
    keep = i != j
    if fibril_of_segment is None:
        return keep
    fib = np.asarray(fibril_of_segment)
    same = fib[i] == fib[j]
    if exclude_neighbours is None:
        return keep & ~same
    if index_in_fibril is None:
        raise ValueError("index_in_fibril is required when exclude_neighbours is an int")
    idx = np.asarray(index_in_fibril)
    near = np.abs(idx[i] - idx[j]) <= int(exclude_neighbours)
    return keep & ~(same & near)


def candidate_pairs(
    seg_a,
    seg_b,
    cutoff: float,
    fibril_of_segment=None,
    index_in_fibril=None,
    exclude_neighbours: int | None = None,
    return_distance: bool = False,
):
    """Segment pairs ``(i, j)``, ``i < j``, whose distance is ``<= cutoff``.

    ``seg_a``/``seg_b`` (S, 3) are the chord end points. With ``fibril_of_segment`` (S,)
    (and ``index_in_fibril`` (S,) for an integer ``exclude_neighbours``) same-fibril pairs
    are dropped as described in the module docstring. Returns an int array (P, 2) sorted
    row-wise lexicographically, and the distances (P,) with ``return_distance``.
    """
    A = np.asarray(seg_a, float).reshape(-1, 3)
    B = np.asarray(seg_b, float).reshape(-1, 3)
    if A.shape != B.shape:
        raise ValueError("seg_a and seg_b must have the same shape")
    if not cutoff >= 0:
        raise ValueError(f"cutoff must be >= 0, got {cutoff}")
    S = A.shape[0]
    empty = (np.zeros((0, 2), np.int64), np.zeros(0))
    if S < 2:
        return empty if return_distance else empty[0]

    L = np.linalg.norm(B - A, axis=1)
    # pieces for the tree: chords longer than 1.5x the median are cut
    ell = 1.5 * float(np.median(L))
    if ell > 0 and L.max() > ell:
        n_pc = np.maximum(1, np.ceil(L / ell).astype(np.int64))
    else:
        n_pc = np.ones(S, np.int64)
    owner = np.repeat(np.arange(S), n_pc)
    start = np.cumsum(n_pc) - n_pc
    k = np.arange(owner.size) - start[owner]
    w0 = k / n_pc[owner]
    w1 = (k + 1) / n_pc[owner]
    d = (B - A)[owner]
    mid = A[owner] + 0.5 * (w0 + w1)[:, None] * d
    half = 0.5 * (L / n_pc)[owner]

    tree = cKDTree(mid)
    radius = float(cutoff) + 2.0 * float(half.max())
    pp = tree.query_pairs(radius, output_type="ndarray")
    if pp.size == 0:
        return empty if return_distance else empty[0]
    pi, pj = pp[:, 0], pp[:, 1]
    # per-pair bound on the pieces
    dm = np.linalg.norm(mid[pi] - mid[pj], axis=1)
    ok = dm <= float(cutoff) + half[pi] + half[pj] + 1e-12 * (1.0 + radius)
    i = owner[pi[ok]]
    j = owner[pj[ok]]
    i, j = np.minimum(i, j), np.maximum(i, j)
    keep = _exclusion_mask(i, j, fibril_of_segment, index_in_fibril, exclude_neighbours)
    i, j = i[keep], j[keep]
    if np.any(n_pc > 1):
        key = np.unique(i.astype(np.int64) * S + j)
        i, j = key // S, key % S
    # exact distance
    dist, _, _ = segment_distance(A[i], B[i], A[j], B[j])
    ok = dist <= cutoff
    pairs = np.stack([i[ok], j[ok]], axis=1).astype(np.int64)
    dist = dist[ok]
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    pairs, dist = pairs[order], dist[order]
    return (pairs, dist) if return_distance else pairs


def candidate_pairs_bruteforce(
    seg_a,
    seg_b,
    cutoff: float,
    fibril_of_segment=None,
    index_in_fibril=None,
    exclude_neighbours: int | None = None,
    chunk: int = 2048,
):
    """O(S^2) reference for ``candidate_pairs``: every pair's exact distance (chunked)."""
    A = np.asarray(seg_a, float).reshape(-1, 3)
    B = np.asarray(seg_b, float).reshape(-1, 3)
    S = A.shape[0]
    out = []
    for i0 in range(0, S, chunk):
        ii = np.arange(i0, min(S, i0 + chunk))
        for j0 in range(i0, S, chunk):
            jj = np.arange(j0, min(S, j0 + chunk))
            I, J = np.meshgrid(ii, jj, indexing="ij")
            m = I < J
            I, J = I[m], J[m]
            d, _, _ = segment_distance(A[I], B[I], A[J], B[J])
            ok = d <= cutoff
            ok &= _exclusion_mask(I, J, fibril_of_segment, index_in_fibril, exclude_neighbours)
            out.append(np.stack([I[ok], J[ok]], axis=1))
    pairs = np.concatenate(out).astype(np.int64) if out else np.zeros((0, 2), np.int64)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order]


# --------------------------------------------------------------------------- the map
@dataclass(frozen=True)
class ContactMap:
    """The discrete contact map (thesis §4.3.4): element pairs and quadrature-point table.

    Arrays (P = number of pairs):

    * ``e_plus``, ``e_minus`` (P,): global element indices, ``e_plus < e_minus``;
    * ``nodes_plus``, ``nodes_minus`` (P, 2): the chord end nodes ``conn[e, 0]``,
      ``conn[e, -1]`` of each element;
    * ``fibril_plus``, ``fibril_minus`` (P,): fibril of each element;
    * ``s_plus`` (P, n_gp): ``(k + 1/2) / n_gp`` on the + chord;
    * ``s_minus`` (P, n_gp): closest points on the - chord, **frozen** at the build state
      (see the module docstring; ``recompute_s_minus``/``refreshed`` give current ones);
    * ``distance`` (P,): chord-chord distance at the build state;
    * ``shift`` (P, 3) or None: a constant vector added to the positions of every node of
      the - element of a pair (a pair with a periodic image of the - fibril); None means
      zero for every pair (the positions are used as they are, bit for bit).
    """

    e_plus: np.ndarray
    e_minus: np.ndarray
    nodes_plus: np.ndarray
    nodes_minus: np.ndarray
    fibril_plus: np.ndarray
    fibril_minus: np.ndarray
    s_plus: np.ndarray
    s_minus: np.ndarray
    distance: np.ndarray
    cutoff: float
    n_gp: int
    exclude_neighbours: int | None = None
    shift: np.ndarray | None = None

    @property
    def n_pairs(self) -> int:
        return int(self.e_plus.shape[0])

    def __len__(self) -> int:
        return self.n_pairs

    @property
    def shifts(self) -> np.ndarray:
        """(P, 3) shift of every pair's - side (zeros when ``shift`` is None)."""
        return np.zeros((self.n_pairs, 3)) if self.shift is None else self.shift

    def _chords(self, x, nodes):
        r = np.asarray(x, float)[:, :3]
        a, b = r[nodes[:, 0]], r[nodes[:, 1]]
        if self.shift is not None and nodes is self.nodes_minus:
            a, b = a + self.shift, b + self.shift
        return a, b

    def plus_points(self, x) -> np.ndarray:
        """Contact points on the + chords, (P, n_gp, 3), for nodal state ``x``."""
        a, b = self._chords(x, self.nodes_plus)
        s = self.s_plus[..., None]
        return (1.0 - s) * a[:, None, :] + s * b[:, None, :]

    def minus_points(self, x, s_minus=None) -> np.ndarray:
        """Contact points on the - chords, (P, n_gp, 3), at ``s_minus`` (default: frozen)."""
        a, b = self._chords(x, self.nodes_minus)
        s = (self.s_minus if s_minus is None else np.asarray(s_minus))[..., None]
        return (1.0 - s) * a[:, None, :] + s * b[:, None, :]

    def recompute_s_minus(self, x) -> np.ndarray:
        """Closest points on the - chords to the + points for state ``x``, (P, n_gp)."""
        a, b = self._chords(x, self.nodes_minus)
        return closest_points(self.plus_points(x), a[:, None, :], b[:, None, :])

    def refreshed(self, x) -> "ContactMap":
        """Same pairs and ``s_plus``; ``s_minus`` and ``distance`` recomputed for ``x``."""
        ap, bp = self._chords(x, self.nodes_plus)
        am, bm = self._chords(x, self.nodes_minus)
        d, _, _ = segment_distance(ap, bp, am, bm)
        return ContactMap(
            e_plus=self.e_plus, e_minus=self.e_minus,
            nodes_plus=self.nodes_plus, nodes_minus=self.nodes_minus,
            fibril_plus=self.fibril_plus, fibril_minus=self.fibril_minus,
            s_plus=self.s_plus, s_minus=self.recompute_s_minus(x), distance=d,
            cutoff=self.cutoff, n_gp=self.n_gp, exclude_neighbours=self.exclude_neighbours,
            shift=self.shift,
        )

    def jump(self, x, s_minus=None) -> np.ndarray:
        """Centroid jump ``[[r]] = r+ - r-`` at every table point, (P, n_gp, 3)."""
        return self.plus_points(x) - self.minus_points(x, s_minus)


def build_contact_map(
    x_nodes_r,
    mesh,
    cutoff: float,
    n_gp: int = 4,
    exclude_neighbours: int | None = None,
    images=None,
    wrap=None,
) -> ContactMap:
    """Build the contact map of ``mesh`` at nodal state ``x_nodes_r`` ((n, 3) or (n, 9)).

    Candidate pairs are element chords within ``cutoff`` (``candidate_pairs``); the table
    has ``n_gp`` points per pair (module docstring for the conventions).

    Periodic images: ``images`` (K, 3) translations T (zero rows are ignored) add the pairs
    between an element and the copy of another element translated by T, as pairs with the
    ``shift`` T on their - side (canonical form: ``e_plus <= e_minus``, the shift negated
    when the roles swap; an element with its own image keeps the shift whose first nonzero
    component is positive, so a symmetric set of images gives each contact once). They
    follow the pairs of the cell itself (which are exactly those of ``images=None``).
    ``wrap`` (as ``element_neighbours``) names the fibrils that continue into their own
    image at ``T = m L_f``: such a pair is a same-fibril pair, dropped or kept by
    ``exclude_neighbours`` with the index difference along the unwrapped fibril.
    """
    a, b = element_segments(x_nodes_r, mesh)
    efib = np.asarray(mesh.elem_fibril)
    idx = np.arange(mesh.n_elements) - np.asarray(mesh.elem_offsets)[efib]
    pairs, dist = candidate_pairs(
        a, b, cutoff, efib, idx, exclude_neighbours=exclude_neighbours, return_distance=True
    )
    ep, em = pairs[:, 0], pairs[:, 1]
    shift = None
    if images is not None:
        ie, im, ish, idist = _image_pairs(a, b, mesh, cutoff, images, wrap, exclude_neighbours)
        if ie.size:
            shift = np.concatenate([np.zeros((ep.size, 3)), ish])
            ep, em, dist = np.concatenate([ep, ie]), np.concatenate([em, im]), np.concatenate([dist, idist])
    sp = np.broadcast_to(gauss_fractions(n_gp), (ep.size, int(n_gp))).copy()
    s = sp[..., None]
    pts = (1.0 - s) * a[ep][:, None, :] + s * b[ep][:, None, :]
    am, bm = a[em], b[em]
    if shift is not None:
        am, bm = am + shift, bm + shift
    sm = closest_points(pts, am[:, None, :], bm[:, None, :])
    conn = mesh.conn
    return ContactMap(
        e_plus=ep, e_minus=em,
        nodes_plus=np.stack([conn[ep, 0], conn[ep, -1]], axis=1),
        nodes_minus=np.stack([conn[em, 0], conn[em, -1]], axis=1),
        fibril_plus=efib[ep], fibril_minus=efib[em],
        s_plus=sp, s_minus=sm, distance=dist,
        cutoff=float(cutoff), n_gp=int(n_gp), exclude_neighbours=exclude_neighbours,
        shift=shift,
    )


def _image_pairs(a, b, mesh, cutoff, images, wrap, exclude_neighbours):
    """Pairs (e+, e-, shift, distance) between the cell's chords and their translated copies.

    One ``candidate_pairs`` search over the cell's chords and, per image, the translated
    chords near the cell (their midpoint within ``cutoff + L_max`` of its bounding box);
    the copies carry fibril ids of their own, so only cell-to-copy pairs are kept."""
    T = np.asarray(images, float).reshape(-1, 3)
    T = T[np.any(T != 0.0, axis=1)]
    E = a.shape[0]
    none = np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
    if T.shape[0] == 0 or E == 0:
        return none
    efib = np.asarray(mesh.elem_fibril)
    nf = int(mesh.n_fibrils)
    idx = np.arange(E) - np.asarray(mesh.elem_offsets)[efib]
    L = np.linalg.norm(b - a, axis=1)
    lo = np.minimum(a, b).min(axis=0) - (cutoff + L.max())
    hi = np.maximum(a, b).max(axis=0) + (cutoff + L.max())
    mid = 0.5 * (a + b)
    segA, segB, fib, elem, img = [a], [b], [efib], [np.arange(E)], [np.full(E, -1)]
    for k, t in enumerate(T):
        near = np.flatnonzero(np.all((mid + t >= lo) & (mid + t <= hi), axis=1))
        segA.append(a[near] + t)
        segB.append(b[near] + t)
        fib.append(efib[near] + nf * (k + 1))
        elem.append(near)
        img.append(np.full(near.size, k))
    fib, elem, img = np.concatenate(fib), np.concatenate(elem), np.concatenate(img)
    pairs, dist = candidate_pairs(np.concatenate(segA), np.concatenate(segB), cutoff, fib, None,
                                  exclude_neighbours=None, return_distance=True)
    i, j = pairs[:, 0], pairs[:, 1]
    cross = (i < E) & (j >= E)  # i < j: the cell's chords come first
    i, j, dist = i[cross], elem[j[cross]], dist[cross]
    t = T[img[pairs[cross, 1]]]
    keep = _image_exclusion(i, j, t, efib, idx, mesh, wrap, exclude_neighbours)
    i, j, t, dist = i[keep], j[keep], t[keep], dist[keep]
    swap = (i > j) | ((i == j) & ~_lex_positive(t))
    ep, em = np.where(swap, j, i), np.where(swap, i, j)
    t = np.where(swap[:, None], -t, t)
    if ep.size == 0:
        return none
    scale = max(float(np.abs(T).max()), 1.0) * 1e-9
    key = np.column_stack([ep, em, np.round(t / scale).astype(np.int64)])
    _, first = np.unique(key, axis=0, return_index=True)  # sorted by (e+, e-, shift)
    return ep[first], em[first], t[first], dist[first]


def _lex_positive(t) -> np.ndarray:
    """True where the first nonzero component of each row of ``t`` is positive."""
    nz = t != 0.0
    first = np.argmax(nz, axis=1)
    return t[np.arange(t.shape[0]), first] > 0.0


def _image_exclusion(i, j, t, efib, idx, mesh, wrap, exclude_neighbours):
    """Keep mask of image pairs: a fibril paired with its own wrap continuation is a
    same-fibril pair (index difference along the unwrapped fibril)."""
    keep = np.ones(i.size, bool)
    if wrap is None or i.size == 0:
        return keep
    period = wrap_vectors(wrap, mesh.n_fibrils)
    same = efib[i] == efib[j]
    Lf = period[efib[i]]
    has = same & np.all(np.isfinite(Lf), axis=1)
    if not has.any():
        return keep
    LL = np.where(has, np.einsum("pi,pi->p", np.nan_to_num(Lf), np.nan_to_num(Lf)), 1.0)
    m = np.where(has, np.round(np.einsum("pi,pi->p", t, np.nan_to_num(Lf)) / LL), 0.0)
    along = has & np.all(np.abs(t - m[:, None] * np.nan_to_num(Lf)) <= 1e-9 * np.sqrt(LL)[:, None], axis=1)
    if exclude_neighbours is None:
        return keep & ~along
    n_el = np.diff(np.asarray(mesh.elem_offsets))[efib[i]]
    near = np.abs(idx[i] - (idx[j] + m * n_el)) <= int(exclude_neighbours)
    return keep & ~(along & near)


def wrap_vectors(wrap, n_fibrils: int) -> np.ndarray:
    """(n_fibrils, 3) period vectors, NaN rows for fibrils that do not wrap."""
    out = np.full((int(n_fibrils), 3), np.nan)
    if wrap is None:
        return out
    if isinstance(wrap, dict):
        for f, v in wrap.items():
            out[int(f)] = np.asarray(v, float)
        return out
    w = np.asarray(wrap, float).reshape(int(n_fibrils), 3)
    return np.where(np.all(w == 0.0, axis=1)[:, None], np.nan, w)


@dataclass(frozen=True)
class ElementNeighbours:
    """The elements before and after every element along its fibril.

    ``next`` / ``prev`` (E,): global element index, -1 at a free fibril end;
    ``next_shift`` / ``prev_shift`` (E, 3): the constant translation of the neighbour's
    positions (zero, except across the wrap of a periodic fibril: the last element's next
    is the first element translated by +L_f, the first's prev the last translated by -L_f)."""

    next: np.ndarray
    prev: np.ndarray
    next_shift: np.ndarray
    prev_shift: np.ndarray


def element_neighbours(mesh, wrap=None) -> ElementNeighbours:
    """``ElementNeighbours`` of ``mesh``; ``wrap`` is None, a dict ``{fibril: L_f}`` or an
    (n_fibrils, 3) array of period vectors (zero or NaN rows: the fibril does not wrap)."""
    E = int(mesh.n_elements)
    off = np.asarray(mesh.elem_offsets)
    first, last = off[:-1], off[1:] - 1
    nxt = np.arange(1, E + 1, dtype=np.int64)
    prv = np.arange(-1, E - 1, dtype=np.int64)
    nxt[last] = -1
    prv[first] = -1
    nsh = np.zeros((E, 3))
    psh = np.zeros((E, 3))
    period = wrap_vectors(wrap, mesh.n_fibrils)
    wr = np.flatnonzero(np.all(np.isfinite(period), axis=1))
    nxt[last[wr]] = first[wr]
    prv[first[wr]] = last[wr]
    nsh[last[wr]] = period[wr]
    psh[first[wr]] = -period[wr]
    return ElementNeighbours(nxt, prv, nsh, psh)
