"""Friction through the RVE pipeline on the curve and smooth contact geometries (p = 2): the
config accepts them, and the strain steps of a tiny cell are equilibria with their friction
history (recomputed from the checkpoint), not without it; the dissipation accumulates."""
import sys
from pathlib import Path

import pytest

from rve.config import validate_config

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_rve_friction import TINY, _spec  # noqa: E402


@pytest.mark.parametrize("geometry", ["curve", "smooth"])
def test_config_accepts_friction_on_the_curves(geometry):
    cfg = validate_config({**TINY, "friction": {"coefficient": 0.2}, "contact": {"geometry": geometry},
                           "mesh": {"elements": 8, "order": 2}})
    assert cfg.has_friction and cfg.contact.geometry == geometry


@pytest.mark.parametrize("geometry", ["curve", "smooth"])
def test_strain_steps_on_the_curves_are_frictional_equilibria(geometry, tmp_path):
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import fabric_job, recomputed_residual, relax_job, strain_job
    from rve.homogenisation.sweeps import load_run_config

    spec = _spec(0.3)
    spec["scene"] = {**spec["scene"], "contact": {"geometry": geometry}, "mesh": {"elements": 8, "order": 2}}
    fabric_job(tmp_path / "initial.nc", None, spec)
    relax_job(tmp_path / "initial.nc", tmp_path / "relaxed.nc", None, spec)
    cfg = load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    prev, d_prev = tmp_path / "relaxed.nc", 0.0
    for i in (1, 2):
        strain_job(prev, tmp_path / f"shear_{i:02d}.nc", None, spec, "base", "shear", i)
        prev = tmp_path / f"shear_{i:02d}.nc"
        st = load_state(prev)
        assert st.friction is not None and len(st.friction["keys"]) > 0
        assert st.solver["converged"] and st.solver["residual_N"] <= 1e-9
        assert recomputed_residual(cfg, fab, mesh, st.x, friction=st.friction) <= 1e-9
        assert recomputed_residual(cfg, fab, mesh, st.x, friction=None) > 1e-6
        fr = st.solver["friction"]
        assert fr["friction_force"] > 0 and fr["stick"] + fr["slip"] > 0 and fr["step_dissipated"] > 0
        assert st.friction["dissipated"] == pytest.approx(d_prev + fr["step_dissipated"], rel=1e-12, abs=1e-18)
        d_prev = st.friction["dissipated"]
