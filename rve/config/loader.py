"""Loading, overriding and validating scene configurations.

``load_config(source, overrides)`` reads a YAML file (or takes a dict), applies
``"dotted.key=value"`` overrides, picks the model from the ``scene`` key and validates.
All problems are reported together in one :class:`ConfigError`, one line each, always
naming the full dotted key, the offending value and what is allowed::

    mesh.order = 5: must be an integer between 1 and 4
    fibril.radius = -0.1 mm: must be > 0
    geometry.colour: unknown key (allowed: half_length, clamp_half_distance)
    load.field_magnitude = '1 m': wrong dimension, expected magnetic field (kT)
    scene missing (allowed: static_wire, dynamic_wire, fabric_relax, rve)

The scene names and their models come from the one scene registry,
``rve.scenes.registry`` (imported when a config is loaded, not when ``rve.config`` is
imported: the registry sits above this package). A pipeline config (Snakemake's
``configs/pipeline.yaml``: no ``scene`` key, top-level keys among ``PIPELINE_KEYS``) is
refused with one :class:`NotASceneConfig` line (docs/configuration.md).
"""
from __future__ import annotations

import copy
import json
import os
import types
import typing
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional, Union

import yaml
from annotated_types import Ge, Gt, Le, Lt
from pydantic import BaseModel, ValidationError

from .fields import SceneConfig, UnitSpec, _iter_metadata
from .units import ConfigError, format_value

__all__ = [
    "ConfigError",
    "NotASceneConfig",
    "PIPELINE_KEYS",
    "scene_models",
    "load_config",
    "read_config_source",
    "StrictLoader",
    "apply_overrides",
    "parse_override",
    "validate_config",
    "config_as_dict",
    "config_units",
    "json_schema",
]


# --------------------------------------------------------------------------- reading
class DuplicateKeyError(yaml.YAMLError):
    """A mapping of a YAML file repeats a key (YAML would silently keep the last one)."""


class StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (PyYAML
    keeps the last one: a repeated section would silently drop the keys of the first)."""

    def construct_mapping(self, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError:
                continue
            if key in seen:
                raise DuplicateKeyError(
                    f"line {key_node.start_mark.line + 1}: duplicate key {key!r} (first at line {seen[key] + 1}); "
                    "YAML would keep only the last one: merge the two")
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


def read_config_source(source: Union[str, os.PathLike, Mapping]) -> dict:
    """The raw (unvalidated) config mapping of a YAML file path or a mapping (deep copy)."""
    if isinstance(source, Mapping):
        return copy.deepcopy(dict(source))
    path = Path(source)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read config file {str(path)!r}: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}, line {line}: {data[exc.start:exc.start + 1]!r}); "
                          "save the file as UTF-8") from None
    try:
        raw = yaml.load(text, Loader=StrictLoader)
    except DuplicateKeyError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {exc}") from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: the config must be a mapping of keys to values, "
                          f"got {type(raw).__name__}")
    return raw


# --------------------------------------------------------------------------- model walking
def _unwrap(annotation) -> list:
    """The concrete types inside Optional/Union/Annotated."""
    out, stack = [], [annotation]
    while stack:
        tp = stack.pop()
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            stack.append(typing.get_args(tp)[0])
        elif origin in (Union, getattr(types, "UnionType", None)):
            stack.extend(typing.get_args(tp))
        else:
            out.append(tp)
    return out


def _submodel(annotation) -> Optional[type[BaseModel]]:
    for tp in _unwrap(annotation):
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            return tp
    return None


def _model_at(model: type[BaseModel], path: tuple) -> Optional[type[BaseModel]]:
    """The section model reached by following ``path`` (field names) from ``model``."""
    for name in path:
        if not isinstance(name, str) or name not in model.model_fields:
            return None
        sub = _submodel(model.model_fields[name].annotation)
        if sub is None:
            return None
        model = sub
    return model


def _allowed(model: Optional[type[BaseModel]]) -> str:
    return ", ".join(model.model_fields) if model is not None else "?"


def _dotted(path: Iterable) -> str:
    return ".".join(str(p) for p in path)


# --------------------------------------------------------------------------- overrides
def parse_override(text: str) -> tuple[str, Any]:
    """``"a.b=value"`` -> ``("a.b", yaml.safe_load("value"))``."""
    if "=" not in text:
        raise ConfigError(f"override {text!r}: expected KEY=VALUE with a dotted key, e.g. mesh.order=3")
    key, _, value = text.partition("=")
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise ConfigError(f"override {text!r}: empty key")
    try:
        parsed = yaml.safe_load(value) if value.strip() else None
    except yaml.YAMLError:
        parsed = value.strip()  # not YAML: take the text as it is
    return key, parsed


#: top-level keys of a pipeline config (workflow/schemas/pipeline.schema.yaml)
PIPELINE_KEYS = ("verification", "rve", "default_targets", "resources", "induced_deformation", "impact")


class NotASceneConfig(ConfigError):
    """The mapping is a pipeline config (Snakemake), not a scene config. One line."""


def scene_models() -> dict[str, type[SceneConfig]]:
    """scene name -> config model, in the registry's order (``rve.scenes.registry``)."""
    from ..scenes.registry import config_models  # the registry is above rve.config: import on use

    return config_models()


def _allowed_scenes() -> str:
    from ..scenes.registry import scene_names

    return ", ".join(scene_names())


def _check_not_pipeline(raw: Mapping) -> None:
    if "scene" not in raw and raw and all(k in PIPELINE_KEYS for k in raw):
        keys = ", ".join(k for k in PIPELINE_KEYS if k in raw)
        raise NotASceneConfig(
            f"a pipeline config (top-level {keys}), not a scene config: Snakemake reads it "
            f"(snakemake -j2 --configfile FILE) and validates it against workflow/schemas/pipeline.schema.yaml")


def _scene_model(name: Any, where: str = "scene") -> type[SceneConfig]:
    """The config model of scene ``name``: only that scene's config module is imported
    (importing all six cost ~0.17 s of every process that loads one config)."""
    from ..scenes.registry import SCENES

    allowed = _allowed_scenes()
    if name is None:
        raise ConfigError(f"{where} missing (allowed: {allowed})")
    if not isinstance(name, str) or name not in SCENES:
        raise ConfigError(f"{where} = {format_value(name)}: unknown scene (allowed: {allowed})")
    return SCENES[name].model


def apply_overrides(raw: dict, overrides: Iterable[str]) -> dict:
    """Apply ``"dotted.key=value"`` overrides to a raw config mapping (returns a new dict).

    Every key must exist in the scene's model (the ``scene`` named by an override, else the
    one in ``raw``); a mapping value replaces keys of a section one by one."""
    raw = copy.deepcopy(raw)
    parsed = [parse_override(o) for o in overrides]
    for key, value in parsed:
        if key == "scene":
            raw["scene"] = value
    if not parsed:
        return raw
    _check_not_pipeline(raw)
    model = _scene_model(raw.get("scene"))
    errors = []
    for key, value in parsed:
        parts = key.split(".")
        target_model: type[BaseModel] = model
        node = raw
        ok = True
        for i, part in enumerate(parts):
            if part not in target_model.model_fields:
                errors.append(f"{_dotted(parts[: i + 1])}: unknown key (allowed: {_allowed(target_model)})")
                ok = False
                break
            if i == len(parts) - 1:
                break
            sub = _submodel(target_model.model_fields[part].annotation)
            if sub is None:
                errors.append(f"{_dotted(parts[: i + 1])} is not a section, so "
                              f"{_dotted(parts[: i + 2])} does not exist")
                ok = False
                break
            target_model = sub
            child = node.get(part)
            if not isinstance(child, dict):
                child = {}
                node[part] = child
            node = child
        if not ok:
            continue
        last = parts[-1]
        if isinstance(value, dict) and isinstance(node.get(last), dict):
            node[last] = _deep_merge(node[last], value)
        else:
            node[last] = value
    if errors:
        raise ConfigError(errors)
    return raw


def _deep_merge(base: dict, update: Mapping) -> dict:
    out = dict(base)
    for k, v in update.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), dict):
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = v
    return out


# --------------------------------------------------------------------------- errors
_NUMBER_ERRORS = {
    "greater_than", "greater_than_equal", "less_than", "less_than_equal",
    "int_parsing", "int_from_float", "int_type", "int_parsing_size",
    "float_parsing", "float_type", "finite_number", "multiple_of",
}


def _fmt_bound(x: Any) -> str:
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return str(x)


def _range_text(model: Optional[type[BaseModel]], name: Any) -> tuple[str, Optional[str]]:
    """("an integer between 1 and 4", unit) for field ``name`` of ``model``."""
    if model is None or not isinstance(name, str) or name not in model.model_fields:
        return "a valid value", None
    info = model.model_fields[name]
    unit = None
    lo = hi = None  # (op, value)
    for meta in _iter_metadata(info.annotation, info.metadata):
        if isinstance(meta, UnitSpec):
            unit = meta.unit
        elif isinstance(meta, Gt):
            lo = (">", meta.gt)
        elif isinstance(meta, Ge):
            lo = (">=", meta.ge)
        elif isinstance(meta, Lt):
            hi = ("<", meta.lt)
        elif isinstance(meta, Le):
            hi = ("<=", meta.le)
    kinds = _unwrap(info.annotation)
    is_int = int in kinds and float not in kinds
    nullable = type(None) in kinds
    if unit in ("dimensionless",):
        unit = None
    nonzero = any(b is not None and b[1] != 0 for b in (lo, hi))
    u = f" {unit}" if unit and nonzero else ""
    if is_int and lo and hi and lo[0] == ">=" and hi[0] == "<=":
        rng = f"between {_fmt_bound(lo[1])} and {_fmt_bound(hi[1])}"
    else:
        parts = [f"{b[0]} {_fmt_bound(b[1])}{u}" for b in (lo, hi) if b is not None]
        rng = " and ".join(parts)
    if is_int:
        text = f"an integer {rng}".rstrip()
    elif rng:
        text = rng
    else:
        text = "a finite number" + (f" (in {unit} or with units)" if unit else "")
    if nullable:
        text += " (or null)"
    return text, unit


_MISSING = object()


def _raw_at(raw: Any, loc: tuple) -> Any:
    node = raw
    for part in loc:
        if isinstance(node, Mapping) and part in node:
            node = node[part]
        elif isinstance(node, (list, tuple)) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        else:
            return _MISSING
    return node


def _value_text(raw_value: Any, validated: Any, unit: Optional[str]) -> str:
    """Show the value as the user gave it; numbers carry the internal unit."""
    u = f" {unit}" if unit and unit != "dimensionless" else ""
    if raw_value is _MISSING:
        raw_value = validated
    if isinstance(raw_value, bool) or not isinstance(raw_value, (int, float)):
        text = format_value(raw_value)
        if (isinstance(validated, (int, float)) and not isinstance(validated, bool)
                and isinstance(raw_value, str) and u):
            internal = f"{validated:.10g}{u}"
            if " ".join(raw_value.split()) != internal:
                text += f" (= {internal})"
        return text
    return f"{format_value(raw_value)}{u}"


def _format_error(err: dict, model: type[BaseModel], raw: dict) -> str:
    loc = tuple(err.get("loc", ()))
    etype = err.get("type", "")
    # pydantic appends the union member ("int", "function-before[...]") to the loc of
    # errors inside Optional/Union fields; keep the field names only.
    path = []
    m: Optional[type[BaseModel]] = model
    for part in loc:
        if m is not None and isinstance(part, str) and part in m.model_fields:
            path.append(part)
            m = _submodel(m.model_fields[part].annotation)
        elif m is not None and etype == "extra_forbidden" and len(path) == len(loc) - 1:
            path.append(part)
        else:
            break
    loc = tuple(path) if path else loc
    key = _dotted(loc)
    parent = _model_at(model, loc[:-1])
    name = loc[-1] if loc else None
    raw_value = _raw_at(raw, loc)
    validated = err.get("input")

    if etype == "full_line":
        return (f"{key}." if key else "") + str(err.get("ctx", {}).get("text", err.get("msg", "")))
    if etype == "extra_forbidden":
        return f"{key}: unknown key (allowed: {_allowed(parent)})"
    if etype == "missing":
        if loc == ("scene",):
            return f"scene missing (allowed: {_allowed_scenes()})"
        return f"{key} missing"
    if etype in ("model_type", "model_attributes_type", "dict_type"):
        section = _model_at(model, loc)
        return f"{key} = {format_value(raw_value if raw_value is not _MISSING else validated)}: " \
               f"must be a section (a mapping with keys: {_allowed(section)})"
    if etype == "cross_field":
        ctx = err.get("ctx", {})
        prefix = key + "." if key else ""
        k, other = ctx["key"], ctx["other"]
        unit = ctx["u"].strip() or None
        shown = _value_text(_raw_at(raw, loc + (k,)), ctx["value"], unit)
        return (f"{prefix}{k} = {shown}: must be {ctx['relation']} {prefix}{other} "
                f"(which is {ctx['other_value']:.10g}{ctx['u']})")
    if etype == "literal_error":
        if loc == ("scene",):
            return f"scene = {format_value(raw_value)}: unknown scene (allowed: {_allowed_scenes()})"
        expected = err.get("ctx", {}).get("expected", "")
        expected = expected.replace(" or ", ", ")
        return f"{key} = {format_value(raw_value if raw_value is not _MISSING else validated)}: " \
               f"must be one of {expected}"
    rng, unit = _range_text(parent, name)
    if etype in _NUMBER_ERRORS:
        return f"{key} = {_value_text(raw_value, validated, unit)}: must be {rng}"
    if etype.startswith("unit_"):
        return f"{key} = {format_value(raw_value if raw_value is not _MISSING else validated)}: {err['msg']}"
    shown = format_value(raw_value if raw_value is not _MISSING else validated)
    msg = str(err.get("msg", etype))
    if msg.startswith("Value error, "):   # pydantic's prefix of a validator's ValueError
        msg = msg[len("Value error, "):]
    return f"{key} = {shown}: {msg}"


def _errors_from_validation(exc: ValidationError, model: type[BaseModel], raw: dict) -> list[str]:
    lines = []
    for err in exc.errors(include_url=False):
        line = _format_error(err, model, raw)
        if line not in lines:
            lines.append(line)
    return lines


# --------------------------------------------------------------------------- public API
def validate_config(raw: Mapping) -> SceneConfig:
    """Validate a raw mapping (after overrides) against the model of its ``scene``."""
    if not isinstance(raw, Mapping):
        raise ConfigError(f"the config must be a mapping, got {type(raw).__name__}")
    _check_not_pipeline(raw)
    model = _scene_model(raw.get("scene"))
    try:
        return model.model_validate(dict(raw))
    except ValidationError as exc:
        raise ConfigError(_errors_from_validation(exc, model, dict(raw))) from None


def load_config(source: Union[str, os.PathLike, Mapping], overrides: Iterable[str] = ()) -> SceneConfig:
    """Read ``source`` (YAML path or mapping), apply ``overrides`` (``"dotted.key=value"``,
    values parsed by ``yaml.safe_load``) and validate. Raises :class:`ConfigError`."""
    raw = read_config_source(source)
    raw = apply_overrides(raw, overrides)
    return validate_config(raw)


def config_as_dict(cfg: BaseModel) -> dict:
    """The validated config in internal units as plain JSON-serialisable data (provenance).

    ``load_config(config_as_dict(cfg))`` gives back an equal config. (pydantic writes a
    non-finite float as null, so the result holds only finite numbers.)"""
    return json.loads(cfg.model_dump_json())


def config_units(model: Union[BaseModel, type[BaseModel]]) -> dict:
    """Nested mapping of the internal unit of every quantity field (None elsewhere)."""
    cls = model if isinstance(model, type) else type(model)
    out = {}
    for name, info in cls.model_fields.items():
        sub = _submodel(info.annotation)
        if sub is not None:
            out[name] = config_units(sub)
            continue
        unit = None
        for meta in _iter_metadata(info.annotation, info.metadata):
            if isinstance(meta, UnitSpec):
                unit = meta.unit
        out[name] = unit
    return out


def json_schema(scene: str) -> dict:
    """JSON schema of the raw input of ``scene`` (numbers or strings with units), e.g.
    for Snakemake's ``validate``. Raises ConfigError for an unknown scene."""
    model = _scene_model(scene, where="scene")
    schema = model.model_json_schema(mode="validation")
    schema.setdefault("$schema", "https://json-schema.org/draft/2020-12/schema")
    return schema
