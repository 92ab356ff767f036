"""The scene registry: the one list naming every scene with its config model and runner.

Contract
--------
:data:`SCENES` maps a scene name (the ``scene`` key of a config) to a :class:`Scene`:
its config model and its runner, both given as import paths and imported only when asked
for (so importing the registry stays cheap and imports no physics). Nothing registers
itself on import: adding a scene is one entry here (docs/configuration.md, "Adding a
scene").

Two kinds of scene:

* ``kind="scene"``: the runner is a module with the scene protocol
  (``rve.scenes.protocol``): ``setup(cfg)``, ``solve(cfg) -> SceneResult``,
  ``run(cfg, out_dir) -> dict`` (the summary; outputs written under ``out_dir``), failures
  raised as ``SceneFailure``. :func:`run_scene` runs it.
* ``kind="pipeline"``: a chain of Snakemake jobs (the RVE homogenisation); the runner
  module gives ``snakemake_command(config_path, overrides)``, the command that builds the
  scene's product (``rve run`` prints it, docs/configuration.md).

The loader (``rve.config.loader``) asks :func:`config_models` for the model of a
``scene`` name, and every "allowed:" list of an error is :func:`scene_names`.
"""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Union

__all__ = ["Scene", "SCENES", "scene_names", "get_scene", "config_models", "run_scene"]


def _load(path: str):
    module, _, attr = path.partition(":")
    obj = importlib.import_module(module)
    return getattr(obj, attr) if attr else obj


@dataclass(frozen=True)
class Scene:
    """One scene: ``config`` ("module:Class") is its config model, ``runner`` ("module")
    the module that runs it; ``kind`` "scene" (in-process) or "pipeline" (Snakemake)."""

    name: str
    config: str
    runner: str
    kind: Literal["scene", "pipeline"] = "scene"

    @property
    def model(self):
        """The config model class (imported on first use)."""
        return _load(self.config)

    @property
    def module(self):
        """The runner module (imported on first use)."""
        return _load(self.runner)

    @property
    def title(self) -> str:
        """First line of the config model's docstring."""
        doc = (self.model.__doc__ or "").strip()
        return doc.splitlines()[0] if doc else ""


#: scene name -> Scene (the one registry; order = the order of every "allowed:" list)
SCENES: dict[str, Scene] = {s.name: s for s in (
    Scene("static_wire", "rve.config.static_wire:StaticWireConfig", "rve.scenes.static_wire"),
    Scene("dynamic_wire", "rve.config.dynamic_wire:DynamicWireConfig", "rve.scenes.dynamic_wire"),
    Scene("fabric_relax", "rve.config.fabric:FabricRelaxConfig", "rve.scenes.fabric_relax"),
    Scene("rve", "rve.config.rve:RVEConfig", "rve.scenes.rve_pipeline", kind="pipeline"),
    Scene("induced_deformation", "rve.config.induced_deformation:InducedDeformationConfig",
          "rve.scenes.induced"),
    Scene("impact", "rve.config.impact:ImpactConfig", "rve.scenes.impact"),
    Scene("capstan", "rve.config.friction:CapstanConfig", "rve.scenes.capstan"),
    Scene("friction_crossing", "rve.config.friction:FrictionCrossingConfig", "rve.scenes.friction_crossing"),
)}


def scene_names() -> tuple[str, ...]:
    """The registered scene names, in registry order."""
    return tuple(SCENES)


def get_scene(name: str) -> Scene:
    """The registry entry of ``name``; KeyError listing the registered names otherwise."""
    try:
        return SCENES[name]
    except (KeyError, TypeError):
        raise KeyError(f"unknown scene {name!r} (allowed: {', '.join(SCENES)})") from None


def config_models() -> dict:
    """scene name -> config model class (imports the config modules, not the runners)."""
    return {name: s.model for name, s in SCENES.items()}


def run_scene(cfg, out_dir: Union[str, os.PathLike]) -> dict:
    """Run the in-process scene named by ``cfg.scene`` with outputs under ``out_dir``
    (created); returns its summary. A ``SceneFailure`` propagates (the scene saved its
    last good state under ``out_dir`` first); a pipeline scene is a ValueError."""
    scene = get_scene(cfg.scene)
    if scene.kind != "scene":
        raise ValueError(f"scene {scene.name!r} is a pipeline scene: build it with Snakemake "
                         f"({scene.runner}.snakemake_command)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary = scene.module.run(cfg, out)
    if not isinstance(summary, dict):
        raise TypeError(f"{scene.runner}.run returned {type(summary).__name__}, expected a dict")
    return summary
