"""The RVE pipeline's stages: one function per Snakemake rule (workflow/rules/rve.smk).

Thesis ch. 7 (Algorithm 7.1); SPEC §6; docs/rve_pipeline.md.

Runs and combinations
=====================
The pipeline config (configs/pipeline.yaml, section ``rve``) names **runs**; a run spec
is a mapping::

    scene_config: configs/rve/plain_weave.yaml   # an RVEConfig file (or null)
    scene: {...}                                 # inline RVEConfig keys merged over it
    overrides: ["mesh.elements=20"]              # dotted KEY=VALUE overrides
    sweep: {fibril_radius: [0.12, 0.15], contact_conductance: [0.5, 1.0], weave: [plain, twill_2_2]}

Every point of the product of the sweep lists is a **combination** with a readable id
(``combo_ids``: ``fibril_radius-0.12__contact_conductance-0.5__weave-plain``; ``base``
without a sweep) and its own jobs. Sweep keys are table dimension names or config paths:
``fibril_radius`` / ``fibril.radius`` (sets ``fabric.fibril_diameter`` = 2 R),
``contact_conductance`` / ``contact.sigma_c`` (``contact.conductance``),
``thermal_contact_conductance`` / ``contact.h_c``, ``contact_penalty``, ``weave``
(``fabric.kind``), ``youngs_modulus``, ``conductivity``, ``thermal_conductivity``,
``spacing``, ``amplitude``, or any dotted RVEConfig path (dimension = the path with
dots replaced by underscores). Numeric values are in internal units or strings with units.

Files (``RVE_DIR`` = results/rve)
=================================
======================================================  ==============================
``{run}/{combo}/states/initial.nc``                     generated fabric (rve_fabric)
``{run}/{combo}/states/relaxed.nc``                     relaxed state = step 0 (rve_relax)
``{run}/{combo}/states/{mode}_{step:02d}.nc``           after strain step i (rve_strain_step)
``{run}/{combo}/probes/{state}.json``                   probe record of a state (rve_probes)
``{run}/table.nc``, ``table.csv``, ``summary.txt``      lookup table (rve_gather)
``{run}/plots/table_*.png``                             figures (rve_report)
======================================================  ==============================

Every output is written atomically (``rve.io.atomic``). The stage functions
(``fabric_job``, ``relax_job``, ``strain_job``, ``probe_job``, ``gather_job``,
``report_job``) read only their input file and the run spec, so a re-run of any job gives
the same bytes of data: a killed run resumes from the last complete step with an
identical table. ``run_local`` runs the same DAG in-process (no Snakemake);
``run_probes_dask`` sends the probe solves of many states to dask.
"""
from __future__ import annotations

import itertools
import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from ..io.atomic import atomic_write_json, atomic_write_text

__all__ = [
    "RVE_DIR", "Combo", "SWEEP_ALIASES", "combos", "combo_ids", "combo_params", "load_run_config",
    "state_name", "state_names", "probe_state_names", "state_path", "record_path", "previous_state",
    "run_record_paths", "table_outputs", "report_outputs", "default_targets", "network_probes",
    "logging_to", "fabric_job", "relax_job", "strain_job", "probe_record", "probe_job", "gather_records",
    "gather_job", "report_job", "run_local", "run_probes_dask",
]

log = logging.getLogger("rve.homogenisation.pipeline")

PathLike = Union[str, os.PathLike]
RVE_DIR = "results/rve"
BASE_COMBO = "base"

#: sweep key -> (table dimension, config path, factor applied to the value)
SWEEP_ALIASES: dict[str, tuple[str, str, Optional[float]]] = {
    "fibril_radius": ("fibril_radius", "fabric.fibril_diameter", 2.0),
    "fibril.radius": ("fibril_radius", "fabric.fibril_diameter", 2.0),
    "fibril_diameter": ("fibril_diameter", "fabric.fibril_diameter", 1.0),
    "contact_conductance": ("contact_conductance", "contact.conductance", 1.0),
    "contact.sigma_c": ("contact_conductance", "contact.conductance", 1.0),
    "thermal_contact_conductance": ("thermal_contact_conductance", "contact.heat_transfer", 1.0),
    "contact.h_c": ("thermal_contact_conductance", "contact.heat_transfer", 1.0),
    "contact_penalty": ("contact_penalty", "contact.penalty", 1.0),
    "weave": ("weave", "fabric.kind", None),
    "youngs_modulus": ("youngs_modulus", "material.youngs_modulus", 1.0),
    "conductivity": ("conductivity", "material.electrical_conductivity", 1.0),
    "thermal_conductivity": ("thermal_conductivity", "material.thermal_conductivity", 1.0),
    "spacing": ("spacing", "fabric.spacing", 1.0),
    "amplitude": ("amplitude", "fabric.amplitude", 1.0),
}


# ============================================================================ logging
from ..io.provenance import logging_to  # noqa: E402  (one implementation for every rule body)


# ============================================================================ runs, combos
@dataclass(frozen=True)
class Combo:
    id: str
    params: dict          # table dimension -> value
    overrides: tuple      # dotted config overrides


def _sweep_key(key: str) -> tuple[str, str, Optional[float]]:
    if key in SWEEP_ALIASES:
        return SWEEP_ALIASES[key]
    if "." not in key:
        raise ValueError(f"unknown sweep parameter {key!r}: use one of {sorted(SWEEP_ALIASES)} or a dotted "
                         "config path such as contact.penalty")
    return key.replace(".", "_"), key, 1.0


def _path_unit(path: str) -> Optional[str]:
    from ..config import config_units

    from .config import RVEConfig

    node: Any = config_units(RVEConfig)
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node if isinstance(node, str) else None


def _sweep_value(value, path: str):
    if isinstance(value, bool):
        raise ValueError(f"sweep of {path}: booleans are not supported")
    if isinstance(value, (int, float)):
        return float(value)
    unit = _path_unit(path)
    if unit is None:
        return str(value)
    from ..config.units import convert

    return float(convert(value, unit))


def _token(v) -> str:
    if isinstance(v, float):
        return format(v, ".12g")
    return str(v)


def combos(spec: Mapping) -> list[Combo]:
    """The combinations of a run spec's ``sweep`` (one ``base`` combination without)."""
    sweep = dict(spec.get("sweep") or {})
    if not sweep:
        return [Combo(BASE_COMBO, {}, ())]
    keys, dims, lists = [], [], []
    for key, values in sweep.items():
        dim, path, factor = _sweep_key(str(key))
        if dim in dims:
            raise ValueError(f"sweep: parameter {dim!r} given twice")
        vals = [_sweep_value(v, path) for v in (values if isinstance(values, (list, tuple)) else [values])]
        if not vals or len(set(map(_token, vals))) != len(vals):
            raise ValueError(f"sweep {key}: needs distinct values, got {values!r}")
        keys.append((dim, path, factor))
        dims.append(dim)
        lists.append(vals)
    out = []
    for point in itertools.product(*lists):
        params, overrides, parts = {}, [], []
        for (dim, path, factor), v in zip(keys, point):
            params[dim] = v
            cv = v * factor if (factor is not None and isinstance(v, float)) else v
            overrides.append(f"{path}={json.dumps(cv)}")
            parts.append(f"{dim}-{_token(v)}")
        out.append(Combo("__".join(parts), params, tuple(overrides)))
    return out


def combo_ids(spec: Mapping) -> list[str]:
    return [c.id for c in combos(spec)]


def _combo(spec: Mapping, combo_id: str) -> Combo:
    for c in combos(spec):
        if c.id == combo_id:
            return c
    raise ValueError(f"unknown combination {combo_id!r} (have {combo_ids(spec)})")


def combo_params(spec: Mapping, combo_id: str) -> dict:
    return dict(_combo(spec, combo_id).params)


def swept_dims(spec: Mapping) -> dict:
    """{table dimension: units} of a run's sweep (in sweep order)."""
    out = {}
    for key in (spec.get("sweep") or {}):
        dim, path, _ = _sweep_key(str(key))
        unit = _path_unit(path)
        out[dim] = _table_unit(unit) if unit else "1"
    return out


_UNIT_TEXT = {"mm": "mm", "MPa": "MPa", "A/(mm^2*V)": "A mm-2 V-1", "W/(mm^2*K)": "W mm-2 K-1", "S/mm": "S mm-1",
              "W/(mm*K)": "W mm-1 K-1", "N/mm^2": "N mm-2", "ms": "ms", "g/mm^3": "g mm-3", "V": "V",
              "g/(mm^3*ms)": "N ms mm-4", "dimensionless": "1"}


def _table_unit(unit: str) -> str:
    """Internal unit of a config field as a UDUNITS-style string for the table."""
    return _UNIT_TEXT.get(unit, unit)


def load_run_config(spec: Mapping, combo_id: str = BASE_COMBO):
    """The validated ``RVEConfig`` of one combination of a run spec."""
    from ..config import apply_overrides, read_config_source, validate_config
    from ..config.loader import _deep_merge

    path = spec.get("scene_config")
    raw = read_config_source(path) if path else {}
    inline = spec.get("scene") or {}
    raw = _deep_merge(raw, dict(inline)) if inline else raw
    raw.setdefault("scene", "rve")
    combo = _combo(spec, combo_id)
    raw = apply_overrides(raw, [*(spec.get("overrides") or []), *combo.overrides])
    return validate_config(raw)


# ============================================================================ names, paths
def state_name(mode: Optional[str], step: int) -> str:
    """``relaxed`` for step 0, ``{mode}_{step:02d}`` after."""
    return "relaxed" if step == 0 else f"{mode}_{int(step):02d}"


def state_names(cfg) -> list[str]:
    """Stored states of a config after relaxation: relaxed + every step of every mode."""
    names = ["relaxed"]
    for m in cfg.strain.modes:
        names += [state_name(m, i) for i in range(1, cfg.strain.steps + 1)]
    return names


probe_state_names = state_names


def state_path(run: str, combo: str, name: str, root: PathLike = RVE_DIR) -> str:
    return f"{root}/{run}/{combo}/states/{name}.nc"


def record_path(run: str, combo: str, name: str, root: PathLike = RVE_DIR) -> str:
    return f"{root}/{run}/{combo}/probes/{name}.json"


def previous_state(run: str, combo: str, mode: str, step: int, root: PathLike = RVE_DIR) -> str:
    """Input of strain step ``step`` of ``mode``: the relaxed state or the previous step."""
    step = int(step)
    if step < 1:
        raise ValueError(f"strain steps start at 1, got {step}")
    return state_path(run, combo, state_name(mode, step - 1), root)


def run_record_paths(spec: Mapping, run: str, root: PathLike = RVE_DIR) -> list[str]:
    """Every probe record of a run (all combinations, all stored states)."""
    out = []
    for c in combos(spec):
        cfg = load_run_config(spec, c.id)
        out += [record_path(run, c.id, n, root) for n in state_names(cfg)]
    return out


def table_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    return {"table": f"{root}/{run}/table.nc", "csv": f"{root}/{run}/table.csv",
            "summary": f"{root}/{run}/summary.txt"}


def report_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    pre = f"{root}/{run}/plots/table"
    return {"reaction_force": f"{pre}_reaction_force.png", "probe_resistance": f"{pre}_probe_resistance.png",
            "temperature_rise": f"{pre}_temperature_rise.png"}


def default_targets(config: Mapping, extra: Optional[Mapping[str, Sequence[str]]] = None) -> list[str]:
    """Targets of ``snakemake -j2``: the table and figures of every run in
    ``rve.default_runs`` when ``default_targets`` lists ``rve`` (the default), plus the
    outputs of the other names ``default_targets`` lists (``extra``: name -> files)."""
    names = list(config.get("default_targets") or ["rve"])
    extra = dict(extra or {})
    out: list[str] = []
    for name in names:
        if name == "rve":
            rve = config.get("rve") or {}
            for run in rve.get("default_runs") or []:
                out += list(table_outputs(run).values()) + list(report_outputs(run).values())
        elif name in extra:
            out += list(extra[name])
        else:
            raise ValueError(f"default_targets: unknown target group {name!r} (have rve, {', '.join(extra)})")
    return out


# ============================================================================ network probes
def network_probes(cfg, fab) -> dict:
    """Probes of ``cfg`` expressed as yarn-end terminals of the network model
    (``rve.tables.YarnNetwork``): {name: ((dir, index, '+'|'-'), ...)}; {} unless the
    fabric is a weave and every terminal is a warp or weft end."""
    if fab.kind == "knit":
        return {}
    index = {}
    for d in ("warp", "weft"):
        ys = sorted((y for y in fab.yarns if y.direction == d), key=lambda y: y.position)
        index.update({(d, round(y.position, 9)): k for k, y in enumerate(ys)})
    out = {}
    for p in cfg.probes:
        terms = []
        for t in p.terminals:
            key = (t.yarn, round(t.position, 9))
            if key not in index:
                return {}
            sign = "+" if t.end.endswith("+") else "-"
            axis_ok = (t.yarn == "warp" and t.end[0] == "x") or (t.yarn == "weft" and t.end[0] == "y")
            if not axis_ok:
                return {}
            terms.append((t.yarn, index[key], sign))
        out[p.name] = tuple(terms)
    return out


# ============================================================================ stages
def _fabric_mesh(cfg):
    from ..fabrics.setup import fabric_and_mesh as build_fabric

    return build_fabric(cfg)


def _write(path, state, fab, mesh, system=None):
    from .checkpoint import write_state

    write_state(path, state, fab, mesh, contact=system)


def _config_dict(cfg) -> dict:
    from ..config import config_as_dict

    return config_as_dict(cfg)


def fabric_job(out_state: PathLike, log_path: Optional[PathLike], spec: Mapping, combo: str = BASE_COMBO):
    """Generate the fabric and its mesh; write the designed initial state."""
    from .checkpoint import State

    with logging_to(log_path):
        t0 = time.perf_counter()
        cfg = load_run_config(spec, combo)
        fab, mesh = _fabric_mesh(cfg)
        x0 = fab.initial_state(mesh)
        st = State(x=x0, w=np.zeros_like(x0), origin=x0, kind="initial", combo=combo,
                   params=combo_params(spec, combo), config=_config_dict(cfg),
                   solver={"wall_s": time.perf_counter() - t0})
        _write(out_state, st, fab, mesh)
        log.info("fabric %s: %d fibrils, %d elements each, %d nodes, %d ends -> %s", fab.kind, mesh.n_fibrils,
                 cfg.mesh.elements, mesh.n_nodes, len(fab.end_tags), out_state)
    return st


def _check_state(st, mesh, path):
    if st.x.shape != (mesh.n_nodes, 9):
        raise ValueError(f"{path}: state has {st.x.shape[0]} nodes, the config's mesh has {mesh.n_nodes} "
                         "(the config changed since the state was written?)")


def relax_job(in_state: PathLike, out_state: PathLike, log_path: Optional[PathLike], spec: Mapping,
              combo: str = BASE_COMBO):
    """Relax the initial state (damped dynamics + static Newton); write step 0 (clamp
    reactions and the contact map included)."""
    from .checkpoint import State, load_state
    from ..fabrics.setup import clamp_reactions as reactions
    from .strain import relax_fabric

    with logging_to(log_path):
        cfg = load_run_config(spec, combo)
        fab, mesh = _fabric_mesh(cfg)
        st0 = load_state(in_state)
        _check_state(st0, mesh, in_state)
        x, system, info = relax_fabric(cfg, fab, mesh, st0.x)
        reac = reactions(fab, system, x)
        cstate = system.contact_state(x.reshape(-1))
        st = State(x=x, w=np.zeros_like(x), origin=x, kind="relaxed", step=0, strain=0.0,
                   time=float(cfg.relaxation.duration), combo=combo, params=combo_params(spec, combo),
                   config=_config_dict(cfg), reaction_force=reac, contact_count=int(cstate["active_points"]),
                   solver=info)
        _write(out_state, st, fab, mesh, system)
        log.info("relaxed: converged=%s (|F| = %.3e N), %d active contact points, reactions %s, %.1f s -> %s",
                 info["converged"], info["residual_N"], st.contact_count, reac, info["wall_s"], out_state)
    return st


def strain_job(in_state: PathLike, out_state: PathLike, log_path: Optional[PathLike], spec: Mapping,
               combo: str, mode: str, step: int):
    """One strain step (Algorithm 7.1) from ``in_state``; write the new state."""
    from .checkpoint import State, load_state
    from ..fabrics.setup import clamp_reactions as reactions
    from .strain import strain_step

    step = int(step)
    with logging_to(log_path):
        cfg = load_run_config(spec, combo)
        if mode not in cfg.strain.modes:
            raise ValueError(f"mode {mode!r} is not in the config's strain.modes {cfg.strain.modes}")
        fab, mesh = _fabric_mesh(cfg)
        prev = load_state(in_state)
        _check_state(prev, mesh, in_state)
        expect = "relaxed" if step == 1 else "strained"
        if prev.kind != expect or (step > 1 and (prev.mode != mode or prev.step != step - 1)):
            raise ValueError(f"{in_state}: expected the {expect} state before {mode} step {step}, got kind="
                             f"{prev.kind} mode={prev.mode!r} step={prev.step}")
        x, system, info = strain_step(cfg, fab, mesh, prev.x, prev.origin, mode, step)
        reac = reactions(fab, system, x)
        cstate = system.contact_state(x.reshape(-1))
        st = State(x=x, w=np.zeros_like(x), origin=prev.origin, kind="strained", mode=mode, step=step,
                   strain=float(info["strain"]), time=prev.time + cfg.strain.t_step + cfg.strain.t_relax,
                   combo=combo, params=combo_params(spec, combo), config=_config_dict(cfg), reaction_force=reac,
                   contact_count=int(cstate["active_points"]), solver=info)
        _write(out_state, st, fab, mesh, system)
        log.info("%s step %d (strain %g): converged=%s (|F| = %.3e N), %d contact points, reactions %s, %.1f s -> %s",
                 mode, step, st.strain, info["converged"], info["residual_N"], st.contact_count, reac, info["wall_s"],
                 out_state)
    return st


def probe_record(state_file: PathLike, spec: Mapping, combo: str = BASE_COMBO) -> dict:
    """The probe solves on one stored state -> its table record (rve.tables format,
    plus diagnostics: state file, kind, step, convergence, wall times)."""
    from .checkpoint import load_state
    from .probes import solve_probes

    t0 = time.perf_counter()
    cfg = load_run_config(spec, combo)
    fab, mesh = _fabric_mesh(cfg)
    st = load_state(state_file)
    _check_state(st, mesh, state_file)
    results = solve_probes(cfg, fab, mesh, st.x)
    rec = {
        "mode": st.mode or None,
        "strain": float(st.strain),
        "params": dict(st.params),
        "reaction_force": st.reaction_force,
        "contact_count": int(st.contact_count),
        "probes": {name: r.record() for name, r in results.items()},
        "state": {"file": str(state_file), "kind": st.kind, "step": int(st.step), "combo": st.combo,
                  "converged": st.solver.get("converged"), "residual_N": st.solver.get("residual_N")},
        "wall_s": time.perf_counter() - t0,
    }
    return rec


def probe_job(in_state: PathLike, out_record: PathLike, log_path: Optional[PathLike], spec: Mapping,
              combo: str = BASE_COMBO) -> dict:
    """Probe solves of one stored state; write its record (JSON, atomic)."""
    with logging_to(log_path):
        rec = probe_record(in_state, spec, combo)
        worst = max((p["conservation_error"] for p in rec["probes"].values()), default=0.0)
        log.info("%s: %s; worst charge-conservation error %.2e; %.1f s", in_state,
                 ", ".join(f"{k} R={v['resistance']:.6g} ohm Tmax={v['temperature_max']:.4g} K"
                           for k, v in rec["probes"].items()), worst, rec["wall_s"])
        atomic_write_json(out_record, rec)
    return rec


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
            "fibril_radius": float(cfg.fabric.fibril_diameter / 2)}
    for d in ("warp", "weft", "loop"):
        n = sum(1 for y in fab.yarns if y.direction == d)
        if n:
            desc[f"n_{d}"] = n
    if fab.kind != "knit":
        desc.update({"spacing": float(cfg.fabric.spacing), "amplitude": float(cfg.fabric.amplitude),
                     "rows": list(cfg.fabric.rows)})
    return desc


def gather_job(record_files: Sequence[PathLike], out_table: PathLike, out_csv: PathLike, out_summary: PathLike,
               log_path: Optional[PathLike], spec: Mapping, run: str = ""):
    """All probe records of a run -> the lookup table (netCDF), its CSV export and a
    text summary (all atomic)."""
    from ..tables import build_table, export_table, summarize, write_table

    with logging_to(log_path):
        cfgs = {c.id: load_run_config(spec, c.id) for c in combos(spec)}
        first = next(iter(cfgs.values()))
        fab, mesh = _fabric_mesh(first)
        records = gather_records(record_files, first.strain.modes)
        kinds = {c.fabric.kind for c in cfgs.values()}
        net = network_probes(first, fab) if len(kinds) == 1 or "knit" not in kinds else {}
        ds = build_table(records, fabric=_fabric_desc(fab, mesh, first),
                         config={"run": run, "spec": dict(spec), "scene": _config_dict(first)},
                         swept=swept_dims(spec) or None, network_probes=net,
                         title=f"RVE lookup table of run {run or '?'}: {fab.kind}",
                         source="rve.homogenisation.pipeline.gather_job (Snakemake workflow/rules/rve.smk)")
        worst = max((p.get("conservation_error", 0.0) for r in records for p in r["probes"].values()), default=0.0)
        ds.attrs["max_charge_conservation_error"] = float(worst)
        unconverged = [f"{r['mode']} strain {r['strain']:g}" for r in records
                       if (r.get("state") or {}).get("converged") is False]
        if unconverged:
            log.warning("table %s: %d state(s) are not static equilibria (see equilibrium_residual): %s",
                        out_table, len(unconverged), ", ".join(unconverged))
        ds.attrs["probe_definitions"] = json.dumps([p.model_dump() for p in first.probes])
        write_table(ds, out_table)
        export_table(ds, out_csv, "csv")
        text = summarize(ds)
        atomic_write_text(out_summary, text)
        log.info("table %s from %d records:\n%s", out_table, len(records), text)
    return ds


def report_job(table: PathLike, out_prefix: PathLike, log_path: Optional[PathLike]) -> list:
    """Figures of the table (thesis Figs. 7.4.3-7.4.4 style)."""
    from ..tables import open_table, plot_table

    with logging_to(log_path):
        ds = open_table(table)
        paths = plot_table(ds, out_prefix)
        log.info("figures: %s", ", ".join(map(str, paths)))
    return paths


# ============================================================================ drivers
def run_local(spec: Mapping, run: str = "local", root: PathLike = RVE_DIR, log_dir: Optional[PathLike] = None,
              plots: bool = False) -> "Any":
    """The whole DAG of one run in-process, in order, skipping outputs that exist (the
    same resume rule as Snakemake's). Returns the table Dataset."""
    root = str(root)
    logs = Path(log_dir) if log_dir else None

    def lp(name):
        return None if logs is None else logs / run / f"{name}.log"

    records = []
    for c in combos(spec):
        cfg = load_run_config(spec, c.id)
        init = state_path(run, c.id, "initial", root)
        if not Path(init).exists():
            fabric_job(init, lp(f"{c.id}/fabric"), spec, c.id)
        relaxed = state_path(run, c.id, "relaxed", root)
        if not Path(relaxed).exists():
            relax_job(init, relaxed, lp(f"{c.id}/relax"), spec, c.id)
        for m in cfg.strain.modes:
            for i in range(1, cfg.strain.steps + 1):
                out = state_path(run, c.id, state_name(m, i), root)
                if not Path(out).exists():
                    strain_job(previous_state(run, c.id, m, i, root), out, lp(f"{c.id}/{m}_{i:02d}"), spec, c.id, m, i)
        for n in state_names(cfg):
            rp = record_path(run, c.id, n, root)
            if not Path(rp).exists():
                probe_job(state_path(run, c.id, n, root), rp, lp(f"{c.id}/probes_{n}"), spec, c.id)
            records.append(rp)
    outs = table_outputs(run, root)
    ds = gather_job(records, outs["table"], outs["csv"], outs["summary"], lp("gather"), spec, run)
    if plots:
        report_job(outs["table"], f"{root}/{run}/plots/table", lp("report"))
    return ds


def _probe_task(state_file: str, spec: Mapping, combo: str) -> dict:
    return probe_record(state_file, spec, combo)


def run_probes_dask(states: Sequence[PathLike], config: Union[Mapping, Any], scheduler: Optional[str] = None,
                    combo: str = BASE_COMBO, num_workers: Optional[int] = None) -> list[dict]:
    """Probe solves of many stored states as independent dask tasks (SPEC §6).

    ``states``: checkpoint files; ``config``: a run spec (mapping, see the module
    docstring) or an ``RVEConfig`` (then used as the inline scene); ``scheduler``: None
    (dask's local multiprocessing scheduler), one of ``"processes"``, ``"threads"``,
    ``"synchronous"``, or the address of a dask.distributed scheduler
    (``"tcp://host:8786"``, needs the ``distributed`` package). Returns the records in the
    order of ``states`` (the same records ``probe_job`` writes)."""
    import dask

    if not isinstance(config, Mapping):
        spec = {"scene": _config_dict(config)}
    else:
        spec = dict(config)
    tasks = [dask.delayed(_probe_task, pure=True)(str(s), spec, combo) for s in states]
    if scheduler is not None and "://" in str(scheduler):
        from dask.distributed import Client  # optional dependency

        with Client(str(scheduler)) as client:
            futures = client.compute(tasks)
            return list(client.gather(futures))
    kwargs = {"scheduler": scheduler or "processes"}
    if num_workers:
        kwargs["num_workers"] = int(num_workers)
    return list(dask.compute(*tasks, **kwargs))
