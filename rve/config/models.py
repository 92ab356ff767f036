"""Pydantic models of the scene configurations.

Every model forbids unknown keys. Fields with a physical dimension are declared with the
annotated quantity types below; they accept a bare number (already in internal units) or
a string with units, and store the converted internal-unit ``float`` after validation::

    class MySection(Section):
        radius: Length = Field(0.02, gt=0, description="fibril radius")
        field: MagneticField = Field("1 T", ge=0, description="|B|")
        speed: Annotated[float, Quantity("mm/ms")] = ...      # any other unit

Constraints (``gt``, ``ge``, ``lt``, ``le``) apply to the converted value, in internal
units. Defaults may carry units too (``"1 T"``): sections validate their defaults.

A new scene is a subclass of :class:`SceneConfig` with ``scene: Literal["name"]``,
registered in :data:`SCENE_MODELS` (``register_scene_model`` does both checks).
"""
from __future__ import annotations

import typing
import types
from typing import Annotated, Any, Literal, Optional

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from .units import UnitConversionError, convert, dimension_name

__all__ = [
    "Quantity",
    "UnitSpec",
    "Integer",
    "Length",
    "Time",
    "Mass",
    "Force",
    "Stress",
    "Energy",
    "Power",
    "Temperature",
    "Current",
    "Charge",
    "Voltage",
    "MagneticField",
    "CurrentDensity",
    "ElectricConductivity",
    "ContactConductance",
    "ThermalConductivity",
    "HeatTransferCoefficient",
    "Density",
    "Velocity",
    "Acceleration",
    "SpecificHeat",
    "DampingCoefficient",
    "Angle",
    "Dimensionless",
    "Section",
    "SceneConfig",
    "cross_field_error",
    "Geometry",
    "Fibril",
    "Material",
    "WireLoad",
    "Mesh",
    "Relaxation",
    "NewtonSettings",
    "StaticWireSolver",
    "StaticWireConfig",
    "SCENE_MODELS",
    "register_scene_model",
    "field_unit",
]


# --------------------------------------------------------------------------- field types
class UnitSpec:
    """Marker in a field's ``Annotated`` metadata recording its internal unit. It also
    widens the JSON schema: the raw input may be a number or a string with units."""

    def __init__(self, unit: str):
        self.unit = unit

    def __repr__(self) -> str:
        return f"UnitSpec({self.unit!r})"

    def __get_pydantic_json_schema__(self, core_schema, handler):
        number = handler(core_schema)
        dim = dimension_name(self.unit)
        if dim == "dimensionless":
            hint = "a number, or a string such as '1 %'"
        else:
            hint = f"{dim}: a number in {self.unit}, or a string with units"
        return {
            "anyOf": [number, {"type": "string", "minLength": 1}],
            "x-unit": self.unit,
            "x-dimension": dim,
            "$comment": hint,
        }


def Quantity(unit: str):
    """Annotated ``float`` field type converted to internal unit ``unit`` at validation.

    Use it directly as a type (``Annotated`` objects compose):
    ``speed: Quantity("mm/ms") = Field(gt=0)``.
    """

    def _convert(value: Any) -> float:
        try:
            return convert(value, unit)
        except UnitConversionError as exc:
            raise PydanticCustomError(f"unit_{exc.kind}", exc.message) from None

    return Annotated[float, BeforeValidator(_convert), UnitSpec(unit)]


def _strict_integer(value: Any) -> Any:
    # pydantic's lax mode reads True as 1; a boolean for a count is always a mistake.
    if isinstance(value, bool):
        raise PydanticCustomError("int_type", "booleans are not integers")
    return value


#: ``int`` that rejects booleans (and, as pydantic does, floats with a fraction).
Integer = Annotated[int, BeforeValidator(_strict_integer)]

Length = Quantity("mm")
Time = Quantity("ms")
Mass = Quantity("g")
Force = Quantity("N")
Stress = Quantity("MPa")
Energy = Quantity("mJ")
Power = Quantity("W")
Temperature = Quantity("K")
Current = Quantity("A")
Charge = Quantity("mC")
Voltage = Quantity("V")
MagneticField = Quantity("kT")
CurrentDensity = Quantity("A/mm^2")
ElectricConductivity = Quantity("S/mm")
ContactConductance = Quantity("A/(mm^2*V)")
ThermalConductivity = Quantity("W/(mm*K)")
HeatTransferCoefficient = Quantity("W/(mm^2*K)")
Density = Quantity("g/mm^3")
Velocity = Quantity("mm/ms")
Acceleration = Quantity("mm/ms^2")
SpecificHeat = Quantity("mJ/(g*K)")
#: volumetric damping coefficient gamma of the force density -gamma v: g/(mm^3 ms) = N ms/mm^4
DampingCoefficient = Quantity("g/(mm^3*ms)")
#: angle in radians; "45 deg", "pi/4 rad" or a bare number (radians)
Angle = Quantity("rad")
#: dimensionless number; also accepts "1 %", "1e-3"
Dimensionless = Quantity("dimensionless")


def field_unit(model: type[BaseModel], name: str) -> Optional[str]:
    """Internal unit of field ``name`` of ``model`` (None for non-quantity fields)."""
    info = model.model_fields[name]
    for meta in _iter_metadata(info.annotation, info.metadata):
        if isinstance(meta, UnitSpec):
            return meta.unit
    return None


def _iter_metadata(annotation, metadata):
    yield from metadata
    stack = [annotation]
    while stack:
        tp = stack.pop()
        if typing.get_origin(tp) is Annotated:
            yield from tp.__metadata__
            stack.append(typing.get_args(tp)[0])
        elif typing.get_origin(tp) in (typing.Union, getattr(types, "UnionType", None)):
            stack.extend(typing.get_args(tp))


# --------------------------------------------------------------------------- base classes
class Section(BaseModel):
    """Base of every config section: unknown keys are errors, defaults (which may carry
    units) are validated, and assignments are validated too."""

    model_config = ConfigDict(extra="forbid", validate_default=True, validate_assignment=True)


class SceneConfig(Section):
    """Base of the scene configurations; ``scene`` is the discriminator (required)."""

    scene: str = Field(description="scene name; selects the model and the code that runs it")


def cross_field_error(key: str, relation: str, other: str, value: float, other_value: float,
                      unit: Optional[str] = None) -> PydanticCustomError:
    """Error for a check between two fields of one section (raise it from a
    ``model_validator(mode="after")``). The loader renders it with full dotted keys:
    ``geometry.clamp_half_distance = 1.0 mm: must be < geometry.half_length (= 1.0 mm)``."""
    u = f" {unit}" if unit else ""
    return PydanticCustomError(
        "cross_field",
        "{key} = {value}{u}: must be {relation} {other} (= {other_value}{u})",
        {"key": key, "relation": relation, "other": other, "value": value,
         "other_value": other_value, "u": u},
    )


# --------------------------------------------------------------------------- static wire
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


class Mesh(Section):
    order: Integer = Field(2, ge=1, le=4, description="Lagrange element order p along the fibril")
    elements: Integer = Field(40, ge=1, description="number of elements along the fibril")
    disk_points: Literal[4, 8, 16] = Field(4, description="points of the unit-disk rule across the section")
    axial_points: Optional[Integer] = Field(
        None, ge=1, description="Gauss-Legendre points per element along the axis; null = order + 1")

    @property
    def resolved_axial_points(self) -> int:
        """``axial_points``, or ``order + 1`` when it is null."""
        return self.order + 1 if self.axial_points is None else self.axial_points


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


class NewtonSettings(Section):
    atol: Dimensionless = Field(1e-10, gt=0, description="absolute tolerance on the residual norm")
    rtol: Dimensionless = Field(1e-12, gt=0, description="relative tolerance on the residual norm")
    max_iter: Integer = Field(50, ge=1, description="maximum Newton iterations")


class StaticWireSolver(Section):
    path: Literal["dynamic_relaxation", "continuation"] = Field(
        "dynamic_relaxation",
        description="how the static solution is reached: dynamic relaxation then static Newton, or load continuation")
    relaxation: Relaxation = Field(default_factory=Relaxation)
    newton: NewtonSettings = Field(default_factory=NewtonSettings)


class StaticWireConfig(SceneConfig):
    """The pinned wire in a magnetic field (thesis ch. 3, §6.3, Tables 6.1-6.2)."""

    scene: Literal["static_wire"] = Field(description="scene name")
    geometry: Geometry = Field(default_factory=Geometry)
    fibril: Fibril = Field(default_factory=Fibril)
    material: Material = Field(default_factory=Material)
    load: WireLoad = Field(default_factory=WireLoad)
    mesh: Mesh = Field(default_factory=Mesh)
    solver: StaticWireSolver = Field(default_factory=StaticWireSolver)


# --------------------------------------------------------------------------- registry
#: scene name -> config model
SCENE_MODELS: dict[str, type[SceneConfig]] = {"static_wire": StaticWireConfig}


def register_scene_model(model: type[SceneConfig]) -> type[SceneConfig]:
    """Class decorator: add ``model`` to :data:`SCENE_MODELS` under the value of its
    ``scene: Literal["name"]`` field."""
    ann = model.model_fields["scene"].annotation
    if typing.get_origin(ann) is not Literal or len(typing.get_args(ann)) != 1:
        raise TypeError(f"{model.__name__}.scene must be declared as Literal['<name>']")
    (name,) = typing.get_args(ann)
    SCENE_MODELS[name] = model
    return model


# Scene models that live in their own modules register themselves on import; importing
# them here makes every scene known wherever SCENE_MODELS is (loader, CLI validate/schema).
from . import dynamic_wire as _dynamic_wire  # noqa: E402,F401
