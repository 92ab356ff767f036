# Verification studies (thesis ch. 6). Each rule is a thin call into rve.studies.*, imported in
# the rule body; every path from rve.studies.layout; memory from config resources.


rule static_wire_point:
    """One solve of the static wire at order p, N elements and radius R (mm)."""
    input:
        scene=STATIC_WIRE["scene_config"],
    output:
        record=study_layout.static_wire_point("{order}", "{elements}", "{radius}"),
    log:
        study_layout.log_path("static_wire", "points/p{order}_N{elements}_R{radius}"),
    benchmark:
        study_layout.benchmark_path("static_wire", "points/p{order}_N{elements}_R{radius}")
    params:
        overrides=STATIC_WIRE["overrides"],
        keep_failure=STATIC_WIRE["keep_failed_points"],
    threads: 1
    resources:
        mem_mb=config["resources"]["static_wire_point_mem_mb"],
        runtime=config["resources"]["static_wire_point_runtime_min"],
    run:
        from rve.studies.static_wire import point_job

        point_job(
            output.record, log[0], input.scene, wildcards, params.overrides, params.keep_failure
        )


rule static_wire_gather:
    """All point records -> results/verification/static_wire.nc (with the fitted orders)."""
    input:
        records=static_wire_point_records,
    output:
        nc=study_layout.STATIC_WIRE_NC,
    log:
        study_layout.log_path("static_wire", "gather"),
    benchmark:
        study_layout.benchmark_path("static_wire", "gather")
    params:
        study=STATIC_WIRE,
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.studies.static_wire import gather_job

        gather_job(input.records, output.nc, log[0], params.study)


rule static_wire_report:
    """Radius-sweep and convergence plots and the fitted-orders table from the netCDF."""
    input:
        nc=study_layout.STATIC_WIRE_NC,
    output:
        radius_png=study_layout.STATIC_WIRE_RADIUS_PNG,
        convergence_png=study_layout.STATIC_WIRE_CONVERGENCE_PNG,
        orders_csv=study_layout.STATIC_WIRE_ORDERS_CSV,
        orders_md=study_layout.STATIC_WIRE_ORDERS_MD,
    log:
        study_layout.log_path("static_wire", "report"),
    benchmark:
        study_layout.benchmark_path("static_wire", "report")
    params:
        study=STATIC_WIRE,
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
        runtime=config["resources"]["gather_runtime_min"],
    run:
        from rve.studies.static_wire import report_job

        report_job(
            input.nc,
            output.radius_png,
            output.convergence_png,
            output.orders_csv,
            output.orders_md,
            log[0],
            params.study,
        )
