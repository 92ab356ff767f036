"""Solvers of the semi-discrete systems (docs/engine.md, docs/time_integration.md,
docs/relaxation.md), lowest first:

* ``system``     -- the ``DynamicSystem`` / ``ContactRelaxable`` protocols, ``FreeDofs``;
* ``linear``     -- linear-solver choices and factorisation backends (with inertia);
* ``newton``     -- Newton's method with line search and admissibility guard;
* ``static``     -- static equilibrium (Newton, pseudo-transient continuation);
* ``dirk``       -- SDIRK time integration with step control;
* ``minimize``   -- energy minimiser and capped Newton under contact;
* ``relaxation`` -- the relaxation driver (energy or damped-dynamics path).

Import the submodules (``from rve.solvers.dirk import integrate``); this package imports
nothing itself, so ``import rve.solvers`` stays cheap. The solvers import neither
``rve.contact`` nor ``rve.model`` (of the package only ``rve.threads``, the job's thread count).
"""
__all__ = ["system", "linear", "newton", "static", "dirk", "minimize", "relaxation"]
