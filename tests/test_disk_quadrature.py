"""Unit-disk quadrature (thesis Appendix B) against exact monomial integrals."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rve.fem.disk_quadrature import (
    ALLOWED_N_POINTS,
    DISK_RULE_DEGREE,
    disk_monomial_integral,
    disk_rule,
)

TOL = 1e-13


def _apply(n, a, b):
    pts, w = disk_rule(n)
    return float(np.sum(w * pts[:, 0] ** a * pts[:, 1] ** b))


def _monomials(degree):
    return [(a, degree - a) for a in range(degree + 1)]


def test_allowed_values_and_degrees_table():
    assert ALLOWED_N_POINTS == (4, 8, 16)
    assert DISK_RULE_DEGREE == {4: 3, 8: 5, 16: 7}


@pytest.mark.parametrize("bad", [0, 1, 3, 5, 7, 9, 12, 32, -4, 8.0, 8.5, "8", None, True])
def test_unknown_rule_is_a_value_error_naming_the_allowed_values(bad):
    with pytest.raises(ValueError, match=r"\[4, 8, 16\]"):
        disk_rule(bad)


@pytest.mark.parametrize("n", [4, 8, 16])
def test_shapes_and_weights(n):
    pts, w = disk_rule(n)
    assert pts.shape == (n, 2) and w.shape == (n,)
    assert pts.dtype == float and w.dtype == float
    assert np.all(w > 0)
    assert abs(w.sum() - math.pi) < TOL
    # points are distinct
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
    assert np.all(d[~np.eye(n, dtype=bool)] > 1e-3)


def test_fresh_arrays_each_call():
    p1, w1 = disk_rule(16)
    p1[:] = 0.0
    w1[:] = 0.0
    p2, w2 = disk_rule(16)
    assert abs(w2.sum() - math.pi) < TOL and np.abs(p2).max() > 0.5


def test_point_radii():
    """4 and 16 lie inside the disk; the 8-point rule's outer ring lies outside (documented)."""
    r4 = np.hypot(*disk_rule(4)[0].T)
    r8 = np.hypot(*disk_rule(8)[0].T)
    r16 = np.hypot(*disk_rule(16)[0].T)
    assert r4.max() < 1 and r16.max() < 1
    np.testing.assert_allclose(np.sort(r16**2), [0.5 - math.sqrt(3) / 6] * 8 + [0.5 + math.sqrt(3) / 6] * 8, atol=1e-15)
    np.testing.assert_allclose(np.sort(r8**2), [1 - math.sqrt(3) / 3] * 4 + [1 + math.sqrt(3) / 3] * 4, atol=1e-15)
    assert r8.max() > 1.25


def test_exact_moments_closed_form_against_known_values_and_numerics():
    assert disk_monomial_integral(0, 0) == pytest.approx(math.pi, abs=1e-15)
    assert disk_monomial_integral(2, 0) == pytest.approx(math.pi / 4, abs=1e-15)
    assert disk_monomial_integral(4, 0) == pytest.approx(math.pi / 8, abs=1e-15)
    assert disk_monomial_integral(2, 2) == pytest.approx(math.pi / 24, abs=1e-15)
    assert disk_monomial_integral(1, 2) == 0.0 and disk_monomial_integral(4, 3) == 0.0
    # independent check of the Gamma formula in polar coordinates: the radial factor is
    # int_0^1 r^(a+b+1) dr = 1/(a+b+2); the angular factor is a trigonometric polynomial of
    # degree a+b, integrated exactly by the periodic trapezoidal rule with 64 > a+b points
    th = np.arange(64) * (2 * math.pi / 64)
    for a, b in [(0, 0), (2, 0), (0, 4), (2, 2), (4, 2), (6, 4), (3, 1), (8, 0), (10, 6)]:
        ang = float(np.sum(np.cos(th) ** a * np.sin(th) ** b)) * (2 * math.pi / 64)
        assert abs(ang / (a + b + 2) - disk_monomial_integral(a, b)) < 1e-13, (a, b)
    with pytest.raises(ValueError):
        disk_monomial_integral(-1, 0)


@pytest.mark.parametrize("n", [4, 8, 16])
def test_exact_up_to_stated_degree(n):
    deg = DISK_RULE_DEGREE[n]
    for d in range(deg + 1):
        for a, b in _monomials(d):
            err = abs(_apply(n, a, b) - disk_monomial_integral(a, b))
            assert err < TOL, (n, a, b, err)


@pytest.mark.parametrize("n", [4, 8, 16])
def test_not_exact_beyond_stated_degree(n):
    """The degree claim is sharp: some monomial of degree deg+1 (all rules here are
    centrally symmetric, so odd degrees are always exact -> then deg+2) fails clearly."""
    deg = DISK_RULE_DEGREE[n]
    worst = {}
    for d in (deg + 1, deg + 2):
        worst[d] = max(abs(_apply(n, a, b) - disk_monomial_integral(a, b)) for a, b in _monomials(d))
    assert max(worst.values()) > 1e-4, worst
    # the first failing degree is deg + 1 (all three stated degrees are odd -> deg+1 is even)
    assert worst[deg + 1] > 1e-4, worst


@pytest.mark.parametrize("n", [4, 8, 16])
def test_exact_for_rotated_polynomial(n):
    """Exactness holds for a generic polynomial of the stated degree, not just monomials."""
    rng = np.random.default_rng(n)
    deg = DISK_RULE_DEGREE[n]
    coeffs = {(a, d - a): rng.standard_normal() for d in range(deg + 1) for a in range(d + 1)}
    pts, w = disk_rule(n)
    vals = sum(c * pts[:, 0] ** a * pts[:, 1] ** b for (a, b), c in coeffs.items())
    exact = sum(c * disk_monomial_integral(a, b) for (a, b), c in coeffs.items())
    assert abs(np.sum(w * vals) - exact) < 1e-12


def test_scaled_section_integral():
    """Appendix B usage: integral over a section of radius R is R**2 * sum w f(R xi)."""
    R = 0.15
    pts, w = disk_rule(16)
    # second moment of area of a circle: pi R^4 / 4
    approx = R**2 * np.sum(w * (R * pts[:, 0]) ** 2)
    assert abs(approx - math.pi * R**4 / 4) < 1e-16
