"""Systems derived from an assembled model: row scaling and the thermal post-solve.

Contract
--------
``RowScaledSystem(system, scale)``: the ``DynamicSystem`` whose equations (rows of M, F, Fx,
Fw) are multiplied by positive ``scale`` (the same solution; Newton's norm weighs each field
in its own unit). ``ThermalPostSystem(model, times, Q, fixed_nodes, fixed_values)``: the heat
equation alone, driven by a stored Joule history (used when T does not feed back). Both
implement the ``DynamicSystem`` protocol of ``rve.solvers.system``; docs/coupled_fields.md.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..physics.electric_forms import section_ops
from ..physics.thermal_forms import capacity_matrix, conduction

__all__ = ["RowScaledSystem", "ThermalPostSystem"]


class RowScaledSystem:
    """A ``DynamicSystem`` whose equations (rows of M and F) are multiplied by positive
    ``scale``: the same solution, but Newton's residual norm weighs every field in its
    own natural unit (the model's rows are forces, heat flows and currents of very
    different magnitudes). Jacobians are scaled exactly the same way.

    ``mass()`` scales the wrapped system's current mass matrix (a contact-map rebuild may
    give it a new pattern). ``residual_at(x, w, t)`` is the unscaled F of the last
    evaluation when that was at exactly (x, w) and t, else None: a balance at an accepted
    step's end state then needs no second evaluation."""

    def __init__(self, system, scale):
        self.system = system
        self.scale = np.asarray(scale, float)
        self.n = system.n
        self.mech = system.mech
        self._rows = {}
        self._last = None

    def _scaled(self, A):
        """S A for CSR A, keeping A's structure arrays (no re-sorting, no copies of indices)."""
        if A is None:
            return None
        if not isinstance(A, sp.csr_matrix):
            A = sp.csr_matrix(A)
        key = id(A.indptr)
        hit = self._rows.get(key)
        if hit is None or hit[0] is not A.indptr:
            if len(self._rows) > 8:
                self._rows.clear()
            hit = self._rows[key] = (A.indptr, self.scale[np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))])
        return sp.csr_matrix((A.data * hit[1], A.indices, A.indptr), shape=A.shape)

    def mass(self):
        return self._scaled(sp.csr_matrix(self.system.mass()))

    def constraints(self, t):
        return self.system.constraints(t)

    def admissible(self, x) -> bool:
        return self.system.admissible(x)

    def evaluate(self, x, w, t, jacobian: bool = True):
        F, Fx, Fw = self.system.evaluate(x, w, t, jacobian)
        self._last = (float(t), np.array(x, copy=True), np.array(w, copy=True), np.array(F, dtype=float, copy=True))
        F = F * self.scale
        if not jacobian:
            return F, None, None
        return F, self._scaled(Fx), self._scaled(Fw)

    def residual_at(self, x, w, t):
        """Unscaled F of the last evaluation if it was at exactly (x, w) and at t (the end
        time of a step may differ from its last stage time in the last bit), else None."""
        if self._last is None:
            return None
        tl, xl, wl, F = self._last
        if abs(tl - t) <= 1e-12 * max(1.0, abs(t)) and np.array_equal(xl, x) and np.array_equal(wl, w):
            return F
        return None

    def __getattr__(self, name):  # everything else (mesh, nodal, ...) from the wrapped model
        return getattr(self.system, name)


class ThermalPostSystem:
    """The heat equation alone, ``M_T dT/dt + K_T T - Q(t) = 0``, driven by a Joule heat
    history Q(t) (nodal, W) sampled at ``times`` and interpolated by a cubic spline
    (O(h^4), so the post-solve keeps the order of the SDIRK schemes up to 3).

    Used when T does not feed back (alpha_mu = 0 and S = 0): the mechanics and electrics are
    integrated without T dofs and T is solved afterwards over the stored states. All dofs
    are T (``mech`` is all False); Dirichlet T at ``fixed_nodes`` with ``fixed_values``."""

    def __init__(self, model, times, Q, fixed_nodes=(), fixed_values=0.0):
        from scipy.interpolate import CubicSpline

        mesh = model.mesh
        ops = model.ops if model.ops is not None else section_ops(model.basis)
        mat = model.material
        E, nn = mesh.n_elements, model.basis.nn
        self.n = mesh.n_nodes
        self.mech = np.zeros(self.n, bool)
        pat_rows = np.repeat(mesh.conn, nn, axis=1).ravel()
        pat_cols = np.tile(mesh.conn, (1, nn)).ravel()
        Mc = capacity_matrix(ops, mat.density * mat.heat_capacity)
        Kc = conduction(ops, mat.thermal_conductivity, np.zeros((E, nn)))[1]
        self._M = sp.csr_matrix((Mc.ravel(), (pat_rows, pat_cols)), shape=(self.n, self.n))
        self._K = sp.csr_matrix((Kc.ravel(), (pat_rows, pat_cols)), shape=(self.n, self.n))
        self._Q = CubicSpline(np.asarray(times, float), np.asarray(Q, float), axis=0)
        self._fixed = np.asarray(fixed_nodes, int)
        self._vals = np.broadcast_to(np.asarray(fixed_values, float), self._fixed.shape).copy()
        self._zero = sp.csr_matrix((self.n, self.n))

    def mass(self):
        return self._M

    def constraints(self, t):
        return self._fixed, self._vals

    def admissible(self, x) -> bool:
        return True

    def evaluate(self, x, w, t, jacobian: bool = True):
        F = self._K @ w - self._Q(t)
        if not jacobian:
            return F, None, None
        return F, self._zero, self._K
