"""The cubic Hermite basis on [0, 1] (the smooth contact curve's, ``rve.physics.contact_smooth``).

Contract
--------
``hermite_basis(s) -> (H, dH, d2H)``: the basis ``(h00, h01, h10, h11)`` and its first and
second derivatives at ``s`` (any shape), each (..., 4).
"""
from __future__ import annotations

import numpy as np

__all__ = ["hermite_basis"]


def hermite_basis(s) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cubic Hermite basis (h00, h01, h10, h11) and its first and second s-derivatives at
    ``s`` (any shape) -> three arrays (..., 4)."""
    s = np.asarray(s, float)
    s2, s3 = s * s, s * s * s
    one = np.ones_like(s)
    H = np.stack([2 * s3 - 3 * s2 + 1, -2 * s3 + 3 * s2, s3 - 2 * s2 + s, s3 - s2], axis=-1)
    dH = np.stack([6 * s2 - 6 * s, -6 * s2 + 6 * s, 3 * s2 - 4 * s + one, 3 * s2 - 2 * s], axis=-1)
    d2H = np.stack([12 * s - 6, -12 * s + 6, 6 * s - 4, 6 * s - 2], axis=-1)
    return H, dH, d2H
