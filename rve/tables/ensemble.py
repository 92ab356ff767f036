"""Ensembles over perturbed packings (thesis §7.5; docs/table_accuracy.md "Ensembles").

A run whose sweep is over ``realization`` (``sweep: {realization: [1, 2, ...]}``: the
alias of ``packing.seed`` in ``rve.homogenisation.sweeps``; with a
``packing.perturbation`` > 0 every seed is another random packing, ``rve.fabrics.perturb``)
is an ordinary Snakemake sweep: one chain of jobs per realisation. Its gathered table has
a ``realization`` dimension (CF: ``standard_name: realization``, the seeds as values) and
``add_ensemble_statistics`` adds, for every numeric table quantity ``v`` that has it:

==================  =====================================================================
``v_mean``          mean over the realisations (``cell_methods: "realization: mean"``)
``v_std``           sample standard deviation, ddof = 1 (``"realization: standard_deviation"``)
``v_q05``, ``v_q95`` the 5 % and 95 % quantiles (linear interpolation between order
                    statistics, ``numpy.nanquantile``): the 90 % band
==================  =====================================================================

with the dimensions of ``v`` less ``realization``, the units of ``v`` (all four), and the
global attribute ``ensemble`` (JSON: realisations, band, quantile method, the packing
settings). NaN entries (a realisation that has no value there) are left out of the
statistics; an entry with no finite value is NaN. The table stays CF-clean: the new
variables are numeric, named, with units and long_name (``rve.tables.io``).

``ensemble_wiggle_report(ds)``: the 90 % band of the probe resistances against the
step-to-step wiggle of a single realisation (the deviation of R at a strain from the
mean of its two neighbours, relative), per mode and probe: is a wiggle of one packing
larger or smaller than the spread over packings? ``plot_ensemble``: every realisation
(thin), the mean and the shaded 90 % band of the probe resistances, the clamp reactions
and the network R_y, R_c against strain.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Mapping, Optional, Union

import numpy as np
import xarray as xr

from ..io.atomic import atomic_path

__all__ = ["REALIZATION", "BAND", "STATISTICS", "add_ensemble_statistics", "ensemble_wiggle", "ensemble_wiggle_report",
           "plot_ensemble", "ensemble_report_job"]

PathLike = Union[str, os.PathLike]

#: the ensemble dimension (CF standard name ``realization``)
REALIZATION = "realization"
#: the central band of the statistics
BAND = 0.90
#: suffix -> (long_name prefix, cell_methods or None)
STATISTICS = {
    "mean": ("mean over the packing realizations of", "realization: mean"),
    "std": ("sample standard deviation (ddof = 1) over the packing realizations of", "realization: standard_deviation"),
    "q05": ("5 % quantile over the packing realizations of", None),
    "q95": ("95 % quantile over the packing realizations of", None),
}

_REALIZATION_ATTRS = {"standard_name": "realization", "units": "1",
                      "long_name": "realization of the fibril packing (packing.seed of rve.fabrics.perturb)"}


def add_ensemble_statistics(ds: xr.Dataset, dim: str = REALIZATION, packing: Optional[Mapping] = None) -> xr.Dataset:
    """``ds`` with the ensemble statistics of every numeric variable over ``dim`` (module
    docstring). Needs at least two realisations."""
    if dim not in ds.dims:
        raise ValueError(f"add_ensemble_statistics: the table has no {dim!r} dimension (dims {dict(ds.sizes)})")
    n = int(ds.sizes[dim])
    if n < 2:
        raise ValueError(f"add_ensemble_statistics: {n} realization(s); an ensemble needs at least 2")
    out = ds.copy()
    out[dim].attrs.update(_REALIZATION_ATTRS)
    lo, hi = 0.5 * (1 - BAND), 0.5 * (1 + BAND)
    made = []
    for name, var in ds.data_vars.items():
        if dim not in var.dims or var.dtype.kind not in "fiu" or any(name.endswith("_" + s) for s in STATISTICS):
            continue
        ax = var.dims.index(dim)
        vals = np.asarray(var.values, float)
        finite = np.isfinite(vals)
        count = finite.sum(axis=ax)
        with np.errstate(invalid="ignore", divide="ignore"):
            masked = np.where(finite, vals, np.nan)
            s = np.nansum(masked, axis=ax)
            mean = np.where(count > 0, s / np.maximum(count, 1), np.nan)
            dev = np.where(finite, masked - np.expand_dims(mean, ax), 0.0)
            std = np.where(count > 1, np.sqrt((dev ** 2).sum(axis=ax) / np.maximum(count - 1, 1)), np.nan)
        q = np.full((2,) + mean.shape, np.nan)
        if finite.any():
            any_finite = count > 0
            qq = np.nanquantile(np.where(np.expand_dims(any_finite, ax), masked, 0.0), [lo, hi], axis=ax)
            q = np.where(any_finite[None], qq, np.nan)
        dims = tuple(d for d in var.dims if d != dim)
        base = {k: v for k, v in var.attrs.items() if k in ("units", "units_metadata")}
        lname = var.attrs.get("long_name", name)
        for suffix, arr in (("mean", mean), ("std", std), ("q05", q[0]), ("q95", q[1])):
            prefix, cm = STATISTICS[suffix]
            attrs = dict(base, long_name=f"{prefix} {lname}")
            if cm:
                attrs["cell_methods"] = cm
            else:
                attrs["comment"] = (f"{int(round(100 * BAND))} % band over {n} realizations "
                                    "(numpy.nanquantile, linear interpolation)")
            out[f"{name}_{suffix}"] = (dims, arr, attrs)
        made.append(name)
    out.attrs["ensemble"] = json.dumps({"dimension": dim, "realizations": [v.item() if hasattr(v, "item") else v
                                                                          for v in ds[dim].values],
                                        "band": BAND, "quantiles": [lo, hi], "quantile_method": "linear",
                                        "statistics": list(STATISTICS), "variables": made,
                                        "packing": dict(packing or {})}, sort_keys=True)
    return out


def ensemble_wiggle(ds: xr.Dataset, var: str = "probe_resistance", dim: str = REALIZATION) -> xr.Dataset:
    """Per mode (and the label dims of ``var``): ``band`` = mean over strains of
    (q95 - q05) / mean, ``std`` = mean over strains of std / mean, and ``wiggle`` = the
    median over realisations of the median over interior strains of
    |R_i - (R_{i-1} + R_{i+1}) / 2| / R_i (all relative)."""
    v = ds[var]
    mean, q05, q95, std = (ds[f"{var}_{s}"] for s in ("mean", "q05", "q95", "std"))
    others = [d for d in v.dims if d not in (dim, "mode", "strain") and d not in ("probe", "side", "component")]
    sel = {d: 0 for d in others}
    v, mean, q05, q95, std = (a.isel({k: i for k, i in sel.items() if k in a.dims}) for a in (v, mean, q05, q95, std))
    band = ((q95 - q05) / mean).mean("strain")
    rstd = (std / mean).mean("strain")
    r = v.transpose(..., "strain")
    mid = r.isel(strain=slice(1, -1))
    nb = 0.5 * (r.isel(strain=slice(0, -2)).values + r.isel(strain=slice(2, None)).values)
    dev = np.abs(mid.values - nb) / np.abs(mid.values)
    wig = mid.copy(data=dev).median("strain").median(dim)
    return xr.Dataset({"band": band, "std": rstd, "wiggle": wig})


def ensemble_wiggle_report(ds: xr.Dataset, var: str = "probe_resistance", dim: str = REALIZATION) -> str:
    """Text: per mode and probe, the relative 90 % band and std over the realisations
    against the step-to-step wiggle of one realisation (``ensemble_wiggle``)."""
    w = ensemble_wiggle(ds, var, dim)
    n = int(ds.sizes[dim])
    lines = [f"ensemble of {n} realizations ({dim} = {', '.join(str(v) for v in ds[dim].values)}); "
             f"{var}: relative {int(round(100 * BAND))} % band and std (mean over strains) vs the step-to-step wiggle "
             "of one realization (median |R_i - (R_i-1 + R_i+1)/2| / R_i, median over realizations)",
             f"  {'mode':10s} {'probe':8s} {'band90 %':>9s} {'std %':>7s} {'wiggle %':>9s} {'band/wiggle':>12s}"]
    for m in w["mode"].values:
        for p in (w["probe"].values if "probe" in w.dims else [None]):
            sel = {"mode": m, **({"probe": p} if p is not None else {})}
            b, s, g = (float(w[k].sel(sel)) for k in ("band", "std", "wiggle"))
            lines.append(f"  {m:10s} {str(p):8s} {100 * b:9.3f} {100 * s:7.3f} {100 * g:9.3f} "
                         f"{(b / g if g > 0 else float('inf')):12.2f}")
    return "\n".join(lines) + "\n"


# ============================================================================ figures
def _figure(nrows: int, ncols: int, w: float = 3.4, h: float = 2.8):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w * ncols, h * nrows + 0.6))
    FigureCanvasAgg(fig)
    axes = np.atleast_2d(fig.subplots(nrows, ncols, squeeze=False))
    fig.subplots_adjust(left=0.8 / (w * ncols), right=1 - 0.15 / (w * ncols), bottom=0.5 / (h * nrows + 0.6),
                        top=1 - 0.8 / (h * nrows + 0.6), wspace=0.42, hspace=0.6)
    return fig, axes


def _band(ax, strain, ds, var, sel, color, label, dim=REALIZATION):
    lines = ds[var].sel(sel).transpose(dim, "strain").values
    for k, row in enumerate(lines):
        ax.plot(strain, row, color=color, lw=0.6, alpha=0.35, label=(f"{label}: realizations" if k == 0 else None))
    ax.fill_between(strain, ds[f"{var}_q05"].sel(sel).values, ds[f"{var}_q95"].sel(sel).values, color=color,
                    alpha=0.25, lw=0, label=f"{label}: {int(round(100 * BAND))} % band")
    ax.plot(strain, ds[f"{var}_mean"].sel(sel).values, color=color, lw=1.8, marker="o", ms=2.5,
            label=f"{label}: mean")


def _dress(ax, title, ylabel, legend=True):
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("strain [1]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=6)


def _save(fig, title, path) -> Path:
    fig.suptitle(title, fontsize=10)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return path


def plot_ensemble(ds: xr.Dataset, outputs: Mapping[str, PathLike], dim: str = REALIZATION) -> list[Path]:
    """The ensemble figures (``outputs``: ``probe_resistance``, ``reaction_force``,
    ``network``): every realisation thin, the mean and the shaded 90 % band, against strain,
    one colour per mode. Other swept dimensions are fixed at their first value."""
    extra = [d for d in ds.dims if d not in (dim, "mode", "strain", "probe", "side", "component", "terminal", "edge",
                                             "yarn")]
    sub = ds.isel({d: 0 for d in extra}) if extra else ds
    strain = sub["strain"].values
    modes = list(sub["mode"].values)
    n = int(sub.sizes[dim])
    note = f"{n} packing realizations" + (f"; {', '.join(f'{d} = {ds[d].values[0]}' for d in extra)}" if extra else "")
    paths = []
    probes = list(sub["probe"].values)
    fig, axes = _figure(1, len(probes))
    for c, p in enumerate(probes):
        for k, m in enumerate(modes):
            _band(axes[0, c], strain, sub, "probe_resistance", {"mode": m, "probe": p}, f"C{k}", m, dim)
        _dress(axes[0, c], str(p), "resistance [ohm]", legend=(c == 0))
    paths.append(_save(fig, f"Probe resistance vs strain, {note}", outputs["probe_resistance"]))

    picks = [("x+", "x"), ("x+", "y"), ("y+", "y"), ("x+", "z")]
    picks = [pk for pk in picks if pk[0] in sub["side"].values]
    fig, axes = _figure(1, len(picks))
    for c, (side, comp) in enumerate(picks):
        for k, m in enumerate(modes):
            _band(axes[0, c], strain, sub, "reaction_force", {"mode": m, "side": side, "component": comp}, f"C{k}", m,
                  dim)
        _dress(axes[0, c], f"side {side}, {comp} component", "reaction force [N]", legend=(c == 0))
    paths.append(_save(fig, f"Clamp reaction forces vs strain, {note}", outputs["reaction_force"]))

    fig, axes = _figure(1, 2)
    for c, (var, sym) in enumerate((("yarn_resistance", "R_y"), ("contact_resistance", "R_c"))):
        for k, m in enumerate(modes):
            _band(axes[0, c], strain, sub, var, {"mode": m}, f"C{k}", m, dim)
        _dress(axes[0, c], f"network {sym}", f"{sym} [ohm]", legend=(c == 0))
    paths.append(_save(fig, f"Network resistances vs strain, {note}", outputs["network"]))
    return paths


def ensemble_report_job(table: PathLike, outputs: Mapping[str, PathLike], log_path: Optional[PathLike]) -> str:
    """Body of rule ``rve_ensemble_report``: the figures of ``plot_ensemble`` and the
    text of ``ensemble_wiggle_report`` (``outputs["report"]``), atomically."""
    import logging

    from ..io.atomic import atomic_write_text
    from ..io.provenance import logging_to
    from .io import open_table

    with logging_to(log_path):
        ds = open_table(table)
        plot_ensemble(ds, outputs)
        text = ensemble_wiggle_report(ds)
        atomic_write_text(outputs["report"], text)
        logging.getLogger("rve.tables.ensemble").info("ensemble report of %s:\n%s", table, text)
    return text
