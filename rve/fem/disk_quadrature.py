"""Quadrature rules on the unit disk (thesis Appendix B, Table B.1, corrected).

Contract
--------
``disk_rule(n_points)`` with ``n_points`` in ``{4, 8, 16}`` returns ``(points, weights)``:

* ``points``: float array of shape ``(n_points, 2)``, Cartesian coordinates ``(xi1, xi2)``
  in the unit-disk coordinates of the cross-section (the physical section of radius R is
  reached with ``X = R * xi`` and the extra Jacobian ``R**2``, see Appendix B);
* ``weights``: float array of shape ``(n_points,)`` summing to ``pi`` (the area of the
  unit disk), so that ``sum(w * f(points)) ~= integral of f over the unit disk``.

Each rule integrates every monomial ``xi1**a * xi2**b`` with ``a + b <= DISK_RULE_DEGREE[n]``
exactly (to rounding), and fails for at least one monomial of degree
``DISK_RULE_DEGREE[n] + 1``:

==========  ======  ==========================================================
n_points    degree  structure
==========  ======  ==========================================================
4           3       one ring, r**2 = 1/2, angles 0, pi/2, pi, 3pi/2
8           5       two 4-point rings rotated by pi/4 against each other;
                    r**2 = 1 + sqrt(3)/3 (angles k pi/2) and 1 - sqrt(3)/3
                    (angles pi/4 + k pi/2).  NOTE: the outer ring lies OUTSIDE
                    the unit disk (|xi| = 1.2559...)
16          7       2-point Gauss-Legendre in r**2 (r**2 = 1/2 +- sqrt(3)/6)
                    times 8 equally spaced angles, inner ring rotated by pi/8
==========  ======  ==========================================================

Any other ``n_points`` raises ``ValueError`` naming the allowed values.

How Table B.1 was read: the 4-point rule is as printed (its column is the radius). In the
8- and 16-point rules the printed "radius" column is r**2, and the last angle of the
16-point rule is ``7*pi/4 + pi/8`` (printed ``7*pi/8 + pi/8``). With these corrections the
printed weights give rules that are exact to the degrees above; this is checked against the
closed-form moments :func:`disk_monomial_integral` in ``tests/test_disk_quadrature.py``.
The 8-point rule is the unique degree-5 rule with that two-ring symmetric structure, and
that structure forces its outer ring outside the disk (see ``docs/disk_quadrature.md``).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["DISK_RULE_DEGREE", "ALLOWED_N_POINTS", "disk_rule", "disk_monomial_integral"]

#: Highest total degree a + b for which every monomial xi1**a xi2**b is integrated exactly.
DISK_RULE_DEGREE: dict[int, int] = {4: 3, 8: 5, 16: 7}

ALLOWED_N_POINTS: tuple[int, ...] = tuple(sorted(DISK_RULE_DEGREE))


def _ring(r: float, angles: np.ndarray) -> np.ndarray:
    return np.column_stack([r * np.cos(angles), r * np.sin(angles)])


def _rule_4() -> tuple[np.ndarray, np.ndarray]:
    r = math.sqrt(2.0) / 2.0
    pts = _ring(r, np.arange(4) * (np.pi / 2))
    w = np.full(4, np.pi / 4)
    return pts, w


def _two_rings(r_out: float, r_in: float, n: int, w_out: float, w_in: float) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points on each of two rings, the inner one turned by half a spacing."""
    angles = np.arange(n) * (2.0 * np.pi / n)
    pts = np.vstack([_ring(r_out, angles), _ring(r_in, angles + np.pi / n)])
    return pts, np.concatenate([np.full(n, w_out), np.full(n, w_in)])


def _rule_8() -> tuple[np.ndarray, np.ndarray]:
    s3 = math.sqrt(3.0)
    # the printed column values are r**2
    return _two_rings(math.sqrt(1.0 + s3 / 3.0), math.sqrt(1.0 - s3 / 3.0), 4,
                      np.pi * (2.0 - s3) / 16.0, np.pi * (2.0 + s3) / 16.0)


def _rule_16() -> tuple[np.ndarray, np.ndarray]:
    s3 = math.sqrt(3.0)
    return _two_rings(math.sqrt(0.5 + s3 / 6.0), math.sqrt(0.5 - s3 / 6.0), 8, np.pi / 16, np.pi / 16)


_BUILDERS = {4: _rule_4, 8: _rule_8, 16: _rule_16}


def disk_rule(n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 2) and weights (n,) of the ``n_points`` rule on the unit disk.

    Weights sum to pi. Fresh arrays are returned on every call (safe to modify).
    """
    builder = None
    if isinstance(n_points, (int, np.integer)) and not isinstance(n_points, bool):
        builder = _BUILDERS.get(int(n_points))
    if builder is None:
        raise ValueError(
            f"unit-disk quadrature is available for n_points in {list(ALLOWED_N_POINTS)}, "
            f"got {n_points!r}"
        )
    return builder()


def disk_monomial_integral(a: int, b: int) -> float:
    """Exact integral of ``x**a * y**b`` over the unit disk.

    Zero if ``a`` or ``b`` is odd, else
    ``2 Gamma((a+1)/2) Gamma((b+1)/2) / ((a+b+2) Gamma((a+b+2)/2))``.
    """
    if a < 0 or b < 0:
        raise ValueError("monomial exponents must be non-negative")
    if a % 2 or b % 2:
        return 0.0
    if a + b < 300:  # Gamma((a+b+2)/2) stays finite: use it directly (most accurate)
        val = (math.gamma((a + 1) / 2) * math.gamma((b + 1) / 2)
               / math.gamma((a + b + 2) / 2))
    else:
        val = math.exp(math.lgamma((a + 1) / 2) + math.lgamma((b + 1) / 2)
                       - math.lgamma((a + b + 2) / 2))
    return 2.0 * val / (a + b + 2)
