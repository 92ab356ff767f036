"""The induced-deformation scene (thesis §8.3): ``scene`` (set-up, solve, run), ``record``
(the per-step recorder and the summary), ``outputs`` (netCDF, VTK, PNG, the combined
figures) and ``jobs`` (the Snakemake job body). The package is the scene module of the
registry: it re-exports the scene protocol of ``scene``.
"""
from .scene import InducedProblem, field_vector, run, setup, solve, warp_circuit

__all__ = ["InducedProblem", "setup", "solve", "run", "field_vector", "warp_circuit"]
