"""The RVE homogenisation as a scene: a pipeline scene built by Snakemake (docs/configuration.md).

Contract
--------
``scene: rve`` (``rve.config.rve.RVEConfig``) is not run in-process by
``rve run``: its chain (fabric -> relax -> strain steps -> probes -> table) is the jobs of
workflow/rules/rve.smk. :func:`snakemake_command(config_path, overrides)` returns the
exact command that builds the table ``results/rve/<run>/table.nc`` of a config file:

* a config that a run of the pipeline config's ``rve.runs`` uses as it is (same file, no
  overrides, no inline keys, no sweep) and no ``--set`` overrides: that run,
  ``snakemake -j2 results/rve/<run>/table.nc``;
* otherwise a run of its own named after the file (``<stem>``, or ``<stem>_<hash>`` when a
  pipeline run already has that name), added by ``--config`` (Snakemake merges it into
  ``rve.runs``): ``snakemake -j2 results/rve/<name>/table.nc --config 'rve={runs:
  {<name>: {scene_config: <path>, overrides: [...]}}}'``.

Paths are relative to the repository root (the directory holding the ``Snakefile``,
searched upwards from the config file); the command starts with ``cd <root> &&`` when
that is not the working directory.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shlex
from pathlib import Path
from typing import Optional, Sequence

__all__ = ["snakemake_command", "find_run", "PIPELINE_CONFIG", "TABLE"]

#: the pipeline config Snakemake reads (Snakefile: ``configfile:``), relative to the root
PIPELINE_CONFIG = "configs/pipeline.yaml"
#: the table of run ``{run}`` (workflow/rules/rve.smk, rule rve_gather; RVE_DIR = results/rve)
TABLE = "results/rve/{run}/table.nc"


def _root_of(path: Path) -> Optional[Path]:
    for d in [path.parent, *path.parent.parents]:
        if (d / "Snakefile").is_file():
            return d
    return None


def _runs(root: Path) -> dict:
    import yaml

    try:
        data = yaml.safe_load((root / PIPELINE_CONFIG).read_text(encoding="utf-8")) or {}
    except OSError:
        return {}
    return dict((data.get("rve") or {}).get("runs") or {})


def find_run(config_path, root: Path, runs: dict) -> Optional[str]:
    """The run of ``runs`` that uses ``config_path`` as it is (no overrides, inline keys or sweep)."""
    target = Path(config_path).resolve()
    for name, spec in runs.items():
        spec = spec or {}
        path = spec.get("scene_config")
        if not path or spec.get("overrides") or spec.get("scene") or spec.get("sweep"):
            continue
        if (root / path).resolve() == target:
            return name
    return None


def _flow(value) -> str:
    """YAML flow text of ``value`` (Snakemake's --config reads values as YAML)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    return json.dumps(str(value))


def snakemake_command(config_path, overrides: Sequence[str] = (), jobs: int = 2) -> str:
    """The ``snakemake`` command building the RVE table of ``config_path`` with
    ``overrides`` (module docstring)."""
    path = Path(config_path)
    root = _root_of(path.resolve()) or Path.cwd()
    rel = os.path.relpath(path.resolve(), root)
    runs = _runs(root)
    overrides = list(overrides)
    run = None if overrides else find_run(path, root, runs)
    extra = ""
    if run is None:
        run = re.sub(r"[^A-Za-z0-9_]", "_", path.stem) or "run"
        spec = {"scene_config": rel, "overrides": overrides}
        if run in runs:
            digest = hashlib.sha1(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:8]
            run = f"{run}_{digest}"
        extra = " --config " + shlex.quote("rve=" + _flow({"runs": {run: spec}}))
    cmd = f"snakemake -j{int(jobs)} {TABLE.format(run=run)}{extra}"
    if root.resolve() != Path.cwd().resolve():
        cmd = f"cd {shlex.quote(str(root))} && {cmd}"
    return cmd
