"""The Snakemake job bodies of the induced deformation (workflow/rules/induced_deformation.smk).

Contract: ``orientation_job(config_path, orientation, out_dir, summary_path, log_path,
overrides=()) -> dict``: one field orientation of the scene, its summary written atomically.
"""
from __future__ import annotations

import json
from pathlib import Path

from ...config.loader import load_config
from ...io.atomic import atomic_write_text
from ..protocol import job_log
from ..registry import run_scene

__all__ = ["orientation_job"]


def orientation_job(config_path, orientation: str, out_dir, summary_path, log_path, overrides=()) -> dict:
    """One Snakemake job (workflow/rules/induced_deformation.smk): the scene of ``config_path``
    with ``field.orientation = orientation`` (+ ``overrides``), outputs under ``out_dir``,
    the summary written (atomically) to ``summary_path``, the log to ``log_path``."""
    with job_log(log_path):
        cfg = load_config(config_path, [f"field.orientation={orientation}", *overrides])
        summary = run_scene(cfg, out_dir)
        atomic_write_text(Path(summary_path), json.dumps(summary, indent=2, default=str))
        return summary
