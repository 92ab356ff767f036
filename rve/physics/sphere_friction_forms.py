"""Regularised Coulomb friction at the sphere-segment contact of the impact (the
projectile's hemispherical ends against the fibril chords): the elastic tangential penalty
with slip by return mapping of ``rve.physics.friction_forms``, with the stick point a
material point of the projectile's surface and one of the fibril chord, and its exact
(unsymmetric in slip) consistent tangent (docs/impact.md "Friction at the projectile").

Contract
--------
Pure, vectorised functions over P sphere-segment pairs (no Python loop over pairs). The
local unknowns of a pair are ``X = (p, d1, d2, a, b)`` (P, 5, 3): the sphere centre (the
projectile's end node) and the two directors of that node, then the chord ends of the
fibril element (``c(s) = a + s (b - a)``). The normal contact is that of
``rve.physics.sphere_contact_forms`` (closest point ``s``, normal ``n`` from the chord to
the centre, distance ``rho``, overlap ``g = R - rho``, point normal force ``f = k g``).

* **Material points.** The projectile's: ``y(X; xi) = p + xi_1 d1 + xi_2 d2 + xi_3 d3``,
  ``d3 = d1 x d2``: body coordinates ``xi`` (mm) in the end node's director frame, so it
  moves with the projectile's translation and rotation (and with the section's stretch,
  which the director beam has). The fibril's: ``c(X; s_bar) = a + s_bar (b - a)`` on the
  chord (the axis, as the fibril-fibril law measures it). Their jump
  ``j(X; xi, s_bar) = y - c`` (the sphere is the + side).
* **History** of a pair (from the last converged state): ``xi``, ``s_bar`` and ``anchor``
  (3,) = ``e_n - j_n``, the elastic tangential gap minus the jump then.
  ``sphere_start_history(X, r_sphere, R)`` is the history with no elastic gap: the
  projectile's material point is the point of its surface in contact, ``p - r_sphere n``
  (``xi`` solves ``[d1 d2 d3] xi = -r_sphere n``), the chord's the closest point ``s``.
* **Trial gap** ``u = anchor + j(X)``, ``e = (I - n n^T) u``; **return map** with
  ``kT`` (N/mm) and ``f``: stick where ``kT |e| <= mu f`` (``t = kT e``), else slip
  (``t = mu f e / |e|``); ``t = 0`` where ``g <= 0``.
* **Residual** (internal-force sign): ``R_l = J_l^T t`` with ``J_l = dj/dX_l``:
  ``J = (I, xi_1 I - xi_3 [d2]x, xi_2 I + xi_3 [d1]x, -(1 - s_bar) I, -s_bar I)``. The
  force ``-t`` acts at the projectile's material point (on its centre and, as a moment,
  on its directors), ``+t`` at the chord's (split linearly): equal and opposite, and
  ``R . w = t . dj/dt`` is the power the friction takes from the motion ``w``.
* **Tangent** ``K_kl = J_k^T dt/dX_l + G_kl`` with ``G_{d1 d2} = -xi_3 [t]x``,
  ``G_{d2 d1} = xi_3 [t]x`` (the second derivative of ``d1 x d2``), and, per pair, with
  ``Q_l = dd/dX_l = c_l I - e_c ds_l^T`` (``d = p - c(s)``, ``c = (1, 0, 0, -(1 - s), -s)``,
  ``e_c = b - a``, ``ds/dX`` of ``rve.physics.sphere_contact_forms``, zero at a clamped
  closest point): ``de/dX_l = P J_l - (n.u / rho) P Q_l - (1/rho) n e^T Q_l``
  (``P = I - n n^T``); stick ``dt = kT de``; slip ``dt = mu e_hat df^T + (mu f/|e|)(I -
  e_hat e_hat^T) de`` with ``df/dX_l = -k c_l n^T``. Unsymmetric in slip.
* ``sphere_friction_state`` returns what a step commits: the new history at the state
  (``xi``, ``s_bar`` of ``sphere_start_history`` there, ``anchor = t/kT - j``) and the
  energy ``t . (e - t/kT)`` dissipated by the return map's slip.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .friction_forms import _return_map
from .sphere_contact_forms import sphere_segment_geometry

__all__ = ["SphereFrictionPoints", "sphere_material_jump", "sphere_jump_jacobian", "sphere_body_coordinates",
           "sphere_start_history", "sphere_friction_state", "sphere_friction_forces", "N_LOCAL"]

#: local nodes of a pair: centre, director 1, director 2, chord end a, chord end b
N_LOCAL = 5


def _skew(v):
    """``[v]x`` (..., 3, 3): ``[v]x w = v x w``."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def sphere_material_jump(X, xi, s_bar) -> np.ndarray:
    """``j = y(X; xi) - c(X; s_bar)`` (P, 3)."""
    p, d1, d2, a, b = (X[:, k] for k in range(N_LOCAL))
    d3 = np.cross(d1, d2)
    y = p + xi[:, 0:1] * d1 + xi[:, 1:2] * d2 + xi[:, 2:3] * d3
    return y - (a + s_bar[:, None] * (b - a))


def sphere_jump_jacobian(X, xi, s_bar) -> np.ndarray:
    """``J = dj/dX`` (P, 3, 5, 3)."""
    P = X.shape[0]
    I3 = np.broadcast_to(np.eye(3), (P, 3, 3))
    J = np.empty((P, 3, N_LOCAL, 3))
    J[:, :, 0] = I3
    J[:, :, 1] = xi[:, 0, None, None] * I3 - xi[:, 2, None, None] * _skew(X[:, 2])
    J[:, :, 2] = xi[:, 1, None, None] * I3 + xi[:, 2, None, None] * _skew(X[:, 1])
    J[:, :, 3] = -(1.0 - s_bar)[:, None, None] * I3
    J[:, :, 4] = -s_bar[:, None, None] * I3
    return J


def sphere_body_coordinates(d1, d2, v) -> np.ndarray:
    """``xi`` (P, 3) with ``xi_1 d1 + xi_2 d2 + xi_3 (d1 x d2) = v``."""
    D = np.stack([d1, d2, np.cross(d1, d2)], axis=-1)
    return np.linalg.solve(D, v[..., None])[..., 0]


def _geometry(X, R):
    return sphere_segment_geometry(X[:, 0], X[:, 3], X[:, 4], R)


def sphere_start_history(X, r_sphere, R, geo=None):
    """``(xi, s_bar, anchor)`` with no elastic gap at ``X`` (module docstring); ``r_sphere``
    the projectile's radius, ``R`` (P,) the contact distance ``r_sphere + R_fibril``."""
    geo = _geometry(X, R) if geo is None else geo
    xi = sphere_body_coordinates(X[:, 1], X[:, 2], -np.asarray(r_sphere, float).reshape(-1, 1) * geo["n"])
    s_bar = np.array(geo["s"], float, copy=True)
    return xi, s_bar, -sphere_material_jump(X, xi, s_bar)


@dataclass
class SphereFrictionPoints:
    """Per pair (P,): ``t`` (P, 3) the friction force (on the chord's material point; the
    projectile's gets -t), ``stick``/``slip`` bool, ``e`` (P, 3) the trial tangential gap,
    the committed history at this state ``xi``, ``s_bar``, ``anchor``, ``dissipation`` (P,)
    (N mm) and ``normal`` (P,) the normal forces (N)."""

    t: np.ndarray
    stick: np.ndarray
    slip: np.ndarray
    e: np.ndarray
    xi: np.ndarray
    s_bar: np.ndarray
    anchor: np.ndarray
    dissipation: np.ndarray
    normal: np.ndarray


def _trial(X, geo, xi, s_bar, anchor):
    n = geo["n"]
    u = anchor + sphere_material_jump(X, xi, s_bar)
    un = np.einsum("pi,pi->p", n, u)
    return u, un, u - un[:, None] * n


def _law(X, geo, xi, s_bar, anchor, k, kT, mu):
    g = geo["g"]
    f = np.where(g > 0.0, k * g, 0.0)
    mu = np.broadcast_to(np.asarray(mu, float), f.shape)
    active = (f > 0.0) & (mu > 0.0)
    u, un, e = _trial(X, geo, xi, s_bar, anchor)
    # the fibril law's return map on (P, 1) points
    en, stick, slip, t = _return_map(e[:, None], f[:, None], kT[:, None], mu[:, None], active[:, None])
    return f, mu, active, u, un, e, en[:, 0], stick[:, 0], slip[:, 0], t[:, 0]


def sphere_friction_state(X, r_sphere, R, xi, s_bar, anchor, k, kT, mu) -> SphereFrictionPoints:
    """Return mapping at ``X`` (P, 5, 3) from the history (``xi`` (P, 3), ``s_bar`` (P,),
    ``anchor`` (P, 3)); ``R`` (P,) the contact distances, ``k`` (P,) the normal point
    penalties, ``kT`` (P,) the tangential ones, ``mu`` scalar or (P,)."""
    k, kT = np.asarray(k, float), np.asarray(kT, float)
    geo = _geometry(X, R)
    f, mu, active, _, _, e, _, stick, slip, t = _law(X, geo, xi, s_bar, anchor, k, kT, mu)
    el = np.where(active[:, None], t / np.where(kT > 0, kT, 1.0)[:, None], 0.0)
    diss = np.where(slip, np.einsum("pi,pi->p", t, e - el), 0.0)
    xi_new, s_new, minus_j = sphere_start_history(X, r_sphere, R, geo)
    return SphereFrictionPoints(t=t, stick=stick, slip=slip, e=e, xi=xi_new, s_bar=s_new, anchor=el + minus_j,
                                dissipation=diss, normal=f)


def sphere_friction_forces(X, R, xi, s_bar, anchor, k, kT, mu, jacobian: bool = True):
    """Friction residual (P, 5, 3) and tangent (P, 5, 3, 5, 3) (None without jacobian) at
    ``X`` from the history (arguments as ``sphere_friction_state``)."""
    k, kT = np.asarray(k, float), np.asarray(kT, float)
    geo = _geometry(X, R)
    f, mu, active, u, un, e, en, stick, slip, t = _law(X, geo, xi, s_bar, anchor, k, kT, mu)
    J = sphere_jump_jacobian(X, xi, s_bar)
    Rl = np.einsum("pilj,pi->plj", J, t)
    if not jacobian:
        return Rl, None
    P = X.shape[0]
    I3 = np.eye(3)
    n = geo["n"]
    s = geo["s"]
    rho = np.where(active, geo["rho"], 1.0)
    ec = geo["e"]
    # ds/dX on (p, a, b) where the closest point is interior (rve.physics.sphere_contact_forms)
    us = np.zeros((P, N_LOCAL, 3))
    us[:, 0] = ec
    us[:, 3] = -(1.0 - s)[:, None] * ec - geo["rho"][:, None] * n
    us[:, 4] = -s[:, None] * ec + geo["rho"][:, None] * n
    ds = np.where(geo["interior"][:, None, None], us / geo["ee"][:, None, None], 0.0)
    cw = np.stack([np.ones(P), np.zeros(P), np.zeros(P), -(1.0 - s), -s], axis=1)    # (P, 5)
    Q = cw[:, :, None, None] * I3 - ec[:, None, :, None] * ds[:, :, None, :]        # (P, 5, 3, 3)
    Pn = I3 - n[:, :, None] * n[:, None, :]
    eQ = np.einsum("pi,plij->plj", e, Q)
    dE = (np.einsum("pij,pjlk->pilk", Pn, J)
          - (un / rho)[:, None, None, None] * np.einsum("pij,pljk->pilk", Pn, Q)
          - n[:, :, None, None] * eQ[:, None, :, :] / rho[:, None, None, None])     # (P, 3, 5, 3)
    ehat = e / np.where(en > 0, en, 1.0)[:, None]
    proj = I3 - ehat[:, :, None] * ehat[:, None, :]
    a_slip = np.where(slip, mu * f / np.where(en > 0, en, 1.0), 0.0)
    df = -(k * mu)[:, None, None] * cw[:, :, None] * n[:, None, :]                 # (P, 5, 3): mu df/dX_l
    dT = np.where(stick[:, None, None, None], kT[:, None, None, None] * dE, 0.0)
    dT = dT + np.where(slip[:, None, None, None],
                       a_slip[:, None, None, None] * np.einsum("pij,pjlk->pilk", proj, dE)
                       + ehat[:, :, None, None] * df[:, None, :, :], 0.0)
    K = np.einsum("pikl,pijm->pkljm", J, dT)
    # the second derivative of d1 x d2 (xi_3 t . (d1 x d2))
    G = xi[:, 2, None, None] * _skew(t)
    K[:, 1, :, 2, :] -= G
    K[:, 2, :, 1, :] += G
    return Rl, K
