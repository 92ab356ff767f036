"""netCDF storage of a lookup table: ``write_table`` (atomic, zlib, CF-1.11) and ``open_table``.

Format ``rve-lookup-table/2`` (docs/lookup_tables.md §2, docs/macro_export.md §4,
``rve.tables.schema``). In memory a table has string index coordinates (``mode``,
``probe``, ``side``, ``component``, ``terminal``, ``edge``, ``yarn`` and string-valued swept
parameters), so ``ds.sel(mode="shear")`` works. On disk CF wants coordinate variables
numeric and monotonic, so ``write_table`` stores each string label dimension ``d`` without
a coordinate variable and its labels as the auxiliary coordinate ``d_label`` (a char
array, dimension ``d_strlen``), listed in the data variables' ``coordinates``;
``open_table`` restores the index coordinates.

``write_table(ds, path)`` writes netCDF-4 through ``rve.io.atomic.atomic_netcdf`` (a file
that exists is complete; Fletcher-32 on every variable and the SHA-256 trailer of
``rve.io.checksum``), zlib level 4 with shuffle on numeric variables, no fill value on
coordinates (CF). ``open_table(path)`` verifies the trailer before HDF5 reads the file
(a table without one, e.g. ``tests/data/table_v1_ci.nc``, is opened in a child process
with a time limit first and used with a warning; every failure is a
``rve.io.checksum.CorruptFileError`` naming the file and what failed), reads it into
memory (the file is closed) and checks that it has the ``mode`` and ``strain``
dimensions; a version-1
table (string coordinate variables, no macro quantities) is read as it was stored plus the
macro quantities derived by ``rve.tables.macro.add_macro_quantities`` (its attribute
``rve_table_format`` stays version 1; ``rve_table_upgraded`` says what was added).

``open_table(path, chunks=...)`` opens the table lazily instead (dask arrays in those
chunks, e.g. ``{"strain": -1, "fibril_radius": 32}``; the file stays open): the trailer is
verified as before, then a variable is read chunk by chunk only when it is computed, so a
lookup of a few variables at many points (``rve.tables.interpolate.lookup``) reads those
variables only. An unsealed or version-1 table is opened eagerly as above whatever
``chunks`` says (its checks need the data in memory). docs/cluster.md "dask" has the
figures: the eager open stays the default.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, Optional, Union

import numpy as np
import xarray as xr

from ..io.atomic import atomic_netcdf

__all__ = ["write_table", "open_table", "LABEL_SUFFIX", "to_cf", "from_cf"]

PathLike = Union[str, os.PathLike]

#: suffix of the auxiliary label coordinate of a string dimension on disk
LABEL_SUFFIX = "_label"


def _string_dims(ds: xr.Dataset) -> list[str]:
    return [d for d in ds.dims if d in ds.coords and ds[d].dtype.kind in "OSU"]


def to_cf(ds: xr.Dataset) -> xr.Dataset:
    """The on-disk layout: string index coordinates -> auxiliary ``<dim>_label`` coordinates;
    ``Conventions`` CF-1.11 and ``rve_table_format`` version 2 (what this layout is)."""
    from .build import CF_VERSION
    from .schema import TABLE_FORMAT

    out = ds.copy()
    out.attrs["Conventions"] = CF_VERSION
    out.attrs["rve_table_format"] = TABLE_FORMAT
    for d in _string_dims(ds):
        var = ds[d].variable
        out = out.drop_vars(d)
        out.coords[d + LABEL_SUFFIX] = xr.Variable((d,), np.array([str(v) for v in var.values], dtype=object),
                                                  attrs=dict(var.attrs))
    return out


def from_cf(ds: xr.Dataset) -> xr.Dataset:
    """Inverse of :func:`to_cf` (a no-op on a version-1 table)."""
    out = ds
    for name in list(ds.variables):
        if not name.endswith(LABEL_SUFFIX):
            continue
        d = name[: -len(LABEL_SUFFIX)]
        var = ds[name].variable
        if var.dims != (d,) or d in ds.coords:
            continue
        labels = np.array([v.decode() if isinstance(v, bytes) else str(v) for v in var.values], dtype=object)
        out = out.drop_vars(name).assign_coords({d: xr.Variable((d,), labels, attrs=dict(var.attrs))})
    return out


def _encoding(ds: xr.Dataset) -> dict:
    enc = {}
    for name, var in ds.variables.items():
        if var.dtype.kind in "fiu":
            e: dict = {"zlib": True, "complevel": 4, "shuffle": True}
            if name in ds.coords:
                e["_FillValue"] = None  # CF: coordinate variables have no missing values
            enc[name] = e
        elif var.dtype.kind in "OSU":  # CF: strings as char arrays
            stem = name[: -len(LABEL_SUFFIX)] if name.endswith(LABEL_SUFFIX) else name
            enc[name] = {"dtype": "S1", "char_dim_name": f"{stem}_strlen", "_FillValue": None}
    return enc


def write_table(ds: xr.Dataset, path: PathLike) -> Path:
    """Write ``ds`` atomically as CF-1.11 netCDF-4 (module docstring)."""
    path = Path(path)
    disk = to_cf(ds)
    atomic_netcdf(disk, path, encoding=_encoding(disk))
    return path


def _open_lazily(path: Path, chunks) -> Optional[xr.Dataset]:
    """The sealed, verified table of ``path`` as dask arrays; None for an unsealed or
    version-1 file (opened eagerly by the caller)."""
    from ..io.checksum import CHECKSUM_ATTR, CorruptFileError, verify
    from .schema import TABLE_FORMAT_V1

    if not verify(path).sealed:
        return None
    try:
        ds = xr.open_dataset(path, chunks=chunks)
    except Exception as exc:  # noqa: BLE001 - HDF5 raises many types
        raise CorruptFileError(path, f"HDF5/netCDF cannot read it ({type(exc).__name__}: {exc})") from None
    if ds.attrs.get("rve_table_format") == TABLE_FORMAT_V1:
        ds.close()
        return None
    ds.attrs.pop(CHECKSUM_ATTR, None)
    ds.encoding["rve_sealed"] = True
    return ds


def open_table(path: PathLike, chunks: Optional[Mapping] = None) -> xr.Dataset:
    """Open a table written by :func:`write_table` (either format version), loaded into
    memory (file closed), with string index coordinates; with ``chunks``, lazily as dask
    arrays (module docstring)."""
    from .macro import MACRO_VARIABLES, add_macro_quantities
    from .schema import TABLE_FORMAT_V1

    from ..io.checksum import CorruptFileError, open_netcdf

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no lookup table at {path}")
    ds = _open_lazily(path, chunks) if chunks is not None else None
    if ds is None:
        ds = open_netcdf(path)
    try:
        ds = from_cf(ds)
    except Exception as exc:  # noqa: BLE001 - a damaged label coordinate of an unsealed file
        raise CorruptFileError(path, f"unreadable table labels ({type(exc).__name__}: {exc})") from None
    for name in ("mode", "strain"):
        if name not in ds.dims:
            raise CorruptFileError(path, f"not an rve lookup table (no {name!r} dimension)", hint="")
    if ds.attrs.get("rve_table_format") == TABLE_FORMAT_V1 and "membrane_force" not in ds:
        ds = add_macro_quantities(ds)
        ds.attrs["rve_table_upgraded"] = ("read as rve-lookup-table/1; derived on reading: "
                                          + ", ".join(v for v in MACRO_VARIABLES if v in ds))
    return ds
