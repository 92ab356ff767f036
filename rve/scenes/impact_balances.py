"""Balances of the impact scene: momentum (projectile; whole system) and energy (the
induced-deformation balances of the fabric plus the projectile's terms); docs/impact.md.

Contract
--------
``ImpactBalances(problem, thermal)``: ``__call__(x, w, t, T)`` -> dict of one state: the
fabric terms of ``rve.scenes.induced_balances.StateBalances`` (fabric slice of the state),
plus ``energy_kinetic``/``energy_strain``/``energy_contact`` including the projectile and
the sphere contact, the projectile's circuit, Joule and Lorentz power, ``heat_sink`` (W into
the projectile through the sphere contact, ``rve.scenes.impact_thermal``), and the momentum
terms (3-vectors): ``momentum_projectile`` (sum over the centroid rows of M w),
``momentum_total``, ``force_sphere_on_projectile`` (N), ``force_lorentz_projectile``,
``force_lorentz`` (fabric + projectile), ``force_damping``, ``force_clamp_static`` (the
residual F at the pinned centroid rows; the clamp force is this plus the pinned rows of
M dw/dt, whose time integral is ``momentum_pinned`` = pinned rows of M w).

``impact_balance_errors(series)`` -> the relative errors (max over t):
momentum_projectile: |ΔP_p - ∫(F_sphere + F_L,p)| / max|∫(F_sphere + F_L,p)|;
momentum_total: |ΔP - J_clamp - ∫F_L - ∫F_d| / max(|J_clamp|, |∫F_L|, |ΔP|) with
J_clamp = Δ momentum_pinned + ∫ force_clamp_static; energy: ``balance_errors`` of the
induced scene on the combined terms (mechanical, total, ...). Trapezoid rule in time.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..model.assembler import ElementState
from ..model.terms.elasticity import beam_strain_energy
from ..physics.thermal_forms import joule_source
from .induced_balances import StateBalances, _cumtrapz, balance_errors

__all__ = ["ImpactBalances", "impact_balance_errors"]

_VEC = ("momentum_projectile", "momentum_total", "momentum_pinned", "force_sphere_on_projectile",
        "force_lorentz_projectile", "force_lorentz", "force_damping", "force_clamp_static")


def _em_force_and_power(model, x, w, t):
    """(Lorentz force sum (3,), Lorentz power W, Joule W) of a BeamModel with V."""
    em = model.assembler.term("electromagnetic")
    state = ElementState(model.basis, model.layout, x, w, t)
    res, _ = em.forms(state, False)
    m = em.emf(state, em.field(t))
    wn = model.nodal(w)
    f, P = np.zeros(3), 0.0
    if "mech" in res:
        Rl = res["mech"].reshape(model.mesh.n_elements, -1, 9)
        f = -Rl[:, :, 0:3].sum(axis=(0, 1))
        P = -float((Rl * wn[:, :9][model.mesh.conn]).sum())
    joule = float(joule_source(model.ops, m, model.material.electrical_conductivity).sum())
    return f, P, joule


class _Remembering:
    """The fabric system for ``StateBalances``, remembering its last residual (so the clamp
    forces need no second evaluation of the fabric)."""

    def __init__(self, system):
        self._system = system
        self.last_F = None

    def evaluate(self, x, w, t, jacobian=True):
        out = self._system.evaluate(x, w, t, jacobian)
        self.last_F = out[0]
        return out

    def __getattr__(self, name):
        return getattr(self._system, name)


class ImpactBalances:
    def __init__(self, problem, thermal):
        self.p = problem
        sysm = problem.system
        self.sysm = sysm
        self.thermal = thermal
        self._fabric = _Remembering(sysm.fabric)
        self.fab = StateBalances(self._fabric, thermal, problem.circuit_in, problem.circuit_leak, problem.dirichlet_V)
        proj = sysm.projectile
        self.proj = proj
        self.Mf = sp.csr_matrix(sysm.fabric.base.assembler.mass())
        self.Mp = sp.csr_matrix(proj.assembler.mass())
        lf, lp = sysm.fabric.layout, proj.layout
        self.rf = lf.dofs("r").reshape(-1, 3)
        self.rp = lp.dofs("r").reshape(-1, 3)
        self.pinned = lf.dofs("r", problem.ends.ravel()).reshape(-1, 3)
        self.damp = sysm.fabric.base.material.damping / sysm.fabric.base.material.density
        self.pmech = np.asarray(proj.mech, bool)
        self.Mpm = self.Mp[self.pmech][:, self.pmech]

    def __call__(self, x, w, t, T) -> dict:
        sysm = self.sysm
        xf, xp = sysm.split(x)
        wf, wp = sysm.split(w)
        if hasattr(self.thermal, "set_state"):
            self.thermal.set_state(x)
        b = self.fab(xf, wf, t, T)
        b["heat_sink"] = self.thermal.sink_heat(T, xf) if hasattr(self.thermal, "sink_heat") else 0.0
        # projectile: kinetic, strain, circuits, EM
        vm = np.asarray(wp, float)[self.pmech]
        kin_p = 0.5 * float(vm @ (self.Mpm @ vm))
        strain_p = beam_strain_energy(self.proj, xp)
        fL_p, PL_p, J_p = _em_force_and_power(self.proj, xp, wp, t)
        wpn = self.proj.nodal(wp)
        oV = self.proj.oV
        P_circ_p = float(sum(-c.area * (c.r_bar * wpn[c.node, oV] + c.J_bar) * wpn[c.node, oV]
                             for c in self.p.projectile_circuits))
        e_sph = sysm.sphere_energy(x)
        b.update({
            "energy_kinetic_fabric": b["energy_kinetic"], "energy_kinetic_projectile": kin_p,
            "energy_kinetic": b["energy_kinetic"] + kin_p,
            "energy_strain": b["energy_strain"] + strain_p, "energy_strain_projectile": strain_p,
            "energy_contact": b["energy_contact"] + e_sph, "energy_sphere_contact": e_sph,
            "power_circuit": b["power_circuit"] + P_circ_p, "power_joule": b["power_joule"] + J_p,
            "power_lorentz": b["power_lorentz"] + PL_p,
        })
        # momentum
        Mw_f = self.Mf @ np.asarray(wf, float)
        Mw_p = self.Mp @ np.asarray(wp, float)
        P_p = Mw_p[self.rp].sum(axis=0)
        P_f = Mw_f[self.rf].sum(axis=0)
        fS = sysm.sphere_forces(x).sum(axis=0)
        fL_f, _, _ = _em_force_and_power(sysm.fabric.base, xf, wf, t)
        Fs, _, _ = sysm.sphere_terms(x, jacobian=False)
        F = np.asarray(self._fabric.last_F, float) + Fs[: sysm.nf]  # fabric rows of the whole residual
        b.update({
            "momentum_projectile": P_p, "momentum_total": P_f + P_p, "momentum_pinned": Mw_f[self.pinned].sum(axis=0),
            "force_sphere_on_projectile": fS, "force_lorentz_projectile": fL_p, "force_lorentz": fL_f + fL_p,
            "force_damping": -self.damp * P_f, "force_clamp_static": F[self.pinned].sum(axis=0),
        })
        return b


def _int(t, v):
    return np.stack([_cumtrapz(t, v[:, i]) for i in range(v.shape[1])], axis=1)


def impact_balance_errors(s: dict) -> dict:
    """Momentum and energy balance errors (module docstring)."""
    t = np.asarray(s["t"], float)
    g = {k: np.asarray(s[k], float) for k in _VEC}
    out = {}
    Pp = g["momentum_projectile"]
    J = _int(t, g["force_sphere_on_projectile"] + g["force_lorentz_projectile"])
    res_p = (Pp - Pp[0]) - J
    norm = max(float(np.abs(J).max()), 1e-300)
    out["momentum_projectile"] = float(np.abs(res_p).max() / norm)
    P = g["momentum_total"]
    Jc = (g["momentum_pinned"] - g["momentum_pinned"][0]) + _int(t, g["force_clamp_static"])
    JL = _int(t, g["force_lorentz"])
    Jd = _int(t, g["force_damping"])
    res_t = (P - P[0]) - Jc - JL - Jd
    norm_t = max(float(np.abs(Jc).max()), float(np.abs(JL).max()), float(np.abs(P - P[0]).max()), 1e-300)
    out["momentum_total"] = float(np.abs(res_t).max() / norm_t)
    out["impulse_sphere_on_projectile_Nms"] = [float(v) for v in J[-1]]
    out["impulse_clamp_Nms"] = [float(v) for v in Jc[-1]]
    out["impulse_lorentz_Nms"] = [float(v) for v in JL[-1]]
    sel = {k: v for k, v in s.items() if k not in _VEC and not k.startswith("energy_kinetic_")
           and k not in ("energy_strain_projectile", "energy_sphere_contact", "heat_sink")}
    if "heat_sink" in s:  # heat leaves through the clamped ends and into the projectile
        sel["heat_out"] = np.asarray(s["heat_out"], float) + np.asarray(s["heat_sink"], float)
    e = balance_errors(sel)
    out.update(e)
    out["series"] = dict(e["series"], momentum_projectile_residual=res_p, momentum_total_residual=res_t)
    return out
