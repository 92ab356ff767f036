# Dynamic wire time-convergence study (thesis §6.4, Fig. 6.4.4, Table 6.4).
# Include from the Snakefile after common.smk:   include: "workflow/rules/dynamic_wire.smk"
# Targets: DYNAMIC_WIRE_OUTPUTS (results/verification/dynamic_wire.nc, the orders table and
# two plots). The study design is rve.studies.dynamic_wire.DEFAULT_PLAN, updated by the
# optional pipeline config key verification.dynamic_wire (scene_config, overrides,
# reference {stages, steps}, series {s: {steps: [...], fit: [lo, hi]}}).
# Jobs: one per scheme (all its step counts in one process: a process start costs more
# than a short run) and one for the reference, so `snakemake -j2` runs the reference on one
# core and the three series on the other.

from rve.studies import dynamic_wire as dynamic_wire_study

DYNAMIC_WIRE = dynamic_wire_study.normalise_plan(config.get("verification", {}).get("dynamic_wire"))
DYNAMIC_WIRE_DIR = "results/verification/dynamic_wire"
DYNAMIC_WIRE_NC = "results/verification/dynamic_wire.nc"
DYNAMIC_WIRE_ORDERS_MD = "results/verification/dynamic_wire_orders.md"
DYNAMIC_WIRE_ERRORS_PNG = "results/verification/dynamic_wire_errors.png"
DYNAMIC_WIRE_WORK_PNG = "results/verification/dynamic_wire_work_precision.png"
DYNAMIC_WIRE_OUTPUTS = [DYNAMIC_WIRE_NC, DYNAMIC_WIRE_ORDERS_MD, DYNAMIC_WIRE_ERRORS_PNG, DYNAMIC_WIRE_WORK_PNG]


wildcard_constraints:
    dw_stages=r"[123]",


rule dynamic_wire_reference:
    """The reference solution: s = 3 with N_ref >= 1500 fixed steps."""
    input:
        scene=DYNAMIC_WIRE["scene_config"],
    output:
        record=f"{DYNAMIC_WIRE_DIR}/reference.json",
    log:
        "results/logs/verification/dynamic_wire/reference.log",
    benchmark:
        "results/benchmarks/verification/dynamic_wire/reference.tsv"
    params:
        overrides=DYNAMIC_WIRE["overrides"],
        stages=DYNAMIC_WIRE["reference"]["stages"],
        steps=DYNAMIC_WIRE["reference"]["steps"],
    threads: 1
    priority: 10  # the longest job: start it first so the series share the other core
    resources:
        mem_mb=config["resources"]["dynamic_wire_mem_mb"],
    run:
        dynamic_wire_study.reference_job(
            output.record, log[0], input.scene, params.overrides, params.stages, params.steps
        )


rule dynamic_wire_series:
    """All step counts of one SDIRK scheme (fixed steps)."""
    input:
        scene=DYNAMIC_WIRE["scene_config"],
    output:
        records=f"{DYNAMIC_WIRE_DIR}/series_s{{dw_stages}}.json",
    log:
        "results/logs/verification/dynamic_wire/series_s{dw_stages}.log",
    benchmark:
        "results/benchmarks/verification/dynamic_wire/series_s{dw_stages}.tsv"
    params:
        overrides=DYNAMIC_WIRE["overrides"],
        steps=lambda wc: DYNAMIC_WIRE["series"][int(wc.dw_stages)]["steps"],
    threads: 1
    resources:
        mem_mb=config["resources"]["dynamic_wire_mem_mb"],
    run:
        dynamic_wire_study.series_job(
            output.records, log[0], input.scene, params.overrides, int(wildcards.dw_stages), params.steps
        )


rule dynamic_wire_study:
    """Gather -> results/verification/dynamic_wire.nc (dims stages x steps, fitted orders),
    the orders table and the error / work-precision plots."""
    input:
        series=expand(f"{DYNAMIC_WIRE_DIR}/series_s{{s}}.json", s=sorted(DYNAMIC_WIRE["series"])),
        reference=f"{DYNAMIC_WIRE_DIR}/reference.json",
    output:
        nc=DYNAMIC_WIRE_NC,
        orders_md=DYNAMIC_WIRE_ORDERS_MD,
        errors_png=DYNAMIC_WIRE_ERRORS_PNG,
        work_png=DYNAMIC_WIRE_WORK_PNG,
    log:
        "results/logs/verification/dynamic_wire/study.log",
    benchmark:
        "results/benchmarks/verification/dynamic_wire/study.tsv"
    params:
        plan=DYNAMIC_WIRE,
    threads: 1
    resources:
        mem_mb=config["resources"]["dynamic_wire_mem_mb"],
    run:
        dynamic_wire_study.gather_job(
            input.series, input.reference, output.nc, output.orders_md, output.errors_png, output.work_png,
            params.plan,
        )
