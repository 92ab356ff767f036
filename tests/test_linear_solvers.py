"""rve.solvers.linear: factorisations solve to round-off, the inertia count is right, the
banded path agrees with SuperLU, the fallback rescues a breakdown, the backend seam, the
backend choice (auto / RVE_LINEAR_BACKEND / backend=, clear errors). Runs without
pypardiso (the PARDISO cases are skipped; the choice then falls back to SuperLU)."""
import re

import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers import linear
from rve.solvers.backends import pardiso
from rve.solvers.linear import (BandedBackend, NotBandedError, SingularFactorError, SuperLUBackend, band_of,
                                factor_inertia, factorize, resolve_backend, shifted, sparse_solve)

HAVE_PARDISO = pardiso.available()
needs_pardiso = pytest.mark.skipif(not HAVE_PARDISO, reason=f"PARDISO unavailable: {pardiso.unavailable_reason()}")
#: every backend that gives an inertia here
INERTIA_BACKENDS = ["superlu"] + (["pardiso"] if HAVE_PARDISO else [])


@pytest.fixture
def no_env(monkeypatch):
    monkeypatch.delenv(linear.BACKEND_ENV, raising=False)


def _sym_indefinite(n, seed, density=0.05, band=None):
    """Random sparse symmetric matrix with a diagonal of both signs, |d| >= 2 (no tiny pivot)."""
    rng = np.random.default_rng(seed)
    B = sp.random(n, n, density=density, random_state=rng, data_rvs=lambda k: rng.uniform(-1, 1, k))
    if band is not None:
        B = sp.triu(sp.tril(B, band), -band)
    d = rng.choice([-1.0, 1.0], n) * rng.uniform(2.0, 6.0, n)
    return sp.csc_matrix(B + B.T + sp.diags(d * (1.0 + abs(B).sum(axis=1).A.ravel())))


@pytest.mark.parametrize("seed", range(5))
def test_factorize_solves_to_round_off(seed):
    A = _sym_indefinite(120, seed)
    b = np.random.default_rng(100 + seed).normal(size=120)
    f = factorize(A)
    x = f.solve(b)
    ref = np.linalg.solve(A.toarray(), b)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    # the unsymmetric (COLAMD + partial pivoting) mode solves as well
    x2 = factorize(A, symmetric=False).solve(b)
    np.testing.assert_allclose(x2, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("seed", range(8))
def test_negative_pivots_count_negative_eigenvalues(seed):
    A = _sym_indefinite(80, seed, density=0.08)
    n_neg = int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))
    assert 0 < n_neg < 80
    f = factorize(A, inertia=True)
    assert f.negative_pivots == n_neg
    # computed lazily too
    assert factorize(A).negative_pivots == n_neg
    lu, neg = factor_inertia(A)
    assert neg == n_neg and np.allclose(A @ lu.solve(np.ones(80)), 1.0)
    # positive definite after a shift past the smallest eigenvalue
    lam = np.linalg.eigvalsh(A.toarray()).min()
    assert factorize(A + (1.0 - lam) * sp.identity(80, format="csc"), inertia=True).negative_pivots == 0


@pytest.mark.parametrize("backend", INERTIA_BACKENDS)
def test_singular_factor(backend):
    A = sp.csc_matrix(np.diag([1.0, 0.0, 2.0, 3.0]))
    with pytest.raises(SingularFactorError):
        factorize(A, inertia=True, backend=backend)
    assert factor_inertia(A, backend=backend) == (None, -1)
    B = A.copy()
    B.data[0] = np.nan
    assert factor_inertia(B, backend=backend) == (None, -1)


def test_banded_path_equals_superlu_path():
    n = 90
    A = _sym_indefinite(n, 7, density=0.3, band=6)
    b = np.random.default_rng(3).normal(size=n)
    assert band_of(A)[:2] == (6, 6)
    x_band = sparse_solve(A, b)  # the banded LAPACK path (bandwidth 6 <= 48)
    np.testing.assert_array_equal(x_band, BandedBackend().factorize(A).solve(b))
    x_lu = SuperLUBackend().factorize(A).solve(b)
    np.testing.assert_allclose(x_band, x_lu, rtol=0, atol=1e-12 * np.abs(x_lu).max())
    with pytest.raises(ValueError):
        BandedBackend().factorize(A, inertia=True)  # LU with partial pivoting: no inertia


def test_wide_band_goes_to_the_sparse_backend(monkeypatch):
    n = 200
    A = _sym_indefinite(n, 11, density=0.02)
    assert band_of(A) is None
    with pytest.raises(NotBandedError):
        BandedBackend().factorize(A)
    b = np.ones(n)
    ref = SuperLUBackend().factorize(A).solve(b)
    monkeypatch.setenv(linear.BACKEND_ENV, "superlu")  # the fallback forced: plain SuperLU exactly
    np.testing.assert_array_equal(sparse_solve(A, b), ref)
    monkeypatch.setenv(linear.BACKEND_ENV, "auto")  # PARDISO where available: the same to round-off
    np.testing.assert_allclose(sparse_solve(A, b), ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_fallback_rescues_zero_diagonal_pivot():
    # a saddle-point block [[0, 1], [1, 0]]: symmetric mode with diagonal pivots breaks down
    A = sp.csc_matrix(sp.block_diag([np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[2.0]])]))
    b = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(sparse_solve(A, b), np.linalg.solve(A.toarray(), b), rtol=1e-14)


def test_backend_registry(no_env):
    assert linear.DEFAULT_BACKEND == "auto"
    assert set(linear.BACKENDS) >= {"superlu", "pardiso", "banded"}
    assert isinstance(linear.get_backend("superlu"), SuperLUBackend)
    with pytest.raises(ValueError, match="unknown linear-solver backend"):
        factorize(sp.identity(3, format="csc"), backend="nope")

    class Dense(linear.LinearBackend):
        """A toy backend with analysis reuse: counts its analyses."""
        name = "dense-test"
        provides_inertia = True
        reuses_analysis = True
        analyses = 0

        def _analyse(self, A):
            type(self).analyses += 1

        def _factorize(self, A):
            self.A = sp.csc_matrix(A).toarray()
            self.d = np.linalg.eigvalsh(self.A)

        def solve(self, b):
            return np.linalg.solve(self.A, b)

        def _pivots(self):
            return self.d

    linear.register_backend("dense-test", Dense)
    try:
        A = _sym_indefinite(30, 1, density=0.2)
        f = factorize(A, inertia=True, backend="dense-test")
        assert f.negative_pivots == factorize(A, inertia=True).negative_pivots
        f.factorize(2.0 * A)  # same pattern: the analysis is reused
        f.factorize(sp.diags(np.arange(1.0, 31.0), format="csc"))  # another pattern: analysed anew
        assert Dense.analyses == 2
    finally:
        del linear.BACKENDS["dense-test"]


# ----------------------------------------------------------------------------- the choice
def test_auto_picks_pardiso_when_available_else_superlu(no_env, monkeypatch):
    assert resolve_backend() == ("pardiso" if HAVE_PARDISO else "superlu")
    assert resolve_backend("auto") == resolve_backend()
    assert resolve_backend("auto", symmetric=False) == "superlu"  # PARDISO here is LDL^T only
    assert linear.get_backend().name == resolve_backend()
    # MKL absent (e.g. aarch64, or pypardiso not installed): auto is SuperLU
    monkeypatch.setattr(pardiso, "available", lambda: False)
    assert resolve_backend() == "superlu"
    assert isinstance(linear.get_backend(), SuperLUBackend)


def test_environment_override(monkeypatch):
    monkeypatch.setenv(linear.BACKEND_ENV, "superlu")
    assert resolve_backend() == "superlu"
    assert isinstance(linear.get_backend(), SuperLUBackend)
    lu, neg = factor_inertia(_sym_indefinite(40, 2))
    assert isinstance(lu, SuperLUBackend)
    monkeypatch.setenv(linear.BACKEND_ENV, " Auto ")
    assert resolve_backend() == ("pardiso" if HAVE_PARDISO else "superlu")
    # the backend= argument wins over the environment
    monkeypatch.setenv(linear.BACKEND_ENV, "pardiso")
    assert resolve_backend("superlu") == "superlu"


def test_bad_backend_name_is_a_clear_error(monkeypatch):
    # every registered name (scenes register their own: the impact's superlu_pruned, auto_pruned)
    assert {"banded", "pardiso", "pardiso_unsym", "superlu"} <= set(linear.BACKENDS)
    allowed = re.escape("allowed: " + ", ".join(["auto", *sorted(linear.BACKENDS)]))
    with pytest.raises(ValueError, match=r"unknown linear-solver backend 'mumps'.*" + allowed):
        resolve_backend("mumps")
    monkeypatch.setenv(linear.BACKEND_ENV, "pardisso")
    with pytest.raises(ValueError, match=r"environment variable RVE_LINEAR_BACKEND.*allowed: auto"):
        resolve_backend()
    with pytest.raises(ValueError, match="pardisso"):
        sparse_solve(_sym_indefinite(60, 1), np.ones(60))


def test_pardiso_named_where_unavailable(monkeypatch):
    monkeypatch.setattr(pardiso, "available", lambda: False)
    monkeypatch.setattr(pardiso, "unavailable_reason", lambda: "pypardiso not importable: test")
    with pytest.raises(RuntimeError, match="not available: pypardiso not importable"):
        linear.get_backend("pardiso")


@pytest.mark.parametrize("backend", INERTIA_BACKENDS)
@pytest.mark.parametrize("seed", range(4))
def test_inertia_equal_across_backends(backend, seed):
    A = _sym_indefinite(150, 20 + seed, density=0.04)
    ref = SuperLUBackend().factorize(A, inertia=True).negative_pivots
    n_neg = int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))
    lu, neg = factor_inertia(A, backend=backend)
    assert neg == ref == n_neg
    b = np.random.default_rng(seed).normal(size=150)
    x = lu.solve(b)
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b) * np.abs(A).max() * 10


@needs_pardiso
def test_pardiso_inertia_with_perturbed_pivot_falls_back_to_superlu():
    # a near-singular 2x2 block (Schur complement -1e-12 << 1e-8 |A|, scaling cannot fix
    # it): PARDISO perturbs that pivot; the count must be SuperLU's
    near = np.array([[1.0, 1.0], [1.0, 1.0 - 1e-12]])
    A = sp.csc_matrix(sp.block_diag([near, np.diag([2.0, -3.0]), _sym_indefinite(30, 4).toarray()]))
    ref = SuperLUBackend().factorize(A, inertia=True).negative_pivots
    f = linear.get_backend("pardiso")
    f.factorize(A)
    assert f.perturbed_pivots > 0
    with pytest.raises(SingularFactorError):
        f.factorize(A, inertia=True)
    lu, neg = factor_inertia(A, backend=f)
    assert neg == ref and isinstance(lu, SuperLUBackend)


@needs_pardiso
def test_sparse_solve_with_pardiso_equals_superlu_and_reuses_the_analysis(monkeypatch):
    A = _sym_indefinite(300, 5, density=0.02)
    assert band_of(A) is None
    b = np.random.default_rng(5).normal(size=300)
    ref = SuperLUBackend().factorize(A).solve(b)
    inst = linear.get_backend("pardiso")
    x1 = sparse_solve(A, b, backend=inst)
    x2 = sparse_solve(2.0 * A, b, backend=inst)  # same pattern: one analysis for both
    assert (inst.analyses, inst.factorizations) == (1, 2)
    np.testing.assert_allclose(x1, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    np.testing.assert_allclose(x2, 0.5 * ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # the shared instance of the module (backend by name) reuses too
    linear.release_shared()
    monkeypatch.setenv(linear.BACKEND_ENV, "pardiso")
    sparse_solve(A, b)
    sparse_solve(3.0 * A, b)
    assert linear._SHARED["pardiso"].analyses == 1
    linear.release_shared()


@needs_pardiso
def test_sparse_solve_unsymmetric_goes_to_superlu():
    A = _sym_indefinite(200, 6, density=0.03).tolil()
    A[3, 150] += 0.7  # not symmetric: PARDISO's LDL^T (one triangle) would be wrong
    A = A.tocsc()
    assert not linear.is_symmetric(A) and linear.is_symmetric(_sym_indefinite(200, 6, density=0.03))
    b = np.ones(200)
    inst = linear.get_backend("pardiso")
    x = sparse_solve(A, b, backend=inst)
    assert inst.factorizations == 0
    np.testing.assert_allclose(A @ x, b, rtol=0, atol=1e-10)


def test_shifted_keeps_the_stored_pattern():
    A = _sym_indefinite(50, 8, density=0.1)
    J = A.copy()
    J.data[::7] = 0.0  # explicit zeros (inactive contact pairs)
    M = sp.diags(np.linspace(1.0, 2.0, 50), format="csc")
    S0 = shifted(J, M, 0.3)
    S1 = shifted(J, M, 0.3, keep_pattern=True)
    assert S0.nnz < J.nnz == S1.nnz  # scipy's sum drops the zeros; keep_pattern keeps them
    np.testing.assert_array_equal(S1.indices, J.indices)
    np.testing.assert_array_equal(S1.toarray(), S0.toarray())
    np.testing.assert_array_equal(shifted(J, M, 0.5, keep_pattern=True).toarray(), (J + 0.5 * M).toarray())
    assert shifted(J, M, 0.0) is J
    # an M entry outside J's pattern: scipy's sum
    M2 = sp.csc_matrix(np.eye(50) + np.eye(50, k=40))
    np.testing.assert_array_equal(shifted(J, M2, 0.3, keep_pattern=True).toarray(), (J + 0.3 * M2).toarray())
    # M stored on J's very index arrays (the contact system's mass on the union pattern):
    # the direct sum, the same entries as the slot path
    J = sp.csc_matrix(J)
    Mj = sp.csc_matrix((np.where(np.arange(J.nnz) % 3 == 0, 1.5, 0.0), J.indices, J.indptr), shape=J.shape)
    assert np.shares_memory(Mj.indices, J.indices)
    S2 = shifted(J, Mj, 0.3, keep_pattern=True)
    assert S2.nnz == J.nnz
    np.testing.assert_array_equal(S2.toarray(), (J + 0.3 * Mj).toarray())
    Mcopy = sp.csc_matrix((Mj.data, Mj.indices.copy(), Mj.indptr.copy()), shape=J.shape)
    np.testing.assert_array_equal(S2.data, shifted(J, Mcopy, 0.3, keep_pattern=True).data)


def test_stage_factorisation_sends_unsymmetric_matrices_past_pardiso():
    """A kept stage factorisation (modified Newton) with the PARDISO backend must still
    solve an unsymmetric stage matrix exactly: the symmetric PARDISO is an LDL^T of the
    upper triangle, so the unsymmetric coupled matrices go past it, to its mtype-11 LU
    companion (a regression guard: with SuperLU's symmetric mode the induced-deformation
    scene's Newton converged only linearly)."""
    from rve.solvers.backends import pardiso
    from rve.solvers.newton import StageFactorisation

    if not pardiso.available():
        pytest.skip(f"PARDISO unavailable: {pardiso.unavailable_reason()}")
    rng = np.random.default_rng(7)
    n = 300
    S = sp.random(n, n, density=0.02, random_state=rng)
    A = (S + S.T + sp.eye(n) * 10.0).tocsr()
    A = A + sp.random(n, n, density=0.005, random_state=rng) * 1e-3  # small unsymmetric coupling
    A = sp.csc_matrix(A)
    assert not linear.is_symmetric(A)
    b = rng.standard_normal(n)
    f = StageFactorisation(A, linear.get_backend("pardiso"))
    assert f.kind == "pardiso_unsym"
    x = f.solve(b)
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)
