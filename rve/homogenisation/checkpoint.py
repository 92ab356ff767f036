"""Self-describing checkpoints of RVE states (netCDF via xarray), written atomically.

The thesis saved the fabric after every stretching iteration "as a precaution against
computer crashes and power outages and to enable further analysis" (§7.3). Every stage
of the pipeline reads the state it starts from and writes the state it ends at as one
file (format ``rve-state/1``); Snakemake's outputs are these files, so a killed run
resumes from the last one written.

Format ``rve-state/1``
======================

Dimensions: ``node``, ``component`` (9: r_x r_y r_z g1_x g1_y g1_z g2_x g2_y g2_z),
``fibril``, ``element``, ``element_node``, ``yarn``, ``end`` (fibril ends), ``side``
(x-, x+, y-, y+), ``xyz`` (3), ``pair`` (contact element pairs of the map at the state).

==========================  ===========================  =======  ==========================
variable                    dims                         units    meaning
==========================  ===========================  =======  ==========================
state                       node, component              mm       centroid r and directors
velocity                    node, component              mm/ms    w (zero after a static solve)
reference                   node, component              mm       natural configuration X0
origin                      node, component              mm       start of the strain path
                                                                  (the relaxed state): the
                                                                  velocity field's X
node_fibril, node_s         node                         -, mm    fibril, parameter s
conn                        element, element_node        1        global nodes of elements
radius                      fibril                       mm       section radius
fibril_name, fibril_yarn    fibril                       1
yarn_name, yarn_direction,  yarn                         1, mm    warp/weft/loop, position
yarn_position
end_fibril, end_node,       end                          1        fibril end tags (clamps,
end_yarn, end_side,                                               probe terminals)
end_which
reaction_force              side, xyz                    N        clamp force on the fibrils
                                                                  summed per side
contact_element_plus/minus  pair                         1        element pairs of the map
contact_active_points       pair                         1        overlapping points per pair
contact_multiplier_key      contact_point, point_key     1        key of each multiplier's
                                                                  point (augmented Lagrangian
                                                                  only; ``point_keys``)
contact_multiplier          contact_point                N/mm     its multiplier (line load)
contact_friction_key        friction_point, point_key    1        key of each friction point
                                                                  (friction only)
contact_friction_s_bar      friction_point               1        its - side material point
contact_friction_anchor     friction_point, xyz          mm       elastic gap minus the jump
contact_friction_d_ref      friction_point, xyz          1        the - chord's direction
                                                                  the anchor is stored in
contact_friction_m_ref      friction_point, xyz          1        (the section frame) the -
                                                                  section's g1 across d_ref
==========================  ===========================  =======  ==========================

Attributes: ``rve_state_format``, ``kind`` (initial | relaxed | strained), ``mode``,
``step``, ``strain``, ``time`` (ms of simulated time), ``combo`` and ``params`` (JSON:
the swept parameter values), ``config`` (JSON: the validated RVEConfig in internal
units), ``fabric_kind``, ``elements``, ``order``, ``half_widths``, ``contact_count``
(overlapping contact points), ``solver`` (JSON: convergence, iterations, wall times),
``rve_version``; with friction ``friction_dissipated`` (N mm).

``write_state`` writes through ``rve.io.atomic.atomic_netcdf`` (temporary file in the
same directory, Fletcher-32 on every variable, the SHA-256 trailer of ``rve.io.checksum``,
then a rename), so a file that exists is complete and proves it. ``load_state`` verifies
the trailer before HDF5 reads the file (a file without one, or with a mismatch, is a
``rve.io.checksum.CorruptFileError`` naming the file and what failed; ``quarantine=True``
also moves it aside as ``<name>.corrupt`` so Snakemake reruns the job that wrote it) and
returns a :class:`State` with the flat dof vectors of the mechanics-only layout (9 per
node). ``non_final_path(path)`` is where a job keeps a state that is not an equilibrium
(``relaxed.unconverged.nc``: no rule's output, so Snakemake reruns the job;
docs/fault_tolerance.md).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..io.provenance import package_version, to_jsonable

__all__ = ["STATE_FORMAT", "COMPONENTS", "SIDES", "State", "write_state", "load_state", "describe", "non_final_path"]

STATE_FORMAT = "rve-state/1"
COMPONENTS = ("r_x", "r_y", "r_z", "g1_x", "g1_y", "g1_z", "g2_x", "g2_y", "g2_z")
SIDES = ("x-", "x+", "y-", "y+")


@dataclass
class State:
    """A stored state: nodal arrays (n_nodes, 9) and the metadata of the file."""

    x: np.ndarray                  # (n_nodes, 9) positions r and directors g1, g2
    w: np.ndarray                  # (n_nodes, 9) velocities
    origin: np.ndarray             # (n_nodes, 9) the relaxed state (start of the strain path)
    kind: str
    mode: str = ""
    step: int = 0
    strain: float = 0.0
    time: float = 0.0
    combo: str = ""
    params: dict = field(default_factory=dict)
    config: dict = field(default_factory=dict)
    reaction_force: dict = field(default_factory=dict)   # side -> [fx, fy, fz]
    contact_count: int = 0
    solver: dict = field(default_factory=dict)
    reference: Optional[np.ndarray] = None
    #: augmented Lagrangian contact multipliers at x: (keys (n, 6) int64, values (n,)) or None
    multipliers: Optional[tuple] = None
    #: friction history at x (``FrictionTerm.record()``: keys, s_bar, anchor, dissipated) or None
    friction: Optional[dict] = None


def write_state(path, state: State, fabric, mesh, contact=None, version: Optional[str] = None) -> Path:
    """Write ``state`` of ``fabric``/``mesh`` atomically as netCDF (module docstring).

    ``contact``: a ``ContactSystem`` whose map (at ``state.x``) is stored, or None."""
    import xarray as xr

    from ..io.atomic import atomic_netcdf

    nn = mesh.n_nodes
    for name in ("x", "w", "origin"):
        arr = getattr(state, name)
        if np.shape(arr) != (nn, 9):
            raise ValueError(f"state.{name} must be (n_nodes, 9) = ({nn}, 9), got {np.shape(arr)}")
    data = _state_arrays(state, fabric, mesh)
    data.update(_contact_arrays(state, contact))
    attrs = _state_attributes(state, fabric, mesh, version)
    if state.friction is not None:
        attrs["friction_dissipated"] = float(state.friction.get("dissipated", 0.0))
    ds = xr.Dataset(data, coords={"component": list(COMPONENTS), "side": list(SIDES), "xyz": ["x", "y", "z"]},
                    attrs=attrs)
    atomic_netcdf(ds, path)
    return Path(path)


def _state_arrays(state: State, fabric, mesh) -> dict:
    """The state, the mesh and the fabric's yarns and ends as checkpoint variables."""
    tags = fabric.end_tags
    mm = {"units": "mm"}
    reac = np.full((len(SIDES), 3), np.nan)
    for i, s in enumerate(SIDES):
        if s in state.reaction_force:
            reac[i] = state.reaction_force[s]
    return {
        "state": (("node", "component"), np.asarray(state.x, float),
                  {"long_name": "beam state: centroid r and directors g1, g2", **mm}),
        "velocity": (("node", "component"), np.asarray(state.w, float),
                     {"long_name": "velocity of the beam state", "units": "mm/ms"}),
        "reference": (("node", "component"), np.asarray(mesh.X0, float),
                      {"long_name": "natural (stress-free) configuration", **mm}),
        "origin": (("node", "component"), np.asarray(state.origin, float),
                   {"long_name": "start of the strain path (relaxed state): X of the velocity field", **mm}),
        "node_fibril": (("node",), mesh.node_fibril.astype(np.int32), {"long_name": "fibril of each node"}),
        "node_s": (("node",), np.asarray(mesh.node_s, float),
                   {"long_name": "reference parameter along the fibril", **mm}),
        "conn": (("element", "element_node"), mesh.conn.astype(np.int32),
                 {"long_name": "global node indices of each element, in axial order"}),
        "radius": (("fibril",), np.asarray(mesh.radius, float), {"long_name": "fibril section radius", **mm}),
        "fibril_name": (("fibril",), np.array(mesh.names, dtype=object), {"long_name": "fibril name"}),
        "fibril_yarn": (("fibril",), np.asarray(fabric.fibril_yarn, np.int32), {"long_name": "yarn of each fibril"}),
        "yarn_name": (("yarn",), np.array([y.name for y in fabric.yarns], dtype=object), {"long_name": "yarn name"}),
        "yarn_direction": (("yarn",), np.array([y.direction for y in fabric.yarns], dtype=object),
                           {"long_name": "yarn direction (warp, weft, loop)"}),
        "yarn_position": (("yarn",), np.array([y.position for y in fabric.yarns], float),
                          {"long_name": "yarn position across the fabric (warp: y, weft: x, loop: y)", **mm}),
        "end_fibril": (("end",), np.array([t.fibril for t in tags], np.int32), {"long_name": "fibril of the end"}),
        "end_node": (("end",), np.array([t.node(mesh) for t in tags], np.int32),
                     {"long_name": "global node of the end"}),
        "end_yarn": (("end",), np.array([t.yarn for t in tags], np.int32), {"long_name": "yarn of the end"}),
        "end_side": (("end",), np.array([t.side for t in tags], dtype=object), {"long_name": "box side of the end"}),
        "end_which": (("end",), np.array([t.end for t in tags], dtype=object),
                      {"long_name": "start (s = 0) or end (s = length) of the fibril"}),
        "reaction_force": (("side", "xyz"), reac,
                           {"long_name": "force of the clamps on the fibril ends, summed per box side", "units": "N"}),
    }


def _contact_arrays(state: State, contact) -> dict:
    """The contact map at the state (pairs, active points) and the augmented Lagrangian
    multipliers, when there are any."""
    data = {}
    if contact is not None and contact.map is not None:
        cmap = contact.map
        xflat = np.ascontiguousarray(state.x).reshape(-1)
        act = contact.active_points(xflat)
        data["contact_element_plus"] = (("pair",), np.asarray(cmap.e_plus, np.int32),
                                        {"long_name": "element (+ side) of each contact pair of the map"})
        data["contact_element_minus"] = (("pair",), np.asarray(cmap.e_minus, np.int32),
                                         {"long_name": "element (- side) of each contact pair of the map"})
        data["contact_active_points"] = (("pair",), act,
                                         {"long_name": "overlapping contact points of the pair at the state"})
    if state.multipliers is not None:
        keys, values = state.multipliers
        data["contact_multiplier_key"] = (("contact_point", "point_key"), np.asarray(keys, np.int64),
                                          {"long_name": "contact point of each multiplier: element a, point index, "
                                                        "fibril of b, shift of b (1e-6 mm units, 3)"})
        data["contact_multiplier"] = (("contact_point",), np.asarray(values, float),
                                      {"long_name": "augmented Lagrangian contact multiplier (line load)",
                                       "units": "N/mm"})
    if state.friction is not None:
        fr = state.friction
        data["contact_friction_key"] = (("friction_point", "point_key"), np.asarray(fr["keys"], np.int64),
                                        {"long_name": "contact point of each friction history: element +, point "
                                                      "index, element -, shift of - (1e-6 mm units, 3)"})
        data["contact_friction_s_bar"] = (("friction_point",), np.asarray(fr["s_bar"], float),
                                          {"long_name": "material point of the - chord in contact at the state"})
        data["contact_friction_anchor"] = (("friction_point", "xyz"), np.asarray(fr["anchor"], float),
                                           {"long_name": "elastic tangential gap minus the jump of the material "
                                                         "points", "units": "mm"})
        if fr.get("d_ref") is not None:
            data["contact_friction_d_ref"] = (("friction_point", "xyz"), np.asarray(fr["d_ref"], float),
                                              {"long_name": "unit direction of the - chord the anchor is stored "
                                                            "in (the anchor turns with the chord)"})
        if fr.get("m_ref") is not None:
            data["contact_friction_m_ref"] = (("friction_point", "xyz"), np.asarray(fr["m_ref"], float),
                                              {"long_name": "unit part across d_ref of the - section's first "
                                                            "director (the section frame the anchor turns with)"})
    return data


def _state_attributes(state: State, fabric, mesh, version: Optional[str]) -> dict:
    """The checkpoint's global attributes: what the state is and how it was made."""
    return {
        "title": f"rve state: {fabric.kind} {state.kind}"
                 + (f" {state.mode} step {state.step} (strain {state.strain:g})" if state.mode else ""),
        "rve_state_format": STATE_FORMAT,
        "kind": state.kind,
        "mode": state.mode,
        "step": int(state.step),
        "strain": float(state.strain),
        "time": float(state.time),
        "combo": state.combo,
        "params": json.dumps(to_jsonable(state.params), sort_keys=True),
        "config": json.dumps(to_jsonable(state.config), sort_keys=True),
        "fabric_kind": fabric.kind,
        "elements": int(mesh.n_elements // max(1, mesh.n_fibrils)),
        "order": int(mesh.order),
        "half_widths": [float(v) for v in fabric.half_widths],
        "contact_count": int(state.contact_count),
        "solver": json.dumps(to_jsonable(state.solver), sort_keys=True),
        "rve_version": version or package_version(),
        "conventions": "node-interleaved beam state (9 per node); internal units mm, ms, g, N, MPa, K, A, V",
    }


def load_state(path, quarantine: bool = False) -> State:
    """Read a checkpoint written by :func:`write_state`, verified first (module docstring).
    Raises ``CorruptFileError`` (a ValueError naming the file and what failed) for a file
    that fails its check, ValueError for another format. ``quarantine``: a corrupt file is
    also renamed to ``<name>.corrupt`` (the producing job then reruns)."""
    from ..io.checksum import CorruptFileError, open_netcdf
    from ..io.checksum import quarantine as move_aside

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no RVE state at {path}")
    try:
        ds = open_netcdf(path, require_seal=True)
        fmt = ds.attrs.get("rve_state_format")
        if fmt != STATE_FORMAT:
            raise CorruptFileError(path, f"not an rve state file (rve_state_format = {fmt!r}, expected "
                                         f"{STATE_FORMAT!r})", hint="")
        return _state_of(ds, path)
    except CorruptFileError as exc:
        if quarantine and exc.hint:
            dest = move_aside(path)
            if dest is not None:
                raise CorruptFileError(path, exc.what, f"moved to {dest.name}: the job that wrote it reruns "
                                                       "on the next snakemake call") from None
        raise


def _state_of(ds, path) -> State:
    from ..io.checksum import CorruptFileError

    missing = [v for v in ("state", "velocity", "origin", "reference", "reaction_force") if v not in ds]
    if missing or "kind" not in ds.attrs:
        raise CorruptFileError(path, "incomplete rve state (missing " + ", ".join(missing or ["attribute kind"]) + ")")
    try:
        return _build_state(ds)
    except (KeyError, TypeError, ValueError) as exc:
        raise CorruptFileError(path, f"unreadable rve state ({type(exc).__name__}: {exc})") from None


def _build_state(ds) -> State:
    reac = {}
    rf = ds["reaction_force"].values
    for i, s in enumerate(ds["side"].values):
        if np.all(np.isfinite(rf[i])):
            reac[str(s)] = [float(v) for v in rf[i]]
    a = ds.attrs
    return State(
        x=np.asarray(ds["state"].values, float),
        w=np.asarray(ds["velocity"].values, float),
        origin=np.asarray(ds["origin"].values, float),
        kind=str(a["kind"]),
        mode=str(a.get("mode", "")),
        step=int(a.get("step", 0)),
        strain=float(a.get("strain", 0.0)),
        time=float(a.get("time", 0.0)),
        combo=str(a.get("combo", "")),
        params=json.loads(a.get("params", "{}")),
        config=json.loads(a.get("config", "{}")),
        reaction_force=reac,
        contact_count=int(a.get("contact_count", 0)),
        solver=json.loads(a.get("solver", "{}")),
        reference=np.asarray(ds["reference"].values, float),
        multipliers=(np.asarray(ds["contact_multiplier_key"].values, np.int64),
                     np.asarray(ds["contact_multiplier"].values, float)) if "contact_multiplier" in ds else None,
        friction=_friction_record(ds),
    )


def _friction_record(ds):
    if "contact_friction_key" not in ds:
        return None
    return {"keys": np.asarray(ds["contact_friction_key"].values, np.int64),
            "s_bar": np.asarray(ds["contact_friction_s_bar"].values, float),
            "anchor": np.asarray(ds["contact_friction_anchor"].values, float),
            "d_ref": (np.asarray(ds["contact_friction_d_ref"].values, float) if "contact_friction_d_ref" in ds
                      else None),
            "m_ref": (np.asarray(ds["contact_friction_m_ref"].values, float) if "contact_friction_m_ref" in ds
                      else None),
            "dissipated": float(ds.attrs.get("friction_dissipated", 0.0))}


def non_final_path(path) -> Path:
    """``states/relaxed.nc`` -> ``states/relaxed.unconverged.nc``: the name under which a job
    keeps a state that failed its equilibrium check (matches no rule output)."""
    path = Path(path)
    return path.with_name(f"{path.stem}.unconverged{path.suffix}")


def describe(path) -> dict[str, Any]:
    """Short summary of a checkpoint (for logs and the CLI)."""
    st = load_state(path)
    return {"kind": st.kind, "mode": st.mode, "step": st.step, "strain": st.strain, "combo": st.combo,
            "contact_count": st.contact_count, "reaction_force": st.reaction_force, "nodes": int(st.x.shape[0])}
