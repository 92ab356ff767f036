"""Work-precision study of the table's levers against one common fine reference
(docs/table_accuracy.md, "Work-precision study").

A study is ordinary pipeline runs (configs/pipeline.yaml, ``rve.work_precision.{study}``):
a **reference** run (one combination, the finest settings), a **default** run (the
configuration whose stated error the study produces) and one sweep run per **lever**
(pinned vs periodic, cell size, p, elements per fibril, contact quadrature count, penalty
vs augmented Lagrangian: each lever its run, each value its combination and chain of jobs).
This module compares their tables (opened by the caller) and the Snakemake benchmark files
of their jobs; a lever whose override key the config does not know is skipped by the caller
(``rve.homogenisation.layout.work_precision_runs``) and listed with its reason.

For every run (a combination of a lever run, the default run) and every table quantity
(``rve.studies.table_convergence.QUANTITIES``) the error against the reference on the
**stated measure** ``STATED_MEASURE``, the **magnitude measure** (``relative_error``:
|q - q_ref| over the largest |q_ref| of that label and mode along the strain path, so a
label that crosses zero is divided by its largest value, not by its value there), and, for
comparison, on the range measure (``range_error``: over the reference's range over the
strain path, floored at ``RANGE_FLOOR`` x the quantity's scale; it divides a nearly
constant label, a sheet resistance or a transverse force, by its few per cent of
variation), max over labels, modes and strains (and per mode); the **work** = summed CPU seconds of the combination's jobs (wall
seconds and the largest job's peak RSS beside it). The **Pareto front** is over (CPU time,
worst target ratio = max over quantities of error / ``TARGETS``): the runs no other run
beats in both.

Contract
--------
* ``run_errors(run_ds, reference_ds)`` -> {"range": {q: e}, "magnitude": {q: e},
  "range_by_mode": {q: {mode: e}}, "magnitude_by_mode": {q: {mode: e}}} (tables aligned on
  their common modes and strains); ``stated(errors)`` its ``STATED_MEASURE`` part;
  ``error_rows(run_ds, reference_ds)`` the rows (label, mode, strain) they are the maxima of;
* ``pareto_front(points)`` -> indices of the non-dominated (cpu, error) points;
* ``work_precision_job(reference, default, levers, costs, skipped, outputs, log_path,
  names)`` writes ``md`` (the table), ``csv`` (every run and quantity), ``png`` (error vs
  CPU time, one marker per lever, the front) and ``json`` (the default run's stated error:
  an accuracy file ``rve.tables.accuracy`` reads, ``method: work_precision``).
"""
from __future__ import annotations

import csv
import io
import json
import logging
import os
from pathlib import Path
from typing import Mapping, Optional, Sequence, Union

import numpy as np

from ..io.atomic import atomic_path, atomic_write_json, atomic_write_text
from ..io.provenance import logging_to
from .table_convergence import NEGLIGIBLE, QUANTITIES, RANGE_FLOOR, relative_errors, summarize_by_mode

__all__ = ["STATED_MEASURE", "TARGETS", "not_comparable", "error_rows", "run_errors", "stated", "worst_ratio", "missing_targets",
           "target_misses", "pareto_front", "front_of", "study_points", "work_precision_report", "work_precision_job"]

log = logging.getLogger("rve.studies.work_precision")

PathLike = Union[str, os.PathLike]

#: the measure of the stated errors and the targets (module docstring)
STATED_MEASURE = "magnitude"

#: the accuracy asked of the default table against the reference (max over strains, labels and
#: modes, the stated measure): forces and Joule rise 2 %, probe resistances 1 %, R_c 2 %, R_y 0.5 %
TARGETS = {"reaction_force": 0.02, "membrane_force": 0.02, "probe_resistance": 0.01, "temperature_rise_max": 0.02,
           "contact_resistance": 0.02, "yarn_resistance": 0.005}

_RUN, _REF = 0.0, 1.0   # the two values of the comparison's stacking dimension
_DIM = "wp_run"


def not_comparable(run_ds, reference_ds) -> dict:
    """{quantity: why} of the table quantities a run cannot be compared on with the
    reference: a per-cell force between cells of different size (the pinned 4 x 4 cell and
    a periodic 2 x 2 one, a repeated cell; ``membrane_force`` is the per-width form), probe
    resistances and Joule rises of different probes (a pinned cell's terminal probes, a
    periodic cell's field probes), and a quantity the reference does not have (or has only
    as NaN: the network R_y, R_c of a periodic cell)."""
    out = {}
    size = [tuple(float(ds[c].values) if c in ds.coords else np.nan for c in ("cell_length_x", "cell_length_y"))
            for ds in (run_ds, reference_ds)]
    if "reaction_force" in reference_ds and not np.allclose(size[0], size[1], rtol=1e-9, equal_nan=True):
        out["reaction_force"] = (f"a force per cell: cell {size[0][0]:g} x {size[0][1]:g} mm against the "
                                 f"reference's {size[1][0]:g} x {size[1][1]:g} mm (membrane_force is per width)")
    probes = [set(ds["probe"].values.tolist()) if "probe" in ds.coords else set() for ds in (run_ds, reference_ds)]
    for q in ("probe_resistance", "temperature_rise_max"):
        if q in reference_ds and q in run_ds and not probes[0] & probes[1]:
            out[q] = f"no common probe (run {sorted(probes[0])}, reference {sorted(probes[1])})"
    for q in TARGETS:
        if q not in out and (q not in reference_ds or not np.isfinite(np.asarray(reference_ds[q].values, float)).any()):
            out[q] = "not in the reference table"
        elif q not in out and q not in run_ds:
            out[q] = "not in the run's table"
    return out


def error_rows(run_ds, reference_ds, skip=None) -> list[dict]:
    """The per-label, mode and strain rows (``table_convergence.relative_errors``) of one
    run's table against the reference's, on the modes and strains both have, for the
    quantities not in ``skip`` (default ``not_comparable``)."""
    import xarray as xr

    skip = not_comparable(run_ds, reference_ds) if skip is None else skip
    names = [q for q in QUANTITIES if q in run_ds and q in reference_ds and q not in skip]
    a, b = xr.align(run_ds[names].reset_coords(drop=True), reference_ds[names].reset_coords(drop=True),
                    join="inner")
    ds = xr.concat([a, b], dim=xr.DataArray([_RUN, _REF], dims=_DIM, name=_DIM))
    return relative_errors(ds, _REF, _DIM)


def run_errors(run_ds, reference_ds) -> dict:
    """Errors of one run's table against the reference's (module docstring), on the modes
    and strains both have; ``not_compared`` {quantity: why} (``not_comparable``)."""
    skip = not_comparable(run_ds, reference_ds)
    rows = error_rows(run_ds, reference_ds, skip)
    out: dict = {"range": {}, "magnitude": {}, "range_by_mode": {}, "magnitude_by_mode": {}, "not_compared": skip}
    for r in rows:
        for key, col in (("range", "range_error"), ("magnitude", "relative_error")):
            e = r[col]
            if np.isfinite(e):
                out[key][r["quantity"]] = max(out[key].get(r["quantity"], 0.0), e)
    for key, col in (("range_by_mode", "range_error"), ("magnitude_by_mode", "relative_error")):
        for q, modes in summarize_by_mode(rows, _DIM, col).items():
            out[key][q] = {m: v[_RUN]["max"] for m, v in modes.items() if _RUN in v}
    return out


def stated(errors: Mapping, by_mode: bool = False) -> dict:
    """The ``STATED_MEASURE`` part of ``run_errors``' result (per mode with ``by_mode``)."""
    return errors.get(f"{STATED_MEASURE}_by_mode" if by_mode else STATED_MEASURE) or {}


def worst_ratio(errors: Mapping[str, float]) -> float:
    """max over quantities of error / target (<= 1: every target met)."""
    vals = [e / TARGETS[q] for q, e in errors.items() if q in TARGETS and e is not None and np.isfinite(e)]
    return float(max(vals)) if vals else float("nan")


def missing_targets(errors: Mapping) -> list:
    """The targeted quantities the reference has but the run got no error for (not
    comparable, or NaN in the run): a run with any is not a candidate for the default, its
    worst ratio omits them."""
    skip = errors.get("not_compared") or {}
    return [q for q in TARGETS if q not in stated(errors) and skip.get(q) != "not in the reference table"]


def target_misses(errors: Mapping) -> dict:
    """{quantity: (error, target)} of the compared quantities above their target."""
    return {q: (e, TARGETS[q]) for q, e in stated(errors).items() if q in TARGETS and e > TARGETS[q]}


def pareto_front(points: Sequence[tuple]) -> list:
    """Indices of the (cpu, error) points that no other point beats in both (ties kept),
    in order of increasing cpu."""
    idx = [i for i, (c, e) in enumerate(points) if np.isfinite(c) and np.isfinite(e)]
    front = [i for i in idx if not any((points[j][0] <= points[i][0] and points[j][1] <= points[i][1])
                                       and (points[j][0] < points[i][0] or points[j][1] < points[i][1]) for j in idx)]
    return sorted(front, key=lambda i: points[i][0])


def _combo_value(params: Mapping) -> str:
    return ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in params.items()) or "base"


def study_points(reference, default, levers: Mapping, costs: Mapping) -> list[dict]:
    """Every run of the study against the reference: one dict per combination (``lever``,
    ``run``, ``combo``, ``label``, ``errors``, ``cost``). ``levers``: {lever: (run name,
    table)}; ``default``: (run name, table) or None; ``costs``: {run: {combo: cost dict}}
    (``table_convergence.combo_costs``)."""
    out = []
    entries = ([("default", default)] if default is not None else []) + list(levers.items())
    for lever, (run, ds) in entries:
        # the table's own record of its sweep (rve.tables.build); label dimensions (side, probe,
        # edge, yarn, ...) are not runs
        named = ds.attrs.get("swept_parameters")
        swept = ([d for d in str(named).split() if d in ds.dims] if named is not None else
                 [d for d in ds.dims if d in ds.coords and d not in ("mode", "strain", "probe", "side", "component",
                                                                      "terminal", "edge", "yarn")])
        combos = [{}]
        for d in swept:
            combos = [dict(c, **{d: v}) for c in combos for v in ds[d].values.tolist()]
        for params in combos:
            sel = ds.sel(params) if params else ds
            errs = run_errors(sel, reference)
            combo = "__".join(f"{k}-{format(v, '.12g') if isinstance(v, float) else v}" for k, v in params.items()) \
                or "base"
            missing = missing_targets(errs)
            ratio = worst_ratio(stated(errs))
            out.append({"lever": lever, "run": run, "combo": combo, "label": _combo_value(params), "errors": errs,
                        "cost": (costs.get(run) or {}).get(combo, {}), "worst_ratio": ratio, "missing": missing,
                        "meets": bool(not missing and np.isfinite(ratio) and ratio <= 1.0)})
    return out


def front_of(points: Sequence[Mapping]) -> list:
    """Indices (into ``points``) of the Pareto front over (CPU time, worst ratio) among the
    runs compared on every targeted quantity the reference has."""
    full = [i for i, p in enumerate(points) if not p["missing"]]
    sub = pareto_front([(points[i]["cost"].get("cpu_s", np.nan) or np.nan, points[i]["worst_ratio"]) for i in full])
    return [full[k] for k in sub]


def work_precision_report(points: Sequence[Mapping], skipped: Mapping[str, str], names: Mapping) -> str:
    """Markdown: every run's error on the stated measure (the range measure in brackets), its
    CPU time, the front, the runs that meet every target, what the default misses, the
    quantities not compared and the skipped levers."""
    qs = [q for q in QUANTITIES if any(q in stated(p["errors"]) for p in points)]
    front = set(front_of(points))
    out = [f"# Work-precision study {names.get('study', '')} (rve.studies.work_precision)", "",
           f"Reference: run {names.get('reference')}. Error = max over labels, modes and strains of |q - q_ref| / "
           "max |q_ref| of the label and mode over the strain path (the magnitude measure, stated; the range "
           f"measure, / max(range of q_ref over the path, {RANGE_FLOOR:g} x the quantity's scale), in brackets); "
           f"labels below {NEGLIGIBLE:g} of the quantity's scale left out. Work = summed CPU time of the run's jobs. Front: among the runs compared on "
           "every targeted quantity the reference has, no other run is both cheaper and more accurate (worst error "
           "/ target over the quantities). meets: every such quantity within its target.", "",
           "| lever | run | CPU s | wall s | peak RSS MB | " + " | ".join(QUANTITIES[q] for q in qs)
           + " | worst / target | front | meets |",
           "|" + "---|" * (len(qs) + 8)]
    for i, p in enumerate(points):
        c = p["cost"]
        cells = [f"{100 * p['errors']['magnitude'][q]:.3g} % ({100 * p['errors']['range'].get(q, np.nan):.3g} %)"
                 if q in p["errors"]["magnitude"] else "n/a" for q in qs]
        meets = "yes" if p["meets"] else ("incomplete" if p["missing"] else "no")
        out.append(f"| {p['lever']} | {p['label']} | {c.get('cpu_s', np.nan):.1f} | {c.get('wall_s', np.nan):.1f} | "
                   f"{c.get('max_rss_mb', np.nan):.0f} | " + " | ".join(cells)
                   + f" | {p['worst_ratio']:.3g} | {'yes' if i in front else ''} | {meets} |")
    out += ["", "Per mode (magnitude measure, max over labels and strains):", ""]
    for p in points:
        by = stated(p["errors"], by_mode=True)
        cells = "; ".join(f"{QUANTITIES[q]} " + ", ".join(f"{m} {100 * e:.3g} %" for m, e in sorted(by[q].items()))
                          for q in qs if q in by)
        out.append(f"* {p['lever']} {p['label']}: {cells}")
    out += ["", "Targets: " + ", ".join(f"{QUANTITIES[q]} {100 * t:g} %" for q, t in TARGETS.items())]
    met = [p for p in points if p["meets"]]
    out += ["", "Runs meeting every target: " + (", ".join(f"{p['lever']} {p['label']} ({p['cost'].get('cpu_s', np.nan):.0f}"
                                                           " CPU s)" for p in sorted(
        met, key=lambda p: p["cost"].get("cpu_s", np.inf))) if met else "none")]
    dp = next((p for p in points if p["lever"] == "default"), None)
    if dp is not None:
        miss = target_misses(dp["errors"])
        out += ["", "The default run against the targets: " + (
            "; ".join(f"{QUANTITIES[q]} {100 * e:.3g} % > {100 * t:g} % ({e / t:.3g} x)" for q, (e, t) in miss.items())
            if miss else "every compared quantity within its target")
            + ("; not compared: " + ", ".join(QUANTITIES[q] for q in dp["missing"]) if dp["missing"] else "")]
    gone = {}
    for p in points:
        for q, why in (p["errors"].get("not_compared") or {}).items():
            gone.setdefault(f"{QUANTITIES[q]}: {why}", []).append(f"{p['lever']} {p['label']}")
    if gone:
        out += ["", "Not compared:", ""] + [f"* {why} ({', '.join(runs)})" for why, runs in gone.items()]
    if skipped:
        out += ["", "Levers skipped (their override key is not known to the config):", ""]
        out += [f"* {lever}: {why}" for lever, why in skipped.items()]
    return "\n".join(out) + "\n"


def _plot(path, points):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4, 4.6))
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    markers = "os^vD<>phX*"
    levers = list(dict.fromkeys(p["lever"] for p in points))
    pts = [(p["cost"].get("cpu_s", np.nan) or np.nan, p["worst_ratio"]) for p in points]
    for k, lever in enumerate(levers):
        sel = [(x, y, p["label"], bool(p["missing"])) for (x, y), p in zip(pts, points) if p["lever"] == lever]
        line, = ax.plot([s[0] for s in sel if not s[3]], [max(s[1], 1e-6) for s in sel if not s[3]], ls="",
                        marker=markers[k % len(markers)], ms=7, label=lever)
        part = [s for s in sel if s[3]]   # compared on a part of the targets only: hollow
        if part:
            ax.plot([s[0] for s in part], [max(s[1], 1e-6) for s in part], ls="", marker=markers[k % len(markers)],
                    ms=7, mfc="none", color=line.get_color(), label=f"{lever} (part of the targets)")
        for x, y, lab, _ in sel:
            ax.annotate(lab, (x, max(y, 1e-6)), textcoords="offset points", xytext=(4, 3), fontsize=6)
    front = front_of(points)
    if front:
        ax.plot([pts[i][0] for i in front], [max(pts[i][1], 1e-6) for i in front], "k--", lw=0.8, label="front")
    ax.axhline(1.0, color="0.5", lw=0.6)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("work: summed job CPU time of the run [s]")
    ax.set_ylabel("worst error / target over the quantities (magnitude measure)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title("work-precision against the common reference", fontsize=10)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=120)


def _csv(points) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["lever", "run", "combo", "quantity", "range_error", "magnitude_error", "cpu_s", "wall_s",
                "max_rss_mb"])
    for p in points:
        for q, e in p["errors"]["range"].items():
            w.writerow([p["lever"], p["run"], p["combo"], q, e, p["errors"]["magnitude"].get(q),
                        p["cost"].get("cpu_s"), p["cost"].get("wall_s"), p["cost"].get("max_rss_mb")])
    return buf.getvalue()


def accuracy_record(points, names: Mapping, default_config: Mapping, skipped: Mapping) -> dict:
    """The accuracy file of the default run (``rve.tables.accuracy``, ``method:
    work_precision``): its error against the reference on the stated measure, per quantity
    and per mode (the range measure beside it), and every run's figures."""
    dp = next((p for p in points if p["lever"] == "default"), None)
    errs = stated(dp["errors"]) if dp else {}
    by_mode = {q: {m: {"max": e} for m, e in modes.items()} for q, modes in (stated(dp["errors"], by_mode=True)
                                                                              if dp else {}).items()}
    ref = names.get("reference")
    return {"method": "work_precision", "measure": STATED_MEASURE, "range_floor": RANGE_FLOOR,
            "negligible_fraction": NEGLIGIBLE, "targets": TARGETS, "default": dict(default_config),
            "reference": ref, "study": names.get("study"),
            "stated_relative_error": errs, "stated_relative_error_by_mode": by_mode,
            "range_relative_error": dict(dp["errors"]["range"]) if dp else {},
            "meets_targets": {q: bool(e <= TARGETS.get(q, np.inf)) for q, e in errs.items()},
            "not_measured": dict(dp["errors"].get("not_compared") or {}) if dp else {},
            "front": [f"{points[i]['lever']}: {points[i]['combo']}" for i in front_of(points)],
            # the layout of a convergence study's file (read_accuracy): the whole error in "mesh"
            "mesh": {"reference": ref, "estimated_relative_error": errs, "stated_relative_error": errs,
                     "by_mode": by_mode},
            "penalty": {"reference": ref, "estimated_relative_error": {}},
            "skipped_levers": dict(skipped),
            "runs": [{"lever": p["lever"], "run": p["run"], "combo": p["combo"], "range_error": p["errors"]["range"],
                      "magnitude_error": p["errors"]["magnitude"], "worst_ratio": p["worst_ratio"],
                      "not_compared": p["errors"].get("not_compared") or {}, "meets": p["meets"], **p["cost"]}
                     for p in points]}


def work_precision_job(reference, default, levers: Mapping, costs: Mapping, skipped: Mapping[str, str],
                       outputs: Mapping[str, PathLike], log_path: Optional[PathLike], names: Mapping,
                       default_config: Mapping) -> dict:
    """The study's report (module docstring). ``reference``: the reference table;
    ``default``: (run, table) or None; ``levers``: {lever: (run, table)}; ``costs``: {run:
    {combo: cost}}; ``skipped``: {lever: why}; ``names``: study, reference (run names);
    ``default_config``: the default run's mesh_elements, contact_penalty (and the other
    lever values) for the accuracy file. Returns the accuracy record."""
    with logging_to(log_path):
        for lever, why in skipped.items():
            log.warning("work-precision %s: lever %s skipped: %s", names.get("study"), lever, why)
        points = study_points(reference, default, levers, costs)
        text = work_precision_report(points, skipped, names)
        atomic_write_text(outputs["md"], text)
        atomic_write_text(outputs["csv"], _csv(points))
        _plot(outputs["png"], points)
        acc = accuracy_record(points, names, default_config, skipped)
        atomic_write_json(outputs["json"], json.loads(json.dumps(acc, default=float)))
        log.info("work-precision study:\n%s", text)
    return acc


def work_precision_rule(wp: Mapping, default_config: Mapping, open_table, table_path, benchmark_dir: PathLike,
                        outputs: Mapping, log_path: Optional[PathLike], study: str) -> dict:
    """The body of the Snakemake rule ``rve_work_precision_report``: ``wp`` the study's runs
    (``rve.homogenisation.layout.work_precision_runs``: reference, default, levers, skipped),
    ``default_config`` the default run's lever values (``rve.homogenisation.sweeps.lever_values``),
    ``open_table(path)`` the table reader, ``table_path(run)`` a run's table files; reads
    each run's job costs and calls :func:`work_precision_job`."""
    from .table_convergence import combo_costs

    default = wp["default"]
    runs = [wp["reference"]] + ([default] if default else []) + list(wp["levers"].values())
    costs = {r: combo_costs(benchmark_dir, r) for r in runs}

    def table(run):
        return open_table(table_path(run)["table"])

    return work_precision_job(table(wp["reference"]), (default, table(default)) if default else None,
                              {lv: (r, table(r)) for lv, r in wp["levers"].items()}, costs, wp["skipped"],
                              outputs, log_path, {"study": study, "reference": wp["reference"]}, dict(default_config))
