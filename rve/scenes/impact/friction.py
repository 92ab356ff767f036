"""Friction at the projectile's sphere contact through the impact's time integration: the
history committed after every accepted step, the friction terms of the energy balances and
the history in the checkpoint (docs/impact.md "Friction at the projectile"). The friction
between fibrils is ``rve.scenes.dynamic_friction``; ``ImpactFriction`` drives both.

Contract
--------
* ``sphere_friction_args(section)``: ``(mu_p, stiffness)`` for ``SphereContactTerm(...,
  friction=...)`` from the validated ``ImpactFrictionSection`` (``friction.projectile``,
  ``friction.stiffness``), or None when mu_p = 0 (no friction term: the frictionless
  sphere contact bit for bit).
* ``SphereFriction.of(system)``: None when the ``ImpactSystem``'s sphere contact has no
  friction; else the driver of its ``SphereFrictionTerm``:
  ``commit(x)`` after an accepted step (before the balances and any pair rebuild: every
  stage of a step return-maps from the last accepted state, backward Euler in the slip),
  keeping the tangential springs' energy |t|^2 / (2 kT) per pair key;
  ``power(w)`` the power the friction forces of the last committed state take from the
  motion ``w`` (W = mJ/ms): sum over the pairs of t . dj/dt = R . w at their material
  points; ``terms(w=None)`` -> ``{"friction_dissipated_sphere": D, "energy_friction_sphere":
  E, "power_friction_sphere": P}`` (as ``DynamicFriction.terms``: D the return maps' slip
  work plus the springs' energy of pairs that lost contact, E the springs' energy now);
  ``arrays()`` the history as plain arrays (``friction/sphere/...``) and ``restore(x,
  arrays)`` after the pair rebuild at the resumed state ``x``: the history as the
  uninterrupted run has it after its rebuild there.
* ``ImpactFriction.of(fibrils, sphere)``: the friction of the impact from the fibrils'
  ``DynamicFriction`` and the ``SphereFriction`` (either None): None when both are, the
  fibrils' driver itself when the sphere has none (the fibril-friction impact unchanged),
  else one object with the drivers' protocol (``commit``, ``on_step``, ``terms``,
  ``arrays``, ``restore``; ``term`` the fibrils' ``FrictionTerm`` or None; ``sphere`` the
  sphere driver).
"""
from __future__ import annotations

import numpy as np

from ...model.terms.friction import match_rows
from ...physics.sphere_friction_forms import sphere_jump_jacobian

__all__ = ["sphere_friction_args", "SphereFriction", "ImpactFriction"]

PREFIX = "friction/sphere/"


def sphere_friction_args(section):
    """``(mu_p, stiffness)`` or None (module docstring)."""
    mu = 0.0 if section is None else float(getattr(section, "projectile", 0.0))
    if mu <= 0.0:
        return None
    return mu, float(section.stiffness)


class SphereFriction:
    """The sphere friction's history through a time integration (module docstring)."""

    def __init__(self, system):
        self.system = system
        self.term = system.sphere.friction
        self._keys = np.zeros((0, 2), np.int64)
        self._energy = np.zeros(0)
        #: springs' energy released by pairs that lost contact (counted as dissipated), mJ
        self.released = 0.0

    @classmethod
    def of(cls, system):
        return None if getattr(system.sphere, "friction", None) is None else cls(system)

    def commit(self, x) -> float:
        """Commit the accepted state ``x``; returns the energy dissipated by the step (mJ)."""
        term = self.term
        d = term.commit(self.system.sphere_local(x))
        released = 0.0
        if self._energy.size and term.last is not None:
            idx = match_rows(term.keys, self._keys)
            lost = (idx >= 0) & (term.last.normal <= 0.0)
            released = float(self._energy[idx[lost]].sum())
        self.released += released
        self._keys, self._energy = np.array(term.keys, np.int64), term.spring_energy()
        return d + released

    def power(self, w) -> float:
        """The friction forces' power on the motion ``w`` at the last commit (W)."""
        term = self.term
        st, X = term.last, term.X_last
        if st is None or X is None or X.shape[0] != self.system.sphere.n_pairs:
            return 0.0
        J = sphere_jump_jacobian(X, st.xi, st.s_bar)
        V = self.system.sphere_local(w)
        return float(np.einsum("pi,pilj,plj->", st.t, J, V))

    def terms(self, w=None) -> dict:
        out = {"friction_dissipated_sphere": float(self.term.dissipated) + self.released,
               "energy_friction_sphere": float(self._energy.sum())}
        if w is not None:
            out["power_friction_sphere"] = self.power(w)
        return out

    def arrays(self) -> dict:
        rec = self.term.record()
        out = {PREFIX + k: np.asarray(v) for k, v in rec.items()}
        out.update({PREFIX + "released": np.array(self.released), PREFIX + "energy_keys": self._keys,
                    PREFIX + "energy": self._energy})
        return out

    def restore(self, x, arrays) -> None:
        """The saved history on the pair table just rebuilt at ``x`` (module docstring)."""
        term = self.term
        rec = {k: arrays[PREFIX + k] for k in ("keys", "xi", "s_bar", "anchor")}
        rec["dissipated"] = float(arrays[PREFIX + "dissipated"])
        self.released = float(arrays[PREFIX + "released"])
        self._keys = np.asarray(arrays[PREFIX + "energy_keys"], np.int64).reshape(-1, 2)
        self._energy = np.asarray(arrays[PREFIX + "energy"], float)
        hit = term.seed(rec)
        # the pairs new to this table take a neighbour's history, as on_rebuild does
        if hit.size and not hit.all():
            term.share_along_fibrils(self.system.sphere_local(x), ~hit)


class ImpactFriction:
    """The fibrils' and the sphere's friction drivers as one (module docstring)."""

    def __init__(self, fibrils, sphere):
        self.fibrils, self.sphere = fibrils, sphere

    @classmethod
    def of(cls, fibrils, sphere):
        if sphere is None:
            return fibrils
        return cls(fibrils, sphere)

    @property
    def term(self):
        return None if self.fibrils is None else self.fibrils.term

    def _parts(self):
        return [p for p in (self.fibrils, self.sphere) if p is not None]

    def commit(self, x) -> float:
        return sum(p.commit(x) for p in self._parts())

    def on_step(self, inner):
        def step(t, x, w, info):
            self.commit(x)
            if inner is not None:
                inner(t, x, w, info)
        return step

    def terms(self, w=None) -> dict:
        out = {}
        for p in self._parts():
            out.update(p.terms(w))
        return out

    def arrays(self) -> dict:
        out = {}
        for p in self._parts():
            out.update(p.arrays())
        return out

    def restore(self, x, arrays) -> None:
        for p in self._parts():
            p.restore(x, arrays)
