"""Contact term: penalty between fibril chords and the thermal / electrical contact
conductance h_C a [[T]], sigma_C a [[V]] through the Hertz width a(g), on pair elements
(thesis §4.3, §4.4.6, Algorithm 5.1; choices and figures: docs/contact.md).

Contract
--------
``ContactParams``: the contact law and map settings (validated). ``ContactTerm(mesh, layout,
params, E_star)``: a term of *pair elements*, not of beam elements:

* ``rebuild(x)`` builds the contact map (``rve.contact.build_contact_map``: KD-tree
  candidates within ``cutoff = 2 max R + params.margin``, ``n_gp`` points per pair) and
  returns the pair connectivity ``local`` (P, m) (m = 4 chord end nodes for mechanics
  only, both elements' nodes with T/V); ``comps`` are the node components a pair touches
  (centroid r, and T / V when their coefficient is > 0);
* ``forms(x, w, jacobian)`` -> ``(act, R, Kx, Kw)`` on the active pairs (local arrays laid
  out as ``UnionPattern.gdofs`` / ``slots``; assembled by ``rve.model.assembler.ContactAssembler``);
  a mechanics-only term takes the compiled kernel ``rve.kernels.contact.penalty_forms`` (and
  ``gaps`` its ``chord_gaps``) when ``rve.kernels.use_numba()``, the numpy forms of
  ``rve.physics.contact_forms`` otherwise (the reference; T/V terms always; docs/kernels.md);
* diagnostics: ``geometry(x)``, ``gaps(x)``, ``active_pairs(x)``, ``energy(x)`` (penalty
  energy, the potential of the mechanical residual), ``contact_state(x)``,
  ``conductance_by_pair(x, field)``; ``curve_heat_transfer_block(x, act, coef)`` (the
  width-law jump matrix of a field on the curve geometries, for the temperature post-solve);
  ``onset`` / ``set_onset`` (C² onset of the penalty law).

Options (``ContactParams``; the defaults are the chord, the penalty and the width law, as in
the thesis): ``geometry="curve"`` evaluates the contact on the elements' Lagrange curves
with two half passes (``rve.model.terms.contact_pairs.HalfPasses``; every pair has m = 2nn
local nodes, its rows are the oriented pairs); ``geometry="smooth"`` the same on the C¹
Hermite contact curve through the end nodes (``rve.physics.contact_smooth``; a side's local
nodes are its element's stencil, the 3nn - 2 distinct nodes of the element and its two
neighbours); ``enforcement="augmented_lagrangian"`` carries
multipliers per point (``multipliers`` (rows, n_gp), kept by point key over rebuilds) that
shift the penalty law's overlap to ``g + lambda/P*``, updated by ``update_multipliers(x)``
(driven by ``rve.solvers.augmented``), ``penetration`` / ``max_penetration`` the true
overlaps, ``set_penalty`` the penalty increase of the loop; ``conductance_law="holm"`` the
a-spot law (``conductance_law``); ``friction`` a ``FrictionLaw``
(``rve.model.terms.friction``): when it is enabled the term owns a ``FrictionTerm``
(``friction``) whose forces are added to ``forms`` and whose history follows every
``rebuild`` (None, the default, or a law with every mu = 0: no friction at all).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ...contact.search import ContactMap, build_contact_map, element_neighbours, segment_distance, wrap_vectors
from ...kernels import use_numba
from ...physics.contact_curve import (
    END_SNAP, chord_deviation, curve_basis, curve_penalty_forces, curve_scalar_jump, lagrange_monomials,
)
from ...physics.contact_forms import (
    chord_gaps, chord_geometry, effective_radius, hertz_kappa, hertz_width, penalty_energy,
    penalty_forces, penalty_law, scalar_jump,
)
from ...physics.contact_smooth import hermite_basis, hermite_deviation, smooth_stencil
from .contact_pairs import HalfPasses, gather_by_key, lattice_translation, point_keys
from .friction import FrictionLaw, FrictionTerm

__all__ = ["ContactParams", "ContactTerm", "GEOMETRIES", "ENFORCEMENTS", "CONDUCTANCE_LAWS"]

#: contact geometry: the linear chords of the elements, their Lagrange centroid curve, or the
#: C¹ Hermite curve through their end nodes
GEOMETRIES = ("chord", "curve", "smooth")
#: how impenetrability is enforced: a penalty, or augmented Lagrangian multipliers on it
ENFORCEMENTS = ("penalty", "augmented_lagrangian")
#: contact conductance: the Hertz width law, or Holm's a-spot constriction from the force
CONDUCTANCE_LAWS = ("width", "holm")


@dataclass(frozen=True)
class ContactParams:
    """Contact law and map settings (units: mm, N, MPa, W, A, V).

    ``penalty`` P*: line load per unit overlap (N/mm per mm = N/mm^2); the penalty force
    per unit length is P* g. ``youngs_modulus`` E* of the Hertz width (None: from the base
    material, 1/E* = 2 (1 - nu^2)/E). ``heat_transfer`` h_C (W/(mm^2 K)) and
    ``conductance`` sigma_C (A/(mm^2 V)) of the jump terms. ``n_gp`` points per pair;
    ``margin`` added to R+ + R- for the search cutoff (covers motion between rebuilds);
    ``g_eps`` the Hertz regularisation as a fraction of the smallest radius;
    ``recompute_closest`` recomputes s- at every evaluation (else frozen per rebuild);
    ``rebuild_every`` is advisory (drivers read it); ``onset`` the width of the C² onset
    of the penalty law as a fraction of the smallest radius (0: the linear law P* g).

    ``geometry``: ``"chord"`` (the linear centroid chords, one-sided points, the closest
    point clamped to the - element) or ``"curve"`` (the elements' Lagrange centroid curve,
    both sides' points, the closest point continued to the neighbour element;
    docs/contact.md "Contact on the centroid curve") or ``"smooth"`` (as ``"curve"``, on a
    C¹ cubic Hermite curve through the element end nodes with averaged nodal tangents;
    docs/contact.md "The smooth contact curve"). ``enforcement``: ``"penalty"`` or
    ``"augmented_lagrangian"`` (Uzawa multipliers driven by ``rve.solvers.augmented``
    until the largest overlap is below ``al_tolerance`` x R, at most ``al_max_iter``
    updates, P* multiplied by ``al_penalty_growth`` after an update that did not reduce the
    overlap enough; ``rve.solvers.augmented``). ``conductance_law``: ``"width"`` (h_C, sigma_C times the Hertz width of the
    line load) or ``"holm"`` (the a-spot constriction conductance of the line load with the
    hardness ``hardness`` (MPa) and a-spot radius ``spot_radius`` (mm): per unit length
    ``2 k0 p / (pi H a_s)``, k0 the material's ``electrical_conductivity`` (V) or
    ``thermal_conductivity`` (T), p the line load; the term of a field is on when that
    conductivity is > 0, and ``conductance``/``heat_transfer`` are not used).
    ``al_tolerance`` is a fraction of the fibril radius (default 1e-4 R)."""

    penalty: float
    youngs_modulus: Optional[float] = None
    heat_transfer: float = 0.0
    conductance: float = 0.0
    n_gp: int = 4
    margin: float = 0.1
    g_eps: float = 1e-3
    recompute_closest: bool = True
    rebuild_every: int = 5
    onset: float = 0.0
    geometry: str = "chord"
    enforcement: str = "penalty"
    al_tolerance: float = 1e-4
    al_max_iter: int = 20
    al_penalty_growth: float = 4.0
    conductance_law: str = "width"
    hardness: float = 0.0
    spot_radius: float = 0.0
    friction: Optional[FrictionLaw] = None

    def __post_init__(self):
        if not self.penalty > 0:
            raise ValueError(f"contact penalty must be > 0, got {self.penalty}")
        if self.heat_transfer < 0 or self.conductance < 0:
            raise ValueError("contact heat_transfer and conductance must be >= 0")
        if int(self.n_gp) < 1:
            raise ValueError(f"n_gp must be >= 1, got {self.n_gp}")
        if not self.margin >= 0:
            raise ValueError(f"margin must be >= 0, got {self.margin}")
        if not self.g_eps >= 0:
            raise ValueError(f"g_eps must be >= 0, got {self.g_eps}")
        if not self.onset >= 0:
            raise ValueError(f"onset must be >= 0, got {self.onset}")
        if self.geometry not in GEOMETRIES:
            raise ValueError(f"contact geometry must be one of {GEOMETRIES}, got {self.geometry!r}")
        if self.enforcement not in ENFORCEMENTS:
            raise ValueError(f"contact enforcement must be one of {ENFORCEMENTS}, got {self.enforcement!r}")
        if not self.al_tolerance > 0:
            raise ValueError(f"al_tolerance must be > 0, got {self.al_tolerance}")
        if int(self.al_max_iter) < 1:
            raise ValueError(f"al_max_iter must be >= 1, got {self.al_max_iter}")
        if not self.al_penalty_growth >= 1:
            raise ValueError(f"al_penalty_growth must be >= 1, got {self.al_penalty_growth}")
        if self.conductance_law not in CONDUCTANCE_LAWS:
            raise ValueError(f"conductance_law must be one of {CONDUCTANCE_LAWS}, got {self.conductance_law!r}")
        if self.conductance_law == "holm" and not (self.hardness > 0 and self.spot_radius > 0):
            raise ValueError("conductance_law 'holm' needs hardness > 0 and spot_radius > 0, got "
                             f"hardness={self.hardness}, spot_radius={self.spot_radius}")


class ContactTerm:
    name = "contact"

    def __init__(self, mesh, layout, params: ContactParams, E_star: float, conductivity: float = 0.0,
                 thermal_conductivity: float = 0.0):
        self.mesh, self.layout, self.params = mesh, layout, params
        self.E_star = float(E_star)
        #: the half passes on a curve (Lagrange or, with ``smooth``, the C¹ Hermite one)
        self.curve = params.geometry in ("curve", "smooth")
        self.smooth = params.geometry == "smooth"
        self.augmented = params.enforcement == "augmented_lagrangian"
        self.holm = params.conductance_law == "holm"
        if self.holm:
            # a-spots of radius a_s, each carrying pi a_s^2 H: 2 sigma0 / (pi H a_s) per line load
            scale = 2.0 / (np.pi * float(params.hardness) * float(params.spot_radius))
            self.law_coef = {"V": scale * float(conductivity), "T": scale * float(thermal_conductivity)}
            self.use_T = layout.has("T") and self.law_coef["T"] > 0
            self.use_V = layout.has("V") and self.law_coef["V"] > 0
        else:
            self.law_coef = {"V": float(params.conductance), "T": float(params.heat_transfer)}
            self.use_T = layout.has("T") and params.heat_transfer > 0
            self.use_V = layout.has("V") and params.conductance > 0
        self.scalar = [f for f, on in (("T", self.use_T), ("V", self.use_V)) if on]
        self.comps = np.array([0, 1, 2] + [layout.offset[f] for f in self.scalar], dtype=np.int64)
        self.nC = len(self.comps)
        #: the components of the normal forms (``comps`` unless the blocks are widened by
        #: directors, ``widen_by_directors``) and their positions among ``comps``
        self.normal_comps, self._normal_cols = self.comps, None
        self.g_eps = float(params.g_eps) * float(mesh.radius.min())
        #: with multipliers, the width regularisation as a line load (N/mm): E* g_eps R, the
        #: load whose Hertz width is ~ sqrt(g_eps) R (independent of P*)
        self.load_eps = self.g_eps * self.E_star
        self.onset = float(params.onset) * float(mesh.radius.min())
        self.cutoff = 2.0 * float(mesh.radius.max()) + float(params.margin)
        self.map: Optional[ContactMap] = None
        #: periodic images searched at every rebuild (translations T, (K, 3)) and the
        #: fibrils that wrap into their own image (``set_periodic``); None: a plain cell
        self.images = None
        self.wrap = None
        self.lattice = None
        #: {field: c (3,)}: on a pair with the image at shift T the - side's field value is
        #: its node value + T . c (the macro jump of T or V over the lattice vector)
        self.field_jumps = {}
        #: the two half passes of the curve geometry (None for the chords)
        self.passes: Optional[HalfPasses] = None
        #: augmented Lagrangian multipliers (rows, n_gp), line loads (N/mm) of the points of
        #: every row (map pair for the chords, oriented row for the curve); None: penalty
        self.multipliers: Optional[np.ndarray] = None
        self._keys = None
        law = params.friction
        #: the friction of the contact points (None: frictionless)
        self.friction: Optional[FrictionTerm] = FrictionTerm(self, law) if law is not None and law.enabled else None
        if self.friction is not None and self.friction.frame:
            self.widen_by_directors(3)    # the section frame's friction also acts on g1

    def widen_by_directors(self, n: int) -> None:
        """The pairs' blocks widened by the first ``n`` director components of every local
        node (before the fields); the normal forms keep their own components, laid out in
        the widened ``comps`` with the director columns zero."""
        normal = self.normal_comps
        self.comps = np.array(list(range(3 + n)) + list(normal[3:]), dtype=np.int64)
        self._normal_cols = np.array([0, 1, 2] + list(range(3 + n, n + normal.size)), dtype=np.int64)
        self.nC = len(self.comps)

    def local_sparsity(self):
        """The entries of a pair's local blocks (m, nC, m, nC) its forms can fill, or None
        (all of them): with the section frame's friction the normal forms fill their own
        components and the friction the centroids of the chord ends (on the curves of every
        local node) and g1 of the - element's section node (``FrictionTerm.
        section_positions``), so the other director entries of the widened blocks are
        structural zeros (``UnionPattern.restrict``)."""
        if self._normal_cols is None or self.friction is None or not self.friction.frame:
            return None
        m, nC, cols = self.m, self.nC, self._normal_cols
        mask = np.zeros((m, nC, m, nC), bool)
        mask[np.ix_(range(m), cols, range(m), cols)] = True
        nodes = np.arange(m) if self.curve else np.asarray(self.endpos)
        r, g1, sec = np.arange(3), np.arange(3, 6), self.friction.section_positions()
        mask[np.ix_(sec, g1, nodes, r)] = True
        mask[np.ix_(nodes, r, sec, g1)] = True
        mask[np.ix_(sec, g1, sec, g1)] = True
        return mask

    def set_periodic(self, images=None, wrap=None, field_jumps=None, lattice=None) -> None:
        """Periodic images for the next ``rebuild``: ``images`` (K, 3) lattice translations
        (each pair with an image of the - element carries that shift), ``wrap`` the period
        vector of every fibril that continues into its own image (``{fibril: L_f}`` or
        (n_fibrils, 3), zero/NaN rows: no wrap), ``field_jumps`` ``{"T"/"V": c (3,)}``: an
        image at shift T carries the field value + T . c (takes effect at once; a constant
        of each pair, so no tangent entry), ``lattice`` (2, 3) the deformed lattice vectors
        the images are made of (then the point keys name a translation by its lattice
        coordinates, ``contact_pairs.lattice_translation``). ``set_periodic()`` returns to a
        plain cell."""
        self.images = None if images is None else np.asarray(images, float).reshape(-1, 3)
        self.lattice = None if lattice is None else np.asarray(lattice, float).reshape(2, 3)
        self.wrap = wrap
        self.field_jumps = {f: np.asarray(c, float).reshape(3) for f, c in (field_jumps or {}).items()}

    def rebuild(self, x) -> np.ndarray:
        """Contact map at state ``x``; returns the pair connectivity (P, m). The multipliers
        of the points that are still in the map are carried over (by point key)."""
        mesh = self.mesh
        xn = self.layout.as_nodal(np.asarray(x, float))
        if self.images is None:
            cmap = build_contact_map(xn[:, :3], mesh, self.cutoff, self.params.n_gp)
        else:
            cmap = build_contact_map(xn[:, :3], mesh, self.cutoff, self.params.n_gp, images=self.images,
                                     wrap=self.wrap)
        self.map = cmap
        conn = mesh.conn
        nn = conn.shape[1]
        ep, em = cmap.e_plus, cmap.e_minus
        stencil = None
        #: the elements before and after every element, across the wraps (the curves' stencils
        #: and the friction history's neighbours)
        self.neighbours = nb = element_neighbours(mesh, self.wrap)
        if self.smooth:
            stencil = smooth_stencil(mesh.order, conn, nb.prev, nb.next, mesh.elem_length)
            local = np.concatenate([stencil.nodes[ep], stencil.nodes[em]], axis=1)  # (P, 2 Ms)
            self.endpos = None
        elif self.scalar or self.curve:
            local = np.concatenate([conn[ep], conn[em]], axis=1)  # (P, 2nn)
            self.endpos = np.array([0, nn - 1, nn, 2 * nn - 1])
        else:
            local = np.concatenate([cmap.nodes_plus, cmap.nodes_minus], axis=1)  # (P, 4)
            self.endpos = np.arange(4)
        self.m = local.shape[1]
        fp, fm = cmap.fibril_plus, cmap.fibril_minus
        R = mesh.radius
        self.gap_radius = R[fp] + R[fm]
        self.kappa = hertz_kappa(effective_radius(R[fp], R[fm]), self.params.penalty, self.E_star)
        if self.curve:
            self.passes = HalfPasses.build(cmap, mesh, self.params.n_gp, nb, stencil)
            self.weight = self.passes.weight
            self.row_pair = np.tile(np.arange(cmap.n_pairs), 2)
        else:
            self.passes = None
            self.weight = mesh.elem_length[ep] / cmap.n_gp
            self.row_pair = np.arange(cmap.n_pairs)
        if self.augmented:
            self._carry_multipliers()
        if self.friction is not None:
            self.friction.on_rebuild(x)
        return local

    # ------------------------------------------------------------------ multipliers
    def _point_keys(self, element_b: bool = False) -> np.ndarray:
        """Keys of the points of every row (``contact_pairs.point_keys``). On the curves a
        point is named by the fibril it touches (its closest point moves on to the next
        element); ``element_b`` names the element instead, as on the chords: one key per row
        and point (the friction history, whose material point is a parameter of that
        element)."""
        cmap, G = self.map, self.params.n_gp
        lattice = self.lattice
        if self.curve:
            ps = self.passes
            fib = self.mesh.elem_fibril[ps.b_elem]
            shift = ps.b_shift - ps.a_shift
            t = None if lattice is None else lattice_translation(
                shift, lattice, wrap_vectors(self.wrap, self.mesh.n_fibrils)[fib])
            return point_keys(ps.a_elem, ps.b_elem if element_b else fib, shift, G, translation=t)
        # the chord's closest point stays on its element (clamped): a point is per pair
        t = None if lattice is None else lattice_translation(cmap.shifts, lattice)
        return point_keys(cmap.e_plus, cmap.e_minus, cmap.shifts, G, translation=t)

    def _carry_multipliers(self) -> None:
        keys = self._point_keys()
        if self.multipliers is None or self._keys is None:
            lam = np.zeros(keys.shape[0])
        else:
            lam = gather_by_key(keys, self._keys, self.multipliers)
        self._keys = keys
        self.multipliers = lam.reshape(self.row_pair.size, self.params.n_gp)

    def multiplier_record(self):
        """``(keys (n, 6) int64, values (n,))`` of the multipliers at the current map (a
        copy), or None for the penalty: what a later system needs to go on from here."""
        if self.multipliers is None or self._keys is None:
            return None
        return np.array(self._keys, np.int64), np.array(self.multipliers, float).reshape(-1)

    def seed_multipliers(self, keys, values) -> None:
        """Multipliers of the current map from a record (``multiplier_record`` of another
        system or a checkpoint): by point key, 0 where a point is not in the record."""
        if self.multipliers is None:
            raise ValueError("seed_multipliers needs enforcement 'augmented_lagrangian'")
        self._keys = np.asarray(keys, np.int64).reshape(-1, 6)
        self.multipliers = np.asarray(values, float).reshape(-1)
        self._carry_multipliers()

    def row_gap_radius(self, rows=None) -> np.ndarray:
        """R+ + R- of every row (rows,), or with the multipliers (rows, G): R+ + R- + lambda/P*
        (the penalty law of the shifted overlap is the augmented Lagrangian line load)."""
        rows = np.arange(self.row_pair.size) if rows is None else rows
        gr = self.gap_radius[self.row_pair[rows]]
        if self.multipliers is None:
            return gr
        return gr[:, None] + self.multipliers[rows] / float(self.params.penalty)

    def penetration(self, x) -> np.ndarray:
        """True overlaps R+ + R- - rho (rows, G) of the points: the law's overlap minus
        lambda/P*. -inf where a curve point is not owned and, with multipliers, where a
        chord point's closest point is clamped to an element end: such a point duplicates
        the contact of the neighbour element's pair, and pushing it out would separate
        fibrils that are not in contact there (it keeps the plain penalty, lambda = 0)."""
        if self.multipliers is None:
            return self.gaps(x)
        if self.curve:
            g = self.gaps(x)
        else:
            geo = self.geometry(x)
            sm = geo.s_minus
            g = np.where((sm > 0.0) & (sm < 1.0), geo.g, -np.inf)
        return g - self.multipliers / float(self.params.penalty)

    def max_penetration(self, x) -> float:
        """Largest true overlap over the radius, max_k g_k / min(R+, R-) (0 if none)."""
        if self.map.n_pairs == 0:
            return 0.0
        g = self.penetration(x)
        R = self.mesh.radius
        rmin = np.minimum(R[self.map.fibril_plus], R[self.map.fibril_minus])[self.row_pair]
        return float(max(0.0, (g / rmin[:, None]).max()))

    def update_multipliers(self, x, relaxation: float = 1.0) -> None:
        """Uzawa update ``lambda <- max(0, lambda + P* g)`` at state ``x`` (g the true overlap
        of the owned points), under-relaxed by ``relaxation`` (w: ``w lambda_new + (1 - w)
        lambda``; 1 the plain update), then shared by point key (``contact_pairs.gather_by_key``)."""
        if self.multipliers is None:
            raise ValueError("update_multipliers needs enforcement 'augmented_lagrangian'")
        if not 0.0 < relaxation <= 1.0:
            raise ValueError(f"relaxation must be in (0, 1], got {relaxation}")
        if self.map.n_pairs == 0:
            return
        g = self.penetration(x)
        new = np.maximum(0.0, self.multipliers + float(self.params.penalty) * np.where(np.isfinite(g), g, -np.inf))
        new = relaxation * new + (1.0 - relaxation) * self.multipliers   # w = 1: new, exactly
        self.multipliers = gather_by_key(self._keys, self._keys, new).reshape(self.multipliers.shape)

    def set_penalty(self, penalty: float, x=None) -> None:
        """P* of the law (and so the Uzawa step) to ``penalty``. Without ``x`` the
        multipliers are kept (the method of multipliers' penalty increase: for the linear law
        the line load at zero overlap is unchanged; with the onset ε it is ``φ'(lambda/P*)``,
        which drops as P* rises, docs/contact.md "Penalty increase"); with ``x`` they are
        re-expressed so that every point's line load ``φ'(g + lambda/P*)`` at ``x`` is
        unchanged: x stays the equilibrium it was (used to return to the configured P* at the
        end of a loop)."""
        if self.multipliers is None:
            raise ValueError("set_penalty needs enforcement 'augmented_lagrangian'")
        P0, P1 = float(self.params.penalty), float(penalty)
        if not P1 > 0:
            raise ValueError(f"contact penalty must be > 0, got {P1}")
        if x is not None and self.map.n_pairs:
            lam = self.multipliers
            gt = self.gaps(x) - lam / P0                     # true overlaps (-inf: a curve point not owned)
            load = penalty_law(np.where(np.isfinite(gt), gt + lam / P0, 0.0), P0, self.onset)[1]
            eps = self.onset
            # the shifted overlap that carries the same load at P1 (the inverse of φ')
            g1 = load / P1 + 0.5 * eps if eps > 0 else load / P1
            if eps > 0:
                g1 = np.where(load < 0.5 * P1 * eps, np.sqrt(2.0 * eps * load / P1), g1)
            fin = np.isfinite(gt)
            new = np.where(fin, np.where(load > 0, P1 * (g1 - np.where(fin, gt, 0.0)), lam * (P1 / P0)), 0.0)
            # a point's rows share its multiplier (those where it is not owned take the owner's)
            self.multipliers = gather_by_key(self._keys, self._keys, new).reshape(lam.shape)
        from dataclasses import replace

        self.params = replace(self.params, penalty=P1)
        if self.map is not None and self.map.n_pairs:
            R = self.mesh.radius
            self.kappa = hertz_kappa(effective_radius(R[self.map.fibril_plus], R[self.map.fibril_minus]), P1,
                                     self.E_star)

    # ------------------------------------------------------------------ geometry
    def set_onset(self, fraction: float) -> None:
        """Onset width of the penalty law as a fraction of the smallest radius (0: linear)."""
        if not fraction >= 0:
            raise ValueError(f"onset must be >= 0, got {fraction}")
        self.onset = float(fraction) * float(self.mesh.radius.min())

    def ends(self, x, sel=None):
        r = self.layout.as_nodal(np.asarray(x, float))[:, :3]
        npl, nmi = self.map.nodes_plus, self.map.nodes_minus
        sh = self.map.shift
        if sel is not None:
            npl, nmi = npl[sel], nmi[sel]
            sh = None if sh is None else sh[sel]
        if sh is not None:
            return r[npl[:, 0]], r[npl[:, 1]], r[nmi[:, 0]] + sh, r[nmi[:, 1]] + sh
        return r[npl[:, 0]], r[npl[:, 1]], r[nmi[:, 0]], r[nmi[:, 1]]

    def _shifted(self, r):
        """Positions and - chord end nodes for the compiled kernels: with shifts, the - ends
        index shifted copies appended to ``r``."""
        cmap = self.map
        if cmap.shift is None:
            return r, cmap.nodes_minus
        P = cmap.n_pairs
        ext = (r[cmap.nodes_minus] + cmap.shift[:, None, :]).reshape(-1, 3)
        return np.concatenate([r, ext]), r.shape[0] + np.arange(2 * P, dtype=cmap.nodes_minus.dtype).reshape(P, 2)

    def _compiled(self) -> bool:
        return not self.scalar and not self.curve and self.multipliers is None and use_numba()

    def geometry(self, x, sel=None):
        """``ChordGeometry`` of the map pairs ``sel`` (all by default), or for the curve the
        ``CurveGeometry`` of their oriented rows (``HalfPasses.rows(sel)``)."""
        if self.curve:
            rows = self.passes.rows(sel)
            r = self.layout.as_nodal(np.asarray(x, float))[:, :3]
            return self.passes.geometry(self.mesh.order, self.mesh.conn, r, self.row_gap_radius(rows), rows)
        cmap = self.map
        sp_, sm = cmap.s_plus, None if self.params.recompute_closest else cmap.s_minus
        gr = self.row_gap_radius()
        if sel is not None:
            sp_, gr = sp_[sel], gr[sel]
            sm = None if sm is None else sm[sel]
        return chord_geometry(*self.ends(x, sel), sp_, gr, sm)

    def gaps(self, x) -> np.ndarray:
        """Overlaps of the law (R+ + R- [+ lambda/P*] - rho) of every point of every row at
        ``x``, (rows, n_gp); -inf where a curve point is not owned."""
        cmap = self.map
        if self.curve:
            out = np.full((self.row_pair.size, self.params.n_gp), -np.inf)
            r, Y = self._curve_data(x)
            cand = self._candidates(r, Y)
            if cand.size and self.smooth:
                rows = self.passes.rows(cand)
                out[rows] = self.passes.smooth_gaps(r, self.row_gap_radius(rows), rows, use_numba(), Y)
            elif cand.size:
                geo = self.geometry(x, cand)
                out[self.passes.rows(cand)] = np.where(geo.owned, geo.g, -np.inf)
            return out
        sm = None if self.params.recompute_closest else cmap.s_minus
        if self.multipliers is None and use_numba():
            from ...kernels.contact import chord_gaps as compiled

            r, nminus = self._shifted(self.layout.as_nodal(np.asarray(x, float))[:, :3])
            return compiled(r, cmap.nodes_plus, nminus, cmap.s_plus, self.gap_radius, sm,
                            bool(self.params.recompute_closest))
        return chord_gaps(*self.ends(x), cmap.s_plus, self.row_gap_radius(), sm)

    def curve_candidates(self, x) -> np.ndarray:
        """Map pairs whose curves may overlap at ``x``: the distance of their chords minus the
        curves' deviation bounds (``chord_deviation``) below the largest gap radius of the
        pair (with its multipliers). The others have no active point, so the curve's
        Newton projection and forms run on these only."""
        return self._candidates(*self._curve_data(x))

    def _curve_data(self, x):
        """``(r, Y)``: the node positions at ``x`` and, on the smooth curve, the elements'
        Hermite data (None on the Lagrange curve), computed once per evaluation for the
        candidate test and the kernels."""
        r = self.layout.as_nodal(np.asarray(x, float))[:, :3]
        return r, (self.passes.stencil.control(r) if self.smooth else None)

    def _candidates(self, r, Y) -> np.ndarray:
        """``curve_candidates`` at positions ``r`` (and Hermite data ``Y``)."""
        cmap, mesh = self.map, self.mesh
        if self.smooth:
            X, dev = Y[:, :2], hermite_deviation(Y)  # the chords run between the end nodes
        else:
            X = r[mesh.conn]
            dev = chord_deviation(mesh.order, X)
        S = cmap.shifts
        d, _, _ = segment_distance(X[cmap.e_plus, 0], X[cmap.e_plus, -1], X[cmap.e_minus, 0] + S,
                                   X[cmap.e_minus, -1] + S)
        reach = self.gap_radius.copy()
        if self.multipliers is not None:
            lam = self.multipliers.reshape(-1, cmap.n_pairs, self.params.n_gp).max(axis=(0, 2))
            reach = reach + lam / float(self.params.penalty)
        return np.flatnonzero(d - dev[cmap.e_plus] - dev[cmap.e_minus] < reach)

    def _pairs_of_rows(self, flags) -> np.ndarray:
        """Map pairs with a True in any of their rows' (rows, G) ``flags``."""
        P = self.map.n_pairs
        any_row = flags.any(axis=1)
        return np.flatnonzero(any_row.reshape(-1, P).any(axis=0))

    def active_pairs(self, x) -> np.ndarray:
        """Indices of the map's pairs with at least one overlapping point at ``x``."""
        if self.map.n_pairs == 0:
            return np.zeros(0, dtype=np.int64)
        return self._pairs_of_rows(self.gaps(x) > 0.0)

    def active_points(self, x) -> np.ndarray:
        """Overlapping (for the curve: owned and overlapping) points of every map pair at
        ``x``, (P,) int32 (the curve's two half passes added)."""
        if self.map.n_pairs == 0:
            return np.zeros(0, np.int32)
        n = self.geometry(x).active.sum(axis=1)
        return n.reshape(-1, self.map.n_pairs).sum(axis=0).astype(np.int32)

    def energy(self, x) -> float:
        """Penalty energy ``Σ w φ(g)`` (N mm) of the map's points at ``x`` (with multipliers:
        of the shifted overlap, the potential of the residual at fixed multipliers); with friction
        at frozen loads (``FrictionTerm.freeze``) plus its incremental potential."""
        if self.map.n_pairs == 0:
            return 0.0
        e = penalty_energy(self.gaps(x), self.weight, self.params.penalty, self.onset)
        if self.friction is not None and self.friction.frozen:
            # the incremental potential of friction at frozen loads (rve.solvers.frictional)
            e = e + self.friction.potential(x)
        return e

    def conductance_law(self, g, field: str, kappa):
        """Conductance per unit length and its derivative in g, ``(k, dk/dg)``, of the
        field's contact law at the law's overlaps ``g``: ``c_C a(g)`` (Hertz width) or the
        Holm a-spot law ``c_H φ'(g)`` (line load φ'). Zero where g <= 0. With multipliers
        the width is ``line_load_width`` (Hertz's width of the line load)."""
        coef = self.law_coef[field]
        if self.holm:
            _, f1, f2 = penalty_law(g, self.params.penalty, self.onset)
            return coef * f1, coef * f2
        if self.augmented:
            a, da = self.line_load_width(g, kappa)
            return coef * a, coef * da
        a, da = hertz_width(np.where(g > 0.0, g, 0.0), kappa, self.g_eps)
        return coef * a, coef * da

    def line_load_width(self, g, kappa):
        """``(a, da/dg)``: Hertz's width ``sqrt(4 R* p / (pi E*))`` of the line load
        ``p = φ'(g)`` (with multipliers ``λ + P* g_true``), regularised in the load,
        ``a = c p / sqrt(p + load_eps)`` (``hertz_width`` of p), c = kappa / sqrt(P*). A
        function of the load alone, so the impenetrable limit's width does not depend on P*
        (for the linear law and ``g_eps = 0`` it is ``kappa sqrt(g)``, the penalty's)."""
        _, p, dp = penalty_law(g, self.params.penalty, self.onset)
        a, da = hertz_width(p, np.asarray(kappa, float) / np.sqrt(float(self.params.penalty)), self.load_eps)
        return a, da * dp

    # ------------------------------------------------------------------ forms
    def forms(self, x, w, jacobian: bool = True):
        """Local residuals and tangents of the active pairs: ``(act, R, Kx, Kw)``, ``act`` the
        active pair indices, ``R`` (len(act), m*nC) laid out as the pair dofs, ``Kx``/``Kw``
        (len(act), (m*nC)^2) (None without jacobian; Kw None for mechanics only); with
        friction, its forces on the same pairs are added."""
        if self._normal_cols is None:
            out = self._normal_forms(x, w, jacobian)
        else:
            out = self._widened_normal_forms(x, w, jacobian)
        if self.friction is None:
            return out
        return self.friction.add_to(x, *out, jacobian)

    def _widened_normal_forms(self, x, w, jacobian: bool):
        """``_normal_forms`` laid out in the widened ``comps`` (the director columns zero)."""
        nC, cols = self.nC, self._normal_cols
        act, R, Kx, Kw = self._normal_forms(x, w, jacobian)
        m, P = self.m, np.size(act)
        Rl = np.zeros((P, m, nC))
        Rl[:, :, cols] = np.asarray(R, float).reshape(P, m, cols.size)
        if not jacobian:
            return act, Rl.reshape(P, m * nC), None, None
        # the normal components are two runs, the centroids and the fields after the directors
        runs = [(slice(0, 3), slice(0, 3)), (slice(3, cols.size), slice(int(cols[3]) if cols.size > 3 else nC, nC))]
        out = []
        for A in (Kx, Kw):
            if A is None:
                out.append(None)
                continue
            A = np.asarray(A, float).reshape(P, m, cols.size, m, cols.size)
            B = np.zeros((P, m, nC, m, nC))
            for a_src, a_dst in runs:
                for b_src, b_dst in runs:
                    B[:, :, a_dst, :, b_dst] = A[:, :, a_src, :, b_src]
            out.append(B.reshape(P, (m * nC) ** 2))
        return act, Rl.reshape(P, m * nC), out[0], out[1]

    def _normal_forms(self, x, w, jacobian: bool):
        none = np.zeros(0, np.int64), np.zeros(0), None, None
        if self.map.n_pairs == 0:
            return none
        if self._compiled():
            return self._forms_compiled(x, jacobian)
        if self.curve:
            return self._forms_curve(x, w, jacobian)
        act = self.active_pairs(x)
        if act.size == 0:
            return none
        geo = self.geometry(x, act)
        wgt = self.weight[act]
        Rm, Km = penalty_forces(geo, wgt, self.params.penalty, jacobian, self.onset)
        if not self.scalar:  # mechanics only: the local unknowns are the 4 chord ends x 3
            return act, Rm, (Km.reshape(act.size, -1) if jacobian else None), None
        return self._with_scalars_chord(x, w, act, geo, wgt, Rm, Km, jacobian)

    def _with_scalars_chord(self, x, w, act, geo, wgt, Rm, Km, jacobian):
        m, nC, Pa = self.m, self.normal_comps.size, act.size
        Rl = np.zeros((Pa, m, nC))
        Kx = np.zeros((Pa, m, nC, m, nC)) if jacobian else None
        Kw = np.zeros((Pa, m, nC, m, nC)) if jacobian else None
        ep = self.endpos
        Rl[:, ep, 0:3] += Rm
        if jacobian:
            for k in range(4):
                for l in range(4):
                    Kx[:, ep[k], 0:3, ep[l], 0:3] += Km[:, k, :, l, :]
        wn = self.layout.as_nodal(np.asarray(w, float))
        conn = self.mesh.conn
        epair, mpair = self.map.e_plus[act], self.map.e_minus[act]
        for ic, f in enumerate(self.scalar):
            c = 3 + ic
            u = wn[:, self.layout.offset[f]]
            u_minus = u[conn[mpair]]
            if f in self.field_jumps and self.map.shift is not None:
                u_minus = u_minus + (self.map.shift[act] @ self.field_jumps[f])[:, None]
            if self.holm or self.augmented:
                width = self.conductance_law(geo.g, f, self.kappa[act][:, None])
                R, Ju, JX = scalar_jump(geo, self.mesh.order, u[conn[epair]], u_minus, wgt, 1.0,
                                        self.kappa[act], self.g_eps, jacobian, width=width)
            else:
                R, Ju, JX = scalar_jump(geo, self.mesh.order, u[conn[epair]], u_minus, wgt,
                                        self.law_coef[f], self.kappa[act], self.g_eps, jacobian)
            Rl[:, :, c] += R
            if jacobian:
                Kw[:, :, c, :, c] += Ju
                for k in range(4):
                    Kx[:, :, c, ep[k], 0:3] += JX[:, :, k, :]
        if not jacobian:
            return act, Rl, None, None
        return act, Rl, Kx.reshape(Pa, -1), Kw.reshape(Pa, -1)

    def _forms_curve(self, x, w, jacobian: bool):
        """``forms`` on the centroid curves: both half passes of every active pair, folded
        into the pair's (e+ nodes, e- nodes) layout."""
        ps = self.passes
        nn = ps.width(self.mesh.order + 1)
        r, Y = self._curve_data(x)
        cand = self._candidates(r, Y)
        if cand.size == 0:
            return np.zeros(0, np.int64), np.zeros(0), None, None
        if not self.scalar and use_numba():
            return self._forms_curve_compiled(r, Y, cand, jacobian)
        geo_c = self.geometry(x, cand)
        hit = geo_c.active.any(axis=1).reshape(2, -1).any(axis=0)
        act = cand[hit]
        if act.size == 0:
            return np.zeros(0, np.int64), np.zeros(0), None, None
        rows = ps.rows(act)
        geo = HalfPasses.take(geo_c, np.concatenate([np.flatnonzero(hit), cand.size + np.flatnonzero(hit)]))
        wgt = self.weight[rows]
        Rm, Km = curve_penalty_forces(geo, wgt, self.params.penalty, jacobian, self.onset)
        Rm = HalfPasses.fold(Rm, nn)
        Km = HalfPasses.fold(Km, nn, axes=(1, 3)) if jacobian else None
        Pa = act.size
        if not self.scalar:
            return act, Rm, (Km.reshape(Pa, -1) if jacobian else None), None
        m, nC = self.m, self.normal_comps.size
        Rl = np.zeros((Pa, m, nC))
        Rl[:, :, 0:3] = Rm
        Kx = np.zeros((Pa, m, nC, m, nC)) if jacobian else None
        Kw = np.zeros((Pa, m, nC, m, nC)) if jacobian else None
        if jacobian:
            Kx[:, :, 0:3, :, 0:3] = Km
        wn = self.layout.as_nodal(np.asarray(w, float))
        conn = self.mesh.conn
        kap = self.kappa[self.row_pair[rows]][:, None]
        for ic, f in enumerate(self.scalar):
            c = 3 + ic
            u = wn[:, self.layout.offset[f]]
            k, dk = self.conductance_law(geo.g, f, kap)
            ua, ub = u[ps.side_nodes(conn, ps.a_elem[rows])], u[ps.side_nodes(conn, ps.b_elem[rows])]
            if f in self.field_jumps:
                ua = ua + (ps.a_shift[rows] @ self.field_jumps[f])[:, None]
                ub = ub + (ps.b_shift[rows] @ self.field_jumps[f])[:, None]
            R, Ju, JX = curve_scalar_jump(geo, ua, ub, wgt * k,
                                          wgt * dk, jacobian)
            Rl[:, :, c] = HalfPasses.fold(R, nn)
            if jacobian:
                Kw[:, :, c, :, c] = HalfPasses.fold(Ju, nn, axes=(1, 2))
                Kx[:, :, c, :, 0:3] = HalfPasses.fold(JX, nn, axes=(1, 2))
        if not jacobian:
            return act, Rl, None, None
        return act, Rl, Kx.reshape(Pa, -1), Kw.reshape(Pa, -1)

    def _forms_curve_compiled(self, r, Y, cand, jacobian: bool):
        """Mechanics-only curve ``forms`` on the candidate pairs by the compiled kernel
        (``rve.kernels.contact_curve``), at positions ``r`` (Hermite data ``Y``)."""
        from ...kernels.contact_curve import curve_penalty_rows

        ps, order = self.passes, self.mesh.order
        rows = ps.rows(cand)
        gr = self.row_gap_radius(rows)
        if self.smooth:
            from ...kernels.contact_curve import smooth_penalty_rows

            Ha = hermite_basis(ps.s)[0]
            active, Ra, Ka = smooth_penalty_rows(Ha, END_SNAP, *ps.smooth_inputs(r, rows, Y), gr, self.weight[rows],
                                                 float(self.params.penalty), self.onset, jacobian)
            act = cand[active]
            if act.size == 0:
                return np.zeros(0, np.int64), np.zeros(0), None, None
            return act, Ra, (Ka.reshape(act.size, -1) if jacobian else None), None
        Xa, Xb, has_next, t_next, has_prev = ps.inputs(order, self.mesh.conn, r, rows)
        active, Rr, Kr = curve_penalty_rows(order, lagrange_monomials(order), curve_basis(order, ps.s)[0], END_SNAP,
                                            Xa, Xb, t_next, has_next, has_prev, ps.s, gr, self.weight[rows],
                                            float(self.params.penalty), self.onset, jacobian)
        return self._compiled_rows(cand, active, Rr, Kr, jacobian)

    @staticmethod
    def _compiled_rows(cand, active, Rr, Kr, jacobian: bool):
        """``forms``' return of a compiled curve kernel's pairs ``cand`` (flags ``active``)."""
        act = cand[active]
        if act.size == 0:
            return np.zeros(0, np.int64), np.zeros(0), None, None
        if not jacobian:
            return act, Rr[active], None, None
        return act, Rr[active], Kr[active].reshape(act.size, -1), None

    def _forms_compiled(self, x, jacobian: bool):
        """``forms`` of a mechanics-only term by the compiled kernel (rve.kernels.contact)."""
        from ...kernels.contact import penalty_forms as compiled

        cmap = self.map
        r, nminus = self._shifted(self.layout.as_nodal(np.asarray(x, float))[:, :3])
        rec = bool(self.params.recompute_closest)
        act, Rm, Km = compiled(r, cmap.nodes_plus, nminus, cmap.s_plus, self.gap_radius,
                               None if rec else cmap.s_minus, rec, self.weight, float(self.params.penalty),
                               self.onset, jacobian)
        if act.size == 0:
            return np.zeros(0, np.int64), np.zeros(0), None, None
        return act, Rm, (Km.reshape(act.size, -1) if jacobian else None), None

    # ------------------------------------------------------------------ diagnostics
    def contact_state(self, x) -> dict:
        """Overlap statistics of the current map at ``x``.

        ``max_overlap`` (mm) and ``max_overlap_over_R`` (true overlap / min(R+, R-)),
        ``pairs``, ``active_pairs``, ``active_points``, ``max_width`` (Hertz a of the line
        load, mm), ``total_normal_force`` (N; sum over points of w φ'(g), i.e. w P* g for
        the linear law; with multipliers g is the shifted overlap, so w φ' is the line load)."""
        out = {"pairs": int(self.map.n_pairs), "active_pairs": 0, "active_points": 0, "max_overlap": 0.0,
               "max_overlap_over_R": 0.0, "max_width": 0.0, "total_normal_force": 0.0}
        if self.map.n_pairs == 0:
            return out
        g = self.gaps(x)
        active = g > 0.0
        g = np.where(active, g, 0.0)
        pen = self.penetration(x)
        pen = np.where(active, pen, 0.0)
        R = self.mesh.radius
        rmin = np.minimum(R[self.map.fibril_plus], R[self.map.fibril_minus])[self.row_pair]
        kap = self.kappa[self.row_pair][:, None]
        a = self.line_load_width(g, kap)[0] if self.augmented else hertz_width(g, kap, self.g_eps)[0]
        w = np.broadcast_to(np.asarray(self.weight, float).reshape(g.shape[0], -1), g.shape)
        out.update(active_pairs=int(self._pairs_of_rows(active).size), active_points=int(active.sum()),
                   max_overlap=float(max(pen.max(), 0.0)), max_overlap_over_R=float(max((pen / rmin[:, None]).max(), 0.0)),
                   max_width=float(a.max()),
                   total_normal_force=float((w * penalty_law(g, self.params.penalty, self.onset)[1]).sum()))
        return out

    def curve_heat_transfer_block(self, x, act, coef: float):
        """``(loc (Pa, m), Ju (Pa, m, m))`` on the curve geometries: the local nodes of the map
        pairs ``act`` (e+ side, then e- side: each side's element nodes, or its stencil on the
        smooth curve) and the Jacobian of ``sum_points [[dT]] coef a(g) [[T]]`` (the width
        law with the conductance ``coef``) in their nodal values, both half passes folded.
        The term is linear in the field, so ``Ju`` is its whole matrix: the same expression
        as ``curve_scalar_jump``'s ``Ju`` without its residual and its dX tangents."""
        if not self.curve:
            raise ValueError("curve_heat_transfer_block needs geometry 'curve' or 'smooth'")
        ps, conn = self.passes, self.mesh.conn
        act = np.asarray(act, np.int64)
        rows = ps.rows(act)
        geo = self.geometry(x, act)
        a, _ = hertz_width(np.where(geo.active, geo.g, 0.0), self.kappa[self.row_pair[rows]][:, None], self.g_eps)
        k = np.where(geo.active, self.weight[rows] * float(coef) * a, 0.0)
        phi = np.concatenate([geo.Na, -geo.Nb], axis=-1)  # (2Pa, G, 2 width)
        Ju = HalfPasses.fold(np.einsum("pgA,pgB->pAB", k[..., None] * phi, phi), ps.width(conn.shape[1]),
                             axes=(1, 2))
        loc = np.concatenate([ps.side_nodes(conn, self.map.e_plus[act]),
                              ps.side_nodes(conn, self.map.e_minus[act])], axis=1)
        return loc, Ju

    def conductance_by_pair(self, x, field: str = "V") -> dict:
        """Discrete contact conductance between every pair of fibrils in contact:
        ``{(f+, f-): sum_points w k(g)}`` (A/V for V, W/K for T; k the field's law)."""
        out: dict = {}
        if self.map.n_pairs == 0:
            return out
        geo = self.geometry(x)
        g = np.where(geo.active, geo.g, 0.0)
        kap = self.kappa[self.row_pair][:, None]
        w = np.broadcast_to(np.asarray(self.weight, float).reshape(g.shape[0], -1), g.shape)
        if self.holm:
            Gp = (w * self.conductance_law(g, field, kap)[0]).sum(axis=1)
        else:
            a = self.line_load_width(g, kap)[0] if self.augmented else hertz_width(g, kap, self.g_eps)[0]
            Gp = (w * self.law_coef[field] * a).sum(axis=1)
        nf = self.mesh.n_fibrils
        pr = self.row_pair
        key = self.map.fibril_plus[pr].astype(np.int64) * nf + self.map.fibril_minus[pr]
        uk, inv = np.unique(key, return_inverse=True)
        tot = np.bincount(inv, weights=Gp, minlength=uk.size)
        return {(int(k // nf), int(k % nf)): float(v) for k, v in zip(uk, tot) if v > 0}
