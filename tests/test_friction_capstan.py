"""The capstan scene on a cheap mesh: once the whole wrap slides, T2/T1 = exp(mu theta)
(within 2 % here; benchmarks/capstan.py runs the full-size cases to 1 %)."""
import math

import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import capstan

CHEAP = ["mesh.elements_per_radian=20", "load.steps=6", "load.pull=0.03 mm", "load.rebuild_every=2"]


@pytest.mark.parametrize("mu, theta", [(0.3, "90 deg"), (0.0, "90 deg")])
def test_capstan_ratio_cheap(mu, theta):
    cfg = load_config("configs/scenes/capstan.yaml", CHEAP + [f"friction.coefficient={mu}",
                                                              f"geometry.wrap_angle={theta}"])
    s = capstan.solve(cfg).summary
    assert np.isclose(s["exact"], math.exp(mu * math.pi / 2))
    last = s["path"][-2:]
    if mu > 0:
        assert all(p["stick"] == 0 and p["slip"] > 0 for p in last)     # the whole wrap slides
        assert s["path"][0]["stick"] > 0                                 # it stuck first
    assert abs(s["relative_error"]) < 0.02, s["relative_error"]
    assert abs(last[0]["ratio"] / last[1]["ratio"] - 1) < 0.02           # on the plateau
