"""The yarn and contact resistances R_y, R_c of a periodic cell, per unit width (docs/periodic.md
"R_y and R_c of the periodic sheet").

The pinned table fits R_y (one yarn across one cell) and R_c (one of the four warp-weft
contact resistors of a crossing) to terminal-pair probes (``rve.homogenisation.network``).
A periodic cell has no terminals; its figures are per unit width, read off the two cell
problems of the **two-potential sheet** that ``rve.tables.macro`` exports (a warp layer and
a weft layer, each with its own potential, joined by an exchange conductance per area):

* **layer sheet resistance** r_y of a yarn family (ohm per reference square): the field probe
  of ``periodic_probes`` (macro field E along the family, periodic potential jump) on the
  cell of that family's fibrils alone (the contacts among them conduct; the other family is
  absent), r_y = |E| / |j| with j the macro current per reference width;
* **exchange resistance per area** r_c (ohm mm^2): no macro field; a current is injected
  uniformly per unit length into the warp fibrils and taken out uniformly per unit length
  from the weft fibrils, balanced in every conduction component that holds both families;
  r_c = A (mean_warp V - mean_weft V) / I (means weighted by fibril length, A the
  reference cell area, I the injected current). The uniform sources are the multipliers of
  the two layer-mean constraints of the bidomain cell problem, so r_c includes the spreading
  in the fibrils between a contact and the layer's mean potential.

The network resistors of the pinned model follow per crossing of the reference pitches
a_x (between weft yarns) and a_y (between warp yarns): a layer of parallel yarns one pitch
apart has r_y = R_y a_y / a_x, and a crossing's four contacts in parallel exchange
4 / R_c per area a_x a_y, so

    R_y = r_y a_x / a_y (warp; weft: r_y a_y / a_x),     R_c = 4 r_c / (a_x a_y)

(c = 4 / (R_c a_x a_y) = 1 / r_c, ``rve.tables.macro``'s exchange conductance per area),

both intensive: a 1 x 1 and a 2 x 2 repeat of one state give the same values (tested).

Contract
--------
``family_sheet_resistance(cfg, fab, mesh, xn, family, graph) -> float`` (``family`` warp |
weft, the field along x | y), ``exchange_resistance(cfg, fab, mesh, xn, graph) -> dict``,
and ``cell_resistances(cfg, fab, mesh, xn, family, graph, multipliers=None)``, with ``graph`` the field
probes' conduction graph (``components(full, mesh, x)``: the component of every fibril,
fibrils joined by active contacts; ``references(ties, mesh, comp)``: one reduced potential
reference node per component; ``periodic_probes.CONDUCTION_GRAPH``): the record a field probe carries
(``periodic_probes.solve_field_probe``: the field-x probe the warp family, the field-y
probe the weft family; both the exchange): ``{"yarn_family", "layer_sheet_resistance_ohm",
"yarn_resistance_ohm", "exchange_resistance_ohm_mm2", "contact_resistance_ohm",
"pitch_mm"}``. The state ``xn`` is a stored full state (n_nodes, 9), mechanics frozen;
``multipliers`` its contact multipliers (an augmented-Lagrangian state's ``(keys, values)``
record, seeded on every map as the field probes do; on a family's own mesh the keys are
renumbered to its elements and fibrils, and points on the other family are dropped).
"""
from __future__ import annotations
import logging

import numpy as np

from ..fabrics.setup import contact_params
from ..fem.mesh import FibrilMesh
from ..model import BeamModel, ContactSystem, Couplings
from ..model.periodic import PeriodicSystem, fibril_end_ties
from ..solvers.static import static_solve
from .multipliers import seed_multipliers
from .periodic import cell_gradient
from .probe_result import _length_weights, conduction_material

__all__ = ["FAMILY_AXIS", "family_mesh", "pitches", "family_sheet_resistance", "exchange_resistance",
           "cell_resistances"]

#: the in-plane axis each yarn family runs along
FAMILY_AXIS = {"warp": 0, "weft": 1}

#: a stalled solve of the linear V problem below this fraction of its initial residual is at
#: its round-off floor (``_at_roundoff_floor``)
ROUNDOFF_FLOOR = 1e-6

log = logging.getLogger("rve.homogenisation.periodic_resistances")

_NO_COUPLING = dict(joule=False, lorentz=False, back_emf=False, seebeck=False, thermal_softening=False)


def family_mesh(mesh, fibrils) -> tuple:
    """The mesh of the fibrils ``fibrils`` alone (in their order) and the full-mesh node of
    each of its nodes: ``(FibrilMesh, nodes)``."""
    fibrils = np.asarray(fibrils, dtype=np.int64)
    nodes = np.concatenate([np.arange(mesh.node_offsets[f], mesh.node_offsets[f + 1]) for f in fibrils])
    elems = np.concatenate([np.arange(mesh.elem_offsets[f], mesh.elem_offsets[f + 1]) for f in fibrils])
    new_node = np.full(mesh.n_nodes, -1, dtype=np.int64)
    new_node[nodes] = np.arange(nodes.size)
    n_nodes = np.diff(mesh.node_offsets)[fibrils]
    n_elems = np.diff(mesh.elem_offsets)[fibrils]
    sub = FibrilMesh(order=mesh.order, conn=new_node[mesh.conn[elems]],
                     elem_fibril=np.repeat(np.arange(fibrils.size), n_elems),
                     node_fibril=np.repeat(np.arange(fibrils.size), n_nodes),
                     node_offsets=np.concatenate([[0], np.cumsum(n_nodes)]).astype(mesh.node_offsets.dtype),
                     elem_offsets=np.concatenate([[0], np.cumsum(n_elems)]).astype(mesh.elem_offsets.dtype),
                     elem_length=mesh.elem_length[elems], node_s=mesh.node_s[nodes], X0=mesh.X0[nodes],
                     radius=mesh.radius[fibrils], names=tuple(mesh.names[f] for f in fibrils) if mesh.names else ())
    return sub, nodes


def _periods(fab) -> np.ndarray:
    hx, hy = float(fab.half_widths[0]), float(fab.half_widths[1])
    return np.array([[2.0 * hx, 0.0, 0.0], [0.0, 2.0 * hy, 0.0]])


def _family_fibrils(fab, family: str) -> np.ndarray:
    return np.flatnonzero(np.asarray(fab.fibril_direction) == family)


def pitches(fab) -> tuple:
    """``(a_x, a_y)``: the reference pitch of the weft yarns along x and of the warp yarns
    along y (cell side over the family's yarn count), mm."""
    L = 2.0 * np.asarray(fab.half_widths[:2], float)
    n_weft = sum(y.direction == "weft" for y in fab.yarns)
    n_warp = sum(y.direction == "warp" for y in fab.yarns)
    return float(L[0] / max(n_weft, 1)), float(L[1] / max(n_warp, 1))


def family_multipliers(record, mesh, fibrils, geometry: str):
    """The multiplier record of the full ``mesh`` on the mesh of ``fibrils`` alone
    (``family_mesh``): element and fibril indices of the point keys renumbered, keys that
    touch another fibril dropped (``contact_pairs.point_keys``: column 0 the element of the
    point, column 2 the fibril it touches, or its element for the chord)."""
    if record is None:
        return None
    keys, values = np.asarray(record[0], np.int64), np.asarray(record[1], float)
    fibrils = np.asarray(fibrils, np.int64)
    elems = np.concatenate([np.arange(mesh.elem_offsets[f], mesh.elem_offsets[f + 1]) for f in fibrils])
    new_elem = np.full(int(mesh.elem_offsets[-1]), -1, np.int64)
    new_elem[elems] = np.arange(elems.size)
    new_fib = np.full(mesh.n_fibrils, -1, np.int64)
    new_fib[fibrils] = np.arange(fibrils.size)
    if keys.shape[0] == 0:
        return keys, values
    a = new_elem[keys[:, 0]]
    b = (new_elem if geometry == "chord" else new_fib)[keys[:, 2]]
    keep = (a >= 0) & (b >= 0)
    out = keys[keep].copy()
    out[:, 0], out[:, 2] = a[keep], b[keep]
    return out, values.ravel()[keep]


def _conduction_system(cfg, mesh, xn, multipliers=None):
    """The frozen (mech, V) contact system of ``mesh`` at the nodal state ``xn``, with the
    contact ``multipliers`` seeded."""
    base = BeamModel(mesh, conduction_material(cfg), fields=("mech", "V"), couplings=Couplings(**_NO_COUPLING),
                     disk_points=cfg.mesh.disk_points, axial_points=cfg.mesh.axial_points)
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = xn
    cparams = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=True)
    system = ContactSystem(base, cparams, x)
    seed_multipliers(system, multipliers)
    return system, x


def _solve(psys, x_full, opts, what):
    """The linear V problem: Newton's first step solves it; a relative tolerance of 1e-10 of
    the initial residual (the injected current) stays above the round-off of a stiff fibril."""
    o = {"atol": 1e-12, "max_iter": 5, "label": what, **opts}
    o["rtol"] = max(float(o.get("rtol", 0.0)), 1e-10)
    xs, ws, res = static_solve(psys, psys.restrict(x_full), np.zeros(psys.n), 0.0, o)
    if not res.converged and not _at_roundoff_floor(res):
        raise RuntimeError(f"periodic {what} solve did not converge: {res.reason}")
    if not res.converged:
        log.info("periodic %s solve: residual %.3e A stalled at the round-off floor of the linear problem "
                 "(%.1e of the initial) after %d Newton steps; accepted", what, res.residuals[-1],
                 res.residuals[-1] / res.residuals[0], res.iterations)
    return xs, ws


def _at_roundoff_floor(res) -> bool:
    """Whether a stalled solve of the linear V problem is at its round-off floor: Newton's
    first step solved it and a refinement step followed (two accepted steps), the residual is
    below ``ROUNDOFF_FLOOR`` of the initial one, and no shorter step lowers it further. A weak
    contact (a nearly floating fibril) makes the potentials large and the floor of the
    residual, eps |J| |V|, can sit above the relative tolerance."""
    r = np.asarray(res.residuals, float)
    return r.size >= 3 and bool(r[-1] <= ROUNDOFF_FLOOR * r[0])


def _reduced_system(full, ties, x, F, E, load, refs, contact_images, multipliers=None):
    """The reduced (mech, V) system: mechanics held, V held (0) at the reduced nodes ``refs``;
    the ``multipliers`` seeded on the map it ends with."""
    lay = PeriodicSystem(full, ties, F=F).layout
    held = np.concatenate([lay.dofs("mech"), lay.dofs("V", refs)])
    psys = PeriodicSystem(full, ties, held, 0.0, F=F, E=E, load=load, contact_images=contact_images)
    if psys.contact_images:
        psys.rebuild(psys.restrict(x))
    seed_multipliers(psys, multipliers)
    return psys, lay


def family_sheet_resistance(cfg, fab, mesh, xn, family: str, graph, multipliers=None) -> float:
    """r_y (ohm per reference square) of the yarn family ``family`` (module docstring): the
    field probe along the family on its fibrils alone."""
    axis = FAMILY_AXIS[family]
    fibrils = _family_fibrils(fab, family)
    sub, nodes = family_mesh(mesh, fibrils)
    ties = fibril_end_ties(sub, _periods(fab))
    F = cell_gradient(fab, mesh, xn)
    sub_mult = family_multipliers(multipliers, mesh, fibrils, cfg.contact.geometry)
    full, x = _conduction_system(cfg, sub, np.asarray(xn, float)[nodes], sub_mult)
    comp = graph.components(full, sub, x)
    E = np.zeros(3)
    E[axis] = float(cfg.probe_solver.voltage) / (2.0 * float(fab.half_widths[axis]))
    psys, _ = _reduced_system(full, ties, x, F, E, None, graph.references(ties, sub, comp), cfg.cell.contact_images, sub_mult)
    ps = cfg.probe_solver
    xs, ws = _solve(psys, x, {"atol": ps.newton_atol, "rtol": ps.newton_rtol}, f"{family} layer")
    j = float(psys.macro_current(xs, ws)[axis])
    return float(E[axis] / j) if j != 0.0 else float("inf")


def exchange_resistance(cfg, fab, mesh, xn, graph, multipliers=None) -> dict:
    """r_c (ohm mm^2) of the cell (module docstring): ``{"exchange_resistance_ohm_mm2",
    "injected_A", "layer_potential_drop_V", "reference_current_A"}`` (the last: what the
    potential references carry, ~0 as the sources balance)."""
    full, x = _conduction_system(cfg, mesh, xn, multipliers)
    ties = fibril_end_ties(mesh, _periods(fab))
    comp = graph.components(full, mesh, x)
    direction = np.asarray(fab.fibril_direction)
    warp_f, weft_f = direction == "warp", direction == "weft"
    both = np.array([warp_f[comp == c].any() and weft_f[comp == c].any() for c in range(comp.max() + 1)])
    wts = _length_weights(mesh)
    node_comp, node_fib = comp[mesh.node_fibril], mesh.node_fibril
    on_w = both[node_comp] & warp_f[node_fib]
    on_f = both[node_comp] & weft_f[node_fib]
    if not on_w.any():
        return {"exchange_resistance_ohm_mm2": float("inf"), "injected_A": 0.0, "layer_potential_drop_V": 0.0,
                "reference_current_A": 0.0}
    q = 1.0 / float(wts[on_w].sum())      # 1 A over all warp fibrils of the two-family components
    inj = np.where(on_w, q * wts, 0.0)
    # each component returns through its weft what its warp takes in
    inj_c = np.bincount(node_comp, weights=inj, minlength=both.size)
    len_f = np.bincount(node_comp, weights=np.where(on_f, wts, 0.0), minlength=both.size)
    ext = np.where(on_f, wts * (inj_c / np.where(len_f > 0, len_f, 1.0))[node_comp], 0.0)
    flay = full.layout
    load = np.zeros(full.n)
    load[flay.dofs("V")] = -(inj - ext)    # the residual is the current leaving a node
    refs = graph.references(ties, mesh, comp)
    psys, lay = _reduced_system(full, ties, x, cell_gradient(fab, mesh, xn), np.zeros(3), load, refs,
                                cfg.cell.contact_images, multipliers)
    ps = cfg.probe_solver
    xs, ws = _solve(psys, x, {"atol": ps.newton_atol, "rtol": ps.newton_rtol}, "exchange")
    V = full.nodal(psys.expand_rates(ws))[:, flay.offset["V"]]
    drop = float((wts * V)[on_w].sum() / wts[on_w].sum() - (wts * V)[on_f].sum() / wts[on_f].sum())
    injected = float(inj.sum())
    R_red = psys.evaluate(xs, ws, 0.0, jacobian=False)[0]
    area = float(ties.area)
    return {"exchange_resistance_ohm_mm2": area * drop / injected, "injected_A": injected,
            "layer_potential_drop_V": drop, "reference_current_A": float(np.abs(R_red[lay.dofs("V", refs)]).sum())}


def cell_resistances(cfg, fab, mesh, xn, family: str, graph, multipliers=None) -> dict:
    """The R_y of ``family`` and the R_c of the cell, per width and as network resistors
    (module docstring)."""
    a_x, a_y = pitches(fab)
    r_y = family_sheet_resistance(cfg, fab, mesh, xn, family, graph, multipliers)
    ex = exchange_resistance(cfg, fab, mesh, xn, graph, multipliers)
    r_c = ex["exchange_resistance_ohm_mm2"]
    along, across = (a_x, a_y) if family == "warp" else (a_y, a_x)
    return {"yarn_family": family, "layer_sheet_resistance_ohm": r_y, "yarn_resistance_ohm": r_y * along / across,
            "exchange_resistance_ohm_mm2": r_c, "contact_resistance_ohm": 4.0 * r_c / (a_x * a_y),
            "pitch_mm": [a_x, a_y], "exchange_reference_current_A": ex["reference_current_A"]}
