# rve pipeline (docs/rve_pipeline.md). Run from the repository root:
#   snakemake -j2                      # the default targets (config `default_targets`)
#   snakemake -j2 --configfile configs/tests/pipeline_ci.yaml   # a quick small run
#   snakemake --lint
# Config: configs/pipeline.yaml, validated by workflow/schemas/pipeline.schema.yaml.


import os

# One BLAS/OpenMP thread per job. Every rule but rve_relax declares `threads: 1` and `-j2`
# runs two jobs side by side: OpenBLAS's default (a thread per core in each job) would
# oversubscribe the cores and tie a job's floating-point results to the thread count. With one thread a
# job's output depends on its input file only, so a killed and resumed run writes the same
# bits as an uninterrupted one (tests/test_rve_pipeline.py). Spawned jobs inherit this
# environment; values the user set are kept. rve_relax (alone on the machine: everything
# after it waits for it) declares `threads: 2` and hands them to the energy minimiser's
# PARDISO factorisations, which run in MKL's reproducible mode for up to 2 threads: the
# same bits on 1 or 2 (Snakemake scales the 2 down under -j1; docs/engine.md "Two threads").
os.environ.setdefault("RVE_PARDISO_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")


configfile: "configs/pipeline.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/verification.smk"
include: "workflow/rules/dynamic_wire.smk"
include: "workflow/rules/rve.smk"
include: "workflow/rules/induced_deformation.smk"
include: "workflow/rules/integrity.smk"
include: "workflow/rules/impact.smk"


rule all:
    """The default targets: the groups in config `default_targets` (rve_default_targets)."""
    input:
        rve_default_targets(config, {"static_wire": STATIC_WIRE_OUTPUTS, "dynamic_wire": DYNAMIC_WIRE_OUTPUTS}),
    default_target: True
