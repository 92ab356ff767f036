"""Macro-FE exports (rve.tables.formats, docs/macro_export.md §3): round trips and headers.

The table is built from records of a known model (forces cubic in strain with a
pretension, network resistances linear in strain), every mode present; each export is
read back (abaqus, lsdyna, curves, comsol), evaluated (hermite against
``interpolate(method="cubic")``) or run (spice through ngspice, where installed).
"""
import json
import math
import shutil
import subprocess

import numpy as np
import pytest

from rve import cli
from rve.tables import YarnNetwork, build_table, default_probe_terminals, interpolate, open_table, write_table
from rve.tables.formats import (UNIT_SYSTEMS, export_macro, hermite_eval, read_abaqus_curves, read_lsdyna_curves,
                                spice_network_deck)

STRAINS = [0.025 * k for k in range(11)]
MODES = ("uniaxial", "shear", "uniaxial_y", "trellis")
SIDES = ("warp-", "warp+", "weft-", "weft+")
NET = YarnNetwork(4, 4)
FABRIC = {"kind": "plain weave", "n_warp": 4, "n_weft": 4, "spacing": 2.0, "half_widths": [4.0, 4.0, 0.6],
          "fibril_mass_g": 0.0384}
N0 = 0.004  # N/mm pretension on every edge


def Ry(m, e):
    return 0.4 * (1 + (0.8, 0.3, 0.5, 0.1)[MODES.index(m)] * e)


def Rc(m, e):
    return 1.5 * (1 - (1.2, 2.0, 1.0, 0.5)[MODES.index(m)] * e)


def force(m, e, r=0.15):
    """N on the + sides: x+ (normal x) and y+; - sides opposite."""
    k = 1 + MODES.index(m)
    a = 8.0 * (N0 + k * (0.3 * e + 2.0 * e ** 3) * (r / 0.15))
    fx = np.array([a, 0.5 * k * e * e if m in ("shear", "trellis") else 0.0, 0.0])
    fy = np.array([0.0, 0.7 * a, 0.0])
    return {"warp+": fx, "warp-": -fx, "weft+": fy, "weft-": -fy}


def record(m, e, params=None):
    R = NET.probe_resistances(Ry(m, e), Rc(m, e))
    rec = {"mode": m, "strain": e, "reaction_force": {s: list(v) for s, v in force(m, e, (params or {}).get(
        "fibril_radius", 0.15)).items()}, "contact_count": 100,
           "probes": {p: {"voltage": 1.0, "current": 1.0 / r} for p, r in R.items()}}
    if params:
        rec["params"] = params
    return rec


@pytest.fixture(scope="module")
def table():
    return build_table([record(m, e) for m in MODES for e in STRAINS], fabric=FABRIC, config={})


@pytest.fixture(scope="module")
def table_two_modes():
    return build_table([record(m, e) for m in ("uniaxial", "shear") for e in STRAINS], fabric=FABRIC, config={})


@pytest.fixture(scope="module")
def swept():
    return build_table([record(m, e, {"fibril_radius": r}) for m in ("uniaxial", "shear") for e in STRAINS
                        for r in (0.1, 0.15, 0.2)], fabric=FABRIC, config={})


def _mids():
    return [0.5 * (a + b) for a, b in zip(STRAINS[:-1], STRAINS[1:])]


# --------------------------------------------------------------------------- hermite
def test_hermite_evaluates_to_interpolate_cubic_at_midpoints(table, tmp_path):
    (path,) = export_macro(table, tmp_path / "h.json", "hermite")
    doc = json.loads(path.read_text())
    assert doc["format"] == "rve-hermite/1"
    names = {(e["name"], e["mode"]) for e in doc["entries"]}
    assert {("N_xx", "uniaxial"), ("N_yy", "uniaxial_y"), ("N_yx", "trellis")} <= names
    mids = _mids()
    ref = {m: interpolate(table, mids, mode=m, method="cubic") for m in MODES}
    checked = 0
    for e in doc["entries"]:
        got = hermite_eval(e, mids)
        r = ref[e["mode"]]
        if e["name"] in ("N_xx", "N_yy", "N_yx"):
            edge, comp = {"N_xx": ("x", "x"), "N_yy": ("y", "y"), "N_yx": ("x", "y")}[e["name"]]
            want = (r["membrane_force"].sel(edge=edge, component=comp).values
                    - float(table["membrane_force_at_zero_strain"].sel(mode=e["mode"], edge=edge, component=comp)))
        else:
            name, _, lab = e["name"].partition("[")
            want = r[name].values if not lab else r[name].sel(yarn=lab.rstrip("]")).values
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max(), err_msg=e["name"])
        np.testing.assert_array_equal(hermite_eval(e, e["t"]), e["p"])
        checked += 1
    assert checked >= 3 + 4 * 6


# --------------------------------------------------------------------------- abaqus / lsdyna / curves / comsol
def test_abaqus_parses_back_to_the_printed_digits(table, tmp_path):
    (path,) = export_macro(table, tmp_path / "fab.inc", "abaqus", thickness="0.5 mm", source="t.nc")
    text = path.read_text()
    assert all(line.startswith("**") or line.startswith("*") or "," in line for line in text.splitlines())
    assert "*MATERIAL" in text and "*FABRIC" in text and "*DENSITY" in text
    assert "pretension N(0) = 4.000000e-03 N mm-1 removed" in text and "KUBC" in text and "t.nc" in text
    curves = read_abaqus_curves(path)
    assert set(curves) == {"1", "2", "12"}
    N = table["membrane_force"]
    strains = table["strain"].values
    eps, sig = curves["1"]
    want = (N.sel(mode="uniaxial", edge="x", component="x").values - N0) / 0.5
    np.testing.assert_array_equal(sig, [float(f"{v:.9e}") for v in want])
    np.testing.assert_array_equal(eps, [float(f"{v:.9e}") for v in strains])
    ang, tau = curves["12"]  # trellis: stress vs the angle drop
    np.testing.assert_array_equal(ang, [float(f"{v:.9e}") for v in strains])
    want = N.sel(mode="trellis", edge="x", component="y").values / 0.5
    np.testing.assert_array_equal(tau, [float(f"{v:.9e}") for v in want])
    rho = float(text.split("*DENSITY\n")[1].splitlines()[0].rstrip(","))
    assert rho == pytest.approx(0.0384 / 64 / 0.5, rel=1e-9)


def test_lsdyna_fixed_fields_parse_back(table, tmp_path):
    (path,) = export_macro(table, tmp_path / "fab.k", "lsdyna", lcid_start=500)
    lines = path.read_text().splitlines()
    assert lines[[k for k, ln in enumerate(lines) if not ln.startswith("$")][0]] == "*KEYWORD"
    assert lines[-1] == "*END"
    curves = read_lsdyna_curves(path)
    assert sorted(curves) == [500, 501, 502]
    for k, ln in enumerate(lines):
        if ln.startswith("*DEFINE_CURVE_TITLE"):
            assert len(lines[k + 3]) == 80  # card 1: 8 fields of 10
            assert int(lines[k + 3][:10]) in curves
    x, y = curves[501]  # weft from uniaxial_y
    want = table["membrane_force"].sel(mode="uniaxial_y", edge="y", component="y").values - 0.7 * N0
    np.testing.assert_array_equal(y, [float(f"{v:.12e}") for v in want])
    np.testing.assert_array_equal(x, table["strain"].values)
    assert "$      500       501       502" in lines  # LCA, LCB, LCAB of the *MAT_FABRIC skeleton


def test_lsdyna_table_2d_for_a_swept_parameter(swept, tmp_path):
    (path,) = export_macro(swept, tmp_path / "fab.k", "lsdyna")
    text = path.read_text()
    curves = read_lsdyna_curves(path)
    assert len(curves) == 3 * 3  # warp, weft (copied), shear per fibril radius
    assert sum(ln == "*DEFINE_TABLE_2D" for ln in text.splitlines()) == 3 and "over fibril_radius" in text
    x, y = curves[1001 + 3]  # the second radius: 0.15, warp
    want = swept["membrane_force"].sel(mode="uniaxial", edge="x", component="x", fibril_radius=0.15).values - N0
    np.testing.assert_array_equal(y, [float(f"{v:.12e}") for v in want])
    with pytest.raises(ValueError, match="--param"):
        export_macro(swept, tmp_path / "a.inc", "abaqus")
    (p2,) = export_macro(swept, tmp_path / "a.inc", "abaqus", params={"fibril_radius": 0.175})
    eps, sig = read_abaqus_curves(p2)["1"]
    N = swept["membrane_force"].sel(mode="uniaxial", edge="x", component="x")
    mid = 0.5 * (N.sel(fibril_radius=0.15).values + N.sel(fibril_radius=0.2).values) - N0
    np.testing.assert_allclose(sig, mid, rtol=1e-9)


def test_curves_and_comsol(table_two_modes, tmp_path):
    paths = export_macro(table_two_modes, tmp_path / "c.csv", "curves", keep_pretension=True)
    assert [p.name for p in paths] == ["c.warp.csv", "c.weft.csv", "c.shear.csv"]
    lines = paths[0].read_text().splitlines()
    assert lines[0].startswith("# ") and not lines[1].startswith("#") and lines[1] == "strain [1],N_xx [N mm-1]"
    data = np.loadtxt(paths[0], delimiter=",", skiprows=2)
    np.testing.assert_array_equal(data[:, 1], table_two_modes["membrane_force"].sel(
        mode="uniaxial", edge="x", component="x").values)
    weft = paths[1].read_text()
    assert "symmetric weave: weft curve copied" in weft and "pretension kept" in weft
    shear = np.loadtxt(paths[2], delimiter=",", skiprows=2)
    np.testing.assert_allclose(shear[:, 0], np.arctan(STRAINS), rtol=1e-15)  # simple shear: angle atan(gamma)
    assert "also stretched" in paths[2].read_text()
    (cp,) = export_macro(table_two_modes, tmp_path / "c.txt", "comsol")
    rows = np.loadtxt(cp, comments="%")
    assert rows.shape == (11, 4)
    assert all(ln.startswith("%") for ln in cp.read_text().splitlines()[:5])


def test_unit_sets_convert_through_pint(table, tmp_path):
    (a,) = export_macro(table, tmp_path / "si.inc", "abaqus", units="m-s-kg-N-Pa")
    (b,) = export_macro(table, tmp_path / "mm.inc", "abaqus")
    sa, sb = read_abaqus_curves(a)["1"][1], read_abaqus_curves(b)["1"][1]
    np.testing.assert_allclose(sa, sb * 1e6, rtol=1e-9)  # MPa -> Pa
    rho = [float(p.read_text().split("*DENSITY\n")[1].splitlines()[0].rstrip(",")) for p in (a, b)]
    assert rho[0] == pytest.approx(rho[1] * 1e6, rel=1e-9)  # g/mm^3 -> kg/m^3
    assert "units (m-s-kg-N-Pa)" in a.read_text()
    assert set(UNIT_SYSTEMS) >= {"mm-s-t-N-MPa"}
    with pytest.raises(ValueError, match="unknown unit set"):
        export_macro(table, tmp_path / "x.inc", "abaqus", units="furlongs")


# --------------------------------------------------------------------------- spice
def _ngspice_current(deck: str, tmp_path, name: str) -> float:
    f = tmp_path / name
    f.write_text(deck)
    out = subprocess.run(["ngspice", "-b", str(f)], capture_output=True, text=True, timeout=120)
    line = next(ln for ln in out.stdout.splitlines() if ln.strip().startswith("i(vp)"))
    return float(line.split("=")[1])


def test_spice_netlist_through_ngspice(table, tmp_path):
    paths = export_macro(table, tmp_path / "cell.cir", "spice", modes=["uniaxial"], strain=0.1)
    assert [p.name for p in paths] == ["cell.cir", "cell.static.cir"]
    text = paths[0].read_text()
    assert ".subckt rve_cell w0 w1 f0 f1 strain" in text and "pwl(V(strain)" in text
    if shutil.which("ngspice") is None:
        pytest.skip("ngspice not installed (Debian package ngspice): the netlist was written but not run")
    probes = {"probe1": (("warp", 1, "+"), ("warp", 1, "-")), "probe3": (("warp", 1, "+"), ("weft", 1, "+"))}
    s = table.sel(mode="uniaxial")
    for e in (0.1, 0.1375):  # a stored strain and one between (pwl = linear interpolation)
        ry = float(np.interp(e, STRAINS, s["yarn_resistance"].values))
        rc = float(np.interp(e, STRAINS, s["contact_resistance"].values))
        for name, (plus, minus) in probes.items():
            I = _ngspice_current(spice_network_deck(paths[0], 4, 4, plus, minus, strain=e), tmp_path, "d.cir")
            assert -1.0 / I == pytest.approx(NET.resistance(plus, minus, ry, rc), rel=1e-6), (name, e)
    ry, rc = float(s["yarn_resistance"].sel(strain=0.1)), float(s["contact_resistance"].sel(strain=0.1))
    I = _ngspice_current(spice_network_deck(paths[1], 4, 4, *probes["probe1"], static=True), tmp_path, "s.cir")
    assert -1.0 / I == pytest.approx(NET.resistance(*probes["probe1"], ry, rc), rel=1e-12)


# --------------------------------------------------------------------------- CLI, pretension, v1
def test_cli_export_every_format(table, tmp_path):
    path = tmp_path / "t.nc"
    write_table(table, path)
    outs = {"abaqus": "a.inc", "lsdyna": "a.k", "curves": "a.csv", "comsol": "a.txt", "hermite": "a.json",
            "spice": "a.cir", "csv": "b.csv", "json": "b.json", "dat": "b.dat"}
    for fmt, out in outs.items():
        assert cli.main(["table", "export", str(path), "--format", fmt, "--out", str(tmp_path / out)]) == 0, fmt
    assert cli.main(["table", "export", str(path), "--format", "abaqus", "--out", str(tmp_path / "k.inc"),
                     "--keep-pretension", "--thickness", "2 mm", "--mode", "uniaxial", "--mode", "shear"]) == 0
    text = (tmp_path / "k.inc").read_text()
    assert "pretension kept" in text and "symmetric weave" in text and "from mode shear" in text
    sig = read_abaqus_curves(tmp_path / "k.inc")["1"][1]
    assert sig[0] == pytest.approx(N0 / 2.0, rel=1e-9)
    assert cli.main(["table", "export", str(path), "--format", "lsdyna", "--out", str(tmp_path / "x.k"),
                     "--lcid-start", "7"]) == 0
    assert sorted(read_lsdyna_curves(tmp_path / "x.k")) == [7, 8, 9]
    assert cli.main(["table", "export", str(path), "--format", "abaqus", "--out", str(tmp_path / "y.inc"),
                     "--mode", "nosuch"]) != 0


def test_exports_of_a_version_1_table(tmp_path):
    from pathlib import Path

    ds = open_table(Path(__file__).parent / "data" / "table_v1_ci.nc")
    for fmt in ("abaqus", "lsdyna", "curves", "hermite"):
        paths = export_macro(ds, tmp_path / f"v1.{fmt}", fmt)
        text = "".join(p.read_text() for p in paths)
        assert "rve-lookup-table/1" in text and "symmetric weave" in text, fmt
    assert "areal density not recorded" in (tmp_path / "v1.abaqus").read_text()
    assert math.isnan(float(ds["areal_density"]))


def test_spice_cell_uses_the_network_fit_of_the_sheet_parameters(tmp_path):
    # a four-probe table: R_yw, R_yf and R_c all from the warp/weft fit (not R_c of the
    # two-resistor fit beside R_yw, R_yf of the other), as the sheet parameters g, c
    from rve.tables.macro import sheet_network_parameters

    probes = default_probe_terminals(4, 4, weft_probe=True)
    recs = []
    for e in STRAINS[:3]:
        R = NET.solve_pairs3(list(probes.values()), 0.29 * (1 + e), 0.35, 11.0 * (1 - e))[0]
        recs.append({"mode": "uniaxial", "strain": e, "contact_count": 100,
                     "reaction_force": {k: list(v) for k, v in force("uniaxial", e, 0.15).items()},
                     "probes": {p: {"voltage": 1.0, "current": 1.0 / r} for p, r in zip(probes, R)}})
    t = build_table(recs, fabric=FABRIC, config={})
    s = t.sel(mode="uniaxial", strain=STRAINS[1])
    assert abs(float(s["contact_resistance"]) / float(s["contact_resistance_warp_weft"]) - 1) > 1e-4
    paths = export_macro(t, tmp_path / "cell.cir", "spice", modes=["uniaxial"], strain=STRAINS[1])
    static = {ln.split()[0]: float(ln.split()[-1]) for ln in paths[1].read_text().splitlines()
              if ln[:1] == "R"}
    net = sheet_network_parameters(t).sel(mode="uniaxial", strain=STRAINS[1])
    assert static["Ryw"] == float(s["yarn_resistance_warp"]) and static["Ryf"] == float(s["yarn_resistance_weft"])
    assert static["Rc0"] == float(s["contact_resistance_warp_weft"]) == float(net["contact_resistance"])
    assert "warp/weft fit" in paths[0].read_text() and "warp/weft fit" in paths[1].read_text()
