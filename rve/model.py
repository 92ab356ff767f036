"""The assembled fibril model: M dw/dt + F(x, w, t) = 0 over all fibrils of a scene.

Contract
--------
``BeamModel`` implements the ``DynamicSystem`` protocol of ``rve.solvers.system``:
``n``, ``mech``, ``mass()``, ``evaluate(x, w, t, jacobian)``, ``constraints(t)``,
``admissible(x)``. x and w are flat arrays in the node-interleaved layout of
``rve.fem.assembly.DofLayout`` (x is a placeholder at T and V dofs).

A scene builds it from a mesh, a ``BeamMaterial`` and a list of terms; only the terms and
fields a scene declares are assembled (SPEC §4 "skip what a scene doesn't need").
Terms implemented here: Neo-Hookean elasticity, consistent mass, volumetric damping
-gamma v (dynamic relaxation), Lorentz force of a prescribed current (static wire).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .fem.assembly import DofLayout, ElementPattern
from .fem.basis import BeamBasis
from .fem.mesh import FibrilMesh
from .physics.beam_forms import internal_force, lorentz_force, mass_matrix
from .physics.elasticity import lame

__all__ = ["BeamMaterial", "DirichletBC", "BeamModel"]


@dataclass(frozen=True)
class BeamMaterial:
    youngs_modulus: float
    poisson_ratio: float = 0.0
    density: float = 1e-3
    damping: float = 0.0  # volumetric gamma: force density -gamma v

    def __post_init__(self):
        if not self.youngs_modulus > 0:
            raise ValueError(f"youngs_modulus must be > 0, got {self.youngs_modulus}")
        if not 0 <= self.poisson_ratio < 0.5:
            raise ValueError(f"poisson_ratio must be in [0, 0.5), got {self.poisson_ratio}")
        if not self.density > 0:
            raise ValueError(f"density must be > 0, got {self.density}")
        if not self.damping >= 0:
            raise ValueError(f"damping must be >= 0, got {self.damping}")


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
        self.mu, self.lam = lame(material.youngs_modulus, material.poisson_ratio)
        self._Me = mass_matrix(self.basis, 1.0)  # unit-density consistent mass (E, naf, naf)
        self._M = self._assemble_mech_matrix(self._expand_isotropic(self._Me * material.density))
        self._C = self._M * (material.damping / material.density) if material.damping > 0 else None
        self.stats = {"assemblies": 0}

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

    def nodal(self, u):
        return self.layout.as_nodal(u)

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
        return self.basis.min_det_F(self.nodal(x)) > 0.0

    def evaluate(self, x, w, t, jacobian: bool = True):
        self.stats["assemblies"] += 1
        U = self.basis.element_values(self.nodal(x))
        Rm, Km = internal_force(self.basis, U, self.mu, self.lam, jacobian)
        if self.prescribed_current is not None:
            I = self.prescribed_current.current[self.mesh.elem_fibril]
            Rl, Kl = lorentz_force(self.basis, U, I, self.prescribed_current.B, jacobian)
            Rm = Rm + Rl
            if jacobian:
                Km = Km + Kl
        F = self.pattern.assemble_vector(self._embed_vector(Rm))
        if self._C is not None:
            F = F + self._C @ w
        if not jacobian:
            return F, None, None
        Fx = self._assemble_mech_matrix(Km)
        Fw = self._C if self._C is not None else sp.csr_matrix((self.n, self.n))
        return F, Fx, Fw
