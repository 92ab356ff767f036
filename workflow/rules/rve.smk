# RVE homogenisation (thesis ch. 7, Algorithm 7.1; docs/rve_pipeline.md). Each rule is a
# thin call into the package: rve.homogenisation.jobs (the states and probe records) and
# rve.tables.jobs (the table and its figures); every path comes from the run layout
# rve.homogenisation.layout (the one place the files of a run are named). Per run (config
# rve.runs) and per sweep combination ({combo}, "base" without a sweep):
#   rve_fabric -> rve_relax -> rve_strain_step (step i from step i-1, per mode)
#   -> rve_probes (one job per stored state, independent) -> rve_gather -> rve_report
#                                                                      -> rve_exports (macro-FE files)
#   -> rve_pictures_relaxed, rve_pictures_mode (per mode; with output.pictures: the probe jobs
#      write each state's tube mesh, these draw the .pvd series and the PNG renders)
# Every output is written atomically, so a killed run resumes from the last complete step.
# The strain steps (the critical path: two chains) have priority; the probe jobs fill in.
# The job modules are imported in the rule bodies: parsing the workflow stays cheap.

from rve.homogenisation import layout as rve_layout


wildcard_constraints:
    run=r"[A-Za-z0-9_]+",
    combo=r"[A-Za-z0-9_.+=-]+",
    mode=r"uniaxial_y|uniaxial|shear|trellis",
    step=r"[0-9]{2}",
    state=r"relaxed|(uniaxial_y|uniaxial|shear|trellis)_[0-9]{2}",
    # (cycle states, {mode}_cycle_{step}, have no probe job: the table takes their mechanics)


rule rve_fabric:
    """Generate the fabric and its mesh; write the designed initial state."""
    output:
        state=rve_layout.state_path("{run}", "{combo}", "initial"),
    log:
        rve_layout.log_path("{run}", "fabric", "{combo}"),
    benchmark:
        rve_layout.benchmark_path("{run}", "fabric", "{combo}")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
        # the resolved scene config: editing the file a spec names reruns the chain
        config_digest=lambda w: rve_layout.config_digest(config["rve"]["runs"][w.run], w.combo),
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    run:
        from rve.homogenisation.jobs import fabric_job

        fabric_job(output.state, log[0], params.spec, wildcards.combo)


rule rve_relax:
    """Relax the initial state to static equilibrium under contact (strain 0)."""
    input:
        state=rve_layout.state_path("{run}", "{combo}", "initial"),
    output:
        state=rve_layout.state_path("{run}", "{combo}", "relaxed"),
    log:
        rve_layout.log_path("{run}", "relax", "{combo}"),
    benchmark:
        rve_layout.benchmark_path("{run}", "relax", "{combo}")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    # the minimiser's PARDISO factorisations on 2 threads (reproducible mode: the same bits
    # when Snakemake scales this down to 1; docs/engine.md "Two threads")
    threads: 2
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    run:
        from rve.homogenisation.jobs import relax_job

        relax_job(input.state, output.state, log[0], params.spec, wildcards.combo, threads=threads)


rule rve_strain_step:
    """Strain step {step} of {mode} (Algorithm 7.1) from the previous stored state."""
    input:
        state=lambda w: rve_layout.previous_state(w.run, w.combo, w.mode, int(w.step)),
    output:
        state=rve_layout.state_path("{run}", "{combo}", "{mode}_{step}"),
    log:
        rve_layout.log_path("{run}", "strain", "{combo}", "{mode}_{step}"),
    benchmark:
        rve_layout.benchmark_path("{run}", "strain", "{combo}", "{mode}_{step}")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    priority: 10
    run:
        from rve.homogenisation.jobs import strain_job

        strain_job(
            input.state,
            output.state,
            log[0],
            params.spec,
            wildcards.combo,
            wildcards.mode,
            int(wildcards.step),
        )


rule rve_cycle_step:
    """Step {step} of the loading-unloading cycle of {mode} (strain.cycle_modes) from the previous state."""
    input:
        state=lambda w: rve_layout.previous_cycle_state(w.run, w.combo, w.mode, int(w.step)),
    output:
        state=rve_layout.state_path("{run}", "{combo}", "{mode}_cycle_{step}"),
    log:
        rve_layout.log_path("{run}", "strain", "{combo}", "{mode}_cycle_{step}"),
    benchmark:
        rve_layout.benchmark_path("{run}", "strain", "{combo}", "{mode}_cycle_{step}")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    priority: 10
    run:
        from rve.homogenisation.jobs import cycle_job

        cycle_job(input.state, output.state, log[0], params.spec, wildcards.combo, wildcards.mode, int(wildcards.step))


# The probe solves: one job per stored state (rve.probe_executor snakemake, the default), or
# one job per run that runs them all on a dask.distributed cluster (dask): the same records,
# bit for bit, without a process per second-long solve (rve.homogenisation.distributed).
PROBE_EXECUTOR = config["rve"].get("probe_executor", "snakemake")

if PROBE_EXECUTOR == "snakemake":

    rule rve_probes:
        """Decoupled probe solves (voltage, terminal currents, Joule temperature) on one state."""
        input:
            state=rve_layout.state_path("{run}", "{combo}", "{state}"),
        output:
            record=rve_layout.record_path("{run}", "{combo}", "{state}"),
        log:
            rve_layout.log_path("{run}", "probes", "{combo}", "{state}"),
        benchmark:
            rve_layout.benchmark_path("{run}", "probes", "{combo}", "{state}")
        params:
            spec=lambda w: config["rve"]["runs"][w.run],
            # side output with output.pictures (rve.homogenisation.pictures): the state's tube mesh
            tubes=lambda w: rve_layout.tubes_path(w.run, w.combo, w.state),
        threads: 1
        resources:
            mem_mb=config["resources"]["rve_mem_mb"],
            runtime=config["resources"]["rve_runtime_min"],
        run:
            from rve.homogenisation.jobs import probe_job

            probe_job(input.state, output.record, log[0], params.spec, wildcards.combo, params.tubes)

else:
    PROBE_DASK = config["rve"].get("probe_dask", {})
    for _run, _spec in config["rve"]["runs"].items():

        rule:
            """Every probe solve of one run on a dask.distributed cluster (rve.probe_executor dask)."""
            name:
                f"rve_probes_dask_{_run}"
            input:
                states=[t.state for t in rve_layout.probe_tasks(_spec, _run)],
            output:
                records=[t.record for t in rve_layout.probe_tasks(_spec, _run)],
            log:
                rve_layout.log_path(_run, "probes_dask"),
            benchmark:
                rve_layout.benchmark_path(_run, "probes_dask")
            params:
                run=_run,
                spec=_spec,
            threads: PROBE_DASK.get("workers", 2) if PROBE_DASK.get("cluster", "local") == "local" else 1
            resources:
                mem_mb=config["resources"]["rve_mem_mb"],
                runtime=config["resources"]["rve_runtime_min"],
            run:
                from rve.homogenisation.distributed import probes_dask_job

                probes_dask_job(params.spec, params.run, log[0], PROBE_DASK, config["resources"], threads)


rule rve_pictures_relaxed:
    """Initial and relaxed state by axial force, the cross-section of a centre yarn (Figs. 7.4.1-2)."""
    input:
        initial=rve_layout.state_path("{run}", "{combo}", "initial"),
        relaxed=rve_layout.state_path("{run}", "{combo}", "relaxed"),
        record=rve_layout.record_path("{run}", "{combo}", "relaxed"),
    output:
        **rve_layout.picture_outputs("{run}", "{combo}"),
    log:
        rve_layout.log_path("{run}", "pictures", "{combo}", "relaxed"),
    benchmark:
        rve_layout.benchmark_path("{run}", "pictures", "{combo}", "relaxed")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
        tubes=lambda w: rve_layout.tubes_path(w.run, w.combo, "relaxed"),
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    run:
        from rve.homogenisation.pictures import pictures_relaxed_job

        pictures_relaxed_job(input.initial, input.relaxed, params.tubes, dict(output.items()), log[0], params.spec,
                             wildcards.combo)


rule rve_pictures_mode:
    """A mode's .pvd series over strain and the renders of its final state (Figs. 7.4.5-7.4.7)."""
    input:
        states=lambda w: [
            rve_layout.state_path(w.run, w.combo, n)
            for n in rve_layout.mode_state_names(config["rve"]["runs"][w.run], w.combo, w.mode)
        ],
        records=lambda w: [
            rve_layout.record_path(w.run, w.combo, n)
            for n in rve_layout.mode_state_names(config["rve"]["runs"][w.run], w.combo, w.mode)
        ],
    output:
        **rve_layout.picture_outputs("{run}", "{combo}", "{mode}"),
    log:
        rve_layout.log_path("{run}", "pictures", "{combo}", "{mode}"),
    benchmark:
        rve_layout.benchmark_path("{run}", "pictures", "{combo}", "{mode}")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
        tubes=lambda w: [
            rve_layout.tubes_path(w.run, w.combo, n)
            for n in rve_layout.mode_state_names(config["rve"]["runs"][w.run], w.combo, w.mode)
        ],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    run:
        from rve.homogenisation.pictures import pictures_mode_job

        pictures_mode_job(wildcards.mode, input.states, params.tubes, dict(output), log[0], params.spec, wildcards.combo)


rule rve_gather:
    """All probe records of a run -> the lookup table (netCDF, CSV, text summary)."""
    input:
        records=lambda w: rve_layout.run_record_paths(config["rve"]["runs"][w.run], w.run),
        # the loading-unloading cycles' states (strain.cycle_modes): the table's cycle_* variables
        cycles=lambda w: rve_layout.cycle_state_paths(config["rve"]["runs"][w.run], w.run),
        accuracy=lambda w: config["rve"]["runs"][w.run].get("accuracy") or [],
    output:
        **rve_layout.table_outputs("{run}"),
    log:
        rve_layout.log_path("{run}", "gather"),
    benchmark:
        rve_layout.benchmark_path("{run}", "gather")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.jobs import gather_job

        gather_job(
            input.records,
            output.table,
            output.csv,
            output.summary,
            log[0],
            params.spec,
            wildcards.run,
            cycle_states=list(input.cycles),
        )


rule rve_exports:
    """Macro-ready exports beside the table: Abaqus, LS-DYNA, Hermite splines, curve CSVs."""
    input:
        table=rve_layout.table_outputs("{run}")["table"],
    output:
        abaqus=rve_layout.export_outputs("{run}")["abaqus"],
        lsdyna=rve_layout.export_outputs("{run}")["lsdyna"],
        hermite=rve_layout.export_outputs("{run}")["hermite"],
        curves=directory(rve_layout.export_outputs("{run}")["curves"]),
    log:
        rve_layout.log_path("{run}", "exports"),
    benchmark:
        rve_layout.benchmark_path("{run}", "exports")
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.jobs import export_job

        export_job(input.table, dict(output.items()), log[0])


rule rve_report:
    """Figures of the table: reaction forces, probe resistances, temperature rises."""
    input:
        table=rve_layout.table_outputs("{run}")["table"],
    output:
        **rve_layout.report_outputs("{run}"),
    log:
        rve_layout.log_path("{run}", "report"),
    benchmark:
        rve_layout.benchmark_path("{run}", "report")
    params:
        prefix=lambda w: rve_layout.report_prefix(w.run),
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.jobs import report_job

        report_job(input.table, params.prefix, log[0])


rule rve_cycle_report:
    """Hysteresis loops of a run's loading-unloading cycles (the table's cycle_* variables)."""
    input:
        table=rve_layout.table_outputs("{run}")["table"],
    output:
        **rve_layout.cycle_report_outputs("{run}"),
    log:
        rve_layout.log_path("{run}", "cycle_report"),
    benchmark:
        rve_layout.benchmark_path("{run}", "cycle_report")
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.cycles import cycle_report_job

        cycle_report_job(input.table, dict(output.items()), log[0])


# --------------------------------------------------------------------------- friction
# The friction coefficient as a sweep axis with a loading-unloading cycle in shear (run
# plain_weave_friction of configs/pipeline.yaml; docs/rve_pipeline.md "Friction"):
#   snakemake -j2 rve_friction
FRICTION_RUN = "plain_weave_friction"


rule rve_friction:
    """`snakemake -j2 rve_friction`: the mu sweep of the plain weave, its table, figures and hysteresis loops."""
    input:
        **rve_layout.table_outputs(FRICTION_RUN),
        **rve_layout.report_outputs(FRICTION_RUN),
        **rve_layout.cycle_report_outputs(FRICTION_RUN),


# --------------------------------------------------------------------------- yarn pull-out
# One yarn of the relaxed cell pulled out along its axis (pullout section of the scene config;
# rve.homogenisation.pullout): a chain of steps per combination, then the force-displacement
# table (peak and sliding force) and its figure. Run plain_weave_pullout: mu = 0, 0.3.
#   snakemake -j2 rve_pullout
PULLOUT_RUN = "plain_weave_pullout"


rule rve_pullout_step:
    """Pull-out step {step} from the previous state (the relaxed one for step 1)."""
    input:
        state=lambda w: rve_layout.previous_pullout_state(w.run, w.combo, int(w.step)),
    output:
        state=rve_layout.state_path("{run}", "{combo}", "pullout_{step}"),
    log:
        rve_layout.log_path("{run}", "pullout", "{combo}", "pullout_{step}"),
    benchmark:
        rve_layout.benchmark_path("{run}", "pullout", "{combo}", "pullout_{step}")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
        runtime=config["resources"]["rve_runtime_min"],
    priority: 10
    run:
        from rve.homogenisation.jobs import pullout_job

        pullout_job(input.state, output.state, log[0], params.spec, wildcards.combo, int(wildcards.step))


rule rve_pullout_table:
    """Every pull-out state of a run -> the force-displacement table (netCDF, CSV)."""
    input:
        states=lambda w: rve_layout.pullout_state_paths(config["rve"]["runs"][w.run], w.run),
    output:
        table=rve_layout.pullout_outputs("{run}")["table"],
        csv=rve_layout.pullout_outputs("{run}")["csv"],
    log:
        rve_layout.log_path("{run}", "pullout_table"),
    benchmark:
        rve_layout.benchmark_path("{run}", "pullout_table")
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.pullout import pullout_table_job

        pullout_table_job(list(input.states), output.table, output.csv, log[0], params.spec)


rule rve_pullout_report:
    """The pull-out table -> its force-displacement figure (one curve per combination)."""
    input:
        table=rve_layout.pullout_outputs("{run}")["table"],
    output:
        curve=rve_layout.pullout_outputs("{run}")["curve"],
    log:
        rve_layout.log_path("{run}", "pullout_report"),
    benchmark:
        rve_layout.benchmark_path("{run}", "pullout_report")
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.pullout import pullout_report_job

        pullout_report_job(input.table, output.curve, log[0])


rule rve_pullout:
    """`snakemake -j2 rve_pullout`: the yarn pull-out of the plain weave (run plain_weave_pullout)."""
    input:
        **rve_layout.pullout_outputs(PULLOUT_RUN),


# --------------------------------------------------------------------------- ensembles
# A run with `sweep: {realization: [...]}` (packing.seed) and a packing.perturbation is an
# ensemble of perturbed packings: its table has a `realization` dimension with mean, std and
# the 90 % band (rve.tables.ensemble, hooked into rve_gather); this rule draws the bands and
# reports them against the step-to-step wiggle of one realization.
ENSEMBLE_RUN = "plain_weave_ensemble"


rule rve_ensemble_report:
    """Ensemble bands of a realization sweep's table (probe resistances, reactions, R_y/R_c)."""
    input:
        table=rve_layout.table_outputs("{run}")["table"],
    output:
        **rve_layout.ensemble_report_outputs("{run}"),
    log:
        rve_layout.log_path("{run}", "ensemble_report"),
    benchmark:
        rve_layout.benchmark_path("{run}", "ensemble_report")
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.tables.ensemble import ensemble_report_job

        ensemble_report_job(input.table, dict(output.items()), log[0])


rule rve_ensemble:
    """`snakemake -j2 rve_ensemble`: the 8 perturbed packings of the plain weave (run plain_weave_ensemble)."""
    input:
        **rve_layout.table_outputs(ENSEMBLE_RUN),
        **rve_layout.ensemble_report_outputs(ENSEMBLE_RUN),


# --------------------------------------------------------------------------- table convergence
# A study {study} is two sweep runs: {study}_mesh over mesh.elements and {study}_penalty over
# contact_penalty (configs/pipeline.yaml: table_convergence_*; the CI config: ci_table_convergence_*).
# The report compares every table quantity with the finest / stiffest run at every strain, fits the
# observed rate with the mesh size and sets it against each run's summed job time
# (rve.studies.table_convergence; docs/table_accuracy.md).
#   snakemake -j2 rve_table_convergence          # the default RVE: 12/18/24/30 elements, P* 5/15/50/150
rule rve_table_convergence_report:
    """Mesh and penalty convergence of a table: errors to the finest run, rates, work-precision."""
    input:
        mesh=lambda w: rve_layout.table_outputs(f"{w.study}_mesh")["table"],
        penalty=lambda w: rve_layout.table_outputs(f"{w.study}_penalty")["table"],
    output:
        **rve_layout.convergence_outputs("{study}"),
    log:
        f"{rve_layout.LOG_DIR}/convergence/{{study}}.log",
    benchmark:
        f"{rve_layout.BENCHMARK_DIR}/convergence/{{study}}.tsv"
    wildcard_constraints:
        study=r"[A-Za-z0-9_]+",
    params:
        default=lambda w: rve_layout.convergence_default(config["rve"]["runs"], w.study),
        runs=lambda w: {"mesh": f"{w.study}_mesh", "penalty": f"{w.study}_penalty"},
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.studies.table_convergence import table_convergence_job
        from rve.tables import open_table

        table_convergence_job(open_table(input.mesh), open_table(input.penalty), params.runs, dict(output), log[0],
                              params.default)


rule rve_table_convergence:
    """`snakemake -j2 rve_table_convergence`: the default RVE's mesh and penalty study."""
    input:
        **rve_layout.convergence_outputs("table_convergence"),


# --------------------------------------------------------------------------- work-precision study
# A study {study} (config rve.work_precision.{study}) is a reference run, a default run and one
# sweep run per lever (boundary, cell size, p, elements, contact points, enforcement). The report
# compares every combination with the reference on the range measure, sets it against the
# combination's summed job CPU time, draws the front and writes the default run's stated error
# as an accuracy file (rve.studies.work_precision; docs/table_accuracy.md). A lever whose run the
# config refuses (an override key it does not know) is skipped and listed in the report.
#   snakemake -j2 rve_work_precision


rule rve_work_precision_report:
    """Every lever's runs against one reference: errors, CPU time, front, the default's stated error."""
    input:
        reference=lambda w: rve_layout.table_outputs(_work_precision(w)["reference"])["table"],
        default=lambda w: [rve_layout.table_outputs(r)["table"] for r in [_work_precision(w)["default"]] if r],
        levers=lambda w: [rve_layout.table_outputs(r)["table"] for r in _work_precision(w)["levers"].values()],
    output:
        **rve_layout.work_precision_outputs("{study}"),
    log:
        f"{rve_layout.LOG_DIR}/work_precision/{{study}}.log",
    benchmark:
        f"{rve_layout.BENCHMARK_DIR}/work_precision/{{study}}.tsv"
    wildcard_constraints:
        study=r"[A-Za-z0-9_]+",
    params:
        runs=_work_precision,
        default_config=_work_precision_levers,
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
    run:
        from rve.studies.work_precision import work_precision_rule
        from rve.tables import open_table

        work_precision_rule(params.runs, params.default_config, open_table, rve_layout.table_outputs,
                            rve_layout.BENCHMARK_DIR, dict(output), log[0], wildcards.study)

rule rve_work_precision:
    """`snakemake -j2 rve_work_precision`: the work-precision study of the default table."""
    input:
        **rve_layout.work_precision_outputs("work_precision"),
