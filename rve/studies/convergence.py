"""The one convergence-order fit of the verification studies (docs/verification_static_wire.md).

Contract
--------
* ``fit_points(n, error, lo=None, hi=None, parity=None, exclude=None) -> mask``: the
  points of a refinement series that enter a fit: the resolution ``n`` (elements N or time
  steps N) in the inclusive asymptotic range ``[lo, hi]`` (None: unbounded), of the given
  ``parity`` ("odd", "even" or None: both), not ``exclude`` (e.g. the reference solution),
  with a finite, positive error.
* ``fit_order(h, error, points=None) -> float``: the observed order, the **ordinary
  least-squares slope of log(error) against log(h)** (``numpy.linalg.lstsq`` on the
  design matrix ``[log h, 1]``) over the points selected by the bool mask ``points`` (all
  by default) that have a finite, positive error; NaN with fewer than two.

Both studies use them: ``rve.studies.static_wire.fit_orders`` (h = 2L/N, ranges per p and
parity of N, the reference excluded) and ``rve.studies.dynamic_wire.fit_orders``
(h = t_max/N, one range per scheme). The static study fitted with this ``lstsq`` before
(its figures are unchanged bit for bit); the dynamic study used ``numpy.polyfit`` of
degree 1, the same least-squares problem solved with scaled columns: the slopes agree to
rounding (docs/coupled_fields.md: the orders are unchanged to the quoted 2 decimals).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

__all__ = ["fit_points", "fit_order"]

_PARITY = {"odd": 1, "even": 0}


def fit_points(n, error, lo: Optional[int] = None, hi: Optional[int] = None, parity: Optional[str] = None,
               exclude=None) -> np.ndarray:
    """Bool mask of the points of the series ``(n, error)`` that enter the fit."""
    n = np.asarray(n)
    e = np.asarray(error, dtype=float)
    if n.shape != e.shape:
        raise ValueError(f"n and error differ in shape: {n.shape} vs {e.shape}")
    keep = np.isfinite(e) & (e > 0)
    if lo is not None:
        keep &= n >= lo
    if hi is not None:
        keep &= n <= hi
    if parity is not None:
        if parity not in _PARITY:
            raise ValueError(f"parity must be 'odd', 'even' or None, not {parity!r}")
        keep &= n % 2 == _PARITY[parity]
    if exclude is not None:
        keep &= ~np.isin(n, np.atleast_1d(exclude))
    return keep


def fit_order(h, error, points=None) -> float:
    """Least-squares slope of log(error) vs log(h) over ``points`` (bool mask) with a
    finite, positive error; NaN with fewer than two such points."""
    h = np.asarray(h, dtype=float)
    e = np.asarray(error, dtype=float)
    if h.shape != e.shape:
        raise ValueError(f"h and error differ in shape: {h.shape} vs {e.shape}")
    keep = np.isfinite(e) & (e > 0)
    if points is not None:
        keep &= np.asarray(points, dtype=bool)
    if keep.sum() < 2:
        return float("nan")
    x, y = np.log(h[keep]), np.log(e[keep])
    A = np.vstack([x, np.ones_like(x)]).T
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(coef[0])
