"""LAPACK's banded LU as a factorisation backend (registry name ``"banded"``).

Contract: ``band_of(J) -> (lo, up, ab) or None`` (the bandwidths and LAPACK band storage
of a CSC matrix, None when wider than ``BANDED_MAX_BANDWIDTH``, empty or tiny);
``BandedBackend`` factorises in each ``solve`` (``gbsv``: LU with partial pivoting, no
inertia) and raises ``NotBandedError`` from ``factorize`` on a wide band.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from .base import LinearBackend, NotBandedError

__all__ = ["BandedBackend", "band_of", "BANDED_MAX_BANDWIDTH"]


#: Single fibrils (and anything else whose node-interleaved matrix is narrowly banded) go
#: to LAPACK's banded LU: for the 451-dof dynamic wire ~10x cheaper than SuperLU.
BANDED_MAX_BANDWIDTH = 48


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
