"""Scene: one crossing, stick then slip (docs/contact.md "Friction").

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
* ``setup(cfg) -> (system, parts)``: the ``ContactSystem`` of a validated
  ``FrictionCrossingConfig`` (rve.config.friction) and the dofs the path moves;
* ``solve(cfg) -> SceneResult``: the indentation, then the tangential cycle of the slider's
  ends 0 -> U -> -U -> U; ``summary["path"]`` per step: ``u`` (end displacement, mm),
  ``slip`` (the contact point's tangential displacement, mm, ``contact_point``), ``force`` (the supports'
  tangential force on the slider, N), ``normal`` (total contact normal force, N),
  ``dissipated`` (N mm, the step's), ``stick``/``slip_points``, ``newton`` (residual
  history); and ``stiffness`` (the point tangential stiffness w eps_T P*, N/mm, w the weight
  of the slider's point: ``point_weight``), ``mu``;
* ``run(cfg, out_dir)``: the summary (and ``crossing_path.json``).

Set-up: the *slider* (fibril 0, the + side of the pair) lies along e2 at height 2R above the
*base* (fibril 1, ``base_elements`` along e1, shifted by ``base_offset``, every dof held); the slider's end nodes are held
(all 9 dofs), lowered by ``indentation`` and then moved along e1, so the slider slides
along the base's axis (the closest point on the base follows; the + point is material). The
slider has an odd number of elements and one contact point per pair (``n_gp = 1``): one
point, at the centre of the middle element, touches. With ``contact.geometry`` curve or smooth
the base's own points (the other half pass) touch too unless they are away from the crossing:
``geometry.base_offset`` puts them there (one base element, its point 0.5 mm from it).
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from ..fem.mesh import fibril_mesh, straight_fibril
from ..model import BeamMaterial, BeamModel, DirichletBC
from ..model.contact_model import ContactSystem
from ..model.terms.contact import ContactParams
from ..physics.contact_curve import curve_basis
from ..physics.contact_smooth import hermite_basis
from .frictional import friction_law, initial_state, reaction, step
from .protocol import SceneFailure, SceneResult

__all__ = ["setup", "solve", "run", "load_path", "point_weight", "contact_point"]

log = logging.getLogger("rve.scenes.friction_crossing")


def setup(cfg):
    g = cfg.geometry
    R, zc = g.radius, 2.0 * g.radius
    slider = straight_fibril([0.0, -g.slider_length / 2, zc], [0.0, g.slider_length / 2, zc], R, "slider")
    o = g.base_offset
    base = straight_fibril([o - g.base_length / 2, 0.0, 0.0], [o + g.base_length / 2, 0.0, 0.0], R, "base")
    mesh = fibril_mesh([slider, base], [cfg.mesh.elements, g.base_elements], cfg.mesh.order)
    a, b = mesh.end_nodes(0)
    model0 = BeamModel(mesh, BeamMaterial(youngs_modulus=cfg.material.youngs_modulus))
    lay = model0.layout
    held = np.concatenate([lay.dofs("mech", [a, b]), lay.dofs("mech", mesh.fibril_nodes(1))])
    model = BeamModel(mesh, BeamMaterial(youngs_modulus=cfg.material.youngs_modulus),
                      bcs=[DirichletBC(held, 0.0)])
    params = ContactParams(penalty=cfg.contact.penalty, n_gp=cfg.contact.n_gp, geometry=cfg.contact.geometry,
                           margin=0.5 * R, friction=friction_law(cfg.friction))
    system = ContactSystem(model, params, initial_state(mesh, lay))
    mid = cfg.mesh.elements // 2
    ca, cb = mesh.conn[mid, 0], mesh.conn[mid, -1]
    nodes, weights = contact_point(system, mid)
    parts = {"z": lay.dofs("r", [a, b], comp=2), "x": lay.dofs("r", [a, b], comp=0),
             "contact_x": lay.dofs("r", [ca, cb], comp=0), "point_x": lay.dofs("r", nodes, comp=0),
             "point_w": weights, "slider_element": mid}
    return system, parts


def contact_point(system, element: int):
    """``(nodes, weights)``: the position of the contact point at the centre of the slider's
    ``element`` as the contact geometry has it, ``sum weights * r[nodes]``: the chord's
    midpoint (the end nodes), the Lagrange curve's point (the element's nodes), or the
    Hermite curve's (the element's stencil)."""
    term, conn = system.term, system.mesh.conn
    if term.smooth:
        st = term.passes.stencil
        return st.nodes[element], hermite_basis(np.array(0.5))[0] @ st.S[element]
    if term.curve:
        return conn[element], curve_basis(system.mesh.order, np.array(0.5))[0]
    return conn[element, [0, -1]], np.array([0.5, 0.5])


def point_weight(system, element: int) -> float:
    """The weight (mm) of the contact points of the slider's ``element`` on its - side: the
    chord's l_e / n_gp; on the curves the half pass's l_e W_k / 2 of the rows whose points
    are on that element."""
    term = system.term
    if term.curve:
        return float(term.weight[term.passes.a_elem == element].max())
    return float(term.weight.max())


def load_path(amplitude: float, n: int) -> np.ndarray:
    """End displacements of the cycle 0 -> U -> -U -> U, ``n`` steps per quarter leg."""
    up = np.linspace(0.0, amplitude, n + 1)[1:]
    down = np.linspace(amplitude, -amplitude, 2 * n + 1)[1:]
    return np.concatenate([up, down, -down])


def solve(cfg) -> SceneResult:
    t0 = time.perf_counter()
    system, parts = setup(cfg)
    fr = system.term.friction
    x = initial_state(system.mesh, system.layout)
    nz = cfg.load.indentation_steps
    z0 = x[parts["z"]].copy()
    for k in range(1, nz + 1):
        x[parts["z"]] = z0 - cfg.geometry.indentation * k / nz
        x, _, _ = step(system, x, 0.0, cfg.newton, "friction_crossing", "indentation", k)
    path = []
    for k, u in enumerate(load_path(cfg.load.amplitude, cfg.load.steps_per_leg), start=1):
        x[parts["x"]] = u
        x, res, diss = step(system, x, 0.0, cfg.newton, "friction_crossing", "cycle", k)
        pts = fr.points() if fr is not None else {"normal_force": system.contact_state(x)["total_normal_force"],
                                                   "stick": 0, "slip": 0}
        path.append({"u": float(u), "slip": float(parts["point_w"] @ x[parts["point_x"]]),
                     "force": float(reaction(system, x, parts["x"]).sum()), "normal": pts["normal_force"],
                     "dissipated": diss, "stick": pts["stick"], "slip_points": pts["slip"],
                     "newton": [float(r) for r in res.residuals]})
    if system.term.map.n_pairs == 0:
        raise SceneFailure("friction_crossing", "no contact pair found", phase="setup")
    w = point_weight(system, parts["slider_element"])
    summary = {"mu": float(cfg.friction.coefficient),
               "stiffness": w * float(cfg.friction.stiffness) * float(cfg.contact.penalty),
               "path": path, "wall_time_s": time.perf_counter() - t0}
    return SceneResult(state={"x": x}, model=system, summary=summary)


def run(cfg, out_dir: Path) -> dict:
    try:
        summary = solve(cfg).summary
    except SceneFailure as failure:
        if failure.state is not None:
            failure.save(Path(out_dir) / "friction_crossing_last_good_state.npz")
        log.error("%s", failure)
        raise
    (Path(out_dir) / "crossing_path.json").write_text(json.dumps(summary["path"], indent=1))
    return summary
