"""The interface between a discretised physical model and the time/static solvers.

Contract
--------
A ``DynamicSystem`` is the semi-discrete system of thesis §6.2.2 written in one mixed
vector ``w`` of size ``n`` (velocities of the mechanical dofs, temperatures, potentials)
and a companion vector ``x`` of the *same* size and layout::

    M dw/dt + F(x, w, t) = 0,        dx/dt = w   on the mechanical dofs (``mech``).

* ``n`` -- number of dofs of ``w`` (and of ``x``).
* ``mech`` -- bool array (n,): True where ``w`` is the velocity of ``x``. At the other dofs
  ``x`` is an unused placeholder (the "null" fields of §6.2.2) that must stay 0; the
  solvers never write anything but 0-increments there.
* ``mass()`` -- the constant sparse mass matrix M (n x n). Rows of massless (algebraic,
  quasistatic) dofs such as the electric potential V are entirely zero; such a dof is an
  index-1 algebraic unknown whose equation ``F_V(x, w, t) = 0`` must be solvable for it
  (``dF_V/dV`` nonsingular).
* ``evaluate(x, w, t, jacobian=True)`` -> ``(F, Fx, Fw)``: the residual F (ndarray, n)
  and the exact partial Jacobians ``Fx = dF/dx`` and ``Fw = dF/dw`` as scipy sparse
  matrices (n x n); both are ``None`` when ``jacobian=False``. Columns of ``Fx`` at
  non-mechanical dofs are ignored by the solvers.
* ``constraints(t)`` -> ``(idx, values)``: Dirichlet conditions on ``w`` at time ``t``
  (int array, float array). At a mechanical dof the value is a prescribed *velocity*
  (``x`` follows by integrating it with the same Runge-Kutta rule); at a temperature or
  potential dof it is the prescribed value itself. The rows of F at constrained dofs are
  never used (reactions can be read from them by the caller).
* ``admissible(x)`` -> bool: False when ``x`` is physically inadmissible (det F <= 0 at a
  quadrature point); Newton steps and Runge-Kutta stages into such states are rejected.
  May always return True.

The solvers only call these members; they never mutate the system.

``ContactRelaxable`` is the larger protocol the energy minimiser and the relaxation
driver (``rve.solvers.minimize``, ``rve.solvers.relaxation``; docs/relaxation.md) need
of a system with a contact map that is rebuilt as the fibrils move (the model with a
contact term, e.g. ``ContactSystem``): a ``DynamicSystem`` plus

* ``layout`` -- its ``DofLayout`` (``layout.dofs("r")``: the centroid dofs, whose motion
  per step is capped);
* ``params.margin`` -- the search margin of the contact map (mm): a map built at ``x0``
  holds every pair that can touch while no centroid moved more than half of it;
* ``rebuild(x)`` -- rebuild the contact map at ``x`` (changes the sparsity structure of
  the Jacobians; the residual and energy at ``x`` do not change under the guard);
  ``max_displacement_since_rebuild(x)`` -- the largest centroid motion since then;
* ``energy(x)`` -- the potential whose gradient is the static residual ``F(x, 0, t)``;
* ``set_onset(fraction)`` -- the penalty onset width (fraction of R) of the contact law;
* ``map`` (``n_pairs``, ``e_plus``, ``e_minus``), ``active_pairs(x)`` (indices of the
  pairs in contact) and ``contact_state(x)`` (dict with ``pairs``, ``active_pairs``,
  ``max_overlap_over_R``) -- for the records and the check that a final rebuild finds no
  pair the map missed.
"""
from __future__ import annotations

from typing import Protocol, Tuple, runtime_checkable

import numpy as np
import scipy.sparse as sp

from ..kernels import index_kernels
from .backends.base import same_structure as _same_structure

__all__ = ["DynamicSystem", "ContactRelaxable", "DeadLoad", "FreeDofs", "friction_of", "massless_dofs", "mech_mask", "scale_columns"]


@runtime_checkable
class DynamicSystem(Protocol):
    """Semi-discrete system ``M dw/dt + F(x, w, t) = 0``, ``dx/dt = w`` on ``mech`` dofs.

    See the module docstring for the full contract.
    """

    n: int
    mech: np.ndarray

    def mass(self) -> sp.spmatrix:
        """Constant mass matrix M (n x n); zero rows at massless (algebraic) dofs."""
        ...

    def evaluate(self, x: np.ndarray, w: np.ndarray, t: float, jacobian: bool = True
                 ) -> Tuple[np.ndarray, "sp.spmatrix | None", "sp.spmatrix | None"]:
        """Return ``(F, dF/dx, dF/dw)``; the Jacobians are None if ``jacobian=False``."""
        ...

    def constraints(self, t: float) -> Tuple[np.ndarray, np.ndarray]:
        """Dirichlet data on ``w`` at time t: ``(idx, values)`` (velocity on mech dofs)."""
        ...

    def admissible(self, x: np.ndarray) -> bool:
        """False if ``x`` is inadmissible (det F <= 0 somewhere)."""
        ...


@runtime_checkable
class ContactRelaxable(DynamicSystem, Protocol):
    """A ``DynamicSystem`` with a rebuildable contact map and a potential energy; see the
    module docstring for the members the minimiser and the relaxation driver use."""

    layout: object
    params: object
    map: object

    def rebuild(self, x: np.ndarray) -> None:
        ...

    def max_displacement_since_rebuild(self, x: np.ndarray) -> float:
        ...

    def energy(self, x: np.ndarray) -> float:
        ...

    def set_onset(self, fraction: float) -> None:
        ...

    def active_pairs(self, x: np.ndarray) -> np.ndarray:
        ...

    def contact_state(self, x: np.ndarray) -> dict:
        ...


def mech_mask(system) -> np.ndarray:
    """The ``mech`` attribute as a bool array of length ``n``."""
    m = np.asarray(system.mech, dtype=bool)
    if m.shape != (system.n,):
        raise ValueError(f"system.mech has shape {m.shape}, expected ({system.n},)")
    return m


def massless_dofs(M) -> np.ndarray:
    """Bool mask of the rows of ``M`` that are identically zero (algebraic dofs)."""
    M = sp.csr_matrix(M)
    rowabs = np.asarray(abs(M).sum(axis=1)).ravel()
    return rowabs == 0.0


class FreeDofs:
    """Restriction of vectors and sparse matrices to the unconstrained dofs.

    Built once per constraint set (``idx``) and reused: ``free`` is the sorted index
    array of unconstrained dofs, ``matrix(A)`` extracts ``A[free][:, free]`` in one
    O(nnz) pass through COO (no fancy CSR indexing), returned in CSC form ready for the
    direct solver.
    """

    def __init__(self, n: int, constrained):
        self.n = int(n)
        self.constrained = np.unique(np.asarray(constrained, dtype=np.int64).ravel())
        is_free = np.ones(self.n, dtype=bool)
        is_free[self.constrained] = False
        self.is_free = is_free
        self.free = np.flatnonzero(is_free)
        self.new_index = np.full(self.n, -1, dtype=np.int64)
        self.new_index[self.free] = np.arange(self.free.size)
        self.key = self.constrained.tobytes()

    @property
    def size(self) -> int:
        return int(self.free.size)

    def matrix(self, A, fmt: str = "csc"):
        """``A[free][:, free]`` as CSC (``fmt="csc"``, default: what SuperLU takes) or CSR
        (``fmt="csr"``: a row filter of a CSR ``A``, no transposition; what the energy
        minimiser hands PARDISO, which reads either)."""
        if isinstance(A, sp.csr_matrix) and A.has_canonical_format:
            # the cached plan of the structure: the same matrix as the COO pass below
            gather, indices, indptr = self._plan(A, fmt)
            return _FORMATS[fmt]((A.data[gather], indices, indptr), shape=(self.size, self.size))
        A = A.tocoo() if sp.issparse(A) else sp.coo_matrix(A)
        r = self.new_index[A.row]
        c = self.new_index[A.col]
        keep = (r >= 0) & (c >= 0)
        m = self.free.size
        return _FORMATS[fmt]((A.data[keep], (r[keep], c[keep])), shape=(m, m))

    def triplets(self, A, coef: float = 1.0, colmask: "np.ndarray | None" = None):
        """Restricted COO triplets ``(rows, cols, data)`` of ``coef * A @ diag(colmask)``."""
        if A is None:  # e.g. Fx of a system without mechanical dofs
            e = np.zeros(0, dtype=np.int64)
            return e, e, np.zeros(0)
        A = A if isinstance(A, (sp.coo_matrix, getattr(sp, "coo_array", sp.coo_matrix))) else sp.coo_matrix(A)
        r = self.new_index[A.row]
        c = self.new_index[A.col]
        keep = (r >= 0) & (c >= 0)
        if colmask is not None:
            keep &= colmask[A.col]
        return r[keep], c[keep], coef * A.data[keep]

    def assemble(self, parts) -> sp.csc_matrix:
        """Sum of restricted triplet sets (from ``triplets``) as one CSC matrix
        (duplicates summed): a single O(nnz) pass, no intermediate sparse additions."""
        parts = [p for p in parts if p[0].size]
        m = self.free.size
        if not parts:
            return sp.csc_matrix((m, m))
        r = np.concatenate([p[0] for p in parts])
        c = np.concatenate([p[1] for p in parts])
        d = np.concatenate([p[2] for p in parts])
        return sp.csc_matrix((d, (r, c)), shape=(m, m))

    def combine(self, terms, fmt: str = "csc"):
        """Restricted ``sum(coef * A @ diag(colmask))`` over ``terms = [(A, coef, colmask)]``,
        as CSC (default) or CSR (``fmt``, see ``matrix``).

        Fast path: when every non-empty ``A`` is CSR with one and the same sparsity
        structure (all the model's matrices come from one element pattern), the sum is
        formed on the ``data`` arrays and restricted with a cached index plan: no COO/CSC
        conversion per Newton iteration (measured: the conversions cost more than the
        physics on small fibril systems). A term whose column mask is identically zero is
        skipped (it adds exact zeros), a mask of ones is not multiplied, and a single
        unscaled term is gathered straight from its ``data`` (the restriction dominates a
        small relaxation otherwise: docs/engine.md). Otherwise falls back to ``assemble``.
        """
        mats = [(A, c, m) for A, c, m in terms if A is not None and A.nnz > 0]
        if not mats:
            return _FORMATS[fmt]((self.size, self.size))
        live = [(A, c, m) for A, c, m in mats if m is None or np.any(m)]
        if live:
            mats = live
        base = mats[0][0]
        same = all(
            isinstance(A, sp.csr_matrix) and A.nnz == base.nnz
            and (A.indices is base.indices or np.array_equal(A.indices, base.indices))
            and (A.indptr is base.indptr or np.array_equal(A.indptr, base.indptr))
            for A, _, _ in mats)
        if not same:
            out = self.assemble([self.triplets(A, c, None if m is None else np.asarray(m) != 0) for A, c, m in mats])
            return out if fmt == "csc" else out.tocsr()
        gather, indices, indptr = self._plan(base, fmt)
        ix = index_kernels()
        if len(mats) == 1 and mats[0][1] == 1.0 and (mats[0][2] is None or np.all(mats[0][2] == 1.0)):
            data = base.data[gather]
        elif ix is not None:
            # the same products and sums per kept entry, in the same order (rve.kernels.index)
            data = np.zeros(gather.size)
            for A, c, m in mats:
                if m is None or np.all(m == 1.0):
                    ix.gather_axpy(data, A.data, float(c), gather)
                else:
                    ix.gather_axpy_masked(data, A.data, float(c), np.asarray(m, float), A.indices, gather)
        else:
            data = np.zeros(base.nnz)
            for A, c, m in mats:
                if m is None or np.all(m == 1.0):
                    data += c * A.data
                else:
                    data += c * (A.data * m[A.indices])
            data = data[gather]
        return _FORMATS[fmt]((data, indices, indptr), shape=(self.size, self.size))

    #: plans shared by the FreeDofs of one constraint set (a StaticProblem is rebuilt after
    #: every contact-map rebuild; the plan of an unchanged structure is kept): at most this
    #: many (each holds ~2 int64 + 1 int32 per stored entry)
    shared_plans = 4
    _SHARED: list = []

    def _plan(self, A, fmt: str = "csc"):
        """``(gather, indices, indptr)``: the restricted CSC (or CSR, ``fmt``) of CSR ``A``
        is ``(A.data[gather], indices, indptr)``. Cached per structure and format: the key
        is the structure itself (identity of the index arrays, else their contents), never
        a digest, so two structures with equal sizes cannot share a plan."""
        if fmt not in _FORMATS:
            raise ValueError(f"fmt = {fmt!r}: expected 'csc' or 'csr'")
        plans = self.__dict__.setdefault("_plans", {})
        for ref_fmt, ref_indptr, ref_indices, plan in plans.values():
            if ref_fmt == fmt and _same_structure(A, ref_indptr, ref_indices):
                return plan
        shared = FreeDofs._SHARED
        for key, ref_indptr, ref_indices, plan in shared:
            if key == (self.key, fmt) and _same_structure(A, ref_indptr, ref_indices):
                plans[len(plans)] = (fmt, ref_indptr, ref_indices, plan)
                return plan
        # the restricted CSR (row filter, no sort) with the positions as values, then scipy's
        # O(nnz) CSR -> CSC transposition: the same plan as a COO -> CSC build, ~20 % cheaper
        c = self.new_index[A.indices]
        ok = (c >= 0) & np.repeat(self.is_free, np.diff(A.indptr))
        keep = np.flatnonzero(ok)
        # kept entries per row: the sorted ``keep`` searched at the n + 1 row starts (the same
        # integers as a cumulative sum over every stored entry, without touching each entry)
        per_row = np.diff(np.searchsorted(keep, A.indptr))
        indptr = np.concatenate(([0], np.cumsum(per_row[self.is_free])))
        m = self.size
        if fmt == "csr":  # the row filter itself: a sequential gather
            plan = (keep, c[keep].astype(np.int32), indptr.astype(np.int32))
        else:
            tag = sp.csr_matrix((np.arange(keep.size, dtype=float), c[keep], indptr), shape=(m, m)).tocsc()
            plan = (keep[tag.data.astype(np.int64)], tag.indices, tag.indptr)
        if len(plans) > 8:
            plans.clear()
        plans[len(plans)] = (fmt, A.indptr, A.indices, plan)
        shared.append(((self.key, fmt), A.indptr, A.indices, plan))
        del shared[:-self.shared_plans]
        return plan

    @classmethod
    def cached(cls, cache: dict, n: int, constrained) -> "FreeDofs":
        """Return the restriction for ``constrained``, reusing one from ``cache``."""
        key = np.unique(np.asarray(constrained, dtype=np.int64).ravel()).tobytes()
        fd = cache.get(key)
        if fd is None:
            fd = cls(n, constrained)
            if len(cache) > 16:
                cache.clear()
            cache[key] = fd
        return fd


_FORMATS = {"csc": sp.csc_matrix, "csr": sp.csr_matrix}


def scale_columns(A, mask: np.ndarray):
    """``A @ diag(mask)`` for a 0/1 column mask, in O(nnz) (returns a new CSR matrix)."""
    A = sp.csr_matrix(A, copy=True)
    A.data *= mask[A.indices]
    return A


def friction_of(system):
    """The friction of ``system`` (``system.term.friction``: the ``FrictionTerm`` of a contact
    system's term), None when it has none: what a solver asks before it chooses the energy
    minimiser (a potential) or the frictional residual (none). A system whose state vector
    is not the contact term's (``rve.model.periodic.PeriodicSystem``: reduced dofs) gives its
    own view as ``friction_view``, the same object taking its states."""
    if hasattr(type(system), "friction_view"):
        return system.friction_view
    term = getattr(system, "term", None)
    return getattr(term, "friction", None) if term is not None else None


class DeadLoad:
    """``system`` with a dead load ``load`` (n,): F -> F - load and, where the system has a
    potential, energy -> energy - load . x (the load's work); every other member is the
    system's."""

    def __init__(self, system, load):
        self.system, self.load = system, np.asarray(load, float)

    def __getattr__(self, name):
        if name == "system":
            raise AttributeError(name)
        return getattr(self.system, name)

    def evaluate(self, x, w, t, jacobian: bool = True):
        F, Fx, Fw = self.system.evaluate(x, w, t, jacobian)
        return F - self.load, Fx, Fw

    def energy(self, x):
        return self.system.energy(x) - float(self.load @ np.asarray(x, float).reshape(-1))
