"""Fabric set-up shared by the relaxation scene and the RVE pipeline (docs/fabrics.md).

Contract
--------
In: config *sections* (duck-typed: any object with the fields of
``rve.config.fabric.FabricSpec``, ``FabricContact``, ``FabricMesh`` and a material with
``youngs_modulus``, ``poisson_ratio``, ``density``), a ``Fabric`` and its mesh. Out:

* :func:`make_fabric` -- the ``Fabric`` of a fabric section (weave or knit);
  :func:`fabric_and_mesh` -- ``(fabric, mesh)`` of a config with ``fabric`` and ``mesh``
  sections (deterministic: the same config gives the same mesh);
* :func:`clamped_ends` -- the boundary conditions of docs/relaxation.md "Set-up": the
  centroid of every fibril end pinned (``layout.dofs("r", ends)``, end-major, 3 per end)
  and the twist gauge g1_z (``layout.dofs("g1", nodes, comp=2)``) at each fibril's first
  node ("first") or at every node ("all");
* :func:`contact_params` -- the ``ContactParams`` of a contact section;
* :func:`mechanics_system` -- the mechanics-only ``ContactSystem`` (``BeamModel`` with
  those clamps, volumetric damping, the contact law) at a state;
* :func:`clamp_reactions` -- the clamp forces summed per box side.

Dof indices come from the ``DofLayout`` (rve.fem.assembly), never from ``node * 9 + k``.
"""
from __future__ import annotations

import numpy as np

from ..model import ContactParams, ContactSystem
from ..fem.assembly import DofLayout
from ..model import BeamMaterial, BeamModel, DirichletBC
from .fabric import Fabric

__all__ = ["make_fabric", "fabric_and_mesh", "end_nodes", "clamped_ends", "contact_params", "mechanics_system",
           "clamp_reactions", "TWIST_GAUGES"]

#: where the twist gauge holds g1_z: each fibril's first node, or every node
TWIST_GAUGES = ("first", "all")


def make_fabric(spec) -> Fabric:
    """The fabric of a fabric section (``rve.config.fabric.FabricSpec``): the thesis knit
    for ``kind: knit``, else the weave ``kind`` (docs/fabrics.md)."""
    from .knit import knit
    from .weave import weave

    if spec.kind == "knit":
        return knit(n_rows=spec.knit_rows, n_loops=spec.knit_loops, fibril_diameter=spec.fibril_diameter)
    return weave(spec.kind, spec.n_warp, spec.n_weft, spacing=spec.spacing, amplitude=spec.amplitude,
                 fibril_diameter=spec.fibril_diameter, rows=tuple(spec.rows))


def fabric_and_mesh(cfg, elements=None):
    """``(fabric, mesh)`` of a config with ``fabric`` and ``mesh`` sections (``elements``
    per fibril: ``cfg.mesh.elements`` unless given); a ``packing`` section with a
    perturbation (the RVE config) perturbs the packing (``rve.fabrics.perturb``)."""
    fab = make_fabric(cfg.fabric)
    packing = getattr(cfg, "packing", None)  # RVEConfig.packing: a perturbed packing (rve.fabrics.perturb)
    if packing is not None and (packing.perturbation > 0 or (packing.crimp_phase or 0) > 0):
        from .perturb import perturb_packing

        fab = perturb_packing(fab, packing.seed, packing.perturbation, packing.crimp_phase)
    mesh = fab.mesh(cfg.mesh.elements if elements is None else elements, cfg.mesh.order)
    return fab, mesh


def end_nodes(fab: Fabric, mesh) -> np.ndarray:
    """Global node of every fibril end, in ``fab.end_tags`` order (int64)."""
    return np.array([t.node(mesh) for t in fab.end_tags], dtype=np.int64)


def clamped_ends(fab: Fabric, mesh, layout: DofLayout | None = None, twist_gauge: str = "first"):
    """``(end nodes, pinned centroid dofs, twist-gauge dofs)`` in ``layout`` (default:
    the mechanics-only layout of ``mesh``). Pinned: the 3 centroid dofs of every fibril
    end, end-major; gauge: g1_z at each fibril's first node (``"first"``, the relaxation
    scene's gauge) or at every node (``"all"``); docs/relaxation.md."""
    if twist_gauge not in TWIST_GAUGES:
        raise ValueError(f"twist_gauge must be 'first' or 'all', got {twist_gauge!r}")
    layout = DofLayout(mesh.n_nodes, ("mech",)) if layout is None else layout
    ends = end_nodes(fab, mesh)
    pinned = layout.dofs("r", ends)
    if twist_gauge == "all":
        nodes = np.arange(mesh.n_nodes, dtype=np.int64)
    else:
        nodes = mesh.node_offsets[:-1].astype(np.int64)
    return ends, pinned, layout.dofs("g1", nodes, comp=2)


def contact_params(contact, rebuild_every: int, conduction: bool = True) -> ContactParams:
    """``ContactParams`` of a contact section (``rve.config.fabric.FabricContact``, or a
    dynamic scene's contact section: ``recompute_closest`` and ``onset`` take the
    ``ContactParams`` defaults where the section has none), the map rebuilt every
    ``rebuild_every`` steps. ``conduction=False`` zeroes the contact heat transfer and
    conductance (the mechanics-only strain steps)."""
    return ContactParams(penalty=contact.penalty, heat_transfer=contact.heat_transfer if conduction else 0.0,
                         conductance=contact.conductance if conduction else 0.0, n_gp=contact.n_gp,
                         margin=contact.margin, g_eps=contact.g_eps,
                         recompute_closest=getattr(contact, "recompute_closest", True),
                         rebuild_every=rebuild_every, onset=float(getattr(contact, "onset", 0.0)),
                         **_contact_options(contact))


#: ContactParams options a contact section may carry (a section without them: the defaults)
_CONTACT_OPTIONS = ("geometry", "enforcement", "al_tolerance", "al_max_iter", "al_penalty_growth", "conductance_law", "hardness",
                    "spot_radius")


def _contact_options(contact) -> dict:
    return {k: getattr(contact, k) for k in _CONTACT_OPTIONS if hasattr(contact, k)}


def mechanics_system(fab: Fabric, mesh, cfg, params: ContactParams, damping: float, x, end_velocity=None,
                     twist_gauge: str = "first") -> ContactSystem:
    """Mechanics-only ``ContactSystem`` at state ``x`` (flat or (n_nodes, 9)): the
    ``BeamModel`` of ``cfg.material`` and ``cfg.mesh`` (disk and axial points) with the
    fibril ends pinned (centroid velocity ``end_velocity``, (n_ends, 3), default 0) and the
    twist gauge (:func:`clamped_ends`), volumetric damping ``damping``, contact ``params``."""
    m = cfg.material
    layout = DofLayout(mesh.n_nodes, ("mech",))
    ends, pinned, gauge = clamped_ends(fab, mesh, layout, twist_gauge)
    vel = np.zeros(pinned.size) if end_velocity is None else np.asarray(end_velocity, float).reshape(-1)
    if vel.size != pinned.size:
        raise ValueError(f"end_velocity must have {ends.size} x 3 values, got {vel.size}")
    mat = BeamMaterial(m.youngs_modulus, m.poisson_ratio, m.density, damping=float(damping))
    base = BeamModel(mesh, mat, disk_points=cfg.mesh.disk_points, axial_points=cfg.mesh.axial_points,
                     bcs=[DirichletBC(pinned, vel.copy()), DirichletBC(gauge, 0.0)])
    return ContactSystem(base, params, np.asarray(x, float).reshape(-1))


def clamp_reactions(fab: Fabric, system, x, t: float = 0.0) -> dict:
    """Force (N) the clamps exert on the fibrils, summed per box side: {side: [Fx, Fy, Fz]}.

    At a pinned centroid the residual F (internal minus external force, contact included)
    is what the clamp must supply, so the clamp force is F there (docs/relaxation.md)."""
    x = np.asarray(x, float).reshape(-1)
    F, _, _ = system.evaluate(x, np.zeros(system.n), t, jacobian=False)
    Fn = system.nodal(F)[:, :3]
    out = {}
    for side in ("x-", "x+", "y-", "y+"):
        nodes = fab.end_nodes(system.mesh, side)
        if nodes.size:
            out[side] = [float(v) for v in Fn[nodes].sum(axis=0)]
    return out
