# Shared set-up of the rve pipeline: config validation, the verification studies' layout,
# the default targets. Rules live in the other .smk files; they call package functions
# (rve.studies.*), imported in the rule bodies; paths come from rve.studies.layout (no study
# module is imported at parse time).

from snakemake.utils import validate

from rve.studies import layout as study_layout


# Snakemake's own YAML load keeps the last of two equal keys (a duplicated section drops the
# first one's keys without a word): every config file is re-read strictly, and a duplicate is
# an error naming the file, the line and the key (docs/fault_tolerance.md).
from rve.config.loader import read_config_source as _read_config_source

for _configfile in workflow.configfiles:
    _read_config_source(_configfile)

validate(config, schema="../schemas/pipeline.schema.yaml")


wildcard_constraints:
    order=r"[1-9]",
    elements=r"[0-9]+",
    radius=r"[0-9]+(\.[0-9]+)?(e-?[0-9]+)?",


# --------------------------------------------------------------------------- static wire
STATIC_WIRE = config["verification"]["static_wire"]
STATIC_WIRE_OUTPUTS = study_layout.STATIC_WIRE_OUTPUTS


def static_wire_point_records(wildcards=None):
    """JSON records of every solve of the study (radius sweep and convergence series)."""
    return [
        study_layout.static_wire_point(p, n, study_layout.radius_token(r))
        for p, n, r in study_layout.study_points(STATIC_WIRE)
    ]


# --------------------------------------------------------------------------- default target
# What `snakemake -j2` builds: the groups listed in config `default_targets`: rve = the
# lookup tables and figures of the runs in rve.default_runs (workflow/rules/rve.smk),
# static_wire / dynamic_wire = the verification studies. The `all` rule in the Snakefile
# resolves them once every rule file is included.
from rve.homogenisation.layout import default_targets as rve_default_targets


def _work_precision(w):
    """The runs of work-precision study ``w.study`` (rve.work_precision in the config)."""
    return rve_layout.work_precision_runs(config["rve"], w.study)


def _work_precision_levers(w):
    """The lever values of study ``w.study``'s default run (else its reference)."""
    from rve.homogenisation.sweeps import lever_values

    wp = _work_precision(w)
    return lever_values(config["rve"]["runs"][wp["default"] or wp["reference"]])

