"""RVE homogenisation (thesis ch. 7): strain steps, probe solves, checkpoints, the pipeline.

Modules (imported lazily: the Snakefile imports ``layout`` at parse time, which must stay
cheap), low to high:

* ``config`` -- the ``RVEConfig`` model (``scene: rve``);
* ``network`` -- the resistor-network model of a woven cell and its fit (R_y, R_c);
* ``checkpoint`` -- the self-describing state files (``write_state``, ``load_state``);
* ``strain`` -- relaxation and the strain steps of Algorithm 7.1 (``strain_step``), the
  quasi-static path, friction along the path, loading-unloading cycles;
* ``pullout`` -- the yarn pull-out (``pullout_step``);
* ``probes`` -- the decoupled voltage / current / Joule-temperature probe solves;
* ``sweeps`` -- runs, sweep combinations and their configs (``load_run_config``);
* ``layout`` -- every file path of a run (shared with workflow/rules/rve.smk);
* ``jobs`` -- the bodies of the state rules (fabric, relax, strain step, cycle step, pull-out
  step, probes).

The table rules (gather, report) are ``rve.tables.jobs``: the tables import this package,
never the other way round. See docs/rve_pipeline.md.
"""
from __future__ import annotations

import importlib

_MODULES = ("config", "network", "checkpoint", "strain", "pullout", "probes", "sweeps", "layout", "jobs")

_WHERE = {
    "RVEConfig": "config",
    "YarnNetwork": "network", "fit_network": "network",
    "State": "checkpoint", "write_state": "checkpoint", "load_state": "checkpoint",
    "strain_step": "strain", "relax_fabric": "strain",
    "solve_probes": "probes", "solve_probe": "probes", "electric_solve": "probes", "temperature_solve": "probes",
    "load_run_config": "sweeps",
}

__all__ = [*_MODULES, *_WHERE]


def __getattr__(name):
    if name in _MODULES:
        return importlib.import_module(f".{name}", __name__)
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
