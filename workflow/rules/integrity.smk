# docs/fault_tolerance.md: before Snakemake builds its DAG, every state and table
# of the configured runs that fails its SHA-256 trailer (rve.io.checksum; bytes only, no
# HDF5, ~1 ms a file) is moved to <name>.corrupt, so the jobs that wrote them rerun now
# instead of "Nothing to be done". States must carry a trailer (load_state refuses them
# otherwise); tables without one (written by an older rve) are kept. Main process only: the
# spawned jobs re-parse the workflow and must not touch files.

import glob as _glob
import sys as _sys

if workflow.is_main_process:
    from rve.io.checksum import quarantine_failing as _quarantine_failing

    from pathlib import Path as _Path

    def _stale(path):
        # an output derived from a quarantined file: moved aside too, so Snakemake does not
        # see the finished targets as up to date ("Nothing to be done") and skips the rebuild
        p = _Path(path)
        if p.exists():
            p.replace(p.with_name(f"{p.name}.stale"))
            return [str(p)]
        return []

    def _integrity_sweep():
        moved, stale = [], []
        for run in config.get("rve", {}).get("runs", {}) or {}:
            base = f"results/rve/{run}"
            bad_states = _quarantine_failing(sorted(_glob.glob(f"{base}/*/states/*.nc")), require_seal=True)
            bad_tables = _quarantine_failing(sorted(_glob.glob(f"{base}/table.nc")), require_seal=False)
            for path, _, _ in bad_states:
                p = _Path(path)   # results/rve/{run}/{combo}/states/{state}.nc
                stale += _stale(rve_layout.record_path(run, p.parent.parent.name, p.stem))
            if bad_states or bad_tables:
                for out in rve_layout.table_outputs(run).values():
                    stale += _stale(out)
            moved += bad_states + bad_tables
        for path, what, dest in moved:
            print(f"rve: {path}: {what}; moved to {dest}: the job that wrote it reruns", file=_sys.stderr)
        for path in stale:
            print(f"rve: {path}: derived from a file that failed its check; moved to {path}.stale", file=_sys.stderr)

    _integrity_sweep()


# A misspelt top-level key of the pipeline config is an error naming it (the
# schema's properties are the allowed keys), and a target naming an unknown run says so
# instead of a bare KeyError.
import yaml as _yaml

import os as _os

_ALLOWED_TOP = list(_yaml.safe_load(open(_os.path.join(workflow.basedir, "workflow", "schemas", "pipeline.schema.yaml")))["properties"])
_unknown_top = [k for k in config if k not in _ALLOWED_TOP]
if _unknown_top:
    raise ValueError(f"pipeline config: unknown top-level key(s) {', '.join(map(repr, _unknown_top))} "
                     f"(allowed: {', '.join(_ALLOWED_TOP)})")


class _Runs(dict):
    def __missing__(self, run):
        raise KeyError(f"unknown run {run!r}: not in the pipeline config's rve.runs (known: "
                       f"{', '.join(self) or 'none'}); add it to rve.runs or fix the target path")


if isinstance(config.get("rve"), dict) and isinstance(config["rve"].get("runs"), dict):
    config["rve"]["runs"] = _Runs(config["rve"]["runs"])
