"""The taut plain weave of the impact scene (thesis §8.4; docs/impact.md "Fabric").

Contract
--------
``taut_weave(n, span, R_warp, R_weft, elements, clearance, pretension)`` -> ``SlackWeave``
(the record of ``rve.fabrics.slack``): n warp yarns along x at
``y_j = (j - (n-1)/2) s`` and n weft yarns along y at ``x_i = (i - (n-1)/2) s``,
``s = span / n``, single fibril each, ends on the box faces ``±span/2``.

* Initial state: the crimped plain weave ``z = ±A cos(pi (u - u_0)/s)`` of the induced scene
  (same phases), with ``A = (R_warp + R_weft + clearance) / 2``: the centrelines of two
  crossing yarns are ``R_warp + R_weft + clearance`` apart.
* Reference (natural) configuration, ``reference``: ``"crimped"`` (default): the crimped
  yarn itself (a heat-set weave: the start state is stress-free, ``F(x0) = 0`` while the
  crossings do not overlap); ``"straight"``: straight of length ``L0 = l_c / (1 +
  pretension)`` (``l_c`` the crimped arc length), the start state bent (and stretched by
  ``pretension``): docs/impact.md "Fabric" records why it is not the default (a frictionless
  weave of straight-natural single-fibril yarns does not come to rest: the yarns slide
  sideways off their crossings).
"""
from __future__ import annotations

import numpy as np

from ..fem.mesh import Fibril, fibril_mesh, orthonormal_directors, straight_fibril
from .slack import SlackWeave, crimped_frame, half_wave_length

__all__ = ["taut_weave", "half_wave_length"]  # half_wave_length: re-exported from induced_fabric


def _crimped_fibril(span, A, spacing, sign, t_ref, lat, pos, radius, length, name):
    """A Fibril whose natural configuration is the crimped yarn (arc-length parametrised)."""
    g1r, g2r = orthonormal_directors(np.asarray(t_ref, float)[None, :])

    def frame(sv):
        sv = np.asarray(sv, float)
        X = crimped_frame(sv, span, A, spacing, sign, t_ref, lat, pos, g1r[0], g2r[0], length)
        return X[:, 0:3], X[:, 3:6], X[:, 6:9]

    return Fibril(length=float(length), radius=float(radius), frame=frame, name=name)


def taut_weave(n: int, span: float, R_warp: float, R_weft: float, elements: int, clearance: float = 0.0,
               pretension: float = 0.0, reference: str = "crimped") -> SlackWeave:
    """The plain weave (module docstring)."""
    A = 0.5 * (R_warp + R_weft + clearance)
    if not A > 0:
        raise ValueError("crimp clearance below -(R_warp + R_weft): no crimp")
    if reference not in ("crimped", "straight"):
        raise ValueError(f"reference must be 'crimped' or 'straight', got {reference!r}")
    if reference == "crimped" and pretension != 0.0:
        raise ValueError("a pretension needs the straight reference (the crimped reference is stress-free)")
    s = span / n
    lc = n * half_wave_length(A, s)
    L0 = lc / (1.0 + pretension)
    ex, ey = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    pos = (np.arange(n) - (n - 1) / 2.0) * s
    fibrils, specs = [], []
    for j, y in enumerate(pos):
        specs.append((ex, ey, y, (-1.0) ** j, R_warp, f"warp{j}"))
    for i, x in enumerate(pos):
        specs.append((ey, ex, x, -(-1.0) ** i, R_weft, f"weft{i}"))
    for t_ref, lat, p, sign, R, name in specs:
        if reference == "crimped":
            fibrils.append(_crimped_fibril(span, A, s, sign, t_ref, lat, p, R, L0, name))
        else:
            a = -0.5 * L0 * t_ref + p * lat
            fibrils.append(straight_fibril(a, a + L0 * t_ref, R, name=name))
    mesh = fibril_mesh(fibrils, elements, 1)
    x0 = np.empty((mesh.n_nodes, 9))
    for f, (t_ref, lat, p, sign, _, _) in enumerate(specs):
        nodes = mesh.fibril_nodes(f)
        if reference == "crimped":
            x0[nodes] = mesh.X0[nodes]
            continue
        g1r, g2r = orthonormal_directors(np.asarray(t_ref, float)[None, :])
        x0[nodes] = crimped_frame(mesh.node_s[nodes], span, A, s, sign, t_ref, lat, p, g1r[0], g2r[0],
                             mesh.node_s[nodes].max())
    direction = ("warp",) * n + ("weft",) * n
    return SlackWeave(mesh, x0, A, A, direction, np.arange(n), n + np.arange(n), float(span),
                      float(2 * A - (R_warp + R_weft)))


def chord_clearance(weave) -> float:
    """Smallest centreline-chord distance between two different fibrils minus their radii
    (what the contact sees: the chords of the linear elements cut inside the crimped curve)."""
    from ..contact.search import candidate_pairs

    mesh = weave.mesh
    r = weave.x0[:, :3]
    A, B = r[mesh.conn[:, 0]], r[mesh.conn[:, -1]]
    Rmax = float(mesh.radius.max())
    pairs, d = candidate_pairs(A, B, 2 * Rmax + 1.0, mesh.elem_fibril, return_distance=True)
    if pairs.size == 0:
        return np.inf
    R = mesh.radius[mesh.elem_fibril]
    return float((d - R[pairs[:, 0]] - R[pairs[:, 1]]).min())


def weave_with_chord_clearance(n, span, R_warp, R_weft, elements, clearance, xtol: float = 1e-7):
    """``taut_weave`` (crimped reference) whose discrete chords at the crossings are
    ``clearance`` apart: the crimp-curve clearance found by Brent's method (the chords of the
    linear elements cut inside the curve, so it is larger than ``clearance``)."""
    from scipy.optimize import brentq

    def f(c):
        return chord_clearance(taut_weave(n, span, R_warp, R_weft, elements, c)) - clearance

    lo = clearance
    if f(lo) >= 0:
        return taut_weave(n, span, R_warp, R_weft, elements, lo)
    grid = lo + (R_warp + R_weft) * np.linspace(0.05, 3.0, 60)
    for hi in grid:  # the first crimp that clears (f is not monotone on coarse meshes)
        if f(hi) > 0:
            break
        lo = hi
    else:
        raise ValueError(f"no crimp amplitude gives a chord clearance of {clearance} mm with {elements} elements "
                         f"per yarn: the mesh is too coarse for the yarn spacing {span / n:.4g} mm")
    c = brentq(f, lo, hi, xtol=xtol)
    return taut_weave(n, span, R_warp, R_weft, elements, c)
