"""Contact on a C¹ contact curve through the element end nodes (docs/contact.md "The smooth
contact curve"): per element a cubic Hermite curve whose end tangents are the averaged
tangents of the Lagrange elements meeting at each node, its closest point, and the
kinematics that the penalty and jump forms of ``rve.physics.contact_curve`` read.

Contract
--------
* **The curve of an element** e (parameter s in [0, 1], nn = p + 1 Lagrange nodes) is
  ``C(s) = h00(s) x_0 + h01(s) x_1 + h10(s) m_0 + h11(s) m_1`` with the cubic Hermite basis
  ``H = (h00, h01, h10, h11)``, ``x_0``, ``x_1`` the element's end nodes and the end
  tangents (d/ds of e)::

      m_0 = (l_e / 2) (t_prev(1) / l_prev + t_e(0) / l_e)     (t_e(0) at a free start)
      m_1 = (l_e / 2) (t_e(1) / l_e + t_next(0) / l_next)     (t_e(1) at a free end)

  where ``t_f(s) = sum_B dN_B/ds x_B`` is the Lagrange tangent of element f and ``l`` the
  elements' reference lengths: the two elements meeting at a node share the tangent
  ``dC/dX`` there, so the contact curve is C¹ along the fibril (for p = 1 and equal
  lengths ``m = (x_{N+1} - x_{N-1}) / 2``, the Catmull-Rom spline). Straight, evenly
  meshed fibrils give the chord exactly.
* **Linear in the nodes, over a stencil.** ``C(s) = H(s) S_e X_e`` with the stencil
  ``X_e`` (Ms, 3): the distinct nodes of prev(e), e and next(e) (``SmoothStencil.nodes``;
  Ms = 3 nn - 2 where neighbours share their end nodes, one more for an element next to a
  periodic wrap, whose neighbour's end node is the tied image node; shorter lists padded
  with an own node of zero weight), and the constant (4, Ms) matrix ``S_e`` (rows: x_0,
  x_1, m_0, m_1). The tangents are differences inside one element (``sum_B dN_B = 0``), so
  a neighbour across a periodic wrap enters with its own positions, unshifted: the curve
  depends on node positions and on the pair's shift only.
* ``smooth_geometry`` gives the ``CurveGeometry`` of points of oriented rows on these
  curves, with the conventions of ``rve.physics.contact_curve`` (closest point by Newton
  from the chord's, snapped within ``END_SNAP`` of an end, owned as there; ``ds`` zero only
  at a free end: at an end that continues into a neighbour the curve is C¹ and the closest
  point moves with the nodes, so the interior formula applies; ``c`` (P, G, M)
  and ``ds`` (P, G, M, 3) over the M = 2 (3 nn) stencil slots of the row: a's stencil, then
  b's), so ``curve_penalty_forces`` and ``curve_scalar_jump`` apply unchanged; ``dc_ds``
  and ``Sb`` (b's stencil matrices) give the friction its material weights
  (``CurveGeometry.material_weights``: ``H(s) S_b`` on b's stencil). ``Na``,
  ``Nb``, ``dNb`` are the Lagrange basis of the scalar fields (T, V) at s_a, s_b, placed in
  the element's own slots of the stencil (``SmoothStencil.own``; zero elsewhere).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fem.hermite import hermite_basis
from .contact_curve import END_SNAP, CurveGeometry, curve_basis

__all__ = ["SmoothStencil", "hermite_basis", "smooth_stencil", "hermite_deviation", "project_to_hermite",
           "smooth_geometry", "smooth_gaps", "HERMITE_BOUND"]

_TINY = 1e-300
#: max over [0, 1] of |h10| and of |h11| (4/27 at s = 1/3, 2/3)
HERMITE_BOUND = 4.0 / 27.0


@dataclass(frozen=True)
class SmoothStencil:
    """Per element (E elements, nn nodes): ``nodes`` (E, Ms) the stencil's distinct nodes
    (module docstring), ``S`` (E, 4, Ms) the Hermite data (x_0, x_1, m_0, m_1) in terms of
    their positions, ``own`` (E, nn) the slots of the element's own nodes."""

    nodes: np.ndarray
    S: np.ndarray
    own: np.ndarray

    @property
    def width(self) -> int:
        return self.nodes.shape[1]

    def control(self, r, elems=None, shift=None) -> np.ndarray:
        """Hermite data Y (n, 4, 3) of the elements ``elems`` (all by default) at positions
        ``r`` (n_nodes, 3), translated by ``shift`` (n, 3) if given."""
        nodes, S = (self.nodes, self.S) if elems is None else (self.nodes[elems], self.S[elems])
        Y = np.matmul(S, r[nodes])
        if shift is not None:
            Y[:, :2] += shift[:, None, :]  # the tangents are differences: no shift
        return Y


def smooth_stencil(order: int, conn, prev, nxt, length) -> SmoothStencil:
    """``SmoothStencil`` of the elements ``conn`` (E, nn) with neighbours ``prev``/``nxt``
    (E,) (-1 at a free end) and reference lengths ``length`` (E,)."""
    conn = np.asarray(conn, np.int64)
    E, nn = conn.shape
    prev, nxt = np.asarray(prev, np.int64), np.asarray(nxt, np.int64)
    length = np.asarray(length, float)
    _, dN, _ = curve_basis(order, np.array([0.0, 1.0]))
    dN0, dN1 = dN[0], dN[1]
    hp, hn = prev >= 0, nxt >= 0
    own = np.arange(E)
    ip, inx = np.where(hp, prev, own), np.where(hn, nxt, own)
    S = np.zeros((E, 4, 3 * nn))
    S[:, 0, nn] = 1.0
    S[:, 1, 2 * nn - 1] = 1.0
    S[:, 2, nn:2 * nn] = np.where(hp, 0.5, 1.0)[:, None] * dN0
    S[:, 2, 0:nn] = np.where(hp, 0.5 * length / length[ip], 0.0)[:, None] * dN1
    S[:, 3, nn:2 * nn] = np.where(hn, 0.5, 1.0)[:, None] * dN1
    S[:, 3, 2 * nn:] = np.where(hn, 0.5 * length / length[inx], 0.0)[:, None] * dN0
    raw = np.concatenate([conn[ip], conn, conn[inx]], axis=1)
    # one slot per distinct node (first occurrence; a shared end node appears twice in raw)
    first = np.argmax(raw[:, :, None] == raw[:, None, :], axis=2)
    is_first = first == np.arange(raw.shape[1])[None, :]
    slot = np.take_along_axis(np.cumsum(is_first, axis=1) - 1, first, axis=1)  # (E, 3 nn)
    Ms = int(is_first.sum(axis=1).max())
    nodes = np.repeat(conn[:, :1], Ms, axis=1)  # padding: an own node, zero weight
    Sc = np.zeros((E, 4, Ms))
    rows = np.arange(E)
    for k in range(raw.shape[1]):
        nodes[rows, slot[:, k]] = raw[:, k]
        Sc[rows, :, slot[:, k]] += S[:, :, k]
    return SmoothStencil(nodes=nodes, S=Sc, own=slot[:, nn:2 * nn])


def hermite_deviation(Y) -> np.ndarray:
    """Bound on the distance of every point of each Hermite curve ``Y`` (E, 4, 3) from its
    chord segment [x_0, x_1]. With d = x_1 - x_0 and ``m_k - d = a_k d + q_k`` (q_k normal to
    d), ``C(s) = x_0 + u(s) d + h10 q_0 + h11 q_1`` with the cubic ``u = s + a_0 h10 + a_1 h11``
    (the basis reproduces the chord when m_0 = m_1 = d): the distance is at most
    4/27 (|q_0| + |q_1|) plus |d| times how far u leaves [0, 1] (its extremes at s = 0, 1 and
    at the roots of u'). Uneven node spacing (a_k != 0) only moves points along the chord."""
    Y = np.asarray(Y, float)
    d = Y[:, 1] - Y[:, 0]
    dd = np.einsum("ei,ei->e", d, d)
    ddsafe = np.where(dd > 0, dd, 1.0)
    a = np.stack([np.einsum("ei,ei->e", Y[:, k] - d, d) / ddsafe for k in (2, 3)], axis=1)  # (E, 2)
    q = [np.linalg.norm(Y[:, k] - d - a[:, k - 2, None] * d, axis=-1) for k in (2, 3)]
    # u' = 3 (a0 + a1) s^2 - (4 a0 + 2 a1) s + (1 + a0): its roots in (0, 1)
    A, B, C = 3.0 * (a[:, 0] + a[:, 1]), -(4.0 * a[:, 0] + 2.0 * a[:, 1]), 1.0 + a[:, 0]
    disc = np.maximum(B * B - 4.0 * A * C, 0.0)
    lin = np.abs(A) < 1e-14
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = np.where(lin, np.where(B != 0, -C / np.where(B != 0, B, 1.0), 0.0), (-B + np.sqrt(disc)) / (2 * A))
        r2 = np.where(lin, 0.0, (-B - np.sqrt(disc)) / (2 * A))
    s = np.clip(np.nan_to_num(np.stack([np.zeros_like(A), np.ones_like(A), r1, r2], axis=1)), 0.0, 1.0)
    H, _, _ = hermite_basis(s)
    u = s + a[:, :1] * H[..., 2] + a[:, 1:] * H[..., 3]
    out = np.maximum(np.maximum(u.max(axis=1) - 1.0, -u.min(axis=1)), 0.0)
    return HERMITE_BOUND * (q[0] + q[1]) + np.sqrt(dd) * out


def project_to_hermite(Yb, p, iterations: int = 12):
    """Closest point parameter on the Hermite curves ``Yb`` (P, 4, 3) of the points ``p``
    (P, G, 3): Newton on ``(C(s) - p).C'(s)`` from the chord's closest point, each iterate
    clamped to [0, 1] (a descent step where the distance is not convex in s), parameters
    within ``END_SNAP`` of an end snapped to it. Returns ``s`` (P, G)."""
    Yb = np.asarray(Yb, float)
    a, b = Yb[:, 0], Yb[:, 1]
    d = b - a
    dd = np.einsum("pi,pi->p", d, d)
    s = np.einsum("pgi,pi->pg", p - a[:, None, :], d) / np.where(dd > 0, dd, 1.0)[:, None]
    s = np.clip(s, 0.0, 1.0)
    for _ in range(iterations):
        H, dH, d2H = hermite_basis(s)
        e = np.matmul(H, Yb) - p
        t = np.matmul(dH, Yb)
        f = np.einsum("pgi,pgi->pg", e, t)
        tt = np.einsum("pgi,pgi->pg", t, t)
        fp = np.maximum(tt + np.einsum("pgi,pgi->pg", e, np.matmul(d2H, Yb)), 0.1 * tt)
        s_new = np.clip(s - f / np.where(fp > 0, fp, 1.0), 0.0, 1.0)
        done = np.abs(s_new - s).max() <= 1e-15
        s = s_new
        if done:
            break
    return np.where(s < END_SNAP, 0.0, np.where(s > 1.0 - END_SNAP, 1.0, s))


def _lagrange_in_stencil(order: int, s, own, Ms: int) -> tuple[np.ndarray, np.ndarray]:
    """Lagrange values and d/ds at ``s`` (P, G) in the stencil layout (P, G, Ms): on the
    element's own slots ``own`` (P, nn), zero elsewhere."""
    N, dN, _ = curve_basis(order, s)
    P, G, nn = N.shape
    Ns, dNs = np.zeros((P, G, Ms)), np.zeros((P, G, Ms))
    idx = np.broadcast_to(np.asarray(own)[:, None, :], (P, G, nn))
    np.put_along_axis(Ns, idx, N, axis=2)
    np.put_along_axis(dNs, idx, dN, axis=2)
    return Ns, dNs


def _closest(Ya, Yb, s_a):
    """The points on a, their Hermite basis and their closest points on b: ``(Ha, p, s_b)``."""
    P = Ya.shape[0]
    G = s_a.shape[-1]
    Ha = np.broadcast_to(hermite_basis(s_a)[0], (P, G, 4))
    p = np.matmul(Ha, Ya)
    s_b = project_to_hermite(Yb, p)
    return Ha, p, s_b


def _owned(Yb, p, s_b, has_next, t_next, has_prev):
    """``(interior, has_next, has_prev, owned)`` of the closest points (P, G)."""
    interior = (s_b > 0.0) & (s_b < 1.0)
    tn = np.asarray(t_next, float)
    tt_next = np.einsum("pi,pi->p", tn, tn)[:, None]
    grows = np.einsum("pgi,pi->pg", Yb[:, 1][:, None, :] - p, tn) >= -2.0 * END_SNAP * tt_next
    hn = np.asarray(has_next, bool)[:, None]
    hp = np.asarray(has_prev, bool)[:, None]
    return interior, hn, hp, interior | ((s_b >= 1.0) & (~hn | grows)) | ((s_b <= 0.0) & ~hp)


def smooth_gaps(Ya, Yb, s_a, gap_radius, has_next, t_next, has_prev) -> np.ndarray:
    """Overlaps (P, G) of ``smooth_geometry``'s points, -inf where not owned (no tangent
    data: the cheap pass of the energy and of the active set)."""
    Ya, Yb = np.asarray(Ya, float), np.asarray(Yb, float)
    _, p, s_b = _closest(Ya, Yb, np.asarray(s_a, float))
    j = p - np.matmul(hermite_basis(s_b)[0], Yb)
    rho = np.sqrt(np.einsum("pgi,pgi->pg", j, j))
    gr = np.asarray(gap_radius, float)
    g = (gr[:, None] if gr.ndim == 1 else gr) - rho
    return np.where(_owned(Yb, p, s_b, has_next, t_next, has_prev)[3], g, -np.inf)


def smooth_geometry(order: int, Ya, Sa, Yb, Sb, s_a, gap_radius, has_next, t_next, has_prev, own_a,
                    own_b) -> CurveGeometry:
    """Contact kinematics of points ``s_a`` (G,) on the Hermite curves ``Ya`` (P, 4, 3)
    (stencil matrices ``Sa`` (P, 4, Ms)) against the curves ``Yb``, ``Sb`` (shifts applied by
    the caller). ``gap_radius`` (P,) or (P, G); ``has_next`` / ``has_prev`` (P,) whether b
    has a next / previous element; ``t_next`` (P, 3) the next element's start tangent (its
    m_0; only its sign against ``C_b(1) - p`` is used, as in ``curve_geometry``); ``own_a``,
    ``own_b`` (P, nn) the stencil slots of the elements' own nodes (``SmoothStencil.own``)."""
    Ya, Yb = np.asarray(Ya, float), np.asarray(Yb, float)
    Sa, Sb = np.asarray(Sa, float), np.asarray(Sb, float)
    P = Ya.shape[0]
    s_a = np.asarray(s_a, float)
    G = s_a.shape[-1]
    Ha, p, s_b = _closest(Ya, Yb, s_a)
    Hb, dHb, d2Hb = hermite_basis(s_b)
    q, t, t2 = np.matmul(Hb, Yb), np.matmul(dHb, Yb), np.matmul(d2Hb, Yb)
    j = p - q
    rho = np.sqrt(np.einsum("pgi,pgi->pg", j, j))
    n = j / np.maximum(rho, _TINY)[..., None]
    gr = np.asarray(gap_radius, float)
    g = (gr[:, None] if gr.ndim == 1 else gr) - rho
    interior, hn, hp, owned = _owned(Yb, p, s_b, has_next, t_next, has_prev)
    ca = np.matmul(Ha, Sa)  # (P, G, Ms): the point's weights on a's stencil
    cb = np.matmul(Hb, Sb)
    c = np.concatenate([ca, -cb], axis=-1)
    m = np.concatenate([np.zeros_like(cb), np.matmul(dHb, Sb)], axis=-1)
    A = np.einsum("pgi,pgi->pg", t, t) - np.einsum("pgi,pgi->pg", j, t2)
    # a closest point snapped to an end that continues into a neighbour still moves with the
    # nodes (the curve is C1 there: its limit from inside b); only a free end clamps it
    free = interior | ((s_b >= 1.0) & hn) | ((s_b <= 0.0) & hp)
    Asafe = np.where(free & (A > 0), A, 1.0)
    ds = (c[..., None] * t[:, :, None, :] + m[..., None] * j[:, :, None, :]) / Asafe[..., None, None]
    ds *= free[..., None, None]
    active = owned & (g > 0.0) & (rho > _TINY)
    Ms = Sa.shape[-1]
    Na, _ = _lagrange_in_stencil(order, np.broadcast_to(s_a, (P, G)), own_a, Ms)
    Nb, dNb = _lagrange_in_stencil(order, s_b, own_b, Ms)
    return CurveGeometry(s_a=np.broadcast_to(s_a, (P, G)), s_b=s_b, j=j, rho=rho, n=n, g=g, c=c, ds=ds,
                         A=A, owned=owned, active=active, Na=Na, Nb=Nb, dNb=dNb, dc_ds=-m, Sb=Sb)
