"""What every factorisation backend shares: the errors, the ``LinearBackend`` interface
and the one structure test of sparse matrices.

Contract
--------
* ``SingularFactorError`` (an exactly zero or non-finite pivot), ``NotPositiveDefiniteError``
  (a Cholesky pivot <= 0), ``NotBandedError`` (too wide for the banded backend).
* ``LinearBackend(symmetric=True)``: ``analyse(pattern)``, ``factorize(A, inertia=False)``
  (returns the instance), ``solve(b)``, ``negative_pivots``; subclasses implement
  ``_analyse``, ``_factorize``, ``solve`` and ``_pivots`` (rve.solvers.linear, "Backends").
* ``same_buffer(a, b)``: the same array or views of the very same memory and layout.
* ``same_structure(A, indptr, indices)``: CSR/CSC ``A`` has exactly these index arrays
  (identity first, then contents): how the kept analyses and restriction plans recognise
  a matrix they have seen.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["SingularFactorError", "NotPositiveDefiniteError", "NotBandedError", "LinearBackend", "same_buffer",
           "same_structure"]


class SingularFactorError(RuntimeError):
    """A factorisation met an exactly zero (or non-finite) pivot."""


class NotPositiveDefiniteError(RuntimeError):
    """A Cholesky factorisation met a pivot <= 0: the matrix is not positive definite."""


class NotBandedError(ValueError):
    """The matrix is too widely banded for the banded backend."""


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


def same_buffer(a, b) -> bool:
    """``a`` and ``b`` are the same array or views of the very same memory with the same
    layout (scipy's constructors wrap index arrays in new views: identity alone misses)."""
    return a is b or (a.shape == b.shape and a.dtype == b.dtype and a.strides == b.strides
                      and a.ctypes.data == b.ctypes.data)


def same_structure(A, indptr, indices) -> bool:
    """True when CSR/CSC ``A`` has exactly the index arrays ``indptr``/``indices``
    (identity first, then contents)."""
    if same_buffer(A.indices, indices) and same_buffer(A.indptr, indptr):
        return True
    return (A.indptr.size == indptr.size and A.indices.size == indices.size
            and np.array_equal(A.indptr, indptr) and np.array_equal(A.indices, indices))
