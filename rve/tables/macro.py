"""Macro quantities of a lookup table, derived once from its stored variables (``add_macro_quantities``).

docs/macro_export.md §1 records what they are and why; every export (``rve.tables.formats``)
is a thin layer over them. Input: a table Dataset (``rve.tables.build``, or a version-1
table from ``rve.tables.open_table``); output: the same Dataset with these additions
(existing variables untouched):

=============================  ======================================  ==========
cell_length_x, cell_length_y   scalar coordinates (RVE box edges)      mm
yarn_pitch                     scalar coordinate (yarn spacing)        mm
membrane_force                 (mode, strain, *swept, edge, component)  N mm-1
membrane_force_at_zero_strain  (mode, *swept, edge, component)         N mm-1
side_force_imbalance           (mode, strain, *swept, edge)            N
yarn_strain                    (mode, strain, *swept, yarn)            1
shear_angle                    (mode, strain, *swept)                  rad
areal_density                  (*swept) or scalar                      g mm-2
gauge_factor                   (mode, strain, *swept, probe)           1
yarn_sheet_conductance         (mode, strain, *swept, yarn)            S
contact_exchange_conductance   (mode, strain, *swept)                  S mm-2
busbar_sheet_resistance        (mode, strain, *swept, yarn)            ohm
transfer_length                (mode, strain, *swept, yarn)            mm
=============================  ======================================  ==========

Definitions (docs/macro_export.md):

* ``membrane_force[edge=e, component=i]`` = F_i(e+) / L_e: the clamp reaction force on
  the + side of edge e (x: ``warp+``/``x+``, y: ``weft+``/``y+``) over that edge's
  reference length (edge x has length ``cell_length_y``); first-Piola force per unit
  reference width. N_xx = [x, x], N_yy = [y, y], the shear resultant N_yx = [x, y].
  Sign: as ``reaction_force`` (the table's clamp force on the + side).
* ``side_force_imbalance[edge]`` = |F(e-) + F(e+)| (Euclidean, N): a check, ~0.
* ``yarn_strain`` (warp, weft) and ``shear_angle`` (NaN where the table has no state) (angle drop between the yarn families,
  rad) follow from the mode's affine deformation F (``strain_path`` in each mode's
  long_name): uniaxial F = I + eps e1 e1 (warp eps, weft 0, angle 0); uniaxial_y
  F = I + eps e2 e2; shear (simple) F = I + gamma e2 e1: warp sqrt(1 + gamma^2) - 1, weft
  0, angle atan(gamma); trellis (picture frame, strain = the angle drop in rad): yarn
  strains 0, angle = strain.
* ``areal_density`` = sum over fibrils of reference length x pi R^2 x rho / (L_x L_y), from
  the fabric attribute's ``fibril_mass_g`` (NaN for a table that does not record it).
* ``gauge_factor`` = (R(eps) - R(0)) / (R(0) eps) per probe and mode (NaN at eps = 0).
* Two-potential sheet model: g = 1/R_y + 1/R_c (S), c = 4 / (R_c a^2) (S mm-2, a = the yarn
  pitch), bus-bar sheet resistance 1/g (ohm per reference square), transfer length
  sqrt(g / 2c) (mm), per yarn family (``yarn`` dimension): with the warp/weft fit
  (``yarn_resistance_warp``, ``yarn_resistance_weft``, ``contact_resistance_warp_weft``)
  where it has values, else the two-resistor fit for both families.
"""
from __future__ import annotations

import json
import math
from typing import Optional

import numpy as np
import xarray as xr

from .schema import DIMENSIONLESS, EDGES, VARIABLES, YARNS

#: the variables a state stores (rve.tables.schema.VARIABLES): their values mark the states
STORED_VARIABLES = tuple(VARIABLES)

__all__ = ["add_macro_quantities", "mode_deformation", "yarn_strain_and_angle", "cell_geometry",
           "sheet_network_parameters", "MACRO_VARIABLES"]

#: the variables add_macro_quantities writes (in this order)
MACRO_VARIABLES = ("membrane_force", "membrane_force_at_zero_strain", "side_force_imbalance", "yarn_strain",
                   "shear_angle", "areal_density", "gauge_factor", "yarn_sheet_conductance",
                   "contact_exchange_conductance", "busbar_sheet_resistance", "transfer_length")

_PLUS = {"x": ("warp+", "x+"), "y": ("weft+", "y+")}
_MINUS = {"x": ("warp-", "x-"), "y": ("weft-", "y-")}


def mode_deformation(mode: str, strain) -> np.ndarray:
    """In-plane deformation gradient F (..., 2, 2) of ``mode`` at ``strain`` (module docstring)."""
    e = np.asarray(strain, dtype=float)
    F = np.zeros(e.shape + (2, 2))
    F[..., 0, 0] = F[..., 1, 1] = 1.0
    if mode == "uniaxial":
        F[..., 0, 0] += e
    elif mode == "uniaxial_y":
        F[..., 1, 1] += e
    elif mode == "shear":
        F[..., 1, 0] = e
    elif mode == "trellis":
        c, s = np.cos(e / 2.0), np.sin(e / 2.0)
        F[..., 0, 0] = F[..., 1, 1] = c
        F[..., 0, 1] = F[..., 1, 0] = s
    else:
        raise ValueError(f"unknown mode {mode!r}")
    return F


def yarn_strain_and_angle(mode: str, strain) -> tuple[np.ndarray, np.ndarray]:
    """(yarn strains (..., 2) warp/weft, angle drop (...)) of ``mode`` at ``strain``:
    |F e_i| - 1 and pi/2 - angle(F e1, F e2)."""
    F = mode_deformation(mode, strain)
    a, b = F[..., :, 0], F[..., :, 1]
    la, lb = np.linalg.norm(a, axis=-1), np.linalg.norm(b, axis=-1)
    strains = np.stack([la - 1.0, lb - 1.0], axis=-1)
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    dot = np.sum(a * b, axis=-1)
    angle = np.pi / 2.0 - np.arctan2(cross, dot)
    if mode in ("uniaxial", "uniaxial_y"):
        angle = np.zeros_like(angle)
    elif mode == "shear":
        angle = np.arctan(np.asarray(strain, dtype=float))  # exact: atan(gamma)
    elif mode == "trellis":
        angle = np.array(strain, dtype=float)
        strains = np.zeros_like(strains)  # both families keep their length (exactly)
    return strains, angle


def _fabric(ds: xr.Dataset) -> dict:
    try:
        return json.loads(ds.attrs.get("fabric", "{}")) or {}
    except (TypeError, ValueError):
        return {}


def cell_geometry(ds: xr.Dataset) -> tuple[float, float, float]:
    """(cell_length_x, cell_length_y, yarn_pitch) in mm from the ``fabric`` attribute:
    2 x half_widths when recorded, else yarn counts x spacing (NaN if unknown)."""
    fab = _fabric(ds)
    pitch = float(fab.get("spacing", math.nan))
    hw = fab.get("half_widths")
    if hw is not None and len(hw) >= 2:
        lx, ly = 2.0 * float(hw[0]), 2.0 * float(hw[1])
    else:
        lx = float(fab.get("n_weft", math.nan)) * pitch
        ly = float(fab.get("n_warp", math.nan)) * pitch
    return lx, ly, pitch


def _side_index(ds: xr.Dataset, names) -> Optional[int]:
    sides = [str(s) for s in ds["side"].values]
    return next((sides.index(n) for n in names if n in sides), None)


def _var(dims, data, units, long_name, **extra) -> xr.Variable:
    return xr.Variable(dims, data, attrs={"units": units, "long_name": long_name, **extra})


def sheet_network_parameters(ds: xr.Dataset) -> xr.Dataset:
    """The network parameters of the two-potential sheet model, one choice per state that
    the sheet parameters (``yarn_sheet_conductance`` ...) and any resistor network of the
    same patch must share (docs/macro_export.md §1, "Which network fit"):

    * ``yarn_resistance`` (*state dims, yarn) [ohm]: R_y of the warp and of the weft yarn
      across one cell; ``contact_resistance`` (*state dims) [ohm]: R_c;
    * ``warp_weft_fit`` (*state dims, bool): True where they are the warp/weft fit
      (``yarn_resistance_warp``, ``yarn_resistance_weft``, ``contact_resistance_warp_weft``,
      four probes or more), False where that fit has no value (a version-1 or 3-probe
      table) and the two-resistor fit (``yarn_resistance``, ``contact_resistance``) stands
      for both families;
    * attribute ``network_fit``: "warp/weft fit (R_yw, R_yf, R_c)", "two-resistor fit
      (R_y, R_c)" or "mixed: ..." over the states that have values.

    The state dims are those of ``contact_resistance`` (mode, strain, *swept)."""
    Ry2, Rc2 = ds["yarn_resistance"], ds["contact_resistance"]
    dims = Rc2.dims
    ry = np.stack([Ry2.transpose(*dims).values, Ry2.transpose(*dims).values], axis=-1)
    rc = Rc2.values.copy()
    ok = np.zeros(Rc2.shape, bool)
    if all(k in ds for k in ("yarn_resistance_warp", "yarn_resistance_weft", "contact_resistance_warp_weft")):
        r3 = np.stack([ds["yarn_resistance_warp"].transpose(*dims).values,
                       ds["yarn_resistance_weft"].transpose(*dims).values], axis=-1)
        rc3 = ds["contact_resistance_warp_weft"].transpose(*dims).values
        ok = np.isfinite(r3).all(axis=-1) & np.isfinite(rc3)
        ry = np.where(ok[..., None], r3, ry)
        rc = np.where(ok, rc3, rc)
    has = np.isfinite(rc) & np.isfinite(ry).all(axis=-1)
    three, two = "warp/weft fit (R_yw, R_yf, R_c)", "two-resistor fit (R_y, R_c)"
    if not has.any() or not ok[has].any():
        which = two
    elif ok[has].all():
        which = three
    else:
        which = f"mixed: {three} at {int(ok[has].sum())} states, {two} at {int((~ok[has]).sum())}"
    coords = {k: v for k, v in Rc2.coords.items() if set(v.dims) <= set(dims)}
    out = xr.Dataset(
        {"yarn_resistance": (dims + ("yarn",), ry, {"units": "ohm", "long_name": "R_y of the sheet model's network"}),
         "contact_resistance": (dims, rc, {"units": "ohm", "long_name": "R_c of the sheet model's network"}),
         "warp_weft_fit": (dims, ok, {"long_name": "True: the warp/weft fit; False: the two-resistor fit"})},
        coords=coords)
    out.coords["yarn"] = ("yarn", np.array(YARNS, dtype=object))
    out.attrs["network_fit"] = which
    return out


def add_macro_quantities(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with the macro quantities of the module docstring added (a new Dataset;
    the stored variables are not touched). Quantities whose inputs are missing are NaN."""
    ds = ds.copy()
    lead = [d for d in ds["reaction_force"].dims if d not in ("side", "component")]
    lx, ly, pitch = cell_geometry(ds)
    ds.coords["cell_length_x"] = _var((), lx, "mm", "reference length of the RVE box along x (warp direction)")
    ds.coords["cell_length_y"] = _var((), ly, "mm", "reference length of the RVE box along y (weft direction)")
    ds.coords["yarn_pitch"] = _var((), pitch, "mm", "reference yarn spacing a (warp and weft)")
    ds.coords["edge"] = _var(("edge",), np.array(EDGES, dtype=object), DIMENSIONLESS,
                             "edge of the RVE box by its reference normal (x: the x+ / warp+ side, "
                             "y: the y+ / weft+ side)")
    ds.coords["yarn"] = _var(("yarn",), np.array(YARNS, dtype=object), DIMENSIONLESS,
                             "yarn family (warp along x, weft along y)")

    strains = np.asarray(ds["strain"].values, float)
    zero = np.nonzero(strains == 0.0)[0]
    _add_membrane_force(ds, lead, lx, ly, strains, zero)
    _add_strain_measures(ds, lead, strains)
    # --- areal density
    fab = _fabric(ds)
    mass = fab.get("fibril_mass_g")
    rho_a = float(mass) / (lx * ly) if mass is not None else math.nan
    ds["areal_density"] = _var((), rho_a, "g mm-2",
                               "areal density: sum of fibril reference length x pi R^2 x rho over the cell area")

    # --- gauge factor
    if "probe_resistance" in ds:
        R = ds["probe_resistance"]
        R0 = (R.isel(strain=int(zero[0])) if zero.size else R.isel(strain=0) * np.nan).drop_vars("strain")
        eps = xr.DataArray(np.where(strains == 0.0, np.nan, strains), dims=("strain",))
        gf = ((R - R0) / (R0 * eps)).transpose(*R.dims)
        ds["gauge_factor"] = _var(R.dims, gf.values, DIMENSIONLESS,
                                  "gauge factor (R(eps) - R(0)) / (R(0) eps) of the probe, eps the mode's strain "
                                  "coordinate (NaN at eps = 0)")

    _add_sheet_parameters(ds, pitch)
    return ds


def _add_membrane_force(ds, lead, lx, ly, strains, zero) -> None:
    """``membrane_force``, its value at zero strain and ``side_force_imbalance``."""
    F = ds["reaction_force"].transpose(*lead, "side", "component").values
    shape = F.shape[:-2]
    N = np.full(shape + (2, 3), np.nan)
    imb = np.full(shape + (2,), np.nan)
    length = {"x": ly, "y": lx}
    for k, e in enumerate(EDGES):
        ip, im = _side_index(ds, _PLUS[e]), _side_index(ds, _MINUS[e])
        if ip is not None:
            N[..., k, :] = F[..., ip, :] / length[e]
        if ip is not None and im is not None:
            imb[..., k] = np.linalg.norm(F[..., ip, :] + F[..., im, :], axis=-1)
    ds["membrane_force"] = _var(
        tuple(lead) + ("edge", "component"), N, "N mm-1",
        "membrane force per unit reference width: clamp force on the + side of the edge / the edge's reference "
        "length (first Piola; N_xx = [edge x, component x], N_yy = [y, y], shear resultant N_yx = [x, y])",
        comment="includes the pretension of the relaxed cell (membrane_force_at_zero_strain)")
    ax = lead.index("strain")
    N0 = (np.take(N, int(zero[0]), axis=ax) if zero.size else np.full(np.delete(N.shape, ax), np.nan))
    ds["membrane_force_at_zero_strain"] = _var(
        tuple(d for d in lead if d != "strain") + ("edge", "component"), N0, "N mm-1",
        "pretension: membrane force of the relaxed cell at zero strain (the exports subtract it unless "
        "asked to keep it)")
    ds["side_force_imbalance"] = _var(
        tuple(lead) + ("edge",), imb, "N",
        "|F(-) + F(+)|: magnitude of the sum of the clamp forces on the two sides of an edge pair (a check, ~0)")


def _add_strain_measures(ds, lead, strains) -> None:
    """``yarn_strain`` and ``shear_angle`` of the modes' paths, NaN where no state is."""
    modes = [str(m) for m in ds["mode"].values]
    ys = np.full((len(modes), len(strains), 2), np.nan)
    th = np.full((len(modes), len(strains)), np.nan)
    for i, m in enumerate(modes):
        try:
            ys[i], th[i] = yarn_strain_and_angle(m, strains)
        except ValueError:
            pass
    lead_shape = tuple(ds.sizes[d] for d in lead)
    ys_da = xr.DataArray(ys, dims=("mode", "strain", "yarn")).transpose(*[d for d in lead if d in ("mode", "strain")],
                                                                         "yarn")
    th_da = xr.DataArray(th, dims=("mode", "strain")).transpose(*[d for d in lead if d in ("mode", "strain")])
    # a (mode, strain, *swept) point is a state if any stored variable has a value there
    present = np.zeros(lead_shape, bool)
    for name in STORED_VARIABLES:
        if name in ds and all(d in ds[name].dims for d in lead):
            arr = ds[name].transpose(*lead, ...).values.reshape(lead_shape + (-1,))
            present |= np.isfinite(arr).any(axis=-1)
    ones = xr.DataArray(np.where(present, 1.0, np.nan), dims=lead)
    ds["yarn_strain"] = _var(
        tuple(lead) + ("yarn",), (ys_da * ones).transpose(*lead, "yarn").values,
        DIMENSIONLESS, "nominal strain of the yarn family under the mode's affine deformation |F e_i| - 1",
        strain_path="uniaxial: F = I + eps e1 e1; uniaxial_y: F = I + eps e2 e2; shear: simple shear "
                    "F = I + gamma e2 e1 (warp stretched by sqrt(1 + gamma^2) - 1); trellis: picture-frame shear, "
                    "both families keep their length")
    ds["shear_angle"] = _var(
        tuple(lead), (th_da * ones).transpose(*lead).values, "rad",
        "shear angle: drop of the angle between the warp and weft directions (shear: atan(gamma); trellis: the "
        "mode's strain)")


def _add_sheet_parameters(ds, pitch) -> None:
    """The two-potential sheet parameters per yarn family: the warp/weft fit where it has
    values, else the two-resistor fit for both (``sheet_network_parameters``)."""
    if "contact_resistance" in ds and "yarn_resistance" in ds:
        net = sheet_network_parameters(ds)
        ry, rc = net["yarn_resistance"].values, net["contact_resistance"].values
        dims = net["contact_resistance"].dims + ("yarn",)
        Rc2 = net["contact_resistance"]
        g = 1.0 / ry + 1.0 / rc[..., None]
        c = 4.0 / (rc * pitch ** 2)
        src = ("R_y, R_c of the warp/weft fit (yarn_resistance_warp/_weft, contact_resistance_warp_weft) where it "
               "has values, else yarn_resistance, contact_resistance (rve.tables.macro.sheet_network_parameters; "
               f"this table: {net.attrs['network_fit']})")
        ds["yarn_sheet_conductance"] = _var(dims, g, "S", "two-potential sheet model: sheet conductance "
                                            "g = 1/R_y + 1/R_c of the yarn family's layer", comment=src)
        ds["contact_exchange_conductance"] = _var(Rc2.dims, c, "S mm-2",
                                                  "two-potential sheet model: warp-weft exchange conductance per "
                                                  "reference area c = 4 / (R_c a^2)", comment=src)
        ds["busbar_sheet_resistance"] = _var(dims, 1.0 / g, "ohm",
                                             "bus-bar sheet resistance 1/g (ohm per reference square) of a yarn layer")
        ds["transfer_length"] = _var(dims, np.sqrt(g / (2.0 * c[..., None])), "mm",
                                     "transfer length sqrt(g / 2c) of the two-potential sheet model")
