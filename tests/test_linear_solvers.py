"""rve.solvers.linear: factorisations solve to round-off, the inertia count is right, the
banded path agrees with SuperLU, the fallback rescues a breakdown, the backend seam."""
import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers import linear
from rve.solvers.linear import (BandedBackend, NotBandedError, SingularFactorError, SuperLUBackend, band_of,
                                factor_inertia, factorize, sparse_solve)


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


def test_singular_factor():
    A = sp.csc_matrix(np.diag([1.0, 0.0, 2.0, 3.0]))
    with pytest.raises(SingularFactorError):
        factorize(A, inertia=True)
    assert factor_inertia(A) == (None, -1)


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


def test_wide_band_goes_to_superlu():
    n = 200
    A = _sym_indefinite(n, 11, density=0.02)
    assert band_of(A) is None
    with pytest.raises(NotBandedError):
        BandedBackend().factorize(A)
    b = np.ones(n)
    np.testing.assert_array_equal(sparse_solve(A, b), SuperLUBackend().factorize(A).solve(b))


def test_fallback_rescues_zero_diagonal_pivot():
    # a saddle-point block [[0, 1], [1, 0]]: symmetric mode with diagonal pivots breaks down
    A = sp.csc_matrix(sp.block_diag([np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[2.0]])]))
    b = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(sparse_solve(A, b), np.linalg.solve(A.toarray(), b), rtol=1e-14)


def test_backend_registry():
    assert linear.DEFAULT_BACKEND == "superlu"
    assert isinstance(linear.get_backend(), SuperLUBackend)
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
