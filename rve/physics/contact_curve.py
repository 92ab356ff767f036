"""Contact forms on the elements' Lagrange centroid curves (docs/contact.md "Contact on the
centroid curve"): closest point on a curved element, its continuation to the neighbour
element, penalty residual and tangent, thermal / electric jump terms.

Contract
--------
Pure, vectorised functions over all contact points of all *oriented* pairs at once. An
oriented pair (a, b) has its points on element a (the "slave" side of this orientation)
and their closest points on element b. A point sits at the element parameter ``s_a`` in
[0, 1] (``xi = 2 s - 1``, the elements' own Lagrange basis, nn = p + 1 nodes):

* ``p = sum_A N_A(s_a) x_A`` on a, ``q = sum_B N_B(s_b) x_B`` on b, ``[[r]] = p - q``,
  ``rho = |[[r]]|``, ``n = [[r]]/rho`` (from b to a), overlap ``g = gap_radius - rho``.
* ``s_b`` is the closest point on b, found by Newton's method on
  ``f(s) = (q(s) - p).t(s) = 0`` (``t = dq/ds``) from the chord's closest point, each
  iterate clamped to [0, 1]; it is recomputed at every evaluation and its dependence on
  the nodes is in the tangent.
* **Ownership** (the closest point continued across element ends): the point belongs to
  the pair whose b holds the closest point of b's *fibril*: an interior ``s_b`` always
  (a local minimum of the distance); ``s_b = 1`` only when b has no next element (a free
  fibril end) or the distance to the next element grows from the shared node,
  ``(x_b(1) - p).t_next(0) >= 0`` (to a tolerance that matches the projection's snap of
  parameters within 1e-9 of an end to the end); ``s_b = 0`` only when b has no previous
  element. So of
  the pairs (a, b) and (a, next b) exactly one takes a point whose closest point is the
  shared node, and a point whose projection moves on leaves one pair for the other with
  the same position, gap and normal: the force is continuous. Not owned points carry no
  force; ``active = owned & (g > 0)``.
* Local unknowns of an oriented pair: the nn nodes of a, then the nn nodes of b (x, y, z).
  With ``c = (N_a(s_a), -N_b(s_b))`` (2nn), ``[[r]] = sum c_K x_K``, ``dg/dX_K = -c_K n``
  (envelope theorem: ``n.t = 0`` at an interior closest point, ``ds = 0`` at a clamped
  one), and with ``m = (0, dN_b/ds)``, ``A = t.t - [[r]].t'``,
  ``ds/dX_K = (c_K t + m_K [[r]]) / A`` (zero where ``s_b`` is clamped). The Hessian of g
  is ``-(1/rho) c c^T (x) (I - n n^T) + (A/rho) ds ds^T`` (symmetric), so for the energy
  density ``phi(g)`` (``rve.physics.contact_forms.penalty_law``)::

      R = -w phi'(g) c (x) n
      K = w [ phi'' c c^T (x) n n^T + (phi'/rho) ( c c^T (x) (n n^T - I) + A ds ds^T ) ]

  For p = 1 (``A = |d|^2``, ``m = (0, 0, -1, 1)``) these are the chord formulas of
  ``rve.physics.contact_forms``.
* Scalar jumps ``[[du]] k(g) [[u]]`` with ``[[u]] = u_a(s_a) - u_b(s_b)``: the per-point
  conductance ``k`` (``w`` times coefficient times width) and ``dk/dg`` are passed in, so
  any conductance law of the gap or of the line load fits.

Arrays: P oriented pairs, G points, nn nodes per element, M = 2 nn local nodes.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Optional

import numpy as np

from ..fem.hermite import hermite_basis
from ..fem.lagrange import lagrange_basis, lagrange_nodes
from .contact_forms import PointKinematics, penalty_law, point_loads

__all__ = [
    "CurveGeometry",
    "curve_basis",
    "curve_geometry",
    "curve_penalty_forces",
    "curve_penalty_energy",
    "curve_scalar_jump",
    "chord_deviation",
    "END_SNAP",
    "lagrange_monomials",
    "gauss_legendre_01",
    "lebesgue_constant",
    "project_to_curve",
]

_TINY = 1e-300
#: closest-point parameters this close to 0 or 1 are taken as the element end
END_SNAP = 1e-9


def gauss_legendre_01(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre points and weights on [0, 1] (weights sum to 1)."""
    t, w = np.polynomial.legendre.leggauss(int(n))
    return 0.5 * (t + 1.0), 0.5 * w


@lru_cache(maxsize=None)
def lagrange_monomials(order: int) -> np.ndarray:
    """(nn, nn) monomial coefficients C of the Lagrange basis in xi: N_a(xi) = sum_k C[a, k] xi^k."""
    xi = lagrange_nodes(order)
    V = np.vander(xi, order + 1, increasing=True)
    return np.linalg.inv(V).T  # N_a(xi) = sum_k C[a, k] xi^k


def curve_basis(order: int, s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lagrange values and their first and second derivatives in s at element parameters
    ``s`` (any shape) -> three arrays (..., nn)."""
    s = np.asarray(s, float)
    xi = (2.0 * s - 1.0).ravel()
    N, dN = lagrange_basis(order, xi)
    C = lagrange_monomials(order)
    nn = order + 1
    k = np.arange(2, nn)
    if k.size:
        mono = (k * (k - 1))[None, :] * xi[:, None] ** (k - 2)[None, :]
        d2N = mono @ C[:, 2:].T
    else:
        d2N = np.zeros_like(N)
    shape = s.shape + (nn,)
    return N.reshape(shape), 2.0 * dN.reshape(shape), 4.0 * d2N.reshape(shape)


def project_to_curve(order: int, Xb, p, iterations: int = 12):
    """Closest point parameter on the element curves ``Xb`` (P, nn, 3) of the points ``p``
    (P, G, 3): Newton on ``(q(s) - p).t(s)`` from the chord's closest point, each iterate
    clamped to [0, 1]. Returns ``s`` (P, G)."""
    Xb = np.asarray(Xb, float)
    a, b = Xb[:, 0], Xb[:, -1]
    d = b - a
    dd = np.einsum("pi,pi->p", d, d)
    s = np.einsum("pgi,pi->pg", p - a[:, None, :], d) / np.where(dd > 0, dd, 1.0)[:, None]
    s = np.clip(s, 0.0, 1.0)
    if order == 1:
        return s
    for _ in range(iterations):
        N, dN, d2N = curve_basis(order, s)
        q = np.matmul(N, Xb)
        t = np.matmul(dN, Xb)
        t2 = np.matmul(d2N, Xb)
        e = q - p
        f = np.einsum("pgi,pgi->pg", e, t)
        tt = np.einsum("pgi,pgi->pg", t, t)
        fp = tt + np.einsum("pgi,pgi->pg", e, t2)
        fp = np.maximum(fp, 0.1 * tt)  # a descent step where the distance is not convex in s
        step = f / np.where(fp > 0, fp, 1.0)
        s_new = np.clip(s - step, 0.0, 1.0)
        done = np.abs(s_new - s).max() <= 1e-15
        s = s_new
        if done:
            break
    # a closest point within END_SNAP of an element end is that end, so that of two
    # neighbour elements exactly one owns a point whose projection is their shared node
    # (round-off in the tangents decides the sign of a zero derivative otherwise)
    s = np.where(s < END_SNAP, 0.0, np.where(s > 1.0 - END_SNAP, 1.0, s))
    return s


@lru_cache(maxsize=None)
def lebesgue_constant(order: int) -> float:
    """max_s sum_a |N_a(s)| of the equispaced Lagrange basis (sampled finely, rounded up by
    1e-6): the interpolant of nodal deviations is at most this times the largest one."""
    N, _, _ = curve_basis(order, np.linspace(0.0, 1.0, 4001))
    return float(np.abs(N).sum(axis=1).max()) + 1e-6


def chord_deviation(order: int, X) -> np.ndarray:
    """Bound on the distance between each element curve ``X`` (E, nn, 3) and its chord at
    the same parameter: the Lebesgue constant times the largest nodal deviation from the
    chord (the chord is reproduced exactly by the basis). Zero for p = 1."""
    X = np.asarray(X, float)
    if order == 1:
        return np.zeros(X.shape[0])
    u = np.linspace(0.0, 1.0, order + 1)
    chord = X[:, :1, :] + u[None, :, None] * (X[:, -1:, :] - X[:, :1, :])
    dev = np.sqrt(((X - chord) ** 2).sum(axis=-1)).max(axis=1)
    return lebesgue_constant(order) * dev


@dataclass
class CurveGeometry(PointKinematics):
    """Kinematics of the points of P oriented pairs (G points each) on the centroid curves:
    :class:`~rve.physics.contact_forms.PointKinematics` (ds zero where s_b is clamped),
    plus s_a, s_b (P, G); A (P, G) = t.t - [[r]].t'; owned (P, G) bool; Na (P, G, nn) (or
    (G, nn)), Nb, dNb (P, G, nn) (the Lagrange basis of the scalar fields).

    What the friction of the points reads (``rve.physics.friction_forms``): ``dc_ds``
    (P, G, M) = d c / d s_b (zero on the a side, minus the b side's basis derivative), so
    ``sum_k dc_ds_k X_k = -dq/ds``; ``material_weights(s)`` (P, G, M): the weights of the
    jump between the a points and the b points at parameters ``s`` (the a side's weights of
    ``c``, minus b's basis at ``s``: Lagrange, or on the smooth curve the Hermite basis
    times the stencil matrix ``Sb`` (P, 4, Ms); ``Sb`` None: the Lagrange curve);
    ``s_plus``, ``s_minus``: s_a and s_b under the chord's names."""

    s_a: np.ndarray
    s_b: np.ndarray
    A: np.ndarray
    owned: np.ndarray
    Na: np.ndarray
    Nb: np.ndarray
    dNb: np.ndarray
    dc_ds: Optional[np.ndarray] = None
    Sb: Optional[np.ndarray] = None

    @property
    def s_plus(self) -> np.ndarray:
        return self.s_a

    @property
    def s_minus(self) -> np.ndarray:
        return self.s_b

    def minus_basis(self, s) -> np.ndarray:
        """b's basis at parameters ``s`` (P, G): (P, G, M/2) (Lagrange, or Hermite times ``Sb``)."""
        s = np.asarray(s, float)
        if self.Sb is None:
            return curve_basis(self.Nb.shape[-1] - 1, s)[0]
        return np.matmul(hermite_basis(s)[0], self.Sb)

    def material_weights(self, s_bar) -> np.ndarray:
        half = self.c.shape[-1] // 2
        plus = np.broadcast_to(self.c[..., :half], np.shape(s_bar) + (half,))
        return np.concatenate([plus, -self.minus_basis(s_bar)], axis=-1)

    def direction_weights(self, s) -> np.ndarray:
        """``(P, G, M)`` weights ``D`` of the - side's direction ``d = sum_k D_k X_k`` at
        points ``s`` (P, G) of b (the friction takes it at the closest point): b's tangent
        ``dq/ds`` there (zero on the a side). Continuous along b's fibril on the smooth curve
        (C^1), so the friction's anchor turns the same way on either side of an element end
        (``rve.physics.friction_forms``)."""
        return self._minus_derivative(s, 1)

    def direction_weights_ds(self, s) -> np.ndarray:
        """``(P, G, M)`` derivative of ``direction_weights`` in ``s`` (b's ``d2q/ds2``)."""
        return self._minus_derivative(s, 2)

    def _minus_derivative(self, s, k: int) -> np.ndarray:
        s = np.asarray(s, float)
        half = self.c.shape[-1] // 2
        if self.Sb is None:
            dN = curve_basis(self.Nb.shape[-1] - 1, s)[k]
        else:
            dN = np.matmul(hermite_basis(s)[k], self.Sb)
        dN = np.broadcast_to(dN, s.shape + (half,))
        return np.concatenate([np.zeros(s.shape + (half,)), dN], axis=-1)


def curve_geometry(order: int, Xa, Xb, s_a, gap_radius, has_next, t_next, has_prev) -> CurveGeometry:
    """Contact kinematics of points ``s_a`` (G,) on the curves ``Xa`` (P, nn, 3) against the
    curves ``Xb`` (P, nn, 3) (positions as they are, shifts applied by the caller).

    ``gap_radius`` (P,) or (P, G); ``has_next`` / ``has_prev`` (P,) whether b has a next /
    previous element along its fibril; ``t_next`` (P, 3) that next element's tangent at its
    first node (any positive scale; only its sign against ``x_b(1) - p`` is used)."""
    Xa = np.asarray(Xa, float)
    Xb = np.asarray(Xb, float)
    P, nn, _ = Xa.shape
    s_a = np.asarray(s_a, float)
    G = s_a.shape[-1]
    Na, _, _ = curve_basis(order, s_a)
    Na = np.broadcast_to(Na, (P, G, nn))
    p = np.matmul(Na, Xa)
    s_b = project_to_curve(order, Xb, p)
    Nb, dNb, d2Nb = curve_basis(order, s_b)
    q = np.matmul(Nb, Xb)
    t = np.matmul(dNb, Xb)
    t2 = np.matmul(d2Nb, Xb)
    j = p - q
    rho = np.sqrt(np.einsum("pgi,pgi->pg", j, j))
    n = j / np.maximum(rho, _TINY)[..., None]
    gr = np.asarray(gap_radius, float)
    g = (gr[:, None] if gr.ndim == 1 else gr) - rho
    interior = (s_b > 0.0) & (s_b < 1.0)
    end_b = Xb[:, -1]
    tn = np.asarray(t_next, float)
    # the distance grows into the next element (its derivative there, d/ds (q - p)^2 / 2,
    # is >= 0); the tolerance matches the end snap of the projection: f ~ -|t|^2 s
    tt_next = np.einsum("pi,pi->p", tn, tn)[:, None]
    grows = np.einsum("pgi,pi->pg", end_b[:, None, :] - p, tn) >= -2.0 * END_SNAP * tt_next
    hn = np.asarray(has_next, bool)[:, None]
    hp = np.asarray(has_prev, bool)[:, None]
    owned = interior | ((s_b >= 1.0) & (~hn | grows)) | ((s_b <= 0.0) & ~hp)
    c = np.concatenate([Na, -Nb], axis=-1)  # (P, G, M)
    m = np.concatenate([np.zeros_like(Nb), dNb], axis=-1)
    A = np.einsum("pgi,pgi->pg", t, t) - np.einsum("pgi,pgi->pg", j, t2)
    Asafe = np.where(interior & (A > 0), A, 1.0)
    ds = (c[..., None] * t[:, :, None, :] + m[..., None] * j[:, :, None, :]) / Asafe[..., None, None]
    ds *= interior[..., None, None]
    active = owned & (g > 0.0) & (rho > _TINY)
    return CurveGeometry(s_a=np.broadcast_to(s_a, (P, G)), s_b=s_b, j=j, rho=rho, n=n, g=g, c=c, ds=ds,
                         A=A, owned=owned, active=active, Na=Na, Nb=Nb, dNb=dNb, dc_ds=-m)


def curve_penalty_energy(geo: CurveGeometry, weight, penalty, onset: float = 0.0) -> float:
    """``sum_points w phi(g)`` over the owned points (its gradient is the residual)."""
    w = np.broadcast_to(np.asarray(weight, float), geo.g.shape)
    e, _, _ = penalty_law(np.where(geo.active, geo.g, 0.0), penalty, onset)
    return float((w * e).sum())


def curve_penalty_forces(geo: CurveGeometry, weight, penalty, jacobian: bool = True, onset: float = 0.0):
    """Penalty residual (P, M, 3) and tangent (P, M, 3, M, 3) (None without jacobian).

    ``weight`` (P, G) or broadcastable; ``penalty`` P* (scalar); ``onset`` ε (mm)."""
    P, G = geo.g.shape
    M = geo.c.shape[-1]
    w = np.broadcast_to(np.asarray(weight, float), (P, G))
    f, B, fr = point_loads(geo, w, penalty, onset, jacobian)
    R = -np.matmul(np.swapaxes(f[..., None] * geo.c, 1, 2), geo.n)
    if not jacobian:
        return R, None
    cc = (geo.c[..., :, None] * geo.c[..., None, :]).reshape(P, G, M * M)
    K = np.matmul(np.swapaxes(cc, 1, 2), B.reshape(P, G, 9)).reshape(P, M, M, 3, 3).transpose(0, 1, 3, 2, 4)
    beta = fr * np.where(geo.active, geo.A, 0.0)
    D = geo.ds.reshape(P, G, 3 * M)
    K = K + np.matmul(np.swapaxes(D * beta[..., None], 1, 2), D).reshape(P, M, 3, M, 3)
    return R, K


def curve_scalar_jump(geo: CurveGeometry, u_a, u_b, cond, dcond, jacobian: bool = True):
    """Jump term ``sum_points [[du]] k [[u]]`` of T or V on the oriented pairs.

    ``u_a``, ``u_b`` (P, nn) nodal values; ``cond`` (P, G) the per-point conductance k
    (zero where not active) and ``dcond`` (P, G) its derivative dk/dg. Returns
    ``(R (P, M), Ju (P, M, M), JX (P, M, M, 3))`` (Ju, JX None without jacobian)."""
    ua = np.asarray(u_a, float)
    ub = np.asarray(u_b, float)
    nn = ua.shape[1]
    jump = np.einsum("pga,pa->pg", geo.Na, ua) - np.einsum("pga,pa->pg", geo.Nb, ub)
    k = np.where(geo.active, cond, 0.0)
    flux = k * jump
    phi = np.concatenate([geo.Na, -geo.Nb], axis=-1)
    R = np.einsum("pg,pgA->pA", flux, phi)
    if not jacobian:
        return R, None, None
    Ju = np.einsum("pg,pgA,pgB->pAB", k, phi, phi, optimize=True)
    dub = np.einsum("pga,pa->pg", geo.dNb, ub)
    dgdX = -geo.c[..., None] * geo.n[:, :, None, :]  # (P, G, M, 3)
    dk = np.where(geo.active, dcond, 0.0)
    dflux = (dk * jump)[..., None, None] * dgdX - (k * dub)[..., None, None] * geo.ds
    JX = np.einsum("pgA,pgKi->pAKi", phi, dflux, optimize=True)
    JX[:, nn:] -= np.einsum("pga,pg,pgKi->paKi", geo.dNb, flux, geo.ds, optimize=True)
    return R, Ju, JX
