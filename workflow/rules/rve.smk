# RVE homogenisation (thesis ch. 7, Algorithm 7.1; SPEC §5-§6; docs/rve_pipeline.md).
# Each rule is a thin call into rve.homogenisation.pipeline. Per run (config rve.runs) and
# per sweep combination ({combo}, "base" without a sweep):
#   rve_fabric -> rve_relax -> rve_strain_step (step i from step i-1, per mode)
#   -> rve_probes (one job per stored state, independent) -> rve_gather -> rve_report
# Every output is written atomically, so a killed run resumes from the last complete step.
# The strain steps (the critical path: two chains) have priority; the probe jobs fill in.

from rve.homogenisation import pipeline as rve_pipeline


RVE_DIR = rve_pipeline.RVE_DIR


wildcard_constraints:
    run=r"[A-Za-z0-9_]+",
    combo=r"[A-Za-z0-9_.+=-]+",
    mode=r"uniaxial|shear",
    step=r"[0-9]{2}",
    state=r"relaxed|(uniaxial|shear)_[0-9]{2}",


rule rve_fabric:
    """Generate the fabric and its mesh; write the designed initial state."""
    output:
        state=f"{RVE_DIR}/{{run}}/{{combo}}/states/initial.nc",
    log:
        "results/logs/rve/{run}/{combo}/fabric.log",
    benchmark:
        "results/benchmarks/rve/{run}/{combo}/fabric.tsv"
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
    run:
        rve_pipeline.fabric_job(output.state, log[0], params.spec, wildcards.combo)


rule rve_relax:
    """Relax the initial state to static equilibrium under contact (strain 0)."""
    input:
        state=f"{RVE_DIR}/{{run}}/{{combo}}/states/initial.nc",
    output:
        state=f"{RVE_DIR}/{{run}}/{{combo}}/states/relaxed.nc",
    log:
        "results/logs/rve/{run}/{combo}/relax.log",
    benchmark:
        "results/benchmarks/rve/{run}/{combo}/relax.tsv"
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
    run:
        rve_pipeline.relax_job(input.state, output.state, log[0], params.spec, wildcards.combo)


rule rve_strain_step:
    """Strain step {step} of {mode} (Algorithm 7.1) from the previous stored state."""
    input:
        state=lambda w: rve_pipeline.previous_state(w.run, w.combo, w.mode, int(w.step), RVE_DIR),
    output:
        state=f"{RVE_DIR}/{{run}}/{{combo}}/states/{{mode}}_{{step}}.nc",
    log:
        "results/logs/rve/{run}/{combo}/strain/{mode}_{step}.log",
    benchmark:
        "results/benchmarks/rve/{run}/{combo}/strain/{mode}_{step}.tsv"
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
    priority: 10
    run:
        rve_pipeline.strain_job(
            input.state,
            output.state,
            log[0],
            params.spec,
            wildcards.combo,
            wildcards.mode,
            int(wildcards.step),
        )


rule rve_probes:
    """Decoupled probe solves (voltage, terminal currents, Joule temperature) on one state."""
    input:
        state=f"{RVE_DIR}/{{run}}/{{combo}}/states/{{state}}.nc",
    output:
        record=f"{RVE_DIR}/{{run}}/{{combo}}/probes/{{state}}.json",
    log:
        "results/logs/rve/{run}/{combo}/probes/{state}.log",
    benchmark:
        "results/benchmarks/rve/{run}/{combo}/probes/{state}.tsv"
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["rve_mem_mb"],
    run:
        rve_pipeline.probe_job(input.state, output.record, log[0], params.spec, wildcards.combo)


rule rve_gather:
    """All probe records of a run -> the lookup table (netCDF, CSV, text summary)."""
    input:
        records=lambda w: rve_pipeline.run_record_paths(config["rve"]["runs"][w.run], w.run, RVE_DIR),
    output:
        table=f"{RVE_DIR}/{{run}}/table.nc",
        csv=f"{RVE_DIR}/{{run}}/table.csv",
        summary=f"{RVE_DIR}/{{run}}/summary.txt",
    log:
        "results/logs/rve/{run}/gather.log",
    benchmark:
        "results/benchmarks/rve/{run}/gather.tsv"
    params:
        spec=lambda w: config["rve"]["runs"][w.run],
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
    run:
        rve_pipeline.gather_job(
            input.records,
            output.table,
            output.csv,
            output.summary,
            log[0],
            params.spec,
            wildcards.run,
        )


rule rve_report:
    """Figures of the table: reaction forces, probe resistances, temperature rises."""
    input:
        table=f"{RVE_DIR}/{{run}}/table.nc",
    output:
        reaction_force=f"{RVE_DIR}/{{run}}/plots/table_reaction_force.png",
        probe_resistance=f"{RVE_DIR}/{{run}}/plots/table_probe_resistance.png",
        temperature_rise=f"{RVE_DIR}/{{run}}/plots/table_temperature_rise.png",
    log:
        "results/logs/rve/{run}/report.log",
    benchmark:
        "results/benchmarks/rve/{run}/report.tsv"
    params:
        prefix=lambda w: f"{RVE_DIR}/{w.run}/plots/table",
    threads: 1
    resources:
        mem_mb=config["resources"]["gather_mem_mb"],
    run:
        rve_pipeline.report_job(input.table, params.prefix, log[0])
