"""The capstan scene on the Lagrange centroid curve and the smooth Hermite curve at p = 2
(cheap mesh, as tests/test_friction_capstan.py on the chord): once the whole wrap slides,
T2/T1 = exp(mu theta) within 2 %. The wrapped fibril's half pass carries the contact (the
cylinder's own points, on its axis 0.58 R_c above and below the wrap's plane, touch nothing)."""
import math

import numpy as np
import pytest

from rve.config.loader import load_config
from rve.scenes import capstan

CHEAP = ["mesh.elements_per_radian=20", "load.steps=6", "load.pull=0.03 mm", "load.rebuild_every=2", "mesh.order=2"]


@pytest.mark.parametrize("geometry, mu", [("curve", 0.3), ("smooth", 0.3), ("curve", 0.0)])
def test_capstan_ratio_on_the_curves(geometry, mu):
    cfg = load_config("configs/scenes/capstan.yaml", CHEAP + [f"contact.geometry={geometry}",
                                                              f"friction.coefficient={mu}", "geometry.wrap_angle=90 deg"])
    s = capstan.solve(cfg).summary
    assert np.isclose(s["exact"], math.exp(mu * math.pi / 2))
    last = s["path"][-2:]
    if mu > 0:
        assert all(p["stick"] == 0 and p["slip"] > 0 for p in last)     # the whole wrap slides
        assert s["path"][0]["stick"] > 0                                 # it stuck first
    assert abs(s["relative_error"]) < 0.02, s["relative_error"]
    assert abs(last[0]["ratio"] / last[1]["ratio"] - 1) < 0.02
