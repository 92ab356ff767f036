"""The temperature post-solve of the dynamic fabric scenes (T does not feed back: S =
alpha_mu = 0), on the one SDIRK stepper.

Contract
--------
``ThermalPostSolver(ops, tableau, T_fixed=0, reuse=True)``: ``step(T0, stages, t0, h) -> T1``,
one SDIRK step of the heat equation ``M dT/dt + (K + K_c(x)) T - Q(x, w, t) = 0`` with the
stage states ``[(x_i, w_i)]`` of the mechanical/electrical step, the same stage equations as
the monolithic solve: ``rve.solvers.dirk.DirkStepper`` on
``rve.model.thermal_post.StageHeatSystem`` with its linear stages
``rve.model.thermal_post.KeptFactorStages`` (the factor of (M + h a_ii K)_ff kept per h a_ii,
the contact part by iterative refinement on it, direct fallback) or, ``reuse=False``, the
plain reference ``FreshStages`` (a fresh solve per stage). Counters ``solves``,
``refinements``, ``fallbacks``, ``wall``. docs/induced_deformation.md "Temperature path".
"""
from __future__ import annotations

import time

import numpy as np

from ..model.thermal_post import FreshStages, KeptFactorStages, StageHeatSystem, ThermalOperators
from ..solvers.dirk import DirkStepper

__all__ = ["ThermalPostSolver"]


class ThermalPostSolver:
    def __init__(self, ops: ThermalOperators, tableau, T_fixed: float = 0.0, reuse: bool = True,
                 refine_tol: float = 1e-14, max_refine: int = 12):
        self.ops, self.tab = ops, tableau
        self.T_fixed = float(T_fixed)
        self.reuse = bool(reuse)
        self.stages = (KeptFactorStages(ops, T_fixed, refine_tol, max_refine) if self.reuse
                       else FreshStages(ops, T_fixed))
        self.system = StageHeatSystem(ops, T_fixed)
        self.stepper = DirkStepper(self.system, tableau, linear_stages=self.stages)
        self.wall = 0.0
        self.solves = self.refinements = self.fallbacks = 0

    def step(self, T0, stages, t0: float, h: float):
        w0 = time.perf_counter()
        self.stages.drive(stages)
        self.system.drive(stages, t0, h, self.tab)
        T0 = np.asarray(T0, float)
        T1 = self.stepper.step(T0, T0, t0, h)[1]
        st = self.stages
        self.solves, self.refinements, self.fallbacks = st.solves, st.refinements, st.fallbacks
        self.wall += time.perf_counter() - w0
        return T1
