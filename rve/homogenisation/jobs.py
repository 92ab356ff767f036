"""The job bodies of the RVE pipeline's state rules (workflow/rules/rve.smk).

docs/rve_pipeline.md ("The DAG"). One function per rule; each reads only its input file
and the run spec (``rve.homogenisation.sweeps``), logs to the rule's log file
(``rve.io.provenance.logging_to``) and writes its output atomically:

==================  ====================================================================
``fabric_job``      run spec -> the designed initial state (``rve_fabric``)
``relax_job``       initial state -> relaxed state, strain 0 (``rve_relax``)
``strain_job``      previous state -> state after one strain step (``rve_strain_step``)
``cycle_job``       previous state -> state after one step of a loading-unloading cycle
                    (``rve_cycle_step``; ``strain.cycle_modes``)
``pullout_job``     previous state -> state after one yarn pull-out step (``rve_pullout_step``)
``probe_job``       a stored state -> its probe record, JSON (``rve_probes``)
==================  ====================================================================

``probe_record`` is the probe job without the file: the record ``rve.tables`` builds from.

Fault checks (docs/fault_tolerance.md): every job reads its input state with
``load_state(..., quarantine=True)`` (a file that fails its checksum is a
``CorruptFileError`` naming it and is moved to ``<name>.corrupt``, so the next snakemake
call reruns the job that wrote it); ``fabric_job`` runs ``rve.homogenisation.preflight``
(geometry, probe terminals, memory, output folder) before anything is computed; the relax
and strain jobs store only equilibria (final |F| finite and within the stage's tolerance;
otherwise the state goes to ``<name>.unconverged.nc`` and :class:`NotAnEquilibrium` is
raised, unless ``checks.keep_unconverged``); the probe job recomputes the state's
equilibrium residual and refuses (:class:`StateRefused`, file quarantined) a state whose
residual is more than ``checks.residual_refuse_factor`` x max(recorded, tolerance).
With friction (``friction.coefficient`` > 0) the relaxed state carries the friction history
with no elastic gap (the relaxation is frictionless), every strain step starts from its input
state's history and writes its own (``State.friction``), and the probe job recomputes the
residual with the stored history; a frictional run refuses a state without a history and a
frictionless run one with a history (``_check_friction``).
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
from .branch import BRANCH_COUNTS
from .sweeps import BASE_COMBO, combo_params, load_run_config

__all__ = ["fabric_job", "relax_job", "strain_job", "cycle_job", "pullout_job", "probe_record", "probe_job", "NotAnEquilibrium", "StateRefused",
           "recomputed_residual", "verify_equilibrium"]

log = logging.getLogger("rve.homogenisation.jobs")

PathLike = Union[str, os.PathLike]


def _fabric_mesh(cfg):
    from ..fabrics.setup import fabric_and_mesh

    return fabric_and_mesh(cfg)


class NotAnEquilibrium(RuntimeError):
    """A relax or strain job ended with |F| above its tolerance or not finite; the state was
    kept under a non-final name (``checkpoint.non_final_path``)."""


class StateRefused(ValueError):
    """The probe job's recomputed equilibrium residual contradicts the one the file records."""


def _write(path, state, fab, mesh, system=None):
    from .checkpoint import write_state

    write_state(path, state, fab, mesh, contact=system)


def _stage_tolerance(cfg, kind: str) -> float:
    return float(cfg.relaxation.static_atol if kind == "relaxed" else cfg.strain.static_atol)


def _store_equilibrium(cfg, out_state, st, fab, mesh, system, what: str) -> None:
    """Write ``st`` as the job's output if it is an equilibrium (or the config keeps
    unconverged states); else keep it as ``<name>.unconverged.nc`` and raise."""
    from .checkpoint import non_final_path

    tol = _stage_tolerance(cfg, st.kind)
    res = st.solver.get("residual_N")
    res = float("nan") if res is None else float(res)
    ok = bool(np.isfinite(res) and res <= tol)
    st.solver["converged"] = bool(ok and st.solver.get("converged", True) is not False)
    st.solver["tolerance_N"] = tol
    if ok or cfg.checks.keep_unconverged:
        if not ok:
            log.warning("%s: |F| = %.3e N exceeds the tolerance %.1e N; stored because checks.keep_unconverged "
                        "is true (the table marks it converged = 0)", what, res, tol)
        _write(out_state, st, fab, mesh, system)
        return
    kept = non_final_path(out_state)
    _write(kept, st, fab, mesh, system)
    raise NotAnEquilibrium(
        f"{what}: final |F| = {res:.3e} N {'is not finite' if not np.isfinite(res) else f'exceeds the tolerance {tol:.1e} N'}"
        f": not an equilibrium, not stored as {out_state}; the state is kept as {kept} for inspection "
        "(set checks.keep_unconverged: true to store it; the table then marks it converged = 0)")


def _config_dict(cfg) -> dict:
    from ..config import config_as_dict

    return config_as_dict(cfg)


def fabric_job(out_state: PathLike, log_path: Optional[PathLike], spec: Mapping, combo: str = BASE_COMBO):
    """Generate the fabric and its mesh; write the designed initial state."""
    from .checkpoint import State

    with logging_to(log_path):
        t0 = time.perf_counter()
        cfg = load_run_config(spec, combo)
        from .preflight import preflight

        fab, mesh = preflight(cfg, outputs=[out_state])
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
              combo: str = BASE_COMBO, threads: Optional[int] = None):
    """Relax the initial state (damped dynamics + static Newton); write step 0 (clamp
    reactions and the contact map included). ``threads``: of the minimiser's PARDISO
    factorisations (None: ``rve.solvers.linear.solver_threads()``; 1 and 2 give the same
    bits)."""
    from .checkpoint import State, load_state
    from ..fabrics.setup import clamp_reactions
    from ..solvers.linear import linear_threads, solver_threads
    from .multipliers import multiplier_record
    from .strain import friction_start, relax_fabric

    with logging_to(log_path), linear_threads(threads):
        log.info("relax job: the minimiser's PARDISO factorisations on %d thread(s)", solver_threads())
        cfg = load_run_config(spec, combo)
        fab, mesh = _fabric_mesh(cfg)
        st0 = load_state(in_state, quarantine=True)
        _check_state(st0, mesh, in_state)
        x, system, info = relax_fabric(cfg, fab, mesh, st0.x)
        # a periodic cell gives its face forces (the Hill-Mandel stress); the pinned cell its clamps
        reac = info.pop("reaction_force", None) or clamp_reactions(fab, system, x)
        cstate = system.contact_state(x.reshape(-1))
        st = State(x=x, w=np.zeros_like(x), origin=x, kind="relaxed", step=0, strain=0.0,
                   time=float(cfg.relaxation.duration), combo=combo, params=combo_params(spec, combo),
                   config=_config_dict(cfg), reaction_force=reac, contact_count=int(cstate["active_points"]),
                   solver=info, multipliers=multiplier_record(system), friction=friction_start(cfg, fab, mesh, x))
        _store_equilibrium(cfg, out_state, st, fab, mesh, system, f"relax job ({combo})")
        log.info("relaxed: converged=%s (|F| = %.3e N), %d active contact points, reactions %s, %.1f s -> %s",
                 info["converged"], info["residual_N"], st.contact_count, reac, info["wall_s"], out_state)
    return st


def strain_job(in_state: PathLike, out_state: PathLike, log_path: Optional[PathLike], spec: Mapping,
               combo: str, mode: str, step: int):
    """One strain step (Algorithm 7.1) from ``in_state``; write the new state."""
    from .checkpoint import State, load_state
    from ..fabrics.setup import clamp_reactions
    from .multipliers import multiplier_record
    from .strain import friction_record, strain_step

    step = int(step)
    with logging_to(log_path):
        cfg = load_run_config(spec, combo)
        if mode not in cfg.strain.modes:
            raise ValueError(f"mode {mode!r} is not in the config's strain.modes {cfg.strain.modes}")
        fab, mesh = _fabric_mesh(cfg)
        prev = load_state(in_state, quarantine=True)
        _check_state(prev, mesh, in_state)
        expect = "relaxed" if step == 1 else "strained"
        if prev.kind != expect or (step > 1 and (prev.mode != mode or prev.step != step - 1)):
            raise ValueError(f"{in_state}: expected the {expect} state before {mode} step {step}, got kind="
                             f"{prev.kind} mode={prev.mode!r} step={prev.step}")
        _check_friction(cfg, prev, in_state)
        x, system, info = strain_step(cfg, fab, mesh, prev.x, prev.origin, mode, step, multipliers=prev.multipliers,
                                      friction=prev.friction)
        # a periodic cell gives its face forces (the Hill-Mandel stress); the pinned cell its clamps
        reac = info.pop("reaction_force", None) or clamp_reactions(fab, system, x)
        cstate = system.contact_state(x.reshape(-1))
        st = State(x=x, w=np.zeros_like(x), origin=prev.origin, kind="strained", mode=mode, step=step,
                   strain=float(info["strain"]), time=prev.time + cfg.strain.t_step + cfg.strain.t_relax,
                   combo=combo, params=combo_params(spec, combo), config=_config_dict(cfg), reaction_force=reac,
                   contact_count=int(cstate["active_points"]), solver=info, multipliers=multiplier_record(system),
                   friction=friction_record(system))
        _store_equilibrium(cfg, out_state, st, fab, mesh, system, f"{mode} step {step} ({combo})")
        log.info("%s step %d (strain %g): converged=%s (|F| = %.3e N), %d contact points, reactions %s, %.1f s -> %s",
                 mode, step, st.strain, info["converged"], info["residual_N"], st.contact_count, reac, info["wall_s"],
                 out_state)
    return st


def cycle_job(in_state: PathLike, out_state: PathLike, log_path: Optional[PathLike], spec: Mapping,
              combo: str, mode: str, step: int):
    """Step ``step`` (1..2n) of the loading-unloading cycle of ``mode`` (``strain.cycle_modes``)
    from ``in_state`` (the relaxed state for step 1): Algorithm 7.1 between the cycle's levels
    (``cell_statics.cycle_levels``), the friction history carried as on the strain path. The
    state (kind ``cycle``) records in ``solver["cycle"]`` its strain, the potential ``energy``
    (N mm), the clamps' ``work_rate`` dW/d eps (N mm; ``strain.pinned_energy``) and whether the
    step loads or unloads; step 1 also the relaxed state's (``start``), so the cycle's table
    needs only the cycle's files."""
    from .cell_statics import cycle_levels
    from .checkpoint import State, load_state
    from ..fabrics.setup import clamp_reactions
    from .multipliers import multiplier_record
    from .strain import friction_record, mech_system, pinned_energy, seed_friction, strain_step

    step = int(step)
    with logging_to(log_path):
        cfg = load_run_config(spec, combo)
        if mode not in cfg.strain.cycle_modes:
            raise ValueError(f"mode {mode!r} is not in the config's strain.cycle_modes {cfg.strain.cycle_modes}")
        levels = cycle_levels(cfg)
        if not 1 <= step < len(levels):
            raise ValueError(f"cycle step must be in 1..{len(levels) - 1}, got {step}")
        fab, mesh = _fabric_mesh(cfg)
        prev = load_state(in_state, quarantine=True)
        _check_state(prev, mesh, in_state)
        expect = "relaxed" if step == 1 else "cycle"
        if prev.kind != expect or (step > 1 and (prev.mode != mode or prev.step != step - 1)):
            raise ValueError(f"{in_state}: expected the {expect} state before {mode} cycle step {step}, got kind="
                             f"{prev.kind} mode={prev.mode!r} step={prev.step}")
        _check_friction(cfg, prev, in_state)
        eps_prev, eps = float(levels[step - 1]), float(levels[step])
        # the friction's stick transient: a loading starts at step 1 and turns at the turning point
        turns = step > 1 and (eps - eps_prev) * (eps_prev - float(levels[step - 2])) < 0
        x, system, info = strain_step(cfg, fab, mesh, prev.x, prev.origin, mode, step, multipliers=prev.multipliers,
                                      friction=prev.friction, levels=(eps_prev, eps),
                                      loading_start="reversal" if turns else step == 1)
        energy, rate = pinned_energy(fab, mesh, system, x, prev.origin, mode, eps)
        info["cycle"] = {"strain": eps, "energy": energy, "work_rate": rate,
                         "leg": "load" if eps > eps_prev else "unload", "steps": len(levels) - 1}
        if step == 1:   # the relaxed state as the cycle's step 0 (its friction forces: none, no elastic gap)
            xf = prev.x.reshape(-1)
            sys0 = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf)
            seed_friction(sys0, prev.friction, xf)
            e0, r0 = pinned_energy(fab, mesh, sys0, prev.x, prev.origin, mode, eps_prev)
            info["cycle"]["start"] = {"strain": eps_prev, "energy": e0, "work_rate": r0,
                                      "reaction_force": prev.reaction_force,
                                      "dissipated": float((prev.friction or {}).get("dissipated", 0.0))}
        reac = clamp_reactions(fab, system, x)
        cstate = system.contact_state(x.reshape(-1))
        st = State(x=x, w=np.zeros_like(x), origin=prev.origin, kind="cycle", mode=mode, step=step, strain=eps,
                   time=prev.time + cfg.strain.t_step + cfg.strain.t_relax, combo=combo,
                   params=combo_params(spec, combo), config=_config_dict(cfg), reaction_force=reac,
                   contact_count=int(cstate["active_points"]), solver=info, multipliers=multiplier_record(system),
                   friction=friction_record(system))
        _store_equilibrium(cfg, out_state, st, fab, mesh, system, f"{mode} cycle step {step} ({combo})")
        log.info("%s cycle step %d (strain %g, %s): converged=%s (|F| = %.3e N), work rate %.6g N mm, energy "
                 "%.6g N mm, dissipated %.6g N mm -> %s", mode, step, eps, info["cycle"]["leg"], info["converged"],
                 info["residual_N"], rate, energy, (st.friction or {}).get("dissipated", 0.0), out_state)
    return st


def pullout_job(in_state: PathLike, out_state: PathLike, log_path: Optional[PathLike], spec: Mapping,
                combo: str, step: int):
    """Step ``step`` of the yarn pull-out (``rve.homogenisation.pullout``) from ``in_state``
    (the relaxed state for step 1); the state (kind ``pullout``) records ``solver["pullout"]``."""
    from .checkpoint import State, load_state
    from .multipliers import multiplier_record
    from .pullout import pullout_step
    from .strain import friction_record

    step = int(step)
    with logging_to(log_path):
        cfg = load_run_config(spec, combo)
        if cfg.boundary != "pinned":
            raise ValueError(f"pullout: boundary = {cfg.boundary!r}; the yarn pull-out is defined on the pinned cell")
        if cfg.contact.enforcement != "penalty":
            raise ValueError("pullout: contact.enforcement must be 'penalty' (the pull-out's static solves have no "
                             "Uzawa loop)")
        fab, mesh = _fabric_mesh(cfg)
        prev = load_state(in_state, quarantine=True)
        _check_state(prev, mesh, in_state)
        expect = "relaxed" if step == 1 else "pullout"
        if prev.kind != expect or (step > 1 and prev.step != step - 1):
            raise ValueError(f"{in_state}: expected the {expect} state before pull-out step {step}, got kind="
                             f"{prev.kind} step={prev.step}")
        _check_friction(cfg, prev, in_state)
        x, system, info = pullout_step(cfg, fab, mesh, prev.x, prev.origin, step, friction=prev.friction)
        cstate = system.contact_state(x.reshape(-1))
        po = info["pullout"]
        st = State(x=x, w=np.zeros_like(x), origin=prev.origin, kind="pullout", mode="pullout", step=step,
                   strain=float(po["displacement"]), time=prev.time, combo=combo, params=combo_params(spec, combo),
                   config=_config_dict(cfg), reaction_force={}, contact_count=int(cstate["active_points"]),
                   solver=info, multipliers=multiplier_record(system), friction=friction_record(system))
        _store_equilibrium(cfg, out_state, st, fab, mesh, system, f"pull-out step {step} ({combo})")
        log.info("pull-out step %d: u = %g mm, force %.6g N (supports %.3g N), released ends moved %.4g mm, "
                 "|F| = %.3e N -> %s", step, po["displacement"], po["force"], po["balance"],
                 po["released_displacement"], info["residual_N"], out_state)
    return st


def recomputed_residual(cfg, fab, mesh, x, multipliers=None, friction=None) -> float:
    """|F(x, 0)| on the free dofs (N) of a stored state, from scratch: the strain path's
    mechanics system (``strain.mech_system``, contact map built at ``x``; a periodic cell's
    reduced system at the macro gradient the state carries), with the state's contact
    ``multipliers`` (augmented Lagrangian: the equilibrium is one at those multipliers) and
    its friction history (``friction``: the friction forces that hold the state)."""
    from .multipliers import seed_multipliers
    from .strain import free_residual, mech_system, seed_friction

    if cfg.boundary == "periodic":
        from .periodic import periodic_free_residual

        return periodic_free_residual(cfg, fab, mesh, x, multipliers=multipliers, friction=friction)
    xf = np.asarray(x, float).reshape(-1)
    system = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf)
    seed_multipliers(system, multipliers)
    seed_friction(system, friction, xf)
    return free_residual(system, xf)


def verify_equilibrium(cfg, fab, mesh, st, path, quarantine: bool = True):
    """(recomputed, recorded) residual; refuses (:class:`StateRefused`; with ``quarantine``
    the file is moved to ``<name>.corrupt``) a state whose recomputed residual is far above
    the recorded one."""
    recorded = st.solver.get("residual_N")
    recorded = float("nan") if recorded is None else float(recorded)
    tol = _stage_tolerance(cfg, st.kind)
    residual = recomputed_residual(cfg, fab, mesh, st.x, st.multipliers, st.friction)
    factor = float(cfg.checks.residual_refuse_factor)
    limit = factor * max(recorded if np.isfinite(recorded) else 0.0, tol)
    log.info("%s: equilibrium residual recomputed %.3e N (recorded %.3e N, limit %.3e N)", path, residual,
             recorded, limit)
    if st.kind == "initial":
        # the designed (unrelaxed) state claims no equilibrium: its residual is recorded, not judged
        return residual, recorded
    if not (np.isfinite(residual) and residual <= limit):
        from ..io.checksum import quarantine as move_aside

        dest = move_aside(path) if quarantine else None
        moved = (f"moved to {dest.name}, so the job that wrote it reruns on the next snakemake call" if dest
                 else "delete it (or `rve check --quarantine`) so the job that wrote it reruns")
        raise StateRefused(
            f"{path}: refused: its equilibrium residual recomputed at load is {residual:.3e} N, the file records "
            f"{recorded:.3e} N (limit {factor:g} x max(recorded, tolerance {tol:.1e} N) = {limit:.3e} N): the "
            f"stored state is not the equilibrium it claims to be (damaged or edited); {moved}")
    return residual, recorded


def _check_multipliers(cfg, st, path) -> None:
    """An augmented Lagrangian state must carry its multipliers: without them its probes would
    take the contact width from the penalty overlap, which the multipliers drove to zero."""
    augmented = cfg.contact.enforcement == "augmented_lagrangian"
    if augmented and st.multipliers is None and st.kind != "initial":
        raise ValueError(f"{path}: contact.enforcement = 'augmented_lagrangian' but the state has no contact "
                         "multipliers (contact_multiplier): it was not written by an augmented Lagrangian run")
    if not augmented and st.multipliers is not None:
        raise ValueError(f"{path}: the state carries contact multipliers but contact.enforcement = "
                         f"{cfg.contact.enforcement!r}: it was written by an augmented Lagrangian run")


def _check_friction(cfg, st, path) -> None:
    """A state of a run with friction must carry its friction history (without it the next
    step would start every contact without elastic gap: another path), and a frictionless
    run must not read a frictional state."""
    if st.kind == "initial":
        return
    if cfg.has_friction and st.friction is None:
        raise ValueError(f"{path}: the config has friction (friction.coefficient = {cfg.friction.coefficient:g}) but "
                         "the state has no friction history (contact_friction_key): it was written by a "
                         "frictionless run")
    if not cfg.has_friction and st.friction is not None:
        raise ValueError(f"{path}: the state carries a friction history but the config has friction.coefficient = "
                         "0: it was written by a run with friction")


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
    st = load_state(state_file, quarantine=True)
    _check_state(st, mesh, state_file)
    _check_multipliers(cfg, st, state_file)
    _check_friction(cfg, st, state_file)
    residual, recorded = verify_equilibrium(cfg, fab, mesh, st, state_file)
    pictures = tubes_path is not None and cfg.output.pictures
    results = solve_probes(cfg, fab, mesh, st.x, with_fields=pictures, multipliers=st.multipliers)
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
                  "converged": st.solver.get("converged"), "residual_N": residual,
                  "residual_N_recorded": recorded},
        "wall_s": time.perf_counter() - t0,
    }
    if st.friction is not None:   # the friction of the state (relaxed: the start of the path, none yet)
        fs = st.solver.get("friction") or {}
        rec["friction"] = {"dissipated_energy": float(st.friction.get("dissipated", 0.0)),
                           "friction_force": float(fs.get("friction_force", 0.0)),
                           "normal_force": float(fs.get("normal_force", 0.0)),
                           "stick_points": int(fs.get("stick", 0)), "slip_points": int(fs.get("slip", 0))}
    branch = st.solver.get("branch")
    if branch:   # the step's equilibrium-path test (rve.homogenisation.branch), for the table's attributes
        rec["state"]["branch"] = {k: branch.get(k) for k in BRANCH_COUNTS + ("kept", "untested")}
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
