# Induced deformation (thesis §8.3, Figs. 8.3.1-8.3.2; docs/induced_deformation.md).
# Include from the Snakefile after common.smk:   include: "workflow/rules/induced_deformation.smk"
# Target `induced_deformation`: the three field orientations B1, B2, B3 as independent jobs
# (`snakemake -j2 induced_deformation` runs two at once), then the combined figures.
# Target `induced_current_sweep`: the warp current density |J_bar| of config
# induced_deformation.currents (A/mm^2), one job each, on orientation sweep_orientation with
# overrides + sweep_overrides, then the sweep's figure (results/induced_deformation/current_sweep/).
# Pipeline config key induced_deformation: {scene_config, overrides: [...], sweep_orientation,
# sweep_overrides, currents}, its defaults in
# workflow/schemas/pipeline.schema.yaml; memory from config resources.induced_mem_mb; every
# path from rve.scenes.layout; the job bodies are imported in the rule bodies.

from rve.scenes import layout as scene_layout

INDUCED = config["induced_deformation"]
INDUCED_ORIENTATIONS = ["B1", "B2", "B3"]
INDUCED_OUTPUTS = [scene_layout.INDUCED_FRAMES_PNG, scene_layout.INDUCED_TEMPERATURE_PNG] + [
    scene_layout.induced_file(o, "summary") for o in INDUCED_ORIENTATIONS]


wildcard_constraints:
    induced_orientation=r"B[123]",


rule induced_deformation:
    """All three orientations and the figures."""
    input:
        INDUCED_OUTPUTS,


rule induced_deformation_orientation:
    """One field orientation to the Appendix A horizon."""
    input:
        scene=INDUCED["scene_config"],
    output:
        summary=scene_layout.induced_file("{induced_orientation}", "summary"),
        nc=scene_layout.induced_file("{induced_orientation}", "netcdf"),
    log:
        scene_layout.log_path("induced_deformation", "{induced_orientation}"),
    benchmark:
        scene_layout.benchmark_path("induced_deformation", "{induced_orientation}")
    params:
        overrides=INDUCED["overrides"],
        out=lambda wc: scene_layout.induced_dir(wc.induced_orientation),
    threads: 1
    resources:
        mem_mb=config["resources"]["induced_mem_mb"],
    run:
        from rve.process import keep_freed_memory
        from rve.scenes.induced.jobs import orientation_job

        keep_freed_memory()  # the allocator reuses freed memory (rve/process.py)

        orientation_job(input.scene, wildcards.induced_orientation, params.out, output.summary,
                        log[0], params.overrides)


rule induced_deformation_figures:
    """Figs. 8.3.1 (time frames x orientations, coloured by current) and 8.3.2 (temperature)."""
    input:
        nc=[scene_layout.induced_file(o, "netcdf") for o in INDUCED_ORIENTATIONS],
    output:
        frames=scene_layout.INDUCED_FRAMES_PNG,
        temperature=scene_layout.INDUCED_TEMPERATURE_PNG,
    log:
        scene_layout.log_path("induced_deformation", "figures"),
    benchmark:
        scene_layout.benchmark_path("induced_deformation", "figures")
    params:
        dirs=[scene_layout.induced_dir(o) for o in INDUCED_ORIENTATIONS],
    threads: 1
    run:
        from rve.scenes.induced.outputs import combine_orientations

        combine_orientations(params.dirs, output.frames, output.temperature)


wildcard_constraints:
    induced_current=r"[0-9]+(\.[0-9]+)?",


rule induced_current_point:
    """One warp current density |J_bar| of the current sweep (orientation
    induced_deformation.sweep_orientation, overrides + sweep_overrides)."""
    input:
        scene=INDUCED["scene_config"],
    output:
        summary=scene_layout.induced_current_file("{induced_current}", "summary"),
        nc=scene_layout.induced_current_file("{induced_current}", "netcdf"),
    log:
        scene_layout.log_path("induced_deformation", "current_sweep_J{induced_current}"),
    benchmark:
        scene_layout.benchmark_path("induced_deformation", "current_sweep_J{induced_current}")
    params:
        overrides=lambda wc: INDUCED["overrides"] + INDUCED["sweep_overrides"] + [f"warp.J_bar=-{wc.induced_current} A/mm^2"],
        orientation=INDUCED["sweep_orientation"],
        out=lambda wc: scene_layout.induced_current_dir(wc.induced_current),
    threads: 1
    resources:
        mem_mb=config["resources"]["induced_mem_mb"],
    run:
        from rve.process import keep_freed_memory
        from rve.scenes.induced.jobs import orientation_job

        keep_freed_memory()  # the allocator reuses freed memory (rve/process.py)

        orientation_job(input.scene, params.orientation, params.out, output.summary, log[0], params.overrides)


rule induced_current_sweep:
    """Deflection and temperature histories, and their end values, against the warp current."""
    input:
        [scene_layout.induced_current_file(c, "summary") for c in INDUCED["currents"]],
        [scene_layout.induced_current_file(c, "netcdf") for c in INDUCED["currents"]],
    output:
        png=scene_layout.INDUCED_CURRENT_SWEEP_PNG,
        json=scene_layout.INDUCED_CURRENT_SWEEP_JSON,
    log:
        scene_layout.log_path("induced_deformation", "current_sweep_curve"),
    benchmark:
        scene_layout.benchmark_path("induced_deformation", "current_sweep_curve")
    params:
        currents=INDUCED["currents"],
        dirs=[scene_layout.induced_current_dir(c) for c in INDUCED["currents"]],
    threads: 1
    run:
        from rve.scenes.induced.jobs import current_sweep_curve
        from rve.scenes.protocol import job_log

        with job_log(log[0]):
            current_sweep_curve(params.dirs, params.currents, output.png, output.json)
