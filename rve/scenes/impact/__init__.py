"""The impact scene (thesis §8.4): ``scene`` (set-up, relaxation, the impact solve and run),
``record`` (the per-step recorder, the checkpoint, the summary), ``thermal`` (the fabric's
temperature post-solve operators with the projectile's sphere contact), ``outputs``
(netCDF, VTK, PNG) and ``jobs`` (the Snakemake job bodies). The package is the scene
module of the registry: it re-exports the scene protocol of ``scene``.
"""
from .scene import (ImpactProblem, angular_velocity, config_digest, load_or_relax, nominal_steps, relax, run, setup,
                    solve, time_step_rule)

__all__ = ["ImpactProblem", "setup", "relax", "load_or_relax", "solve", "run", "time_step_rule", "nominal_steps",
           "angular_velocity", "config_digest"]
