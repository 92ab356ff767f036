"""Woven RVEs from an interlacing pattern (thesis ch. 7, §5.4; docs/fabrics.md).

Layout (defaults = the thesis plain-weave RVE)
----------------------------------------------
* ``n_warp`` warp yarns along x at ``y_j = (j - (n_warp - 1)/2) * spacing`` and ``n_weft``
  weft yarns along y at ``x_i = (i - (n_weft - 1)/2) * spacing``; with 4 x 4 and a 2 mm
  spacing: y, x = -3, -1, 1, 3. Warp fibrils span ``x in [-hx, hx]``, weft fibrils
  ``y in [-hy, hy]``, ``hx = n_weft * spacing / 2``, ``hy = n_warp * spacing / 2`` (4 mm).
* Each yarn is a packed stack of fibrils (``rows``, bottom to top; 3-4-3 = 10 fibrils of
  diameter 0.3 mm), hexagonally packed in the yarn's cross-section plane and centred on
  the yarn axis (``hex_stack_offsets``). The lateral axis of a yarn with direction d is
  ``e_z x d`` (+y for warp, -x for weft); the vertical axis is the crimp-plane normal.

Interlacing pattern
-------------------
``pattern[j % m][i % n] = 1`` when warp j is on top of weft i at their crossing, 0 when
the weft is on top (rows: warp yarns, columns: weft yarns). At that crossing the warp
centreline is at ``z = +A`` (warp on top) or ``-A`` and the weft at the opposite value,
so the centrelines differ by ``2A`` in the right order. Between two consecutive crossings
of a yarn the centreline follows a half cosine between the two crossing heights (flat
when the yarn floats over or under both), with zero slope at every crossing; ends beyond
the first/last crossing continue the periodic pattern. For the plain weave
``[[1, 0], [0, 1]]`` this is exactly ``z = +-A sin(pi s / spacing)`` with the sign
alternating from yarn to yarn and warp/weft in opposite phase.

Reference and initial state (thesis §5.4, §7.4)
-----------------------------------------------
A fibril's **reference** (natural) configuration is straight: ``straight_fibril`` along
the yarn line at its stack offset (e.g. warp: from ``(-hx, y_j + l, v)`` to
``(hx, y_j + l, v)``), with directors ``G1 = e_z x t``, ``G2 = t x G1``. The parameter s is
the arc length of that straight line from the ``'start'`` end (x = -hx for warp,
y = -hy for weft). The **initial state** puts the node of parameter s at
``c(s) + l e_lat + v n(s)``: ``c`` the crimped yarn centreline at the same coordinate
along the yarn (x = -hx + s for warp), ``n(s)`` the unit normal of ``c`` in its crimp
plane (so the stack keeps its packing perpendicular to the curved axis). The crimped
fibrils are longer than the straight ones and cross each other's reference positions:
the initial state is stressed and may interpenetrate; relaxation resolves it. The
initial directors are the reference directors turned by the smallest rotation that takes
the reference tangent onto the designed tangent, so they stay orthonormal and
perpendicular to the displaced centroid tangent.
"""
from __future__ import annotations

import functools

import numpy as np

from rve.fem.mesh import straight_fibril

from ..config.weaves import WEAVE_PATTERNS, twill_pattern
from .fabric import EndTag, Fabric, Yarn, hex_stack_offsets, minimal_rotation

__all__ = [
    "WEAVE_PATTERNS",
    "basket_weave",
    "float_lengths",
    "plain_weave",
    "twill_pattern",
    "twill_weave",
    "weave",
]


def float_lengths(states) -> list[int]:
    """Cyclic run lengths of equal consecutive values (a yarn's floats over/under)."""
    st = np.asarray(states).ravel()
    if st.size == 0:
        return []
    change = np.flatnonzero(st != np.roll(st, 1))
    if change.size == 0:
        return [int(st.size)]
    starts = np.sort(change)
    return [int(v) for v in np.diff(np.append(starts, starts[0] + st.size))]


def _crimp(s, heights, first, spacing):
    """Crimp height z(s), z'(s), z''(s) through ``heights(k)`` at ``first + k*spacing``."""
    u = (s - first) / spacing
    k = np.floor(u).astype(int)
    u = u - k
    z0, z1 = heights(k), heights(k + 1)
    mean, half = 0.5 * (z0 + z1), 0.5 * (z0 - z1)
    w = np.pi / spacing
    z = mean + half * np.cos(np.pi * u)
    dz = -half * w * np.sin(np.pi * u)
    ddz = -half * w * w * np.cos(np.pi * u)
    return z, dz, ddz


def _end_parameter(target, v, heights, first, spacing):
    """c with c - v z'(c) / q(c) = target (Newton; monotone when v * curvature < 1)."""
    c = np.array([float(target)])
    for _ in range(50):
        _, dz, ddz = _crimp(c, heights, first, spacing)
        q = np.sqrt(1.0 + dz * dz)
        f = c - v * dz / q - target
        c = c - f / (1.0 - v * ddz / q ** 3)
        if abs(f[0]) < 1e-15 * (1.0 + abs(target)):
            break
    return float(c[0])


_EZ = np.array([0.0, 0.0, 1.0])


def _yarn_centre(s, base, heights, half, first, spacing):
    """The crimped centre line of a yarn at arc parameter ``s`` in [0, 2 half]."""
    c = np.asarray(s, float) - half
    z = _crimp(c, heights, first, spacing)[0]
    return base(c) + z[:, None] * _EZ


class _YarnLine:
    """One yarn's crimp line (``base(c)``: the straight line, ``heights``: the crimp heights
    at the crossings); ``designed(l, v, g1_ref, g2_ref)`` is the designed frame of the
    fibril at stack offset (l, v): ``s -> (r, g1, g2)``."""

    def __init__(self, base, heights, half, first, spacing, t_ref, lat):
        self.base, self.heights, self.half, self.first, self.sp = base, heights, half, first, spacing
        self.t_ref, self.lat = t_ref, lat

    def designed(self, l, v, g1_ref, g2_ref):
        # the normal offset v n(c) moves x by -v z'/q: pick the end parameters so
        # that the ends land on the box faces, and map s linearly onto [c0, c1]
        half, t_ref, lat, ez = self.half, self.t_ref, self.lat, _EZ
        c0, c1 = (_end_parameter(t, v, self.heights, self.first, self.sp) for t in (-half, half))

        def frame(s):
            s = np.asarray(s, float)
            ds = (c1 - c0) / (2.0 * half)
            c = c0 + s * ds
            z, dz, ddz = _crimp(c, self.heights, self.first, self.sp)
            q = np.sqrt(1.0 + dz * dz)
            dq = dz * ddz / q
            # crimp-plane normal n = (-z' t_ref + e_z) / q and its derivative
            nrm = (-dz[:, None] * t_ref + ez) / q[:, None]
            dn = (-ddz[:, None] * t_ref) / q[:, None] - nrm * (dq / q)[:, None]
            r = self.base(c) + z[:, None] * ez + l * lat + v * nrm
            dr = t_ref + dz[:, None] * ez + v * dn  # d r / d c (same direction)
            t = dr / np.linalg.norm(dr, axis=1, keepdims=True)
            tr = np.broadcast_to(t_ref, t.shape)
            g1 = minimal_rotation(tr, t, np.broadcast_to(g1_ref, t.shape))
            g2 = minimal_rotation(tr, t, np.broadcast_to(g2_ref, t.shape))
            return r, g1, g2
        return frame


def weave(
    pattern="plain",
    n_warp: int = 4,
    n_weft: int = 4,
    spacing: float = 2.0,
    amplitude: float = 0.525,
    fibril_diameter: float = 0.3,
    rows=(3, 4, 3),
    name: str | None = None,
) -> Fabric:
    """A woven RVE; ``pattern`` is a name in ``WEAVE_PATTERNS`` or a 0/1 matrix."""
    pname = pattern if isinstance(pattern, str) else (name or "custom")
    P = np.asarray(WEAVE_PATTERNS[pattern] if isinstance(pattern, str) else pattern, int)
    if P.ndim != 2 or not np.isin(P, (0, 1)).all():
        raise ValueError("pattern must be a 2D matrix of 0/1")
    if n_warp < 1 or n_weft < 1:
        raise ValueError("need at least one warp and one weft yarn")
    sp, A, d = float(spacing), float(amplitude), float(fibril_diameter)
    R = d / 2.0
    hx, hy = n_weft * sp / 2.0, n_warp * sp / 2.0
    ywarp = (np.arange(n_warp) - (n_warp - 1) / 2.0) * sp
    xweft = (np.arange(n_weft) - (n_weft - 1) / 2.0) * sp
    offsets = hex_stack_offsets(rows, d)
    m, n = P.shape
    warp_top = np.array([[P[j % m, i % n] for i in range(n_weft)] for j in range(n_warp)])

    fibrils, fib_yarn, yarns, tags, designed = [], [], [], [], []
    ez = np.array([0.0, 0.0, 1.0])

    def add_yarn(direction, index, pos):
        y_id = len(yarns)
        if direction == "warp":
            t_ref = np.array([1.0, 0.0, 0.0])
            half, first = hx, xweft[0]
            base = lambda c: np.stack([c, np.full_like(c, pos), np.zeros_like(c)], 1)
            heights = lambda k: A * (2 * P[index % m, k % n] - 1.0)
            sides = ("x-", "x+")
        else:
            t_ref = np.array([0.0, 1.0, 0.0])
            half, first = hy, ywarp[0]
            base = lambda c: np.stack([np.full_like(c, pos), c, np.zeros_like(c)], 1)
            heights = lambda k: -A * (2 * P[k % m, index % n] - 1.0)
            sides = ("y-", "y+")
        lat = np.cross(ez, t_ref)
        centre = functools.partial(_yarn_centre, base=base, heights=heights, half=half, first=first, spacing=sp)
        yarn_line = _YarnLine(base, heights, half, first, sp, t_ref, lat)
        members = []
        for k, (l, v) in enumerate(offsets):
            f = len(fibrils)
            # reference: straight along the yarn line at the stack offset (l, v)
            line = (np.array([pos, 0.0, 0.0]) if direction == "weft"
                    else np.array([0.0, pos, 0.0]))
            start = line - half * t_ref + l * lat + v * ez
            end = line + half * t_ref + l * lat + v * ez
            fib = straight_fibril(start, end, R, name=f"{direction}{index}_f{k:02d}")
            g1_ref, g2_ref = fib.frame(np.zeros(1))[1:]
            fibrils.append(fib)
            fib_yarn.append(y_id)
            designed.append(yarn_line.designed(l, v, g1_ref[0], g2_ref[0]))
            tags.append(EndTag(f, "start", y_id, sides[0]))
            tags.append(EndTag(f, "end", y_id, sides[1]))
            members.append(f)
        yarns.append(Yarn(y_id, f"{direction}{index}", direction, tuple(members),
                          float(pos), centre))

    for j, y in enumerate(ywarp):
        add_yarn("warp", j, y)
    for i, x in enumerate(xweft):
        add_yarn("weft", i, x)

    hz = A + np.abs(offsets[:, 1]).max() + R
    return Fabric(
        kind=f"{pname} weave",
        fibrils=fibrils,
        fibril_yarn=np.array(fib_yarn),
        yarns=yarns,
        half_widths=np.array([hx, hy, hz]),
        end_tags=tags,
        designed=designed,
        params=dict(pattern=P, warp_on_top=warp_top, n_warp=n_warp, n_weft=n_weft,
                    spacing=sp, amplitude=A, fibril_diameter=d, rows=tuple(rows),
                    stack_offsets=offsets, warp_y=ywarp, weft_x=xweft),
    )


def plain_weave(n_warp: int = 4, n_weft: int = 4, **kw) -> Fabric:
    """The thesis plain weave (pattern [[1, 0], [0, 1]])."""
    return weave("plain", n_warp, n_weft, **kw)


def twill_weave(over: int = 2, under: int = 1, n_warp: int = 6, n_weft: int = 6,
                **kw) -> Fabric:
    """An ``over``/``under`` twill; the default 6 x 6 holds two 2/1 repeats."""
    return weave(twill_pattern(over, under), n_warp, n_weft,
                 name=f"twill {over}/{under}", **kw)


def basket_weave(n_warp: int = 4, n_weft: int = 4, **kw) -> Fabric:
    """A 2 x 2 basket weave (pairs of yarns interlace like a plain weave)."""
    return weave("basket_2_2", n_warp, n_weft, **kw)
