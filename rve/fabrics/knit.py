"""Knitted RVE from the thesis loop curve with Frenet-Serret directors (thesis §5.4).

The designed curve (thesis Fig. 5.4.1), in the curve's own axes (e1, e2, e3)::

    y(X3) = A1 cos(p X3 / 2) e1 + A2 cos(p X3) e2 + ((1 + C) X3 + B sin(p X3)) e3

C is a uniform "squishing", B the forward-backward amplitude (the curve runs backwards,
making a loop, where ``B p > 1 + C``), A1 and A2 the sideways amplitudes, p the looping
wave number. One loop advances ``loop_length = 2 pi (1 + C) / p`` along e3.

Lab axes: e3 -> x (the course direction), e1 -> y (across courses), e2 -> z (out of the
fabric plane); a cyclic permutation, so frames stay right-handed.

Parameter s
-----------
For a knit the designed curve **is** the natural (reference) configuration, so the
``Fibril`` is curved and ``initial_state`` returns the reference itself. The fibril
parameter is ``s = X3 - X3_start in [0, length]`` with ``X3_start = -length / 2`` and
``length = n_loops * loop_length / (1 + C)``; s is *not* arc length (the beam kinematics
only need a consistent parametrisation, F = (dx/dxi)(dX0/dxi)^-1). ``p X3`` runs over
``[-n_loops pi, n_loops pi]`` so the yarn ends sit at x = -+ n_loops * loop_length / 2.

Directors (``CurveFrame``)
--------------------------
Following the thesis, the directors of the yarn axis are the Frenet-Serret frame built
from y' and y''::

    G1 = y' x y'' / |y' x y''|          (binormal)
    G2 = y' x (y' x y'') / |...|        (minus the principal normal)

so (G1, G2, y'/|y'|) is right-handed and G1, G2 are orthonormal and perpendicular to the
tangent. Where the curvature vanishes (y'' = 0 or y'' parallel to y') the Frenet frame
is undefined and, at an inflection of a planar curve, it flips by pi. The frame is made
continuous as follows: a reference field U(s), perpendicular to the tangent and
continuous, is carried along the curve on a fine grid (projected transport, starting
from the Frenet G1 or, if the start is straight, from e_z projected); G1 is written as
the angle theta from U. Where the curvature kappa = |y' x y''| / |y'|^3 exceeds
``10 * kappa_tol`` (``kappa_tol = curvature_tol * max kappa``) theta is the exact Frenet
angle on the branch (mod pi) nearest the grid-continued value: G1 = +-binormal, G2 =
-+normal (a flip by pi is absorbed, which keeps a planar sine's frame constant through
its inflections). Where kappa < kappa_tol theta is interpolated linearly in s between
the neighbouring Frenet values (constant beyond the last one; zero, i.e. G1 = U, on a
straight curve), and in between the two are blended smoothly.

Yarns of several fibrils
------------------------
A yarn holds fibrils at the offsets ``hex_stack_offsets(rows, d)`` = (a, b) in the
(G1, G2) plane of the yarn axis: ``r_f(s) = y(s) + a G1(s) + b G2(s)``. Each fibril's own
directors are the yarn's G1 made perpendicular to the fibril's tangent (computed by a
central difference of r_f) and G2 = t_f x G1. The offsets must stay below the radius of
curvature of the yarn axis (checked).
"""
from __future__ import annotations

import numpy as np

from rve.fem.mesh import Fibril

from .fabric import EndTag, Fabric, Yarn, hex_stack_offsets

__all__ = ["CurveFrame", "frenet_directors", "knit", "knit_curve"]

# local curve axes (e1, e2, e3) -> lab (y, z, x): lab = local[:, _LAB]
_LAB = [2, 0, 1]


def knit_curve(X3, A1=0.8, A2=0.4, B=0.5, C=0.0, p=np.pi):
    """y, y', y'' (each (n, 3), in the curve axes e1, e2, e3) of the thesis knit curve."""
    X = np.asarray(X3, float)
    h, f = p * X / 2.0, p * X
    z0 = np.zeros_like(X)
    y = np.stack([A1 * np.cos(h), A2 * np.cos(f), (1.0 + C) * X + B * np.sin(f)], 1)
    d1 = np.stack([-A1 * p / 2 * np.sin(h), -A2 * p * np.sin(f),
                   (1.0 + C) + z0 + B * p * np.cos(f)], 1)
    d2 = np.stack([-A1 * p * p / 4 * np.cos(h), -A2 * p * p * np.cos(f),
                   -B * p * p * np.sin(f)], 1)
    return y, d1, d2


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def frenet_directors(d1, d2):
    """Pointwise thesis directors: T, G1 = y'xy''/|.|, G2 = y'x(y'xy'')/|.|, kappa.

    Where y' x y'' = 0 the returned G1, G2 are zero (undefined); see ``CurveFrame``.
    """
    d1 = np.asarray(d1, float)
    d2 = np.asarray(d2, float)
    b = np.cross(d1, d2)
    sp = np.linalg.norm(d1, axis=1)
    kappa = np.linalg.norm(b, axis=1) / sp ** 3
    return _unit(d1), _unit(b), _unit(np.cross(d1, b)), kappa


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


class CurveFrame:
    """Continuous Frenet-Serret directors of a curve on ``[s0, s1]`` (module docstring).

    ``d1(s)``, ``d2(s)`` return y' and y'' (n, 3). Calling the frame with s (n,) returns
    ``(T, G1, G2)``, each (n, 3), orthonormal with G1 x G2 = T.
    """

    def __init__(self, d1, d2, s0: float, s1: float, n_grid: int = 4097,
                 curvature_tol: float = 1e-6, helper=(0.0, 0.0, 1.0)):
        self.d1, self.d2 = d1, d2
        self.grid = np.linspace(float(s0), float(s1), int(n_grid))
        T, G1F, _, kap = frenet_directors(d1(self.grid), d2(self.grid))
        kmax = float(kap.max())
        self.kappa_tol = curvature_tol * kmax if kmax > 0 else np.inf
        valid = kap > self.kappa_tol
        # continuous reference field U (projected transport along the grid)
        U = np.empty_like(T)
        if valid[0]:
            u = G1F[0]
        else:
            h = np.asarray(helper, float)
            u = h - (h @ T[0]) * T[0]
            if np.linalg.norm(u) < 1e-8:
                h = np.array([1.0, 0.0, 0.0])
                u = h - (h @ T[0]) * T[0]
        U[0] = u / np.linalg.norm(u)
        for k in range(1, len(T)):
            u = U[k - 1] - (U[k - 1] @ T[k]) * T[k]
            U[k] = u / np.linalg.norm(u)
        self.U = U
        theta_raw = self._angle(T, U, G1F)
        theta = np.zeros(len(T))
        idx = np.flatnonzero(valid)
        if idx.size:
            th = theta_raw[idx]
            # unwrap modulo pi: absorb Frenet flips at inflections
            steps = np.diff(th)
            th = th - np.pi * np.concatenate([[0.0], np.cumsum(np.round(steps / np.pi))])
            theta = np.interp(self.grid, self.grid[idx], th)
        self.theta = theta

    @staticmethod
    def _angle(T, U, G):
        return np.arctan2(np.einsum("ij,ij->i", G, np.cross(T, U)),
                          np.einsum("ij,ij->i", G, U))

    def __call__(self, s):
        s = np.atleast_1d(np.asarray(s, float))
        T, G1F, _, kap = frenet_directors(self.d1(s), self.d2(s))
        U = np.stack([np.interp(s, self.grid, self.U[:, c]) for c in range(3)], 1)
        U = _unit(U - np.einsum("ij,ij->i", U, T)[:, None] * T)
        th_ref = np.interp(s, self.grid, self.theta)
        w = _smoothstep((kap / self.kappa_tol - 1.0) / 9.0) if np.isfinite(self.kappa_tol) \
            else np.zeros_like(s)
        th_f = self._angle(T, U, G1F)
        th_f = th_f + np.pi * np.round((th_ref - th_f) / np.pi)
        th = np.where(w > 0, th_ref + w * (th_f - th_ref), th_ref)
        G1 = np.cos(th)[:, None] * U + np.sin(th)[:, None] * np.cross(T, U)
        G2 = np.cross(T, G1)
        return T, G1, G2


def knit(
    n_rows: int = 3,
    n_loops: int = 4,
    loop_length: float = 2.0,
    row_spacing: float = 1.0,
    A1: float = 0.9,
    A2: float = 0.5,
    B: float = 0.45,
    C: float = 0.0,
    row_phase: float = 0.5,
    fibril_diameter: float = 0.3,
    rows=(1, 2),
    n_grid: int = 4097,
) -> Fabric:
    """Rows (courses) of knitted loops as an RVE; each course a yarn of ``rows`` fibrils.

    Course r lies along x at ``y_r = (r - (n_rows - 1)/2) * row_spacing`` and is the
    curve shifted along itself by ``phi_r = (r * row_phase mod 1)`` loops (X3 -> X3 +
    phi_r * 2 pi / p, then translated back by phi_r loops in x: with the default 1/2 odd
    courses are shifted by half a loop; a shift by a whole loop would mirror the e1 term,
    hence the mod 1; a multiple of 1/2 keeps every yarn end on the box faces x = -+hx). The box is ``hx = n_loops * loop_length / 2``,
    ``hy = n_rows * row_spacing / 2``, ``hz = |A2| + stack reach + R``. ``rows=(1,)``
    gives one fibril per yarn. The defaults keep the yarn axes of neighbouring courses
    more than a yarn diameter apart (tests/test_fabrics.py).
    """
    if n_rows < 1 or n_loops < 1:
        raise ValueError("need at least one row and one loop")
    if abs(2.0 * row_phase - round(2.0 * row_phase)) > 1e-12:
        raise ValueError(f"row_phase must be a multiple of 1/2, got {row_phase}")
    d = float(fibril_diameter)
    R = d / 2.0
    p = 2.0 * np.pi * (1.0 + C) / float(loop_length)
    length = n_loops * loop_length / (1.0 + C)
    X_start = -length / 2.0
    par = dict(A1=A1, A2=A2, B=B, C=C, p=p)
    offsets = hex_stack_offsets(rows, d)
    reach = float(np.linalg.norm(offsets, axis=1).max())
    h_fd = 1e-6 * length

    fibrils, fib_yarn, yarns, tags, frames = [], [], [], [], []
    ycourse = (np.arange(n_rows) - (n_rows - 1) / 2.0) * row_spacing
    for r, yr in enumerate(ycourse):
        phi = ((r * row_phase) % 1.0) * 2.0 * np.pi / p
        shift = np.array([-(1.0 + C) * phi, yr, 0.0])

        def local(s, phi=phi):
            return knit_curve(X_start + phi + np.asarray(s, float), **par)

        d1 = lambda s, local=local: local(s)[1][:, _LAB]
        d2 = lambda s, local=local: local(s)[2][:, _LAB]
        frame = CurveFrame(d1, d2, 0.0, length, n_grid=n_grid)
        frames.append(frame)
        kmax = float(frenet_directors(d1(frame.grid), d2(frame.grid))[3].max())
        if reach > 0 and kmax * reach >= 1.0:
            raise ValueError(f"yarn stack reach {reach:.3g} mm exceeds the loop's radius "
                             f"of curvature {1 / kmax:.3g} mm: offset fibrils would fold")

        def axis(s, shift=shift, local=local):
            return local(s)[0][:, _LAB] + shift

        members = []
        for k, (a, b) in enumerate(offsets):

            def position(s, a=a, b=b, axis=axis, frame=frame):
                _, g1, g2 = frame(s)
                return axis(s) + a * g1 + b * g2

            def fib_frame(s, a=a, b=b, position=position, frame=frame):
                s = np.atleast_1d(np.asarray(s, float))
                T, g1, g2 = frame(s)
                r0 = position(s)
                if a == 0.0 and b == 0.0:
                    return r0, g1, g2
                t = _unit(position(s + h_fd) - position(s - h_fd))
                G1 = _unit(g1 - np.einsum("ij,ij->i", g1, t)[:, None] * t)
                return r0, G1, np.cross(t, G1)

            f = len(fibrils)
            fibrils.append(Fibril(length=length, radius=R, frame=fib_frame,
                                  name=f"loop{r}_f{k:02d}"))
            fib_yarn.append(r)
            tags.append(EndTag(f, "start", r, "x-"))
            tags.append(EndTag(f, "end", r, "x+"))
            members.append(f)
        yarns.append(Yarn(r, f"loop{r}", "loop", tuple(members), float(yr), axis))

    hz = abs(A2) + reach + R
    return Fabric(
        kind="knit",
        fibrils=fibrils,
        fibril_yarn=np.array(fib_yarn),
        yarns=yarns,
        half_widths=np.array([n_loops * loop_length / 2.0, n_rows * row_spacing / 2.0, hz]),
        end_tags=tags,
        designed=[fib.frame for fib in fibrils],
        params=dict(n_rows=n_rows, n_loops=n_loops, loop_length=loop_length,
                    row_spacing=row_spacing, A1=A1, A2=A2, B=B, C=C, p=p,
                    row_phase=row_phase, X3_start=X_start, fibril_diameter=d,
                    rows=tuple(rows), stack_offsets=offsets, frames=frames),
    )
