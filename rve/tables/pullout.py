"""The yarn pull-out's force-displacement table and figure (``rve.homogenisation.pullout``;
docs/rve_pipeline.md "Yarn pull-out").

Contract
--------
* :func:`pullout_curve` ``(states, swept, sliding_fraction)`` -> xarray Dataset on
  ``pullout_step`` (0: the released relaxed state) and the swept parameters:
  ``pullout_displacement`` (mm), ``pullout_force`` (N), ``pullout_released_displacement``
  (mm), ``pullout_friction_dissipated`` (N mm), ``pullout_support_balance`` (N: the other
  supports' axial forces, minus the pull at an equilibrium), and per combination
  ``pullout_peak_force`` (the largest pull force) and ``pullout_sliding_force`` (the mean
  pull force of the steps whose displacement lies in the last ``sliding_fraction`` of the
  largest one); CF attributes
  (units, long_name) on every variable and coordinate;
* :func:`plot_pullout` ``(ds, path)``: the curves, one per combination (per mu), with the
  peak and sliding forces in the legend, written atomically;
* :func:`pullout_table_job`, :func:`pullout_report_job`: the rules ``rve_pullout_table``
  (``pullout.nc`` sealed as the tables, ``pullout.csv``) and ``rve_pullout_report``.
"""
from __future__ import annotations

import itertools
import logging
import os
from pathlib import Path
from typing import Mapping, Optional, Sequence, Union

import numpy as np

from .schema import KNOWN_PARAMETERS

__all__ = ["pullout_curve", "plot_pullout", "pullout_table_job", "pullout_report_job"]

log = logging.getLogger("rve.tables.pullout")

PathLike = Union[str, os.PathLike]


def pullout_curve(states: Sequence, swept: Optional[Mapping[str, str]] = None, sliding_fraction: float = 1 / 3):
    """The force-displacement table of a run's pull-out states (``State`` or files; module
    docstring): dims ``pullout_step`` and the swept parameters."""
    import xarray as xr

    from ..homogenisation.checkpoint import load_state

    states = [load_state(s) if isinstance(s, (str, os.PathLike)) else s for s in states]
    states = [s for s in states if s.kind == "pullout"]
    if not states:
        raise ValueError("pullout_curve: no pull-out states")
    pnames = list(swept or {})
    values = {p: sorted({s.params[p] for s in states}, key=lambda v: (isinstance(v, str), v)) for p in pnames}
    n = max(int(s.solver["pullout"]["steps"]) for s in states)
    shape = (n + 1,) + tuple(len(values[p]) for p in pnames)
    arr = {k: np.full(shape, np.nan) for k in ("displacement", "force", "released", "dissipated", "balance")}
    for st in states:
        pidx = tuple(values[p].index(st.params[p]) for p in pnames)
        po = st.solver["pullout"]
        i = int(st.step)
        arr["displacement"][(i,) + pidx] = po["displacement"]
        arr["force"][(i,) + pidx] = po["force"]
        arr["released"][(i,) + pidx] = po["released_displacement"]
        arr["balance"][(i,) + pidx] = po["balance"]
        arr["dissipated"][(i,) + pidx] = float((st.friction or {}).get("dissipated", 0.0))
        if i == 1:   # step 0: the relaxed state with the pulled yarn's - ends released, u = 0
            s0 = po.get("start", {})
            arr["displacement"][(0,) + pidx] = 0.0
            arr["force"][(0,) + pidx] = s0.get("force", np.nan)
            arr["released"][(0,) + pidx] = s0.get("released_displacement", np.nan)
            arr["balance"][(0,) + pidx] = s0.get("balance", np.nan)
            arr["dissipated"][(0,) + pidx] = float(s0.get("dissipated", 0.0))
    dims = ("pullout_step",) + tuple(pnames)
    coords = {"pullout_step": ("pullout_step", np.arange(n + 1),
                               {"units": "1", "long_name": "step of the yarn pull-out (0: the relaxed state)"})}
    for p in pnames:
        units, long_name = KNOWN_PARAMETERS.get(p, ((swept or {}).get(p, "1"), p.replace("_", " ")))
        vals = values[p]
        coords[p] = (p, np.array(vals, dtype=object if isinstance(vals[0], str) else float),
                     {"units": (swept or {}).get(p) or units, "long_name": long_name})
    ds = xr.Dataset({
        "pullout_displacement": (dims, arr["displacement"], {"units": "mm", "long_name": "pull-out displacement of "
                                                             "the pulled yarn's ends along its axis"}),
        "pullout_force": (dims, arr["force"], {"units": "N", "long_name": "pull-out force: the force on the pulled "
                                               "yarn's ends along its axis"}),
        "pullout_released_displacement": (dims, arr["released"], {"units": "mm", "long_name": "mean axial "
                                                                  "displacement of the pulled yarn's released ends"}),
        "pullout_friction_dissipated": (dims, arr["dissipated"], {"units": "N mm", "long_name": "energy dissipated "
                                                                  "by friction since the relaxed state"}),
        "pullout_support_balance": (dims, arr["balance"], {"units": "N", "long_name": "sum of the axial forces of "
                                                           "all other supports (minus the pull at equilibrium)"}),
    }, coords=coords)
    force, disp = arr["force"], arr["displacement"]
    # the sliding part: the steps whose displacement is within the last sliding_fraction of the largest
    sliding = disp >= (1.0 - sliding_fraction) * np.nanmax(disp, axis=0, keepdims=True) - 1e-12
    ds["pullout_peak_force"] = (tuple(pnames), np.nanmax(force, axis=0),
                                {"units": "N", "long_name": "peak pull-out force"})
    ds["pullout_sliding_force"] = (tuple(pnames), np.nanmean(np.where(sliding, force, np.nan), axis=0),
                                   {"units": "N", "long_name": f"sliding pull-out force: mean force over the steps in "
                                                               f"the last {sliding_fraction:.3g} of the displacement"})
    ds.attrs.update({"title": "RVE yarn pull-out: force-displacement", "Conventions": "CF-1.11",
                     "swept_parameters": " ".join(pnames), "yarn": str(states[0].solver["pullout"]["yarn"])})
    return ds


def plot_pullout(ds, path: PathLike) -> None:
    """Force-displacement curves, one per combination (per mu), peak and sliding force noted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path

    pnames = [p for p in str(ds.attrs.get("swept_parameters", "")).split() if p in ds.dims]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for point in itertools.product(*[range(ds.sizes[p]) for p in pnames]):
        one = ds.isel(dict(zip(pnames, point)))
        label = ", ".join(f"{p} = {one[p].values.item():g}" for p in pnames) or "pull-out"
        ax.plot(one["pullout_displacement"], one["pullout_force"], marker="o", ms=3,
                label=f"{label}: peak {float(one['pullout_peak_force']):.3g} N, sliding "
                      f"{float(one['pullout_sliding_force']):.3g} N")
    ax.set_xlabel("pull-out displacement (mm)")
    ax.set_ylabel("pull-out force (N)")
    ax.set_title(f"yarn pull-out ({ds.attrs.get('yarn', '')})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def pullout_table_job(states: Sequence[PathLike], out_table: PathLike, out_csv: PathLike,
                      log_path: Optional[PathLike], spec: Mapping) -> None:
    """The rule ``rve_pullout_table``: a run's pull-out states -> ``pullout.nc`` and ``pullout.csv``."""
    from ..homogenisation.sweeps import combo_ids, load_run_config, swept_dims
    from ..io.atomic import atomic_netcdf, atomic_write_text
    from ..io.provenance import logging_to

    with logging_to(log_path):
        cfg = load_run_config(spec, combo_ids(spec)[0])
        ds = pullout_curve(list(states), swept_dims(spec), float(cfg.pullout.sliding_fraction))
        atomic_netcdf(ds, out_table)
        atomic_write_text(out_csv, ds[[v for v in ds.data_vars if "pullout_step" in ds[v].dims]]
                          .to_dataframe().to_csv())
        log.info("pull-out: peak force %s N, sliding force %s N -> %s",
                 np.asarray(ds["pullout_peak_force"]).ravel().tolist(),
                 np.asarray(ds["pullout_sliding_force"]).ravel().tolist(), out_table)


def pullout_report_job(table: PathLike, out_png: PathLike, log_path: Optional[PathLike]) -> None:
    """The rule ``rve_pullout_report``: ``pullout.nc`` -> the force-displacement figure."""
    from ..io.checksum import open_netcdf
    from ..io.provenance import logging_to

    with logging_to(log_path):
        plot_pullout(open_netcdf(table, require_seal=True), out_png)
        log.info("pull-out figure -> %s", out_png)
