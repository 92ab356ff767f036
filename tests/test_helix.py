"""Analytical helix of thesis chapter 3: every root satisfies the string equations."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rve.analytic.helix import (
    HelixSolution,
    helix_frame,
    helix_solutions,
    omega_roots,
    static_wire_reference,
)

THESIS_CASE = (0.1, 0.5, math.pi / 4)  # Table 6.1: k = IB/EA, delta = L/2, phi

CASES = [
    THESIS_CASE,
    (0.0, 0.075, math.pi / 4),  # Figure 3.5.1 (rigid-string limit: many roots)
    (0.3, 0.2, math.pi / 3),
    (-0.2, 0.4, 2.0),
    (1.0, 0.8, 0.5),
    (0.05, 1.2, 1.0),  # supports farther apart than the wire's length
    (2.5, 0.3, -1.1),
    (0.1, 0.5, math.pi / 2),  # alpha = 0
]

P = np.linspace(-1.0, 1.0, 401)


def _all(case, **kw):
    sols = helix_solutions(*case, **kw)
    assert sols, case
    return sols


@pytest.mark.parametrize("case", CASES)
def test_every_root_satisfies_force_balance(case):
    for h in _all(case):
        res = (0.0 * h.dx_dp(P)  # U' = 0: the stretch is uniform by construction
               + (h.U - 1.0) * h.d2x_dp2(P) + h.k * h.U * np.cross(h.dx_dp(P), h.a))
        scale = max(1.0, abs(h.r) * h.omega**2 * abs(h.U))
        assert np.abs(res).max() < 1e-12 * scale, (case, h)
        np.testing.assert_array_equal(res, h.force_balance_residual(P))


@pytest.mark.parametrize("case", CASES)
def test_every_root_satisfies_end_conditions_and_stretch(case):
    k, delta, phi = case
    for h in _all(case):
        ends = h.x(np.array([-1.0, 1.0]))
        np.testing.assert_allclose(ends[0], -delta * h.e_delta, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ends[1], delta * h.e_delta, rtol=0, atol=1e-12)
        speed = np.linalg.norm(h.dx_dp(P), axis=-1)
        assert h.U > 0
        np.testing.assert_allclose(speed, h.U, rtol=0, atol=1e-12)
        # the scalar parameters of thesis section 3.6
        assert h.alpha == pytest.approx(delta * math.cos(phi), abs=1e-15)
        assert h.U == pytest.approx(h.omega / (h.omega - k), rel=1e-15)
        assert h.tension == pytest.approx(h.U - 1.0, abs=1e-15)
        assert h.d == pytest.approx(-h.r * math.cos(h.omega), abs=1e-15)
        assert abs(h.r) == pytest.approx(
            math.sqrt(1 / (h.omega - k) ** 2 - (delta * math.cos(phi)) ** 2 / h.omega**2), rel=1e-13)
        # the thesis root equation, with the sign of r
        lhs = delta * math.sin(phi)
        rhs = h.r_sign * math.sin(h.omega) * math.sqrt(
            1 / (h.omega - k) ** 2 - (delta * math.cos(phi)) ** 2 / h.omega**2)
        assert abs(lhs - rhs) < 1e-12
        assert h.centre_displacement == pytest.approx(abs(h.r * (1 - math.cos(h.omega))), abs=1e-13)


@pytest.mark.parametrize("case", CASES[:4])
def test_derivatives_match_finite_differences(case):
    eps = 1e-5
    p = np.linspace(-0.9, 0.9, 37)
    for h in _all(case):
        fd1 = (h.x(p + eps) - h.x(p - eps)) / (2 * eps)
        fd2 = (h.dx_dp(p + eps) - h.dx_dp(p - eps)) / (2 * eps)
        sc = max(1.0, abs(h.r) * h.omega**2)
        assert np.abs(fd1 - h.dx_dp(p)).max() < 1e-8 * sc
        assert np.abs(fd2 - h.d2x_dp2(p)).max() < 1e-8 * sc


def test_shapes():
    h = static_wire_reference(*THESIS_CASE)
    assert h.x(0.3).shape == (3,)
    assert h.x(P).shape == (P.size, 3)
    assert h.dx_dp(P.reshape(-1, 1)).shape == (P.size, 1, 3)
    assert h.d2x_dp2(P).shape == (P.size, 3)


def _brute_force_count(k, delta, phi, n=400_001):
    """Independent count of sign changes of the thesis equation on a uniform grid."""
    al = delta * math.cos(phi)
    M = 1 / abs(delta * math.sin(phi))
    w = np.linspace(k - M - 1e-6, k + M + 1e-6, n)
    w = w[(np.abs(w) > 1e-9) & (np.abs(w - k) > 1e-9)]
    U = w / (w - k)
    q = 1 / (w - k) ** 2 - al**2 / w**2
    ok = (q > 0) & (U > 0)
    count = 0
    for s in (1, -1):
        f = s * np.sin(w) * np.sqrt(np.where(ok, q, 0.0)) - delta * math.sin(phi)
        ch = (np.sign(f[:-1]) != np.sign(f[1:])) & ok[:-1] & ok[1:]
        ch &= ~((w[:-1] < k) & (w[1:] > k)) & ~((w[:-1] < 0) & (w[1:] > 0))
        count += int(ch.sum())
    return count


@pytest.mark.parametrize("case", CASES)
def test_finds_every_root(case):
    assert len(helix_solutions(*case)) == _brute_force_count(*case)


def test_thesis_case_root_structure_and_reference_value():
    sols = helix_solutions(*THESIS_CASE)
    # three admissible helices: two compressive (w < 0, r < 0), one in tension
    assert [h.is_tension for h in sols] == [False, False, True]
    assert [h.r_sign for h in sols] == [-1, -1, 1]
    h = static_wire_reference(*THESIS_CASE)
    assert (h.omega, h.r) == (sols[-1].omega, sols[-1].r)
    assert round(h.U, 3) == 1.047  # printed in the thesis
    assert round(h.centre_displacement, 5) == 0.71243  # Table 6.1 (docs/analytic_helix.md)
    assert h.omega == pytest.approx(2.2202787605, abs=1e-9)
    assert h.centre_displacement == pytest.approx(0.7124254037, abs=1e-9)


def test_frames_and_bulge_direction():
    k, delta, phi = THESIS_CASE
    a, e_delta, e_r = helix_frame(phi)
    np.testing.assert_allclose(a, [math.cos(phi), 0, math.sin(phi)])
    np.testing.assert_allclose(e_delta, [1, 0, 0])
    np.testing.assert_allclose(np.cross(e_delta, a), math.sin(phi) * e_r, atol=1e-15)
    # current along +e1, B with a +e3 component: I e1 x B points to -y ...
    push = np.cross([1.0, 0, 0], a)
    assert push[1] < 0
    # ... and the reference helix bulges there (it is the +r side in this frame)
    h = static_wire_reference(k, delta, phi)
    x0 = h.x(0.0)
    assert h.r > 0 and x0[1] < 0 and abs(x0[0]) < 1e-15 and abs(x0[2]) < 1e-15
    # the thesis frame (a = e1, e_delta in the xz plane): same helix, bulging to +y
    ht = static_wire_reference(k, delta, phi, frame="thesis")
    assert ht.x(0.0)[1] > 0
    assert ht.centre_displacement == pytest.approx(h.centre_displacement, abs=1e-15)
    at, edt, ert = helix_frame(phi, "thesis")
    np.testing.assert_allclose(np.cross(edt, at), math.sin(phi) * ert, atol=1e-15)
    # reversing the current (k -> -k) moves the bulge to the other side
    hn = static_wire_reference(-k, delta, phi)
    assert hn.is_tension and hn.x(0.0)[1] > 0
    with pytest.raises(ValueError):
        helix_frame(phi, "nope")


def test_reference_is_lowest_tension_root_on_pushed_side():
    for case in CASES:
        k, delta, phi = case
        if k == 0:
            with pytest.raises(ValueError):
                static_wire_reference(*case)
            continue
        h = static_wire_reference(*case)
        push = k * np.cross(h.e_delta, h.a)
        others = [g for g in helix_solutions(*case)
                  if g.is_tension and np.dot(g.x(0.0), push) > 0]
        assert h.is_tension and np.dot(h.x(0.0), push) > 0
        assert all(abs(h.omega) <= abs(g.omega) for g in others)


def test_negative_r_roots_differ_from_flipping_r():
    """A root of the r > 0 equation with r flipped does not meet the supports."""
    h = static_wire_reference(*THESIS_CASE)
    flipped = HelixSolution(h.k, h.delta, h.phi, h.omega, -h.r, h.a, h.e_delta, h.e_r)
    assert np.abs(flipped.x(1.0) - h.delta * h.e_delta).max() > 0.1
    for s in (1, -1):
        for w in omega_roots(*THESIS_CASE, r_sign=s):
            assert np.sign(math.sin(w)) == s  # sin(phi) > 0: sign(r) = sign(sin w)


def test_zero_field_limit_symmetry():
    """k = 0 (Figure 3.5.1): roots come in pairs w <-> -w with opposite r sign."""
    k, delta, phi = CASES[1]
    plus = omega_roots(k, delta, phi, 1)
    minus = omega_roots(k, delta, phi, -1)
    np.testing.assert_allclose(np.sort(-minus), plus, rtol=1e-13)
    assert len(plus) > 5  # a small support distance allows many circularities
    for h in helix_solutions(k, delta, phi):
        assert h.U == 1.0 and h.tension == 0.0


def test_inverted_branch_is_opt_in():
    k, delta, phi = THESIS_CASE
    base = helix_solutions(k, delta, phi)
    allsol = helix_solutions(k, delta, phi, include_inverted=True)
    extra = [h for h in allsol if h.U <= 0]
    assert len(allsol) == len(base) + len(extra) and extra
    for h in extra:
        assert 0 < h.omega < k
        # the formal equation still holds, with |x'| = |U|
        assert np.abs(h.force_balance_residual(P)).max() < 1e-12 * max(1, abs(h.r) * h.omega**2)
        np.testing.assert_allclose(np.linalg.norm(h.dx_dp(P), axis=-1), abs(h.U), atol=1e-12)


@pytest.mark.parametrize("bad", [(0.1, 0.0, 1.0), (0.1, -0.5, 1.0), (0.1, 0.5, 0.0), (0.1, 0.5, math.pi)])
def test_degenerate_inputs_are_errors(bad):
    with pytest.raises(ValueError):
        helix_solutions(*bad)
    with pytest.raises(ValueError):
        omega_roots(*bad)
