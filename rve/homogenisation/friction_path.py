"""One equilibrium path with friction: the branch test of a frictional strain step on the
quasi-static path, pinned or periodic (docs/table_accuracy.md "One equilibrium path",
docs/contact.md "Friction in the RVE pipeline").

Friction has no potential, but a quasi-static frictional path still balances energy: the
work of the macro load equals the change of the elastic potential plus the energy the
return map dissipates,

    W = (Pi(b) + D(b)) - (Pi(a) + D(a)),     W ~ (P(a) + P(b)) d / 2,

with D the friction's dissipation counter (``FrictionTerm.dissipated``, carried in the
history record) and P the work rate of the macro load at the state with its committed
history (the clamps' forces, or the Hill-Mandel stress, whose pairs across a face carry
their friction forces). So the test of ``rve.homogenisation.branch`` applies with Pi + D as
the energy. One thing breaks the trapezoid: at a loading start or reversal the contacts
stick first, and the work rate rises steeply until they slip (a kink of P(eps) inside the
step, ~1.5e-3 strain on the tests' tiny cell). A step that starts a loading therefore first
takes an untested **start-up** of ``START_UP`` of the step (``START_UP_REVERSAL`` at a
reversal, where the friction forces turn over twice the way), which holds that transient,
and the branch test runs from its end; a step that continues a loading starts from the
incoming state's committed history, which already slides with the load.

Contract
--------
``frictional_branch_step(cfg, cell, x_prev, eps_prev, eps, multipliers, friction,
loading_start) -> (x, system, info)``: ``cell`` has ``periodic``, ``part(x, e_from, e_to,
lam=, fr=) -> (x, system, info)`` (the path's own step from a state with its multipliers
and friction record), ``fab``, ``mesh``, ``origin``, ``mode``, ``branch_step`` (the strain
path's ``follow_branch`` wrapper, ``strain._branch_step``) and, for the pinned cell,
``system(x)`` (a fresh mechanics system at x) and ``energy(system, x, eps)`` (``(Pi, P)``,
``strain.pinned_energy``). ``info["branch"]`` is the follower's record with ``start_up``
(its strain and wall time; None without one). ``loading_start``: False, True (a loading
starts) or "reversal". No continuation through limit points: a detected frictional step is
followed by halving.
"""
from __future__ import annotations

import time

import numpy as np

from .branch import StepSolution
from .friction_history import friction_record, seed_friction
from .multipliers import multiplier_record, seed_multipliers

__all__ = ["START_UP", "START_UP_REVERSAL", "frictional_branch_step", "frictional_energy"]

#: the start-up's share of a step that starts a loading: it must hold the stick transient
#: (1/16 of the friction table's first shear step did not, a quarter did:
#: ``benchmarks/friction_path_checks.py weave``), and it is not tested
START_UP = 0.25
#: the start-up's share at a reversal: the friction forces turn from +mu N to -mu N, twice
#: the way of a loading start at the same tangential stiffness
START_UP_REVERSAL = 0.5


def frictional_energy(cfg, cell, system, x, eps, multipliers, friction) -> tuple:
    """``(Pi + D, P)`` of an equilibrium ``x`` at strain ``eps``: its potential plus the
    dissipation so far and the work rate of the macro load with the friction forces of its
    committed history. ``system``: the step's own system at ``x`` (its multipliers and
    history), or None for the step's incoming state (``multipliers``, ``friction``)."""
    lam = multipliers if system is None else multiplier_record(system)
    rec = friction if system is None else friction_record(system)
    if cell.periodic:
        from .periodic import periodic_energy

        pi, rate = periodic_energy(cfg, cell.fab, cell.mesh, x, cell.mode, eps, lam, friction=rec)
    else:
        if system is None:
            xf = np.asarray(x, float).reshape(-1)
            system = cell.system(xf)
            seed_multipliers(system, lam)
            seed_friction(system, rec, xf)
        pi, rate = cell.energy(system, x, eps)
    return pi + float((rec or {}).get("dissipated", 0.0)), rate


def frictional_branch_step(cfg, cell, x_prev, eps_prev: float, eps: float, multipliers, friction,
                           loading_start):
    """The frictional step from ``x_prev`` at ``eps_prev`` to ``eps`` on one equilibrium path
    (module docstring)."""
    t0 = time.perf_counter()
    nn = cell.mesh.n_nodes
    start, up, e_a = None, None, float(eps_prev)
    if loading_start:
        share = START_UP_REVERSAL if loading_start == "reversal" else START_UP
        e_a = float(eps_prev) + share * (float(eps) - float(eps_prev))
        x1, sys1, info1 = cell.part(x_prev, eps_prev, e_a, lam=multipliers, fr=friction)
        start = StepSolution(np.array(x1, float).reshape(nn, 9), info1, sys1)
        up = {"strain": e_a, "converged": info1.get("converged"), "wall_s": time.perf_counter() - t0}

    def energy_of(system, x, e):
        return frictional_energy(cfg, cell, system, x, e, multipliers, friction)

    x, system, info = cell.branch_step(cell.mesh, x_prev, e_a, eps, cfg.strain, cell.part, energy_of, multipliers,
                                       friction=friction, start=start)
    info["branch"]["start_up"] = up
    info.update({"strain_increment": float(eps - eps_prev), "wall_s": time.perf_counter() - t0})
    if up is not None and info.get("friction"):
        # the step's dissipation counts from the step's start, the start-up's included
        info["friction"]["step_dissipated"] = float(info["friction"]["dissipated"]
                                                    - float((friction or {}).get("dissipated", 0.0)))
    return x, system, info
