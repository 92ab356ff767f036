"""RVE homogenisation (thesis ch. 7): strain steps, probe solves, checkpoints, pipeline.

Modules (imported lazily: the Snakefile imports ``pipeline`` at parse time, which must stay
cheap):

* ``config`` -- the ``RVEConfig`` model (``scene: rve``), registered with rve.config;
* ``checkpoint`` -- the self-describing state files (``write_state``, ``load_state``);
* ``strain`` -- relaxation and the strain steps of Algorithm 7.1 (``strain_step``);
* ``probes`` -- the decoupled voltage / current / Joule-temperature probe solves;
* ``pipeline`` -- one function per Snakemake rule, runs and sweeps, ``run_local``,
  ``run_probes_dask``.

See docs/rve_pipeline.md.
"""
from __future__ import annotations

import importlib

__all__ = [
    "config", "checkpoint", "strain", "probes", "pipeline",
    "RVEConfig", "State", "write_state", "load_state", "strain_step", "relax_fabric", "solve_probes",
    "solve_probe", "electric_solve", "temperature_solve", "run_local", "run_probes_dask", "load_run_config",
]

_WHERE = {
    "RVEConfig": "config",
    "State": "checkpoint", "write_state": "checkpoint", "load_state": "checkpoint",
    "strain_step": "strain", "relax_fabric": "strain",
    "solve_probes": "probes", "solve_probe": "probes", "electric_solve": "probes", "temperature_solve": "probes",
    "run_local": "pipeline", "run_probes_dask": "pipeline", "load_run_config": "pipeline",
}


def __getattr__(name):
    if name in ("config", "checkpoint", "strain", "probes", "pipeline"):
        return importlib.import_module(f".{name}", __name__)
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
