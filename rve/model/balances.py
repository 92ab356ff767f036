"""Balances of the dynamic fabric scenes: the charge and energy terms of one state of a
current-carrying fabric (docs/induced_deformation.md "Balances") and, for the impact, the
momentum (projectile; whole system) and the energy terms with the projectile (docs/impact.md).

Contract
--------
* ``StateBalances(system, ops, circuits)``: ``__call__(x, w, t, T)`` -> dict of the charge
  (currents in/out/leak, A), electrical (circuit power, Joule, contact Joule, Lorentz power,
  W), mechanical (kinetic, strain, contact energy, mJ; damping power, W) and thermal (heat
  content mJ, heat leaving through the ends W) terms of one state.
* ``balance_errors(series)``: time integrals (trapezoid over the accepted steps) and the
  relative errors of the charge, electrical, mechanical, thermal and total balances.

``ImpactBalances(problem, thermal)``: ``__call__(x, w, t, T, F=None)`` -> dict of one state
(``F``: the unscaled residual of the whole ``ImpactSystem`` at (x, w, t) when the caller has
it, e.g. ``RowScaledSystem.residual_at`` after the last stage's Newton; else the fabric's is
evaluated here): the fabric terms of ``StateBalances`` (fabric slice of the state),
plus ``energy_kinetic``/``energy_strain``/``energy_contact`` including the projectile and
the sphere contact, the projectile's circuit, Joule and Lorentz power, ``heat_sink`` (W into
the projectile through the sphere contact, ``rve.scenes.impact.thermal``), and the momentum
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

from .assembler import ElementState
from .terms.elasticity import beam_strain_energy
from ..physics.thermal_forms import joule_source

__all__ = ["StateBalances", "balance_errors", "ImpactBalances", "impact_balance_errors"]

class StateBalances:
    """The balance terms of one state (module docstring)."""

    def __init__(self, system, thermal, circuit_in, circuit_leak, dirichlet_out):
        self.system, self.base, self.thermal = system, system.base, thermal
        base = self.base
        self.mech = np.asarray(base.mech, bool)
        M = sp.csr_matrix(base.assembler.mass())  # unscaled
        self.Mm = M[self.mech][:, self.mech]
        mat = base.material
        self.damp = mat.damping / mat.density
        self.oV = base.oV
        self.circuit_in = list(circuit_in)        # CircuitBC at the warp terminals
        self.circuit_leak = list(circuit_leak)    # CircuitBC pull-downs of the weft
        self.dirichlet_out = np.asarray(dirichlet_out, np.int64)  # V dofs held at 0
        self.em = base.assembler.term("electromagnetic")
        self.last_F = None   # the residual of the last call

    def _circuit_current(self, circ, wn):
        """Current leaving through each circuit end, A, and the power into the fibril (W)."""
        I = np.array([c.area * (c.r_bar * wn[c.node, self.oV] + c.J_bar) for c in circ])
        V = np.array([wn[c.node, self.oV] for c in circ])
        return I, -(I * V)

    def __call__(self, x, w, t, T, F=None) -> dict:
        """``F``: the system residual F(x, w, t) if the caller has it (else evaluated here);
        kept as ``last_F`` (the impact's clamp forces read it: no second evaluation)."""
        base, sysm = self.base, self.system
        wn = base.nodal(w)
        I_in_out, P_in = self._circuit_current(self.circuit_in, wn)
        I_leak, P_leak = self._circuit_current(self.circuit_leak, wn) if self.circuit_leak else (np.zeros(0),) * 2
        if F is None:
            F = sysm.evaluate(x, w, t, jacobian=False)[0]
        F = self.last_F = np.asarray(F, float)
        I_out = -F[self.dirichlet_out]
        # Lorentz force on the nodes (minus the electromagnetic term's mech residual)
        state = ElementState(base.basis, base.layout, x, w, t)
        res, _ = self.em.forms(state, False)
        P_L = 0.0
        if "mech" in res:
            Rl = res["mech"].reshape(base.mesh.n_elements, -1, 9)
            v = wn[:, :9][base.mesh.conn]  # (E, nn, 9)
            P_L = -float((Rl * v).sum())
        joule = float(self.thermal.joule(x, w, t).sum())  # memoised: the post-solve's last stage
        Fc, _, _, _ = sysm.contact_terms(x, w, jacobian=False)
        P_cj = float(base.nodal(Fc)[:, self.oV] @ wn[:, self.oV]) if sysm.use_V else 0.0
        vm = np.asarray(w, float)[self.mech]
        Mv = self.Mm @ vm
        kin = 0.5 * float(vm @ Mv)
        strain = beam_strain_energy(base, x)
        cen = float(sysm.contact_energy(x))
        Tdot, q_out = self.thermal.rate(T, x, w, t)
        heat = float((self.thermal.M @ T).sum())
        return {
            "current_in": float(-I_in_out.sum()), "current_out": float(I_out.sum()),
            "current_leak": float(I_leak.sum()), "terminal_currents": -I_in_out,
            "power_circuit": float(P_in.sum() + (P_leak.sum() if len(P_leak) else 0.0)),
            "power_joule": joule, "power_contact_joule": P_cj, "power_lorentz": P_L,
            "power_damping": float(self.damp * (vm @ Mv)),
            "energy_kinetic": kin, "energy_strain": strain, "energy_contact": cen,
            "heat_content": heat, "heat_out": q_out, "max_temperature": float(np.max(T)),
        }


def _cumtrapz(t, y):
    t, y = np.asarray(t, float), np.asarray(y, float)
    return np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])


def balance_errors(s: dict) -> dict:
    """Relative balance errors of a series of balance terms over the accepted steps ``s['t']``.

    charge: max |I_in - I_out - I_leak| / max |I_in| (instantaneous);
    electrical: max |P_circuit - (Joule + contact Joule + Lorentz power)| / max |P_circuit|;
    mechanical: max |Δ(kin + strain + contact) + ∫P_damping - ∫P_Lorentz| / max(|∫P_L|, |ΔE_mech|);
    thermal: max |ΔH + ∫q_out - ∫Joule| / max ∫Joule;
    total: max |∫P_circuit - ΔE_mech - ∫P_damping - ∫Joule - ∫P_contact_joule| / max |∫P_circuit|.
    With friction (``power_friction``, ``friction_dissipated``, ``energy_friction`` in ``s``):
    the work of the friction forces ∫P_friction (W_f) is dissipated work beside ∫P_damping in
    the mechanical and total balances; ``friction_work_mJ`` W_f, ``friction_dissipated_mJ`` the
    return maps' dissipated energy D and ``friction_elastic_energy_mJ`` the springs' energy
    E_T at the end (W_f = D + E_T up to the first-order error of the return map's estimate).
    With friction at the projectile's sphere contact (``power_friction_sphere``,
    ``friction_dissipated_sphere``, ``energy_friction_sphere``; rve.scenes.impact.friction):
    W_f, D and E_T are the sums of both frictions', and ``friction_work_sphere_mJ``,
    ``friction_dissipated_sphere_mJ``, ``friction_elastic_energy_sphere_mJ`` the sphere's."""
    t = np.asarray(s["t"], float)
    g = {k: np.asarray(v, float) for k, v in s.items() if k != "terminal_currents"}
    I_in = g["current_in"]
    charge = np.abs(I_in - g["current_out"] - g["current_leak"])
    P_el = g["power_circuit"]
    elec = np.abs(P_el - g["power_joule"] - g["power_contact_joule"] - g["power_lorentz"])
    Em = g["energy_kinetic"] + g["energy_strain"] + g["energy_contact"]
    W_d = _cumtrapz(t, g["power_damping"])
    fric = [k for k in ("", "_sphere") if "power_friction" + k in g]
    if fric:
        # friction (rve.scenes.dynamic_friction, rve.scenes.impact.friction): the work taken
        # from the motion by the friction forces, by the trapezoid rule like every other
        # power here (the return maps' dissipated energy plus the springs' energy is a
        # backward-Euler estimate of the same work: first order in h, docs/impact.md
        # "Friction between fibrils")
        W_fk = {k: _cumtrapz(t, g["power_friction" + k]) for k in fric}
        W_f = sum(W_fk.values())
        W_dis = W_d + W_f
    else:
        W_dis = W_d
    dEm = Em - Em[0]
    W_L = _cumtrapz(t, g["power_lorentz"])
    mech = np.abs(dEm + W_dis - W_L)
    Q_J = _cumtrapz(t, g["power_joule"])
    Q_out = _cumtrapz(t, g["heat_out"])
    dH = g["heat_content"] - g["heat_content"][0]
    therm = np.abs(dH + Q_out - Q_J)
    W_el = _cumtrapz(t, P_el)
    W_cj = _cumtrapz(t, g["power_contact_joule"])
    total = np.abs(W_el - dEm - W_dis - Q_J - W_cj)
    tiny = 1e-300
    return {
        "charge": float(charge.max() / max(np.abs(I_in).max(), tiny)),
        "electrical": float(elec.max() / max(np.abs(P_el).max(), tiny)),
        "mechanical": float(mech.max() / max(np.abs(W_L).max(), np.abs(dEm).max(), tiny)),
        "thermal": float(therm.max() / max(np.abs(Q_J).max(), tiny)) if Q_J.max() > 0 else 0.0,
        "total": float(total.max() / max(np.abs(W_el).max(), tiny)),
        "work_lorentz_mJ": float(W_L[-1]), "work_circuit_mJ": float(W_el[-1]), "joule_heat_mJ": float(Q_J[-1]),
        "damping_mJ": float(W_d[-1]), "delta_mechanical_energy_mJ": float(dEm[-1]),
        **({"friction_work_mJ": float(W_f[-1]),
            "friction_dissipated_mJ": sum(float(g["friction_dissipated" + k][-1] - g["friction_dissipated" + k][0])
                                          for k in fric),
            "friction_elastic_energy_mJ": sum(float(g["energy_friction" + k][-1]) for k in fric)} if fric else {}),
        **({"friction_work_sphere_mJ": float(W_fk["_sphere"][-1]),
            "friction_dissipated_sphere_mJ": float(g["friction_dissipated_sphere"][-1]
                                                   - g["friction_dissipated_sphere"][0]),
            "friction_elastic_energy_sphere_mJ": float(g["energy_friction_sphere"][-1])} if "_sphere" in fric else {}),
        "series": {"mechanical_residual": dEm + W_dis - W_L, "thermal_residual": dH + Q_out - Q_J,
                   "total_residual": W_el - dEm - W_dis - Q_J - W_cj, "charge_residual": I_in - g["current_out"]
                   - g["current_leak"], "electrical_residual": P_el - g["power_joule"] - g["power_contact_joule"]
                   - g["power_lorentz"]},
    }


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


class ImpactBalances:
    def __init__(self, problem, thermal):
        self.p = problem
        sysm = problem.system
        self.sysm = sysm
        self.thermal = thermal
        self.fab = StateBalances(sysm.fabric, thermal, problem.circuit_in, problem.circuit_leak, problem.dirichlet_V)
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

    def __call__(self, x, w, t, T, F=None) -> dict:
        sysm = self.sysm
        xf, xp = sysm.split(x)
        wf, wp = sysm.split(w)
        if hasattr(self.thermal, "set_state"):
            self.thermal.set_state(x)
        Fs, _, _ = sysm.sphere_terms(x, jacobian=False)
        # the whole residual's fabric rows are the fabric's plus the sphere contact's
        # (ImpactSystem.evaluate); the sphere term has no V rows, so the fabric's currents
        # read the same entries either way
        Ff = None if F is None else np.asarray(F, float)[: sysm.nf] - Fs[: sysm.nf]
        b = self.fab(xf, wf, t, T, Ff)
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
        F_rows = self.fab.last_F + Fs[: sysm.nf] if F is None else np.asarray(F, float)[: sysm.nf]
        b.update({
            "momentum_projectile": P_p, "momentum_total": P_f + P_p, "momentum_pinned": Mw_f[self.pinned].sum(axis=0),
            "force_sphere_on_projectile": fS, "force_lorentz_projectile": fL_p, "force_lorentz": fL_f + fL_p,
            "force_damping": -self.damp * P_f, "force_clamp_static": F_rows[self.pinned].sum(axis=0),
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
