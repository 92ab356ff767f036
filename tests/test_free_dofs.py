"""Free-dof bookkeeping of rve.solvers.system (FreeDofs, massless_dofs) and the static
problem's restriction of a mixed state (rve.solvers.static.StaticProblem)."""
import numpy as np
import pytest
import scipy.sparse as sp

from rve.solvers.static import StaticProblem
from rve.solvers.system import FreeDofs, massless_dofs, scale_columns


def _random_csr(n, seed, density=0.15):
    rng = np.random.default_rng(seed)
    return sp.random(n, n, density=density, format="csr", random_state=rng,
                     data_rvs=lambda k: rng.normal(size=k))


def test_index_maps_round_trip():
    n = 20
    fd = FreeDofs(n, [7, 3, 3, 19, 0])  # unsorted, with a duplicate
    np.testing.assert_array_equal(fd.constrained, [0, 3, 7, 19])
    assert fd.size == 16 and np.all(np.diff(fd.free) > 0)
    np.testing.assert_array_equal(fd.new_index[fd.free], np.arange(fd.size))
    assert np.all(fd.new_index[fd.constrained] == -1)
    assert not fd.is_free[fd.constrained].any() and fd.is_free[fd.free].all()
    # restrict then expand: the free values come back, the constrained ones are untouched
    v = np.random.default_rng(0).normal(size=n)
    u = v[fd.free]
    back = np.full(n, np.nan)
    back[fd.free] = u
    np.testing.assert_array_equal(back[fd.free], v[fd.free])
    assert np.isnan(back[fd.constrained]).all()
    # cached: the same restriction for the same set, in any order
    cache = {}
    assert FreeDofs.cached(cache, n, [0, 3, 7, 19]) is FreeDofs.cached(cache, n, [19, 7, 3, 0, 3])
    assert FreeDofs.cached(cache, n, [1]) is not FreeDofs.cached(cache, n, [2])


def test_matrix_and_triplets_restrict():
    n = 25
    A = _random_csr(n, 1)
    fd = FreeDofs(n, [2, 5, 11, 24])
    dense = A.toarray()[np.ix_(fd.free, fd.free)]
    np.testing.assert_array_equal(fd.matrix(A).toarray(), dense)
    assert fd.matrix(A).format == "csc"
    mask = (np.arange(n) % 3 == 0).astype(float)
    r, c, d = fd.triplets(A, 2.5, mask != 0)
    ref = (2.5 * A.toarray() * mask[None, :])[np.ix_(fd.free, fd.free)]
    np.testing.assert_allclose(fd.assemble([(r, c, d)]).toarray(), ref, rtol=0, atol=1e-15)
    e = fd.triplets(None)
    assert e[0].size == 0 and fd.assemble([e]).shape == (fd.size, fd.size)
    np.testing.assert_array_equal(scale_columns(A, mask).toarray(), A.toarray() * mask[None, :])


def _dense_combination(fd, terms):
    out = sum(c * A.toarray() * (np.ones(A.shape[0]) if m is None else np.asarray(m, float))[None, :]
              for A, c, m in terms)
    return out[np.ix_(fd.free, fd.free)]


@pytest.mark.parametrize("seed", range(4))
def test_combine_fast_path_equals_slow_path_same_pattern(seed):
    """All terms CSR with one pattern: the cached index plan (fast path) gives the same
    matrix as the triplet assembly (slow path), entry by entry."""
    n = 40
    P = _random_csr(n, seed)
    rng = np.random.default_rng(50 + seed)
    A1 = P.copy()
    A2 = sp.csr_matrix((rng.normal(size=P.nnz), P.indices.copy(), P.indptr.copy()), shape=P.shape)
    mech = (rng.uniform(size=n) < 0.6).astype(float)
    fd = FreeDofs(n, rng.choice(n, 6, replace=False))
    terms = [(A1, 1.0, mech), (A2, 0.7, 1.0 - mech), (A1, -0.3, None)]
    fast = fd.combine(terms)
    assert fd.__dict__.get("_plans"), "the fast path was not taken"
    slow = fd.assemble([fd.triplets(A, c, None if m is None else np.asarray(m) != 0) for A, c, m in terms])
    np.testing.assert_allclose(fast.toarray(), slow.toarray(), rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(fast.toarray(), _dense_combination(fd, terms), rtol=1e-14, atol=1e-14)
    # the plan is reused: a second call with new values on the same pattern
    A2.data *= 2.0
    again = fd.combine(terms)
    assert len(fd._plans) == 1
    np.testing.assert_allclose(again.toarray(), _dense_combination(fd, terms), rtol=1e-14, atol=1e-14)


def test_combine_different_patterns_falls_back():
    n = 30
    A1, A2 = _random_csr(n, 10), _random_csr(n, 11)
    assert not np.array_equal(A1.indices, A2.indices)
    fd = FreeDofs(n, [0, 29])
    mask = (np.arange(n) % 2).astype(float)
    terms = [(A1, 1.0, mask), (A2, 2.0, 1.0 - mask), (None, 5.0, None), (sp.csr_matrix((n, n)), 1.0, None)]
    out = fd.combine(terms)
    assert not fd.__dict__.get("_plans")  # the slow path
    np.testing.assert_allclose(out.toarray(), _dense_combination(fd, terms[:2]), rtol=1e-14, atol=1e-14)
    assert fd.combine([(None, 1.0, None)]).nnz == 0


def test_massless_dofs():
    # a row with an explicitly stored zero is massless too
    M = sp.csr_matrix((np.array([1.0, 2.0, 0.0]), (np.array([0, 2, 3]), np.array([0, 2, 3]))), shape=(4, 4))
    assert M.nnz == 3
    np.testing.assert_array_equal(massless_dofs(M), [False, True, False, True])


class _Mixed:
    """4 nodes x (3 mechanical, T, V): V massless; constraints on a mechanical dof
    (velocity), on T (value 7) and on V (value -2)."""

    def __init__(self):
        self.n = 20
        self.mech = np.tile([True, True, True, False, False], 4)
        d = np.tile([1.0, 1.0, 1.0, 0.5, 0.0], 4)
        self.M = sp.diags(d, format="csr")
        self.K = _random_csr(20, 3, 0.3) + sp.identity(20, format="csr") * 5

    def mass(self):
        return self.M

    def evaluate(self, x, w, t, jacobian=True):
        F = self.K @ np.where(self.mech, x, w)
        if not jacobian:
            return F, None, None
        return F, sp.csr_matrix(self.K), sp.csr_matrix(self.K)

    def constraints(self, t):
        return np.array([1, 8, 14]), np.array([0.25, 7.0, -2.0])

    def admissible(self, x):
        return True


def test_static_problem_state_round_trip_and_prescribed_values():
    s = _Mixed()
    rng = np.random.default_rng(4)
    x = rng.normal(size=s.n)
    w = rng.normal(size=s.n)
    prob = StaticProblem(s, x, w, 0.0)
    np.testing.assert_array_equal(prob.free, np.setdiff1d(np.arange(s.n), [1, 8, 14]))
    np.testing.assert_array_equal(massless_dofs(s.mass()), np.tile([False] * 4 + [True], 4))
    # state(u0) reproduces the start: mechanical x kept (incl. the constrained dof 1, a
    # prescribed *velocity* there), T / V from w, prescribed T and V set, velocities 0
    xs, ws = prob.state(prob.u0())
    np.testing.assert_array_equal(xs[s.mech], x[s.mech])
    assert np.all(xs[~s.mech] == 0.0)
    assert np.all(ws[s.mech] == 0.0)
    assert ws[8] == 7.0 and ws[14] == -2.0
    other = np.setdiff1d(np.flatnonzero(~s.mech), [8, 14])
    np.testing.assert_array_equal(ws[other], w[other])
    # any u: restrict(expand(u)) == u, constrained entries stay prescribed
    u = rng.normal(size=prob.free.size)
    xs, ws = prob.state(u)
    np.testing.assert_array_equal(np.where(prob.free_mech, xs[prob.free], ws[prob.free]), u)
    assert xs[1] == x[1] and ws[8] == 7.0 and ws[14] == -2.0
    # the Jacobian: dF/dx on mechanical columns, dF/dw on the others, restricted
    F, J = prob(u)
    np.testing.assert_allclose(J.toarray(), s.K.toarray()[np.ix_(prob.free, prob.free)], rtol=1e-15)
    np.testing.assert_allclose(F, (s.K @ np.where(s.mech, xs, ws))[prob.free], rtol=1e-15)


def test_plan_is_keyed_on_the_whole_structure():
    """Two structures with the same size, the same first row entries and the same trailing
    row pointers (the fields a digest key of size and end rows would see) but one entry moved in a middle
    row: each gets its own plan and its own, correct restriction (such a key would hand the
    first one's plan to the second: a silently wrong matrix)."""
    n = 200
    rows = np.arange(n)
    A = sp.csr_matrix((np.ones(2 * n), (np.r_[rows, rows], np.r_[rows, (rows + 1) % n])), shape=(n, n))
    B = A.copy()
    r = 100  # row 100: entry (100, 101) moved to (100, 150)
    k = B.indptr[r] + 1
    assert B.indices[k] == 101
    B.indices = B.indices.copy()
    B.indices[k] = 150
    B.data = np.arange(1.0, B.nnz + 1.0)
    assert A.nnz == B.nnz and np.array_equal(A.indptr, B.indptr)
    assert np.array_equal(A.indices[:64], B.indices[:64]) and B.has_canonical_format
    fd = FreeDofs(n, [0, 7])
    for M in (A, B, A, B):
        np.testing.assert_array_equal(fd.combine([(M, 1.0, None)]).toarray(),
                                      M.toarray()[np.ix_(fd.free, fd.free)])
        np.testing.assert_array_equal(fd.matrix(M).toarray(), M.toarray()[np.ix_(fd.free, fd.free)])
    # a second restriction of the same constraint set finds the plans already built
    fd2 = FreeDofs(n, [7, 0])
    np.testing.assert_array_equal(fd2.matrix(B).toarray(), B.toarray()[np.ix_(fd.free, fd.free)])


def test_combine_skips_a_zero_mask_and_equals_the_masked_sum():
    n = 40
    P = _random_csr(n, 3)
    Q = sp.csr_matrix((np.random.default_rng(4).normal(size=P.nnz), P.indices, P.indptr), shape=P.shape)
    fd = FreeDofs(n, [1, 5])
    ones, zeros = np.ones(n), np.zeros(n)
    out = fd.combine([(P, 1.0, ones), (Q, 1.0, zeros)])
    np.testing.assert_array_equal(out.toarray(), P.toarray()[np.ix_(fd.free, fd.free)])
    mask = (np.arange(n) % 2).astype(float)
    out = fd.combine([(P, 2.0, mask), (Q, 0.5, 1.0 - mask)])
    np.testing.assert_allclose(out.toarray(), _dense_combination(fd, [(P, 2.0, mask), (Q, 0.5, 1.0 - mask)]),
                               rtol=1e-15, atol=1e-15)


@pytest.mark.parametrize("seed", range(3))
def test_csr_restriction_equals_the_csc_one(seed):
    """``fmt="csr"`` (the minimiser's, for PARDISO): the same matrix as the CSC restriction
    and the dense one, in canonical CSR (sorted indices, no duplicates), with its own plan."""
    n = 40
    P = _random_csr(n, seed)
    rng = np.random.default_rng(90 + seed)
    fd = FreeDofs(n, rng.choice(n, 7, replace=False))
    mech = (rng.uniform(size=n) < 0.5).astype(float)
    terms = [(P, 1.0, mech), (P, 0.4, 1.0 - mech)]
    csr, csc = fd.combine(terms, fmt="csr"), fd.combine(terms)
    assert csr.format == "csr" and csc.format == "csc" and len(fd._plans) == 2
    assert csr.has_canonical_format
    np.testing.assert_array_equal(csr.toarray(), csc.toarray())
    np.testing.assert_allclose(csr.toarray(), _dense_combination(fd, terms), rtol=1e-14, atol=1e-14)
    M = fd.matrix(P, fmt="csr")
    assert M.format == "csr" and np.shares_memory(M.indices, csr.indices)  # one plan per structure and format
    np.testing.assert_array_equal(M.toarray(), P.toarray()[np.ix_(fd.free, fd.free)])
    with pytest.raises(ValueError, match="csr"):
        fd.matrix(P, fmt="coo")


@pytest.mark.parametrize("seed", range(3))
def test_combine_compiled_gives_the_numpy_bits(seed, monkeypatch):
    """The fast path's sums by the compiled gathers (rve.kernels.index.gather_axpy[_masked])
    equal the numpy expressions bit for bit, CSC and CSR."""
    from rve.kernels import numba_available

    if not numba_available():
        pytest.skip("numba not installed")
    n = 60
    P = _random_csr(n, seed)
    rng = np.random.default_rng(70 + seed)
    A1 = P.copy()
    A2 = sp.csr_matrix((rng.normal(size=P.nnz), P.indices.copy(), P.indptr.copy()), shape=P.shape)
    A3 = sp.csr_matrix((rng.normal(size=P.nnz) * 1e3, P.indices.copy(), P.indptr.copy()), shape=P.shape)
    mech = (rng.uniform(size=n) < 0.6).astype(float)
    free = rng.choice(n, 45, replace=False)
    terms = [(A1, 1.0, None), (A2, 0.37, None), (A3, 0.37 ** 2, mech)]
    out = {}
    for path in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", path)
        out[path] = [FreeDofs(n, free).combine(terms, fmt) for fmt in ("csc", "csr")]
    for a, b in zip(out["numpy"], out["numba"]):
        assert np.array_equal(a.data, b.data) and np.array_equal(a.indices, b.indices)
