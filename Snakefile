# rve pipeline (SPEC §6). Run from the repository root:
#   snakemake -j2                      # the default targets (config `default_targets`)
#   snakemake -j2 --configfile configs/tests/pipeline_ci.yaml   # a quick small run
#   snakemake --lint
# Config: configs/pipeline.yaml, validated by workflow/schemas/pipeline.schema.yaml.


configfile: "configs/pipeline.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/verification.smk"
include: "workflow/rules/dynamic_wire.smk"
include: "workflow/rules/rve.smk"


rule all:
    """The default targets: the groups in config `default_targets` (rve_default_targets)."""
    input:
        rve_default_targets(config, {"static_wire": STATIC_WIRE_OUTPUTS, "dynamic_wire": DYNAMIC_WIRE_OUTPUTS}),
    default_target: True
