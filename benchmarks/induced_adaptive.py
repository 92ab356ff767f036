"""Fixed against error-controlled steps on one induced-deformation orientation, in one run
(docs/engine.md "Error-controlled steps of the induced deformation").

    python benchmarks/induced_adaptive.py [--steps 3000] [--orientation B2] [--order fixed,adaptive]
        [--adaptive KEY=VALUE ...] [--set KEY=VALUE ...] [--out-dir DIR]

Runs ``benchmarks/dynamic_compare.py run induced`` once per mode, each in a fresh process, one
after the other in ``--order``, on the same store grid (``time.store_every=10``: with error
control the steps land there, so both histories have the same times); ``--adaptive`` are
``time.adaptive.*`` overrides of the adaptive run (``enabled=true`` is implied). Prints each
run's wall and CPU seconds, steps, rejections, Newton iterations per stage, the ratio adaptive /
fixed of wall and CPU, and then ``dynamic_compare.py diff`` (deflection and max T histories
at the common times, balances).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--orientation", default="B2")
    ap.add_argument("--order", default="fixed,adaptive")
    ap.add_argument("--adaptive", nargs="*", default=[])
    ap.add_argument("--set", nargs="*", default=[])
    ap.add_argument("--out-dir", default="/tmp/rve_induced_adaptive")
    a = ap.parse_args()
    out = Path(a.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    base = [sys.executable, str(HERE / "dynamic_compare.py"), "run", "induced", "--steps", str(a.steps),
            "--orientation", a.orientation]
    sets = {"fixed": ["time.store_every=10", *a.set],
            "adaptive": ["time.store_every=10", *a.set, "time.adaptive.enabled=true",
                         *[f"time.adaptive.{kv}" for kv in a.adaptive]]}
    files = {}
    for mode in a.order.split(","):
        files[mode] = out / f"{mode}.npz"
        cmd = base + ["--set", *sets[mode], "--out", str(files[mode])]
        print("$", " ".join(cmd), flush=True)
        subprocess.run(cmd, check=True, env=os.environ.copy())
    metas = {m: json.loads(str(np.load(f)["meta"])) for m, f in files.items()}
    for m, meta in metas.items():
        print(f"{m}: wall {meta['wall_s']:.1f} s, CPU {meta['cpu_s']:.1f} s, {meta['steps']} steps, "
              f"{meta['rejected']} rejected ({meta.get('error_rejections', 0)} by the error estimate), "
              f"Newton its/stage {meta['newton_iterations_per_stage']:.2f}, factorisations {meta['factorizations']}, "
              f"step ms {json.dumps(meta.get('step_ms', {}))}")
    if {"fixed", "adaptive"} <= set(metas):
        f, d = metas["fixed"], metas["adaptive"]
        print(f"ratio adaptive / fixed: wall {d['wall_s'] / f['wall_s']:.3f}, CPU {d['cpu_s'] / f['cpu_s']:.3f}")
        subprocess.run([sys.executable, str(HERE / "dynamic_compare.py"), "diff", str(files["fixed"]),
                        str(files["adaptive"])], check=True)


if __name__ == "__main__":
    main()
