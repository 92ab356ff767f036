"""The temperature post-solve of the dynamic fabric scenes on the one SDIRK stepper.

Contract
--------
``DirkThermalPost(ops, tableau, T_fixed=0, rtol=1e-12)``: ``step(T0, stages, t0, h) -> T1``
as ``rve.model.thermal_post.ThermalPostSolver``, each stage one (modified) Newton solve of
``rve.solvers.dirk.DirkStepper`` on ``rve.model.thermal_post.StageHeatSystem``. Not the
scenes' default: it agrees with ``ThermalPostSolver`` to the Newton tolerance, not bit for
bit (benchmarks/thermal_post_dirk.py measures the difference).
"""
from __future__ import annotations

import numpy as np

from ..model.thermal_post import StageHeatSystem, ThermalOperators
from ..solvers.dirk import DirkStepper

__all__ = ["DirkThermalPost"]


class DirkThermalPost:
    """The temperature post-solve on ``rve.solvers.dirk.DirkStepper``: the same stage
    equations as :class:`ThermalPostSolver`, each stage one Newton solve of the linear heat
    equation (modified Newton on a kept factorisation: on a linear equation that is
    iterative refinement with the exact stage matrix in the residual). Equal to
    ``ThermalPostSolver`` to the Newton tolerance ``rtol`` (relative to the stage's first
    residual), not bit for bit: the stage right-hand sides are summed in another order.
    ``step(T0, stages, t0, h) -> T1`` and the counters ``solves``, ``refinements``,
    ``fallbacks`` (always 0) and ``wall`` as ``ThermalPostSolver``."""

    def __init__(self, ops: ThermalOperators, tableau, T_fixed: float = 0.0, rtol: float = 1e-12,
                 jacobian_reuse: bool = True):
        self.ops, self.tab = ops, tableau
        self.system = StageHeatSystem(ops, T_fixed)
        self.stepper = DirkStepper(self.system, tableau, {"atol": 0.0, "rtol": float(rtol), "max_iter": 30,
                                                          "line_search": False},
                                   predictor_degree=0, lazy_jacobian=True, jacobian_reuse=jacobian_reuse)
        self.solves = 0
        self.refinements = 0
        self.fallbacks = 0
        self.wall = 0.0

    def step(self, T0, stages, t0: float, h: float):
        import time

        w0 = time.perf_counter()
        self.system.drive(stages, t0, h, self.tab)
        T0 = np.asarray(T0, float)
        _, T1, info = self.stepper.step(T0, T0, t0, h)
        self.solves += int(info.linear_solves)
        self.refinements += int(sum(info.stage_reuses))
        self.wall += time.perf_counter() - w0
        return T1
