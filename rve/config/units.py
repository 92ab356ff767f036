"""The package's unit registry and the conversion of config values to internal units.

Internally every number is a float in one consistent unit system (docs/configuration.md "Internal units", thesis
Table 2.3): mm, ms, g, N, MPa, K, A, mC, V, kT (1 T = 0.001 kT), S/mm, W, W/(mm K),
W/(mm² K), A/(mm² V). Consistency means no conversion factor ever appears in the
physics code: e.g. a current density (A/mm²) times a field (kT) is a force density
(N/mm³), and N = g·mm/ms².

Config values are converted exactly once, at load time, by :func:`to_internal`:

* a bare number (int/float) is taken as already being in internal units;
* a string is parsed by pint (``"1 T"``, ``"0.02 mm"``, ``"45 deg"``, ``"pi/4 rad"``,
  ``"30 m/s"``, ``"1 A/mm^2"``, ``"20 degC"``) and converted to the internal unit;
  a string that is only a number (``"1e-3"``, which YAML 1.1 reads as a string) is a
  bare number;
* a value of the wrong dimension raises :class:`ConfigError` naming the key.
"""
from __future__ import annotations

import math
from numbers import Real

import pint

__all__ = [
    "ureg",
    "Q_",
    "ConfigError",
    "UnitConversionError",
    "INTERNAL_UNITS",
    "to_internal",
    "convert",
    "dimension_name",
    "format_value",
]

#: The one unit registry of the package. Offset units (degC) convert to kelvin when
#: multiplied by a number, so ``"20 degC"`` reads as 293.15 K.
#: ``cache_folder=":auto:"`` keeps pint's parsed definitions in the user cache folder:
#: building the registry from scratch costs ~1 s per process (measured), which dominated
#: short Snakemake jobs.
ureg = pint.UnitRegistry(autoconvert_offset_to_baseunit=True, cache_folder=":auto:")
Q_ = ureg.Quantity


class ConfigError(ValueError):
    """Invalid configuration. ``errors`` holds one message per problem; ``str()``
    joins them one per line. Each message names the full dotted key."""

    def __init__(self, errors):
        if isinstance(errors, str):
            errors = [errors]
        self.errors = list(errors)
        super().__init__("\n".join(self.errors))


class UnitConversionError(ValueError):
    """A value could not be converted (raised without the key; callers add it)."""

    def __init__(self, kind: str, message: str):
        self.kind = kind  # "wrong_dimension" | "unparsable" | "not_finite" | "bad_type"
        self.message = message
        super().__init__(message)


#: Internal unit of each physical quantity (documentation and the CLI's annotations).
INTERNAL_UNITS: dict[str, str] = {
    "length": "mm",
    "time": "ms",
    "mass": "g",
    "force": "N",
    "stress": "MPa",
    "energy": "mJ",
    "power": "W",
    "temperature": "K",
    "current": "A",
    "charge": "mC",
    "voltage": "V",
    "magnetic field": "kT",
    "current density": "A/mm^2",
    "electric conductivity": "S/mm",
    "electric contact conductance": "A/(mm^2*V)",
    "thermal conductivity": "W/(mm*K)",
    "heat transfer coefficient": "W/(mm^2*K)",
    "density": "g/mm^3",
    "velocity": "mm/ms",
    "acceleration": "mm/ms^2",
    "frequency": "1/ms",
    "specific heat": "mJ/(g*K)",
    "seebeck coefficient": "V/K",
    "force per length": "N/mm",
    "volumetric damping coefficient": "g/(mm^3*ms)",
    "angle": "rad",
    "dimensionless": "dimensionless",
}

# Human names of dimensionalities, for error messages. Several quantities share a
# dimensionality (stress and contact penalty, say); the first name listed wins.
_DIM_NAMES: dict = {}
for _name, _unit in INTERNAL_UNITS.items():
    if _name == "angle":
        continue
    _DIM_NAMES.setdefault(ureg.Unit(_unit).dimensionality, _name)


def _is_angle_unit(unit: str) -> bool:
    try:
        _, root = ureg.get_root_units(unit)
    except Exception:
        return False
    return root == ureg.radian


def dimension_name(unit: str) -> str:
    """Human-readable name of the dimension of ``unit`` (``"kT"`` -> ``"magnetic field"``)."""
    if unit in ("", "dimensionless"):
        return "dimensionless"
    if _is_angle_unit(unit):
        return "angle"
    dim = ureg.Unit(unit).dimensionality
    name = _DIM_NAMES.get(dim)
    return name if name is not None else str(dim)


def _describe_expected(unit: str) -> str:
    name = dimension_name(unit)
    if name == "dimensionless":
        return "a dimensionless number"
    return f"{name} ({unit})"


def format_value(value) -> str:
    """Render a raw config value for messages: strings quoted, numbers plain."""
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, float):
        return repr(value)
    return str(value)


def convert(value, unit: str) -> float:
    """Convert ``value`` to ``unit`` (see module docstring); raises UnitConversionError."""
    if isinstance(value, bool):
        raise UnitConversionError(
            "bad_type", f"expected a number or a string with units, got a boolean; "
            f"expected {_describe_expected(unit)}")
    if isinstance(value, Real):
        out = float(value)
    elif isinstance(value, str):
        text = value.strip()
        if not text:
            raise UnitConversionError("unparsable", f"empty value; expected {_describe_expected(unit)}")
        try:
            q = Q_(text)
        except Exception as exc:  # pint raises a zoo of error types (and AssertionError)
            detail = str(exc).strip() or type(exc).__name__
            raise UnitConversionError(
                "unparsable",
                f"cannot read as a quantity ({detail}); expected {_describe_expected(unit)}, "
                f"e.g. '1.5 {unit}' or a bare number in {unit}" if unit not in ("", "dimensionless")
                else f"cannot read as a number ({detail})",
            ) from None
        if not isinstance(q, pint.Quantity):  # a plain number came back
            out = float(q)
        elif q.units == ureg.dimensionless:  # only a number: "1e-3", "2*pi"
            out = float(q.magnitude)
        else:
            try:
                out = float(q.to(unit).magnitude)
            except pint.DimensionalityError:
                raise UnitConversionError(
                    "wrong_dimension", f"wrong dimension, expected {_describe_expected(unit)}"
                ) from None
            except Exception as exc:
                raise UnitConversionError(
                    "unparsable", f"cannot convert to {unit} ({exc})") from None
    else:
        raise UnitConversionError(
            "bad_type", f"expected a number or a string with units, got {type(value).__name__}; "
            f"expected {_describe_expected(unit)}")
    if not math.isfinite(out):
        raise UnitConversionError("not_finite", "must be a finite number")
    return out


def to_internal(value, unit: str, key: str) -> float:
    """Convert a config value to the internal unit ``unit``.

    ``value`` is a bare number (already internal) or a string with units parsed by pint.
    Raises :class:`ConfigError` naming ``key``, the value and the expected dimension::

        >>> to_internal("1 T", "kT", "load.field_magnitude")
        0.001
        >>> to_internal("30 m/s", "mm/ms", "v")
        30.0
    """
    try:
        return convert(value, unit)
    except UnitConversionError as exc:
        raise ConfigError(f"{key} = {format_value(value)}: {exc.message}") from None
