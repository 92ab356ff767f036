"""Sphere-segment contact: a penalty between a sphere (the hemispherical end of the
projectile of thesis §8.4) and a fibril chord, with its exact tangent (docs/impact.md).

Contract
--------
Pure, vectorised functions over P sphere-segment pairs (no Python loop over pairs). A pair
is the sphere centre ``p`` (the projectile's end node) and the chord ``a -> b`` of a fibril
element (conventions of ``rve.contact.search``: ``c(s) = a + s (b - a)``).

* Geometry: ``s = clamp((p - a).(b - a) / |b - a|^2, 0, 1)`` (the exact closest point),
  ``c = a + s (b - a)``, ``d = p - c``, ``rho = |d|``, ``n = d / rho`` (from the fibril to
  the sphere centre), overlap ``g = R - rho`` with ``R = R_sphere + R_fibril``.
* Energy ``phi = k/2 <g>^2`` per pair (``k`` a point penalty, N/mm). Residual (internal-force
  sign of ``M dw/dt + F = 0``) on the local unknowns ``X = (p, a, b)`` (3 nodes x 3):
  ``F = -k g beta (x) n``, ``beta = (1, -(1 - s), -s)``: the force ``k g n`` pushes the
  sphere away and ``-k g n`` acts on the chord at c, split linearly (equal and opposite:
  the pair adds no momentum).
* Tangent (the Hessian of phi, symmetric), with ``e = b - a``::

      K = k [ beta beta^T (x) ((1 + g/rho) n n^T - (g/rho) I) ] + k g / (rho |e|^2) u u^T

  ``u = (e, -(1 - s) e, -s e) - rho (0, n, -n)`` (9,), the second term only where the
  closest point is interior (0 < s < 1, where ``ds/dX = u/|e|^2``); zero for ``g <= 0``.
  Same structure as the chord-chord form of ``rve.physics.contact_forms`` (a point is a
  chord of length 0).

Functions: ``sphere_segment_geometry(p, a, b, R)`` -> dict (s, n, rho, g, interior, e),
``sphere_segment_gaps(p, a, b, R)`` -> g (P,), ``sphere_segment_forces(p, a, b, R, k,
jacobian)`` -> (F (P, 3, 3), K (P, 3, 3, 3, 3) or None), ``sphere_segment_energy`` -> float.
"""
from __future__ import annotations

import numpy as np

__all__ = ["sphere_segment_geometry", "sphere_segment_gaps", "sphere_segment_forces", "sphere_segment_energy"]


def _dot(u, v):
    return np.einsum("...i,...i->...", u, v)


def sphere_segment_geometry(p, a, b, R) -> dict:
    """Closest point, normal, distance and overlap of every pair (module docstring)."""
    p, a, b = (np.asarray(v, float).reshape(-1, 3) for v in (p, a, b))
    e = b - a
    ee = _dot(e, e)
    ee_s = np.where(ee > 0.0, ee, 1.0)
    s_raw = np.where(ee > 0.0, _dot(p - a, e) / ee_s, 0.0)
    interior = (s_raw > 0.0) & (s_raw < 1.0) & (ee > 0.0)
    s = np.clip(s_raw, 0.0, 1.0)
    c = a + s[:, None] * e
    d = p - c
    rho = np.sqrt(_dot(d, d))
    n = d / np.where(rho > 0.0, rho, 1.0)[:, None]
    g = np.asarray(R, float) - rho
    return {"s": s, "n": n, "rho": rho, "g": g, "interior": interior, "e": e, "ee": ee_s}


def sphere_segment_gaps(p, a, b, R) -> np.ndarray:
    """Overlaps g = R - |p - c| (P,) (positive: in contact)."""
    return sphere_segment_geometry(p, a, b, R)["g"]


def sphere_segment_energy(p, a, b, R, k) -> float:
    """Penalty energy sum k/2 <g>^2 (N mm)."""
    g = sphere_segment_gaps(p, a, b, R)
    return float((0.5 * np.asarray(k, float) * np.where(g > 0.0, g, 0.0) ** 2).sum())


def sphere_segment_forces(p, a, b, R, k, jacobian: bool = True):
    """Residual (P, 3 nodes, 3) and tangent (P, 3, 3, 3, 3) of the penalty (module docstring);
    pairs with g <= 0 give zeros. Node order (p, a, b)."""
    geo = sphere_segment_geometry(p, a, b, R)
    s, n, rho, g = geo["s"], geo["n"], geo["rho"], geo["g"]
    P = s.size
    k = np.broadcast_to(np.asarray(k, float), (P,))
    on = g > 0.0
    kg = np.where(on, k * g, 0.0)
    beta = np.stack([np.ones(P), -(1.0 - s), -s], axis=1)  # (P, 3)
    F = -kg[:, None, None] * beta[:, :, None] * n[:, None, :]
    if not jacobian:
        return F, None
    kk = np.where(on, k, 0.0)
    gr = np.where(on, g / np.where(rho > 0.0, rho, 1.0), 0.0)
    nn = n[:, :, None] * n[:, None, :]
    I3 = np.eye(3)[None]
    core = kk[:, None, None] * ((1.0 + gr)[:, None, None] * nn - gr[:, None, None] * I3)  # (P, 3, 3)
    bb = beta[:, :, None] * beta[:, None, :]  # (P, 3, 3)
    K = bb[:, :, None, :, None] * core[:, None, :, None, :]  # (P, node, i, node, j)
    e = geo["e"]
    u = np.stack([e, -(1.0 - s)[:, None] * e, -s[:, None] * e], axis=1)  # (P, 3, 3)
    u[:, 1] -= rho[:, None] * n
    u[:, 2] += rho[:, None] * n
    coef = np.where(on & geo["interior"], kk * gr / geo["ee"], 0.0)
    uf = u.reshape(P, 9)
    K = K + (coef[:, None, None] * uf[:, :, None] * uf[:, None, :]).reshape(P, 3, 3, 3, 3)
    return F, K
