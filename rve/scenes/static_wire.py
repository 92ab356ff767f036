"""Scene: the current-carrying wire in a magnetic field, solved statically (thesis §6.3).

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
* ``setup(cfg, order=None, elements=None, gauge_end=0) -> BeamModel``: the wire of a
  validated ``StaticWireConfig`` (rve.config.static_wire) on the configured mesh (or on
  (order, elements)), with its boundary conditions;
* ``solve(cfg) -> SceneResult``: relax (optionally on a coarse mesh), then static Newton
  on the target mesh; ``state["x"]`` is the equilibrium, ``model`` the ``BeamModel``,
  ``summary``: ``centre_displacement`` (the midpoint's distance from the support line, in
  units of L), ``analytical_centre_displacement`` (chapter 3 helix, same units),
  ``newton_iterations`` (static phase), ``relaxation_steps``, ``dofs``, ``wall_time_s`` per
  phase and in total, and the Newton residual history of the static phase. A phase that
  does not converge raises ``SceneFailure`` (phase named, the state it started from);
* ``run(cfg, out_dir) -> dict``: the summary (``rve run`` writes summary.json); on a
  failure the last good state goes to ``out_dir/static_wire_last_good_state.npz``.

Set-up (docs/static_solution_path.md, thesis §6.3): the wire lies along e1 from -L to L (straight natural
configuration, directors G1 = e2, G2 = e3); B = |B| (cos phi, 0, sin phi); a current
I = J pi R^2 flows along +e1; the centroid ends are pinned and moved from +-L e1 to
+-Delta e1. Solution path ``dynamic_relaxation``: backward-Euler dynamics with damping
-gamma v from the straight wire (tiny cosine z-offset, uniform compression velocity as the
thesis), ends moving at constant speed for ``duration``, then static Newton from the relaxed
state with velocities zeroed. Path ``continuation``: pseudo-transient continuation
(K + sigma M) from the same start with the ends already at +-Delta. A twist gauge fixes
the z component of g1 at the first node (the uniform rotation of circular sections about
the centroid is a zero-energy mode; docs/static_solution_path.md).
"""
from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from ..analytic.helix import static_wire_reference
from ..fem.assembly import DofLayout
from ..fem.lagrange import lagrange_basis
from ..fem.mesh import fibril_mesh, straight_fibril
from ..fem.transfer import interpolate_nodal
from ..model import BeamMaterial, BeamModel, DirichletBC, PrescribedCurrent
from ..solvers.dirk import integrate
from ..solvers.static import static_solve
from .protocol import SceneFailure, SceneResult

__all__ = ["setup", "solve", "run", "centre_displacement", "initial_state", "clamp_ends", "newton_options"]

log = logging.getLogger("rve.scenes.static_wire")


def setup(cfg, order: int | None = None, elements: int | None = None, gauge_end: int = 0) -> BeamModel:
    """The wire model on the configured mesh, or on (order, elements) if given.

    ``gauge_end`` picks the end (0 or 1) whose g1_z component carries the twist gauge."""
    L = cfg.geometry.half_length
    delta = cfg.geometry.clamp_half_distance
    R = cfg.fibril.radius
    order = cfg.mesh.order if order is None else order
    elements = cfg.mesh.elements if elements is None else elements
    mesh = fibril_mesh([straight_fibril([-L, 0, 0], [L, 0, 0], R, "wire")], elements, order)
    phi = cfg.load.field_angle
    B = cfg.load.field_magnitude * np.array([np.cos(phi), 0.0, np.sin(phi)])
    current = cfg.load.current_density * np.pi * R**2
    mat = BeamMaterial(
        youngs_modulus=cfg.material.youngs_modulus,
        poisson_ratio=cfg.material.poisson_ratio,
        density=cfg.material.density,
        damping=cfg.solver.relaxation.damping,
    )
    n0, n1 = mesh.end_nodes(0)
    T = cfg.solver.relaxation.duration
    speed = (L - delta) / T

    def end_velocity(sign):
        # left end (sign=-1) moves toward +e1, right end toward -e1, over (0, T]. A step
        # ending at T uses the velocity at its end (backward Euler), so T itself is inside.
        return lambda t: np.array([-sign * speed if t <= T * (1 + 1e-12) else 0.0, 0.0, 0.0])

    layout = DofLayout(mesh.n_nodes, ("mech",))
    bcs_dyn = [
        DirichletBC(layout.dofs("r", n0), end_velocity(-1)),
        DirichletBC(layout.dofs("r", n1), end_velocity(+1)),
        DirichletBC(layout.dofs("g1", (n0, n1)[gauge_end], comp=2), 0.0),  # twist gauge: g1_z at one end
    ]
    model = BeamModel(
        mesh, mat,
        disk_points=cfg.mesh.disk_points,
        axial_points=cfg.mesh.axial_points,
        bcs=bcs_dyn,
        prescribed_current=PrescribedCurrent(np.array([current]), B),
    )
    return model


def initial_state(model, cfg, ends_at_clamps: bool = False):
    L = cfg.geometry.half_length
    delta = cfg.geometry.clamp_half_distance
    X0 = model.mesh.X0
    x = np.zeros(model.n)
    w = np.zeros(model.n)
    xn = model.nodal(x)
    xn[:, :9] = X0
    s = X0[:, 0] / L  # -1..1
    xn[:, 2] += cfg.solver.relaxation.perturbation * L * np.cos(0.5 * np.pi * s)
    if ends_at_clamps:
        xn[:, 0] *= delta / L
    else:
        T = cfg.solver.relaxation.duration
        model.nodal(w)[:, 0] = -(L - delta) / T * s  # thesis: vq = -(L - Delta)/T X1 e1
    return x, w


def clamp_ends(model, x, cfg):
    """Put the pinned centroids exactly at +-Delta e1 (removes time-integration round-off)."""
    delta = cfg.geometry.clamp_half_distance
    n0, n1 = model.mesh.end_nodes(0)
    xn = model.nodal(x)
    xn[n0, 0:3] = [-delta, 0.0, 0.0]
    xn[n1, 0:3] = [delta, 0.0, 0.0]
    return x


def centre_displacement(model, x, L) -> float:
    """Distance of the centroid at the wire's midpoint from the support line (units of L)."""
    mesh = model.mesh
    p = mesh.order
    # find the element containing s = L (the midpoint of [0, 2L]) and interpolate there
    s_mid = 0.5 * mesh.elem_length.sum()
    e = min(int(s_mid // mesh.elem_length[0]), mesh.n_elements - 1)
    s0 = mesh.node_s[mesh.conn[e, 0]]
    t = 2.0 * (s_mid - s0) / mesh.elem_length[e] - 1.0
    N, _ = lagrange_basis(p, np.array([t]))
    r = N[0] @ model.nodal(x)[mesh.conn[e], 0:3]
    return float(np.hypot(r[1], r[2]) / L)


def newton_options(cfg, model):
    # residuals are forces: scale the absolute tolerance with the axial stiffness E A
    EA = cfg.material.youngs_modulus * np.pi * cfg.fibril.radius**2
    return {
        "atol": cfg.solver.newton.atol * EA,
        "rtol": cfg.solver.newton.rtol,
        "max_iter": cfg.solver.newton.max_iter,
        # |r| mixes forces (centroid rows) and moments (director rows): a backtracking line
        # search on it stalls near the solution of thin wires, while full Newton steps from
        # the relaxed state converge quadratically; det F > 0 is still enforced by halving.
        "line_search": False,
    }


# The relaxation transient only has to lead to the right equilibrium: its stages need not be
# converged to round-off (the static Newton that follows is). Measured on p=2/N=8: cuts the
# relaxation's Newton iterations by about half with the same final state.
RELAXATION_NEWTON = {"rtol": 1e-6, "max_iter": 25}


def _relax(model, cfg, nopts):
    """Phase 1 on ``model``: reach the neighbourhood of the equilibrium from the straight wire."""
    T = cfg.solver.relaxation.duration
    if cfg.solver.path == "dynamic_relaxation":
        x, w = initial_state(model, cfg)
        res = integrate(model, x, w, 0.0, T, cfg.solver.relaxation.steps, stages=1,
                        newton_opts={**nopts, **RELAXATION_NEWTON}, consistent=False)
        return clamp_ends(model, res.x, cfg), res.steps, res.newton_iterations
    if cfg.solver.path == "continuation":
        from ..solvers.static import pseudo_transient_solve

        x, w = initial_state(model, cfg, ends_at_clamps=True)
        x, w, pres = pseudo_transient_solve(model, x, np.zeros_like(w), T, atol=nopts["atol"], rtol=nopts["rtol"])
        if not pres.converged:
            raise SceneFailure("static_wire", f"pseudo-transient continuation failed: {pres.reason}",
                               phase="continuation", state={"x": x}, model=model)
        return x, pres.iterations, pres.iterations
    raise ValueError(f"solver.path = {cfg.solver.path!r}: must be 'dynamic_relaxation' or 'continuation'")


def _static(model, x, T, nopts, what):
    x_start = x
    x, w, nres = static_solve(model, x, np.zeros_like(x), T, nopts)
    if not nres.converged:
        raise SceneFailure(
            "static_wire",
            f"static Newton on the {what} did not converge after {nres.iterations} iterations: {nres.reason}; "
            f"residuals {[f'{r:.3e}' for r in nres.residuals]}",
            phase=f"static Newton ({what})", step=f"Newton iteration {nres.iterations}",
            state={"x": x_start}, model=model, details={"residuals": [float(r) for r in nres.residuals]})
    return x, nres


def solve(cfg) -> SceneResult:
    """Relax (optionally on a coarse mesh), then static Newton on the target mesh."""
    t_start = time.perf_counter()
    timings = {}
    model = setup(cfg)
    L = cfg.geometry.half_length
    T = cfg.solver.relaxation.duration
    nopts = newton_options(cfg, model)
    rx = cfg.solver.relaxation
    coarse = rx.coarse_order is not None and rx.coarse_elements is not None and (
        (rx.coarse_order, rx.coarse_elements) != (cfg.mesh.order, cfg.mesh.elements))
    relax_model = setup(cfg, rx.coarse_order, rx.coarse_elements) if coarse else model
    timings["setup"] = time.perf_counter() - t_start
    t1 = time.perf_counter()
    x, relax_steps, relax_newton = _relax(relax_model, cfg, nopts)
    coarse_newton = 0
    settle_its = 0
    if coarse:
        # converge on the coarse mesh, then carry the equilibrium to the target mesh
        x, cres = _static(relax_model, x, T, nopts, "coarse relaxation mesh")
        coarse_newton = cres.iterations
        xt = np.zeros(model.n)
        model.nodal(xt)[:, :9] = interpolate_nodal(relax_model.mesh, relax_model.nodal(x)[:, :9], model.mesh)
        x = clamp_ends(model, xt, cfg)
        # The twist of the sections is a very soft mode (torsional stiffness ~ R^4): the
        # prolonged state's twist is off by more than Newton's basin on thin wires, so a
        # few mass-regularised (pseudo-transient) steps settle it on the target mesh first.
        from ..solvers.static import pseudo_transient_solve

        x, _, pres = pseudo_transient_solve(model, x, np.zeros_like(x), T, atol=nopts["atol"], rtol=1e-3)
        settle_its = pres.iterations
    timings["relaxation"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    x, nres = _static(model, x, T, nopts, "target mesh")
    timings["static"] = time.perf_counter() - t2
    timings["total"] = time.perf_counter() - t_start
    ref = static_wire_reference(
        cfg.load.current_density * cfg.load.field_magnitude / cfg.material.youngs_modulus,
        cfg.geometry.clamp_half_distance / L, cfg.load.field_angle)
    n_fixed = len(model.constraints(0.0)[0])
    summary = {
        "centre_displacement": centre_displacement(model, x, L),
        "analytical_centre_displacement": float(ref.centre_displacement),
        "newton_iterations": int(nres.iterations),
        "newton_residuals": [float(r) for r in nres.residuals],
        "newton_rates": [float(r) for r in nres.rates],
        "relaxation_steps": int(relax_steps),
        "relaxation_newton_iterations": int(relax_newton),
        "coarse_static_newton_iterations": int(coarse_newton),
        "settle_iterations": int(settle_its),
        "relaxation_mesh": {"order": int(relax_model.mesh.order), "elements": int(relax_model.mesh.n_elements)},
        "dofs": int(model.n),
        "free_dofs": int(model.n - n_fixed),
        "fields": list(model.layout.fields),
        "order": int(cfg.mesh.order),
        "elements": int(cfg.mesh.elements),
        "radius": float(cfg.fibril.radius),
        "min_det_F": model.basis.min_det_F(model.nodal(x)),
        "wall_time_s": {k: float(v) for k, v in timings.items()},
    }
    return SceneResult(state={"x": x}, model=model, summary=summary)


def run(cfg, out_dir: Path) -> dict:
    try:
        return solve(cfg).summary
    except SceneFailure as failure:
        if failure.state is not None:
            failure.save(Path(out_dir) / "static_wire_last_good_state.npz")
        log.error("%s", failure)
        raise
