# Electromagnetically enhanced armour (thesis §8.4, Figs. 8.4.1-8.4.6; docs/impact.md).
# Include from the Snakefile after common.smk:   include: "workflow/rules/impact.smk"
# Target `impact`: the relaxation (saved, reused by every impact run), the full thesis impact
# (32 x 32 yarns, 80 elements, 0.5 ms in 1000 SDIRK2 steps) and its figures.
# Target `impact_sweep`: final speed, tilt rate and peak temperature against the warp current
# density (config impact.currents), on the reduced case of impact.sweep_overrides: the weave,
# the projectile and the horizon scaled by 1/4 (same yarn spacing, elements of 0.64 mm, the
# same deflection-to-span ratio at t_end); each point of the full size costs as much as the
# full run.
# Target `impact_velocity_sweep`: the projectile speeds of config impact.velocities (mm/ms) on
# the same reduced case and relaxed state as the current sweep, then the sweep's figure.
# Pipeline config key impact: {scene_config, overrides, sweep_overrides, currents, velocities}, its
# defaults in workflow/schemas/pipeline.schema.yaml; the full run's memory from config
# resources.impact_mem_mb (the others: the profile's default-resources);
# every path from rve.scenes.layout; the job bodies (rve.scenes.impact.jobs) are imported in
# the rule bodies.

import os

from rve.scenes import layout as scene_layout

IMPACT = config["impact"]


rule impact:
    """Relaxation + the full thesis impact and its outputs."""
    input:
        scene_layout.impact_file("full", "summary"),


rule impact_relax:
    """The relaxed fabric with the projectile present and at rest (B off)."""
    input:
        scene=IMPACT["scene_config"],
    output:
        state=scene_layout.impact_file("{case}", "relaxed"),
        record=scene_layout.impact_file("{case}", "relaxation"),
    log:
        scene_layout.log_path("impact", "{case}_relax"),
    benchmark:
        scene_layout.benchmark_path("impact", "{case}_relax")
    params:
        overrides=lambda wc: IMPACT["overrides"] if wc.case == "full" else IMPACT["overrides"] + IMPACT["sweep_overrides"],
        out=lambda wc: scene_layout.impact_dir(wc.case),
    threads: 1
    run:
        from rve.process import keep_freed_memory
        from rve.scenes.impact.jobs import impact_job

        keep_freed_memory()  # the allocator reuses freed memory (rve/process.py)

        impact_job(input.scene, params.out, output.record, log[0], params.overrides,
                   relaxed=output.state, relax_only=True)


rule impact_full:
    """The thesis impact from the saved relaxed state (outputs under results/impact/full)."""
    input:
        scene=IMPACT["scene_config"],
        relaxed=scene_layout.impact_file("full", "relaxed"),
    output:
        summary=scene_layout.impact_file("full", "summary"),
        nc=scene_layout.impact_file("full", "netcdf"),
    log:
        scene_layout.log_path("impact", "full"),
    benchmark:
        scene_layout.benchmark_path("impact", "full")
    params:
        overrides=IMPACT["overrides"],
        out=lambda w, output: os.path.dirname(output.summary),
    threads: 1
    resources:
        mem_mb=config["resources"]["impact_mem_mb"],
    run:
        from rve.process import keep_freed_memory
        from rve.scenes.impact.jobs import impact_job

        keep_freed_memory()  # the allocator reuses freed memory (rve/process.py)

        impact_job(input.scene, params.out, output.summary, log[0], params.overrides,
                   relaxed=input.relaxed)


rule impact_sweep_point:
    """One current density of the sweep (reduced case)."""
    input:
        scene=IMPACT["scene_config"],
        relaxed=scene_layout.impact_file("sweep", "relaxed"),
    output:
        summary=scene_layout.impact_file("sweep/J{current}", "summary"),
    log:
        scene_layout.log_path("impact", "sweep_J{current}"),
    benchmark:
        scene_layout.benchmark_path("impact", "sweep_J{current}")
    params:
        overrides=lambda wc: IMPACT["overrides"] + IMPACT["sweep_overrides"] + [f"warp.J_bar=-{wc.current} A/mm^2"],
        out=lambda wc: scene_layout.impact_sweep_dir(wc.current),
    threads: 1
    run:
        from rve.process import keep_freed_memory
        from rve.scenes.impact.jobs import impact_job

        keep_freed_memory()  # the allocator reuses freed memory (rve/process.py)

        impact_job(input.scene, params.out, output.summary, log[0], params.overrides,
                   relaxed=input.relaxed)


rule impact_sweep:
    """Final speed, tilt rate and peak temperature against the warp current density."""
    input:
        [scene_layout.impact_file(f"sweep/J{c}", "summary") for c in IMPACT["currents"]],
    output:
        png=scene_layout.IMPACT_SWEEP_PNG,
        json=scene_layout.IMPACT_SWEEP_JSON,
    log:
        scene_layout.log_path("impact", "sweep_curve"),
    params:
        currents=IMPACT["currents"],
    threads: 1
    run:
        from rve.scenes.impact.jobs import sweep_curve

        sweep_curve(input, params.currents, output.png, output.json)


wildcard_constraints:
    impact_speed=r"[0-9]+(\.[0-9]+)?",


rule impact_velocity_point:
    """One impact speed of the velocity sweep (the reduced case of impact.sweep_overrides,
    from the sweep's relaxed state: the relaxation does not depend on the speed)."""
    input:
        scene=IMPACT["scene_config"],
        relaxed=scene_layout.impact_file("sweep", "relaxed"),
    output:
        summary=scene_layout.impact_file("velocity_sweep/v{impact_speed}", "summary"),
        nc=scene_layout.impact_file("velocity_sweep/v{impact_speed}", "netcdf"),
    log:
        scene_layout.log_path("impact", "velocity_sweep_v{impact_speed}"),
    benchmark:
        scene_layout.benchmark_path("impact", "velocity_sweep_v{impact_speed}")
    params:
        overrides=lambda wc: IMPACT["overrides"] + IMPACT["sweep_overrides"] + [f"projectile.speed={wc.impact_speed} mm/ms"],
        out=lambda wc: scene_layout.impact_velocity_dir(wc.impact_speed),
    threads: 1
    run:
        from rve.process import keep_freed_memory
        from rve.scenes.impact.jobs import impact_job

        keep_freed_memory()  # the allocator reuses freed memory (rve/process.py)

        impact_job(input.scene, params.out, output.summary, log[0], params.overrides,
                   relaxed=input.relaxed)


rule impact_velocity_sweep:
    """Speed histories, speed kept, tilt rate and peak temperature against the impact speed."""
    input:
        [scene_layout.impact_file(f"velocity_sweep/v{v}", "summary") for v in IMPACT["velocities"]],
        [scene_layout.impact_file(f"velocity_sweep/v{v}", "netcdf") for v in IMPACT["velocities"]],
    output:
        png=scene_layout.IMPACT_VELOCITY_SWEEP_PNG,
        json=scene_layout.IMPACT_VELOCITY_SWEEP_JSON,
    log:
        scene_layout.log_path("impact", "velocity_sweep_curve"),
    benchmark:
        scene_layout.benchmark_path("impact", "velocity_sweep_curve")
    params:
        speeds=IMPACT["velocities"],
        dirs=[scene_layout.impact_velocity_dir(v) for v in IMPACT["velocities"]],
    threads: 1
    run:
        from rve.scenes.impact.jobs import velocity_curve
        from rve.scenes.protocol import job_log

        with job_log(log[0]):
            velocity_curve(params.dirs, params.speeds, output.png, output.json)
