"""Friction at the projectile's sphere contact: regularised Coulomb at every sphere-segment
pair of a ``SphereContactTerm``, with the stick history carried across steps and pair
rebuilds (law and tangent: ``rve.physics.sphere_friction_forms``; docs/impact.md
"Friction at the projectile").

Contract
--------
``SphereFrictionTerm(sphere, coefficient, stiffness)`` is owned by a ``SphereContactTerm``
(``sphere.friction``; 0 < coefficient <= 2, stiffness = eps_T / P* > 0: the tangential
point penalty is ``stiffness * k`` with ``k`` the pair's normal point penalty). Local
unknowns of a pair ``(p, d1, d2, a, b)``: the centre and the two directors of the
projectile's end node, the chord ends. The contact term calls

* ``on_rebuild(X)`` after every pair rebuild (``X`` (P, 5, 3) the local unknowns of the new
  table): a pair whose key (centre, element) was in the old table keeps its history; a new
  pair takes the history of a pair in contact at ``X`` with the same centre on a
  neighbouring element of the same fibril (``share_along_fibrils``), else it starts with no
  elastic gap (its material points: the projectile's surface point in contact and the
  closest point of the chord);
* ``forces(X, sel, jacobian)``: the friction residual (len(sel), 5, 3) and tangent
  (len(sel), 5, 3, 5, 3) of pairs ``sel``.

Drivers call ``commit(X)`` at every converged state (the history becomes that state's; the
pairs out of contact take that of a neighbouring pair in contact; the dissipated energy is
accumulated in ``dissipated``); ``state(X)`` the return map from the held history;
``last`` the return map of the last commit and ``X_last`` its unknowns; ``spring_energy()``
|t|^2 / (2 kT) per pair then; ``record()`` / ``seed(record)`` the history by pair key.
"""
from __future__ import annotations

import numpy as np

from ...physics.sphere_friction_forms import (sphere_friction_forces, sphere_friction_state, sphere_material_jump,
                                              sphere_start_history)
from .friction import match_rows

__all__ = ["SphereFrictionTerm", "MAX_COEFFICIENT"]

MAX_COEFFICIENT = 2.0


class SphereFrictionTerm:
    name = "sphere_friction"

    def __init__(self, sphere, coefficient: float, stiffness: float):
        if not 0.0 < coefficient <= MAX_COEFFICIENT:
            raise ValueError(f"sphere friction coefficient {coefficient} must be in (0, {MAX_COEFFICIENT}]")
        if not stiffness > 0.0:
            raise ValueError(f"sphere friction stiffness {stiffness} must be > 0")
        self.sphere = sphere
        self.mu = float(coefficient)
        self.stiffness = float(stiffness)
        self.keys = np.zeros((0, 2), np.int64)
        self.xi = np.zeros((0, 3))
        self.s_bar = np.zeros(0)
        self.anchor = np.zeros((0, 3))
        self.dissipated = 0.0
        self.last = None
        self.X_last = None

    # ------------------------------------------------------------------ per pair
    def _keys(self) -> np.ndarray:
        return np.stack([self.sphere.centre, self.sphere.element], axis=1).astype(np.int64)

    def _sel(self, sel):
        return np.arange(self.sphere.n_pairs) if sel is None else np.asarray(sel, np.int64)

    def _loads(self, sel):
        sp_ = self.sphere
        return sp_.gap_radius[sel], sp_.k[sel], self.stiffness * sp_.k[sel]

    def state(self, X, sel=None):
        """``SphereFrictionPoints`` of pairs ``sel`` (all by default) at ``X`` from the history."""
        sel = self._sel(sel)
        R, k, kT = self._loads(sel)
        return sphere_friction_state(X, self.sphere.radius, R, self.xi[sel], self.s_bar[sel], self.anchor[sel], k,
                                     kT, self.mu)

    def forces(self, X, sel, jacobian: bool):
        """Friction residual (len(sel), 5, 3) and tangent of pairs ``sel`` at their unknowns ``X``."""
        sel = self._sel(sel)
        R, k, kT = self._loads(sel)
        return sphere_friction_forces(X, R, self.xi[sel], self.s_bar[sel], self.anchor[sel], k, kT, self.mu,
                                      jacobian)

    # ------------------------------------------------------------------ history
    def on_rebuild(self, X) -> None:
        """History of the new pair table (module docstring)."""
        keys = self._keys()
        P = keys.shape[0]
        R, _, _ = self._loads(np.arange(P))
        xi, s_bar, anchor = sphere_start_history(X, self.sphere.radius, R) if P else \
            (np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
        hit = np.zeros(P, bool)
        if self.keys.shape[0] and P:
            idx = match_rows(keys, self.keys)
            hit = idx >= 0
            xi[hit], s_bar[hit], anchor[hit] = self.xi[idx[hit]], self.s_bar[idx[hit]], self.anchor[idx[hit]]
        self.keys, self.xi, self.s_bar, self.anchor = keys, xi, s_bar, anchor
        if P and not hit.all():
            self.share_along_fibrils(X, ~hit)

    def commit(self, X) -> float:
        """Make ``X`` (the unknowns of every pair at a converged state) the history; returns
        the energy dissipated since the last commit (N mm), added to ``dissipated``."""
        if self.sphere.n_pairs == 0:
            self.last, self.X_last = None, None
            return 0.0
        st = self.state(X)
        self.last, self.X_last = st, np.array(X, float, copy=True)
        self.xi, self.s_bar, self.anchor = st.xi, st.s_bar, st.anchor
        self.share_along_fibrils(X, st.normal <= 0.0)
        d = float(st.dissipation.sum())
        self.dissipated += d
        return d

    def share_along_fibrils(self, X, receivers) -> None:
        """The history of the ``receivers`` (P,) bool pairs from a *donor*: the pair in
        contact at ``X`` (largest overlap) with the same centre and fibril, on a
        neighbouring element. The donor's chord point is named by its fibril parameter
        S = S0(e) + s_bar h(e) and re-expressed on the receiver's chord (outside [0, 1]
        until the contact reaches it: the chord continued); the projectile's material point
        ``xi`` is the donor's, and so is the elastic gap at ``X``: ``anchor = e - j'(X)``.
        So a sphere rolling or sliding on to the next element carries its stick state."""
        mesh, sp_ = self.sphere.mesh, self.sphere
        rec = np.asarray(receivers, bool)
        P = rec.size
        R, k, kT = self._loads(np.arange(P))
        st = sphere_friction_state(X, sp_.radius, R, self.xi, self.s_bar, self.anchor, k, kT, self.mu)
        on = st.normal > 0.0
        donor_ok = on & ~rec
        if not donor_ok.any() or not rec.any():
            return
        elem = self.keys[:, 1]
        group = np.stack([self.keys[:, 0], mesh.elem_fibril[elem]], axis=1)
        _, inv = np.unique(group, axis=0, return_inverse=True)
        inv = inv.ravel()
        order = np.lexsort((-st.normal, ~donor_ok, inv))       # per group: donors first, the most loaded first
        starts = np.r_[True, inv[order][1:] != inv[order][:-1]]
        lead = order[starts]
        first = np.full(inv.max() + 1, -1, np.int64)
        first[inv[lead]] = np.where(donor_ok[lead], lead, -1)
        donor = first[inv]
        take = rec & (donor >= 0) & (np.abs(elem - elem[np.maximum(donor, 0)]) == 1)
        if not take.any():
            return
        r, d = np.flatnonzero(take), donor[take]
        S0 = mesh.node_s[mesh.conn[:, 0]]
        h = mesh.node_s[mesh.conn[:, -1]] - S0
        S = S0[elem[d]] + self.s_bar[d] * h[elem[d]]
        xi, s_bar, anchor = self.xi.copy(), self.s_bar.copy(), self.anchor.copy()
        s_bar[r] = (S - S0[elem[r]]) / h[elem[r]]
        xi[r] = self.xi[d]
        anchor[r] = st.e[d] - sphere_material_jump(X[r], xi[r], s_bar[r])
        self.xi, self.s_bar, self.anchor = xi, s_bar, anchor

    def spring_energy(self) -> np.ndarray:
        """|t|^2 / (2 kT) per pair of the last commit (zeros before it)."""
        st = self.last
        if st is None:
            return np.zeros(self.keys.shape[0])
        kT = self.stiffness * self.sphere.k
        return np.where(st.normal > 0.0, np.einsum("pi,pi->p", st.t, st.t) / (2.0 * kT), 0.0)

    def record(self) -> dict:
        """The history by pair key (copies): ``keys`` (n, 2), ``xi`` (n, 3), ``s_bar`` (n,),
        ``anchor`` (n, 3), ``dissipated``."""
        return {"keys": np.array(self.keys, np.int64), "xi": np.array(self.xi, float),
                "s_bar": np.array(self.s_bar, float), "anchor": np.array(self.anchor, float),
                "dissipated": float(self.dissipated)}

    def seed(self, record) -> np.ndarray:
        """The history of the current table from a ``record`` (by pair key; a pair not in the
        record keeps the history it has); returns which pairs were found."""
        idx = match_rows(self.keys, np.asarray(record["keys"], np.int64).reshape(-1, 2))
        hit = idx >= 0
        self.xi[hit] = np.asarray(record["xi"], float).reshape(-1, 3)[idx[hit]]
        self.s_bar[hit] = np.asarray(record["s_bar"], float).reshape(-1)[idx[hit]]
        self.anchor[hit] = np.asarray(record["anchor"], float).reshape(-1, 3)[idx[hit]]
        self.dissipated = float(record.get("dissipated", 0.0))
        return hit
