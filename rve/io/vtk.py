"""Tube meshes of the fibrils for ParaView (thesis Appendix D) and headless renders.

Contract
--------
* ``tube_surface(mesh, x, n_theta=12, point_data=None, caps=True)`` -> ``pyvista.PolyData``:
  around every node a ring of ``n_theta`` points ``r + R (cos t g1 + sin t g2)``, i.e.
  the beam kinematics x = r + xi1 g1 + xi2 g2 on the section boundary |xi| = R (so the
  tube shows the section's stretch and shear, not only the centroid); consecutive rings
  of a fibril are joined by quads, the two ends closed by polygons (``caps``). Point
  data: ``fibril`` (id), plus every ``point_data`` entry given per node ((n_nodes,) or
  (n_nodes, k)), repeated over the ring. ``x`` is the nodal state (n_nodes, >= 9) or a
  flat state vector with ``block`` components per node.
* ``write_tubes(path, ...)`` writes it as VTK XML PolyData (``.vtp``), atomically.
* ``write_pvd(path, entries)`` writes a ParaView collection (``.pvd``) of
  ``(time, file)`` entries (file paths relative to the .pvd), atomically: a time series.
* ``render_png(path, surface, scalars=None, ...)``: an off-screen pyvista render; if no
  OpenGL context can be created headless, a matplotlib 3D render of the same surface
  (returns ``"pyvista"`` or ``"matplotlib"``: which one made the file).
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .atomic import atomic_path, atomic_write_text

__all__ = ["tube_surface", "write_tubes", "write_pvd", "render_png", "quad_faces"]

log = logging.getLogger("rve.io.vtk")


def _nodal(mesh, x, block=None):
    x = np.asarray(x, float)
    if x.ndim == 1:
        b = block if block is not None else x.size // mesh.n_nodes
        x = x.reshape(mesh.n_nodes, b)
    if x.shape[0] != mesh.n_nodes or x.shape[1] < 9:
        raise ValueError(f"expected a nodal state (n_nodes={mesh.n_nodes}, >=9), got {x.shape}")
    return x


def tube_surface(mesh, x, n_theta: int = 12, point_data: dict | None = None, caps: bool = True, block=None):
    import pyvista as pv

    xn = _nodal(mesh, x, block)
    nt = int(n_theta)
    if nt < 3:
        raise ValueError("n_theta must be >= 3")
    th = 2.0 * np.pi * np.arange(nt) / nt
    R = mesh.radius[mesh.node_fibril][:, None, None]
    r, g1, g2 = xn[:, None, 0:3], xn[:, None, 3:6], xn[:, None, 6:9]
    pts = r + R * (np.cos(th)[None, :, None] * g1 + np.sin(th)[None, :, None] * g2)  # (N, nt, 3)
    pts = pts.reshape(-1, 3)
    N = mesh.n_nodes
    nf = mesh.node_fibril
    seg = np.flatnonzero(nf[:-1] == nf[1:])  # node i joined to node i+1
    j = np.arange(nt)
    jn = (j + 1) % nt
    a = seg[:, None] * nt
    quads = np.stack([a + j, a + jn, a + nt + jn, a + nt + j], axis=-1).reshape(-1, 4)
    faces = [np.hstack([np.full((quads.shape[0], 1), 4), quads]).ravel()]
    if caps:
        starts = mesh.node_offsets[:-1]
        ends = mesh.node_offsets[1:] - 1
        cap0 = starts[:, None] * nt + j[::-1][None, :]  # outward normals
        cap1 = ends[:, None] * nt + j[None, :]
        cp = np.vstack([cap0, cap1])
        faces.append(np.hstack([np.full((cp.shape[0], 1), nt), cp]).ravel())
    surf = pv.PolyData(pts, np.concatenate(faces).astype(np.int64))
    surf.point_data["fibril"] = np.repeat(np.asarray(nf, np.int32), nt)
    for name, val in (point_data or {}).items():
        v = np.asarray(val)
        if v.shape[0] != N:
            raise ValueError(f"point_data[{name!r}] has {v.shape[0]} rows, expected one per node ({N})")
        surf.point_data[name] = np.repeat(v, nt, axis=0)
    return surf


def write_tubes(path, mesh, x, n_theta: int = 12, point_data: dict | None = None, caps: bool = True,
                block=None) -> Path:
    """Write the tube surface as VTK XML PolyData (.vtp) atomically; returns the path."""
    path = Path(path)
    if path.suffix != ".vtp":
        raise ValueError(f"tube meshes are written as .vtp, got {path.name}")
    surf = tube_surface(mesh, x, n_theta, point_data, caps, block)
    with atomic_path(path) as tmp:
        surf.save(str(tmp), binary=True)
    return path


def write_pvd(path, entries) -> Path:
    """ParaView collection file for a time series: ``entries`` = [(time, file), ...]."""
    path = Path(path)
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
             "  <Collection>"]
    for t, f in entries:
        rel = os.path.relpath(Path(f), path.parent) if Path(f).is_absolute() else str(f)
        lines.append(f'    <DataSet timestep="{float(t):.9g}" group="" part="0" file={quoteattr(rel)}/>')
    lines += ["  </Collection>", "</VTKFile>", ""]
    return atomic_write_text(path, "\n".join(lines))


def render_png(path, surface, scalars: str | None = None, title: str = "", window_size=(1600, 1000),
               camera=None, cmap: str = "viridis") -> str:
    """Headless render of ``surface`` to ``path`` (PNG); see the module docstring."""
    path = Path(path)
    try:
        import pyvista as pv

        pl = pv.Plotter(off_screen=True, window_size=list(window_size))
        pl.set_background("white")
        pl.add_mesh(surface, scalars=scalars, cmap=cmap, smooth_shading=True,
                    show_scalar_bar=scalars is not None,
                    scalar_bar_args={"title": scalars or "", "color": "black"} if scalars else None)
        if title:
            pl.add_text(title, font_size=12, color="black")
        if camera is not None:
            pl.camera_position = camera
        else:
            pl.view_isometric()
            pl.camera.zoom(1.3)
        with atomic_path(path) as tmp:
            pl.screenshot(str(tmp))
        pl.close()
        return "pyvista"
    except Exception as exc:  # no GL context headless: matplotlib fallback
        log.warning("pyvista off-screen render failed (%s); falling back to a matplotlib 3D render", exc)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    quads = quad_faces(surface)
    pts = np.asarray(surface.points)
    fig = plt.figure(figsize=(window_size[0] / 100, window_size[1] / 100), dpi=100)
    ax = fig.add_subplot(111, projection="3d")
    vals = np.asarray(surface.point_data[scalars])[quads].mean(axis=1) if scalars else None
    col = Poly3DCollection(pts[quads], linewidths=0)
    if vals is not None:
        col.set_array(vals)
        col.set_cmap(cmap)
    else:
        col.set_facecolor("lightsteelblue")
    ax.add_collection3d(col)
    lo, hi = pts.min(0), pts.max(0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(hi - lo + 1e-9)
    ax.set_title(title + " (matplotlib fallback)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    return "matplotlib"


def quad_faces(surface) -> np.ndarray:
    """The quadrilaterals of a pyvista surface's VTK face stream, (n, 4) point indices
    (faces of other sizes are skipped)."""
    faces = np.asarray(surface.faces)
    quads = []
    i = 0
    while i < faces.size:  # one pass over the stream: [n, i_1 .. i_n, n, ...]
        k = int(faces[i])
        if k == 4:
            quads.append(faces[i + 1:i + 5])
        i += k + 1
    return np.asarray(quads)

