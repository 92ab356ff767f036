"""The model with contact between fibrils: a ``BeamModel``'s terms plus the contact term,
assembled on one union sparsity pattern (thesis §4.3, §4.4.6, Algorithm 5.1; choices and
figures: docs/contact.md).

Contract
--------
``ContactSystem(base, params, x=None)``: ``base`` a ``BeamModel`` (its ``assembler`` is the
element group), ``params`` a ``ContactParams`` (the ``ContactTerm``'s law); implements the
``DynamicSystem`` protocol:

* ``rebuild(x)`` rebuilds the contact map (the term's pairs) and the union CSR structure of
  the element pattern and every candidate pair's blocks (``rve.fem.assembly.UnionPattern``).
  Until the next ``rebuild``, ``evaluate`` returns ``Fx``, ``Fw`` and ``mass()`` returns
  ``M`` on that one structure, so the solvers' restriction fast path applies. ``rebuild``
  changes the structure (a solver that cached ``mass()`` must be restarted after it) unless
  the pair connectivity is unchanged: then the union, its index arrays and ``mass()`` are
  kept (``assembler.reused`` counts those rebuilds).
* Between rebuilds the *pairs* are fixed; on each pair the closest points are recomputed at
  every evaluation (``params.recompute_closest``, default) with their tangent, or frozen.
* ``evaluate(x, w, t, jacobian)``: the base terms + penalty + ``h_C a [[T]]`` (T and
  ``heat_transfer > 0``) + ``sigma_C a [[V]]`` (V and ``conductance > 0``), exact tangents
  (``rve.model.assembler.ContactAssembler``).
* Options of ``params`` (docs/contact.md): ``geometry="curve"`` (contact on the elements'
  Lagrange curves, both half passes), ``enforcement="augmented_lagrangian"``
  (``max_penetration``, ``update_multipliers``, ``multipliers``; the Uzawa loop around a
  solve is ``rve.solvers.augmented``), ``conductance_law="holm"``.
* ``energy(x)``: beam strain energy (``beam_strain_energy``) + penalty energy
  (``contact_energy``) of a mechanics-only system; ``F(x, 0)`` is its exact gradient.
* Diagnostics: ``gaps``, ``active_pairs``, ``active_points``, ``geometry``, ``contact_state``,
  ``fibril_contact_forces``, ``contact_conductance``, ``max_displacement_since_rebuild``;
  ``onset`` / ``set_onset``, ``map``; ``stats`` (counts and wall times).

Everything else (``mesh``, ``layout``, ``nodal``, ``end_currents``, ...) is the base model's.
"""
from __future__ import annotations

import time

import numpy as np

from ..physics.contact_forms import effective_modulus
from .assembler import ContactAssembler
from .terms.contact import ContactParams, ContactTerm
from .terms.elasticity import beam_strain_energy

__all__ = ["ContactParams", "ContactSystem"]


def _timer(stats, key, t0):
    stats[key] = stats.get(key, 0.0) + (time.perf_counter() - t0)


class ContactSystem:
    def __init__(self, base, params: ContactParams, x=None):
        self.base = base
        self.params = params
        self.mesh = base.mesh
        self.layout = base.layout
        self.n = base.n
        self.mech = base.mech
        mat = getattr(base, "material", None)
        if params.youngs_modulus is not None:
            E_star = float(params.youngs_modulus)
        elif mat is not None:
            E_star = float(effective_modulus(mat.youngs_modulus, mat.youngs_modulus,
                                             mat.poisson_ratio, mat.poisson_ratio))
        else:
            raise ValueError("ContactParams.youngs_modulus is needed when the base model has no material")
        cond = (float(getattr(mat, "electrical_conductivity", 0.0)), float(getattr(mat, "thermal_conductivity", 0.0))) \
            if mat is not None else (0.0, 0.0)
        self.term = ContactTerm(self.mesh, self.layout, params, E_star, *cond)
        self.E_star = self.term.E_star
        self.fields = [f for f in ("T", "V") if self.layout.has(f)]
        self.use_T, self.use_V, self.scalar = self.term.use_T, self.term.use_V, self.term.scalar
        self.comps, self.nC = self.term.comps, self.term.nC
        self.g_eps, self.cutoff = self.term.g_eps, self.term.cutoff
        self.assembler = ContactAssembler(base.assembler, self.term)
        self.stats = {"rebuilds": 0, "evaluations": 0, "rebuild_s": 0.0, "contact_s": 0.0, "base_s": 0.0}
        self.rebuild(np.zeros(self.n) if x is None else x)

    # ------------------------------------------------------------------ forwarding
    def __getattr__(self, name):
        if name in ("base", "term"):  # not yet set (during construction)
            raise AttributeError(name)
        return getattr(self.base, name)

    @property
    def map(self):
        return self.term.map

    @property
    def onset(self) -> float:
        return self.term.onset

    def nodal(self, u):
        return self.layout.as_nodal(u)

    def mass(self):
        return self.assembler.mass(self.base.mass())

    def constraints(self, t):
        return self.base.constraints(t)

    def admissible(self, x) -> bool:
        return self.base.admissible(x)

    # ------------------------------------------------------------------ map + pattern
    def rebuild(self, x):
        """Rebuild the contact map at state ``x`` and the union sparsity pattern."""
        t0 = time.perf_counter()
        self.assembler.rebuild(x)
        self._x_rebuild = np.array(self.nodal(np.asarray(x, float))[:, :3], copy=True)
        self.mass()
        self.stats["rebuilds"] += 1
        _timer(self.stats, "rebuild_s", t0)
        return self.term.map

    def set_periodic(self, images=None, wrap=None, x=None, field_jumps=None, lattice=None) -> None:
        """Periodic images of the contact search (``ContactTerm.set_periodic``); with ``x``
        the map and the union structure are rebuilt at once."""
        self.term.set_periodic(images, wrap, field_jumps, lattice=lattice)
        if x is not None:
            self.rebuild(x)

    # ------------------------------------------------------------------ contact terms
    def set_onset(self, fraction: float) -> None:
        """Onset width of the penalty law as a fraction of the smallest radius (0: linear)."""
        self.term.set_onset(fraction)

    def geometry(self, x, sel=None):
        """``ChordGeometry`` of the map's pairs (or pairs ``sel``) at ``x``; with ``geometry:
        curve`` the ``CurveGeometry`` of their oriented rows."""
        return self.term.geometry(x, sel)


    def gaps(self, x) -> np.ndarray:
        """Overlaps g (n_pairs, n_gp) of every point of the map at ``x`` (no tangent data)."""
        return self.term.gaps(x)

    def active_pairs(self, x) -> np.ndarray:
        """Indices of the map's pairs with at least one overlapping point at ``x``."""
        return self.term.active_pairs(x)

    def active_points(self, x) -> np.ndarray:
        """Overlapping points of every map pair at ``x``, (n_pairs,) int32."""
        return self.term.active_points(x)

    def contact_energy(self, x) -> float:
        """Penalty energy ``Σ w φ(g)`` (N mm) of the map's points at ``x``."""
        return self.term.energy(x)

    def energy(self, x) -> float:
        """Total potential (N mm) of a mechanics-only system: beam strain energy + penalty
        energy; +inf where det F <= 0 somewhere. Its gradient is ``F(x, 0, t)``."""
        return beam_strain_energy(self.base, x) + self.contact_energy(x)

    def contact_terms(self, x, w, jacobian: bool = True):
        """The contact term alone: ``(F (n,), act, Kx, Kw)``, ``act`` the active pairs, ``Kx``/
        ``Kw`` their local entries laid out as the union's ``slots[act]``."""
        act, R, Kx, Kw = self.term.forms(x, w, jacobian)
        F = np.bincount(self.assembler.union.gdofs[act].ravel(), weights=R.ravel(), minlength=self.n) \
            if act.size else np.zeros(self.n)
        return F, act, Kx, Kw

    # ------------------------------------------------------------------ augmented Lagrangian
    @property
    def augmented(self) -> bool:
        """True when impenetrability is enforced by multipliers (``enforcement:
        augmented_lagrangian``; ``rve.solvers.augmented`` drives their updates)."""
        return self.term.augmented

    @property
    def multipliers(self):
        """Contact multipliers (rows, n_gp) (line loads, N/mm) or None for the penalty."""
        return self.term.multipliers

    def max_penetration(self, x) -> float:
        """Largest true overlap over the radius at ``x`` (g / min(R+, R-), 0 if none)."""
        return self.term.max_penetration(x)

    def update_multipliers(self, x, relaxation: float = 1.0) -> None:
        """One Uzawa update of the multipliers at ``x`` (``ContactTerm.update_multipliers``,
        under-relaxed by ``relaxation``); the structure is unchanged."""
        self.term.update_multipliers(x, relaxation)

    @property
    def penalty(self) -> float:
        """The contact law's current P* (the Uzawa loop may raise it; ``set_penalty``)."""
        return float(self.term.params.penalty)

    def set_penalty(self, penalty: float, x=None) -> None:
        """P* of the contact law (``ContactTerm.set_penalty``: with ``x`` the line loads at
        ``x`` are kept); the structure is unchanged."""
        self.term.set_penalty(penalty, x)

    # ------------------------------------------------------------------ DynamicSystem
    def evaluate(self, x, w, t, jacobian: bool = True):
        self.stats["evaluations"] += 1
        t0 = time.perf_counter()
        self.base.stats["assemblies"] += 1
        box = {}
        out = self.assembler.evaluate(x, w, t, jacobian, self.base.row_scale,
                                      on_elements=lambda s: box.setdefault("t", time.perf_counter()))
        t1 = box.get("t", t0)
        self.stats["base_s"] += t1 - t0
        _timer(self.stats, "contact_s", t1)
        return out

    # ------------------------------------------------------------------ diagnostics
    def max_displacement_since_rebuild(self, x) -> float:
        r = self.nodal(np.asarray(x, float))[:, :3]
        return float(np.sqrt(((r - self._x_rebuild) ** 2).sum(axis=1)).max())

    def contact_state(self, x) -> dict:
        """Overlap statistics of the current map at ``x`` (``ContactTerm.contact_state``)."""
        return self.term.contact_state(x)

    def fibril_contact_forces(self, x) -> np.ndarray:
        """Contact force acting on every fibril (N), (n_fibrils, 3): minus the contact
        residual summed over the fibril's centroid dofs."""
        Fc, _, _, _ = self.contact_terms(x, np.zeros(self.n), jacobian=False)
        rn = self.nodal(Fc)[:, :3]
        out = np.zeros((self.mesh.n_fibrils, 3))
        np.add.at(out, self.mesh.node_fibril, -rn)
        return out

    def contact_conductance(self, x, field: str = "V") -> dict:
        """Discrete contact conductance between every pair of fibrils in contact:
        ``{(f+, f-): sum_points w c_C a(g)}`` (A/V for V, W/K for T)."""
        return self.term.conductance_by_pair(x, field)
