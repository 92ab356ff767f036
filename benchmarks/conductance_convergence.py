"""The contact conductance laws under refinement of the contact sampling (docs/contact.md
"Conductance laws", docs/table_accuracy.md): the probes of stored relaxed states of the
work-precision runs (the periodic 2 x 2 thesis weave, p = 2, the smooth contact curve, the
augmented Lagrangian) solved again with each law, ``width`` (Hertz's width of the line load,
the thesis's) and ``holm`` (force-based a-spots), per state: the sheet resistance, R_y, R_c
and the Joule rise of the x field probe, and each one's difference to the finest case.

    python benchmarks/conductance_convergence.py [--root DIR ...] [--hardness "100 MPa"]
        [--spot-radius "0.001 mm"] [CASE ...]

A CASE is ``LABEL=RUN/COMBO[+override+...]`` (default: the 6, 12 and 18 element runs and 12
elements with 8 contact points); its state is ``<root>/rve/RUN/COMBO/states/relaxed.nc``
under the first ``--root`` that has it (default ``results``), built by e.g.
``snakemake -j2 results/rve/work_precision_elements/mesh_elements-6/states/relaxed.nc``.
The run's config (configs/pipeline.yaml) with the overrides is the probe job's, the law's
keys added; the finest case is the one with the most contact points per fibril. The Holm
constants are illustrative (not calibrated): the comparison is of convergence, not of value.
"""
from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT  # noqa: E402

DEFAULT_CASES = ("6 el=work_precision_elements/mesh_elements-6+mesh.elements=6",
                 "12 el=work_precision_default/base",
                 "18 el=work_precision_reference_18/base",
                 "12 el, 8 points=work_precision_n_gp/contact_n_gp-8+contact.n_gp=8")


def _case(text: str, roots) -> dict:
    label, rest = text.split("=", 1)
    where, *overrides = rest.split("+")
    run, combo = where.split("/")
    for root in roots:
        state = Path(root) / "rve" / run / combo / "states" / "relaxed.nc"
        if state.exists():
            return {"label": label, "run": run, "overrides": overrides, "state": state}
    raise SystemExit(f"{label}: no {run}/{combo}/states/relaxed.nc under {roots}")


def _points_per_fibril(spec: dict) -> int:
    from rve.homogenisation.sweeps import load_run_config

    cfg = load_run_config(spec)
    return int(cfg.mesh.elements) * int(cfg.contact.n_gp)


def main():
    from rve.homogenisation.jobs import probe_record

    ap = argparse.ArgumentParser()
    ap.add_argument("cases", nargs="*", default=list(DEFAULT_CASES))
    ap.add_argument("--root", action="append", help="results directories to look in (default: results)")
    ap.add_argument("--hardness", default="100 MPa")
    ap.add_argument("--spot-radius", default="0.001 mm")
    a = ap.parse_args()
    roots = a.root or ["results"]
    runs = yaml.safe_load((ROOT / "configs" / "pipeline.yaml").read_text())["rve"]["runs"]
    laws = {"width": [], "holm": ["contact.conductance_law=holm", f"contact.hardness={a.hardness}",
                                  f"contact.spot_radius={a.spot_radius}"]}
    rows = []
    for text in a.cases:
        case = _case(text, roots)
        for law, keys in laws.items():
            spec = copy.deepcopy(runs[case["run"]])
            spec.pop("sweep", None)
            spec["overrides"] = list(spec.get("overrides", [])) + case["overrides"] + keys
            t0 = time.process_time()
            rec = probe_record(case["state"], spec, "base")
            fx = rec["probes"]["field_x"]
            rows.append({"law": law, "case": case["label"], "points": _points_per_fibril(spec),
                         "sheet": fx["resistance"], "R_y": fx["yarn_resistance_ohm"],
                         "R_c": fx["contact_resistance_ohm"], "T_max": fx["temperature_max"],
                         "cpu_s": time.process_time() - t0})
            r = rows[-1]
            print(f"  {law:5s} {r['case']:16s} {r['points']:4d} points/fibril  sheet {r['sheet']:.6f}  "
                  f"R_y {r['R_y']:.6f}  R_c {r['R_c']:.5g}  T_max {r['T_max']:.5g}  ({r['cpu_s']:.0f} s CPU)",
                  file=sys.stderr, flush=True)
    print("law    case              points/fibril   sheet resistance   R_y            R_c               Joule T_max")
    for law in laws:
        mine = [r for r in rows if r["law"] == law]
        ref = max(mine, key=lambda r: r["points"])
        for r in sorted(mine, key=lambda r: r["points"]):
            d = {k: 100.0 * (r[k] - ref[k]) / abs(ref[k]) for k in ("sheet", "R_y", "R_c", "T_max")}
            print(f"{law:6s} {r['case']:17s} {r['points']:4d}   {r['sheet']:.6f} ({d['sheet']:+.2f} %)   "
                  f"{r['R_y']:.6f} ({d['R_y']:+.3f} %)   {r['R_c']:.5g} ({d['R_c']:+.1f} %)   "
                  f"{r['T_max']:.5g} ({d['T_max']:+.1f} %)")


if __name__ == "__main__":
    main()
