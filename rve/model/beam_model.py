"""The assembled fibril model: M dw/dt + F(x, w, t) = 0 over all fibrils of a scene, as a sum
of terms (docs/coupled_fields.md, "How the model is assembled (terms)").

Contract
--------
``BeamModel`` implements the ``DynamicSystem`` protocol of ``rve.solvers.system``:
``n``, ``mech``, ``mass()``, ``evaluate(x, w, t, jacobian)``, ``constraints(t)``,
``admissible(x)``. x and w are flat arrays in the node-interleaved layout of
``rve.fem.assembly.DofLayout``: per node w = [v (9), T, V] restricted to the declared
fields (x is a placeholder, kept 0, at T and V dofs).

A scene declares what it needs and only that is assembled (docs/coupled_fields.md: "skip
what a scene doesn't need"): ``fields`` ("mech",), ("mech", "V"), ("mech", "T"),
("mech", "T", "V"); ``couplings`` a ``Couplings`` (flags whose fields are missing are an
error, flags with a zero coefficient are dropped: ``active``); ``prescribed_current``
(the static wire's Lorentz load); ``circuits`` (mixed V end conditions); ``field_ramp``
(t -> factor on B).

The constructor picks the terms (``terms``, in this order, which is the order of every
floating-point sum): ``Elasticity`` (mu(T) with softening), ``PrescribedLorentz``,
``HeatConduction`` (T), ``Electromagnetic`` (V: current conservation with back-EMF and
Seebeck, Lorentz force of the conduction current, Joule heat), ``Damping``, ``Inertia``
(mass blocks: rho, rho c_p), ``Circuits``; one ``rve.model.assembler.Assembler`` sums
them. The mechanics-only model is the same assembler with fewer terms (its damping is
the constant assembled operator C: ``F += C w``, ``Fw = C``).
"""
from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp

from ..fem.assembly import DofLayout, ElementPattern
from ..fem.basis import BeamBasis
from ..fem.mesh import FibrilMesh
from ..fem.small_matrix import det3
from ..physics.beam_forms import mass_matrix
from ..physics.electric_forms import axial_current, potential_equation, section_ops
from ..physics.elasticity import lame
from ..physics.thermal_forms import capacity_matrix, joule_source
from .assembler import Assembler, ElementState, RowScale
from .materials import BeamMaterial, CircuitBC, Couplings, DirichletBC, PrescribedCurrent, resolve_couplings
from .terms import Circuits, Damping, Elasticity, Electromagnetic, HeatConduction, Inertia, PrescribedLorentz
from .terms.electromagnetic import field_at

__all__ = ["BeamModel"]


def _expand_isotropic(Me):
    E, naf, _ = Me.shape
    return np.einsum("eab,im->eaibm", Me, np.eye(3)).reshape(E, naf, 3, naf, 3)


class BeamModel:
    def __init__(
        self,
        mesh: FibrilMesh,
        material: BeamMaterial,
        *,
        disk_points: int = 4,
        axial_points: int | None = None,
        fields=("mech",),
        bcs: list[DirichletBC] | None = None,
        prescribed_current: PrescribedCurrent | None = None,
        couplings: Couplings | None = None,
        circuits: list[CircuitBC] | tuple = (),
        field_ramp=None,
    ):
        self.mesh = mesh
        self.material = material
        self.basis = BeamBasis(mesh, disk_points, axial_points)
        self.layout = DofLayout(mesh.n_nodes, fields)
        self.pattern = ElementPattern(self.layout, mesh.conn)
        self.n = self.layout.n
        self.mech = self.layout.mech
        self.bcs = list(bcs or [])
        self.prescribed_current = prescribed_current
        self.has_T = self.layout.has("T")
        self.has_V = self.layout.has("V")
        self.oT = self.layout.offset.get("T")
        self.oV = self.layout.offset.get("V")
        self.couplings = couplings if couplings is not None else Couplings(
            lorentz=False, back_emf=False, joule=False, seebeck=False, thermal_softening=False)
        self.active = resolve_couplings(self.couplings, material, self.layout)
        self.B = np.asarray(self.couplings.B, float)
        #: optional t -> factor on B (a smooth switch-on of the field); None: B constant
        self.field_ramp = field_ramp
        self.circuits = list(circuits)
        if circuits and "V" not in tuple(fields):
            raise ValueError("circuit boundary conditions need the 'V' field")
        if self.has_V and not material.electrical_conductivity > 0:
            raise ValueError("the 'V' field needs electrical_conductivity > 0")
        mu, lam = lame(material.youngs_modulus, material.poisson_ratio)
        self.mu, self.lam = float(mu), float(lam)
        self.ops = section_ops(self.basis) if (self.has_T or self.has_V) else None
        self.terms = self._terms()
        self.assembler = Assembler(self.layout, self.pattern, self.basis, self.terms)
        self._M = self.assembler.mass()
        #: row scale of the equations (``with_row_scale``), None: unscaled
        self.row_scale: RowScale | None = None
        self.stats = {"assemblies": 0}

    def _terms(self) -> list:
        """The model's terms, in the order of the sums (module docstring)."""
        mat, a = self.material, self.active
        E = self.mesh.n_elements
        terms = [Elasticity(self.basis, self.mu, self.lam,
                            mat.alpha_mu if a["thermal_softening"] else 0.0, self.ops)]
        if self.prescribed_current is not None:
            pc = self.prescribed_current
            terms.append(PrescribedLorentz(self.basis, pc.current[self.mesh.elem_fibril], pc.B))
        if self.has_T:
            terms.append(HeatConduction(self.ops, mat.thermal_conductivity, E))
        if self.has_V:
            terms.append(Electromagnetic(self.ops, mat.electrical_conductivity, self.B, a, mat.seebeck,
                                         self.field_ramp))
        Mm = _expand_isotropic(mass_matrix(self.basis, 1.0) * mat.density)  # consistent mass (E, naf, 3, naf, 3)
        if mat.damping > 0:
            terms.append(Damping(Mm, mat.damping / mat.density, assembled=not (self.has_T or self.has_V)))
        cap = capacity_matrix(self.ops, mat.density * mat.heat_capacity) if self.has_T else None
        terms.append(Inertia(Mm, cap))
        if self.circuits:
            terms.append(Circuits(self.layout, self.circuits))
        return terms

    def with_row_scale(self, scale) -> "BeamModel":
        """A shallow copy of the model whose equations (rows of M, F, Fx, Fw) are multiplied
        by ``scale`` inside the assembler (what ``RowScaledSystem`` does, without rebuilding
        sparse matrices every call). Same solutions; Newton's norms weigh every field in its
        own unit (``row_scales``)."""
        m = copy.copy(self)
        m.row_scale = rs = RowScale(scale, self.pattern)
        pat = self.pattern
        M = sp.csr_matrix(self._M)
        if M.nnz == pat.nnz and np.array_equal(M.indices, pat.indices) and np.array_equal(M.indptr, pat.indptr):
            m._M = sp.csr_matrix((M.data * rs.data, pat.indices, pat.indptr), shape=M.shape)
        else:  # pragma: no cover - the mass matrix always has the element pattern
            m._M = (sp.diags(rs.s) @ M).tocsr()
        m.stats = {"assemblies": 0}
        return m

    def dof_counts(self) -> dict:
        """Dofs per field and in total (for run summaries)."""
        out = {f: int(self.mesh.n_nodes * (9 if f == "mech" else 1)) for f in self.layout.fields}
        out["total"] = int(self.n)
        return out

    def nodal(self, u):
        return self.layout.as_nodal(u)

    def field_dofs(self, field: str, nodes=None) -> np.ndarray:
        return self.layout.field_dofs(field, nodes)

    def element_fields(self, x, w):
        """(U, Uv, Te, Ve) element arrays of a state (Te/Ve None without the field)."""
        s = ElementState(self.basis, self.layout, x, w, None)
        return s.U, s.Uv, s.T, s.V

    # ------------------------------------------------------------------ DynamicSystem
    def mass(self):
        return self._M

    def constraints(self, t):
        if not self.bcs:
            return np.zeros(0, int), np.zeros(0)
        idx = np.concatenate([bc.dofs for bc in self.bcs])
        val = np.concatenate([bc(t) for bc in self.bcs])
        return idx, val

    def admissible(self, x) -> bool:
        """det F > 0 at every quadrature point (same as ``basis.min_det_F(x) > 0``); by the
        compiled pass (``rve.kernels.beam.min_det_F``) when ``rve.kernels.use_numba()``."""
        from ..kernels import use_numba

        if use_numba():
            from ..kernels.beam import min_det_F

            return bool(min_det_F(self.basis.D, self.nodal(x), self.basis.mesh.conn) > 0.0)
        U = self.basis.element_values(self.nodal(x))
        F = np.matmul(self.basis.D, U[:, None, :, :])  # F^T, same determinant
        return bool(det3(F).min() > 0.0)

    def field(self, t=None) -> np.ndarray:
        """B at time t (the full B when t is None or there is no ramp)."""
        return field_at(self.B, self.field_ramp, t)

    def assemble(self, x, w, t, jacobian: bool = True):
        """The assembler's ``Evaluation`` (F, Fx, Fw, fw_constant) with the model's row scale."""
        self.stats["assemblies"] += 1
        return self.assembler.evaluate(x, w, t, jacobian, self.row_scale)

    def evaluate(self, x, w, t, jacobian: bool = True):
        ev = self.assemble(x, w, t, jacobian)
        return ev.F, ev.Fx, ev.Fw

    # ------------------------------------------------------------------ post-processing
    def _emf(self, x, w, t):
        if not self.has_V:
            raise ValueError("no 'V' field: the current is not a model unknown")
        state = ElementState(self.basis, self.layout, x, w, t)
        return self.assembler.term("electromagnetic").emf(state, self.field(t))

    def axial_current(self, x, w, t=None) -> np.ndarray:
        """Current through the section at every axial Gauss point, (E, ng), in A."""
        return axial_current(self.ops, self._emf(x, w, t), self.material.electrical_conductivity)

    def end_currents(self, x, w, t=None) -> np.ndarray:
        """Current leaving every fibril through its (first, last) end node, (n_fibrils, 2), in A.

        It is minus the conduction part of the V equation at the end node (the weak form
        -int delta V' I + sum_ends delta V I_out = 0); at a Dirichlet end it is the reaction
        current, at a circuit end it equals area (r_bar V + J_bar) at convergence."""
        RV, _ = potential_equation(self.ops, self._emf(x, w, t), self.material.electrical_conductivity, False)
        rv = np.bincount(self.mesh.conn.ravel(), weights=RV.ravel(), minlength=self.mesh.n_nodes)
        out = np.zeros((self.mesh.n_fibrils, 2))
        for f in range(self.mesh.n_fibrils):
            n0, n1 = self.mesh.end_nodes(f)
            out[f] = -rv[n0], -rv[n1]
        return out

    def joule_power(self, x, w, t=None) -> np.ndarray:
        """Nodal Joule heat input int N_a sigma0 e^2 dV0 (W), (n_nodes,)."""
        Q = joule_source(self.ops, self._emf(x, w, t), self.material.electrical_conductivity)
        return np.bincount(self.mesh.conn.ravel(), weights=Q.ravel(), minlength=self.mesh.n_nodes)

    def joule_power_fused(self, x, w, t=None) -> np.ndarray:
        """``joule_power`` by the compiled fused kernel the monolithic solve takes its Joule
        rows from (``rve.kernels.electric.coupled_forms``: no Lorentz force, no tangents) when
        ``rve.kernels.use_numba()``, else the numpy reference ``joule_power`` (the two agree to
        rounding). Needs the electromagnetic term."""
        from ..kernels import use_numba

        if not use_numba():
            return self.joule_power(x, w, t)
        from ..kernels.electric import coupled_forms as compiled

        em = self.assembler.term("electromagnetic")
        a = em.active
        st = ElementState(self.basis, self.layout, x, w, t)
        S = em.seebeck if a["seebeck"] else 0.0
        R, _ = compiled(self.ops, st.U, st.Uv if a["back_emf"] else None, st.T if S else None, st.V,
                        self.field(t), self.material.electrical_conductivity, S, a["back_emf"], False, True, False)
        return np.bincount(self.mesh.conn.ravel(), weights=-R["T"].ravel(), minlength=self.mesh.n_nodes)

    def row_scales(self, t_ref: float, x, w) -> np.ndarray:
        """Positive row scales (Jacobi scaling of the nominal stage matrix
        ``M + t_ref Fw + t_ref^2 Fx`` at the state (x, w)): the scaled stage residual of row i
        is then about the Newton error of w_i in its own unit (mm/ms, 1/ms, K, V), whatever
        the mass, stiffness or conductance behind it. See ``RowScaledSystem``."""
        _, Fx, Fw = self.evaluate(x, w, 0.0, jacobian=True)
        A = abs(self._M) + t_ref * abs(Fw) + t_ref**2 * abs(Fx)
        d = np.abs(A.diagonal())
        rs = np.asarray(A.sum(axis=1)).ravel()
        d = np.where(d > 1e-12 * rs, d, rs)
        s = np.ones(self.n)
        pos = d > 0
        s[pos] = 1.0 / d[pos]
        return s
