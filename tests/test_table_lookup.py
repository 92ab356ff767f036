"""Pointwise lookups of many macro points (``rve.tables.lookup``) on a table in memory and on
the same table opened lazily with dask chunks (``open_table(path, chunks=...)``)."""
from __future__ import annotations

import numpy as np
import pytest

from rve.tables import build_table, interpolate, lookup, open_table, write_table

RADII = [0.10, 0.12, 0.15]
CONDUCTANCES = [0.5, 1.0]
STRAINS = [0.0, 0.05, 0.1]


def _count(strain, radius, conductance):
    # linear in each coordinate: multilinear interpolation reproduces it between the samples
    return 100.0 + 400.0 * strain - 200.0 * radius + 30.0 * conductance


def _records():
    rng = np.random.default_rng(3)
    out = []
    for r in RADII:
        for g in CONDUCTANCES:
            for s in STRAINS:
                probes = {p: {"voltage": 1.0, "current": {"+": c, "-": -c}, "temperature_max": float(rng.random()),
                              "temperature_mean": 0.1}
                          for p, c in zip(("probe1", "probe2", "probe3", "probe4"), 0.5 + rng.random(4))}
                out.append({"mode": "uniaxial", "strain": s, "params": {"fibril_radius": r, "contact_conductance": g},
                            "reaction_force": {side: rng.normal(size=3).tolist() for side in
                                               ("warp-", "warp+", "weft-", "weft+")},
                            "contact_count": _count(s, r, g), "equilibrium_residual": 1e-10, "converged": True,
                            "probes": probes})
    return out


@pytest.fixture(scope="module")
def table_path(tmp_path_factory):
    ds = build_table(_records(), fabric={"kind": "plain", "n_warp": 2, "n_weft": 2}, config={},
                     swept=["fibril_radius", "contact_conductance"])
    return write_table(ds, tmp_path_factory.mktemp("lookup") / "table.nc")


def _points(n=500, seed=0):
    rng = np.random.default_rng(seed)
    return {"strain": rng.uniform(0, 0.1, n), "fibril_radius": rng.uniform(0.10, 0.15, n),
            "contact_conductance": rng.uniform(0.5, 1.0, n)}


def test_lookup_reproduces_a_multilinear_field_between_the_samples(table_path):
    pts = _points()
    out = lookup(open_table(table_path), "uniaxial", variables=["contact_count"], **pts)
    expected = _count(pts["strain"], pts["fibril_radius"], pts["contact_conductance"])
    np.testing.assert_allclose(out["contact_count"].values, expected, rtol=1e-13)


def test_lookup_at_stored_points_returns_stored_values(table_path):
    ds = open_table(table_path)
    r, g, s = np.meshgrid(RADII, CONDUCTANCES, STRAINS, indexing="ij")
    out = lookup(ds, "uniaxial", strain=s.ravel(), fibril_radius=r.ravel(), contact_conductance=g.ravel(),
                 variables=["probe_resistance", "reaction_force"])
    for name in ("probe_resistance", "reaction_force"):
        stored = ds[name].sel(mode="uniaxial").transpose("fibril_radius", "contact_conductance", "strain", ...)
        np.testing.assert_array_equal(out[name].values, stored.values.reshape((-1,) + stored.shape[3:]))


def test_lookup_equals_interpolate_point_by_point(table_path):
    ds = open_table(table_path)
    pts = _points(n=20, seed=1)
    out = lookup(ds, "uniaxial", variables=["probe_resistance"], **pts)
    for i in range(20):
        one = interpolate(ds, pts["strain"][i], mode="uniaxial", fibril_radius=pts["fibril_radius"][i],
                          contact_conductance=pts["contact_conductance"][i])
        np.testing.assert_allclose(out["probe_resistance"].values[i], one["probe_resistance"].values, rtol=1e-12)


def test_lazily_opened_table_gives_the_same_bits(table_path):
    pts = _points()
    names = ["probe_resistance", "reaction_force", "temperature_rise_max"]
    eager = lookup(open_table(table_path), "uniaxial", variables=names, **pts)
    lazy_ds = open_table(table_path, chunks={"strain": -1, "fibril_radius": 2, "contact_conductance": 1})
    assert lazy_ds["probe_resistance"].chunks is not None  # dask arrays, not loaded
    lazy = lookup(lazy_ds, "uniaxial", variables=names, **pts).compute()
    for name in names:
        np.testing.assert_array_equal(lazy[name].values, eager[name].values, err_msg=name)


def test_a_point_outside_the_table_names_the_range(table_path):
    ds = open_table(table_path)
    with pytest.raises(ValueError, match=r"fibril_radius 0.2 is outside the table range \[0.1, 0.15\]"):
        lookup(ds, "uniaxial", strain=0.05, fibril_radius=0.2, contact_conductance=0.7)
    with pytest.raises(ValueError, match="strain 0.2 is outside"):
        lookup(ds, "uniaxial", strain=0.2, fibril_radius=0.12, contact_conductance=0.7)
