"""Relax a generated fabric to static equilibrium under contact (docs/relaxation.md).

Contract
--------
In: a config with ``fabric``, ``material`` (``youngs_modulus``, ``poisson_ratio``,
``density``), ``contact``, ``mesh`` and ``relaxation`` sections (a
``rve.config.fabric.FabricRelaxConfig`` or an ``rve.config.rve.RVEConfig``;
duck-typed, nothing is imported from rve.config). Out:

* :func:`relaxation_system` -- ``(fabric, system, x0)``: the mechanics-only
  ``ContactSystem`` of the designed initial state ``x0`` with the clamps of
  ``rve.fabrics.setup`` (docs/relaxation.md "Set-up"), damping ``relaxation.damping``;
* :func:`relax_settings` -- the ``RelaxSettings`` of the relaxation section;
* :func:`relax` -- the whole relaxation (optional mesh sequencing, then
  ``relax_to_equilibrium``) and its summary: a :class:`RelaxedFabric`.

Used by the relaxation scene (``rve.scenes.fabric_relax``) and by the RVE pipeline's
energy path (``rve.homogenisation.strain.relax_fabric``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..solvers.linear import negative_eigenvalue_count
from ..solvers.relaxation import RelaxSettings, relax_to_equilibrium
from .setup import clamp_reactions, contact_params, fabric_and_mesh, mechanics_system
from .stack import stack_geometry

__all__ = ["RelaxedFabric", "relaxation_system", "relax_settings", "relax", "sequenced", "coarse_mesh_section",
           "fine_settings"]


@dataclass
class RelaxedFabric:
    """The outcome of :func:`relax`: the fabric, its system, the designed state ``x0``,
    the relaxed state ``x`` (flat, the system's layout) and the summary figures."""

    fabric: object
    system: object
    x0: np.ndarray
    x: np.ndarray
    summary: dict


def relaxation_system(cfg, mesh_section=None):
    """``(fabric, system, x0)`` of the relaxation (module docstring); ``mesh_section``
    replaces ``cfg.mesh`` (the coarse mesh of the mesh sequencing)."""
    m = cfg.mesh if mesh_section is None else mesh_section
    view = cfg if mesh_section is None else cfg.model_copy(update={"mesh": m})
    fab, mesh = fabric_and_mesh(view)
    x0n = fab.initial_state(mesh)
    params = contact_params(cfg.contact, rebuild_every=cfg.relaxation.rebuild_every)
    x0 = np.array(x0n, dtype=float).reshape(-1)
    system = mechanics_system(fab, mesh, view, params, cfg.relaxation.damping, x0)
    return fab, system, x0


def relax_settings(cfg, schedule=None) -> RelaxSettings:
    """``RelaxSettings`` of ``cfg.relaxation``; the onset schedule (fractions of R) is
    ``relaxation.onset_continuation`` + ``[contact.onset]`` unless given."""
    r = cfg.relaxation
    if schedule is None:
        schedule = [float(v) for v in r.onset_continuation] + [float(cfg.contact.onset)]
    return RelaxSettings(duration=r.duration, steps=r.steps, rebuild_every=r.rebuild_every,
                         newton_rtol=r.newton_rtol, newton_max_iter=r.newton_max_iter,
                         newton_atol=r.static_atol, static=r.static, static_atol=r.static_atol,
                         static_rounds=r.static_rounds, static_max_iter=r.static_max_iter,
                         method=r.method, onset_schedule=tuple(schedule), energy_max_iter=r.energy_max_iter,
                         time_budget=r.wall_budget_s, backtrack=r.backtrack)


def sequenced(cfg) -> bool:
    """Whether ``cfg``'s relaxation is mesh-sequenced: the energy path with a
    ``relaxation.coarse_elements`` other than ``mesh.elements``."""
    r = cfg.relaxation
    return r.method == "energy" and bool(r.coarse_elements) and int(r.coarse_elements) != int(cfg.mesh.elements)


def coarse_mesh_section(cfg):
    """The mesh section of the mesh sequencing's coarse stage: ``relaxation.coarse_elements``
    elements per fibril (and ``coarse_axial_points`` Gauss points where given)."""
    r = cfg.relaxation
    update = {"elements": int(r.coarse_elements)}
    if r.coarse_axial_points is not None:
        update["axial_points"] = int(r.coarse_axial_points)
    return cfg.mesh.model_copy(update=update)


def fine_settings(cfg) -> RelaxSettings:
    """The sequenced relaxation's settings on the target mesh: the onset stages
    ``relaxation.fine_onset_continuation`` + ``[contact.onset]``."""
    return relax_settings(cfg, [float(v) for v in (cfg.relaxation.fine_onset_continuation or [])]
                          + [float(cfg.contact.onset)])


def _coarse_stage(cfg, system):
    """Mesh sequencing: relax on ``relaxation.coarse_elements`` with the whole onset
    schedule, then interpolate the coarse minimum onto the target mesh (rve.fem.transfer).
    Returns ``(x, RelaxResult, dofs)`` of the coarse stage."""
    from ..fem.transfer import interpolate_nodal

    _, csys, cx0 = relaxation_system(cfg, coarse_mesh_section(cfg))
    cres = relax_to_equilibrium(csys, cx0, np.zeros(csys.n), relax_settings(cfg))
    x = np.zeros(system.n)
    xn = system.nodal(x)
    xn[:, :9] = interpolate_nodal(csys.mesh, csys.nodal(cres.x)[:, :9], system.mesh)
    return x, cres, int(csys.n)


def relax(cfg, on_rebuild=None, problem=None) -> RelaxedFabric:
    """Relax the designed fabric of ``cfg`` (module docstring). ``problem``: the
    ``(fabric, system, x0)`` of :func:`relaxation_system` if already built;
    ``on_rebuild(chunk, t, x, w)`` is called at every contact-map rebuild of the target
    mesh. The summary: dofs, contact pairs, overlaps, clamp reactions per box side, yarn
    stack geometry before/after, Newton figures, energy, negative pivots of the final
    tangent (``stable``), wall times, per-stage history (docs/relaxation.md)."""
    t_start = time.perf_counter()
    fab, system, x0 = relaxation_system(cfg) if problem is None else problem
    mesh = system.mesh
    t_setup = time.perf_counter() - t_start
    st0 = system.contact_state(x0)
    r = cfg.relaxation
    settings = relax_settings(cfg)
    history = []
    xs = x0
    coarse = None
    if sequenced(cfg):
        xs, cres, cdofs = _coarse_stage(cfg, system)
        for h in cres.history:
            history.append(dict(h, mesh_elements=int(r.coarse_elements)))
        coarse = {"elements_per_fibril": int(r.coarse_elements), "dofs": cdofs,
                  "axial_points": r.coarse_axial_points,
                  "onset_schedule_over_R": [float(v) for v in r.onset_continuation] + [float(cfg.contact.onset)],
                  "converged": bool(cres.static_converged), "newton_iterations": int(cres.static_newton_iterations),
                  "wall_s": float(cres.timings.get("total", 0.0))}
        settings = fine_settings(cfg)
        system.rebuild(xs)
    res = relax_to_equilibrium(system, xs, np.zeros(system.n), settings, on_rebuild=on_rebuild)
    for h in res.history:
        history.append(dict(h, mesh_elements=int(cfg.mesh.elements)))
    st = system.contact_state(res.x)
    n_fixed = len(system.constraints(0.0)[0])
    xn0, xn = system.nodal(x0), system.nodal(res.x)
    its = sum(int(h.get("newton_iterations", 0)) for h in history if h.get("phase") == "static")
    summary = {
        "fabric": fab.kind,
        "fibrils": int(mesh.n_fibrils),
        "elements_per_fibril": int(cfg.mesh.elements),
        "order": int(mesh.order),
        "dofs": int(system.n),
        "free_dofs": int(system.n - n_fixed),
        "method": r.method,
        "onset_schedule_over_R": [float(v) for v in settings.onset_schedule],
        "coarse_stage": coarse,
        "contact_pairs": int(st["pairs"]),
        "active_contact_pairs": int(st["active_pairs"]),
        "initial_max_overlap_over_R": float(st0["max_overlap_over_R"]),
        "max_overlap_over_R": float(st["max_overlap_over_R"]),
        "max_overlap_mm": float(st["max_overlap"]),
        "total_contact_force_N": float(st["total_normal_force"]),
        "clamp_reactions_N": clamp_reactions(fab, system, res.x, res.t),
        "stack": {"initial": stack_geometry(fab, mesh, xn0), "relaxed": stack_geometry(fab, mesh, xn)},
        "static_converged": bool(res.static_converged),
        "dynamic_steps": int(res.dynamic_steps),
        "dynamic_newton_iterations": int(res.dynamic_newton_iterations),
        "static_newton_iterations": int(its if r.method == "energy" else res.static_newton_iterations),
        "static_residuals": [float(v) for v in getattr(res.static_result, "residuals", [])],
        "map_rebuilds": int(system.stats["rebuilds"]),
        "min_det_F": float(system.base.basis.min_det_F(xn)),
        "wall_time_s": {"setup": t_setup, "dynamic": res.timings.get("dynamic", 0.0),
                        "static": res.timings.get("static", 0.0), "total": time.perf_counter() - t_start},
        "history": history,
    }
    if r.method == "energy":
        sres = res.static_result
        summary["energy_mJ"] = float(system.energy(res.x))  # N mm = mJ
        summary["static_rates"] = [float(v) for v in getattr(sres, "rates", [])]
    # stability: inertia of the static tangent at the result (0 negative pivots: a local
    # minimum of the energy, not a saddle)
    from ..solvers.static import StaticProblem

    prob = StaticProblem(system, res.x, np.zeros(system.n), res.t)
    _, J = prob(prob.u0())
    neg = negative_eigenvalue_count(J)
    summary["negative_pivots"] = int(neg)
    summary["stable"] = bool(neg == 0)
    try:
        import resource

        summary["peak_rss_mb"] = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
    except (ImportError, OSError):  # pragma: no cover - non-POSIX
        pass
    return RelaxedFabric(fab, system, x0, res.x, summary)
