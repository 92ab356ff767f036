"""The impact's per-step balances from the residual the last stage's Newton left behind equal
the balances that evaluate the residual again (rve.model.balances.ImpactBalances)."""
import numpy as np

from rve.config.loader import load_config
from rve.model.balances import ImpactBalances
from rve.scenes import impact

TINY = ["geometry.n_warp=4", "geometry.n_weft=4", "geometry.span=6.35 mm", "mesh.elements=8",
        "projectile.radius=2 mm", "time.t_end=0.02 ms", "time.steps=40", "relaxation.steps=5",
        "relaxation.t_end=0.2 ms", "field.magnitude=0.001 kT"]


def _close(a, b, scale):
    return np.all(np.abs(np.asarray(a, float) - np.asarray(b, float)) <= 1e-11 * scale + 1e-300)


def test_reused_residual_balances_equal_the_recomputed_ones(monkeypatch):
    pairs = []
    call = ImpactBalances.__call__

    def both(self, x, w, t, T, F=None):
        b = call(self, x, w, t, T, F)
        if F is not None:
            pairs.append((b, call(self, x, w, t, T)))
        return b

    monkeypatch.setattr(ImpactBalances, "__call__", both)
    cfg = load_config("configs/scenes/impact.yaml", TINY)
    x, info = impact.relax(cfg)
    s = impact.solve(cfg, x_start=x, relax_info=info, record=False).summary
    # every accepted step reused the stage residual (the initial state evaluates it)
    assert s["balance_residuals_reused"] == s["steps_accepted"] == len(pairs) == 40
    assert s["sphere_pairs_active_max"] > 0   # the projectile is on the fabric
    keys = list(pairs[0][1])
    for k in keys:
        ref = np.array([r[k] for _, r in pairs], float)
        new = np.array([b[k] for b, _ in pairs], float)
        scale = max(float(np.abs(ref).max()), 1e-300)
        assert _close(new, ref, scale), k
    # the terms the residual enters are not trivially zero
    for k in ("current_out", "force_clamp_static"):
        assert np.abs(np.array([r[k] for _, r in pairs], float)).max() > 0, k


def test_stage_mass_products_on_the_nonzeros_give_the_same_bits():
    """The stepper's products M w (``DirkStepper.Mv``: the union-pattern mass without its
    stored zeros) are bitwise those of the union-pattern mass, with far fewer entries."""
    from rve.model import RowScaledSystem
    from rve.solvers.dirk import DirkStepper, sdirk

    cfg = load_config("configs/scenes/impact.yaml", TINY)
    problem = impact.setup(cfg, "impact")
    sysm = problem.system
    x = problem.x0.copy()
    sysm.rebuild(x)
    rs = RowScaledSystem(sysm, sysm.row_scales(cfg.time.t_end / cfg.time.steps, x, np.zeros(sysm.n)))
    st = DirkStepper(rs, sdirk(2), {"atol": 1e-9, "rtol": 1e-12, "max_iter": 20})
    assert st.Mv.nnz < st.M.nnz
    rng = np.random.default_rng(1)
    for _ in range(3):
        w = rng.standard_normal(sysm.n)
        assert np.array_equal(st.Mv @ w, st.M @ w)


def test_impact_union_by_the_index_kernels_equals_the_numpy_one(monkeypatch):
    """ImpactSystem's union of fabric, sphere-pair and projectile entries built with the
    compiled index loops (rve.kernels.index.copy_rows / csr_positions / rows_increasing)
    has exactly the structure, fabric positions and sphere-pair positions of the numpy
    reference, at a state with the projectile on the fabric; an entry outside it raises."""
    import pytest

    from rve.kernels import numba_available

    if not numba_available():
        pytest.skip("numba not installed")
    cfg = load_config("configs/scenes/impact.yaml", TINY)
    problem = impact.setup(cfg, "impact")
    sysm = problem.system
    x = problem.x0.copy()
    # push the projectile onto the fabric so that sphere pairs exist
    xp = sysm.projectile.nodal(sysm.split(x)[1])
    xp[:, 2] -= 0.5
    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        sysm.rebuild(x)
        fab_pos = next(iter(sysm._maps.values()))[2]
        rows = np.repeat(np.arange(sysm.n), np.diff(sysm.indptr))
        probe = sysm._positions_of(rows[::7], sysm.indices[::7])
        out[path] = (sysm.indptr.copy(), sysm.indices.copy(), fab_pos.copy(), sysm._pos_sphere.copy(), probe)
        with pytest.raises(RuntimeError):
            sysm._positions_of(np.array([0]), np.array([sysm.n - 1]))
    assert out["numba"][3].size > 0
    for a, b in zip(out["numpy"], out["numba"]):
        assert np.array_equal(a, b)


def test_segments_not_carried_free_their_factorisations(monkeypatch):
    """A restart that does not carry the held factorisation (a checkpoint boundary) releases
    the previous segment's (JacobianReuse.release: factor and backend gone), so a run holds one
    factorisation at a time; the released objects keep their counts."""
    from rve.solvers.newton import JacobianReuse

    made = []
    init = JacobianReuse.__init__

    def record(self, *a, **k):
        init(self, *a, **k)
        made.append(self)

    monkeypatch.setattr(JacobianReuse, "__init__", record)
    cfg = load_config("configs/scenes/impact.yaml", TINY + ["time.checkpoint_every=10"])
    x, info = impact.relax(cfg)
    made.clear()
    s = impact.solve(cfg, x_start=x, relax_info=info, record=False).summary
    assert s["steps_accepted"] == 40
    assert len(made) >= 4    # one per segment (a carried one replaces the segment's own)
    assert sum(r.factorizations > 0 for r in made) >= 4    # a fresh one after every boundary
    # at the end only the last segment's factorisation is held
    assert sum(r._backend is not None or r.factor is not None for r in made) <= 1
