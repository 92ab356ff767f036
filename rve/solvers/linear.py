"""Linear solves of the sparse tangents: the one home of the solver choices (docs/engine.md).

Contract
--------
* Backend choice: ``resolve_backend(name=None, symmetric=True) -> str``. ``name`` (the
  ``backend=`` argument of the functions below) wins; else the environment variable
  ``RVE_LINEAR_BACKEND``; else ``DEFAULT_BACKEND = "auto"``. ``"auto"`` is ``"pardiso"``
  when ``rve.solvers.backends.pardiso.available()`` (and the matrix is symmetric), else
  ``"superlu"``. A name outside ``BACKENDS`` / ``"auto"`` raises ``ValueError`` listing the
  allowed ones; ``"pardiso"`` named explicitly where it is unavailable raises
  ``RuntimeError`` with the reason. ``RVE_LINEAR_BACKEND=superlu`` forces the pure-scipy
  fallback everywhere (docs/engine.md, "Backend choice").
* Threads of the energy minimiser's PARDISO factorisations (defined in ``rve.threads``,
  re-exported here; the compiled kernels use the same count): ``solver_threads() -> int``
  (``linear_threads(n)`` in effect, else ``$RVE_PARDISO_THREADS``, else
  ``min(DEFAULT_THREADS, cores)``), in MKL's reproducible mode (``rve.solvers.backends.
  registry.CNR_THREADS``: 1 and 2 threads give the same bits; docs/engine.md "Two threads").
* ``sparse_solve(J, r, backend=None) -> du``: one direct solve ``J du = r`` (Newton, the
  static and pseudo-transient solvers, the capped Newton): LAPACK's banded LU when ``J``
  is narrowly banded (single fibrils); else the chosen backend — PARDISO (only when ``J``
  is symmetric to rounding: a two-vector bilinear test) or SuperLU in symmetric mode
  (``SUPERLU_SYMMETRIC``) — checked by its residual ``|J du - r| <= 1e-8 |r|``; a failed
  check or a breakdown (PARDISO's perturbed pivots show up here) falls back to SuperLU
  symmetric mode and then to COLAMD + partial pivoting (``SUPERLU_FALLBACK_PERMC``).
  Raises ``RuntimeError`` only if the last fallback does. ``backend`` may be a backend
  *instance* (``get_backend(...)``): keeping one across calls reuses PARDISO's analysis
  while the pattern is unchanged; by default (a name or None) one shared instance per
  backend name is kept by this module (``release_shared()`` frees it).
* ``factorize(A, symmetric=True, inertia=False, backend=None) -> backend instance``: a
  factorisation of ``A`` with ``.solve(b)`` and ``.negative_pivots`` (the number of
  negative pivots of a symmetric factorisation; by Sylvester's law of inertia the number
  of negative eigenvalues of a symmetric ``A``). With ``inertia=True`` the pivots are
  checked at once and a factorisation with a zero or non-finite pivot raises
  ``SingularFactorError``. ``backend`` is a name or an instance (reused, analysis kept).
* ``factor_inertia(A, backend=None) -> (factorisation, n_negative)``: the energy
  minimiser's inertia check (docs/relaxation.md); ``(None, -1)`` for a zero or non-finite
  pivot. With PARDISO a factorisation that perturbed a pivot (its count of that pivot's
  sign is then not SuperLU's) or failed is redone by SuperLU, so the count always equals
  SuperLU's on the same matrix; a backend without inertia (``pardiso_unsym``) leaves it to
  SuperLU.
* ``factor_positive_definite(A, backend=None) -> factorisation or None``: the energy
  minimiser's definiteness test of ``K + sigma M``: a factorisation to solve with when
  ``A`` is positive definite, None when it is not. With PARDISO the instance's Cholesky
  companion (mtype 2, ``PardisoFactorization.cholesky``), which stops at the first pivot
  <= 0 (a tenth of a factorisation or less on the minimiser's indefinite matrices:
  docs/engine.md "Cholesky as the definiteness test"); otherwise ``factor_inertia`` and
  its count (with SuperLU, the LU pivots' signs).
* ``negative_eigenvalue_count(A, backend=None) -> int``: the stability check of a
  relaxed state (its static tangent's negative eigenvalues): 0 when the Cholesky companion
  of a PARDISO instance succeeds, otherwise ``factor_inertia``'s count (-1 for a zero or
  non-finite pivot). The same number as ``factor_inertia`` (a Cholesky succeeds exactly on
  positive definite matrices); it saves the LDL^T's analysis with weighted matching where
  the answer is 0, which it is for every stable state.
* ``shifted(J, M, sigma, keep_pattern=False)``: ``J + sigma M`` (the minimiser's and
  the pseudo-transient solver's regularised tangent). ``keep_pattern=False`` is scipy's
  sum (explicit zeros dropped); ``True`` keeps ``J``'s stored pattern
  (explicit zeros of inactive contact pairs included) when ``M``'s pattern lies in it.

Backends. A backend instance is stateful and used as ``analyse(pattern)`` (fill-reducing
ordering / symbolic factorisation; ``factorize`` calls it itself when the pattern
changes), ``factorize(A)`` (numeric factorisation; returns the instance), ``solve(b)`` and
``negative_pivots``. Keeping one instance across calls with the same pattern reuses the
analysis.

* ``"pardiso"`` (``PardisoBackend``, ``rve/solvers/backends/pardiso.py``): MKL PARDISO LDL^T,
  symmetric indefinite, one MKL thread, explicit zeros dropped, the analysis (METIS +
  matching) reused while the nonzero pattern lies in the analysed one (a new analysis on
  the union when small). The energy minimiser hands it the contact map's stored pattern
  and analyses that (``analyse_stored``; ``rve.solvers.backends.run_backend``): measured
  the best of four choices, docs/engine.md "Backend choice". ``symmetric=True`` reads one
  triangle (symmetric matrices only); ``symmetric=False`` is PARDISO's LU of a real
  unsymmetric matrix (mtype 11: full pattern, nonsymmetric matching and scaling, pivot
  perturbation 1e-13, the same analysis reuse; no inertia). ``"auto"`` with
  ``symmetric=False`` stays ``"superlu"``; ``rve.solvers.newton.StageFactorisation`` routes
  an unsymmetric stage matrix handed to a symmetric ``"pardiso"`` instance to its mtype-11
  companion (docs/engine.md "Unsymmetric stage matrices").
* ``"pardiso_unsym"`` (``PardisoUnsymBackend``): mtype 11 whatever ``symmetric`` says.
* ``"superlu"`` (``SuperLUBackend``): scipy's SuperLU. ``symmetric=True``: minimum degree
  on A^T + A with diagonal pivots only (``SUPERLU_SYMMETRIC``), so the diagonal of U is
  the D of A = L D L^T (up to rounding) and gives the inertia; ``symmetric=False``:
  COLAMD with partial pivoting (no inertia). SuperLU orders every factorisation afresh,
  so ``analyse`` only records the pattern.
* ``"banded"`` (``BandedBackend``): LAPACK ``gbsv`` on the band of ``A`` (LU with partial
  pivoting, no inertia); ``factorize`` raises ``NotBandedError`` when the bandwidth
  exceeds ``BANDED_MAX_BANDWIDTH``. The band is factorised in each ``solve``.
  ``sparse_solve`` takes this path itself for narrow bands, whatever the backend.
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
