"""Fault injection, livelocks: the dynamic wire at +-200 V and at
alpha_mu = -100 MPa/K used to cut the step to ~1e-27 ms with t no longer advancing and
nothing written. Now each stops within 60 s with the named failure (the minimum step of
rve.solvers.dirk.integrate) and the last good state saved by the scene's ``run``."""
from __future__ import annotations

import time

import numpy as np
import pytest

from rve.config import load_config
from rve.scenes.protocol import SceneFailure

pytestmark = [pytest.mark.faults, pytest.mark.slow]

CASES = {
    "200V": ["load.voltage_left=-200 V", "load.voltage_right=200 V"],
    "alpha_mu": ["material.alpha_mu=-100 MPa/K"],
}


@pytest.mark.parametrize("case", list(CASES))
def test_livelock_dynamic_wire_stops_within_60_s_with_the_last_good_state(case, tmp_path):
    from rve.scenes import dynamic_wire

    cfg = load_config("configs/scenes/dynamic_wire.yaml", CASES[case])
    t0 = time.perf_counter()
    with pytest.raises(SceneFailure) as ei:
        dynamic_wire.run(cfg, tmp_path)
    wall = time.perf_counter() - t0
    f = ei.value
    msg = str(f)
    print(f"{case}: stopped after {wall:.1f} s: {msg[:400]}")
    assert wall < 60
    assert f.phase == "time integration" and "minimum step" in msg and "residual" in msg
    assert f.saved and f.saved.endswith("dynamic_wire_last_good_state.npz")
    saved = np.load(f.saved)
    assert float(saved["t"]) == pytest.approx(f.time) and 0 < f.time < cfg.time.t_max
    assert np.all(np.isfinite(saved["x"])) and np.all(np.isfinite(saved["w"]))
    assert (tmp_path / "dynamic_wire_history.nc").exists()   # the history up to the failure
