"""Projectile-fibril contact: the projectile's end nodes act as spheres (hemispherical ends,
thesis §8.4) against the fibril chords (docs/impact.md).

Contract
--------
``sphere_candidates(centres, seg_a, seg_b, cutoff)`` -> (i_centre, i_segment) of every
centre-segment pair whose distance is <= cutoff: a vectorised brute-force pass (2 centres x
S segments; exact point-segment distances). The fibril search of ``rve.contact.search``
(one cutoff 2 max R + margin for all pairs) is not used: the projectile's radius is ~45x a
fibril's.

``SphereContactTerm(mesh, radius, penalty, margin)``: the pair term between sphere centres
(end nodes of the projectile model) and every element of the fibril ``mesh``.

* ``rebuild(centres, r_fabric)`` keeps the pairs within ``cutoff = radius + R_f + margin``;
* ``forms(centres, r_fabric, jacobian)`` -> ``(act, F, K)``: the active pairs, their local
  residuals (Pa, 3 nodes (centre, a, b), 3) and tangents (Pa, 9, 9)
  (``rve.physics.sphere_contact_forms``); point penalty ``k = penalty * l_e`` (the fibrils'
  line penalty P* times the element's reference length: the line load P* g integrated with
  one point at the closest point);
* ``gaps``, ``energy``, ``forces_on_centres`` (N, (n_centres, 3));
* ``centre``/``element``/``node_a``/``node_b``: the pair table (fibril-mesh node numbers).

Friction (``friction=(mu, stiffness)``, mu > 0; ``self.friction`` a
``rve.model.terms.sphere_friction.SphereFrictionTerm``, else None): the local unknowns of a
pair are then ``(centre, director 1, director 2, a, b)`` (``n_local`` = 5 nodes of 3; 3
without friction), ``rebuild`` and ``forms`` take the end nodes' directors ``frames``
(n_centres, 2, 3), ``forms`` returns F (Pa, 5, 3) and K (Pa, 15, 15) with the friction of
the active pairs added (the directors' rows carry its moment), and ``rebuild`` carries the
friction history to the new table (``SphereFrictionTerm.on_rebuild``). ``local(centres,
r_fabric, frames, sel)`` the unknowns (P, n_local, 3) of pairs ``sel``.
"""
from __future__ import annotations

import numpy as np

from ...physics.sphere_contact_forms import sphere_segment_energy, sphere_segment_forces, sphere_segment_gaps
from .sphere_friction import SphereFrictionTerm

__all__ = ["sphere_candidates", "SphereContactTerm"]


def _point_segment_distance(p, a, b):
    e = b - a
    ee = np.einsum("...i,...i->...", e, e)
    s = np.where(ee > 0, np.einsum("...i,...i->...", p - a, e) / np.where(ee > 0, ee, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)
    d = p - (a + s[..., None] * e)
    return np.sqrt(np.einsum("...i,...i->...", d, d))


def sphere_candidates(centres, seg_a, seg_b, cutoff: float):
    """Pairs (centre i, segment j) with point-segment distance <= cutoff (module docstring)."""
    c = np.asarray(centres, float).reshape(-1, 3)
    A = np.asarray(seg_a, float).reshape(-1, 3)
    B = np.asarray(seg_b, float).reshape(-1, 3)
    dist = _point_segment_distance(c[:, None, :], A[None, :, :], B[None, :, :])  # (nc, S)
    i, j = np.nonzero(dist <= cutoff)
    return i.astype(np.int64), j.astype(np.int64)


class SphereContactTerm:
    name = "sphere_contact"

    def __init__(self, mesh, radius: float, penalty: float, margin: float, n_centres: int = 2, friction=None):
        if not radius > 0 or not penalty > 0 or not margin >= 0:
            raise ValueError("sphere contact needs radius > 0, penalty > 0, margin >= 0")
        self.mesh = mesh
        self.radius = float(radius)
        self.penalty = float(penalty)
        self.margin = float(margin)
        self.n_centres = int(n_centres)
        self.cutoff = self.radius + float(mesh.radius.max()) + self.margin
        self.centre = np.zeros(0, np.int64)
        self.element = np.zeros(0, np.int64)
        self._set_pairs(self.centre, self.element)
        self.friction = None if friction is None else SphereFrictionTerm(self, *friction)

    @property
    def n_local(self) -> int:
        """Local nodes of a pair: (centre, a, b), with friction (centre, d1, d2, a, b)."""
        return 3 if self.friction is None else 5

    def _set_pairs(self, ci, ej):
        mesh = self.mesh
        self.centre, self.element = ci, ej
        self.node_a = mesh.conn[ej, 0]
        self.node_b = mesh.conn[ej, -1]
        self.gap_radius = self.radius + mesh.radius[mesh.elem_fibril[ej]]
        self.k = self.penalty * mesh.elem_length[ej]

    @property
    def n_pairs(self) -> int:
        return int(self.centre.size)

    def rebuild(self, centres, r_fabric, frames=None) -> int:
        """New pair table at the centres (n_centres, 3) and fibril node positions (n_nodes, 3)
        (with friction: its history carried over, ``frames`` the end nodes' directors)."""
        r = np.asarray(r_fabric, float)
        ci, ej = sphere_candidates(centres, r[self.mesh.conn[:, 0]], r[self.mesh.conn[:, -1]], self.cutoff)
        self._set_pairs(ci, ej)
        if self.friction is not None:
            self.friction.on_rebuild(self.local(centres, r, frames))
        return self.n_pairs

    def local(self, centres, r_fabric, frames, sel=None) -> np.ndarray:
        """The local unknowns (P, n_local, 3) of pairs ``sel`` (all by default)."""
        p, a, b = self._ends(centres, r_fabric, sel)
        if self.friction is None:
            return np.stack([p, a, b], axis=1)
        ci = self.centre if sel is None else self.centre[sel]
        f = np.asarray(frames, float)[ci]
        return np.stack([p, f[:, 0], f[:, 1], a, b], axis=1)

    def _ends(self, centres, r_fabric, sel=None):
        ci, na, nb = self.centre, self.node_a, self.node_b
        if sel is not None:
            ci, na, nb = ci[sel], na[sel], nb[sel]
        c = np.asarray(centres, float)
        r = np.asarray(r_fabric, float)
        return c[ci], r[na], r[nb]

    def gaps(self, centres, r_fabric) -> np.ndarray:
        if self.n_pairs == 0:
            return np.zeros(0)
        return sphere_segment_gaps(*self._ends(centres, r_fabric), self.gap_radius)

    def active_pairs(self, centres, r_fabric) -> np.ndarray:
        return np.flatnonzero(self.gaps(centres, r_fabric) > 0.0)

    def energy(self, centres, r_fabric) -> float:
        if self.n_pairs == 0:
            return 0.0
        return sphere_segment_energy(*self._ends(centres, r_fabric), self.gap_radius, self.k)

    def forms(self, centres, r_fabric, jacobian: bool = True, frames=None):
        """``(act, F (Pa, n_local, 3), K (Pa, 3 n_local, 3 n_local) or None)`` of the active
        pairs (with friction: its forces added, ``frames`` the end nodes' directors)."""
        act = self.active_pairs(centres, r_fabric)
        m = self.n_local
        if act.size == 0:
            return act, np.zeros((0, m, 3)), (np.zeros((0, 3 * m, 3 * m)) if jacobian else None)
        F, K = sphere_segment_forces(*self._ends(centres, r_fabric, act), self.gap_radius[act], self.k[act],
                                     jacobian)
        if self.friction is None:
            return act, F, (K.reshape(act.size, 9, 9) if jacobian else None)
        # the normal form's nodes (centre, a, b) are local nodes 0, 3, 4
        nodes = np.array([0, 3, 4])
        Rf, Kf = self.friction.forces(self.local(centres, r_fabric, frames, act), act, jacobian)
        Rf[:, nodes] += F
        if not jacobian:
            return act, Rf, None
        Kf[np.ix_(np.arange(act.size), nodes, np.arange(3), nodes, np.arange(3))] += K
        return act, Rf, Kf.reshape(act.size, 3 * m, 3 * m)

    def forces_on_centres(self, centres, r_fabric, frames=None) -> np.ndarray:
        """Contact force (N) acting on every sphere centre, (n_centres, 3) (with friction:
        normal and friction force)."""
        act, F, _ = self.forms(centres, r_fabric, jacobian=False, frames=frames)
        out = np.zeros((self.n_centres, 3))
        np.add.at(out, self.centre[act], -F[:, 0, :])
        return out
