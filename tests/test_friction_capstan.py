"""The capstan scene on a cheap mesh, on the chord and (p = 2) on the Lagrange centroid curve
and the smooth Hermite curve: once the whole wrap slides, T2/T1 = exp(mu theta) (within 2 %
here; benchmarks/capstan.py runs the full-size cases to 1 %). On the curves the wrapped
fibril's half pass carries the contact (the cylinder's own points, on its axis 0.58 R_c above
and below the wrap's plane, touch nothing)."""
import math

import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import capstan

CHEAP = ["mesh.elements_per_radian=20", "load.steps=6", "load.pull=0.03 mm", "load.rebuild_every=2"]
CURVE = ["mesh.order=2"]


@pytest.mark.parametrize("geometry, mu", [("chord", 0.3), ("chord", 0.0), ("curve", 0.3), ("smooth", 0.3),
                                          ("curve", 0.0)])
def test_capstan_ratio_cheap(geometry, mu):
    sets = CHEAP + (CURVE + [f"contact.geometry={geometry}"] if geometry != "chord" else [])
    cfg = load_config("configs/scenes/capstan.yaml", sets + [f"friction.coefficient={mu}", "geometry.wrap_angle=90 deg"])
    s = capstan.solve(cfg).summary
    assert np.isclose(s["exact"], math.exp(mu * math.pi / 2))
    last = s["path"][-2:]
    if mu > 0:
        assert all(p["stick"] == 0 and p["slip"] > 0 for p in last)     # the whole wrap slides
        assert s["path"][0]["stick"] > 0                                 # it stuck first
    assert abs(s["relative_error"]) < 0.02, s["relative_error"]
    assert abs(last[0]["ratio"] / last[1]["ratio"] - 1) < 0.02           # on the plateau
