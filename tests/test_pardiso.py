"""The PARDISO backend (rve/solvers/pardiso.py): accuracy against SuperLU / dense solves,
inertia against eigvalsh, analysis reuse per sparsity pattern. Skipped without pypardiso
(e.g. on aarch64, where MKL has no wheel)."""
import os

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from rve.solvers.backends import pardiso

pytestmark = pytest.mark.skipif(not pardiso.available(),
                                reason=f"PARDISO unavailable: {pardiso.unavailable_reason()}")


def _rel_res(A, x, b):
    return np.linalg.norm(A @ x - b) / np.linalg.norm(b)


def random_pattern(n, density, seed):
    """A random symmetric sparsity pattern with a full diagonal (values 1)."""
    B = sp.random(n, n, density=density, random_state=seed, format="coo")
    P = (B + B.T + sp.eye(n)).tocsr()
    P.data[:] = 1.0
    return P


def spd(n=400, density=0.01, seed=0):
    rng = np.random.default_rng(seed)
    P = random_pattern(n, density, seed)
    A = P.copy()
    A.data = rng.standard_normal(A.nnz)
    A = (A + A.T) * 0.5
    A = A + sp.diags(np.asarray(abs(A).sum(axis=1)).ravel() + 1.0)  # diagonally dominant
    return A.tocsr()


def with_inertia(n=300, n_neg=37, density=0.02, seed=1):
    """Symmetric indefinite sparse matrix with exactly ``n_neg`` negative eigenvalues:
    a congruence S D Sᵀ of a diagonal D with n_neg negative entries, S sparse unit lower
    triangular (Sylvester's law of inertia)."""
    rng = np.random.default_rng(seed)
    L = sp.tril(sp.random(n, n, density=density / 4, random_state=seed), k=-1)
    S = (sp.eye(n) + L).tocsr()
    d = rng.uniform(0.5, 2.0, n)
    d[rng.choice(n, n_neg, replace=False)] *= -1.0
    A = (S @ sp.diags(d) @ S.T).tocsr()
    A = ((A + A.T) * 0.5).tocsr()
    A.sum_duplicates()  # canonical: sorted indices
    return A


@pytest.mark.parametrize("matching", [True, False])
def test_spd_solve_matches_superlu(matching):
    A = spd()
    b = np.random.default_rng(2).standard_normal(A.shape[0])
    f = pardiso.PardisoFactorization(matching=matching, check=True).factorize(A)
    x = f.solve(b)
    ref = spla.splu(A.tocsc()).solve(b)
    assert _rel_res(A, x, b) < 1e-10
    assert np.linalg.norm(x - ref) <= 1e-9 * np.linalg.norm(ref)
    assert f.negative_pivots == 0 and f.positive_pivots == A.shape[0]
    assert f.factor_nnz >= A.shape[0]


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("fmt", ["csr", "csc"])
def test_indefinite_solve_and_inertia(seed, fmt):
    n_neg = 10 + 13 * seed
    A = with_inertia(n_neg=n_neg, seed=seed)
    neg = int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))
    assert neg == n_neg  # the construction
    b = np.random.default_rng(seed).standard_normal(A.shape[0])
    f = pardiso.PardisoFactorization(check=True).factorize(A.asformat(fmt))
    x = f.solve(b)
    assert _rel_res(A, x, b) < 1e-10
    assert np.allclose(x, np.linalg.solve(A.toarray(), b), rtol=0, atol=1e-8 * np.abs(x).max())
    assert f.negative_pivots == neg
    assert f.positive_pivots == A.shape[0] - neg


def test_random_indefinite_inertia_eigvalsh():
    rng = np.random.default_rng(5)
    P = random_pattern(250, 0.03, 5)
    A = P.copy()
    A.data = rng.standard_normal(A.nnz)
    A = ((A + A.T) * 0.5 + sp.diags(rng.uniform(-2, 2, 250))).tocsr()
    ev = np.linalg.eigvalsh(A.toarray())
    assert np.abs(ev).min() > 1e-6  # not near singular: the inertia is well defined
    f = pardiso.PardisoFactorization().factorize(A)
    b = rng.standard_normal(250)
    assert _rel_res(A, f.solve(b), b) < 1e-10
    assert f.negative_pivots == int(np.count_nonzero(ev < 0))


def test_several_right_hand_sides():
    A = with_inertia(seed=4)
    B = np.random.default_rng(4).standard_normal((A.shape[0], 3))
    f = pardiso.PardisoFactorization().factorize(A)
    X = f.solve(B)
    assert X.shape == B.shape
    for k in range(3):
        assert _rel_res(A, X[:, k], B[:, k]) < 1e-10


def test_analysis_reused_for_the_same_pattern_and_redone_for_a_new_one():
    A = with_inertia(n_neg=20, seed=6)
    rng = np.random.default_rng(6)
    b = rng.standard_normal(A.shape[0])
    f = pardiso.PardisoFactorization()
    f.factorize(A)
    assert (f.analyses, f.factorizations) == (1, 1)
    # same pattern, new values (a different inertia: shift)
    A2 = A.copy()
    A2.data = A2.data * 1.7
    A2 = (A2 + 0.3 * sp.diags(np.ones(A.shape[0]))).tocsr()  # the diagonal is in the pattern
    assert np.array_equal(A2.indptr, A.indptr) and np.array_equal(A2.indices, A.indices)
    f.factorize(A2)
    assert (f.analyses, f.factorizations) == (1, 2)
    assert _rel_res(A2, f.solve(b), b) < 1e-10
    assert f.negative_pivots == int(np.count_nonzero(np.linalg.eigvalsh(A2.toarray()) < 0))
    # an entry pair set to 0.0: the nonzero pattern is a subset of the analysed one; the
    # default (drop_zeros, reuse_subpattern) factorises on the analysed pattern, no analysis
    A3 = A2.copy()
    rows = np.repeat(np.arange(A3.shape[0]), np.diff(A3.indptr))
    k = np.flatnonzero(rows < A3.indices)[0]
    i, j = rows[k], A3.indices[k]
    kt = A3.indptr[j] + np.flatnonzero(A3.indices[A3.indptr[j]:A3.indptr[j + 1]] == i)[0]
    A3.data[[k, kt]] = 0.0
    f.factorize(A3)
    # (A3 has A2's stored structure, which lies in the analysed pattern: the stored-structure
    # fast path factorises it there, the same numbers as the sub-pattern path)
    assert (f.analyses, f.factorizations) == (1, 3) and f.subpattern_reuses + f.stored_fast >= 1
    assert _rel_res(A3, f.solve(b), b) < 1e-10
    assert f.negative_pivots == int(np.count_nonzero(np.linalg.eigvalsh(A3.toarray()) < 0))
    A3b = A3.copy()
    A3b.data = A3b.data * 0.9  # same zeros, new values: reused (the fast path)
    f.factorize(A3b)
    assert (f.analyses, f.factorizations) == (1, 4) and f.subpattern_reuses + f.stored_fast >= 2
    assert _rel_res(A3b, f.solve(b), b) < 1e-10
    f.factorize(A2)  # the zeros become nonzeros again: the analysed pattern itself
    assert f.analyses == 1
    assert _rel_res(A2, f.solve(b), b) < 1e-10
    # without subpattern reuse: every new nonzero pattern is analysed
    h = pardiso.PardisoFactorization(reuse_subpattern=False)
    h.factorize(A2)
    h.factorize(A3)
    h.factorize(A3b)
    h.factorize(A2)
    assert (h.analyses, h.factorizations) == (3, 4)
    assert _rel_res(A2, h.solve(b), b) < 1e-10
    h.release()
    # drop_zeros=False: explicit zeros are part of the (stored) pattern, no new analysis
    g = pardiso.PardisoFactorization(drop_zeros=False)
    g.factorize(A2)
    g.factorize(A3)
    assert (g.analyses, g.factorizations) == (1, 2)
    assert _rel_res(A3, g.solve(b), b) < 1e-10
    g.release()
    # a new pattern: one new analysis (on the union when it is small: A2 then lies in it)
    A4 = (A2 + sp.random(A.shape[0], A.shape[0], density=0.002, random_state=7) * 1e-3).tocsr()
    A4 = ((A4 + A4.T) * 0.5).tocsr()
    n_before = f.analyses
    f.factorize(A4)
    assert f.analyses == n_before + 1
    assert _rel_res(A4, f.solve(b), b) < 1e-10
    f.factorize(A2)
    assert f.analyses == n_before + 1
    assert _rel_res(A2, f.solve(b), b) < 1e-10
    # a larger new pattern (A5 ⊃ A2): analysed on the union with the old one (A4's
    # extra entries are then zeros in it), and A2 lies in it: no further analysis
    A5 = (A2 + sp.random(A.shape[0], A.shape[0], density=0.05, random_state=8) * 1e-3).tocsr()
    A5 = ((A5 + A5.T) * 0.5).tocsr()
    f.factorize(A5)
    assert f.analyses == n_before + 2 and f._plan[3] > 0
    assert _rel_res(A5, f.solve(b), b) < 1e-10
    f.factorize(A2)
    assert f.analyses == n_before + 2
    assert _rel_res(A2, f.solve(b), b) < 1e-10
    # a small matrix outside it: the union would be > grow_limit x its pattern, so it is
    # analysed alone (no entry of the analysed pattern missing from it)
    n = A.shape[0]
    A6 = sp.csr_matrix(sp.diags(np.full(n, 3.0)) + sp.csr_matrix(([1.0, 1.0], ([0, n - 1], [n - 1, 0])), shape=(n, n)))
    assert f._map(A6, *pardiso._upper_entries(A6)) is None
    f.factorize(A6)
    assert f.analyses == n_before + 3 and f._plan[3] == 0
    assert _rel_res(A6, f.solve(b), b) < 1e-12
    f.release()


def test_missing_diagonal_is_inserted():
    # a saddle-point matrix [[K, B^T], [B, 0]] whose (2,2) block has no stored diagonal
    K = spd(60, 0.05, 3)
    B = sp.random(10, 60, density=0.2, random_state=3)
    A = sp.bmat([[K, B.T], [B, None]]).tocsr()
    assert np.count_nonzero(A.diagonal()) == 60
    f = pardiso.PardisoFactorization().factorize(A)
    assert f.inserted_diagonal > 0
    b = np.random.default_rng(3).standard_normal(70)
    assert _rel_res(A, f.solve(b), b) < 1e-10
    assert f.negative_pivots == int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))


def test_errors_and_release():
    f = pardiso.PardisoFactorization()
    with pytest.raises(RuntimeError):
        f.solve(np.ones(3))
    with pytest.raises(ValueError):
        f.factorize(sp.random(3, 4, density=0.5, format="csr"))
    f.factorize(spd(50, 0.1, 9))
    with pytest.raises(ValueError):
        f.solve(np.ones(7))
    f.release()
    with pytest.raises(RuntimeError):
        f.solve(np.ones(50))
    f.release()  # idempotent


def test_unavailable_reason_is_empty_when_available():
    assert pardiso.unavailable_reason() == ""
    assert pardiso.mkl_library()


# ----------------------------------------------------------------------------- in the solvers
SMALL_WEAVE = {
    "scene": "fabric_relax",
    "fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]},
    "mesh": {"elements": 12},
    "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2},
}


def _small_weave(tmp_path):
    import yaml

    from rve.config import load_config

    p = tmp_path / "cfg.yaml"
    p.write_text(yaml.safe_dump(SMALL_WEAVE))
    return load_config(str(p))


def _relax(cfg, backend, monkeypatch):
    from rve.scenes import fabric_relax

    monkeypatch.setenv("RVE_LINEAR_BACKEND", backend)
    res = fabric_relax.solve(cfg)
    return np.asarray(res.state["x"], float), res.summary


def test_minimiser_with_pardiso_equals_superlu_on_a_small_weave(tmp_path, monkeypatch):
    cfg = _small_weave(tmp_path)
    x_lu, s_lu = _relax(cfg, "superlu", monkeypatch)
    x_pd, s_pd = _relax(cfg, "pardiso", monkeypatch)
    stages = [h for h in s_pd["history"] if h.get("method") == "minimize_energy"]
    assert stages and all(h["linear_backend"] == "pardiso" and h["analyses"] >= 1 for h in stages)
    # analysis reused: fewer analyses than factorisations
    assert sum(h["analyses"] for h in stages) < sum(h["factorizations"] for h in stages)
    assert all(h["linear_backend"] == "superlu" for h in s_lu["history"] if h.get("method") == "minimize_energy")
    assert s_lu["static_converged"] and s_pd["static_converged"]
    assert np.abs(x_pd - x_lu).max() <= 1e-10 * np.abs(x_lu).max()
    assert abs(s_pd["energy_mJ"] - s_lu["energy_mJ"]) <= 1e-10 * abs(s_lu["energy_mJ"])
    assert s_pd["negative_pivots"] == s_lu["negative_pivots"] == 0
    # the sigma ladder is the same on both (the Cholesky test's verdicts are the inertia's)
    lu_stages = [h for h in s_lu["history"] if h.get("method") == "minimize_energy"]
    assert [h["indefinite"] for h in stages] == [h["indefinite"] for h in lu_stages]
    assert [h["factorizations"] for h in stages] == [h["factorizations"] for h in lu_stages]
    assert sum(h["indefinite"] for h in stages) > 0


def test_inertia_of_weave_tangents_equals_superlu(tmp_path):
    """K + sigma M of the small weave at its (stressed, indefinite) initial state, for a
    range of shifts through the indefinite range: PARDISO's count (one instance, analysis
    reused) = SuperLU's = the dense eigenvalue count."""
    from rve.fabrics.relaxation import relaxation_system
    from rve.solvers.linear import SuperLUBackend, factor_inertia, shifted
    from rve.solvers.static import StaticProblem

    cfg = _small_weave(tmp_path)
    fab, system, x0 = relaxation_system(cfg)[:3]
    prob = StaticProblem(system, x0, np.zeros(system.n), 0.0)
    _, J = prob(prob.u0())
    M = prob.fd.matrix(system.mass())
    scale = np.abs(J.diagonal()).max() / np.abs(M.diagonal()).max()
    inst = pardiso.PardisoFactorization()
    counts = []
    for sigma in [0.0] + list(scale * np.logspace(-9, 0, 10)):
        A = shifted(J, M, sigma)
        ref = SuperLUBackend().factorize(A, inertia=True).negative_pivots
        lu, neg = factor_inertia(A, backend=inst)
        dense = int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))
        assert neg == ref == dense, sigma
        counts.append(neg)
    assert counts[0] > 0 and counts[-1] == 0  # indefinite at sigma = 0, definite after the shift
    assert inst.analyses < len(counts)


def test_analyse_stored_pattern():
    """``analyse_stored``: the analysis is of the stored pattern (zeros included), so a
    later matrix whose nonzeros lie in it (a contact activated) needs no new analysis."""
    A = with_inertia(n_neg=15, seed=9)
    b = np.random.default_rng(9).standard_normal(A.shape[0])
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    inactive = (rows != A.indices) & ((rows + A.indices) % 3 == 0)  # a symmetric choice
    Z = A.copy()
    Z.data[inactive] = 0.0  # stored zeros (inactive pairs): same stored pattern as A
    assert Z.nnz == A.nnz and np.count_nonzero(Z.data) < A.nnz
    for stored, analyses in ((True, 1), (False, 2)):
        f = pardiso.PardisoFactorization(analyse_stored=stored, grow_limit=1.0)
        for M in (Z, A, Z):
            f.factorize(M)
            assert _rel_res(M, f.solve(b), b) < 1e-10
            assert f.negative_pivots == int(np.count_nonzero(np.linalg.eigvalsh(M.toarray()) < 0))
        assert f.analyses == analyses, stored
        f.release()


def _grid_laplacian_indefinite(m=24, shift=0.5):
    """A 3D 7-point Laplacian on an m^3 grid minus shift: symmetric indefinite, large
    enough (13,824 dofs) that PARDISO factorises supernodes in parallel."""
    one = sp.diags([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], [-1, 0, 1])
    eye = sp.eye(m)
    L = (sp.kron(sp.kron(one, eye), eye) + sp.kron(sp.kron(eye, one), eye) + sp.kron(sp.kron(eye, eye), one))
    return (L - shift * sp.eye(m ** 3)).tocsc()


def test_cnr_mode_gives_the_same_bits_on_one_and_two_threads():
    A = _grid_laplacian_indefinite()
    b = np.random.default_rng(3).standard_normal(A.shape[0])
    xs, negs = [], []
    for threads in (1, 2, 2, 1):
        f = pardiso.PardisoFactorization(threads=threads, cnr=2)
        f.factorize(A)
        xs.append(f.solve(b))
        negs.append(f.negative_pivots)
        f.release()
    for x in xs[1:]:
        assert np.array_equal(x, xs[0])
    assert _rel_res(A, xs[0], b) < 1e-10
    # the inertia of L - 0.5 I: eigenvalues of the 1D operators 2 - 2 cos(k pi / (m + 1))
    m = 24
    lam1 = 2.0 - 2.0 * np.cos(np.arange(1, m + 1) * np.pi / (m + 1))
    lam = lam1[:, None, None] + lam1[None, :, None] + lam1[None, None, :]
    assert len(set(negs)) == 1 and negs[0] == int(np.count_nonzero(lam < 0.5))


def test_minimiser_backend_threads_from_context_and_environment(monkeypatch):
    from rve.solvers import linear
    from rve.solvers.backends import registry

    monkeypatch.delenv(linear.THREADS_ENV, raising=False)
    monkeypatch.setenv("RVE_LINEAR_BACKEND", "pardiso")
    solver, owned = registry.run_instance()
    assert owned and solver.threads == min(linear.DEFAULT_THREADS, os.cpu_count())
    assert solver.iparm[33] == registry.CNR_THREADS
    solver.release()
    monkeypatch.setenv(linear.THREADS_ENV, "1")
    solver, _ = registry.run_instance()
    assert solver.threads == 1 and solver.iparm[33] == 2
    solver.release()
    with linear.linear_threads(2):
        solver, _ = registry.run_instance()
        assert solver.threads == 2
        solver.release()
    assert linear.solver_threads() == 1
    monkeypatch.setenv(linear.THREADS_ENV, "two")
    with pytest.raises(ValueError, match="RVE_PARDISO_THREADS"):
        linear.solver_threads()
    with pytest.raises(ValueError, match="positive integer"):
        with linear.linear_threads(0):
            pass


# ----------------------------------------------------------------------------- Cholesky
def test_cholesky_verdict_equals_the_dense_inertia_over_a_shift_sweep(tmp_path):
    """The minimiser's definiteness test: PARDISO's Cholesky companion (mtype 2) of K + sigma M
    of the small weave, one kept instance over shifts through the indefinite range, succeeds
    exactly where eigvalsh finds no negative eigenvalue, and then solves as accurately as
    the LDL^T; ``factor_positive_definite`` with SuperLU gives the same verdicts."""
    from rve.fabrics.relaxation import relaxation_system
    from rve.solvers.linear import factor_positive_definite, shifted
    from rve.solvers.static import StaticProblem

    cfg = _small_weave(tmp_path)
    fab, system, x0 = relaxation_system(cfg)[:3]
    prob = StaticProblem(system, x0, np.zeros(system.n), 0.0)
    _, J = prob(prob.u0())
    M = prob.fd.matrix(system.mass())
    scale = np.abs(J.diagonal()).max() / np.abs(M.diagonal()).max()
    b = np.random.default_rng(5).standard_normal(J.shape[0])
    inst = pardiso.PardisoFactorization()
    verdicts = []
    for sigma in [0.0] + list(scale * np.logspace(-9, 0, 10)):
        A = shifted(J, M, sigma)
        definite = bool(np.linalg.eigvalsh(A.toarray()).min() > 0)
        f = factor_positive_definite(A, backend=inst)
        assert (f is not None) == definite, sigma
        assert (factor_positive_definite(A, backend="superlu") is not None) == definite, sigma
        if definite:
            assert f.name == "pardiso_spd" and f.negative_pivots == 0
            assert _rel_res(A, f.solve(b), b) < 1e-12
        verdicts.append(definite)
    assert not verdicts[0] and verdicts[-1]
    chol = inst.cholesky()
    assert chol.indefinite == verdicts.count(False) and chol.factorizations == len(verdicts)
    assert chol.analyses < len(verdicts) and inst.factorizations == 0  # the LDL^T was not needed
    inst.release()


def test_cholesky_raises_on_an_indefinite_matrix_and_stays_usable():
    from rve.solvers.linear import NotPositiveDefiniteError

    A, S = with_inertia(n_neg=3, seed=4), spd(n=300, density=0.02, seed=4)
    b = np.random.default_rng(4).standard_normal(300)
    f = pardiso.PardisoFactorization(positive_definite=True)
    assert f.mtype == 2 and f.iparm[20] == 0 and f.iparm[12] == 0  # no Bunch-Kaufman, no matching
    with pytest.raises(NotPositiveDefiniteError):
        f.factorize(A)
    with pytest.raises(RuntimeError, match="before factorize"):
        f.solve(b)
    f.factorize(S)
    assert _rel_res(S, f.solve(b), b) < 1e-12 and f.negative_pivots == 0 and f.positive_pivots == 300
    assert f.indefinite == 1 and f.factorizations == 2
    with pytest.raises(ValueError, match="symmetric"):
        pardiso.PardisoFactorization(positive_definite=True, symmetric=False)
    with pytest.raises(ValueError, match="Cholesky"):
        pardiso.PardisoFactorization(symmetric=False).cholesky()
    f.release()


def test_cholesky_cnr_gives_the_same_bits_on_one_and_two_threads():
    A = _grid_laplacian_indefinite(shift=-0.5)  # L + 0.5 I: positive definite
    b = np.random.default_rng(6).standard_normal(A.shape[0])
    xs = []
    for threads in (1, 2, 2, 1):
        f = pardiso.PardisoFactorization(threads=threads, cnr=2, positive_definite=True)
        xs.append(f.factorize(A).solve(b))
        f.release()
    for x in xs[1:]:
        assert np.array_equal(x, xs[0])
    assert _rel_res(A, xs[0], b) < 1e-12


def test_stored_fast_path_with_entries_outside_the_analysis():
    """A stored structure with entries the analysis has not seen (candidate pairs of a
    rebuilt contact map) takes the fast path while those hold explicit zeros — the same
    bits as a fresh instance — and leaves it for a new analysis when one becomes nonzero."""
    A = with_inertia(n_neg=0, seed=11)
    A = (A + sp.eye(A.shape[0]) * 0.0).tocsr()
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    extra = (rows != A.indices) & ((rows * 7 + A.indices * 7) % 5 == 1)  # symmetric choice
    Z = A.copy()
    Z.data[extra] = 0.0
    Z0 = Z.copy()
    Z0.eliminate_zeros()
    b = np.random.default_rng(11).standard_normal(A.shape[0])
    f = pardiso.PardisoFactorization(analyse_stored=False, grow_limit=1.0)
    f.factorize(Z0)  # the analysis knows only the nonzeros
    assert f.analyses == 1
    x_general = f.factorize(Z).solve(b)  # the stored structure: mapped after this call
    fast0 = f.stored_fast
    for k in range(3):
        Zk = Z.copy()
        Zk.data = Z.data * (1.0 + 0.1 * k)
        x = f.factorize(Zk).solve(b)
        ref = pardiso.PardisoFactorization(analyse_stored=False)
        ref.factorize(Z0)
        Z0k = Z0.copy()
        Z0k.data = Z0.data * (1.0 + 0.1 * k)
        assert np.array_equal(x, ref.factorize(Z0k).solve(b))
        ref.release()
    assert f.stored_fast == fast0 + 3 and f.analyses == 1
    assert np.array_equal(x_general, f.factorize(Z).solve(b))
    f.factorize(A)  # the outside entries now nonzero: a new analysis, the right answer
    assert f.analyses == 2 and _rel_res(A, f.solve(b), b) < 1e-12
    f.release()


@pytest.mark.parametrize("n_neg", [0, 1, 37])
def test_negative_eigenvalue_count_equals_eigvalsh_and_skips_the_ldlt_when_definite(n_neg):
    """The relaxation's stability check (``negative_eigenvalue_count``): a Cholesky first, the
    LDL^T count only where it fails; the number equals the dense eigenvalue count, with
    PARDISO and with SuperLU."""
    from rve.solvers.linear import negative_eigenvalue_count

    A = spd(n=300, density=0.02, seed=7) if n_neg == 0 else with_inertia(n_neg=n_neg, seed=7)
    expected = int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))
    assert expected == n_neg
    inst = pardiso.PardisoFactorization(threads=2, cnr=2)
    assert negative_eigenvalue_count(A, backend=inst) == expected
    assert inst.cholesky().factorizations == 1
    assert inst.factorizations == (0 if n_neg == 0 else 1)  # the LDL^T only for an indefinite matrix
    assert negative_eigenvalue_count(A, backend="superlu") == expected
    inst.release()
