"""The run layout of the RVE pipeline: every file path of a run, defined once.

docs/rve_pipeline.md ("Files"). The package (job bodies, tests, benchmarks) and the
Snakemake rules (workflow/rules/rve.smk) both take their paths from here. Every function
is a plain format of its arguments, so called with wildcard placeholders it returns the
rule's pattern: ``state_path("{run}", "{combo}", "{state}")`` ->
``results/rve/{run}/{combo}/states/{state}.nc``.

======================================================  =================================
``{RVE_DIR}/{run}/{combo}/states/initial.nc``           generated fabric (rve_fabric)
``{RVE_DIR}/{run}/{combo}/states/relaxed.nc``           relaxed state = step 0 (rve_relax)
``{RVE_DIR}/{run}/{combo}/states/{mode}_{step:02d}.nc`` after strain step i (rve_strain_step)
``{RVE_DIR}/{run}/{combo}/states/{mode}_cycle_{i:02d}.nc``  after step i of a loading-unloading
                                                        cycle (rve_cycle_step)
``{RVE_DIR}/{run}/{combo}/probes/{state}.json``         probe record of a state (rve_probes)
``{RVE_DIR}/{run}/table.nc``, ``table.csv``,            lookup table (rve_gather)
``summary.txt``
``{RVE_DIR}/{run}/table_abaqus.inc``, ``table_lsdyna.k``,  macro-FE exports (rve_exports;
``table_hermite.json``, ``table_curves/{curve}.csv``      docs/macro_export.md)
``{RVE_DIR}/{run}/plots/table_*.png``                   figures (rve_report)
``{RVE_DIR}/{run}/plots/table_cycle_loops.png``         hysteresis loops (rve_cycle_report)
``{RVE_DIR}/{run}/{combo}/states/pullout_{i:02d}.nc``   after yarn pull-out step i (rve_pullout_step)
``{RVE_DIR}/{run}/pullout.nc``, ``pullout.csv``,        pull-out curve (rve_pullout_table) and
``plots/table_pullout.png``                             its figure (rve_pullout_report)
``{RVE_DIR}/{run}/{combo}/tubes/{state}.vtp``           tube mesh of a state (rve_probes,
                                                        with ``output.pictures``)
``{RVE_DIR}/{run}/{combo}/pictures/{mode}.pvd``, ``*.png``  series and renders
                                                        (rve_pictures_relaxed, rve_pictures_mode)
``{RVE_DIR}/{run}/plots/ensemble_*.png``, ``ensemble.txt``  ensemble bands (rve_ensemble_report)
``{LOG_DIR}/{run}/{job}.log``                           log of a job (every rule)
``{BENCHMARK_DIR}/{run}/{job}.tsv``                     benchmark of a job (every rule)
======================================================  =================================

``{job}`` (``job_name``): ``{combo}/fabric``, ``{combo}/relax``,
``{combo}/strain/{state}``, ``{combo}/probes/{state}``, ``{combo}/pictures/{relaxed|mode}``, ``gather``,
``exports``, ``report``, ``ensemble_report``, ``cycle_report``, ``pullout_table``,
``pullout_report`` (a cycle step is ``{combo}/strain/{mode}_cycle_{step}``, a pull-out step
``{combo}/pullout/pullout_{step}``).
``RVE_DIR`` = results/rve, ``LOG_DIR`` = results/logs/rve, ``BENCHMARK_DIR`` =
results/benchmarks/rve; every function takes ``root`` to place a run elsewhere.

Also here: the state names (``state_name``, ``state_names``: ``relaxed``, then
``{mode}_{step:02d}``), the input of a strain step (``previous_state``), every record of a
run (``run_record_paths``) and the default targets of ``snakemake -j2``
(``default_targets``). Cheap to import (the Snakefile imports it at parse time).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
from typing import Mapping, NamedTuple, Optional, Sequence, Union

from .sweeps import combos, load_run_config

__all__ = [
    "ProbeTask", "probe_tasks", "RVE_DIR", "LOG_DIR", "BENCHMARK_DIR", "STAGES", "state_name", "state_names", "state_path", "record_path",
    "previous_state", "run_record_paths", "table_outputs", "export_outputs", "report_prefix", "report_outputs", "job_name",
    "log_path", "benchmark_path", "default_targets", "tubes_path", "picture_outputs", "picture_targets",
    "ensemble_report_outputs", "mode_state_names", "convergence_outputs", "convergence_default", "config_digest",
    "work_precision_outputs", "work_precision_runs", "cycle_state_name", "cycle_state_names", "previous_cycle_state",
    "cycle_state_paths", "cycle_report_outputs", "pullout_state_name", "previous_pullout_state",
    "pullout_state_paths", "pullout_outputs",
]

PathLike = Union[str, os.PathLike]

RVE_DIR = "results/rve"
LOG_DIR = "results/logs/rve"
BENCHMARK_DIR = "results/benchmarks/rve"

#: the jobs of a run, in DAG order (one Snakemake rule each)
STAGES = ("fabric", "relax", "strain", "probes", "probes_dask", "pictures", "gather", "exports", "report",
          "ensemble_report", "cycle_report", "pullout", "pullout_table", "pullout_report")


# ============================================================================ state names
def state_name(mode: Optional[str], step: int) -> str:
    """``relaxed`` for step 0, ``{mode}_{step:02d}`` after."""
    return "relaxed" if step == 0 else f"{mode}_{int(step):02d}"


def state_names(cfg) -> list[str]:
    """Stored states of a config after relaxation: relaxed + every step of every mode."""
    names = ["relaxed"]
    for m in cfg.strain.modes:
        names += [state_name(m, i) for i in range(1, cfg.strain.steps + 1)]
    return names


# ============================================================================ data files
def state_path(run: str, combo: str, name: str, root: PathLike = RVE_DIR) -> str:
    """Checkpoint of state ``name`` (``initial``, ``relaxed``, ``{mode}_{step:02d}``)."""
    return f"{root}/{run}/{combo}/states/{name}.nc"


def record_path(run: str, combo: str, name: str, root: PathLike = RVE_DIR) -> str:
    """Probe record (JSON) of state ``name``."""
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
    """The gather's outputs: ``table`` (netCDF), ``csv``, ``summary``."""
    return {"table": f"{root}/{run}/table.nc", "csv": f"{root}/{run}/table.csv",
            "summary": f"{root}/{run}/summary.txt"}


def export_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    """The macro-ready exports beside the table (``rve.tables.formats``): ``abaqus``,
    ``lsdyna``, ``hermite`` (files) and ``curves`` (a folder of ``{curve}.csv``)."""
    return {"abaqus": f"{root}/{run}/table_abaqus.inc", "lsdyna": f"{root}/{run}/table_lsdyna.k",
            "hermite": f"{root}/{run}/table_hermite.json", "curves": f"{root}/{run}/table_curves"}


def report_prefix(run: str, root: PathLike = RVE_DIR) -> str:
    """Path prefix of the report's figures (``rve.tables.plot_table``)."""
    return f"{root}/{run}/plots/table"


def report_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    """The report's figures: ``reaction_force``, ``probe_resistance``, ``temperature_rise``,
    ``by_parameter`` (``rve.tables.plot.plot_table``)."""
    pre = report_prefix(run, root)
    return {"reaction_force": f"{pre}_reaction_force.png", "probe_resistance": f"{pre}_probe_resistance.png",
            "temperature_rise": f"{pre}_temperature_rise.png", "by_parameter": f"{pre}_by_parameter.png"}


# ============================================================================ pictures
def tubes_path(run: str, combo: str, name: str, root: PathLike = RVE_DIR) -> str:
    """Tube mesh (.vtp) of state ``name``, written by its probe job (``output.pictures``)."""
    return f"{root}/{run}/{combo}/tubes/{name}.vtp"


def picture_outputs(run: str, combo: str, mode: Optional[str] = None, root: PathLike = RVE_DIR) -> dict:
    """Files of ``rve_pictures_relaxed`` (``mode`` None: ``relaxed_axial_force``,
    ``cross_section``) or of ``rve_pictures_mode`` (``pvd``, ``axial_force``, ``current``,
    ``temperature``) in ``{run}/{combo}/pictures/``."""
    d = f"{root}/{run}/{combo}/pictures"
    if mode is None:
        return {"relaxed_axial_force": f"{d}/relaxed_axial_force.png", "cross_section": f"{d}/cross_section.png"}
    return {"pvd": f"{d}/{mode}.pvd", "axial_force": f"{d}/{mode}_axial_force.png",
            "current": f"{d}/{mode}_current.png", "temperature": f"{d}/{mode}_temperature.png"}


def picture_targets(spec: Mapping, run: str, root: PathLike = RVE_DIR) -> list[str]:
    """Every picture file of a run whose combinations have ``output.pictures`` on."""
    out: list[str] = []
    for c in combos(spec):
        cfg = load_run_config(spec, c.id)
        if not cfg.output.pictures:
            continue
        out += list(picture_outputs(run, c.id, None, root).values())
        for m in cfg.strain.modes:
            out += list(picture_outputs(run, c.id, m, root).values())
    return out


# ============================================================================ loading-unloading cycles
def cycle_state_name(mode: str, step: int) -> str:
    """``{mode}_cycle_{step:02d}`` after step ``step`` of ``mode``'s cycle; ``relaxed`` for step 0."""
    return "relaxed" if int(step) == 0 else f"{mode}_cycle_{int(step):02d}"


def cycle_state_names(cfg, mode: str) -> list[str]:
    """The states of ``mode``'s loading-unloading cycle after the relaxed one (2n)."""
    n = int(cfg.strain.cycle_steps or cfg.strain.steps)
    return [cycle_state_name(mode, i) for i in range(1, 2 * n + 1)]


def previous_cycle_state(run: str, combo: str, mode: str, step: int, root: PathLike = RVE_DIR) -> str:
    """Input of cycle step ``step`` of ``mode``: the relaxed state or the previous cycle step."""
    step = int(step)
    if step < 1:
        raise ValueError(f"cycle steps start at 1, got {step}")
    return state_path(run, combo, cycle_state_name(mode, step - 1), root)


def cycle_state_paths(spec: Mapping, run: str, root: PathLike = RVE_DIR) -> list[str]:
    """Every cycle state of a run (all combinations, every mode of ``strain.cycle_modes``),
    the gather's input for the cycle variables of the table."""
    out = []
    for c in combos(spec):
        cfg = load_run_config(spec, c.id)
        for m in cfg.strain.cycle_modes:
            out += [state_path(run, c.id, n, root) for n in cycle_state_names(cfg, m)]
    return out


def cycle_report_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    """The hysteresis figure of a run with cycles: ``loops`` (work rate against strain per mode
    and combination)."""
    return {"loops": f"{report_prefix(run, root)}_cycle_loops.png"}


# ============================================================================ yarn pull-out
def pullout_state_name(step: int) -> str:
    """``pullout_{step:02d}`` after pull-out step ``step``; ``relaxed`` for step 0."""
    return "relaxed" if int(step) == 0 else f"pullout_{int(step):02d}"


def previous_pullout_state(run: str, combo: str, step: int, root: PathLike = RVE_DIR) -> str:
    """Input of pull-out step ``step``: the relaxed state or the previous pull-out step."""
    if int(step) < 1:
        raise ValueError(f"pull-out steps start at 1, got {step}")
    return state_path(run, combo, pullout_state_name(int(step) - 1), root)


def pullout_state_paths(spec: Mapping, run: str, root: PathLike = RVE_DIR) -> list[str]:
    """Every pull-out state of a run (all combinations, ``pullout.steps`` each)."""
    out = []
    for c in combos(spec):
        n = int(load_run_config(spec, c.id).pullout.steps)
        out += [state_path(run, c.id, pullout_state_name(i), root) for i in range(1, n + 1)]
    return out


def pullout_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    """The pull-out table of a run: ``table`` (netCDF) and ``csv``; and its figure ``curve``."""
    return {"table": f"{root}/{run}/pullout.nc", "csv": f"{root}/{run}/pullout.csv",
            "curve": f"{report_prefix(run, root)}_pullout.png"}


def mode_state_names(spec: Mapping, combo: str, mode: str) -> list[str]:
    """The relaxed state and every step of ``mode`` of one combination, in order."""
    steps = load_run_config(spec, combo).strain.steps
    return ["relaxed"] + [state_name(mode, i) for i in range(1, steps + 1)]


@functools.lru_cache(maxsize=None)
def _config_digest(spec_json: str, combo: str, source_text: str) -> str:
    cfg = load_run_config(json.loads(spec_json), combo)
    return hashlib.sha256(cfg.model_dump_json().encode()).hexdigest()[:16]


def config_digest(spec: Mapping, combo: str) -> str:
    """A digest of the resolved, validated scene config of one combination (16 hex digits).

    The first rule of a chain (``rve_fabric``) takes it as a param, so editing the scene
    config a run spec names (``scene_config``, e.g. ``mesh.elements`` in
    configs/rve/plain_weave.yaml) reruns that run's chain: Snakemake compares params, and a
    spec that only names the file would not change. Formatting and comments of the file do
    not change the digest; any resolved value does."""
    path = spec.get("scene_config")
    text = open(path, encoding="utf-8").read() if path and os.path.exists(path) else ""
    return _config_digest(json.dumps(spec, sort_keys=True, default=str), combo, text)   # cached per file content


def convergence_outputs(study: str, root: PathLike = RVE_DIR) -> dict:
    """Files of the table-convergence report of ``study`` (``rve.studies.table_convergence``)."""
    d = f"{root}/convergence/{study}"
    return {"csv": f"{d}/table_convergence.csv", "md": f"{d}/table_convergence.md",
            "png": f"{d}/table_convergence.png", "json": f"{d}/accuracy.json"}


def convergence_default(runs: Mapping, study: str) -> dict:
    """The default run's mesh and penalty of a study: its runs' configs without their sweeps."""
    cm = load_run_config({**runs[f"{study}_mesh"], "sweep": {}})
    cp = load_run_config({**runs[f"{study}_penalty"], "sweep": {}})
    return {"mesh_elements": float(cm.mesh.elements), "contact_penalty": float(cp.contact.penalty)}


def work_precision_outputs(study: str, root: PathLike = RVE_DIR) -> dict:
    """Files of the work-precision report of ``study`` (``rve.studies.work_precision``)."""
    d = f"{root}/work_precision/{study}"
    return {"md": f"{d}/work_precision.md", "csv": f"{d}/work_precision.csv", "png": f"{d}/work_precision.png",
            "json": f"{d}/accuracy.json"}


def _config_refusal(spec: Optional[Mapping], run: str) -> Optional[str]:
    """None when every combination of run ``run`` validates, else why not (the first refusal)."""
    if spec is None:
        return f"run {run!r} is not in rve.runs"
    try:
        for c in combos(spec):
            load_run_config(spec, c.id)
    except Exception as exc:   # a ConfigError, a pydantic ValidationError, a unit error: the config refuses it
        text = " ".join(str(exc).split())
        return f"run {run}: {text[:300]}"
    return None


def work_precision_runs(rve_config: Mapping, study: str) -> dict:
    """The runs of work-precision study ``study`` (``rve.work_precision.{study}`` of the
    pipeline config: ``reference``, ``default``, ``levers: {lever: run}``): ``{"reference",
    "default", "levers": {lever: run}, "skipped": {lever: why}}``. A lever whose run the
    config refuses (an override key it does not know, e.g. a lever not built yet) is
    skipped with the config's message; a refused reference or default is an error."""
    studies = rve_config.get("work_precision") or {}
    if study not in studies:
        raise ValueError(f"work-precision study {study!r} is not in rve.work_precision (have {sorted(studies)})")
    st, runs = studies[study], rve_config.get("runs") or {}
    for role in ("reference", "default"):
        why = _config_refusal(runs.get(st[role]), st[role]) if st.get(role) else None
        if why:
            raise ValueError(f"work-precision study {study}: its {role} run cannot run: {why}")
    levers, skipped = {}, {}
    for lever, run in (st.get("levers") or {}).items():
        why = _config_refusal(runs.get(run), run)
        if why:
            skipped[lever] = why
        else:
            levers[lever] = run
    return {"reference": st["reference"], "default": st.get("default"), "levers": levers, "skipped": skipped}


def ensemble_report_outputs(run: str, root: PathLike = RVE_DIR) -> dict:
    """Figures of an ensemble table (``rve.tables.ensemble.plot_ensemble``) and its text
    report (``report``: the band against the step-to-step wiggle)."""
    pre = f"{root}/{run}/plots/ensemble"
    return {"probe_resistance": f"{pre}_probe_resistance.png", "reaction_force": f"{pre}_reaction_force.png",
            "network": f"{pre}_network.png", "report": f"{root}/{run}/ensemble.txt"}


# ============================================================================ logs, benchmarks
def job_name(stage: str, combo: Optional[str] = None, state: Optional[str] = None) -> str:
    """Name of a job within its run (the relative path of its log and benchmark):
    ``{combo}/fabric``, ``{combo}/relax``, ``{combo}/strain/{state}``,
    ``{combo}/probes/{state}``, ``probes_dask`` (every probe job of the run on dask), ``gather``,
    ``report``."""
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r} (have {', '.join(STAGES)})")
    if stage in ("probes_dask", "gather", "exports", "report", "ensemble_report", "cycle_report", "pullout_table",
                 "pullout_report"):
        return stage
    if combo is None:
        raise ValueError(f"stage {stage!r}: a job of one combination needs its combo")
    if stage in ("fabric", "relax"):
        return f"{combo}/{stage}"
    if state is None:
        raise ValueError(f"stage {stage!r}: a job of one state needs its state name")
    return f"{combo}/{stage}/{state}"


def log_path(run: str, stage: str, combo: Optional[str] = None, state: Optional[str] = None,
             root: PathLike = LOG_DIR) -> str:
    """Log file of a job (``job_name``)."""
    return f"{root}/{run}/{job_name(stage, combo, state)}.log"


def benchmark_path(run: str, stage: str, combo: Optional[str] = None, state: Optional[str] = None,
                   root: PathLike = BENCHMARK_DIR) -> str:
    """Snakemake benchmark file of a job (``job_name``)."""
    return f"{root}/{run}/{job_name(stage, combo, state)}.tsv"


# ============================================================================ targets
def default_targets(config: Mapping, extra: Optional[Mapping[str, Sequence[str]]] = None) -> list[str]:
    """Targets of ``snakemake -j2``: the table, its macro-ready exports (runs without a
    parameter sweep: the exports need the swept values chosen, ``rve table export --param``)
    and figures (with the hysteresis loops of a run with ``strain.cycle_modes``) of every run in
    ``rve.default_runs`` when ``default_targets`` lists ``rve``
    (the default), plus the outputs of the other names ``default_targets`` lists
    (``extra``: name -> files)."""
    names = list(config.get("default_targets") or ["rve"])
    extra = dict(extra or {})
    out: list[str] = []
    for name in names:
        if name == "rve":
            rve = config.get("rve") or {}
            for run in rve.get("default_runs") or []:
                out += list(table_outputs(run).values()) + list(report_outputs(run).values())
                out += picture_targets(rve.get("runs", {}).get(run) or {}, run)
                if cycle_state_paths(rve.get("runs", {}).get(run) or {}, run):
                    out += list(cycle_report_outputs(run).values())
                if not (rve.get("runs", {}).get(run) or {}).get("sweep"):
                    out += list(export_outputs(run).values())
        elif name in extra:
            out += list(extra[name])
        else:
            raise ValueError(f"default_targets: unknown target group {name!r} (have rve, {', '.join(extra)})")
    return out


class ProbeTask(NamedTuple):
    """One probe job: the stored state, its record, its log, its combination, its tube file."""

    state: str
    record: str
    log: str
    combo: str
    tubes: str


def probe_tasks(spec: Mapping, run: str, root: str = RVE_DIR, log_root: str = LOG_DIR) -> list[ProbeTask]:
    """Every probe job of run ``run``, in the order of :func:`layout.run_record_paths`."""
    tasks = []
    for c in combos(spec):
        for name in state_names(load_run_config(spec, c.id)):
            tasks.append(ProbeTask(state_path(run, c.id, name, root), record_path(run, c.id, name, root),
                                   log_path(run, "probes", c.id, name, log_root), c.id,
                                   tubes_path(run, c.id, name, root)))
    return tasks
