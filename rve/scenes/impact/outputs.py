"""Outputs of the impact scene, like Figs. 8.4.1-8.4.6 (docs/impact.md "Outputs").

Contract
--------
``write_outputs(cfg, result, history, out_dir) -> dict`` (name -> path) writes, atomically:

* ``impact.nc``: dim ``step_time`` (every accepted step): ``projectile_com_velocity``,
  ``projectile_bottom_velocity``, ``projectile_top_velocity``, ``projectile_com`` (mm/ms, mm;
  dim ``xyz``), ``projectile_angular_velocity`` (rad/ms, the rigid-body formula of §8.4),
  ``yarn_current`` (A; dim ``sampled`` = minus_y, plus_y, edge), ``max_temperature``,
  ``mean_temperature`` (K), the balance terms and residuals; dims ``time`` (stored states),
  ``fibril``, ``node``: ``position``, ``current``, ``temperature``; attributes: B, the
  sampled yarns, balance errors;
* ``impact_velocity.png`` (Fig. 8.4.2: v_z of the centre of mass and both ends),
  ``impact_angular_velocity.png`` (Fig. 8.4.3), ``impact_currents.png`` (Fig. 8.4.4),
  ``impact_temperature_series.png`` (max / mean T), ``frames.png`` (Fig. 8.4.1: snapshots
  coloured by current, the projectile drawn as its capsule), ``temperature.png`` (Fig.
  8.4.5: T at t_end), ``closeup.png`` (Fig. 8.4.6: impact site, looking along -y);
* ``tubes/impact.pvd`` + ``tubes/impact_NNNN.vtp`` (fabric tubes with current, potential,
  temperature) and ``tubes/projectile_NNNN.vtp`` (the projectile capsule) for ParaView.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...io.atomic import atomic_path
from ..induced.outputs import nodal_fields, tube_series, write_netcdf

__all__ = ["write_outputs", "capsule"]

_SAMPLED = ("minus_y", "plus_y", "edge")


def capsule(xp9, radius, n_theta=24):
    """The projectile's surface: a cylinder between its end nodes and the two hemispheres."""
    import pyvista as pv

    a, b = np.asarray(xp9[0, :3]), np.asarray(xp9[1, :3])
    d = b - a
    L = float(np.linalg.norm(d))
    parts = [pv.Sphere(radius=radius, center=a, theta_resolution=n_theta, phi_resolution=n_theta),
             pv.Sphere(radius=radius, center=b, theta_resolution=n_theta, phi_resolution=n_theta)]
    if L > 0:
        parts.append(pv.Cylinder(center=0.5 * (a + b), direction=d / L, radius=radius, height=L,
                                 resolution=n_theta).triangulate())
    surf = parts[0].merge(parts[1:])
    surf.point_data["current"] = np.full(surf.n_points, np.nan)
    surf.point_data["temperature"] = np.full(surf.n_points, np.nan)
    return surf


def _save_vtp(surf, path):
    """Atomic .vtp write (pyvista picks the format from the suffix)."""
    import os

    tmp = Path(path).with_name(Path(path).stem + ".tmp.vtp")
    surf.save(str(tmp))
    os.replace(tmp, path)


def _dataset(cfg, result, history):
    import xarray as xr

    sysm = result.model
    mesh = sysm.fabric.mesh
    base = sysm.fabric.base
    st, se, bal = history["stored"], history["series"], history["balances"]
    nt, nf = len(st["t"]), mesh.n_fibrils
    npf = int(np.diff(mesh.node_offsets)[0])
    cur = np.zeros((nt, mesh.n_nodes))
    pot = np.zeros((nt, mesh.n_nodes))
    for k in range(nt):
        cur[k], pot[k] = nodal_fields(base, st["x"][k], st["w"][k], float(st["t"][k]))
    shp = (nt, nf, npf)
    data = {
        "position": (("time", "fibril", "node", "xyz"), st["x"][:, :, :3].reshape(nt, nf, npf, 3), {"units": "mm"}),
        "current": (("time", "fibril", "node"), cur.reshape(shp), {"units": "A", "long_name": "section current"}),
        "potential": (("time", "fibril", "node"), pot.reshape(shp), {"units": "V"}),
        "temperature": (("time", "fibril", "node"), np.asarray(st["T"]).reshape(shp), {"units": "K"}),
        "projectile_nodes": (("time", "end", "xyz"), np.asarray(st["xp"])[:, :, :3], {"units": "mm"}),
        "radius": ("fibril", np.asarray(mesh.radius, float), {"units": "mm"}),
        "projectile_com_velocity": (("step_time", "xyz"), se["v_com"], {"units": "mm/ms"}),
        "projectile_bottom_velocity": (("step_time", "xyz"), se["v_bottom"], {"units": "mm/ms"}),
        "projectile_top_velocity": (("step_time", "xyz"), se["v_top"], {"units": "mm/ms"}),
        "projectile_com": (("step_time", "xyz"), se["com"], {"units": "mm"}),
        "projectile_angular_velocity": (("step_time", "xyz"), se["omega"],
                                        {"units": "rad/ms", "long_name": "rigid-body estimate of thesis §8.4"}),
        "yarn_current": (("step_time", "sampled"), se["yarn_currents"], {"units": "A"}),
        "max_temperature": ("step_time", se["max_T"], {"units": "K"}),
        "mean_temperature": ("step_time", se["mean_T"], {"units": "K"}),
        "sphere_pairs_active": ("step_time", se["sphere_pairs_active"], {"units": "1"}),
        "contact_active_pairs": ("step_time", se["contact_active_pairs"], {"units": "1"}),
    }
    for k, v in bal.items():
        if k == "t":
            continue
        a = np.asarray(v, float)
        if a.ndim == 1:
            data[f"balance_{k}"] = ("step_time", a)
        elif k == "terminal_currents":
            data["terminal_currents"] = (("step_time", "warp"), a, {"units": "A"})
        else:
            data[f"balance_{k}"] = (("step_time", "xyz"), a)
    for k, v in history.get("balance_series", {}).items():
        a = np.asarray(v, float)
        data[k] = ("step_time", a) if a.ndim == 1 else (("step_time", "xyz"), a)
    ds = xr.Dataset(data, coords={"time": ("time", np.asarray(st["t"]), {"units": "ms"}),
                                  "step_time": ("step_time", np.asarray(se["t"]), {"units": "ms"}),
                                  "fibril": ("fibril", list(mesh.names)), "sampled": ("sampled", list(_SAMPLED)),
                                  "xyz": ("xyz", ["x", "y", "z"])})
    s = result.summary
    ds.attrs.update({"scene": "impact", "B_kT": json.dumps(s["geometry"]["B_kT"]),
                     "sampled_yarns": json.dumps(s["sampled_yarns"]),
                     "balance_errors": json.dumps(s["balance_errors"])})
    return ds, cur, pot


def _plot(path, t, curves, ylabel, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    for y, label, style in curves:
        ax.plot(t, y, style, label=label, lw=1.4)
    ax.set_xlabel("t (ms)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return str(path)


def _render(path, panels, titles, scalars, clim, view, window=(700, 520), zoom=1.2):
    import pyvista as pv

    nc = len(panels)
    pl = pv.Plotter(off_screen=True, shape=(1, nc), window_size=[window[0] * nc, window[1]], border=False)
    pl.set_background("white")
    for j, (fab, prj) in enumerate(panels):
        pl.subplot(0, j)
        pl.add_mesh(fab, scalars=scalars, cmap="jet", clim=clim, smooth_shading=True,
                    scalar_bar_args={"title": {"current": "current (A)", "temperature": "T (K)"}[scalars],
                                     "color": "black", "n_labels": 3, "fmt": "%.3g"})
        pl.add_text(titles[j], font_size=10, color="black")
        pl.view_vector(view[0], viewup=view[1])
        pl.reset_camera()  # on the fabric: the projectile is drawn over it, clipped by the view
        pl.camera.zoom(zoom)
        pl.add_mesh(prj, color="lightgray", opacity=0.35, smooth_shading=True, reset_camera=False)
    with atomic_path(Path(path)) as tmp:
        pl.screenshot(str(tmp))
    pl.close()
    return str(path)


def write_outputs(cfg, result, history, out_dir) -> dict:
    from ...io.vtk import tube_surface, write_pvd

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    ds, cur, pot = _dataset(cfg, result, history)
    files["netcdf"] = write_netcdf(ds, out_dir / "impact.nc")
    sysm = result.model
    mesh = sysm.fabric.mesh
    st, se = history["stored"], history["series"]
    o = cfg.output
    nt = len(st["t"])
    Rp = cfg.projectile.radius
    if o.vtk:
        tdir = out_dir / "tubes"
        files["pvd"] = tube_series(tdir, "impact", mesh, st, cur, pot, o)
        for k in range(0, nt, o.vtk_every):
            _save_vtp(capsule(st["xp"][k], Rp), tdir / f"projectile_{k:04d}.vtp")
        files["pvd_projectile"] = str(write_pvd(tdir / "projectile.pvd", [
            (float(st["t"][k]), f"projectile_{k:04d}.vtp") for k in range(0, nt, o.vtk_every)]))
    if o.png:
        t = np.asarray(se["t"])
        v_com, v_b, v_t = (np.asarray(se[k]) for k in ("v_com", "v_bottom", "v_top"))
        files["velocity_png"] = _plot(out_dir / "impact_velocity.png", t,
                                      [(v_com[:, 2], "centre of mass", "k-"), (v_b[:, 2], "bottom end", "b--"),
                                       (v_t[:, 2], "top end", "r:")], "v_z (mm/ms = m/s)",
                                      "Projectile velocity along z (cf. Fig. 8.4.2)")
        files["angular_velocity_png"] = _plot(out_dir / "impact_angular_velocity.png", t,
                                              [(np.asarray(se["omega"])[:, 0], "omega_x", "k-")], "omega_x (rad/ms)",
                                              "Angular velocity about x, rigid-body formula (cf. Fig. 8.4.3)")
        yc = np.asarray(se["yarn_currents"])
        files["currents_png"] = _plot(out_dir / "impact_currents.png", t,
                                      [(yc[:, 0], "-y side yarn", "b-"), (yc[:, 1], "+y side yarn", "r-"),
                                       (yc[:, 2], "edge yarn", "k--")], "current (A)",
                                      "Current in three warp yarns (cf. Fig. 8.4.4)")
        files["temperature_series_png"] = _plot(out_dir / "impact_temperature_series.png", t,
                                                [(np.asarray(se["max_T"]), "max T", "r-"),
                                                 (np.asarray(se["mean_T"]), "mean T", "k--")], "T (K)",
                                                "Fabric temperature (above the initial 0 K)")
        ks = np.unique(np.linspace(0, nt - 1, o.frames).round().astype(int))
        clim = [float(np.min(cur)), float(np.max(cur))]

        def panel(k, scalars="current"):
            fab = tube_surface(mesh, st["x"][k], o.n_theta,
                               point_data={"current": cur[k], "temperature": np.asarray(st["T"][k])})
            return fab, capsule(st["xp"][k], Rp)

        view3 = ((0.55, -0.85, 0.45), (0.0, 0.0, 1.0))
        files["frames_png"] = _render(out_dir / "frames.png", [panel(int(k)) for k in ks],
                                      [f"t = {float(st['t'][k]):.3g} ms" for k in ks], "current", clim, view3)
        Tmax = max(1e-9, float(np.max(st["T"][-1])))
        files["temperature_png"] = _render(out_dir / "temperature.png", [panel(nt - 1)],
                                           [f"T at t = {float(st['t'][-1]):.3g} ms"], "temperature", [0.0, Tmax],
                                           ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)), window=(900, 800))
        files["closeup_png"] = _render(out_dir / "closeup.png", [panel(nt - 1)],
                                       [f"impact site, view along -y, t = {float(st['t'][-1]):.3g} ms"], "current",
                                       clim, ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), window=(900, 700), zoom=2.0)
    return files
