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
    strip = demo.strip_reactions(entries, strains)
    N = ds["membrane_force"].sel(mode="uniaxial", edge="x", component="x").values
    want = N - float(ds["membrane_force_at_zero_strain"].sel(mode="uniaxial", edge="x", component="x"))
    np.testing.assert_allclose(strip.reaction, want, rtol=0, atol=1e-10 * np.abs(want).max())
    assert max(strip.iterations) <= 5, strip.iterations
    # every predictor reaches the same states (the law is hyperelastic)
    for predictor in ("tangent", "none"):
        other = demo.strip_reactions(entries, strains, predictor=predictor)
        np.testing.assert_allclose(other.reaction, want, rtol=0, atol=1e-10 * np.abs(want).max())
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


def test_strip_is_held_against_every_rigid_motion(demo, ds):
    # the tangent of the strip's free dofs is nonsingular: the node at (0, 0) is held in y
    # (a corner picked by get_dofs(lambda) is empty: the rigid y translation was free)
    from skfem import BilinearForm, asm

    entries = demo.hermite_law_entries(ds)
    strip = demo.strip_reactions(entries, [float(ds["strain"].values[1])], hole=2.0, n=4)
    m, basis, u, law = strip.state

    @BilinearForm
    def jacobian(du, v, w):
        Fq = np.eye(2)[:, :, None, None] + w["u"].grad
        return np.einsum("ijkl...,kl...,ij...->...", law.tangent(Fq), du.grad, v.grad)

    K = asm(jacobian, basis, u=basis.interpolate(u)).toarray()
    x, y = m.p
    held = np.concatenate([basis.nodal_dofs[0, np.isclose(x, 0.0) | np.isclose(x, 20.0)],
                           basis.nodal_dofs[1, np.isclose(x, 0.0) & np.isclose(y, 0.0)]])
    assert held.size == 2 * np.isclose(x, 0.0).sum() + 1
    free = np.setdiff1d(np.arange(basis.N), held)
    eig = np.linalg.eigvalsh(K[np.ix_(free, free)])
    assert eig[0] > 1e-8 * eig[-1], eig[:3]


def test_strip_newton_converges_quadratically_with_the_exact_tangent(demo, ds):
    # the strip with a hole (a non-uniform field: the uniform strip is solved by its
    # predictor): the Newton corrections fall quadratically, |du_k+1| <= C |du_k|^2
    entries = demo.hermite_law_entries(ds)
    e1 = float(ds["strain"].values[1])
    path = [e1 / 2, e1]
    strip = demo.strip_reactions(entries, path, hole=2.0)
    assert max(strip.iterations) <= 5, strip.iterations
    for res, cor in zip(strip.residuals, strip.corrections):
        assert res[-1] < 1e-11 * res[0], res
        assert cor[-1] < 1e-6 * cor[0], cor
        ratios = demo.quadratic_ratios(cor)
        assert max(ratios) < 10.0, ratios  # mm-1
    # the same Newton with a 10 % wrong tangent converges linearly: the ratio blows up
    class Inexact(demo.FabricLaw):
        def tangent(self, F):
            return 1.1 * super().tangent(F)

    slow = demo.strip_reactions(entries, path[:1], hole=2.0, law=Inexact(entries))
    assert slow.iterations[0] > strip.iterations[0] + 3, (slow.iterations, strip.iterations)
    assert max(max(demo.quadratic_ratios(c)) for c in slow.corrections) > 1e3


def test_strip_with_a_hole_feeds_the_sheet_model(demo, ds, tmp_path):
    entries = demo.hermite_law_entries(ds)
    e = float(ds["strain"].values[-1])
    dR0, _ = demo.sensor_patch(ds, entries, e, hole=0.0)
    t = demo.table_sheet(ds)
    eps, g = t["strain"], t["g"][:, 0]
    # uniform-strain limit: R ~ 1/g_warp(eps) on the reference configuration
    assert dR0 == pytest.approx(g[0] / np.interp(e, eps, g) - 1.0, abs=1e-9)
    dR, fields = demo.sensor_patch(ds, entries, e, hole=2.0)
    assert max(fields["strip"].iterations) <= 5, fields["strip"].iterations
    assert np.isfinite(dR) and dR != pytest.approx(dR0, abs=1e-6)
    assert fields["warp_strain"].max() > 1.2 * e  # the hole concentrates the strain
    png = demo.figure(fields, tmp_path / "fields.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------- a four-probe table
MACRO_FABRIC = {"kind": "plain weave", "n_warp": 4, "n_weft": 4, "spacing": 2.0, "half_widths": [4.0, 4.0, 0.6],
                "fibril_mass_g": 0.0384}


def _warp_weft(e):
    """R_yw, R_yf, R_c of a synthetic four-probe table (the default run's magnitudes, the
    weft 20 % more resistive so the two fits differ)."""
    return 0.29 * (1 + 0.1 * e), 0.35 * (1 - 0.05 * e), 11.0 * (1 - 0.3 * e)


@pytest.fixture(scope="module")
def ds4():
    from rve.homogenisation.network import YarnNetwork, default_probe_terminals
    from rve.tables import build_table

    probes = default_probe_terminals(4, 4, weft_probe=True)
    net = YarnNetwork(4, 4)
    recs = []
    for m in ("uniaxial", "shear"):
        for e in (0.0, 0.125, 0.25):
            R = net.solve_pairs3(list(probes.values()), *_warp_weft(e))[0]
            recs.append({"mode": m, "strain": e,
                         "probes": {p: {"voltage": 1.0, "current": 1.0 / r} for p, r in zip(probes, R)}})
    return build_table(recs, fabric=MACRO_FABRIC, config={})


def test_sheet_network_parameters_pick_the_warp_weft_fit_else_the_two_resistor_fit(ds, ds4):
    from rve.tables.macro import sheet_network_parameters

    p4 = sheet_network_parameters(ds4)
    assert p4.attrs["network_fit"].startswith("warp/weft fit") and bool(p4["warp_weft_fit"].all())
    s = dict(mode="uniaxial", strain=0.25)
    np.testing.assert_allclose(p4["yarn_resistance"].sel(**s).values, _warp_weft(0.25)[:2], rtol=1e-8)
    assert float(p4["contact_resistance"].sel(**s)) == pytest.approx(_warp_weft(0.25)[2], rel=1e-8)
    # the sheet parameters of the table are made from the same values
    g = ds4["yarn_sheet_conductance"].sel(**s).values
    ry, rc = p4["yarn_resistance"].sel(**s).values, float(p4["contact_resistance"].sel(**s))
    np.testing.assert_allclose(g, 1 / ry + 1 / rc, rtol=1e-14)
    # a version-1 / three-probe table: the two-resistor fit for both families
    p3 = sheet_network_parameters(ds)
    assert p3.attrs["network_fit"].startswith("two-resistor fit") and not bool(p3["warp_weft_fit"].any())
    s3 = dict(mode="uniaxial", strain=float(ds["strain"].values[-1]))
    np.testing.assert_array_equal(p3["yarn_resistance"].sel(**s3).values,
                                  [float(ds["yarn_resistance"].sel(**s3))] * 2)
    # a state without the warp/weft fit falls back on its own
    ds_mixed = ds4.copy()
    ds_mixed["yarn_resistance_weft"] = ds4["yarn_resistance_weft"].where(ds4["strain"] != 0.25)
    pm = sheet_network_parameters(ds_mixed)
    assert pm.attrs["network_fit"].startswith("mixed") and not bool(pm["warp_weft_fit"].sel(**s))
    assert float(pm["contact_resistance"].sel(**s)) == float(ds4["contact_resistance"].sel(**s))


def test_network_with_warp_and_weft_resistors_against_the_rve_network(demo):
    from rve.homogenisation.network import YarnNetwork

    net = YarnNetwork(4, 4)
    for plus, minus in (([1], [1]), ([0, 1, 2, 3], [0, 1, 2, 3]), ([0], [3])):
        R = demo.network_resistance(4, 4, (0.7, 1.9), 3.0, plus, minus)
        if len(plus) == 1:
            want = net.solve_pairs3([(("warp", plus[0], "-"), ("warp", minus[0], "+"))], 0.7, 1.9, 3.0)[0][0]
            assert R == pytest.approx(want, rel=1e-12)
    # the weft resistors carry current: a different R_yf changes a two-yarn resistance
    assert demo.network_resistance(4, 4, (0.7, 1.9), 3.0, [0], [3]) != pytest.approx(
        demo.network_resistance(4, 4, (0.7, 0.7), 3.0, [0], [3]), rel=1e-6)


def test_four_probe_table_busbar_pads_and_probes(demo, ds4):
    assert demo.table_sheet(ds4)["network_fit"].startswith("warp/weft fit")
    out = demo.check_busbar(ds4)
    assert out["reference"] < 1e-10 and out["deformed"] < 1e-10, out
    pads = demo.check_pads(ds4)
    assert abs(pads["two_potential"]) < 0.05 and abs(pads["one_potential"]) > 0.20, pads
    assert demo.check_probes(ds4) < 1e-9
    # the mismatch the shared choice removes: the sheet of the warp/weft fit against the
    # network of the two-resistor fit is off by far more than round-off
    a = float(ds4["yarn_pitch"])
    t = demo.table_sheet(ds4)
    m = demo.patch_mesh(4, 4, a, 1)
    ep, em = demo.electrodes(m, 4, a, 0.0, 4 * a)
    s = ds4.sel(mode="uniaxial", strain=0.25)
    Rn2 = demo.network_resistance(4, 4, float(s["yarn_resistance"]), float(s["contact_resistance"]), range(4), range(4))
    Rs = demo.sheet_resistance(m, t["g"][-1, 0], t["g"][-1, 1], t["c"][-1], ep, em)
    assert abs(Rs / Rn2 - 1.0) > 1e-4  # 7e-4 here, 7.6e-3 on the default run's four-probe table
