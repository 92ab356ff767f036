"""The lookup-table format ``rve-lookup-table/2``: dimensions, variables, attributes.

docs/lookup_tables.md (§2 "The table") records the format; this module is where it is spelt:
the coordinate and variable metadata every module of ``rve.tables`` writes and reads, the
known swept parameters with their units, and the one JSON-safe conversion of table
metadata (``json_safe``, built on ``rve.io.provenance.to_jsonable``).

Contract
--------
* ``TABLE_FORMAT``, ``TABLE_FORMAT_V1``, ``MODES``, ``TERMINALS``, ``COMPONENTS``,
  ``SIDE_ORDER``, ``EDGES``, ``YARNS``: the format ids (version 2 adds the macro
  quantities of ``rve.tables.macro`` and stores label coordinates CF-style, ``rve.tables.io``;
  version 1 is still read) and the label coordinates' values.
* ``COORD_ATTRS`` (name -> CF attrs), ``VARIABLES`` (name -> (dims after the leading
  ``(mode, strain, *swept)``, units, long_name, extra attrs)), ``KNOWN_PARAMETERS``
  (swept name -> (units, long_name)).
* ``LABEL_DIMS`` and ``lead_dims(ds)``: the label dimensions (probe, side, component,
  terminal) and the others, in dataset order (mode, strain, swept parameters).
* ``json_safe(obj, nonfinite_as_null=False)``: ``obj`` as plain JSON types (an object
  ``to_jsonable`` cannot convert becomes its ``repr``), NaN/inf as None on request.
"""
from __future__ import annotations

import math
from typing import Any

import xarray as xr

from ..homogenisation.network import TERMINALS
from ..io.provenance import to_jsonable

__all__ = ["TABLE_FORMAT", "TABLE_FORMAT_V1", "EDGES", "YARNS", "MODES", "TERMINALS", "COMPONENTS", "SIDE_ORDER", "DIMENSIONLESS", "STRAIN_DECIMALS",
           "COORD_ATTRS", "VARIABLES", "FRICTION_VARIABLES", "FRICTION_RECORD_KEYS", "KNOWN_PARAMETERS", "LABEL_DIMS", "CYCLE_DIMS", "lead_dims", "json_safe"]

TABLE_FORMAT = "rve-lookup-table/2"
TABLE_FORMAT_V1 = "rve-lookup-table/1"
#: deformation modes, in table order (the first two are the thesis's)
MODES = ("uniaxial", "shear", "uniaxial_y", "trellis")
EDGES = ("x", "y")
YARNS = ("warp", "weft")
COMPONENTS = ("x", "y", "z")
SIDE_ORDER = ("warp-", "warp+", "weft-", "weft+", "x-", "x+", "y-", "y+")
DIMENSIONLESS = "1"
STRAIN_DECIMALS = 12

COORD_ATTRS = {
    "mode": {"units": DIMENSIONLESS, "long_name": "deformation mode of the strain path "
             "(uniaxial: stretch along the warp direction x; shear: simple shear, "
             "displacement along y proportional to x; uniaxial_y: stretch along the weft "
             "direction y; trellis: picture-frame shear, both yarn families keep their length)"},
    "strain": {"units": DIMENSIONLESS, "long_name": "engineering strain of the applied deformation "
               "(uniaxial: elongation / initial length along x; shear: engineering shear "
               "strain gamma = displacement along y / initial length along x; uniaxial_y: "
               "elongation / initial length along y; trellis: angle drop between the yarn "
               "families in rad)"},
    "probe": {"units": DIMENSIONLESS, "long_name": "electrical probe (pair of terminals a test "
              "voltage is applied across)"},
    "side": {"units": DIMENSIONLESS, "long_name": "side of the RVE box the clamped fibril ends "
             "are on (warp-/warp+ = x-/x+, the warp yarn ends; weft-/weft+ = y-/y+)"},
    "component": {"units": DIMENSIONLESS, "long_name": "Cartesian component (x warp, y weft, "
                  "z out of plane)"},
    "terminal": {"units": DIMENSIONLESS, "long_name": "probe terminal (+: at the test voltage, "
                 "-: at 0 V)"},
    "probe_terminals": {"units": DIMENSIONLESS, "long_name": "yarn ends the probe connects in the "
                        "network model (+ terminal | - terminal), empty if not modelled"},
}

# name: (dims after (mode, strain, *swept), units, long_name, extra attrs)
VARIABLES: dict[str, tuple[tuple[str, ...], str, str, dict]] = {
    "reaction_force": (("side", "component"), "N",
                       "total reaction force of the clamped fibril ends on one side of the RVE",
                       {}),
    "contact_count": ((), DIMENSIONLESS, "number of active fibril-fibril contacts", {}),
    "equilibrium_residual": ((), "N",
                             "norm of the out-of-balance force on the free dofs of the stored "
                             "state (static equilibrium: ~0; NaN if not recorded)", {}),
    "converged": ((), DIMENSIONLESS,
                  "1 if the stored state is a static equilibrium (final |F| within the stage's tolerance), "
                  "0 if it is not and was kept on purpose (checks.keep_unconverged); NaN if not recorded", {}),
    "probe_voltage": (("probe",), "V", "test voltage applied across the probe terminals", {}),
    "probe_current": (("probe", "terminal"), "A",
                      "electric current into the fabric through the probe terminal", {}),
    "probe_resistance": (("probe",), "ohm",
                         "effective electrical resistance between the probe terminals "
                         "(test voltage / mean terminal current)", {}),
    "temperature_rise_max": (("probe",), "K",
                             "maximum Joule-heating temperature rise above the boundary "
                             "temperature during the probe solve",
                             {"units_metadata": "temperature: difference"}),
    "temperature_rise_mean": (("probe",), "K",
                              "mean Joule-heating temperature rise above the boundary "
                              "temperature during the probe solve",
                              {"units_metadata": "temperature: difference"}),
    "yarn_resistance": ((), "ohm",
                        "network-model yarn resistance R_y of one yarn across one cell "
                        "(one crossing) of the RVE", {}),
    "contact_resistance": ((), "ohm",
                           "network-model contact resistance R_c, one of the four warp-weft "
                           "contact resistors of a cell", {}),
    "network_fit_residual": ((), DIMENSIONLESS,
                             "RMS of log(model / measured probe resistance) of the network "
                             "fit (0: the probes are consistent with the network model)", {}),
    # format 2: the fit with separate warp and weft yarn resistors (four probes or more)
    "yarn_resistance_warp": ((), "ohm", "network-model warp yarn resistance R_yw of one warp yarn across one "
                             "cell, fitted with separate warp and weft yarn resistors", {}),
    "yarn_resistance_weft": ((), "ohm", "network-model weft yarn resistance R_yf of one weft yarn across one "
                             "cell, fitted with separate warp and weft yarn resistors", {}),
    "contact_resistance_warp_weft": ((), "ohm", "network-model contact resistance R_c of the fit with "
                                     "separate warp and weft yarn resistors", {}),
    "network_fit_residual_warp_weft": ((), DIMENSIONLESS,
                                       "RMS of log(model / measured probe resistance) of the fit with "
                                       "separate warp and weft yarn resistors (four probes or more: one "
                                       "left over as a check; NaN with fewer)", {}),
}

#: variables of a table whose run has friction (``friction`` in its records; absent otherwise, so
#: a frictionless table is unchanged): name -> (label dims, units, long_name, extra attrs)
FRICTION_VARIABLES: dict[str, tuple[tuple[str, ...], str, str, dict]] = {
    "friction_dissipated_energy": ((), "N mm",
                                   "energy dissipated by fibril-fibril friction along the mode's strain path from "
                                   "the relaxed state (sum of the return-map dissipation of every committed "
                                   "step; 0 without friction)", {}),
    "friction_force": ((), "N", "sum over the contact points of the magnitude of the friction force at the "
                       "stored state", {}),
    "friction_stick_points": ((), DIMENSIONLESS, "contact points that stick at the stored state", {}),
    "friction_slip_points": ((), DIMENSIONLESS, "contact points that slip at the stored state", {}),
}
#: the record key of each friction variable (``record["friction"]``)
FRICTION_RECORD_KEYS = {"friction_dissipated_energy": "dissipated_energy", "friction_force": "friction_force",
                        "friction_stick_points": "stick_points", "friction_slip_points": "slip_points"}

# known swept parameters: name -> (units, long_name)
KNOWN_PARAMETERS: dict[str, tuple[str, str]] = {
    "fibril_radius": ("mm", "fibril radius R"),
    "fibril_diameter": ("mm", "fibril diameter"),
    "contact_conductance": ("A mm-2 V-1", "electrical contact conductance sigma_C"),
    "thermal_contact_conductance": ("W mm-2 K-1", "thermal contact conductance h_C"),
    "contact_penalty": ("N mm-1", "contact penalty stiffness P*"),
    "conductivity": ("S mm-1", "fibril electrical conductivity sigma"),
    "thermal_conductivity": ("W mm-1 K-1", "fibril thermal conductivity k"),
    "youngs_modulus": ("MPa", "fibril Young's modulus E"),
    "spacing": ("mm", "yarn spacing"),
    "amplitude": ("mm", "crimp amplitude"),
    "weave": (DIMENSIONLESS, "weave pattern"),
    "friction_coefficient": (DIMENSIONLESS, "Coulomb friction coefficient mu between fibrils"),
}


#: dimensions of the label coordinates; the others lead (mode, strain, swept parameters)
LABEL_DIMS = ("probe", "side", "component", "terminal", "edge", "yarn")


#: dimensions of a loading-unloading cycle (``rve.tables.cycles``): neither labels nor swept
CYCLE_DIMS = ("cycle_mode", "cycle_step")


def lead_dims(ds: xr.Dataset) -> list[str]:
    """The leading (non-label) dimensions of ``ds``, in dataset order (mode, strain, swept
    parameters; not the cycle's)."""
    return [d for d in ds.dims if d not in LABEL_DIMS and d not in CYCLE_DIMS]


def _nonfinite_to_null(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _nonfinite_to_null(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_nonfinite_to_null(v) for v in obj]
    return obj


def json_safe(obj: Any, nonfinite_as_null: bool = False) -> Any:
    """``obj`` as plain JSON types (``rve.io.provenance.to_jsonable``); an object it cannot
    convert is written as its ``repr``. ``nonfinite_as_null``: NaN and inf become None
    (strict JSON, the ``json`` export)."""
    try:
        out = to_jsonable(obj)
    except TypeError:
        return repr(obj)
    return _nonfinite_to_null(out) if nonfinite_as_null else out
