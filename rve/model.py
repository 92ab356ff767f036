"""The assembled fibril model: M dw/dt + F(x, w, t) = 0 over all fibrils of a scene.

Contract
--------
``BeamModel`` implements the ``DynamicSystem`` protocol of ``rve.solvers.system``:
``n``, ``mech``, ``mass()``, ``evaluate(x, w, t, jacobian)``, ``constraints(t)``,
``admissible(x)``. x and w are flat arrays in the node-interleaved layout of
``rve.fem.assembly.DofLayout``: per node w = [v (9), T, V] restricted to the declared
fields (x is a placeholder, kept 0, at T and V dofs).

A scene declares what it needs and only that is assembled (SPEC §4 "skip what a scene
doesn't need"):

* ``fields``: ("mech",), ("mech", "V"), ("mech", "T"), ("mech", "T", "V");
* ``couplings``: a ``Couplings`` with the field B and the flags ``lorentz`` (force of the
  conduction current), ``back_emf`` (v x B in the current), ``joule`` (heat source),
  ``seebeck`` (-S T' in the current), ``thermal_softening`` (mu(T) = mu0 + alpha_mu T). A
  flag that needs a field the scene did not declare is an error naming both. Flags whose
  coefficient is zero (S = 0, alpha_mu = 0, B = 0) are dropped (``active`` lists the rest).
  ``feedback_from_temperature(material, couplings)`` tells a scene whether T feeds back
  (otherwise T can be post-solved: ``ThermalPostSystem``).

Terms: Neo-Hookean elasticity (mu(T) if softening), consistent mass rho (mech) and heat
capacity rho c_p (T), no mass for V (a DAE), volumetric damping -gamma v, conduction
k0 (T), current conservation (V) with Dirichlet or circuit ends (``CircuitBC``: the current
leaving through an end is ``area (r_bar V + J_bar)``, thesis eq. 2.8.2 with the outward
normal), Lorentz force of the conduction current, Joule heating, and the Lorentz force of
a prescribed current (static wire, no V field). Every term has its exact tangent:
``Fx`` (position columns), ``Fw`` (velocity, T and V columns). Forms: rve.physics.*;
derivation: docs/coupled_fields.md.

Also here: ``RowScaledSystem`` (equilibrates the rows of a system for the Newton norms)
and ``ThermalPostSystem`` (the heat equation alone, driven by a stored Joule history).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .fem.assembly import DofLayout, ElementPattern
from .fem.basis import BeamBasis
from .fem.mesh import FibrilMesh
from .physics.beam_forms import lorentz_force, mass_matrix
from .physics.electric_forms import axial_current, coupled_forms, emf, potential_equation, section_ops
from .physics.elasticity import lame
from .physics.thermal_forms import (
    capacity_matrix, conduction, joule_source, temperature_at_quadrature,
)

__all__ = ["BeamMaterial", "DirichletBC", "PrescribedCurrent", "Couplings", "CircuitBC", "BeamModel",
           "feedback_from_temperature", "RowScaledSystem", "ThermalPostSystem"]


def _det3(F):
    a, b, c = F[..., 0, 0], F[..., 0, 1], F[..., 0, 2]
    d, e, f = F[..., 1, 0], F[..., 1, 1], F[..., 1, 2]
    g, h, i = F[..., 2, 0], F[..., 2, 1], F[..., 2, 2]
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def _inv_det3(F):
    """Inverse and determinant of a batch of 3x3 matrices by cofactors (no LAPACK call
    per matrix: ~10x faster than np.linalg.inv on the (E, nq) batches of a fibril)."""
    Ff = F.reshape(F.shape[:-2] + (9,))
    a, b, c, d, e, f, g, h, i = np.moveaxis(Ff, -1, 0)
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    adj = np.stack([A, c * h - b * i, b * f - c * e,
                    B, a * i - c * g, c * d - a * f,
                    C, b * g - a * h, a * e - b * d], axis=-1)
    inv = (adj / det[..., None]).reshape(F.shape)
    return inv, det


_DTD = {}


def _DtD_cache(basis: BeamBasis) -> np.ndarray:
    key = id(basis)
    hit = _DTD.get(key)
    if hit is None or hit[0] is not basis:
        if len(_DTD) > 32:
            _DTD.clear()
        DD = np.matmul(np.swapaxes(basis.D, 2, 3), basis.D)  # (E, nq, naf, naf)
        hit = _DTD[key] = (basis, DD)
    return hit[1]


def neo_hookean_element_forces(basis: BeamBasis, U, mu, lam, want_tangent: bool = True, want_dmu: bool = False):
    """Neo-Hookean internal force of all elements with mu per quadrature point, in a form
    that costs a few batched matmuls (the coupled scenes call it thousands of times).

    Same result as ``rve.physics.beam_forms.internal_force`` (tested to rounding), using the
    structure of the tangent: with G = D^T F^-1 ... precisely G[a, k] = sum_J D[J, a] Finv[J, k],
    H[a, i] = sum_J D[J, a] F[i, J]:
        R[a, i]       = sum_q W (mu H + (lam ln J - mu) G)[a, i]
        K[a, i, b, k] = sum_q W (mu delta_ik (D^T D)[a, b] + (mu - lam ln J) G[a,k] G[b,i] + lam G[a,i] G[b,k])
        dR/dmu_q      = W (H - G)  (returned as (E, nq, naf, 3) when ``want_dmu``).
    Returns (R (E, naf, 3), K (E, naf, 3, naf, 3) or None, dRdmu or None)."""
    D, W = basis.D, basis.W  # (E, nq, 3, naf), (E, nq)
    E, nq, _, naf = D.shape
    mu = np.broadcast_to(np.asarray(mu, float), (E, nq))
    lam = np.broadcast_to(np.asarray(lam, float), (E, nq))
    Dt = np.swapaxes(D, 2, 3)  # (E, nq, naf, 3)
    F = np.swapaxes(np.matmul(D, U[:, None, :, :]), -1, -2)  # (E, nq, i, J)
    Finv, det = _inv_det3(F)
    lnJ = np.log(det)
    G = np.matmul(Dt, Finv)  # (E, nq, naf, 3)
    H = np.matmul(Dt, np.swapaxes(F, -1, -2))  # (E, nq, naf, 3)
    c1 = mu - lam * lnJ
    R = np.einsum("eqai,eq->eai", H, W * mu) - np.einsum("eqai,eq->eai", G, W * c1)
    dR = (H - G) * W[:, :, None, None] if want_dmu else None
    if not want_tangent:
        return R, None, dR
    Gf = G.reshape(E, nq, naf * 3)
    Gc1 = Gf * (W * c1)[:, :, None]
    # accumulate in the layout [a, k, b, i] (the c1 term is a plain matmul there); the
    # returned [a, i, b, k] is a transposed view (the caller's reshape copies it once)
    Kt = np.matmul(np.swapaxes(Gc1, 1, 2), Gf).reshape(E, naf, 3, naf, 3)
    if np.any(lam != 0):
        Gl = Gf * (W * lam)[:, :, None]
        Kt += np.matmul(np.swapaxes(Gl, 1, 2), Gf).reshape(E, naf, 3, naf, 3).transpose(0, 1, 4, 3, 2)
    DD = _DtD_cache(basis)  # (E, nq, naf, naf): sum_J D[J, a] D[J, b] per quadrature point
    DtD = np.matmul((W * mu)[:, None, :], DD.reshape(E, nq, naf * naf)).reshape(E, naf, naf)
    for i in range(3):
        Kt[:, :, i, :, i] += DtD
    K = Kt.transpose(0, 1, 4, 3, 2)
    return R, K, dR


@dataclass(frozen=True)
class BeamMaterial:
    youngs_modulus: float
    poisson_ratio: float = 0.0
    density: float = 1e-3
    damping: float = 0.0  # volumetric gamma: force density -gamma v
    electrical_conductivity: float = 0.0  # sigma0 (S/mm), reference configuration
    seebeck: float = 0.0  # S (V/K)
    heat_capacity: float = 0.0  # c_p (mJ/(g K)); rho c_p is the volumetric capacity
    thermal_conductivity: float = 0.0  # k0 (W/(mm K)), reference configuration
    alpha_mu: float = 0.0  # d mu / d T (MPa/K)

    def __post_init__(self):
        if not self.youngs_modulus > 0:
            raise ValueError(f"youngs_modulus must be > 0, got {self.youngs_modulus}")
        if not 0 <= self.poisson_ratio < 0.5:
            raise ValueError(f"poisson_ratio must be in [0, 0.5), got {self.poisson_ratio}")
        if not self.density > 0:
            raise ValueError(f"density must be > 0, got {self.density}")
        for name in ("damping", "electrical_conductivity", "heat_capacity", "thermal_conductivity"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


@dataclass
class DirichletBC:
    """Prescribed w at ``dofs``: a velocity on mechanical dofs, a value on T or V dofs.

    ``value(t)`` returns an array of len(dofs) (or a scalar)."""

    dofs: np.ndarray
    value: object = 0.0

    def __call__(self, t):
        v = self.value(t) if callable(self.value) else self.value
        return np.broadcast_to(np.asarray(v, float), (len(self.dofs),))


@dataclass
class PrescribedCurrent:
    """Lorentz load of a known current along the centroid (no potential field)."""

    current: np.ndarray  # per fibril (A)
    B: np.ndarray  # (3,) kT


@dataclass(frozen=True)
class Couplings:
    """Which coupling terms a scene declares (see the module docstring)."""

    B: tuple = (0.0, 0.0, 0.0)  # kT
    lorentz: bool = True
    back_emf: bool = True
    joule: bool = True
    seebeck: bool = True
    thermal_softening: bool = True


@dataclass(frozen=True)
class CircuitBC:
    """Mixed circuit condition on a fibril end (thesis eq. 2.8.2, outward normal): the
    current leaving the fibril through the end at ``node`` is ``area * (r_bar V + J_bar)``.

    A passive resistor R from the end to a terminal held at ``V_ext``: ``resistor(...)``."""

    node: int
    r_bar: float
    J_bar: float
    area: float

    @classmethod
    def resistor(cls, node: int, resistance: float, V_ext: float, area: float) -> "CircuitBC":
        if not resistance > 0:
            raise ValueError(f"circuit resistance must be > 0, got {resistance}")
        return cls(int(node), 1.0 / (resistance * area), -V_ext / (resistance * area), float(area))


def feedback_from_temperature(material: BeamMaterial, couplings: Couplings) -> bool:
    """True when T enters the mechanics or the electrics (mu(T) or the Seebeck EMF)."""
    return bool((couplings.thermal_softening and material.alpha_mu != 0.0)
                or (couplings.seebeck and material.seebeck != 0.0))


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
        self.active = self._resolve_couplings(self.couplings, material)
        self.B = np.asarray(self.couplings.B, float)
        #: optional t -> factor on B (a smooth switch-on of the field); None: B constant
        self.field_ramp = field_ramp
        self.circuits = list(circuits)
        if circuits and "V" not in tuple(fields):
            raise ValueError("circuit boundary conditions need the 'V' field")
        if self.has_V and not material.electrical_conductivity > 0:
            raise ValueError("the 'V' field needs electrical_conductivity > 0")
        self.mu, self.lam = lame(material.youngs_modulus, material.poisson_ratio)
        self.mu = float(self.mu)
        self.lam = float(self.lam)
        self.ops = section_ops(self.basis) if (self.has_T or self.has_V) else None
        nn, b = self.basis.nn, self.layout.block
        self._Me = mass_matrix(self.basis, 1.0)  # unit-density consistent mass (E, naf, naf)
        Mm = self._expand_isotropic(self._Me * material.density)
        self._M_mech = self._assemble_mech_matrix(Mm)
        Me = self._embed_matrix(Mm).reshape(-1, nn, b, nn, b).copy()
        if self.has_T:
            rho_cp = material.density * material.heat_capacity
            Me[:, :, self.oT, :, self.oT] = capacity_matrix(self.ops, rho_cp)
            self._KTT = conduction(self.ops, material.thermal_conductivity, np.zeros((mesh.n_elements, nn)))[1]
        self._M = self.pattern.assemble_matrix(Me.reshape(-1, nn * b, nn * b)) if self.has_T else self._M_mech
        self._C = (self._M_mech * (material.damping / material.density)).tocsr() if material.damping > 0 else None
        # damping as element arrays too, so that Fw keeps the element pattern's CSR structure
        self._Ce = (Mm * (material.damping / material.density)).reshape(-1, nn, 9, nn, 9) \
            if material.damping > 0 else None
        if self.circuits:
            idx = np.array([self.layout.dof(c.node, self.oV) for c in self.circuits])
            self._circ_idx = idx
            self._circ_r = np.array([c.area * c.r_bar for c in self.circuits])
            self._circ_J = np.array([c.area * c.J_bar for c in self.circuits])
            ip, ind = self.pattern.indptr, self.pattern.indices
            self._circ_slot = np.array([ip[i] + int(np.flatnonzero(ind[ip[i]:ip[i + 1]] == i)[0]) for i in idx])
        self._csr_template = self.pattern.assemble_matrix(np.zeros((mesh.n_elements, (nn * b) ** 2)))
        self._rs = None  # row scale (see with_row_scale)
        self._rs_data = None
        self.stats = {"assemblies": 0}

    def with_row_scale(self, scale) -> "BeamModel":
        """A shallow copy of the model whose equations (rows of M, F, Fx, Fw) are multiplied
        by ``scale`` inside the kernel (what ``RowScaledSystem`` does, without rebuilding
        sparse matrices every call). Same solutions; Newton's norms weigh every field in its
        own unit (``row_scales``)."""
        import copy

        m = copy.copy(self)
        m._rs = np.asarray(scale, float).copy()
        pat = self.pattern
        rows = np.repeat(np.arange(self.n), np.diff(pat.indptr))
        m._rs_data = m._rs[rows]
        M = sp.csr_matrix(self._M)
        if M.nnz == pat.nnz and np.array_equal(M.indices, pat.indices) and np.array_equal(M.indptr, pat.indptr):
            m._M = sp.csr_matrix((M.data * m._rs_data, pat.indices, pat.indptr), shape=M.shape)
        else:  # pragma: no cover - the mass matrix always has the element pattern
            m._M = (sp.diags(m._rs) @ M).tocsr()
        m._C_scaled = None
        m.stats = {"assemblies": 0}
        return m

    # ------------------------------------------------------------------ couplings
    def _resolve_couplings(self, c: Couplings, mat: BeamMaterial) -> dict:
        need = {"lorentz": ("V",), "back_emf": ("V",), "joule": ("T", "V"), "seebeck": ("T", "V"),
                "thermal_softening": ("T",)}
        coef = {"lorentz": np.any(np.asarray(c.B, float) != 0), "back_emf": np.any(np.asarray(c.B, float) != 0),
                "joule": True, "seebeck": mat.seebeck != 0.0, "thermal_softening": mat.alpha_mu != 0.0}
        active = {}
        for name, fields in need.items():
            want = bool(getattr(c, name))
            missing = [f for f in fields if not self.layout.has(f)]
            if want and missing and (name not in ("seebeck", "thermal_softening") or coef[name]):
                raise ValueError(f"coupling {name!r} needs the field(s) {missing}, which the scene did not "
                                 f"declare (fields = {self.layout.fields})")
            active[name] = bool(want and not missing and coef[name])
        return active

    def dof_counts(self) -> dict:
        """Dofs per field and in total (for run summaries)."""
        out = {f: int(self.mesh.n_nodes * (9 if f == "mech" else 1)) for f in self.layout.fields}
        out["total"] = int(self.n)
        return out

    # ------------------------------------------------------------------ layout helpers
    def _expand_isotropic(self, Me):
        E, naf, _ = Me.shape
        return np.einsum("eab,im->eaibm", Me, np.eye(3)).reshape(E, naf, 3, naf, 3)

    def _embed_vector(self, Rm):
        E = Rm.shape[0]
        nn, b = self.basis.nn, self.layout.block
        if b == 9:
            return Rm.reshape(E, nn * 9)
        out = np.zeros((E, nn, b))
        out[:, :, :9] = Rm.reshape(E, nn, 9)
        return out

    def _embed_matrix(self, Km):
        E = Km.shape[0]
        nn, b = self.basis.nn, self.layout.block
        if b == 9:
            return Km.reshape(E, nn * 9, nn * 9)
        out = np.zeros((E, nn, b, nn, b))
        out[:, :, :9, :, :9] = Km.reshape(E, nn, 9, nn, 9)
        return out

    def _assemble_mech_matrix(self, Km):
        return self.pattern.assemble_matrix(self._embed_matrix(Km))

    def _pattern_csr(self, Ke):
        """Assemble element matrices (E, nn, b, nn, b) into a CSR matrix that shares the
        pattern's index arrays: a shallow copy of a template with new data (building a
        csr_matrix validates its structure every time, which costs more than the sum)."""
        import copy

        data = np.bincount(self.pattern.slot, weights=Ke.reshape(-1), minlength=self.pattern.nnz)
        A = copy.copy(self._csr_template)
        A.data = data
        return A

    def nodal(self, u):
        return self.layout.as_nodal(u)

    def field_dofs(self, field: str, nodes=None) -> np.ndarray:
        return self.layout.field_dofs(field, nodes)

    def element_fields(self, x, w):
        """(U, Uv, Te, Ve) element arrays of a state (Te/Ve None without the field)."""
        xn, wn = self.nodal(x), self.nodal(w)
        conn = self.mesh.conn
        U = self.basis.element_values(xn)
        Uv = self.basis.element_values(wn)
        Te = wn[:, self.oT][conn] if self.has_T else None
        Ve = wn[:, self.oV][conn] if self.has_V else None
        return U, Uv, Te, Ve

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
        """det F > 0 at every quadrature point (same as ``basis.min_det_F(x) > 0``)."""
        U = self.basis.element_values(self.nodal(x))
        F = np.matmul(self.basis.D, U[:, None, :, :])  # F^T, same determinant
        return bool(_det3(F).min() > 0.0)

    def field(self, t=None) -> np.ndarray:
        """B at time t (the full B when t is None or there is no ramp)."""
        if self.field_ramp is None or t is None:
            return self.B
        return self.B * float(self.field_ramp(t))

    def _emf(self, U, Uv, Te, Ve, B=None):
        a = self.active
        zeros = np.zeros_like(Ve)
        return emf(self.ops, U, Uv, Te if Te is not None else zeros, Ve, self.B if B is None else B,
                   seebeck=self.material.seebeck if a["seebeck"] else 0.0, back_emf=a["back_emf"])

    def evaluate(self, x, w, t, jacobian: bool = True):
        self.stats["assemblies"] += 1
        if not (self.has_T or self.has_V):
            return self._evaluate_mech(x, w, jacobian)
        a = self.active
        mat = self.material
        E, nn, b = self.mesh.n_elements, self.basis.nn, self.layout.block
        oT, oV = self.oT, self.oV
        U, Uv, Te, Ve = self.element_fields(x, w)
        # --- mechanics: mu(T)
        mu = self.mu
        soft = a["thermal_softening"]
        if soft:
            mu = self.mu + mat.alpha_mu * temperature_at_quadrature(self.ops, Te)
        Rm, Km, dRdmu = neo_hookean_element_forces(self.basis, U, mu, self.lam, jacobian, soft and jacobian)
        Re = np.zeros((E, nn, b))
        Kx = np.zeros((E, nn, b, nn, b)) if jacobian else None
        Kw = np.zeros((E, nn, b, nn, b)) if jacobian else None
        Re[:, :, :9] = Rm.reshape(E, nn, 9)
        if jacobian:
            Kx[:, :, :9, :, :9] = Km.reshape(E, nn, 9, nn, 9)
            if soft:
                # d R_int / d T_b = alpha_mu sum_q (dR/dmu_q) N_b(q)
                G = dRdmu.reshape(E, -1, nn * 9).transpose(0, 2, 1)  # (E, af*i, q)
                Kw[:, :, :9, :, oT] = (mat.alpha_mu * np.matmul(G, self.ops.Nq)).reshape(E, nn, 9, nn)
        if self.prescribed_current is not None:
            I = self.prescribed_current.current[self.mesh.elem_fibril]
            Rl, Kl = lorentz_force(self.basis, U, I, self.prescribed_current.B, jacobian)
            Re[:, :, :9] += Rl.reshape(E, nn, 9)
            if jacobian:
                Kx[:, :, :9, :, :9] += Kl.reshape(E, nn, 9, nn, 9)
        # --- heat conduction
        if self.has_T:
            Re[:, :, oT] += np.einsum("eab,eb->ea", self._KTT, Te)
            if jacobian:
                Kw[:, :, oT, :, oT] += self._KTT
        # --- electrics: current conservation, Lorentz force, Joule heat (one fused kernel)
        if self.has_V:
            sig = mat.electrical_conductivity
            Bt = self.field(t)
            m = self._emf(U, Uv, Te, Ve, Bt)
            R, J = coupled_forms(self.ops, m, sig, Bt, lorentz=a["lorentz"], joule=a["joule"],
                                 want_tangent=jacobian)
            Re[:, :, oV] += R["V"]
            if a["joule"]:
                Re[:, :, oT] += R["T"]
            if a["lorentz"]:
                Re[:, :, :9] += R["L"].reshape(E, nn, 9)
            if jacobian:
                S = m.seebeck
                rows = [(oV, slice(0, nn))]
                if a["joule"]:
                    rows.append((oT, slice(nn, 2 * nn)))
                for o, sl in rows:
                    if J["Sx"] is not None:
                        Kx[:, :, o, :, :9] += J["Sx"][:, sl].reshape(E, nn, nn, 9)
                        Kw[:, :, o, :, :9] += J["Sv"][:, sl].reshape(E, nn, nn, 9)
                    bV = J["SV"][:, sl]
                    Kw[:, :, o, :, oV] += bV
                    if S:
                        Kw[:, :, o, :, oT] += S * bV
                if a["lorentz"]:
                    Kx[:, :, :9, :, :9] += J["Lx"].reshape(E, nn, 9, nn, 9)
                    if J["Lv"] is not None:
                        Kw[:, :, :9, :, :9] += J["Lv"].reshape(E, nn, 9, nn, 9)
                    bV = J["LV"].reshape(E, nn, 9, nn)
                    Kw[:, :, :9, :, oV] += bV
                    if S:
                        Kw[:, :, :9, :, oT] += S * bV
        if self._Ce is not None:  # damping -gamma v, element by element (no sparse mat-vec)
            Re[:, :, :9] += np.matmul(self._Ce.reshape(E, nn * 9, nn * 9), Uv.reshape(E, nn * 9, 1)).reshape(E, nn, 9)
        F = self.pattern.assemble_vector(Re)
        if self.circuits:
            F[self._circ_idx] += self._circ_r * w[self._circ_idx] + self._circ_J
        if self._rs is not None:
            F *= self._rs
        if not jacobian:
            return F, None, None
        if self._Ce is not None:
            Kw[:, :, :9, :, :9] += self._Ce
        # Fx, Fw (and M) share the element pattern's CSR structure (fast path of FreeDofs.combine)
        Fx = self._pattern_csr(Kx)
        Fw = self._pattern_csr(Kw)
        if self.circuits:
            Fw.data[self._circ_slot] += self._circ_r
        if self._rs is not None:
            Fx.data *= self._rs_data
            Fw.data *= self._rs_data
        return F, Fx, Fw

    def _evaluate_mech(self, x, w, jacobian):
        U = self.basis.element_values(self.nodal(x))
        Rm, Km, _ = neo_hookean_element_forces(self.basis, U, self.mu, self.lam, jacobian)
        if self.prescribed_current is not None:
            I = self.prescribed_current.current[self.mesh.elem_fibril]
            Rl, Kl = lorentz_force(self.basis, U, I, self.prescribed_current.B, jacobian)
            Rm = Rm + Rl
            if jacobian:
                Km = Km + Kl
        F = self.pattern.assemble_vector(self._embed_vector(Rm))
        if self._C is not None:
            F = F + self._C @ w
        if self._rs is not None:
            F *= self._rs
        if not jacobian:
            return F, None, None
        Fx = self._assemble_mech_matrix(Km)
        Fw = self._C if self._C is not None else sp.csr_matrix((self.n, self.n))
        if self._rs is not None:
            Fx.data *= self._rs_data
            if self._C is not None:
                if getattr(self, "_C_scaled", None) is None:
                    self._C_scaled = (sp.diags(self._rs) @ self._C).tocsr()
                Fw = self._C_scaled
        return F, Fx, Fw

    # ------------------------------------------------------------------ post-processing
    def axial_current(self, x, w, t=None) -> np.ndarray:
        """Current through the section at every axial Gauss point, (E, ng), in A."""
        if not self.has_V:
            raise ValueError("no 'V' field: the current is not a model unknown")
        U, Uv, Te, Ve = self.element_fields(x, w)
        return axial_current(self.ops, self._emf(U, Uv, Te, Ve, self.field(t)), self.material.electrical_conductivity)

    def end_currents(self, x, w, t=None) -> np.ndarray:
        """Current leaving every fibril through its (first, last) end node, (n_fibrils, 2), in A.

        It is minus the conduction part of the V equation at the end node (the weak form
        -int delta V' I + sum_ends delta V I_out = 0); at a Dirichlet end it is the reaction
        current, at a circuit end it equals area (r_bar V + J_bar) at convergence."""
        U, Uv, Te, Ve = self.element_fields(x, w)
        RV, _ = potential_equation(self.ops, self._emf(U, Uv, Te, Ve, self.field(t)),
                                   self.material.electrical_conductivity, False)
        rv = np.bincount(self.mesh.conn.ravel(), weights=RV.ravel(), minlength=self.mesh.n_nodes)
        out = np.zeros((self.mesh.n_fibrils, 2))
        for f in range(self.mesh.n_fibrils):
            n0, n1 = self.mesh.end_nodes(f)
            out[f] = -rv[n0], -rv[n1]
        return out

    def joule_power(self, x, w, t=None) -> np.ndarray:
        """Nodal Joule heat input int N_a sigma0 e^2 dV0 (W), (n_nodes,)."""
        U, Uv, Te, Ve = self.element_fields(x, w)
        Q = joule_source(self.ops, self._emf(U, Uv, Te, Ve, self.field(t)), self.material.electrical_conductivity)
        return np.bincount(self.mesh.conn.ravel(), weights=Q.ravel(), minlength=self.mesh.n_nodes)

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


class RowScaledSystem:
    """A ``DynamicSystem`` whose equations (rows of M and F) are multiplied by positive
    ``scale``: the same solution, but Newton's residual norm weighs every field in its
    own natural unit (the model's rows are forces, heat flows and currents of very
    different magnitudes). Jacobians are scaled exactly the same way."""

    def __init__(self, system, scale):
        self.system = system
        self.scale = np.asarray(scale, float)
        self.n = system.n
        self.mech = system.mech
        self._rows = {}
        self._M = self._scaled(sp.csr_matrix(system.mass()))

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
        return self._M

    def constraints(self, t):
        return self.system.constraints(t)

    def admissible(self, x) -> bool:
        return self.system.admissible(x)

    def evaluate(self, x, w, t, jacobian: bool = True):
        F, Fx, Fw = self.system.evaluate(x, w, t, jacobian)
        F = F * self.scale
        if not jacobian:
            return F, None, None
        return F, self._scaled(Fx), self._scaled(Fw)

    def __getattr__(self, name):  # everything else (mesh, nodal, ...) from the wrapped model
        return getattr(self.system, name)


class ThermalPostSystem:
    """The heat equation alone, ``M_T dT/dt + K_T T - Q(t) = 0``, driven by a Joule heat
    history Q(t) (nodal, W) sampled at ``times`` and interpolated by a cubic spline
    (O(h^4), so the post-solve keeps the order of the SDIRK schemes up to 3).

    Used when T does not feed back (alpha_mu = 0 and S = 0): the mechanics and electrics are
    integrated without T dofs and T is solved afterwards over the stored states. All dofs
    are T (``mech`` is all False); Dirichlet T at ``fixed_nodes`` with ``fixed_values``."""

    def __init__(self, model: BeamModel, times, Q, fixed_nodes=(), fixed_values=0.0):
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
