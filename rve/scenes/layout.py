"""File layout of the dynamic scenes' Snakemake targets (workflow/rules/impact.smk,
induced_deformation.smk): every path those rules name comes from here, as the RVE
pipeline's come from ``rve.homogenisation.layout``. Data only: importing it imports no
scene. Every function takes plain strings, so a rule passes wildcards as ``"{case}"``.

Contract
--------
* impact: ``impact_dir(case)`` (``results/impact/<case>``), ``impact_relaxed(case)``,
  ``impact_relax_record(case)``, ``impact_summary(case)``, ``impact_nc(case)``,
  ``impact_sweep_dir(current)``, ``impact_sweep_summary(current)``, ``IMPACT_SWEEP_PNG``,
  ``IMPACT_SWEEP_JSON``;
* induced deformation: ``induced_dir(orientation)``, ``induced_summary(orientation)``,
  ``induced_nc(orientation)``, ``INDUCED_FRAMES_PNG``, ``INDUCED_TEMPERATURE_PNG``;
* ``log_path(scene, name)`` (``results/logs/<scene>/<name>.log``) and
  ``benchmark_path(scene, name)`` (``results/benchmarks/<scene>/<name>.tsv``).
"""
from __future__ import annotations

__all__ = ["IMPACT_DIR", "impact_dir", "impact_relaxed", "impact_relax_record", "impact_summary", "impact_nc",
           "impact_sweep_dir", "impact_sweep_summary", "IMPACT_SWEEP_PNG", "IMPACT_SWEEP_JSON", "INDUCED_DIR",
           "induced_dir", "induced_summary", "induced_nc", "INDUCED_FRAMES_PNG", "INDUCED_TEMPERATURE_PNG",
           "log_path", "benchmark_path"]

IMPACT_DIR = "results/impact"
INDUCED_DIR = "results/induced_deformation"
IMPACT_SWEEP_PNG = f"{IMPACT_DIR}/sweep/current_sweep.png"
IMPACT_SWEEP_JSON = f"{IMPACT_DIR}/sweep/current_sweep.json"
INDUCED_FRAMES_PNG = f"{INDUCED_DIR}/fig_8_3_1_frames.png"
INDUCED_TEMPERATURE_PNG = f"{INDUCED_DIR}/fig_8_3_2_temperature.png"


def impact_dir(case: str) -> str:
    return f"{IMPACT_DIR}/{case}"


def impact_relaxed(case: str) -> str:
    return f"{impact_dir(case)}/relaxed_state.npz"


def impact_relax_record(case: str) -> str:
    return f"{impact_dir(case)}/relaxation.json"


def impact_summary(case: str) -> str:
    return f"{impact_dir(case)}/summary.json"


def impact_nc(case: str) -> str:
    return f"{impact_dir(case)}/impact.nc"


def impact_sweep_dir(current: str) -> str:
    return f"{IMPACT_DIR}/sweep/J{current}"


def impact_sweep_summary(current: str) -> str:
    return f"{impact_sweep_dir(current)}/summary.json"


def induced_dir(orientation: str) -> str:
    return f"{INDUCED_DIR}/{orientation}"


def induced_summary(orientation: str) -> str:
    return f"{induced_dir(orientation)}/summary.json"


def induced_nc(orientation: str) -> str:
    return f"{induced_dir(orientation)}/induced_deformation.nc"


def log_path(scene: str, name: str) -> str:
    return f"results/logs/{scene}/{name}.log"


def benchmark_path(scene: str, name: str) -> str:
    return f"results/benchmarks/{scene}/{name}.tsv"
