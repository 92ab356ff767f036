"""Friction between fibrils: regularised Coulomb at the contact points of a ``ContactTerm``,
with the stick history carried across steps and map rebuilds (law and tangent:
``rve.physics.friction_forms``; choices: docs/contact.md "Friction").

Contract
--------
``FrictionLaw(coefficient, stiffness, pairs)``: the validated law. ``coefficient`` mu of
every pair of fibrils, ``pairs`` ``((family_a, family_b, mu), ...)`` overrides it for the
pairs of those fibril families (unordered), ``stiffness`` eps_T / P*: the tangential penalty
per unit length relative to the normal one (P* as configured when the term is built,
``FrictionTerm.penalty``; the augmented Lagrangian's penalty increase does not change it).
``enabled`` is False when every mu is 0 (the contact term then carries no friction at all:
the frictionless results bit for bit).

``FrictionTerm(contact, law)`` is owned by a ``ContactTerm`` of any contact geometry
(``contact.friction``). Its points are those of the term's *rows*: the map pairs on the
chords, the two half passes' oriented rows on the curves (``HalfPasses``: a's points pressed
on b), each row with G points, M local nodes (the chord ends; a's then b's element nodes or
stencils) and its own history; the forces of a pair's rows are folded into the pair's local
layout. The contact term calls

* ``on_rebuild(x)`` after every map rebuild: the history of every point of the new map by
  point key (``ContactTerm._point_keys``: + element, point index, - element, shift; on the
  curves a's element, the point, b's element, the shift); a
  point whose key was in the old map keeps its history, a new point takes the history of
  the same + point on a neighbouring element of the same - fibril when that one is in
  contact at ``x`` (``share_along_fibrils``), else it starts at ``x`` with no elastic gap
  (its material point the closest point at ``x``);
* ``add_to(x, act, R, Kx, Kw, jacobian)``: the friction residual and tangent of the active
  pairs added to the contact term's local arrays (the mechanical block of the chord ends, or
  of every local node on the curves).

``start(x)`` commits the state the history started at (no elastic gap anywhere: nothing is
dissipated, whatever rounding the frame's turn leaves; ``forget()`` before a map rebuild
makes that rebuild start every point anew). Drivers call ``commit(x)`` at every converged
state (the history becomes that state's, the
points out of contact take that of a point in contact on the same + point and - fibril, on
the curves of the point whose row owns the closest point where none is in contact, and
the dissipated energy is accumulated in ``dissipated``); the history of a point is its
material point ``s_bar``, its ``anchor`` and ``d_ref``, the direction of the - side the
anchor is stored in (the chord; on the curves the tangent at the closest point; the law
turns the anchor with it); ``record()`` / ``seed(record)`` carry the
history to another system or through a checkpoint (by point key; a record without ``d_ref``
takes the directions at the seeding state);
``set_families(labels)`` names the family of every fibril (default: one family);
``state(x)`` the return mapping at ``x`` from the held history (``FrictionPoints``, per row);
``material_weights(s_bar)``, ``local_nodes(v)`` and ``local_directors(v)`` the rows'
material weights and local values of a nodal field and of its first-director part (the
dynamic scenes' friction power);
``last`` the return mapping of the last committed state and ``points()`` its summary (total
friction and normal force, stick and slip counts).

Frozen loads (the predictor of ``rve.solvers.frictional``): ``freeze(x)`` (or
``freeze(None)``: the loads of the last committed state) fixes the normal force ``f0`` and
normal ``n0`` of every point by point key, and the point of the - chord the friction force
acts on (the closest point at ``x``: the history's material point moved there with the
same trial gap, ``friction_forms.moved_history``, and the anchor's turn linearised there,
``friction_forms.frozen_turn``); until ``unfreeze()`` the term's forces are those
of the convex incremental potential ``sum psi(e0)`` (``rve.physics.friction_forms.
frozen_potential``) on every pair with a frozen load (also pairs not in contact now, so the
potential and its gradient are smooth in x), ``potential(x)`` its value (added to the
contact term's ``energy``), and a map rebuild carries the frozen loads by point key (a new
point: no load). ``hold_loads(x)`` keeps the loads at ``x`` by point key and ``freeze_held()`` freezes them
later, on the map of then (the augmented Lagrangian's re-solves: the loads of the last
converged solve, before the multiplier update); ``frozen`` says whether loads are frozen; ``smoothing`` (eta >= 0, set by
the solver, reset by ``unfreeze``) rounds the corner of the cone in that potential.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...physics.contact_curve import curve_basis
from ...physics.contact_forms import penalty_law
from ...physics.contact_smooth import hermite_basis
from ...physics.friction_forms import (frame_friction_forces, frame_friction_state, frame_frozen_potential,
                                      frame_frozen_turn, frame_refreeze, frame_tangential_gap, friction_forces,
                                      friction_state, frozen_potential, frozen_turn, material_weights,
                                      minus_direction, moved_history, section_frame, start_history, tangential_gap)
from ...kernels import use_numba
from .contact_pairs import HalfPasses

__all__ = ["FrictionLaw", "FrictionTerm", "MAX_FRICTION_COEFFICIENT", "match_rows", "row_groups"]

#: largest accepted friction coefficient (dry polymer and rubber contacts stay below it)
MAX_FRICTION_COEFFICIENT = 2.0


@dataclass(frozen=True)
class FrictionLaw:
    """Regularised Coulomb law (module docstring); ``stiffness`` eps_T / P* > 0."""

    coefficient: float = 0.0
    stiffness: float = 1.0
    pairs: tuple = ()
    #: the frame the anchor turns with: "chord" (the - direction's smallest rotation) or
    #: "section" (the - cross-section's frame from the first director of the - element's
    #: section node, ``FrictionTerm.section_node``)
    frame: str = "chord"

    def __post_init__(self):
        _check_mu("friction coefficient", self.coefficient)
        if self.frame not in ("chord", "section"):
            raise ValueError(f"friction frame must be 'chord' or 'section', got {self.frame!r}")
        if not self.stiffness > 0:
            raise ValueError(f"friction stiffness (eps_T / P*) must be > 0, got {self.stiffness}")
        for item in self.pairs:
            if len(item) != 3:
                raise ValueError(f"friction pairs are (family_a, family_b, mu), got {item!r}")
            _check_mu(f"friction coefficient of the pair {item[0]}-{item[1]}", item[2])

    @property
    def enabled(self) -> bool:
        return self.coefficient > 0 or any(float(m) > 0 for _, _, m in self.pairs)

    def matrix(self, families) -> np.ndarray:
        """mu of every pair of the ``families`` (names, in order): (n, n), symmetric."""
        names = list(families)
        M = np.full((len(names), len(names)), float(self.coefficient))
        for a, b, m in self.pairs:
            if a in names and b in names:
                i, j = names.index(a), names.index(b)
                M[i, j] = M[j, i] = float(m)
        return M


def _check_mu(what, value):
    if not 0.0 <= float(value) <= MAX_FRICTION_COEFFICIENT:
        raise ValueError(f"{what} must be in [0, {MAX_FRICTION_COEFFICIENT}], got {value}")


def match_rows(keys_to, keys_from) -> np.ndarray:
    """For every row of ``keys_to`` (n, k) the index of the equal row of ``keys_from``
    (m, k), -1 where there is none (rows of ``keys_from`` are unique)."""
    keys_to = np.asarray(keys_to, np.int64)
    keys_from = np.asarray(keys_from, np.int64)
    out = np.full(keys_to.shape[0], -1, np.int64)
    if keys_to.shape[0] == 0 or keys_from.shape[0] == 0:
        return out
    inv = row_groups(np.concatenate([keys_from, keys_to]))
    owner = np.full(inv.max() + 1, -1, np.int64)
    owner[inv[:keys_from.shape[0]]] = np.arange(keys_from.shape[0])
    return owner[inv[keys_from.shape[0]:]]


def row_groups(keys) -> np.ndarray:
    """The group index (n,) of every row of ``keys`` (n, k): equal rows, equal index (the
    indices of ``np.unique(keys, axis=0, return_inverse=True)``, by a lexicographic sort of
    the columns: ``np.unique(axis=0)`` compares rows as opaque bytes, ~20x slower on the
    weave's maps)."""
    keys = np.asarray(keys, np.int64)
    if keys.shape[0] == 0:
        return np.zeros(0, np.int64)
    order = np.lexsort(keys.T[::-1])
    srt = keys[order]
    first = np.r_[True, (srt[1:] != srt[:-1]).any(axis=1)]
    inv = np.empty(keys.shape[0], np.int64)
    inv[order] = np.cumsum(first) - 1
    return inv


class FrictionTerm:
    name = "friction"

    def __init__(self, contact, law: FrictionLaw):
        self.contact, self.law = contact, law
        #: P* of the law as configured: eps_T = stiffness * this, whatever P* the augmented
        #: Lagrangian's penalty increase (``ContactTerm.set_penalty``) sets meanwhile, so that the
        #: stick length stays the law's and the loop's return to the configured P* (line loads
        #: unchanged) changes no friction force either
        self.penalty = float(contact.params.penalty)
        self.family_names = ("fibril",)
        self.fibril_family = np.zeros(contact.mesh.n_fibrils, np.int64)
        self._mu_matrix = law.matrix(self.family_names)
        #: history of the map's points (rows: the pairs, or the curves' oriented rows):
        #: keys (rows*G, 6), s_bar (rows, G), anchor (rows, G, 3), d_ref (rows, G, 3) the - side's
        #: direction the anchor was stored in (``friction_forms``: the anchor turns with it)
        self.keys = None
        self.s_bar = None
        self.anchor = None
        self.d_ref = None
        #: the section frame (``law.frame == "section"``): the anchor turns with the - cross-section's
        #: frame, ``m_ref`` (rows, G, 3) its first director's unit part across ``d_ref`` then
        self.frame = law.frame == "section"
        self.m_ref = None
        #: energy dissipated by slip over the committed states (N mm)
        self.dissipated = 0.0
        self.mu_pair = np.zeros(0)
        #: the return mapping of the last committed state (FrictionPoints), None before
        self.last = None
        #: loads of the last committed state by point key: (keys, f, n, s_plus), None before
        self._committed_loads = None
        #: frozen loads of the map's points (dict f0 (rows, G), n0 (rows, G, 3), s_plus (rows, G)), or None
        self._frozen = None
        #: the rounding of the cone's corner in the frozen-load potential (0: the law's)
        self.smoothing = 0.0
        #: ``(frozen loads, pairs, inputs)`` of the last ``_frozen_inputs`` call
        self._frozen_cache = None
        #: True while ``multipliers.equilibrium`` re-solves the step at updated multipliers:
        #: ``frictional_solve`` then takes its predictor in rounds (``RESOLVE_ROUNDS``)
        self.resolving = False
        #: True while a solve's state only feeds the next multiplier update
        #: (``multipliers.equilibrium``): ``frictional_solve`` then takes its first predictor
        #: stage alone and stops there (``rve.solvers.frictional._provisional``)
        self.provisional = False
        #: False while the caller solves a failed solve again itself: ``frictional_solve`` then
        #: skips its fallback (``multipliers.equilibrium``'s full solve at a raised P*)
        self.fallback = True
        #: ``(keys, loads)``: the loads (``loads_at``) of the last converged solve of the Uzawa
        #: loop by point key (``hold_loads``), or None
        self._held_loads = None

    # ------------------------------------------------------------------ set-up
    def set_families(self, labels) -> None:
        """The family of every fibril (n_fibrils labels, e.g. the yarn directions); the
        pair coefficients of the law apply to their pairs (takes effect at once)."""
        labels = [str(v) for v in labels]
        if len(labels) != self.contact.mesh.n_fibrils:
            raise ValueError(f"set_families needs one label per fibril ({self.contact.mesh.n_fibrils}), "
                             f"got {len(labels)}")
        self.family_names = tuple(dict.fromkeys(labels))
        self.fibril_family = np.array([self.family_names.index(v) for v in labels], np.int64)
        self._mu_matrix = self.law.matrix(self.family_names)
        self._pair_coefficients()

    def set_coefficient(self, mu: float) -> None:
        """One coefficient for every pair from now on (the history is kept)."""
        self.law = FrictionLaw(float(mu), self.law.stiffness, (), self.law.frame)
        self._mu_matrix = self.law.matrix(self.family_names)
        self._pair_coefficients()

    def _pair_coefficients(self) -> None:
        cmap = self.contact.map
        if cmap is None:
            return
        F = self.fibril_family
        self.mu_pair = self._mu_matrix[F[cmap.fibril_plus], F[cmap.fibril_minus]]

    # ------------------------------------------------------------------ the points' rows
    # A row holds G points of one side pressed on the other: the map pair on the chords,
    # an oriented row of the half passes on the curves (``contact_pairs.HalfPasses``).
    def _rows(self, sel=None) -> np.ndarray:
        """The rows of the map pairs ``sel`` (all by default)."""
        c = self.contact
        if c.curve:
            return c.passes.rows(sel)
        return np.arange(c.map.n_pairs) if sel is None else np.asarray(sel, np.int64)

    def _mu(self, rows) -> np.ndarray:
        return self.mu_pair[self.contact.row_pair[rows]]

    def _map_keys(self) -> np.ndarray:
        # one key per row and point: the material point s_bar is a parameter of the row's -
        # element (the chord's e-, the curve row's b)
        return self.contact._point_keys(element_b=True) if self.contact.curve else self.contact._point_keys()

    def _local(self, x, rows, shifted: bool = True) -> np.ndarray:
        """The rows' local node positions (n, M, 3) at ``x`` (the chord ends; on the curves
        the nodes of a then of b, each side's element or stencil), the - side (b) translated
        by its periodic shift (``shifted``; a velocity field takes none)."""
        c = self.contact
        if not c.curve:
            if shifted:
                return np.stack(c.ends(x, rows), axis=1)
            r = c.layout.as_nodal(np.asarray(x, float))[:, :3]
            return np.stack([r[c.map.nodes_plus[rows, 0]], r[c.map.nodes_plus[rows, 1]],
                             r[c.map.nodes_minus[rows, 0]], r[c.map.nodes_minus[rows, 1]]], axis=1)
        ps, conn = c.passes, c.mesh.conn
        r = c.layout.as_nodal(np.asarray(x, float))[:, :3]
        Xa = r[ps.side_nodes(conn, ps.a_elem[rows])]
        Xb = r[ps.side_nodes(conn, ps.b_elem[rows])]
        if shifted:
            Xa = Xa + ps.a_shift[rows][:, None, :]
            Xb = Xb + ps.b_shift[rows][:, None, :]
        return np.concatenate([Xa, Xb], axis=1)

    def _directors(self, x, rows) -> np.ndarray:
        """The rows' local nodes' first directors g1 (n, M, 3) at ``x``, in the layout of
        ``_local`` (no periodic shift: an image is a translated copy)."""
        c = self.contact
        g = c.layout.as_nodal(np.asarray(x, float))[:, 3:6]
        if not c.curve:
            return np.stack([g[c.map.nodes_plus[rows, 0]], g[c.map.nodes_plus[rows, 1]],
                             g[c.map.nodes_minus[rows, 0]], g[c.map.nodes_minus[rows, 1]]], axis=1)
        ps, conn = c.passes, c.mesh.conn
        return np.concatenate([g[ps.side_nodes(conn, ps.a_elem[rows])], g[ps.side_nodes(conn, ps.b_elem[rows])]],
                              axis=1)

    #: the chord's local node whose g1 the section frame reads: the - element's first node
    SECTION_NODE = 2

    def section_node(self) -> int:
        """The node of a - element whose g1 the section frame reads, as an index into the
        element's nodes: its first on the chords (a chord end); on the curves the one nearest
        the element's middle (``order // 2``: the first at p = 1, the middle one at p = 2)."""
        return self.contact.mesh.order // 2 if self.contact.curve else 0

    def _side_width(self) -> int:
        """On the curves: the local nodes per side of a row (an element's, or its stencil's)."""
        return self.contact.passes.width(self.contact.mesh.conn.shape[1])

    def _side_slots(self, elems) -> np.ndarray:
        """On the curves: the slot of the section node of each element of ``elems`` among its
        side's local nodes (on the C¹ curve its slot in the element's stencil)."""
        ps, k = self.contact.passes, self.section_node()
        elems = np.asarray(elems, np.int64)
        return np.full(elems.size, k, np.int64) if ps.stencil is None else ps.stencil.own[elems, k]

    def section_slots(self, rows) -> np.ndarray:
        """(n,) the position of each row's section node among its local nodes (``_local``):
        ``SECTION_NODE`` on the chords; on the curves in b's side, after a's nodes."""
        rows = np.asarray(rows, np.int64)
        if not self.contact.curve:
            return np.full(rows.size, self.SECTION_NODE, np.int64)
        return self._side_width() + self._side_slots(self.contact.passes.b_elem[rows])

    def section_positions(self) -> np.ndarray:
        """The positions among a pair's local nodes (the contact term's ``m``) where a section
        node can sit: the - chord end ``a-`` on the chords; on the curves the section slots
        of both halves (each half pass presses one side on the other: either element is a
        row's - side), every slot a stencil gives it."""
        c = self.contact
        if not c.curve:
            return np.array([c.endpos[self.SECTION_NODE]], np.int64)
        slots = np.unique(self._side_slots(np.arange(c.mesh.conn.shape[0])))
        return np.concatenate([slots, self._side_width() + slots])

    def _section_weights(self, rows):
        """``s -> (gw, d gw/ds)`` (n, G, M): the weights of the rows' section director, the g1
        of their - element's section node (``section_slots``), the same at every ``s``."""
        slots = self.section_slots(rows)
        M = 2 * self._side_width() if self.contact.curve else 4

        def weights(s):
            w = np.zeros(np.shape(s) + (M,))
            np.put_along_axis(w, np.broadcast_to(slots.reshape((-1,) + (1,) * np.ndim(s)), np.shape(s) + (1,)), 1.0,
                              axis=-1)
            return w, np.zeros_like(w)
        return weights

    def _section_m(self, x, rows, d):
        """``b_hat`` (n, G, 3): the unit part across ``d`` (n, G, 3) of the rows' section g1."""
        rows = np.asarray(rows, np.int64)
        g = self._directors(x, rows)[np.arange(rows.size), self.section_slots(rows)][:, None, :]
        return section_frame(d, np.broadcast_to(g, d.shape))[0]

    def _s_plus(self, rows) -> np.ndarray:
        """The + points' parameters (n, G) of ``rows``."""
        c = self.contact
        G = c.params.n_gp
        if c.curve:
            return np.broadcast_to(c.passes.s, (np.size(rows), G))
        return np.broadcast_to(c.map.s_plus, (c.map.n_pairs, G))[rows]

    def _weights(self, rows, s_plus):
        """``s -> cb`` (n, G', M): the material weights of the rows' points (+ points at
        ``s_plus`` (n, G'), - material points at ``s``) without a geometry evaluation (the
        frozen potential); equal to ``geometry.material_weights``."""
        c = self.contact
        if not c.curve:
            return lambda s: material_weights(s_plus, s)
        ps = c.passes
        if ps.stencil is None:
            order = c.mesh.order
            Na = curve_basis(order, s_plus)[0]
            return lambda s: np.concatenate([Na, -curve_basis(order, s)[0]], axis=-1)
        S = ps.stencil.S
        Sa, Sb = S[ps.a_elem[rows]], S[ps.b_elem[rows]]
        Ha = np.matmul(hermite_basis(s_plus)[0], Sa)
        return lambda s: np.concatenate([Ha, -np.matmul(hermite_basis(s)[0], Sb)], axis=-1)

    def _geometry(self, x, rows):
        """The geometry of ``rows`` at ``x`` (``ChordGeometry`` or ``CurveGeometry``)."""
        c = self.contact
        if not c.curve:
            return c.geometry(x, rows)
        r = c.layout.as_nodal(np.asarray(x, float))[:, :3]
        return c.passes.geometry(c.mesh.order, c.mesh.conn, r, c.row_gap_radius(rows), rows)

    def _fold(self, R, K=None):
        """Row arrays (the curves' 2n oriented rows) in the pairs' local layout (n pairs)."""
        c = self.contact
        if not c.curve:
            return R, K
        w = R.shape[1] // 2
        return HalfPasses.fold(R, w), (None if K is None else HalfPasses.fold(K, w, axes=(1, 3)))

    def _place(self, Rl, K5, pos, Rf, Kf):
        """Add pair arrays ``Rf`` (n, M, 3), ``Kf`` (n, M, 3, M, 3) to the contact term's
        local arrays ``Rl`` (., m, nC), ``K5`` (., m, nC, m, nC) at pair positions ``pos``:
        on the chord ends' slots (``endpos``), or on every local node for the curves."""
        c = self.contact
        ep, nc = c.endpos, Rf.shape[-1]
        if c.curve or np.array_equal(ep, np.arange(Rl.shape[1])):   # the forms' nodes in order: slices
            Rl[pos, :, 0:nc] += Rf
            if K5 is not None:
                K5[pos, :, 0:nc, :, 0:nc] += Kf
            return
        Rl[pos[:, None], ep[None, :], 0:nc] += Rf
        if K5 is not None:   # one scatter: (pairs, k, l) advanced, the nc x nc blocks sliced
            K5[pos[:, None, None], ep[None, :, None], 0:nc, ep[None, None, :], 0:nc] += Kf.transpose(0, 1, 3, 2, 4)

    # ------------------------------------------------------------------ history
    def on_rebuild(self, x) -> None:
        """History of the new map's points (module docstring)."""
        c = self.contact
        self._pair_coefficients()
        G = c.params.n_gp
        rows = self._rows()
        P = rows.size
        keys = self._map_keys()
        geo = c.geometry(x) if P else None
        if P:
            X = self._local(x, rows)
            s_new, a_new = start_history(X, None, geo.s_minus, weights=geo.material_weights)
            d_new = minus_direction(X, geo.direction_weights(geo.s_minus))[0]
        else:
            s_new, a_new, d_new = np.zeros((0, G)), np.zeros((0, G, 3)), np.zeros((0, G, 3))
        m_new = self._section_m(x, rows, d_new).reshape(-1, 3) if self.frame and P else np.zeros((P * G, 3))
        hit = np.zeros(P * G, bool)
        if self.keys is not None and P:
            idx = match_rows(keys, self.keys)
            hit = idx >= 0
            s_new = s_new.reshape(-1)
            a_new = a_new.reshape(-1, 3)
            d_new = d_new.reshape(-1, 3)
            s_new[hit] = self.s_bar.reshape(-1)[idx[hit]]
            a_new[hit] = self.anchor.reshape(-1, 3)[idx[hit]]
            d_new[hit] = self.d_ref.reshape(-1, 3)[idx[hit]]
            if self.frame:
                m_new[hit] = self.m_ref.reshape(-1, 3)[idx[hit]]
        old_keys = self.keys
        self.keys = keys
        self.s_bar = s_new.reshape(P, G)
        self.anchor = a_new.reshape(P, G, 3)
        self.d_ref = d_new.reshape(P, G, 3)
        self.m_ref = m_new.reshape(P, G, 3) if self.frame else None
        if P and not hit.all():
            self.share_along_fibrils(x, receivers=~hit.reshape(P, G), geo=geo)
        if self._frozen is not None:
            self._frozen = self._loads_by_key(old_keys, self._frozen)

    def forget(self) -> None:
        """Drop the history's point keys: the next map rebuild starts every point anew, with
        no elastic gap at its state (a history started on a map of other curves, e.g. before a
        periodic cell's wraps joined the C¹ curves across the seams, is not carried)."""
        self.keys = None

    def _loads(self, geo, rows):
        c = self.contact
        w = np.asarray(c.weight[rows], float)
        w = np.broadcast_to(w[:, None] if w.ndim == 1 else w, geo.g.shape)
        _, phi1, phi2 = penalty_law(np.where(geo.active, geo.g, 0.0), float(c.params.penalty), c.onset)
        f = np.where(geo.active, w * phi1, 0.0)
        kN = np.where(geo.active, w * phi2, 0.0)
        kT = w * float(self.law.stiffness) * self.penalty
        return f, kN, kT

    def state(self, x, sel=None):
        """``FrictionPoints`` of the rows of the map pairs ``sel`` (all by default) at ``x``
        from the held history (on the curves the oriented rows ``HalfPasses.rows(sel)``)."""
        rows = self._rows(sel)
        geo = self._geometry(x, rows)
        f, _, kT = self._loads(geo, rows)
        if self.frame:
            return frame_friction_state(geo, self._local(x, rows), self._directors(x, rows), self.s_bar[rows],
                                        self.anchor[rows], self.d_ref[rows], self.m_ref[rows], f, kT, self._mu(rows),
                                        self._section_weights(rows))
        return friction_state(geo, self._local(x, rows), self.s_bar[rows], self.anchor[rows], f, kT, self._mu(rows),
                              d_ref=self.d_ref[rows])

    def commit(self, x) -> float:
        """Make ``x`` (a converged state) the history; returns the energy dissipated since the
        last commit (N mm), added to ``dissipated``."""
        if self.contact.map.n_pairs == 0:
            return 0.0
        rows = self._rows()
        geo = self.contact.geometry(x)
        f, _, kT = self._loads(geo, rows)
        X = self._local(x, rows)
        if self.frame:
            Gl = self._directors(x, rows)
            st = frame_friction_state(geo, X, Gl, self.s_bar, self.anchor, self.d_ref, self.m_ref, f, kT,
                                      self._mu(rows), self._section_weights(rows))
        else:
            st = friction_state(geo, X, self.s_bar, self.anchor, f, kT, self._mu(rows), d_ref=self.d_ref)
        self._committed_loads = (np.array(self.keys, np.int64), np.array(f, float), np.array(geo.n, float),
                                 np.array(geo.s_plus, float))
        self.last = st
        self.s_bar, self.anchor, self.d_ref = st.s_bar, st.anchor, st.d_ref
        # the committed state's frozen form (``freeze(None)``): its turn, and the anchor less
        # the turn's linear part, so that the frozen gap is the law's at the state
        D = geo.direction_weights(geo.s_minus)
        if self.frame:
            self.m_ref = st.m_ref
            gw = self._section_weights(rows)(geo.s_minus)[0]
            Dw, Jd, d, gw, Jg, g = frame_frozen_turn(X, Gl, D, gw, geo.n, geo.rho, geo.active)
            anchor_f = self.anchor - np.einsum("pgij,pgj->pgi", Jd, d) - np.einsum("pgij,pgj->pgi", Jg, g)
            self._committed_history = (self.s_bar.copy(), anchor_f, self.d_ref.copy(), Jd, Dw, self.m_ref.copy(),
                                       Jg, gw)
        else:
            Dw, Jd, d = frozen_turn(X, D, geo.n, geo.rho, geo.active)
            self._committed_history = (self.s_bar.copy(), self.anchor - np.einsum("pgij,pgj->pgi", Jd, d),
                                       self.d_ref.copy(), Jd, Dw)
        self.share_along_fibrils(x, receivers=(st.normal <= 0.0) & ~self._owners(geo), geo=geo)
        d = float(st.dissipation.sum())
        self.dissipated += d
        return d

    def start(self, x) -> None:
        """Commit ``x``, the state the history started at (``on_rebuild`` with no keys, or
        after ``forget``): its trial gaps vanish, with the section frame to the rounding of the
        anchor taken apart in the section's frame and put back together, which the return map
        of a point with a vanishing normal force can count as a slip (~1e-33 N mm); the start
        dissipates nothing."""
        self.commit(x)
        self.dissipated = 0.0

    def _owners(self, geo) -> np.ndarray:
        """(rows, G) bool: on the curves the points whose closest point their row owns (an
        interior one, ``CurveGeometry.owned``), in contact or not; none on the chords."""
        owned = getattr(geo, "owned", None)
        return np.zeros(geo.active.shape, bool) if owned is None else np.asarray(owned, bool)

    def share_along_fibrils(self, x, receivers, geo=None) -> None:
        """The history of the ``receivers`` (rows, G) bool points from a *donor*: the point in
        contact at ``x`` (largest overlap) with the same + point (+ element, point
        index), - fibril and shift, on a neighbouring - element; on the curves, where none is
        in contact, the point whose row owns the closest point (so the rows of a + point on
        both sides of an element end of the - fibril hold one material point before the
        contact reaches them). The donor's material point is
        named by its fibril parameter S = S0(e-) + s_bar h(e-) and re-expressed on the
        receiver's element, ``s_bar = (S - S0(e-')) / h(e-')`` (outside [0, 1] until the
        contact reaches that element: the element's chord, curve or Hermite cubic continued),
        and the receiver keeps the donor's elastic gap at ``x``: ``anchor = e - j'(x;
        s_bar)``, stored in the direction of the turn at the receiver's closest point on the
        chords and at the donor's on the curves (where the contact is; when it reaches the
        element end the two rows turn their anchors alike). So a contact that moves on to
        the next element of the - fibril carries its stick state instead of sticking anew."""
        c, mesh = self.contact, self.contact.mesh
        P, G = self.s_bar.shape
        rows = self._rows()
        geo = c.geometry(x) if geo is None else geo
        X = self._local(x, rows)
        keys = self.keys
        group = keys.copy()
        group[:, 2] = mesh.elem_fibril[keys[:, 2]]
        inv = row_groups(group)
        rec = np.asarray(receivers, bool).reshape(-1)
        donor_ok = (geo.active | self._owners(geo)).reshape(-1) & ~rec & (np.repeat(self._mu(rows), G) > 0)
        if not donor_ok.any() or not rec.any():
            return
        fN = np.where(geo.active, geo.g, -np.inf).reshape(-1)
        order = np.lexsort((-fN, ~donor_ok, inv))      # per group: donors first, the most loaded first
        first = np.full(inv.max() + 1, -1, np.int64)
        grp_sorted = inv[order]
        starts = np.r_[True, grp_sorted[1:] != grp_sorted[:-1]]
        lead = order[starts]
        first[inv[lead]] = np.where(donor_ok[lead], lead, -1)
        donor = first[inv]
        # neighbours along the - fibril only (the element continued over one element); a
        # fibril that wraps into its own image continues from its last element into its
        # first (the keys' translations are taken modulo the wrap, so both are one group)
        em = keys[:, 2]
        nb = c.neighbours
        ed = em[np.maximum(donor, 0)]
        ahead, behind = nb.next[ed] == em, nb.prev[ed] == em
        take = rec & (donor >= 0) & (ahead | behind)
        if not take.any():
            return
        r, d = np.flatnonzero(take), donor[take]
        conn, node_s = mesh.conn, mesh.node_s
        S0 = node_s[conn[:, 0]]
        h = node_s[conn[:, -1]] - S0
        S = S0[em[d]] + self.s_bar.reshape(-1)[d] * h[em[d]]
        # across the seam the fibril parameter runs on by one fibril length
        off = np.asarray(mesh.elem_offsets)
        fib = mesh.elem_fibril[em[r]]
        length = S0[off[1:] - 1] + h[off[1:] - 1] - S0[off[:-1]]
        seam = np.where(ahead[r] & (em[r] < em[d]), 1.0, 0.0) - np.where(behind[r] & (em[r] > em[d]), 1.0, 0.0)
        sb = (S - seam * length[fib] - S0[em[r]]) / h[em[r]]
        if self.frame:
            e = frame_tangential_gap(geo, X, self._directors(x, rows), self.s_bar, self.anchor, self.d_ref,
                                     self.m_ref, self._section_weights(rows)).reshape(-1, 3)[d]
        else:
            e = tangential_gap(geo, X, self.s_bar, self.anchor, self.d_ref).reshape(-1, 3)[d]
        pr = r // G
        wr = self._weights(pr, geo.s_plus.reshape(-1)[r][:, None])
        cb = wr(sb[:, None])[:, 0]     # (n, M)
        jr = np.einsum("nk,nki->ni", cb, X[pr])
        s_flat, a_flat = self.s_bar.reshape(-1).copy(), self.anchor.reshape(-1, 3).copy()
        d_flat = self.d_ref.reshape(-1, 3).copy()
        s_flat[r], a_flat[r] = sb, e - jr       # the donor's gap at x: stored in the receiver's chord now
        # the direction of the turn: the receiver's at x on the chords, the donor's on the curves
        via = d if c.curve else r
        Dv = geo.direction_weights(geo.s_minus).reshape(P * G, -1)[via]
        d_flat[r] = minus_direction(X[via // G], Dv[:, None, :])[0][:, 0]
        if self.frame:   # and the receiver's section frame at x
            m_flat = self.m_ref.reshape(-1, 3).copy()
            m_flat[r] = self._section_m(x, r // G, d_flat[r][:, None, :])[:, 0]
            self.m_ref = m_flat.reshape(P, G, 3)
        self.s_bar, self.anchor, self.d_ref = s_flat.reshape(P, G), a_flat.reshape(P, G, 3), d_flat.reshape(P, G, 3)

    def record(self) -> dict:
        """The history by point key (copies): ``keys`` (n, 6), ``s_bar`` (n,), ``anchor``
        (n, 3), ``d_ref`` (n, 3), ``dissipated``."""
        rec = {"keys": np.array(self.keys, np.int64), "s_bar": np.array(self.s_bar, float).reshape(-1),
               "anchor": np.array(self.anchor, float).reshape(-1, 3), "d_ref": np.array(self.d_ref, float).reshape(-1, 3),
               "dissipated": float(self.dissipated)}
        if self.frame:
            rec["m_ref"] = np.array(self.m_ref, float).reshape(-1, 3)
        return rec

    def seed(self, record) -> None:
        """The history of the current map from a ``record`` (by point key; a point not in the
        record keeps the history it has; a record without ``d_ref`` keeps the directions of
        the map, i.e. its anchors are taken as stored in the chords at the seeding state)."""
        idx = match_rows(self.keys, record["keys"])
        hit = idx >= 0
        s = self.s_bar.reshape(-1).copy()
        a = self.anchor.reshape(-1, 3).copy()
        d = self.d_ref.reshape(-1, 3).copy()
        s[hit] = np.asarray(record["s_bar"], float)[idx[hit]]
        a[hit] = np.asarray(record["anchor"], float).reshape(-1, 3)[idx[hit]]
        if record.get("d_ref") is not None:
            d[hit] = np.asarray(record["d_ref"], float).reshape(-1, 3)[idx[hit]]
        if self.frame and record.get("m_ref") is not None:
            m = self.m_ref.reshape(-1, 3).copy()
            m[hit] = np.asarray(record["m_ref"], float).reshape(-1, 3)[idx[hit]]
            self.m_ref = m.reshape(self.anchor.shape)
        self.s_bar, self.anchor = s.reshape(self.s_bar.shape), a.reshape(self.anchor.shape)
        self.d_ref = d.reshape(self.anchor.shape)
        self.dissipated = float(record.get("dissipated", 0.0))

    def material_weights(self, s_bar=None) -> np.ndarray:
        """``(rows, G, M)``: the weights of the local nodes in the jump between the + points
        and the - material points ``s_bar`` (rows, G) (default: the held history's)."""
        rows = self._rows()
        return self._weights(rows, self._s_plus(rows))(self.s_bar if s_bar is None else s_bar)

    def local_nodes(self, v, shifted: bool = True) -> np.ndarray:
        """``(rows, M, 3)``: a nodal field ``v`` at every row's local nodes (positions with the
        - side's periodic shift, ``shifted``; a velocity field without)."""
        return self._local(v, self._rows(), shifted)

    def local_directors(self, v) -> np.ndarray:
        """``(rows, M, 3)``: the first-director part of a nodal field ``v`` at every row's local
        nodes (the section frame's director weights act on them)."""
        return self._directors(v, self._rows())

    # ------------------------------------------------------------------ frozen loads
    @property
    def frozen(self) -> bool:
        return self._frozen is not None

    def _loads_by_key(self, keys_from, loads) -> dict:
        """Frozen loads given per point of ``keys_from`` (a dict of per-point arrays)
        re-expressed on the current map's points (a point not among them: no load, and the
        held history)."""
        P, G = self.s_bar.shape
        idx = match_rows(self.keys, keys_from) if keys_from is not None else np.full(P * G, -1)
        hit = idx >= 0
        M = np.shape(loads["Dw"])[-1]
        out = {"f0": np.zeros(P * G), "n0": np.zeros((P * G, 3)), "s_plus": np.full(P * G, 0.5),
               "s_bar": self.s_bar.reshape(-1).copy(), "anchor": self.anchor.reshape(-1, 3).copy(),
               "d_ref": self.d_ref.reshape(-1, 3).copy(), "Jd": np.zeros((P * G, 3, 3)), "Dw": np.zeros((P * G, M))}
        if self.frame:
            out.update(m_ref=self.m_ref.reshape(-1, 3).copy(), Jg=np.zeros((P * G, 3, 3)), gw=np.zeros((P * G, M)))
        for k, v in out.items():
            v[hit] = np.asarray(loads[k], float).reshape((-1,) + v.shape[1:])[idx[hit]]
        return {k: v.reshape((P, G) + v.shape[1:]) for k, v in out.items()}

    def freeze(self, x=None) -> None:
        """Freeze the normal force and normal of every point, and the point its friction acts
        on, at state ``x`` (None: at the last committed state, by point key, where the
        material point is that point; before any commit, an error)."""
        if x is None:
            if self._committed_loads is None:
                raise ValueError("freeze(None): no committed state yet")
            keys, f, n, s_plus = self._committed_loads
            s_bar, anchor, d_ref, Jd, Dw = self._committed_history[:5]
            by_key = {"f0": f, "n0": n, "s_plus": s_plus, "s_bar": s_bar, "anchor": anchor, "d_ref": d_ref,
                      "Jd": Jd, "Dw": Dw}
            if self.frame:
                by_key.update(zip(("m_ref", "Jg", "gw"), self._committed_history[5:]))
            self._frozen = self._loads_by_key(keys, by_key)
            return
        self._frozen = self.loads_at(x)

    def loads_at(self, x) -> dict:
        """The loads of every point of the map at ``x``: ``f0`` (rows, G) the normal forces (0
        out of contact), ``n0`` (rows, G, 3) the normals (0 out of contact), ``s_plus``, and
        the held history with its material point moved to the closest point at ``x``
        (``s_bar``, ``anchor``; unchanged out of contact). The geometry is evaluated on the
        rows in contact only (the gaps select them)."""
        c = self.contact
        P, G = self.s_bar.shape
        sel = np.flatnonzero((np.asarray(c.gaps(x)) > 0.0).any(axis=1))
        f0, n0 = np.zeros((P, G)), np.zeros((P, G, 3))
        s_bar, anchor, d_ref = self.s_bar.copy(), self.anchor.copy(), self.d_ref.copy()
        M = self._local(x, np.arange(min(P, 1))).shape[1] if P else 0
        Jd, Dw = np.zeros((P, G, 3, 3)), np.zeros((P, G, M))
        extra = {}
        if self.frame:
            extra = {"m_ref": self.m_ref.copy(), "Jg": np.zeros((P, G, 3, 3)), "gw": np.zeros((P, G, M))}
        if sel.size:
            geo = self._geometry(x, sel)
            f, _, _ = self._loads(geo, sel)
            f0[sel] = f
            n0[sel] = np.where(geo.active[..., None], geo.n, 0.0)
            sm = np.where(geo.active, geo.s_minus, self.s_bar[sel])
            X = self._local(x, sel)
            if self.frame:
                if use_numba():   # the compiled refreeze (rve.kernels.friction_frame): the same arrays
                    from ...kernels.friction_frame import frame_refreeze as refreeze
                else:
                    refreeze = frame_refreeze
                section = self._section_weights(sel)
                s_bar[sel] = sm
                Dw[sel], Jd[sel], extra["gw"][sel], extra["Jg"][sel], anchor[sel], d_ref[sel], extra["m_ref"][sel] = \
                    refreeze(X, self._directors(x, sel), self.s_bar[sel], self.anchor[sel], self.d_ref[sel],
                             self.m_ref[sel], sm, geo.n, geo.rho, geo.active, geo.material_weights,
                             geo.direction_weights, lambda s: section(s)[0])
            else:
                Dw[sel], Jd[sel], d = frozen_turn(X, geo.direction_weights(sm), geo.n, geo.rho, geo.active)
                s_bar[sel], a_sel, d_ref[sel] = moved_history(X, None, self.s_bar[sel], self.anchor[sel], sm,
                                                              weights=geo.material_weights, d_ref=self.d_ref[sel],
                                                              directions=geo.direction_weights)
                anchor[sel] = a_sel - np.einsum("pgij,pgj->pgi", Jd[sel], d)
        return {"f0": f0, "n0": n0, "s_plus": np.array(self._s_plus(np.arange(P)), float),
                "s_bar": s_bar, "anchor": anchor, "d_ref": d_ref, "Jd": Jd, "Dw": Dw, **extra}

    def hold_loads(self, x) -> None:
        """Keep the loads at ``x`` (``loads_at``: at the current multipliers and P*) by point
        key for ``freeze_held``; None drops them."""
        self._held_loads = None if x is None else (self.keys.copy(), self.loads_at(x))

    def freeze_held(self) -> bool:
        """Freeze the loads kept by ``hold_loads`` (carried to the current map by point key;
        a point not among them: no load); False, nothing frozen, when none are kept."""
        if self._held_loads is None:
            return False
        keys, loads = self._held_loads
        self._frozen = self._loads_by_key(keys, loads)
        return True

    def blend_frozen(self, keys, f0, weight: float) -> None:
        """The frozen normal forces ``weight f0_frozen + (1 - weight) f0`` where ``keys`` (n, 6)
        has the point (``f0`` (n,) by point; the other points keep theirs)."""
        idx = match_rows(self.keys, keys)
        hit = idx >= 0
        f = self._frozen["f0"].reshape(-1).copy()
        f[hit] = weight * f[hit] + (1.0 - weight) * np.asarray(f0, float)[idx[hit]]
        self._frozen = dict(self._frozen, f0=f.reshape(self._frozen["f0"].shape))

    def unfreeze(self) -> None:
        """Back to the exact law (the frozen loads dropped, no smoothing)."""
        self._frozen = None
        self._frozen_cache = None
        self.smoothing = 0.0

    def frozen_loads(self) -> dict:
        """The frozen loads (copies): ``f0`` (rows, G), ``n0`` (rows, G, 3), ``s_plus`` (rows, G)."""
        return {k: np.array(v) for k, v in self._frozen.items()}

    def _frozen_pairs(self) -> np.ndarray:
        fp = self.contact._pairs_of_rows(self._frozen["f0"] > 0.0)
        return fp[self.mu_pair[fp] > 0.0]

    def _frozen_inputs(self, sel) -> tuple:
        """``(rows, inputs)``: the frozen potential's per-point arrays of the map pairs ``sel``
        (weights, loads, anchors, turn, kT, mu), fixed while these loads stay frozen, so
        computed once per freeze and selection."""
        fz = self._frozen
        hit = self._frozen_cache
        if hit is not None and hit[0] is fz and np.array_equal(hit[1], sel):
            return hit[2]
        rows = self._rows(sel)
        f0 = fz["f0"][rows]
        w = np.asarray(self.contact.weight[rows], float)
        w = np.broadcast_to(w[:, None] if w.ndim == 1 else w, f0.shape)
        kT = w * float(self.law.stiffness) * self.penalty
        cb = self._weights(rows, fz["s_plus"][rows])(fz["s_bar"][rows])
        mu = np.broadcast_to(np.asarray(self._mu(rows), float)[:, None], f0.shape)
        c = np.ascontiguousarray
        arrays = (cb, fz["anchor"][rows], f0, fz["n0"][rows], kT, mu, fz["Dw"][rows], fz["Jd"][rows])
        if self.frame:
            arrays = arrays + (fz["gw"][rows], fz["Jg"][rows])
        out = (rows, tuple(c(a, dtype=float) for a in arrays))
        self._frozen_cache = (fz, np.array(sel, copy=True), out)
        return out

    def _frozen_forms(self, x, sel, jacobian: bool):
        """``(psi (rows, G), R, K)`` of the frozen potential on the map pairs ``sel``, R and K
        in the pairs' local layout (the compiled kernel ``rve.kernels.friction`` when
        ``use_numba()``, else ``friction_forms.frozen_potential`` or, with the section frame,
        ``frame_frozen_potential``: the same arrays)."""
        rows, arrays = self._frozen_inputs(sel)
        X = self._local(x, rows)
        if self.frame:   # the section frame's potential (numpy forms), in centroids and g1
            cb, anchor, f0, n0, kT, mu, Dw, Jd, gw, Jg = arrays
            Y = np.concatenate([X, self._directors(x, rows)], axis=-1)
            potential = frame_frozen_potential
            if use_numba():
                from ...kernels.friction import frame_frozen_potential as potential
            psi, R, K = potential(Y, cb, anchor, f0, n0, kT, mu, jacobian, self.smoothing, (Dw, Jd, gw, Jg))
            return (psi,) + self._fold(R, K)
        cb, anchor, f0, n0, kT, mu, Dw, Jd = arrays
        if use_numba():
            from ...kernels.friction import frozen_potential as compiled

            psi, R, K = compiled(X, cb, anchor, f0, n0, kT, mu, jacobian, self.smoothing, Dw, Jd)
        else:
            psi, R, K = frozen_potential(X, None, None, anchor, f0, n0, kT, mu, jacobian, self.smoothing,
                                         weights=lambda s: cb, turn=(Dw, Jd))
        return (psi,) + self._fold(R, K)

    def potential(self, x) -> float:
        """The incremental potential (N mm) at ``x`` of the frozen loads (0 when none are frozen)."""
        if self._frozen is None or self.contact.map.n_pairs == 0:
            return 0.0
        sel = self._frozen_pairs()
        if sel.size == 0:
            return 0.0
        return float(self._frozen_forms(x, sel, False)[0].sum())

    def _add_frozen(self, x, act, R, Kx, Kw, jacobian: bool):
        """``add_to`` at frozen loads: the potential's forces on the pairs with a frozen load,
        the active pairs extended by them (their normal forms zero)."""
        fp = self._frozen_pairs()
        if fp.size == 0:
            return act, R, Kx, Kw
        c = self.contact
        m, nC = c.m, c.nC
        act = np.asarray(act, np.int64)
        where = np.full(c.map.n_pairs, -1, np.int64)
        where[act] = np.arange(act.size)
        extra = fp[where[fp] < 0]                  # frozen pairs out of contact: appended
        allp = np.concatenate([act, extra])
        where[extra] = act.size + np.arange(extra.size)
        fpos = where[fp]
        Rl = np.zeros((allp.size, m, nC))
        if act.size:
            Rl[:act.size] = np.asarray(R, float).reshape(act.size, m, nC)
        _, Rf, Kf = self._frozen_forms(x, fp, jacobian)
        if not jacobian:
            self._place(Rl, None, fpos, Rf, None)
            return allp, Rl.reshape(allp.size, -1), None, Kw
        if extra.size:
            K5 = np.zeros((allp.size, m, nC, m, nC))
            if act.size:
                K5[:act.size] = np.asarray(Kx, float).reshape(act.size, m, nC, m, nC)
        else:
            K5 = np.array(Kx, float).reshape(allp.size, m, nC, m, nC)
        self._place(Rl, K5, fpos, Rf, Kf)
        if Kw is not None and extra.size:
            Kw_all = np.zeros((allp.size,) + np.shape(Kw)[1:])
            if act.size:
                Kw_all[:act.size] = Kw
            Kw = Kw_all
        return allp, Rl.reshape(allp.size, -1), K5.reshape(allp.size, -1), Kw

    # ------------------------------------------------------------------ forms
    def forces(self, x, sel, jacobian: bool):
        """Friction residual (len(sel), M, 3) and tangent (len(sel), M, 3, M, 3) of map pairs
        ``sel`` at ``x`` in the pairs' local layout (the chord ends a+, b+, a-, b-; on the
        curves the e+ side's nodes, then the e- side's, both half passes folded)."""
        rows = self._rows(sel)
        geo = self.contact.geometry(x, sel)
        f, kN, kT = self._loads(geo, rows)
        X = self._local(x, rows)
        if self.frame:   # the section frame's law (numpy forms), in centroids and g1
            return self._fold(*frame_friction_forces(geo, X, self._directors(x, rows), self.s_bar[rows],
                                                     self.anchor[rows], self.d_ref[rows], self.m_ref[rows], f, kN, kT,
                                                     self._mu(rows), self._section_weights(rows), jacobian))
        if use_numba():   # the compiled law (rve.kernels.friction): the same arrays
            from ...kernels.friction import friction_forces as compiled

            mu = np.broadcast_to(np.asarray(self._mu(rows), float)[:, None], f.shape)
            R, K = compiled(geo.c, geo.ds, geo.n, geo.rho, geo.active, geo.dc_ds,
                            geo.material_weights(self.s_bar[rows]), X, self.anchor[rows], f, kN, kT, mu, jacobian,
                            D=geo.direction_weights(geo.s_minus), d_ref=self.d_ref[rows],
                            Dp=geo.direction_weights_ds(geo.s_minus))
            return self._fold(R, K)
        R, K = friction_forces(geo, X, self.s_bar[rows], self.anchor[rows], f, kN, kT, self._mu(rows), jacobian,
                               d_ref=self.d_ref[rows])
        return self._fold(R, K)

    def add_to(self, x, act, R, Kx, Kw, jacobian: bool):
        """The contact term's ``forms`` output with the friction of its active pairs added."""
        if self._frozen is not None:
            return self._add_frozen(x, act, R, Kx, Kw, jacobian)
        if act.size == 0:
            return act, R, Kx, Kw
        c = self.contact
        Rf, Kf = self.forces(x, act, jacobian)
        m, nC, Pa = c.m, c.nC, act.size
        Rl = np.array(R, float).reshape(Pa, m, nC)
        K5 = np.array(Kx, float).reshape(Pa, m, nC, m, nC) if jacobian else None
        self._place(Rl, K5, np.arange(Pa), Rf, Kf)
        if not jacobian:
            return act, Rl.reshape(R.shape), None, Kw
        return act, Rl.reshape(R.shape), K5.reshape(Kx.shape), Kw

    def points(self) -> dict:
        """The last committed state: ``friction_force`` (N, the sum of |t|), ``normal_force``
        (N), ``stick`` and ``slip`` point counts (zeros before the first commit)."""
        st = self.last
        if st is None or st.t.size == 0:
            return {"friction_force": 0.0, "normal_force": 0.0, "stick": 0, "slip": 0}
        return {"friction_force": float(np.sqrt((st.t ** 2).sum(-1)).sum()), "normal_force": float(st.normal.sum()),
                "stick": int(st.stick.sum()), "slip": int(st.slip.sum())}
