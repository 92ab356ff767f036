"""Config model of the fabric relaxation scene (``scene: fabric_relax``; thesis §7.3-7.4).

Contract: :class:`FabricRelaxConfig` and its sections (fabric, material, contact, mesh,
relaxation, output); the RVE config (``rve.config.rve.RVEConfig``) reuses the
sections. Named in ``rve.scenes.registry.SCENES``; the scene is
``rve.scenes.fabric_relax``. Parameter choices: docs/relaxation.md.
"""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field, field_validator, model_validator

from .fields import (
    ContactConductance, DampingCoefficient, Density, Dimensionless, HeatTransferCoefficient, Integer, Length,
    Penalty, SceneConfig, Section, Stress, Time
)
from .sections import BeamMesh

__all__ = ["FabricRelaxConfig"]

#: line load per unit overlap of the contact penalty (N/mm per mm)


class FabricSpec(Section):
    kind: Literal["plain", "twill_2_1", "twill_2_2", "basket_2_2", "knit"] = Field(
        "plain", description="weave pattern (rve.fabrics.WEAVE_PATTERNS) or the thesis knit")
    n_warp: Integer = Field(4, ge=1, description="warp yarns (weaves)")
    n_weft: Integer = Field(4, ge=1, description="weft yarns (weaves)")
    spacing: Length = Field("2 mm", gt=0, description="yarn spacing (weaves); half-width = n * spacing / 2")
    amplitude: Length = Field("0.525 mm", ge=0, description="crimp amplitude A (weaves)")
    fibril_diameter: Length = Field("0.3 mm", gt=0, description="fibril diameter d = 2R")
    rows: list[Integer] = Field([3, 4, 3], min_length=1, description="fibrils per stack row, bottom to top")
    knit_rows: Integer = Field(3, ge=1, description="courses (knit)")
    knit_loops: Integer = Field(4, ge=1, description="loops per course (knit)")

    @field_validator("rows")
    @classmethod
    def _rows_hold_fibrils(cls, v):
        # here rather than in the fabric generator: the error then names the key
        if any(n < 1 for n in v):
            raise ValueError(f"every stack row must hold >= 1 fibril (got {list(v)})")
        return v


class FabricMaterial(Section):
    youngs_modulus: Stress = Field("1.26 MPa", gt=0, description="Young's modulus E (Table 7.1)")
    poisson_ratio: Dimensionless = Field(0.0, ge=0, lt=0.5, description="Poisson ratio (0 in the thesis)")
    density: Density = Field("1 g/cm^3", gt=0, description="mass density (Table 7.1's '1.0 g/mm^3' read as g/cm^3)")


class FabricContact(Section):
    penalty: Penalty = Field("50 N/mm^2", gt=0, description="P*: penalty line load per unit overlap")
    heat_transfer: HeatTransferCoefficient = Field(
        "0.1 W/(mm^2*K)", ge=0, description="h_C (stored for the probe solves; unused in a mechanics-only relaxation)")
    conductance: ContactConductance = Field(
        "1 A/(mm^2*V)", ge=0, description="sigma_C (stored for the probe solves; unused in relaxation)")
    n_gp: Integer = Field(4, ge=1, description="contact points per element pair")
    margin: Length = Field("0.1 mm", ge=0, description="search cutoff = 2R + margin")
    g_eps: Dimensionless = Field(1e-3, ge=0, description="Hertz width regularisation, fraction of R")
    recompute_closest: bool = Field(True, description="recompute s- at every evaluation (else frozen per rebuild)")
    onset: Dimensionless = Field(
        0.0, ge=0, description="width of the C2 onset of the penalty law, fraction of R (0: the linear law P* g); "
                               "the law of the relaxed state")
    geometry: Literal["chord", "curve", "smooth"] = Field(
        "chord", description="chord: the elements' linear chords, one-sided points, clamped closest point (thesis); "
                             "curve: the Lagrange centroid curves, both sides, closest point continued to the "
                             "neighbour element; smooth: as curve on the C1 Hermite curve through the element end "
                             "nodes with averaged nodal tangents (docs/contact.md)")
    enforcement: Literal["penalty", "augmented_lagrangian"] = Field(
        "penalty", description="penalty (Table 7.1's P*) or augmented Lagrangian (Uzawa multipliers until the "
                               "largest overlap is below al_tolerance R)")
    al_tolerance: Dimensionless = Field(1e-4, gt=0, description="augmented Lagrangian: largest overlap, fraction of R")
    al_max_iter: Integer = Field(20, ge=1, description="augmented Lagrangian: most multiplier updates per solve")
    al_penalty_growth: Dimensionless = Field(
        4.0, ge=1, description="augmented Lagrangian: factor on P* after an update that left more than 1/4 of the "
                               "largest overlap (1: the plain Uzawa loop; docs/contact.md)")
    conductance_law: Literal["width", "holm"] = Field(
        "width", description="width: h_C, sigma_C times the Hertz width (thesis); holm: Holm a-spots of radius "
                             "spot_radius carrying the line load at the hardness")
    hardness: Stress = Field("0 MPa", ge=0, description="holm: hardness H of the contact spots")
    spot_radius: Length = Field("0 mm", ge=0, description="holm: a-spot radius a_s")

    @model_validator(mode="after")
    def _holm_needs_its_constants(self):
        if self.conductance_law == "holm" and not (self.hardness > 0 and self.spot_radius > 0):
            raise ValueError("contact.conductance_law = 'holm' needs contact.hardness > 0 and contact.spot_radius > 0 "
                             f"(got hardness = {self.hardness} MPa, spot_radius = {self.spot_radius} mm)")
        return self


class FabricMesh(BeamMesh):
    """Mesh of the fabric's fibrils (the shared defaults: linear elements, 30 per fibril)."""


class FabricRelaxation(Section):
    method: Literal["energy", "dynamic"] = Field(
        "energy", description="energy: static energy minimisation (trust-region Newton with inertia check, "
                              "continuation in the penalty onset); dynamic: damped backward Euler + capped Newton")
    onset_continuation: list[Dimensionless] = Field(
        [0.05], description="energy: onset widths (fractions of R) of the stages before the final one, "
                                  "which uses contact.onset")
    coarse_elements: Optional[Integer] = Field(
        None, ge=1, description="energy: mesh sequencing, relax first on this many elements per fibril, "
                                "interpolate, finish on mesh.elements (null: target mesh only)")
    coarse_axial_points: Optional[Integer] = Field(
        None, ge=1, description="energy + coarse_elements: Gauss points per element on the coarse mesh (null: as "
                                "mesh.axial_points); 1 relieves the locking of coarse linear elements")
    fine_onset_continuation: Optional[list[Dimensionless]] = Field(
        None, description="energy + coarse_elements: onset stages on the target mesh before the final one "
                          "(null: none, the target mesh starts from the interpolated coarse minimum with contact.onset)")
    energy_max_iter: Integer = Field(300, ge=1, description="energy: Newton iterations per stage")
    backtrack: Integer = Field(3, ge=0, description="energy: step halvings (energy evaluations only) before a "
                                                    "trial is rejected and refactorised with a larger sigma")
    wall_budget_s: Optional[float] = Field(None, gt=0, description="energy: stop after this wall time (s)")
    damping: DampingCoefficient = Field("20 N*ms/mm^4", ge=0, description="volumetric damping gamma (heavy)")
    duration: Time = Field("20 ms", gt=0, description="dynamic relaxation time")
    steps: Integer = Field(40, ge=1, description="backward-Euler steps of the dynamic relaxation")
    rebuild_every: Integer = Field(5, ge=1, description="contact map rebuilt every k steps (thesis: 5)")
    newton_rtol: Dimensionless = Field(1e-6, gt=0, description="stage Newton relative tolerance (relaxation)")
    newton_max_iter: Integer = Field(25, ge=1, description="stage Newton iterations (relaxation)")
    static: bool = Field(True, description="static Newton solve after the dynamic relaxation")
    static_atol: Dimensionless = Field(1e-9, gt=0, description="static Newton absolute tolerance on |F| (N)")
    static_rounds: Integer = Field(4, ge=1, description="static solves, each after a map rebuild, until the map is stable")
    static_max_iter: Integer = Field(40, ge=1, description="Newton iterations per static solve")


class FabricOutput(Section):
    netcdf: bool = Field(True, description="relaxed state as netCDF (relaxed_state.nc)")
    vtk: bool = Field(True, description="tube meshes (.vtp) of the initial and relaxed states + a .pvd series")
    png: bool = Field(True, description="headless render of the relaxed state")
    n_theta: Integer = Field(12, ge=3, description="points per ring of the tube mesh")
    vtk_every: Integer = Field(0, ge=0, description="also write the state every k map rebuilds (0: only start/end)")


class FabricRelaxConfig(SceneConfig):
    """Relax a generated fabric to static equilibrium under contact (thesis §7.3-7.4)."""

    scene: Literal["fabric_relax"] = Field(description="scene name")
    fabric: FabricSpec
    material: FabricMaterial
    contact: FabricContact
    mesh: FabricMesh
    relaxation: FabricRelaxation
    output: FabricOutput
