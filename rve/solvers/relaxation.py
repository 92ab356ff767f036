"""Relaxation of a fibril assembly in contact to static equilibrium (thesis §6.3, §7.3).

Contract
--------
``relax_to_equilibrium(system, x, w, settings, on_rebuild=None, t0=0) -> RelaxResult``
for a ``ContactRelaxable`` system (``rve.solvers.system``: a ``DynamicSystem`` with a
rebuildable contact map, ``energy(x)``, ``set_onset``, ``params.margin``; e.g.
``rve.model.ContactSystem``); ``settings.method`` picks the path
(docs/relaxation.md):

* ``"energy"`` (the fabric scene's default): the static equilibrium as a **local minimum
  of the potential** ``system.energy(x)`` (beam strain energy + penalty energy; the static
  residual is its exact gradient), by ``rve.solvers.minimize.minimize_energy``: Newton
  with a Levenberg-Marquardt trust region ``(K + sigma M) du = -F``, sigma raised until
  the factorisation has no negative pivot (``rve.solvers.linear.factor_inertia``: the
  tangent of a stack of frictionless fibrils is indefinite on the way down), the energy as merit (with ``backtrack`` energy-only step
  halvings), the centroid step capped at half the search margin and the map rebuilt
  before a trial that leaves the guard (no contact jumped over). A continuation in the
  penalty onset (``onset_schedule``, fractions of R, the C² onset of
  ``contact_forms.penalty_law``; the last entry is the law of the result) smooths the
  first stages; the last stage ends with sigma = 0, i.e. plain Newton, quadratically.
  Velocities are zero throughout. A system with friction (``rve.solvers.frictional.
  friction_of``) has no potential: ``"energy"`` then solves the static residual by
  ``rve.solvers.frictional.frictional_solve`` from the friction history of the last converged state, and commits
  the history at the solution. ``"dynamic"`` commits the friction history after every
  accepted time step (each step's stages return-map from the last accepted state) and
  after every converged static round.
* ``"dynamic"`` (the previous path):

1. **Dynamic relaxation**: backward Euler (``rve.solvers.dirk.integrate``, step control)
   of the heavily damped dynamics over ``duration`` in ``steps`` nominal steps, the contact
   map rebuilt every ``rebuild_every`` steps (Algorithm 5.2, thesis k = 5). ``integrate``
   is called once per chunk of ``rebuild_every`` steps because a rebuild changes the
   sparsity structure the stepper caches (docs/contact.md). A safety rebuild happens after
   any step that moved a centroid more than half the search margin since the last
   rebuild. Stops early when the largest nodal speed falls below ``v_tol``.
2. **Static Newton with a capped step** (``rve.solvers.minimize.capped_newton``) from
   the relaxed state with velocities zeroed: the Newton step is scaled so that no centroid moves more than
   ``step_cap`` (default half the search margin) in one iteration, halved while it makes
   det F <= 0, and the contact map is rebuilt whenever a centroid has moved more than
   half the margin since the last rebuild. Contacts the map did not hold cannot be skipped
   over this way, and near the solution the full step is taken (quadratic convergence).
   Repeated (``static_rounds``) until a rebuild at the solution finds no active pair the
   previous map missed. If it fails, pseudo-transient continuation takes over.

Linear solver: ``settings.linear_backend`` (None: ``$RVE_LINEAR_BACKEND``, else "auto":
PARDISO when available, SuperLU otherwise; docs/engine.md); each static solve keeps one
backend instance (analysis reuse).

``RelaxResult``: final ``x``, ``w`` (zero velocities after the static phase), ``t``,
``history`` (one dict per chunk/solve/stage: iterations, factorisations, residuals,
energies, pairs, active pairs, max overlap / R, wall time), ``timings`` (seconds:
dynamic, static, total), iteration counts, and the last static ``NewtonResult``
(``MinimizeResult`` for the energy path).

"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from .dirk import IntegrationFailure, integrate, integrator_options
from .frictional import friction_of
from .minimize import active_pair_keys, capped_newton, minimize_energy
from .newton import NewtonResult
from .static import pseudo_transient_solve

__all__ = ["RelaxSettings", "RelaxResult", "relax_to_equilibrium"]

log = logging.getLogger("rve.solvers.relaxation")


@dataclass
class RelaxSettings:
    duration: float
    steps: int
    rebuild_every: int = 5
    newton_atol: float = 1e-9
    newton_rtol: float = 1e-6
    newton_max_iter: int = 25
    v_tol: float = 0.0
    static: bool = True
    static_atol: float = 1e-9
    static_rtol: float = 1e-12
    static_rounds: int = 4
    static_max_iter: int = 40
    step_cap: Optional[float] = None
    method: str = "dynamic"
    onset_schedule: tuple = (0.0,)
    energy_max_iter: int = 300
    time_budget: Optional[float] = None
    backtrack: int = 3
    linear_backend: Optional[str] = None   # None: $RVE_LINEAR_BACKEND, else auto (rve.solvers.linear)
    #: flat ``rve.solvers.dirk.integrator_options`` of the dynamic phase's ``integrate`` calls
    #: (e.g. ``{"jacobian_reuse": True}``); empty: the integrator's defaults
    integrator_options: dict = field(default_factory=dict)


@dataclass
class RelaxResult:
    x: np.ndarray
    w: np.ndarray
    t: float
    history: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    dynamic_steps: int = 0
    dynamic_newton_iterations: int = 0
    static_newton_iterations: int = 0
    static_converged: bool = False
    static_result: object = None
    #: the ``IntegrationResult`` of every ``integrate`` call of the dynamic phase, counts only
    #: (states and step history dropped)
    integrations: list = field(default_factory=list)


def relax_to_equilibrium(system, x, w, settings: RelaxSettings, on_rebuild: Optional[Callable] = None,
                         t0: float = 0.0) -> RelaxResult:
    if settings.method == "energy" and friction_of(system) is not None:
        return _relax_frictional(system, x, settings, t0)
    if settings.method == "energy":
        return _relax_energy(system, x, settings, on_rebuild, t0)
    if settings.method != "dynamic":
        raise ValueError(f"unknown relaxation method {settings.method!r} (energy, dynamic)")
    s = settings
    t_start = time.perf_counter()
    x = np.array(x, float, copy=True)
    w = np.array(w, float, copy=True)
    t = float(t0)
    out = RelaxResult(x, w, t)
    x, w, t = _relax_dynamic(system, x, w, t, s, out, on_rebuild, t_start)
    out.timings["dynamic"] = time.perf_counter() - t_start
    t1 = time.perf_counter()
    w = np.zeros_like(w)
    if s.static:
        x, w = _relax_static(system, x, w, t, s, out, t_start)
    out.timings["static"] = time.perf_counter() - t1
    out.timings["total"] = time.perf_counter() - t_start
    out.x, out.w, out.t = x, w, t
    return out


def _relax_dynamic(system, x, w, t, s: RelaxSettings, out: RelaxResult, on_rebuild, t_start: float):
    """The damped backward-Euler phase in chunks of ``rebuild_every`` steps (the map rebuilt
    before every chunk and at once when something moved half the margin); returns the
    ``(x, w, t)`` it ended at (early when the speed is below ``v_tol``)."""
    h = s.duration / max(1, s.steps)
    nopts = {"atol": s.newton_atol, "rtol": s.newton_rtol, "max_iter": s.newton_max_iter}
    k = max(1, int(s.rebuild_every))
    done = 0
    chunk = 0
    guard = 0.5 * float(system.params.margin)
    extra = [0]

    friction = friction_of(system)

    def on_step(t_, x_, w_, info):
        if friction is not None:      # the accepted step is the history of the next one
            friction.commit(x_)
        # safety: fibrils moved more than half the search margin since the last rebuild
        # -> rebuild now (the stepper then assembles through its general path for the
        # rest of the chunk, still exact)
        if guard > 0 and system.max_displacement_since_rebuild(x_) > guard:
            system.rebuild(x_)
            extra[0] += 1

    while done < s.steps and s.duration > 0:
        m = min(k, s.steps - done)
        system.rebuild(x)
        try:
            res = integrate(system, x, w, t, t + m * h, m, stages=1, newton_opts=nopts, consistent=False,
                            on_step=on_step, **integrator_options(**s.integrator_options))
        except IntegrationFailure as exc:
            log.warning("dynamic relaxation stopped at t = %.4g: %s", exc.t, exc)
            x, w, t = exc.x, exc.w, exc.t
            break
        x, w, t = res.x, res.w, res.t
        out.integrations.append(dataclasses.replace(res, x=None, w=None, history=[]))
        done += m
        chunk += 1
        out.dynamic_steps += res.steps
        out.dynamic_newton_iterations += res.newton_iterations
        st = system.contact_state(x)
        vmax = float(np.abs(w[system.mech]).max()) if np.any(system.mech) else 0.0
        rec = {"phase": "dynamic", "t": t, "steps": res.steps, "rejected": res.rejected, "extra_rebuilds": extra[0],
               "newton_iterations": res.newton_iterations, "pairs": st["pairs"],
               "active_pairs": st["active_pairs"], "max_overlap_over_R": st["max_overlap_over_R"],
               "max_speed": vmax, "wall_s": time.perf_counter() - t_start}
        out.history.append(rec)
        log.info("relax chunk %d: %s", chunk, rec)
        if on_rebuild is not None:
            on_rebuild(chunk, t, x, w)
        if s.v_tol > 0 and vmax < s.v_tol:
            break
    return x, w, t


def _relax_static(system, x, w, t, s: RelaxSettings, out: RelaxResult, t_start: float):
    """Static rounds: capped Newton (pseudo-transient continuation where it fails), then a
    map rebuild at the solution, until no new pair came into contact; returns ``(x, w)``."""
    cap = s.step_cap if s.step_cap is not None else 0.5 * float(system.params.margin)
    for rnd in range(s.static_rounds):
        system.rebuild(x)
        xs, ws, nres = capped_newton(system, x, t, atol=s.static_atol, rtol=s.static_rtol,
                                     max_iter=s.static_max_iter, step_cap=cap, backend=s.linear_backend)
        how = "capped newton"
        if not nres.converged:
            log.warning("static Newton failed (%s); pseudo-transient continuation", nres.reason)
            system.rebuild(xs)
            xs2, ws2, pres = pseudo_transient_solve(system, xs, w, t, atol=s.static_atol, rtol=s.static_rtol,
                                                    max_iter=200, backend=s.linear_backend)
            how = "pseudo-transient"
            nres = NewtonResult(pres.u, pres.converged, nres.iterations + pres.iterations,
                                nres.residuals + pres.residuals, pres.reason)
            xs, ws = xs2, ws2
        out.static_newton_iterations += nres.iterations
        x, w = xs, ws
        if nres.converged and friction_of(system) is not None:
            friction_of(system).commit(x)
        out.static_result = nres
        out.static_converged = bool(nres.converged)
        # a rebuild at the solution: did pairs the map missed come into contact?
        before = set(zip(*active_pair_keys(system, x)))
        system.rebuild(x)
        after = set(zip(*active_pair_keys(system, x)))
        st = system.contact_state(x)
        rec = {"phase": "static", "round": rnd + 1, "method": how, "converged": bool(nres.converged),
               "newton_iterations": int(nres.iterations), "residuals": [float(r) for r in nres.residuals],
               "pairs": st["pairs"], "active_pairs": st["active_pairs"],
               "max_overlap_over_R": st["max_overlap_over_R"], "wall_s": time.perf_counter() - t_start}
        out.history.append(rec)
        log.info("static round %d: converged=%s its=%d", rnd + 1, nres.converged, nres.iterations)
        if nres.converged and after <= before:
            break
    return x, w


def _relax_frictional(system, x, s: RelaxSettings, t0) -> RelaxResult:
    """The static residual of a frictional system from the held history by
    ``rve.solvers.frictional.frictional_solve`` (the energy minimiser at frozen normal
    loads, then Newton on the exact residual; the capped Newton and pseudo-transient
    continuation where that fails); the history is committed at the solution
    (``RelaxResult.static_converged``)."""
    from .frictional import frictional_solve

    t_start = time.perf_counter()
    x = np.array(x, float, copy=True)
    out = RelaxResult(x, np.zeros(system.n), float(t0))
    xs, res = frictional_solve(system, x, t0, atol=s.static_atol, rtol=s.static_rtol, max_iter=s.static_max_iter,
                               step_cap=s.step_cap, backend=s.linear_backend)
    if res.converged:
        friction_of(system).commit(xs)
    st = system.contact_state(xs)
    out.history.append({"phase": "static", "method": res.method or "friction (not converged)",
                        "converged": bool(res.converged), "newton_iterations": int(res.iterations),
                        "predictor_rounds": int(res.rounds), "predictor_iterations": int(res.predictor_iterations),
                        "corrector_iterations": int(res.corrector_iterations),
                        "fallback_iterations": int(res.fallback_iterations),
                        "load_changes": [float(v) for v in res.load_changes],
                        "residuals": [float(r) for r in res.residuals],
                        "pairs": st["pairs"], "active_pairs": st["active_pairs"],
                        "max_overlap_over_R": st["max_overlap_over_R"], "wall_s": time.perf_counter() - t_start})
    out.static_newton_iterations = int(res.iterations)
    out.static_result = res
    out.static_converged = bool(res.converged)
    out.timings["dynamic"] = 0.0
    out.timings["static"] = out.timings["total"] = time.perf_counter() - t_start
    out.x, out.w = xs, np.zeros(system.n)
    return out


def _relax_energy(system, x, s: RelaxSettings, on_rebuild, t0) -> RelaxResult:
    """Continuation in the penalty onset: ``minimize_energy`` with the onset width set to
    each entry of ``s.onset_schedule`` in turn (fractions of R; the last is the law of the
    result), each stage from the previous one's minimum. A map rebuild at the end checks
    that no pair came into contact unseen (cannot happen under the step guard; logged)."""
    t_start = time.perf_counter()
    x = np.array(x, float, copy=True)
    out = RelaxResult(x, np.zeros(system.n), float(t0))
    sched = [float(v) for v in s.onset_schedule] or [float(system.params.onset)]
    system.rebuild(x)
    for k, eps in enumerate(sched):
        system.set_onset(eps)
        budget = None if s.time_budget is None else max(1.0, s.time_budget - (time.perf_counter() - t_start))
        xs, _, res = minimize_energy(system, x, t0, atol=s.static_atol, rtol=s.static_rtol,
                                     max_iter=s.energy_max_iter, step_cap=s.step_cap, label=f"onset={eps:g}R",
                                     time_budget=budget, sigma0=None if k == 0 else 0.0,
                                     backtrack=s.backtrack,
                                     backend=s.linear_backend)
        x = xs
        st = system.contact_state(x)
        rec = {"phase": "static", "stage": k + 1, "method": "minimize_energy", "onset_over_R": eps,
               "converged": bool(res.converged), "newton_iterations": int(res.iterations),
               "factorizations": int(res.factorizations), "indefinite": int(res.indefinite),
               "rejections": int(res.rejections), "linear_backend": res.backend, "analyses": int(res.analyses),
               "map_rebuilds": int(res.rebuilds), "negative_pivots": int(res.negative_pivots),
               "residuals": [float(v) for v in res.residuals], "energies": [float(v) for v in res.energies],
               "sigmas": [float(v) for v in res.sigmas], "steps": [float(v) for v in res.steps],
               "pairs": st["pairs"], "active_pairs": st["active_pairs"],
               "max_overlap_over_R": st["max_overlap_over_R"], "wall_s": time.perf_counter() - t_start,
               "reason": res.reason}
        out.history.append(rec)
        out.static_newton_iterations += res.iterations
        out.static_result = res
        out.static_converged = bool(res.converged)
        log.info("onset stage %d (%gR): converged=%s its=%d factorizations=%d (indefinite %d) |F|=%.3e Pi=%.10g "
                 "wall=%.1f s", k + 1, eps, res.converged, res.iterations, res.factorizations, res.indefinite,
                 res.residuals[-1],
                 res.energies[-1], rec["wall_s"])
        if on_rebuild is not None:
            on_rebuild(k + 1, float(t0), x, np.zeros(system.n))
        if not res.converged and res.reason.startswith("time budget"):
            break
    before = set(zip(*active_pair_keys(system, x)))
    system.rebuild(x)
    after = set(zip(*active_pair_keys(system, x)))
    if not after <= before:
        log.warning("final map rebuild found %d active pairs the map had missed", len(after - before))
        out.static_converged = False
    out.timings["dynamic"] = 0.0
    out.timings["static"] = out.timings["total"] = time.perf_counter() - t_start
    out.x, out.w = x, np.zeros(system.n)
    return out
