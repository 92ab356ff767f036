"""Scene: the capstan, a fibril wrapped over a rigid cylinder slides at T2/T1 = exp(mu theta)
(docs/contact.md "Friction").

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
* ``setup(cfg) -> (system, parts)``: the ``DeadLoad`` of the ``ContactSystem`` of a
  validated ``CapstanConfig`` (rve.config.friction) with T1 at the free end, and the dofs,
  directions and initial state ``x0`` the path uses;
* ``solve(cfg) -> SceneResult``: the frictionless pretension (the free end pulled along its
  tail by T1 L / (E A) in ``load.pretension_steps`` with both ends held, then released
  under the dead load T1), then friction switched on from that
  state (no elastic gap) and the pulled end moved by ``load.pull`` in ``load.steps``;
  ``summary``: ``ratio`` (T2/T1 at the last step), ``exact`` (exp(mu theta)),
  ``relative_error``, ``path`` per step (``pull`` mm, ``T2`` N, ``ratio``, ``stick`` /
  ``slip`` points, ``newton`` residuals), ``elements``, ``dofs``, ``wall_time_s``;
* ``run(cfg, out_dir)``: the summary (and ``capstan_path.json``).

Set-up: the *cylinder* is fibril 1, one straight element along e3 through the origin with
every dof held, radius R_c; the *fibril* (fibril 0, the + side of every pair, so its points
are material and slide over the cylinder's axis) is naturally straight and starts bent in
the e1-e2 plane: a straight tail, an arc of angle theta about e3 at radius R_c + R_f - g (g
the overlap T1 / (R P*) expected under T1), a straight tail, meshed at one element size. The end of the first tail carries
the dead load T1 along the tail (its e3 position held: a plane problem); the end of the
second is held (all 9 dofs) and pulled along its tail. The support force there, along
the tail, is T2. The map is rebuilt every ``load.rebuild_every`` steps (the history
carried by point key).
"""
from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

import numpy as np

from ..fem.assembly import DofLayout
from ..fem.mesh import Fibril, fibril_mesh, orthonormal_directors, straight_fibril
from ..model import BeamMaterial, BeamModel, DirichletBC
from ..model.contact_model import ContactSystem
from ..model.terms.contact import ContactParams
from .frictional import DeadLoad, friction_law, initial_state, reaction, step
from .protocol import SceneFailure, SceneResult

__all__ = ["setup", "solve", "run", "wrapped_fibril"]

log = logging.getLogger("rve.scenes.capstan")


def wrapped_fibril(theta: float, radius_path: float, tail: float, fibril_radius: float) -> Fibril:
    """Tail, arc of ``theta`` at ``radius_path`` about e3 (symmetric about e2), tail."""
    phiA = 0.5 * math.pi - 0.5 * theta
    arc = radius_path * theta

    def frame(s):
        s = np.asarray(s, float)
        phi = phiA + np.clip(s - tail, 0.0, arc) / radius_path
        t = np.stack([-np.sin(phi), np.cos(phi), np.zeros_like(s)], 1)
        on = radius_path * np.stack([np.cos(phi), np.sin(phi), np.zeros_like(s)], 1)
        off = np.where(s < tail, s - tail, np.where(s > tail + arc, s - tail - arc, 0.0))
        r0 = on + off[:, None] * t
        g1, g2 = orthonormal_directors(t)
        return r0, g1, g2

    return Fibril(length=2 * tail + arc, radius=fibril_radius, frame=frame, name="wrapped")


def setup(cfg):
    g = cfg.geometry
    Rc, Rf, theta = g.cylinder_radius, g.fibril_radius, g.wrap_angle
    Rpath = Rc + Rf
    overlap = cfg.load.tension / (Rpath * cfg.contact.penalty)
    Rpath -= overlap
    fib = wrapped_fibril(theta, Rpath, g.tail_length, Rf)
    h = Rpath / cfg.mesh.elements_per_radian
    n_el = int(math.ceil(fib.length / h))
    cyl = straight_fibril([0.0, 0.0, -Rc], [0.0, 0.0, Rc], Rc, "cylinder")
    # the fibril is naturally straight (a rope bent over the capstan): sliding around the wrap
    # then changes no stored energy, as in the capstan's derivation
    straight = straight_fibril([0.0, 0.0, 0.0], [fib.length, 0.0, 0.0], Rf, "wrapped")
    mesh = fibril_mesh([straight, cyl], [n_el, 1], cfg.mesh.order)
    a, b = mesh.end_nodes(0)
    lay = DofLayout(mesh.n_nodes, ("mech",))
    rest = [lay.dofs("mech", [b]), lay.dofs("mech", mesh.fibril_nodes(1))]
    bcs_pull = [DirichletBC(np.concatenate([lay.dofs("r", [a], comp=2)] + rest), 0.0)]
    bcs_pretension = [DirichletBC(np.concatenate([lay.dofs("r", [a])] + rest), 0.0)]
    E = cfg.material.youngs_modulus
    model = BeamModel(mesh, BeamMaterial(youngs_modulus=E), bcs=bcs_pull)
    params = ContactParams(penalty=cfg.contact.penalty, n_gp=cfg.contact.n_gp, geometry=cfg.contact.geometry,
                           margin=0.5 * Rc, friction=friction_law(cfg.friction))
    x0 = _wrapped_state(mesh, lay, fib)
    system = ContactSystem(model, params, x0)
    r = lay.as_nodal(x0)[:, :3]
    tA = r[a] - r[a + 1]
    tA /= np.linalg.norm(tA)
    tB = r[b] - r[b - 1]
    tB /= np.linalg.norm(tB)
    load = np.zeros(lay.n)
    parts = {"A": lay.dofs("r", [a]), "B": lay.dofs("r", [b]), "tA": tA, "tB": tB, "load": load,
             "x0": x0, "elements": n_el, "overlap": overlap, "bcs_pull": bcs_pull, "bcs_pretension": bcs_pretension,
             "stretch": cfg.load.tension * fib.length / (E * math.pi * Rf ** 2)}
    return DeadLoad(system, load), parts


def _wrapped_state(mesh, layout, fib):
    """x of the wrapped fibril (its straight reference bent onto ``fib``), the cylinder as meshed."""
    x = initial_state(mesh, layout)
    nodes = mesh.fibril_nodes(0)
    r0, g1, g2 = fib.frame(mesh.node_s[nodes])
    layout.as_nodal(x)[nodes, :9] = np.hstack([r0, g1, g2])
    return x


def _ratio(system, x, parts, T1):
    T2 = float(reaction(system, x, parts["B"]) @ parts["tB"])
    return T2, T2 / T1


def _pretension(system, x, parts, cfg):
    """Frictionless pretension: the free end pulled along its tail (held there, a stiff
    problem from the stress-free wrap, whose free tail is laterally soft), by the stretch
    T1 L / (E A) in ``pretension_steps``; then that end released under the dead load T1."""
    base = system.system.base
    base.bcs = parts["bcs_pretension"]
    A = parts["A"]
    xA0 = x[A].copy()
    nP = cfg.load.pretension_steps
    for k in range(1, nP + 1):
        x[A] = xA0 + parts["stretch"] * k / nP * parts["tA"]
        x, _, _ = step(system, x, 0.0, cfg.newton, "capstan", "pretension", k)
    base.bcs = parts["bcs_pull"]
    parts["load"][A] = cfg.load.tension * parts["tA"]
    x, _, _ = step(system, x, 0.0, cfg.newton, "capstan", "pretension", nP + 1)
    return x


def solve(cfg) -> SceneResult:
    t0 = time.perf_counter()
    system, parts = setup(cfg)
    fr = system.term.friction
    mu, T1 = float(cfg.friction.coefficient), float(cfg.load.tension)
    x = parts["x0"].copy()
    if fr is not None:
        fr.set_coefficient(0.0)
    x = _pretension(system, x, parts, cfg)
    if fr is not None:
        fr.commit(x)              # the frictionless state: every point without elastic gap
        fr.set_coefficient(mu)
    xB0 = x[parts["B"]].copy()
    path = []
    for k in range(1, cfg.load.steps + 1):
        if k > 1 and (k - 1) % cfg.load.rebuild_every == 0:
            system.rebuild(x)
        pull = cfg.load.pull * k / cfg.load.steps
        x[parts["B"]] = xB0 + pull * parts["tB"]
        x, res, _ = step(system, x, 0.0, cfg.newton, "capstan", "pull", k)
        T2, ratio = _ratio(system, x, parts, T1)
        pts = fr.points() if fr is not None else {"stick": 0, "slip": 0}
        path.append({"pull": pull, "T2": T2, "ratio": ratio, "stick": pts["stick"], "slip": pts["slip"],
                     "newton": [float(r) for r in res.residuals]})
    if not path:
        raise SceneFailure("capstan", "no pull step", phase="pull")
    exact = math.exp(mu * cfg.geometry.wrap_angle)
    ratio = path[-1]["ratio"]
    summary = {"ratio": ratio, "exact": exact, "relative_error": ratio / exact - 1.0, "path": path,
               "elements": parts["elements"], "dofs": int(system.n), "overlap": parts["overlap"],
               "wall_time_s": time.perf_counter() - t0}
    return SceneResult(state={"x": x}, model=system, summary=summary)


def run(cfg, out_dir: Path) -> dict:
    try:
        summary = solve(cfg).summary
    except SceneFailure as failure:
        if failure.state is not None:
            failure.save(Path(out_dir) / "capstan_last_good_state.npz")
        log.error("%s", failure)
        raise
    (Path(out_dir) / "capstan_path.json").write_text(json.dumps(summary["path"], indent=1))
    return summary
