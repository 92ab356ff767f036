"""Loading-unloading cycles in the lookup table: the hysteresis loop and the energy of a cycle
(``strain.cycle_modes``; docs/rve_pipeline.md "Loading-unloading cycles").

Contract
--------
* :func:`add_cycle_variables` ``(ds, states)``: the cycle states of a run (``rve.homogenisation
  .checkpoint.State`` of kind ``cycle``, written by ``jobs.cycle_job``; or their files) as
  variables of the table ``ds`` on the dimensions ``cycle_mode`` (the cycled modes),
  ``cycle_step`` (0 = the relaxed state, n = the turning point, 2n = back at strain 0) and
  the table's swept parameters:

  =========================  ===============================================  =====
  cycle_strain               (cycle_mode, cycle_step, *swept)                 1
  cycle_work_rate            (cycle_mode, cycle_step, *swept)                 N mm
  cycle_energy               (cycle_mode, cycle_step, *swept)                 N mm
  cycle_friction_dissipated  (cycle_mode, cycle_step, *swept)                 N mm
  cycle_reaction_force       (cycle_mode, cycle_step, *swept, side, component) N
  cycle_converged            (cycle_mode, cycle_step, *swept)                 1
  cycle_branch_jumps         (cycle_mode, cycle_step, *swept)                 1
  cycle_branch_limit_points  (cycle_mode, cycle_step, *swept)                 1
  cycle_work                 (cycle_mode, *swept)                             N mm
  cycle_potential_change     (cycle_mode, *swept)                             N mm
  cycle_dissipated_energy    (cycle_mode, *swept)                             N mm
  =========================  ===============================================  =====

  ``cycle_work_rate`` is dW/d eps of the clamps at the equilibrium (``strain.pinned_energy``:
  the clamp forces times d(end position)/d eps, the generalised force of the strain); the
  loop of ``cycle_work_rate`` against ``cycle_strain`` encloses ``cycle_work``, the clamps'
  work over the closed cycle by the trapezoid rule. ``cycle_dissipated_energy`` is the
  friction's return-map dissipation over the cycle (``FrictionTerm.dissipated``, 0 without
  friction). The balance ``cycle_work = cycle_potential_change + cycle_dissipated_energy``
  holds to the trapezoid rule's error on a quasi-static path (``strain.path: quasi_static``;
  tests/test_rve_friction.py checks it converges with the step). ``cycle_branch_jumps`` and
  ``cycle_branch_limit_points`` are the step's equilibrium-path test (``strain.follow_branch``,
  ``rve.homogenisation.branch``): jumps to another equilibrium that following the branch
  avoided, and limit points where the branch ended and the jump was kept; NaN where the step
  was not tested (the option off, or a frictional step) and at step 0.
* :func:`plot_cycles` ``(ds, path)``: the loops, one panel per cycled mode, one line per
  combination of the swept parameters (labelled by them), with the dissipated energy.
* :func:`cycle_report_job` ``(table, outputs, log)``: the rule ``rve_cycle_report``.
"""
from __future__ import annotations

import itertools
import logging
import os
from typing import Mapping, Optional, Sequence, Union

import numpy as np
import xarray as xr

from .schema import COMPONENTS, DIMENSIONLESS

__all__ = ["CYCLE_VARIABLES", "add_cycle_variables", "plot_cycles", "cycle_report_job"]

log = logging.getLogger("rve.tables.cycles")

#: name -> (trailing dims, units, long_name); the leading dims are (cycle_mode, [cycle_step,] *swept)
CYCLE_VARIABLES = {
    "cycle_strain": (("cycle_step",), DIMENSIONLESS, "applied strain of the loading-unloading cycle (up to the "
                     "turning point, then back to 0)"),
    "cycle_work_rate": (("cycle_step",), "N mm", "work of the clamps per unit applied strain dW/d(strain) at the "
                        "equilibrium (the generalised force of the strain)"),
    "cycle_energy": (("cycle_step",), "N mm", "stored potential energy of the cell (beam strain and contact "
                     "penalty energy)"),
    "cycle_friction_dissipated": (("cycle_step",), "N mm", "energy dissipated by fibril-fibril friction since the "
                                  "start of the cycle (return-map dissipation; 0 without friction)"),
    "cycle_reaction_force": (("cycle_step", "side", "component"), "N", "total reaction force of the clamped "
                             "fibril ends on one side of the RVE during the cycle"),
    "cycle_converged": (("cycle_step",), DIMENSIONLESS, "1 if the cycle state is a static equilibrium, 0 if it "
                        "was kept unconverged"),
    "cycle_branch_jumps": (("cycle_step",), DIMENSIONLESS, "jumps to another equilibrium avoided by following the "
                           "branch in the cycle step (NaN: the step was not tested)"),
    "cycle_branch_limit_points": (("cycle_step",), DIMENSIONLESS, "limit points of the branch in the cycle step, "
                                  "where the jump to another equilibrium was kept (NaN: the step was not tested)"),
    "cycle_work": ((), "N mm", "work of the clamps over the closed loading-unloading cycle (trapezoid rule over "
                   "the cycle's steps: the area of the cycle_work_rate loop)"),
    "cycle_potential_change": ((), "N mm", "stored potential energy at the end of the cycle minus at its start"),
    "cycle_dissipated_energy": ((), "N mm", "energy dissipated by friction per loading-unloading cycle "
                                "(return-map dissipation over the cycle)"),
}

PathLike = Union[str, os.PathLike]


def _swept(ds) -> list[str]:
    return [p for p in str(ds.attrs.get("swept_parameters", "")).split() if p in ds.coords]


def add_cycle_variables(ds: xr.Dataset, states: Sequence) -> xr.Dataset:
    """The cycle variables of the states (module docstring) added to ``ds`` (returned)."""
    from ..homogenisation.checkpoint import load_state

    states = [load_state(s) if isinstance(s, (str, os.PathLike)) else s for s in states]
    states = [s for s in states if s.kind == "cycle"]
    if not states:
        return ds
    pnames = _swept(ds)
    modes = sorted({s.mode for s in states})
    n_steps = max(int(s.solver["cycle"]["steps"]) for s in states)
    sides = [str(v) for v in ds["side"].values] if "side" in ds.coords else ["x-", "x+", "y-", "y+"]
    ppos = {p: {(float(v) if not isinstance(v, str) else v): i for i, v in enumerate(ds[p].values.tolist())}
            for p in pnames}
    shape = (len(modes), n_steps + 1) + tuple(ds.sizes[p] for p in pnames)
    arr = {k: np.full(shape, np.nan) for k in ("cycle_strain", "cycle_work_rate", "cycle_energy",
                                               "cycle_friction_dissipated", "cycle_converged",
                                               "cycle_branch_jumps", "cycle_branch_limit_points")}
    reac = np.full(shape + (len(sides), 3), np.nan)
    start_d = np.full((len(modes),) + shape[2:], np.nan)
    last_d = {}
    for st in states:
        c = st.solver["cycle"]
        pidx = tuple(ppos[p][float(st.params[p]) if not isinstance(st.params[p], str) else st.params[p]]
                     for p in pnames)
        m = modes.index(st.mode)
        dissipated = float((st.friction or {}).get("dissipated", 0.0))
        rows = [(int(st.step), c, st.reaction_force, dissipated, st.solver.get("converged"))]
        if "start" in c:
            s0 = c["start"]
            rows.append((0, s0, s0.get("reaction_force") or {}, float(s0.get("dissipated", 0.0)), True))
            start_d[(m,) + pidx] = float(s0.get("dissipated", 0.0))
        for step, rec, rf, d, conv in rows:
            idx = (m, step) + pidx
            arr["cycle_strain"][idx] = float(rec["strain"])
            arr["cycle_work_rate"][idx] = float(rec["work_rate"])
            arr["cycle_energy"][idx] = float(rec["energy"])
            arr["cycle_friction_dissipated"][idx] = d
            arr["cycle_converged"][idx] = 1.0 if conv is not False else 0.0
            for side, vec in (rf or {}).items():
                if side in sides:
                    reac[idx + (sides.index(side),)] = np.asarray(vec, float)
        branch = st.solver.get("branch") or {}
        if branch and not branch.get("untested"):
            arr["cycle_branch_jumps"][(m, int(st.step)) + pidx] = float(branch.get("branch_jumps") or 0)
            arr["cycle_branch_limit_points"][(m, int(st.step)) + pidx] = float(branch.get("limit_points") or 0)
        last_d[(m,) + pidx] = max(last_d.get((m,) + pidx, (-1, 0.0)), (int(st.step), dissipated))
    arr["cycle_friction_dissipated"] -= start_d[:, None]
    lead = ("cycle_mode", "cycle_step") + tuple(pnames)
    out = ds.assign_coords(
        cycle_mode=("cycle_mode", np.array(modes, dtype=object),
                    {"units": DIMENSIONLESS, "long_name": "deformation mode of the loading-unloading cycle"}),
        cycle_step=("cycle_step", np.arange(n_steps + 1),
                    {"units": DIMENSIONLESS, "long_name": "step of the loading-unloading cycle (0: the relaxed "
                                                          "state, n: the turning point, 2n: back at strain 0)"}))
    for name, (dims, units, long_name) in CYCLE_VARIABLES.items():
        attrs = {"units": units, "long_name": long_name}
        if name in arr:
            out[name] = (lead, arr[name], attrs)
        elif name == "cycle_reaction_force":
            out[name] = (lead + ("side", "component"), reac, attrs)
    eps, rate, energy = arr["cycle_strain"], arr["cycle_work_rate"], arr["cycle_energy"]
    work = np.nansum(0.5 * (rate[:, 1:] + rate[:, :-1]) * np.diff(eps, axis=1), axis=1)
    complete = np.all(np.isfinite(rate), axis=1)
    lead2 = ("cycle_mode",) + tuple(pnames)
    for name, val in (("cycle_work", np.where(complete, work, np.nan)),
                      ("cycle_potential_change", energy[:, -1] - energy[:, 0]),
                      ("cycle_dissipated_energy", arr["cycle_friction_dissipated"][:, -1])):
        _, units, long_name = CYCLE_VARIABLES[name]
        out[name] = (lead2, val, {"units": units, "long_name": long_name})
    if "component" not in out.coords:
        out = out.assign_coords(component=("component", np.array(COMPONENTS, dtype=object)))
    out["cycle_work"].attrs["comment"] = ("balance: cycle_work = cycle_potential_change + cycle_dissipated_energy "
                                          "to the trapezoid rule's error on a quasi-static path")
    return out


def plot_cycles(ds: xr.Dataset, path: PathLike) -> None:
    """The hysteresis loops of the table's cycles (module docstring), written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pathlib import Path

    from ..io.atomic import atomic_path

    pnames = [p for p in _swept(ds) if p in ds["cycle_work_rate"].dims]
    modes = [str(m) for m in ds["cycle_mode"].values]
    fig, axes = plt.subplots(1, len(modes), figsize=(5.5 * len(modes), 4.2), squeeze=False)
    for ax, mode in zip(axes[0], modes):
        sub = ds.sel(cycle_mode=mode)
        for point in itertools.product(*[range(sub.sizes[p]) for p in pnames]):
            sel = dict(zip(pnames, point))
            one = sub.isel(sel)
            label = ", ".join(f"{p} = {one[p].values.item():g}" if not isinstance(one[p].values.item(), str)
                              else f"{p} = {one[p].values.item()}" for p in pnames) or "cycle"
            d = float(one["cycle_dissipated_energy"])
            ax.plot(one["cycle_strain"], one["cycle_work_rate"], marker="o", ms=3,
                    label=f"{label}: dissipated {d:.3g} N mm")
        ax.set_xlabel(f"{mode} strain")
        ax.set_ylabel("clamp work rate dW/d(strain) (N mm)")
        ax.set_title(f"{mode}: loading-unloading cycle")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def cycle_report_job(table: PathLike, outputs: Mapping[str, PathLike], log_path: Optional[PathLike]) -> None:
    """The rule ``rve_cycle_report``: the table's loops -> ``outputs["loops"]``."""
    from ..io.provenance import logging_to
    from .io import open_table

    with logging_to(log_path):
        ds = open_table(table)
        if "cycle_work_rate" not in ds:
            raise ValueError(f"{table}: the table has no loading-unloading cycle (strain.cycle_modes is empty)")
        plot_cycles(ds, outputs["loops"])
        for mode in ds["cycle_mode"].values:
            sub = ds.sel(cycle_mode=mode)
            log.info("%s cycle: work %s N mm, potential change %s N mm, friction dissipated %s N mm", mode,
                     np.asarray(sub["cycle_work"]).ravel().tolist(),
                     np.asarray(sub["cycle_potential_change"]).ravel().tolist(),
                     np.asarray(sub["cycle_dissipated_energy"]).ravel().tolist())
