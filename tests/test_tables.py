"""RVE lookup tables (rve.tables): built from records of a known analytic model.

The model: per mode, yarn and contact resistances linear in strain, probe resistances from
the forward network model, temperature rises linear in strain (and in the fibril radius
when swept), reaction forces quadratic in strain, contact counts linear.
"""
import json
import math
from datetime import datetime
from importlib.metadata import version

import numpy as np
import pytest
import xarray as xr

from rve import cli
from rve import tables
from rve.tables import (
    YarnNetwork,
    build_table,
    default_probe_terminals,
    export_table,
    fit_network,
    interpolate,
    open_table,
    read_table_csv,
    summarize,
    write_table,
)

STRAINS = [0.025 * k for k in range(11)]  # 0 .. 0.25 in 10 steps (0.075000...01 on purpose)
SIDES = ("warp-", "warp+", "weft-", "weft+")
VOLTAGE = {"probe1": 1.0, "probe2": 1.0, "probe3": 2.0}
NET = YarnNetwork(4, 4)
CONFIG = {"scene": "plain_weave_rve", "steps": 10, "max_strain": 0.25,
          "fibril": {"radius": 0.15}, "probes": {"voltage": 1.0}}


def R_y(mode, e):
    return 0.4 * (1.0 + (0.8 if mode == "uniaxial" else 0.3) * e)


def R_c(mode, e):
    return 1.5 * (1.0 - (1.2 if mode == "uniaxial" else 2.0) * e)


def temp_max(mode, e, r=0.15):
    return 0.3 + (2.0 if mode == "uniaxial" else 1.0) * e + 4.0 * r


def temp_mean(mode, e, r=0.15):
    return 0.1 + 0.5 * e + 1.0 * r


def reaction(mode, side, e):
    """(3,) N: quadratic in strain, different per side and mode."""
    s = SIDES.index(side) + 1
    m = 1.0 if mode == "uniaxial" else -0.5
    return np.array([2.0 + 10.0 * m * s * e * e, 0.1 * s - 3.0 * e * e, 0.0])


def contacts(e):
    return 400 + round(40 * e / 0.025)


def record(mode, e, params=None, probes=None):
    R = NET.probe_resistances(R_y(mode, e), R_c(mode, e))
    r = (params or {}).get("fibril_radius", 0.15)
    probe_data = {}
    for p in probes or R:
        I = VOLTAGE[p] / R[p]
        probe_data[p] = {"voltage": VOLTAGE[p], "current": {"+": I, "-": -I},
                         "temperature_max": temp_max(mode, e, r),
                         "temperature_mean": temp_mean(mode, e, r)}
    rec = {"mode": mode, "strain": e,
           "reaction_force": {s: list(reaction(mode, s, e)) for s in SIDES},
           "contact_count": contacts(e), "probes": probe_data}
    if params is not None:
        rec["params"] = dict(params)
    return rec


@pytest.fixture(scope="module")
def records():
    return [record(m, e) for m in ("uniaxial", "shear") for e in STRAINS]


@pytest.fixture(scope="module")
def table(records):
    return build_table(records, fabric={"kind": "plain weave", "n_warp": 4, "n_weft": 4},
                       config=CONFIG)


@pytest.fixture(scope="module")
def table_file(table, tmp_path_factory):
    path = tmp_path_factory.mktemp("table") / "rve_table.nc"
    write_table(table, path)
    return path


@pytest.fixture(scope="module")
def swept_table():
    recs = [record("uniaxial", e, {"fibril_radius": r, "weave": w})
            for e in (0.0, 0.125, 0.25) for r in (0.1, 0.2) for w in ("plain", "basket")]
    return build_table(recs, fabric="plain weave", config=CONFIG)


# --------------------------------------------------------------------------- build
def test_build_dims_and_values(table):
    assert dict(table.sizes) == {"mode": 2, "strain": 11, "probe": 3, "side": 4,
                                 "component": 3, "terminal": 2, "edge": 2, "yarn": 2}
    assert list(table["mode"].values) == ["uniaxial", "shear"]
    np.testing.assert_array_equal(table["strain"].values, np.round(STRAINS, 12))
    assert list(table["terminal"].values) == ["+", "-"]
    assert list(table["side"].values) == list(SIDES)
    for mode in ("uniaxial", "shear"):
        for e in STRAINS:
            st = table.sel(mode=mode, strain=round(e, 12))
            R = NET.probe_resistances(R_y(mode, e), R_c(mode, e))
            for p in R:
                np.testing.assert_allclose(st["probe_resistance"].sel(probe=p), R[p], rtol=1e-14)
                I = st["probe_current"].sel(probe=p).values
                np.testing.assert_allclose(I, [VOLTAGE[p] / R[p], -VOLTAGE[p] / R[p]], rtol=1e-15)
                assert float(st["probe_voltage"].sel(probe=p)) == VOLTAGE[p]
                assert float(st["temperature_rise_max"].sel(probe=p)) == temp_max(mode, e)
            for s in SIDES:
                np.testing.assert_array_equal(st["reaction_force"].sel(side=s).values,
                                              reaction(mode, s, e))
            assert float(st["contact_count"]) == contacts(e)


def test_probe_resistance_is_voltage_over_mean_current():
    rec = record("uniaxial", 0.0)
    # unequal terminal currents (a not fully converged solve): R = V / ((I+ - I-) / 2)
    rec["probes"]["probe1"]["current"] = {"+": 0.50, "-": -0.30}
    rec["probes"]["probe2"]["current"] = 0.25  # scalar: I+ = 0.25, I- = -0.25
    ds = build_table([rec], fabric=None, config={})
    ds = ds.squeeze()
    assert float(ds["probe_resistance"].sel(probe="probe1")) == pytest.approx(1.0 / 0.40, rel=1e-15)
    assert float(ds["probe_resistance"].sel(probe="probe2")) == pytest.approx(4.0, rel=1e-15)
    np.testing.assert_array_equal(ds["probe_current"].sel(probe="probe2").values.ravel(), [0.25, -0.25])
    assert ds["probe_resistance"].attrs["units"] == "ohm"


def test_missing_values_are_nan():
    recs = [record("uniaxial", 0.0), record("uniaxial", 0.1), record("shear", 0.0)]
    del recs[1]["contact_count"]
    ds = build_table(recs, fabric=None, config={})
    assert list(ds["strain"].values) == [0.0, 0.1]
    assert np.isnan(float(ds["contact_count"].sel(mode="uniaxial", strain=0.1)))
    assert np.isnan(ds["probe_resistance"].sel(mode="shear", strain=0.1).values).all()
    assert float(ds["contact_count"].sel(mode="shear", strain=0.0)) == contacts(0.0)


@pytest.mark.parametrize("change, message", [
    (lambda r: r.update(mode="biaxial"), "mode must be one of"),
    (lambda r: r["probes"]["probe1"].update(current={"+": 0.5, "-": 0.5}), "same sign"),
    (lambda r: r["reaction_force"].update({"warp-": [1.0, 2.0]}), "3 components"),
    (lambda r: r.pop("strain"), "strain"),
])
def test_bad_records_raise(change, message):
    rec = record("uniaxial", 0.05)
    change(rec)
    with pytest.raises(ValueError, match=message):
        build_table([rec], fabric=None, config={})


def test_duplicate_state_raises():
    # 0.1 + 0.2 and 0.3 are the same strain level
    with pytest.raises(ValueError, match="given twice"):
        build_table([record("shear", 0.1 + 0.2), record("shear", 0.3)], fabric=None, config={})


# --------------------------------------------------------------------------- netCDF and metadata
def test_write_open_round_trip(table, table_file):
    opened = open_table(table_file)
    xr.testing.assert_identical(opened, table)
    assert opened["probe_resistance"].encoding.get("zlib") is True
    # atomic write: nothing but the table is left in the directory
    assert sorted(p.name for p in table_file.parent.iterdir()) == [table_file.name]


def test_open_table_rejects_other_files(tmp_path):
    path = tmp_path / "other.nc"
    xr.Dataset({"a": ("x", [1.0, 2.0])}).to_netcdf(path)
    with pytest.raises(ValueError, match="not an rve lookup table"):
        open_table(path)
    with pytest.raises(FileNotFoundError):
        open_table(tmp_path / "missing.nc")


def test_every_variable_and_coordinate_has_units_and_long_name(table_file):
    ds = open_table(table_file)
    for name, var in ds.variables.items():
        assert var.attrs.get("units"), name
        assert var.attrs.get("long_name"), name
    assert ds["strain"].attrs["units"] == "1"
    assert "engineering strain" in ds["strain"].attrs["long_name"]
    expected = {"reaction_force": "N", "probe_current": "A", "probe_voltage": "V",
                "probe_resistance": "ohm", "temperature_rise_max": "K",
                "temperature_rise_mean": "K", "contact_count": "1",
                "yarn_resistance": "ohm", "contact_resistance": "ohm"}
    for name, units in expected.items():
        assert ds[name].attrs["units"] == units, name


def test_provenance_attributes(table_file):
    ds = open_table(table_file)
    assert ds.attrs["Conventions"] == "CF-1.11"
    assert ds.attrs["title"]
    assert ds.attrs["source"]
    assert json.loads(ds.attrs["config"]) == CONFIG
    assert json.loads(ds.attrs["fabric"])["n_warp"] == 4
    assert ds.attrs["rve_version"] == version("rve")
    created = datetime.fromisoformat(ds.attrs["date_created"])
    assert created.tzinfo is not None


def test_fabric_object_sizes_the_network():
    from rve.fabrics import plain_weave

    fab = plain_weave(n_warp=6, n_weft=4)
    net = YarnNetwork(6, 4)
    probes = default_probe_terminals(6, 4)
    R = net.probe_resistances(0.3, 0.7, probes)
    rec = {"mode": "uniaxial", "strain": 0.0,
           "probes": {p: {"voltage": 1.0, "current": 1.0 / r} for p, r in R.items()}}
    ds = build_table([rec], fabric=fab, config={}).squeeze()
    assert json.loads(ds.attrs["fabric"])["kind"] == "plain weave"
    assert "n_warp=6, n_weft=4" in ds.attrs["network_model"]
    np.testing.assert_allclose(float(ds["yarn_resistance"]), 0.3, rtol=1e-9)
    np.testing.assert_allclose(float(ds["contact_resistance"]), 0.7, rtol=1e-9)


# --------------------------------------------------------------------------- interpolation
STATE_VARS = ("reaction_force", "probe_resistance", "probe_current", "temperature_rise_max",
              "temperature_rise_mean", "contact_count", "yarn_resistance", "contact_resistance")


@pytest.mark.parametrize("method", ["linear", "cubic"])
def test_interpolate_at_stored_strains_is_exact(table, method):
    for mode in ("uniaxial", "shear"):
        out = interpolate(table, list(table["strain"].values), mode=mode, method=method)
        for name in STATE_VARS:
            np.testing.assert_array_equal(out[name].values, table[name].sel(mode=mode).values,
                                          err_msg=f"{name} {mode} {method}")
        one = interpolate(table, 0.25, mode=mode, method=method)  # last point, scalar query
        assert one["strain"].ndim == 0
        np.testing.assert_array_equal(one["reaction_force"].values,
                                      table["reaction_force"].sel(mode=mode, strain=0.25).values)


def test_interpolate_linear_between_strains(table):
    mids = [0.5 * (a + b) for a, b in zip(STRAINS[:-1], STRAINS[1:])] + [0.0101, 0.2499]
    for mode in ("uniaxial", "shear"):
        out = interpolate(table, mids, mode=mode, method="linear")
        # temperature rises are linear in strain: reproduced to rounding
        np.testing.assert_allclose(out["temperature_rise_max"].sel(probe="probe2").values,
                                   [temp_max(mode, e) for e in mids], rtol=1e-13)
        np.testing.assert_allclose(out["temperature_rise_mean"].sel(probe="probe3").values,
                                   [temp_mean(mode, e) for e in mids], rtol=1e-13)
        # reactions are quadratic: at midpoints the chord, q h^2 / 4 away from the model
        for k, e in enumerate(mids[:10]):
            for s in SIDES:
                chord = 0.5 * (reaction(mode, s, STRAINS[k]) + reaction(mode, s, STRAINS[k + 1]))
                got = out["reaction_force"].sel(side=s).isel(strain=k).values
                np.testing.assert_allclose(got, chord, rtol=1e-13, atol=1e-15)
                q = reaction(mode, s, 1.0) - reaction(mode, s, 0.0)  # coefficient of e^2
                np.testing.assert_allclose(got - reaction(mode, s, e), q * 0.025 ** 2 / 4,
                                           rtol=1e-6, atol=1e-14)


def test_interpolate_cubic_reproduces_linear_data_and_stays_monotone(table):
    e = np.linspace(0.0, 0.25, 37)
    out = interpolate(table, e, mode="uniaxial", method="cubic")
    np.testing.assert_allclose(out["temperature_rise_max"].sel(probe="probe1").values,
                               temp_max("uniaxial", e), rtol=1e-13)
    fx = out["reaction_force"].sel(side="weft+", component="x").values
    assert np.all(np.diff(fx) >= 0)  # PCHIP keeps the monotone data monotone
    exact = np.array([reaction("uniaxial", "weft+", x)[0] for x in e])
    linear_error = 10 * 4 * 0.025 ** 2 / 4  # q h^2 / 4 of the chord at a midpoint
    assert 0 < np.max(np.abs(fx - exact)) < 0.5 * linear_error


def test_interpolate_all_modes(table):
    out = interpolate(table, [0.05, 0.0625])
    assert list(out["mode"].values) == ["uniaxial", "shear"]
    assert out["probe_resistance"].dims[:2] == ("mode", "strain")
    np.testing.assert_allclose(out["temperature_rise_max"].sel(mode="shear", probe="probe1"),
                               [temp_max("shear", 0.05), temp_max("shear", 0.0625)], rtol=1e-13)


@pytest.mark.parametrize("strain", [0.2500001, -0.01, [0.1, 0.3]])
def test_interpolate_out_of_range_raises(table, strain):
    with pytest.raises(ValueError, match=r"outside the table range \[0, 0\.25\]"):
        interpolate(table, strain, mode="uniaxial")


def test_interpolate_bad_arguments(table):
    with pytest.raises(ValueError, match="mode 'biaxial'"):
        interpolate(table, 0.1, mode="biaxial")
    with pytest.raises(ValueError, match="method"):
        interpolate(table, 0.1, mode="shear", method="spline")
    with pytest.raises(ValueError, match="not a swept parameter"):
        interpolate(table, 0.1, mode="shear", fibril_radius=0.1)


def test_interpolate_uses_only_a_modes_own_states():
    recs = [record("uniaxial", e) for e in (0.0, 0.1, 0.2)] + [record("shear", e) for e in (0.0, 0.1)]
    ds = build_table(recs, fabric=None, config={})
    assert float(interpolate(ds, 0.15, mode="uniaxial")["contact_count"]) == pytest.approx(
        0.5 * (contacts(0.1) + contacts(0.2)))
    with pytest.raises(ValueError, match=r"\[0, 0\.1\] of mode 'shear'"):
        interpolate(ds, 0.15, mode="shear")


# --------------------------------------------------------------------------- network model
def test_network_single_cell_analytic():
    net = YarnNetwork(1, 1)
    # warp end to end: R_y in parallel with R_c/2 + R_c/2 (the weft midpoint carries nothing)
    R = net.resistance(("warp", 0, "+"), ("warp", 0, "-"), 2.0, 3.0)
    assert R == pytest.approx(2.0 * 3.0 / 5.0, rel=1e-13)
    assert len(net.edges[0]) == 2 and len(net.edges[1]) == 4


def test_network_counts_and_limits():
    net = YarnNetwork(4, 4)
    assert len(net.edges[0]) == 16 * 2 and len(net.edges[1]) == 16 * 4
    # insulating contacts: probe 1 is the bare yarn, 4 cells long; probes 2, 3 ~ R_c
    R = net.probe_resistances(1.0, 1e9)
    assert R["probe1"] == pytest.approx(4.0, rel=1e-6)
    assert R["probe2"] > 1e7 and R["probe3"] > 1e7
    # homogeneous of degree one
    a = net.probe_resistances(0.3, 0.9)
    b = net.probe_resistances(3.0, 9.0)
    for p in a:
        assert b[p] == pytest.approx(10.0 * a[p], rel=1e-12)


def test_network_power_fractions_are_log_derivatives():
    net = YarnNetwork(4, 4)
    pairs = list(default_probe_terminals().values())
    ry, rc, h = 0.4, 1.3, 1e-6
    R, py, pc = net.solve_pairs(pairs, ry, rc)
    np.testing.assert_allclose(py + pc, 1.0, rtol=1e-12)
    dy = (np.log(net.solve_pairs(pairs, ry * math.exp(h), rc)[0])
          - np.log(net.solve_pairs(pairs, ry * math.exp(-h), rc)[0])) / (2 * h)
    dc = (np.log(net.solve_pairs(pairs, ry, rc * math.exp(h))[0])
          - np.log(net.solve_pairs(pairs, ry, rc * math.exp(-h))[0])) / (2 * h)
    np.testing.assert_allclose(py, dy, rtol=1e-7)
    np.testing.assert_allclose(pc, dc, rtol=1e-7)


def test_table_recovers_yarn_and_contact_resistance(table):
    for mode in ("uniaxial", "shear"):
        ry = np.array([R_y(mode, e) for e in STRAINS])
        rc = np.array([R_c(mode, e) for e in STRAINS])
        np.testing.assert_allclose(table["yarn_resistance"].sel(mode=mode), ry, rtol=1e-9)
        np.testing.assert_allclose(table["contact_resistance"].sel(mode=mode), rc, rtol=1e-9)
        assert float(table["network_fit_residual"].sel(mode=mode).max()) < 1e-10


@pytest.mark.parametrize("ry, rc", [(0.3, 0.05), (1.0, 7.0), (2e-3, 5.0)])
@pytest.mark.parametrize("use", [("probe1", "probe2"), ("probe1", "probe3")])
def test_fit_network_from_two_probes(ry, rc, use):
    # probe 1 and one other: R_probe / R_probe1 is monotone in R_c / R_y (probes 2 and 3
    # alone are not: their ratio has a minimum, docs/lookup_tables.md)
    R = NET.probe_resistances(ry, rc)
    got_y, got_c, res = fit_network({p: R[p] for p in use}, NET)
    assert got_y == pytest.approx(ry, rel=1e-8)
    assert got_c == pytest.approx(rc, rel=1e-8)
    assert res < 1e-10


def test_fit_network_reports_inconsistent_probes():
    R = NET.probe_resistances(0.5, 2.0)
    R["probe3"] *= 1.5  # not a network of this kind
    _, _, res = fit_network(R, NET)
    assert res > 0.05
    assert all(math.isnan(v) for v in fit_network({"probe1": 1.0}, NET))


def test_network_needs_two_probes():
    recs = [record("uniaxial", e, probes=["probe1"]) for e in (0.0, 0.1)]
    ds = build_table(recs, fabric=None, config={})
    assert np.isnan(ds["yarn_resistance"].values).all()
    assert np.isfinite(ds["probe_resistance"].values).all()


# --------------------------------------------------------------------------- swept parameters
def test_swept_parameter_dims(swept_table):
    ds = swept_table
    assert ds.sizes["fibril_radius"] == 2 and ds.sizes["weave"] == 2
    assert ds["probe_resistance"].dims == ("mode", "strain", "fibril_radius", "weave", "probe")
    assert ds["fibril_radius"].attrs["units"] == "mm"
    assert list(ds["weave"].values) == ["basket", "plain"]
    assert ds.attrs["swept_parameters"] == "fibril_radius weave"
    ds = ds.sel(mode="uniaxial")
    np.testing.assert_allclose(
        ds["temperature_rise_max"].sel(fibril_radius=0.2, weave="plain", strain=0.125, probe="probe1"),
        temp_max("uniaxial", 0.125, 0.2))
    np.testing.assert_allclose(ds["yarn_resistance"].sel(weave="basket", fibril_radius=0.1),
                               [R_y("uniaxial", e) for e in (0.0, 0.125, 0.25)], rtol=1e-9)


def test_swept_table_round_trip_and_interpolation(swept_table, tmp_path):
    write_table(swept_table, tmp_path / "swept.nc")
    ds = open_table(tmp_path / "swept.nc")
    xr.testing.assert_identical(ds, swept_table)
    out = interpolate(ds, 0.0625, mode="uniaxial", fibril_radius=0.15, weave="plain")
    assert float(out["fibril_radius"]) == 0.15 and str(out["weave"].values) == "plain"
    np.testing.assert_allclose(out["temperature_rise_max"].sel(probe="probe2"),
                               temp_max("uniaxial", 0.0625, 0.15), rtol=1e-13)
    stored = interpolate(ds, 0.125, mode="uniaxial", fibril_radius=0.2)
    np.testing.assert_array_equal(stored["probe_resistance"].values,
                                  ds["probe_resistance"].sel(mode="uniaxial", strain=0.125,
                                                             fibril_radius=0.2).values)
    with pytest.raises(ValueError, match=r"fibril_radius 0.3 is outside the table range \[0.1, 0.2\]"):
        interpolate(ds, 0.1, mode="uniaxial", fibril_radius=0.3)
    with pytest.raises(ValueError, match="weave 'twill'"):
        interpolate(ds, 0.1, mode="uniaxial", weave="twill")


def test_swept_metadata_and_missing_parameter():
    recs = [record("shear", 0.0, {"contact_conductance": 1.0}),
            record("shear", 0.0, {"contact_conductance": 2.0})]
    ds = build_table(recs, fabric=None, config={},
                     swept={"contact_conductance": {"units": "A mm-2 V-1", "long_name": "sigma_C"}})
    assert ds["contact_conductance"].attrs == {"units": "A mm-2 V-1", "long_name": "sigma_C"}
    recs.append(record("shear", 0.1))
    with pytest.raises(ValueError, match="missing swept parameter 'contact_conductance'"):
        build_table(recs, fabric=None, config={})


# --------------------------------------------------------------------------- export, summary, plots
def test_export_csv_round_trip(table, tmp_path):
    (path,) = export_table(table, tmp_path / "t.csv", "csv")
    text = path.read_text()
    header = next(line for line in text.splitlines() if not line.startswith("#"))
    assert header == "variable,units,mode,strain [1],probe,side,component,terminal,edge,yarn,value"
    assert "# variable probe_resistance [ohm] dims (mode, strain, probe)" in text
    back = read_table_csv(path)
    kept = [n for n, v in table.data_vars.items() if "strain" in v.dims or v.ndim == 0]
    assert set(back.data_vars) == set(kept)
    for name in kept:
        ref = table[name]
        got = back[name].transpose(*ref.dims)
        for d in ref.dims:
            np.testing.assert_array_equal(got[d].values, ref[d].values)
        np.testing.assert_array_equal(got.values, ref.values, err_msg=name)
        assert got.attrs["units"] == ref.attrs["units"]
        assert got.attrs["long_name"] == ref.attrs["long_name"]
    assert back.attrs["Conventions"] == "CF-1.11"


def test_export_csv_is_tidy(table, tmp_path):
    import pandas as pd

    (path,) = export_table(table, tmp_path / "t.csv", "csv")
    df = pd.read_csv(path, comment="#", keep_default_na=False)
    assert len(df) == sum(v.size for v in table.data_vars.values() if "strain" in v.dims)
    row = df[(df.variable == "reaction_force") & (df["mode"] == "shear") & (df.side == "weft-")
             & (df.component == "x") & (df["strain [1]"] == 0.2)]
    assert len(row) == 1 and row.units.iloc[0] == "N"
    assert float(row.value.iloc[0]) == reaction("shear", "weft-", 0.2)[0]


def test_export_json_and_dat(table, tmp_path):
    (jpath,) = export_table(table, tmp_path / "t.json", "json")
    data = json.loads(jpath.read_text())
    assert data["format"] == tables.TABLE_FORMAT
    assert data["data_vars"]["probe_resistance"]["attrs"]["units"] == "ohm"
    back = xr.Dataset.from_dict(data)
    np.testing.assert_array_equal(back["probe_resistance"].values, table["probe_resistance"].values)

    paths = export_table(table, tmp_path / "fe" / "t.dat", "dat")
    assert [p.name for p in paths] == ["t.uniaxial.dat", "t.shear.dat"]
    lines = paths[1].read_text().splitlines()
    names = next(line for line in lines if line.startswith("# strain ")).split()[1:]
    assert any("probe_resistance[probe2]" in line and "[ohm]" in line for line in lines)
    arr = np.loadtxt(paths[1])
    assert arr.shape == (11, len(names))
    np.testing.assert_allclose(arr[:, names.index("strain")], table["strain"].values, rtol=1e-12)
    np.testing.assert_allclose(arr[:, names.index("probe_resistance[probe2]")],
                               table["probe_resistance"].sel(mode="shear", probe="probe2"), rtol=1e-12)
    np.testing.assert_allclose(arr[:, names.index("reaction_force[weft+,y]")],
                               table["reaction_force"].sel(mode="shear", side="weft+", component="y"),
                               rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="unknown export format"):
        export_table(table, tmp_path / "t.xlsx", "xlsx")


def test_export_dat_with_swept_parameters(swept_table, tmp_path):
    paths = export_table(swept_table, tmp_path / "s.txt", "dat")
    assert sorted(p.name for p in paths) == ["s.uniaxial.weave-basket.txt", "s.uniaxial.weave-plain.txt"]
    arr = np.loadtxt(paths[0])
    assert arr.shape[0] == 2 * 3  # fibril_radius x strain, strain fastest
    np.testing.assert_array_equal(arr[:, 0], [0.1, 0.1, 0.1, 0.2, 0.2, 0.2])
    np.testing.assert_array_equal(arr[:, 1], [0.0, 0.125, 0.25] * 2)


def test_summarize(table):
    text = summarize(table)
    assert "mode=2" in text and "strain=11" in text
    assert "mode uniaxial: strain 0 .. 0.25 (11 levels)" in text
    for p in ("probe1", "probe2", "probe3"):
        assert p in text
    r1 = table["probe_resistance"].sel(mode="uniaxial", probe="probe1").values
    assert f"{r1.min():.6g} .. {r1.max():.6g}" in text
    assert "reaction force [N] at strain 0" in text
    assert "R_y" in text and "R_c" in text


def test_plot_table(swept_table, tmp_path):
    # the small swept table (one mode) keeps the figures cheap; swept values: the first
    paths = tables.plot_table(swept_table, tmp_path / "plots" / "rve")
    assert [p.name for p in paths] == ["rve_reaction_force.png", "rve_probe_resistance.png",
                                       "rve_temperature_rise.png", "rve_by_parameter.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(x.name for x in (tmp_path / "plots").iterdir()) == sorted(p.name for p in paths)


# --------------------------------------------------------------------------- CLI
def test_cli_table_summary(table_file, capsys):
    assert cli.main(["table", "summary", str(table_file)]) == 0
    out = capsys.readouterr().out
    assert "strain=11" in out and "probe3" in out


def test_cli_table_interpolate(table_file, table, capsys):
    assert cli.main(["table", "interpolate", str(table_file), "--mode", "uniaxial",
                     "--strain", "0.125", "--strain", "0.1"]) == 0
    out = capsys.readouterr().out
    assert "# mode=uniaxial strain=0.125 method=linear" in out
    line = next(x for x in out.splitlines() if x.startswith("temperature_rise_max[probe1] ="))
    assert float(line.split()[2]) == pytest.approx(temp_max("uniaxial", 0.125), rel=1e-9)
    assert line.endswith(" K")
    r = float(table["probe_resistance"].sel(mode="uniaxial", strain=0.1, probe="probe3"))
    block = out.split("strain=0.1 ")[1]
    line = next(x for x in block.splitlines() if x.startswith("probe_resistance[probe3] ="))
    assert float(line.split()[2]) == pytest.approx(r, rel=1e-9)

    assert cli.main(["table", "interpolate", str(table_file), "--mode", "shear", "--strain", "0.05",
                     "--var", "contact_count", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["data_vars"]["contact_count"]["data"] == contacts(0.05)


def test_cli_table_interpolate_out_of_range(table_file, capsys):
    assert cli.main(["table", "interpolate", str(table_file), "--mode", "uniaxial",
                     "--strain", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "outside the table range [0, 0.25]" in err and "Traceback" not in err


def test_cli_table_export(table_file, table, tmp_path, capsys):
    out = tmp_path / "exp" / "table.csv"
    assert cli.main(["table", "export", str(table_file), "--format", "csv", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().err
    np.testing.assert_array_equal(read_table_csv(out)["reaction_force"].values,
                                  table["reaction_force"].values)
    assert cli.main(["table", "summary", str(tmp_path / "nope.nc")]) == 2


def test_cubic_interpolation_falls_back_to_linear_on_series_with_nan_or_inf():
    """A series that is not recorded (NaN) or an open circuit (inf resistance) cannot be
    PCHIP-interpolated: such series go linearly, the finite ones still by PCHIP; stored
    strains return stored values."""
    recs = []
    for e in STRAINS:
        r = record("uniaxial", e)
        r["equilibrium_residual"] = 1e-10 * (1 + e)
        if e < 0.1:  # probe3 open-circuited at the first strains (as the knit's outer probe)
            r["probes"]["probe3"]["current"] = {"+": 0.0, "-": 0.0}
        recs.append(r)
    t = build_table(recs, fabric={"kind": "plain weave", "n_warp": 4, "n_weft": 4}, config=CONFIG)
    assert np.isinf(t["probe_resistance"].sel(mode="uniaxial", probe="probe3", strain=0.05))
    e = np.linspace(0.0, 0.25, 21)
    out = interpolate(t, e, mode="uniaxial", method="cubic")
    np.testing.assert_allclose(out["temperature_rise_max"].sel(probe="probe1").values,
                               temp_max("uniaxial", e), rtol=1e-13)  # finite: PCHIP, exact on linear data
    np.testing.assert_allclose(out["equilibrium_residual"].values, 1e-10 * (1 + e), rtol=1e-12)
    r3 = out["probe_resistance"].sel(probe="probe3").values
    assert np.isfinite(r3[e > 0.1 + 1e-9]).all()
    s = t["strain"].values
    at = interpolate(t, s, mode="uniaxial", method="cubic")
    np.testing.assert_array_equal(at["probe_resistance"].values,
                                  t["probe_resistance"].sel(mode="uniaxial").values)


# --------------------------------------------------------------------------- macro quantities (docs/macro_export.md §1)
from pathlib import Path  # noqa: E402

DATA = Path(__file__).parent / "data"
MACRO_FABRIC = {"kind": "plain weave", "n_warp": 4, "n_weft": 4, "spacing": 2.0, "half_widths": [4.0, 4.0, 0.6],
                "fibril_mass_g": 0.0384}


@pytest.fixture(scope="module")
def macro_table(records):
    extra = [record("trellis", e) for e in STRAINS[:3]] + [record("uniaxial_y", e) for e in STRAINS[:3]]
    return build_table(records + extra, fabric=MACRO_FABRIC, config=CONFIG)


def test_macro_geometry_and_membrane_force(macro_table):
    t = macro_table
    assert float(t["cell_length_x"]) == 8.0 and float(t["cell_length_y"]) == 8.0 and float(t["yarn_pitch"]) == 2.0
    assert t["membrane_force"].attrs["units"] == "N mm-1"
    for mode in ("uniaxial", "shear"):
        for e in (0.0, 0.1, 0.25):
            N = t["membrane_force"].sel(mode=mode, strain=round(e, 12))
            Fx, Fy = reaction(mode, "warp+", e), reaction(mode, "weft+", e)
            np.testing.assert_array_equal(N.sel(edge="x").values, Fx / 8.0)  # edge x: length L_y = 8
            np.testing.assert_array_equal(N.sel(edge="y").values, Fy / 8.0)
            imb = t["side_force_imbalance"].sel(mode=mode, strain=round(e, 12))
            assert float(imb.sel(edge="x")) == pytest.approx(
                np.linalg.norm(reaction(mode, "warp-", e) + reaction(mode, "warp+", e)), rel=1e-15)
    np.testing.assert_array_equal(t["membrane_force_at_zero_strain"].sel(mode="shear").values,
                                  t["membrane_force"].sel(mode="shear", strain=0.0).values)


def test_macro_strain_measures_by_hand(macro_table):
    t = macro_table
    ys, th = t["yarn_strain"], t["shear_angle"]
    assert th.attrs["units"] == "rad"
    # simple shear gamma = 0.25: warp stretched by sqrt(1 + 1/16) - 1 = 3.078 %, angle drop atan(0.25)
    assert float(ys.sel(mode="shear", strain=0.25, yarn="warp")) == pytest.approx(0.030776406404415, rel=1e-12)
    assert float(ys.sel(mode="shear", strain=0.25, yarn="weft")) == 0.0
    assert float(th.sel(mode="shear", strain=0.25)) == pytest.approx(0.244978663126864, rel=1e-13)
    assert float(ys.sel(mode="uniaxial", strain=0.1, yarn="warp")) == pytest.approx(0.1, rel=1e-14)
    assert float(ys.sel(mode="uniaxial_y", strain=0.05, yarn="weft")) == pytest.approx(0.05, rel=1e-14)
    assert float(ys.sel(mode="uniaxial_y", strain=0.05, yarn="warp")) == 0.0
    assert float(th.sel(mode="trellis", strain=0.05)) == 0.05
    assert float(ys.sel(mode="trellis", strain=0.05, yarn="warp")) == 0.0
    # trellis states exist only up to 0.05: no strain measure where no state is stored
    assert np.isnan(float(th.sel(mode="trellis", strain=0.25)))
    # the picture-frame F keeps both yarn lengths and drops the angle by the strain
    from rve.tables.macro import mode_deformation, yarn_strain_and_angle
    F = mode_deformation("trellis", 0.3)
    np.testing.assert_allclose(np.linalg.norm(F, axis=0), 1.0, rtol=0, atol=1e-15)
    assert math.acos(F[:, 0] @ F[:, 1]) == pytest.approx(math.pi / 2 - 0.3, rel=1e-14)
    s, a = yarn_strain_and_angle("shear", np.array([0.0, 0.25]))
    assert a[0] == 0.0 and s[0, 0] == 0.0


def test_macro_areal_density_gauge_factor_sheet(macro_table):
    t = macro_table
    assert float(t["areal_density"]) == pytest.approx(0.0384 / 64.0, rel=1e-15)
    assert t["areal_density"].attrs["units"] == "g mm-2"
    R = t["probe_resistance"].sel(mode="uniaxial", probe="probe1")
    gf = t["gauge_factor"].sel(mode="uniaxial", probe="probe1")
    assert np.isnan(float(gf.sel(strain=0.0)))
    R0, R1 = float(R.sel(strain=0.0)), float(R.sel(strain=0.1))
    assert float(gf.sel(strain=0.1)) == pytest.approx((R1 - R0) / (R0 * 0.1), rel=1e-13)
    # sheet parameters from the fitted (= generating) R_y, R_c
    ry, rc = R_y("uniaxial", 0.1), R_c("uniaxial", 0.1)
    sel = dict(mode="uniaxial", strain=0.1)
    g = 1.0 / ry + 1.0 / rc
    c = 4.0 / (rc * 2.0 ** 2)
    for yarn in ("warp", "weft"):  # three probes: no warp/weft fit, the two-resistor fit for both
        assert float(t["yarn_sheet_conductance"].sel(**sel, yarn=yarn)) == pytest.approx(g, rel=1e-8)
        assert float(t["busbar_sheet_resistance"].sel(**sel, yarn=yarn)) == pytest.approx(1.0 / g, rel=1e-8)
        assert float(t["transfer_length"].sel(**sel, yarn=yarn)) == pytest.approx(math.sqrt(g / (2 * c)), rel=1e-8)
    assert float(t["contact_exchange_conductance"].sel(**sel)) == pytest.approx(c, rel=1e-8)
    assert np.isnan(t["yarn_resistance_warp"]).all()


def test_macro_stored_variables_unchanged_by_the_new_quantities(records):
    """The macro quantities are additions: the stored variables are those of the table built without them."""
    from rve.tables.schema import VARIABLES

    t = build_table(records, fabric=MACRO_FABRIC, config=CONFIG)
    for name in VARIABLES:
        assert name in t
    assert "axis" not in t["strain"].attrs  # CF: strain is not a space axis


def test_v1_table_still_opens_with_macro_quantities():
    ds = open_table(DATA / "table_v1_ci.nc")
    assert ds.attrs["rve_table_format"] == "rve-lookup-table/1"
    assert "membrane_force" in ds and "rve_table_upgraded" in ds.attrs
    Fx = ds["reaction_force"].sel(mode="uniaxial", side="x+", component="x")
    np.testing.assert_array_equal(ds["membrane_force"].sel(mode="uniaxial", edge="x", component="x").values,
                                  Fx.values / float(ds["cell_length_y"]))
    assert float(ds["cell_length_y"]) == 4.0  # the CI cell: 2 x 2 yarns, 2 mm apart
    assert np.isnan(float(ds["areal_density"]))  # version 1 did not record the fibril mass


#: table variables fitted to the probe resistances (rve.homogenisation.network.fit_network)
NETWORK_FIT = ("yarn_resistance", "contact_resistance", "network_fit_residual", "yarn_resistance_warp",
               "yarn_resistance_weft")


def test_gather_reproduces_the_v1_table_bit_for_bit(tmp_path):
    """The stored records of the v1 fixture's CI run, gathered by the current code: every
    version-1 variable is identical (the new quantities are additions); the network-fit
    parameters to their fit's own tolerance (where an iterative fit stops depends on
    the library build)."""
    import yaml

    from rve.tables.jobs import gather_job

    spec = yaml.safe_load((Path(__file__).parents[1] / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    spec["scene"]["strain"]["modes"] = ["uniaxial", "shear"]  # the modes of the v1 run
    records = sorted((DATA / "records_v1_ci").glob("*.json"))
    out = tmp_path / "table.nc"
    gather_job(records, out, tmp_path / "t.csv", tmp_path / "s.txt", None, spec, "ci")
    new, old = open_table(out), xr.open_dataset(DATA / "table_v1_ci.nc").load()
    assert new.attrs["rve_table_format"] == "rve-lookup-table/2"
    for name in old.data_vars:
        if name in NETWORK_FIT:
            # an iterative least-squares fit (scipy least_squares, xtol = 1e-15 on log R, |log R|
            # < 10): where it stops depends on the scipy/LAPACK build, so it reproduces to its
            # own tolerance, 1e-15 x (1 + |log R|) < 1e-13 relative (9e-15 seen between
            # machines; the measured quantities are plain arithmetic and stay bit for bit); the residual (rms of log R, ~1e-7) moves by the same absolute amount
            tol = dict(rtol=0, atol=1e-13) if name == "network_fit_residual" else dict(rtol=1e-13, atol=0)
            np.testing.assert_allclose(new[name].values, old[name].values, err_msg=name, **tol)
        else:
            np.testing.assert_array_equal(new[name].values, old[name].values, err_msg=name)
    for name in old.coords:
        assert list(new[name].values) == list(old[name].values), name
    assert float(new["areal_density"]) > 0


# --------------------------------------------------------------------------- CF conventions (docs/macro_export.md §4)
def _all_units(ds):
    return {name: v.attrs["units"] for name, v in ds.variables.items() if "units" in v.attrs}


@pytest.fixture(scope="module")
def ci_table_file(tmp_path_factory):
    """The CI run's table, gathered by the current code from the stored records."""
    import yaml

    from rve.tables.jobs import gather_job

    spec = yaml.safe_load((Path(__file__).parents[1] / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    spec["scene"]["strain"]["modes"] = ["uniaxial", "shear"]
    out = tmp_path_factory.mktemp("ci") / "table.nc"
    gather_job(sorted((DATA / "records_v1_ci").glob("*.json")), out, out.with_suffix(".csv"),
               out.with_suffix(".txt"), None, spec, "ci")
    return out


def test_cf_layout_on_disk(ci_table_file, swept_table, tmp_path):
    import netCDF4

    write_table(swept_table, tmp_path / "swept.nc")
    for path in (ci_table_file, tmp_path / "swept.nc"):
        with netCDF4.Dataset(path) as f:
            assert f.Conventions == "CF-1.11"
            for name, var in f.variables.items():
                if name in f.dimensions:  # a coordinate variable: numeric, no string
                    assert var.dtype.kind in "fiu", name
                assert "axis" not in var.ncattrs() or name != "strain"
                if var.dtype != str and var.dtype.kind == "S":
                    assert var.dimensions[-1].endswith("_strlen"), name  # a char array
                if var.dtype is str:
                    pytest.fail(f"{name}: variable-length string (CF wants char arrays)")
            assert f.variables["mode_label"].dimensions == ("mode", "mode_strlen")
            assert "mode_label" in f.variables["membrane_force"].coordinates
    back = open_table(tmp_path / "swept.nc")
    assert list(back["weave"].values) == list(swept_table["weave"].values)
    assert back.sel(mode="uniaxial", weave="plain", fibril_radius=0.1)["contact_count"].size == 3


def test_every_units_string_parses_with_udunits(ci_table_file, swept_table, macro_table):
    cf_units = pytest.importorskip("cf_units", reason="cf_units (UDUNITS-2 parser; Debian libudunits2-0) "
                                                      "not installed: units strings not checked")
    seen = {}
    for ds in (open_table(ci_table_file), swept_table, macro_table):
        seen.update({f"{name}: {u}": u for name, u in _all_units(ds).items()})
    from rve.tables.schema import KNOWN_PARAMETERS
    seen.update({f"parameter {n}": u for n, (u, _) in KNOWN_PARAMETERS.items()})
    bad = []
    for where, u in seen.items():
        try:
            cf_units.Unit(u)
        except ValueError:
            bad.append(where)
    assert not bad, f"units UDUNITS cannot parse: {bad}"
    assert cf_units.Unit("N mm-1").convert(1.0, "N m-1") == pytest.approx(1000.0)
    assert cf_units.Unit("g mm-2").convert(1.0, "kg m-2") == pytest.approx(1000.0)


def test_cf_checker_reports_no_errors(ci_table_file, swept_table, tmp_path):
    """The reference CF checker (cfchecker, newest 4.1: knows CF up to 1.8) on the CI table
    and a swept table: 0 errors, 0 warnings. The copy it checks declares CF-1.8 (the
    newest it knows) instead of CF-1.11 (units_metadata); the standard-name tables are
    local stubs (the table uses no standard_name; the checker would download them)."""
    import shutil
    import subprocess

    from cf_checker import cfchecks_command

    exe, env = cfchecks_command(tmp_path)
    if exe is None:
        pytest.skip("the CF checker (pip cfchecker; needs Debian libudunits2-0 / udunits-bin) is not installed")
    import netCDF4

    write_table(swept_table, tmp_path / "swept.nc")
    cft = DATA / "cf_tables"
    for k, src in enumerate((ci_table_file, tmp_path / "swept.nc")):
        path = tmp_path / f"check{k}.nc"
        shutil.copy(src, path)
        with netCDF4.Dataset(path, "a") as f:
            assert f.Conventions == "CF-1.11"
            f.Conventions = "CF-1.8"
        run = subprocess.run([exe, "-v", "1.8", "-s", str(cft / "standard_name_table.xml"),
                              "-a", str(cft / "area_type_table.xml"), "-r", str(cft / "region_names.xml"),
                              str(path)], capture_output=True, text=True, timeout=300, env=env)
        assert "ERRORS detected: 0" in run.stdout, run.stdout[-3000:] + run.stderr[-2000:]
        assert "WARNINGS given: 0" in run.stdout, run.stdout[-3000:]
        assert run.returncode == 0


# --------------------------------------------------------------------------- the 4th probe: warp and weft yarns apart
def test_fit_network3_recovers_separate_warp_and_weft_resistances():
    from rve.homogenisation.network import fit_network3

    net = YarnNetwork(4, 4)
    probes = default_probe_terminals(4, 4, weft_probe=True)
    assert probes["probe4"] == (("weft", 1, "+"), ("weft", 1, "-"))
    for rw, rf, rc in ((0.4, 0.9, 1.5), (2.0, 0.5, 0.05), (0.3, 0.3, 30.0)):
        R = net.solve_pairs3(list(probes.values()), rw, rf, rc)[0]
        got = fit_network3(dict(zip(probes, R)), net, probes)
        np.testing.assert_allclose(got[:3], (rw, rf, rc), rtol=1e-8)
        assert got[3] < 1e-10
        # equal yarn resistances: the same network as the two-resistor model
    R2 = net.solve_pairs3(list(probes.values()), 0.7, 0.7, 1.1)[0]
    np.testing.assert_allclose(R2, net.solve_pairs(list(probes.values()), 0.7, 1.1)[0], rtol=1e-13)
    # the power fractions are the log-derivatives (finite differences) and sum to 1
    pairs = list(probes.values())
    R, pw, pf, pc = net.solve_pairs3(pairs, 0.4, 0.9, 1.5)
    np.testing.assert_allclose(pw + pf + pc, 1.0, rtol=1e-12)
    h = 1e-6
    dR = (np.log(net.solve_pairs3(pairs, 0.4, 0.9 * math.exp(h), 1.5)[0])
          - np.log(net.solve_pairs3(pairs, 0.4, 0.9 * math.exp(-h), 1.5)[0])) / (2 * h)
    np.testing.assert_allclose(dR, pf, rtol=1e-7, atol=1e-10)
    # an inconsistent 4th probe shows up in the residual; fewer than four probes: NaN
    bad = dict(zip(probes, net.solve_pairs3(pairs, 0.4, 0.9, 1.5)[0]))
    bad["probe2"] *= 1.2
    assert fit_network3(bad, net, probes)[3] > 1e-2
    assert all(np.isnan(fit_network3({k: bad[k] for k in ("probe1", "probe2", "probe3")}, net, probes)))


def test_table_with_the_weft_probe_fits_warp_and_weft():
    probes = default_probe_terminals(4, 4, weft_probe=True)
    recs = []
    for m in ("uniaxial", "shear"):
        for e in (0.0, 0.1, 0.2):
            rw, rf, rc = 0.4 * (1 + e), 0.6 * (1 + 0.2 * e), 1.5 * (1 - e)
            R = NET.solve_pairs3(list(probes.values()), rw, rf, rc)[0]
            recs.append({"mode": m, "strain": e, "probes": {p: {"voltage": 1.0, "current": 1.0 / r}
                                                            for p, r in zip(probes, R)}})
    t = build_table(recs, fabric=MACRO_FABRIC, config={})
    s = dict(mode="uniaxial", strain=0.2)
    assert float(t["yarn_resistance_warp"].sel(**s)) == pytest.approx(0.48, rel=1e-8)
    assert float(t["yarn_resistance_weft"].sel(**s)) == pytest.approx(0.624, rel=1e-8)
    assert float(t["contact_resistance_warp_weft"].sel(**s)) == pytest.approx(1.2, rel=1e-8)
    assert float(t["network_fit_residual_warp_weft"].sel(**s)) < 1e-10
    assert float(t["network_fit_residual"].sel(**s)) > 1e-3  # one R_y cannot explain both families
    g = t["yarn_sheet_conductance"].sel(**s)
    assert float(g.sel(yarn="warp")) == pytest.approx(1 / 0.48 + 1 / 1.2, rel=1e-8)
    assert float(g.sel(yarn="weft")) == pytest.approx(1 / 0.624 + 1 / 1.2, rel=1e-8)
