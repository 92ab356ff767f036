"""Per-state probe and reaction records -> the lookup-table Dataset (``build_table``).

The RVE pipeline (thesis ch. 7, Algorithm 7.1; docs/rve_pipeline.md) relaxes a fabric,
strains it step by step (uniaxial and simple shear) and, on every stored state, runs
decoupled probe solves: a test voltage across a probe's two terminals gives the terminal
currents, then the Joule heating gives a temperature field with T = 0 on the boundary.
This module turns those records into the table of docs/lookup_tables.md; it knows nothing
about the physics except the network fit, which it calls
(``rve.homogenisation.network.fit_network``).

Contract
========

Input: a list of **records**, one per stored state (and per point of a parameter sweep)::

    {
      "mode": "uniaxial",                 # or "shear"
      "strain": 0.05,                     # engineering strain (uniaxial) / shear strain
      "params": {"fibril_radius": 0.15},  # swept parameter values (optional; alias "swept")
      "reaction_force": {                 # N, per box side (alias "reactions"):
          "warp-": [fx, fy, fz],          #   sides warp-/warp+/weft-/weft+ or x-/x+/y-/y+,
          "warp+": {"x": .., "y": .., "z": ..},   # a list/tuple of 3 or a dict x/y/z
          ...},
      "contact_count": 412,               # active contact points of the state
      "equilibrium_residual": 3e-10,      # N, |F| on the free dofs (or "state": {"residual_N": ..})
      "probes": {
          "probe1": {"voltage": 1.0,                  # V, + terminal; - terminal at 0 V
                     "current": {"+": 0.52, "-": -0.52},
                     "temperature_max": 0.8,          # K above the boundary (T = 0 there)
                     "temperature_mean": 0.1},
          ...},
    }

Terminal currents are the current flowing **into the fabric** through each terminal (A),
so a conserving solve has I(+) = -I(-) > 0; a scalar ``"current": I`` means I(+) = I,
I(-) = -I. Currents of opposite sign convention are rejected. Records may omit any
quantity (it becomes NaN); strains are rounded to 12 decimals so that 0.1 + 0.2 and 0.3
are the same level.

Output of :func:`build_table`: an :class:`xarray.Dataset` with dimensions ``mode``,
``strain``, one per swept parameter (in ``swept`` order, after ``strain``), ``probe``,
``side``, ``component``, ``terminal`` and the variables of ``rve.tables.schema.VARIABLES``:

=========================  =====================================  ======
reaction_force             (mode, strain, *swept, side, component)  N
contact_count              (mode, strain, *swept)                  1
equilibrium_residual       (mode, strain, *swept)                  N
converged                  (mode, strain, *swept)                  1   (1 equilibrium, 0 kept unconverged)
probe_voltage              (mode, strain, *swept, probe)           V
probe_current              (mode, strain, *swept, probe, terminal) A
probe_resistance           (mode, strain, *swept, probe)           ohm
temperature_rise_max       (mode, strain, *swept, probe)           K
temperature_rise_mean      (mode, strain, *swept, probe)           K
yarn_resistance            (mode, strain, *swept)                  ohm
contact_resistance         (mode, strain, *swept)                  ohm
network_fit_residual       (mode, strain, *swept)                  1
=========================  =====================================  ======

With friction (a record with ``friction``: ``dissipated_energy``, ``friction_force``,
``stick_points``, ``slip_points``) also the variables of ``schema.FRICTION_VARIABLES`` on
``(mode, strain, *swept)`` (``friction_dissipated_energy`` N mm, ``friction_force`` N,
``friction_stick_points``, ``friction_slip_points``); a record without ``friction`` in such a
table (a frictionless combination of a mu sweep) has 0 there. Without friction in any record
they are absent (the frictionless table is unchanged).

``probe_resistance = V / I`` with I = (I(+) - I(-))/2; the internal units are V and A, so
this is in ohm directly. ``yarn_resistance`` R_y and ``contact_resistance`` R_c are the
two resistors of the network model of thesis Fig. 7.2.1
(``rve.homogenisation.network.YarnNetwork``, docs/lookup_tables.md), fitted to the probe
resistances (least squares on log R over the probes the model knows; two probes determine
them exactly, the third is a check reported by ``network_fit_residual``). Every variable
and coordinate has ``units`` and ``long_name``; the global attributes
(``rve.io.provenance.cf_attributes``, Conventions CF-1.11) hold the provenance (config and
fabric as JSON, rve version, creation date, source). Last, the macro quantities
(membrane force per width, yarn strains, shear angle, areal density, gauge factors, the
two-potential sheet parameters) are derived once by ``rve.tables.macro.add_macro_quantities``.
"""
from __future__ import annotations

import json
import logging
import math
from typing import Any, Iterable, Mapping, Optional, Sequence, Union

import numpy as np
import xarray as xr

from ..homogenisation.network import (Terminal, YarnNetwork, default_probe_terminals, fit_network, fit_network3,
                                      terminal_text)
from ..io.provenance import cf_attributes, package_version
from .macro import add_macro_quantities
from .schema import (COMPONENTS, COORD_ATTRS, DIMENSIONLESS, FRICTION_RECORD_KEYS, FRICTION_VARIABLES, KNOWN_PARAMETERS,
                     MODES, SIDE_ORDER, STRAIN_DECIMALS, TABLE_FORMAT, TERMINALS, VARIABLES, json_safe)

__all__ = ["build_table", "CF_VERSION"]

#: units_metadata (temperature differences) is CF-1.11 (docs/macro_export.md §4)
CF_VERSION = "CF-1.11"

log = logging.getLogger("rve.tables")


def _fabric_description(fabric: Any) -> tuple[dict, int, int]:
    """JSON-able description of ``fabric`` and its (n_warp, n_weft)."""
    n_warp = n_weft = 4
    if fabric is None:
        return {}, n_warp, n_weft
    if isinstance(fabric, str):
        return {"kind": fabric}, n_warp, n_weft
    if isinstance(fabric, Mapping):
        desc = dict(fabric)
    else:  # rve.fabrics.Fabric (or anything with kind/params)
        desc = {"kind": getattr(fabric, "kind", type(fabric).__name__)}
        params = dict(getattr(fabric, "params", {}) or {})
        desc.update(params)
        for attr in ("n_fibrils", "half_widths"):
            if hasattr(fabric, attr):
                desc[attr] = getattr(fabric, attr)
        yarns = getattr(fabric, "yarns", None)
        if yarns is not None:
            n_warp = sum(1 for y in yarns if getattr(y, "direction", None) == "warp") or n_warp
            n_weft = sum(1 for y in yarns if getattr(y, "direction", None) == "weft") or n_weft
    n_warp = int(desc.get("n_warp", n_warp))
    n_weft = int(desc.get("n_weft", n_weft))
    return json_safe(desc), n_warp, n_weft


def _param_meta(swept) -> tuple[list[str], dict[str, dict]]:
    """Names and attrs of the swept parameters from ``swept`` (None, names, or a dict)."""
    if swept is None:
        return [], {}
    if isinstance(swept, str):
        swept = [swept]
    names: list[str] = []
    meta: dict[str, dict] = {}
    items = swept.items() if isinstance(swept, Mapping) else ((n, None) for n in swept)
    for name, spec in items:
        name = str(name)
        units, long_name = KNOWN_PARAMETERS.get(name, (None, name.replace("_", " ")))
        extra: dict = {}
        if isinstance(spec, str):
            units = spec
        elif isinstance(spec, Mapping):
            extra = {k: v for k, v in spec.items() if k not in ("units", "long_name")}
            units = spec.get("units", units)
            long_name = spec.get("long_name", long_name)
        if units is None:
            log.warning("swept parameter %r has no units given; writing units '1'", name)
            units = DIMENSIONLESS
        names.append(name)
        meta[name] = {"units": str(units), "long_name": str(long_name), **extra}
    return names, meta


def _record_params(rec: Mapping) -> Mapping:
    params = rec.get("params", rec.get("swept", {}))
    return params or {}


def _sorted_unique(values: list) -> list:
    uniq = list(dict.fromkeys(values))
    if all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
           for v in uniq):
        return sorted(float(v) for v in uniq)
    if all(isinstance(v, str) for v in uniq):
        return sorted(uniq)
    raise ValueError(f"swept values must be all numbers or all strings, got {uniq!r}")


def _vector3(value, where: str) -> np.ndarray:
    if isinstance(value, Mapping):
        try:
            return np.array([float(value[c]) for c in COMPONENTS])
        except KeyError as exc:
            raise ValueError(f"{where}: needs components x, y, z, got {sorted(value)}") from exc
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.size != 3:
        raise ValueError(f"{where}: a force needs 3 components, got {arr.size}")
    return arr


def _terminal_currents(value, where: str) -> tuple[float, float]:
    if isinstance(value, Mapping):
        aliases = {"+": ("+", "plus", "pos", "positive"), "-": ("-", "minus", "neg", "negative")}
        out = []
        for t in TERMINALS:
            key = next((k for k in aliases[t] if k in value), None)
            if key is None:
                raise ValueError(f"{where}: current needs terminals '+' and '-', got {sorted(value)}")
            out.append(float(value[key]))
        ip, im = out
    else:
        ip = float(value)
        im = -ip
    if ip * im > 0:
        raise ValueError(f"{where}: terminal currents {ip} and {im} have the same sign; give the "
                         "current flowing into the fabric through each terminal (I+ = -I-)")
    return ip, im


def _side_order(sides: Iterable[str]) -> list[str]:
    sides = list(dict.fromkeys(sides))
    known = [s for s in SIDE_ORDER if s in sides]
    return known + sorted(s for s in sides if s not in SIDE_ORDER)


def build_table(records: Sequence[Mapping], *, fabric: Any, config: Any,
                swept: Union[None, Sequence[str], Mapping[str, Any]] = None,
                network_probes: Optional[Mapping[str, tuple[Terminal, Terminal]]] = None,
                title: Optional[str] = None, source: Optional[str] = None) -> xr.Dataset:
    """Build the lookup-table Dataset from per-state ``records`` (module docstring).

    ``fabric``: an ``rve.fabrics.Fabric``, a dict or a name, described in the ``fabric``
    attribute (its warp/weft counts size the network model). ``config``: the run's
    configuration (dict or pydantic model), stored as JSON in the ``config`` attribute.
    ``swept``: the swept parameter names (list) or ``{name: units}`` /
    ``{name: {"units": .., "long_name": ..}}``; None takes the names found in the records'
    ``params`` (known names get their units, KNOWN_PARAMETERS). ``network_probes``: the
    probes the network fit uses, name -> (+ terminal, - terminal), default
    :func:`default_probe_terminals`. Missing combinations are NaN; a repeated
    (mode, strain, params) state is an error.
    """
    records = list(records)
    if not records:
        raise ValueError("build_table: no records")
    fabric_desc, n_warp, n_weft = _fabric_description(fabric)
    pnames, pmeta, pvalues = _swept_parameters(records, swept)
    mode_coord, strains, strain_coord, probes, sides = _axes(records, n_warp, n_weft)
    data, filled, pidx = _fill(records, pnames, pvalues, mode_coord, strains, strain_coord, probes, sides)
    net_probes, usable = _fit_networks(data, filled, pidx, network_probes, n_warp, n_weft)
    lead = ("mode", "strain") + tuple(pnames)
    coords: dict[str, Any] = {
        "mode": ("mode", np.array(mode_coord, dtype=object), dict(COORD_ATTRS["mode"])),
        "strain": ("strain", np.array(strain_coord, dtype=float), dict(COORD_ATTRS["strain"])),
        "probe": ("probe", np.array(probes, dtype=object), dict(COORD_ATTRS["probe"])),
        "side": ("side", np.array(sides, dtype=object), dict(COORD_ATTRS["side"])),
        "component": ("component", np.array(COMPONENTS, dtype=object), dict(COORD_ATTRS["component"])),
        "terminal": ("terminal", np.array(TERMINALS, dtype=object), dict(COORD_ATTRS["terminal"])),
        "probe_terminals": ("probe", np.array(
            [" | ".join(terminal_text(t) for t in net_probes[p]) if p in net_probes else ""
             for p in probes], dtype=object), dict(COORD_ATTRS["probe_terminals"])),
    }
    for p in pnames:
        vals = pvalues[p]
        arr = np.array(vals, dtype=object if isinstance(vals[0], str) else float)
        coords[p] = (p, arr, dict(pmeta[p]))
    data_vars = {}
    for name, (dims, units, long_name, extra) in VARIABLES.items():
        attrs = {"units": units, "long_name": long_name, **extra}
        data_vars[name] = (lead + dims, data[name], attrs)
    if any(rec.get("friction") is not None for rec in records):
        for name, (dims, units, long_name, extra) in FRICTION_VARIABLES.items():
            data_vars[name] = (lead + dims, data[name], {"units": units, "long_name": long_name, **extra})
    ds = xr.Dataset(data_vars, coords=coords)
    ds["yarn_resistance"].attrs["comment"] = ds["contact_resistance"].attrs["comment"] = (
        "fitted to the probe resistances under the network model of docs/lookup_tables.md "
        f"({n_warp} x {n_weft} cells, probes {', '.join(usable) or 'none'})")
    if any(pr.get("yarn_family") for rec in records for pr in (rec.get("probes") or {}).values()):
        ds.attrs["periodic_resistances"] = PERIODIC_RESISTANCES
        for v in ("yarn_resistance", "contact_resistance", "yarn_resistance_warp", "yarn_resistance_weft",
                  "contact_resistance_warp_weft"):
            ds[v].attrs["comment"] = PERIODIC_RESISTANCES
    ds["probe_resistance"].attrs["comment"] = ("V / I with I = (I(+) - I(-)) / 2; internal "
                                               "units are V and A, so ohm directly")

    ds.attrs.update(cf_attributes(
        title=title or "RVE lookup table: reaction forces, probe resistances and Joule "
                       "temperature rises of a textile unit cell vs applied strain",
        source=source or f"rve {package_version()} RVE pipeline (rve.tables.build_table)",
        references="Queiruga (2015), ch. 7 (Algorithm 7.1, Figs. 7.2.1, 7.4.3-7.4.4); "
                   "docs/lookup_tables.md",
        history=f"rve.tables.build_table from {len(records)} records",
        rve_table_format=TABLE_FORMAT,
        config=json.dumps(json_safe(config), sort_keys=True),
        fabric=json.dumps(fabric_desc, sort_keys=True),
        network_model=(f"YarnNetwork(n_warp={n_warp}, n_weft={n_weft}): per crossing 2 yarn "
                       "resistors R_y and 4 warp-weft contact resistors R_c"),
        swept_parameters=" ".join(pnames),
        internal_units="mm, ms, g, N, MPa, K, A, mC, V (ohm = V/A)",
    ))
    ds.attrs["Conventions"] = CF_VERSION
    branch = _branch_attributes(records)
    if branch:
        ds.attrs.update(branch)
    return add_macro_quantities(ds)


#: how a periodic cell's R_y and R_c are defined (no fit: two cell problems per state)
PERIODIC_RESISTANCES = (
    "periodic cell (rve.homogenisation.periodic_resistances, docs/periodic.md): R_y = r_y a_x / a_y (warp; weft "
    "r_y a_y / a_x) with r_y the sheet resistance (ohm per reference square) of the yarn family's fibrils alone "
    "under a macro field along it; R_c = 4 r_c / (a_x a_y) with r_c (ohm mm2) the warp-weft exchange resistance "
    "per reference area (uniform injection per length into the warp, out of the weft, no macro field); "
    "a_x, a_y the reference yarn pitches; yarn_resistance = the mean of the warp and weft R_y")


def _branch_attributes(records: Sequence[Mapping]) -> dict:
    """``branch_jumps``, ``branch_limit_points``, ``branch_detections``, ``branch_false_alarms``,
    ``branch_limit_points_passed`` (by the continuation), ``branch_untested_steps`` (steps of a
    frictional path, which have no energy test): JSON {mode: count summed over the mode's steps} of the records' equilibrium-path tests
    (``state.branch``, rve.homogenisation.branch); empty when no record carries one."""
    per: dict = {}
    for rec in records:
        b = (rec.get("state") or {}).get("branch")
        if not b or not rec.get("mode"):
            continue
        m = per.setdefault(str(rec["mode"]), {})
        for k in ("branch_jumps", "limit_points", "detections", "false_alarms", "limit_points_passed"):
            m[k] = m.get(k, 0) + int(b.get(k) or 0)
        m["untested"] = m.get("untested", 0) + int(bool(b.get("untested")))
    if not per:
        return {}
    name = {"branch_jumps": "branch_jumps", "limit_points": "branch_limit_points", "detections": "branch_detections",
            "false_alarms": "branch_false_alarms", "limit_points_passed": "branch_limit_points_passed",
            "untested": "branch_untested_steps"}
    if not any(c.get("untested") for c in per.values()):
        name.pop("untested")     # a frictionless table's attributes stay as they are
    return {attr: json.dumps({mode: c[k] for mode, c in sorted(per.items())}, sort_keys=True)
            for k, attr in name.items()}


def _swept_parameters(records, swept):
    """``(names, metadata, sorted values)`` of the swept parameters (``build_table``)."""
    if swept is None:
        found: list[str] = []
        for rec in records:
            for k in _record_params(rec):
                if k not in found:
                    found.append(str(k))
        swept = found
    pnames, pmeta = _param_meta(swept)
    pvalues: dict[str, list] = {}
    for name in pnames:
        vals = []
        for n, rec in enumerate(records):
            params = _record_params(rec)
            if name not in params:
                raise ValueError(f"record {n}: missing swept parameter {name!r}")
            vals.append(params[name])
        pvalues[name] = _sorted_unique(vals)
    return pnames, pmeta, pvalues


def _axes(records, n_warp: int, n_weft: int):
    """The mode, strain, probe and side axes of the records (``build_table``)."""
    modes, strains, probes, sides = [], [], [], []
    for n, rec in enumerate(records):
        mode = rec.get("mode")
        if mode not in MODES:
            raise ValueError(f"record {n}: mode must be one of {MODES}, got {mode!r}")
        modes.append(mode)
        try:
            s = round(float(rec["strain"]), STRAIN_DECIMALS)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"record {n}: needs a numeric 'strain'") from exc
        if not math.isfinite(s):
            raise ValueError(f"record {n}: strain {s} is not finite")
        strains.append(s + 0.0)  # -0.0 -> 0.0
        for p in (rec.get("probes") or {}):
            if str(p) not in probes:
                probes.append(str(p))
        sides.extend(str(s_) for s_ in (rec.get("reaction_force", rec.get("reactions")) or {}))
    mode_coord = [m for m in MODES if m in modes]
    strain_coord = sorted(set(strains))
    sides = _side_order(sides) or list(SIDE_ORDER[:4])
    if not probes:
        probes = list(default_probe_terminals(max(n_warp, 2), max(n_weft, 2)))
    return mode_coord, strains, strain_coord, probes, sides


def _fill(records, pnames, pvalues, mode_coord, strains, strain_coord, probes, sides):
    """``(data, filled, probe index)``: every variable of ``VARIABLES`` on the table's grid,
    NaN where no record is (``build_table``)."""
    shape0 = (len(mode_coord), len(strain_coord)) + tuple(len(pvalues[p]) for p in pnames)
    sizes = {"probe": len(probes), "side": len(sides), "component": 3, "terminal": 2}
    data = {name: np.full(shape0 + tuple(sizes[d] for d in dims), np.nan)
            for name, (dims, *_rest) in {**VARIABLES, **FRICTION_VARIABLES}.items()}
    filled = np.zeros(shape0, dtype=bool)

    pidx = {p: i for i, p in enumerate(probes)}
    sidx = {s: i for i, s in enumerate(sides)}
    # positions by dict, not list.index: a 1-D sweep of N runs would cost O(N^2) otherwise
    mpos = {m: i for i, m in enumerate(mode_coord)}
    spos = {s: i for i, s in enumerate(strain_coord)}
    ppos = {p: {v: i for i, v in enumerate(pvalues[p])} for p in pnames}
    for n, rec in enumerate(records):
        params = _record_params(rec)
        idx = (mpos[rec["mode"]], spos[strains[n]]) + tuple(
            ppos[p][float(params[p]) if not isinstance(params[p], str) else params[p]] for p in pnames)
        if filled[idx]:
            raise ValueError(f"record {n}: state mode={rec['mode']}, strain={strains[n]}"
                             f"{''.join(f', {p}={params[p]}' for p in pnames)} given twice")
        filled[idx] = True
        where = f"record {n} ({rec['mode']}, strain {strains[n]})"
        for side, vec in (rec.get("reaction_force", rec.get("reactions")) or {}).items():
            data["reaction_force"][idx + (sidx[str(side)],)] = _vector3(vec, f"{where}, side {side}")
        if rec.get("contact_count") is not None:
            data["contact_count"][idx] = float(rec["contact_count"])
        resid = rec.get("equilibrium_residual", (rec.get("state") or {}).get("residual_N"))
        if resid is not None:
            data["equilibrium_residual"][idx] = float(resid)
        conv = rec.get("converged", (rec.get("state") or {}).get("converged"))
        if conv is not None:
            data["converged"][idx] = 1.0 if conv else 0.0
        fr = rec.get("friction") or {}
        for name, key in FRICTION_RECORD_KEYS.items():   # (only written to the table with friction)
            data[name][idx] = float(fr.get(key, 0.0))
        for pname, pr in (rec.get("probes") or {}).items():
            k = idx + (pidx[str(pname)],)
            pw = f"{where}, probe {pname}"
            if pr.get("voltage") is not None:
                data["probe_voltage"][k] = float(pr["voltage"])
            if pr.get("current") is not None:
                ip, im = _terminal_currents(pr["current"], pw)
                data["probe_current"][k] = (ip, im)
                i_mean = 0.5 * (ip - im)
                if pr.get("voltage") is not None:
                    data["probe_resistance"][k] = (float(pr["voltage"]) / i_mean
                                                   if i_mean != 0 else math.inf)
            for key in ("max", "mean"):
                val = pr.get(f"temperature_{key}", pr.get(f"temperature_rise_{key}"))
                if val is not None:
                    data[f"temperature_rise_{key}"][k] = float(val)
            _cell_resistances(data, idx, pr)
    return data, filled, pidx


def _cell_resistances(data, idx, pr) -> None:
    """A periodic field probe's R_y of its yarn family and the cell's R_c
    (``rve.homogenisation.periodic_resistances``), per crossing as the network's resistors;
    the two-resistor ``yarn_resistance`` is the mean of the families' (docs/periodic.md)."""
    family = pr.get("yarn_family")
    if family not in ("warp", "weft") or pr.get("yarn_resistance_ohm") is None:
        return
    data[f"yarn_resistance_{family}"][idx] = float(pr["yarn_resistance_ohm"])
    data["contact_resistance_warp_weft"][idx] = data["contact_resistance"][idx] = float(pr["contact_resistance_ohm"])
    data["yarn_resistance"][idx] = float(np.nanmean([data["yarn_resistance_warp"][idx],
                                                     data["yarn_resistance_weft"][idx]]))


def _fit_networks(data, filled, pidx, network_probes, n_warp: int, n_weft: int):
    """The yarn-network fits of every filled state into ``data``; returns ``(the network
    probes, the usable ones)`` (``build_table``)."""
    network = YarnNetwork(n_warp, n_weft)
    try:
        net_probes = (dict(network_probes) if network_probes is not None
                      else default_probe_terminals(n_warp, n_weft))
    except ValueError:
        net_probes = {}
    usable = [p for p in net_probes if p in pidx]
    cache: dict = {}
    if len(usable) >= 2:
        for idx in zip(*np.nonzero(filled)):
            measured = {p: data["probe_resistance"][idx + (pidx[p],)] for p in usable}
            ry, rc, res = fit_network(measured, network, {p: net_probes[p] for p in usable},
                                      _grid_cache=cache)
            data["yarn_resistance"][idx] = ry
            data["contact_resistance"][idx] = rc
            data["network_fit_residual"][idx] = res
    else:
        log.warning("build_table: records have fewer than two of the network probes %s; "
                    "yarn_resistance and contact_resistance are NaN", list(net_probes))
    # separate warp and weft yarn resistors (format 2): four probes or more
    probes3 = (dict(network_probes) if network_probes is not None
               else default_probe_terminals(n_warp, n_weft, weft_probe=True) if min(n_warp, n_weft) >= 2 else {})
    usable3 = [p for p in probes3 if p in pidx]
    if len(usable3) >= 4:
        for idx in zip(*np.nonzero(filled)):
            measured = {p: data["probe_resistance"][idx + (pidx[p],)] for p in usable3}
            rw, rf, rc3, res3 = fit_network3(measured, network, {p: probes3[p] for p in usable3})
            data["yarn_resistance_warp"][idx] = rw
            data["yarn_resistance_weft"][idx] = rf
            data["contact_resistance_warp_weft"][idx] = rc3
            data["network_fit_residual_warp_weft"][idx] = res3
    return net_probes, usable
