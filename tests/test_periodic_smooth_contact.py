"""The periodic cell's pipeline job bodies (rve.homogenisation.jobs) with the smooth (C¹
Hermite) contact curve: relax -> one uniaxial strain step -> the field probes, converged, the
contact seen, charge conserved (the whole Snakemake DAG with ``contact.geometry=smooth``:
docs/contact.md "The smooth contact curve in the pipeline")."""
from __future__ import annotations

import json

import numpy as np
import pytest


@pytest.mark.parametrize("geometry", ["smooth"])
def test_relax_step_and_probe_with_the_smooth_curve(tmp_path, geometry):
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import fabric_job, probe_job, relax_job, strain_job

    spec = {"scene_config": None, "overrides": [f"contact.geometry={geometry}"],
            "scene": {"scene": "rve", "boundary": "periodic", "fabric": {"kind": "plain", "rows": [1]},
                      "mesh": {"elements": 6}, "output": {"pictures": False},
                      "strain": {"modes": ["uniaxial"], "total": 0.05, "steps": 1}}}
    d = tmp_path
    fabric_job(d / "initial.nc", None, spec)
    relax_job(d / "initial.nc", d / "relaxed.nc", None, spec)
    strain_job(d / "relaxed.nc", d / "uniaxial_01.nc", None, spec, "base", "uniaxial", 1)
    probe_job(d / "uniaxial_01.nc", d / "uniaxial_01.json", None, spec)
    rec = json.loads((d / "uniaxial_01.json").read_text())
    assert rec["state"]["converged"] and rec["state"]["residual_N"] < 1e-8
    assert rec["contact_count"] > 0   # the crossings touch on the Hermite curves
    for name, p in rec["probes"].items():
        I = p["current"]
        assert p["connected"] and np.isfinite(p["resistance"]) and p["resistance"] > 0, name
        # the current that enters leaves: the contact conductances on the curve conserve charge
        assert abs(I["+"] + I["-"]) <= 1e-12 * abs(I["+"]) and p["conservation_error"] < 1e-10, name
    cfg = load_state(d / "uniaxial_01.nc").config
    assert cfg["contact"]["geometry"] == geometry
