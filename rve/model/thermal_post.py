"""The temperature post-solve of the dynamic fabric scenes (T does not feed back: S =
alpha_mu = 0): the thermal operators (conduction, capacity, contact heat transfer) and the
stage solves of the heat equation on the converged stage states of the
mechanical/electrical step (docs/induced_deformation.md).

Contract
--------
* ``ThermalOperators(system, h_C)``: for a ``ContactSystem`` (mech + V, or mech + T + V):
  ``M`` (capacity, W... mJ/K), ``K`` (conduction, W/K) on the nodes, ``contact(x)`` the
  contact heat-transfer matrix ``h_C a [[T]]`` of the map's active pairs at x (exactly the
  monolithic contact term's T block: ``rve.physics.contact_forms.scalar_jump`` on the
  chords, ``rve.physics.contact_curve.curve_scalar_jump`` on the curves), ``joule(x,
  w, t)`` the nodal Joule heat (W), ``fixed`` the T = 0 end nodes; ``active_pairs``,
  ``contact_triplets``, ``contact_apply`` and ``joule`` memoised for the last state (and
  contact map).
* ``KeptFactorStages(ops, T_fixed=0)``: the stage solves of the heat equation
  ``M dT/dt + (K + K_c(x)) T - Q(x, w, t) = 0`` on the stage states ``[(x_i, w_i)]`` of the
  mechanical/electrical step (``drive(stages)``; T does not feed back: S = alpha_mu = 0), as
  the ``linear_stages`` of ``rve.solvers.dirk.DirkStepper``: (M + h a_ii K)_ff factorised
  once per h a_ii, the contact part by iterative refinement on that factor (direct
  fallback); ``FreshStages`` the plain reference (a fresh solve per stage). Counters
  ``solves``, ``refinements``, ``fallbacks``. The stepping itself is
  ``rve.scenes.thermal_post.ThermalPostSolver``.
* ``StageHeatSystem(ops, T_fixed)``: the same heat equation as a ``DynamicSystem`` (all dofs
  T), ``drive(stages, t0, h, tableau)`` giving it the stage states of one step.
* ``heat_transfer_block(geo, order, weight, coef, kappa, g_eps)``: scalar_jump's ``Ju`` alone
  (the chords); ``contact_heat_block(term, mesh, x, act, coef)`` the local nodes and the
  matrix on the term's geometry (chord, curve or smooth: on the curves the two half passes'
  ``curve_scalar_jump`` ``Ju``, each side's nodes the element's or its smooth stencil's).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..physics.contact_curve import curve_scalar_jump
from ..physics.contact_forms import hertz_width, lagrange_at, scalar_jump
from ..physics.thermal_forms import capacity_matrix, conduction
from .terms.contact_pairs import HalfPasses

__all__ = ["ThermalOperators", "KeptFactorStages", "FreshStages", "StageHeatSystem", "heat_transfer_block",
           "contact_heat_block"]


class ThermalOperators:
    def __init__(self, system, h_C: float, fixed_nodes):
        base = system.base
        self.system, self.base = system, base
        mesh, ops, mat = base.mesh, base.ops, base.material
        self.n = mesh.n_nodes
        nn = base.basis.nn
        rows = np.repeat(mesh.conn, nn, axis=1).ravel()
        cols = np.tile(mesh.conn, (1, nn)).ravel()
        E = mesh.n_elements
        Mc = capacity_matrix(ops, mat.density * mat.heat_capacity)
        Kc = conduction(ops, mat.thermal_conductivity, np.zeros((E, nn)))[1]
        self.M = sp.csr_matrix((Mc.ravel(), (rows, cols)), shape=(self.n, self.n))
        self.K = sp.csr_matrix((Kc.ravel(), (rows, cols)), shape=(self.n, self.n))
        self.h_C = float(h_C)
        self.fixed = np.asarray(fixed_nodes, np.int64)
        self.free = np.setdiff1d(np.arange(self.n), self.fixed)
        # free / fixed blocks, built once (the post-solve and the balances slice nothing per step)
        self.new_index = np.full(self.n, -1, np.int64)
        self.new_index[self.free] = np.arange(self.free.size)
        fr, fx = self.free, self.fixed
        self.M_ff, self.M_fc = self.M[fr][:, fr].tocsc(), self.M[fr][:, fx].tocsr()
        self.K_ff, self.K_fc = self.K[fr][:, fr].tocsc(), self.K[fr][:, fx].tocsr()
        self._M_lu = None
        self._memo = {}

    def _memoised(self, what, key_arrays, t, compute, refs=()):
        """The last value of ``what`` if it was computed at equal arrays and time (times equal
        to 1e-12 relative: the integrator's accepted time t0 + k h0 and the stage time t0 + h
        of the same step may differ in the last bit) and with the same objects ``refs``
        (compared by identity: the contact map, replaced by every rebuild)."""
        hit = self._memo.get(what)
        refs = tuple(refs)
        if hit is not None and abs(hit[1] - t) <= 1e-12 * max(1.0, abs(t)) and len(hit[3]) == len(refs) \
                and all(a is b for a, b in zip(hit[3], refs)) \
                and all(a is b or np.array_equal(a, b) for a, b in zip(hit[0], key_arrays)):
            return hit[2]
        val = compute()
        self._memo[what] = (tuple(np.array(a, copy=True) for a in key_arrays), float(t), val, refs)
        return val

    def active_pairs(self, x):
        """The contact map's active pairs at x (memoised for the last state; empty without
        a map)."""
        def compute():
            term = self.system.term
            if term.map is None or term.map.n_pairs == 0:
                return np.zeros(0, np.int64)
            return term.active_pairs(x)
        return self._memoised("active", (x,), 0.0, compute, (self.system.term.map,))

    def contact_triplets(self, x):
        """COO triplets (rows, cols, values) of the contact heat-transfer matrix h_C a [[T]]
        of the map's active pairs at x (exactly the monolithic contact term's T block:
        ``rve.physics.contact_forms.scalar_jump``'s ``Ju``, by ``heat_transfer_block``);
        empty arrays without active pairs. Memoised for the last state."""
        def compute():
            term = self.system.term
            e = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
            act = self.active_pairs(x) if self.h_C > 0 else ()
            if len(act) == 0:
                return e
            loc, Ju = contact_heat_block(term, self.base.mesh, x, act, self.h_C)
            m = loc.shape[1]
            return np.repeat(loc, m, axis=1).ravel(), np.tile(loc, (1, m)).ravel(), Ju.ravel()
        return self._memoised("contact", (x,), 0.0, compute, (self.system.term.map,))

    def contact(self, x):
        """Contact heat-transfer matrix (n_nodes, n_nodes) at x (the map's active pairs)."""
        r, c, v = self.contact_triplets(x)
        return sp.csr_matrix((v, (r, c)), shape=(self.n, self.n))

    def contact_apply(self, x, T):
        """K_c(x) T (n_nodes,) from the triplets (no matrix is built)."""
        r, c, v = self.contact_triplets(x)
        if v.size == 0:
            return np.zeros(self.n)
        return np.bincount(r, weights=v * np.asarray(T, float)[c], minlength=self.n)

    def contact_blocks(self, x):
        """(free x free CSC, free x fixed CSR) blocks of the contact matrix, or None without
        active pairs."""
        r, c, v = self.contact_triplets(x)
        if v.size == 0:
            return None
        ri, ci = self.new_index[r], self.new_index[c]
        nf = self.free.size
        ff = (ri >= 0) & (ci >= 0)
        Kff = sp.csc_matrix((v[ff], (ri[ff], ci[ff])), shape=(nf, nf))
        fc = (ri >= 0) & (ci < 0)
        fix_pos = np.full(self.n, -1, np.int64)
        fix_pos[self.fixed] = np.arange(self.fixed.size)
        Kfc = sp.csr_matrix((v[fc], (ri[fc], fix_pos[c[fc]])), shape=(nf, self.fixed.size))
        return Kff, Kfc

    def joule_now(self, x, w, t):
        """Nodal Joule heat (W) at the state, not memoised: the compiled fused kernel the
        monolithic solve takes its Joule rows from (``BeamModel.joule_power_fused``: compiled
        when ``rve.kernels.use_numba()``, else ``BeamModel.joule_power``, the numpy reference;
        the two agree to rounding)."""
        return self.base.joule_power_fused(x, w, t)

    def joule(self, x, w, t):
        """Nodal Joule heat (W) at the state (memoised for the last state)."""
        return self._memoised("joule", (x, w), float(t), lambda: self.joule_now(x, w, t))

    def residual(self, T, x, w, t):
        """F_T = (K + K_c(x)) T - Q (no capacity term)."""
        return self.K @ T + self.contact_apply(x, T) - self.joule(x, w, t)

    def rate(self, T, x, w, t):
        """dT/dt at the free nodes from the heat equation (0 at the fixed ends) and the heat
        leaving through the fixed ends (W): q_out = -sum_fixed (M dT/dt + F_T)."""
        F = self.residual(T, x, w, t)
        fr = self.free
        if self._M_lu is None:
            self._M_lu = spla.splu(self.M_ff)
        Tdot = np.zeros(self.n)
        Tdot[fr] = self._M_lu.solve(-F[fr])
        q_out = -float((self.M @ Tdot + F)[self.fixed].sum())
        return Tdot, q_out


def heat_transfer_block(geo, order: int, weight, coef, kappa, g_eps: float = 0.0):
    """``Ju`` (P, 2nn, 2nn) of ``rve.physics.contact_forms.scalar_jump`` alone: the Jacobian
    of ``int [[dT]] coef a(g) [[T]]`` with respect to the nodal T of the two elements (the
    term is linear in T, so this is the whole contact heat-transfer matrix). The same
    expressions as ``scalar_jump`` without its residual and its dX tangents."""
    P, G = geo.g.shape
    w = np.broadcast_to(np.asarray(weight, float).reshape(P, -1), (P, G))
    kap = np.asarray(kappa, float)
    kap = kap[:, None] if kap.ndim == 1 else kap
    a, _ = hertz_width(np.where(geo.active, geo.g, 0.0), kap, g_eps)
    N, _ = lagrange_at(order, np.stack([geo.s_plus, geo.s_minus]))  # one call: (2, P, G, nn)
    Np, Nm = N[0], N[1]
    k = np.where(geo.active, w * coef, 0.0)
    phi = np.concatenate([Np, -Nm], axis=-1)  # (P, G, 2nn)
    return np.einsum("pgA,pgB->pAB", (k * a)[..., None] * phi, phi)


def contact_heat_block(term, mesh, x, act, coef):
    """``(loc (Pa, m), Ju (Pa, m, m))``: the local nodes of the contact pairs ``act`` and
    their contact heat-transfer matrix at x, on the term's geometry (the chords:
    ``heat_transfer_block``; the curves: ``ContactTerm.curve_heat_transfer_block``)."""
    if term.curve:
        return term.curve_heat_transfer_block(x, act, coef)
    geo = term.geometry(x, act)
    conn, cmap = mesh.conn, term.map
    Ju = heat_transfer_block(geo, mesh.order, term.weight[act], coef, term.kappa[act], term.g_eps)
    return np.concatenate([conn[cmap.e_plus[act]], conn[cmap.e_minus[act]]], axis=1), Ju


def _reference_heat_block(term, mesh, x, act, coef):
    """``contact_heat_block`` by the monolithic term's own jump forms (``scalar_jump``,
    ``curve_scalar_jump`` at zero field; their ``Ju``), the plain reference."""
    conn, cmap = mesh.conn, term.map
    if term.curve:
        ps = term.passes
        rows = ps.rows(act)
        geo = term.geometry(x, act)
        a, da = hertz_width(np.where(geo.active, geo.g, 0.0), term.kappa[term.row_pair[rows]][:, None], term.g_eps)
        z = np.zeros(geo.Na.shape[::2])
        wgt = term.weight[rows]
        Ju = curve_scalar_jump(geo, z, z, wgt * coef * a, wgt * coef * da, True)[1]
        nn = ps.width(conn.shape[1])
        loc = np.concatenate([ps.side_nodes(conn, cmap.e_plus[act]), ps.side_nodes(conn, cmap.e_minus[act])], axis=1)
        return loc, HalfPasses.fold(Ju, nn, axes=(1, 2))
    geo = term.geometry(x, act)
    z = np.zeros((act.size, conn.shape[1]))
    Ju = scalar_jump(geo, mesh.order, z, z, term.weight[act], coef, term.kappa[act], term.g_eps, True)[1]
    return np.concatenate([conn[cmap.e_plus[act]], conn[cmap.e_minus[act]]], axis=1), Ju


class KeptFactorStages:
    """The stage solves of the heat equation on the free nodes for
    ``rve.solvers.dirk.DirkStepper(linear_stages=...)``, driven by the stage states
    ``[(x_i, w_i)]`` of a mechanical/electrical step (``drive``): stage i solves
    ``(M + h a_ii (K + K_c(x_i)))_ff T_i = rhs_ff`` less the fixed ends' columns.

    ``(M + h a_ii K)_ff`` is factorised once per ``h a_ii`` (one per step size, kept across
    steps and contact patterns); without active contact pairs the stage is that one solve;
    with active pairs the contact part ``h a_ii K_c(x_i)`` (a small, positive semi-definite
    perturbation: ~3e-5 of the capacity) is taken by iterative refinement on the kept
    factor, ``T <- T + LU^-1 (rhs - A T)`` with the exact stage matrix A in the residual,
    until the correction is <= ``refine_tol`` times |T| (3-5 solves); if a correction does
    not shrink by half the stage falls back to a direct sparse solve of A (``fallbacks``).
    Joule heat and the contact matrix come from ``ThermalOperators`` (memoised per state:
    the last stage's values serve the balances of the accepted state). Counters ``solves``,
    ``refinements``, ``fallbacks``."""

    def __init__(self, ops: ThermalOperators, T_fixed: float = 0.0, refine_tol: float = 1e-14,
                 max_refine: int = 12):
        self.ops = ops
        self.T_fixed = float(T_fixed)
        self.refine_tol, self.max_refine = float(refine_tol), int(max_refine)
        self.solves = 0
        self.refinements = 0
        self.fallbacks = 0
        self._lu = {}
        self._stages: list = []

    def drive(self, stages) -> None:
        """The stage states ``[(x_i, w_i)]`` of the step about to be taken."""
        self._stages = list(stages)

    def _base(self, haii):
        """(LU of (M + h a_ii K)_ff, (M + h a_ii K)_fc, M + h a_ii K), kept per h a_ii."""
        hit = self._lu.get(haii)
        if hit is None:
            if len(self._lu) > 8:
                self._lu.clear()
            op = self.ops
            hit = self._lu[haii] = (spla.splu((op.M_ff + haii * op.K_ff).tocsc()),
                                    (op.M_fc + haii * op.K_fc).tocsr(), (op.M + haii * op.K).tocsr())
        return hit

    def source(self, i, t):
        x, w = self._stages[i]
        return self.ops.joule(x, w, t)

    def apply(self, i, T, t):
        x = self._stages[i][0]
        return self.ops.K @ T + self.ops.contact_apply(x, T)

    def solve(self, i, haii, rhs, t):
        op = self.ops
        fr, fx = op.free, op.fixed
        x = self._stages[i][0]
        T_fix = np.full(fx.size, self.T_fixed)
        lu, A_fc, A = self._base(haii)
        T = np.empty(op.n)
        T[fx] = T_fix
        T[fr] = lu.solve(rhs[fr] - A_fc @ T_fix)
        self.solves += 1
        if op.contact_triplets(x)[2].size:  # active pairs (or, impact, the projectile sink)
            T = self._refine(T, rhs, lu, A, haii, x)
        return T

    def _refine(self, T, rhs, lu, A, haii, x):
        """Iterative refinement of the stage solve with the contact part (class docstring)."""
        op, fr = self.ops, self.ops.free
        prev = np.inf
        for _ in range(self.max_refine):
            r = rhs - A @ T - haii * op.contact_apply(x, T)
            d = lu.solve(r[fr])
            self.solves += 1
            self.refinements += 1
            T[fr] += d
            nd = float(np.abs(d).max())
            if nd <= self.refine_tol * max(float(np.abs(T).max()), 1e-300):
                return T
            if nd > 0.5 * prev:
                break
            prev = nd
        # not contracting (a contact much stiffer than the capacity): a direct solve of A
        self.fallbacks += 1
        Kff, Kfc = op.contact_blocks(x)
        T_fix = T[op.fixed]
        rhs_f = rhs[fr] - (op.M_fc + haii * (op.K_fc + Kfc)) @ T_fix
        T[fr] = spla.spsolve((op.M_ff + haii * (op.K_ff + Kff)).tocsc(), rhs_f)
        self.solves += 1
        return T


class FreshStages(KeptFactorStages):
    """The plain reference of :class:`KeptFactorStages`: a fresh ``spsolve`` of the stage
    matrix at every stage with active pairs, Joule by ``BeamModel.joule_power`` and the
    contact matrix by ``scalar_jump`` at every stage; only the base factor is kept (the
    reference of tests/test_induced_deformation.py)."""

    def __init__(self, ops: ThermalOperators, T_fixed: float = 0.0):
        super().__init__(ops, T_fixed)
        self._Kc: dict = {}

    def drive(self, stages) -> None:
        super().drive(stages)
        self._Kc = {}

    def source(self, i, t):
        return self.ops.base.joule_power(*self._fabric(*self._stages[i]), t)

    def apply(self, i, T, t):
        return self.ops.K @ T + self._Kc[i] @ T

    def solve(self, i, haii, rhs, t):
        op = self.ops
        fr, fx = op.free, op.fixed
        T_fix = np.full(fx.size, self.T_fixed)
        Kc = self._Kc[i] = self._contact_fresh(self._stages[i][0])
        rhs_f = rhs[fr] - (op.M_fc + haii * op.K_fc) @ T_fix
        T = np.empty(op.n)
        T[fx] = T_fix
        if Kc.nnz == 0:
            T[fr] = self._base(haii)[0].solve(rhs_f)
        else:
            Kff, Kfc = Kc[fr][:, fr].tocsc(), Kc[fr][:, fx].tocsr()
            rhs_f = rhs_f - haii * (Kfc @ T_fix)
            T[fr] = spla.spsolve((op.M_ff + haii * (op.K_ff + Kff)).tocsc(), rhs_f)
        self.solves += 1
        return T

    def _fabric(self, x, w):
        """The fabric part of (x, w) (the impact scene's operators take full states)."""
        split = getattr(self.ops, "_split", None)
        if split is None:
            return x, w
        xf = split(x)
        w = np.asarray(w, float)
        return xf, (w[: xf.size] if w.size != xf.size else w)

    def _contact_fresh(self, x):
        """The contact heat-transfer matrix at x by ``scalar_jump`` (no memo, no shortcut)."""
        op = self.ops
        term = op.system.term
        n = op.n
        extra = None
        if hasattr(op, "sink_matrix"):  # the impact scene's projectile sink (centres from x)
            x = op._split(x)
            extra = op.sink_matrix(x)
        K = sp.csr_matrix((n, n))
        if op.h_C > 0 and term.map is not None and term.map.n_pairs > 0:
            act = term.active_pairs(x)
            if act.size:
                loc, Ju = _reference_heat_block(term, op.base.mesh, x, act, op.h_C)
                m = loc.shape[1]
                K = sp.csr_matrix((Ju.ravel(), (np.repeat(loc, m, axis=1).ravel(), np.tile(loc, (1, m)).ravel())),
                                  shape=(n, n))
        return K if extra is None else (K + extra).tocsr()


class StageHeatSystem:
    """The heat equation of one mechanical/electrical step as a ``DynamicSystem`` (all dofs
    T, none mechanical): ``M dT/dt + (K + K_c(x_i)) T - Q(x_i, w_i, t_i) = 0`` at the stage
    times ``t0 + c_i h``, each stage taking the contact matrix and the Joule heat of its own
    mechanical/electrical stage state."""

    def __init__(self, ops: ThermalOperators, T_fixed: float):
        self.ops = ops
        self.n = ops.n
        self.mech = np.zeros(ops.n, bool)
        self._fixed_values = np.full(ops.fixed.size, float(T_fixed))
        self._zero = sp.csr_matrix((ops.n, ops.n))
        self._times = np.zeros(0)
        self._stages: list = []

    def drive(self, stages, t0: float, h: float, tableau) -> None:
        """The stage states ``[(x_i, w_i)]`` of the step from ``t0`` of size ``h``."""
        self._stages = list(stages)
        self._times = t0 + np.asarray(tableau.c, float)[: len(self._stages)] * h

    def mass(self):
        return self.ops.M

    def constraints(self, t):
        return self.ops.fixed, self._fixed_values

    def admissible(self, x) -> bool:
        return True

    def evaluate(self, x, w, t, jacobian: bool = True):
        xi, wi = self._stages[int(np.argmin(np.abs(self._times - t)))]
        op = self.ops
        F = op.K @ w + op.contact_apply(xi, w) - op.joule(xi, wi, t)
        if not jacobian:
            return F, None, None
        return F, self._zero, (op.K + op.contact(xi)).tocsr()

