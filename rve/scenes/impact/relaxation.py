"""What the impact's damped relaxation keeps while it integrates: the mechanical energy
series and its balance, the fabric's centroid drift and speed, and, with
``relaxation.friction``, the fibril friction's history handed to the impact run
(docs/impact.md "Relaxation with friction").

Contract
--------
* ``relaxation_friction(cfg)``: True when the relaxation carries the fibril friction
  (``relaxation.friction`` and some fibril mu > 0 in the ``friction`` section; the
  projectile's mu_p is not used: the projectile is held clear of the fabric).
* ``RelaxationRecorder(problem, friction=None)``: ``record(t, x, w)`` appends one state's
  mechanical terms (the ``ImpactSystem``'s kinetic, strain and contact energy, fabric +
  projectile + sphere contact, mJ; the damping power and, with ``friction`` a
  ``DynamicFriction``, the friction power of its last committed state, W = mJ/ms, and its
  ``terms()``) and the fabric's centroid drift from the start state ``problem.x0``;
  ``on_step(t, x, w, info)`` is the integrator's callback (the driver commits the friction
  history before it: ``DynamicFriction.on_step(recorder.on_step)``); ``summary()`` -> the
  JSON-able figures: ``max_centroid_drift_mm`` (max over the nodes of |r - r0| at the end),
  ``max_centroid_drift_over_run_mm`` (the same, max over the accepted states),
  ``max_centroid_speed_mm_per_ms`` (max over the nodes of |dr/dt| at the end), the
  mechanical balance of ``rve.model.balances.balance_errors`` (B is off: no Lorentz work, so
  the balance is ΔE_mech + W_damping + W_friction = 0, relative to max |ΔE_mech|) with its
  works (``delta_mechanical_energy_mJ``, ``damping_mJ``, ``friction_work_mJ``,
  ``friction_dissipated_mJ``, ``friction_elastic_energy_mJ``), and with friction the stick
  and slip counts of the last commit (``FrictionTerm.points``).
* ``RelaxInfo(info, friction=None)``: the relaxation's summary (a dict, JSON-able;
  ``with_friction`` says whether it carried the friction) with the friction history of the
  relaxed state as plain arrays in the attribute ``friction`` (the names ``friction/...`` of
  ``DynamicFriction.arrays``; None without friction).
* ``seed_impact_friction(friction, x, arrays)``: the impact's fibril friction (the scene's
  ``DynamicFriction`` or ``ImpactFriction``) seeded with the relaxed state's history, after
  the impact's first map rebuild at ``x``: the points of the relaxed map keep their history
  by point key, new ones take a neighbour's (``DynamicFriction.restore``); the dissipated
  energy and the released springs' energy count from the impact's start (0), the springs'
  energy per point is the relaxed state's.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...model.balances import balance_errors
from ...model.terms.elasticity import beam_strain_energy
from ...model.terms.friction import FrictionLaw
from .friction import ImpactFriction

__all__ = ["relaxation_friction", "RelaxationRecorder", "RelaxInfo", "seed_impact_friction"]

#: the terms of balance_errors the relaxation does not have (B off: no Lorentz work; no
#: temperature is solved): zero series, so its mechanical balance reads ΔE + W_d + W_f
_ZERO = ("current_in", "current_out", "current_leak", "power_circuit", "power_joule", "power_contact_joule",
         "power_lorentz", "heat_content", "heat_out")


def relaxation_friction(cfg) -> bool:
    """Whether the relaxation carries the fibril friction (module docstring)."""
    if not cfg.relaxation.friction:
        return False
    mu, stiffness, pairs = cfg.friction.law_args()
    return FrictionLaw(mu, stiffness, pairs).enabled


class RelaxInfo(dict):
    """The relaxation's summary with the relaxed state's friction history (module docstring)."""

    def __init__(self, info=(), friction: dict | None = None):
        super().__init__(info)
        self.friction = None if friction is None else {k: np.asarray(v) for k, v in friction.items()}


class RelaxationRecorder:
    """The relaxation's energy series and centroid drift (module docstring)."""

    def __init__(self, problem, friction=None):
        sysm = problem.system
        self.sysm, self.friction = sysm, friction
        fab, proj = sysm.fabric.base, sysm.projectile
        self.mech_f = np.asarray(fab.mech, bool)
        self.mech_p = np.asarray(proj.mech, bool)
        self.Mf = sp.csr_matrix(fab.assembler.mass())[self.mech_f][:, self.mech_f]
        self.Mp = sp.csr_matrix(proj.assembler.mass())[self.mech_p][:, self.mech_p]
        self.damp = fab.material.damping / fab.material.density
        self.r0 = self._centroids(problem.x0)
        self.series = {k: [] for k in ("t", "energy_kinetic", "energy_strain", "energy_contact", "power_damping")}
        if friction is not None:
            self.series.update({k: [] for k in ("power_friction", "friction_dissipated", "energy_friction")})
        self.drift_max = 0.0
        self.last = None

    def _centroids(self, x) -> np.ndarray:
        return self.sysm.fabric.base.nodal(self.sysm.split(x)[0])[:, 0:3].copy()

    def record(self, t, x, w) -> None:
        sysm = self.sysm
        xf, xp = sysm.split(x)
        wf, wp = sysm.split(w)
        vf, vp = np.asarray(wf, float)[self.mech_f], np.asarray(wp, float)[self.mech_p]
        Mv = self.Mf @ vf
        s = self.series
        s["t"].append(float(t))
        s["energy_kinetic"].append(0.5 * float(vf @ Mv) + 0.5 * float(vp @ (self.Mp @ vp)))
        s["energy_strain"].append(beam_strain_energy(sysm.fabric.base, xf) + beam_strain_energy(sysm.projectile, xp))
        s["energy_contact"].append(float(sysm.fabric.contact_energy(xf)) + float(sysm.sphere_energy(x)))
        s["power_damping"].append(self.damp * float(vf @ Mv))
        if self.friction is not None:
            for k, v in self.friction.terms(w).items():
                s[k].append(v)
        drift = np.linalg.norm(self._centroids(x) - self.r0, axis=1)
        self.drift_max = max(self.drift_max, float(drift.max()))
        self.last = (x, w)

    def on_step(self, t, x, w, info) -> None:
        self.record(t, x, w)

    def summary(self) -> dict:
        x, w = self.last
        sysm = self.sysm
        drift = np.linalg.norm(self._centroids(x) - self.r0, axis=1)
        speed = np.linalg.norm(sysm.fabric.base.nodal(sysm.split(w)[0])[:, 0:3], axis=1)
        n = len(self.series["t"])
        errs = balance_errors({**self.series, **{k: np.zeros(n) for k in _ZERO}})
        out = {"max_centroid_drift_mm": float(drift.max()), "max_centroid_drift_over_run_mm": self.drift_max,
               "max_centroid_speed_mm_per_ms": float(speed.max()),
               "mechanical_balance": errs["mechanical"],
               "energies_mJ": {k: errs[k] for k in ("delta_mechanical_energy_mJ", "damping_mJ", "friction_work_mJ",
                                                    "friction_dissipated_mJ", "friction_elastic_energy_mJ")
                               if k in errs}}
        if self.friction is not None:
            out["friction_points"] = self.friction.term.points()
        return out


def seed_impact_friction(friction, x, arrays) -> None:
    """The relaxed state's fibril friction history into the impact (module docstring)."""
    fibrils = friction.fibrils if isinstance(friction, ImpactFriction) else friction
    if fibrils is None:
        raise ValueError("the relaxed state carries a fibril friction history but the impact has no fibril friction")
    fibrils.restore(x, arrays)
    # the impact's balances count the friction dissipated from their own start
    fibrils.term.dissipated = 0.0
    fibrils.released = 0.0
