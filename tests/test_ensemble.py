"""Ensembles over perturbed packings (thesis §7.5): the perturbed packing
(rve.fabrics.perturb), the `packing` config block, the `realization` sweep alias, the
ensemble statistics of rve.tables.ensemble against numpy on known data, their CF-clean
round trip, and (slow) the CI ensemble through Snakemake."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from rve.fabrics.perturb import packing_draws, perturb_packing
from rve.fabrics.weave import weave
from rve.homogenisation import sweeps as S
from rve.tables.ensemble import add_ensemble_statistics, ensemble_wiggle, ensemble_wiggle_report

ROOT = Path(__file__).resolve().parents[1]


# --------------------------------------------------------------------------- packing
def test_zero_perturbation_is_the_designed_packing_bit_for_bit():
    from rve.fabrics.setup import fabric_and_mesh, make_fabric
    from rve.config.rve import RVEConfig

    cfg = RVEConfig(scene="rve", fabric={"n_warp": 2, "n_weft": 2}, mesh={"elements": 6})
    assert cfg.packing.perturbation == 0.0
    fab, mesh = fabric_and_mesh(cfg)
    ref = make_fabric(cfg.fabric)
    assert np.array_equal(fab.initial_state(mesh), ref.initial_state(ref.mesh(6)))
    assert perturb_packing(ref, 7, 0.0) is ref


def test_perturbed_packing_keeps_the_ends_on_the_faces_and_moves_fibrils_within_the_bounds():
    fab = weave("plain", 4, 4)
    mesh = fab.mesh(12)
    a = 0.2
    R = 0.15
    pert = perturb_packing(fab, 5, a)
    x0, x1 = fab.initial_state(mesh), pert.initial_state(mesh)
    # the along-yarn coordinate of every node is the designed one (ends stay on the box faces)
    along = np.array([0 if fab.yarns[fab.fibril_yarn[f]].direction == "warp" else 1 for f in mesh.node_fibril])
    idx = np.arange(mesh.n_nodes)
    assert np.array_equal(x1[idx, along], x0[idx, along])
    # in-section offsets: the perpendicular move from the phase-shifted designed point is dl g1 + dv g2
    phi, dlv = packing_draws(fab, 5, a, a)
    assert np.abs(dlv).max() <= a * R and np.abs(phi).max() <= a * R
    assert np.abs(dlv).max() > 0.5 * a * R  # the draws fill the interval (80 fibrils)
    for f in (0, 13, 47, 79):
        nodes = mesh.fibril_nodes(f)
        r, g1, g2 = fab.designed[f](mesh.node_s[nodes] + phi[f])
        want = r + dlv[f, 0] * g1 + dlv[f, 1] * g2
        k = 1 - along[nodes[0]]
        np.testing.assert_allclose(x1[nodes, k], want[:, k], atol=1e-13)
        np.testing.assert_allclose(x1[nodes, 2], want[:, 2], atol=1e-13)
    # directors: orthonormal and perpendicular to the new centroid tangent
    g1, g2 = x1[:, 3:6], x1[:, 6:9]
    np.testing.assert_allclose(np.linalg.norm(g1, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose((g1 * g2).sum(1), 0.0, atol=1e-12)
    nodes = mesh.fibril_nodes(3)
    t = np.gradient(x1[nodes, 0:3], mesh.node_s[nodes], axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    assert np.abs((t[1:-1] * g1[nodes][1:-1]).sum(1)).max() < 2e-2  # vs a centred difference on the mesh
    # a seed names a packing; another seed is another packing
    assert np.array_equal(perturb_packing(fab, 5, a).initial_state(mesh), x1)
    assert not np.allclose(perturb_packing(fab, 6, a).initial_state(mesh), x1)


def test_packing_config_is_validated_and_a_knit_is_refused():
    from rve.config import ConfigError, validate_config
    from rve.fabrics.knit import knit

    with pytest.raises(Exception, match="perturbation"):
        validate_config({"scene": "rve", "packing": {"perturbation": 0.9}})
    with pytest.raises(ValueError, match="weaves"):
        perturb_packing(knit(n_rows=2, n_loops=2), 1, 0.1)
    assert ConfigError is not None


def test_realization_sweep_is_a_seed_sweep():
    spec = {"scene": {"scene": "rve", "packing": {"perturbation": 0.1}}, "sweep": {"realization": [1, 2, 3]}}
    cs = S.combos(spec)
    assert [c.id for c in cs] == ["realization-1", "realization-2", "realization-3"]
    assert [S.load_run_config(spec, c.id).packing.seed for c in cs] == [1, 2, 3]
    assert S.swept_dims(spec) == {"realization": "1"}


# --------------------------------------------------------------------------- statistics
def _synthetic(n_real=9, seed=0):
    rng = np.random.default_rng(seed)
    strain = np.linspace(0, 0.25, 6)
    vals = 2.0 + strain[None, :, None] + 0.1 * rng.standard_normal((n_real, 6, 3))
    ds = xr.Dataset(
        {"probe_resistance": (("realization", "strain", "probe"), vals, {"units": "ohm", "long_name": "R"}),
         "label": (("probe",), np.array(["a", "b", "c"], dtype=object))},
        coords={"realization": np.arange(1.0, n_real + 1), "strain": strain, "probe": ["p1", "p2", "p3"]})
    return ds, vals


def test_statistics_match_numpy_and_skip_nan():
    ds, vals = _synthetic()
    vals = vals.copy()
    vals[2, 3, 1] = np.nan
    ds["probe_resistance"].values[:] = vals
    out = add_ensemble_statistics(ds)
    np.testing.assert_allclose(out["probe_resistance_mean"].values, np.nanmean(vals, axis=0), rtol=1e-14)
    np.testing.assert_allclose(out["probe_resistance_std"].values, np.nanstd(vals, axis=0, ddof=1), rtol=1e-12)
    np.testing.assert_allclose(out["probe_resistance_q05"].values, np.nanquantile(vals, 0.05, axis=0), rtol=1e-14)
    np.testing.assert_allclose(out["probe_resistance_q95"].values, np.nanquantile(vals, 0.95, axis=0), rtol=1e-14)
    assert (out["probe_resistance_q05"] <= out["probe_resistance_mean"]).all()
    assert (out["probe_resistance_mean"] <= out["probe_resistance_q95"]).all()
    assert out["probe_resistance_mean"].dims == ("strain", "probe")
    assert out["probe_resistance_mean"].attrs["cell_methods"] == "realization: mean"
    assert out["probe_resistance_std"].attrs["units"] == "ohm"
    assert out["realization"].attrs["standard_name"] == "realization"
    assert json.loads(out.attrs["ensemble"])["variables"] == ["probe_resistance"]
    # an entry with no finite realization is NaN
    v2 = vals.copy()
    v2[:, 0, 0] = np.nan
    ds["probe_resistance"].values[:] = v2
    out2 = add_ensemble_statistics(ds)
    assert all(np.isnan(out2[f"probe_resistance_{s}"].values[0, 0]) for s in ("mean", "std", "q05", "q95"))
    with pytest.raises(ValueError, match="at least 2"):
        add_ensemble_statistics(ds.isel(realization=[0]))


def test_wiggle_of_a_zigzag_and_the_band_of_identical_realizations():
    ds, _ = _synthetic(n_real=4)
    zig = 2.0 * (1 + 0.01 * (-1.0) ** np.arange(6))  # +-1 % alternating: |R_i - mean(nb)| / R_i = 2 %/(1 +- 1 %)
    ds["probe_resistance"].values[:] = zig[None, :, None]
    ds = ds.expand_dims(mode=["uniaxial"]).transpose("mode", ...)
    out = add_ensemble_statistics(ds)
    w = ensemble_wiggle(out)
    assert float(w["band"].max()) == 0.0
    np.testing.assert_allclose(w["wiggle"].values, np.median(0.04 / (2 * (1 + 0.01 * (-1.0) ** np.arange(1, 5)))), rtol=1e-12)
    assert "band/wiggle" in ensemble_wiggle_report(out)


def test_ensemble_table_is_cf_clean_on_disk(tmp_path):
    from rve.tables.io import open_table, write_table

    ds, _ = _synthetic()
    ds = ds.drop_vars("label").expand_dims(mode=["uniaxial"]).transpose("mode", ...)
    out = add_ensemble_statistics(ds)
    write_table(out, tmp_path / "t.nc")
    back = open_table(tmp_path / "t.nc")
    for name in ("probe_resistance_mean", "probe_resistance_std", "probe_resistance_q05", "probe_resistance_q95"):
        np.testing.assert_array_equal(back[name].values, out[name].values)
        assert back[name].attrs["units"] == "ohm"
    assert back["realization"].attrs["standard_name"] == "realization"
    with xr.open_dataset(tmp_path / "t.nc") as raw:
        assert raw["realization"].dtype.kind == "f" and raw.attrs["Conventions"].startswith("CF-")


# --------------------------------------------------------------------------- through Snakemake
# long: three CI realisations through Snakemake (~3 min); the statistics and the gather are
# tested above, `pytest -m long` runs the sweep end to end
@pytest.mark.slow
@pytest.mark.long
def test_ci_ensemble_through_snakemake(tmp_path):
    """3 realizations of a 2 x 2 weave with 2 fibrils per yarn: one chain each, a table with a
    `realization` dimension and bands, the figures and the band/wiggle report."""
    pytest.importorskip("snakemake")
    from workflow_copy import workflow_copy

    from rve.homogenisation import layout as L
    from rve.tables import open_table

    work = workflow_copy(tmp_path)
    run = "ci_ensemble"
    outs = [L.table_outputs(run)["table"], *L.ensemble_report_outputs(run).values()]
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-j2", *outs, "--configfile",
                           "configs/tests/pipeline_ci.yaml"], cwd=work, capture_output=True, text=True, timeout=1500)
    assert proc.returncode == 0, proc.stderr[-4000:]
    ds = open_table(work / outs[0])
    assert ds.sizes["realization"] == 3
    np.testing.assert_array_equal(ds["realization"].values, [1.0, 2.0, 3.0])
    r = ds["probe_resistance"].sel(mode="uniaxial")
    # the packings differ: the realizations give different probe-2 resistances
    assert float(r.sel(probe="probe2").std("realization").max()) > 0
    for v in ("probe_resistance", "reaction_force", "yarn_resistance"):
        assert (ds[f"{v}_q05"] <= ds[f"{v}_mean"] + 1e-15).all() and (ds[f"{v}_mean"] <= ds[f"{v}_q95"] + 1e-15).all()
    text = (work / L.ensemble_report_outputs(run)["report"]).read_text()
    assert "ensemble of 3 realizations" in text and "probe2" in text
    for k in ("probe_resistance", "reaction_force", "network"):
        assert (work / L.ensemble_report_outputs(run)[k]).stat().st_size > 10_000
