"""The probes of a run's stored states solved again under changed probe settings (e.g. the
contact conductance law), and the lookup table built from them, without re-running the
mechanics: the states' positions and multipliers are the run's, the probes the new config's.

    python benchmarks/reprobe_table.py RUN STATES_DIR OUT_DIR [--set KEY=VALUE ...]

RUN names the run in configs/pipeline.yaml (its scene config and overrides, ``--set``
appended); STATES_DIR holds its ``relaxed.nc`` and ``<mode>_NN.nc`` states (e.g.
``results/rve/RUN/base/states``); OUT_DIR gets ``records/*.json`` and ``table.nc`` (with
``table.csv``, ``summary.txt``). Compare two such tables with
``benchmarks/table_against_reference.py``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import pipeline_spec  # noqa: E402


def main():
    from rve.homogenisation.jobs import probe_record
    from rve.tables.jobs import gather_job

    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("states")
    ap.add_argument("out")
    ap.add_argument("--set", action="append", default=[], help="an override KEY=VALUE (repeatable)")
    a = ap.parse_args()
    spec = pipeline_spec(a.run, a.set)
    out = Path(a.out)
    (out / "records").mkdir(parents=True, exist_ok=True)
    states = sorted(p for p in Path(a.states).glob("*.nc") if p.stem != "initial" and "unconverged" not in p.stem)
    records = []
    for st in states:
        t0 = time.process_time()
        rec = probe_record(st, spec, "base")
        path = out / "records" / f"{st.stem}.json"
        path.write_text(json.dumps(rec, default=float))
        records.append(path)
        print(f"{st.stem}: {time.process_time() - t0:.1f} s CPU", file=sys.stderr, flush=True)
    gather_job(records, out / "table.nc", out / "table.csv", out / "summary.txt", None, spec, a.run)
    print(f"{len(records)} states re-probed -> {out / 'table.nc'}")


if __name__ == "__main__":
    main()
