"""A human-readable text summary of a lookup table (``summarize``; ``rve table summary``).

Input: a table Dataset; output: text with the dimensions, the strain range per mode, the
swept values, the probe resistance ranges, the network resistances, the worst equilibrium
residual and the reaction forces at the smallest strain (docs/lookup_tables.md). Entries
whose state is not an equilibrium (``converged`` = 0, kept by ``checks.keep_unconverged``)
are listed first, before anything else (docs/fault_tolerance.md).
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from .schema import lead_dims

__all__ = ["summarize", "unconverged_entries"]


def unconverged_entries(ds: xr.Dataset) -> list[str]:
    """``["uniaxial strain 0.05 (|F| = 3.1e-02 N)", ...]``: the entries with converged == 0."""
    if "converged" not in ds:
        return []
    conv = ds["converged"]
    bad = (conv == 0).values
    if not bad.any():
        return []
    dims = conv.dims
    resid = ds["equilibrium_residual"].transpose(*dims).values if "equilibrium_residual" in ds else None
    out = []
    for idx in zip(*np.nonzero(bad)):
        where = " ".join(f"{d} {ds[d].values[i]:g}" if ds[d].dtype.kind in "fiu" else f"{d} {ds[d].values[i]}"
                         for d, i in zip(dims, idx) if d in ds.coords)
        r = f" (|F| = {resid[idx]:.3g} N)" if resid is not None and np.isfinite(resid[idx]) else ""
        out.append(where.replace("mode ", "", 1) + r)
    return out


def _rng(a) -> str:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return "n/a"
    return f"{a.min():.6g} .. {a.max():.6g}"


def summarize(ds: xr.Dataset) -> str:
    """Human-readable summary: dims, strain range per mode, swept values, per-probe
    resistance range, network resistances and the reaction forces at zero strain."""
    bad = unconverged_entries(ds)
    lines = [f"NOT CONVERGED: {len(bad)} table entr{'y' if len(bad) == 1 else 'ies'} whose state is not a static equilibrium "
             "(kept by checks.keep_unconverged; converged = 0):"] + [f"  {b}" for b in bad] if bad else []
    lines.append(f"rve lookup table: {ds.attrs.get('title', '(untitled)')}")
    lines.append(f"  created {ds.attrs.get('date_created', '?')} by rve {ds.attrs.get('rve_version', '?')}"
                 f" ({ds.attrs.get('rve_table_format', '?')})")
    lines.append("  dims: " + ", ".join(f"{d}={n}" for d, n in ds.sizes.items()))
    for m in ds["mode"].values:
        one = ds.sel(mode=m)
        present = np.isfinite(one["probe_resistance"].transpose("strain", ...).values
                              .reshape(one.sizes["strain"], -1)).any(axis=1) | \
            np.isfinite(one["reaction_force"].transpose("strain", ...).values
                        .reshape(one.sizes["strain"], -1)).any(axis=1)
        s = one["strain"].values[present]
        lines.append(f"  mode {m}: strain {_rng(s)} ({s.size} levels)")
    for d in lead_dims(ds):
        if d in ("mode", "strain"):
            continue
        vals = ", ".join(str(v) for v in ds[d].values)
        lines.append(f"  swept {d} [{ds[d].attrs.get('units', '')}]: {vals}")
    lines.append("  probe resistance [ohm] (min .. max over strains and sweeps):")
    for p in ds["probe"].values:
        per_mode = "; ".join(f"{m} {_rng(ds['probe_resistance'].sel(probe=p, mode=m).values)}"
                             for m in ds["mode"].values)
        term = str(ds["probe_terminals"].sel(probe=p).values) if "probe_terminals" in ds.coords else ""
        lines.append(f"    {p}{f' ({term})' if term else ''}: {per_mode}")
    for name, sym in (("yarn_resistance", "R_y"), ("contact_resistance", "R_c")):
        if name in ds:
            lines.append(f"  network {sym} [ohm]: " + "; ".join(
                f"{m} {_rng(ds[name].sel(mode=m).values)}" for m in ds["mode"].values))
    if "network_fit_residual" in ds:
        lines.append(f"  network fit residual (rms log): max {_rng(ds['network_fit_residual'].values).split(' .. ')[-1]}")
    stated = [(v, ds[v].attrs) for v in ds.data_vars if "estimated_relative_error" in ds[v].attrs]
    if stated:
        lines.append("  estimated relative error (convergence study: mesh + penalty):")
        for v, a in stated:
            lines.append(f"    {v}: {100 * a['estimated_relative_error']:.3g} % (mesh "
                         f"{100 * a.get('estimated_relative_error_mesh', float('nan')):.3g} %, penalty "
                         f"{100 * a.get('estimated_relative_error_penalty', float('nan')):.3g} %)")
    if "equilibrium_residual" in ds and np.isfinite(ds["equilibrium_residual"].values).any():
        r = ds["equilibrium_residual"].values
        lines.append(f"  equilibrium residual [N]: max {np.nanmax(r):.3g} over {int(np.isfinite(r).sum())} table entries")
    if "friction_dissipated_energy" in ds:
        lines.append("  friction dissipated along the path [N mm]: " + "; ".join(
            f"{m} {_rng(ds['friction_dissipated_energy'].sel(mode=m).values)}" for m in ds["mode"].values))
    if "cycle_work" in ds:   # loading-unloading cycles (rve.tables.cycles)
        lines.append("  loading-unloading cycles [N mm] (work of the clamps = potential change + friction "
                     "dissipation):")
        for m in ds["cycle_mode"].values:
            c = ds.sel(cycle_mode=m)
            for name, label in (("cycle_work", "work"), ("cycle_potential_change", "potential change"),
                                ("cycle_dissipated_energy", "dissipated")):
                vals = " ".join(f"{v:.5g}" for v in np.asarray(c[name].values).ravel())
                lines.append(f"    {m} {label}: {vals}")
    # reactions at the smallest |strain|
    k = int(np.argmin(np.abs(ds["strain"].values)))
    s0 = float(ds["strain"].values[k])
    rf = ds["reaction_force"].isel(strain=k)
    extra = [d for d in rf.dims if d not in ("mode", "side", "component")]
    if extra:
        rf = rf.isel({d: 0 for d in extra})
        note = " (" + ", ".join(f"{d}={ds[d].values[0]}" for d in extra) + ")"
    else:
        note = ""
    lines.append(f"  reaction force [N] at strain {s0:g}{note}:")
    lines.append("    " + f"{'mode':10s} {'side':6s}" + "".join(f"{c:>13s}" for c in ds["component"].values))
    for m in ds["mode"].values:
        for side in ds["side"].values:
            vals = rf.sel(mode=m, side=side).values
            lines.append("    " + f"{m:10s} {side:6s}" + "".join(f"{v:13.5g}" for v in vals))
    return "\n".join(lines) + "\n"
