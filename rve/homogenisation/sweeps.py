"""Runs and sweeps of the RVE pipeline: combinations, their ids and their configs.

docs/rve_pipeline.md ("Sweeps"). The pipeline config (configs/pipeline.yaml, section
``rve``) names **runs**; a run spec is a mapping::

    scene_config: configs/rve/plain_weave.yaml   # an RVEConfig file (or null)
    scene: {...}                                 # inline RVEConfig keys merged over it
    overrides: ["mesh.elements=20"]              # dotted KEY=VALUE overrides
    sweep: {fibril_radius: [0.12, 0.15], contact_conductance: [0.5, 1.0], weave: [plain, twill_2_2]}

Every point of the product of the sweep lists is a **combination** (:class:`Combo`) with a
readable id (``combo_ids``: ``fibril_radius-0.12__contact_conductance-0.5__weave-plain``;
``base`` without a sweep) and its own jobs. Sweep keys are table dimension names or config
paths (``SWEEP_ALIASES``): ``fibril_radius`` / ``fibril.radius`` (sets
``fabric.fibril_diameter`` = 2 R), ``contact_conductance`` / ``contact.sigma_c``
(``contact.conductance``), ``thermal_contact_conductance`` / ``contact.h_c``,
``contact_penalty``, ``weave`` (``fabric.kind``), ``youngs_modulus``, ``conductivity``,
``thermal_conductivity``, ``spacing``, ``amplitude``, ``realization`` (``packing.seed``: an
ensemble of perturbed packings, ``rve.tables.ensemble``), ``friction_coefficient`` /
``friction.coefficient`` (mu of every fibril pair), or any dotted RVEConfig path
(dimension = the path with dots replaced by underscores). Numeric values are in internal
units or strings with units (converted with the unit of the config field).

Contract
--------
* ``combos(spec)`` -> [Combo(id, params {dimension: value}, overrides (dotted))];
  ``combo_ids(spec)``, ``combo_params(spec, id)``;
* ``swept_dims(spec)`` -> {table dimension: UDUNITS-style units}, in sweep order;
* ``load_run_config(spec, combo_id)`` -> the validated ``RVEConfig`` of one combination.

Cheap to import (the Snakefile imports it at parse time through ``layout``): the config
machinery is imported inside the functions.
"""
from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from typing import Any, Mapping, Optional

__all__ = ["BASE_COMBO", "SWEEP_ALIASES", "Combo", "combos", "combo_ids", "combo_params", "swept_dims",
           "load_run_config", "lever_values"]

#: the one combination of a run without a sweep
BASE_COMBO = "base"

#: sweep key -> (table dimension, config path, factor applied to the value)
SWEEP_ALIASES: dict[str, tuple[str, str, Optional[float]]] = {
    "fibril_radius": ("fibril_radius", "fabric.fibril_diameter", 2.0),
    "fibril.radius": ("fibril_radius", "fabric.fibril_diameter", 2.0),
    "fibril_diameter": ("fibril_diameter", "fabric.fibril_diameter", 1.0),
    "contact_conductance": ("contact_conductance", "contact.conductance", 1.0),
    "contact.sigma_c": ("contact_conductance", "contact.conductance", 1.0),
    "thermal_contact_conductance": ("thermal_contact_conductance", "contact.heat_transfer", 1.0),
    "contact.h_c": ("thermal_contact_conductance", "contact.heat_transfer", 1.0),
    "contact_penalty": ("contact_penalty", "contact.penalty", 1.0),
    "weave": ("weave", "fabric.kind", None),
    "youngs_modulus": ("youngs_modulus", "material.youngs_modulus", 1.0),
    "conductivity": ("conductivity", "material.electrical_conductivity", 1.0),
    "thermal_conductivity": ("thermal_conductivity", "material.thermal_conductivity", 1.0),
    "spacing": ("spacing", "fabric.spacing", 1.0),
    "amplitude": ("amplitude", "fabric.amplitude", 1.0),
    "realization": ("realization", "packing.seed", 1.0),  # an ensemble of packings (rve.tables.ensemble)
    "friction_coefficient": ("friction_coefficient", "friction.coefficient", 1.0),
    "friction.coefficient": ("friction_coefficient", "friction.coefficient", 1.0),
}



@dataclass(frozen=True)
class Combo:
    id: str
    params: dict          # table dimension -> value
    overrides: tuple      # dotted config overrides


def _sweep_key(key: str) -> tuple[str, str, Optional[float]]:
    if key in SWEEP_ALIASES:
        return SWEEP_ALIASES[key]
    if "." not in key:
        raise ValueError(f"unknown sweep parameter {key!r}: use one of {sorted(SWEEP_ALIASES)} or a dotted "
                         "config path such as contact.penalty")
    return key.replace(".", "_"), key, 1.0


def _path_unit(path: str) -> Optional[str]:
    from ..config import config_units

    from ..config.rve import RVEConfig

    node: Any = config_units(RVEConfig)
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node if isinstance(node, str) else None


def _sweep_value(value, path: str):
    if isinstance(value, bool):
        raise ValueError(f"sweep of {path}: booleans are not supported")
    if isinstance(value, (int, float)):
        return float(value)
    unit = _path_unit(path)
    if unit is None:
        return str(value)
    from ..config.units import convert

    return float(convert(value, unit))


def _token(v) -> str:
    if isinstance(v, float):
        return format(v, ".12g")
    return str(v)


def combos(spec: Mapping) -> list[Combo]:
    """The combinations of a run spec's ``sweep`` (one ``base`` combination without)."""
    sweep = dict(spec.get("sweep") or {})
    if not sweep:
        return [Combo(BASE_COMBO, {}, ())]
    keys, dims, lists = [], [], []
    for key, values in sweep.items():
        dim, path, factor = _sweep_key(str(key))
        if dim in dims:
            raise ValueError(f"sweep: parameter {dim!r} given twice")
        vals = []
        for v in (values if isinstance(values, (list, tuple)) else [values]):
            try:
                vals.append(_sweep_value(v, path))
            except ValueError as exc:   # name the sweep key (UnitConversionError is a ValueError)
                from ..config import ConfigError

                raise ConfigError(f"sweep.{key} = {v!r}: {getattr(exc, 'message', exc)} (sweep parameter {key} "
                                  f"sets {path}, unit {_path_unit(path) or '1'})") from None
        if not vals or len(set(map(_token, vals))) != len(vals):
            raise ValueError(f"sweep {key}: needs distinct values, got {values!r}")
        keys.append((dim, path, factor))
        dims.append(dim)
        lists.append(vals)
    out = []
    for point in itertools.product(*lists):
        params, overrides, parts = {}, [], []
        for (dim, path, factor), v in zip(keys, point):
            params[dim] = v
            cv = v * factor if (factor is not None and isinstance(v, float)) else v
            overrides.append(f"{path}={json.dumps(cv)}")
            parts.append(f"{dim}-{_token(v)}")
        out.append(Combo("__".join(parts), params, tuple(overrides)))
    return out


def combo_ids(spec: Mapping) -> list[str]:
    return [c.id for c in combos(spec)]


def _combo(spec: Mapping, combo_id: str) -> Combo:
    for c in combos(spec):
        if c.id == combo_id:
            return c
    raise ValueError(f"unknown combination {combo_id!r} (have {combo_ids(spec)})")


def combo_params(spec: Mapping, combo_id: str) -> dict:
    return dict(_combo(spec, combo_id).params)


def swept_dims(spec: Mapping) -> dict:
    """{table dimension: units} of a run's sweep (in sweep order)."""
    out = {}
    for key in (spec.get("sweep") or {}):
        dim, path, _ = _sweep_key(str(key))
        unit = _path_unit(path)
        out[dim] = _table_unit(unit) if unit else "1"
    return out


_UNIT_TEXT = {"mm": "mm", "MPa": "MPa", "A/(mm^2*V)": "A mm-2 V-1", "W/(mm^2*K)": "W mm-2 K-1", "S/mm": "S mm-1",
              "W/(mm*K)": "W mm-1 K-1", "N/mm^2": "N mm-2", "ms": "ms", "g/mm^3": "g mm-3", "V": "V",
              "g/(mm^3*ms)": "N ms mm-4", "dimensionless": "1"}


def _table_unit(unit: str) -> str:
    """Internal unit of a config field as a UDUNITS-style string for the table."""
    return _UNIT_TEXT.get(unit, unit)


def load_run_config(spec: Mapping, combo_id: str = BASE_COMBO):
    """The validated ``RVEConfig`` of one combination of a run spec."""
    from ..config import apply_overrides, read_config_source, validate_config
    from ..config.loader import _deep_merge

    path = spec.get("scene_config")
    raw = read_config_source(path) if path else {}
    inline = spec.get("scene") or {}
    raw = _deep_merge(raw, dict(inline)) if inline else raw
    raw.setdefault("scene", "rve")
    combo = _combo(spec, combo_id)
    raw = apply_overrides(raw, [*(spec.get("overrides") or []), *combo.overrides])
    return validate_config(raw)


def lever_values(spec: Mapping) -> dict:
    """The method levers of a run's base combination, as a work-precision study names them
    (``rve.studies.work_precision``): elements per fibril, P*, p, contact points, boundary,
    cell repeat, contact geometry and enforcement."""
    cfg = load_run_config(spec)
    return {"mesh_elements": float(cfg.mesh.elements), "contact_penalty": float(cfg.contact.penalty),
            "mesh_order": int(cfg.mesh.order), "contact_n_gp": int(cfg.contact.n_gp),
            "boundary": str(cfg.boundary), "cell_repeat": int(cfg.cell.repeat),
            "contact_geometry": str(cfg.contact.geometry), "contact_enforcement": str(cfg.contact.enforcement)}

