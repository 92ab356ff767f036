"""Convergence of the RVE lookup table with the mesh and the contact penalty
(docs/table_accuracy.md).

A study is two ordinary sweep runs of the pipeline (configs/pipeline.yaml: ``{study}_mesh``
over ``mesh.elements``, ``{study}_penalty`` over ``contact_penalty``; each combination its
own chain of jobs). This module compares their tables (opened by the caller: the tables are
a higher layer, ``rve.tables.open_table``) and the Snakemake benchmark files of their jobs.

For every **table quantity** (``QUANTITIES``: clamp reaction forces, membrane forces, probe
resistances, Joule temperature rises, the network R_y and R_c) and every label of it (side
and component, probe, ...), at every mode and strain, the difference of each run to the
**reference run** (the finest mesh; the stiffest penalty) relative to the reference's
magnitude ``scale`` = max over strains of |q_ref| at that label and mode (``relative_error``,
the magnitude measure) and, beside it, relative to the reference's **range** over the strain
path at that label and mode, max - min over strains, floored at ``RANGE_FLOOR`` x the
quantity's overall scale (``range_error``, the range measure: a label that crosses zero or
hardly moves is judged against how much it varies). Labels whose
scale is below ``NEGLIGIBLE`` x the quantity's largest value (e.g. the z reactions of an
in-plane cell, the shear reaction of a uniaxial stretch at strain 0) are left out: their
relative error measures noise. Per run and quantity, ``error`` = the maximum over the kept
labels, modes and strains (every strain is in the CSV).

The **observed rate** with mesh size h = 1/N: the least-squares slope of log error against
log h over the runs other than the reference (``rve.studies.convergence.fit_order``), NaN
when fewer than two errors are positive. Reference-based errors of the run next to the
reference are biased low, so the rate is indicative. **Work**: the summed wall time of a
combination's jobs (fabric, relax, strain steps, probes; from
``results/benchmarks/rve/{run}/{combo}/**.tsv``) and, for the default job, the ratio to
the reference run's.

Contract
--------
* ``relative_errors(tables, reference, dim)`` -> long rows (quantity, label, mode, strain,
  value, run value, reference value, relative error);
* ``summarize_errors(rows)`` -> {quantity: {run value: max error}};
* ``observed_rates(summary, reference)`` -> {quantity: rate} (mesh: h = 1/N);
* ``combo_wall_times(bench_root, run)`` -> {combo: summed job seconds};
* ``table_convergence_job(mesh_table, penalty_table, bench_root, runs, outputs, log_path,
  default)`` writes ``csv``, ``md``, ``png``, ``json`` (the accuracy of the default run
  against both references and whether it meets ``TARGETS``) atomically.
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

from ..io.atomic import atomic_path, atomic_write_text
from ..io.provenance import logging_to
from .convergence import fit_order

__all__ = ["QUANTITIES", "TARGETS", "NEGLIGIBLE", "RANGE_FLOOR", "REFERENCE_ORDER", "range_scale", "relative_errors", "summarize_errors",
           "summarize_by_mode", "observed_rates", "reference_error", "combo_costs", "combo_wall_times", "convergence_report", "table_convergence_job"]

log = logging.getLogger("rve.studies.table_convergence")

PathLike = Union[str, os.PathLike]

#: table variable -> short name in the report
QUANTITIES = {
    "reaction_force": "reaction force",
    "membrane_force": "membrane force",
    "probe_resistance": "probe resistance",
    "temperature_rise_max": "Joule rise (max)",
    "yarn_resistance": "R_y",
    "contact_resistance": "R_c",
}
#: the accuracy asked of the default mesh (relative to the finest run): docs/table_accuracy.md
TARGETS = {"reaction_force": 0.02, "membrane_force": 0.02, "probe_resistance": 0.01, "yarn_resistance": 0.01,
           "contact_resistance": 0.01, "temperature_rise_max": 0.02}
#: labels smaller than this fraction of the quantity's largest reference value are not assessed
NEGLIGIBLE = 0.05
#: floor of the range measure's denominator, as a fraction of the quantity's overall scale
RANGE_FLOOR = 0.05
#: the convergence order assumed to estimate the finest mesh's own error (``reference_error``)
REFERENCE_ORDER = 1.0

_LEAD = ("mode", "strain")


def _labels(var, dim):
    return [d for d in var.dims if d not in _LEAD and d != dim]


def relative_errors(ds, reference, dim: str) -> list[dict]:
    """Rows of the relative difference of every run (value of ``dim``) to the ``reference``
    run, per quantity, label, mode and strain (module docstring)."""
    rows = []
    ref_ds = ds.sel({dim: reference})
    for name in QUANTITIES:
        if name not in ds:
            continue
        var = ds[name]
        labels = _labels(var, dim)
        ref = ref_ds[name].transpose("mode", "strain", *labels)
        rv = np.asarray(ref.values, float)
        scale = np.nanmax(np.abs(rv), axis=1)                          # (mode, *labels)
        big = np.nanmax(scale) if np.isfinite(scale).any() else np.nan
        keep = scale >= NEGLIGIBLE * big
        span = range_scale(rv, big)                                    # (mode, *labels)
        for val in ds[dim].values:
            if val == reference:
                continue
            run = np.asarray(var.sel({dim: val}).transpose("mode", "strain", *labels).values, float)
            err = np.abs(run - rv) / np.expand_dims(np.where(keep, scale, np.nan), 1)
            err_range = np.abs(run - rv) / np.expand_dims(np.where(keep, span, np.nan), 1)
            for idx in np.ndindex(err.shape):
                m, s, lab = idx[0], idx[1], idx[2:]
                if not keep[(m,) + lab]:
                    continue
                label = "/".join(str(ds[d].values[i]) for d, i in zip(labels, lab)) or "-"
                rows.append({"quantity": name, "label": label, "mode": str(ds["mode"].values[m]),
                             "strain": float(ds["strain"].values[s]), dim: float(val),
                             "value": float(run[idx]), "reference": float(rv[idx]),
                             "relative_error": float(err[idx]), "range_error": float(err_range[idx])})
    return rows


def range_scale(ref, big: float) -> np.ndarray:
    """Denominator of the range measure, (mode, *labels) of a reference (mode, strain,
    *labels): the reference's range over the strain path at that label and mode (max - min
    over strains), floored at ``RANGE_FLOOR`` x ``big`` (the quantity's overall scale, max
    |q_ref|) so that a label that hardly varies is not divided by ~0."""
    ref = np.asarray(ref, float)
    with np.errstate(invalid="ignore"):
        span = np.nanmax(ref, axis=1) - np.nanmin(ref, axis=1)
    return np.maximum(np.nan_to_num(span, nan=0.0), RANGE_FLOOR * big)


def summarize_errors(rows: Sequence[Mapping], dim: str, measure: str = "relative_error") -> dict:
    """{quantity: {run value: max error over labels, modes, strains}} of ``measure``
    (``relative_error``: to the label's magnitude; ``range_error``: to its range)."""
    out: dict = {}
    for r in rows:
        e = r.get(measure, np.nan)
        if not np.isfinite(e):
            continue
        q = out.setdefault(r["quantity"], {})
        q[r[dim]] = max(q.get(r[dim], 0.0), e)
    return out


def observed_rates(summary: Mapping, h_of=lambda v: 1.0 / v) -> dict:
    """{quantity: least-squares slope of log(max error) vs log h} (``fit_order``)."""
    out = {}
    for q, errs in summary.items():
        vals = sorted(errs)
        out[q] = float(fit_order(np.array([h_of(v) for v in vals]), np.array([errs[v] for v in vals])))
    return out


def combo_costs(bench_root: PathLike, run: str) -> dict:
    """{combo: {"wall_s", "cpu_s", "max_rss_mb"}}: the summed wall and CPU seconds of a
    combination's jobs and the largest resident set of any of them, from the Snakemake
    benchmark files (CPU is the fair work figure on a shared machine: wall times of jobs that
    ran under other jobs' load are inflated, their CPU time is not)."""
    root = Path(bench_root) / run
    out: dict = {}
    if not root.exists():
        return out
    for p in sorted(root.glob("*/**/*.tsv")):
        combo = p.relative_to(root).parts[0]
        rows = list(csv.DictReader(io.StringIO(p.read_text()), delimiter="\t"))
        if not rows:
            continue
        last = rows[-1]
        c = out.setdefault(combo, {"wall_s": 0.0, "cpu_s": 0.0, "max_rss_mb": 0.0})
        c["wall_s"] += float(last["s"])
        c["cpu_s"] += _float(last.get("cpu_time"))
        c["max_rss_mb"] = max(c["max_rss_mb"], _float(last.get("max_rss")))
    return out


def _float(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):   # "-" where psutil could not read the figure
        return 0.0


def combo_wall_times(bench_root: PathLike, run: str) -> dict:
    """{combo: summed wall seconds of its jobs} from the Snakemake benchmark files."""
    return {k: v["wall_s"] for k, v in combo_costs(bench_root, run).items()}


def summarize_by_mode(rows: Sequence[Mapping], dim: str, measure: str = "relative_error") -> dict:
    """{quantity: {mode: {run value: {"max": .., "median": ..}}}} over labels and strains."""
    acc: dict = {}
    for r in rows:
        e = r.get(measure, np.nan)
        if np.isfinite(e):
            acc.setdefault(r["quantity"], {}).setdefault(r["mode"], {}).setdefault(r[dim], []).append(e)
    return {q: {m: {v: {"max": float(np.max(e)), "median": float(np.median(e))} for v, e in sorted(runs.items())}
                for m, runs in modes.items()} for q, modes in acc.items()}


def reference_error(summary: Mapping, reference: float, order: float = REFERENCE_ORDER) -> dict:
    """{quantity: estimated error of the reference run itself}: the difference of the next
    finer-than-all-others run N_2 to the reference N_1 times the Richardson factor
    r / (1 - r), r = (N_2 / N_1)^order, i.e. what is left of a power-law error of that
    order at N_1 (``order`` = 1, the observed order of the median force and resistance
    errors, is the conservative choice: a higher order gives a smaller factor)."""
    out = {}
    for q, errs in summary.items():
        coarser = [v for v in errs if v < reference]
        if not coarser:
            out[q] = None
            continue
        n2 = max(coarser)
        r = (n2 / reference) ** order
        out[q] = float(errs[n2] * r / (1.0 - r))
    return out


def _combo_value(combo: str, dim: str) -> Optional[float]:
    key = f"{dim}-"
    for part in combo.split("__"):
        if part.startswith(key):
            return float(part[len(key):])
    return None


def _md_table(summary, rates, times, dim, reference, default, unit, cpu=None, rss=None) -> list[str]:
    vals = sorted({v for e in summary.values() for v in e} | {reference})
    head = f"| quantity | " + " | ".join(f"{dim} = {v:g}{unit}" for v in vals) + " | observed rate |"
    lines = [head, "|" + "---|" * (len(vals) + 2)]
    for q, errs in summary.items():
        cells = [("(reference)" if v == reference else (f"**{100 * errs[v]:.3g} %**" if v == default else
                                                         f"{100 * errs[v]:.3g} %")) if (v in errs or v == reference)
                 else "n/a" for v in vals]
        r = rates.get(q, float("nan"))
        lines.append(f"| {QUANTITIES[q]} | " + " | ".join(cells) + f" | {r:.2f} |" if np.isfinite(r) else
                     f"| {QUANTITIES[q]} | " + " | ".join(cells) + " | none |")
    lines.append("| wall time (sum of jobs) | " + " | ".join(
        f"{times[v]:.0f} s" if v in times else "n/a" for v in vals) + " | |")
    if cpu:
        lines.append("| CPU time (sum of jobs) | " + " | ".join(
            f"{cpu[v]:.0f} s" if cpu.get(v) else "n/a" for v in vals) + " | |")
    if rss:
        lines.append("| peak RSS (largest job) | " + " | ".join(
            f"{rss[v]:.0f} MB" if rss.get(v) else "n/a" for v in vals) + " | |")
    return lines


def convergence_report(mesh, penalty, default: Mapping) -> str:
    """Markdown of the two studies (``mesh``/``penalty``: dicts with summary, rates, times,
    reference, dim)."""
    out = ["# Table convergence (rve.studies.table_convergence)", ""]
    for title, st, unit in (("Mesh (elements per fibril, relative to the finest)", mesh, ""),
                            ("Contact penalty P* (N/mm², relative to the stiffest)", penalty, "")):
        if st is None:
            continue
        out += [f"## {title}", ""]
        out += _md_table(st["summary"], st["rates"], st["times"], st["dim"], st["reference"],
                         default.get(st["dim"]), unit, st.get("cpu"), st.get("rss"))
        dv = default.get(st["dim"])
        if st.get("by_mode"):
            runs = sorted({v for q in st["by_mode"].values() for m in q.values() for v in m})
            out += ["", f"Per mode, max / median over labels and strains ({st['dim']} = "
                    + ", ".join(f"{v:g}" for v in runs) + "):", "",
                    "| quantity | mode | " + " | ".join(f"{v:g}" for v in runs) + " |",
                    "|" + "---|" * (len(runs) + 2)]
            for q, modes in st["by_mode"].items():
                for m, e in modes.items():
                    out.append(f"| {QUANTITIES[q]} | {m} | " + " | ".join(
                        (f"{100 * e[v]['max']:.3g} / {100 * e[v]['median']:.3g} %" if v in e else "n/a")
                        for v in runs) + " |")
        if st.get("summary_range"):
            out += ["", "The same runs on the range measure (max over labels, modes and strains of |q - q_ref| / "
                    f"max(range of q_ref over the strain path, {RANGE_FLOOR:g} x the quantity's scale)) beside "
                    "the magnitude measure above:", "",
                    "| quantity | " + " | ".join(f"{v:g}" for v in sorted({v for e in st['summary_range'].values()
                                                                            for v in e})) + " |",
                    "|" + "---|" * (1 + len({v for e in st['summary_range'].values() for v in e}))]
            vals = sorted({v for e in st["summary_range"].values() for v in e})
            for q, errs in st["summary_range"].items():
                mag = st["summary"].get(q, {})
                out.append(f"| {QUANTITIES[q]} | " + " | ".join(
                    (f"{100 * errs[v]:.3g} % (magnitude {100 * mag[v]:.3g} %)" if v in errs and v in mag else "n/a")
                    for v in vals) + " |")
        if st.get("reference_error"):
            out += ["", f"Estimated error of the reference run itself (Richardson, order {REFERENCE_ORDER:g}, "
                    "from the next-finest run) and the stated error of the default run (difference to the "
                    "reference + the reference's own error):", ""]
            for q, er in st["reference_error"].items():
                e = st["summary"][q].get(dv)
                if er is not None and e is not None:
                    out.append(f"* {QUANTITIES[q]}: reference {100 * er:.3g} %, default {100 * e:.3g} % "
                               f"-> stated {100 * (e + er):.3g} %")
        if st.get("overlap"):
            out += ["", "max overlap / R after relaxation: " + ", ".join(
                f"{st['dim']} = {k:g}: {v:.3g}" for k, v in sorted(st["overlap"].items()))]
        out.append("")
    return "\n".join(out) + "\n"


def _plot(path, mesh, penalty, default):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels = [p for p in (mesh, penalty) if p is not None]
    fig = Figure(figsize=(5.2 * len(panels) + 0.4, 4.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, st in zip(axes, panels):
        dim = st["dim"]
        for k, (q, errs) in enumerate(st["summary"].items()):
            vals = sorted(errs)
            if dim == "mesh_elements":
                cpu = st.get("cpu") or {}
                x = [cpu.get(v) or st["times"].get(v, np.nan) for v in vals]
                ax.set_xlabel("work: summed job CPU time of the run [s]" if cpu else
                              "work: summed job wall time of the run [s]")
                ax.set_xscale("log")
            else:
                x = vals
                ax.set_xscale("log")
                ax.set_xlabel("contact penalty P* [N/mm²]")
            y = [max(errs[v], 1e-12) for v in vals]
            ax.plot(x, y, marker="o", color=f"C{k}", label=QUANTITIES[q])
            for xv, yv, v in zip(x, y, vals):
                if v == default.get(dim):
                    ax.plot([xv], [yv], marker="*", ms=13, color=f"C{k}", mec="k")
            if dim == "mesh_elements":
                for xv, yv, v in zip(x, y, vals):
                    if k == 0:
                        ax.annotate(f"N={v:g}", (xv, yv), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.set_yscale("log")
        ax.set_ylabel("max relative difference to the reference run")
        ax.grid(alpha=0.3, which="both")
        ref = st["reference"]
        ax.set_title(("work-precision: mesh (reference N = %g)" if dim == "mesh_elements" else
                      "penalty (reference P* = %g N/mm²)") % ref, fontsize=10)
        ax.legend(fontsize=7)
    fig.suptitle("RVE table convergence (star: the default run)", fontsize=10)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=120)
    return path


def _overlaps(states_root: PathLike, run: str, dim: str) -> dict:
    """{value: max overlap / R of the relaxed state} from the relaxed states' solver attrs."""
    import xarray as xr

    out = {}
    for p in sorted(Path(states_root, run).glob("*/states/relaxed.nc")):
        v = _combo_value(p.parts[-3], dim)
        with xr.open_dataset(p) as ds:
            s = json.loads(ds.attrs.get("solver", "{}"))
        ov = (s.get("relax") or {}).get("max_overlap_over_R")
        if v is not None and ov is not None:
            out[v] = float(ov)
    return out


def _study(ds, dim, bench_root, run, states_root):
    if ds is None:
        return None, []
    vals = [float(v) for v in ds[dim].values]
    reference = max(vals)
    rows = relative_errors(ds, reference, dim)
    summary = summarize_errors(rows, dim)
    h_of = (lambda v: 1.0 / v)
    rates = observed_rates(summary, h_of)
    times, cpu, rss = {}, {}, {}
    for combo, c in combo_costs(bench_root, run).items():
        v = _combo_value(combo, dim)
        if v is not None:
            times[v], cpu[v], rss[v] = c["wall_s"], c["cpu_s"], c["max_rss_mb"]
    st = {"dim": dim, "reference": reference, "summary": summary, "rates": rates, "times": times, "cpu": cpu,
          "summary_range": summarize_errors(rows, dim, "range_error"),
          "rss": rss, "by_mode": summarize_by_mode(rows, dim),
          # the finest mesh's own error (Richardson, order REFERENCE_ORDER); the penalty's limit
          # P* -> inf is not extrapolated (rate 0.2-0.4: docs/table_accuracy.md)
          "reference_error": reference_error(summary, reference) if dim == "mesh_elements" else {}}
    if dim == "mesh_elements":
        st["reference_error_by_mode"] = {
            q: {m: reference_error({q: {v: e["max"] for v, e in runs_.items()}}, reference)[q]
                for m, runs_ in modes.items()} for q, modes in st["by_mode"].items()}
    if dim == "contact_penalty":
        st["overlap"] = _overlaps(states_root, run, dim)
    return st, rows


def table_convergence_job(mesh_table, penalty_table, runs: Mapping[str, str], outputs: Mapping[str, PathLike],
                          log_path: Optional[PathLike], default: Mapping[str, float], bench_root: PathLike =
                          "results/benchmarks/rve", states_root: PathLike = "results/rve") -> dict:
    """The study's report (module docstring). ``mesh_table``/``penalty_table``: opened
    tables (or None), swept over ``mesh_elements`` / ``contact_penalty``; ``runs``: their
    run names (``mesh``, ``penalty``); ``default``: the default run's values
    ({"mesh_elements": 12, "contact_penalty": 50}); ``outputs``: csv, md, png, json."""
    with logging_to(log_path):
        mesh, rows_m = _study(mesh_table, "mesh_elements", bench_root, runs.get("mesh", ""), states_root)
        pen, rows_p = _study(penalty_table, "contact_penalty", bench_root, runs.get("penalty", ""), states_root)
        fields = ["study", "quantity", "label", "mode", "strain", "run_value", "value", "reference", "relative_error",
                  "range_error"]
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=fields)
        w.writeheader()
        for study, dim, rows in (("mesh", "mesh_elements", rows_m), ("penalty", "contact_penalty", rows_p)):
            for r in rows:
                w.writerow({"study": study, "run_value": r[dim], **{k: r[k] for k in fields if k in r}})
        atomic_write_text(outputs["csv"], buf.getvalue())
        text = convergence_report(mesh, pen, default)
        atomic_write_text(outputs["md"], text)
        _plot(outputs["png"], mesh, pen, default)
        acc: dict = {"targets": TARGETS, "negligible_fraction": NEGLIGIBLE, "default": dict(default)}
        for name, st in (("mesh", mesh), ("penalty", pen)):
            if st is None:
                continue
            dv = default.get(st["dim"])
            errs = {q: e.get(dv) for q, e in st["summary"].items()}
            ref_err = st.get("reference_error") or {}
            stated = {q: (None if e is None else e + (ref_err.get(q) or 0.0)) for q, e in errs.items()}
            cpu = st.get("cpu") or {}
            acc[name] = {"reference": st["reference"], "estimated_relative_error": errs,
                         "range_error": {q: e.get(dv) for q, e in (st.get("summary_range") or {}).items()},
                         "reference_error": ref_err, "stated_relative_error": stated,
                         "reference_error_by_mode": st.get("reference_error_by_mode") or {},
                         "by_mode": {q: {m: e.get(dv) for m, e in modes.items()} for q, modes in st["by_mode"].items()},
                         "observed_rate": st["rates"],
                         "runs": {f"{v:g}": {"max_relative_error": {q: st["summary"][q].get(v) for q in st["summary"]},
                                            "wall_s": st["times"].get(v), "cpu_s": cpu.get(v),
                                            "max_rss_mb": (st.get("rss") or {}).get(v)}
                                  for v in sorted({v for e in st["summary"].values() for v in e} | {st["reference"]})},
                         "meets_targets": {q: (e is not None and e <= TARGETS.get(q, np.inf)) for q, e in stated.items()},
                         "cpu_time_ratio_default_to_reference": (cpu[dv] / cpu[st["reference"]]
                                                                 if cpu.get(dv) and cpu.get(st["reference"]) else None),
                         "wall_time_ratio_default_to_reference": (st["times"].get(dv, np.nan)
                                                                  / st["times"].get(st["reference"], np.nan)
                                                                  if st["times"].get(st["reference"]) else None)}
        from ..io.atomic import atomic_write_json

        atomic_write_json(outputs["json"], json.loads(json.dumps(acc, default=float)))
        log.info("table convergence:\n%s", text)
    return acc
