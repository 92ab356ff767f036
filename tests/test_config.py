"""Config: units, models, loader, overrides and error messages."""
import json
import math
from pathlib import Path
from typing import Literal

import pytest

from rve.config import (
    ConfigError,
    config_as_dict,
    json_schema,
    load_config,
    to_internal,
)
from rve.config.fields import Length, MagneticField, SceneConfig, Section
from rve.config.static_wire import StaticWireConfig
from rve.scenes.registry import SCENES, Scene

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "configs" / "scenes" / "static_wire.yaml"


def wire(**sections):
    return {"scene": "static_wire", **sections}


def error_of(source, overrides=()):
    with pytest.raises(ConfigError) as info:
        load_config(source, overrides)
    return str(info.value)


# --------------------------------------------------------------------------- units
@pytest.mark.parametrize(
    "value, unit, expected",
    [
        ("1 T", "kT", 1e-3),
        ("0.02 mm", "mm", 0.02),
        ("20 um", "mm", 0.02),
        ("10 kPa", "MPa", 0.01),
        ("45 deg", "rad", math.pi / 4),
        ("pi/4 rad", "rad", math.pi / 4),
        (0.5, "rad", 0.5),  # bare numbers are radians
        ("30 m/s", "mm/ms", 30.0),
        ("1 A/mm^2", "A/mm^2", 1.0),
        ("1 A/m^2", "A/mm^2", 1e-6),
        ("1 g/cm^3", "g/mm^3", 1e-3),
        ("2e-3 N*ms/mm^4", "g/(mm^3*ms)", 2e-3),
        ("1 W/(m*K)", "W/(mm*K)", 1e-3),
        ("1 S/m", "S/mm", 1e-3),
        ("1 C", "mC", 1e3),
        ("20 degC", "K", 293.15),
        ("1 %", "dimensionless", 0.01),
        ("1e-3", "mm", 1e-3),  # YAML 1.1 reads 1e-3 as a string: still a bare number
        (7, "mm", 7.0),
    ],
)
def test_to_internal_converts(value, unit, expected):
    assert to_internal(value, unit, "k") == pytest.approx(expected, rel=1e-12)


def test_consistent_units_force_density():
    # J x B in internal units is a force density in N/mm^3: no hidden factors.
    jb = to_internal("1 A/mm^2", "A/mm^2", "j") * to_internal("1 T", "kT", "b")
    assert jb == pytest.approx(to_internal("1e6 N/m^3", "N/mm^3", "f"))


@pytest.mark.parametrize(
    "value, unit, expected_text",
    [
        ("1 m", "kT", "expected magnetic field (kT)"),
        ("45 deg", "mm", "expected length (mm)"),
        ("1 m", "rad", "expected angle (rad)"),
        ("3 s", "mm/ms", "expected velocity (mm/ms)"),
        ("1 mm", "dimensionless", "expected a dimensionless number"),
    ],
)
def test_to_internal_wrong_dimension(value, unit, expected_text):
    with pytest.raises(ConfigError) as info:
        to_internal(value, unit, "a.key")
    msg = str(info.value)
    assert msg.startswith(f"a.key = {value!r}: wrong dimension")
    assert expected_text in msg


@pytest.mark.parametrize("value", ["not a unit", True, [1.0], "nan mm", float("inf")])
def test_to_internal_rejects_garbage(value):
    with pytest.raises(ConfigError, match=r"^a\.key = "):
        to_internal(value, "mm", "a.key")


# --------------------------------------------------------------------------- defaults
def test_default_config_internal_values():
    cfg = load_config(DEFAULT)
    assert isinstance(cfg, StaticWireConfig)
    assert cfg.geometry.half_length == 1.0
    assert cfg.geometry.clamp_half_distance == 0.5
    assert cfg.fibril.radius == pytest.approx(0.02)
    assert cfg.material.youngs_modulus == pytest.approx(0.01)  # 10 kPa
    assert cfg.material.poisson_ratio == 0.0
    assert cfg.material.density == pytest.approx(1e-3)  # 1 g/cm^3
    assert cfg.load.current_density == pytest.approx(1.0)
    assert cfg.load.field_magnitude == pytest.approx(1e-3)  # 1 T
    assert cfg.load.field_angle == pytest.approx(math.pi / 4)  # 45 deg
    assert (cfg.mesh.order, cfg.mesh.elements, cfg.mesh.disk_points) == (2, 40, 4)
    assert cfg.mesh.axial_points is None and cfg.mesh.resolved_axial_points == 3
    assert cfg.solver.path == "dynamic_relaxation"
    assert cfg.solver.relaxation.duration == pytest.approx(5.0)
    assert cfg.solver.relaxation.steps == 50
    assert cfg.solver.relaxation.damping == pytest.approx(2e-3)
    assert cfg.solver.relaxation.perturbation == pytest.approx(0.01)
    assert cfg.solver.newton.atol == pytest.approx(1e-10)
    assert cfg.solver.newton.rtol == pytest.approx(1e-12)
    assert cfg.solver.newton.max_iter == 50
    # Table 6.1: k = J B / E = 0.1 (per unit half length)
    k = cfg.load.current_density * cfg.load.field_magnitude / cfg.material.youngs_modulus
    assert k * cfg.geometry.half_length == pytest.approx(0.1)


def test_yaml_file_equals_model_defaults():
    # The YAML writes every key out; it must describe the same case as the defaults.
    assert load_config(DEFAULT) == load_config({"scene": "static_wire"})


def test_yaml_file_writes_every_key():
    import yaml

    raw = yaml.safe_load(DEFAULT.read_text())

    def keys(model, prefix=""):
        out = set()
        for name, info in model.model_fields.items():
            ann = info.annotation
            if isinstance(ann, type) and issubclass(ann, Section):
                out |= keys(ann, prefix + name + ".")
            else:
                out.add(prefix + name)
        return out

    def raw_keys(d, prefix=""):
        out = set()
        for k, v in d.items():
            out |= raw_keys(v, prefix + k + ".") if isinstance(v, dict) else {prefix + k}
        return out

    assert raw_keys(raw) == keys(StaticWireConfig)


def test_config_as_dict_roundtrip_and_json():
    cfg = load_config(DEFAULT)
    d = config_as_dict(cfg)
    json.dumps(d)  # serialisable
    assert d["load"]["field_magnitude"] == pytest.approx(1e-3)
    assert d["scene"] == "static_wire"
    assert load_config(d) == cfg


# --------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "source, expected",
    [
        (wire(geometry={"colour": "red"}),
         "geometry.colour: unknown key (allowed: half_length, clamp_half_distance)"),
        (wire(colour=1), "colour: unknown key (allowed: scene, geometry"),
        ({"mesh": {"order": 2}}, "scene missing (allowed: static_wire, dynamic_wire, fabric_relax, rve, induced_deformation, impact, capstan, friction_crossing)"),
        ({"scene": "nope"}, "scene = 'nope': unknown scene (allowed: static_wire, dynamic_wire, fabric_relax, rve, induced_deformation, impact, capstan, friction_crossing)"),
        (wire(load={"field_magnitude": "1 m"}),
         "load.field_magnitude = '1 m': wrong dimension, expected magnetic field (kT)"),
        (wire(load={"field_angle": "1 m"}), "load.field_angle = '1 m': wrong dimension, expected angle (rad)"),
        (wire(fibril={"radius": -0.1}), "fibril.radius = -0.1 mm: must be > 0"),
        (wire(fibril={"radius": "-100 um"}), "fibril.radius = '-100 um' (= -0.1 mm): must be > 0"),
        (wire(fibril={"radius": 0}), "fibril.radius = 0 mm: must be > 0"),
        (wire(mesh={"order": 0}), "mesh.order = 0: must be an integer between 1 and 4"),
        (wire(mesh={"order": 5}), "mesh.order = 5: must be an integer between 1 and 4"),
        (wire(mesh={"order": 2.5}), "mesh.order = 2.5: must be an integer between 1 and 4"),
        (wire(mesh={"order": True}), "mesh.order = True: must be an integer between 1 and 4"),
        (wire(mesh={"elements": 0}), "mesh.elements = 0: must be an integer >= 1"),
        (wire(mesh={"disk_points": 5}), "mesh.disk_points = 5: must be one of 4, 8, 16"),
        (wire(mesh={"axial_points": 0}), "mesh.axial_points = 0: must be an integer >= 1"),
        (wire(material={"poisson_ratio": 0.5}), "material.poisson_ratio = 0.5: must be >= 0 and < 0.5"),
        (wire(solver={"path": "newton"}),
         "solver.path = 'newton': must be one of 'dynamic_relaxation', 'continuation'"),
        (wire(solver={"relaxation": {"damping": -1}}), "solver.relaxation.damping = -1 g/(mm^3*ms): must be >= 0"),
        (wire(solver={"newton": {"max_iter": 0}}), "solver.newton.max_iter = 0: must be an integer >= 1"),
        (wire(solver={"newton": {"colour": 0}}),
         "solver.newton.colour: unknown key (allowed: atol, rtol, max_iter)"),
        (wire(geometry=5), "geometry = 5: must be a section (a mapping with keys: half_length, clamp_half_distance)"),
        (wire(geometry={"clamp_half_distance": 1.0}),
         "geometry.clamp_half_distance = 1.0 mm: must be < geometry.half_length (which is 1 mm)"),
        (wire(geometry={"clamp_half_distance": "3 mm", "half_length": "2 mm"}),
         "geometry.clamp_half_distance = '3 mm': must be < geometry.half_length (which is 2 mm)"),
    ],
)
def test_error_messages(source, expected):
    assert expected in error_of(source)


def test_all_errors_listed_one_per_line():
    msg = error_of(wire(mesh={"order": 5, "elements": 0}, fibril={"radius": -1}, geometry={"colour": 1}))
    lines = msg.splitlines()
    assert len(lines) == 4
    assert any(line.startswith("mesh.order = 5") for line in lines)
    assert any(line.startswith("mesh.elements = 0") for line in lines)
    assert any(line.startswith("fibril.radius = -1 mm") for line in lines)
    assert any(line.startswith("geometry.colour: unknown key") for line in lines)


def test_config_error_is_value_error():
    assert issubclass(ConfigError, ValueError)
    with pytest.raises(ValueError):
        load_config(wire(mesh={"order": 9}))


def test_missing_required_key_in_a_new_scene(monkeypatch):
    from pydantic import Field

    class Needs(Section):
        elements: int = Field(ge=1)

    class NewScene(SceneConfig):
        scene: Literal["needs"]
        mesh: Needs

    import sys
    import types

    module = types.ModuleType("rve_needs_scene_for_tests")
    module.NewScene = NewScene
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(SCENES, "needs", Scene("needs", f"{module.__name__}:NewScene", module.__name__))
    assert "mesh.elements missing" in error_of({"scene": "needs", "mesh": {}})
    assert "mesh missing" in error_of({"scene": "needs"})


def test_missing_file_and_bad_yaml(tmp_path):
    assert "cannot read config file" in error_of(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("scene: [static_wire\n")
    assert "invalid YAML" in error_of(bad)
    listy = tmp_path / "list.yaml"
    listy.write_text("- 1\n- 2\n")
    assert "must be a mapping" in error_of(listy)


# --------------------------------------------------------------------------- overrides
def test_overrides_with_units_and_numbers():
    cfg = load_config(DEFAULT, [
        "load.field_magnitude=2 T",
        "mesh.order=3",
        "fibril.radius=10 um",
        "solver.relaxation.duration=0.002 s",
        "load.field_angle=pi/2 rad",
        "mesh.axial_points=5",
        "solver.newton.atol=1e-8",
    ])
    assert cfg.load.field_magnitude == pytest.approx(2e-3)
    assert cfg.mesh.order == 3 and isinstance(cfg.mesh.order, int)
    assert cfg.fibril.radius == pytest.approx(0.01)
    assert cfg.solver.relaxation.duration == pytest.approx(2.0)
    assert cfg.load.field_angle == pytest.approx(math.pi / 2)
    assert cfg.mesh.axial_points == 5
    assert cfg.solver.newton.atol == pytest.approx(1e-8)
    # untouched values survive
    assert cfg.material.youngs_modulus == pytest.approx(0.01)


def test_override_of_missing_section_and_mapping_value():
    cfg = load_config({"scene": "static_wire"}, ["solver.newton.max_iter=7", "mesh={order: 4, elements: 3}"])
    assert cfg.solver.newton.max_iter == 7
    assert (cfg.mesh.order, cfg.mesh.elements) == (4, 3)


def test_override_last_wins_and_null():
    cfg = load_config(DEFAULT, ["mesh.order=3", "mesh.order=1", "mesh.axial_points=null"])
    assert cfg.mesh.order == 1 and cfg.mesh.axial_points is None


@pytest.mark.parametrize(
    "override, expected",
    [
        ("geometry.colour=1", "geometry.colour: unknown key (allowed: half_length, clamp_half_distance)"),
        ("colour=1", "colour: unknown key"),
        ("mesh.order.deep=1", "mesh.order is not a section"),
        ("mesh.order", "expected KEY=VALUE"),
        ("mesh.order=5", "mesh.order = 5: must be an integer between 1 and 4"),
        ("load.field_magnitude=1 m", "load.field_magnitude = '1 m': wrong dimension, expected magnetic field (kT)"),
    ],
)
def test_bad_overrides(override, expected):
    assert expected in error_of(DEFAULT, [override])


def test_override_does_not_modify_source_dict():
    src = wire(mesh={"order": 2})
    load_config(src, ["mesh.order=3"])
    assert src == wire(mesh={"order": 2})


# --------------------------------------------------------------------------- extension points
def test_quantity_types_for_new_models():
    from pydantic import Field

    class Probe(Section):
        gap: Length = Field(gt=0)
        field: MagneticField = Field("2 T", ge=0)

    p = Probe(gap="3 um")
    assert p.gap == pytest.approx(3e-3) and p.field == pytest.approx(2e-3)
    with pytest.raises(Exception):
        Probe(gap="1 T")
    with pytest.raises(Exception):
        Probe(gap=1, colour=2)


def test_bare_section_field_takes_the_section_defaults():
    from pydantic import Field

    class Inner(Section):
        gap: Length = Field("2 mm", gt=0)

    def _wide():
        return Inner(gap="5 mm")

    class Needs(Section):
        elements: int = Field(ge=1)

    class Outer(SceneConfig):
        scene: Literal["outer"] = Field(description="scene name")
        first: Inner
        count: int
        wide: Inner = Field(default_factory=_wide)
        last: Inner
        needs: Needs

    keys = ["scene", "first", "count", "wide", "last", "needs"]
    assert list(Outer.model_fields) == keys
    assert Outer.model_json_schema()["required"] == ["scene", "count", "needs"]
    cfg = Outer(scene="outer", count=1, last={"gap": "3 mm"}, needs={"elements": 2})
    assert (cfg.first.gap, cfg.wide.gap, cfg.last.gap) == (2.0, 5.0, 3.0)
    assert list(cfg.model_dump()) == keys
    with pytest.raises(Exception, match="first.gap"):
        Outer(scene="outer", count=1, first={"gap": -1}, needs={"elements": 2})


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scene_sections_default_in_declaration_order(name):
    from rve.config.loader import scene_models

    model = scene_models()[name]
    declared = [k for cls in reversed(model.__mro__) for k in getattr(cls, "__annotations__", {})
                if k in model.model_fields]
    assert list(model.model_fields) == list(dict.fromkeys(declared))
    cfg = model(scene=name)
    for key, info in model.model_fields.items():
        if isinstance(info.annotation, type) and issubclass(info.annotation, Section):
            assert not info.is_required(), key
            assert isinstance(getattr(cfg, key), info.annotation)


def test_json_schema_accepts_raw_yaml():
    import jsonschema
    import yaml

    schema = json_schema("static_wire")
    raw = yaml.safe_load(DEFAULT.read_text())
    jsonschema.validate(raw, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**raw, "colour": 1}, schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({k: v for k, v in raw.items() if k != "scene"}, schema)
    radius = schema["$defs"]["Fibril"]["properties"]["radius"]
    assert radius["x-unit"] == "mm"
    with pytest.raises(ConfigError, match="unknown scene"):
        json_schema("nope")
