"""The temperature post-solve on the SDIRK stepper against the kept-factorisation solver:
how far apart the two are, next to the time-integration error of T.

    nice -n 10 python benchmarks/thermal_post_dirk.py [--steps 200]

Runs the induced deformation case of benchmarks/compare_outputs.py (orientation B2 to
t = 1 ms) three times: ``post_reuse=True`` (``ThermalPostSolver``, the scenes' default),
``post_reuse="dirk"`` (``rve.scenes.thermal_post.DirkThermalPost``) and the default again
with twice the steps. Prints max |T_dirk - T_kept| and max |T_h - T_h/2| over the stored
states (K), relative to max |T|, and the post-solve wall times and solve counts.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def _run(steps: int, post):
    from compare_outputs import INDUCED
    from rve.config.loader import load_config
    from rve.scenes.induced.scene import solve

    over = [o for o in INDUCED if not o.startswith("time.steps")] + [f"time.steps={steps}"]
    cfg = load_config(ROOT / "configs/scenes/induced_deformation.yaml", over)
    res = solve(cfg, post_reuse=post)
    st = res.summary["history"]["stored"]
    return np.asarray(st["t"]), np.asarray(st["T"]), res.summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=200)
    a = ap.parse_args(argv)
    t, T_kept, s_kept = _run(a.steps, True)
    t_d, T_dirk, s_dirk = _run(a.steps, "dirk")
    t_h, T_half, _ = _run(2 * a.steps, True)
    assert np.array_equal(t, t_d)
    scale = float(np.abs(T_kept).max())
    d_post = float(np.abs(T_dirk - T_kept).max())
    common = [int(np.argmin(np.abs(t_h - tk))) for tk in t]
    ok = np.abs(t_h[common] - t) <= 1e-9 * max(1.0, float(t[-1]))
    d_time = float(np.abs(T_half[common][ok] - T_kept[ok]).max())
    print(f"induced B2 to t = {t[-1]:.4g} ms, {a.steps} steps; {T_kept.shape[0]} stored states, max |T| = {scale:.6g} K")
    print(f"  max |T_dirk - T_kept|         = {d_post:.3e} K ({d_post / scale:.3e} of max |T|)")
    print(f"  max |T(h) - T(h/2)| (kept)    = {d_time:.3e} K ({d_time / scale:.3e} of max |T|), "
          f"{int(ok.sum())} common times")
    for name, s in (("kept", s_kept), ("dirk", s_dirk)):
        print(f"  {name}: post-solve wall {s.get('wall_time_s', {}).get('thermal_post', float('nan')):.3f} s, "
              f"solves {s.get('thermal_post_solves')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
