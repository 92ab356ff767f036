"""The scikit-fem macro demo (examples/macro_demo.py, docs/macro_export.md §5) on the CI
fixture table: the two-potential sheet against the sparse resistor network, the membrane
strip with the exported fabric curves, the strip with a hole feeding the sheet model."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("skfem", reason="scikit-fem not installed: the macro demo is not run")

ROOT = Path(__file__).resolve().parents[1]
TABLE = ROOT / "tests" / "data" / "table_v1_ci.nc"


@pytest.fixture(scope="module")
def demo():
    spec = importlib.util.spec_from_file_location("macro_demo", ROOT / "examples" / "macro_demo.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["macro_demo"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def ds():
    from rve.tables import open_table

    return open_table(TABLE)


def test_busbar_resistance_equals_the_network_on_reference_and_deformed_mesh(demo, ds):
    out = demo.check_busbar(ds)
    assert out["reference"] < 1e-10 and out["deformed"] < 1e-10
    # forgetting the push-forward G = F G0 F^T / J is off by the stretch (10 % at the last strain)
    assert out["no_push_forward"] == pytest.approx(0.1, rel=1e-9)


def test_network_solver_against_the_rve_network_model(demo):
    from rve.homogenisation.network import YarnNetwork

    # the sparse patch network is the YarnNetwork topology: one warp end to end
    R = demo.network_resistance(4, 4, 0.7, 3.0, [1], [1])
    assert R == pytest.approx(YarnNetwork(4, 4).resistance(("warp", 1, "-"), ("warp", 1, "+"), 0.7, 3.0), rel=1e-12)


def test_pads_two_potential_within_5_percent_one_potential_far_off(demo, ds):
    out = demo.check_pads(ds)
    assert abs(out["two_potential"]) < 0.05, out
    assert abs(out["one_potential"]) > 0.20, out


def test_fitted_network_reproduces_the_probes_to_the_fit_residual(demo, ds):
    assert demo.check_probes(ds) < 1e-9


def test_membrane_strip_reaction_per_width_is_the_tables_n_xx(demo, ds):
    entries = demo.hermite_law_entries(ds)
    strains = [float(e) for e in ds["strain"].values]
    Nxx, iters = demo.strip_reactions(entries, strains)
    N = ds["membrane_force"].sel(mode="uniaxial", edge="x", component="x").values
    want = N - float(ds["membrane_force_at_zero_strain"].sel(mode="uniaxial", edge="x", component="x"))
    np.testing.assert_allclose(Nxx, want, rtol=0, atol=1e-10 * np.abs(want).max())
    assert max(iters) <= 5, iters
    # the complex-step tangent is the derivative of P (finite differences)
    law = demo.FabricLaw(entries)
    F = np.array([[1.06, 0.02], [0.01, 0.99]])[:, :, None]
    A = law.tangent(F)[..., 0]
    h = 1e-7
    for k in range(2):
        for L in range(2):
            dF = np.zeros((2, 2, 1))
            dF[k, L] = h
            fd = (law.piola(F + dF) - law.piola(F - dF))[..., 0] / (2 * h)
            np.testing.assert_allclose(A[:, :, k, L], fd, rtol=1e-6, atol=1e-9)


def test_strip_with_a_hole_feeds_the_sheet_model(demo, ds, tmp_path):
    entries = demo.hermite_law_entries(ds)
    e = float(ds["strain"].values[-1])
    dR0, _ = demo.sensor_patch(ds, entries, e, hole=0.0)
    eps, _, _, g, _ = demo.table_sheet(ds)
    # uniform-strain limit: R ~ 1/g(eps) on the reference configuration
    assert dR0 == pytest.approx(g[0] / np.interp(e, eps, g) - 1.0, abs=1e-9)
    dR, fields = demo.sensor_patch(ds, entries, e, hole=2.0)
    assert np.isfinite(dR) and dR != pytest.approx(dR0, abs=1e-6)
    assert fields["warp_strain"].max() > 1.2 * e  # the hole concentrates the strain
    png = demo.figure(fields, tmp_path / "fields.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
