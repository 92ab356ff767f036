"""Scene: relax a generated fabric to static equilibrium under contact (thesis §7.3-7.4).

Contract
--------
``run(cfg, out_dir) -> dict`` for a validated ``FabricRelaxConfig`` (rve.config.fabric):

* builds the fabric (``rve.fabrics``: plain/twill/basket weave or the thesis knit), its
  mesh, a mechanics-only ``BeamModel`` (SPEC §4: no T or V during relaxation) with the
  centroid of every fibril end pinned at its designed position and the directors free
  (a twist gauge, g1_z at each fibril's first node, removes the zero-energy rotation of
  each fibril about its own axis; SPEC §7), wrapped in a ``ContactSystem``;
* relaxes it (``rve.contact.relax.relax_to_equilibrium``: damped backward-Euler dynamics
  with the map rebuilt every k steps, then static Newton);
* writes to ``out_dir``: ``relaxed_state.nc`` (xarray/netCDF: reference, initial and
  relaxed nodal states, fibril and yarn ids, radius, connectivity, the config in the
  attributes), ``tubes_initial.vtp``, ``tubes_relaxed.vtp`` (+ intermediate states with
  ``output.vtk_every``) and ``relaxation.pvd`` (Appendix D tube meshes), ``relaxed.png``
  (headless render), and returns the summary (``rve run`` writes it to summary.json):
  dofs, contact pairs, max overlap / R, clamp reactions per box side (3 components, N),
  yarn stack geometry before/after (``stack``), wall times, Newton iterations, energy,
  negative pivots of the final tangent (``stable``), peak RSS (``peak_rss_mb``).

``solve(cfg)`` does the same without writing files and returns the summary with the
state under ``"_state"``. ``build(cfg)`` returns ``(fabric, system, x0)``.
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from ..solvers.relaxation import RelaxSettings, relax_to_equilibrium
from ..contact.system import ContactParams, ContactSystem
from ..model import BeamMaterial, BeamModel, DirichletBC

__all__ = ["build", "solve", "run", "make_fabric", "clamp_reactions", "stack_geometry", "write_state",
           "plot_sections"]

log = logging.getLogger("rve.scenes.fabric_relax")


def make_fabric(spec):
    from .. import fabrics

    if spec.kind == "knit":
        return fabrics.knit(n_rows=spec.knit_rows, n_loops=spec.knit_loops, fibril_diameter=spec.fibril_diameter)
    return fabrics.weave(spec.kind, spec.n_warp, spec.n_weft, spacing=spec.spacing, amplitude=spec.amplitude,
                         fibril_diameter=spec.fibril_diameter, rows=tuple(spec.rows))


def build(cfg):
    fab = make_fabric(cfg.fabric)
    mesh = fab.mesh(cfg.mesh.elements, cfg.mesh.order)
    x0n = fab.initial_state(mesh)
    ends = np.array([t.node(mesh) for t in fab.end_tags], dtype=np.int64)
    first = mesh.node_offsets[:-1].astype(np.int64)
    pinned = (ends[:, None] * 9 + np.arange(3)[None, :]).ravel()
    gauge = first * 9 + 5  # g1_z at each fibril's first node (velocity 0)
    mat = BeamMaterial(cfg.material.youngs_modulus, cfg.material.poisson_ratio, cfg.material.density,
                       damping=cfg.relaxation.damping)
    base = BeamModel(mesh, mat, disk_points=cfg.mesh.disk_points, axial_points=cfg.mesh.axial_points,
                     bcs=[DirichletBC(pinned, 0.0), DirichletBC(gauge, 0.0)])
    c = cfg.contact
    params = ContactParams(penalty=c.penalty, heat_transfer=c.heat_transfer, conductance=c.conductance,
                           n_gp=c.n_gp, margin=c.margin, g_eps=c.g_eps, recompute_closest=c.recompute_closest,
                           rebuild_every=cfg.relaxation.rebuild_every, onset=c.onset)
    x0 = np.zeros(base.n)
    base.nodal(x0)[:, :9] = x0n
    system = ContactSystem(base, params, x0)
    return fab, system, x0


def clamp_reactions(fab, system, x, t=0.0) -> dict:
    """Force (N) the clamps exert on the fibrils, summed per box side: {side: [Fx, Fy, Fz]}.

    At a pinned centroid the residual F (internal minus external force) is what the clamp
    must supply, so the clamp force is F there."""
    F, _, _ = system.evaluate(x, np.zeros(system.n), t, jacobian=False)
    Fn = system.nodal(F)[:, :3]
    out = {}
    for side in ("x-", "x+", "y-", "y+"):
        nodes = fab.end_nodes(system.mesh, side)
        if nodes.size:
            out[side] = [float(v) for v in Fn[nodes].sum(axis=0)]
    return out


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


def _settings(cfg, schedule=None) -> RelaxSettings:
    r = cfg.relaxation
    if schedule is None:
        schedule = [float(v) for v in r.onset_continuation] + [float(cfg.contact.onset)]
    return RelaxSettings(duration=r.duration, steps=r.steps, rebuild_every=r.rebuild_every,
                         newton_rtol=r.newton_rtol, newton_max_iter=r.newton_max_iter,
                         newton_atol=r.static_atol, static=r.static, static_atol=r.static_atol,
                         static_rounds=r.static_rounds, static_max_iter=r.static_max_iter,
                         method=r.method, onset_schedule=tuple(schedule), energy_max_iter=r.energy_max_iter,
                         time_budget=r.wall_budget_s, backtrack=r.backtrack, near=r.near_band,
                         reuse=r.reuse)


def _coarse_stage(cfg, system):
    """Mesh sequencing: relax on ``relaxation.coarse_elements`` with the whole onset
    schedule, then interpolate the coarse minimum onto the target mesh (rve.fem.transfer).
    Returns ``(x, RelaxResult, dofs)`` of the coarse stage."""
    from ..config import config_as_dict
    from ..fem.transfer import interpolate_nodal

    data = config_as_dict(cfg)
    data["mesh"]["elements"] = int(cfg.relaxation.coarse_elements)
    if cfg.relaxation.coarse_axial_points is not None:
        data["mesh"]["axial_points"] = int(cfg.relaxation.coarse_axial_points)
    ccfg = type(cfg).model_validate(data)
    _, csys, cx0 = build(ccfg)
    cres = relax_to_equilibrium(csys, cx0, np.zeros(csys.n), _settings(ccfg))
    x = np.zeros(system.n)
    xn = system.nodal(x)
    xn[:, :9] = interpolate_nodal(csys.mesh, csys.nodal(cres.x)[:, :9], system.mesh)
    return x, cres, int(csys.n)


def solve(cfg, on_rebuild=None) -> dict:
    t_start = time.perf_counter()
    fab, system, x0 = build(cfg)
    mesh = system.mesh
    t_setup = time.perf_counter() - t_start
    st0 = system.contact_state(x0)
    r = cfg.relaxation
    settings = _settings(cfg)
    history = []
    xs = x0
    coarse = None
    if r.method == "energy" and r.coarse_elements and int(r.coarse_elements) != int(cfg.mesh.elements):
        xs, cres, cdofs = _coarse_stage(cfg, system)
        for h in cres.history:
            history.append(dict(h, mesh_elements=int(r.coarse_elements)))
        coarse = {"elements_per_fibril": int(r.coarse_elements), "dofs": cdofs,
                  "axial_points": r.coarse_axial_points,
                  "onset_schedule_over_R": [float(v) for v in r.onset_continuation] + [float(cfg.contact.onset)],
                  "converged": bool(cres.static_converged), "newton_iterations": int(cres.static_newton_iterations),
                  "wall_s": float(cres.timings.get("total", 0.0))}
        settings = _settings(cfg, [float(v) for v in (r.fine_onset_continuation or [])] + [float(cfg.contact.onset)])
        system.rebuild(xs)
    res = relax_to_equilibrium(system, xs, np.zeros(system.n), settings, on_rebuild=on_rebuild)
    for h in res.history:
        history.append(dict(h, mesh_elements=int(cfg.mesh.elements)))
    st = system.contact_state(res.x)
    n_fixed = len(system.constraints(0.0)[0])
    xn0, xn = system.nodal(x0), system.nodal(res.x)
    its = sum(int(h.get("newton_iterations", 0)) for h in history if h.get("phase") == "static")
    summary = {
        "fabric": fab.kind,
        "fibrils": int(mesh.n_fibrils),
        "elements_per_fibril": int(cfg.mesh.elements),
        "order": int(mesh.order),
        "dofs": int(system.n),
        "free_dofs": int(system.n - n_fixed),
        "method": r.method,
        "onset_schedule_over_R": [float(v) for v in settings.onset_schedule],
        "coarse_stage": coarse,
        "contact_pairs": int(st["pairs"]),
        "active_contact_pairs": int(st["active_pairs"]),
        "initial_max_overlap_over_R": float(st0["max_overlap_over_R"]),
        "max_overlap_over_R": float(st["max_overlap_over_R"]),
        "max_overlap_mm": float(st["max_overlap"]),
        "total_contact_force_N": float(st["total_normal_force"]),
        "clamp_reactions_N": clamp_reactions(fab, system, res.x, res.t),
        "stack": {"initial": stack_geometry(fab, mesh, xn0), "relaxed": stack_geometry(fab, mesh, xn)},
        "static_converged": bool(res.static_converged),
        "dynamic_steps": int(res.dynamic_steps),
        "dynamic_newton_iterations": int(res.dynamic_newton_iterations),
        "static_newton_iterations": int(its if r.method == "energy" else res.static_newton_iterations),
        "static_residuals": [float(v) for v in getattr(res.static_result, "residuals", [])],
        "map_rebuilds": int(system.stats["rebuilds"]),
        "min_det_F": float(system.base.basis.min_det_F(xn)),
        "wall_time_s": {"setup": t_setup, "dynamic": res.timings.get("dynamic", 0.0),
                        "static": res.timings.get("static", 0.0), "total": time.perf_counter() - t_start},
        "history": history,
        "_state": {"fabric": fab, "system": system, "x0": x0, "x": res.x},
    }
    if r.method == "energy":
        sres = res.static_result
        summary["energy_mJ"] = float(system.energy(res.x))  # N mm = mJ
        summary["static_rates"] = [float(v) for v in getattr(sres, "rates", [])]
    # stability: inertia of the static tangent at the result (0 negative pivots: a local
    # minimum of the energy, not a saddle)
    from ..solvers.linear import factor_inertia
    from ..solvers.static import StaticProblem

    prob = StaticProblem(system, res.x, np.zeros(system.n), res.t)
    _, J = prob(prob.u0())
    _, neg = factor_inertia(J)
    summary["negative_pivots"] = int(neg)
    summary["stable"] = bool(neg == 0)
    try:
        import resource

        summary["peak_rss_mb"] = float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
    except (ImportError, OSError):  # pragma: no cover - non-POSIX
        pass
    return summary


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
               "config": json.dumps(_cfg_dict(cfg)) if cfg is not None else "{}"},
    )
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)
    return Path(path)


def _cfg_dict(cfg):
    from ..config import config_as_dict

    return config_as_dict(cfg)


def run(cfg, out_dir: Path) -> dict:
    from ..io.vtk import render_png, tube_surface, write_pvd, write_tubes

    out_dir = Path(out_dir)
    o = cfg.output
    series = []
    if o.vtk:
        # the initial state is written before the run (useful when a run is interrupted)
        fab0 = make_fabric(cfg.fabric)
        mesh0 = fab0.mesh(cfg.mesh.elements, cfg.mesh.order)
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

    summary = solve(cfg, on_rebuild)
    state = summary.pop("_state")
    fab, system, x0, x = state["fabric"], state["system"], state["x0"], state["x"]
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
