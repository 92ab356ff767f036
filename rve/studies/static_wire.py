"""Verification study of the static wire (thesis §6.3, Fig. 6.3.2, Fig. 6.3.3, Table 6.2).

Two sweeps of :func:`rve.scenes.static_wire.solve`, both described by the pipeline config
(``verification.static_wire`` in ``configs/pipeline.yaml``; nothing about the study design
is hard-coded here):

* **radius sweep** at fixed order p and N elements: the centre displacement approaches the
  chapter-3 string solution (0.71243 L) as the radius R -> 0 (J, B, E fixed, so k = JB/E
  does not change; the bending contribution falls like R^2, docs/verification_static_wire.md);
* **convergence** at one radius: p = 1..4, a list of N per p. The error of the centre
  displacement is measured against the finest solution of the study (highest p, largest
  N), as in the thesis, and its order is fitted by least squares on log(error) vs log(h),
  h = 2L/N, over a stated asymptotic range of N, separately for odd and even N.

Where the centre sits decides the rate (docs/verification_static_wire.md, "Why odd and
even N"). Even N: the centre is an element end
node, where 1D Galerkin solutions superconverge toward O(h^2p). Odd N: the centre is the
midpoint of an element, an interior Lobatto node for even p (O(h^(p+2))) and not a node at
all for odd p (O(h^(p+1)), the thesis's p+1). :func:`expected_order` returns these.

The Snakemake rules (``workflow/rules/verification.smk``) call the ``*_job`` functions:
:func:`point_job` (one solve -> JSON record), :func:`gather_job` (records -> netCDF with
the fitted orders) and :func:`report_job` (netCDF -> PNG plots and the orders table).
"""
from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import subprocess
import time
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Optional, Sequence, Union

import numpy as np

from ..io.atomic import atomic_path, atomic_write_json, atomic_write_text
from ..io.provenance import cf_attributes, logging_to, package_version, to_jsonable
from .convergence import fit_order, fit_points
from .layout import point_name, radius_token, study_points

__all__ = [
    "PARITIES",
    "radius_token",
    "point_name",
    "point_overrides",
    "study_points",
    "study_fit_ranges",
    "study_reference",
    "expected_order",
    "total_newton_iterations",
    "convergence_point",
    "build_dataset",
    "gather_static_wire",
    "fit_orders",
    "orders_table",
    "write_orders_table",
    "plot_radius_sweep",
    "plot_convergence",
    "point_job",
    "gather_job",
    "report_job",
]

log = logging.getLogger("rve.studies.static_wire")

PathLike = Union[str, os.PathLike]

#: parity coordinate of the fitted orders: odd N (centre inside an element), even N (node)
PARITIES = ("odd", "even")

_DIMLESS = "1"  # CF/udunits unit of a dimensionless number


# --------------------------------------------------------------------------- study design
def point_overrides(order: int, elements: int, radius: float, overrides: Iterable[str] = ()) -> list[str]:
    """Scene-config overrides of one study point (radius in mm); the study's own overrides
    come first so that the point's order, N and R always win."""
    return [*overrides, f"mesh.order={int(order)}", f"mesh.elements={int(elements)}",
            f"fibril.radius={radius_token(radius)} mm"]


def _range_pair(value: Any) -> tuple[int, int]:
    if isinstance(value, Mapping):
        return int(value["min"]), int(value["max"])
    lo, hi = value
    return int(lo), int(hi)


def _normalise_ranges(ranges: Mapping) -> dict[int, dict[str, tuple[int, int]]]:
    """``{p: (lo, hi)}``, ``{p: {"min": lo, "max": hi}}`` or ``{p: {"odd": .., "even": ..}}``
    -> ``{p: {"odd": (lo, hi), "even": (lo, hi)}}`` (inclusive N ranges)."""
    out = {}
    for p, value in ranges.items():
        if isinstance(value, Mapping) and ("odd" in value or "even" in value):
            out[int(p)] = {par: _range_pair(value[par]) for par in PARITIES if par in value}
        else:
            pair = _range_pair(value)
            out[int(p)] = {par: pair for par in PARITIES}
    return out


def study_fit_ranges(study: Mapping) -> dict[int, dict[str, tuple[int, int]]]:
    """The asymptotic N ranges of the convergence series: ``fit`` applies to both
    parities, ``fit_odd`` / ``fit_even`` (if given) replace it for one parity."""
    out = {}
    for series in study.get("convergence", {}).get("series", []):
        p = int(series["order"])
        base = series.get("fit")
        per = {}
        for par in PARITIES:
            value = series.get(f"fit_{par}", base)
            if value is not None:
                per[par] = _range_pair(value)
        if per:
            out[p] = per
    return out


def study_reference(study: Mapping) -> Optional[tuple[int, int]]:
    """``(order, elements)`` of the reference solution if the config names one, else None
    (then the finest solution of the study is used: highest p, then largest N)."""
    ref = study.get("convergence", {}).get("reference")
    if not ref:
        return None
    return int(ref["order"]), int(ref["elements"])


def expected_order(order: int, parity: str) -> int:
    """Asymptotic order of the centre-displacement error for 1D Galerkin elements of order
    p: even N (centre at an element end node) 2p; odd N (centre at an element midpoint)
    p+2 when the midpoint is an interior Lobatto node (even p), else p+1."""
    p = int(order)
    if parity == "even":
        return 2 * p
    if parity == "odd":
        return p + 2 if p % 2 == 0 else p + 1
    raise ValueError(f"parity must be 'odd' or 'even', got {parity!r}")


def total_newton_iterations(result: Mapping) -> int:
    """All Newton iterations of a solve: static, relaxation and any intermediate phases
    (every ``*newton_iterations`` key plus ``settle_iterations``)."""
    total = 0
    for key, value in result.items():
        if (key.endswith("newton_iterations") or key == "settle_iterations") and isinstance(value, (int, float)):
            if value == value:  # not NaN
                total += int(value)
    return total


# --------------------------------------------------------------------------- one solve
def convergence_point(scene_config_path: PathLike, order: int, elements: int, radius: float,
                      overrides: Iterable[str] = (), keep_failure: bool = False) -> dict:
    """Solve the static wire at order p, N elements and radius R (mm) and return a
    JSON-serialisable record: the point, every scalar of the scene's result (centre and
    analytical displacement in units of L, Newton iterations, dofs, wall times, ...),
    ``converged`` and the config used.

    With ``keep_failure`` a solver failure gives a record with ``converged = False``, NaN
    displacements and the error message instead of raising (configuration errors always
    raise)."""
    from ..config.loader import config_as_dict, load_config
    from ..scenes.static_wire import solve

    overrides = list(overrides)
    cfg = load_config(scene_config_path, overrides=point_overrides(order, elements, radius, overrides))
    record: dict[str, Any] = {
        "order": int(order),
        "elements": int(elements),
        "radius": float(radius),
        "radius_units": "mm",
        "scene_config_path": os.fspath(scene_config_path),
        "overrides": overrides,
        "solver_path": cfg.solver.path,
    }
    t0 = time.perf_counter()
    try:
        result = solve(cfg).summary
    except Exception as exc:  # noqa: BLE001 - recorded, or re-raised below
        if not keep_failure:
            raise
        log.error("p=%d N=%d R=%s mm: solve failed: %s", order, elements, radius_token(radius), exc)
        record.update({
            "converged": False,
            "error_message": f"{type(exc).__name__}: {exc}",
            "centre_displacement": math.nan,
            "analytical_centre_displacement": math.nan,
            "newton_iterations": math.nan,
            "relaxation_newton_iterations": math.nan,
            "dofs": math.nan,
            "wall_time_s": {"total": time.perf_counter() - t0},
        })
    else:
        for key in ("order", "elements", "radius"):
            result.pop(key, None)
        record.update(to_jsonable(result))
        record["converged"] = True
        record["error_message"] = None
        record["total_newton_iterations"] = total_newton_iterations(result)
        log.info("p=%d N=%d R=%s mm: centre displacement %.12f L (analytical %.6f L), "
                 "%d static Newton iterations, %d dofs, %.2f s",
                 order, elements, radius_token(radius), record["centre_displacement"],
                 record["analytical_centre_displacement"], record["newton_iterations"],
                 record["dofs"], record["wall_time_s"].get("total", math.nan))
    record["config"] = config_as_dict(cfg)
    return record


# --------------------------------------------------------------------------- dataset
def _git_revision() -> str:
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip()
    except Exception:  # noqa: BLE001 - not a checkout, git missing
        return "unknown"
    return out + ("+dirty" if dirty else "")


def _load_records(records: Iterable[Union[Mapping, PathLike]]) -> list[dict]:
    out = []
    for rec in records:
        if isinstance(rec, Mapping):
            out.append(dict(rec))
        else:
            with open(rec, encoding="utf-8") as fh:
                out.append(json.load(fh))
    return out


def _num(value: Any) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return math.nan
    return x


_VARIABLES = {
    # name: (units, long_name, value getter)
    "centre_displacement": (
        _DIMLESS, "distance of the wire's midpoint centroid from the support line, divided by "
        "the half-length L", lambda r: _num(r.get("centre_displacement"))),
    "analytical_centre_displacement": (
        _DIMLESS, "centre displacement of the chapter-3 analytical string helix, divided by L",
        lambda r: _num(r.get("analytical_centre_displacement"))),
    "newton_iterations": (
        _DIMLESS, "Newton iterations of the final static solve",
        lambda r: _num(r.get("newton_iterations"))),
    "relaxation_newton_iterations": (
        _DIMLESS, "Newton iterations of the path to the static solve (relaxation or continuation)",
        lambda r: _num(r.get("relaxation_newton_iterations"))),
    "total_newton_iterations": (
        _DIMLESS, "Newton iterations of the whole solve (all phases)",
        lambda r: _num(r.get("total_newton_iterations", math.nan))),
    "wall_time_s": (
        "s", "wall-clock time of the solve (set-up, path and static Newton)",
        lambda r: _num((r.get("wall_time_s") or {}).get("total"))),
    "dofs": (
        _DIMLESS, "number of degrees of freedom of the discretised wire",
        lambda r: _num(r.get("dofs"))),
    "converged": (
        _DIMLESS, "1 where the solve converged, 0 where it failed (NaN: not computed)",
        lambda r: 1.0 if r.get("converged", True) else 0.0),
}


def build_dataset(records: Iterable[Union[Mapping, PathLike]], *, convergence_radius: Optional[float] = None,
                  reference: Optional[tuple[int, int]] = None, provenance: Optional[Mapping] = None):
    """The study Dataset of point records (dicts or JSON paths) without writing it.

    Dimensions ``order``, ``elements``, ``radius`` (mm), NaN where not computed. ``error`` is
    |c - c_ref| at the convergence radius (default: the radius with the most points), c_ref
    the reference solution there (default: highest converged p, then largest N);
    ``error_vs_analytical`` is |c - c_analytical| everywhere."""
    recs = _load_records(records)
    if not recs:
        raise ValueError("build_dataset: no records")
    ds = _point_grid(recs)
    ref_p, ref_n, r_sel = _add_errors(ds, convergence_radius, reference)
    # flag variable: make the meaning machine-readable too (CF flags)
    ds["converged"].attrs.update({"flag_values": np.array([0, 1], dtype=np.int8),
                                  "flag_meanings": "failed converged"})
    _add_attributes(ds, recs, f"p={ref_p}, N={ref_n}, R={radius_token(r_sel)} mm", r_sel, provenance)
    return ds


def _point_grid(recs: list):
    """The Dataset of the ``_VARIABLES`` of the records on the (order, elements, radius)
    grid (radii descending), NaN where no record is."""
    import xarray as xr

    orders = sorted({int(r["order"]) for r in recs})
    elements = sorted({int(r["elements"]) for r in recs})
    radii = sorted({float(radius_token(r["radius"])) for r in recs}, reverse=True)
    shape = (len(orders), len(elements), len(radii))
    index = {}
    for r in recs:
        key = (orders.index(int(r["order"])), elements.index(int(r["elements"])),
               radii.index(float(radius_token(r["radius"]))))
        index[key] = r
    data = {}
    for name, (units, long_name, get) in _VARIABLES.items():
        arr = np.full(shape, np.nan)
        for key, r in index.items():
            arr[key] = get(r)
        data[name] = xr.Variable(("order", "elements", "radius"), arr,
                                 attrs={"units": units, "long_name": long_name})

    coords = {
        "order": ("order", np.asarray(orders, dtype=np.int32),
                  {"units": _DIMLESS, "long_name": "Lagrange polynomial order p of the elements"}),
        "elements": ("elements", np.asarray(elements, dtype=np.int32),
                     {"units": _DIMLESS, "long_name": "number of elements N along the wire"}),
        "radius": ("radius", np.asarray(radii, dtype=float),
                   {"units": "mm", "long_name": "fibril (wire) radius R"}),
        "h": ("elements", 2.0 / np.asarray(elements, dtype=float),
              {"units": _DIMLESS, "long_name": "element length h = 2L/N divided by the half-length L"}),
    }
    return xr.Dataset(data, coords=coords)


def _add_errors(ds, convergence_radius: Optional[float], reference: Optional[tuple[int, int]]):
    """Add ``error``, ``error_vs_analytical`` and ``reference_centre_displacement`` to the
    grid; returns the reference (p, N) and the convergence radius."""
    import xarray as xr

    orders, elements = [int(p) for p in ds["order"].values], [int(n) for n in ds["elements"].values]
    radii = [float(r) for r in ds["radius"].values]
    c = ds["centre_displacement"]
    if convergence_radius is None:
        counts = np.isfinite(c.values).sum(axis=(0, 1))
        convergence_radius = float(ds["radius"].values[int(np.argmax(counts))])
    r_sel = float(radius_token(convergence_radius))
    if r_sel not in radii:
        raise ValueError(f"convergence radius {convergence_radius} mm is not among the study radii {radii}")
    at_r = c.sel(radius=r_sel)
    if reference is None:
        finite = np.isfinite(at_r.values)
        if not finite.any():
            raise ValueError(f"no converged solution at the convergence radius {r_sel} mm")
        ip = int(np.nonzero(finite.any(axis=1))[0].max())
        ie = int(np.nonzero(finite[ip])[0].max())
        reference = (orders[ip], elements[ie])
    ref_p, ref_n = int(reference[0]), int(reference[1])
    c_ref = float(at_r.sel(order=ref_p, elements=ref_n))
    if not math.isfinite(c_ref):
        raise ValueError(f"reference p={ref_p} N={ref_n} R={r_sel} mm has no converged solution")
    err = np.full(c.shape, np.nan)
    err[:, :, radii.index(r_sel)] = np.abs(at_r.values - c_ref)
    ds["error"] = xr.Variable(("order", "elements", "radius"), err, attrs={
        "units": _DIMLESS,
        "long_name": "|centre displacement - reference centre displacement| divided by L "
                     "(convergence radius only)",
        "reference_order": ref_p,
        "reference_elements": ref_n,
        "reference_radius_mm": r_sel,
    })
    ds["error_vs_analytical"] = xr.Variable(
        ("order", "elements", "radius"), np.abs(c.values - ds["analytical_centre_displacement"].values),
        attrs={"units": _DIMLESS,
               "long_name": "|centre displacement - analytical centre displacement| divided by L"})
    ds["reference_centre_displacement"] = xr.Variable((), c_ref, attrs={
        "units": _DIMLESS,
        "long_name": f"centre displacement of the reference solution (p={ref_p}, N={ref_n}, "
                     f"R={radius_token(r_sel)} mm) divided by L",
    })
    return ref_p, ref_n, r_sel


def _add_attributes(ds, recs: list, reference_solution: str, r_sel: float, provenance: Optional[Mapping]) -> None:
    """The CF attributes, the scene config of the study and the caller's provenance."""
    n_failed = int(np.nansum(ds["converged"].values == 0))
    ds.attrs.update(cf_attributes(
        title="Static wire verification study (thesis section 6.3): radius sweep and "
              "convergence of the centre displacement",
        source=f"rve {package_version()} rve.scenes.static_wire.solve",
        references="Queiruga (2015), section 6.3, Figs. 6.3.2-6.3.3, Tables 6.1-6.2; "
                   "docs/verification_static_wire.md",
        history="rve.studies.static_wire.build_dataset",
        source_revision=_git_revision(),
        reference_solution=reference_solution,
        convergence_radius_mm=r_sel,
        points=len(recs),
        failed_points=n_failed,
        length_unit="displacements and h are divided by the half-length L of the wire",
    ))
    # one config per dataset: the scene config of the first converged point without the
    # point's own order / elements / radius (those are coordinates)
    first = next((r for r in recs if r.get("config")), None)
    if first is not None:
        scene = json.loads(json.dumps(first["config"]))
        scene.get("mesh", {}).pop("order", None)
        scene.get("mesh", {}).pop("elements", None)
        scene.get("fibril", {}).pop("radius", None)
        ds.attrs["scene_config"] = json.dumps(scene, sort_keys=True)
        ds.attrs["scene_config_path"] = str(first.get("scene_config_path", ""))
        ds.attrs["scene_overrides"] = json.dumps(first.get("overrides", []))
        ds.attrs["solver_path"] = str(first.get("solver_path", ""))
    for key, value in (provenance or {}).items():
        ds.attrs[key] = value if isinstance(value, (str, int, float)) else json.dumps(to_jsonable(value))


def gather_static_wire(records: Iterable[Union[Mapping, PathLike]], out_nc: PathLike, *,
                       convergence_radius: Optional[float] = None, reference: Optional[tuple[int, int]] = None,
                       fit_ranges: Optional[Mapping] = None, study_config: Optional[Mapping] = None):
    """Build the study Dataset (:func:`build_dataset`), fit the orders over ``fit_ranges``
    (:func:`fit_orders`) and write it atomically to ``out_nc`` (netCDF). ``study_config``
    (the pipeline's ``verification.static_wire`` section) goes into the attributes as JSON.
    Returns the Dataset."""
    provenance = {}
    if study_config is not None:
        provenance["study_config"] = json.dumps(to_jsonable(study_config), sort_keys=True)
    ds = build_dataset(records, convergence_radius=convergence_radius, reference=reference,
                       provenance=provenance)
    if fit_ranges:
        fit_orders(ds, fit_ranges)
    with atomic_path(out_nc) as tmp:
        ds.to_netcdf(tmp)
    return ds


# --------------------------------------------------------------------------- fits
def _fit_selection(err_at_r, order: int, parity: str, lo: int, hi: int, ref_p, ref_n):
    """(N, error, mask) of the points of order p, given parity, N in [lo, hi], finite
    positive error, the reference solution excluded (``rve.studies.convergence.fit_points``)."""
    e = err_at_r.sel(order=order)
    Ns = np.asarray(e["elements"].values, dtype=int)
    vals = np.asarray(e.values, dtype=float)
    exclude = int(ref_n) if ref_p is not None and int(ref_p) == int(order) else None
    return Ns, vals, fit_points(Ns, vals, lo, hi, parity, exclude=exclude)


def _error_at_reference_radius(ds):
    err = ds["error"]
    ref_p = err.attrs.get("reference_order")
    ref_n = err.attrs.get("reference_elements")
    r_sel = err.attrs.get("reference_radius_mm")
    if r_sel is not None:
        err = err.sel(radius=float(r_sel))
    elif "radius" in err.dims:  # a hand-made dataset without the attributes
        err = err.max("radius", skipna=True)
    return err, ref_p, ref_n


def fit_orders(ds, ranges: Mapping):
    """Fit the convergence order of ``ds["error"]`` per p and parity of N.

    ``ranges`` maps p to the inclusive asymptotic N range: ``(lo, hi)``, ``{"min": lo,
    "max": hi}`` or per parity ``{"odd": (lo, hi), "even": (lo, hi)}``. The slope of
    log(error) vs log(h) is fitted by least squares over the points in range with a finite,
    positive error; the reference solution (``error`` attributes) is excluded. Needs 2
    points, else NaN (``rve.studies.convergence.fit_order``: the one fit of both studies).

    Stores ``fitted_order`` (order x parity) with ``fit_elements_min/max`` and
    ``fit_points`` in ``ds`` (in place) and returns the table as a pandas DataFrame with
    columns order, parity, elements_min, elements_max, points, fitted_order,
    expected_order (:func:`expected_order`) and thesis_order (p + 1)."""
    import pandas as pd
    import xarray as xr

    norm = _normalise_ranges(ranges)
    err, ref_p, ref_n = _error_at_reference_radius(ds)
    orders = [int(p) for p in ds["order"].values]
    shape = (len(orders), len(PARITIES))
    fitted = np.full(shape, np.nan)
    nmin = np.full(shape, -1, dtype=np.int32)
    nmax = np.full(shape, -1, dtype=np.int32)
    npts = np.zeros(shape, dtype=np.int32)
    rows = []
    for i, p in enumerate(orders):
        for j, parity in enumerate(PARITIES):
            if p not in norm or parity not in norm[p]:
                continue
            lo, hi = norm[p][parity]
            nmin[i, j], nmax[i, j] = lo, hi
            Ns, vals, keep = _fit_selection(err, p, parity, lo, hi, ref_p, ref_n)
            npts[i, j] = int(keep.sum())
            if npts[i, j] >= 2:
                fitted[i, j] = fit_order(2.0 / Ns, vals, keep)
            rows.append({
                "order": p, "parity": parity, "elements_min": lo, "elements_max": hi,
                "points": int(npts[i, j]),
                "elements_used": " ".join(str(n) for n in Ns[keep]),
                "fitted_order": fitted[i, j],
                "expected_order": expected_order(p, parity),
                "thesis_order": p + 1,
            })
    range_text = "; ".join(
        f"p={p} {par} N in [{lo}, {hi}]" for p in sorted(norm) for par, (lo, hi) in norm[p].items())
    dims = ("order", "parity")
    ds.coords["parity"] = ("parity", np.array(PARITIES),
                           {"long_name": "parity of the number of elements N (even: the centre is a node)",
                            "units": _DIMLESS})
    ds["fitted_order"] = xr.Variable(dims, fitted, attrs={
        "units": _DIMLESS,
        "long_name": "least-squares slope of log(error) vs log(h) over the asymptotic range of N",
        "fit_range": range_text,
        "reference_excluded": f"p={ref_p}, N={ref_n}",
    })
    ds["fit_elements_min"] = xr.Variable(dims, nmin, attrs={
        "units": _DIMLESS, "long_name": "smallest N of the fit range (-1: not fitted)"})
    ds["fit_elements_max"] = xr.Variable(dims, nmax, attrs={
        "units": _DIMLESS, "long_name": "largest N of the fit range (-1: not fitted)"})
    ds["fit_points"] = xr.Variable(dims, npts, attrs={
        "units": _DIMLESS, "long_name": "number of (p, N) points in the fit"})
    ds["expected_order"] = xr.Variable(dims, np.array(
        [[expected_order(p, par) for par in PARITIES] for p in orders], dtype=np.int32), attrs={
        "units": _DIMLESS,
        "long_name": "asymptotic order expected where the centre sits: even N 2p, odd N p+2 "
                     "(even p) or p+1 (odd p)"})
    ds.attrs["fit_range"] = range_text
    columns = ["order", "parity", "elements_min", "elements_max", "points", "elements_used",
               "fitted_order", "expected_order", "thesis_order"]
    return pd.DataFrame(rows, columns=columns)


def orders_table(ds):
    """The fitted-orders table stored in ``ds`` by :func:`fit_orders` (a DataFrame)."""
    import pandas as pd

    if "fitted_order" not in ds:
        raise KeyError("the dataset has no fitted_order: run fit_orders first")
    err, ref_p, ref_n = _error_at_reference_radius(ds)
    rows = []
    for p in ds["order"].values:
        for par in PARITIES:
            lo = int(ds["fit_elements_min"].sel(order=p, parity=par))
            hi = int(ds["fit_elements_max"].sel(order=p, parity=par))
            if lo < 0:
                continue
            Ns, _, keep = _fit_selection(err, int(p), par, lo, hi, ref_p, ref_n)
            rows.append({
                "order": int(p), "parity": par, "elements_min": lo, "elements_max": hi,
                "points": int(ds["fit_points"].sel(order=p, parity=par)),
                "elements_used": " ".join(str(n) for n in Ns[keep]),
                "fitted_order": float(ds["fitted_order"].sel(order=p, parity=par)),
                "expected_order": int(ds["expected_order"].sel(order=p, parity=par)),
                "thesis_order": int(p) + 1,
            })
    return pd.DataFrame(rows)


def write_orders_table(ds, csv_path: PathLike, md_path: PathLike):
    """Write the fitted orders as CSV and as a markdown table (both atomically)."""
    table = orders_table(ds)
    atomic_write_text(csv_path, table.to_csv(index=False, float_format="%.4f"))
    head = ("| p | N parity | N range | points | fitted order | expected (node/Lobatto) | thesis (p+1) |\n"
            "|---|---|---|---|---|---|---|\n")
    lines = []
    for row in table.itertuples(index=False):
        fitted = "n/a" if not math.isfinite(row.fitted_order) else f"{row.fitted_order:.2f}"
        lines.append(f"| {row.order} | {row.parity} | {row.elements_min}-{row.elements_max} "
                     f"({row.elements_used}) | {row.points} | {fitted} | {row.expected_order} | "
                     f"{row.thesis_order} |")
    note = (f"\nReference: {ds.attrs.get('reference_solution', '?')} "
            f"(centre displacement {float(ds['reference_centre_displacement']):.12f} L), "
            f"excluded from the fits. Error = |c(p, N) - c_ref|; h = 2L/N.\n")
    atomic_write_text(md_path, head + "\n".join(lines) + "\n" + note)
    return table


# --------------------------------------------------------------------------- plots
@contextlib.contextmanager
def _figure(out_png: PathLike, **kwargs) -> Iterator:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig = plt.figure(**kwargs)
    try:
        yield fig
        with atomic_path(out_png) as tmp:
            fig.savefig(tmp, dpi=150, bbox_inches="tight")
    finally:
        plt.close(fig)


def plot_radius_sweep(ds, out_png: PathLike, order: Optional[int] = None, elements: Optional[int] = None):
    """Centre displacement vs R (log x) at (p, N), the analytical value dashed (Fig. 6.3.2).
    Default (p, N): the pair with the most radii computed."""
    c = ds["centre_displacement"]
    if order is None or elements is None:
        counts = np.isfinite(c.values).sum(axis=2)
        ip, ie = np.unravel_index(int(np.argmax(counts)), counts.shape)
        order, elements = int(ds["order"].values[ip]), int(ds["elements"].values[ie])
    line = c.sel(order=order, elements=elements)
    R = np.asarray(ds["radius"].values, dtype=float)
    y = np.asarray(line.values, dtype=float)
    ok = np.isfinite(y)
    analytical = np.nanmax(ds["analytical_centre_displacement"].values)
    with _figure(out_png, figsize=(5.5, 4)) as fig:
        ax = fig.add_subplot(111)
        ax.semilogx(R[ok], y[ok], "o-", label=f"numerical, p={order}, N={elements}")
        ax.axhline(analytical, ls="--", color="k", label=f"analytical (ch. 3) {analytical:.5f}")
        lo = min(analytical, float(np.min(y[ok])) if ok.any() else analytical)
        hi = max(analytical, float(np.max(y[ok])) if ok.any() else analytical)
        pad = 0.08 * (hi - lo) if hi > lo else 0.01
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_xticks(R[ok])
        ax.set_xticks([], minor=True)
        ax.set_xticklabels([radius_token(r) for r in R[ok]])
        ax.set_xlabel("radius R [mm]  (L = 1 mm)")
        ax.set_ylabel("centre displacement / L")
        ax.set_title("Static wire: approach to the string limit")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()


def plot_convergence(ds, out_png: PathLike):
    """Left: centre displacement vs N per p. Right: error vs h (log-log) per p with the
    fitted slopes (odd N open markers / dashed fits, even N filled / solid)."""
    err = ds["error"]
    r_sel = float(err.attrs.get("reference_radius_mm", ds.attrs.get("convergence_radius_mm")))
    c = ds["centre_displacement"].sel(radius=r_sel)
    e = err.sel(radius=r_sel)
    Ns = np.asarray(ds["elements"].values, dtype=int)
    colours = ["C0", "C1", "C2", "C3", "C4", "C5", "C6"]
    with _figure(out_png, figsize=(11, 4.5)) as fig:
        ax1 = fig.add_subplot(121)
        ax2 = fig.add_subplot(122)
        for i, p in enumerate(ds["order"].values):
            col = colours[i % len(colours)]
            y = np.asarray(c.sel(order=p).values, dtype=float)
            ev = np.asarray(e.sel(order=p).values, dtype=float)
            if not np.isfinite(y).any():
                continue
            ax1.plot(Ns[np.isfinite(y)], y[np.isfinite(y)], "-", color=col, alpha=0.4, lw=0.8)
            for par in PARITIES:
                sel = np.isfinite(y) & (Ns % 2 == (1 if par == "odd" else 0))
                face = "none" if par == "odd" else col
                ax1.plot(Ns[sel], y[sel], "o" if par == "even" else "s", mfc=face, mec=col, ls="none",
                         label=f"p={p} {par} N")
                sel_e = sel & (ev > 0)
                label = f"p={p} {par} N"
                if "fitted_order" in ds:
                    q = float(ds["fitted_order"].sel(order=p, parity=par))
                    lo = int(ds["fit_elements_min"].sel(order=p, parity=par))
                    hi = int(ds["fit_elements_max"].sel(order=p, parity=par))
                    if math.isfinite(q):
                        label += f": slope {q:.2f} (N {lo}-{hi})"
                        fit = sel_e & (Ns >= lo) & (Ns <= hi)
                        if fit.sum() >= 2:
                            hh = 2.0 / Ns[fit]
                            b = np.mean(np.log(ev[fit]) - q * np.log(hh))
                            hl = np.array([hh.min(), hh.max()])
                            ax2.loglog(hl, np.exp(b) * hl**q, "-" if par == "even" else "--", color=col, lw=1)
                ax2.loglog(2.0 / Ns[sel_e], ev[sel_e], "o" if par == "even" else "s", mfc=face, mec=col,
                           ls="none", label=label)
        ax1.set_xscale("log")
        ax1.axhline(float(ds["reference_centre_displacement"]), color="k", lw=0.6, ls=":",
                    label="reference")
        ax1.set_xlabel("elements N")
        ax1.set_ylabel("centre displacement / L")
        ax1.set_title(f"R = {radius_token(r_sel)} mm")
        ax1.grid(True, which="both", alpha=0.3)
        ax1.legend(fontsize=6, ncol=2)
        from matplotlib.ticker import NullFormatter

        for ax in (ax1, ax2):
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax2.set_xlabel("h / L = 2 / N")
        ax2.set_ylabel("|c - c_ref| / L")
        ax2.set_title(f"error vs {ds.attrs.get('reference_solution', 'reference')}")
        ax2.grid(True, which="both", alpha=0.3)
        ax2.legend(fontsize=6)
        fig.tight_layout()


# --------------------------------------------------------------------------- rule bodies
def point_job(record_path: PathLike, log_path: Optional[PathLike], scene_config: PathLike, point: Any,
              overrides: Sequence[str] = (), keep_failure: bool = False) -> dict:
    """Rule body of one solve: ``point`` has ``order``, ``elements`` and ``radius`` (mm)
    (attributes, e.g. Snakemake wildcards, or keys); writes the record JSON atomically."""
    get = (lambda k: point[k]) if isinstance(point, Mapping) else (lambda k: getattr(point, k))
    with logging_to(log_path):
        record = convergence_point(scene_config, int(get("order")), int(get("elements")),
                                   float(get("radius")), overrides=list(overrides), keep_failure=keep_failure)
        atomic_write_json(record_path, record)
    return record


def gather_job(record_paths: Iterable[PathLike], out_nc: PathLike, log_path: Optional[PathLike], study: Mapping):
    """Rule body of the gather: records -> netCDF with the fitted orders."""
    with logging_to(log_path):
        conv = study.get("convergence") or {}
        ds = gather_static_wire(
            list(record_paths), out_nc,
            convergence_radius=conv.get("radius_mm"),
            reference=study_reference(study),
            fit_ranges=study_fit_ranges(study),
            study_config=study,
        )
        log.info("wrote %s: %d points, %d failed, reference %s", out_nc, ds.attrs["points"],
                 ds.attrs["failed_points"], ds.attrs["reference_solution"])
        if "fitted_order" in ds:
            log.info("fitted orders (order x %s):\n%s", "/".join(PARITIES), ds["fitted_order"].values)
    return ds


def report_job(nc_path: PathLike, radius_png: PathLike, convergence_png: PathLike, table_csv: PathLike,
               table_md: PathLike, log_path: Optional[PathLike], study: Mapping):
    """Rule body of the report: netCDF -> radius-sweep and convergence PNGs, orders table."""
    import xarray as xr

    with logging_to(log_path):
        with xr.open_dataset(nc_path) as ds:
            ds.load()
        sweep = study.get("radius_sweep") or {}
        plot_radius_sweep(ds, radius_png, sweep.get("order"), sweep.get("elements"))
        plot_convergence(ds, convergence_png)
        table = write_orders_table(ds, table_csv, table_md)
        log.info("fitted orders:\n%s", table.to_string(index=False))
    return table
