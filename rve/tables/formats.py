"""Macro-FE exports of a lookup table: Abaqus, LS-DYNA, curve CSVs, COMSOL, Hermite splines, SPICE.

docs/macro_export.md (§3) records the formats, what each assumes and how each is checked.
Every writer is a thin layer over the table's macro quantities (``rve.tables.macro``):

* :func:`fabric_curves` -- the fabric card curves: warp N_xx vs warp strain (mode
  ``uniaxial``), weft N_yy vs weft strain (``uniaxial_y``; else the warp curve copied, said
  in the header: "symmetric weave"), in-plane shear N_yx vs the angle drop (``trellis``; else
  ``shear``: simple shear, whose warp is also stretched by sqrt(1 + gamma^2) - 1). Pretension
  N(0) removed unless ``keep_pretension``.
* :func:`export_macro` ``(ds, path, fmt, **options)`` -> written paths, ``fmt`` one of
  :data:`MACRO_FORMATS`; options: ``thickness`` (mm or a pint string, default 1 mm),
  ``keep_pretension``, ``modes`` (restrict the curves to these modes), ``params`` (swept
  parameter values: strings select, numbers select or interpolate linearly), ``lcid_start``
  (LS-DYNA curve ids), ``units`` (a consistent unit set of :data:`UNIT_SYSTEMS`; conversion
  through pint, ``rve.config.units.ureg``), ``strain`` (the static SPICE variant's strain),
  ``source`` (the table's path, for the header).
* Readers/evaluators for the round trips: :func:`read_abaqus_curves`,
  :func:`read_lsdyna_curves`, :func:`hermite_eval`, :func:`spice_network_deck`.

Every header states the source (table path, title, rve version, format, creation date),
the units, the BCs (pinned fibril ends: a Dirichlet/KUBC estimate, the stiffer bound), the
strain path of each curve, what was assumed, and the pretension N(0).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Optional, Sequence, Union

import numpy as np
import xarray as xr

from ..io.atomic import atomic_write_text
from .schema import LABEL_DIMS, TABLE_FORMAT

__all__ = ["MACRO_FORMATS", "UNIT_SYSTEMS", "Curve", "fabric_curves", "select_params", "export_macro",
           "hermite_entries", "hermite_eval", "read_abaqus_curves", "read_lsdyna_curves", "spice_network_deck",
           "BCS_TEXT"]

PathLike = Union[str, os.PathLike]

MACRO_FORMATS = ("abaqus", "lsdyna", "curves", "comsol", "hermite", "spice")

#: consistent unit sets: name -> (length, mass, time, force, stress); the table is in the first
UNIT_SYSTEMS = {
    "mm-ms-g-N-MPa": ("mm", "g", "ms", "N", "MPa"),
    "mm-s-t-N-MPa": ("mm", "t", "s", "N", "MPa"),
    "m-s-kg-N-Pa": ("m", "kg", "s", "N", "Pa"),
    "mm-ms-kg-kN-GPa": ("mm", "kg", "ms", "kN", "GPa"),
}

BCS_TEXT = ("BCs: every fibril end pinned to the affine field (a Dirichlet / KUBC estimate of the cell response, "
            "the stiffer bound), directors free")

_PATHS = {
    "uniaxial": "uniaxial: F = I + eps e1 e1 (stretch along the warp x, weft ends held at their y)",
    "uniaxial_y": "uniaxial_y: F = I + eps e2 e2 (stretch along the weft y)",
    "shear": "shear: simple shear F = I + gamma e2 e1, angle drop atan(gamma); the warp is stretched too, "
             "by sqrt(1 + gamma^2) - 1 (3.1 % at gamma = 0.25)",
    "trellis": "trellis: picture-frame shear, both yarn families keep their length, only the angle drops",
}


@dataclass
class Curve:
    """One fabric curve: ``y`` (force per width, table units N mm-1) vs ``x``."""

    key: str                # "warp" | "weft" | "shear"
    component: str          # Abaqus component "1" | "2" | "12"
    name: str               # "N_xx" | "N_yy" | "N_yx"
    x_name: str             # "strain" | "shear_angle"
    x_units: str
    mode: str
    x: np.ndarray
    y: np.ndarray
    pretension: float       # N mm-1 removed from y (0 if kept)
    path: str
    assumption: str = ""
    param: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- selection
def select_params(ds: xr.Dataset, params: Optional[Mapping] = None, allow_free: Sequence[str] = ()) -> xr.Dataset:
    """``ds`` with its swept parameters fixed by ``params`` (string: selected; number:
    selected when stored, else interpolated linearly, ``rve.tables.interpolate``). A swept
    parameter left free is an error unless it is in ``allow_free``."""
    from .interpolate import _interp_dim

    params = dict(params or {})
    swept = [d for d in ds.dims if d not in LABEL_DIMS and d not in ("mode", "strain")]
    for name in params:
        if name not in swept:
            raise ValueError(f"{name!r} is not a swept parameter of the table (swept: {swept})")
    for name, value in params.items():
        if ds[name].dtype.kind in "OSU":
            if str(value) not in [str(v) for v in ds[name].values]:
                raise ValueError(f"{name} {value!r} is not in the table ({list(ds[name].values)})")
            ds = ds.sel({name: str(value)})
        else:
            stored = np.asarray(ds[name].values, float)
            if np.any(stored == float(value)):
                ds = ds.sel({name: float(value)})
            else:
                ds = _interp_dim(ds, name, float(value), "linear", context=f" of {name}")
    free = [d for d in swept if d not in params and d not in allow_free]
    if free:
        raise ValueError(f"the table sweeps {free}: choose values with --param NAME=VALUE "
                         f"({', '.join(f'{d}: {list(ds[d].values)}' for d in free)})")
    return ds


def _mode_states(ds: xr.Dataset, mode: str) -> np.ndarray:
    """Strain indices at which ``mode`` has a state (finite membrane force)."""
    N = ds["membrane_force"].sel(mode=mode)
    other = [d for d in N.dims if d != "strain"]
    return np.nonzero(np.isfinite(N.transpose("strain", *other).values.reshape(N.sizes["strain"], -1)).any(axis=1))[0]


def fabric_curves(ds: xr.Dataset, keep_pretension: bool = False, modes: Optional[Sequence[str]] = None
                  ) -> list[Curve]:
    """The fabric card curves of ``ds`` (swept parameters already fixed; module docstring)."""
    have = [str(m) for m in ds["mode"].values]
    use = [m for m in have if modes is None or m in modes]
    if modes is not None:
        unknown = [m for m in modes if m not in have]
        if unknown:
            raise ValueError(f"mode {unknown[0]!r} is not in the table (modes: {have})")
    N = ds["membrane_force"]
    curves: list[Curve] = []

    def one(key, comp, name, mode, edge, component, xvar, x_name, x_units, assumption=""):
        idx = _mode_states(ds, mode)
        sub = N.sel(mode=mode, edge=edge, component=component).isel(strain=idx)
        y = np.asarray(sub.values, float)
        if xvar == "strain":
            x = np.asarray(ds["strain"].values, float)[idx]
        else:
            x = np.asarray(ds[xvar].sel(mode=mode).isel(strain=idx).values, float)
        n0 = float(ds["membrane_force_at_zero_strain"].sel(mode=mode, edge=edge, component=component))
        if not keep_pretension:
            y = y - n0
        curves.append(Curve(key, comp, name, x_name, x_units, mode, x, y, 0.0 if keep_pretension else n0,
                            _PATHS[mode], assumption))

    if "uniaxial" in use:
        one("warp", "1", "N_xx", "uniaxial", "x", "x", "strain", "strain", "1")
    if "uniaxial_y" in use:
        one("weft", "2", "N_yy", "uniaxial_y", "y", "y", "strain", "strain", "1")
    elif "uniaxial" in use:
        one("weft", "2", "N_yy", "uniaxial", "x", "x", "strain", "strain", "1",
            assumption="symmetric weave: weft curve copied from the warp curve (the table has no uniaxial_y mode)")
    shear_mode = "trellis" if "trellis" in use else ("shear" if "shear" in use else None)
    if shear_mode:
        one("shear", "12", "N_yx", shear_mode, "x", "y", "shear_angle", "shear_angle", "rad",
            assumption="" if shear_mode == "trellis" else
            "shear curve from simple shear (no trellis mode in the table): the warp is also stretched")
    if not curves:
        raise ValueError(f"no fabric curve: the table's modes {have} (selected: {use}) have no uniaxial, "
                         "uniaxial_y, shear or trellis data")
    return curves


# --------------------------------------------------------------------------- units
def _factor(from_unit: str, to_unit: str) -> float:
    from ..config.units import ureg

    return float(ureg.Quantity(1.0, from_unit).to(to_unit).magnitude)


def _unit_set(units: Optional[str]):
    name = units or "mm-ms-g-N-MPa"
    if name not in UNIT_SYSTEMS:
        raise ValueError(f"unknown unit set {name!r} (known: {', '.join(UNIT_SYSTEMS)})")
    L, M, T, F, S = UNIT_SYSTEMS[name]
    # display strings in UDUNITS syntax (as the table's); conversions use the pint forms
    return name, {"length": L, "mass": M, "time": T, "force": F, "stress": S,
                  "force_per_length": f"{F} {L}-1", "density": f"{M} {L}-3", "areal_density": f"{M} {L}-2"}


def _thickness_mm(thickness) -> float:
    from ..config.units import convert

    t = 1.0 if thickness is None else convert(thickness, "mm")
    if not t > 0:
        raise ValueError(f"thickness must be positive, got {thickness!r}")
    return t


# --------------------------------------------------------------------------- headers
def _header(ds: xr.Dataset, curves: Sequence[Curve], opts: dict, extra: Sequence[str] = ()) -> list[str]:
    a = ds.attrs
    lines = [f"rve lookup-table export ({opts['fmt']}), from {opts.get('source') or 'a table'}",
             f"table: {a.get('title', '?')}; format {a.get('rve_table_format', TABLE_FORMAT)}; "
             f"rve {a.get('rve_version', '?')}; created {a.get('date_created', '?')}",
             f"units ({opts['units_name']}): " + ", ".join(f"{k} {v}" for k, v in opts["units"].items()
                                                          if k in ("length", "mass", "time", "force", "stress")),
             BCS_TEXT]
    if opts.get("params"):
        lines.append("swept parameters fixed: " + ", ".join(f"{k}={v}" for k, v in opts["params"].items()))
    for c in curves:
        n0 = c.pretension * opts["fpl"]
        lines.append(f"curve {c.key} ({c.name}, component {c.component}) from mode {c.mode}: {c.path}; "
                     + (f"pretension N(0) = {n0:.6e} {opts['units']['force_per_length']} removed"
                        if not opts.get("keep_pretension") else "pretension kept (N(0) is the first value)"))
        if c.assumption:
            lines.append(f"assumed: {c.assumption}")
    lines.extend(extra)
    return lines


def _options(ds, fmt, thickness=None, keep_pretension=False, units=None, params=None, source=None) -> dict:
    name, us = _unit_set(units)
    t = _thickness_mm(thickness)
    return {"fmt": fmt, "units_name": name, "units": us, "thickness_mm": t,
            "thickness": t * _factor("mm", us["length"]),
            "fpl": _factor("N/mm", f"{us['force']}/{us['length']}"), "stress": _factor("N/mm**2", us["stress"]),
            "areal": _factor("g/mm**2", f"{us['mass']}/{us['length']}**2"),
            "keep_pretension": keep_pretension, "params": dict(params or {}), "source": source}


def _e(v: float, digits: int) -> str:
    return f"{v:.{digits}e}"


# --------------------------------------------------------------------------- abaqus
ABAQUS_DIGITS = 10  # significant digits on a data line


def _abaqus(ds, curves, opts, path: Path) -> list[Path]:
    t = opts["thickness"]
    rho_a = float(ds["areal_density"]) * opts["areal"]
    d = ABAQUS_DIGITS - 1
    head = _header(ds, curves, opts, [
        f"stress = N / t with t = {opts['thickness_mm']:g} mm: use the same thickness on the section; strain "
        "nominal; shear: stress vs the angle drop in rad",
        "format as documented in docs/macro_export.md (confirm against the Abaqus manual: component numbering "
        "1 warp, 2 weft, 12 shear; the order stress, strain on a data line)"])
    lines = ["** " + h for h in head]
    lines += ["*MATERIAL, NAME=RVE_FABRIC", "*DENSITY",
              (f"{_e(rho_a / t, d)}," if math.isfinite(rho_a) else "** areal density not recorded in the table"),
              "*FABRIC"]
    if not math.isfinite(rho_a):
        lines[-3] = "** *DENSITY: areal density not recorded in the table"
        lines.pop(-2)
    for c in curves:
        lines += [f"** {c.key}: {c.name} / t vs {c.x_name} [{c.x_units}]",
                  f"*UNIAXIAL, COMPONENT={c.component}", "*LOADING DATA"]
        for x, y in zip(c.x, c.y):
            lines.append(f"{_e(y * opts['fpl'] / t, d)}, {_e(x, d)}")
    atomic_write_text(path, "\n".join(lines) + "\n")
    return [path]


def read_abaqus_curves(path: PathLike) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Component -> (strain, stress) arrays from an ``abaqus`` export (``**`` comments skipped)."""
    out: dict[str, list] = {}
    comp = None
    for line in Path(path).read_text().splitlines():
        if line.startswith("**") or not line.strip():
            continue
        if line.startswith("*"):
            kw = line.upper().replace(" ", "")
            comp = kw.split("COMPONENT=")[1].split(",")[0] if kw.startswith("*UNIAXIAL") else \
                (comp if kw.startswith("*LOADING") else None)
            continue
        if comp is not None:
            s, e = (float(v) for v in line.split(",")[:2])
            out.setdefault(comp, []).append((e, s))
    return {k: (np.array([p[0] for p in v]), np.array([p[1] for p in v])) for k, v in out.items()}


# --------------------------------------------------------------------------- ls-dyna
LSDYNA_DIGITS = 13  # significant digits in a 20-character data field


def _f10(v) -> str:
    s = str(v) if isinstance(v, (int, np.integer, str)) else f"{v:.4g}"
    if len(s) > 10:
        raise ValueError(f"LS-DYNA field {s!r} is wider than 10 characters")
    return f"{s:>10}"


def _f20(v: float) -> str:
    return f"{v:20.{LSDYNA_DIGITS - 1}e}"


def _lsdyna_curve(lcid: int, title: str, x, y) -> list[str]:
    lines = ["*DEFINE_CURVE_TITLE", title[:80],
             "$#    lcid      sidr       sfa       sfo      offa      offo    dattyp     lcint",
             "".join(_f10(v) for v in (lcid, 0, 1.0, 1.0, 0.0, 0.0, 0, 0)),
             "$#                a1                  o1"]
    lines += [_f20(a) + _f20(o) for a, o in zip(x, y)]
    return lines


def _lsdyna(ds_all, params, opts, path: Path, lcid_start: int, keep_pretension, modes) -> list[Path]:
    swept = [d for d in ds_all.dims if d not in LABEL_DIMS and d not in ("mode", "strain")]
    free = [d for d in swept if d not in params]
    num_free = [d for d in free if ds_all[d].dtype.kind not in "OSU"]
    if len(num_free) > 1 or len(free) > len(num_free):
        raise ValueError(f"lsdyna: one free numeric swept parameter at most (a *DEFINE_TABLE_2D); fix {free} "
                         "with --param NAME=VALUE")
    ds = select_params(ds_all, params, allow_free=num_free)
    t = opts["thickness"]
    sets = [(None, ds)] if not num_free else [(float(v), ds.sel({num_free[0]: v})) for v in ds[num_free[0]].values]
    curves0 = fabric_curves(sets[0][1], keep_pretension, modes)
    extra = [f"stress = N / t (t = {opts['thickness_mm']:g} mm, set the same shell thickness): engineering "
             "(nominal, first-Piola) stress vs engineering strain; shear vs the angle drop in rad (confirm: "
             "*MAT_FABRIC FORM=14 curve conventions)",
             "cards: card 1 of *DEFINE_CURVE_TITLE in 8 fields of 10 characters, data in 2 fields of 20"]
    if num_free:
        extra.append(f"*DEFINE_TABLE_2D per direction over {num_free[0]} "
                     f"[{ds[num_free[0]].attrs.get('units', '')}] = {list(ds[num_free[0]].values)}")
    lines = ["$ " + h for h in _header(ds, curves0, opts, extra)] + ["*KEYWORD"]
    lcid = int(lcid_start)
    ids: dict[str, list[int]] = {}
    for value, sub in sets:
        for c in fabric_curves(sub, keep_pretension, modes):
            tag = f"{c.key} {c.name}/t vs {c.x_name}" + (f" at {num_free[0]}={value:g}" if value is not None else "")
            lines += _lsdyna_curve(lcid, tag, c.x, c.y * opts["fpl"] / t)
            ids.setdefault(c.key, []).append(lcid)
            lcid += 1
    lc = {k: v[0] for k, v in ids.items()}
    if num_free:
        for k, v in ids.items():
            lines += ["*DEFINE_TABLE_2D", f"{k} curves over {num_free[0]}",
                      "$#    tbid       sfa      offa", "".join(_f10(x) for x in (lcid, 1.0, 0.0)),
                      "$#               value             curveid"]
            lines += [_f20(float(val)) + f"{cid:>20d}" for (val, _), cid in zip(sets, v)]
            lc[k] = lcid
            lcid += 1
    rho = float(ds["areal_density"]) * opts["areal"] / t
    lines += ["$ *MAT_FABRIC skeleton (FORM=14): fill the other fields; LCA warp, LCB weft, LCAB shear",
              "$*MAT_FABRIC_TITLE", "$rve_fabric",
              "$#     mid        ro        ea        eb      (ec)      prba    (prca)    (prcb)",
              "$" + _f10(1)[1:] + (_f10(float(f"{rho:.4g}")) if math.isfinite(rho) else _f10("rho?")),
              "$#     gab      (gbc)     (gca)     cse        el      prl    lratio     damp",
              "$#    aopt       flc        fac      ela      lnrc      form      fvopt   tsrfac",
              "$" + _f10(0)[1:] + _f10(0) + _f10(0) + _f10(0) + _f10(0) + _f10(14),
              "$#     lca       lcb      lcab",
              "$" + "".join(_f10(lc.get(k, 0)) for k in ("warp", "weft", "shear"))[1:],
              "*END"]
    atomic_write_text(path, "\n".join(lines) + "\n")
    return [path]


def read_lsdyna_curves(path: PathLike) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """LCID -> (abscissa, ordinate) of every *DEFINE_CURVE[_TITLE] of an ``lsdyna`` export,
    read by the fixed field widths (card 1: 10 characters, data: 20)."""
    out: dict[int, tuple] = {}
    lines = [ln for ln in Path(path).read_text().splitlines() if not ln.startswith("$")]
    k = 0
    while k < len(lines):
        ln = lines[k]
        if ln.startswith("*DEFINE_CURVE"):
            k += 1
            if ln.startswith("*DEFINE_CURVE_TITLE"):
                k += 1
            lcid = int(lines[k][:10])
            k += 1
            xs, ys = [], []
            while k < len(lines) and not lines[k].startswith("*"):
                xs.append(float(lines[k][:20]))
                ys.append(float(lines[k][20:40]))
                k += 1
            out[lcid] = (np.array(xs), np.array(ys))
        else:
            k += 1
    return out


# --------------------------------------------------------------------------- curves, comsol
def _curves_csv(ds, curves, opts, path: Path) -> list[Path]:
    written = []
    if not path.suffix:  # a folder: <folder>/<curve>.csv
        path.mkdir(parents=True, exist_ok=True)
    for c in curves:
        out = path / f"{c.key}.csv" if not path.suffix else path.with_name(f"{path.stem}.{c.key}{path.suffix}")
        head = " | ".join(_header(ds, [c], opts))
        lines = [f"# {head}", f"{c.x_name} [{c.x_units}],{c.name} [{opts['units']['force_per_length']}]"]
        lines += [f"{x!r},{y * opts['fpl']!r}" for x, y in zip(c.x.tolist(), c.y.tolist())]
        atomic_write_text(out, "\n".join(lines) + "\n")
        written.append(out)
    return written


def _comsol(ds, curves, opts, path: Path) -> list[Path]:
    grids = [np.asarray(ds["strain"].values, float)[_mode_states(ds, c.mode)] for c in curves]
    common = sorted(set(grids[0].tolist()).intersection(*[set(g.tolist()) for g in grids[1:]]))
    lines = ["% " + h for h in _header(ds, curves, opts, [
        "COMSOL spreadsheet (interpolation function): column 1 the argument = the table's strain coordinate "
        "(uniaxial / uniaxial_y: nominal strain; shear: gamma; trellis: the angle drop in rad), then one column "
        "per function; each function's own abscissa is named below",
        f"force per width in {opts['units']['force_per_length']}"])]
    for k, c in enumerate(curves, start=2):
        lines.append(f"% column {k}: {c.name} ({c.key}, mode {c.mode}; strain measure {c.x_name})")
    lines.append("% strain " + " ".join(c.name for c in curves))
    strains = np.asarray(ds["strain"].values, float)
    for s in common:
        row = [s]
        for c, g in zip(curves, grids):
            row.append(float(c.y[list(g).index(s)]) * opts["fpl"])
        lines.append(" ".join(repr(float(v)) for v in row))
    del strains
    atomic_write_text(path, "\n".join(lines) + "\n")
    return [path]


# --------------------------------------------------------------------------- hermite
#: per-mode scalar quantities a macro model evaluates vs strain (besides the fabric curves)
HERMITE_EXTRA = ("yarn_resistance", "yarn_resistance_warp", "yarn_resistance_weft", "contact_resistance",
                 "yarn_sheet_conductance", "contact_exchange_conductance", "busbar_sheet_resistance",
                 "transfer_length")


def _pchip_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Knot slopes of the curve ``rve.tables.interpolate(..., method="cubic")`` evaluates:
    PCHIP (scipy) for 3+ points, the secant for 2 (that method is linear there)."""
    if len(x) == 1:
        return np.zeros(1)
    if len(x) == 2:
        s = (y[1] - y[0]) / (x[1] - x[0])
        return np.array([s, s])
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(x, y).derivative()(x)


def hermite_entries(ds: xr.Dataset, curves: Sequence[Curve], opts: dict) -> list[dict]:
    """The spline entries of the ``hermite`` export (knots ``t``, values ``p``, slopes ``m``)."""
    entries = []
    for c in curves:
        y = c.y * opts["fpl"]
        strain = np.asarray(ds["strain"].values, float)[_mode_states(ds, c.mode)]
        entries.append({"name": c.name, "curve": c.key, "mode": c.mode, "argument": "strain",
                        "argument_units": "1", "argument_meaning": f"the mode's strain coordinate ({c.path})",
                        "strain_measure": c.x_name, "strain_measure_values": c.x.tolist(),
                        "units": opts["units"]["force_per_length"], "pretension": c.pretension * opts["fpl"],
                        "t": strain.tolist(), "p": y.tolist(), "m": _pchip_slopes(strain, y).tolist()})
    for name in HERMITE_EXTRA:
        if name not in ds:
            continue
        var = ds[name]
        for mode in [str(m) for m in ds["mode"].values]:
            idx = _mode_states(ds, mode)
            sub = var.sel(mode=mode).isel(strain=idx)
            labels = [d for d in sub.dims if d != "strain"]
            for lab in np.ndindex(*[sub.sizes[d] for d in labels]):
                one = sub.isel(dict(zip(labels, lab))) if labels else sub
                y = np.asarray(one.values, float)
                if not np.all(np.isfinite(y)):
                    continue
                tag = "".join(f"[{sub[d].values[i]}]" for d, i in zip(labels, lab))
                x = np.asarray(ds["strain"].values, float)[idx]
                entries.append({"name": name + tag, "mode": mode, "argument": "strain", "argument_units": "1",
                                "units": var.attrs.get("units", ""), "t": x.tolist(), "p": y.tolist(),
                                "m": _pchip_slopes(x, y).tolist()})
    return entries


def hermite_eval(entry: Mapping, xq) -> np.ndarray:
    """Evaluate a ``hermite`` entry (knots t, values p, slopes m) at ``xq`` (within [t0, tn])."""
    t, p, m = (np.asarray(entry[k], float) for k in ("t", "p", "m"))
    xq = np.asarray(xq, float)
    if len(t) == 1:
        return np.full(xq.shape, p[0])
    i = np.clip(np.searchsorted(t, xq, side="right") - 1, 0, len(t) - 2)
    h = t[i + 1] - t[i]
    s = (xq - t[i]) / h
    h00, h10 = (1 + 2 * s) * (1 - s) ** 2, s * (1 - s) ** 2
    h01, h11 = s * s * (3 - 2 * s), s * s * (s - 1)
    out = h00 * p[i] + h10 * h * m[i] + h01 * p[i + 1] + h11 * h * m[i + 1]
    exact = np.isin(xq, t)
    out[exact] = p[np.searchsorted(t, xq[exact])]
    return out


def _hermite(ds, curves, opts, path: Path) -> list[Path]:
    doc = {"format": "rve-hermite/1", "header": _header(ds, curves, opts, [
               "cubic Hermite splines: on [t_i, t_i+1] with s = (x - t_i)/h, h = t_i+1 - t_i: "
               "p_i h00(s) + h m_i h10(s) + p_i+1 h01(s) + h m_i+1 h11(s) (field names as HYLC's 1-D entries); "
               "slopes m are those of rve.tables.interpolate(method='cubic') (monotone PCHIP)",
               *_network_fit_line(ds)]),
           "table_format": ds.attrs.get("rve_table_format", TABLE_FORMAT),
           "units": opts["units"], "entries": hermite_entries(ds, curves, opts)}
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    return [path]


def _network_fit_line(ds: xr.Dataset) -> list[str]:
    """The header line naming the network fit of the sheet parameters (and of the SPICE cell)."""
    if "contact_resistance" not in ds or "yarn_resistance" not in ds:
        return []
    from .macro import sheet_network_parameters

    return [f"network fit of the sheet parameters g, c (and of the SPICE cell): "
            f"{sheet_network_parameters(ds).attrs['network_fit']} (docs/macro_export.md §1)"]


# --------------------------------------------------------------------------- spice
SPICE_OPTIONS = ".options reltol=1e-9 abstol=1e-15 vntol=1e-12"


def _spice_resistances(ds: xr.Dataset, mode: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(strains, R_yw, R_yf, R_c) of ``mode``: the network fit of the sheet parameters
    (``rve.tables.macro.sheet_network_parameters``: the warp/weft fit where it has values,
    else the two-resistor fit), never R_y of one fit with R_c of the other."""
    from .macro import sheet_network_parameters

    idx = _mode_states(ds, mode)
    x = np.asarray(ds["strain"].values, float)[idx]
    net = sheet_network_parameters(ds).sel(mode=mode).isel(strain=idx)
    ry = np.asarray(net["yarn_resistance"].transpose("strain", "yarn").values, float)
    rw, rf = ry[:, 0], ry[:, 1]
    rc = np.asarray(net["contact_resistance"].values, float)
    if not (np.all(np.isfinite(rc)) and np.all(np.isfinite(rw)) and np.all(np.isfinite(rf))):
        raise ValueError(f"spice: the table has no fitted network resistances for mode {mode!r}")
    return x, rw, rf, rc


def _pwl(x, y) -> str:
    return ", ".join(f"{a!r}, {b!r}" for a, b in zip(x.tolist(), y.tolist()))


def _spice(ds, opts, path: Path, mode: str, strain: float) -> list[Path]:
    x, rw, rf, rc = _spice_resistances(ds, mode)
    head = _header(ds, [], opts, [
        *_network_fit_line(ds),
        f"one crossing cell of the network model (docs/lookup_tables.md): warp yarn w0-w1 (R_yw), weft yarn f0-f1 "
        f"(R_yf), four contacts R_c (w0, w1 to f0, f1); R(strain) of mode {mode} ({_PATHS.get(mode, mode)}), "
        "piecewise linear in the strain, read as the voltage of node 'strain' (1 V = strain 1)",
        f"use with: {SPICE_OPTIONS} (default tolerances give errors up to 1e-4)"])
    lines = ["* " + h for h in head]
    lines += [".subckt rve_cell w0 w1 f0 f1 strain",
              f"Byw w0 w1 I = V(w0, w1) / pwl(V(strain), {_pwl(x, rw)})",
              f"Byf f0 f1 I = V(f0, f1) / pwl(V(strain), {_pwl(x, rf)})"]
    for k, (a, b) in enumerate((("w0", "f0"), ("w0", "f1"), ("w1", "f0"), ("w1", "f1"))):
        lines.append(f"Bc{k} {a} {b} I = V({a}, {b}) / pwl(V(strain), {_pwl(x, rc)})")
    lines += [".ends rve_cell"]
    atomic_write_text(path, "\n".join(lines) + "\n")
    # static variant: plain R elements at one strain (linear interpolation, as pwl)
    if not (x[0] <= strain <= x[-1]):
        raise ValueError(f"spice: strain {strain:g} outside the table range [{x[0]:g}, {x[-1]:g}] of mode {mode!r}")
    r = [float(np.interp(strain, x, v)) for v in (rw, rf, rc)]
    spath = path.with_name(f"{path.stem}.static{path.suffix or '.cir'}")
    lines = ["* " + h for h in head[:-2]] + [  # without the pwl cell and the options lines
        f"* static variant: mode {mode} at strain {strain!r} (linear between the stored strains)",
        ".subckt rve_cell_static w0 w1 f0 f1",
        f"Ryw w0 w1 {r[0]!r}", f"Ryf f0 f1 {r[1]!r}",
        f"Rc0 w0 f0 {r[2]!r}", f"Rc1 w0 f1 {r[2]!r}", f"Rc2 w1 f0 {r[2]!r}", f"Rc3 w1 f1 {r[2]!r}",
        ".ends rve_cell_static"]
    atomic_write_text(spath, "\n".join(lines) + "\n")
    return [path, spath]


def spice_network_deck(cell_file: PathLike, n_warp: int, n_weft: int, plus, minus, strain: float = 0.0,
                       static: bool = False, voltage: float = 1.0) -> str:
    """A top-level ngspice deck: the ``n_warp x n_weft`` cells of ``rve.homogenisation.network.YarnNetwork``
    from the exported subcircuit, ``voltage`` across the yarn ends ``plus`` - ``minus``
    ((direction, index, '+'|'-')), the strain node at ``strain``; prints the source current
    (``i(vp)``) by ``.op``."""
    def wn(j, i):
        return f"w{j}_{i}"

    def fn(i, j):
        return f"f{i}_{j}"

    def end(t):
        d, k, e = t
        return wn(k, n_weft if e == "+" else 0) if d == "warp" else fn(k, n_warp if e == "+" else 0)

    sub = "rve_cell_static" if static else "rve_cell"
    lines = ["* rve network deck", f".include {Path(cell_file).resolve()}", SPICE_OPTIONS]
    if not static:
        lines.append(f"Vs strain 0 {strain!r}")
    k = 0
    for j in range(n_warp):
        for i in range(n_weft):
            nodes = f"{wn(j, i)} {wn(j, i + 1)} {fn(i, j)} {fn(i, j + 1)}"
            lines.append(f"X{k} {nodes} {'' if static else 'strain '}{sub}".replace("  ", " "))
            k += 1
    lines += [f"Vp {end(plus)} 0 {voltage!r}", f"Vm {end(minus)} 0 0",
              ".control", "set numdgt=15", "op", "print i(vp)", ".endc", ".end"]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- entry point
def export_macro(ds: xr.Dataset, path: PathLike, fmt: str, *, thickness=None, keep_pretension: bool = False,
                 modes: Optional[Sequence[str]] = None, params: Optional[Mapping] = None, lcid_start: int = 1001,
                 units: Optional[str] = None, strain: float = 0.0, source: Optional[str] = None) -> list[Path]:
    """Write the macro export ``fmt`` (:data:`MACRO_FORMATS`) of ``ds`` to ``path``; returns
    the written paths (module docstring for the options)."""
    fmt = fmt.lower()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if "membrane_force" not in ds:
        from .macro import add_macro_quantities

        ds = add_macro_quantities(ds)
    opts = _options(ds, fmt, thickness, keep_pretension, units, params, source)
    if fmt == "lsdyna":
        return _lsdyna(ds, dict(params or {}), opts, path, lcid_start, keep_pretension, modes)
    sub = select_params(ds, params)
    if fmt == "spice":
        mode = (modes or ["uniaxial"])[0]
        if mode not in [str(m) for m in sub["mode"].values]:
            raise ValueError(f"mode {mode!r} is not in the table")
        return _spice(sub, opts, path, mode, float(strain))
    curves = fabric_curves(sub, keep_pretension, modes)
    writer = {"abaqus": _abaqus, "curves": _curves_csv, "comsol": _comsol, "hermite": _hermite}.get(fmt)
    if writer is None:
        raise ValueError(f"unknown macro export format {fmt!r} (known: {', '.join(MACRO_FORMATS)})")
    return writer(sub, curves, opts, path)
