# Induced deformation (thesis §8.3, Figs. 8.3.1-8.3.2; docs/induced_deformation.md).
# Include from the Snakefile after common.smk:   include: "workflow/rules/induced_deformation.smk"
# Target `induced_deformation`: the three field orientations B1, B2, B3 as independent jobs
# (`snakemake -j2 induced_deformation` runs two at once), then the combined figures.
# Optional pipeline config key induced_deformation: {scene_config, overrides: [...]}.

INDUCED = {"scene_config": "configs/scenes/induced_deformation.yaml", "overrides": [],
           **config.get("induced_deformation", {})}
INDUCED_DIR = "results/induced_deformation"
INDUCED_ORIENTATIONS = ["B1", "B2", "B3"]
INDUCED_OUTPUTS = [f"{INDUCED_DIR}/fig_8_3_1_frames.png", f"{INDUCED_DIR}/fig_8_3_2_temperature.png"] + [
    f"{INDUCED_DIR}/{o}/summary.json" for o in INDUCED_ORIENTATIONS]


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
        summary=f"{INDUCED_DIR}/{{induced_orientation}}/summary.json",
        nc=f"{INDUCED_DIR}/{{induced_orientation}}/induced_deformation.nc",
    log:
        "results/logs/induced_deformation/{induced_orientation}.log",
    benchmark:
        "results/benchmarks/induced_deformation/{induced_orientation}.tsv"
    params:
        overrides=INDUCED["overrides"],
        out=lambda wc: f"{INDUCED_DIR}/{wc.induced_orientation}",
    threads: 1
    resources:
        mem_mb=1000,
    run:
        from rve.scenes.induced.jobs import orientation_job

        orientation_job(input.scene, wildcards.induced_orientation, params.out, output.summary,
                        log[0], params.overrides)


rule induced_deformation_figures:
    """Figs. 8.3.1 (time frames x orientations, coloured by current) and 8.3.2 (temperature)."""
    input:
        nc=expand(f"{INDUCED_DIR}/{{o}}/induced_deformation.nc", o=INDUCED_ORIENTATIONS),
    output:
        frames=f"{INDUCED_DIR}/fig_8_3_1_frames.png",
        temperature=f"{INDUCED_DIR}/fig_8_3_2_temperature.png",
    log:
        "results/logs/induced_deformation/figures.log",
    benchmark:
        "results/benchmarks/induced_deformation/figures.tsv"
    params:
        dirs=[f"{INDUCED_DIR}/{o}" for o in INDUCED_ORIENTATIONS],
    threads: 1
    run:
        from rve.scenes.induced.outputs import combine_orientations

        combine_orientations(params.dirs, output.frames, output.temperature)
