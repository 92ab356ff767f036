"""Holm's force-based contact conductance calibrated against the thesis's width law
(docs/contact.md "Conductance laws", "Calibrating Holm's law").

The thesis's contact conductance is sigma_C times the Hertz width of the line load at its
penalty P* (Table 7.1's law on the overlap). With the augmented Lagrangian that law has no
limit under refinement (the width of a point contact shrinks with the resolved length), so
the periodic tables use Holm's law, whose conductance is linear in the line load with the
coefficient ``2 sigma0 / (pi H a_s)``. Its one free constant (H a_s) is chosen here so that
the periodic cell's relaxed warp-weft exchange resistance r_c (ohm mm^2, the probe's
``exchange_resistance_ohm_mm2``; R_c = 4 r_c / (a_x a_y)) equals the thesis law's:

1. the thesis state: the run's cell relaxed with the penalty (``contact.enforcement=penalty``,
   the scene config's P*, the linear law ``contact.onset=0``) and probed with the width law;
2. the table's state: the run's own relaxed state (augmented Lagrangian), probed with Holm's
   law at the hardness ``--hardness`` and a spot radius a_s; r_c is close to proportional
   to H a_s (the contacts' share of the exchange path), so a_s is rescaled by the ratio of
   the two r_c until they agree to ``--rtol``.

    python benchmarks/holm_calibration.py [--run work_precision_default] [--hardness "100 MPa"]
        [--work DIR] [--relaxed RUN_RELAXED.nc] [--rtol 1e-3] [--set KEY=VALUE ...]

Prints the thesis r_c and R_c, each Holm iterate (a_s, r_c, its ratio to the target) and the
calibrated ``contact.spot_radius`` with the CPU seconds of every solve.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import ROOT, pipeline_spec, relaxed_state  # noqa: E402


def exchange(state: Path, spec: dict) -> tuple[float, float]:
    """(r_c ohm mm^2, R_c ohm) of the x field probe of ``state`` under ``spec``."""
    from rve.homogenisation.jobs import probe_record

    c0 = time.process_time()
    p = probe_record(state, spec, "base")["probes"]["field_x"]
    r_c = float(p["exchange_resistance_ohm_mm2"])
    print(f"  probe {state.parent.name}: r_c {r_c:.6g} ohm mm2, R_c {p['contact_resistance_ohm']:.6g} ohm "
          f"({time.process_time() - c0:.1f} s CPU)", flush=True)
    return r_c, float(p["contact_resistance_ohm"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", default="work_precision_default")
    ap.add_argument("--hardness", default="100 MPa")
    ap.add_argument("--spot-radius", type=float, default=0.02, help="first a_s guess (mm)")
    ap.add_argument("--work", default=None)
    ap.add_argument("--relaxed", default=None, help="the run's relaxed state, if built already")
    ap.add_argument("--rtol", type=float, default=1e-3)
    ap.add_argument("--max-iter", type=int, default=6)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args()
    from rve.homogenisation.sweeps import load_run_config

    work = Path(a.work or tempfile.mkdtemp(prefix="holm_"))
    base = pipeline_spec(a.run, a.set)
    thesis = pipeline_spec(a.run, [*a.set, "contact.enforcement=penalty", "contact.onset=0", "contact.conductance_law=width",
                              f"contact.penalty={_scene_penalty(base)}"])
    target, target_R = exchange(relaxed_state(thesis, "base", work / "thesis_penalty"), thesis)
    print(f"thesis law (width, penalty {_scene_penalty(base)}): r_c {target:.6g} ohm mm2, R_c {target_R:.6g} ohm")
    state = Path(a.relaxed) if a.relaxed else relaxed_state(base, "base", work / "run")
    a_s = float(a.spot_radius)
    for k in range(a.max_iter):
        holm = pipeline_spec(a.run, [*a.set, "contact.conductance_law=holm", f"contact.hardness={a.hardness}",
                                f"contact.spot_radius={a_s:.9g} mm"])
        r_c, R_c = exchange(state, holm)
        ratio = r_c / target
        print(f"holm iterate {k + 1}: spot_radius {a_s:.6g} mm, r_c {r_c:.6g} ohm mm2 (R_c {R_c:.6g} ohm), "
              f"ratio to the thesis law {ratio:.6f}", flush=True)
        if abs(ratio - 1.0) <= a.rtol:
            H = load_run_config(holm, "base").contact.hardness   # N/mm^2, converted by the config
            print(f"calibrated: contact.hardness = {a.hardness}, contact.spot_radius = {a_s:.4g} mm "
                  f"(H a_s = {H * a_s:.4g} N/mm; c_H = 2 sigma0/(pi H a_s))")
            return 0
        a_s /= ratio
    print("not calibrated within --max-iter iterations")
    return 1


def _scene_penalty(spec: dict) -> str:
    """The scene config's P* (Table 7.1's law of the thesis tables), not the run's override."""
    cfg = yaml.safe_load((ROOT / spec["scene_config"]).read_text())
    return str(cfg["contact"]["penalty"]).replace(" ", "")


if __name__ == "__main__":
    sys.exit(main())
