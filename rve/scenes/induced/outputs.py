"""Outputs of the induced-deformation scene (docs/induced_deformation.md "Outputs").

Contract
--------
``write_outputs(cfg, result, history, out_dir) -> dict`` (file name -> path) writes

* ``induced_deformation.nc``: dims ``time`` (stored states), ``fibril``, ``node`` (per
  fibril), ``xyz``: ``position`` (mm), ``current`` (A, node average of the section current
  of the adjacent elements, along the fibril's reference direction), ``potential`` (V),
  ``temperature`` (K); dim ``step_time`` (every accepted step): terminal currents, the
  charge, power and energy terms of ``rve.model.balances`` and the balance
  residuals; attributes: orientation, B, balance errors;
* ``tubes/induced.pvd`` + ``tubes/induced_NNNN.vtp``: tube meshes with point data
  ``current`` and ``temperature`` (every ``output.vtk_every``-th stored state);
* ``frames.png`` (``output.frames`` time frames coloured by current, the field arrow drawn)
  and ``temperature.png`` (final state coloured by temperature), rendered off-screen.

``nodal_fields(model, x9, w, t)`` -> (current, potential) per node. ``render_strip(path,
rows, ...)`` renders a grid of tube surfaces (rows x columns) with arrows (used by
``combine_orientations`` for the three-orientation figure of Fig. 8.3.1 / 8.3.2).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...io.atomic import atomic_path

__all__ = ["write_outputs", "nodal_fields", "render_strip", "combine_orientations"]


def _flat_x(model, x9):
    x = np.zeros(model.n)
    model.nodal(x)[:, :9] = x9
    return x


def nodal_fields(model, x9, w, t):
    """Per-node section current (A, along the fibril's parameter) and potential (V)."""
    x = _flat_x(model, x9)
    mesh = model.mesh
    I = model.axial_current(x, w, t).mean(axis=1)  # (E,)
    acc = np.bincount(mesh.conn.ravel(), weights=np.repeat(I, mesh.conn.shape[1]), minlength=mesh.n_nodes)
    cnt = np.bincount(mesh.conn.ravel(), minlength=mesh.n_nodes)
    return acc / cnt, model.nodal(w)[:, model.oV].copy()


def _dataset(cfg, result, history):
    import xarray as xr

    model = result.model
    mesh = model.mesh
    st, bal = history["stored"], history["balances"]
    nt, nf = len(st["t"]), mesh.n_fibrils
    npf = int(np.diff(mesh.node_offsets)[0])
    cur = np.zeros((nt, mesh.n_nodes))
    pot = np.zeros((nt, mesh.n_nodes))
    for k in range(nt):
        cur[k], pot[k] = nodal_fields(model, st["x"][k], st["w"][k], float(st["t"][k]))
    shp = (nt, nf, npf)
    names = list(mesh.names)
    data = {
        "position": (("time", "fibril", "node", "xyz"), st["x"][:, :, :3].reshape(nt, nf, npf, 3),
                     {"units": "mm", "long_name": "centroid position"}),
        "current": (("time", "fibril", "node"), cur.reshape(shp), {"units": "A", "long_name": "section current"}),
        "potential": (("time", "fibril", "node"), pot.reshape(shp), {"units": "V", "long_name": "potential"}),
        "temperature": (("time", "fibril", "node"), np.asarray(st["T"]).reshape(shp),
                        {"units": "K", "long_name": "temperature change"}),
    }
    data["radius"] = ("fibril", np.asarray(mesh.radius, float), {"units": "mm"})
    units = {"current_in": "A", "current_out": "A", "current_leak": "A", "power_circuit": "W", "power_joule": "W",
             "power_contact_joule": "W", "power_lorentz": "W", "power_damping": "W", "energy_kinetic": "mJ",
             "energy_strain": "mJ", "energy_contact": "mJ", "heat_content": "mJ", "heat_out": "W",
             "max_temperature": "K", "contact_active_pairs": "1"}
    for k, u in units.items():
        if k in bal:
            data[k] = ("step_time", np.asarray(bal[k], float), {"units": u})
    data["terminal_currents"] = (("step_time", "warp"), np.asarray(bal["terminal_currents"], float),
                                 {"units": "A", "long_name": "current into each warp terminal"})
    for k, v in history.get("balance_series", {}).items():
        data[k] = ("step_time", np.asarray(v, float), {"units": "A" if k.startswith("charge") else
                                                       ("W" if k.startswith("electrical") else "mJ")})
    ds = xr.Dataset(data, coords={"time": ("time", np.asarray(st["t"]), {"units": "ms"}),
                                  "step_time": ("step_time", np.asarray(bal["t"]), {"units": "ms"}),
                                  "fibril": ("fibril", names)})
    s = result.summary
    ds.attrs.update({"scene": "induced_deformation", "orientation": json.dumps(s["orientation"]),
                     "B_kT": json.dumps(s["B_kT"]), "temperature_mode": s["temperature_mode"],
                     "balance_errors": json.dumps(s["balance_errors"])})
    return ds, cur, pot


def _arrow(B, center, length):
    import pyvista as pv

    d = np.asarray(B, float)
    n = np.linalg.norm(d)
    d = d / n if n > 0 else np.array([0.0, 0.0, 1.0])
    return pv.Arrow(start=np.asarray(center) - 0.5 * length * d, direction=d, scale=length)


def render_strip(path, rows, titles=None, scalars="current", clim=None, window=(600, 480)) -> str:
    """Off-screen grid render: ``rows`` a list of rows, each a list of (surface, B) panels."""
    import pyvista as pv

    nr, nc = len(rows), max(len(r) for r in rows)
    pl = pv.Plotter(off_screen=True, shape=(nr, nc), window_size=[window[0] * nc, window[1] * nr], border=False)
    pl.set_background("white")
    for i, row in enumerate(rows):
        for j, (surf, B) in enumerate(row):
            pl.subplot(i, j)
            pl.add_mesh(surf, scalars=scalars, cmap="jet", clim=clim, smooth_shading=True,
                        scalar_bar_args={"title": {"current": "current (A)", "temperature": "T (K)"}.get(
                            scalars, scalars), "color": "black", "n_labels": 3, "fmt": "%.2g"})
            b = surf.bounds
            c = [0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3]), b[5] + 2.5]
            pl.add_mesh(_arrow(B, c, 3.0), color="black")
            if titles is not None:
                pl.add_text(titles[i][j], font_size=10, color="black")
            pl.view_vector((0.55, -0.85, 0.55), viewup=(0.0, 0.0, 1.0))
            pl.reset_camera()
            pl.camera.zoom(1.25)
    with atomic_path(Path(path)) as tmp:
        pl.screenshot(str(tmp))
    pl.close()
    return str(path)


def _surfaces(model, stored, cur, k, n_theta):
    from ...io.vtk import tube_surface

    return tube_surface(model.mesh, stored["x"][k], n_theta,
                        point_data={"current": cur[k], "temperature": np.asarray(stored["T"][k])})


def write_netcdf(ds, path: Path) -> str:
    """``ds`` written to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)
    return str(path)


def tube_series(tdir: Path, name: str, mesh, stored, cur, pot, output) -> str:
    """Every ``output.vtk_every``-th stored state as ``tdir/<name>_<k>.vtp`` (tubes coloured by
    current, potential and temperature) and their series ``tdir/<name>.pvd``; returns its path."""
    from ...io.vtk import write_pvd, write_tubes

    tdir.mkdir(parents=True, exist_ok=True)
    entries = []
    for k in range(0, len(stored["t"]), output.vtk_every):
        f = tdir / f"{name}_{k:04d}.vtp"
        write_tubes(f, mesh, stored["x"][k], output.n_theta,
                    point_data={"current": cur[k], "potential": pot[k], "temperature": np.asarray(stored["T"][k])})
        entries.append((float(stored["t"][k]), f.name))
    return str(write_pvd(tdir / f"{name}.pvd", entries))


def write_outputs(cfg, result, history, out_dir) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    ds, cur, pot = _dataset(cfg, result, history)
    files["netcdf"] = write_netcdf(ds, out_dir / "induced_deformation.nc")
    model, st = result.model, history["stored"]
    o = cfg.output
    nt = len(st["t"])
    B = result.summary["B_kT"]
    if o.vtk:
        files["pvd"] = tube_series(out_dir / "tubes", "induced", model.mesh, st, cur, pot, o)
    if o.png:
        ks = np.unique(np.linspace(0, nt - 1, o.frames).round().astype(int))
        panels = [[(_surfaces(model, st, cur, int(k), o.n_theta), B) for k in ks]]
        titles = [[f"{result.summary['orientation']}  t = {float(st['t'][k]):.3g} ms" for k in ks]]
        clim = [float(np.min(cur)), float(np.max(cur))]
        files["frames_png"] = render_strip(out_dir / "frames.png", panels, titles, "current", clim)
        last = [[(_surfaces(model, st, cur, nt - 1, o.n_theta), B)]]
        files["temperature_png"] = render_strip(
            out_dir / "temperature.png", last, [[f"{result.summary['orientation']}  t = {float(st['t'][-1]):.3g} ms"]],
            "temperature", [0.0, max(1e-9, float(np.max(st["T"][-1])))])
    return files


def combine_orientations(run_dirs, out_png, out_temperature_png, frames: int = 4, n_theta: int = 12) -> list:
    """Figs. 8.3.1-8.3.2 from the netCDF files of runs (one per orientation): time frames
    (rows) x orientations (columns) coloured by current, and the final temperatures."""
    import pyvista as pv  # noqa: F401
    import xarray as xr

    from ...fem.mesh import FibrilMesh  # noqa: F401

    cols, tcols, titles, ttitles = [], [], [], []
    clim_c, clim_t = [np.inf, -np.inf], [0.0, 0.0]
    dss = [xr.open_dataset(Path(d) / "induced_deformation.nc") for d in run_dirs]
    for ds in dss:
        clim_c = [min(clim_c[0], float(ds.current.min())), max(clim_c[1], float(ds.current.max()))]
        clim_t[1] = max(clim_t[1], float(ds.temperature.isel(time=-1).max()))
    for ds in dss:
        nt = ds.sizes["time"]
        ks = np.unique(np.linspace(0, nt - 1, frames).round().astype(int))
        B = json.loads(ds.attrs["B_kT"])
        name = json.loads(ds.attrs["orientation"])
        col, tit = [], []
        for k in ks:
            col.append((_tube_from_ds(ds, int(k), "current", n_theta), B))
            tit.append(f"{name}  t = {float(ds.time[k]):.3g} ms")
        cols.append(col)
        titles.append(tit)
        tcols.append((_tube_from_ds(ds, nt - 1, "temperature", n_theta), B))
        ttitles.append(f"{name}  t = {float(ds.time[-1]):.3g} ms")
    rows = [[cols[j][i] for j in range(len(cols))] for i in range(len(cols[0]))]
    trow = [[[ttitles[j] for j in range(len(cols))]]]
    render_strip(out_png, rows, [[titles[j][i] for j in range(len(cols))] for i in range(len(rows))], "current",
                 clim_c)
    render_strip(out_temperature_png, [tcols], trow[0], "temperature", clim_t)
    for ds in dss:
        ds.close()
    return [str(out_png), str(out_temperature_png)]


def _tube_from_ds(ds, k, scalars, n_theta):
    """A centre-line tube (pyvista ``tube`` of the polylines) of stored state k of a dataset."""
    import pyvista as pv

    pos = ds.position.isel(time=k).values  # (nf, npf, 3)
    blocks = []
    R = ds.radius.values
    for f, name in enumerate(ds.fibril.values):
        line = pv.lines_from_points(pos[f])
        line.point_data[scalars] = ds[scalars].isel(time=k, fibril=f).values
        blocks.append(line.tube(radius=float(R[f]), n_sides=n_theta, scalars=None))
    surf = blocks[0].merge(blocks[1:]) if len(blocks) > 1 else blocks[0]
    return surf
