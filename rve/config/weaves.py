"""The weave patterns as data: ``WEAVE_PATTERNS[kind]`` (m, n) int, ``pattern[j % m][i % n]
= 1`` when warp j is on top of weft i at their crossing (``rve.fabrics.weave``); its shape
is the weave's repeat (m warps x n wefts). Read by the fabric
generators (``rve.fabrics.weave``) and by the RVE config's periodic-cell check, which may
not import the generators."""
from __future__ import annotations

import numpy as np

__all__ = ["WEAVE_PATTERNS", "twill_pattern"]


def twill_pattern(over: int = 2, under: int = 1) -> np.ndarray:
    """``over``/``under`` twill: warp j floats over ``over`` wefts, under ``under``, and
    the pattern shifts by one weft from one warp to the next."""
    n = int(over) + int(under)
    base = np.array([1] * int(over) + [0] * int(under))
    return np.array([np.roll(base, j) for j in range(n)])


WEAVE_PATTERNS = {
    "plain": np.array([[1, 0], [0, 1]]),
    "twill_2_1": twill_pattern(2, 1),
    "twill_2_2": twill_pattern(2, 2),
    "basket_2_2": np.array([[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 1], [0, 0, 1, 1]]),
}
