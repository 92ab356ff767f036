"""Config model of the impact scene (thesis §8.4, Table 8.2; SPEC §9).

Contract: :class:`ImpactConfig` and its sections. Named in ``rve.scenes.registry.SCENES``;
the scene is ``rve.scenes.impact``. Readings of Table 8.2 and the choices where the thesis
is silent: docs/impact.md.
"""
from __future__ import annotations

from typing import Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from .friction import ImpactFrictionSection
from .fields import (
    CircuitConductance, ContactConductance, CurrentDensity, DampingCoefficient, Density, Dimensionless,
    ElectricConductivity, HeatTransferCoefficient, Integer, Length, MagneticField, Penalty, SceneConfig, Section,
    Stress, Temperature, Time, Velocity, cross_field_error
)
from .sections import LinearMesh, SceneOutput, StageNewton, WeaveMaterial

__all__ = ["ImpactConfig"]



class ImpactGeometry(Section):
    n_warp: Integer = Field(32, ge=1, description="warp yarns (along x, single fibril, current-carrying)")
    n_weft: Integer = Field(32, ge=1, description="weft yarns (along y, single fibril, insulated)")
    span: Length = Field("50.8 mm", gt=0, description="L: distance between the pinned ends of every yarn")
    crimp_clearance: Length = Field(
        "0.01 mm", description="crimped reference: distance of the element chords at the crossings minus "
                                "R_warp + R_weft (> 0: the yarns start apart); straight: of the crimp curves")
    reference: Literal["crimped", "straight"] = Field(
        "crimped", description="natural configuration of the yarns: the crimped weave (stress-free start) or "
                               "straight (the start is bent; docs/impact.md 'Fabric')")
    pretension: Dimensionless = Field(0.0, ge=0, lt=0.2, description="straight reference only: the yarns start "
                                                                      "stretched by this (L0 = crimped length / "
                                                                      "(1 + it))")

    @model_validator(mode="after")
    def _equal_counts(self):
        if self.n_warp != self.n_weft:
            raise cross_field_error("geometry.n_weft", "==", "geometry.n_warp", self.n_weft, self.n_warp)
        if self.reference == "crimped" and self.pretension != 0:
            raise ValueError("geometry.pretension needs geometry.reference = 'straight' (the crimped reference "
                             "is stress-free)")
        return self


class ImpactYarn(Section):
    radius: Length = Field("0.4 mm", gt=0, description="fibril radius R")
    r_bar: CircuitConductance = Field(description="r_bar of the mixed end condition J_n = r_bar V + J_bar")
    J_bar: CurrentDensity = Field(description="J_bar of the mixed end condition (negative: current flows in)")


def _warp():
    return ImpactYarn(radius="0.4 mm", r_bar="100 A/(mm^2*V)", J_bar="-100 A/mm^2")


def _weft():
    return ImpactYarn(radius="0.4 mm", r_bar="0.001 A/(mm^2*V)", J_bar="0 A/mm^2")


class ImpactMaterial(WeaveMaterial):
    electrical_conductivity: ElectricConductivity = Field("1e5 S/mm", gt=0, description="sigma (Table 8.2: 10^5)")


class ImpactProjectile(Section):
    radius: Length = Field("18 mm", gt=0, description="R_projectile: radius of the element and of its "
                                                      "hemispherical ends")
    cylinder_length: Length = Field("5.5 mm", ge=0, description="L_projectile = this + 2 R: the element's length "
                                                                "between its end nodes")
    density: Density = Field("0.01 g/mm^3", gt=0, description="rho_projectile")
    youngs_modulus: Stress = Field("1.26 MPa", gt=0, description="E of the projectile (not in Table 8.2: the "
                                                                 "fabric's)")
    electrical_conductivity: ElectricConductivity = Field("1 S/mm", gt=0, description="sigma_projectile")
    damping: DampingCoefficient = Field("0 N*s/m^4", ge=0, description="gamma_projectile (Table 8.2: 0)")
    r_bar: CircuitConductance = Field("0.001 A/(mm^2*V)", ge=0, description="weakened insulation at both ends")
    J_bar: CurrentDensity = Field("0 A/mm^2", description="J_bar of the projectile ends")
    speed: Velocity = Field("30 mm/ms", ge=0, description="impact speed (velocity -speed e_z); 30 m/s")
    gap: Length = Field("0.2 mm", ge=0, description="initial distance from the lower hemisphere to the fabric top")
    offset: list[float] = Field([0.0, 0.0], description="(x, y) of the projectile axis (mm)")

    @field_validator("offset")
    @classmethod
    def _two(cls, v):
        if len(v) != 2:
            raise ValueError("projectile.offset must have 2 components (x, y in mm)")
        return v


class ImpactContact(Section):
    penalty: Penalty = Field("20 N/mm^2", gt=0, description="P* (Table 8.2 '20 N/mm', per unit overlap); the "
                                                            "sphere contact uses the point penalty P* l_e")
    heat_transfer: HeatTransferCoefficient = Field("0.1 W/(mm^2*K)", ge=0, description="h_C (fabric-fabric)")
    conductance: ContactConductance = Field("0 A/(mm^2*V)", ge=0, description="sigma_C (Table 8.2: 0)")
    projectile_heat_sink: bool = Field(True, description="heat transfer h_C a l_e from the fibrils to the projectile "
                                                         "(a reservoir at T = 0) through the sphere contact")
    n_gp: Integer = Field(4, ge=1, description="contact points per fibril element pair")
    margin: Length = Field("0.3 mm", ge=0, description="search margin (fibrils: cutoff 2R + margin; spheres: "
                                                       "R_p + R_f + margin)")
    g_eps: Dimensionless = Field(1e-3, ge=0, description="Hertz width regularisation, fraction of R")
    rebuild_every: Integer = Field(5, ge=1, description="contact maps rebuilt every k steps (Appendix A)")
    rebuild: Literal["every", "skin"] = Field(
        "every", description="impact phase: every = every rebuild_every steps and when a node moved half the "
                             "margin; skin = only when a node moved half the margin (Verlet skin; "
                             "rve.scenes.rebuild)")


class ImpactField(Section):
    magnitude: MagneticField = Field("0.001 kT", ge=0, description="|B| (Table 8.2: 0.001 kT = 1 T)")
    orientation: list[float] = Field([0.0, 0.7071067811865476, 0.7071067811865476],
                                     description="direction of B (normalised): cos pi/4 e_y + sin pi/4 e_z")

    @field_validator("orientation")
    @classmethod
    def _vector(cls, v):
        if len(v) != 3 or sum(c * c for c in v) == 0:
            raise ValueError("orientation vector must have 3 components, not all 0")
        return v


class ImpactMesh(LinearMesh):
    elements: Integer = Field(80, ge=1, description="linear elements per yarn")


class ImpactRelaxation(Section):
    t_end: Time = Field("1 ms", gt=0, description="damped dynamic relaxation horizon (B off, projectile held)")
    steps: Integer = Field(20, ge=1, description="steps of the relaxation")
    damping: DampingCoefficient = Field("0.0144 g/(mm^3*ms)", ge=0,
                                        description="fabric damping during the relaxation (decay rate gamma/rho)")
    state_file: Optional[str] = Field(None, description="relaxed state (.npz) to load instead of relaxing; "
                                                        "written by the relaxation if missing")
    friction: bool = Field(
        False, description="the relaxation carries the fibril friction of the friction section (its mu, pairs, "
                           "stiffness; not the projectile's mu_p), its history committed every accepted step and "
                           "handed to the impact run (docs/impact.md 'Relaxation with friction'); false: the "
                           "frictionless relaxation")


class ImpactTime(Section):
    t_end: Time = Field("0.5 ms", gt=0, description="impact horizon (thesis: 0.5 ms)")
    steps: Union[Integer, Literal["auto"]] = Field(
        1000, description="nominal steps (thesis: 1000); 'auto': the rule dt <= R_min / (20 v)")
    stages: Literal[1, 2, 3] = Field(2, description="SDIRK stages (thesis: 2)")
    step_control: bool = Field(True, description="halve and retry failed steps")
    max_cuts: Integer = Field(8, ge=0, description="consecutive cuts before giving up")
    store_every: Integer = Field(10, ge=1, description="store the state every k accepted steps")
    checkpoint_every: Integer = Field(50, ge=1, description="write a checkpoint every k accepted steps (run only)")

    @field_validator("steps")
    @classmethod
    def _pos(cls, v):
        if v != "auto" and v < 1:
            raise ValueError("time.steps must be >= 1 or 'auto'")
        return v


class ImpactNewton(StageNewton):
    reuse_across_restarts: bool = Field(
        True, description="the kept stage factorisation (and its PARDISO analysis) survives the restart of the step "
                           "control after a contact-map rebuild, judged by the contraction test (docs/engine.md "
                           "'Dynamic scenes: profile and levers'), except after a checkpoint boundary; false: a fresh "
                           "one after every rebuild")
    predictor_across_restarts: bool = Field(
        True, description="the stage predictor keeps its history over those restarts (false: the first step after a "
                           "rebuild starts its stages from the previous stage value)")
    linear_backend: Literal["superlu_pruned", "superlu", "auto", "auto_pruned"] = Field(
        "auto_pruned", description="stage-matrix factorisation: auto_pruned (PARDISO unsymmetric, mtype 11, where MKL "
                                   "is available, else superlu_pruned), superlu_pruned (SuperLU on the nonzero pattern, "
                                   "rve.solvers.backends.pruned), or a backend of rve.solvers.linear")


class ImpactConfig(SceneConfig):
    """A projectile into a current-carrying plain weave in a magnetic field (thesis §8.4)."""

    scene: Literal["impact"] = Field(description="scene name")
    geometry: ImpactGeometry
    warp: ImpactYarn = Field(default_factory=_warp)
    weft: ImpactYarn = Field(default_factory=_weft)
    material: ImpactMaterial
    projectile: ImpactProjectile
    contact: ImpactContact
    field: ImpactField
    mesh: ImpactMesh
    relaxation: ImpactRelaxation
    time: ImpactTime
    newton: ImpactNewton
    friction: ImpactFrictionSection = Field(
        default_factory=ImpactFrictionSection,
        description="Coulomb friction between fibrils and at the projectile (rve.config.friction; default mu = 0 "
                    "and mu_p = 0: frictionless)")
    output: SceneOutput
    end_temperature: Temperature = Field("0 K", description="T held at every fibril end (T-bar)")
    label: Optional[str] = Field(None, description="free text for the outputs")
