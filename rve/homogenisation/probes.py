"""Decoupled probe solves on a stored RVE state (thesis Algorithm 7.1 step 2c, §7.3).

Mechanics frozen (every mechanical dof constrained at the stored state), for each probe:

1. **voltage solve**: fields ("mech", "V") of ``BeamModel`` with the fibril conductivity
   sigma, plus the contact conductance ``sigma_C a(g)`` of ``ContactSystem`` through the
   Hertz width a(g) of the frozen contact state; V = U (the test voltage) on every node
   of the '+' terminal, V = 0 on the '-' terminal (Dirichlet); every other fibril end is
   insulated (natural condition), and the fibrils with no terminal node get the
   **weakened insulation** of thesis §8.2 (``rve.model.insulation.pull_down_circuits``:
   a pull-down resistor ``R_ext = insulation_factor x`` the fibril's own resistance to
   0 V), which keeps a fibril that touches nothing well defined.
2. **terminal currents**: the current into the fabric through a terminal is the reaction
   of its Dirichlet rows, the sum over its nodes of the V residual (conduction and contact
   terms). A probe whose terminals are not connected (only the pull-downs carry a
   round-off current, < 1e3 x their conductance) gets currents 0 (resistance inf,
   ``connected`` False). ``I(+) + I(-) = -I_leak`` exactly (charge conservation; ``I_leak`` the current
   into the fabric through the pull-downs, ~1/insulation_factor of the probe current),
   up to the solver tolerance.
3. **Joule-heating temperature solve**: fields ("mech", "T", "V") with V prescribed
   everywhere (the solution of 1), the Joule source sigma0 |e|^2 in the fibrils, contact
   heat transfer ``h_C a(g)``, T = 0 (the boundary temperature) at every fibril end.
   Recorded: the maximum and the mean (over the fibril length) temperature rise.

With ``contact.enforcement: augmented_lagrangian`` every probe system carries the stored
state's contact multipliers (``multipliers``: the record of ``multipliers.multiplier_record``,
seeded by point key), so the contact width and conductance come from the line load
``lambda + P* g`` of the impenetrable limit, not from the penalty overlap (which the
multipliers drive to zero). With the penalty (``multipliers`` None) nothing is seeded.

Both problems are linear; they go through ``rve.solvers.static.static_solve`` (Newton
converges in one iteration). Charge conservation is checked and reported
(``conservation_error`` = |I(+) + I(-) + I_leak| / |I(+)|).

Low-level API (used by tests on simple networks): ``electric_solve`` and
``temperature_solve`` take a mesh, a nodal state and Dirichlet node sets.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..model.insulation import pull_down_circuits
from ..model import ContactParams, ContactSystem
from ..fabrics.setup import contact_params, end_nodes
from ..fem.assembly import DofLayout
from ..model import BeamMaterial, BeamModel, Couplings, DirichletBC
from ..solvers.static import static_solve
from .multipliers import seed_multipliers
from .probe_result import ProbeResult, _length_weights, conduction_material

__all__ = ["ProbeResult", "ElectricSolution", "terminal_nodes", "electric_solve", "temperature_solve",
           "solve_probe", "solve_probes", "conduction_material"]

log = logging.getLogger("rve.homogenisation.probes")

_NO_COUPLING = dict(lorentz=False, back_emf=False, seebeck=False, thermal_softening=False)


@dataclass
class ElectricSolution:
    V: np.ndarray                         # nodal potential (V)
    currents: list                        # current into the fabric through each Dirichlet group (A)
    leak: float                           # current into the fabric through the pull-downs (A)
    newton_iterations: int
    residual: float
    pull_downs: int
    system: object = field(default=None, repr=False)
    x: Optional[np.ndarray] = field(default=None, repr=False)
    w: Optional[np.ndarray] = field(default=None, repr=False)


def terminal_nodes(fab, mesh, terminal) -> np.ndarray:
    """Nodes of a probe terminal: every fibril end of the yarn (direction, position) on
    the box side ``end``. ``terminal``: a ``ProbeTerminal`` or a dict with yarn, position, end."""
    get = (lambda k: terminal[k]) if isinstance(terminal, dict) else (lambda k: getattr(terminal, k))
    yarn = fab.yarn_at(get("yarn"), float(get("position")), tol=1e-6)
    nodes = fab.end_nodes(mesh, side=get("end"), yarn=yarn.index)
    if nodes.size == 0:
        raise ValueError(f"probe terminal {get('yarn')} yarn at {get('position')} has no fibril end on side "
                         f"{get('end')}")
    return nodes


def _full_state(model, xn, V=None):
    """Flat (x, w) of ``model``'s layout from nodal mechanics (n_nodes, 9) (+ V)."""
    x = np.zeros(model.n)
    w = np.zeros(model.n)
    model.nodal(x)[:, :9] = xn
    if V is not None:
        model.nodal(w)[:, model.oV] = V
    return x, w


def _frozen_solve(base, contact: Optional[ContactParams], x, w, what: str, newton_opts: Optional[dict],
                  multipliers=None):
    """The linear probe problem on the frozen state (mechanics constrained): the model with
    the contact terms of ``contact`` (None: none) and the state's contact ``multipliers``
    (a record, or None), one tight Newton solve. Returns ``(system, x, w, NewtonResult)``;
    raises RuntimeError naming ``what`` if it fails."""
    system = ContactSystem(base, contact, x) if contact is not None else base
    seed_multipliers(system, multipliers)
    opts = {"atol": 1e-12, "rtol": 1e-12, "max_iter": 5, "label": f"probe {what}"}
    opts.update(newton_opts or {})
    xs, ws, res = static_solve(system, x, w, 0.0, opts)
    if not res.converged:
        raise RuntimeError(f"probe {what} solve did not converge: {res.reason}")
    return system, xs, ws, res


def electric_solve(mesh, xn, material: BeamMaterial, contact: Optional[ContactParams], groups, values,
                   insulation_factor: float = 1e12, insulation_ends: str = "both", disk_points: int = 4,
                   axial_points=None, newton_opts: Optional[dict] = None, multipliers=None) -> ElectricSolution:
    """Potential on the frozen state ``xn`` (n_nodes, 9) with V = ``values[k]`` on the
    nodes ``groups[k]`` (Dirichlet) and weakened insulation on every fibril with no
    Dirichlet node. ``contact``: contact law (its ``conductance`` couples V) or None;
    ``multipliers``: the state's contact multipliers (augmented Lagrangian) or None.
    Returns the nodal V, the current into the fabric through every group, the pull-down
    leak and solver figures."""
    groups = [np.asarray(g, dtype=np.int64) for g in groups]
    wired = np.concatenate(groups) if groups else np.zeros(0, np.int64)
    circuits = pull_down_circuits(mesh, material.electrical_conductivity, wired, factor=insulation_factor,
                                  ends=insulation_ends)
    lay = DofLayout(mesh.n_nodes, ("mech", "V"))
    bcs = [DirichletBC(lay.dofs("mech"), 0.0)]
    for g, v in zip(groups, values):
        bcs.append(DirichletBC(lay.dofs("V", g), float(v)))
    base = BeamModel(mesh, material, fields=("mech", "V"), couplings=Couplings(joule=False, **_NO_COUPLING),
                     disk_points=disk_points, axial_points=axial_points, bcs=bcs, circuits=circuits)
    x, w = _full_state(base, xn)
    system, xs, ws, res = _frozen_solve(base, contact, x, w, "voltage", newton_opts, multipliers)
    F, _, _ = system.evaluate(xs, ws, 0.0, jacobian=False)
    FV = base.nodal(F)[:, base.oV]
    currents = [float(FV[g].sum()) for g in groups]
    V = base.nodal(ws)[:, base.oV].copy()
    leak = 0.0
    for c in circuits:  # current leaving through the pull-down: area (r_bar V + J_bar)
        leak -= c.area * (c.r_bar * V[c.node] + c.J_bar)
    return ElectricSolution(V, currents, float(leak), int(res.iterations), float(res.residuals[-1]), len(circuits),
                            system, xs, ws)


def temperature_solve(mesh, xn, V, material: BeamMaterial, contact: Optional[ContactParams], fixed_nodes,
                      disk_points: int = 4, axial_points=None, newton_opts: Optional[dict] = None,
                      multipliers=None):
    """Joule-heating temperature rise on the frozen state with the potential ``V``
    (nodal, prescribed everywhere) and T = 0 at ``fixed_nodes`` (``multipliers`` as
    ``electric_solve``). Returns (T nodal, Newton result)."""
    lay = DofLayout(mesh.n_nodes, ("mech", "T", "V"))
    fixed = np.asarray(fixed_nodes, dtype=np.int64)
    bcs = [DirichletBC(lay.dofs("mech"), 0.0), DirichletBC(lay.dofs("V"), np.asarray(V, float)),
           DirichletBC(lay.dofs("T", fixed), 0.0)]
    base = BeamModel(mesh, material, fields=("mech", "T", "V"), couplings=Couplings(joule=True, **_NO_COUPLING),
                     disk_points=disk_points, axial_points=axial_points, bcs=bcs)
    x, w = _full_state(base, xn, V)
    _, _, ws, res = _frozen_solve(base, contact, x, w, "temperature", newton_opts, multipliers)
    return base.nodal(ws)[:, base.oT].copy(), res


def solve_probe(cfg, fab, mesh, xn, probe, with_fields: bool = False, multipliers=None) -> ProbeResult:
    """One probe (``ProbeSpec``) on the frozen state ``xn`` with its contact ``multipliers``
    (module docstring)."""
    ps = cfg.probe_solver
    t0 = time.perf_counter()
    plus, minus = (terminal_nodes(fab, mesh, t) for t in probe.terminals)
    if np.intersect1d(plus, minus).size:
        raise ValueError(f"probe {probe.name}: its terminals share fibril ends")
    mat = conduction_material(cfg)
    cparams = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=True)
    opts = {"atol": ps.newton_atol, "rtol": ps.newton_rtol}
    el = electric_solve(mesh, xn, mat, cparams, [plus, minus], [ps.voltage, 0.0], ps.insulation_factor,
                        ps.insulation_ends, cfg.mesh.disk_points, cfg.mesh.axial_points, opts, multipliers)
    ip, im = el.currents
    cons = abs(ip + im + el.leak) / max(abs(ip), 1e-300)
    # no conducting path between the terminals: only the pull-downs carry (round-off) current
    lengths = np.bincount(mesh.elem_fibril, weights=mesh.elem_length, minlength=mesh.n_fibrils)
    g_leak = 1.0 / (ps.insulation_factor * float(np.min(lengths / (mat.electrical_conductivity * np.pi
                                                                   * mesh.radius ** 2))))
    connected = abs(ip) > 1e3 * ps.voltage * g_leak * mesh.n_fibrils
    if not connected:
        log.warning("probe %s: no conducting path between the terminals (I+ = %.3e A); currents set to 0",
                    probe.name, ip)
        ip = im = 0.0
        cons = 0.0
    res = ProbeResult(probe.name, float(ps.voltage), ip, im, el.leak, float(cons),
                      newton_iterations={"V": el.newton_iterations}, wall_s={"V": time.perf_counter() - t0},
                      connected=bool(connected))
    if with_fields:
        res.V = el.V
    if ps.temperature:
        t1 = time.perf_counter()
        ends = end_nodes(fab, mesh)
        T, tres = temperature_solve(mesh, xn, el.V, mat, cparams, ends, cfg.mesh.disk_points, cfg.mesh.axial_points,
                                    opts, multipliers)
        wts = _length_weights(mesh)
        res.temperature_max = float(T.max())
        res.temperature_mean = float((wts * T).sum() / wts.sum())
        res.newton_iterations["T"] = int(tres.iterations)
        res.wall_s["T"] = time.perf_counter() - t1
        if with_fields:
            res.T = T
    log.info("probe %s: I+ = %.6e A, I- = %.6e A, leak = %.3e A, R = %.6g ohm, conservation %.2e, Tmax = %.4g K",
             probe.name, ip, im, el.leak, res.resistance, cons, res.temperature_max)
    return res


def solve_probes(cfg, fab, mesh, xn, with_fields: bool = False, multipliers=None) -> dict:
    """All probes of ``cfg.probes`` on the frozen state ``xn`` with the state's contact
    ``multipliers`` (``State.multipliers``; None for the penalty): {name: ProbeResult} (a
    periodic cell's field probes: ``rve.homogenisation.periodic_probes``)."""
    if getattr(cfg, "boundary", "pinned") == "periodic":
        from .periodic_probes import solve_field_probe

        return {p.name: solve_field_probe(cfg, fab, mesh, xn, p, with_fields, multipliers) for p in cfg.probes}
    return {p.name: solve_probe(cfg, fab, mesh, xn, p, with_fields, multipliers) for p in cfg.probes}
