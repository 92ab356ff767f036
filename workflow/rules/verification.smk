# Verification studies (thesis ch. 6). Each rule is a thin call into rve.studies.*.


rule static_wire_point:
    """One solve of the static wire at order p, N elements and radius R (mm)."""
    input:
        scene=STATIC_WIRE["scene_config"],
    output:
        record=f"{STATIC_WIRE_DIR}/points/p{{order}}_N{{elements}}_R{{radius}}.json",
    log:
        "results/logs/verification/static_wire/points/p{order}_N{elements}_R{radius}.log",
    benchmark:
        "results/benchmarks/verification/static_wire/points/p{order}_N{elements}_R{radius}.tsv"
    params:
        overrides=STATIC_WIRE["overrides"],
        keep_failure=STATIC_WIRE["keep_failed_points"],
    threads: 1
    resources:
        mem_mb=resource_mem_mb("static_wire_point_mem_mb"),
        runtime=config["resources"]["static_wire_point_runtime_min"],
    run:
        static_wire_study.point_job(
            output.record, log[0], input.scene, wildcards, params.overrides, params.keep_failure
        )


rule static_wire_gather:
    """All point records -> results/verification/static_wire.nc (with the fitted orders)."""
    input:
        records=static_wire_point_records,
    output:
        nc=STATIC_WIRE_NC,
    log:
        "results/logs/verification/static_wire/gather.log",
    benchmark:
        "results/benchmarks/verification/static_wire/gather.tsv"
    params:
        study=STATIC_WIRE,
    threads: 1
    resources:
        mem_mb=resource_mem_mb("gather_mem_mb"),
        runtime=config["resources"]["gather_runtime_min"],
    run:
        static_wire_study.gather_job(input.records, output.nc, log[0], params.study)


rule static_wire_report:
    """Radius-sweep and convergence plots and the fitted-orders table from the netCDF."""
    input:
        nc=STATIC_WIRE_NC,
    output:
        radius_png=STATIC_WIRE_RADIUS_PNG,
        convergence_png=STATIC_WIRE_CONVERGENCE_PNG,
        orders_csv=STATIC_WIRE_ORDERS_CSV,
        orders_md=STATIC_WIRE_ORDERS_MD,
    log:
        "results/logs/verification/static_wire/report.log",
    benchmark:
        "results/benchmarks/verification/static_wire/report.tsv"
    params:
        study=STATIC_WIRE,
    threads: 1
    resources:
        mem_mb=resource_mem_mb("gather_mem_mb"),
        runtime=config["resources"]["gather_runtime_min"],
    run:
        static_wire_study.report_job(
            input.nc,
            output.radius_png,
            output.convergence_png,
            output.orders_csv,
            output.orders_md,
            log[0],
            params.study,
        )
