"""Config sections that several scenes share, subclassed per scene only where a default
differs.

Contract
--------
* ``BeamMesh``: ``order``, ``elements``, ``disk_points``, ``axial_points`` (null: order + 1,
  ``resolved_axial_points``) of the Lagrange beam elements.
* ``LinearMesh``: ``elements`` (linear) and ``disk_points`` of the dynamic fabric scenes.
* ``Newton``: ``atol``, ``rtol``, ``max_iter`` of a Newton solve.
* ``StageNewton``: the stage Newton of the dynamic fabric scenes: ``Newton`` plus
  ``jacobian_reuse`` (modified Newton) and ``reuse_contraction``; each scene adds its
  ``linear_backend`` (the choices differ by scene).
* ``WeaveMaterial``: the beam and field material of the dynamic fabric scenes (E, nu,
  rho, sigma, k, c_p, the volumetric damping gamma; Tables 8.1/8.2).
* ``SceneOutput``: ``vtk``, ``vtk_every``, ``png``, ``frames``, ``n_theta`` of the outputs
  of the dynamic fabric scenes.
* ``WireSceneConfig``: base of the pinned-wire scenes; a subclass names its
  ``dofs_per_node`` and is checked by ``rve.config.limits.wire_feasibility`` (radius
  against length, the mesh against the available memory).
"""
from __future__ import annotations

from typing import ClassVar, Literal, Optional

from pydantic import Field, model_validator

from .fields import (DampingCoefficient, Density, Dimensionless, ElectricConductivity, Integer, SceneConfig,
                     Section, SpecificHeat, Stress, ThermalConductivity)
from .limits import wire_feasibility

__all__ = ["BeamMesh", "LinearMesh", "Newton", "StageNewton", "WeaveMaterial", "SceneOutput", "WireSceneConfig"]


class BeamMesh(Section):
    order: Integer = Field(1, ge=1, le=4, description="Lagrange element order p (all fields)")
    elements: Integer = Field(30, ge=1, description="elements per fibril")
    disk_points: Literal[4, 8, 16] = Field(4, description="points of the unit-disk rule across the section")
    axial_points: Optional[Integer] = Field(
        None, ge=1, description="Gauss-Legendre points per element along the axis; null = order + 1")

    @property
    def resolved_axial_points(self) -> int:
        """``axial_points``, or ``order + 1`` when it is null."""
        return self.order + 1 if self.axial_points is None else self.axial_points


class LinearMesh(Section):
    elements: Integer = Field(30, ge=1, description="linear elements per fibril")
    disk_points: Literal[4, 8, 16] = Field(4, description="points of the unit-disk rule across the section")


class Newton(Section):
    atol: Dimensionless = Field(1e-10, gt=0, description="absolute tolerance on the residual norm")
    rtol: Dimensionless = Field(1e-12, gt=0, description="relative tolerance on the residual norm")
    max_iter: Integer = Field(50, ge=1, description="maximum Newton iterations")


class StageNewton(Newton):
    atol: Dimensionless = Field(1e-9, gt=0, description="absolute tolerance of the row-scaled stage residual")
    max_iter: Integer = Field(20, ge=1, description="Newton iterations per stage")
    jacobian_reuse: Literal[False, True, "auto"] = Field(
        "auto", description="factorisation reuse across stage iterations, stages and steps (modified Newton, "
                            "docs/time_integration.md section 7): false, true or auto (by measured costs)")
    reuse_contraction: Dimensionless = Field(0.5, gt=0, lt=1, description="refactorise when the observed "
                                             "contraction |r_k+1|/|r_k| of a reused factorisation exceeds this")


class WeaveMaterial(Section):
    youngs_modulus: Stress = Field("1.26 MPa", gt=0, description="E")
    poisson_ratio: Dimensionless = Field(0.0, ge=0, lt=0.5, description="nu")
    density: Density = Field("0.00144 g/mm^3", gt=0, description="rho")
    electrical_conductivity: ElectricConductivity = Field("10 S/mm", gt=0, description="sigma")
    thermal_conductivity: ThermalConductivity = Field("1.0 W/(mm*K)", gt=0, description="k")
    heat_capacity: SpecificHeat = Field("1000 J/(kg*K)", gt=0,
                                        description="c_p: not in Tables 8.1/8.2 (chosen, docs/induced_deformation.md)")
    damping: DampingCoefficient = Field(
        "0.1 N*s/m^4", ge=0, description="volumetric gamma; Tables 8.1/8.2's '0.1 N s/m' read per volume as for "
                                         "the dynamic wire (docs/coupled_fields.md); Appendix A's script has 0.01")


class SceneOutput(Section):
    vtk: bool = Field(True, description="write the .pvd series of tube meshes")
    vtk_every: Integer = Field(1, ge=1, description="every k-th stored state goes to the .pvd series")
    png: bool = Field(True, description="render PNG plots and frames (headless)")
    frames: Integer = Field(4, ge=1, description="time frames in the PNG strip")
    n_theta: Integer = Field(12, ge=3, description="points around a tube section")


class WireSceneConfig(SceneConfig):
    """Base of the pinned-wire scenes: radius against length and the mesh against memory
    are checked after validation."""

    #: unknowns per node of the scene's beam model (the memory estimate)
    dofs_per_node: ClassVar[int]

    @model_validator(mode="after")
    def _feasible(self):
        return wire_feasibility(self, self.dofs_per_node)
