"""Friction between fibrils in the dynamic fabric scenes (the impact, the induced
deformation): the law from the config, the history committed after every accepted time
step, the friction terms of the energy balances, and the history in the checkpoints
(docs/contact.md "Friction", docs/impact.md "Friction between fibrils").

Contract
--------
* ``contact_params_with_friction(params, section)``: ``params`` (``ContactParams``) with the
  ``FrictionLaw`` of the validated ``FrictionSection`` when it is enabled (some mu > 0);
  otherwise ``params`` itself, unchanged (no friction term: the frictionless scene bit for
  bit).
* ``DynamicFriction.of(contact_system, families=None, part=None)``: None for a frictionless
  system; else the driver of its ``FrictionTerm`` (``families``: 'warp'/'weft' per fibril,
  for the pair coefficients; ``part(x)``: the contact system's state in the state ``x`` the
  integrator hands over, e.g. the fabric part of the impact's state; default: ``x`` itself).
* ``DynamicFriction.commit(x)``: after an accepted step (the integrator's ``on_step``, before
  the balances are recorded and before any map rebuild): the step's state becomes the
  history of the next step (every stage of a step return-maps from the last accepted
  state: backward Euler in the slip). Keeps, per contact point, the elastic energy
  ``|t|^2 / (2 kT)`` of the tangential spring at that state.
* ``on_step(inner)``: an ``on_step`` callable that commits, then calls ``inner``.
* ``power(w)``: the power (W = mJ/ms) the friction forces of the last committed state take
  from the motion ``w``: sum over the points of t . (v+ - v-) at their material points, the
  couple's forces on the - chord ends and, with the section frame (``friction.frame``), its
  force on the - section's first director.
* ``terms(w=None)`` -> ``{"friction_dissipated": D, "energy_friction": E, "power_friction":
  P}`` (mJ, mJ, W; ``P`` only with ``w``): ``D`` the energy dissipated since the start
  (``FrictionTerm.dissipated``, the work of the return maps' slip, plus the elastic energy
  of the tangential springs of points that lost contact: their force drops to zero without
  returning it), ``E`` the elastic energy of the tangential springs now, ``P`` = ``power(w)``.
  The energy balances (``rve.model.balances.balance_errors``) count the friction work
  ∫P dt (trapezoid rule, like their other powers) as dissipated work; ``D + E`` is the
  return maps' first-order estimate of the same work, reported beside it.
* ``FrictionBalances(balances, friction)``: a balances callable whose dict has ``terms()``
  added.
* ``arrays()`` -> the history as plain arrays (names ``friction/...``, for an npz
  checkpoint; the section frame's committed frames as ``friction/m_ref``); ``restore(x, arrays)``: after the map rebuild at the resumed state, the
  history as the uninterrupted run has it after its rebuild there (the points of the saved
  map by key, the new points as ``FrictionTerm.on_rebuild`` gives them).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..model.terms.friction import FrictionLaw, match_rows

__all__ = ["contact_params_with_friction", "DynamicFriction", "FrictionBalances"]

PREFIX = "friction/"


def contact_params_with_friction(params, section):
    """``params`` with the friction law of ``section`` (module docstring)."""
    if section is None:
        return params
    mu, stiffness, pairs = section.law_args()
    law = FrictionLaw(mu, stiffness, pairs, frame=getattr(section, "frame", "chord"))
    if not law.enabled:
        return params
    return dataclasses.replace(params, friction=law)


class DynamicFriction:
    """The friction history of a contact system through a time integration (module docstring)."""

    def __init__(self, term, part=None):
        self.term = term
        self.part = (lambda x: x) if part is None else part
        #: elastic energy of the tangential springs per point at the last commit, by point key
        self._keys = np.zeros((0, 6), np.int64)
        self._energy = np.zeros(0)
        #: energy released by points that lost contact (counted as dissipated), mJ
        self.released = 0.0

    @classmethod
    def of(cls, contact_system, families=None, part=None):
        term = getattr(getattr(contact_system, "term", None), "friction", None)
        if term is None:
            return None
        if families is not None:
            term.set_families(list(families))
        return cls(term, part)

    # ------------------------------------------------------------------ steps
    def _spring_energy(self) -> np.ndarray:
        """|t|^2 / (2 kT) per point (flat) of the last committed return map."""
        st = self.term.last
        c = self.term.contact
        if st is None or st.t.size == 0:
            return np.zeros(0 if self.term.keys is None else self.term.keys.shape[0])
        kT = np.asarray(c.weight, float)[:, None] * float(self.term.law.stiffness) * float(c.params.penalty)
        e = np.einsum("pgi,pgi->pg", st.t, st.t) / (2.0 * np.broadcast_to(kT, st.t.shape[:2]))
        return np.where(st.normal > 0.0, e, 0.0).reshape(-1)

    def commit(self, x) -> float:
        """Commit the accepted state ``x``; returns the energy dissipated by the step (mJ)."""
        term = self.term
        if term.contact.map is None or term.contact.map.n_pairs == 0:
            return 0.0
        d = term.commit(self.part(x))
        st = term.last
        keys = np.array(term.keys, np.int64)
        released = 0.0
        if self._energy.size:
            idx = match_rows(keys, self._keys)
            lost = (idx >= 0) & (st.normal.reshape(-1) <= 0.0)
            released = float(self._energy[idx[lost]].sum())
        self.released += released
        self._keys, self._energy = keys, self._spring_energy()
        return d + released

    def on_step(self, inner):
        def step(t, x, w, info):
            self.commit(x)
            if inner is not None:
                inner(t, x, w, info)
        return step

    def power(self, w) -> float:
        """The power the friction forces of the last committed state take from the motion
        ``w`` (W = mJ/ms): sum over the points of t . (v+ - v-) at the material points, and
        of the couple's forces on the - chord ends (with the section frame also its force
        on the - section's first director)."""
        st, c = self.term.last, self.term.contact
        if st is None or st.t.size == 0 or c.map is None or c.row_pair.size != st.t.shape[0]:
            return 0.0
        if c.map.shift is not None:
            raise ValueError("friction power: periodic shifts are not supported")
        V = self.term.local_nodes(self.part(w), shifted=False)
        cb = self.term.material_weights(st.s_bar)
        p = float(np.einsum("pgk,pki,pgi->", cb, V, st.t))
        if st.couple is not None:   # the couple on the - chord ends (rve.physics.friction_forms)
            p += float(np.einsum("pgk,pki,pgi->", st.chord_weights, V, st.couple))
        if st.director_couple is not None:   # and the section frame's on the - section's g1
            Vg = self.term.local_directors(self.part(w))
            p += float(np.einsum("pgk,pki,pgi->", st.director_weights, Vg, st.director_couple))
        return p

    def terms(self, w=None) -> dict:
        out = {"friction_dissipated": float(self.term.dissipated) + self.released,
               "energy_friction": float(self._energy.sum())}
        if w is not None:
            out["power_friction"] = self.power(w)
        return out

    # ------------------------------------------------------------------ checkpoints
    def arrays(self) -> dict:
        rec = self.term.record()
        out = {PREFIX + "keys": rec["keys"], PREFIX + "s_bar": rec["s_bar"], PREFIX + "anchor": rec["anchor"],
               PREFIX + "d_ref": rec["d_ref"],
               PREFIX + "dissipated": np.array(rec["dissipated"]), PREFIX + "released": np.array(self.released),
               PREFIX + "energy_keys": self._keys, PREFIX + "energy": self._energy}
        if rec.get("m_ref") is not None:   # the section frame's committed frames
            out[PREFIX + "m_ref"] = rec["m_ref"]
        return out

    def restore(self, x, arrays) -> None:
        """The saved history on the map just rebuilt at ``x`` (module docstring)."""
        term = self.term
        x = self.part(x)
        rec = {"keys": np.asarray(arrays[PREFIX + "keys"], np.int64), "s_bar": arrays[PREFIX + "s_bar"],
               "anchor": arrays[PREFIX + "anchor"], "d_ref": arrays[PREFIX + "d_ref"] if PREFIX + "d_ref" in arrays else None,
               "m_ref": arrays[PREFIX + "m_ref"] if PREFIX + "m_ref" in arrays else None,
               "dissipated": float(arrays[PREFIX + "dissipated"])}
        self.released = float(arrays[PREFIX + "released"])
        self._keys = np.asarray(arrays[PREFIX + "energy_keys"], np.int64).reshape(-1, 6)
        self._energy = np.asarray(arrays[PREFIX + "energy"], float)
        if term.keys is None or term.s_bar is None or term.s_bar.size == 0:
            term.dissipated = rec["dissipated"]
            return
        hit = match_rows(term.keys, rec["keys"]) >= 0
        term.seed(rec)
        P, G = term.s_bar.shape
        # the points new to this map take a neighbour's history, as on_rebuild does
        if not hit.all():
            term.share_along_fibrils(x, receivers=~hit.reshape(P, G))


class FrictionBalances:
    """``balances`` (a callable returning the dict of one state) with the friction terms."""

    def __init__(self, balances, friction: DynamicFriction):
        self.balances, self.friction = balances, friction

    def __getattr__(self, name):
        if name in ("balances", "friction"):
            raise AttributeError(name)
        return getattr(self.balances, name)

    def __call__(self, *args, **kwargs) -> dict:
        b = self.balances(*args, **kwargs)
        w = args[1] if len(args) > 1 else kwargs.get("w")
        b.update(self.friction.terms(w))
        return b
