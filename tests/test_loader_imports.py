"""Loading one scene config imports only that scene's config module (rve.config.loader
``_scene_model``: the others cost ~0.17 s of every process, docs/engine.md, "the fixed costs of a process"),
while every error still lists all registered scenes."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_loading_a_config_imports_only_its_scene_model():
    code = ("import sys; from rve.config import load_config; "
            "load_config('configs/scenes/plain_weave_relax.yaml', ['mesh.elements=12']); "
            "mods = ['rve.config.static_wire', 'rve.config.dynamic_wire', 'rve.config.impact', "
            "'rve.config.induced_deformation', 'rve.config.rve']; "
            "print([m for m in mods if m in sys.modules]); print('rve.config.fabric' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    loaded, fabric = out.stdout.strip().splitlines()
    assert loaded == "[]" and fabric == "True"


def test_unknown_scene_error_still_lists_every_scene():
    from rve.config import ConfigError, load_config
    from rve.scenes.registry import scene_names

    with pytest.raises(ConfigError) as err:
        load_config({"scene": "no_such_scene"})
    msg = str(err.value)
    assert "unknown scene" in msg and all(name in msg for name in scene_names())
