"""Time-convergence study of the dynamic wire (thesis §6.4, Fig. 6.4.4, Table 6.4).

The dynamic wire (``rve.scenes.dynamic_wire``) is integrated to t_max with the SDIRK
schemes s = 1, 2, 3 over a range of fixed step counts N; the four probes y(0), z(1/2),
T(1/2), V(1/2) at t_max are compared with a reference solution (s = 3, N_ref >= 1500 steps)
and an order is fitted per scheme and probe by least squares on log(error) vs log(h) over
the stated range of N. Everything about the study design is in a plan (``DEFAULT_PLAN``,
overridable from the pipeline config ``verification.dynamic_wire``).

Products (``write_study``): ``results/verification/dynamic_wire.nc`` (dims ``stages``,
``steps``; the probes, their errors, wall times and Newton iterations per run; the reference
values; fitted orders per field with dim ``stages``; units and long names on everything),
``dynamic_wire_orders.md`` (the Table 6.4 analogue), ``dynamic_wire_errors.png`` (error vs
h per field, Fig. 6.4.4) and ``dynamic_wire_work_precision.png`` (error vs wall time).

Runs are independent: ``run_point`` (one (s, N)), ``run_series`` (one scheme, all its N),
``run_reference``; ``run_study`` runs them on a process pool (2 workers by default, longest
first) and returns the gathered dataset. The Snakemake rules in
``workflow/rules/dynamic_wire.smk`` call the ``*_job`` functions.
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from ..io.atomic import atomic_path, atomic_write_json, atomic_write_text
from ..io.provenance import cf_attributes, logging_to, package_version
from .convergence import fit_order, fit_points

__all__ = ["DEFAULT_PLAN", "PROBE_NAMES", "load_scene_config", "run_point", "run_series", "run_reference",
           "run_study", "build_dataset", "fit_orders", "orders_table", "plot_errors", "plot_work_precision",
           "write_study", "series_job", "reference_job", "gather_job"]

log = logging.getLogger("rve.studies.dynamic_wire")

PROBE_NAMES = ("y0", "z_half", "T_half", "V_half")

#: The study design. ``steps`` per scheme; ``fit`` the inclusive range of N used for the
#: order fit (the asymptotic range: see docs/coupled_fields.md); the reference run. The
#: series add up to about the reference's 4500 stage solves, so two workers stay balanced.
DEFAULT_PLAN = {
    "scene_config": "configs/scenes/dynamic_wire.yaml",
    "overrides": [],
    "reference": {"stages": 3, "steps": 1500},
    "series": {
        1: {"steps": [150, 300, 600], "fit": [150, 600]},
        2: {"steps": [75, 150, 300], "fit": [75, 300]},
        3: {"steps": [75, 150, 225, 300], "fit": [75, 300]},
    },
}


def normalise_plan(plan: Optional[Mapping] = None) -> dict:
    """DEFAULT_PLAN updated by ``plan`` (keys of ``series`` may be str or int)."""
    out = json.loads(json.dumps(DEFAULT_PLAN))
    out["series"] = {int(k): v for k, v in out["series"].items()}
    if plan:
        for k, v in plan.items():
            if k == "series":
                out["series"] = {int(s): dict(d) for s, d in v.items()}
            elif k == "reference":
                out["reference"] = {**out["reference"], **v}
            else:
                out[k] = v
    if out["reference"]["stages"] != 3 or out["reference"]["steps"] < 1500:
        log.warning("the thesis reference is s = 3 with >= 1500 steps; plan has %s", out["reference"])
    return out


def load_scene_config(path=None, overrides: Sequence[str] = ()):
    """The validated ``DynamicWireConfig`` of ``path`` (YAML) with ``overrides``; the
    built-in defaults (the same numbers as configs/scenes/dynamic_wire.yaml) when ``path``
    is None."""
    from ..config.loader import load_config

    source = {"scene": "dynamic_wire"} if path is None else path
    return load_config(source, list(overrides))


def run_point(cfg, stages: int, steps: int, integrator_options: Optional[Mapping] = None) -> dict:
    """One fixed-step run -> record (probes at t_max, wall time, Newton iterations);
    ``integrator_options`` (flat ``rve.solvers.dirk.integrator_options`` names, e.g.
    ``{"jacobian_reuse": True}``) go to the scene's ``integrate``."""
    from ..scenes.dynamic_wire import solve
    from ..scenes.protocol import SceneFailure

    t0 = time.perf_counter()
    try:
        out = solve(cfg, stages=stages, steps=steps, fixed_step=True, record=True,
                    integrator_options=dict(integrator_options or {})).summary
    except SceneFailure as exc:  # a fixed-step run that cannot be done: recorded as NaN
        log.warning("s = %d, N = %d failed: %s", stages, steps, exc)
        return {"stages": int(stages), "steps": int(steps), "failed": str(exc),
                "probes": {k: float("nan") for k in PROBE_NAMES}, "wall_time_s": time.perf_counter() - t0,
                "newton_iterations": 0, "t_max": float(cfg.time.t_max), "V_half_initial": float("nan")}
    wall = time.perf_counter() - t0
    hist = out["history"]
    history = {k: np.asarray(hist[k], float).tolist() for k in ("t",) + PROBE_NAMES if k in hist}
    return {"stages": int(stages), "steps": int(steps), "probes": out["probes"], "wall_time_s": wall,
            "history": history,
            "newton_iterations": int(out["newton_iterations"]),
            "newton_iterations_per_stage": float(out["newton_iterations_per_stage"]),
            "newton_observed_order_median": out["newton"]["observed_orders_median"],
            "dofs": out["dofs"], "V_half_initial": out["V_half_initial"], "t_max": float(cfg.time.t_max)}


def run_series(cfg, stages: int, steps: Sequence[int], integrator_options: Optional[Mapping] = None) -> list:
    return [run_point(cfg, stages, n, integrator_options) for n in steps]


def run_reference(cfg, stages: int = 3, steps: int = 1500, integrator_options: Optional[Mapping] = None) -> dict:
    rec = run_point(cfg, stages, steps, integrator_options)
    rec["reference"] = True
    return rec


def _task(args):
    kind, cfg_path, overrides, s, steps, options = args
    cfg = load_scene_config(cfg_path, overrides)
    if kind == "reference":
        return [run_reference(cfg, s, steps, options)]
    return [run_point(cfg, s, steps, options)]


def run_study(plan: Optional[Mapping] = None, workers: int = 2, integrator_options: Optional[Mapping] = None) -> tuple:
    """All runs of the plan on ``workers`` processes, ``integrator_options`` given to every
    run (``run_point``). Returns (dataset, timings)."""
    options = dict(integrator_options or {})
    plan = normalise_plan(plan)
    ref = plan["reference"]
    tasks = [("reference", plan["scene_config"], plan["overrides"], ref["stages"], ref["steps"], options)]
    for s, ser in plan["series"].items():
        for n in ser["steps"]:
            tasks.append(("point", plan["scene_config"], plan["overrides"], s, n, options))
    tasks.sort(key=lambda t: -t[3] * t[4])  # longest (stages x steps) first
    t0 = time.perf_counter()
    records = []
    if workers <= 1:
        for t in tasks:
            records += _task(t)
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else None
        with ProcessPoolExecutor(workers, mp_context=ctx) as ex:
            for r in ex.map(_task, tasks):
                records += r
    wall = time.perf_counter() - t0
    reference = next(r for r in records if r.get("reference"))
    points = [r for r in records if not r.get("reference")]
    ds = build_dataset(points, reference, plan)
    return ds, {"study_wall_s": wall, "reference_wall_s": reference["wall_time_s"],
                "sum_of_run_walls_s": sum(r["wall_time_s"] for r in records)}


# --------------------------------------------------------------------------- dataset
_UNITS = {"y0": "mm", "z_half": "mm", "T_half": "K", "V_half": "V"}
_LONG = {
    "y0": "centroid y displacement at the centre (l = 0) at t_max",
    "z_half": "centroid z displacement at l = 1/2 at t_max",
    "T_half": "temperature change at l = 1/2 at t_max",
    "V_half": "electric potential at l = 1/2 at t_max",
}


def build_dataset(points: Sequence[Mapping], reference: Mapping, plan: Mapping):
    import xarray as xr

    stages = sorted({int(p["stages"]) for p in points})
    steps = sorted({int(p["steps"]) for p in points})
    shape = (len(stages), len(steps))
    val = {k: np.full(shape, np.nan) for k in PROBE_NAMES}
    wall = np.full(shape, np.nan)
    its = np.full(shape, np.nan)
    for p in points:
        i, j = stages.index(int(p["stages"])), steps.index(int(p["steps"]))
        for k in PROBE_NAMES:
            val[k][i, j] = p["probes"][k]
        wall[i, j] = p["wall_time_s"]
        its[i, j] = p["newton_iterations"]
    t_max = float(reference["t_max"])
    data = {}
    for k in PROBE_NAMES:
        data[k] = (("stages", "steps"), val[k], {"units": _UNITS[k], "long_name": _LONG[k]})
        data[f"error_{k}"] = (("stages", "steps"), np.abs(val[k] - reference["probes"][k]),
                              {"units": _UNITS[k], "long_name": f"|{k} - reference| at t_max"})
        data[f"reference_{k}"] = ((), float(reference["probes"][k]),
                                  {"units": _UNITS[k], "long_name": f"reference {_LONG[k]}"})
    # sup over time of the probe errors, on the grid times a run shares with the reference
    # (a measure that does not depend on one final time; NaN without histories)
    maxerr = {k: np.full(shape, np.nan) for k in PROBE_NAMES}
    rh = reference.get("history")
    if rh:
        rt = np.asarray(rh["t"], float)
        for p in points:
            ph = p.get("history")
            if not ph:
                continue
            pt = np.asarray(ph["t"], float)
            idx = np.searchsorted(rt, pt)
            idx = np.clip(idx, 0, len(rt) - 1)
            shared = np.abs(rt[idx] - pt) <= 1e-9 * t_max
            if shared.sum() < 2:
                continue
            i, j = stages.index(int(p["stages"])), steps.index(int(p["steps"]))
            for k in PROBE_NAMES:
                if k in ph and k in rh:
                    d = np.asarray(ph[k], float)[shared] - np.asarray(rh[k], float)[idx[shared]]
                    maxerr[k][i, j] = np.nanmax(np.abs(d))
    for k in PROBE_NAMES:
        data[f"max_error_{k}"] = (("stages", "steps"), maxerr[k],
                                  {"units": _UNITS[k], "long_name": f"max over the shared grid times of |{k} - reference|"})
    data["wall_time"] = (("stages", "steps"), wall, {"units": "s", "long_name": "wall time of the run"})
    data["newton_iterations"] = (("stages", "steps"), its, {"units": "1", "long_name": "Newton iterations"})
    data["reference_wall_time"] = ((), float(reference["wall_time_s"]),
                                   {"units": "s", "long_name": "wall time of the reference run"})
    coords = {
        "stages": ("stages", np.array(stages), {"long_name": "SDIRK stages s (order s)", "units": "1"}),
        "steps": ("steps", np.array(steps), {"long_name": "number of time steps N", "units": "1"}),
        "h": ("steps", t_max / np.array(steps, float), {"long_name": "time step h = t_max / N", "units": "ms"}),
    }
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(cf_attributes(
        title="rve dynamic wire: SDIRK time convergence (thesis §6.4, Table 6.4)",
        source=f"rve {package_version()} rve.scenes.dynamic_wire.simulate",
        references="Queiruga (2015), section 6.4, Fig. 6.4.4, Table 6.4; docs/coupled_fields.md",
        history="rve.studies.dynamic_wire.build_dataset",
        t_max_ms=t_max,
        reference_stages=int(reference["stages"]),
        reference_steps=int(reference["steps"]),
        plan=json.dumps(plan, default=str),
        V_half_initial=float(reference["V_half_initial"]),
    ))
    orders = fit_orders(ds, plan)
    orders_max = fit_orders(ds, plan, prefix="max_error_")
    for k in PROBE_NAMES:
        ds[f"order_{k}"] = (("stages",), np.array([orders[s][k] for s in stages]),
                            {"units": "1", "long_name": f"fitted convergence order of {k} at t_max "
                                                        "(least squares over the fit range)"})
        ds[f"order_max_{k}"] = (("stages",), np.array([orders_max[s][k] for s in stages]),
                                {"units": "1", "long_name": f"fitted convergence order of the max-in-time error of {k}"})
    return ds


def fit_orders(ds, plan: Mapping, prefix: str = "error_") -> dict:
    """{s: {probe: slope of log(error) vs log(h) over the plan's fit range}} for the error
    variables ``<prefix><probe>`` (``error_``: at t_max; ``max_error_``: max over time);
    the one least-squares fit of ``rve.studies.convergence.fit_order`` (NaN with fewer than
    two finite, positive errors in range)."""
    plan = normalise_plan(plan)
    out = {}
    for s in ds.stages.values:
        ser = plan["series"].get(int(s), {})
        lo, hi = ser.get("fit", [min(ds.steps.values), max(ds.steps.values)])
        out[int(s)] = {}
        for k in PROBE_NAMES:
            e = ds[f"{prefix}{k}"].sel(stages=s).values
            out[int(s)][k] = fit_order(ds.h.values, e, fit_points(ds.steps.values, e, lo, hi))
    return out


def orders_table(ds) -> str:
    """Markdown: fitted orders at t_max (Table 6.4) and of the max-in-time errors."""
    lines = ["| s | " + " | ".join(PROBE_NAMES) + " | " + " | ".join(f"max-in-time {k}" for k in PROBE_NAMES) + " |",
             "|---|" + "---|" * (2 * len(PROBE_NAMES))]
    for s in ds.stages.values:
        row = [f"{float(ds[f'order_{k}'].sel(stages=s)):.2f}" for k in PROBE_NAMES]
        if f"order_max_{PROBE_NAMES[0]}" in ds:
            row += [f"{float(ds[f'order_max_{k}'].sel(stages=s)):.2f}" for k in PROBE_NAMES]
        lines.append(f"| {int(s)} | " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def plot_errors(ds, out_png) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(9, 7), constrained_layout=True)
    for ax, k in zip(axes.ravel(), PROBE_NAMES):
        for s in ds.stages.values:
            e = ds[f"error_{k}"].sel(stages=s)
            ok = np.isfinite(e.values)
            line, = ax.loglog(ds.h.values[ok], e.values[ok], "o-", label=f"s = {int(s)} "
                              f"(order {float(ds[f'order_{k}'].sel(stages=s)):.2f})")
        ax.set_title(f"{k} ({_UNITS[k]})")
        ax.set_xlabel("h (ms)")
        ax.set_ylabel("|error| at t_max")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"dynamic wire: SDIRK errors vs the s = {ds.attrs['reference_stages']}, "
                 f"N = {ds.attrs['reference_steps']} reference")
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def plot_work_precision(ds, out_png) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(2, 2, figsize=(9, 7), constrained_layout=True)
    for ax, k in zip(axes.ravel(), PROBE_NAMES):
        for s in ds.stages.values:
            e = ds[f"error_{k}"].sel(stages=s).values
            t = ds["wall_time"].sel(stages=s).values
            ok = np.isfinite(e) & np.isfinite(t)
            ax.loglog(t[ok], e[ok], "o-", label=f"s = {int(s)}")
        ax.set_title(f"{k} ({_UNITS[k]})")
        # plain numbers on the time axis (the default minor labels 2x10^0, 3x10^0 collide)
        ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("|error| at t_max")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("dynamic wire: work-precision of the SDIRK schemes")
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def write_study(ds, nc_path, orders_md=None, errors_png=None, work_png=None) -> None:
    with atomic_path(nc_path) as tmp:
        ds.to_netcdf(tmp)
    if orders_md:
        atomic_write_text(orders_md, "# Dynamic wire: fitted SDIRK orders (Table 6.4)\n\n" + orders_table(ds))
    if errors_png:
        plot_errors(ds, errors_png)
    if work_png:
        plot_work_precision(ds, work_png)


# --------------------------------------------------------------------------- Snakemake jobs
def series_job(out_json, log_path, scene_config, overrides, stages: int, steps: Sequence[int]) -> None:
    """Snakemake: all runs of one scheme -> JSON list of records."""
    with logging_to(log_path):
        cfg = load_scene_config(scene_config, overrides)
        recs = run_series(cfg, int(stages), [int(n) for n in steps])
        atomic_write_json(out_json, recs)


def reference_job(out_json, log_path, scene_config, overrides, stages: int, steps: int) -> None:
    with logging_to(log_path):
        cfg = load_scene_config(scene_config, overrides)
        atomic_write_json(out_json, run_reference(cfg, int(stages), int(steps)))


def gather_job(series_jsons, reference_json, nc_path, orders_md, errors_png, work_png, plan) -> None:
    points = []
    for p in series_jsons:
        points += json.loads(Path(p).read_text())
    reference = json.loads(Path(reference_json).read_text())
    ds = build_dataset(points, reference, normalise_plan(plan))
    write_study(ds, nc_path, orders_md, errors_png, work_png)
