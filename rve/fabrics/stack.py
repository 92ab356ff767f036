"""Yarn stack geometry of a woven fabric state (docs/relaxation.md, "Stack geometry").

Contract: :func:`stack_geometry(fab, mesh, xn)` -> dict of the yarn cross-sections at
the crossings (height, width, levels, thickness, layers, rows), averaged over yarns and
crossings, for a nodal state ``xn`` (n_nodes, >= 3) of a weave (empty for knits).
"""
from __future__ import annotations

import numpy as np

__all__ = ["stack_geometry"]


def _yarn_sections(fab, mesh, xn, yarn):
    """Fibril centroids of ``yarn`` at each crossing coordinate: (n_cross, n_fib, 2)
    = (lateral, vertical) offsets from the yarn's mean centroid there."""
    p = fab.params
    direction = yarn.direction
    if direction == "warp":
        along, lat_ax, cuts = 0, 1, p["weft_x"]
    else:
        along, lat_ax, cuts = 1, 0, p["warp_y"]
    secs = []
    for f in yarn.fibrils:  # per fibril of one yarn (10): vectorised over nodes and cuts
        nodes = mesh.fibril_nodes(f)
        r = xn[nodes, :3]
        s = r[:, along]
        order = np.argsort(s)
        pts = np.stack([np.interp(cuts, s[order], r[order, k]) for k in range(3)], axis=-1)  # (n_cut, 3)
        secs.append(pts)
    secs = np.stack(secs, axis=1)  # (n_cut, n_fib, 3)
    secs = secs - secs.mean(axis=1, keepdims=True)
    return np.stack([secs[..., lat_ax], secs[..., 2]], axis=-1)


def _levels(z, gap):
    """Number of clusters of the sorted values z separated by more than ``gap``."""
    zs = np.sort(z)
    return int(1 + np.count_nonzero(np.diff(zs) > gap))


def stack_geometry(fab, mesh, xn) -> dict:
    """Yarn cross-sections at the crossings, averaged over yarns and crossings (weaves only;
    empty for knits):

    * ``height_mm``, ``width_mm``: extent of the fibril centroids along the vertical and the
      lateral axis; ``levels_mean``/``levels_histogram``: clusters of centroid heights more
      than R apart (a tilted or draped layer counts as one level);
    * ``thickness_mm``: extent across the section's principal (widest) direction, i.e. the
      thickness of the stack whatever its tilt, and ``layers_mean`` = 1 + thickness /
      (√3/2 · d), the number of hexagonally packed rows that thickness holds (3 for the
      designed 3-4-3 stack, 2 for a two-level stack, 1 for a single row);
    * ``rows_from_width``: n / ((width − R)/d + 1), the number of rows of a staggered stack
      of n fibrils whose centroid width is ``width`` (2.86 for the designed 3-4-3 stack of
      width 3d, 2 for two staggered rows of five)."""
    if "weft_x" not in fab.params:
        return {}
    R = float(mesh.radius.min())
    d = 2.0 * R
    H, W, L, T = [], [], [], []
    for y in fab.yarns:
        sec = _yarn_sections(fab, mesh, xn, y)  # (n_cut, n_fib, 2), centred
        H.append(sec[..., 1].max(axis=1) - sec[..., 1].min(axis=1))
        W.append(sec[..., 0].max(axis=1) - sec[..., 0].min(axis=1))
        L.append([_levels(s[:, 1], R) for s in sec])
        cov = np.einsum("cfi,cfj->cij", sec, sec)
        _, vec = np.linalg.eigh(cov)  # ascending: vec[..., 0] the thin direction
        proj = np.einsum("cfi,ci->cf", sec, vec[:, :, 0])
        T.append(proj.max(axis=1) - proj.min(axis=1))
    H, W, L, T = np.concatenate(H), np.concatenate(W), np.concatenate(L), np.concatenate(T)
    layers = 1.0 + T / (0.5 * np.sqrt(3.0) * d)
    nf = np.mean([len(y.fibrils) for y in fab.yarns])
    rows_w = nf / ((W - R) / d + 1.0)
    return {"height_mm": float(H.mean()), "width_mm": float(W.mean()), "levels_mean": float(L.mean()),
            "levels_histogram": {int(k): int(v) for k, v in zip(*np.unique(L, return_counts=True))},
            "thickness_mm": float(T.mean()), "layers_mean": float(layers.mean()),
            "rows_from_width": float(rows_w.mean()),
            "layers_histogram": {int(k): int(v) for k, v in zip(*np.unique(np.rint(layers).astype(int),
                                                                            return_counts=True))}}
