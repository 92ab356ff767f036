"""Scene: relax a generated fabric to static equilibrium under contact (thesis §7.3-7.4).

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
* ``setup(cfg) -> (fabric, system, x0)`` for a validated ``FabricRelaxConfig``
  (rve.config.fabric): the fabric (``rve.fabrics``: plain/twill/basket weave or the thesis
  knit), its mesh and a mechanics-only ``BeamModel`` (docs/relaxation.md: no T or V
  during relaxation) with the centroid of every fibril end pinned at its designed position
  and the directors free, a twist gauge (g1_z at each fibril's first node) removing the
  zero-energy rotation of each fibril about its own axis (docs/relaxation.md "Set-up"),
  wrapped in a ``ContactSystem`` (``rve.fabrics.relaxation.relaxation_system``);
* ``solve(cfg, problem=None, on_rebuild=None) -> SceneResult``: the relaxation
  (``rve.fabrics.relaxation.relax``: energy minimisation with onset continuation and mesh
  sequencing, or damped backward-Euler dynamics then static Newton); ``state`` holds
  ``x0`` (designed) and ``x`` (relaxed), ``model`` the ``ContactSystem``, ``summary`` the
  figures: dofs, contact pairs, max overlap / R, clamp reactions per box side (3
  components, N), yarn stack geometry before/after (``stack``), wall times, Newton
  iterations, energy, negative pivots of the final tangent (``stable``), peak RSS;
* ``run(cfg, out_dir) -> dict``: ``solve`` plus the files under ``out_dir``:
  ``relaxed_state.nc`` (xarray/netCDF: reference, initial and relaxed nodal states,
  fibril and yarn ids, radius, connectivity, the config in the attributes),
  ``tubes_initial.vtp``, ``tubes_relaxed.vtp`` (+ intermediate states with
  ``output.vtk_every``) and ``relaxation.pvd`` (Appendix D tube meshes), ``relaxed.png``
  (headless render), ``sections.png`` (weaves); returns the summary (``rve run`` writes
  it to summary.json).

The relaxation never raises a ``SceneFailure``: a static solve that does not converge is
reported (``static_converged``), the state reached is the result.
"""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..config.loader import config_as_dict
from ..fabrics.relaxation import relax, relaxation_system
from ..fabrics.setup import fabric_and_mesh
from .protocol import SceneResult

__all__ = ["setup", "solve", "run", "write_state", "plot_sections"]

log = logging.getLogger("rve.scenes.fabric_relax")


def setup(cfg):
    """``(fabric, system, x0)``: the relaxation problem of ``cfg`` (module docstring)."""
    return relaxation_system(cfg)


def solve(cfg, problem=None, on_rebuild=None) -> SceneResult:
    """Relax the fabric of ``cfg`` (``problem``: the result of :func:`setup`, built if None)."""
    out = relax(cfg, on_rebuild=on_rebuild, problem=problem)
    return SceneResult(state={"x0": out.x0, "x": out.x}, model=out.system, summary=out.summary)


def plot_sections(path, fab, mesh, states, cuts=(-1.0, 1.0), titles=None):
    """Cross-sections of the warp yarns at ``x = cuts`` (centroid circles of radius R,
    coloured by yarn) for each state in ``states`` (nodal arrays): the thesis Fig. 7.4.2
    view, initial vs relaxed. Weft centrelines near the cut are drawn as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    fig, axs = plt.subplots(len(states), len(cuts), figsize=(6.5 * len(cuts), 2.4 * len(states)), squeeze=False)
    R = mesh.radius
    for i, xn in enumerate(states):
        for j, c in enumerate(cuts):
            ax = axs[i, j]
            for f in range(mesh.n_fibrils):
                r = xn[mesh.fibril_nodes(f), :3]
                yarn = fab.yarns[fab.fibril_yarn[f]]
                if yarn.direction == "warp":
                    o = np.argsort(r[:, 0])
                    p = (np.interp(c, r[o, 0], r[o, 1]), np.interp(c, r[o, 0], r[o, 2]))
                    ax.add_patch(Circle(p, R[f], color=f"C{fab.fibril_yarn[f] % 10}", alpha=0.75, lw=0))
                elif abs(yarn.position - c) < 0.5:
                    ax.plot(r[:, 1], r[:, 2], "-", lw=0.4, color="0.3")
            h = fab.half_widths
            ax.set_xlim(-h[1], h[1])
            ax.set_ylim(-h[2] - 0.2, h[2] + 0.2)
            ax.set_aspect("equal")
            ax.set_title(f"{titles[i] if titles else ''} x = {c:g} mm", fontsize=9)
            ax.set_xlabel("y (mm)", fontsize=8)
            ax.set_ylabel("z (mm)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_state(path, fab, system, x0, x, cfg=None) -> Path:
    """The relaxed state as a self-describing netCDF file (xarray), written atomically."""
    import xarray as xr

    from ..io.atomic import atomic_path

    mesh = system.mesh
    comp = ["r_x", "r_y", "r_z", "g1_x", "g1_y", "g1_z", "g2_x", "g2_y", "g2_z"]
    nodal = lambda v: system.nodal(v)[:, :9]  # noqa: E731
    ds = xr.Dataset(
        {
            "reference": (("node", "component"), mesh.X0,
                          {"long_name": "natural (stress-free) configuration r0, G1, G2", "units": "mm"}),
            "initial": (("node", "component"), nodal(x0),
                        {"long_name": "designed initial state r, g1, g2", "units": "mm"}),
            "relaxed": (("node", "component"), nodal(x),
                        {"long_name": "relaxed static equilibrium r, g1, g2", "units": "mm"}),
            "node_fibril": (("node",), mesh.node_fibril.astype(np.int32), {"long_name": "fibril of each node"}),
            "node_s": (("node",), mesh.node_s, {"long_name": "reference parameter along the fibril", "units": "mm"}),
            "fibril_yarn": (("fibril",), np.asarray(fab.fibril_yarn, np.int32), {"long_name": "yarn of each fibril"}),
            "radius": (("fibril",), mesh.radius, {"long_name": "fibril section radius", "units": "mm"}),
            "fibril_name": (("fibril",), np.array(mesh.names, dtype=str), {"long_name": "fibril name"}),
            "conn": (("element", "element_node"), mesh.conn.astype(np.int32),
                     {"long_name": "global node indices of each element, in axial order"}),
            "yarn_direction": (("yarn",), np.array([y.direction for y in fab.yarns], dtype=str),
                               {"long_name": "yarn direction"}),
        },
        coords={"component": comp},
        attrs={"title": f"relaxed {fab.kind}", "element_order": int(mesh.order),
               "half_widths_mm": [float(v) for v in fab.half_widths],
               "conventions": "node-interleaved beam state: centroid r and directors g1, g2 per node (mm)",
               "config": json.dumps(config_as_dict(cfg)) if cfg is not None else "{}"},
    )
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)
    return Path(path)


def run(cfg, out_dir: Path) -> dict:
    from ..io.vtk import render_png, tube_surface, write_pvd, write_tubes

    out_dir = Path(out_dir)
    o = cfg.output
    series = []
    if o.vtk:
        # the initial state is written before the run (useful when a run is interrupted)
        fab0, mesh0 = fabric_and_mesh(cfg)
        p = write_tubes(out_dir / "tubes_initial.vtp", mesh0, fab0.initial_state(mesh0), o.n_theta,
                        {"yarn": np.asarray(fab0.fibril_yarn)[mesh0.node_fibril]})
        series.append((0.0, p.name))
    on_rebuild = None
    if o.vtk and o.vtk_every > 0:
        def on_rebuild(chunk, t, x, w):
            if chunk % o.vtk_every == 0:
                mesh = fab0.mesh(cfg.mesh.elements, cfg.mesh.order)
                xn = x.reshape(mesh.n_nodes, -1)
                q = write_tubes(out_dir / f"tubes_{chunk:04d}.vtp", mesh, xn, o.n_theta,
                                {"yarn": np.asarray(fab0.fibril_yarn)[mesh.node_fibril]})
                series.append((float(t), q.name))

    problem = setup(cfg)
    result = solve(cfg, problem, on_rebuild)
    fab = problem[0]
    summary, system = result.summary, result.model
    x0, x = result.state["x0"], result.state["x"]
    mesh = system.mesh
    files = {}
    yarn = np.asarray(fab.fibril_yarn)[mesh.node_fibril]
    if o.netcdf:
        files["state"] = write_state(out_dir / "relaxed_state.nc", fab, system, x0, x, cfg).name
    if o.vtk:
        p = write_tubes(out_dir / "tubes_relaxed.vtp", mesh, system.nodal(x), o.n_theta, {"yarn": yarn})
        series.append((float(summary["history"][-1].get("t", 1.0)) if summary["history"] else 1.0, p.name))
        files["vtk"] = [name for _, name in series]
        files["pvd"] = write_pvd(out_dir / "relaxation.pvd", series).name
    if o.png:
        if "weft_x" in fab.params:
            plot_sections(out_dir / "sections.png", fab, mesh, [system.nodal(x0), system.nodal(x)],
                          titles=["initial", "relaxed"])
            files["sections_png"] = "sections.png"
        surf = tube_surface(mesh, system.nodal(x), o.n_theta, {"yarn": yarn})
        files["png"] = "relaxed.png"
        summary["render"] = render_png(out_dir / "relaxed.png", surf, scalars="yarn",
                                       title=f"relaxed {fab.kind}: {mesh.n_fibrils} fibrils")
    summary["files"] = files
    return summary
