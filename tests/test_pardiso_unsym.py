"""PARDISO's LU of real unsymmetric matrices (mtype 11, ``PardisoFactorization(symmetric=False)``,
registry name ``pardiso_unsym``) and its use for the dynamic scenes' stage matrices
(``rve.solvers.newton.StageFactorisation``); docs/engine.md "Unsymmetric stage matrices
". References: numpy's dense LU (``np.linalg.solve``) and scipy's SuperLU."""
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from rve.solvers import linear
from rve.solvers.backends import pardiso
from rve.solvers.newton import JacobianReuse, StageFactorisation

needs_mkl = pytest.mark.skipif(not pardiso.available(), reason=f"PARDISO unavailable: {pardiso.unavailable_reason()}")


def _unsym(n, seed, density=0.02, zeros=0):
    """A structurally symmetric, numerically unsymmetric sparse matrix with a dominant but
    not overwhelming diagonal (random signs), CSR; ``zeros`` explicit zeros stored."""
    rng = np.random.default_rng(seed)
    S = sp.random(n, n, density=density, random_state=rng)
    P = (S + S.T + sp.eye(n)).tocsr()
    P.data[:] = rng.standard_normal(P.nnz)        # values independent on (i, j) and (j, i)
    P = P + sp.diags(rng.choice([-1.0, 1.0], n) * (2.0 + rng.random(n)))
    P = sp.csr_matrix(P)
    if zeros:
        P.data[rng.choice(P.nnz, zeros, replace=False)] = 0.0  # kept as explicit zeros
    return P


def _stage_like(n, seed):
    """Mass-dominated like the SDIRK stage matrices: ``_unsym`` with its diagonal raised to
    1 + the absolute row sum (SuperLU's diagonal pivots are then stable too)."""
    A = _unsym(n, seed).tolil()
    rs = np.asarray(abs(sp.csr_matrix(A)).sum(axis=1)).ravel()
    A.setdiag(1.0 + rs)
    return sp.csc_matrix(A)


def _backward(A, x, b):
    """Normwise relative residual |A x - b| / |b|."""
    return float(np.linalg.norm(A @ x - b) / np.linalg.norm(b))


@needs_mkl
@pytest.mark.parametrize("fmt", ["csr", "csc"])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("kind", ["stage_like", "indefinite"])
def test_solves_like_dense_lu(fmt, seed, kind):
    """Default settings on mass-dominated (stage-like) matrices; two refinement steps on
    indefinite ones (condition 400-700: PARDISO's pivoting within supernodes alone left
    residuals of 2e-12 there, the dense LU 1e-14)."""
    A = (_stage_like(250, seed) if kind == "stage_like" else _unsym(250, seed)).asformat(fmt)
    assert not linear.is_symmetric(A)
    rng = np.random.default_rng(10 + seed)
    b = rng.standard_normal(A.shape[0])
    f = pardiso.PardisoFactorization(symmetric=False, refinement=0 if kind == "stage_like" else 2)
    x = f.factorize(A).solve(b)
    xd = np.linalg.solve(A.toarray(), b)
    assert _backward(A, x, b) <= 1e-12
    assert np.abs(x - xd).max() <= 1e-10 * np.abs(xd).max()
    # several right-hand sides; a transposed solve would fail this (A is unsymmetric)
    B = rng.standard_normal((A.shape[0], 3))
    X = f.solve(B)
    assert X.shape == B.shape
    assert np.linalg.norm(A @ X - B) <= 1e-12 * np.linalg.norm(B)
    assert np.linalg.norm(A.T @ x - b) > 1e-3 * np.linalg.norm(b)
    assert f.mtype == 11 and f.name == "pardiso_unsym"


@needs_mkl
def test_explicit_zeros_and_missing_diagonal():
    A = _unsym(200, 3, zeros=150)
    A = A.tolil()
    A[5, 5] = 0.0  # an explicitly zero diagonal entry (a pivot then comes from the matching)
    A[5, 6], A[6, 5] = 3.0, -2.0
    A = sp.csr_matrix(A)
    b = np.random.default_rng(3).standard_normal(200)
    x = pardiso.PardisoFactorization(symmetric=False).factorize(A).solve(b)
    ref = spla.spsolve(sp.csc_matrix(A), b)
    assert _backward(A, x, b) <= 1e-12
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()


@needs_mkl
def test_analysis_reused_on_the_same_pattern_and_redone_on_a_new_one():
    A = sp.csc_matrix(_unsym(300, 4))
    rng = np.random.default_rng(4)
    b = rng.standard_normal(300)
    f = pardiso.PardisoFactorization(symmetric=False)
    f.factorize(A)
    assert (f.analyses, f.factorizations) == (1, 1)
    for k in range(3):  # new values, the same pattern
        B = A.copy()
        B.data = B.data * (1.0 + 0.2 * rng.standard_normal(B.nnz))
        x = f.factorize(B).solve(b)
        assert _backward(B, x, b) <= 1e-12
    assert (f.analyses, f.factorizations) == (1, 4)
    assert f.stored_fast >= 2  # the same stored structure: the gather fast path
    # fewer entries (a pattern inside the analysed one): still no analysis
    C = A.tolil()
    C[10, 11], C[11, 10] = 0.0, 0.0
    C = sp.csc_matrix(C)
    C.eliminate_zeros()
    x = f.factorize(C).solve(b)
    assert _backward(C, x, b) <= 1e-12 and f.analyses == 1
    # a new entry outside the analysed pattern: a new analysis
    D = A.tolil()
    i, j = next((i, j) for i in range(300) for j in range(300) if i != j and A[i, j] == 0 and A[j, i] == 0)
    D[i, j], D[j, i] = 0.7, -0.3
    D = sp.csc_matrix(D)
    x = f.factorize(D).solve(b)
    assert _backward(D, x, b) <= 1e-12
    assert f.analyses == 2


@needs_mkl
def test_no_inertia_from_the_lu():
    A = _unsym(100, 5)
    f = pardiso.PardisoFactorization(symmetric=False).factorize(A)
    assert not f.provides_inertia
    with pytest.raises(ValueError, match="inertia"):
        f.negative_pivots
    with pytest.raises(ValueError, match="inertia"):
        f.factorize(A, inertia=True)
    assert f.stats()["negative_pivots"] is None
    # factor_inertia with this backend leaves the count to SuperLU
    S = sp.csc_matrix(A + A.T)
    lu, neg = linear.factor_inertia(S, backend=f)
    assert neg == int(np.count_nonzero(np.linalg.eigvalsh(S.toarray()) < 0))


@needs_mkl
def test_registry_names():
    u = linear.get_backend("pardiso_unsym")
    assert u.mtype == 11 and not u.symmetric
    s = linear.get_backend("pardiso")
    assert s.mtype == -2
    assert linear.get_backend("pardiso", symmetric=False).mtype == 11
    assert s.unsymmetric().mtype == 11 and s.unsymmetric() is s.unsymmetric()
    assert u.unsymmetric() is u
    s.release()
    u.release()


@needs_mkl
def test_symmetric_mode_unchanged_by_the_companion():
    """The symmetric instance's own factorisation is not touched by its mtype-11 companion."""
    rng = np.random.default_rng(6)
    S = sp.random(200, 200, density=0.03, random_state=rng)
    K = sp.csc_matrix(S + S.T + sp.eye(200) * 5.0)
    b = rng.standard_normal(200)
    f = linear.get_backend("pardiso")
    x1 = f.factorize(K).solve(b)
    f.unsymmetric().factorize(_unsym(200, 6)).solve(b)
    x2 = f.solve(b)
    assert np.array_equal(x1, x2)
    assert f.negative_pivots == int(np.count_nonzero(np.linalg.eigvalsh(K.toarray()) < 0))


@needs_mkl
def test_stage_factorisation_routes_unsymmetric_matrices_to_mtype_11():
    A = sp.csc_matrix(_unsym(300, 7))
    b = np.random.default_rng(7).standard_normal(300)
    be = linear.get_backend("pardiso")
    f = StageFactorisation(A, be)
    assert f.kind == "pardiso_unsym"
    assert _backward(A, f.solve(b), b) <= 1e-12
    # the companion is kept: a second stage matrix on the same pattern reuses its analysis
    A2 = A.copy()
    A2.data *= 1.1
    f2 = StageFactorisation(A2, be)
    assert _backward(A2, f2.solve(b), b) <= 1e-12
    assert be.unsymmetric().analyses == 1 and be.unsymmetric().factorizations == 2
    # a symmetric stage matrix stays on the LDL^T
    K = sp.csc_matrix(A + A.T + sp.eye(300) * 20.0)
    assert StageFactorisation(K, be).kind == "pardiso"
    # the explicit name
    assert StageFactorisation(A, linear.get_backend("pardiso_unsym")).kind == "pardiso_unsym"


@needs_mkl
def test_failed_mtype_11_falls_back_to_superlu(monkeypatch):
    A = sp.csc_matrix(_unsym(200, 8))
    b = np.random.default_rng(8).standard_normal(200)
    be = linear.get_backend("pardiso")
    ref = StageFactorisation(A, be).solve(b)

    def fail(self, *a, **k):
        raise pardiso.PardisoError(-4, 22)

    monkeypatch.setattr(pardiso.PardisoFactorization, "factorize", fail)
    f = StageFactorisation(A, be)
    assert f.kind == "superlu-colamd"
    x = f.solve(b)
    assert _backward(A, x, b) <= 1e-12
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()


def test_without_mkl_the_scenes_backends_fall_back_to_superlu(monkeypatch):
    """MKL absent (``available()`` False): "auto" is SuperLU and the stage matrix is solved
    by it; "pardiso" / "pardiso_unsym" named explicitly say why they are unavailable."""
    A = _stage_like(200, 9)
    assert not linear.is_symmetric(A)
    b = np.random.default_rng(9).standard_normal(200)
    ref = np.linalg.solve(A.toarray(), b)
    with_mkl = None
    if pardiso.available():
        with_mkl = StageFactorisation(A, linear.get_backend("pardiso")).solve(b)
    monkeypatch.setattr(pardiso, "available", lambda: False)
    monkeypatch.setattr(pardiso, "unavailable_reason", lambda: "monkeypatched away")
    monkeypatch.delenv(linear.BACKEND_ENV, raising=False)
    assert linear.resolve_backend("auto") == "superlu"
    reuse = JacobianReuse(backend=None)
    reuse.factorize(A)
    assert reuse.factor.kind == "superlu"
    x = reuse.solve(b)
    assert _backward(A, x, b) <= 1e-12
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()
    if with_mkl is not None:
        assert np.abs(x - with_mkl).max() <= 1e-10 * np.abs(ref).max()
    for name in ("pardiso", "pardiso_unsym"):
        with pytest.raises(RuntimeError, match="monkeypatched away"):
            linear.get_backend(name)


# ----------------------------------------------------------------------------- a real stage matrix
_SMALL_IMPACT = ["output.vtk=false", "output.png=false", "geometry.n_warp=4", "geometry.n_weft=4",
                 "geometry.span=6.35 mm", "mesh.elements=8", "projectile.radius=2.5 mm", "projectile.gap=0.01 mm",
                 "relaxation.steps=2", "projectile.speed=300 mm/ms"]


@pytest.fixture(scope="module")
def impact_stage_matrices():
    """The stage matrices a reduced impact run (4 x 4 yarns, 8 elements, fast projectile:
    sphere contact from the first steps) hands its kept factorisations (SuperLU run)."""
    from pathlib import Path

    from rve.config.loader import load_config
    from rve.scenes import impact
    from rve.solvers import newton

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs/scenes/impact.yaml", _SMALL_IMPACT)
    x, info = impact.relax(cfg)
    got = []
    orig = newton.StageFactorisation.__init__

    def init(self, J, backend):
        got.append(sp.csc_matrix(J, copy=True))
        orig(self, J, backend)

    newton.StageFactorisation.__init__ = init
    try:
        res = impact.solve(cfg, x_start=x, relax_info=info, record=False, t_end=5e-4 * 8, steps=8,
                           integrator_options={"linear_backend": "superlu_pruned"})
    finally:
        newton.StageFactorisation.__init__ = orig
    assert res.summary["sphere_pairs_active_max"] > 0
    return cfg, x, info, res, got


@needs_mkl
def test_real_impact_stage_matrix(impact_stage_matrices):
    *_, mats = impact_stage_matrices
    A = mats[-1]
    assert not linear.is_symmetric(A)
    assert np.count_nonzero(A.data == 0.0) > 0  # inactive candidate pairs stored as zeros
    rng = np.random.default_rng(11)
    xt = rng.standard_normal(A.shape[0])
    b = A @ xt
    f = pardiso.PardisoFactorization(symmetric=False)
    x = f.factorize(A).solve(b)
    ref = spla.spsolve(A, b)
    xd = np.linalg.solve(A.toarray(), b)
    assert _backward(A, x, b) <= 1e-12
    assert _backward(A, x, b) <= 100 * max(_backward(A, ref, b), 1e-16)
    assert np.abs(x - xd).max() <= 1e3 * max(np.abs(ref - xd).max(), 1e-14 * np.abs(xd).max())
    # all the matrices of the run on one instance: analyses only when the pattern grows
    for M in mats:
        y = f.factorize(M).solve(M @ xt)
        assert _backward(M, y, M @ xt) <= 1e-12
    assert f.analyses <= len({(M.indptr.tobytes(), M.indices.tobytes()) for M in mats})


@needs_mkl
def test_reduced_impact_run_with_pardiso_unsym_equals_superlu(impact_stage_matrices):
    """The whole reduced impact run (backend ``auto_pruned``): PARDISO mtype 11 gives the SuperLU run's states to
    round-off (the residual tolerance decides convergence; both converge to it)."""
    from rve.scenes import impact

    cfg, x, info, ref, _ = impact_stage_matrices
    res = impact.solve(cfg, x_start=x, relax_info=info, record=False, t_end=5e-4 * 8, steps=8,
                       integrator_options={"linear_backend": "auto_pruned"})
    for k in ("x", "w", "T"):
        a, b = np.asarray(ref.state[k]), np.asarray(res.state[k])
        assert np.abs(a - b).max() <= 1e-8 * max(np.abs(a).max(), 1e-300), k
    assert res.summary["steps_accepted"] == ref.summary["steps_accepted"]
    for k, v in ref.summary["balance_errors"].items():
        assert abs(res.summary["balance_errors"][k] - v) <= 1e-6 * max(abs(v), 1e-12) + 1e-12, k


# ----------------------------------------------------------------------------- the impact scene's backend
@pytest.mark.parametrize("mkl", [True, False])
def test_auto_pruned_is_pardiso_with_mkl_else_superlu_pruned(mkl, monkeypatch):
    from rve.solvers.backends.pruned import NAME, NAME_AUTO, PardisoOrPruned, PrunedSuperLU

    if mkl and not pardiso.available():
        pytest.skip(f"PARDISO unavailable: {pardiso.unavailable_reason()}")
    if not mkl:
        monkeypatch.setattr(pardiso, "available", lambda: False)
    A = _stage_like(300, 12)
    b = np.random.default_rng(12).standard_normal(300)
    ref = np.linalg.solve(A.toarray(), b)
    be = PardisoOrPruned(border=5)  # the last 5 unknowns by a Schur complement
    f = StageFactorisation(A, be)
    assert be.kind == ("pardiso_unsym" if mkl else "superlu_pruned")
    x = f.solve(b)
    assert _backward(A, x, b) <= 1e-12
    assert np.abs(x - ref).max() <= 1e-10 * np.abs(ref).max()
    with pytest.raises(ValueError, match="inertia"):
        be.negative_pivots
    assert linear.BACKENDS[NAME_AUTO] is PardisoOrPruned and linear.BACKENDS[NAME] is PrunedSuperLU


@needs_mkl
def test_auto_pruned_falls_back_to_superlu_pruned_when_pardiso_fails(monkeypatch):
    from rve.solvers.backends.pruned import PardisoOrPruned

    A = _stage_like(200, 13)
    b = np.random.default_rng(13).standard_normal(200)
    be = PardisoOrPruned()

    def fail(self, *a, **k):
        raise pardiso.PardisoError(-4, 22)

    monkeypatch.setattr(pardiso.PardisoFactorization, "factorize", fail)
    x = StageFactorisation(A, be).solve(b)
    assert be.kind == "superlu_pruned" and be.fallbacks == 1
    assert _backward(A, x, b) <= 1e-12
