# Issue 15 (docs/fault_tolerance.md): before Snakemake builds its DAG, every state and table
# of the configured runs that fails its SHA-256 trailer (rve.io.checksum; bytes only, no
# HDF5, ~1 ms a file) is moved to <name>.corrupt, so the jobs that wrote them rerun now
# instead of "Nothing to be done". States must carry a trailer (load_state refuses them
# otherwise); tables without one (written before issue 15) are kept. Main process only: the
# spawned jobs re-parse the workflow and must not touch files.

import glob as _glob
import sys as _sys

if workflow.is_main_process:
    from rve.io.checksum import quarantine_failing as _quarantine_failing

    def _integrity_sweep():
        moved = []
        for run in config.get("rve", {}).get("runs", {}) or {}:
            base = f"results/rve/{run}"
            moved += _quarantine_failing(sorted(_glob.glob(f"{base}/*/states/*.nc")), require_seal=True)
            moved += _quarantine_failing(sorted(_glob.glob(f"{base}/table.nc")), require_seal=False)
        for path, what, dest in moved:
            print(f"rve: {path}: {what}; moved to {dest}: the job that wrote it reruns", file=_sys.stderr)

    _integrity_sweep()
