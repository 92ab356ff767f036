# Dynamic wire time-convergence study (thesis §6.4, Fig. 6.4.4, Table 6.4).
# Include from the Snakefile after common.smk:   include: "workflow/rules/dynamic_wire.smk"
# Targets: DYNAMIC_WIRE_OUTPUTS (results/verification/dynamic_wire.nc, the orders table and
# two plots). The study design is the pipeline config key verification.dynamic_wire
# (scene_config, overrides, reference {stages, steps}, series {s: {steps: [...], fit: [lo, hi]}}),
# its defaults in workflow/schemas/pipeline.schema.yaml; memory from config
# resources.dynamic_wire_mem_mb; every path from rve.studies.layout; the job bodies
# (rve.studies.dynamic_wire) are imported in the rule bodies.
# Jobs: one per scheme (all its step counts in one process: a process start costs more
# than a short run) and one for the reference, so `snakemake -j2` runs the reference on one
# core and the three series on the other.

DYNAMIC_WIRE = config["verification"]["dynamic_wire"]
DYNAMIC_WIRE_SERIES = {int(s): series for s, series in DYNAMIC_WIRE["series"].items()}
DYNAMIC_WIRE_OUTPUTS = study_layout.DYNAMIC_WIRE_OUTPUTS


wildcard_constraints:
    dw_stages=r"[123]",


rule dynamic_wire_reference:
    """The reference solution: s = 3 with N_ref >= 1500 fixed steps."""
    input:
        scene=DYNAMIC_WIRE["scene_config"],
    output:
        record=study_layout.dynamic_wire_reference(),
    log:
        study_layout.log_path("dynamic_wire", "reference"),
    benchmark:
        study_layout.benchmark_path("dynamic_wire", "reference")
    params:
        overrides=DYNAMIC_WIRE["overrides"],
        stages=DYNAMIC_WIRE["reference"]["stages"],
        steps=DYNAMIC_WIRE["reference"]["steps"],
    threads: 1
    priority: 10  # the longest job: start it first so the series share the other core
    resources:
        mem_mb=config["resources"]["dynamic_wire_mem_mb"],
    run:
        from rve.studies.dynamic_wire import reference_job

        reference_job(
            output.record, log[0], input.scene, params.overrides, params.stages, params.steps
        )


rule dynamic_wire_series:
    """All step counts of one SDIRK scheme (fixed steps)."""
    input:
        scene=DYNAMIC_WIRE["scene_config"],
    output:
        records=study_layout.dynamic_wire_series("{dw_stages}"),
    log:
        study_layout.log_path("dynamic_wire", "series_s{dw_stages}"),
    benchmark:
        study_layout.benchmark_path("dynamic_wire", "series_s{dw_stages}")
    params:
        overrides=DYNAMIC_WIRE["overrides"],
        steps=lambda wc: DYNAMIC_WIRE_SERIES[int(wc.dw_stages)]["steps"],
    threads: 1
    resources:
        mem_mb=config["resources"]["dynamic_wire_mem_mb"],
    run:
        from rve.studies.dynamic_wire import series_job

        series_job(
            output.records, log[0], input.scene, params.overrides, int(wildcards.dw_stages), params.steps
        )


rule dynamic_wire_study:
    """Gather -> results/verification/dynamic_wire.nc (dims stages x steps, fitted orders),
    the orders table and the error / work-precision plots."""
    input:
        series=[study_layout.dynamic_wire_series(s) for s in sorted(DYNAMIC_WIRE_SERIES)],
        reference=study_layout.dynamic_wire_reference(),
    output:
        nc=study_layout.DYNAMIC_WIRE_NC,
        orders_md=study_layout.DYNAMIC_WIRE_ORDERS_MD,
        errors_png=study_layout.DYNAMIC_WIRE_ERRORS_PNG,
        work_png=study_layout.DYNAMIC_WIRE_WORK_PNG,
    log:
        study_layout.log_path("dynamic_wire", "study"),
    benchmark:
        study_layout.benchmark_path("dynamic_wire", "study")
    params:
        plan=DYNAMIC_WIRE,
    threads: 1
    resources:
        mem_mb=config["resources"]["dynamic_wire_mem_mb"],
    run:
        from rve.studies.dynamic_wire import gather_job

        gather_job(
            input.series, input.reference, output.nc, output.orders_md, output.errors_png, output.work_png,
            params.plan,
        )
