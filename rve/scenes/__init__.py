"""Scenes: the numerical experiments, each a module with ``run(cfg, out_dir) -> dict``.

:data:`SCENES` maps a scene name (the config's ``scene`` key, see
``rve.config.models.SCENE_MODELS``) to the module implementing it; modules are imported
only when a scene runs, so importing ``rve.scenes`` stays cheap.
"""
from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Union

from ..config import fabric as _fabric_config  # noqa: F401  (registers the fabric_relax config model)
from ..config import dynamic_wire as _dynamic_wire_config  # noqa: F401  (registers the dynamic_wire config model)

__all__ = ["SCENES", "scene_module", "run_scene"]

#: scene name -> module path; the module defines ``run(cfg, out_dir: pathlib.Path) -> dict``
SCENES: dict[str, str] = {
    "static_wire": "rve.scenes.static_wire",
    "fabric_relax": "rve.scenes.fabric_relax",
    "dynamic_wire": "rve.scenes.dynamic_wire",
}


def scene_module(name: str):
    """Import and return the module of scene ``name``."""
    try:
        module_path = SCENES[name]
    except KeyError:
        raise KeyError(f"unknown scene {name!r} (known: {', '.join(SCENES)})") from None
    return importlib.import_module(module_path)


def run_scene(cfg, out_dir: Union[str, os.PathLike]) -> dict:
    """Run the scene named by ``cfg.scene`` with outputs under ``out_dir`` (created);
    returns the scene's summary dict."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    module = scene_module(cfg.scene)
    summary = module.run(cfg, out)
    if not isinstance(summary, dict):
        raise TypeError(f"{SCENES[cfg.scene]}.run returned {type(summary).__name__}, expected a dict")
    return summary
