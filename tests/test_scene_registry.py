"""The one scene registry (rve.scenes.registry): complete, the only list, no side effects."""
import subprocess
import sys
from pathlib import Path

import pytest

from rve import cli
from rve.config import ConfigError, SceneConfig, json_schema, load_config, scene_name, scene_models
from rve.scenes.registry import SCENES, get_scene, scene_names

ROOT = Path(__file__).resolve().parents[1]
EXPECTED = ("static_wire", "dynamic_wire", "fabric_relax", "rve", "induced_deformation", "impact", "capstan",
            "friction_crossing")


def test_the_registry_names_every_scene():
    assert scene_names() == EXPECTED


@pytest.mark.parametrize("name", EXPECTED)
def test_every_scene_has_a_config_model_and_a_runner(name):
    scene = get_scene(name)
    model = scene.model
    assert issubclass(model, SceneConfig) and scene_name(model) == name
    module = scene.module
    if scene.kind == "scene":
        for fn in ("setup", "solve", "run"):
            assert callable(getattr(module, fn)), (name, fn)
    else:
        assert scene.kind == "pipeline" and callable(module.snakemake_command)
    assert scene.title


def test_the_loader_uses_the_registry():
    assert list(scene_models()) == list(SCENES)
    assert all(scene_models()[n] is SCENES[n].model for n in SCENES)


def test_rve_scenes_lists_exactly_the_registry(capsys):
    assert cli.main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == list(SCENES)
    assert [line.split()[1] for line in lines] == [s.kind for s in SCENES.values()]


def test_unknown_scene_errors_list_the_registry(capsys):
    allowed = "(allowed: " + ", ".join(SCENES) + ")"
    for raw in ({"scene": "nope"}, {"mesh": {}}):
        with pytest.raises(ConfigError) as info:
            load_config(raw)
        assert allowed in str(info.value)
    with pytest.raises(ConfigError, match=r"\(allowed: static_wire, dynamic_wire, fabric_relax, rve, induced_deformation, impact, capstan, friction_crossing\)"):
        json_schema("nope")
    with pytest.raises(ConfigError, match=r"\(allowed: static_wire, dynamic_wire, fabric_relax, rve, induced_deformation, impact, capstan, friction_crossing\)"):
        load_config({"mesh": {}}, ["mesh.order=2"])
    assert cli.main(["schema", "nope"]) == 2
    assert allowed in capsys.readouterr().err
    with pytest.raises(KeyError, match="allowed: static_wire, dynamic_wire, fabric_relax, rve, induced_deformation, impact, capstan, friction_crossing"):
        get_scene("nope")


@pytest.mark.parametrize("name", EXPECTED)
def test_schema_of_every_scene(name):
    schema = json_schema(name)
    assert "properties" in schema and "scene" in schema["properties"]


def _modules_after(statement: str) -> set:
    code = f"import sys; {statement}; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return set(out.stdout.split())


def test_no_module_registers_on_import():
    """Importing the config package imports no scene and no scene config module; importing
    the registry imports no config model and no runner."""
    mods = _modules_after("import rve.config")
    assert not {m for m in mods if m.startswith(("rve.scenes", "rve.homogenisation"))}
    assert not {"rve.config.static_wire", "rve.config.dynamic_wire", "rve.config.fabric"} & mods
    mods = _modules_after("import rve.scenes.registry")
    assert not {"rve.scenes.static_wire", "rve.scenes.dynamic_wire", "rve.scenes.fabric_relax",
                "rve.config.rve", "rve.config.static_wire", "rve.model"} & mods
    for module in ("rve.config.static_wire", "rve.config.dynamic_wire", "rve.config.fabric",
                   "rve.config.rve"):
        mods = _modules_after(f"import {module}")
        assert not {m for m in mods if m.startswith("rve.scenes")}, module


def test_homogenisation_does_not_import_scenes():
    mods = _modules_after("import rve.homogenisation.strain, rve.homogenisation.probes, rve.homogenisation.jobs, rve.homogenisation.sweeps")
    assert not {m for m in mods if m.startswith("rve.scenes")}


def test_no_registration_helpers_left():
    import rve.config

    assert not hasattr(rve.config, "SCENE_MODELS") and not hasattr(rve.config, "register_scene_model")
    src = "\n".join(p.read_text() for p in (ROOT / "rve").rglob("*.py"))
    assert "register_scene_model" not in src and "SimulationAborted" not in src and '"_state"' not in src
