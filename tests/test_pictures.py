"""Pictures of every stored RVE state (rve.homogenisation.pictures): the nodal
fields against closed-form values, the tube meshes and .pvd series read back with
pyvista (frame count = stored states, the named point arrays present), the PNG renders,
and the Snakemake DAG (the picture rules are default targets when ``output.pictures``)."""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.homogenisation import layout as L
from rve.homogenisation.pictures import axial_force, nodal_mean, section_currents

ROOT = Path(__file__).resolve().parents[1]


def _straight(n_el=5, R=0.15, Lx=2.0):
    fib = straight_fibril(np.zeros(3), np.array([Lx, 0.0, 0.0]), R, name="f")
    return fibril_mesh([fib], n_el, 1)


@pytest.mark.parametrize("nu", [0.0, 0.3])
def test_axial_force_of_a_stretched_fibril_is_the_neo_hookean_closed_form(nu):
    mesh = _straight()
    lam_s = 1.2
    x = mesh.X0.copy()
    x[:, 0] *= lam_s  # centroid stretched, section directors unchanged: F = diag(lam, 1, 1) in the beam frame
    E = 1.26
    f = axial_force(mesh, E, nu, x)
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    R = 0.15
    expect = np.pi * R ** 2 * (mu * (lam_s - 1 / lam_s) + lam * np.log(lam_s) / lam_s)
    np.testing.assert_allclose(f, expect, rtol=1e-12)
    # unstretched: no force; compressed: negative
    assert np.abs(axial_force(mesh, E, nu, mesh.X0)).max() < 1e-15
    xc = mesh.X0.copy()
    xc[:, 0] *= 0.9
    assert (axial_force(mesh, E, nu, xc) < 0).all()


def test_section_current_of_a_linear_potential_is_sigma_A_over_L():
    mesh = _straight(n_el=4, Lx=3.0)
    V = 1.0 - mesh.X0[:, 0] / 3.0
    sigma = 10.0
    cur = section_currents(mesh, sigma, mesh.X0, {"p": V})["p"]
    np.testing.assert_allclose(cur, sigma * np.pi * 0.15 ** 2 / 3.0, rtol=1e-12)
    # the pull-back of thesis §7.4: the same current on the fibril stretched 20 %
    x = mesh.X0.copy()
    x[:, 0] *= 1.2
    np.testing.assert_allclose(section_currents(mesh, sigma, x, {"p": V})["p"], cur, rtol=1e-12)


def test_nodal_mean_averages_the_elements_of_each_node():
    mesh = _straight(n_el=3)
    np.testing.assert_allclose(nodal_mean(mesh, np.array([1.0, 2.0, 4.0])), [1.0, 1.5, 3.0, 4.0])


# --------------------------------------------------------------------------- the job bodies
SPEC = {"scene_config": None, "overrides": [],
        "scene": {"scene": "rve", "fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]},
                  "mesh": {"elements": 6},
                  "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2, "static_atol": 1e-9,
                                 "static_max_iter": 40},
                  "strain": {"modes": ["uniaxial"], "total": 0.05, "steps": 2, "static_atol": 1e-9,
                             "static_max_iter": 40}}}


@pytest.fixture(scope="module")
def pictured_run(tmp_path_factory):
    """fabric, relax, two uniaxial steps, the probe jobs (with tube files) and both
    picture jobs of a 2 x 2 weave, in process."""
    from rve.homogenisation.jobs import fabric_job, probe_job, relax_job, strain_job
    from rve.homogenisation.pictures import pictures_mode_job, pictures_relaxed_job

    root = tmp_path_factory.mktemp("pictures")
    run, combo = "pic", "base"
    sp = lambda n: L.state_path(run, combo, n, root)
    tp = lambda n: L.tubes_path(run, combo, n, root)
    fabric_job(sp("initial"), None, SPEC)
    relax_job(sp("initial"), sp("relaxed"), None, SPEC)
    names = ["relaxed", "uniaxial_01", "uniaxial_02"]
    for k in (1, 2):
        strain_job(sp(names[k - 1]), sp(names[k]), None, SPEC, combo, "uniaxial", k)
    for n in names:
        probe_job(sp(n), L.record_path(run, combo, n, root), None, SPEC, combo, tp(n))
    out_r = L.picture_outputs(run, combo, None, root)
    pictures_relaxed_job(sp("initial"), sp("relaxed"), tp("relaxed"), out_r, None, SPEC, combo)
    out_m = L.picture_outputs(run, combo, "uniaxial", root)
    Path(tp("uniaxial_02")).unlink()  # a tube file missing: the picture job computes it (ensure_tubes)
    pictures_mode_job("uniaxial", [sp(n) for n in names], [tp(n) for n in names], out_m, None, SPEC, combo)
    return {"root": root, "names": names, "relaxed": out_r, "mode": out_m, "tubes": [tp(n) for n in names]}


@pytest.mark.slow  # the fixture runs a small RVE (relax, 2 steps, probes, pictures): ~35 s
def test_pvd_series_reads_back_with_one_frame_per_stored_state(pictured_run):
    pv = pytest.importorskip("pyvista")
    from rve.homogenisation.checkpoint import load_state

    pvd = Path(pictured_run["mode"]["pvd"])
    frames = ET.parse(pvd).getroot().findall("./Collection/DataSet")
    assert len(frames) == len(pictured_run["names"]) == 3
    reader = pv.get_reader(str(pvd))
    strains = [load_state(L.state_path("pic", "base", n, pictured_run["root"])).strain for n in pictured_run["names"]]
    np.testing.assert_allclose(reader.time_values, strains, rtol=0, atol=1e-15)
    probes = ["probe1", "probe2", "probe3", "probe4"]
    want = {"fibril", "yarn", "displacement", "axial_force", *(f"{k}_{p}" for k in ("potential", "current",
                                                                                       "temperature") for p in probes)}
    for k, t in enumerate(reader.time_values):
        reader.set_active_time_value(t)
        mesh = reader.read()[0]
        assert want <= set(mesh.point_data.keys()), sorted(want - set(mesh.point_data.keys()))
        assert mesh.point_data["displacement"].shape[1] == 3
        if k == 0:  # the relaxed state is the origin of the displacement
            assert np.abs(mesh.point_data["displacement"]).max() == 0.0
    # last frame: stretched 5 % along x, the x+ ends moved by 0.05 * half-width
    u = mesh.point_data["displacement"]
    assert u[:, 0].max() == pytest.approx(0.05 * 2.0, rel=1e-6)
    # probe 1 at 1 V: the potential spans [0, 1]
    v = mesh.point_data["potential_probe1"]
    assert v.max() == pytest.approx(1.0, abs=1e-12) and v.min() == pytest.approx(0.0, abs=1e-9)


@pytest.mark.slow  # the fixture runs a small RVE (relax, 2 steps, probes, pictures): ~35 s
def test_tube_point_data_match_the_probe_record(pictured_run):
    import json

    import pyvista as pv

    mesh = pv.read(pictured_run["tubes"][1])
    rec = json.loads(Path(L.record_path("pic", "base", "uniaxial_01", pictured_run["root"])).read_text())
    for p, r in rec["probes"].items():
        assert mesh.point_data[f"temperature_{p}"].max() == pytest.approx(r["temperature_max"], rel=1e-12)
        # the current into the + terminal equals the section current at the terminal ends (within
        # the nodal averaging of the element next to the end; probe1's yarn carries all of it)
    i1 = rec["probes"]["probe1"]["current"]["+"]
    assert mesh.point_data["current_probe1"].max() == pytest.approx(i1, rel=1e-6)


@pytest.mark.slow  # the fixture runs a small RVE (relax, 2 steps, probes, pictures): ~35 s
def test_every_render_was_written(pictured_run):
    from PIL import Image

    for out in (pictured_run["relaxed"], pictured_run["mode"]):
        for key, f in out.items():
            if f.endswith(".png"):
                im = Image.open(f)
                assert im.size[0] >= 800 and im.size[1] >= 300, (f, im.size)
                assert len(set(np.asarray(im.convert("L")).ravel()[::97])) > 10, f"{f} looks blank"


def test_pictures_off_writes_no_tube_file(tmp_path):
    from rve.homogenisation.jobs import fabric_job, probe_record

    spec = {**SPEC, "overrides": ["output.pictures=false"]}
    fabric_job(tmp_path / "initial.nc", None, spec)
    probe_record(tmp_path / "initial.nc", spec, "base", tmp_path / "t.vtp")
    assert not (tmp_path / "t.vtp").exists()


def test_picture_rules_are_default_targets_and_run_beside_the_chains():
    """snakemake -n on the CI config: one rve_pictures_relaxed and one rve_pictures_mode
    per mode, each needing only its own chain's states."""
    pytest.importorskip("snakemake")
    cfg = yaml.safe_load((ROOT / "configs/tests/pipeline_ci.yaml").read_text())
    spec = cfg["rve"]["runs"]["ci"]
    targets = L.picture_targets(spec, "ci")
    assert len(targets) == 2 + 4 * 4
    assert set(targets) <= set(L.default_targets(cfg, {"static_wire": []}))
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--forceall", *targets[-4:], "--configfile",
                           "configs/tests/pipeline_ci.yaml"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout + proc.stderr
    assert "rve_pictures_mode" in out
    # the trellis pictures need the trellis chain only (not the other modes' steps)
    assert "mode=trellis" in out and "mode=shear" not in out and "state=shear_01" not in out


def test_a_periodic_cell_is_drawn_tiled_by_its_deformed_lattice():
    """The 3 x 3 tiling of a periodic cell: nine copies, each the cell translated by a
    lattice vector of the macro gradient the state carries (here a shear); a pinned cell
    is drawn as it is."""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.config.rve import RVEConfig
    from rve.homogenisation.periodic import _affine_predictor, macro_gradient
    from rve.homogenisation.pictures import tiled
    from rve.io.vtk import tube_surface

    cfg = RVEConfig(scene="rve", boundary="periodic", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 4})
    fab, mesh = fabric_and_mesh(cfg)
    F = macro_gradient("shear", 0.2)
    x = _affine_predictor(fab.initial_state(mesh), F, np.zeros(3))
    surf = tube_surface(mesh, x, 8, {"fibril": mesh.node_fibril.astype(float)})
    big = tiled(surf, cfg, fab, mesh, x)
    assert big.n_points == 9 * surf.n_points and set(big.point_data) >= set(surf.point_data)
    a1, a2 = 2.0 * fab.half_widths[0] * F[:, 0], 2.0 * fab.half_widths[1] * F[:, 1]
    pts, copies = np.asarray(surf.points), np.asarray(big.points).reshape(9, -1, 3)
    shifts = {tuple(np.round(c[0] - pts[0], 12)) for c in copies}
    want = {tuple(np.round(i * a1 + j * a2, 12)) for i in (-1, 0, 1) for j in (-1, 0, 1)}
    assert shifts == want
    for c in copies:  # each copy is a rigid translation of the cell
        assert np.allclose(c - pts, c[0] - pts[0], atol=1e-12)
    pinned = RVEConfig(scene="rve", fabric={"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]},
                       mesh={"elements": 4})
    assert tiled(surf, pinned, fab, mesh, x) is surf
