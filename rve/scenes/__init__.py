"""Scenes: the numerical experiments (docs/configuration.md).

``registry`` names every scene with its config model and runner; ``protocol`` is what a
scene module provides (``setup``, ``solve -> SceneResult``, ``run``; ``SceneFailure``).
The scene modules (``static_wire``, ``dynamic_wire``, ``fabric_relax``; ``rve_pipeline``
for the Snakemake-built RVE tables) and the packages of the dynamic fabric scenes
(``impact``, ``induced``) are imported only when a scene runs; ``rebuild`` holds their
contact-map rebuild hooks, ``layout`` the file names of their Snakemake targets.
"""
from __future__ import annotations

from .protocol import SceneFailure, SceneResult
from .registry import SCENES, Scene, get_scene, run_scene, scene_names

__all__ = ["SCENES", "Scene", "get_scene", "scene_names", "run_scene", "SceneResult", "SceneFailure"]
