"""Analytical helix solution for a current-carrying elastic string in a uniform field.

Thesis chapter 3 (Queiruga 2015), nondimensionalised with the half-length L = 1.

Problem
-------
An elastic string of reference length 2 (reference coordinate p in [-1, 1]) is pinned at
``x(-1) = -delta e_delta`` and ``x(1) = +delta e_delta``, carries a current I flowing in the
direction of increasing p (from the -delta pin to the +delta pin) and sits in a uniform
field ``B = B a``. With the linear tension ``T = EA (U - 1)``, U = |dx/dp| the stretch, and
``k = I B / (E A)``, the force balance in the reference configuration is (thesis 3.4.40)::

    0 = U' x' + (U - 1) x'' + k U x' x a          (' = d/dp)

Solution (thesis 3.4.44-3.4.47, section 3.6)
--------------------------------------------
Helices about the field axis with constant stretch::

    x(p) = alpha p a + r cos(w p) e_r + r sin(w p) (a x e_r) + d e_r
    U = w / (w - k),  alpha = delta cos(phi),  d = -r cos(w),
    r**2 = 1/(w - k)**2 - alpha**2 / w**2          (arc length: alpha**2 + r**2 w**2 = U**2)
    delta sin(phi) = r sin(w)                       (end condition along a x e_r)

where phi is the angle between a and e_delta and e_r is the unit vector fixed by
``e_delta x a = sin(phi) e_r`` (so ``e_delta = cos(phi) a + sin(phi) (a x e_r)``).

Roots and signs of r. The thesis writes the last condition with r = +sqrt(...). Flipping
the sign of r at the *same* w does not satisfy the end conditions in a fixed frame; the
solutions "with negative r" are the roots of ``delta sin(phi) = -sin(w) sqrt(...)``, i.e.
r = delta sin(phi) / sin(w) with the sign of sin(w). :func:`omega_roots` solves
``delta sin(phi) = s sin(w) sqrt(1/(w-k)**2 - alpha**2/w**2)`` for a chosen sign s of r;
:func:`helix_solutions` returns every (w, s) pair. Admissible w: the square root is real
(``U**2 >= alpha**2``) and the stretch is positive (``U > 0``, which excludes w between 0
and k: there the formal solution has U < 0, an orientation-reversed string; it can be
requested with ``include_inverted=True``). Tension branch: U > 1 (w > k for k > 0);
compression: 0 < U < 1 (w < 0 for k > 0). All roots lie in ``|w - k| <= 1/(delta |sin phi|)``.

Coordinate frames
-----------------
``frame="project"`` (default; the project's static-wire scene): supports along e1,
``e_delta = (1, 0, 0)``, field in the x-z plane ``a = (cos phi, 0, sin phi)``. Then
``e_r = e_delta x a / sin(phi) = (0, -1, 0)`` and ``a x e_r = (sin phi, 0, -cos phi)``.
A straight wire carrying current along +e1 is pushed by ``I e1 x B = -I B sin(phi) e2``:
for k > 0 and 0 < phi < pi it bulges toward **-y**, which is the **+r** side. In general
positive r means a bulge toward ``e_r``, the side the current pushes toward when
``k sin(phi) > 0``.

``frame="thesis"`` (Figure 3.1.1): ``a = e1``, ``e_delta = (cos phi, 0, sin phi)``,
``e_r = e2``; the current pushes toward +y.

Any frame satisfies ``e_delta x a = sin(phi) e_r``; ``sin(phi) = 0`` or ``delta <= 0``
(infinitely many or no meaningful roots) is a ValueError.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

__all__ = [
    "HelixSolution",
    "helix_frame",
    "omega_roots",
    "helix_solutions",
    "static_wire_reference",
]

_FRAMES = ("project", "thesis")


def helix_frame(phi: float, frame: str = "project") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit vectors ``(a, e_delta, e_r)`` with ``e_delta x a = sin(phi) e_r``."""
    c, s = math.cos(phi), math.sin(phi)
    if frame == "project":
        e_delta = np.array([1.0, 0.0, 0.0])
        a = np.array([c, 0.0, s])
        e_r = np.array([0.0, -1.0, 0.0])
    elif frame == "thesis":
        a = np.array([1.0, 0.0, 0.0])
        e_delta = np.array([c, 0.0, s])
        e_r = np.array([0.0, 1.0, 0.0])
    else:
        raise ValueError(f"frame must be one of {_FRAMES}, got {frame!r}")
    return a, e_delta, e_r


def _check_inputs(delta: float, phi: float) -> None:
    if not (np.isfinite(delta) and delta > 0):
        raise ValueError(f"delta must be positive, got {delta!r}")
    if abs(math.sin(phi)) < 1e-12:
        raise ValueError(
            "sin(phi) = 0 (field along the supports): the root equation degenerates "
            "(no bulging force; infinitely many formal roots)"
        )


def _numerator(w: np.ndarray, k: float, alpha: float, dsin: float, s: int) -> np.ndarray:
    """|w| |w - k| times (s sin w sqrt(1/(w-k)^2 - alpha^2/w^2) - delta sin phi).

    Same roots as the thesis equation away from w = 0 and w = k, but continuous and bounded
    there (no poles), so sign changes on a grid are genuine roots.
    """
    rad = np.maximum(w * w - alpha * alpha * (w - k) ** 2, 0.0)
    return s * np.sin(w) * np.sqrt(rad) - dsin * np.abs(w * (w - k))


def _admissible_intervals(k: float, alpha: float, wmin: float, wmax: float,
                          include_inverted: bool) -> list[tuple[float, float]]:
    aa = abs(alpha)
    cuts = {wmin, wmax, 0.0, k, aa * k / (1.0 + aa)}
    if aa != 1.0:
        cuts.add(-aa * k / (1.0 - aa))
    pts = sorted(c for c in cuts if wmin <= c <= wmax)
    out = []
    for lo, hi in zip(pts[:-1], pts[1:]):
        if hi - lo <= 0:
            continue
        m = 0.5 * (lo + hi)
        if m == 0.0 or m == k:
            continue
        U = m / (m - k)
        if U * U - alpha * alpha <= 0:
            continue
        if U <= 0 and not include_inverted:
            continue
        out.append((lo, hi))
    return out


def _grid(lo: float, hi: float, h: float) -> np.ndarray:
    n = max(int(math.ceil((hi - lo) / h)), 8)
    uni = np.linspace(lo, hi, n + 1)
    # geometric clustering toward both ends (roots near w = k, w = 0 or a radicand zero)
    width = hi - lo
    g = width * np.logspace(-14, -1, 60)
    pts = np.concatenate([uni, lo + g, hi - g])
    pts = np.unique(pts[(pts > lo) & (pts < hi)])
    return pts


def omega_roots(k: float, delta: float, phi: float, r_sign: int = 1, *,
                include_inverted: bool = False, grid_step: float = 1e-2) -> np.ndarray:
    """All roots w of ``delta sin(phi) = r_sign sin(w) sqrt(1/(w-k)^2 - (delta cos phi)^2/w^2)``.

    Only admissible roots are returned (real square root, U = w/(w-k) > 0 unless
    ``include_inverted``), sorted by increasing w. Roots are bracketed by sign changes on
    a grid of spacing ``grid_step`` (refined geometrically toward the ends of every
    admissible interval) and polished with brentq to machine precision. A root where the
    curve only touches zero without crossing (a double root, non-generic) can be missed.
    """
    _check_inputs(delta, phi)
    if r_sign not in (1, -1):
        raise ValueError("r_sign must be +1 or -1")
    k = float(k)
    alpha = delta * math.cos(phi)
    dsin = delta * math.sin(phi)
    M = 1.0 / abs(dsin)
    M = M * (1.0 + 1e-9) + 1e-9
    roots: list[float] = []
    f = lambda w: float(_numerator(np.asarray(w), k, alpha, dsin, r_sign))  # noqa: E731
    for lo, hi in _admissible_intervals(k, alpha, k - M, k + M, include_inverted):
        w = _grid(lo, hi, grid_step)
        v = _numerator(w, k, alpha, dsin, r_sign)
        exact = w[v == 0.0]
        roots.extend(float(x) for x in exact)
        sc = np.nonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)[0]
        for i in sc:
            roots.append(brentq(f, w[i], w[i + 1], xtol=1e-300, rtol=4 * np.finfo(float).eps,
                                maxiter=200))
    roots = sorted(roots)
    out: list[float] = []
    for x in roots:
        if x == 0.0 or x == k:
            continue
        if out and abs(x - out[-1]) <= 1e-13 * max(1.0, abs(x)):
            continue
        out.append(x)
    return np.array(out)


@dataclass(frozen=True, eq=False)
class HelixSolution:
    """One equilibrium helix (nondimensional, L = 1). See the module docstring.

    ``r`` is signed; ``a``, ``e_delta``, ``e_r`` are the frame vectors (3,), expected to
    satisfy ``e_delta x a = sin(phi) e_r`` (as :func:`helix_frame` builds them).
    Instances compare by identity (they hold arrays).
    """

    k: float
    delta: float
    phi: float
    omega: float
    r: float
    a: np.ndarray = field(repr=False)
    e_delta: np.ndarray = field(repr=False)
    e_r: np.ndarray = field(repr=False)

    # -- scalar parameters -------------------------------------------------------------
    @property
    def alpha(self) -> float:
        return self.delta * math.cos(self.phi)

    @property
    def d(self) -> float:
        return -self.r * math.cos(self.omega)

    @property
    def U(self) -> float:
        """Stretch U = w / (w - k) (constant along the wire)."""
        return self.omega / (self.omega - self.k)

    stretch = U

    @property
    def tension(self) -> float:
        """Tension in units of EA: U - 1 (negative = compression)."""
        return self.U - 1.0

    @property
    def is_tension(self) -> bool:
        return self.U > 1.0

    @property
    def r_sign(self) -> int:
        return 1 if self.r > 0 else -1

    @property
    def turns(self) -> float:
        """Number of helix turns along the wire, |2 w| / (2 pi)."""
        return abs(self.omega) / math.pi

    @property
    def a_cross_er(self) -> np.ndarray:
        return np.cross(self.a, self.e_r)

    @property
    def centre_displacement(self) -> float:
        """Distance of the mid point x(0) from the support line (= |r (1 - cos w)|)."""
        x0 = self.x(0.0)
        perp = x0 - np.dot(x0, self.e_delta) * self.e_delta
        return float(np.linalg.norm(perp))

    # -- fields along the wire ---------------------------------------------------------
    def _parts(self, p):
        p = np.asarray(p, dtype=float)
        wp = self.omega * p
        return p, np.cos(wp), np.sin(wp)

    @staticmethod
    def _combine(ca, cr, cb, a, er, b):
        return (np.multiply.outer(ca, a) + np.multiply.outer(cr, er)
                + np.multiply.outer(cb, b))

    def x(self, p):
        """Position, shape ``p.shape + (3,)``."""
        p, c, s = self._parts(p)
        return self._combine(self.alpha * p, self.r * c + self.d, self.r * s,
                             self.a, self.e_r, self.a_cross_er)

    def dx_dp(self, p):
        p, c, s = self._parts(p)
        rw = self.r * self.omega
        return self._combine(np.full_like(p, self.alpha), -rw * s, rw * c,
                             self.a, self.e_r, self.a_cross_er)

    def d2x_dp2(self, p):
        p, c, s = self._parts(p)
        rw2 = self.r * self.omega ** 2
        return self._combine(np.zeros_like(p), -rw2 * c, -rw2 * s,
                             self.a, self.e_r, self.a_cross_er)

    def force_balance_residual(self, p):
        """(U - 1) x'' + k U x' x a (thesis 3.4.40 with U' = 0); zero for a solution."""
        xp = self.dx_dp(p)
        return (self.U - 1.0) * self.d2x_dp2(p) + self.k * self.U * np.cross(xp, self.a)


def helix_solutions(k: float, delta: float, phi: float, *, frame: str = "project",
                    include_inverted: bool = False, grid_step: float = 1e-2) -> list[HelixSolution]:
    """Every admissible helix (both signs of r), sorted by |w| then by sign of r (+ first)."""
    a, e_delta, e_r = helix_frame(phi, frame)
    alpha = delta * math.cos(phi)
    sols = []
    for s in (1, -1):
        for w in omega_roots(k, delta, phi, s, include_inverted=include_inverted,
                             grid_step=grid_step):
            rad = 1.0 / (w - k) ** 2 - alpha ** 2 / w ** 2
            r = s * math.sqrt(max(rad, 0.0))
            sols.append(HelixSolution(float(k), float(delta), float(phi), float(w), r,
                                      a, e_delta, e_r))
    sols.sort(key=lambda h: (abs(h.omega), -h.r_sign))
    return sols


def static_wire_reference(k: float, delta: float, phi: float, *,
                          frame: str = "project") -> HelixSolution:
    """The helix a straight wire relaxes into: tension (U > 1), bulging to the side the
    current pushes the straight wire (``k e_delta x a``), lowest circularity (smallest |w|).

    For the thesis case (k, delta, phi) = (0.1, 0.5, pi/4): U = 1.04716,
    centre displacement 0.712425.
    """
    if k == 0:
        raise ValueError("k = 0: no current/field, the straight wire is not pushed")
    a, e_delta, _ = helix_frame(phi, frame)
    push = k * np.cross(e_delta, a)
    cands = [h for h in helix_solutions(k, delta, phi, frame=frame)
             if h.is_tension and np.dot(h.x(0.0), push) > 0]
    if not cands:
        raise ValueError(f"no tension helix on the pushed side for k={k}, delta={delta}, phi={phi}")
    return min(cands, key=lambda h: abs(h.omega))
