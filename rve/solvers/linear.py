"""Linear solves of the sparse tangents: the one home of the solver choices (docs/engine.md).

Contract
--------
* ``sparse_solve(J, r) -> du``: one direct solve ``J du = r`` (Newton, the static and
  pseudo-transient solvers, the capped Newton): LAPACK's banded LU when ``J`` is narrowly
  banded (single fibrils), else SuperLU in symmetric mode (``SUPERLU_SYMMETRIC``),
  checked by its residual, with COLAMD + partial pivoting (``SUPERLU_FALLBACK_PERMC``) as
  the fallback. Raises ``RuntimeError`` only if the fallback does.
* ``factorize(A, symmetric=True, inertia=False, backend=None) -> LinearBackend``: a
  factorisation of ``A`` with ``.solve(b)`` and ``.negative_pivots`` (the number of
  negative pivots of a symmetric factorisation with diagonal pivots; by Sylvester's law of
  inertia the number of negative eigenvalues of a symmetric ``A``). With ``inertia=True``
  the pivots are checked at once and a factorisation with a zero or non-finite pivot
  raises ``SingularFactorError`` (the energy minimiser then raises its shift). Backends
  are chosen by name from ``BACKENDS`` (default ``DEFAULT_BACKEND = "superlu"``).
* ``factor_inertia(A) -> (factorisation, n_negative)``: the same with ``inertia=True``,
  ``(None, -1)`` instead of the exception (the energy minimiser's inertia check,
  docs/relaxation.md).

Backends (the seam of issue 10: a supernodal LDL^T with its analysis reused per sparsity
pattern plugs in here by ``register_backend``). A backend instance is stateful and used
as ``analyse(pattern)`` (fill-reducing ordering / symbolic factorisation of a sparsity
pattern; ``factorize`` calls it itself when the pattern changes), ``factorize(A)``
(numeric factorisation; returns the instance), ``solve(b)`` and ``negative_pivots``.
Keeping one instance across calls with the same pattern reuses the analysis.

* ``"superlu"`` (``SuperLUBackend``): scipy's SuperLU. ``symmetric=True``: minimum degree
  on A^T + A with diagonal pivots only (``SUPERLU_SYMMETRIC``), so the diagonal of U is
  the D of A = L D L^T (up to rounding) and gives the inertia; ``symmetric=False``:
  COLAMD with partial pivoting (no inertia). SuperLU orders every factorisation afresh,
  so ``analyse`` only records the pattern.
* ``"banded"`` (``BandedBackend``): LAPACK ``gbsv`` on the band of ``A`` (LU with partial
  pivoting, no inertia); ``factorize`` raises ``NotBandedError`` when the bandwidth
  exceeds ``BANDED_MAX_BANDWIDTH``. The band is factorised in each ``solve``.
"""
from __future__ import annotations

from typing import Callable, Dict, Optional

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["sparse_solve", "factorize", "factor_inertia", "LinearBackend", "SuperLUBackend", "BandedBackend", "BACKENDS",
           "DEFAULT_BACKEND", "register_backend", "get_backend", "SingularFactorError", "NotBandedError",
           "SUPERLU_SYMMETRIC", "SUPERLU_FALLBACK_PERMC", "BANDED_MAX_BANDWIDTH", "band_of"]


#: Our Jacobians are structurally symmetric with dominant diagonals (beam stiffness, mass,
#: conduction, contact penalties). SuperLU in symmetric mode (minimum degree on A^T + A,
#: diagonal pivots) fills about half as much as COLAMD with partial pivoting: measured on
#: the 80-fibril weave (21,760 free dofs) 0.77 s vs 1.65 s per factorisation, 4.2 M vs
#: 9.1 M factor entries (docs/engine.md). With diagonal pivots only, the diagonal of U of a
#: symmetric matrix is the D of A = L D L^T: its signs give the inertia (Sylvester).
SUPERLU_SYMMETRIC = dict(permc_spec="MMD_AT_PLUS_A", options=dict(SymmetricMode=True, DiagPivotThresh=0.0))

#: Column ordering of the unsymmetric fallback (partial pivoting).
SUPERLU_FALLBACK_PERMC = "COLAMD"

#: A symmetric-mode solution is accepted when ``|J du - r| <= _FALLBACK_RTOL |r|``; else
#: (or if a diagonal pivot breaks down) the fallback solves.
_FALLBACK_RTOL = 1e-8

#: Single fibrils (and anything else whose node-interleaved matrix is narrowly banded) go
#: to LAPACK's banded LU: for the 451-dof dynamic wire ~10x cheaper than SuperLU.
BANDED_MAX_BANDWIDTH = 48


class SingularFactorError(RuntimeError):
    """A factorisation met an exactly zero (or non-finite) pivot."""


class NotBandedError(ValueError):
    """The matrix is too widely banded for the banded backend."""


# ----------------------------------------------------------------------------- backends
class LinearBackend:
    """Interface of a factorisation backend (see the module docstring).

    Subclasses implement ``_analyse(A)`` (optional), ``_factorize(A, inertia)``,
    ``solve(b)`` and ``_pivots()`` (the diagonal pivots, for ``negative_pivots``)."""

    #: registry name
    name = "abstract"
    #: whether the backend can count negative pivots (inertia)
    provides_inertia = False

    def __init__(self, symmetric: bool = True):
        self.symmetric = bool(symmetric)
        self.pattern_key = None
        self._negative = None

    # -- analysis --------------------------------------------------------------
    @staticmethod
    def pattern_of(A) -> tuple:
        """A key of the sparsity pattern of the CSC matrix ``A`` (shape, indptr, indices)."""
        return (A.shape, A.indptr.tobytes(), A.indices.tobytes())

    def analyse(self, pattern) -> "LinearBackend":
        """Symbolic analysis of the sparsity pattern of ``pattern`` (a sparse matrix)."""
        P = sp.csc_matrix(pattern)
        self._analyse(P)
        self.pattern_key = self.pattern_of(P) if self.reuses_analysis else None
        return self

    #: True when ``analyse`` does work worth reusing (then ``factorize`` compares patterns)
    reuses_analysis = False

    def _analyse(self, A) -> None:
        pass

    # -- numeric factorisation ---------------------------------------------------
    def factorize(self, A, inertia: bool = False) -> "LinearBackend":
        """Numeric factorisation of ``A`` (re-analysing if its pattern changed).
        ``inertia=True`` computes ``negative_pivots`` now and raises
        ``SingularFactorError`` on a zero or non-finite pivot."""
        if inertia and not (self.provides_inertia and self.symmetric):
            raise ValueError(f"backend {self.name!r} (symmetric={self.symmetric}) does not give the inertia")
        if self.reuses_analysis:
            A = sp.csc_matrix(A)
            if self.pattern_key != self.pattern_of(A):
                self.analyse(A)
        self._negative = None
        self._factorize(A)
        if inertia:
            d = self._pivots()
            if not np.all(np.isfinite(d)):
                raise SingularFactorError("non-finite pivot")
            self._negative = int(np.count_nonzero(d < 0.0))
        return self

    def _factorize(self, A) -> None:
        raise NotImplementedError

    def solve(self, b) -> np.ndarray:
        raise NotImplementedError

    def _pivots(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def negative_pivots(self) -> int:
        """Number of negative pivots of the last factorisation (= negative eigenvalues of a
        symmetric matrix factorised with diagonal pivots)."""
        if self._negative is None:
            if not (self.provides_inertia and self.symmetric):
                raise ValueError(f"backend {self.name!r} (symmetric={self.symmetric}) does not give the inertia")
            self._negative = int(np.count_nonzero(self._pivots() < 0.0))
        return self._negative


class SuperLUBackend(LinearBackend):
    """scipy's SuperLU: symmetric mode with diagonal pivots (``SUPERLU_SYMMETRIC``), or
    COLAMD with partial pivoting when ``symmetric=False``."""

    name = "superlu"
    provides_inertia = True

    def _factorize(self, A) -> None:
        try:
            if self.symmetric:
                self.lu = spla.splu(sp.csc_matrix(A), **SUPERLU_SYMMETRIC)
            else:
                self.lu = spla.splu(sp.csc_matrix(A), permc_spec=SUPERLU_FALLBACK_PERMC)
        except RuntimeError as exc:  # exactly singular pivot
            self.lu = None
            raise SingularFactorError(str(exc)) from exc

    def solve(self, b) -> np.ndarray:
        return self.lu.solve(b)

    def _pivots(self) -> np.ndarray:
        return self.lu.U.diagonal()


def band_of(J):
    """``(lo, up, ab)``: lower and upper bandwidth and LAPACK band storage of the CSC
    matrix ``J`` (no duplicate entries); ``None`` if ``J`` is empty, smaller than 8 or
    banded wider than ``BANDED_MAX_BANDWIDTH``."""
    n = J.shape[0]
    if J.nnz == 0 or n < 8:
        return None
    # J is CSC without duplicate entries: columns from indptr, rows in indices
    cols = np.repeat(np.arange(n), np.diff(J.indptr))
    d = cols - J.indices
    lo, up = int(max(0, -d.min())), int(max(0, d.max()))
    if max(lo, up) > BANDED_MAX_BANDWIDTH:
        return None
    ab = np.zeros((lo + up + 1, n))
    ab[up - d, cols] = J.data
    return lo, up, ab


class BandedBackend(LinearBackend):
    """LAPACK's banded LU (``scipy.linalg.solve_banded``) on a narrowly banded matrix."""

    name = "banded"
    provides_inertia = False

    def _factorize(self, A) -> None:
        J = sp.csc_matrix(A)
        J.sum_duplicates()
        band = band_of(J)
        if band is None:
            raise NotBandedError(f"bandwidth above {BANDED_MAX_BANDWIDTH} (or an empty / tiny matrix)")
        self.band = band

    def solve(self, b) -> np.ndarray:
        """Raises ``numpy.linalg.LinAlgError`` for a singular band."""
        lo, up, ab = self.band
        return scipy.linalg.solve_banded((lo, up), ab, b, check_finite=False)


#: backend classes by name
BACKENDS: Dict[str, Callable[..., LinearBackend]] = {"superlu": SuperLUBackend, "banded": BandedBackend}

#: the backend ``factorize`` uses when none is named
DEFAULT_BACKEND = "superlu"


def register_backend(name: str, cls: Callable[..., LinearBackend]) -> None:
    """Make ``cls`` (a ``LinearBackend`` subclass) available as ``factorize(..., backend=name)``."""
    BACKENDS[str(name)] = cls


def get_backend(name: Optional[str] = None, symmetric: bool = True) -> LinearBackend:
    """A fresh instance of the backend ``name`` (default ``DEFAULT_BACKEND``)."""
    key = DEFAULT_BACKEND if name is None else str(name)
    try:
        cls = BACKENDS[key]
    except KeyError:
        raise ValueError(f"unknown linear-solver backend {key!r} (known: {', '.join(sorted(BACKENDS))})") from None
    return cls(symmetric=symmetric)


def factorize(A, symmetric: bool = True, inertia: bool = False, backend: Optional[str] = None) -> LinearBackend:
    """Factorise ``A`` with a fresh backend instance; returns it (``.solve(b)``,
    ``.negative_pivots``). Raises ``SingularFactorError`` on an exactly zero pivot (and,
    with ``inertia=True``, on a non-finite one)."""
    return get_backend(backend, symmetric=symmetric).factorize(A, inertia=inertia)


# ----------------------------------------------------------------------------- one solve
def sparse_solve(J, r):
    """Direct sparse solve J du = r: banded LAPACK for narrow bands, else SuperLU in
    symmetric mode, with COLAMD + partial pivoting as the fallback."""
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
    try:
        du = SuperLUBackend(symmetric=True).factorize(J).solve(r)
        rn = np.linalg.norm(r)
        if np.all(np.isfinite(du)) and np.linalg.norm(J @ du - r) <= _FALLBACK_RTOL * max(rn, 1e-300):
            return du
    except RuntimeError:  # exactly singular diagonal pivot
        pass
    return spla.spsolve(J, r, permc_spec=SUPERLU_FALLBACK_PERMC)


def factor_inertia(A, backend: Optional[str] = None):
    """Factorise the symmetric sparse ``A`` with diagonal pivots and count its negative
    eigenvalues from the pivots (the minimiser's inertia check). Returns
    ``(factorisation, n_negative)``; ``(None, -1)`` when a pivot is zero or not finite."""
    try:
        lu = factorize(A, symmetric=True, inertia=True, backend=backend)
    except SingularFactorError:
        return None, -1
    return lu, lu.negative_pivots
