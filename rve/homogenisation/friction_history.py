"""The friction history on the RVE strain path: the law of a config, a system's record, seeding
a rebuilt system from a record, and the summary a step stores (docs/contact.md "Friction in
the RVE pipeline").

Contract
--------
* ``friction_law(cfg)`` -> the ``FrictionLaw`` of the config's ``friction`` section, or None
  when every mu is 0;
* ``friction_record(system)`` -> ``FrictionTerm.record()`` of a system, None without friction;
* ``seed_friction(system, record, x)``: the record on the system's map (built at ``x``);
* ``friction_summary(system, start_dissipated)`` -> the figures of the last committed state.
"""
from __future__ import annotations

import numpy as np

from ..solvers.system import friction_of

__all__ = ["friction_law", "friction_record", "seed_friction", "friction_summary"]


def friction_law(cfg):
    """The ``FrictionLaw`` of the config's ``friction`` section, None when every mu is 0 (the
    frictionless path, bit for bit)."""
    if not getattr(cfg, "has_friction", False):
        return None
    from ..model.terms.friction import FrictionLaw

    return FrictionLaw(*cfg.friction.law_args(), frame=cfg.friction.frame)


def friction_record(system):
    """The friction history of ``system`` (``FrictionTerm.record()``), None without friction."""
    fr = friction_of(system)
    return None if fr is None else fr.record()


def seed_friction(system, record, x) -> None:
    """The friction history of ``system``'s current map (built at ``x``) from ``record`` by
    point key; a point not in the record takes the history of its neighbour along the -
    fibril (``FrictionTerm.share_along_fibrils``, as at a map rebuild), else it keeps the
    start it has (no elastic gap at ``x``). No-op without friction or record."""
    fr = friction_of(system)
    if fr is None or record is None:
        return
    from ..model.terms.friction import match_rows

    fr.seed(record)
    if fr.keys is not None and len(fr.keys):
        new = match_rows(fr.keys, record["keys"]) < 0
        if new.any():
            fr.share_along_fibrils(np.asarray(x, float).reshape(-1), receivers=new.reshape(fr.s_bar.shape))


def friction_summary(system, start_dissipated: float = 0.0) -> dict:
    """The friction of the last committed state of ``system``: total friction and normal
    force of the contact points (N), stick and slip counts (the return map of the last
    increment: its static solve is committed once, ``multipliers.equilibrium``), the energy
    dissipated since the start of the path (``dissipated``, N mm) and by this step
    (``step_dissipated``)."""
    fr = friction_of(system)
    if fr is None:
        return {}
    out = fr.points()
    out.update({"dissipated": float(fr.dissipated), "step_dissipated": float(fr.dissipated - start_dissipated)})
    return out
