"""Table values between the stored strains (and numeric swept parameters): ``interpolate``.

docs/lookup_tables.md (§4 "Interpolation"): piecewise linear or monotone cubic (PCHIP) in
strain, per mode over the strains at which that mode has a state; numeric swept
parameters are interpolated the same way, string-valued ones selected. Stored points
return the stored values exactly; a point outside the table raises ValueError naming the
range. Input: a table Dataset (``rve.tables.build``/``io``); output: a Dataset with the
same variables.

``lookup`` is the pointwise form for macro points: N points (strain_i, p_i, ...) of one
mode give N values per variable along a new dimension ``point`` (not the N x N outer
product ``interpolate`` returns for arrays of strains and parameters), multilinear in
strain and the numeric swept parameters. It works the same on a table in memory and on one
opened lazily (``open_table(path, chunks=...)``): then only the variables asked for are
read, and dask computes the result chunk by chunk.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import xarray as xr

__all__ = ["interpolate", "lookup"]

#: dimensions of a table that are not swept parameters
_TABLE_DIMS = ("mode", "strain", "probe", "side", "component", "terminal", "edge", "yarn")


def _interp_axis(x: np.ndarray, y: np.ndarray, xq: np.ndarray, axis: int, method: str) -> np.ndarray:
    """Interpolate ``y`` (sampled at increasing ``x`` along ``axis``) to ``xq``; points of
    ``xq`` equal to a sample return that sample exactly. ``xq`` must lie in [x0, x_-1]."""
    y = np.moveaxis(np.asarray(y, dtype=float), axis, 0)
    n = len(x)
    out = np.empty((len(xq),) + y.shape[1:])
    exact = np.searchsorted(x, xq)
    is_exact = (exact < n) & (x[np.minimum(exact, n - 1)] == xq)
    if n == 1:
        out[:] = y[0]
    elif method == "linear" or n == 2:
        i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, n - 2)
        t = ((xq - x[i]) / (x[i + 1] - x[i])).reshape((-1,) + (1,) * (y.ndim - 1))
        with np.errstate(invalid="ignore"):  # 0 * inf at a stored point: overwritten below
            out[:] = (1.0 - t) * y[i] + t * y[i + 1]
    elif method == "cubic":
        from scipy.interpolate import PchipInterpolator

        # PCHIP needs finite samples: series with a NaN or inf (a quantity not recorded, an
        # open circuit's infinite resistance) are interpolated linearly instead
        y2 = y.reshape(n, -1)
        o2 = out.reshape(len(xq), -1)
        ok = np.isfinite(y2).all(axis=0)
        if ok.any():
            o2[:, ok] = PchipInterpolator(x, y2[:, ok], axis=0, extrapolate=False)(xq)
        if not ok.all():
            o2[:, ~ok] = _interp_axis(x, y2[:, ~ok], xq, 0, "linear")
    else:
        raise ValueError(f"method must be 'linear' or 'cubic', got {method!r}")
    out[is_exact] = y[exact[is_exact]]
    return np.moveaxis(out, 0, axis)


def _interp_dim(ds: xr.Dataset, dim: str, values, method: str, valid: Optional[np.ndarray] = None,
                context: str = "") -> xr.Dataset:
    """Interpolate every variable of ``ds`` having ``dim`` to ``values`` along it."""
    x_all = np.asarray(ds[dim].values, dtype=float)
    keep = np.ones(len(x_all), bool) if valid is None else np.asarray(valid, bool)
    x = x_all[keep]
    if x.size == 0:
        raise ValueError(f"no stored {dim} values{context}")
    scalar = np.ndim(values) == 0
    xq = np.atleast_1d(np.asarray(values, dtype=float))
    if not np.all(np.isfinite(xq)):
        raise ValueError(f"{dim} values must be finite, got {values!r}")
    lo, hi = float(x.min()), float(x.max())
    bad = xq[(xq < lo) | (xq > hi)]
    if bad.size:
        raise ValueError(f"{dim} {bad[0]:g} is outside the table range [{lo:g}, {hi:g}]{context}")
    out = xr.Dataset(attrs=ds.attrs)
    sub = ds.isel({dim: np.nonzero(keep)[0]})
    for name, var in sub.data_vars.items():
        if dim in var.dims:
            ax = var.dims.index(dim)
            vals = _interp_axis(x, var.values, xq, ax, method)
            out[name] = xr.Variable(var.dims, vals, attrs=var.attrs)
        else:
            out[name] = var.variable
    for name, c in sub.coords.items():
        if dim not in c.dims:
            out.coords[name] = c.variable
    out.coords[dim] = xr.Variable((dim,), xq, attrs=ds[dim].attrs)
    if scalar:
        out = out.isel({dim: 0})
    return out


def interpolate(ds: xr.Dataset, strain, mode: Optional[str] = None, method: str = "linear",
                **params) -> xr.Dataset:
    """Table values at arbitrary ``strain`` (a number or a sequence) for ``mode`` (None:
    every mode of the table, each checked against its own strain range).

    ``method``: ``"linear"`` (piecewise linear) or ``"cubic"`` (monotone piecewise cubic
    Hermite, PCHIP: no overshoot between samples). Only the strains at which a mode has
    a state are used. Stored strains return the stored values exactly. ``params`` select
    swept parameters: a string (or any value of a string-valued dimension) selects that
    entry; a number of a numeric dimension is interpolated with the same ``method``
    (exact at stored values). A strain or parameter outside the table raises ValueError
    naming the range. Returns a Dataset with the table's variables, ``strain`` (and each
    numeric ``params``) as a dimension, or a scalar coordinate if a scalar was given.
    """
    if method not in ("linear", "cubic"):
        raise ValueError(f"method must be 'linear' or 'cubic', got {method!r}")
    for name in params:
        if name not in ds.dims or name in ("mode", "strain", "probe", "side", "component", "terminal"):
            swept = [d for d in ds.dims if d not in ("mode", "strain", "probe", "side",
                                                     "component", "terminal")]
            raise ValueError(f"{name!r} is not a swept parameter of the table (swept: {swept})")
    sel = ds
    for name, value in params.items():
        if sel[name].dtype.kind in "OSU":
            values = list(sel[name].values)
            wanted = [value] if np.ndim(value) == 0 else list(value)
            missing = [v for v in wanted if v not in values]
            if missing:
                raise ValueError(f"{name} {missing[0]!r} is not in the table ({values})")
            sel = sel.sel({name: value})
        else:
            sel = _interp_dim(sel, name, value, method, context=f" of {name}")
    modes = list(sel["mode"].values)
    if mode is not None:
        if mode not in modes:
            raise ValueError(f"mode {mode!r} is not in the table (modes: {modes})")
        modes = [mode]
    parts = []
    state_vars = [v for v in sel.data_vars if "strain" in sel[v].dims]
    for m in modes:
        one = sel.sel(mode=m)
        # a strain level is a state of this mode if any variable has a value there
        present = np.zeros(one.sizes["strain"], bool)
        for v in state_vars:
            arr = one[v].transpose("strain", ...).values.reshape(one.sizes["strain"], -1)
            present |= np.isfinite(arr).any(axis=1)
        parts.append(_interp_dim(one, "strain", strain, method, valid=present,
                                 context=f" of mode {m!r}"))
    if mode is not None:
        out = parts[0]
    else:
        out = xr.concat(parts, dim="mode", data_vars="all", coords="minimal",
                        compat="override", join="override", combine_attrs="override")
        out["mode"].attrs = ds["mode"].attrs
    out.attrs = dict(ds.attrs)
    out.attrs["interpolation"] = f"{method} in strain" + (
        f" and {', '.join(params)}" if params else "")
    return out


def _mode_strains(ds: xr.Dataset, mode: str) -> np.ndarray:
    """Mask of the strain levels at which ``mode`` has a state: any of the per-state
    variables (no dimension besides mode, strain and the swept ones) is finite there.
    Those are the table's small variables, so a lazily opened table reads little here."""
    lead = {d for d in ds.dims if d not in _TABLE_DIMS[2:]}
    names = [v for v in ds.data_vars if "strain" in ds[v].dims and set(ds[v].dims) <= lead]
    present = np.zeros(ds.sizes["strain"], bool)
    for v in names:
        arr = np.asarray(ds[v].sel(mode=mode).transpose("strain", ...).values)
        present |= np.isfinite(arr.reshape(arr.shape[0], -1)).any(axis=1)
    return present


def lookup(ds: xr.Dataset, mode: str, strain, variables=None, **params) -> xr.Dataset:
    """The table at N macro points of ``mode``: ``strain`` and every numeric swept
    parameter in ``params`` are arrays of one length N (or scalars, broadcast), linear in
    each of them; a string-valued parameter is one value, selected. ``variables``: the
    names to look up (default: every variable with a strain dimension). A point outside the
    table raises ValueError naming the range. Returns the variables with the dimension
    ``point`` in place of strain and those parameters; on a lazily opened table, dask
    arrays (``.compute()`` reads the chunks).
    """
    modes = list(ds["mode"].values)
    if mode not in modes:
        raise ValueError(f"mode {mode!r} is not in the table (modes: {modes})")
    swept = [d for d in ds.dims if d not in _TABLE_DIMS]
    names = list(variables) if variables is not None else [v for v in ds.data_vars if "strain" in ds[v].dims]
    missing = [v for v in names if v not in ds.data_vars]
    if missing:
        raise ValueError(f"{missing[0]!r} is not a variable of the table")
    sel = ds[names].sel(mode=mode)
    points = {"strain": np.atleast_1d(np.asarray(strain, dtype=float))}
    for name, value in params.items():
        if name not in swept:
            raise ValueError(f"{name!r} is not a swept parameter of the table (swept: {swept})")
        if sel[name].dtype.kind in "OSU":
            if value not in list(sel[name].values):
                raise ValueError(f"{name} {value!r} is not in the table ({list(sel[name].values)})")
            sel = sel.sel({name: value})
        else:
            points[name] = np.atleast_1d(np.asarray(value, dtype=float))
    n = max(v.size for v in points.values())
    present = _mode_strains(ds, mode)
    sel = sel.isel(strain=np.nonzero(present)[0])
    for name, v in points.items():
        if v.size not in (1, n):
            raise ValueError(f"{name}: {v.size} values for {n} points")
        points[name] = np.broadcast_to(v, (n,))
        x = np.asarray(sel[name].values, dtype=float)
        context = f" of mode {mode!r}" if name == "strain" else ""
        if not np.all(np.isfinite(points[name])):
            raise ValueError(f"{name} values must be finite")
        bad = points[name][(points[name] < x.min()) | (points[name] > x.max())]
        if bad.size:
            raise ValueError(f"{name} {bad[0]:g} is outside the table range [{x.min():g}, {x.max():g}]{context}")
    # a dimension with one stored value has nothing to interpolate: the range check above
    # made every point equal to it
    at = {name: xr.DataArray(v, dims="point") for name, v in points.items() if sel.sizes[name] > 1}
    sel = sel.isel({name: 0 for name in points if sel.sizes[name] == 1})
    out = sel.interp(at, method="linear", assume_sorted=True) if at else sel.expand_dims(point=n)
    out.attrs = dict(ds.attrs)
    out.attrs["interpolation"] = f"linear at {n} points in {', '.join(points)}"
    return out
