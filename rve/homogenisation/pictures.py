"""Pictures of every stored RVE state (thesis Figs. 7.4.1, 7.4.2, 7.4.5-7.4.7; docs/rve_pipeline.md "Pictures").

Switched by ``output.pictures`` of the RVE config (on by default). Three kinds of output:

* **a tube mesh per stored state** (``write_state_tubes``; VTK XML PolyData ``.vtp``, the
  rings of ``rve.io.vtk.tube_surface``), written by the probe job of that state from the
  fields its probe solves computed anyway. Point data (nodal, repeated over the ring):

  ======================  =======  ==================================================
  ``fibril``, ``yarn``    1        fibril and yarn index
  ``displacement``        mm       r - r(relaxed state): the displacement along the
                                   strain path (its origin, the relaxed state)
  ``axial_force``         N        section force along the current centroid tangent,
                                   int_C P E3 dA . t (tension > 0; thesis Fig. 7.4.1)
  ``potential_<probe>``   V        the probe's voltage solve
  ``current_<probe>``     A        |current through the section| of the probe's solve
  ``temperature_<probe>`` K        the probe's Joule temperature rise (T = 0 at the ends)
  ======================  =======  ==================================================

  Nodal values of element quantities (axial force, current) are the mean over the
  elements that share the node of each element's Gauss-point mean.
* **a ParaView collection per mode** (``write_mode_series``): ``{mode}.pvd``, the relaxed
  state at strain 0 then every step, the timestep being the strain; ParaView opens it as
  a time series over strain.
* **headless PNG renders** (pyvista off-screen; a matplotlib 3D fallback when no OpenGL
  context can be made): the initial and the relaxed state by axial force
  (``relaxed_axial_force.png``, Fig. 7.4.1), the cross-section of one centre warp yarn
  before and after relaxation (``cross_section.png``, Fig. 7.4.2), and per mode the final
  strained state by axial force (``{mode}_axial_force.png``, Fig. 7.4.5), the current
  and the temperature of every probe at the final strain (``{mode}_current.png``,
  ``{mode}_temperature.png``, Figs. 7.4.6-7.4.7). A periodic cell (``boundary: periodic``)
  is drawn tiled 3 x 3 (``tiled``: copies translated by the deformed lattice vectors), so
  the picture reads as a fabric; its tube files and ``.pvd`` series hold the one cell.

Job bodies (workflow/rules/rve.smk): ``pictures_relaxed_job`` (rule ``rve_pictures_relaxed``:
initial + relaxed state) and ``pictures_mode_job`` (rule ``rve_pictures_mode``, one per
mode, so a mode's pictures are drawn as soon as its chain and probes are done, beside the
other chain). A state whose tube file is missing (pictures switched on after its probe
job ran) gets it here, from a probe solve with fields (``ensure_tubes``). Paths:
``rve.homogenisation.layout`` (``tubes_path``, ``picture_outputs``). Nothing here changes
a probe record or the table.
"""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Mapping, Optional, Sequence, Union

import numpy as np

from ..io.atomic import atomic_path
from ..io.provenance import logging_to

__all__ = ["axial_force", "nodal_mean", "section_currents", "state_point_data", "write_state_tubes",
           "ensure_tubes", "write_mode_series", "tiled", "render_panels", "plot_cross_section", "pictures_relaxed_job",
           "pictures_mode_job"]

log = logging.getLogger("rve.homogenisation.pictures")

PathLike = Union[str, os.PathLike]

#: camera of the 3D renders: looking down on the cell from the -y side (a little -x), 50 degrees up
_VIEW_ELEVATION_DEG = 50.0
_VIEW_AZIMUTH_DEG = -75.0


# ============================================================================ nodal fields
def nodal_mean(mesh, element_values: np.ndarray) -> np.ndarray:
    """(E,) element values -> (n_nodes,): the mean over the elements sharing each node."""
    conn = mesh.conn
    nn = conn.shape[1]
    v = np.repeat(np.asarray(element_values, float), nn)
    s = np.bincount(conn.ravel(), weights=v, minlength=mesh.n_nodes)
    c = np.bincount(conn.ravel(), minlength=mesh.n_nodes)
    return s / np.maximum(c, 1)


def axial_force(mesh, youngs_modulus: float, poisson_ratio: float, xn: np.ndarray, disk_points: int = 4,
                axial_points=None, basis=None) -> np.ndarray:
    """Section force along the tangent at every element: (E, ng) in N.

    At axial Gauss point g the section resultant is n_g = sum_d w_d R^2 det0 P(q) E3 (the
    first Piola stress of the Neo-Hookean beam, ``rve.physics.elasticity``, on the
    reference section of normal E3, the reference tangent), and the axial force is
    n_g . t with t the unit tangent of the current centroid (tension > 0). A straight
    fibril stretched by lambda with its section unchanged carries
    pi R^2 (mu (lambda - 1/lambda) + lam ln(lambda) / lambda)."""
    from ..fem.basis import BeamBasis
    from ..physics.elasticity import lame, neo_hookean_stress

    b = basis if basis is not None else BeamBasis(mesh, disk_points, axial_points)
    xn = np.asarray(xn, float)
    F = b.deformation_gradient(xn)                                     # (E, nq, 3, 3)
    mu, lam = lame(youngs_modulus, poisson_ratio)
    P = neo_hookean_stress(F, float(mu), float(lam))
    X0 = mesh.X0[mesh.conn]                                            # (E, nn, 9)
    E3 = X0[:, -1, 0:3] - X0[:, 0, 0:3]
    E3 /= np.linalg.norm(E3, axis=1, keepdims=True)
    traction = np.einsum("eqij,ej->eqi", P, E3)                        # P E3 per quadrature point
    area_w = (b.W / np.repeat(b.Wg, b.nd, axis=1))                     # w_d R^2 det0
    E, nq = b.W.shape
    n_g = (traction * area_w[..., None]).reshape(E, b.ng, b.nd, 3).sum(axis=2)  # (E, ng, 3)
    U = xn[mesh.conn][:, :, 0:3]                                       # centroid nodes (E, nn, 3)
    dN = b.dN                                                          # (E, ng, nn) d/ds
    dr = np.einsum("egn,eni->egi", dN, U)
    t = dr / np.linalg.norm(dr, axis=2, keepdims=True)
    return np.einsum("egi,egi->eg", n_g, t)


def section_currents(mesh, electrical_conductivity: float, xn: np.ndarray, potentials: Mapping[str, np.ndarray],
                     disk_points: int = 4, axial_points=None) -> dict:
    """|current through the section| per element and Gauss point, (E, ng) in A, of every
    nodal potential in ``potentials`` (name -> (n_nodes,)), mechanics frozen at ``xn``."""
    from ..model import BeamMaterial, BeamModel, Couplings

    mat = BeamMaterial(1.0, 0.0, 1.0, electrical_conductivity=float(electrical_conductivity))
    model = BeamModel(mesh, mat, fields=("mech", "V"), disk_points=disk_points, axial_points=axial_points,
                      couplings=Couplings(lorentz=False, back_emf=False, joule=False, seebeck=False,
                                          thermal_softening=False))
    x = np.zeros(model.n)
    model.nodal(x)[:, :9] = xn
    out = {}
    for name, V in potentials.items():
        w = np.zeros(model.n)
        model.nodal(w)[:, model.oV] = V
        out[name] = np.abs(model.axial_current(x, w))
    return out


def state_point_data(cfg, fab, mesh, xn, origin, probe_results: Optional[Mapping] = None) -> dict:
    """The point data of a state's tube mesh (module docstring): name -> (n_nodes,) or (n_nodes, 3)."""
    xn = np.asarray(xn, float)
    data = {"yarn": np.asarray(fab.fibril_yarn, np.int32)[mesh.node_fibril],
            "displacement": xn[:, 0:3] - np.asarray(origin, float)[:, 0:3]}
    f = axial_force(mesh, cfg.material.youngs_modulus, cfg.material.poisson_ratio, xn, cfg.mesh.disk_points,
                    cfg.mesh.axial_points)
    data["axial_force"] = nodal_mean(mesh, f.mean(axis=1))
    probe_results = dict(probe_results or {})
    pots = {n: r.V for n, r in probe_results.items() if getattr(r, "V", None) is not None}
    if pots:
        cur = section_currents(mesh, cfg.material.electrical_conductivity, xn, pots, cfg.mesh.disk_points,
                               cfg.mesh.axial_points)
        for n in probe_results:
            if n in pots:
                data[f"potential_{n}"] = np.asarray(pots[n], float)
                data[f"current_{n}"] = nodal_mean(mesh, cur[n].mean(axis=1))
            T = getattr(probe_results[n], "T", None)
            if T is not None:
                data[f"temperature_{n}"] = np.asarray(T, float)
    return data


def write_state_tubes(path: PathLike, cfg, fab, mesh, state, probe_results: Optional[Mapping] = None) -> Path:
    """The tube mesh of a stored ``state`` (``rve.homogenisation.checkpoint.State``) with
    its probe fields (``solve_probes(..., with_fields=True)``), atomically."""
    from ..io.vtk import write_tubes

    t0 = time.perf_counter()
    data = state_point_data(cfg, fab, mesh, state.x, state.origin, probe_results)
    p = write_tubes(path, mesh, state.x, int(cfg.output.n_theta), data)
    log.info("tubes %s: %d arrays (%s), %.2f s", p, len(data), ", ".join(data), time.perf_counter() - t0)
    return p


def ensure_tubes(tubes: PathLike, state_file: PathLike, spec: Mapping, combo: str) -> Path:
    """The tube file of a state; computed here (probe solves with fields) if missing."""
    tubes = Path(tubes)
    if tubes.exists():
        return tubes
    from .checkpoint import load_state
    from .probes import solve_probes
    from .sweeps import load_run_config
    from ..fabrics.setup import fabric_and_mesh

    log.info("%s missing (pictures switched on after the probe job?): solving the probes of %s with fields",
             tubes, state_file)
    cfg = load_run_config(spec, combo)
    fab, mesh = fabric_and_mesh(cfg)
    st = load_state(state_file)
    res = solve_probes(cfg, fab, mesh, st.x, with_fields=True, multipliers=st.multipliers)
    return write_state_tubes(tubes, cfg, fab, mesh, st, res)


def write_mode_series(pvd: PathLike, entries: Sequence[tuple[float, PathLike]]) -> Path:
    """``{mode}.pvd``: (strain, tube file) entries, file names relative to the .pvd."""
    from ..io.vtk import write_pvd

    pvd = Path(pvd)
    rel = [(float(s), os.path.relpath(Path(f).resolve(), pvd.parent.resolve())) for s, f in entries]
    return write_pvd(pvd, rel)


# ============================================================================ renders
#: copies of a periodic cell per side in the renders (the cell drawn among its neighbours)
PERIODIC_TILES = 3


def tiled(surface, cfg, fab, mesh, xn, n: int = PERIODIC_TILES):
    """A periodic cell's tube surface drawn ``n`` x ``n`` times, each copy translated by a
    lattice vector of the deformed cell, i F L1 + j F L2 (F the macro gradient the state
    carries), so that the picture reads as a piece of fabric; the point data are copied
    with it. A pinned cell (or ``n`` = 1) is returned as it is."""
    if getattr(cfg, "boundary", "pinned") != "periodic" or int(n) <= 1:
        return surface
    from .periodic import cell_gradient, cell_ties

    a1, a2 = cell_ties(fab, mesh).periods @ cell_gradient(fab, mesh, xn).T
    k = np.arange(int(n)) - (int(n) - 1) / 2.0
    copies = [surface.translate(i * a1 + j * a2, inplace=False) for i in k for j in k]
    return copies[0].merge(copies[1:])


def _cell_text(cfg, fab, mesh) -> str:
    """Title line of a render: the fabric, its fibrils and mesh (and the tiling of a periodic cell)."""
    text = f"{fab.kind}: {mesh.n_fibrils} fibrils, {cfg.mesh.elements} elements each"
    if getattr(cfg, "boundary", "pinned") == "periodic":
        text += f"\nperiodic cell, drawn {PERIODIC_TILES} x {PERIODIC_TILES}"
    return text


def _camera(bounds, elevation=_VIEW_ELEVATION_DEG, azimuth=_VIEW_AZIMUTH_DEG, distance=2.35, shift=0.08):
    """Camera [position, focal point, view up] looking at the box ``bounds`` from
    ``elevation``/``azimuth`` (deg); the focal point moved by ``shift`` x the box size to
    the screen's right, so the colour bar on the right leaves the fabric free."""
    lo, hi = np.asarray(bounds[0::2]), np.asarray(bounds[1::2])
    L = float(np.max(hi - lo))
    el, az = np.radians(elevation), np.radians(azimuth)
    d = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.cross(-d, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    c = 0.5 * (lo + hi) + shift * L * right
    return [tuple(c + distance * L * d), tuple(c), (0.0, 0.0, 1.0)]


def render_panels(path: PathLike, panels: Sequence[tuple], title: str = "", panel_size=(900, 760),
                  cmap: str = "viridis") -> str:
    """Side-by-side off-screen renders: ``panels`` = [(surface, scalars, panel title,
    scalar-bar title), ...], each with its own colour bar and range (pyvista links the bars
    of equal titles, so a repeated bar title gets the panel's number); ``title`` heads
    every panel; the same camera for all (the bounds of the first). Returns ``"pyvista"``
    or ``"matplotlib"`` (the fallback)."""
    path = Path(path)
    n = len(panels)
    ncols = n if n <= 3 else int(np.ceil(n / 2))
    nrows = int(np.ceil(n / ncols))
    try:
        import pyvista as pv

        pl = pv.Plotter(off_screen=True, shape=(nrows, ncols), window_size=[panel_size[0] * ncols,
                                                                            panel_size[1] * nrows], border=False)
        cam = _camera(panels[0][0].bounds)
        bars = [p[3] for p in panels]
        for k, (surf, scalars, ptitle, bar) in enumerate(panels):
            if bars.count(bar) > 1:
                bar = f"{bar} ({k + 1})" if len(panels) > 1 else bar
            ptitle = f"{title}\n{ptitle}" if title else ptitle
            pl.subplot(k // ncols, k % ncols)
            pl.set_background("white")
            pl.add_mesh(surf, scalars=scalars, cmap=cmap, smooth_shading=True, show_scalar_bar=True,
                        scalar_bar_args={"title": bar + "\n", "color": "black", "vertical": True,
                                         "position_x": 0.80, "position_y": 0.12, "width": 0.07, "height": 0.66,
                                         "title_font_size": 18, "label_font_size": 16, "n_labels": 5,
                                         "fmt": "%.3g"})
            pl.add_text(ptitle, position="upper_edge", font_size=12, color="black")
            pl.camera_position = cam
        with atomic_path(path) as tmp:
            pl.screenshot(str(tmp))
        pl.close()
        return "pyvista"
    except Exception as exc:  # no GL context headless
        log.warning("pyvista off-screen render failed (%s); matplotlib 3D fallback", exc)
    return _render_panels_matplotlib(path, panels, title, cmap)


def _render_panels_matplotlib(path, panels, title, cmap) -> str:
    from ..io.vtk import quad_faces
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    n = len(panels)
    ncols = n if n <= 3 else int(np.ceil(n / 2))
    nrows = int(np.ceil(n / ncols))
    fig = Figure(figsize=(5.5 * ncols, 5.0 * nrows))
    FigureCanvasAgg(fig)
    for k, (surf, scalars, ptitle, bar) in enumerate(panels):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        quads = quad_faces(surf)
        pts = np.asarray(surf.points)
        col = Poly3DCollection(pts[quads], linewidths=0, cmap=cmap)
        col.set_array(np.asarray(surf.point_data[scalars])[quads].mean(axis=1))
        ax.add_collection3d(col)
        lo, hi = pts.min(0), pts.max(0)
        ax.set_xlim(lo[0], hi[0]); ax.set_ylim(lo[1], hi[1]); ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo + 1e-9)
        ax.view_init(_VIEW_ELEVATION_DEG, _VIEW_AZIMUTH_DEG)
        ax.set_title(ptitle, fontsize=10)
        fig.colorbar(col, ax=ax, orientation="horizontal", shrink=0.7, label=bar)
    if title:
        fig.suptitle(title, fontsize=10)
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=110)
    return "matplotlib"


# ============================================================================ cross-section
def _section_polygons(mesh, xn, fibrils, x_cut: float, n_theta: int = 24):
    """Outline of every fibril of ``fibrils`` (warp: along x) in the plane x = x_cut:
    the section ring r + R (cos t g1 + sin t g2) at the crossing point (centroid, directors
    interpolated linearly on the element that crosses the plane), projected onto the plane
    along the centroid tangent. Returns [(fibril, (n_theta, 2) y-z outline, element)]."""
    th = 2 * np.pi * np.arange(n_theta) / n_theta
    out = []
    for f in fibrils:
        nodes = mesh.fibril_nodes(f)
        r = xn[nodes, 0:3]
        k = np.flatnonzero((r[:-1, 0] - x_cut) * (r[1:, 0] - x_cut) <= 0)
        if k.size == 0:
            continue
        k = int(k[0])
        a, b = nodes[k], nodes[k + 1]
        s = (x_cut - xn[a, 0]) / (xn[b, 0] - xn[a, 0]) if xn[b, 0] != xn[a, 0] else 0.0
        p = (1 - s) * xn[a] + s * xn[b]
        t = xn[b, 0:3] - xn[a, 0:3]
        t /= np.linalg.norm(t)
        R = float(mesh.radius[f])
        ring = p[0:3] + R * (np.cos(th)[:, None] * p[3:6] + np.sin(th)[:, None] * p[6:9])
        ring = ring - ((ring[:, 0] - x_cut) / t[0])[:, None] * t[None, :]
        elem = int(np.flatnonzero(mesh.elem_fibril == f)[0]) + k // max(mesh.order, 1)
        out.append((f, ring[:, 1:3], elem))
    return out


def plot_cross_section(path: PathLike, mesh, states: Sequence[tuple[str, np.ndarray, np.ndarray]], fibrils,
                       x_cut: float, yarn_label: str) -> Path:
    """Cross-sections of one yarn's fibrils in the plane x = ``x_cut`` (thesis Fig. 7.4.2):
    one panel per (title, nodal state, element axial force (E,)), discs coloured by the
    axial force (one colour scale for all panels), equal aspect, mm."""
    from matplotlib import cm, colors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    polys = [(ttl, _section_polygons(mesh, xn, fibrils, x_cut), fe) for ttl, xn, fe in states]
    vals = np.concatenate([[fe[e] for _, _, e in pl] for _, pl, fe in polys])
    norm = colors.Normalize(vmin=float(vals.min()), vmax=float(vals.max()))
    allpts = np.vstack([ring for _, pl, _ in polys for _, ring, _ in pl])
    lo, hi = allpts.min(0), allpts.max(0)
    pad = 0.1 * float(np.max(hi - lo))
    fig = Figure(figsize=(4.2 * len(polys) + 1.2, 3.6))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(polys), squeeze=False)[0]
    for ax, (ttl, pl, fe) in zip(axes, polys):
        pc = PolyCollection([ring for _, ring, _ in pl], array=np.array([fe[e] for _, _, e in pl]), cmap="viridis",
                            norm=norm, edgecolors="k", linewidths=0.6)
        ax.add_collection(pc)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        ax.set_title(ttl, fontsize=10)
        ax.set_xlabel("y [mm]")
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.set_ylabel("z [mm]")
        ax.grid(alpha=0.3)
    fig.subplots_adjust(left=0.08, right=0.86, bottom=0.17, top=0.8, wspace=0.35)
    cax = fig.add_axes([0.89, 0.17, 0.018, 0.63])
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="viridis"), cax=cax, label="axial force [N]")
    fig.suptitle(f"Cross-section of the {yarn_label} at x = {x_cut:g} mm (fibril sections, coloured by axial force)",
                 fontsize=10)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130)
    return path


# ============================================================================ job bodies
def _cfg_fab_mesh(spec, combo):
    from .sweeps import load_run_config
    from ..fabrics.setup import fabric_and_mesh

    cfg = load_run_config(spec, combo)
    fab, mesh = fabric_and_mesh(cfg)
    return cfg, fab, mesh


def _read(path):
    import pyvista as pv

    return pv.read(str(path))


def _centre_warp_yarn(fab):
    warps = [y for y in fab.yarns if y.direction == "warp"]
    if not warps:
        return None
    return min(warps, key=lambda y: (abs(y.position + 1.0), abs(y.position)))


def pictures_relaxed_job(initial_state: PathLike, relaxed_state: PathLike, relaxed_tubes: PathLike,
                         outputs: Mapping[str, PathLike], log_path: Optional[PathLike], spec: Mapping,
                         combo: str) -> dict:
    """Initial and relaxed state by axial force (Fig. 7.4.1) and the cross-section of a
    centre warp yarn (Fig. 7.4.2). ``outputs``: ``relaxed_axial_force``, ``cross_section``."""
    from .checkpoint import load_state
    from ..io.vtk import tube_surface

    with logging_to(log_path):
        t0 = time.perf_counter()
        cfg, fab, mesh = _cfg_fab_mesh(spec, combo)
        st0, st1 = load_state(initial_state), load_state(relaxed_state)
        tubes = _read(ensure_tubes(relaxed_tubes, relaxed_state, spec, combo))
        m = cfg.material
        f0 = axial_force(mesh, m.youngs_modulus, m.poisson_ratio, st0.x, cfg.mesh.disk_points, cfg.mesh.axial_points)
        f1 = axial_force(mesh, m.youngs_modulus, m.poisson_ratio, st1.x, cfg.mesh.disk_points, cfg.mesh.axial_points)
        s0 = tube_surface(mesh, st0.x, int(cfg.output.n_theta), {"axial_force": nodal_mean(mesh, f0.mean(1))})
        how = render_panels(outputs["relaxed_axial_force"],
                            [(tiled(s0, cfg, fab, mesh, st0.x), "axial_force", "designed initial state",
                              "initial: axial force [N]"),
                             (tiled(tubes, cfg, fab, mesh, st1.x), "axial_force", "relaxed state (strain 0)",
                              "relaxed: axial force [N]")],
                            title=_cell_text(cfg, fab, mesh))
        yarn = _centre_warp_yarn(fab)
        if yarn is not None:
            xs = [float(x) for x in fab.params.get("weft_x", [0.0])]
            x_cut = xs[1] if len(xs) > 1 else xs[0]  # at a crossing: the stack is flat there
            plot_cross_section(outputs["cross_section"], mesh,
                               [("designed initial state", st0.x, f0.mean(1)), ("relaxed state", st1.x, f1.mean(1))],
                               yarn.fibrils, x_cut, f"warp yarn at y = {yarn.position:g} mm")
        else:  # knit: no warp yarn; a cut through the first course
            y = fab.yarns[0]
            plot_cross_section(outputs["cross_section"], mesh,
                               [("designed initial state", st0.x, f0.mean(1)), ("relaxed state", st1.x, f1.mean(1))],
                               y.fibrils, 0.0, f"course {y.name}")
        log.info("relaxed pictures (%s): %s, %.1f s", how, ", ".join(map(str, outputs.values())),
                 time.perf_counter() - t0)
    return dict(outputs)


def pictures_mode_job(mode: str, state_files: Sequence[PathLike], tubes_files: Sequence[PathLike],
                      outputs: Mapping[str, PathLike], log_path: Optional[PathLike], spec: Mapping,
                      combo: str) -> dict:
    """One mode: its ``.pvd`` series (relaxed state, then every step; timestep = strain)
    and the renders of its final state: axial force, current and temperature of every
    probe. ``state_files``/``tubes_files``: the relaxed state first, then the steps in
    order. ``outputs``: ``pvd``, ``axial_force``, ``current``, ``temperature``."""
    from .checkpoint import load_state

    with logging_to(log_path):
        t0 = time.perf_counter()
        cfg, fab, mesh = _cfg_fab_mesh(spec, combo)
        entries = []
        for sf, tf in zip(state_files, tubes_files):
            st = load_state(sf)
            ensure_tubes(tf, sf, spec, combo)
            entries.append((float(st.strain), tf))
        pvd = write_mode_series(outputs["pvd"], entries)
        final = tiled(_read(tubes_files[-1]), cfg, fab, mesh, st.x)
        strain = entries[-1][0]
        what = f"{mode} {strain:g}"
        how = render_panels(outputs["axial_force"], [(final, "axial_force", f"{mode}, strain {strain:g}",
                                                      "axial force [N]")],
                            title=_cell_text(cfg, fab, mesh) if cfg.boundary == "periodic" else "",
                            panel_size=(1200, 900))
        probes = [p.name for p in cfg.probes]
        for key, field, bar in (("current", "current", "current [A]"),
                                ("temperature", "temperature", "T rise [K]")):
            panels = [(final, f"{field}_{p}", f"{p} ({_probe_text(cfg, p)})", f"{p} {bar}") for p in probes
                      if f"{field}_{p}" in final.point_data]
            render_panels(outputs[key], panels, title=f"{mode}, strain {strain:g}: {field} of each probe at "
                                                      f"{cfg.probe_solver.voltage:g} V")
        log.info("%s pictures (%s): %s (%d frames), %.1f s", what, how, pvd, len(entries), time.perf_counter() - t0)
    return dict(outputs)


def _probe_text(cfg, name: str) -> str:
    p = next(p for p in cfg.probes if p.name == name)
    if getattr(p, "field", None) is not None:
        return f"macro field along {p.field}"
    return " to ".join(f"{t.yarn} {t.position:g} {t.end}" for t in p.terminals)
