"""Perturbed packings of a woven RVE (thesis §7.5: "other packings are possible ... a more
detailed study would repeat the analyses on perturbed initial states").

``perturb_packing(fab, seed, offset, phase)`` returns a new :class:`Fabric` whose designed
initial state differs from ``fab``'s by, drawn from ``numpy.random.default_rng(seed)``:

* per yarn, a **crimp phase** shift ``phi`` uniform in ``[-phase R, phase R]``: every
  fibril of the yarn follows its designed curve shifted by ``phi`` along the yarn;
* per fibril, an **in-plane offset** ``(dl, dv)`` uniform in ``[-offset R, offset R]^2``
  along its two section directors ``g1``, ``g2`` (the lateral and the crimp-plane normal
  directions of the stack), i.e. a move within the yarn's cross-section.

The draws are made in a fixed order (yarn by yarn: ``phi``, then ``(dl, dv)`` of its
fibrils in stack order), so a seed names one packing on every machine. The coordinate
of every node **along its yarn** is kept from the designed state, so the fibril ends stay
on the box faces (the clamps and the probe terminals do not move off the cell); the
directors are the designed ones at the shifted parameter turned by the smallest rotation
onto the new centroid tangent (orthonormal, perpendicular to it). The reference (natural,
straight) fibrils, the yarns, the end tags and the box are those of ``fab``; so is the
mesh of a given element count. ``offset = phase = 0`` returns ``fab`` itself (the designed
packing, bit for bit). Offsets of a fraction of R make neighbours of a packed stack
overlap by up to 2 offset R: the relaxation (onset continuation) resolves them, as it
does the designed crossings' interpenetration.

Weaves only (their yarns are straight lines in plan, the along-yarn direction is x or y);
a knit raises ``ValueError``.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .fabric import Fabric, minimal_rotation

__all__ = ["perturb_packing", "packing_draws"]

#: parameter step of the centred difference that gives the new tangent (mm)
_FD_STEP = 1e-6


def packing_draws(fab: Fabric, seed: int, offset: float, phase: float) -> tuple[np.ndarray, np.ndarray]:
    """The random numbers of a packing: ``(phi per fibril (n_fibrils,), (dl, dv) per
    fibril (n_fibrils, 2))`` in mm (``phi`` is its yarn's phase)."""
    rng = np.random.default_rng(int(seed))
    n = fab.n_fibrils
    phi = np.zeros(n)
    dlv = np.zeros((n, 2))
    for y in fab.yarns:
        R = float(fab.fibrils[y.fibrils[0]].radius)
        p = rng.uniform(-1.0, 1.0) * phase * R
        for f in y.fibrils:
            phi[f] = p
            dlv[f] = rng.uniform(-1.0, 1.0, size=2) * offset * float(fab.fibrils[f].radius)
    return phi, dlv


def _along(direction: str) -> np.ndarray:
    if direction == "warp":
        return np.array([1.0, 0.0, 0.0])
    if direction == "weft":
        return np.array([0.0, 1.0, 0.0])
    raise ValueError(f"perturbed packings are implemented for weaves (warp/weft yarns), got a {direction!r} yarn")


def _perturbed_frame(frame, t_ref: np.ndarray, phi: float, dl: float, dv: float):
    P = np.eye(3) - np.outer(t_ref, t_ref)

    def position(s):
        s = np.asarray(s, float)
        r0 = frame(s)[0]
        r, g1, g2 = frame(s + phi)
        r = r + dl * g1 + dv * g2
        return r @ P + (r0 @ t_ref)[:, None] * t_ref[None, :], g1, g2

    def new_frame(s):
        s = np.asarray(s, float)
        r, g1, g2 = position(s)
        rp, rm = position(s + _FD_STEP)[0], position(s - _FD_STEP)[0]
        t_new = rp - rm
        t_new /= np.linalg.norm(t_new, axis=1, keepdims=True)
        t_old = np.cross(g1, g2)
        t_old /= np.linalg.norm(t_old, axis=1, keepdims=True)
        return r, minimal_rotation(t_old, t_new, g1), minimal_rotation(t_old, t_new, g2)

    return new_frame


def perturb_packing(fab: Fabric, seed: int, offset: float, phase: float | None = None) -> Fabric:
    """``fab`` with a random packing (module docstring); ``phase`` None: = ``offset``
    (fractions of the fibril radius R)."""
    offset = float(offset)
    phase = offset if phase is None else float(phase)
    if offset < 0 or phase < 0:
        raise ValueError(f"packing perturbation amplitudes must be >= 0, got offset={offset}, phase={phase}")
    if offset == 0.0 and phase == 0.0:
        return fab
    if fab.kind == "knit" or any(y.direction not in ("warp", "weft") for y in fab.yarns):
        raise ValueError("packing.perturbation: perturbed packings are implemented for weaves, not for a "
                         f"{fab.kind}")
    phi, dlv = packing_draws(fab, seed, offset, phase)
    designed = []
    for f, frame in enumerate(fab.designed):
        t_ref = _along(fab.yarns[fab.fibril_yarn[f]].direction)
        designed.append(_perturbed_frame(frame, t_ref, float(phi[f]), float(dlv[f, 0]), float(dlv[f, 1])))
    params = dict(fab.params)
    params["packing"] = {"seed": int(seed), "offset": offset, "phase": phase}
    return replace(fab, designed=designed, params=params)
