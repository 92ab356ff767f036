"""File layout of the dynamic scenes' Snakemake targets (workflow/rules/impact.smk,
induced_deformation.smk): every path those rules name comes from here, as the RVE
pipeline's come from ``rve.homogenisation.layout``. Data only: importing it imports no
scene. Every function takes plain strings, so a rule passes wildcards as ``"{case}"``.

Contract
--------
* ``impact_dir(case)`` (``results/impact/<case>``) and ``impact_file(case, kind)``, ``kind``
  one of ``IMPACT_FILES`` (relaxed state, relaxation record, summary, netCDF); the current
  sweep: ``impact_sweep_dir(current)``, ``impact_file(f"sweep/J{current}", "summary")``,
  ``IMPACT_SWEEP_PNG``, ``IMPACT_SWEEP_JSON``; the velocity sweep: ``impact_velocity_dir(speed)``,
  ``impact_file(f"velocity_sweep/v{speed}", "summary")``, ``IMPACT_VELOCITY_SWEEP_PNG``,
  ``IMPACT_VELOCITY_SWEEP_JSON``;
* ``induced_dir(orientation)`` and ``induced_file(orientation, kind)``, ``kind`` one of
  ``INDUCED_FILES``; ``INDUCED_FRAMES_PNG``, ``INDUCED_TEMPERATURE_PNG``; the current sweep:
  ``induced_current_dir(current)``, ``induced_current_file(current, kind)``,
  ``INDUCED_CURRENT_SWEEP_PNG``, ``INDUCED_CURRENT_SWEEP_JSON``;
* ``log_path(scene, name)`` (``results/logs/<scene>/<name>.log``) and
  ``benchmark_path(scene, name)`` (``results/benchmarks/<scene>/<name>.tsv``).
"""
from __future__ import annotations

__all__ = ["IMPACT_DIR", "IMPACT_FILES", "impact_dir", "impact_file", "impact_sweep_dir", "IMPACT_SWEEP_PNG",
           "IMPACT_SWEEP_JSON", "INDUCED_DIR", "INDUCED_FILES", "induced_dir", "induced_file", "INDUCED_FRAMES_PNG",
           "INDUCED_TEMPERATURE_PNG", "log_path", "benchmark_path", "impact_velocity_dir", "IMPACT_VELOCITY_SWEEP_PNG",
           "IMPACT_VELOCITY_SWEEP_JSON", "induced_current_dir", "induced_current_file", "INDUCED_CURRENT_SWEEP_PNG",
           "INDUCED_CURRENT_SWEEP_JSON"]

IMPACT_DIR = "results/impact"
INDUCED_DIR = "results/induced_deformation"
IMPACT_FILES = {"relaxed": "relaxed_state.npz", "relaxation": "relaxation.json", "summary": "summary.json",
                "netcdf": "impact.nc"}
INDUCED_FILES = {"summary": "summary.json", "netcdf": "induced_deformation.nc"}
IMPACT_SWEEP_PNG = f"{IMPACT_DIR}/sweep/current_sweep.png"
IMPACT_SWEEP_JSON = f"{IMPACT_DIR}/sweep/current_sweep.json"
INDUCED_FRAMES_PNG = f"{INDUCED_DIR}/fig_8_3_1_frames.png"
INDUCED_TEMPERATURE_PNG = f"{INDUCED_DIR}/fig_8_3_2_temperature.png"
IMPACT_VELOCITY_SWEEP_PNG = f"{IMPACT_DIR}/velocity_sweep/velocity_sweep.png"
IMPACT_VELOCITY_SWEEP_JSON = f"{IMPACT_DIR}/velocity_sweep/velocity_sweep.json"
INDUCED_CURRENT_SWEEP_PNG = f"{INDUCED_DIR}/current_sweep/current_sweep.png"
INDUCED_CURRENT_SWEEP_JSON = f"{INDUCED_DIR}/current_sweep/current_sweep.json"


def impact_dir(case: str) -> str:
    return f"{IMPACT_DIR}/{case}"


def impact_file(case: str, kind: str) -> str:
    return f"{impact_dir(case)}/{IMPACT_FILES[kind]}"


def impact_sweep_dir(current: str) -> str:
    return impact_dir(f"sweep/J{current}")


def impact_velocity_dir(speed: str) -> str:
    return impact_dir(f"velocity_sweep/v{speed}")


def induced_current_dir(current: str) -> str:
    return f"{INDUCED_DIR}/current_sweep/J{current}"


def induced_current_file(current: str, kind: str) -> str:
    return f"{induced_current_dir(current)}/{INDUCED_FILES[kind]}"


def induced_dir(orientation: str) -> str:
    return f"{INDUCED_DIR}/{orientation}"


def induced_file(orientation: str, kind: str) -> str:
    return f"{induced_dir(orientation)}/{INDUCED_FILES[kind]}"


def log_path(scene: str, name: str) -> str:
    return f"results/logs/{scene}/{name}.log"


def benchmark_path(scene: str, name: str) -> str:
    return f"results/benchmarks/{scene}/{name}.tsv"
