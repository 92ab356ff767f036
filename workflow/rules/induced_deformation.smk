# Induced deformation (thesis §8.3, Figs. 8.3.1-8.3.2; docs/induced_deformation.md).
# Include from the Snakefile after common.smk:   include: "workflow/rules/induced_deformation.smk"
# Target `induced_deformation`: the three field orientations B1, B2, B3 as independent jobs
# (`snakemake -j2 induced_deformation` runs two at once), then the combined figures.
# Pipeline config key induced_deformation: {scene_config, overrides: [...]}, its defaults in
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
        from rve.scenes.induced.jobs import orientation_job

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
