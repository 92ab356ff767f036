"""Materials, boundary conditions and coupling declarations of the fibril model.

Contract
--------
``BeamMaterial`` (validated constants, units mm, ms, g, N, MPa, K, V, A, W), ``DirichletBC``
(prescribed w at dofs: a velocity on mechanical dofs, a value on T or V dofs),
``PrescribedCurrent`` (the Lorentz load of a known current, no V field), ``Couplings``
(which coupling terms a scene declares), ``CircuitBC`` (mixed end condition of the V
field, thesis eq. 2.8.2), ``feedback_from_temperature`` (does T feed back?) and
``resolve_couplings`` (the active coupling flags of a layout). Pure data: no assembly here.
Decisions: docs/coupled_fields.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BeamMaterial", "DirichletBC", "PrescribedCurrent", "Couplings", "CircuitBC",
           "feedback_from_temperature", "resolve_couplings"]


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


#: fields each coupling flag needs
_COUPLING_FIELDS = {"lorentz": ("V",), "back_emf": ("V",), "joule": ("T", "V"), "seebeck": ("T", "V"),
                    "thermal_softening": ("T",)}


def resolve_couplings(c: Couplings, mat: BeamMaterial, layout) -> dict:
    """{flag: active} for a ``DofLayout``: a flag is active when declared, its fields exist
    and its coefficient is nonzero. A declared flag whose fields are missing is an error
    naming both (except seebeck / thermal_softening with a zero coefficient)."""
    coef = {"lorentz": np.any(np.asarray(c.B, float) != 0), "back_emf": np.any(np.asarray(c.B, float) != 0),
            "joule": True, "seebeck": mat.seebeck != 0.0, "thermal_softening": mat.alpha_mu != 0.0}
    active = {}
    for name, fields in _COUPLING_FIELDS.items():
        want = bool(getattr(c, name))
        missing = [f for f in fields if not layout.has(f)]
        if want and missing and (name not in ("seebeck", "thermal_softening") or coef[name]):
            raise ValueError(f"coupling {name!r} needs the field(s) {missing}, which the scene did not "
                             f"declare (fields = {layout.fields})")
        active[name] = bool(want and not missing and coef[name])
    return active
