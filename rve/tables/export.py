"""Exports of a lookup table for macroscale codes: csv, json, dat (``export_table``).

docs/lookup_tables.md (§5 "Export formats") describes the three formats; ``read_table_csv`` reads
the csv export back into a Dataset and ``to_json_dict`` is what the json export writes
(NaN as null). Input: a table Dataset; output: the written paths (all atomic,
``rve.io.atomic``).
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Union

import numpy as np
import xarray as xr

from ..io.atomic import atomic_write_text
from .schema import DIMENSIONLESS, LABEL_DIMS, TABLE_FORMAT, json_safe, lead_dims

__all__ = ["EXPORT_FORMATS", "export_table", "read_table_csv", "to_json_dict"]

PathLike = Union[str, os.PathLike]

EXPORT_FORMATS = ("csv", "json", "dat")


def _fmt_num(x: float) -> str:
    return repr(float(x)) if math.isfinite(x) else ("nan" if math.isnan(x) else repr(float(x)))


def export_table(ds: xr.Dataset, path: PathLike, fmt: str) -> list[Path]:
    """Export ``ds`` for macroscale codes; returns the written paths (all atomic).

    * ``"csv"``: one long (tidy) table, one row per value: columns ``variable``,
      ``units``, the leading coordinates with units in the header (``strain [1]``,
      ``fibril_radius [mm]``, ...), the label coordinates ``probe``, ``side``,
      ``component``, ``terminal`` (empty where a variable has no such dimension) and
      ``value``; ``#`` comment lines first (title, provenance, variable units, the
      scalar constants such as ``areal_density``). Only per-state variables (those with a
      ``strain`` dimension) are rows; ``membrane_force_at_zero_strain`` is the strain-0
      row of ``membrane_force``.
      :func:`read_table_csv` reads it back into the Dataset.
    * ``"json"``: ``xarray.Dataset.to_dict`` layout (``coords``, ``data_vars`` with
      ``dims``, ``attrs`` and ``data``; missing values as null) plus ``"format"``.
    * ``"dat"``: one whitespace-separated lookup file per mode (and per value of a
      string-valued swept parameter), ``<stem>.<mode>[.<name>-<value>]<suffix>``: ``#``
      header lines numbering every column with its units and meaning, then one row per
      strain (numeric swept parameters as leading columns, strain varying fastest).
    """
    fmt = fmt.lower()
    path = Path(path)
    if fmt == "csv":
        atomic_write_text(path, _csv_text(ds))
        return [path]
    if fmt == "json":
        atomic_write_text(path, json.dumps(to_json_dict(ds), indent=1, allow_nan=False) + "\n")
        return [path]
    if fmt in ("dat", "txt", "table"):
        return _export_dat(ds, path)
    raise ValueError(f"unknown export format {fmt!r} (known: {', '.join(EXPORT_FORMATS)})")


def _state_vars(ds: xr.Dataset) -> dict:
    """The per-state variables (those with a ``strain`` dimension), in dataset order."""
    return {n: v for n, v in ds.data_vars.items() if "strain" in v.dims}


def _csv_text(ds: xr.Dataset) -> str:
    import csv
    import io

    lead = lead_dims(ds)
    header = ["variable", "units"] + [
        d if ds[d].dtype.kind in "OSU" else f"{d} [{ds[d].attrs.get('units', '')}]" for d in lead
    ] + list(LABEL_DIMS) + ["value"]
    buf = io.StringIO()
    buf.write(f"# rve lookup table, {TABLE_FORMAT} long csv: one row per value; an empty "
              "label cell = not a dimension of the variable\n")
    for key in ("title", "Conventions", "rve_version", "date_created", "source",
                "swept_parameters"):
        if key in ds.attrs:
            buf.write(f"# {key}: {ds.attrs[key]}\n")
    for name, var in ds.data_vars.items():
        if "strain" not in var.dims and var.ndim == 0:
            buf.write(f"# constant {name} [{var.attrs.get('units', '')}] = {_fmt_num(float(var.values))}: "
                      f"{var.attrs.get('long_name', '')}\n")
    for name, var in _state_vars(ds).items():
        buf.write(f"# variable {name} [{var.attrs.get('units', '')}] dims ({', '.join(var.dims)}): "
                  f"{var.attrs.get('long_name', '')}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for name, var in _state_vars(ds).items():
        dims = var.dims
        coords = [ds[d].values for d in dims]
        units = var.attrs.get("units", "")
        for index in np.ndindex(var.shape):
            label = dict(zip(dims, (c[i] for c, i in zip(coords, index))))
            row = [name, units]
            for d in lead:
                v = label.get(d, "")
                row.append(_fmt_num(v) if isinstance(v, (float, np.floating)) else str(v))
            row += [str(label.get(d, "")) for d in LABEL_DIMS]
            row.append(_fmt_num(var.values[index]))
            w.writerow(row)
    return buf.getvalue()


def read_table_csv(path: PathLike) -> xr.Dataset:
    """Read a ``csv`` export back into a Dataset (values, coordinates, units, long names;
    global attributes only those in the comment header)."""
    import csv

    comments, rows = [], []
    with open(path, newline="", encoding="utf-8") as fh:
        lines = []
        for line in fh:
            (comments if line.startswith("#") else lines).append(line)
        rows = list(csv.reader(lines))
    header, body = rows[0], rows[1:]
    col = {h: k for k, h in enumerate(header)}
    lead, lead_units = [], {}
    for h in header[2:header.index(LABEL_DIMS[0])]:
        name, _, unit = h.partition(" [")
        lead.append(name)
        lead_units[name] = unit.rstrip("]")
    var_meta: dict[str, dict] = {}
    constants: dict[str, tuple] = {}
    attrs: dict[str, str] = {}
    for c in comments:
        text = c[1:].strip()
        if text.startswith("constant "):
            name, rest = text[len("constant "):].split(" [", 1)
            units, rest = rest.split("] = ", 1)
            value, long_name = rest.split(": ", 1)
            constants[name] = (float(value), units, long_name)
        elif text.startswith("variable "):
            rest = text[len("variable "):]
            name, rest = rest.split(" [", 1)
            units, rest = rest.split("] dims (", 1)
            dims, long_name = rest.split("): ", 1)
            var_meta[name] = {"units": units, "long_name": long_name,
                              "dims": tuple(d for d in dims.split(", ") if d)}
        elif ": " in text and not text.startswith("rve lookup table,"):
            k, v = text.split(": ", 1)
            attrs[k] = v
    # coordinate values, in order of first appearance (numeric ones sorted)
    coord_vals: dict[str, list] = {}
    for d in lead + list(LABEL_DIMS):
        key = col[d] if d in col else col[d + f" [{lead_units[d]}]"]
        seen = list(dict.fromkeys(r[key] for r in body if r[key] != ""))
        coord_vals[d] = seen
    numeric = {}
    for d in lead:
        try:
            numeric[d] = sorted(float(v) for v in coord_vals[d])
        except ValueError:
            numeric[d] = None
    ds = xr.Dataset(attrs=attrs)
    lead_col = {d: col[next(h for h in header if h.partition(" [")[0] == d)] for d in lead}
    for name, meta in var_meta.items():
        dims = meta["dims"]
        shape = tuple(len(coord_vals[d]) for d in dims)
        arr = np.full(shape, np.nan)
        for r in body:
            if r[0] != name:
                continue
            index = []
            for d in dims:
                v = r[lead_col[d]] if d in lead_col else r[col[d]]
                if d in numeric and numeric[d] is not None:
                    index.append(numeric[d].index(float(v)))
                else:
                    index.append(coord_vals[d].index(v))
            arr[tuple(index)] = float(r[col["value"]]) if r[col["value"]] != "" else np.nan
        ds[name] = xr.Variable(dims, arr, attrs={"units": meta["units"], "long_name": meta["long_name"]})
    for d in coord_vals:
        if d not in ds.dims:
            continue
        vals = np.array(numeric[d], dtype=float) if numeric.get(d) is not None \
            else np.array(coord_vals[d], dtype=object)
        attrs_d = {"units": lead_units.get(d) or DIMENSIONLESS}
        ds.coords[d] = xr.Variable((d,), vals, attrs=attrs_d)
    for name, (value, units, long_name) in constants.items():
        ds[name] = xr.Variable((), value, attrs={"units": units, "long_name": long_name})
    return ds


def to_json_dict(ds: xr.Dataset) -> dict:
    """``ds`` as a JSON-able dict (``xarray.Dataset.to_dict`` layout, NaN -> None, plus
    ``"format"``); what the ``json`` export writes."""
    d = json_safe(ds.to_dict(data="list"), nonfinite_as_null=True)
    d["format"] = TABLE_FORMAT
    return d


def _export_dat(ds: xr.Dataset, path: Path) -> list[Path]:
    lead = [d for d in lead_dims(ds) if d not in ("mode", "strain")]
    str_dims = [d for d in lead if ds[d].dtype.kind in "OSU"]
    num_dims = [d for d in lead if d not in str_dims]
    written = []
    import itertools

    for mode in ds["mode"].values:
        for combo in itertools.product(*(list(ds[d].values) for d in str_dims)):
            sub = ds.sel(mode=mode, **dict(zip(str_dims, combo)))
            # columns: numeric swept params, strain, then every variable flattened
            columns: list[tuple[str, str, str]] = [
                (d, sub[d].attrs.get("units", ""), sub[d].attrs.get("long_name", ""))
                for d in num_dims + ["strain"]]
            blocks = []
            for name, var in _state_vars(sub).items():
                other = [d for d in var.dims if d not in num_dims and d != "strain"]
                v = var.transpose(*(num_dims + ["strain"] + other))
                nrow = int(np.prod([sub.sizes[d] for d in num_dims + ["strain"]]))
                blocks.append(v.values.reshape(nrow, -1))
                for labels in itertools.product(*(list(sub[d].values) for d in other)):
                    tag = f"{name}[{','.join(str(x) for x in labels)}]" if labels else name
                    columns.append((tag, var.attrs.get("units", ""), var.attrs.get("long_name", "")))
            grids = np.meshgrid(*(sub[d].values.astype(float) for d in num_dims + ["strain"]),
                                indexing="ij")
            table = np.hstack([np.column_stack([g.reshape(-1) for g in grids])] + blocks)
            suffix = "".join(f".{d}-{v}" for d, v in zip(str_dims, combo))
            out = path.with_name(f"{path.stem}.{mode}{suffix}{path.suffix or '.dat'}")
            lines = [f"# rve lookup table ({TABLE_FORMAT}), mode: {mode}"
                     + "".join(f", {d}: {v}" for d, v in zip(str_dims, combo)),
                     f"# {ds.attrs.get('title', '')}",
                     f"# rve {ds.attrs.get('rve_version', '?')}, created {ds.attrs.get('date_created', '?')}",
                     f"# {table.shape[0]} rows ({' x '.join(f'{d} {sub.sizes[d]}' for d in num_dims + ['strain'])},"
                     " last varies fastest), "
                     f"{table.shape[1]} columns; nan = no value",
                     "# column  name  [units]  meaning"]
            for k, (tag, units, long_name) in enumerate(columns, start=1):
                lines.append(f"# {k:4d}  {tag}  [{units}]  {long_name}")
            for name, var in sub.data_vars.items():
                if "strain" not in var.dims and var.ndim == 0:
                    lines.append(f"# constant {name} = {_fmt_num(float(var.values))} [{var.attrs.get('units', '')}]"
                                 f"  {var.attrs.get('long_name', '')}")
            lines.append("# " + " ".join(tag for tag, _, _ in columns))
            for row in table:
                lines.append(" ".join(f"{x: .12e}" if math.isfinite(x) else "nan" for x in row))
            atomic_write_text(out, "\n".join(lines) + "\n")
            written.append(out)
    return written
