"""netCDF storage of a lookup table: ``write_table`` (atomic, zlib) and ``open_table``.

Format ``rve-lookup-table/1`` (docs/lookup_tables.md §2, ``rve.tables.schema``):
``write_table(ds, path)`` writes netCDF-4 through ``rve.io.atomic.atomic_path`` (a file
that exists is complete), zlib level 4 with shuffle on numeric variables, no fill value
on coordinates (CF). ``open_table(path)`` reads any table written so far into memory (the
file is closed) and checks that it has the ``mode`` and ``strain`` dimensions.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Union

import xarray as xr

from ..io.atomic import atomic_path

__all__ = ["write_table", "open_table"]

PathLike = Union[str, os.PathLike]


def _encoding(ds: xr.Dataset) -> dict:
    enc = {}
    for name, var in ds.variables.items():
        if var.dtype.kind in "fiu":
            e: dict = {"zlib": True, "complevel": 4, "shuffle": True}
            if name in ds.coords:
                e["_FillValue"] = None  # CF: coordinate variables have no missing values
            enc[name] = e
    return enc


def write_table(ds: xr.Dataset, path: PathLike) -> Path:
    """Write ``ds`` atomically as netCDF-4 (zlib level 4 on numeric variables)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=_encoding(ds))
    return path


def open_table(path: PathLike) -> xr.Dataset:
    """Open a table written by :func:`write_table`, loaded into memory (file closed)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no lookup table at {path}")
    with xr.open_dataset(path, engine="netcdf4") as ds:
        ds = ds.load()
    for name in ("mode", "strain"):
        if name not in ds.dims:
            raise ValueError(f"{path} is not an rve lookup table (no {name!r} dimension)")
    return ds
