"""Regularised Coulomb friction at the beam-beam contact points: the elastic tangential
penalty with slip by return mapping, and its exact (unsymmetric) consistent tangent
(choices and derivation: docs/contact.md "Friction").

Contract
--------
Pure, vectorised functions over ALL contact points of a contact geometry at once (P pairs
or oriented rows, G points, M local nodes ``X`` (P, M, 3)): the chord (M = 4, ``X = (a+,
b+, a-, b-)``, ``rve.physics.contact_forms``), the Lagrange centroid curve (M = 2 nn, the
nodes of a then of b, ``rve.physics.contact_curve``) and the smooth Hermite curve (M = 2 Ms,
the stencils of a then of b, ``rve.physics.contact_smooth``). The + side is the side of the
points (the chord's + element, a curve row's a), the - side the side of their current
closest points ``s-`` (s_b). What the geometry ``geo`` supplies: ``c`` (P, G, M) the
current weights of the jump ``j = p - q(s-) = sum_k c_k X_k``, ``ds`` (P, G, M, 3) =
d s- / d X, ``n`` from - to +, ``rho``, ``j``, ``active``, ``s_minus``, ``dc_ds`` (P, G, M) =
dc / ds- (so ``sum_k dc_ds_k X_k = -dq/ds``), and ``material_weights(s)`` (P, G, M): the
weights of the jump between the + points and the - points at parameters ``s`` (equal to
``c`` at ``s = s-``). Chord: ``c = (1 - s+, s+, -(1 - s-), -s-)``, ``dc_ds = (0, 0, 1, -1)``.

* **History** of a point (from the last converged state): ``s_bar``, the *material* point
  of the - side that was in contact then (a parameter of the - element, continued beyond
  [0, 1] by its polynomial), and ``anchor`` (3,) = ``e_n - j_n``, its elastic tangential
  gap minus the jump ``j_n = p - q(s_bar)`` of the two material points then, and
  ``d_ref`` (3,), the unit direction of the - side at the material point then
  (``minus_direction`` with the geometry's ``direction_weights``: the - element's chord; on
  the curves b's tangent at ``s_bar``, continuous along the smooth curve).
  ``start_history(X, s_plus, s_minus)`` is the history of points with no elastic gap.
* **Trial gap**: ``u = R anchor + j(X; s_bar)`` with ``j(X; s_bar) = sum_k cb_k X_k``,
  ``cb = material_weights(s_bar)`` (chord: ``(1 - s+, s+, -(1 - s_bar), -s_bar)``), and
  ``R`` the smallest rotation that turns ``d_ref`` into the - chord's current direction
  ``h = d/|d|`` (Rodrigues: ``R a = a + v x a + v x (v x a)/(1 + c)``, ``v = d_ref x h``,
  ``c = d_ref . h``; ``d_ref`` None: ``R = I``): the elastic gap of the last converged state
  plus the relative displacement of the two material points since then, the stored part
  turned with the - element. Why ``R``: the anchor holds ``-j_n``, a vector of the length of
  the two radii along the old normal; left unturned, a rigid rotation of the pair about an
  axis across the - fibril would read as a tangential slip of (angle x radii), far above the
  stick length. ``R`` makes the gap objective under every rotation but the one about the -
  fibril's own axis, which positions alone cannot tell from the + side sliding around it
  (the capstan) and which counts as sliding. ``e = (I - n n^T) u`` its part in the current
  tangent plane (so the friction force is tangent to the contact at every state).
* **Return mapping**: with the point stiffness ``kT = w eps_T`` (N/mm) and the point normal
  force ``f = w phi'(g)`` (N), the trial force ``kT e`` sticks where ``kT |e| <= mu f``,
  else it slips: ``t = mu f e / |e|``. Inactive points (g <= 0): ``t = 0``.
* **Residual** (internal-force sign, the - side gets the opposite force): the force on the
  + material point is ``-t``, on the - side ``+t`` at the *current* closest point ``s-``
  (where the fibrils touch), distributed with the current weights ``c``: ``R_k = c_k t``.
  With ``d_ref`` the - chord's ends also carry the couple of the anchor's turn, ``R_k += D_k
  C`` (``D`` the chord's weights, ``C = rho h x (n x t) / |d|``: its moment is the part
  across the - fibril of ``rho n x t``), evaluated from the current geometry, so that the
  work of the forces is that of the turned gap. So a commit (the material point moved to
  ``s-``, the anchor so that ``u`` is unchanged, ``d_ref = h``) changes no force: a converged
  state stays an equilibrium under its own history.
* **Tangent** ``K_kl = c_k dt/dX_l + t dc_k/dX_l + D_k dC/dX_l`` (``dc_k/dX_l = dc_ds_k ds_l^T``) with,
  per point, ``Q_l = c_l I + jd ds_l^T`` (``dj/dX_l`` of the current jump, ``jd = sum_k
  dc_ds_k X_k = -dq/ds`` at ``s-``; chord: ``jd = -(b- - a-)``),
  ``de/dX_l = P du_l - (n.u / rho) P Q_l - (1/rho) n e^T Q_l`` (``P = I - n n^T``,
  ``du_l = cb_l I + J (I - h h^T) D_l / |d|``, ``J = d(R anchor)/dh``, ``D`` the weights of
  the chord direction ``d = sum_k D_k X_k``),
  stick: ``dt/dX_l = kT de/dX_l``; slip: ``dt/dX_l = mu e_hat df/dX_l + (mu f/|e|)
  (I - e_hat e_hat^T) de/dX_l`` with ``df/dX_l = -w phi''(g) c_l n^T``. Unsymmetric in
  slip (the ``df`` column and the projection).
* ``friction_state`` also returns what a step commits: the new history at the state
  (``s_bar`` = the current closest point, ``anchor = t/kT - j``, ``d_ref = h``) and the dissipated energy
  ``t . (e - t/kT)`` of every point (the work of the force on the slip of the return map).
* **Incremental potential at frozen loads** (``frozen_potential``; the predictor of the
  frictional static step, ``rve.solvers.frictional``): with the normal force ``f0`` and
  the normal ``n0`` of every point frozen (taken from a state), the gap
  ``e0 = (I - n0 n0^T) u`` is linear in ``X`` and the return map ``t(e0)`` is the gradient
  of the convex, C^1 Huber function ``psi(e0) = kT |e0|^2 / 2`` (stick,
  ``kT |e0| <= mu f0``), ``mu f0 |e0| - (mu f0)^2 / (2 kT)`` (slip). So
  ``sum_p psi(e0_p(X))`` is a convex potential whose gradient is ``R_k = cb_k t`` and
  whose Hessian is ``K_kl = cb_k cb_l D`` with ``D = kT P0`` (stick),
  ``(mu f0/|e0|)(P0 - e_hat e_hat^T)`` (slip): symmetric, positive semi-definite. The
  material point is frozen with the loads: ``moved_history(X, s_plus, s_bar, anchor,
  s_star, d_ref=...)`` is the history with the material point at ``s_star``, the anchor
  turned by ``R`` (and ``d_ref`` the chord's direction at ``X``), the same ``u`` at ``X``. At loads and point frozen at the state itself (``f0 = f(X)``, ``n0 = n(X)``,
  ``s_star = s-(X)``) the potential's gradient is the residual of the law above.
  ``start_history``, ``moved_history`` and ``frozen_potential`` take the chord's ``s_plus``
  or, on any geometry, ``weights``: a function ``s -> (P, G, M)`` material weights (e.g.
  ``geo.material_weights``; ``s_plus`` is then not read).
* **The frame law** (``frame_friction_forces``; the reference forms, not yet the assembled
  term's law): the anchor carried by the - cross-section's frame ``(h, b_hat, h x b_hat)``,
  ``b_hat`` the unit part of the - side's first director g1 across ``h`` (``section_frame``,
  ``framed_anchor``), so the gap is objective under every rotation, the twist about the -
  fibril included; the history adds ``m_ref``, ``b_hat`` at the commit. Residual and tangent
  in the centroid and g1 components of the local nodes (6 a node); the couple's twist part,
  which a chord cannot take, goes to g1 (docs/contact.md "Objectivity").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .contact_forms import chord_direction_weights

__all__ = ["FrictionPoints", "friction_state", "friction_forces", "start_history", "material_weights",
           "tangential_gap", "frozen_potential", "moved_history", "minus_direction", "turned_anchor",
           "frozen_turn", "section_frame", "framed_anchor", "frame_friction_forces", "frame_friction_state",
           "frame_tangential_gap", "frame_moved_history", "frame_frozen_turn", "frame_frozen_potential",
           "frame_refreeze"]


def material_weights(s_plus, s_bar) -> np.ndarray:
    """``cb`` (P, G, 4): the weights of the chord ends in the jump of the material points
    (``ChordGeometry.material_weights``)."""
    sp_ = np.asarray(s_plus, float)
    sb = np.asarray(s_bar, float)
    return np.stack([1.0 - sp_, sp_, -(1.0 - sb), -sb], axis=-1)


def _weights_of(s_plus, weights):
    """The material weights function: ``weights`` itself, or the chord's of ``s_plus``."""
    if weights is not None:
        return weights
    return lambda s: material_weights(s_plus, s)


def start_history(X, s_plus, s_minus, weights=None):
    """``(s_bar, anchor)`` of points with no elastic gap at local nodes ``X`` (P, M, 3): the
    material point is the closest point ``s_minus`` (P, G), ``anchor = -j(X; s_minus)``
    (``weights``: module docstring)."""
    cb = _weights_of(s_plus, weights)(s_minus)
    return np.array(s_minus, float, copy=True), -np.einsum("pgk,pki->pgi", cb, X)


def minus_direction(X, D):
    """``(h, D, |d|)``: the unit direction ``h`` (P, G, 3) of the - side at local nodes ``X``
    (P, M, 3), ``d = sum_k D_k X_k`` with the weights ``D`` (P, G, M) of a geometry's
    ``direction_weights`` (the chord's ``b- - a-``; on the curves b's tangent at the material
    point), and ``|d|`` (P, G)."""
    D = np.asarray(D, float)
    d = np.einsum("pgk,pki->pgi", D, X)
    dn = np.sqrt(np.einsum("pgi,pgi->pg", d, d))
    return d / np.where(dn > 0, dn, 1.0)[..., None], D, dn


def _skew(a):
    """``S(a)`` (..., 3, 3) with ``S(a) y = a x y``."""
    z = np.zeros(a.shape[:-1])
    return np.stack([np.stack([z, -a[..., 2], a[..., 1]], -1), np.stack([a[..., 2], z, -a[..., 0]], -1),
                     np.stack([-a[..., 1], a[..., 0], z], -1)], -2)


def turned_anchor(anchor, d_ref, h, jacobian: bool = False):
    """``R anchor`` (P, G, 3), ``R`` the smallest rotation from ``d_ref`` to ``h`` (module
    docstring), and with ``jacobian`` its derivative ``J = d(R anchor)/dh`` (P, G, 3, 3)
    (``d_ref`` None: ``anchor``, ``J`` None)."""
    a = np.asarray(anchor, float)
    if d_ref is None:
        return (a, None) if jacobian else a
    r = np.asarray(d_ref, float)
    v = np.cross(r, h)
    c1 = 1.0 + np.einsum("pgi,pgi->pg", r, h)
    w = np.cross(v, a)
    z = np.cross(v, w)
    out = a + w + z / c1[..., None]
    if not jacobian:
        return out
    Sr, Sa = _skew(r), _skew(a)
    dw = -Sa @ Sr
    dz = -_skew(w) @ Sr + _skew(v) @ dw
    J = dw + dz / c1[..., None, None] - z[..., :, None] * r[..., None, :] / (c1 * c1)[..., None, None]
    return out, J


def section_frame(h, g):
    """``(b_hat, w_hat, |b|)`` (P, G, 3), (P, G, 3), (P, G): the - cross-section's frame
    ``(h, b_hat, w_hat = h x b_hat)`` from the unit - direction ``h`` and the - side's
    director ``g`` (g1 at the point): ``b = g - h (h . g)``, its part across ``h``."""
    b = g - np.einsum("pgi,pgi->pg", h, g)[..., None] * h
    bn = np.sqrt(np.einsum("pgi,pgi->pg", b, b))
    bh = b / np.where(bn > 0, bn, 1.0)[..., None]
    return bh, np.cross(h, bh), bn


def framed_anchor(anchor, d_ref, m_ref, h, g, jacobian: bool = False):
    """``Q anchor`` (P, G, 3) with ``Q = F(h, g) F_ref^T`` the rotation that takes the
    committed frame ``F_ref = (d_ref, m_ref, d_ref x m_ref)`` of the - cross-section to its
    current one ``F = (h, b_hat, h x b_hat)`` (``section_frame``): the anchor carried by the
    - cross-section, so a rigid rotation about any axis, the - fibril's own included, turns
    it with the pair. With ``jacobian`` also ``(Jh, Jg)`` (P, G, 3, 3), ``d(Q anchor)/dh``
    and ``d(Q anchor)/dg`` (``Jg = (h x (Q anchor)) w_hat^T / |b|``: only the director's
    component along ``w_hat`` turns the frame)."""
    a = np.asarray(anchor, float)
    r, m = np.asarray(d_ref, float), np.asarray(m_ref, float)
    al1 = np.einsum("pgi,pgi->pg", r, a)
    al2 = np.einsum("pgi,pgi->pg", m, a)
    al3 = np.einsum("pgi,pgi->pg", np.cross(r, m), a)
    bh, wh, bn = section_frame(h, g)
    out = al1[..., None] * h + al2[..., None] * bh + al3[..., None] * wh
    if not jacobian:
        return out
    I3 = np.eye(3)
    inv_b = 1.0 / np.where(bn > 0, bn, 1.0)
    hg = np.einsum("pgi,pgi->pg", h, g)
    # d b_hat = (I - b_hat b_hat^T) db / |b|, db = (I - h h^T) dg - ((h . g) I + h g^T) dh
    Pb = (I3 - bh[..., :, None] * bh[..., None, :]) * inv_b[..., None, None]
    dbh_dh = -Pb @ (hg[..., None, None] * I3 + h[..., :, None] * g[..., None, :])
    dbh_dg = Pb @ (I3 - h[..., :, None] * h[..., None, :])
    Sh = _skew(h)
    # d w_hat = -S(b_hat) dh + S(h) d b_hat
    Jh = (al1[..., None, None] * I3 + al2[..., None, None] * dbh_dh
          + al3[..., None, None] * (-_skew(bh) + Sh @ dbh_dh))
    Jg = (al2[..., None, None] * I3 + al3[..., None, None] * Sh) @ dbh_dg
    return out, (Jh, Jg)


def frozen_turn(X, D, n, rho, active):
    """``(Dw, Jd, d)``: the turn of the anchor frozen at local nodes ``X`` (P, M, 3) for
    ``frozen_potential(turn=(Dw, Jd))``: ``Dw`` (P, G, M) = ``D``, the direction weights of
    the - side at the points' material points (``minus_direction``), ``d`` (P, G, 3) that
    direction, ``Jd = J0 (I - h h^T) / |d|`` with ``J0 = -S(a) S(h)`` the derivative of the
    smallest rotation from ``h`` at ``h`` applied to ``a = -rho n`` (the points' normals ``n``
    and distances ``rho``; zero where not ``active``), so that the frozen potential's gradient
    at ``X`` carries the law's couple ``rho h x (n x t) / |d|``."""
    h, Dw, dn = minus_direction(X, D)
    a = -np.where(active, rho, 0.0)[..., None] * n
    # J0 = -S(a) S(h) = (a.h) I - h a^T; J0 (I - h h^T) = (a.h)(I - h h^T) - h (a - (a.h) h)^T
    ah = np.einsum("pgi,pgi->pg", a, h)
    Pi = np.eye(3) - h[..., :, None] * h[..., None, :]
    J0Pi = ah[..., None, None] * Pi - h[..., :, None] * (a - ah[..., None] * h)[..., None, :]
    Jd = J0Pi / np.where(dn > 0, dn, 1.0)[..., None, None]
    return Dw, Jd, h * dn[..., None]


def moved_history(X, s_plus, s_bar, anchor, s_star, weights=None, d_ref=None, directions=None):
    """``(s_star, anchor')`` (and ``d_ref'`` when ``d_ref`` is given): the history
    (``s_bar`` (P, G), ``anchor`` (P, G, 3), ``d_ref`` (P, G, 3)) with its material point
    moved to ``s_star`` (P, G) (the closest point at ``X``), its anchor turned to the - side's
    direction there (``d_ref'``, the direction of the turn at ``X``), the trial gap ``u`` at
    local nodes ``X`` (P, M, 3) unchanged, ``anchor' = R anchor + j(X; s_bar) - j(X;
    s_star)``; ``directions`` the direction weights ``s -> (P, G, M)`` (a geometry's
    ``direction_weights``; None: the chord's)."""
    wf = _weights_of(s_plus, weights)
    jb = np.einsum("pgk,pki->pgi", wf(s_bar), X)
    js = np.einsum("pgk,pki->pgi", wf(s_star), X)
    if d_ref is None:
        return np.array(s_star, float, copy=True), np.asarray(anchor, float) + jb - js
    h = minus_direction(X, (chord_direction_weights if directions is None else directions)(s_star))[0]
    return np.array(s_star, float, copy=True), turned_anchor(anchor, d_ref, h) + jb - js, h


@dataclass
class FrictionPoints:
    """Per point (P, G): ``t`` (P, G, 3) the friction force (on the - material point; the +
    side gets -t); ``slip`` bool (active and slipping), ``stick`` bool (active and
    sticking); ``e`` (P, G, 3) the trial tangential gap; the committed history at this
    state ``s_bar``, ``anchor``, ``d_ref`` (None when the history has none);
    ``dissipation`` (P, G) the energy of the return map's slip (N mm); ``normal`` (P, G)
    the point normal forces; with ``d_ref``, ``couple`` (P, G, 3) the couple's force ``C``
    on the - chord ends with the weights ``chord_weights`` (P, G, M) (``R_k += D_k C``)."""

    t: np.ndarray
    slip: np.ndarray
    stick: np.ndarray
    e: np.ndarray
    s_bar: np.ndarray
    anchor: np.ndarray
    dissipation: np.ndarray
    normal: np.ndarray
    d_ref: np.ndarray = None
    couple: np.ndarray = None
    chord_weights: np.ndarray = None
    #: the frame law (``frame_friction_state``): the committed frame's ``b_hat``, the couple
    #: ``C_g`` on the - side's g1 and its weights (P, G, M)
    m_ref: np.ndarray = None
    director_couple: np.ndarray = None
    director_weights: np.ndarray = None


def _trial(geo, X, s_bar, anchor, d_ref=None):
    """``(cb, u, un, e, chord)``: the trial gap and, with ``d_ref``, the - chord's
    ``(h, D, |d|)`` at the closest point ``s-`` (``minus_direction``; None without ``d_ref``)."""
    cb = geo.material_weights(s_bar)
    jb = np.einsum("pgk,pki->pgi", cb, X)
    chord = None
    u = anchor
    if d_ref is not None:
        chord = minus_direction(X, geo.direction_weights(geo.s_minus))
        u = turned_anchor(anchor, d_ref, chord[0])
    u = u + jb
    un = np.einsum("pgi,pgi->pg", geo.n, u)
    e = u - un[..., None] * geo.n
    return cb, u, un, e, chord


def tangential_gap(geo, X, s_bar, anchor, d_ref=None) -> np.ndarray:
    """The trial tangential gap ``e`` (P, G, 3) at ``X`` from the history: at the state the
    history was committed at, the elastic gap of every contact point."""
    return _trial(geo, X, s_bar, anchor, d_ref)[3]


def _return_map(e, f, kT, mu, active):
    en = np.sqrt(np.einsum("pgi,pgi->pg", e, e))
    limit = mu * f
    stick = active & (kT * en <= limit)
    slip = active & ~stick
    scale = np.where(stick, kT, np.where(slip, limit / np.where(en > 0, en, 1.0), 0.0))
    return en, stick, slip, scale[..., None] * e


def friction_state(geo, X, s_bar, anchor, f, kT, mu, d_ref=None) -> FrictionPoints:
    """Return mapping at local nodes ``X`` (P, M, 3) from the history (``s_bar`` (P, G),
    ``anchor`` (P, G, 3), ``d_ref`` (P, G, 3) or None); ``f`` (P, G) the point normal forces
    (zero where inactive), ``kT`` (P, G) the point tangential stiffnesses, ``mu`` (P,) or
    (P, G)."""
    mu = _per_point(mu, f.shape)
    active = geo.active & (f > 0.0) & (mu > 0.0)
    _, _, _, e, chord = _trial(geo, X, s_bar, anchor, d_ref)
    _, stick, slip, t = _return_map(e, f, kT, mu, active)
    el = np.where(active[..., None], t / np.where(kT > 0, kT, 1.0)[..., None], 0.0)
    diss = np.where(slip, np.einsum("pgi,pgi->pg", t, e - el), 0.0)
    h = D = C = None
    if chord is not None:
        h, D, dn = chord
        C = _couple(geo, t, h, dn, active)
    return FrictionPoints(t=t, slip=slip, stick=stick, e=e, s_bar=np.array(geo.s_minus, float, copy=True),
                          anchor=el - geo.j, dissipation=diss, normal=np.asarray(f, float), d_ref=h, couple=C,
                          chord_weights=D)


def _per_point(mu, shape):
    mu = np.asarray(mu, float)
    return np.broadcast_to(mu[:, None] if mu.ndim == 1 else mu, shape)


def friction_forces(geo, X, s_bar, anchor, f, kN, kT, mu, jacobian: bool = True, d_ref=None):
    """Friction residual (P, M, 3) and tangent (P, M, 3, M, 3) (None without jacobian).

    ``geo`` the geometry of the points at local nodes ``X`` (P, M, 3) (module docstring);
    history ``s_bar``, ``anchor``, ``d_ref`` (None: no turn); per point ``f`` the normal
    force and ``kN`` its stiffness ``w phi''(g)`` (zero where inactive), ``kT`` the
    tangential stiffness; ``mu`` (P,) or (P, G)."""
    mu = _per_point(mu, f.shape)
    active = geo.active & (f > 0.0) & (mu > 0.0)
    cb, u, un, e, chord = _trial(geo, X, s_bar, anchor, d_ref)
    en, stick, slip, t = _return_map(e, f, kT, mu, active)
    R = np.einsum("pgk,pgi->pki", geo.c, t)
    if chord is not None:   # the couple of the turned anchor (module docstring)
        h, D, dn = chord
        C = _couple(geo, t, h, dn, active)
        R = R + np.einsum("pgk,pgi->pki", D, C)
    if not jacobian:
        return R, None
    P_, G_ = f.shape
    I3 = np.eye(3)
    n = geo.n
    rho = np.where(active, geo.rho, 1.0)
    dc_ds = geo.dc_ds
    jd = np.einsum("pgk,pki->pgi", dc_ds, X)       # dj/ds- = -dq/ds at the closest point
    # Q_l = c_l I + jd ds_l^T: (P, G, M, 3, 3)
    Q = geo.c[..., None, None] * I3 + jd[:, :, None, :, None] * geo.ds[:, :, :, None, :]
    Pn = I3 - n[..., :, None] * n[..., None, :]
    PQ = np.einsum("pgij,pgljk->pglik", Pn, Q)
    eQ = np.einsum("pgi,pglij->pglj", e, Q)
    dE = (cb[..., None, None] * Pn[:, :, None]
          - (un / rho)[..., None, None, None] * PQ
          - n[:, :, None, :, None] * eQ[:, :, :, None, :] / rho[..., None, None, None])
    if chord is not None:   # the turned anchor: du_l += J (I - h h^T) dd_l / |d|
        _, J = turned_anchor(anchor, d_ref, h, jacobian=True)
        Jd = J @ (I3 - h[..., :, None] * h[..., None, :]) / np.where(dn > 0, dn, 1.0)[..., None, None]
        PJd = Pn @ Jd
        dE = dE + D[..., None, None] * PJd[:, :, None]
        # dd/dX_l = D_l I + q'' ds_l^T: the direction is taken at the closest point s-(X)
        Dp = geo.direction_weights_ds(geo.s_minus)
        q2 = np.einsum("pgk,pki->pgi", Dp, X)
        dE = dE + np.einsum("pgij,pgj->pgi", PJd, q2)[:, :, None, :, None] * geo.ds[:, :, :, None, :]
    # stick: kT dE; slip: mu e_hat df^T + (mu f/|e|)(I - e_hat e_hat^T) dE
    ehat = e / np.where(en > 0, en, 1.0)[..., None]
    proj = I3 - ehat[..., :, None] * ehat[..., None, :]
    a_slip = np.where(slip, mu * f / np.where(en > 0, en, 1.0), 0.0)
    dT = np.where(stick[..., None, None, None], kT[..., None, None, None] * dE, 0.0)
    slip_dE = a_slip[..., None, None, None] * np.einsum("pgij,pgljk->pglik", proj, dE)
    # df/dX_l = -kN c_l n^T
    df = -(kN * mu)[..., None, None] * geo.c[..., None] * n[:, :, None, :]  # (P, G, M, 3) = mu df/dX_l
    slip_df = np.where(slip[..., None, None, None], ehat[:, :, None, :, None] * df[:, :, :, None, :], 0.0)
    dT = dT + np.where(slip[..., None, None, None], slip_dE + slip_df, 0.0)
    # K_kilj = sum_g c_gk dT_g,l,i,j + t_gi dc_gk/dX_lj, dc_k/dX_l = dc_ds_k ds_l
    K = np.einsum("pgk,pglij->pkilj", geo.c, dT, optimize=True)
    K += np.einsum("pgk,pgilj->pkilj", dc_ds, t[..., :, None, None] * geo.ds[:, :, None, :, :])
    if chord is not None:
        K += np.einsum("pgk,pglij->pkilj", D, _couple_tangent(geo, t, h, D, dn, Q, dT, rho, active, q2))
        # the weights D_k(s-) of the couple (C above) move with the closest point
        K += np.einsum("pgk,pgi,pglj->pkilj", Dp, C, geo.ds)
    return R, K


def _couple(geo, t, h, dn, active):
    """``C = rho h x (n x t) / |d|`` (P, G, 3): the force pair ``(-C, +C)`` on the - chord's
    ends whose moment is the part across the - fibril of ``rho n x t``, the moment of the
    friction force about the - centre line (the work of turning the anchor with the chord)."""
    rho = np.where(active, geo.rho, 0.0)
    M = np.cross(geo.n, t)
    return (rho / np.where(dn > 0, dn, 1.0))[..., None] * np.cross(h, M)


def _couple_tangent(geo, t, h, D, dn, Q, dT, rho, active, q2):
    """``dC/dX_l`` (P, G, M, 3, 3) of ``_couple`` (``Q_l = dj/dX_l``, ``dT`` = dt/dX_l,
    ``dd/dX_l = D_l I + q2 ds_l^T``, ``q2`` (P, G, 3) the direction's derivative in s-)."""
    I3 = np.eye(3)
    n = geo.n
    inv_d = 1.0 / np.where(dn > 0, dn, 1.0)
    r = np.where(active, rho, 0.0)
    M = np.cross(n, t)
    hM = np.cross(h, M)                                          # h x (n x t)
    Pn = I3 - n[..., :, None] * n[..., None, :]
    Pi = I3 - h[..., :, None] * h[..., None, :]
    Sh, Sn, St, SM = _skew(h), _skew(n), _skew(t), _skew(M)
    drho = np.einsum("pgi,pglij->pglj", n, Q)                      # (P, G, M, 3)
    dn_ = np.einsum("pgij,pgljk->pglik", Pn, Q) / np.where(active, rho, 1.0)[..., None, None, None]
    dh = D[..., None, None] * (Pi * inv_d[..., None, None])[:, :, None]          # (P, G, M, 3, 3)
    dh = dh + (np.einsum("pgij,pgj->pgi", Pi, q2) * inv_d[..., None])[:, :, None, :, None] * geo.ds[:, :, :, None, :]
    ddn = D[..., None] * h[:, :, None, :] + np.einsum("pgi,pgi->pg", h, q2)[..., None, None] * geo.ds  # d|d|/dX_l
    # d(h x (n x t)) = -S(M) dh - S(h) S(t) dn + S(h) S(n) dt
    dhM = (-np.einsum("pgij,pgljk->pglik", SM, dh) - np.einsum("pgij,pgljk->pglik", Sh @ St, dn_)
           + np.einsum("pgij,pgljk->pglik", Sh @ Sn, dT))
    out = (inv_d[..., None, None, None] * (hM[:, :, None, :, None] * drho[:, :, :, None, :]
                                           + r[..., None, None, None] * dhM)
           - (r * inv_d * inv_d)[..., None, None, None] * hM[:, :, None, :, None] * ddn[:, :, :, None, :])
    return np.where(active[..., None, None, None], out, 0.0)


def _smooth_cone(x, eta):
    """The smoothed corner of the return map (``frozen_potential`` with ``eta > 0``): with
    ``x = |e| / delta``, the force ``mu f0 phi(x)`` and the potential ``(mu f0)^2 / kT Phi(x)``,
    ``phi(x) = (x + 1 - sqrt((x - 1)^2 + eta^2)) / 2 - c0`` (``c0`` so that phi(0) = 0: min(x, 1)
    with its corner rounded over ~eta), ``Phi`` its integral from 0; returns ``(Phi, phi,
    phi', phi / x)``."""
    def S(z):
        r = np.sqrt(z * z + eta * eta)
        return 0.5 * (z * r + eta * eta * np.arcsinh(z / eta))

    r = np.sqrt((x - 1.0) ** 2 + eta * eta)
    c0 = 0.5 * (1.0 - np.sqrt(1.0 + eta * eta))
    phi = 0.5 * (x + 1.0 - r) - c0
    dphi = 0.5 * (1.0 - (x - 1.0) / r)
    Phi = 0.25 * x * x + 0.5 * x - 0.5 * (S(x - 1.0) - S(-1.0)) - c0 * x
    small = x < 1e-8
    over = np.where(small, dphi, phi / np.where(small, 1.0, x))
    return Phi, phi, dphi, over


def frozen_potential(X, s_plus, s_bar, anchor, f0, n0, kT, mu, jacobian: bool = True, eta: float = 0.0,
                     weights=None, turn=None):
    """The incremental potential of the points at frozen loads (module docstring):
    ``(psi (P, G), R (P, M, 3), K (P, M, 3, M, 3) or None)`` at local nodes ``X`` (P, M, 3)
    from the history (``s_bar``, ``anchor``), ``s_plus`` (P, G) the chord's + points (or
    ``weights``, module docstring), the frozen normal forces ``f0`` (P, G) (0: no friction
    at the point) and normals ``n0`` (P, G, 3), ``kT`` (P, G) and ``mu`` (P,) or (P, G).
    ``eta > 0``: the corner of the cone rounded (``_smooth_cone``; convex and C^2, the force
    within ``(1 + eta^2/4) mu f0``), the predictor's continuation towards ``eta = 0``, the
    law. ``turn = (Dw, Jd)`` (``Dw`` (P, G, M) the weights of the - chord ``d``, ``Jd`` (P, G,
    3, 3)): the anchor's turn with the chord frozen as linear, ``u = anchor + sum_k cb_k X_k
    + Jd d(X)``, i.e. the matrix weights ``W_k = cb_k I + Dw_k Jd``: ``R_k = W_k^T t``, ``K_kl =
    W_k^T D W_l`` (symmetric, positive semi-definite)."""
    f0 = np.asarray(f0, float)
    cb = _weights_of(s_plus, weights)(s_bar)
    if eta > 0.0:
        return _frozen_smooth(X, cb, anchor, f0, n0, kT, mu, jacobian, float(eta), turn)
    mu = _per_point(mu, f0.shape)
    u = _frozen_gap(X, cb, anchor, turn)
    e = u - np.einsum("pgi,pgi->pg", n0, u)[..., None] * n0
    limit = np.where((f0 > 0.0) & (mu > 0.0), mu * f0, 0.0)
    en, stick, slip, t = _return_map(e, limit, kT, 1.0, limit > 0.0)
    kTs = np.where(kT > 0, kT, 1.0)
    psi = np.where(stick, 0.5 * kT * en * en, np.where(slip, limit * en - 0.5 * limit * limit / kTs, 0.0))
    R = _frozen_force(cb, turn, t)
    if not jacobian:
        return psi, R, None
    I3 = np.eye(3)
    P0 = I3 - n0[..., :, None] * n0[..., None, :]
    ehat = e / np.where(en > 0, en, 1.0)[..., None]
    a_slip = np.where(slip, limit / np.where(en > 0, en, 1.0), 0.0)
    D = (np.where(stick, kT, 0.0)[..., None, None] * P0
         + a_slip[..., None, None] * (P0 - ehat[..., :, None] * ehat[..., None, :]))
    return psi, R, _frozen_hessian(cb, turn, D)


def _frozen_gap(X, cb, anchor, turn):
    u = anchor + np.einsum("pgk,pki->pgi", cb, X)
    if turn is not None:
        Dw, Jd = turn
        u = u + np.einsum("pgij,pgj->pgi", Jd, np.einsum("pgk,pki->pgi", Dw, X))
    return u


def _frozen_force(cb, turn, t):
    R = np.einsum("pgk,pgi->pki", cb, t)
    if turn is not None:
        Dw, Jd = turn
        R = R + np.einsum("pgk,pgi->pki", Dw, np.einsum("pgji,pgj->pgi", Jd, t))
    return R


def _frozen_hessian(cb, turn, D):
    if turn is None:
        return np.einsum("pgk,pgl,pgij->pkilj", cb, cb, D, optimize=True)
    if turn is not None:
        # K_kl = sum_g W_k^T D W_l with W_k = cb_k I + Dw_k Jd, as (3M x 3) blocks per point
        Dw, Jd = turn
        P_, G_, M_ = cb.shape
        W = Dw[..., None, None] * Jd[:, :, None]                                       # (P, G, M, 3, 3)
        i3 = np.arange(3)
        W[..., i3, i3] += cb[..., None]
        B = np.ascontiguousarray(W.transpose(0, 1, 3, 2, 4)).reshape(P_, G_, 3, 3 * M_)  # B[a, (k, i)]
        K = (np.swapaxes(B, -1, -2) @ D @ B).sum(axis=1).reshape(P_, M_, 3, M_, 3)
    return K


def _frozen_smooth(X, cb, anchor, f0, n0, kT, mu, jacobian, eta, turn=None):
    mu = _per_point(mu, f0.shape)
    u = _frozen_gap(X, cb, anchor, turn)
    e = u - np.einsum("pgi,pgi->pg", n0, u)[..., None] * n0
    on = (f0 > 0.0) & (mu > 0.0) & (kT > 0.0)
    L = np.where(on, mu * f0, 0.0)
    kTs = np.where(kT > 0, kT, 1.0)
    delta = np.where(on, L / kTs, 1.0)
    en = np.sqrt(np.einsum("pgi,pgi->pg", e, e))
    Phi, phi, dphi, over = _smooth_cone(en / delta, eta)
    psi = np.where(on, L * delta * Phi, 0.0)
    ehat = e / np.where(en > 0, en, 1.0)[..., None]
    t = np.where(on, L * phi, 0.0)[..., None] * ehat
    R = _frozen_force(cb, turn, t)
    if not jacobian:
        return psi, R, None
    I3 = np.eye(3)
    P0 = I3 - n0[..., :, None] * n0[..., None, :]
    a = np.where(on, kTs * dphi, 0.0)          # along e_hat: d|t|/d|e|
    b = np.where(on, kTs * over, 0.0)          # across: |t| / |e|
    ee = ehat[..., :, None] * ehat[..., None, :]
    D = a[..., None, None] * ee + b[..., None, None] * (P0 - ee)
    return psi, R, _frozen_hessian(cb, turn, D)


# --------------------------------------------------------------------------- the frame law
def _dmul(A, dV):
    """``A dV`` for per-point matrices ``A`` (P, G, 3, 3) and derivatives ``dV`` (P, G, M, 3, c)."""
    return np.einsum("pgij,pgljc->pglic", A, dV)


def _outer_d(v, ds):
    """``v ds^T`` as a derivative (P, G, M, 3, c): ``v`` (P, G, 3), ``ds`` (P, G, M, c)."""
    return v[:, :, None, :, None] * ds[:, :, :, None, :]


def _vdot_d(v, dV):
    """``v^T dV`` (P, G, M, c) for ``v`` (P, G, 3)."""
    return np.einsum("pgi,pglic->pglc", v, dV)


def _frame_trial(geo, X, G, s_bar, anchor, d_ref, m_ref, director_weights, directions, jacobian):
    """The frame law's trial gap: ``(cb, D, Dp, h, |d|, gw, gw_ds, g, u, e, J)`` with ``J =
    (Jh, Jg)`` of ``framed_anchor`` (None without ``jacobian``)."""
    cb = geo.material_weights(s_bar)
    if directions is None:
        D, Dp = geo.direction_weights(geo.s_minus), geo.direction_weights_ds(geo.s_minus)
    else:
        D, Dp = directions(geo.s_minus)
    h, _, dn = minus_direction(X, D)
    gw, gw_ds = director_weights(geo.s_minus)
    g = np.einsum("pgk,pki->pgi", gw, G)
    J = None
    if jacobian:
        Qa, J = framed_anchor(anchor, d_ref, m_ref, h, g, jacobian=True)
    else:
        Qa = framed_anchor(anchor, d_ref, m_ref, h, g)
    u = Qa + np.einsum("pgk,pki->pgi", cb, X)
    e = u - np.einsum("pgi,pgi->pg", geo.n, u)[..., None] * geo.n
    return cb, D, Dp, h, dn, gw, gw_ds, g, u, e, J


def frame_tangential_gap(geo, X, G, s_bar, anchor, d_ref, m_ref, director_weights, directions=None) -> np.ndarray:
    """``tangential_gap`` of the frame law: the trial tangential gap ``e`` (P, G, 3) at ``(X, G)``."""
    return _frame_trial(geo, X, G, s_bar, anchor, d_ref, m_ref, director_weights, directions, False)[9]


def _frame_couples(geo, t, h, dn, g, active):
    """``(C_h, C_g, m, k, b_hat, w_hat, |b|)`` of the frame law (``frame_friction_forces``)."""
    bh, wh, bn = section_frame(h, g)
    inv_b = 1.0 / np.where(bn > 0, bn, 1.0)
    inv_d = 1.0 / np.where(dn > 0, dn, 1.0)
    rho = np.where(active, geo.rho, 0.0)
    m = -rho[..., None] * np.cross(geo.n, t)
    k = np.einsum("pgi,pgi->pg", h, m)
    hg = np.einsum("pgi,pgi->pg", h, g)
    Ch = (np.cross(m, h) - (hg * k * inv_b)[..., None] * wh) * inv_d[..., None]
    Cg = (k * inv_b)[..., None] * wh
    return Ch, Cg, m, k, bh, wh, bn


def frame_friction_state(geo, X, G, s_bar, anchor, d_ref, m_ref, f, kT, mu, director_weights,
                         directions=None) -> FrictionPoints:
    """``friction_state`` of the frame law (``frame_friction_forces``): the return mapping at
    ``(X, G)`` and the history a commit there takes (``s_bar`` the closest point, ``anchor =
    t/kT - j``, ``d_ref = h`` and ``m_ref = b_hat`` the frame there), with the couples
    ``couple`` (C_h, on the - direction's weights ``chord_weights``) and ``director_couple``
    (C_g, on ``director_weights``)."""
    mu = _per_point(mu, f.shape)
    active = geo.active & (f > 0.0) & (mu > 0.0)
    _, D, _, h, dn, gw, _, g, _, e, _ = _frame_trial(geo, X, G, s_bar, anchor, d_ref, m_ref, director_weights,
                                                     directions, False)
    _, stick, slip, t = _return_map(e, f, kT, mu, active)
    el = np.where(active[..., None], t / np.where(kT > 0, kT, 1.0)[..., None], 0.0)
    diss = np.where(slip, np.einsum("pgi,pgi->pg", t, e - el), 0.0)
    Ch, Cg, _, _, bh, _, _ = _frame_couples(geo, t, h, dn, g, active)
    return FrictionPoints(t=t, slip=slip, stick=stick, e=e, s_bar=np.array(geo.s_minus, float, copy=True),
                          anchor=el - geo.j, dissipation=diss, normal=np.asarray(f, float), d_ref=h, couple=Ch,
                          chord_weights=D, m_ref=bh, director_couple=Cg, director_weights=gw)


def frame_friction_forces(geo, X, G, s_bar, anchor, d_ref, m_ref, f, kN, kT, mu, director_weights,
                          jacobian: bool = True, directions=None):
    """The friction law with the anchor carried by the - cross-section's frame
    (``framed_anchor``): residual (P, M, 6) and tangent (P, M, 6, M, 6) (None without
    ``jacobian``) in the local nodes' centroid and first-director components ``Y = (X, G)``.

    ``G`` (P, M, 3) the local nodes' g1; ``director_weights(s)`` -> ``(gw, gw_ds)`` (P, G, M)
    the weights of the - side's g1 at the - parameter ``s`` and their s-derivative (zero on
    the + nodes); ``directions(s)`` -> ``(D, D_s)`` the weights of the - direction ``h`` and
    their s-derivative (None: the geometry's; the section frame of the contact term takes the
    - element's chord); ``d_ref``, ``m_ref`` (P, G, 3) the committed frame (``m_ref`` the unit
    part of g1 across ``d_ref`` then). The law is that of ``friction_forces`` with ``u = Q anchor +
    j(X; s_bar)``; its couple is the work of the frame's turn at the current state with the
    anchor ``a = -rho n``: the turn's angular velocity is ``h x dh + h (w_hat . dg - (h . g)
    w_hat . dh) / |b|``, so with ``m = a x t`` the - direction's ends carry ``+-C_h``, ``C_h =
    (m x h - (h . g)(h . m) w_hat / |b|) / |d|`` (the first term ``friction_forces``'s couple),
    and the - side's g1 the force ``gw_k C_g``, ``C_g = (h . m) w_hat / |b|``: together the
    moment ``-rho n x t`` that balances the friction forces' pair, its twist about the -
    fibril included."""
    mu = _per_point(mu, f.shape)
    active = geo.active & (f > 0.0) & (mu > 0.0)
    P_, G_ = f.shape
    M_ = X.shape[1]
    I3 = np.eye(3)
    cb, D, Dp, h, dn, gw, gw_ds, g, u, e, J = _frame_trial(geo, X, G, s_bar, anchor, d_ref, m_ref, director_weights,
                                                            directions, jacobian)
    n = geo.n
    un = np.einsum("pgi,pgi->pg", n, u)
    en, stick, slip, t = _return_map(e, f, kT, mu, active)
    Ch, Cg, m, k, bh, wh, bn = _frame_couples(geo, t, h, dn, g, active)
    rho = np.where(active, geo.rho, 0.0)
    Nh = Ch * dn[..., None]
    R = np.zeros((P_, M_, 6))
    R[..., :3] = np.einsum("pgk,pgi->pki", geo.c, t) + np.einsum("pgk,pgi->pki", D, Ch)
    R[..., 3:] = np.einsum("pgk,pgi->pki", gw, Cg)
    if not jacobian:
        return R, None
    Jh, Jg = J
    dS, dN, drho, dh, ddn, dg = _frame_geometry_d(geo, X, G, D, Dp, h, dn, gw, gw_ds, active)
    # the trial gap: du_l = cb_l (I, 0) + Jh dh_l + Jg dg_l, de_l from it and the turning normal
    cbI = np.zeros((P_, G_, M_, 3, 6))
    cbI[..., :3] = cb[..., None, None] * I3
    du = cbI + _dmul(Jh, dh) + _dmul(Jg, dg)
    Pn = I3 - n[..., :, None] * n[..., None, :]
    de = _dmul(Pn, du) - un[..., None, None, None] * dN - n[:, :, None, :, None] * _vdot_d(e, dN)[:, :, :, None, :]
    dT = _return_map_d(e, en, de, f, kN, kT, mu, stick, slip, drho)
    dCh, dCg = _frame_couples_d(n, t, h, g, m, k, bh, wh, bn, dn, rho, Nh, dN, drho, dh, ddn, dg, dT, active)
    K = np.zeros((P_, M_, 6, M_, 6))
    K[:, :, :3] = (np.einsum("pgk,pglic->pkilc", geo.c, dT) + np.einsum("pgk,pgi,pglc->pkilc", geo.dc_ds, t, dS)
                   + np.einsum("pgk,pglic->pkilc", D, dCh) + np.einsum("pgk,pgi,pglc->pkilc", Dp, Ch, dS))
    K[:, :, 3:] = (np.einsum("pgk,pglic->pkilc", gw, dCg) + np.einsum("pgk,pgi,pglc->pkilc", gw_ds, Cg, dS))
    return R, K.reshape(P_, M_, 6, M_, 6)


def _frame_geometry_d(geo, X, G, D, Dp, h, dn, gw, gw_ds, active):
    """The derivatives with respect to ``Y_l = (X_l, G_l)`` of the frame law's geometry:
    ``(dS, dN, drho, dh, d|d|, dg)``, vectors (P, G, M, 3, 6), scalars (P, G, M, 6): the closest
    point, the normal, the distance, the - direction, its length and the - side's g1."""
    P_, G_, M_ = geo.c.shape
    I3 = np.eye(3)
    dS = np.zeros((P_, G_, M_, 6))
    dS[..., :3] = geo.ds
    cI = np.zeros((P_, G_, M_, 3, 6))
    cI[..., :3] = geo.c[..., None, None] * I3
    dJ = cI + _outer_d(np.einsum("pgk,pki->pgi", geo.dc_ds, X), dS)      # the current jump
    n = geo.n
    rho_s = np.where(active, geo.rho, 1.0)
    dN = _dmul(I3 - n[..., :, None] * n[..., None, :], dJ) / rho_s[..., None, None, None]
    drho = _vdot_d(n, dJ)
    dd = np.zeros((P_, G_, M_, 3, 6))
    dd[..., :3] = D[..., None, None] * I3
    dd = dd + _outer_d(np.einsum("pgk,pki->pgi", Dp, X), dS)              # d = sum_k D_k(s-) X_k
    dh = _dmul(I3 - h[..., :, None] * h[..., None, :], dd) / np.where(dn > 0, dn, 1.0)[..., None, None, None]
    dg = np.zeros((P_, G_, M_, 3, 6))
    dg[..., 3:] = gw[..., None, None] * I3
    dg = dg + _outer_d(np.einsum("pgk,pki->pgi", gw_ds, G), dS)           # g = sum_k gw_k(s-) G_k
    return dS, dN, drho, dh, _vdot_d(h, dd), dg


def _return_map_d(e, en, de, f, kN, kT, mu, stick, slip, drho):
    """``dt/dY_l`` (P, G, M, 3, c) of the return map from ``de`` and the normal force's
    ``df = -kN drho``: stick ``kT de``, slip ``mu e_hat df + (mu f/|e|)(I - e_hat e_hat^T) de``."""
    ehat = e / np.where(en > 0, en, 1.0)[..., None]
    proj = np.eye(3) - ehat[..., :, None] * ehat[..., None, :]
    a_slip = np.where(slip, mu * f / np.where(en > 0, en, 1.0), 0.0)
    df = -(kN * mu)[..., None, None] * drho                              # mu df/dY_l
    dT = np.where(stick[..., None, None, None], kT[..., None, None, None] * de, 0.0)
    return dT + np.where(slip[..., None, None, None],
                         a_slip[..., None, None, None] * _dmul(proj, de) + _outer_d(ehat, df), 0.0)


def _frame_couples_d(n, t, h, g, m, k, bh, wh, bn, dn, rho, Nh, dN, drho, dh, ddn, dg, dT, active):
    """``(dC_h, dC_g)`` (P, G, M, 3, 6) of ``_frame_couples`` (``Nh = |d| C_h``)."""
    I3 = np.eye(3)
    inv_b = 1.0 / np.where(bn > 0, bn, 1.0)
    inv_d = 1.0 / np.where(dn > 0, dn, 1.0)
    hg = np.einsum("pgi,pgi->pg", h, g)
    Pb = (I3 - bh[..., :, None] * bh[..., None, :]) * inv_b[..., None, None]
    Ph = I3 - h[..., :, None] * h[..., None, :]
    dbh = (_dmul(-Pb @ (hg[..., None, None] * I3 + h[..., :, None] * g[..., None, :]), dh) + _dmul(Pb @ Ph, dg))
    dwh = _dmul(-_skew(bh), dh) + _dmul(_skew(h), dbh)
    dbn = _vdot_d(bh, dg) - hg[..., None, None] * _vdot_d(bh, dh)
    dhg = _vdot_d(g, dh) + _vdot_d(h, dg)
    nt = np.cross(n, t)
    r = rho[..., None, None, None]
    dm = -nt[:, :, None, :, None] * drho[:, :, :, None, :] + r * _dmul(_skew(t), dN) - r * _dmul(_skew(n), dT)
    dk = _vdot_d(m, dh) + _vdot_d(h, dm)
    q = hg * k * inv_b
    dq = ((k[..., None, None] * dhg + hg[..., None, None] * dk) * inv_b[..., None, None]
          - (q * inv_b)[..., None, None] * dbn)
    dNh = (_dmul(-_skew(h), dm) + _dmul(_skew(m), dh) - wh[:, :, None, :, None] * dq[:, :, :, None, :]
           - q[..., None, None, None] * dwh)
    dCh = dNh * inv_d[..., None, None, None] - _outer_d(Nh * (inv_d * inv_d)[..., None], ddn)
    dCg = (_outer_d(wh, dk * inv_b[..., None, None] - (k * inv_b * inv_b)[..., None, None] * dbn)
           + (k * inv_b)[..., None, None, None] * dwh)
    on = active[..., None, None, None]
    return np.where(on, dCh, 0.0), np.where(on, dCg, 0.0)


def frame_moved_history(X, G, s_bar, anchor, d_ref, m_ref, s_star, weights, directions, director_weights):
    """``moved_history`` of the frame law: ``(s_star, anchor', d_ref', m_ref')``, the material
    point moved to ``s_star`` (P, G) and the anchor re-expressed in the frame there, the trial
    gap at ``(X, G)`` unchanged: ``anchor' = Q anchor + j(X; s_bar) - j(X; s_star)``."""
    jb = np.einsum("pgk,pki->pgi", weights(s_bar), X)
    js = np.einsum("pgk,pki->pgi", weights(s_star), X)
    h = minus_direction(X, directions(s_star))[0]
    g = np.einsum("pgk,pki->pgi", director_weights(s_star), G)
    Qa = framed_anchor(anchor, d_ref, m_ref, h, g)
    return np.array(s_star, float, copy=True), Qa + jb - js, h, section_frame(h, g)[0]


def frame_refreeze(X, G, s_bar, anchor, d_ref, m_ref, s_star, n, rho, active, weights, directions,
                   director_weights):
    """The section frame's loads refrozen at local nodes ``(X, G)`` (``FrictionTerm.loads_at``):
    ``(Dw, Jd, gw, Jg, anchor', h, b_hat)``, the frame's turn frozen at the state
    (``frame_frozen_turn`` with the direction and section-node weights at ``s_star``), the
    history moved to ``s_star`` (``frame_moved_history``: ``h``, ``b_hat`` the new ``d_ref``,
    ``m_ref``), and its anchor less the frozen turn's linear part, ``anchor' = Q anchor + j(X;
    s_bar) - j(X; s_star) - Jd d - Jg g``, so that the frozen gap is the law's at the state.
    The compiled kernel ``rve.kernels.friction_frame.frame_refreeze`` gives the same arrays."""
    gw = director_weights(s_star)
    Dw, Jd, d, gw, Jg, g = frame_frozen_turn(X, G, directions(s_star), gw, n, rho, active)
    _, a_moved, h, bh = frame_moved_history(X, G, s_bar, anchor, d_ref, m_ref, s_star, weights, directions,
                                            director_weights)
    a_moved = a_moved - np.einsum("pgij,pgj->pgi", Jd, d) - np.einsum("pgij,pgj->pgi", Jg, g)
    return Dw, Jd, gw, Jg, a_moved, h, bh


def frame_frozen_turn(X, G, D, gw, n, rho, active):
    """``(Dw, Jd, d, gw, Jg, g)``: the frame's turn frozen at ``(X, G)`` as linear in the -
    direction ``d = sum_k D_k X_k`` and the - side's g1 ``g = sum_k gw_k G_k`` (``frozen_turn``
    of the frame law): ``Jd = Jh (I - h h^T) / |d|`` and ``Jg`` the derivatives of the frame's
    turn of ``a = -rho n`` at the state's own frame (zero where not ``active``)."""
    h, Dw, dn = minus_direction(X, D)
    g = np.einsum("pgk,pki->pgi", gw, G)
    a = -np.where(active, rho, 0.0)[..., None] * n
    bh = section_frame(h, g)[0]
    _, (Jh, Jg) = framed_anchor(a, h, bh, h, g, jacobian=True)
    Pi = np.eye(3) - h[..., :, None] * h[..., None, :]
    Jd = Jh @ Pi / np.where(dn > 0, dn, 1.0)[..., None, None]
    return Dw, Jd, h * dn[..., None], np.asarray(gw, float), Jg, g


def frame_frozen_potential(Y, cb, anchor, f0, n0, kT, mu, jacobian: bool, eta: float, turn):
    """``frozen_potential`` of the frame law at local nodes ``Y`` (P, M, 6) (centroids, g1):
    ``u = anchor + sum_k W_k Y_k`` with ``W_k = (cb_k I + Dw_k Jd, gw_k Jg)`` (3 x 6), ``turn
    = (Dw, Jd, gw, Jg)`` (``frame_frozen_turn``); ``(psi (P, G), R (P, M, 6), K (P, M, 6, M,
    6) or None)``, ``R_k = W_k^T t``, ``K_kl = W_k^T D W_l``."""
    Dw, Jd, gw, Jg = turn
    P_, G_, M_ = cb.shape
    W = np.zeros((P_, G_, M_, 3, 6))
    W[..., :3] = Dw[..., None, None] * Jd[:, :, None]
    i3 = np.arange(3)
    W[..., i3, i3] += cb[..., None]
    W[..., 3:] = gw[..., None, None] * Jg[:, :, None]
    mu = _per_point(mu, f0.shape)
    u = anchor + np.einsum("pgkic,pkc->pgi", W, Y)
    e = u - np.einsum("pgi,pgi->pg", n0, u)[..., None] * n0
    on = (f0 > 0.0) & (mu > 0.0) & (kT > 0.0)
    L = np.where(on, mu * f0, 0.0)
    kTs = np.where(kT > 0, kT, 1.0)
    en = np.sqrt(np.einsum("pgi,pgi->pg", e, e))
    ehat = e / np.where(en > 0, en, 1.0)[..., None]
    I3 = np.eye(3)
    P0 = I3 - n0[..., :, None] * n0[..., None, :]
    ee = ehat[..., :, None] * ehat[..., None, :]
    if eta > 0.0:
        delta = np.where(on, L / kTs, 1.0)
        Phi, phi, dphi, over = _smooth_cone(en / delta, eta)
        psi = np.where(on, L * delta * Phi, 0.0)
        t = np.where(on, L * phi, 0.0)[..., None] * ehat
        a = np.where(on, kTs * dphi, 0.0)
        b = np.where(on, kTs * over, 0.0)
        Dm = a[..., None, None] * ee + b[..., None, None] * (P0 - ee)
    else:
        _, stick, slip, t = _return_map(e, L, kT, 1.0, L > 0.0)
        psi = np.where(stick, 0.5 * kT * en * en, np.where(slip, L * en - 0.5 * L * L / kTs, 0.0))
        a_slip = np.where(slip, L / np.where(en > 0, en, 1.0), 0.0)
        Dm = np.where(stick, kT, 0.0)[..., None, None] * P0 + a_slip[..., None, None] * (P0 - ee)
    R = np.einsum("pgkic,pgi->pkc", W, t)
    if not jacobian:
        return psi, R, None
    B = np.ascontiguousarray(W.transpose(0, 1, 3, 2, 4)).reshape(P_, G_, 3, 6 * M_)
    K = (np.swapaxes(B, -1, -2) @ Dm @ B).sum(axis=1).reshape(P_, M_, 6, M_, 6)
    return psi, R, K
