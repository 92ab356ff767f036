"""Linear solves of the sparse tangents, on the factorisation backends of
``rve.solvers.backends`` (names, the default choice and the backends' own contracts are
there; the full text and the measurements: docs/engine.md, "The linear-solver layer in
full").

Contract
--------
* ``sparse_solve(J, r, backend=None) -> du``: one direct solve ``J du = r``: LAPACK's banded
  LU for narrow bands, else the backend (PARDISO only for a matrix symmetric to rounding)
  checked by its residual ``|J du - r| <= 1e-8 |r|``, falling back to SuperLU's symmetric
  mode and then COLAMD with partial pivoting; one shared instance per backend name
  (``release_shared()`` frees them).
* ``factorize(A, symmetric=True, inertia=False, backend=None) -> backend instance``.
* ``factor_inertia(A, backend=None) -> (factorisation, n_negative)`` (``(None, -1)`` for a
  zero or non-finite pivot; always SuperLU's count), ``factor_positive_definite(A,
  backend=None, cholesky=True) -> factorisation or None`` (PARDISO's Cholesky where it
  is there), ``negative_eigenvalue_count(A, backend=None) -> int``.
* ``shifted(J, M, sigma, keep_pattern=False)``: ``J + sigma M`` (scipy's sum, or on J's
  stored pattern); ``is_symmetric(J, rtol=1e-10)``.
* Re-exported for callers: the backends, their registry (``resolve_backend``,
  ``get_backend``, ``register_backend``, ``BACKENDS``), the errors and the thread helpers
  of ``rve.threads`` (``solver_threads``, ``linear_threads``).
"""
from __future__ import annotations

import copy
import os
from typing import Dict, Union

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..threads import DEFAULT_THREADS, THREADS_ENV, linear_threads, solver_threads
from .backends.banded import BANDED_MAX_BANDWIDTH, BandedBackend, NotBandedError, band_of
from .backends.base import LinearBackend, NotPositiveDefiniteError, SingularFactorError
from .backends.base import same_buffer as _same_buffer
from .backends.registry import (BACKEND_ENV, BACKENDS, DEFAULT_BACKEND, PardisoBackend, PardisoUnsymBackend,
                                get_backend, register_backend, resolve_backend)
from .backends.superlu import SUPERLU_FALLBACK_PERMC, SUPERLU_SYMMETRIC, SuperLUBackend

__all__ = ["sparse_solve", "factorize", "factor_inertia", "factor_positive_definite", "negative_eigenvalue_count", "shifted", "LinearBackend", "SuperLUBackend", "BandedBackend",
           "solver_threads", "linear_threads", "THREADS_ENV", "DEFAULT_THREADS",
           "PardisoBackend", "PardisoUnsymBackend", "BACKENDS", "DEFAULT_BACKEND", "BACKEND_ENV", "resolve_backend", "register_backend",
           "get_backend", "release_shared", "SingularFactorError", "NotPositiveDefiniteError", "NotBandedError", "SUPERLU_SYMMETRIC",
           "SUPERLU_FALLBACK_PERMC", "BANDED_MAX_BANDWIDTH", "band_of", "is_symmetric"]


#: A symmetric-mode solution is accepted when ``|J du - r| <= _FALLBACK_RTOL |r|``; else
#: (or if a diagonal pivot breaks down) the fallback solves.
_FALLBACK_RTOL = 1e-8

BackendSpec = Union[None, str, LinearBackend, object]


def _instance(backend: BackendSpec, symmetric: bool = True):
    """``backend`` if it is an instance, else a fresh one by name."""
    if backend is None or isinstance(backend, str):
        return get_backend(backend, symmetric=symmetric)
    return backend


def factorize(A, symmetric: bool = True, inertia: bool = False, backend: BackendSpec = None):
    """Factorise ``A`` with ``backend`` (an instance: reused; a name or None: a fresh
    instance); returns the instance (``.solve(b)``, ``.negative_pivots``). Raises
    ``SingularFactorError`` on an exactly zero pivot (and, with ``inertia=True``, on a
    non-finite one)."""
    return _instance(backend, symmetric).factorize(A, inertia=inertia)


def shifted(J, M, sigma: float, keep_pattern: bool = False):
    """``J + sigma M`` as CSC. ``keep_pattern=False``: scipy's sum (explicit zeros dropped);
    ``True``: on ``J``'s stored pattern when ``M``'s pattern lies in it (else scipy's sum);
    ``J`` and ``M`` of one structure (the same index arrays, CSR or CSC) keep that format."""
    if sigma == 0.0:
        return J
    if not keep_pattern:
        return (J + sigma * M).tocsc()
    if not (sp.issparse(J) and sp.issparse(M) and J.format == M.format and J.format in ("csr", "csc")):
        J = sp.csc_matrix(J)
        M = sp.csc_matrix(M)
    if _same_buffer(M.indices, J.indices) and _same_buffer(M.indptr, J.indptr) and J.has_canonical_format:
        # M on J's very structure (both restricted through one plan: the contact system's mass
        # lives on the union pattern): entry by entry, the same sums as the slot path
        A = copy.copy(J)  # a shallow copy sharing J's checked index arrays (no re-validation)
        A.data = J.data + sigma * M.data
        return A
    J = sp.csc_matrix(J)
    M = sp.csc_matrix(M)
    c = _SLOT_CACHE
    if c and all(_same_arrays(c[k], X) for k, X in (("J", J), ("M", M))):
        slots = c["slots"]
    else:
        slots = _slots_in(J, M)
        # the arrays themselves are kept (not copies): matrices restricted through one plan
        # share them, so the next call is an identity check
        c.update(J=(J.shape, J.indptr, J.indices), M=(M.shape, M.indptr, M.indices), slots=slots)
    if slots is None:
        return (J + sigma * M).tocsc()
    data = J.data.copy()
    data[slots] += sigma * M.data  # canonical M: distinct slots
    return sp.csc_matrix((data, J.indices, J.indptr), shape=J.shape)


_SLOT_CACHE: dict = {}


def _same_arrays(key, X) -> bool:
    shape, indptr, indices = key
    if _same_buffer(X.indices, indices) and _same_buffer(X.indptr, indptr):
        return True
    return (X.shape == shape and X.indptr.size == indptr.size and X.indices.size == indices.size
            and np.array_equal(X.indptr, indptr) and np.array_equal(X.indices, indices))


def _slots_in(J, M):
    """Positions in ``J.data`` of the entries of ``M`` (both canonical CSC), or None when
    an entry of ``M`` is not stored in ``J``."""
    J.sum_duplicates()
    M.sum_duplicates()
    n = J.shape[0]
    kj = np.repeat(np.arange(J.shape[1], dtype=np.int64), np.diff(J.indptr)) * n + J.indices
    km = np.repeat(np.arange(M.shape[1], dtype=np.int64), np.diff(M.indptr)) * n + M.indices
    pos = np.searchsorted(kj, km)
    pos = np.minimum(pos, kj.size - 1)
    if kj.size == 0 or not np.array_equal(kj[pos], km):
        return None
    return pos


# ----------------------------------------------------------------------------- one solve
_SHARED: Dict[str, object] = {}


def release_shared() -> None:
    """Free the backend instances ``sparse_solve`` keeps between calls."""
    for inst in _SHARED.values():
        rel = getattr(inst, "release", None)
        if rel is not None:
            rel()
    _SHARED.clear()


def is_symmetric(J, rtol: float = 1e-10) -> bool:
    """Entry by entry ``|J_ij - J_ji| <= rtol (|J_ij| + |J_ji|) + 1e-14 max|J|``: True for
    matrices symmetric to rounding (assembled beam, contact and mass blocks), False as soon
    as one coupling block is unsymmetric, however small its entries are against the
    stiffness (the Lorentz / back-EMF blocks of the coupled stage matrices: a symmetric
    LDL^T of those would solve the symmetrised system and Newton would lose its quadratic
    rate). O(nnz): one transpose and one sparse difference."""
    n = J.shape[0]
    if J.shape[1] != n:
        return False
    A = sp.csr_matrix(J)
    D = (A - A.T).tocoo()
    if D.nnz == 0:
        return True
    big = np.abs(D.data)
    amax = float(np.abs(A.data).max()) if A.nnz else 0.0
    if not np.all(np.isfinite(big)):
        return False
    if big.max() <= 1e-14 * amax:
        return True
    if big.max() > (2.0 * rtol + 1e-14) * amax:   # above the bound at any entry (|J_ij| + |J_ji| <= 2 max|J|)
        return False
    S = (abs(A) + abs(A).T).tocsr()
    s = np.asarray(S[D.row, D.col]).ravel()
    return bool(np.all(big <= rtol * s + 1e-14 * amax))


def _accept(J, du, r) -> bool:
    rn = np.linalg.norm(r)
    return bool(np.all(np.isfinite(du)) and np.linalg.norm(J @ du - r) <= _FALLBACK_RTOL * max(rn, 1e-300))


def sparse_solve(J, r, backend: BackendSpec = None):
    """Direct sparse solve J du = r: banded LAPACK for narrow bands, else the chosen
    backend (PARDISO for symmetric ``J`` when available, SuperLU in symmetric mode) checked
    by its residual, with SuperLU symmetric mode and then COLAMD + partial pivoting as the
    fallbacks (module docstring)."""
    J = sp.csc_matrix(J)
    J.sum_duplicates()
    r = np.asarray(r, float)
    band = band_of(J)
    if band is not None:
        lo, up, ab = band
        try:
            du = scipy.linalg.solve_banded((lo, up), ab, r, check_finite=False)
        except np.linalg.LinAlgError:
            du = None
        if du is not None and np.all(np.isfinite(du)):
            return du
    if backend is None or isinstance(backend, str):
        name = resolve_backend(backend, symmetric=True)
        if name == "banded":
            name = "superlu"
        solver = None
        if name != "superlu":
            solver = _SHARED.get(name)
            if solver is None:
                solver = _SHARED[name] = get_backend(name, symmetric=True)
    else:
        solver = backend if getattr(backend, "name", "") != "superlu" else None
    if solver is not None and getattr(solver, "symmetric", True) and is_symmetric(J):
        try:
            du = solver.factorize(J).solve(r)
            if _accept(J, du, r):
                return du
        except RuntimeError:  # PardisoError, SingularFactorError
            pass
    try:
        du = SuperLUBackend(symmetric=True).factorize(J).solve(r)
        if _accept(J, du, r):
            return du
    except RuntimeError:  # exactly singular diagonal pivot
        pass
    return spla.spsolve(J, r, permc_spec=SUPERLU_FALLBACK_PERMC)


def factor_inertia(A, backend: BackendSpec = None):
    """Factorise the symmetric sparse ``A`` and count its negative eigenvalues from the
    pivots (the minimiser's inertia check). ``backend``: a name or an instance (kept:
    PARDISO's analysis reused). A PARDISO factorisation that perturbed a pivot or failed
    is redone by SuperLU (whose count is then returned). Returns ``(factorisation,
    n_negative)``; ``(None, -1)`` when a pivot is zero or not finite."""
    solver = _instance(backend, symmetric=True)
    if getattr(solver, "name", "") != "superlu" and getattr(solver, "provides_inertia", True):
        try:
            lu = solver.factorize(A, inertia=False)
            if getattr(lu, "perturbed_pivots", 0) == 0:
                return lu, lu.negative_pivots
        except SingularFactorError:  # a non-finite entry
            return None, -1
        except RuntimeError:  # PardisoError: SuperLU decides below
            pass
    try:
        lu = SuperLUBackend(symmetric=True).factorize(A, inertia=True)
    except SingularFactorError:
        return None, -1
    return lu, lu.negative_pivots


def _cholesky_verdict(A, solver):
    """The Cholesky companion's verdict on ``A`` (``solver``: an instance): its factorisation
    when ``A`` is positive definite, False when it is not (a pivot <= 0, a non-finite entry),
    None when there is no verdict (no Cholesky companion, another PARDISO error)."""
    chol = getattr(solver, "cholesky", None)
    if chol is None or not getattr(solver, "symmetric", False):
        return None
    try:
        return chol().factorize(A)
    except (NotPositiveDefiniteError, SingularFactorError):
        return False
    except RuntimeError:  # another PARDISO error: the inertia path decides
        return None


def negative_eigenvalue_count(A, backend: BackendSpec = None) -> int:
    """Number of negative eigenvalues of the symmetric sparse ``A`` (module contract): 0
    when a PARDISO Cholesky of ``A`` succeeds, else ``factor_inertia(A, backend)[1]``."""
    solver = _instance(backend, symmetric=True)
    if _cholesky_verdict(A, solver):
        return 0
    return int(factor_inertia(A, backend=solver)[1])


def factor_positive_definite(A, backend: BackendSpec = None, cholesky: bool = True):
    """The factorisation of the symmetric ``A`` when it is positive definite, else None (the
    energy minimiser's test of ``K + sigma M``). ``backend``: a name or an instance (kept).
    A PARDISO instance tries its Cholesky companion (``cholesky()``), which stops at the
    first pivot <= 0; any other PARDISO failure, every other backend, and ``cholesky=False``
    (the LDL^T inertia test, for A/B benchmarks) go through ``factor_inertia`` (positive
    definite = no negative and no zero pivot)."""
    solver = _instance(backend, symmetric=True)
    verdict = _cholesky_verdict(A, solver) if cholesky else None
    if verdict is not None:
        return verdict or None
    lu, neg = factor_inertia(A, backend=solver)
    return lu if neg == 0 else None
