"""Contact forms between fibrils: penalty traction, Hertz width, thermal and electric jumps.

Thesis §4.3.2-4.3.3 and §4.4.6 (the contact integral of the summed variational form);
SPEC §3; derivation and choices in docs/contact.md.

Contract
--------
Pure, vectorised functions over ALL contact quadrature points at once (no Python loop over
pairs or points). A contact point k of pair p sits at the chord parameter ``s+`` on the +
element and ``s-`` on the - element (conventions of ``rve.contact.search``: the chord of an
element runs from its first to its last node, ``r(s) = (1 - s) r_a + s r_b``).

* Geometry on the **linear centroid chords** (SPEC §3, thesis simplification 1): the four
  chord end positions ``X = (a+, b+, a-, b-)`` (each (P, 3)) are the only mechanical
  unknowns of a pair. ``p = a+ + s+ (b+ - a+)``, ``q = a- + s- (b- - a-)``,
  ``[[r]] = p - q``, ``rho = |[[r]]|``, ``n = [[r]]/rho`` (pointing from - to +),
  overlap ``g = R+ + R- - rho``.
* ``s-`` is **recomputed at every evaluation** as the clamped closest point (eq. 4.3.2)
  by default (``chord_geometry(..., s_minus=None)``), and its dependence on X is in the
  tangent (``ds`` below; zero where the closest point is clamped to a chord end). The
  contact is then the gradient of the energy ``sum_k w_k P*/2 <g_k>^2`` of a frictionless
  contact: no spurious tangential force when fibrils slide between two rebuilds of the map.
  Passing a frozen ``s_minus`` gives the frozen-table variant of the thesis (``ds = 0``,
  the tangent is exact for it too).
* Penalty (mechanics): on the points with ``g > 0`` the force on the + side is
  ``w P* g n`` (and its opposite on the - side), distributed to the chord ends with the
  linear weights ``c = (1 - s+, s+, -(1 - s-), -s-)``. Residual (internal-force sign of
  ``M dw/dt + F = 0``): ``F_X = -w P* g c n``. Tangent, with ``d = b- - a-``::

      K = w P* [ c c^T (x) ((1 + g/rho) n n^T - (g/rho) I) + (g/rho) |d|^2 ds ds^T ]

  (exact; ``ds`` = d s- / d X, (4, 3) per point). Zero for ``g <= 0``: the residual is C^1
  at the onset g = 0 (it vanishes there), the tangent jumps.
* **Onset smoothing** (``onset`` = ε, mm; default 0 = the linear law above): the penalty is
  the derivative of the energy density ``φ(g)`` per unit length, ``φ = P* g³/(6ε)`` for
  ``0 < g < ε`` and ``P* (g²/2 − ε g/2 + ε²/6)`` beyond, so the line load ``φ'`` rises as
  ``P* g²/(2ε)`` and joins ``P* (g − ε/2)``, and the stiffness ``φ''`` ramps from 0 to P*
  (C² energy, continuous tangent: Newton's model does not jump when a point touches).
  With ``φ'`` and ``φ''`` the tangent above reads
  ``K = w [φ'' c cᵀ ⊗ n nᵀ + (φ'/ρ)(c cᵀ ⊗ (n nᵀ − I) + |d|² ds dsᵀ)]``; ε = 0 gives
  ``φ' = P* g``, ``φ'' = P*``. ``penalty_law`` evaluates φ, φ', φ''; ``penalty_energy`` the
  summed energy ``Σ w φ(g)`` (the residual is its exact gradient). ``chord_gaps`` is the
  overlap alone (no tangent data), for a cheap pass over all pairs.
* Hertz line-contact width ``a(g) = kappa sqrt(g)``, ``kappa = sqrt(4 R* P* / (pi E*))``
  (P* g is the line load). Its derivative ``kappa / (2 sqrt g)`` is unbounded at the onset;
  ``hertz_width`` regularises with ``a = kappa g / sqrt(g + g_eps)`` (relative error
  ``g_eps / (2 g)`` for ``g >> g_eps``, slope ``kappa / sqrt(g_eps)`` at g = 0, a(0) = 0).
  ``g_eps = 0`` gives the exact square root (derivative infinite at 0).
* Thermal / electric jump terms ``[[du]] c_C a(g) [[u]]`` (u = T with c_C = h_C, u = V with
  c_C = sigma_C): u is interpolated with the **elements' own Lagrange basis** at the
  reference coordinate ``xi = 2 s - 1`` (so interior nodes of p >= 2 elements take part);
  ``[[u]] = u+(s+) - u-(s-)``. Residual rows: ``+w c_C a [[u]] N+`` on the + element's
  nodes and ``-w c_C a [[u]] N-(s-)`` on the - element's. Positive semi-definite in u, as
  the conduction terms of the model. The x-tangent has the a'(g) term and, with a
  recomputed s-, the dN-/ds terms.
* Weights: ``w = l+ / n_gp`` per point, ``l+`` the + element's length in the reference
  parameter xi3 (the thesis integrates ``d xi3`` along the + element; see docs).

Arrays: P pairs, G points per pair, nn nodes per element. Local mechanical unknowns are
ordered (node k in (a+, b+, a-, b-), component i), local scalar unknowns (+ element nodes,
then - element nodes).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fem.lagrange import lagrange_basis

__all__ = [
    "ChordGeometry",
    "chord_direction_weights",
    "chord_geometry",
    "hertz_kappa",
    "hertz_width",
    "penalty_forces",
    "penalty_law",
    "penalty_energy",
    "chord_gaps",
    "scalar_jump",
    "effective_modulus",
    "effective_radius",
]

_CM = np.array([0.0, 0.0, 1.0, -1.0])  # d(d)/dX coefficients, with d = b- - a- (sign: -C^T)
#: d c / d s- of the chord weights c = (1 - s+, s+, -(1 - s-), -s-)
_DIRECTION = np.array([0.0, 0.0, -1.0, 1.0])


def chord_direction_weights(s) -> np.ndarray:
    """``(P, G, 4)`` weights of the chord ``b- - a-`` in the chord ends at any points ``s``
    (P, G): (0, 0, -1, 1) (``ChordGeometry.direction_weights``)."""
    return np.broadcast_to(_DIRECTION, np.shape(s) + (4,))
_DC_DS = np.array([0.0, 0.0, 1.0, -1.0])


def effective_radius(R_plus, R_minus):
    """R* = (1/R+ + 1/R-)^-1."""
    return 1.0 / (1.0 / np.asarray(R_plus, float) + 1.0 / np.asarray(R_minus, float))


def effective_modulus(E_plus, E_minus, nu_plus=0.0, nu_minus=0.0):
    """Hertz E* with 1/E* = (1 - nu+^2)/E+ + (1 - nu-^2)/E- (E/2 for equal fibrils, nu = 0)."""
    return 1.0 / ((1.0 - nu_plus**2) / E_plus + (1.0 - nu_minus**2) / E_minus)


def hertz_kappa(R_star, penalty, E_star):
    """kappa of a = kappa sqrt(g): sqrt(4 R* P* / (pi E*))."""
    return np.sqrt(4.0 * np.asarray(R_star, float) * penalty / (np.pi * E_star))


def hertz_width(g, kappa, g_eps: float = 0.0):
    """Regularised Hertz width and its derivative, ``(a, da/dg)``; zero for g <= 0.

    ``a = kappa g / sqrt(g + g_eps)``; with ``g_eps = 0`` the exact ``kappa sqrt(g)``."""
    g = np.asarray(g, float)
    pos = g > 0
    gp = np.where(pos, g, 0.0)
    den = np.sqrt(gp + g_eps)
    safe = np.where(pos, den, 1.0)
    a = np.where(pos, kappa * gp / safe, 0.0)
    da = np.where(pos, kappa * (gp + 2.0 * g_eps) / (2.0 * safe**3), 0.0)
    return a, da


@dataclass
class PointKinematics:
    """What a contact point's forms read, for the chord and the curve alike: j (P, G, 3) =
    [[r]]; rho (P, G) = |[[r]]|; n (P, G, 3) = [[r]]/rho; g (P, G) the overlap; c (P, G, M)
    the node weights of [[r]]; ds (P, G, M, 3) = d s/d X of the closest point; active
    (P, G) bool."""

    j: np.ndarray
    rho: np.ndarray
    n: np.ndarray
    g: np.ndarray
    c: np.ndarray
    ds: np.ndarray
    active: np.ndarray


@dataclass
class ChordGeometry(PointKinematics):
    """Per-point kinematics of the contact table (P pairs, G points) on the chords
    (:class:`PointKinematics`, M = 4: c the chord weights of X in [[r]], ds zero when
    clamped or frozen; active = g > 0), plus s_plus, s_minus (P, G) and dd (P,) =
    |b- - a-|^2."""

    s_plus: np.ndarray
    s_minus: np.ndarray
    dd: np.ndarray

    def material_weights(self, s_bar) -> np.ndarray:
        """``(P, G, 4)`` weights of the chord ends in the jump between the + points and the
        - points at ``s_bar`` (P, G): ``(1 - s+, s+, -(1 - s_bar), -s_bar)`` (the friction's
        material points, ``rve.physics.friction_forms``)."""
        sb = np.asarray(s_bar, float)
        return np.stack([1.0 - self.s_plus, self.s_plus, -(1.0 - sb), -sb], axis=-1)

    def direction_weights(self, s_bar) -> np.ndarray:
        """``(P, G, 4)`` weights ``D`` of the - side's direction ``d = sum_k D_k X_k`` at
        points ``s_bar`` (P, G): the chord ``b- - a-``, (0, 0, -1, 1) at every point (the
        friction's turn of its anchor, ``rve.physics.friction_forms``)."""
        return chord_direction_weights(s_bar)

    def direction_weights_ds(self, s_bar) -> np.ndarray:
        """``(P, G, 4)`` derivative of ``direction_weights`` in ``s``: zero (a chord's
        direction is the same at every point)."""
        return np.zeros(np.shape(s_bar) + (4,))

    @property
    def dc_ds(self) -> np.ndarray:
        """``(P, G, 4)`` derivative of ``c`` in the closest point ``s-``: (0, 0, 1, -1)."""
        return np.broadcast_to(_DC_DS, self.c.shape)


def chord_geometry(ap, bp, am, bm, s_plus, gap_radius, s_minus=None) -> ChordGeometry:
    """Contact kinematics for chords (a+, b+) and (a-, b-), each (P, 3).

    ``gap_radius`` (P,) is R+ + R- (or (P, G), one per point: R+ + R- + lambda/P* of the
    augmented Lagrangian). ``s_minus=None`` recomputes the clamped closest points
    (with their tangent ``ds``); an array freezes them (``ds = 0``)."""
    ap, bp, am, bm = (np.asarray(v, float) for v in (ap, bp, am, bm))
    sp_ = np.asarray(s_plus, float)
    P, G = sp_.shape
    p = ap[:, None, :] + sp_[..., None] * (bp - ap)[:, None, :]
    d = bm - am
    dd = np.einsum("pi,pi->p", d, d)
    ddsafe = np.where(dd > 0, dd, 1.0)
    if s_minus is None:
        st = np.einsum("pgi,pi->pg", p - am[:, None, :], d) / ddsafe[:, None]
        st = np.where(dd[:, None] > 0, st, 0.0)
        s = np.clip(st, 0.0, 1.0)
        free = (st > 0.0) & (st < 1.0)
    else:
        s = np.broadcast_to(np.asarray(s_minus, float), (P, G)).copy()
        free = np.zeros((P, G), bool)
    q = am[:, None, :] + s[..., None] * d[:, None, :]
    j = p - q
    rho = np.sqrt(np.einsum("pgi,pgi->pg", j, j))
    tiny = 1e-300
    n = j / np.maximum(rho, tiny)[..., None]
    gr = np.asarray(gap_radius, float)
    g = (gr[:, None] if gr.ndim == 1 else gr) - rho
    c = np.stack([1.0 - sp_, sp_, -(1.0 - s), -s], axis=-1)  # (P, G, 4)
    # ds/dX_k = (c_k d - cm_k [[r]]) / |d|^2 where the closest point is interior
    ds = (c[..., None] * d[:, None, None, :] - _CM[None, None, :, None] * j[:, :, None, :]) / ddsafe[:, None, None, None]
    ds *= free[..., None, None]
    active = (g > 0.0) & (rho > tiny)
    return ChordGeometry(j=j, rho=rho, n=n, g=g, c=c, ds=ds, active=active, s_plus=sp_, s_minus=s, dd=dd)


def penalty_law(g, penalty, onset: float = 0.0):
    """Energy density per unit length ``φ(g)``, line load ``φ'(g)`` and stiffness ``φ''(g)``
    of the penalty (all zero for g <= 0); ``onset`` ε (mm) is the width of the C² cubic
    onset (0: ``φ = P* g²/2``). ``penalty`` scalar or broadcastable to g."""
    g = np.asarray(g, float)
    P = np.asarray(penalty, float)
    gp = np.maximum(g, 0.0)
    if onset <= 0.0:
        return 0.5 * P * gp * gp, P * gp, np.where(g > 0.0, P, 0.0)
    eps = float(onset)
    lo = gp < eps
    e = np.where(lo, P * gp**3 / (6.0 * eps), P * (0.5 * gp * gp - 0.5 * eps * gp + eps * eps / 6.0))
    f = np.where(lo, P * gp * gp / (2.0 * eps), P * (gp - 0.5 * eps))
    k = np.where(g > 0.0, np.where(lo, P * gp / eps, P), 0.0)
    return e, f, k


def penalty_energy(geo, weight, penalty, onset: float = 0.0) -> float:
    """``Σ_points w φ(g)``: the penalty energy whose gradient is ``penalty_forces``' residual.
    ``geo`` needs ``g`` (and ``active``) only: a ``ChordGeometry`` or the ``chord_gaps`` array."""
    g = geo.g if hasattr(geo, "g") else np.asarray(geo, float)
    w = np.broadcast_to(np.asarray(weight, float).reshape(g.shape[0], -1), g.shape)
    Ps = np.asarray(penalty, float)
    Ps = Ps[:, None] if Ps.ndim == 1 else Ps
    e, _, _ = penalty_law(g, Ps, onset)
    return float((w * e).sum())



def point_loads(geo, weight, penalty, onset, jacobian: bool):
    """Per contact point of a penalty law on overlaps ``geo.g`` (P, G) with normals ``geo.n``
    and distances ``geo.rho``: ``f`` the line load times ``weight`` (zero where not active)
    and, with ``jacobian``, the point stiffness ``A = (k + f/rho) n n^T - (f/rho) I``
    (P, G, 3, 3) and ``f/rho`` (else None, None); shared by the chord and the curve forms."""
    _, phi1, phi2 = penalty_law(np.where(geo.active, geo.g, 0.0), penalty, onset)
    f = np.where(geo.active, weight * phi1, 0.0)
    if not jacobian:
        return f, None, None
    k = np.where(geo.active, weight * phi2, 0.0)
    rho = np.where(geo.active, geo.rho, 1.0)
    fr = f / rho
    nn = geo.n[..., :, None] * geo.n[..., None, :]
    return f, (k + fr)[..., None, None] * nn - fr[..., None, None] * np.eye(3), fr


def penalty_forces(geo: ChordGeometry, weight, penalty, jacobian: bool = True, onset: float = 0.0):
    """Penalty residual (P, 4, 3) and tangent (P, 4, 3, 4, 3) (None without jacobian).

    ``weight`` (P,) or (P, G): quadrature weight of each point; ``penalty`` P* (scalar or
    (P,)), the line load per unit overlap; ``onset`` the C² onset width ε (mm, 0: linear)."""
    w = np.broadcast_to(np.asarray(weight, float).reshape(geo.g.shape[0], -1), geo.g.shape)
    Ps = np.asarray(penalty, float)
    Ps = Ps[:, None] if Ps.ndim == 1 else Ps
    f, A, fr = point_loads(geo, w, Ps, onset, jacobian)
    R = -np.einsum("pg,pgk,pgi->pki", f, geo.c, geo.n)
    if not jacobian:
        return R, None
    P_, G_ = geo.g.shape
    # sum over points as batched matmuls: (c_k c_l) x A_ij and (beta ds_ki) x ds_lj
    cc = (geo.c[..., :, None] * geo.c[..., None, :]).reshape(P_, G_, 16)
    K = np.matmul(np.swapaxes(cc, 1, 2), A.reshape(P_, G_, 9)).reshape(P_, 4, 4, 3, 3).transpose(0, 1, 3, 2, 4)
    beta = fr * geo.dd[:, None]  # (P, G)
    if np.any(beta != 0.0):
        D = geo.ds.reshape(P_, G_, 12)
        K = K + np.matmul(np.swapaxes(D * beta[..., None], 1, 2), D).reshape(P_, 4, 3, 4, 3)
    else:
        K = np.ascontiguousarray(K)
    return R, K


def chord_gaps(ap, bp, am, bm, s_plus, gap_radius, s_minus=None) -> np.ndarray:
    """Overlaps ``g`` (P, G) only (same conventions as ``chord_geometry``, no tangent data):
    the cheap pass that finds the active pairs before the full geometry of those pairs."""
    ap, bp, am, bm = (np.asarray(v, float) for v in (ap, bp, am, bm))
    sp_ = np.asarray(s_plus, float)
    e = bp - ap
    d = bm - am
    h = ap - am
    if s_minus is None:
        dd = np.einsum("pi,pi->p", d, d)
        ddsafe = np.where(dd > 0, dd, 1.0)
        # (p - a-).d = h.d + s+ e.d, linear in s+
        hd = np.einsum("pi,pi->p", h, d)
        ed = np.einsum("pi,pi->p", e, d)
        s = np.clip((hd[:, None] + sp_ * ed[:, None]) / ddsafe[:, None], 0.0, 1.0)
        s = np.where(dd[:, None] > 0, s, 0.0)
    else:
        s = np.asarray(s_minus, float)
    j = h[:, None, :] + sp_[..., None] * e[:, None, :] - s[..., None] * d[:, None, :]
    rho = np.sqrt(np.einsum("pgi,pgi->pg", j, j))
    gr = np.asarray(gap_radius, float)
    return (gr[:, None] if gr.ndim == 1 else gr) - rho


def lagrange_at(order: int, s) -> tuple[np.ndarray, np.ndarray]:
    """Element Lagrange values and d/ds at chord parameters s (any shape) -> (..., nn) each."""
    s = np.asarray(s, float)
    N, dN = lagrange_basis(order, (2.0 * s - 1.0).ravel())
    nn = order + 1
    return N.reshape(s.shape + (nn,)), 2.0 * dN.reshape(s.shape + (nn,))


def scalar_jump(geo: ChordGeometry, order: int, u_plus, u_minus, weight, coef, kappa, g_eps: float = 0.0,
                jacobian: bool = True, width=None):
    """Thermal or electric contact term ``int [[du]] coef a(g) [[u]]`` for all pairs.

    ``u_plus``, ``u_minus`` (P, nn): nodal T or V of the two elements; ``coef`` h_C or
    sigma_C; ``kappa`` (scalar or (P,)) of the Hertz width. Returns ``(R, Ju, JX)``:
    R (P, 2nn) rows (+ nodes, - nodes); Ju (P, 2nn, 2nn) = dR/du; JX (P, 2nn, 4, 3) =
    dR/dX (chord ends). Ju, JX are None without jacobian. ``width`` (optional) is a pair
    ``(a, da/dg)`` of (P, G) arrays that replaces the Hertz width (another conductance law)."""
    P, G = geo.g.shape
    w = np.broadcast_to(np.asarray(weight, float).reshape(P, -1), (P, G))
    kap = np.asarray(kappa, float)
    kap = kap[:, None] if kap.ndim == 1 else kap
    if width is None:
        a, da = hertz_width(np.where(geo.active, geo.g, 0.0), kap, g_eps)
    else:
        a, da = (np.where(geo.active, v, 0.0) for v in width)
    Np, _ = lagrange_at(order, geo.s_plus)  # (P, G, nn)
    Nm, dNm = lagrange_at(order, geo.s_minus)
    up = np.asarray(u_plus, float)
    um = np.asarray(u_minus, float)
    jump = np.einsum("pga,pa->pg", Np, up) - np.einsum("pga,pa->pg", Nm, um)
    k = np.where(geo.active, w * coef, 0.0)  # (P, G)
    flux = k * a * jump
    phi = np.concatenate([Np, -Nm], axis=-1)  # (P, G, 2nn)
    R = np.einsum("pg,pgA->pA", flux, phi)
    if not jacobian:
        return R, None, None
    Ju = np.einsum("pg,pgA,pgB->pAB", k * a, phi, phi, optimize=True)
    # d flux / dX = k [ a'(g) [[u]] dg/dX - a (du-/ds) ds/dX ],  dg/dX_k = -c_k n
    dum = np.einsum("pga,pa->pg", dNm, um)
    dgdX = -geo.c[..., None] * geo.n[:, :, None, :]  # (P, G, 4, 3)
    dflux = (k * da * jump)[..., None, None] * dgdX - (k * a * dum)[..., None, None] * geo.ds
    JX = np.einsum("pgA,pgki->pAki", phi, dflux, optimize=True)
    # the - rows also move with N-(s-): d(-N- flux)/dX = -dN-/ds flux ds/dX
    nn = order + 1
    JX[:, nn:] -= np.einsum("pga,pg,pgki->paki", dNm, flux, geo.ds, optimize=True)
    return R, Ju, JX
