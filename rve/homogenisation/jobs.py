"""The job bodies of the RVE pipeline's state rules (workflow/rules/rve.smk).

docs/rve_pipeline.md ("The DAG"). One function per rule; each reads only its input file
and the run spec (``rve.homogenisation.sweeps``), logs to the rule's log file
(``rve.io.provenance.logging_to``) and writes its output atomically:

==================  ====================================================================
``fabric_job``      run spec -> the designed initial state (``rve_fabric``)
``relax_job``       initial state -> relaxed state, strain 0 (``rve_relax``)
``strain_job``      previous state -> state after one strain step (``rve_strain_step``)
``probe_job``       a stored state -> its probe record, JSON (``rve_probes``)
==================  ====================================================================

``probe_record`` is the probe job without the file: the record ``rve.tables`` builds from.
The table rules (``rve_gather``, ``rve_report``) are ``rve.tables.jobs``: the tables are the
higher layer and import this package, never the other way round. A re-run of any job
gives the same bytes of data, so a killed run resumes from the last complete step with an
identical table (docs/rve_pipeline.md "Resume").
"""
from __future__ import annotations

import logging
import os
import time
from typing import Mapping, Optional, Union

import numpy as np

from ..io.atomic import atomic_write_json
from ..io.provenance import logging_to
from .sweeps import BASE_COMBO, combo_params, load_run_config

__all__ = ["fabric_job", "relax_job", "strain_job", "probe_record", "probe_job"]

log = logging.getLogger("rve.homogenisation.jobs")

PathLike = Union[str, os.PathLike]


def _fabric_mesh(cfg):
    from ..fabrics.setup import fabric_and_mesh

    return fabric_and_mesh(cfg)


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
    from ..fabrics.setup import clamp_reactions
    from .strain import relax_fabric

    with logging_to(log_path):
        cfg = load_run_config(spec, combo)
        fab, mesh = _fabric_mesh(cfg)
        st0 = load_state(in_state)
        _check_state(st0, mesh, in_state)
        x, system, info = relax_fabric(cfg, fab, mesh, st0.x)
        reac = clamp_reactions(fab, system, x)
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
    from ..fabrics.setup import clamp_reactions
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
        reac = clamp_reactions(fab, system, x)
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


def probe_record(state_file: PathLike, spec: Mapping, combo: str = BASE_COMBO,
                 tubes_path: Optional[PathLike] = None) -> dict:
    """The probe solves on one stored state -> its table record (rve.tables format,
    plus diagnostics: state file, kind, step, convergence, wall times). With
    ``tubes_path`` and the config's ``output.pictures``, also the state's tube mesh
    (``rve.homogenisation.pictures``) from the same probe fields."""
    from .checkpoint import load_state
    from .probes import solve_probes

    t0 = time.perf_counter()
    cfg = load_run_config(spec, combo)
    fab, mesh = _fabric_mesh(cfg)
    st = load_state(state_file)
    _check_state(st, mesh, state_file)
    pictures = tubes_path is not None and cfg.output.pictures
    results = solve_probes(cfg, fab, mesh, st.x, with_fields=pictures)
    if pictures:
        from .pictures import write_state_tubes

        write_state_tubes(tubes_path, cfg, fab, mesh, st, results)
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
              combo: str = BASE_COMBO, tubes_path: Optional[PathLike] = None) -> dict:
    """Probe solves of one stored state; write its record (JSON, atomic) and, with
    ``output.pictures``, first its tube mesh ``tubes_path`` (so a record on disk means
    its tube file is too)."""
    with logging_to(log_path):
        rec = probe_record(in_state, spec, combo, tubes_path)
        worst = max((p["conservation_error"] for p in rec["probes"].values()), default=0.0)
        log.info("%s: %s; worst charge-conservation error %.2e; %.1f s", in_state,
                 ", ".join(f"{k} R={v['resistance']:.6g} ohm Tmax={v['temperature_max']:.4g} K"
                           for k, v in rec["probes"].items()), worst, rec["wall_s"])
        atomic_write_json(out_record, rec)
    return rec
