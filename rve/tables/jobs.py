"""The job bodies of the table rules (workflow/rules/rve.smk): ``rve_gather``, ``rve_exports``, ``rve_report``.

docs/rve_pipeline.md ("The DAG"). ``gather_job``: every probe record of a run -> the
lookup table (netCDF), its csv export and a text summary, all atomic; ``export_job``: the
table -> its macro-ready exports (docs/macro_export.md); ``report_job``: the table -> its figures. ``gather_records`` turns probe records into table records (the
relaxed state becomes the strain-0 record of every mode).

The tables are the higher layer: this module imports the homogenisation (run configs,
fabric, network probes); nothing in ``rve.homogenisation`` imports ``rve.tables``.
"""
from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from ..config import config_as_dict
from ..homogenisation.network import network_probes
from ..fabrics.setup import fabric_and_mesh
from ..homogenisation.sweeps import combos, load_run_config, swept_dims
from ..io.atomic import atomic_write_text
from ..io.provenance import logging_to
from .build import build_table
from .export import export_table
from .io import open_table, write_table
from .plot import plot_table
from .summary import summarize

__all__ = ["gather_records", "gather_job", "export_job", "report_job"]

log = logging.getLogger("rve.tables.jobs")

PathLike = Union[str, os.PathLike]


def gather_records(records: Iterable[Union[PathLike, Mapping]], modes: Sequence[str]) -> list[dict]:
    """Probe records -> table records: the relaxed state's record (mode None) becomes the
    strain-0 record of every mode in ``modes``."""
    out = []
    for r in records:
        rec = json.loads(Path(r).read_text()) if not isinstance(r, Mapping) else dict(r)
        if rec.get("mode") is None:
            for m in modes:
                out.append({**rec, "mode": m, "strain": 0.0})
        else:
            out.append(rec)
    return out


def _fabric_desc(fab, mesh, cfg) -> dict:
    desc = {"kind": fab.kind, "n_fibrils": int(fab.n_fibrils), "half_widths": [float(v) for v in fab.half_widths],
            "elements_per_fibril": int(cfg.mesh.elements), "order": int(cfg.mesh.order),
            "fibril_radius": float(cfg.fabric.fibril_diameter / 2),
            # g: sum of reference length x pi R^2 x rho (the areal density of rve.tables.macro)
            "fibril_mass_g": float(sum(f.length * np.pi * f.radius ** 2 for f in fab.fibrils)
                                   * float(cfg.material.density))}
    for d in ("warp", "weft", "loop"):
        n = sum(1 for y in fab.yarns if y.direction == d)
        if n:
            desc[f"n_{d}"] = n
    if fab.kind != "knit":
        desc.update({"spacing": float(cfg.fabric.spacing), "amplitude": float(cfg.fabric.amplitude),
                     "rows": list(cfg.fabric.rows)})
    return desc


def _describe_periodic(ds, cfg) -> None:
    """What the face forces and resistances of a periodic cell's table are (docs/periodic.md)."""
    ds.attrs["boundary"] = "periodic"
    ds.attrs["cell_repeat"] = int(cfg.cell.repeat)
    for name in ("reaction_force", "membrane_force"):
        if name in ds:
            ds[name].attrs["comment"] = "; ".join(filter(None, [
                ds[name].attrs.get("comment"), "periodic cell: the Hill-Mandel stress P times the face length "
                "(tie forces and contact forces on the periodic images), x+ = P e1 L_y, y+ = P e2 L_x"]))
    if "probe_resistance" in ds:
        ds["probe_resistance"].attrs["comment"] = "; ".join(filter(None, [
            ds["probe_resistance"].attrs.get("comment"), "periodic cell: sheet resistance (ohm per square) of a "
            "macro field along the probe's axis, E / j with j the current per unit reference width"]))


def gather_job(record_files: Sequence[PathLike], out_table: PathLike, out_csv: PathLike, out_summary: PathLike,
               log_path: Optional[PathLike], spec: Mapping, run: str = "", cycle_states: Sequence[PathLike] = ()):
    """All probe records of a run -> the lookup table (netCDF), its CSV export and a
    text summary (all atomic). ``cycle_states``: the states of the run's loading-unloading
    cycles (``strain.cycle_modes``), added as the ``cycle_*`` variables (``rve.tables.cycles``)."""
    with logging_to(log_path):
        cfgs = {c.id: load_run_config(spec, c.id) for c in combos(spec)}
        first = next(iter(cfgs.values()))
        fab, mesh = fabric_and_mesh(first)
        records = gather_records(record_files, first.strain.modes)
        kinds = {c.fabric.kind for c in cfgs.values()}
        net = network_probes(first, fab) if len(kinds) == 1 or "knit" not in kinds else {}
        ds = build_table(records, fabric=_fabric_desc(fab, mesh, first),
                         config={"run": run, "spec": dict(spec), "scene": config_as_dict(first)},
                         swept=swept_dims(spec) or None, network_probes=net,
                         title=f"RVE lookup table of run {run or '?'}: {fab.kind}",
                         source="rve.tables.jobs.gather_job (Snakemake workflow/rules/rve.smk)")
        worst = max((p.get("conservation_error", 0.0) for r in records for p in r["probes"].values()), default=0.0)
        ds.attrs["max_charge_conservation_error"] = float(worst)
        unconverged = [f"{r['mode']} strain {r['strain']:g}" for r in records
                       if (r.get("state") or {}).get("converged") is False]
        if unconverged:
            log.warning("table %s: %d state(s) are not static equilibria (see equilibrium_residual): %s",
                        out_table, len(unconverged), ", ".join(unconverged))
        ds.attrs["probe_definitions"] = json.dumps([p.model_dump() for p in first.probes])
        if first.boundary == "periodic":
            _describe_periodic(ds, first)
        if spec.get("accuracy"):  # the stated accuracy of this run's table, from its convergence study
            from .accuracy import annotate_accuracy, read_accuracy

            annotated = annotate_accuracy(ds, read_accuracy(spec["accuracy"]), first.mesh.elements,
                                          first.contact.penalty, source=str(spec["accuracy"]))
            log.info("accuracy %s: estimated_relative_error on %s", spec["accuracy"], ", ".join(annotated) or "nothing")
        if "realization" in ds.dims:  # a sweep over packing realizations: mean, std, 90 % band
            from .ensemble import add_ensemble_statistics

            ds = add_ensemble_statistics(ds, packing=first.packing.model_dump(exclude={"seed"}))
        if cycle_states:
            from .cycles import add_cycle_variables

            ds = add_cycle_variables(ds, list(cycle_states))
        write_table(ds, out_table)
        export_table(ds, out_csv, "csv")
        text = summarize(ds)
        atomic_write_text(out_summary, text)
        log.info("table %s from %d records:\n%s", out_table, len(records), text)
    return ds


def export_job(table: PathLike, outputs: Mapping[str, PathLike], log_path: Optional[PathLike]) -> list:
    """The macro-ready exports of the table (``rve.tables.formats.export_macro`` with its
    defaults: pretension removed, t = 1 mm, the table's units): ``outputs`` maps a format
    (abaqus, lsdyna, hermite, curves) to its path."""
    from .formats import export_macro

    with logging_to(log_path):
        ds = open_table(table)
        paths = []
        for fmt, out in outputs.items():
            paths += export_macro(ds, out, fmt, source=str(table))
        log.info("exports: %s", ", ".join(map(str, paths)))
    return paths


def report_job(table: PathLike, out_prefix: PathLike, log_path: Optional[PathLike]) -> list:
    """Figures of the table (thesis Figs. 7.4.3-7.4.4 style)."""
    with logging_to(log_path):
        ds = open_table(table)
        paths = plot_table(ds, out_prefix)
        log.info("figures: %s", ", ".join(map(str, paths)))
    return paths
