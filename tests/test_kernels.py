"""Compiled kernels (rve.kernels, docs/kernels.md) against the numpy reference, the kernel
switch RVE_KERNELS, exact tangents of both paths by finite differences, and the union
sparsity pattern (structure against a brute-force construction; reuse on an unchanged
pair set)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from rve.kernels import kernels_mode, numba_available, use_numba

needs_numba = pytest.mark.skipif(not numba_available(), reason="numba not installed")
PATHS = ["numpy", pytest.param("numba", marks=needs_numba)]
RTOL = 1e-12


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


# ---------------------------------------------------------------------------- the switch
def test_kernel_switch(monkeypatch):
    monkeypatch.setenv("RVE_KERNELS", "numpy")
    assert kernels_mode() == "numpy" and not use_numba()
    monkeypatch.setenv("RVE_KERNELS", "auto")
    assert use_numba() == numba_available()
    monkeypatch.delenv("RVE_KERNELS")
    assert kernels_mode() == "auto"
    monkeypatch.setenv("RVE_KERNELS", "fortran")
    with pytest.raises(ValueError):
        use_numba()
    # without numba (simulated): auto falls back to numpy, numba is an error
    import rve.kernels.select as sel

    monkeypatch.setattr(sel, "_AVAILABLE", False)
    monkeypatch.setenv("RVE_KERNELS", "auto")
    assert not use_numba()
    monkeypatch.setenv("RVE_KERNELS", "numba")
    with pytest.raises(ImportError):
        use_numba()


def test_model_runs_on_the_numpy_path_without_numba(monkeypatch):
    """With numba unavailable, auto assembles on the numpy path (the compiled modules are
    never imported by it)."""
    import rve.kernels.select as sel

    monkeypatch.setattr(sel, "_AVAILABLE", False)
    monkeypatch.setenv("RVE_KERNELS", "auto")
    sysm, x = _mech_contact_system()
    F, Fx, Fw = sysm.evaluate(x, np.zeros(sysm.n), 0.0)
    assert np.isfinite(F).all() and Fx.nnz > 0 and sysm.energy(x) > 0


# ---------------------------------------------------------------------------- beam kernel
def _beam(order=1, ne=5, curved=True, seed=0):
    from rve.fem.basis import BeamBasis
    from rve.fem.mesh import fibril_mesh, straight_fibril

    fib = straight_fibril([0, 0, 0], [2.0, 0.3, -0.2], 0.15, "a")
    mesh = fibril_mesh([fib], ne, order)
    basis = BeamBasis(mesh, disk_points=4)
    rng = np.random.default_rng(seed)
    X = mesh.X0 + (rng.normal(size=mesh.X0.shape) * 0.02 if curved else 0.0)
    U = basis.element_values(X)
    return basis, U, rng


@needs_numba
@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("lam", [0.0, 0.7])
def test_beam_kernel_matches_numpy(order, lam):
    from rve.kernels.beam import neo_hookean_element_forces as compiled
    from rve.physics.beam_forms import neo_hookean_element_forces as reference

    basis, U, rng = _beam(order)
    E, nq = basis.W.shape
    mu = 0.42 * (1.0 + 0.3 * rng.random((E, nq)))  # per quadrature point (thermal softening)
    for jac in (True, False):
        R0, K0, d0 = reference(basis, U, mu, lam, jac, jac)
        R1, K1, d1 = compiled(basis.D, basis.W, U, mu, lam, jac, jac)
        assert _rel(R1, R0) < RTOL
        if jac:
            assert _rel(K1, K0) < RTOL and _rel(d1, d0) < RTOL
        else:
            assert K1 is None and d1 is None


# ---------------------------------------------------------------------------- contact kernel
def _random_pairs(P=40, G=4, seed=1, nodes=60):
    rng = np.random.default_rng(seed)
    r = rng.normal(size=(nodes, 3)) * 0.2
    npl = rng.integers(0, nodes, size=(P, 2))
    nmi = rng.integers(0, nodes, size=(P, 2))
    nmi[0, 1] = nmi[0, 0]  # a zero-length - chord
    sp_ = np.broadcast_to((np.arange(G) + 0.5) / G, (P, G)).copy()
    gr = rng.uniform(0.1, 0.4, size=P)
    sm = rng.random((P, G))
    w = rng.uniform(0.05, 0.2, size=P)
    return r, npl, nmi, sp_, gr, sm, w


@needs_numba
@pytest.mark.parametrize("recompute", [True, False])
@pytest.mark.parametrize("onset", [0.0, 0.03])
def test_contact_kernel_matches_numpy(recompute, onset):
    from rve.kernels.contact import chord_gaps as cgaps, penalty_forms
    from rve.physics.contact_forms import chord_gaps, chord_geometry, penalty_forces

    r, npl, nmi, sp_, gr, sm, w = _random_pairs()
    Ps = 50.0
    s_minus = None if recompute else sm
    ends = lambda sel: (r[npl[sel, 0]], r[npl[sel, 1]], r[nmi[sel, 0]], r[nmi[sel, 1]])  # noqa: E731
    g_ref = chord_gaps(*ends(slice(None)), sp_, gr, s_minus)
    assert _rel(cgaps(r, npl, nmi, sp_, gr, s_minus, recompute), g_ref) < RTOL
    act_ref = np.flatnonzero((g_ref > 0.0).any(axis=1))
    assert 0 < act_ref.size < len(gr)
    for jac in (True, False):
        act, R, K = penalty_forms(r, npl, nmi, sp_, gr, s_minus, recompute, w, Ps, onset, jac)
        np.testing.assert_array_equal(act, act_ref)
        geo = chord_geometry(*ends(act), sp_[act], gr[act], None if recompute else sm[act])
        R0, K0 = penalty_forces(geo, w[act], Ps, jac, onset)
        assert _rel(R, R0) < RTOL
        if jac:
            assert _rel(K, K0) < RTOL
        else:
            assert K is None


# ---------------------------------------------------------------------------- EMF kernel
@needs_numba
@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("back_emf,lorentz,joule,seebeck", [
    (True, True, True, 0.3), (False, True, True, 0.0), (True, False, True, 0.2), (True, True, False, 0.0),
    (False, False, False, 0.1)])
def test_emf_kernel_matches_numpy(order, back_emf, lorentz, joule, seebeck):
    from rve.fem.basis import BeamBasis
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.kernels.electric import coupled_forms as compiled
    from rve.physics.electric_forms import coupled_forms, emf, section_ops

    mesh = fibril_mesh([straight_fibril([-1, 0, 0], [1, 0.1, 0], 0.15, "w")], 6, order)
    basis = BeamBasis(mesh, disk_points=4)
    ops = section_ops(basis)
    rng = np.random.default_rng(order)
    U = basis.element_values(mesh.X0 + rng.normal(size=mesh.X0.shape) * 0.02)
    Uv = basis.element_values(rng.normal(size=mesh.X0.shape))
    E, nn = mesh.conn.shape
    Te, Ve = rng.normal(size=(E, nn)), rng.normal(size=(E, nn))
    B = np.array([0.3, -0.5, 0.8])
    sigma = 10.0 * (1.0 + rng.random(E))
    for jac in (True, False):
        m = emf(ops, U, Uv, Te, Ve, B, seebeck=seebeck, back_emf=back_emf)
        R0, J0 = coupled_forms(ops, m, sigma, B, lorentz=lorentz, joule=joule, want_tangent=jac)
        R1, J1 = compiled(ops, U, Uv, Te, Ve, B, sigma, seebeck, back_emf, lorentz, joule, jac)
        for d0, d1 in ((R0, R1), (J0, J1)) if jac else ((R0, R1),):
            assert set(d0) == set(d1)
            for k in d0:
                assert (d0[k] is None) == (d1[k] is None), k
                if d0[k] is not None:
                    assert _rel(d1[k], d0[k]) < RTOL, k
        assert (J1 is None) == (not jac)


# ---------------------------------------------------------------------------- assembled models
def _mech_contact_system(onset=0.0, recompute=True, seed=4):
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem

    R = 0.15
    fibs = [straight_fibril([-1, 0.02, 0], [1, 0.02, 0], R, "a"),
            straight_fibril([0.05, -1, -0.26], [0.05, 1, -0.26], R, "b"),
            straight_fibril([-1, 0.1, -0.27], [1, -0.1, -0.27], R, "c")]
    mesh = fibril_mesh(fibs, 5, 1)
    base = BeamModel(mesh, BeamMaterial(1.26, density=1e-3, damping=0.01))
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0 + np.random.default_rng(seed).normal(size=mesh.X0.shape) * 0.01
    params = ContactParams(penalty=50.0, n_gp=4, margin=0.1, onset=onset, recompute_closest=recompute)
    return ContactSystem(base, params, x), x


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("onset,recompute", [(0.0, True), (0.1, True), (0.0, False)])
def test_mechanics_contact_tangent_fd_both_paths(monkeypatch, path, onset, recompute):
    monkeypatch.setenv("RVE_KERNELS", path)
    sysm, x = _mech_contact_system(onset, recompute)
    w = np.zeros(sysm.n)
    F, Fx, _ = sysm.evaluate(x, w, 0.0)
    assert sysm.contact_state(x)["active_points"] > 0
    Fxd = Fx.toarray()
    h = 1e-7
    cols = np.flatnonzero(sysm.mech)
    scale = 1e-6 * (1 + np.abs(Fxd).max())
    for c in cols:
        xp, xm = x.copy(), x.copy()
        xp[c] += h
        xm[c] -= h
        fd = (sysm.evaluate(xp, w, 0, False)[0] - sysm.evaluate(xm, w, 0, False)[0]) / (2 * h)
        np.testing.assert_allclose(Fxd[:, c], fd, rtol=1e-5, atol=scale)
    # the residual is the gradient of the energy
    d = np.random.default_rng(0).normal(size=sysm.n) * 1e-2
    fd = (sysm.energy(x + 1e-6 * d) - sysm.energy(x - 1e-6 * d)) / 2e-6
    assert abs(fd - F @ d) <= 1e-6 * max(1.0, abs(F @ d))


@pytest.mark.parametrize("path", PATHS)
def test_coupled_and_contact_fd_tests_pass_on_both_paths(monkeypatch, path):
    """The FD Jacobian tests of the coupled terms and the T/V contact system, run with the
    kernel path forced (tests/test_coupled_jacobians.py, tests/test_contact_jacobians.py)."""
    import test_contact_jacobians as tcj
    import test_coupled_jacobians as tco

    monkeypatch.setenv("RVE_KERNELS", path)
    for case in list(tco.CASES)[:3]:
        tco.test_coupled_tangents_match_fd(case, 1, True)
    tco.test_feedback_from_temperature()
    tcj.test_contact_system_jacobians(1, True)
    tcj.test_contact_system_energy_gradient()


@needs_numba
@pytest.mark.parametrize("elements", [12])
def test_weave_numba_equals_numpy(monkeypatch, elements):
    """The 80-fibril thesis plain weave: F, Fx, Fw and the energy of both paths agree to
    1e-12 (relative to the largest entry) at a perturbed designed state, with and without
    the onset."""
    from rve.config.loader import load_config
    from rve.scenes.fabric_relax import setup
    from pathlib import Path

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs/scenes/plain_weave_relax.yaml",
                      [f"mesh.elements={elements}"])
    _, system, x = setup(cfg)
    x = x + 0.01 * np.random.default_rng(3).standard_normal(x.size) * system.mech
    w = np.zeros(system.n)
    for onset in (0.0, 0.05):
        system.set_onset(onset)
        out = {}
        for path in ("numpy", "numba"):
            monkeypatch.setenv("RVE_KERNELS", path)
            F, Fx, Fw = system.evaluate(x, w, 0.0, True)
            out[path] = (F, Fx, Fw, system.evaluate(x, w, 0.0, False)[0], system.energy(x))
        a, b = out["numpy"], out["numba"]
        assert system.active_pairs(x).size > 1000
        assert np.array_equal(a[1].indices, b[1].indices) and np.array_equal(a[1].indptr, b[1].indptr)
        assert _rel(b[0], a[0]) < RTOL and _rel(b[3], a[3]) < RTOL
        assert _rel(b[1].data, a[1].data) < RTOL and _rel(b[2].data, a[2].data) < RTOL
        assert abs(b[4] - a[4]) <= RTOL * abs(a[4])


def test_weave_kernels_give_the_same_bits_on_one_and_two_threads():
    """The compiled kernels split their elements / pairs over the job's threads
    (rve.threads.run_chunked): F, Fx and the energy of the 80-fibril weave are bitwise the
    same on 1 and 2 threads, and 2 threads really split (enough elements and pairs)."""
    from pathlib import Path

    from rve.config.loader import load_config
    from rve.kernels import beam, contact
    from rve.scenes.fabric_relax import setup
    from rve.threads import linear_threads

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs/scenes/plain_weave_relax.yaml",
                      ["mesh.elements=12"])
    _, system, x = setup(cfg)
    x = x + 0.01 * np.random.default_rng(4).standard_normal(x.size) * system.mech
    w = np.zeros(system.n)
    assert system.mesh.n_elements >= 2 * beam.MIN_CHUNK and system.map.n_pairs >= 2 * contact.MIN_CHUNK
    out = {}
    for threads in (1, 2):
        with linear_threads(threads):
            F, Fx, _ = system.evaluate(x, w, 0.0, True)
            out[threads] = (F, Fx.data, system.energy(x), system.gaps(x))
    for a, b in zip(out[1], out[2]):
        assert np.array_equal(a, b)


def test_run_chunked_covers_the_range_once_and_raises():
    from rve.threads import linear_threads, run_chunked

    for threads, n in ((1, 1000), (2, 1000), (2, 7), (3, 1001)):
        hits = np.zeros(n, int)

        def fn(a, b):
            hits[a:b] += 1

        with linear_threads(threads):
            run_chunked(n, fn, min_chunk=2)
        assert np.all(hits == 1)

    def bad(a, b):
        raise RuntimeError(f"chunk {a}:{b}")

    with linear_threads(2), pytest.raises(RuntimeError, match="chunk"):
        run_chunked(100, bad, min_chunk=10)


# ---------------------------------------------------------------------------- union pattern
def _brute_union(pattern, local, comps, b):
    n = pattern.n
    rows = np.repeat(np.arange(n), np.diff(pattern.indptr))
    g = (np.asarray(local)[:, :, None] * b + np.asarray(comps)[None, None, :]).reshape(local.shape[0], -1)
    pr = np.repeat(g, g.shape[1], axis=1).ravel()
    pc = np.tile(g, (1, g.shape[1])).ravel()
    A = sp.csr_matrix((np.ones(rows.size + pr.size), (np.concatenate([rows, pr]),
                                                     np.concatenate([pattern.indices, pc]))), shape=(n, n))
    A.sum_duplicates()
    A.sort_indices()
    return A


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("dense", [True, False])
def test_union_pattern_structure_and_slots(dense, path, monkeypatch):
    """The union structure against a brute-force COO construction, on the numpy reference and
    on the compiled index kernels (rve.kernels.index)."""
    from rve.fem.assembly import DofLayout, ElementPattern, UnionPattern

    monkeypatch.setenv("RVE_KERNELS", path)

    rng = np.random.default_rng(5)
    nodes = 40
    conn = np.stack([np.arange(nodes - 1), np.arange(1, nodes)], axis=1)
    conn = conn[np.arange(nodes - 1) % 10 != 9]  # 4 fibrils of 10 nodes
    layout = DofLayout(nodes, ("mech", "T", "V"))
    pat = ElementPattern(layout, conn)
    local = np.concatenate([conn[rng.integers(0, len(conn), 50)], conn[rng.integers(0, len(conn), 50)]], axis=1)
    comps = np.array([0, 1, 2, 9, 10])
    monkeypatch.setattr(UnionPattern, "dense_limit", 2**25 if dense else 0)
    u = UnionPattern(pat, local, comps)
    ref = _brute_union(pat, local, comps, layout.block)
    np.testing.assert_array_equal(u.indptr, ref.indptr)
    np.testing.assert_array_equal(u.indices, ref.indices)
    # base entries and pair slots land on their (row, col) in the union
    rows_u = np.repeat(np.arange(u.n), np.diff(u.indptr))
    rows_p = np.repeat(np.arange(pat.n), np.diff(pat.indptr))
    np.testing.assert_array_equal(rows_u[u.base_map], rows_p)
    np.testing.assert_array_equal(u.indices[u.base_map], pat.indices)
    m = u.gdofs.shape[1]
    np.testing.assert_array_equal(rows_u[u.slots].reshape(-1, m, m), np.repeat(u.gdofs[:, :, None], m, axis=2))
    np.testing.assert_array_equal(u.indices[u.slots].reshape(-1, m, m), np.repeat(u.gdofs[:, None, :], m, axis=1))
    # a second union on the same element pattern (its node-pair tables reused when dense)
    local2 = np.concatenate([conn[rng.integers(0, len(conn), 30)], conn[rng.integers(0, len(conn), 30)]], axis=1)
    u2 = UnionPattern(pat, local2, comps)
    ref2 = _brute_union(pat, local2, comps, layout.block)
    np.testing.assert_array_equal(u2.indptr, ref2.indptr)
    np.testing.assert_array_equal(u2.indices, ref2.indices)
    rows_u2 = np.repeat(np.arange(u2.n), np.diff(u2.indptr))
    np.testing.assert_array_equal(rows_u2[u2.slots].reshape(-1, m, m), np.repeat(u2.gdofs[:, :, None], m, axis=2))
    assert dense == ("_union_tables" in pat.__dict__)


def test_restricted_union_hands_out_the_kept_entries_only():
    """``UnionPattern.restrict``: a matrix on union data is handed out on the kept entries, in
    canonical CSR, equal to the whole union's where the left-out entries are zero; None
    restores the whole union."""
    from rve.fem.assembly import DofLayout, ElementPattern, UnionPattern

    rng = np.random.default_rng(7)
    nodes = 40
    conn = np.stack([np.arange(nodes - 1), np.arange(1, nodes)], axis=1)
    conn = conn[np.arange(nodes - 1) % 10 != 9]
    pat = ElementPattern(DofLayout(nodes, ("mech",)), conn)
    local = np.concatenate([conn[rng.integers(0, len(conn), 30)], conn[rng.integers(0, len(conn), 30)]], axis=1)
    u = UnionPattern(pat, local, np.arange(6))
    data = rng.normal(size=u.nnz)
    keep = rng.random(u.nnz) < 0.6
    keep[u.base_map] = True
    whole = u.csr(np.where(keep, data, 0.0))
    u.restrict(keep)
    kept = u.csr(data)
    assert kept.nnz == keep.sum() and kept.has_canonical_format
    assert (kept.toarray() == whole.toarray()).all()
    assert u.csr(data).indices is kept.indices          # one structure for every matrix
    u.restrict(None)
    assert u.csr(data).nnz == u.nnz


def test_rebuild_keeps_the_union_when_the_pairs_are_unchanged():
    sysm, x = _mech_contact_system()
    ca = sysm.assembler
    u, M = ca.union, sysm.mass()
    F0, Fx0, _ = sysm.evaluate(x, np.zeros(sysm.n), 0.0)
    sysm.rebuild(x + 1e-6 * sysm.mech)  # same pairs
    assert ca.union is u and sysm.mass() is M and ca.reused == 1
    F1, Fx1, _ = sysm.evaluate(x, np.zeros(sysm.n), 0.0)
    assert Fx1.indices is Fx0.indices and Fx1.indptr is Fx0.indptr
    np.testing.assert_array_equal(F1, F0)
    np.testing.assert_array_equal(Fx1.data, Fx0.data)
    # fibrils moved apart: other pairs, a new structure
    xn = sysm.nodal(x.copy())
    xn[sysm.mesh.fibril_nodes(2), 2] -= 1.0
    sysm.rebuild(xn.reshape(-1))
    assert ca.union is not u and ca.reused == 1


# ---------------------------------------------------------------------------- index kernels
@needs_numba
def test_sorted_positions_is_the_clipped_searchsorted():
    from rve.kernels.index import sorted_positions

    rng = np.random.default_rng(11)
    ref = np.unique(rng.integers(0, 10_000, 3_000))
    for keys in (np.sort(rng.choice(ref, 500, replace=False)),                 # all inside
                 np.unique(rng.integers(-50, 10_100, 800)),                     # outside, below and above
                 np.zeros(0, np.int64), ref.copy()):
        pos, ok = sorted_positions(ref, keys.astype(np.int64))
        assert ok
        np.testing.assert_array_equal(pos, np.minimum(np.searchsorted(ref, keys), ref.size - 1))
    _, ok = sorted_positions(ref, np.array([5, 3], np.int64))  # not sorted: the caller falls back
    assert not ok


@needs_numba
def test_upper_entries_kernel_equals_numpy(monkeypatch):
    from rve.solvers.backends.pardiso import _upper_entries

    A = sp.random(300, 300, density=0.05, random_state=np.random.default_rng(12), format="csr")
    A = (A + A.T + sp.eye(300)).tocsr()
    A.sort_indices()
    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        out[path] = _upper_entries(A)
    for a, b in zip(out["numpy"], out["numba"]):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    keys, keep = out["numpy"]
    rows = np.repeat(np.arange(300), np.diff(A.indptr))
    assert np.all(A.indices[keep] >= rows[keep]) and keep.size == sp.triu(A).nnz


@needs_numba
def test_pair_data_gives_the_same_bits_as_bincount_and_add(monkeypatch):
    """``UnionPattern.pair_data`` (one compiled scatter) against the numpy reference
    (``np.bincount`` of the pair slots, then the element matrix added): the same sums in the
    same order, bitwise; and a matrix off the base pattern takes the reference path."""
    from rve.fem.assembly import DofLayout, ElementPattern, UnionPattern

    rng = np.random.default_rng(13)
    nodes = 40
    conn = np.stack([np.arange(nodes - 1), np.arange(1, nodes)], axis=1)
    conn = conn[np.arange(nodes - 1) % 10 != 9]
    layout = DofLayout(nodes, ("mech",))
    pat = ElementPattern(layout, conn)
    local = np.concatenate([conn[rng.integers(0, len(conn), 60)], conn[rng.integers(0, len(conn), 60)]], axis=1)
    u = UnionPattern(pat, local, np.arange(3))
    act = np.sort(rng.choice(local.shape[0], 35, replace=False))
    K = rng.standard_normal((act.size, u.slots.shape[1]))
    A = pat.assemble_csr(rng.standard_normal((len(conn), 18, 18)))
    ref = u.add(np.bincount(u.slots[act].ravel(), weights=K.ravel(), minlength=u.nnz), A)
    monkeypatch.setenv("RVE_KERNELS", "numba")
    assert np.array_equal(u.pair_data(act, K, A), ref)
    monkeypatch.setenv("RVE_KERNELS", "numpy")
    assert np.array_equal(u.pair_data(act, K, A), ref)
    monkeypatch.setenv("RVE_KERNELS", "numba")
    B = u.csr(rng.standard_normal(u.nnz))  # on the union, not the base pattern
    ref_b = u.add(np.bincount(u.slots[act].ravel(), weights=K.ravel(), minlength=u.nnz), B)
    assert np.array_equal(u.pair_data(act, K, B), ref_b)


@needs_numba
def test_index_kernels_build_the_same_union_on_the_weave(monkeypatch):
    """The 12-element weave's union structure is the very same integers with the index
    kernels as on the numpy reference, and its tangent agrees to the contact kernels' rounding."""
    from pathlib import Path

    from rve.config.loader import load_config
    from rve.fem.assembly import UnionPattern
    from rve.scenes.fabric_relax import setup

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs/scenes/plain_weave_relax.yaml",
                      ["mesh.elements=12"])
    _, system, x = setup(cfg)
    x = x + 0.01 * np.random.default_rng(14).standard_normal(x.size) * system.mech
    local, comps = system.assembler._local, system.assembler._comps
    w = np.zeros(system.n)
    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        u = UnionPattern(system.assembler.elements.pattern, local, comps)
        system.assembler.union = u
        system.assembler._fw_cache = None
        out[path] = (u, system.evaluate(x, w, 0.0, True)[1])
    (ua, Ja), (ub, Jb) = out["numpy"], out["numba"]
    for name in ("indptr", "indices", "slots", "base_map", "gdofs"):
        a, b = getattr(ua, name), getattr(ub, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert np.array_equal(Ja.indices, Jb.indices) and _rel(Jb.data, Ja.data) < RTOL  # the contact kernels' rounding


@needs_numba
def test_min_det_kernel_equals_the_reference(monkeypatch):
    """The compiled admissibility test (``rve.kernels.beam.min_det_F``) gives
    ``BeamBasis.min_det_F`` to rounding on the 80-fibril weave at a perturbed state, and
    ``BeamModel.admissible`` says the same on both paths, also where an element is folded
    (det F < 0 at some point)."""
    from pathlib import Path

    from rve.config.loader import load_config
    from rve.kernels.beam import min_det_F
    from rve.scenes.fabric_relax import setup

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs/scenes/plain_weave_relax.yaml",
                      ["mesh.elements=12"])
    _, system, x = setup(cfg)
    model = system.base
    rng = np.random.default_rng(5)
    for amp in (0.0, 0.01, 0.3):
        y = x + amp * rng.standard_normal(x.size) * system.mech
        ref = model.basis.min_det_F(model.nodal(y))
        got = min_det_F(model.basis.D, model.nodal(y), model.basis.mesh.conn)
        assert abs(got - ref) <= 1e-13 * max(1.0, abs(ref))
        verdict = {}
        for path in ("numpy", "numba"):
            monkeypatch.setenv("RVE_KERNELS", path)
            verdict[path] = model.admissible(y)
        assert verdict["numpy"] == verdict["numba"] == (ref > 0.0)
    # a folded element: one director of one node reversed
    y = x.copy()
    model.nodal(y)[0, 3:6] *= -1.0
    ref = model.basis.min_det_F(model.nodal(y))
    assert ref < 0.0
    assert abs(min_det_F(model.basis.D, model.nodal(y), model.basis.mesh.conn) - ref) <= 1e-13 * abs(ref)
    monkeypatch.setenv("RVE_KERNELS", "numba")
    assert not model.admissible(y)
