"""Field types and base sections of every config model (docs/configuration.md).

Contract
--------
In: nothing but pydantic and the unit conversion of :mod:`rve.config.units`. Out: the
annotated quantity types (``Length``, ``MagneticField``, ... or ``Quantity(unit)``), the
strict ``Integer``, the base classes :class:`Section` and :class:`SceneConfig`,
:func:`cross_field_error` and :func:`field_unit`. No scene model lives here: the scene
models are in their own modules (``rve.config.static_wire``, ``rve.config.dynamic_wire``,
``rve.config.fabric``, ``rve.config.rve``) and the one list of scenes is
``rve.scenes.registry``.

Every model forbids unknown keys. Fields with a physical dimension are declared with the
annotated quantity types below; they accept a bare number (already in internal units) or
a string with units, and store the converted internal-unit ``float`` after validation::

    class MySection(Section):
        radius: Length = Field(0.02, gt=0, description="fibril radius")
        field: MagneticField = Field("1 T", ge=0, description="|B|")
        speed: Annotated[float, Quantity("mm/ms")] = ...      # any other unit

Constraints (``gt``, ``ge``, ``lt``, ``le``) apply to the converted value, in internal
units. Defaults may carry units too (``"1 T"``): sections validate their defaults.

A field whose type is a section and that is declared without a default defaults to that
section's own defaults (when every key of the section has one), so a scene lists its
sections by type alone::

    class MySceneConfig(SceneConfig):
        scene: Literal["my_scene"] = Field(description="scene name")
        mesh: BeamMesh                                  # default: BeamMesh()
        warp: Yarn = Field(default_factory=_warp)       # any other default is explicit

A new scene is a subclass of :class:`SceneConfig` with ``scene: Literal["name"]``, named
in ``rve.scenes.registry.SCENES`` (docs/configuration.md, "Adding a scene").
"""
from __future__ import annotations

import logging
import math
import re
import typing
import types
from numbers import Real
from typing import Annotated, Any, Literal, Optional

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field
from pydantic.fields import FieldInfo
from pydantic_core import PydanticCustomError

from .units import UnitConversionError, convert, dimension_name

__all__ = [
    "Quantity",
    "SeebeckCoefficient",
    "SofteningRate",
    "CircuitConductance",
    "Penalty",
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
    "line_error",
    "scene_name",
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


# every Temperature of rve is a difference (T = 0 is the reference or boundary
# temperature); an offset unit ("20 degC" = 293.15 K) there is always a mistake
_ABSOLUTE_T = re.compile(r"(?<![A-Za-z_])(degC|degF|degree_Celsius|degree_Fahrenheit|celsius|fahrenheit)\b|°[CF]",
                         re.IGNORECASE)


def _temperature_difference(value: Any) -> Any:
    if isinstance(value, str) and _ABSOLUTE_T.search(value) and "delta" not in value.lower():
        try:
            absolute = f" = {convert(value, 'K'):.6g} K"
        except UnitConversionError:
            absolute = ""
        raise PydanticCustomError(
            "unit_absolute_temperature",
            "an absolute temperature{absolute}, but this key is a temperature difference (rise above the "
            "reference, T = 0): write e.g. '20 K' or '20 delta_degC'", {"absolute": absolute})
    return value


#: above this a bare angle is probably in degrees (a warning; bare numbers are radians)
ANGLE_WARN_RAD = 2.0 * math.pi


def _bare_angle(value: Any, info) -> Any:
    bare = isinstance(value, Real) and not isinstance(value, bool)
    if isinstance(value, str):
        try:
            float(value)
            bare = True
        except ValueError:
            pass
    if bare and math.isfinite(float(value)) and abs(float(value)) > ANGLE_WARN_RAD:
        logging.getLogger("rve.config").warning(
            "%s = %s: a bare number is an angle in radians (= %.6g deg); write '%s deg' if degrees are meant",
            getattr(info, "field_name", "angle"), value, math.degrees(float(value)), value)
    return value


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
Temperature = Annotated[Quantity("K"), BeforeValidator(_temperature_difference)]
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
Angle = Annotated[Quantity("rad"), BeforeValidator(_bare_angle)]
#: dimensionless number; also accepts "1 %", "1e-3"
Dimensionless = Quantity("dimensionless")
SeebeckCoefficient = Quantity("V/K")
#: d mu / d T of the temperature-dependent shear modulus mu(T) = mu0 + alpha_mu T
SofteningRate = Quantity("MPa/K")
#: r_bar of the mixed condition J_n = r_bar V + J_bar (current density per volt)
CircuitConductance = Quantity("A/(mm^2*V)")
#: contact penalty stiffness per area
Penalty = Quantity("N/mm^2")


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

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs: Any) -> None:
        # a section-typed field declared without a default takes the section's defaults where
        # every key of the section has one (else the section stays required: "mesh missing");
        # the fields keep their declaration order (it is the key order of every dump)
        super().__pydantic_init_subclass__(**kwargs)
        fields = cls.__pydantic_fields__
        bare = [name for name, info in fields.items()
                if info.is_required() and isinstance(info.annotation, type) and issubclass(info.annotation, Section)
                and not any(f.is_required() for f in info.annotation.model_fields.values())]
        for name in bare:
            fields[name] = FieldInfo.merge_field_infos(fields[name], default_factory=fields[name].annotation)
        if bare:
            cls.model_rebuild(force=True)


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


def line_error(text: str) -> PydanticCustomError:
    """An error whose message is a whole line relative to the section that raises it
    (``"elements = 10000000: ..."``); the loader prefixes the section's dotted key."""
    return PydanticCustomError("full_line", "{text}", {"text": text})


def scene_name(model: type[SceneConfig]) -> str:
    """The scene name a config model declares: the value of its ``scene: Literal["name"]``
    field. Raises TypeError if ``scene`` is not a one-value ``Literal``."""
    ann = model.model_fields["scene"].annotation
    if typing.get_origin(ann) is not Literal or len(typing.get_args(ann)) != 1:
        raise TypeError(f"{model.__name__}.scene must be declared as Literal['<name>']")
    return typing.get_args(ann)[0]
