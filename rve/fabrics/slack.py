"""The slack plain weave of the induced-deformation scene (thesis §8.3; docs/induced_deformation.md).

Contract
--------
``slack_weave(n_warp, n_weft, span, natural_length, R_warp, R_weft, elements)`` ->
``SlackWeave``: single-fibril yarns, warp along x at ``y_j = (j - (n_warp-1)/2) s`` and weft
along y at ``x_i = (i - (n_weft-1)/2) s`` (``s = span / n``, the other count), every
fibril's ends on the box faces ``±span/2``.

* Reference (natural) configuration: straight, length ``natural_length`` (L0 > span).
* Initial state: the crimped plain weave ``z = ±A cos(pi (u - u_0)/s)`` (u the coordinate
  along the yarn, the sign alternating from yarn to yarn, warp and weft in opposite
  phase), with the amplitude A chosen so that the crimped arc length between the pinned
  ends is exactly L0: the node of reference arc length s sits at arc length s of the
  crimped curve, so the fibrils start unstretched and only bent (the slack of §8.3).
  Directors: the reference directors turned by the minimal rotation onto the tangent.
* ``mesh`` (``FibrilMesh``), ``x0`` (n_nodes, 9) the initial state, ``amplitude`` A,
  ``direction`` ('warp'/'weft' per fibril), ``warp``/``weft`` fibril indices,
  ``clearance`` (centreline distance at a crossing minus R_warp + R_weft: > 0 means the
  yarns start apart, as in the thesis's first frame).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .fabric import minimal_rotation
from ..fem.mesh import FibrilMesh, fibril_mesh, straight_fibril

__all__ = ["SlackWeave", "slack_weave", "crimp_amplitude", "half_wave_length", "crimped_frame"]

_QUAD = np.polynomial.legendre.leggauss(64)


def half_wave_length(A: float, s: float) -> float:
    """Arc length of z = A cos(pi u / s) over one spacing s (Gauss-Legendre, smooth integrand)."""
    xg, wg = _QUAD
    u = 0.5 * s * (xg + 1.0)
    dz = A * np.pi / s * np.sin(np.pi * u / s)
    return float(0.5 * s * (wg * np.sqrt(1.0 + dz * dz)).sum())


def crimp_amplitude(span: float, natural_length: float, n_crossings: int) -> float:
    """A such that n half waves of z = A cos(pi u / s), s = span / n, have length L0."""
    s = span / n_crossings
    target = natural_length / n_crossings
    return float(brentq(lambda A: half_wave_length(A, s) - target, 0.0, natural_length))


@dataclass(frozen=True)
class SlackWeave:
    mesh: FibrilMesh
    x0: np.ndarray
    amplitude_warp: float
    amplitude_weft: float
    direction: tuple
    warp: np.ndarray
    weft: np.ndarray
    span: float
    clearance: float


def crimped_frame(s_nodes, span, A, spacing, sign, t_ref, lat_axis, pos, g1_ref, g2_ref, length=None):
    """Nodes at reference arc length s on the crimped yarn (module docstring), spread uniformly
    in arc length between its ends; the reference length ``length`` (default s_nodes.max())
    maps onto the whole crimped yarn."""
    n_fine = 4001
    u = np.linspace(-span / 2, span / 2, n_fine)
    u0 = -span / 2 + spacing / 2  # first crossing
    k = np.pi / spacing
    dz = -sign * A * k * np.sin(k * (u - u0))
    q = np.sqrt(1.0 + dz * dz)
    arc = np.concatenate([[0.0], np.cumsum(0.5 * (q[1:] + q[:-1]) * np.diff(u))])
    # reference -> crimped arc length (also removes the tiny trapezoid error: ends exactly on the faces)
    arc *= (s_nodes.max() if length is None else length) / arc[-1]
    uu = np.interp(s_nodes, arc, u)
    z = sign * A * np.cos(k * (uu - u0))
    dzz = -sign * A * k * np.sin(k * (uu - u0))
    r = uu[:, None] * t_ref + pos * lat_axis + z[:, None] * np.array([0.0, 0.0, 1.0])
    t = t_ref + dzz[:, None] * np.array([0.0, 0.0, 1.0])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    tr = np.broadcast_to(t_ref, t.shape)
    g1 = minimal_rotation(tr, t, np.broadcast_to(g1_ref, t.shape))
    g2 = minimal_rotation(tr, t, np.broadcast_to(g2_ref, t.shape))
    return np.hstack([r, g1, g2])


def slack_weave(n_warp: int, n_weft: int, span: float, natural_length: float, R_warp: float, R_weft: float,
                elements: int) -> SlackWeave:
    """The slack plain weave (module docstring)."""
    ex, ey = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    s_warp, s_weft = span / n_weft, span / n_warp  # warp crosses n_weft wefts
    A_warp = crimp_amplitude(span, natural_length, n_weft)
    A_weft = crimp_amplitude(span, natural_length, n_warp)
    ywarp = (np.arange(n_warp) - (n_warp - 1) / 2.0) * s_weft
    xweft = (np.arange(n_weft) - (n_weft - 1) / 2.0) * s_warp
    fibrils, specs = [], []
    L0 = natural_length
    for j, y in enumerate(ywarp):
        fib = straight_fibril([-L0 / 2, y, 0.0], [L0 / 2, y, 0.0], R_warp, name=f"warp{j}")
        fibrils.append(fib)
        specs.append(("warp", A_warp, s_warp, (-1.0) ** j, ex, ey, y))
    for i, x in enumerate(xweft):
        fib = straight_fibril([x, -L0 / 2, 0.0], [x, L0 / 2, 0.0], R_weft, name=f"weft{i}")
        fibrils.append(fib)
        specs.append(("weft", A_weft, s_weft, -(-1.0) ** i, ey, ex, x))
    mesh = fibril_mesh(fibrils, elements, 1)
    x0 = np.empty((mesh.n_nodes, 9))
    for f, (kind, A, spc, sign, t_ref, lat, pos) in enumerate(specs):
        nodes = mesh.fibril_nodes(f)
        G = mesh.X0[nodes[0]]
        x0[nodes] = crimped_frame(mesh.node_s[nodes], span, A, spc, sign, t_ref, lat, pos, G[3:6], G[6:9])
    direction = tuple(s[0] for s in specs)
    clearance = (A_warp + A_weft) - (R_warp + R_weft)
    return SlackWeave(mesh, x0, A_warp, A_weft, direction, np.arange(n_warp), n_warp + np.arange(n_weft),
                      float(span), float(clearance))
