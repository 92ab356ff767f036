"""Field probes of a periodic cell (docs/periodic.md "Probes").

On a stored full state (mechanics frozen), a probe with ``field: x`` (or ``y``) applies
the macro field ``E = U / L_x e_x`` (U the test voltage ``probe_solver.voltage``, L_x the
period along x, per unit reference length) as the potential jump of the ties,
``V(end) = V(start) - E . dX`` (``rve.model.periodic``), with V = 0 at one node as the
reference. Out:

* the current per unit reference width through the cell face normal to the field,
  ``j = I_face / L_y`` (A/mm; ``I_face`` the current leaving through that face: its ties
  and, with ``cell.contact_images``, the contacts with the periodic images across it,
  ``PeriodicSystem.macro_current``; an image's potential is lower by E . dX over the
  lattice vector), recorded as the current through a **square** of the fabric with U across it,
  ``I = j L_x`` (``current`` +I / -I), so the record's resistance ``U / I = E / j`` is
  the sheet resistance (ohm per square): independent of the cell size;
* the transverse current per width (``current_transverse``, the face along the field);
* the Joule temperature: T periodic (no jump), the Joule power of the fibrils removed by a
  uniform sink per unit fibril length (the macro heat balance: what the cell makes, its
  surroundings take; one sink per conduction component, fibrils joined by active
  contacts), T = 0 at one node of each component, then the cell's length-weighted mean
  subtracted.
  Recorded: ``temperature_max`` = hottest point above the cell mean (the micro hot spot of
  a uniformly heated fabric), ``temperature_mean`` = 0 (the reference), and the Joule
  power per unit area ``joule_power_per_area`` = j . E (W/mm^2).

With ``contact.enforcement: augmented_lagrangian`` the frozen systems carry the stored
state's contact multipliers (seeded by point key after every map build), so the contact
conductances come from the line load ``lambda + P* g``, not from the penalty overlap.

Charge conservation: the residual left at the V reference node (the net current the
ties fail to carry; one reference per conduction component, so a fibril that touches
nothing keeps a defined potential) over I_face, ``conservation_error``.
"""
from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np

from ..fabrics.setup import contact_params
from ..model import BeamModel, ContactSystem, Couplings
from ..model.periodic import PeriodicSystem
from ..solvers.static import static_solve
from .multipliers import seed_multipliers
from .periodic import cell_gradient, cell_ties
from .periodic_resistances import cell_resistances
from .probe_result import ProbeResult, _length_weights, conduction_material

__all__ = ["field_solve", "solve_field_probe"]

_NO_COUPLING = dict(lorentz=False, back_emf=False, seebeck=False, thermal_softening=False)


def _frozen(mesh, material, fields, joule, cparams, xn, disk_points, axial_points, multipliers=None):
    base = BeamModel(mesh, material, fields=fields, couplings=Couplings(joule=joule, **_NO_COUPLING),
                     disk_points=disk_points, axial_points=axial_points)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = xn
    system = ContactSystem(base, cparams, x) if cparams is not None else base
    seed_multipliers(system, multipliers)
    return system, x


def _components(full, mesh, x) -> np.ndarray:
    """Connected component of every fibril in the conduction graph (fibrils joined by an
    active contact pair): each component gets its own potential and temperature reference
    (a fibril that touches nothing floats, its level is otherwise undefined)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nf = mesh.n_fibrils
    a = b = np.zeros(0, np.int64)
    if hasattr(full, "active_pairs"):
        act = full.active_pairs(x)
        a, b = mesh.elem_fibril[full.map.e_plus[act]], mesh.elem_fibril[full.map.e_minus[act]]
    graph = coo_matrix((np.ones(a.size), (a, b)), shape=(nf, nf))
    return connected_components(graph, directed=False)[1]


def _reference_nodes(ties, mesh, comp) -> np.ndarray:
    """Reduced node of the first node of the first fibril of every component."""
    first_fibril = np.array([np.flatnonzero(comp == c)[0] for c in range(comp.max() + 1)])
    return np.searchsorted(ties.kept_nodes, mesh.node_offsets[first_fibril])


#: the conduction graph of a frozen state, for ``periodic_resistances``
CONDUCTION_GRAPH = SimpleNamespace(components=_components, references=_reference_nodes)


def _solve(psys, x_full, w_red, opts, what):
    xs, ws, res = static_solve(psys, psys.restrict(x_full), w_red, 0.0, dict({"max_iter": 5, "label": what}, **opts))
    if not res.converged:
        raise RuntimeError(f"periodic {what} solve did not converge: {res.reason}")
    return xs, ws, res


def _periodic(full, ties, x, held, values, F, E, contact_images, multipliers=None):
    """The reduced system of a frozen state; with ``contact_images`` the contact map sees
    the periodic images (their potential jumps by E over the lattice vector). The
    ``multipliers`` are seeded on the map it ends with."""
    psys = PeriodicSystem(full, ties, held, values, F=F, E=E, contact_images=contact_images)
    if psys.contact_images:
        psys.rebuild(psys.restrict(x))
    seed_multipliers(psys, multipliers)
    return psys


def field_solve(mesh, ties, xn, F, material, cparams, E, temperature=True, disk_points=4, axial_points=None,
                newton_opts=None, contact_images: bool = True, multipliers=None) -> dict:
    """Potential (and Joule temperature) of the frozen periodic state ``xn`` (n_nodes, 9) at
    macro gradient ``F`` under the macro field ``E`` (3,), V/mm per reference length.
    Returns ``{"V", "T" (nodal, full mesh), "tie_currents" (n_ties,), "macro_current" (3,)
    (A per mm of reference width: the ties' and the image contacts' currents), "conservation",
    "iterations", "joule_power"}``. ``multipliers``: the state's contact multipliers (a record)
    or None."""
    opts = {"atol": 1e-12, "rtol": 1e-12, **(newton_opts or {})}
    full, x = _frozen(mesh, material, ("mech", "V"), False, cparams, xn, disk_points, axial_points, multipliers)
    lay = _periodic(full, ties, x, (), 0.0, F, None, contact_images, multipliers).layout
    comp = _components(full, mesh, x)
    refs = _reference_nodes(ties, mesh, comp)
    held = np.concatenate([lay.dofs("mech"), lay.dofs("V", refs)])
    psys = _periodic(full, ties, x, held, 0.0, F, E, contact_images, multipliers)
    xs, ws, res = _solve(psys, x, np.zeros(psys.n), opts, "voltage")
    R_red = psys.evaluate(xs, ws, 0.0, jacobian=False)[0]
    out = {"tie_currents": psys.tie_currents(xs, ws), "macro_current": psys.macro_current(xs, ws),
           "iterations": {"V": int(res.iterations)},
           "reference_current": float(np.abs(R_red[lay.dofs("V", refs)]).sum()), "components": comp}
    w_full = psys.expand_rates(ws)
    out["V"] = full.nodal(w_full)[:, full.layout.offset["V"]].copy()
    out["T"] = None
    if temperature:
        out.update(_joule_temperature(mesh, ties, xn, F, material, cparams, E, ws, lay, comp, disk_points,
                                      axial_points, opts, contact_images, multipliers))
    return out


def _joule_temperature(mesh, ties, xn, F, material, cparams, E, V_ws, vlay, comp, disk_points, axial_points,
                       opts, contact_images, multipliers=None):
    """The periodic Joule temperature with the uniform sink of each conduction component
    (module docstring)."""

    full, x = _frozen(mesh, material, ("mech", "T", "V"), True, cparams, xn, disk_points, axial_points, multipliers)
    flay = full.layout
    lay = PeriodicSystem(full, ties, F=F).layout
    V_red = V_ws[vlay.dofs("V")]
    refs = _reference_nodes(ties, mesh, comp)
    held = np.concatenate([lay.dofs("mech"), lay.dofs("V"), lay.dofs("T", refs)])
    values = np.concatenate([np.zeros(lay.dofs("mech").size), V_red, np.zeros(refs.size)])
    psys = _periodic(full, ties, x, held, values, F, E, contact_images, multipliers)
    w0 = np.zeros(psys.n)
    w0[lay.dofs("V")] = V_red
    # the Joule heat the fibrils make (the T rows at T = 0), removed again by the sink
    R0 = psys.full_residual(psys.restrict(x), w0)
    wts = _length_weights(mesh)
    q = R0[flay.dofs("T")]
    node_comp = comp[mesh.node_fibril]
    per_comp = np.bincount(node_comp, weights=q) / np.bincount(node_comp, weights=wts)
    load = np.zeros(full.n)
    load[flay.dofs("T")] = -per_comp[node_comp] * wts
    psys.load = load
    xs, ws, res = _solve(psys, x, w0, opts, "temperature")
    T = full.nodal(psys.expand_rates(ws))[:, flay.offset["T"]].copy()
    T -= (wts * T).sum() / wts.sum()
    return {"T": T, "joule_power": float(-q.sum()), "iterations_T": int(res.iterations)}


def solve_field_probe(cfg, fab, mesh, xn, probe, with_fields: bool = False, multipliers=None):
    """One field probe (``ProbeSpec`` with ``field``) on the stored full state ``xn`` with its
    contact ``multipliers``: a ``probes.ProbeResult`` whose resistance is the sheet
    resistance (module docstring)."""

    ps = cfg.probe_solver
    t0 = time.perf_counter()
    ties = cell_ties(fab, mesh)
    axis = {"x": 0, "y": 1}[probe.field]
    L = 2.0 * np.asarray(fab.half_widths[:2], float)
    E = np.zeros(3)
    E[axis] = ps.voltage / L[axis]
    cparams = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=True)
    sol = field_solve(mesh, ties, xn, cell_gradient(fab, mesh, xn), conduction_material(cfg), cparams, E,
                      ps.temperature, cfg.mesh.disk_points, cfg.mesh.axial_points,
                      {"atol": ps.newton_atol, "rtol": ps.newton_rtol}, cfg.cell.contact_images, multipliers)
    j, j_side = (float(v) for v in sol["macro_current"][[axis, 1 - axis]])
    I_face = j * L[1 - axis]  # leaving through the + face (its ties and the contacts across it)
    I_sq = j * L[axis]
    res = ProbeResult(probe.name, float(ps.voltage), I_sq, -I_sq, 0.0,
                      abs(sol["reference_current"]) / max(abs(I_face), 1e-300),
                      newton_iterations=dict(sol["iterations"]), connected=bool(I_face != 0.0))
    area = float(L[0] * L[1])
    res.extra = {"field": probe.field, "field_V_per_mm": float(E[axis]), "current_per_width_A_per_mm": j,
                 "transverse_current_per_width_A_per_mm": j_side, "sheet_resistance_ohm": res.resistance}
    if sol["T"] is not None:
        res.extra["joule_power_per_area_W_per_mm2"] = sol["joule_power"] / area
    # the R_y of the yarn family along the field and the cell's R_c (docs/periodic.md)
    res.extra.update(cell_resistances(cfg, fab, mesh, xn, {"x": "warp", "y": "weft"}[probe.field], CONDUCTION_GRAPH,
                                       multipliers))
    if sol["T"] is not None:
        res.temperature_max = float(sol["T"].max())
        res.temperature_mean = 0.0
        res.newton_iterations["T"] = sol["iterations_T"]
    res.wall_s = {"total": time.perf_counter() - t0}
    if with_fields:
        res.V, res.T = sol["V"], sol["T"]
    return res
