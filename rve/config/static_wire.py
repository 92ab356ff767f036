"""Config model of the static wire scene (``scene: static_wire``; thesis ch. 3, §6.3).

Contract: :class:`StaticWireConfig` and its sections (geometry, fibril, material, load,
mesh, solver). Named in ``rve.scenes.registry.SCENES``; the scene is
``rve.scenes.static_wire``. Parameter choices: docs/static_solution_path.md,
docs/verification_static_wire.md; the config file is configs/scenes/static_wire.yaml.
"""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, model_validator

from .fields import (
    Angle, CurrentDensity, DampingCoefficient, Density, Dimensionless, Integer, Length, MagneticField,
    Section, Stress, Time, cross_field_error,
)
from .sections import BeamMesh, Newton, WireSceneConfig

__all__ = ["StaticWireConfig", "Geometry", "Fibril", "Material", "WireLoad", "Mesh", "Relaxation", "NewtonSettings",
           "StaticWireSolver"]


class Geometry(Section):
    half_length: Length = Field(1.0, gt=0, description="half length L of the wire (mm); reference X1 in [-L, L]")
    clamp_half_distance: Length = Field(
        0.5, ge=0, description="half distance Delta between the pinned ends (mm); must be < half_length")

    @model_validator(mode="after")
    def _clamp_inside(self):
        if not self.clamp_half_distance < self.half_length:
            raise cross_field_error("clamp_half_distance", "<", "half_length",
                                    self.clamp_half_distance, self.half_length, "mm")
        return self


class Fibril(Section):
    radius: Length = Field(0.02, gt=0, description="fibril radius R (mm)")


class Material(Section):
    youngs_modulus: Stress = Field(0.01, gt=0, description="Young's modulus E (MPa)")
    poisson_ratio: Dimensionless = Field(0.0, ge=0, lt=0.5, description="Poisson ratio nu (0 in all thesis results)")
    density: Density = Field(1e-3, gt=0, description="mass density rho (g/mm^3)")


class WireLoad(Section):
    current_density: CurrentDensity = Field(1.0, description="axial current density J (A/mm^2)")
    field_magnitude: MagneticField = Field("1 T", ge=0, description="magnetic field magnitude |B| (kT)")
    field_angle: Angle = Field(
        "45 deg", description="angle phi between B and the line through the supports (rad)")


class Mesh(BeamMesh):
    order: Integer = Field(2, ge=1, le=4, description="Lagrange element order p along the fibril")
    elements: Integer = Field(40, ge=1, description="number of elements along the fibril")


class Relaxation(Section):
    duration: Time = Field(5.0, gt=0, description="dynamic relaxation time T_max (ms)")
    steps: Integer = Field(50, ge=1, description="time steps of the dynamic relaxation")
    damping: DampingCoefficient = Field(
        2e-3, ge=0, description="volumetric damping coefficient gamma of f = -gamma v (g/(mm^3 ms) = N ms/mm^4)")
    perturbation: Dimensionless = Field(
        0.01, ge=0, description="amplitude of the initial cosine z-offset, as a fraction of half_length")
    coarse_order: Optional[Integer] = Field(
        2, ge=1, le=4, description="relax on a coarse mesh of this order, then prolong (null: relax on the target mesh)")
    coarse_elements: Optional[Integer] = Field(
        8, ge=1, description="elements of the coarse relaxation mesh (null: relax on the target mesh)")


class StaticWireSolver(Section):
    path: Literal["dynamic_relaxation", "continuation"] = Field(
        "dynamic_relaxation",
        description="how the static solution is reached: dynamic relaxation then static Newton, or load continuation")
    relaxation: Relaxation
    newton: Newton


class StaticWireConfig(WireSceneConfig):
    """The pinned wire in a magnetic field (thesis ch. 3, §6.3, Tables 6.1-6.2)."""

    scene: Literal["static_wire"] = Field(description="scene name")
    dofs_per_node = 9
    geometry: Geometry
    fibril: Fibril
    material: Material
    load: WireLoad
    mesh: Mesh
    solver: StaticWireSolver
