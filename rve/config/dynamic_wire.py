"""Config model of the dynamic wire scene (thesis §6.4, Tables 6.3-6.4).

Contract: :class:`DynamicWireConfig` and its sections. Named in
``rve.scenes.registry.SCENES``; the scene is ``rve.scenes.dynamic_wire``. Parameter
choices for what Table 6.3 does not give: docs/coupled_fields.md.
"""
from __future__ import annotations

from typing import Literal, Optional

from pydantic import Field

from .fields import (
    Angle, DampingCoefficient, Density, Dimensionless, ElectricConductivity, Integer, Length, MagneticField,
    Quantity, Section, SeebeckCoefficient, SofteningRate, SpecificHeat, Stress, Temperature,
    ThermalConductivity, Time, Voltage
)
from .sections import BeamMesh, Newton, WireSceneConfig

__all__ = ["DynamicWireConfig"]

Resistance = Quantity("V/A")


class DynamicWireGeometry(Section):
    half_length: Length = Field(1.0, gt=0, description="half length L of the wire (mm); reference X1 in [-L, L]")


class DynamicWireFibril(Section):
    radius: Length = Field(0.02, gt=0, description="fibril radius R (mm)")


class DynamicWireMaterial(Section):
    youngs_modulus: Stress = Field("10 MPa", gt=0, description="Young's modulus E (MPa); mu0 = E / 2(1 + nu)")
    poisson_ratio: Dimensionless = Field(0.0, ge=0, lt=0.5, description="Poisson ratio nu (0 in the thesis)")
    density: Density = Field("5e-9 g/mm^3", gt=0, description="mass density rho (g/mm^3); not in Table 6.3")
    heat_capacity: SpecificHeat = Field(
        "5e4 J/(kg*K)", gt=0, description="specific heat c_p (mJ/(g K)); not in Table 6.3")
    thermal_conductivity: ThermalConductivity = Field(
        "0.2 W/(mm*K)", gt=0, description="thermal conductivity k0 (W/(mm K)); not in Table 6.3")
    electrical_conductivity: ElectricConductivity = Field("10 S/mm", gt=0, description="sigma0 (S/mm)")
    seebeck: SeebeckCoefficient = Field("0.1 V/K", description="Seebeck coefficient S (V/K)")
    alpha_mu: SofteningRate = Field("-0.1 MPa/K", description="d mu / d T of mu(T) = mu0 + alpha_mu T (MPa/K)")
    damping: DampingCoefficient = Field(
        "0.01 N*s/m^4", ge=0,
        description="volumetric damping gamma of the force density -gamma v (g/(mm^3 ms)); "
                    "Table 6.3's '0.01 N s/m' read as a density per volume")


class DynamicWireLoad(Section):
    voltage_left: Voltage = Field("-0.2 V", description="potential at the X1 = -L end (V)")
    voltage_right: Voltage = Field("0.2 V", description="potential at the X1 = +L end (V), or the circuit's "
                                                        "terminal potential when circuit_resistance is set")
    circuit_resistance: Optional[Resistance] = Field(
        None, gt=0, description="if set, the +L end is a mixed circuit condition (eq. 2.8.2): a resistor "
                                "(ohm) to a terminal at voltage_right instead of a Dirichlet potential")
    end_temperature: Temperature = Field(0.0, description="temperature change held at both ends (K)")
    field_magnitude: MagneticField = Field("1 T", ge=0, description="|B| (kT)")
    field_angle: Angle = Field("45 deg", description="angle phi of B = |B|(cos phi, 0, sin phi) to the wire (rad)")
    field_ramp_time: Time = Field(
        "0.5 us", ge=0, description="B is switched on smoothly (C2 quintic) over this time (ms); 0 = a step at "
                                    "t = 0 (see docs/coupled_fields.md: the step excites unresolvable axial modes)")


class DynamicWireCouplings(Section):
    lorentz: bool = Field(True, description="Lorentz force of the conduction current")
    back_emf: bool = Field(True, description="motional EMF (v x B) . F E3 in the current")
    joule: bool = Field(True, description="Joule heating")
    seebeck: bool = Field(True, description="Seebeck EMF -S T' in the current")
    thermal_softening: bool = Field(True, description="mu(T) = mu0 + alpha_mu T")
    temperature: Literal["auto", "coupled", "post"] = Field(
        "auto", description="T dofs in the monolithic solve ('coupled'), or T solved after the run from the "
                            "stored Joule history ('post', only when nothing feeds back from T); "
                            "'auto' picks 'post' when alpha_mu and S are off")


class DynamicWireMesh(BeamMesh):
    elements: Integer = Field(40, ge=1, description="elements along the wire")


class DynamicWireTime(Section):
    t_max: Time = Field("2.1 us", gt=0, description="final time t_max (ms); not in Table 6.3")
    steps: Integer = Field(400, ge=1, description="nominal number of time steps")
    stages: Literal[1, 2, 3] = Field(3, description="SDIRK stages s (order s)")
    step_control: bool = Field(True, description="halve and retry failed steps (else: fixed steps, fail at once)")
    max_cuts: Integer = Field(8, ge=0, description="consecutive step cuts before giving up")
    history_every: Integer = Field(1, ge=1, description="store the probe history every k accepted steps")


class DynamicWireNewton(Newton):
    atol: Dimensionless = Field(
        1e-8, gt=0, description="absolute tolerance on the row-scaled stage residual (natural units of w: "
                                "mm/ms, 1/ms, K, V; the velocities are ~100 mm/ms)")
    max_iter: Integer = Field(20, ge=1, description="Newton iterations per stage")


class DynamicWireConfig(WireSceneConfig):
    """The pinned wire with coupled current, heat and motion in a magnetic field (thesis §6.4)."""

    scene: Literal["dynamic_wire"] = Field(description="scene name")
    dofs_per_node = 11
    geometry: DynamicWireGeometry
    fibril: DynamicWireFibril
    material: DynamicWireMaterial
    load: DynamicWireLoad
    couplings: DynamicWireCouplings
    mesh: DynamicWireMesh
    time: DynamicWireTime
    newton: DynamicWireNewton
