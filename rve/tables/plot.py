"""Figures of a lookup table (thesis Figs. 7.4.3-7.4.4 style): ``plot_table``.

Input: a table Dataset and a path prefix; output: four PNG files written atomically with
matplotlib's Agg canvas (no pyplot state): reaction forces, probe resistances with the
network R_y and R_c, Joule temperature rises, each against strain, and the main quantities
of every combination of the swept parameters side by side (docs/lookup_tables.md).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Optional, Union

import numpy as np
import xarray as xr

from ..io.atomic import atomic_path
from .schema import lead_dims

__all__ = ["plot_table"]

PathLike = Union[str, os.PathLike]


def _select_first(ds: xr.Dataset, select: Optional[Mapping]) -> tuple[xr.Dataset, str]:
    extra = [d for d in lead_dims(ds) if d not in ("mode", "strain")]
    select = dict(select or {})
    for d in extra:
        select.setdefault(d, ds[d].values[0])
    note = ", ".join(f"{d} = {select[d]}" for d in extra)
    return (ds.sel({d: select[d] for d in extra}) if extra else ds), note


def _figure(nrows: int, ncols: int, w: float = 3.2, h: float = 2.6):
    """A figure of ``nrows`` x ``ncols`` panels on an Agg canvas, fixed margins."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w * ncols, h * nrows + 0.5))
    FigureCanvasAgg(fig)
    axes = np.atleast_2d(fig.subplots(nrows, ncols, squeeze=False))
    # fixed margins (constrained layout costs seconds on many panels)
    fig.subplots_adjust(left=0.75 / (w * ncols), right=1 - 0.15 / (w * ncols),
                        bottom=0.5 / (h * nrows + 0.5), top=1 - 0.75 / (h * nrows + 0.5),
                        wspace=0.45, hspace=0.55)
    return fig, axes


def _label(ax, title: str, ylabel: str, legend: Optional[int] = None) -> None:
    """The common dress of every panel: title, axis labels against strain, grid, legend."""
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("strain [1]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=legend)


def _finish(fig, title: str, note: str, path: PathLike) -> Path:
    """Title the figure (with the fixed swept values) and write it atomically."""
    fig.suptitle(title + (f" ({note})" if note else ""))
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return path


def plot_table(ds: xr.Dataset, out_png_prefix: PathLike, select: Optional[Mapping] = None) -> list[Path]:
    """Figures in the manner of thesis Figs. 7.4.3-7.4.4, written atomically (Agg):

    * ``<prefix>_reaction_force.png``: reaction force components vs strain, one panel
      per mode and side;
    * ``<prefix>_probe_resistance.png``: probe resistance vs strain, one panel per
      probe, one line per mode, plus a panel of the network R_y and R_c;
    * ``<prefix>_temperature_rise.png``: max (solid) and mean (dashed) Joule
      temperature rise vs strain per probe;
    * ``<prefix>_by_parameter.png``: one row per mode, one line per combination of the swept
      parameters (all of them, not ``select``): the face force along the mode's loading,
      R_c, and the friction dissipation (a frictional table) or the first probe's Joule rise.

    Swept parameters are fixed at ``select`` (default: their first values) in the first three.
    Returns the paths.
    """
    prefix = str(out_png_prefix)
    sub, note = _select_first(ds, select)
    modes = list(sub["mode"].values)
    sides = list(sub["side"].values)
    probes = list(sub["probe"].values)
    strain = sub["strain"].values
    paths = []
    styles = {"uniaxial": "-", "shear": "--", "uniaxial_y": "-.", "trellis": ":"}
    marks = {"x": "o", "y": "s", "z": "^"}

    # reaction forces
    fig, axes = _figure(len(modes), len(sides))
    for r, m in enumerate(modes):
        for c, side in enumerate(sides):
            ax = axes[r, c]
            for comp in sub["component"].values:
                y = sub["reaction_force"].sel(mode=m, side=side, component=comp).values
                ax.plot(strain, y, marker=marks.get(comp, "."), ms=3, label=str(comp))
            _label(ax, f"{m}, side {side}", "reaction force [N]")
    axes[0, 0].legend(fontsize=8)
    paths.append(_finish(fig, "Reaction forces vs strain", note, prefix + "_reaction_force.png"))

    # probe resistances (+ network)
    fig, axes = _figure(1, len(probes) + 1)
    for c, p in enumerate(probes):
        ax = axes[0, c]
        for m in modes:
            ax.plot(strain, sub["probe_resistance"].sel(mode=m, probe=p).values,
                    styles.get(m, ":"), marker="o", ms=3, label=m)
        _label(ax, f"{p}", "resistance [ohm]", legend=8)
    ax = axes[0, -1]
    for m in modes:
        ax.plot(strain, sub["yarn_resistance"].sel(mode=m).values, styles.get(m, ":"),
                marker="o", ms=3, label=f"R_y {m}")
        ax.plot(strain, sub["contact_resistance"].sel(mode=m).values, styles.get(m, ":"),
                marker="s", ms=3, label=f"R_c {m}")
    _label(ax, "network model", "resistance [ohm]", legend=7)
    paths.append(_finish(fig, "Probe resistance vs strain", note, prefix + "_probe_resistance.png"))

    # temperature rises
    fig, axes = _figure(1, len(probes))
    for c, p in enumerate(probes):
        ax = axes[0, c]
        for k, m in enumerate(modes):
            color = f"C{k}"
            ax.plot(strain, sub["temperature_rise_max"].sel(mode=m, probe=p).values, "-",
                    color=color, marker="o", ms=3, label=f"max, {m}")
            ax.plot(strain, sub["temperature_rise_mean"].sel(mode=m, probe=p).values, "--",
                    color=color, label=f"mean, {m}")
        _label(ax, f"{p}", "temperature rise [K]", legend=7)
    paths.append(_finish(fig, "Joule temperature rise vs strain", note, prefix + "_temperature_rise.png"))
    paths.append(_plot_by_parameter(ds, prefix + "_by_parameter.png"))
    return paths


def _loading(force: xr.DataArray) -> tuple[str, str]:
    """The side and component of a mode's face force (side, component, strain, ...) with the
    largest range over the strain path: the one that carries the mode's loading."""
    extra = [d for d in force.dims if d not in ("side", "component", "strain")]
    f = force.isel({d: 0 for d in extra}) if extra else force
    spread = (f.max("strain") - f.min("strain")).fillna(-1.0)
    i, j = np.unravel_index(int(np.argmax(spread.transpose("side", "component").values)), spread.shape)
    return str(spread["side"].values[i]), str(spread["component"].values[j])


def _combinations(ds: xr.Dataset) -> list[tuple[dict, str]]:
    """Every combination of the swept parameters as ``(selection, label)``."""
    import itertools

    extra = [d for d in lead_dims(ds) if d not in ("mode", "strain")]
    if not extra:
        return [({}, "")]
    out = []
    for point in itertools.product(*(list(ds[d].values) for d in extra)):
        sel = dict(zip(extra, point))
        out.append((sel, ", ".join(f"{d} = {v:g}" if isinstance(v, (float, np.floating)) else f"{d} = {v}"
                                   for d, v in sel.items())))
    return out


def _plot_by_parameter(ds: xr.Dataset, path: PathLike) -> Path:
    modes, strain = list(ds["mode"].values), ds["strain"].values
    third = "friction_dissipated_energy" if "friction_dissipated_energy" in ds else "temperature_rise_max"
    combos = _combinations(ds)
    fig, axes = _figure(len(modes), 3)
    for r, m in enumerate(modes):
        side, comp = _loading(ds["reaction_force"].sel(mode=m))
        for k, (sel, label) in enumerate(combos):
            sub = ds.sel(sel).sel(mode=m)
            kw = dict(color=f"C{k % 10}", marker="o", ms=3, label=label or None)
            axes[r, 0].plot(strain, sub["reaction_force"].sel(side=side, component=comp).values, **kw)
            axes[r, 1].plot(strain, sub["contact_resistance"].values, **kw)
            y = sub[third] if third != "temperature_rise_max" else sub[third].isel(probe=0)
            axes[r, 2].plot(strain, y.values, **kw)
        _label(axes[r, 0], f"{m}: face {side}, component {comp}", "force [N]")
        _label(axes[r, 1], f"{m}: network R_c", "resistance [ohm]")
        _label(axes[r, 2], f"{m}: " + ("friction dissipated" if third != "temperature_rise_max"
                                       else f"Joule rise, {ds['probe'].values[0]}"),
               "energy [N mm]" if third != "temperature_rise_max" else "temperature rise [K]")
    if len(combos) > 1:
        axes[0, 0].legend(fontsize=7)
    return _finish(fig, "The swept parameters side by side" if len(combos) > 1 else
                   "Loading force, contact resistance and " + ("friction" if third != "temperature_rise_max" else
                                                               "Joule rise"), "", path)
