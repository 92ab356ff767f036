"""RVE lookup tables: per-state probe and reaction records -> a CF-style xarray Dataset.

docs/lookup_tables.md. One concept per module:

* ``schema`` -- the table format (dimensions, variables and their CF metadata);
* ``build`` -- records -> Dataset (:func:`build_table`; the network fit is
  ``rve.homogenisation.network``);
* ``io`` -- netCDF (:func:`write_table`, :func:`open_table`);
* ``interpolate`` -- :func:`interpolate` in strain and numeric swept parameters,
  :func:`lookup` at many macro points (pointwise);
* ``export`` -- csv, json, dat (:func:`export_table`, :func:`read_table_csv`,
  :func:`to_json_dict`);
* ``macro`` -- the macro quantities (:func:`add_macro_quantities`, docs/macro_export.md §1);
* ``formats`` -- the macro-FE exports abaqus, lsdyna, curves, comsol, hermite, spice
  (:func:`export_macro`, docs/macro_export.md §3);
* ``summary`` -- :func:`summarize`; ``plot`` -- :func:`plot_table`;
* ``cycles`` -- the loading-unloading cycles' variables and loops (``add_cycle_variables``);
  ``pullout`` -- the yarn pull-out's force-displacement table and figure (not imported here);
* ``jobs`` -- the bodies of the Snakemake rules ``rve_gather`` and ``rve_report`` (not
  imported here: they need the homogenisation pipeline).
"""
from __future__ import annotations

from ..homogenisation.network import YarnNetwork, default_probe_terminals, fit_network
from ..io.provenance import package_version
from .build import build_table
from .export import EXPORT_FORMATS, export_table, read_table_csv, to_json_dict
from .formats import MACRO_FORMATS, export_macro
from .interpolate import interpolate, lookup
from .io import open_table, write_table
from .macro import add_macro_quantities
from .plot import plot_table
from .schema import KNOWN_PARAMETERS, MODES, TABLE_FORMAT
from .summary import summarize

__all__ = [
    "MODES",
    "TABLE_FORMAT",
    "EXPORT_FORMATS",
    "MACRO_FORMATS",
    "KNOWN_PARAMETERS",
    "YarnNetwork",
    "default_probe_terminals",
    "fit_network",
    "build_table",
    "write_table",
    "open_table",
    "interpolate",
    "lookup",
    "export_table",
    "export_macro",
    "add_macro_quantities",
    "read_table_csv",
    "to_json_dict",
    "summarize",
    "plot_table",
    "package_version",
]
