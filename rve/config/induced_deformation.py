"""Config model of the induced-deformation scene (thesis §8.3, Table 8.1, Appendix A).

Contract: :class:`InducedDeformationConfig` and its sections. Named in
``rve.scenes.registry.SCENES``; the scene is ``rve.scenes.induced``. The
readings of Table 8.1 and the choices where the thesis is silent: docs/induced_deformation.md.
"""
from __future__ import annotations

from typing import Literal, Optional, Union

from pydantic import Field, field_validator, model_validator

from .friction import DynamicFrictionSection
from .fields import (
    CircuitConductance, ContactConductance, CurrentDensity, Dimensionless, HeatTransferCoefficient, Integer, Length,
    MagneticField, Penalty, SceneConfig, Section, SeebeckCoefficient, SofteningRate, Temperature, Time, Velocity,
    cross_field_error, line_error,
)
from .sections import LinearMesh, SceneOutput, StageNewton, WeaveMaterial

__all__ = ["InducedDeformationConfig", "ORIENTATIONS"]


#: the three field orientations of §8.3 (unit vectors; B = |B| * orientation)
ORIENTATIONS = {
    "B1": (0.7071067811865476, 0.7071067811865476, 0.0),   # cos pi/4 e_x + sin pi/4 e_y: cork-screw
    "B2": (0.0, 1.0, 0.0),                                  # e_y: current along x -> force along +z
    "B3": (0.0, 0.7071067811865476, 0.7071067811865476),   # cos pi/4 e_y + sin pi/4 e_z: up and sideways
}


class InducedGeometry(Section):
    n_warp: Integer = Field(4, ge=1, description="warp yarns (along x, single fibril each)")
    n_weft: Integer = Field(4, ge=1, description="weft yarns (along y, single fibril each)")
    span: Length = Field("10 mm", gt=0, description="L: distance between the pinned ends of every yarn; "
                                                    "yarn spacing = span / count")
    natural_length: Length = Field("12.5 mm", gt=0, description="L0: natural (reference) length of every fibril; "
                                                                "L0 > L: the yarns start slack, crimped")

    @model_validator(mode="after")
    def _slack(self):
        if not self.natural_length > self.span:
            raise cross_field_error("geometry.natural_length", ">", "geometry.span", self.natural_length,
                                    self.span, "mm")
        return self


class InducedYarn(Section):
    radius: Length = Field(gt=0, description="fibril radius R (mm)")
    r_bar: CircuitConductance = Field(description="r_bar of the mixed end condition J_n = r_bar V + J_bar")
    J_bar: CurrentDensity = Field(description="J_bar of the mixed end condition (outward normal; negative = "
                                              "current flows into the fibril)")


def _warp():
    return InducedYarn(radius="0.4 mm", r_bar="100 A/(mm^2*V)", J_bar="-1000 A/mm^2")


def _weft():
    return InducedYarn(radius="0.6 mm", r_bar="0.001 A/(mm^2*V)", J_bar="0 A/mm^2")


class InducedMaterial(WeaveMaterial):
    seebeck: SeebeckCoefficient = Field("0 V/K", description="S (0: T does not feed back)")
    alpha_mu: SofteningRate = Field("0 MPa/K", description="d mu / d T (0: T does not feed back)")


class InducedContact(Section):
    penalty: Penalty = Field("500 N/mm^2", gt=0, description="P* (Table 8.1 '500 N/mm', per unit overlap)")
    heat_transfer: HeatTransferCoefficient = Field("0.1 W/(mm^2*K)", ge=0, description="h_C")
    conductance: ContactConductance = Field("1.0 A/(mm^2*V)", ge=0, description="sigma_C")
    n_gp: Integer = Field(4, ge=1, description="contact points per element pair")
    margin: Length = Field("0.3 mm", ge=0, description="search cutoff = 2 max R + margin (1.5 mm: Appendix A)")
    g_eps: Dimensionless = Field(1e-3, ge=0, description="Hertz width regularisation, fraction of R")
    rebuild_every: Integer = Field(5, ge=1, description="contact map rebuilt every k accepted steps (Appendix A)")
    rebuild: Literal["every", "skin"] = Field(
        "every", description="every = every rebuild_every accepted steps and when a centroid moved half the margin; "
                             "skin = only when a centroid moved half the margin (Verlet skin; rve.scenes.rebuild)")


class InducedField(Section):
    magnitude: MagneticField = Field("0.005 kT", ge=0, description="|B|")
    orientation: Union[Literal["B1", "B2", "B3"], list[float]] = Field(
        "B2", description="B1, B2, B3 (§8.3) or any 3-vector (normalised)")
    ramp_time: Time = Field("0 ms", ge=0, description="C2 switch-on of B over this time (0: a step, the thesis)")

    @field_validator("orientation")
    @classmethod
    def _vector(cls, v):
        if isinstance(v, list):
            if len(v) != 3 or sum(c * c for c in v) == 0:
                raise ValueError("orientation vector must have 3 components, not all 0")
        return v


class InducedCoupling(Section):
    temperature: Literal["post", "monolithic"] = Field(
        "post", description="post: T solved after every accepted step from the stage states (S = alpha_mu = 0); "
                            "monolithic: T dofs inside every stage Newton")
    lorentz: bool = Field(True, description="Lorentz force of the conduction current")
    back_emf: bool = Field(True, description="motional EMF")


class InducedAdaptive(Section):
    """Error-controlled steps (rve.solvers.dirk.AdaptiveControl; docs/time_integration.md §4)."""

    enabled: bool = Field(False, description="false: the thesis's steps of t_end/steps (halved only when Newton "
                                             "fails; the model's default); true: steps from the embedded error "
                                             "estimate (configs/scenes/induced_deformation.yaml: measured, "
                                             "docs/engine.md)")
    rtol: Dimensionless = Field(2e-2, ge=0, le=1, description="relative tolerance of the local error")
    atol: Length = Field("2e-2 mm", gt=0, le=1.0,
                         description="absolute tolerance (mm, at most 1) of the positions' local error")
    atol_velocity: Optional[Velocity] = Field(None, gt=0, description="absolute tolerance of the velocities' local "
                                                                       "error (null: positions only)")
    safety: Dimensionless = Field(0.9, gt=0, le=1, description="safety factor of the step proposal")
    min_factor: Dimensionless = Field(0.2, gt=0, lt=1, description="smallest step ratio per step")
    max_factor: Dimensionless = Field(4.0, gt=1, le=10, description="largest step ratio per step")
    hold_band: Dimensionless = Field(1.2, ge=1, le=2, description="step ratios in [1, hold_band] keep h (the held "
                                                                  "factorisation depends on h)")
    controller: Literal["pi", "elementary"] = Field("pi", description="PI (Gustafsson) or elementary controller")
    h_max: Time = Field("0.05 ms", gt=0, description="largest step")


class InducedTime(Section):
    t_end: Time = Field("15 ms", gt=0, description="horizon (Appendix A: 15 ms)")
    steps: Integer = Field(3000, ge=1, description="nominal steps (Appendix A: 3000)")
    stages: Literal[1, 2, 3] = Field(2, description="SDIRK stages (Appendix A: 2)")
    step_control: bool = Field(True, description="halve and retry failed steps")
    max_cuts: Integer = Field(8, ge=0, description="consecutive cuts before giving up")
    store_every: Integer = Field(10, ge=1, description="store the state every k accepted steps "
                                                       "(Appendix A outputs every 10 steps); with adaptive "
                                                       "steps every k nominal steps of time (the steps land there)")
    adaptive: InducedAdaptive = Field(default_factory=InducedAdaptive, description="error-controlled steps")

    @model_validator(mode="after")
    def _adaptive(self):
        if self.adaptive.enabled and self.stages < 2:
            raise line_error(f"adaptive.enabled = true: needs stages 2 or 3 (an embedded error estimate), "
                             f"not stages = {self.stages}")
        if self.adaptive.enabled and not self.step_control:
            raise line_error("adaptive.enabled = true: needs step_control = true (fixed steps exclude it)")
        return self


class InducedNewton(StageNewton):
    linear_backend: Optional[Literal["auto", "superlu", "superlu_pruned", "pardiso"]] = Field(
        "superlu", description="backend of the kept stage factorisations (rve.solvers.linear.get_backend): "
                               "superlu = SuperLU in symmetric mode (MMD on A^T + A, diagonal pivots; the stage "
                               "matrices are structurally symmetric and mass-dominated: half the fill of COLAMD, "
                               "docs/induced_deformation.md); superlu_pruned = the same ordering on the nonzero "
                               "pattern (the stored zeros of the inactive candidate contact pairs dropped: less "
                               "than half the fill and a third of the time per factorisation, docs/engine.md), "
                               "threshold pivoting 0.01; auto = the engine's choice (unsymmetric stage "
                               "matrices go to SuperLU COLAMD with partial pivoting)")


class InducedDeformationConfig(SceneConfig):
    """A current-carrying plain weave moved by a magnetic field (thesis §8.3)."""

    scene: Literal["induced_deformation"] = Field(description="scene name")
    geometry: InducedGeometry
    warp: InducedYarn = Field(default_factory=_warp)
    weft: InducedYarn = Field(default_factory=_weft)
    material: InducedMaterial
    contact: InducedContact
    field: InducedField
    coupling: InducedCoupling
    mesh: LinearMesh
    time: InducedTime
    newton: InducedNewton
    friction: DynamicFrictionSection = Field(
        default_factory=DynamicFrictionSection,
        description="Coulomb friction between fibrils (rve.config.friction; default mu = 0: frictionless)")
    output: SceneOutput
    end_temperature: Temperature = Field("0 K", description="T held at every fibril end")
    label: Optional[str] = Field(None, description="free text for the outputs")
