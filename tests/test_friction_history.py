"""The friction history through a checkpoint: the netCDF state carries it, and a run
resumed from a recorded history (with map rebuilds between the steps) is bit-identical to
the uninterrupted one; without the history it is not."""
import numpy as np

from rve.config.loader import load_config
from rve.scenes import friction_crossing
from rve.scenes.frictional import initial_state, step

CFG = "configs/scenes/crossing.yaml"


def _indented(cfg):
    system, parts = friction_crossing.setup(cfg)
    x = initial_state(system.mesh, system.layout)
    z0 = x[parts["z"]].copy()
    for k in (1, 2):
        x[parts["z"]] = z0 - cfg.geometry.indentation * k / 2
        x, _, _ = step(system, x, 0.0, cfg.newton, "t", "indent", k)
    return system, parts, x


def _steps(system, parts, x, cfg, us):
    for k, u in enumerate(us):
        system.rebuild(x)
        x[parts["x"]] = u
        x, _, _ = step(system, x, 0.0, cfg.newton, "t", "cycle", k)
    return x


def test_resume_from_record_is_bit_identical():
    cfg = load_config(CFG)
    us = friction_crossing.load_path(0.1, 4)[:10]     # stick, slip, reversal
    system, parts, x = _indented(cfg)
    full = _steps(system, parts, x.copy(), cfg, us)
    system, parts, x = _indented(cfg)
    mid = _steps(system, parts, x, cfg, us[:5])
    rec, d = system.term.friction.record(), system.term.friction.dissipated
    fresh, parts2 = friction_crossing.setup(cfg)
    fresh.rebuild(mid)
    fresh.term.friction.seed(rec)
    resumed = _steps(fresh, parts2, mid.copy(), cfg, us[5:])
    assert np.array_equal(full, resumed)
    assert fresh.term.friction.dissipated > d > 0
    other, parts3 = friction_crossing.setup(cfg)     # the same state without its history
    other.rebuild(mid)
    assert not np.array_equal(full, _steps(other, parts3, mid.copy(), cfg, us[5:]))


def test_checkpoint_carries_the_friction_history(tmp_path):
    import xarray as xr

    from rve.config.rve import RVEConfig
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.checkpoint import State, load_state, write_state

    cfg = RVEConfig(scene="rve", fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6})
    fab, mesh = fabric_and_mesh(cfg)
    x0 = fab.initial_state(mesh).reshape(-1, 9)
    rng = np.random.default_rng(1)
    rec = {"keys": rng.integers(0, 50, size=(7, 6)), "s_bar": rng.random(7), "anchor": rng.normal(size=(7, 3)),
           "dissipated": 0.125}
    path = write_state(tmp_path / "f.nc", State(x=x0, w=np.zeros_like(x0), origin=x0, kind="relaxed", friction=rec),
                       fab, mesh)
    back = load_state(path).friction
    for k in ("keys", "s_bar", "anchor"):
        assert np.array_equal(back[k], rec[k])
    assert back["dissipated"] == rec["dissipated"]
    plain = write_state(tmp_path / "p.nc", State(x=x0, w=np.zeros_like(x0), origin=x0, kind="relaxed"), fab, mesh)
    assert load_state(plain).friction is None
    with xr.open_dataset(plain) as ds:
        assert not any(v.startswith("contact_friction") for v in ds.variables)
        assert "friction_dissipated" not in ds.attrs


def test_row_groups_are_the_indices_of_unique_rows():
    """``row_groups`` (the grouping of the history's sharing along fibrils) gives the same
    group indices as ``np.unique(axis=0, return_inverse=True)``."""
    from rve.model.terms.friction import row_groups

    rng = np.random.default_rng(3)
    keys = rng.integers(-2, 4, size=(3000, 6))
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    np.testing.assert_array_equal(row_groups(keys), inv.ravel())
    assert row_groups(np.zeros((0, 6), np.int64)).size == 0
