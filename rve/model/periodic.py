"""Periodic boundary conditions by master-slave elimination (docs/periodic.md).

Contract
--------
A periodic cell's fibrils each span one period: the last node of a fibril is the
**image** of its first node. :func:`fibril_end_ties` lists those ties (image node, its
master, the reference jump ``dX = X(end) - X(start)``) and :class:`PeriodicSystem` wraps
a full ("unrolled") system -- a ``BeamModel`` or a ``ContactSystem`` on the whole mesh,
without boundary conditions -- into the system of the **reduced** dofs (every node
except the images):

    x_full = T x_red + s(F, grad T, E),    R_red = T^T R_full,    K_red = T^T K_full T.

T copies a master node's dofs onto its image; the shift s puts the macro jumps on the
images: centroid ``r(end) = r(start) + F dX``, temperature ``T(end) = T(start) +
grad_T . dX``, potential ``V(end) = V(start) - E . dX`` (``E`` the macro field per unit
reference length). The directors of an image equal its master's: the micro fluctuation
``x - F X`` is periodic, so is its derivative across the section, and the reference
directors of a periodic cell are periodic (``G(end) = G(start)``); a rigid rotation
``F = Q`` therefore rotates every director alike and leaves the cell stress-free
(tested). The tie is linear in the dofs with a constant shift, so the reduced tangent is
exact.

``PeriodicSystem`` implements the ``DynamicSystem`` and ``ContactRelaxable`` protocols
(``rve/solvers/system.py``) on the reduced dofs (its ``layout`` is the reduced
``DofLayout``: ``layout.dofs("r")`` are the master centroids), so the energy minimiser,
the capped Newton and the relaxation driver run on it unchanged. Its constraints are the
reduced dofs given at construction (e.g. one centroid against the rigid translation, the
twist gauge, a potential reference); ``set_macro`` changes the jumps; ``load`` is a
constant vector added to the full residual
(the uniform heat sink of the periodic Joule solve). ``tie_forces`` are
the forces on the images, and ``macro_stress`` the first Piola-Kirchhoff membrane stress
of the cell (N/mm):

    P = (1 / A) sum_ties f_tie (x) dX,        A = |L1 x L2| (reference cell area),

which is the Hill-Mandel average: at an equilibrium of the reduced dofs the derivative
of the total potential with respect to F is ``A P`` (``tests/test_periodic.py``).

Friction (a ``ContactSystem`` whose term carries a ``FrictionTerm``): ``friction_view`` is
a :class:`ReducedFriction`, the term's friction taking reduced states (expanded before every
call that reads a state: ``commit``, ``start``, ``freeze``, ``loads_at``, ``state``,
``share_along_fibrils``; everything else is the term's), so the frictional solvers
(``rve.solvers.frictional``) run on the cell unchanged. The history is keyed by point as in
any cell; a pair with a periodic image carries its lattice translation in the key, and its
- chord ends are the image's (``ContactTerm.ends``), so the friction forces act on the
image, i.e. on the master's nodes through the tie, and are internal to the cell.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..fem.assembly import DofLayout

__all__ = ["PeriodicTies", "fibril_end_ties", "PeriodicSystem", "ReducedFriction", "polar_rotation",
           "in_plane_gradient"]


@dataclass(frozen=True)
class PeriodicTies:
    """Image nodes of a periodic mesh: ``image[k]`` is the image of ``master[k]`` with the
    reference jump ``jump[k]`` (3,); ``periods`` (2, 3) are the cell's period vectors L1, L2
    (the reference area is ``|L1 x L2|``)."""

    n_nodes: int
    image: np.ndarray
    master: np.ndarray
    jump: np.ndarray
    periods: np.ndarray

    @property
    def area(self) -> float:
        return float(np.linalg.norm(np.cross(self.periods[0], self.periods[1])))

    @property
    def kept_nodes(self) -> np.ndarray:
        """Full node index of every reduced node (all nodes but the images, in order)."""
        keep = np.ones(self.n_nodes, bool)
        keep[self.image] = False
        return np.flatnonzero(keep)

    def reduced_node(self) -> np.ndarray:
        """(n_nodes,): the reduced node each full node takes its dofs from."""
        kept = self.kept_nodes
        red = np.full(self.n_nodes, -1, dtype=np.int64)
        red[kept] = np.arange(kept.size)
        red[self.image] = red[self.master]
        if np.any(red < 0):
            raise ValueError("an image node is the master of another image (chained ties)")
        return red


def fibril_end_ties(mesh, periods) -> PeriodicTies:
    """Each fibril's last node is the image of its first node (every fibril spans exactly one
    period of the cell); ``periods`` (2, 3): the cell's period vectors."""
    first = mesh.node_offsets[:-1].astype(np.int64)
    last = (mesh.node_offsets[1:] - 1).astype(np.int64)
    jump = mesh.X0[last, :3] - mesh.X0[first, :3]
    return PeriodicTies(int(mesh.n_nodes), last, first, jump, np.asarray(periods, float).reshape(2, 3))


def in_plane_gradient(F2) -> np.ndarray:
    """An in-plane macro gradient (2, 2) embedded in 3-D with F33 = 1 (a (3, 3) passes)."""
    F2 = np.asarray(F2, float)
    if F2.shape == (3, 3):
        return F2.copy()
    F = np.eye(3)
    F[:2, :2] = F2
    return F


def polar_rotation(F) -> np.ndarray:
    """The rotation Q of the polar decomposition F = Q U (det F > 0)."""
    u, _, vt = np.linalg.svd(np.asarray(F, float))
    Q = u @ vt
    if np.linalg.det(Q) < 0:
        raise ValueError("polar_rotation: det F <= 0")
    return Q


class _Reduction:
    """x_full = x_red[src] + shift; vectors and CSR matrices pulled back by T^T (. ) T with
    a cached plan per full sparsity structure (the reduced CSR keeps its index arrays, so
    the solvers' restriction plans are reused too)."""

    def __init__(self, src: np.ndarray, n_red: int):
        self.src = src
        self.n_red = int(n_red)
        self._plans = []

    def vector(self, R_full):
        return np.bincount(self.src, weights=R_full, minlength=self.n_red)

    def _plan(self, A):
        for indptr, indices, plan in self._plans:
            if (A.indptr is indptr and A.indices is indices) or (
                    A.indptr.size == indptr.size and A.indices.size == indices.size
                    and np.array_equal(A.indptr, indptr) and np.array_equal(A.indices, indices)):
                return plan
        n = self.n_red
        rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
        key = self.src[rows] * n + self.src[A.indices]
        uniq, inv = np.unique(key, return_inverse=True)
        r = uniq // n
        indptr = np.concatenate(([0], np.cumsum(np.bincount(r, minlength=n)))).astype(np.int32)
        plan = (inv, (uniq % n).astype(np.int32), indptr, uniq.size)
        self._plans = (self._plans + [(A.indptr, A.indices, plan)])[-4:]
        return plan

    def matrix(self, A):
        if A is None:
            return None
        A = A if isinstance(A, sp.csr_matrix) and A.has_canonical_format else sp.csr_matrix(A)
        inv, indices, indptr, nnz = self._plan(A)
        data = np.bincount(inv, weights=A.data, minlength=nnz)
        return sp.csr_matrix((data, indices, indptr), shape=(self.n_red, self.n_red))


class ReducedFriction:
    """A ``FrictionTerm`` of the full system seen through the reduced dofs of a
    ``PeriodicSystem`` (module docstring): the methods that read a state expand it first;
    every other attribute (read or set) is the term's."""

    def __init__(self, system, term):
        object.__setattr__(self, "_system", system)
        object.__setattr__(self, "_term", term)

    def __getattr__(self, name):
        return getattr(self._term, name)

    def __setattr__(self, name, value):
        setattr(self._term, name, value)

    def _full(self, x):
        return None if x is None else self._system.expand(x)

    def commit(self, x) -> float:
        return self._term.commit(self._full(x))

    def start(self, x) -> None:
        self._term.start(self._full(x))

    def freeze(self, x=None) -> None:
        self._term.freeze(self._full(x))

    def loads_at(self, x) -> dict:
        return self._term.loads_at(self._full(x))

    def hold_loads(self, x) -> None:
        self._term.hold_loads(self._full(x))

    def state(self, x, sel=None):
        return self._term.state(self._full(x), sel)

    def share_along_fibrils(self, x, receivers, geo=None) -> None:
        self._term.share_along_fibrils(self._full(x), receivers, geo)


class PeriodicSystem:
    """The reduced system of a periodic cell (module docstring).

    ``full``: a ``DynamicSystem`` on the whole mesh without constraints (a ``BeamModel`` or
    ``ContactSystem``); ``ties``: its ``PeriodicTies``; ``constrained``: reduced dofs held
    (their values in ``values``: a velocity on mechanical dofs, the value on T/V dofs);
    ``F`` (2x2 in-plane or 3x3), ``grad_T`` (3,), ``E`` (3,): the macro jumps."""

    def __init__(self, full, ties: PeriodicTies, constrained=(), values=0.0, F=None, grad_T=None, E=None,
                 load=None, contact_images: bool = False):
        self.full = full
        #: the contact search sees the periodic images (a ``ContactSystem`` full system)
        self.contact_images = bool(contact_images) and hasattr(full, "set_periodic")
        #: a constant vector added to the full residual (e.g. a uniform heat sink), or None
        self.load = None if load is None else np.asarray(load, float)
        self.ties = ties
        flay = full.layout
        if flay.n_nodes != ties.n_nodes:
            raise ValueError(f"ties of {ties.n_nodes} nodes for a system of {flay.n_nodes}")
        self.kept = ties.kept_nodes
        self.layout = DofLayout(self.kept.size, flay.fields)
        self.n = self.layout.n
        self.mech = self.layout.mech
        block = flay.block
        src = (ties.reduced_node()[:, None] * block + np.arange(block)[None, :]).ravel()
        self._red = _Reduction(src, self.n)
        self._kept_dofs = (self.kept[:, None] * block + np.arange(block)[None, :]).ravel()
        self._image_r = flay.dofs("r", ties.image).reshape(-1, 3)
        self._image_T = flay.dofs("T", ties.image) if flay.has("T") else None
        self._image_V = flay.dofs("V", ties.image) if flay.has("V") else None
        self._cidx = np.asarray(constrained, dtype=np.int64).ravel()
        self._cval = np.broadcast_to(np.asarray(values, float), self._cidx.shape).copy()
        self._M = None
        self.set_macro(np.eye(3) if F is None else F, grad_T, E)

    # ------------------------------------------------------------------ maps
    def set_macro(self, F=None, grad_T=None, E=None) -> None:
        """Set the macro jumps (None keeps the current one); the shift follows, and with
        ``contact_images`` the lattice of the contact search (the images F L1, F L2 and
        their sums; every fibril wraps into its image F dX): it takes effect at the next
        ``rebuild``, which the caller makes at the new state."""
        if F is not None:
            self.F = in_plane_gradient(F)
        if grad_T is not None or not hasattr(self, "grad_T"):
            self.grad_T = np.zeros(3) if grad_T is None else np.asarray(grad_T, float)
        if E is not None or not hasattr(self, "E"):
            self.E = np.zeros(3) if E is None else np.asarray(E, float)
        if self.contact_images:
            self._set_images()
        s = np.zeros(self.full.n)
        s[self._image_r] = self.ties.jump @ self.F.T
        if self._image_T is not None:
            s[self._image_T] = self.ties.jump @ self.grad_T
        if self._image_V is not None:
            s[self._image_V] = -(self.ties.jump @ self.E)
        mech = np.asarray(self.full.mech, bool)
        self._shift_x = np.where(mech, s, 0.0)
        self._shift_w = np.where(mech, 0.0, s)

    def _set_images(self) -> None:
        """The contact search's lattice (F L1, F L2 and their sums), the fibrils' wraps (each
        into its image F dX) and the field values of an image at deformed shift T: T + grad_T
        . F^-1 T, V - E . F^-1 T (the ties' jumps over the reference lattice vector)."""
        a1, a2 = self.ties.periods @ self.F.T
        images = [i * a1 + j * a2 for i in (-1, 0, 1) for j in (-1, 0, 1) if (i, j) != (0, 0)]
        wrap = np.zeros((self.full.mesh.n_fibrils, 3))
        wrap[self.full.mesh.node_fibril[self.ties.image]] = self.ties.jump @ self.F.T
        Finv_T = np.linalg.inv(self.F).T
        self.full.set_periodic(np.array(images), wrap, field_jumps={"T": Finv_T @ self.grad_T, "V": -(Finv_T @ self.E)},
                               lattice=np.array([a1, a2]))

    def expand(self, x_red) -> np.ndarray:
        """The full (unrolled) ``x`` of a reduced one: ``T x + s`` on the mechanical dofs (the
        other entries of ``x`` are the solvers' zero placeholders)."""
        return np.asarray(x_red, float)[self._red.src] + self._shift_x

    def expand_rates(self, w_red) -> np.ndarray:
        """The full ``w`` of a reduced one at fixed macro jumps: ``T w`` on the velocities,
        ``T w + s`` on the temperatures and potentials (their jumps)."""
        return np.asarray(w_red, float)[self._red.src] + self._shift_w

    def restrict(self, x_full) -> np.ndarray:
        """The reduced dofs of a full vector (its values at the kept nodes)."""
        return np.asarray(x_full, float).reshape(-1)[self._kept_dofs].copy()

    def nodal(self, u):
        return self.layout.as_nodal(u)

    # ------------------------------------------------------------------ DynamicSystem
    def mass(self):
        if self._M is None:
            self._M = self._red.matrix(sp.csr_matrix(self.full.mass()))
        return self._M

    def constraints(self, t):
        return self._cidx, self._cval

    def admissible(self, x) -> bool:
        return self.full.admissible(self.expand(x))

    def evaluate(self, x, w, t, jacobian: bool = True):
        F, Fx, Fw = self.full.evaluate(self.expand(x), self.expand_rates(w), t, jacobian)
        if self.load is not None:
            F = F + self.load
        Fr = self._red.vector(F)
        if not jacobian:
            return Fr, None, None
        return Fr, self._red.matrix(Fx), self._red.matrix(Fw)

    # ------------------------------------------------------------------ ContactRelaxable
    @property
    def params(self):
        return self.full.params

    @property
    def map(self):
        return self.full.map

    @property
    def mesh(self):
        return self.full.mesh

    def rebuild(self, x):
        out = self.full.rebuild(self.expand(x))
        self._M = None  # the union structure may have changed
        return out

    def max_displacement_since_rebuild(self, x) -> float:
        return self.full.max_displacement_since_rebuild(self.expand(x))

    def energy(self, x) -> float:
        return float(self.full.energy(self.expand(x)))

    def set_onset(self, fraction: float) -> None:
        self.full.set_onset(fraction)

    def active_pairs(self, x):
        return self.full.active_pairs(self.expand(x))

    def contact_state(self, x) -> dict:
        return self.full.contact_state(self.expand(x))

    @property
    def friction_view(self):
        """The full system's friction on the reduced dofs (``ReducedFriction``), None without
        friction (``rve.solvers.system.friction_of``)."""
        fr = getattr(getattr(self.full, "term", None), "friction", None)
        return None if fr is None else ReducedFriction(self, fr)

    # the augmented Lagrangian protocol of rve.solvers.augmented, on the full system
    @property
    def augmented(self) -> bool:
        return self.full.augmented

    @property
    def multipliers(self):
        return self.full.multipliers

    def max_penetration(self, x) -> float:
        return self.full.max_penetration(self.expand(x))

    def update_multipliers(self, x, relaxation: float = 1.0) -> None:
        self.full.update_multipliers(self.expand(x), relaxation)

    @property
    def penalty(self) -> float:
        return self.full.penalty

    def set_penalty(self, penalty: float, x=None) -> None:
        self.full.set_penalty(penalty, None if x is None else self.expand(x))

    # ------------------------------------------------------------------ macro quantities
    def full_residual(self, x, w=None, t: float = 0.0) -> np.ndarray:
        w = np.zeros(self.n) if w is None else w
        F, _, _ = self.full.evaluate(self.expand(x), self.expand_rates(w), t, jacobian=False)
        return F if self.load is None else F + self.load

    def tie_forces(self, x, w=None, t: float = 0.0) -> np.ndarray:
        """(n_ties, 3): the residual at every image centroid, i.e. the force the periodic
        neighbour exerts through the tie on the image (internal + contact)."""
        return self.full_residual(x, w, t)[self._image_r]

    def _image_pair_moment(self, x, w, cols) -> np.ndarray:
        """(len(cols), 3): sum over the active contact pairs with a periodic image of the
        residual components ``cols`` (local pair columns) on the - side (x) the reference
        lattice vector F^-1 T of the pair."""
        cmap = self.full.map if self.contact_images else None
        if cmap is None or cmap.shift is None:
            return np.zeros((len(cols), 3))
        term = self.full.term
        w_full = np.zeros(self.full.n) if w is None else self.expand_rates(w)
        act, R, _, _ = term.forms(self.expand(x), w_full, jacobian=False)
        if act.size == 0:
            return np.zeros((len(cols), 3))
        # the local nodes of a pair are its + element's, then its - element's
        R = np.asarray(R).reshape(act.size, term.m, -1)[:, :, cols]
        f_minus = R[:, term.m // 2:, :].sum(axis=1)
        ref = np.linalg.solve(self.F, cmap.shifts[act].T).T
        return f_minus.T @ ref

    def image_contact_moment(self, x) -> np.ndarray:
        """(3, 3): sum over the contact pairs with a periodic image of the force on the image
        side (x) its reference lattice vector F^-1 T: the derivative of the contact energy
        with respect to F through the shifts T = F (i L1 + j L2)."""
        return self._image_pair_moment(x, None, [0, 1, 2])

    def macro_stress(self, x, w=None, t: float = 0.0) -> np.ndarray:
        """First Piola-Kirchhoff membrane stress (3, 3), N/mm: (sum_ties f (x) dX + the image
        contacts' ``image_contact_moment``) / A, i.e. dPi/dF / A at an equilibrium."""
        f = self.tie_forces(x, w, t)
        return (f.T @ self.ties.jump + self.image_contact_moment(x)) / self.ties.area

    def tie_currents(self, x, w) -> np.ndarray:
        """(n_ties,): the V residual at every image node: the current leaving the cell
        through the tie into the periodic neighbour (A)."""
        return self.full_residual(x, w)[self._image_V]

    def macro_current(self, x, w) -> np.ndarray:
        """(3,): the macro current per unit reference width (A/mm) leaving the cell,
        -(sum_ties i dX + the image contacts' current (x) F^-1 T) / A: the conduction
        counterpart of ``macro_stress`` (the current of a face is carried by its ties and by
        the contacts across it)."""
        i = self.tie_currents(x, w)
        term = getattr(self.full, "term", None)
        img = np.zeros(3)
        if term is not None and "V" in getattr(term, "scalar", ()):
            img = self._image_pair_moment(x, w, [3 + term.scalar.index("V")])[0]
        return -(i @ self.ties.jump + img) / self.ties.area
