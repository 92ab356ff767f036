"""Studies: sweeps of scene solves gathered into netCDF datasets, fits and plots.

Each study module offers package functions that the Snakemake rules call (the rules stay
thin): one function per solve returning a JSON-serialisable record, a gather function that
builds an xarray Dataset (named dimensions, ``units`` and ``long_name`` on every variable,
provenance attributes) and writes it atomically, and plotting/table helpers.

Modules are imported on demand (``from rve.studies import static_wire``) so that
``import rve.studies`` stays cheap.
"""
from __future__ import annotations

__all__ = ["static_wire", "dynamic_wire", "convergence"]
