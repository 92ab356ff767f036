"""One assembler for the model as a sum of terms (docs/coupled_fields.md "How the model is
assembled (terms)"; contact pairs: docs/contact.md).

Contract
--------
``ElementState(basis, layout, x, w, t)``: the element arrays of a state, computed once and
only when a term asks: ``U`` (E, nn*3, 3) positions, ``Uv`` velocities, ``T`` / ``V``
(E, nn) nodal T and V (None without the field), ``t``.

``Assembler(layout, pattern, basis, terms)`` (terms: see ``rve.model.terms.base``):

* ``mass()``: the terms' mass blocks summed into one CSR matrix on the element pattern;
* ``evaluate(x, w, t, jacobian, scale=None)`` -> ``Evaluation(F, Fx, Fw, fw_constant)``:
  per field block the terms' element residuals and tangents are added **in term order**,
  scattered once through the pattern (one bincount each), then the constant operators
  (``F += C w``), then the assembled-array terms (circuits), then the row scale. ``Fx`` and
  ``Fw`` share the pattern's CSR structure; when no term has element w-blocks ``Fw`` is the
  constant operator itself (or an empty matrix) and ``fw_constant`` is True.
* ``scale``: a ``RowScale`` (rows of F, Fx, Fw multiplied by s; see ``BeamModel.with_row_scale``).

``ContactAssembler(elements, term)``: the element group of ``elements`` (an ``Assembler``)
and the pair group of a contact term on the union CSR structure of the two
(``rve.fem.assembly.UnionPattern``); ``rebuild(x)`` rebuilds the pairs and the union (the
union object, its index arrays and the union copies of M and of a constant Fw are kept
when the pair connectivity did not change: ``reused`` counts those rebuilds),
``evaluate`` adds the pair group to the element group's evaluation: F = F_elements + F_pairs,
union data = pair bincount + element data (two partial sums, so the order of every
floating-point sum is that of the element and pair groups assembled apart).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ..fem.assembly import UnionPattern

__all__ = ["ElementState", "Evaluation", "RowScale", "Assembler", "ContactAssembler"]

_SIZE = {"mech": 9, "T": 1, "V": 1}


class ElementState:
    def __init__(self, basis, layout, x, w, t):
        self.basis, self.layout = basis, layout
        self.x, self.w, self.t = x, w, t

    @cached_property
    def U(self):
        return self.basis.element_values(self.layout.as_nodal(self.x))

    @cached_property
    def Uv(self):
        return self.basis.element_values(self.layout.as_nodal(self.w))

    def _scalar(self, field):
        if not self.layout.has(field):
            return None
        return self.layout.as_nodal(self.w)[:, self.layout.offset[field]][self.basis.mesh.conn]

    @cached_property
    def T(self):
        return self._scalar("T")

    @cached_property
    def V(self):
        return self._scalar("V")


@dataclass
class Evaluation:
    F: np.ndarray
    Fx: object = None
    Fw: object = None
    fw_constant: bool = False


class RowScale:
    """Row scale s of a model on its pattern: ``data`` = s of every pattern entry's row."""

    def __init__(self, s, pattern):
        self.s = np.asarray(s, float).copy()
        self.data = self.s[np.repeat(np.arange(pattern.n), np.diff(pattern.indptr))]
        self._scaled = {}

    def matrix(self, A):
        """S A for a constant matrix A (cached by identity: the scaled operator is built once)."""
        hit = self._scaled.get(id(A))
        if hit is None or hit[0] is not A:
            hit = self._scaled[id(A)] = (A, (sp.diags(self.s) @ A).tocsr())
        return hit[1]


class Assembler:
    def __init__(self, layout, pattern, basis, terms):
        self.layout, self.pattern, self.basis = layout, pattern, basis
        self.terms = list(terms)
        for term in self.terms:
            term.bind(pattern)
        self.operators = [C for C in (term.operator() for term in self.terms) if C is not None]
        self.nn = basis.nn
        self.single = layout.fields == ("mech",)

    def term(self, name):
        """The term called ``name`` (KeyError if the model has none)."""
        for t in self.terms:
            if t.name == name:
                return t
        raise KeyError(f"the model has no {name!r} term (terms: {[t.name for t in self.terms]})")

    # ------------------------------------------------------------------ element sums
    def _block_vector(self, blocks):
        E, nn = self.basis.mesh.n_elements, self.nn
        if self.single:
            R = blocks.get("mech")
            return R.reshape(E, nn, 9) if R is not None else np.zeros((E, nn, 9))
        Re = np.zeros((E, nn, self.layout.block))
        for f, R in blocks.items():
            o = self.layout.offset[f]
            Re[:, :, o:o + _SIZE[f]] = R
        return Re

    def _block_matrix(self, blocks):
        E, nn, b = self.basis.mesh.n_elements, self.nn, self.layout.block
        if self.single and list(blocks) == [("mech", "mech")]:
            return blocks[("mech", "mech")]
        K = np.zeros((E, nn, b, nn, b))
        for (r, c), B in blocks.items():
            ro, co = self.layout.offset[r], self.layout.offset[c]
            K[:, :, ro:ro + _SIZE[r], :, co:co + _SIZE[c]] = B
        return K

    def element_sums(self, state, jacobian: bool):
        """(R, Kx, Kw) per field block, summed over the terms in order (Kx/Kw None if empty)."""
        E, nn = self.basis.mesh.n_elements, self.nn
        R, Kx, Kw = {}, {}, {}
        for term in self.terms:
            r, k = term.forms(state, jacobian)
            for f, blk in r.items():
                blk = blk.reshape(E, nn, _SIZE[f])
                R[f] = blk if f not in R else R[f] + blk
            for (row, col, d), blk in k.items():
                acc = Kx if d == "x" else Kw
                blk = blk.reshape(E, nn, _SIZE[row], nn, _SIZE[col])
                acc[row, col] = blk if (row, col) not in acc else acc[row, col] + blk
        return (self._block_vector(R), self._block_matrix(Kx) if Kx else None,
                self._block_matrix(Kw) if Kw else None)

    # ------------------------------------------------------------------ global arrays
    def mass(self):
        blocks = {}
        E, nn = self.basis.mesh.n_elements, self.nn
        for term in self.terms:
            for (row, col), blk in term.mass_blocks().items():
                blk = blk.reshape(E, nn, _SIZE[row], nn, _SIZE[col])
                blocks[row, col] = blk if (row, col) not in blocks else blocks[row, col] + blk
        return self.pattern.assemble_matrix(self._block_matrix(blocks))

    def evaluate(self, x, w, t, jacobian: bool = True, scale: RowScale | None = None) -> Evaluation:
        state = ElementState(self.basis, self.layout, x, w, t)
        Re, Kx, Kw = self.element_sums(state, jacobian)
        F = self.pattern.assemble_vector(Re)
        for C in self.operators:
            F = F + C @ w
        for term in self.terms:
            term.add_to_residual(F, w)
        if scale is not None:
            F *= scale.s
        if not jacobian:
            return Evaluation(F)
        pat = self.pattern
        Fx = pat.assemble_csr(Kx) if Kx is not None else pat.assemble_csr(np.zeros(pat.slot.size))
        constant = Kw is None
        if not constant:
            Fw = pat.assemble_csr(Kw)
            for C in self.operators:
                Fw = (Fw + C).tocsr()
        elif len(self.operators) == 1:
            Fw = self.operators[0]
        elif self.operators:
            Fw = sum(self.operators[1:], self.operators[0]).tocsr()
        else:
            Fw = sp.csr_matrix((pat.n, pat.n))
        for term in self.terms:
            term.add_to_tangent(Fx, Fw)
        if scale is not None:
            Fx.data *= scale.data
            if not constant:
                Fw.data *= scale.data
            elif Fw.nnz:
                Fw = scale.matrix(Fw)
        return Evaluation(F, Fx, Fw, constant)


class ContactAssembler:
    def __init__(self, elements: Assembler, term):
        self.elements = elements
        self.term = term
        self.union: UnionPattern | None = None
        self._fw_cache = None
        self._M = None
        self._local = self._comps = None
        #: rebuilds that kept the union structure (unchanged pair connectivity)
        self.reused = 0

    @property
    def n(self):
        return self.elements.pattern.n

    def rebuild(self, x) -> bool:
        """Rebuild the contact term's pairs at ``x`` and the union structure; the union (and
        the matrices cached on it) is kept when the pair connectivity is unchanged, so every
        matrix keeps the very same index arrays (a solver's analysis of the pattern stays
        valid). Returns True when the structure changed."""
        local = self.term.rebuild(x)
        comps = np.asarray(self.term.comps)
        u = self.union
        if (u is not None and self._local is not None and self._local.shape == local.shape
                and np.array_equal(self._local, local) and np.array_equal(self._comps, comps)):
            self.reused += 1
            return False
        self._local, self._comps = np.array(local, copy=True), comps.copy()
        self.union = UnionPattern(self.elements.pattern, local, comps)
        self.union.restrict(self._filled(self.union))
        self._fw_cache = None
        self._M = None
        return True

    def _filled(self, union):
        """The union entries the forms can fill (bool over the union data), or None (all):
        the elements' and those of the pairs' ``local_sparsity`` (the contact term's)."""
        local = self.term.local_sparsity()
        if local is None or union.slots.size == 0:
            return None
        keep = np.zeros(union.nnz, bool)
        keep[union.base_map] = True
        keep[union.slots[:, np.asarray(local, bool).ravel()].ravel()] = True
        return keep

    def mass(self, M_elements):
        if self._M is None or self._M[0] is not M_elements:
            self._M = (M_elements, self.union.csr(self.union.data_of(M_elements)))
        return self._M[1]

    def evaluate(self, x, w, t, jacobian: bool = True, scale: RowScale | None = None, on_elements=None):
        """F, Fx, Fw on the union; ``on_elements`` (optional) is called with the elements'
        wall time (the contact system's stats)."""
        import time

        t0 = time.perf_counter()
        ev = self.elements.evaluate(x, w, t, jacobian, scale)
        if on_elements is not None:
            on_elements(t0)
        u = self.union
        act, Rl, Kx, Kw = self.term.forms(x, w, jacobian)
        Fc = np.bincount(u.gdofs[act].ravel(), weights=Rl.ravel(), minlength=self.n) if act.size \
            else np.zeros(self.n)
        F = np.asarray(ev.F, float) + Fc
        if not jacobian:
            return F, None, None
        if act.size:
            dx = u.pair_data(act, Kx, ev.Fx)
        else:
            dx = u.data_of(ev.Fx)
        if ev.fw_constant and Kw is None:
            # a constant Fw (the damping operator, or none): its union copy is kept until
            # the next rebuild (consumers do not modify matrices in place)
            hit = self._fw_cache is not None and (
                self._fw_cache[0] is ev.Fw or (ev.Fw.nnz == 0 and self._fw_cache[0].nnz == 0))
            if not hit:
                self._fw_cache = (ev.Fw, u.csr(u.data_of(ev.Fw)))
            Fw = self._fw_cache[1]
        elif Kw is not None and act.size:
            # one compiled pass (UnionPattern.pair_data) where Fw lies on the base pattern: the
            # same bits as data_of(Fw) + bincount (0 + a = a, and a + b = b + a exactly)
            Fw = u.csr(u.pair_data(act, Kw, ev.Fw))
        else:
            Fw = u.csr(u.data_of(ev.Fw))
        return F, u.csr(dx), Fw
