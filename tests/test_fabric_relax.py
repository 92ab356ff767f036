"""The fabric relaxation scene on a small weave (2 x 2 single-fibril yarns) and its outputs;
the full thesis RVE (80 fibrils x 30 elements) runs in benchmarks/weave_relaxation.py."""
import json

import numpy as np
import pytest

from rve.config import load_config
from rve.solvers.minimize import capped_newton
from rve.io.vtk import tube_surface, write_pvd, write_tubes
from rve.scenes import SCENES, run_scene

SMALL = {
    "scene": "fabric_relax",
    "fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]},
    "mesh": {"elements": 12},
    "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2},
}


def _cfg(tmp_path, data):
    import yaml

    p = tmp_path / "cfg.yaml"
    p.write_text(yaml.safe_dump(data))
    return load_config(str(p))


def test_scene_registered():
    assert SCENES["fabric_relax"].runner == "rve.scenes.fabric_relax"


def test_small_weave_relaxes_without_overlap(tmp_path):
    cfg = _cfg(tmp_path, SMALL)
    out = tmp_path / "out"
    summary = run_scene(cfg, out)
    assert summary["static_converged"]
    assert summary["max_overlap_over_R"] < 0.05
    assert summary["active_contact_pairs"] > 0  # the crossings touch
    # reactions reported on every side, 3 components; the fabric is in tension, so the
    # clamps pull outwards (x- clamp force along -x)
    reac = summary["clamp_reactions_N"]
    assert set(reac) == {"x-", "x+", "y-", "y+"} and all(len(v) == 3 for v in reac.values())
    assert reac["x-"][0] < 0 < reac["x+"][0]
    # the clamps balance the fabric: total force ~ 0
    tot = np.sum([v for v in reac.values()], axis=0)
    assert np.abs(tot).max() < 1e-6
    # the static residuals end quadratically
    r = summary["static_residuals"]
    assert r[-1] < 1e-9
    # outputs
    for name in ("relaxed_state.nc", "tubes_initial.vtp", "tubes_relaxed.vtp", "relaxation.pvd", "relaxed.png"):
        assert (out / name).stat().st_size > 0, name
    import xarray as xr

    ds = xr.open_dataset(out / "relaxed_state.nc")
    assert ds["relaxed"].shape == (4 * 13, 9)
    assert ds["relaxed"].attrs["units"] == "mm"
    assert json.loads(ds.attrs["config"])["scene"] == "fabric_relax"
    np.testing.assert_allclose(ds["radius"].values, 0.15)
    ds.close()
    pvd = (out / "relaxation.pvd").read_text()
    assert "tubes_initial.vtp" in pvd and "tubes_relaxed.vtp" in pvd
    assert summary["render"] in ("pyvista", "matplotlib")


def test_tube_mesh_rings():
    from rve.fem.mesh import fibril_mesh, straight_fibril

    mesh = fibril_mesh([straight_fibril([0, 0, 0], [2, 0, 0], 0.1), straight_fibril([0, 1, 0], [0, 3, 0], 0.2)], 4, 1)
    surf = tube_surface(mesh, mesh.X0, n_theta=8, point_data={"s": mesh.node_s})
    assert surf.n_points == mesh.n_nodes * 8
    # every ring point is R from its centroid
    pts = np.asarray(surf.points).reshape(mesh.n_nodes, 8, 3)
    d = np.linalg.norm(pts - mesh.X0[:, None, :3], axis=-1)
    np.testing.assert_allclose(d, np.broadcast_to(mesh.radius[mesh.node_fibril][:, None], d.shape), rtol=1e-12)
    # quads: 4 segments x 8 per fibril; caps: 2 per fibril
    assert surf.n_cells == 2 * (4 * 8 + 2)
    np.testing.assert_array_equal(np.asarray(surf.point_data["s"])[::8], mesh.node_s)


def test_vtk_files(tmp_path):
    import pyvista as pv
    from rve.fem.mesh import fibril_mesh, straight_fibril

    mesh = fibril_mesh([straight_fibril([0, 0, 0], [2, 0, 0], 0.1)], 3, 2)
    p = write_tubes(tmp_path / "t.vtp", mesh, mesh.X0, 6)
    back = pv.read(p)
    assert back.n_points == mesh.n_nodes * 6
    q = write_pvd(tmp_path / "s.pvd", [(0.0, "t.vtp"), (1.5, "t.vtp")])
    assert 'timestep="1.5"' in q.read_text()
    with pytest.raises(ValueError):
        write_tubes(tmp_path / "t.vtu", mesh, mesh.X0)


def test_capped_newton_does_not_skip_contacts():
    """Two fibrils pulled straight through each other's path: the capped steps and map
    rebuilds stop them at contact instead of jumping through."""
    from rve.model import ContactParams, ContactSystem
    from rve.fem.assembly import DofLayout
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.model import BeamMaterial, BeamModel, DirichletBC

    R = 0.15
    fibs = [straight_fibril([-1, 0, 0], [1, 0, 0], R, "a"), straight_fibril([0, -1, 0.6], [0, 1, 0.6], R, "b")]
    mesh = fibril_mesh(fibs, 10, 1)
    a0, a1 = mesh.end_nodes(0)
    b0, b1 = mesh.end_nodes(1)
    layout = DofLayout(mesh.n_nodes)
    pinned = layout.dofs("r", [a0, a1, b0, b1])
    base = BeamModel(mesh, BeamMaterial(1.26), bcs=[DirichletBC(pinned, 0.0),
                                                   DirichletBC(layout.dofs("g1", [a0, b0], comp=2), 0.0)])
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0
    # fibril a starts bowed up by 1.2 mm in the middle (above b): straightening crosses b
    s = mesh.node_s[mesh.fibril_nodes(0)] / 2.0
    xn[mesh.fibril_nodes(0), 2] += 1.2 * np.sin(np.pi * s)
    sysm = ContactSystem(base, ContactParams(penalty=50.0, margin=0.1), x)
    assert sysm.map.n_pairs == 0  # nothing near at the start
    xs, _, res = capped_newton(sysm, x, 0.0, atol=1e-10, max_iter=80, step_cap=0.05)
    assert res.converged
    r = sysm.nodal(xs)
    mid_a = r[mesh.fibril_nodes(0), 2].max()
    mid_b = r[mesh.fibril_nodes(1), 2].min()
    assert mid_a > mid_b + 0.25  # a rests on b, not below it
    assert sysm.contact_state(xs)["max_overlap_over_R"] < 0.05


def test_small_weave_energy_minimum_is_stable_and_quadratic(tmp_path):
    """The default path (energy minimisation, onset continuation 0.05 R -> 0):
    converged to 1e-9 N, a local minimum (no negative pivot of the tangent), the last
    Newton iterations quadratic, energies decreasing in every stage."""
    from rve.scenes import fabric_relax

    cfg = _cfg(tmp_path, SMALL)
    s = fabric_relax.solve(cfg).summary
    assert s["method"] == "energy" and s["static_converged"]
    assert s["negative_pivots"] == 0 and s["stable"]
    assert s["static_residuals"][-1] < 1e-9
    assert max(s["static_rates"][-2:]) > 1.8
    for h in s["history"]:
        e = np.asarray(h["energies"])
        assert np.all(np.diff(e) <= 1e-12 * abs(e[0]))
    assert s["onset_schedule_over_R"] == [0.05, 0.0]
    assert s["max_overlap_over_R"] < 0.05


def test_mesh_sequencing(tmp_path):
    """relaxation.coarse_elements: relax on 6 elements, interpolate, finish on 12."""
    from rve.scenes import fabric_relax

    data = dict(SMALL, relaxation=dict(SMALL["relaxation"], coarse_elements=6))
    s = fabric_relax.solve(_cfg(tmp_path, data)).summary
    assert s["coarse_stage"]["elements_per_fibril"] == 6 and s["coarse_stage"]["converged"]
    assert s["static_converged"] and s["static_residuals"][-1] < 1e-9 and s["stable"]
    assert {h["mesh_elements"] for h in s["history"]} == {6, 12}


def test_factor_inertia_counts_negative_eigenvalues():
    import scipy.sparse as sp

    from rve.solvers.linear import factor_inertia

    rng = np.random.default_rng(3)
    A = sp.random(60, 60, density=0.1, random_state=3)
    A = (A + A.T + sp.diags(rng.normal(size=60) * 2)).tocsc()
    lu, neg = factor_inertia(A)
    assert neg == int((np.linalg.eigvalsh(A.toarray()) < 0).sum())
    b = rng.normal(size=60)
    np.testing.assert_allclose(A @ lu.solve(b), b, atol=1e-8)


def test_dynamic_method_still_available(tmp_path):
    data = dict(SMALL, relaxation=dict(SMALL["relaxation"], method="dynamic"))
    from rve.scenes import fabric_relax

    s = fabric_relax.solve(_cfg(tmp_path, data)).summary
    assert s["static_converged"] and s["max_overlap_over_R"] < 0.05
