# rve pipeline (SPEC §6). Run from the repository root:
#   snakemake -j2                      # the default targets (DEFAULT_TARGETS in common.smk)
#   snakemake -j2 --configfile configs/tests/pipeline_ci.yaml   # a quick small run
#   snakemake --lint
# Config: configs/pipeline.yaml, validated by workflow/schemas/pipeline.schema.yaml.


configfile: "configs/pipeline.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/verification.smk"


rule all:
    """The default targets (see DEFAULT_TARGETS in workflow/rules/common.smk)."""
    input:
        DEFAULT_TARGETS,
    default_target: True
