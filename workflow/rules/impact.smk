# Electromagnetically enhanced armour (thesis §8.4, Figs. 8.4.1-8.4.6; docs/impact.md).
# Include from the Snakefile after common.smk:   include: "workflow/rules/impact.smk"
# Target `impact`: the relaxation (saved, reused by every impact run), the full thesis impact
# (32 x 32 yarns, 80 elements, 0.5 ms in 1000 SDIRK2 steps) and its figures.
# Target `impact_sweep`: final speed, tilt rate and peak temperature against the warp current
# density (config impact.currents), on the reduced case of impact.sweep_overrides: the weave,
# the projectile and the horizon scaled by 1/4 (same yarn spacing, elements of 0.64 mm, the
# same deflection-to-span ratio at t_end); each point of the full size costs as much as the
# full run.
# Optional pipeline config key impact: {scene_config, overrides, sweep_overrides, currents}.

import os

IMPACT = {"scene_config": "configs/scenes/impact.yaml", "overrides": [],
          "sweep_overrides": ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=20",
                              "projectile.radius=4.5 mm", "time.t_end=0.125 ms", "time.steps=250",
                              "output.vtk=false"],
          "currents": [0, 50, 100, 200], **config.get("impact", {})}
IMPACT_DIR = "results/impact"


rule impact:
    """Relaxation + the full thesis impact and its outputs."""
    input:
        f"{IMPACT_DIR}/full/summary.json",


rule impact_relax:
    """The relaxed fabric with the projectile present and at rest (B off)."""
    input:
        scene=IMPACT["scene_config"],
    output:
        state=f"{IMPACT_DIR}/{{case}}/relaxed_state.npz",
        record=f"{IMPACT_DIR}/{{case}}/relaxation.json",
    log:
        "results/logs/impact/{case}_relax.log",
    benchmark:
        "results/benchmarks/impact/{case}_relax.tsv"
    params:
        overrides=lambda wc: IMPACT["overrides"] if wc.case == "full" else IMPACT["overrides"] + IMPACT["sweep_overrides"],
        out=lambda wc: f"{IMPACT_DIR}/{wc.case}",
    threads: 1
    run:
        from rve.scenes.impact.jobs import impact_job

        impact_job(input.scene, params.out, output.record, log[0], params.overrides,
                   relaxed=output.state, relax_only=True)


rule impact_full:
    """The thesis impact from the saved relaxed state (outputs under results/impact/full)."""
    input:
        scene=IMPACT["scene_config"],
        relaxed=f"{IMPACT_DIR}/full/relaxed_state.npz",
    output:
        summary=f"{IMPACT_DIR}/full/summary.json",
        nc=f"{IMPACT_DIR}/full/impact.nc",
    log:
        "results/logs/impact/full.log",
    benchmark:
        "results/benchmarks/impact/full.tsv"
    params:
        overrides=IMPACT["overrides"],
        out=lambda w, output: os.path.dirname(output.summary),
    threads: 1
    resources:
        mem_mb=4000,
    run:
        from rve.scenes.impact.jobs import impact_job

        impact_job(input.scene, params.out, output.summary, log[0], params.overrides,
                   relaxed=input.relaxed)


rule impact_sweep_point:
    """One current density of the sweep (reduced case)."""
    input:
        scene=IMPACT["scene_config"],
        relaxed=f"{IMPACT_DIR}/sweep/relaxed_state.npz",
    output:
        summary=f"{IMPACT_DIR}/sweep/J{{current}}/summary.json",
    log:
        "results/logs/impact/sweep_J{current}.log",
    benchmark:
        "results/benchmarks/impact/sweep_J{current}.tsv"
    params:
        overrides=lambda wc: IMPACT["overrides"] + IMPACT["sweep_overrides"] + [f"warp.J_bar=-{wc.current} A/mm^2"],
        out=lambda wc: f"{IMPACT_DIR}/sweep/J{wc.current}",
    threads: 1
    run:
        from rve.scenes.impact.jobs import impact_job

        impact_job(input.scene, params.out, output.summary, log[0], params.overrides,
                   relaxed=input.relaxed)


rule impact_sweep:
    """Final speed, tilt rate and peak temperature against the warp current density."""
    input:
        expand(f"{IMPACT_DIR}/sweep/J{{current}}/summary.json", current=IMPACT["currents"]),
    output:
        png=f"{IMPACT_DIR}/sweep/current_sweep.png",
        json=f"{IMPACT_DIR}/sweep/current_sweep.json",
    log:
        "results/logs/impact/sweep_curve.log",
    params:
        currents=IMPACT["currents"],
    threads: 1
    run:
        from rve.scenes.impact.jobs import sweep_curve

        sweep_curve(input, params.currents, output.png, output.json)
