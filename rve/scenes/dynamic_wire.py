"""Scene: the dynamic wire (thesis §6.4, Tables 6.3-6.4): current, heat and motion coupled.

Contract (the scene protocol, rve.scenes.protocol)
--------------------------------------------------
``setup(cfg, mode=None) -> BeamModel`` builds the wire of a validated ``DynamicWireConfig``
(rve.config.dynamic_wire) with its boundary conditions; ``solve(cfg, ...) -> SceneResult``
integrates from rest to ``t_max`` with the SDIRK scheme of ``cfg.time.stages`` in memory
(``state``: ``x``, ``w`` at t_max and, with the temperature post-solved, ``T``; ``model``:
the ``BeamModel``; ``summary``: the figures below, with the probe history under
``"history"`` when ``record``); ``run(cfg, out_dir) -> dict`` returns the summary: the probes
``y0`` (centre centroid y), ``z_half``, ``T_half``, ``V_half`` (at l = 1/2, a quarter of the
way from the +L end... i.e. X1 = L/2) at t_max, ``V_half_initial`` (t = 0, the voltage
divider, 0.1 V for Table 6.3), the dofs per field (``dofs``) of each solve, Newton
statistics (iterations, observed convergence rates of the stage solves), step-control
statistics and wall times. It writes ``out_dir/dynamic_wire_history.nc`` (probe time
history, netCDF, written atomically). When the time integration gives up, ``solve`` raises
``SceneFailure`` (phase "time integration", the time, the step size and the Newton
residual history, the last good state); ``run`` then writes that state to
``out_dir/dynamic_wire_last_good_state.npz`` (and the history so far) and re-raises.

Set-up: the wire lies along e1 from -L to L (straight natural configuration, directors
G1 = e2, G2 = e3), centroids pinned at both ends, the sections free to rotate;
B = |B| (cos phi, 0, sin phi); V = voltage_left / voltage_right at the ends (or a resistor
circuit at +L), T = end_temperature at both ends; everything starts at rest with T = 0 and
V consistent (solved at t = 0). The current along +e1 (from +0.2 V at +L to -0.2 V at -L
flows along -e1: the Lorentz force I r' x B then points along +e2) bends the wire, whose
motion induces the back-EMF; T enters through mu(T) and the Seebeck EMF. Parameters that
Table 6.3 lacks and the reading of its garbled entries: docs/coupled_fields.md.

Dofs: "only what a scene needs": with T feeding back (alpha_mu or S non-zero) the monolithic
solve has (mech, T, V) = 11 dofs a node; otherwise (mech, V) = 10 a node and T is solved
afterwards (``ThermalPostSystem``) from the stored Joule heat history.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from ..fem.assembly import DofLayout
from ..fem.lagrange import lagrange_basis
from ..fem.mesh import fibril_mesh, straight_fibril
from ..model import (
    BeamMaterial, BeamModel, CircuitBC, Couplings, DirichletBC, RowScaledSystem, ThermalPostSystem,
    feedback_from_temperature,
)
from ..solvers.dirk import IntegrationFailure, consistent_initialization, integrate
from ..solvers.dirk import integrator_options as integrator_options_of
from .protocol import SceneFailure, SceneResult

__all__ = ["setup", "initial_state", "probes", "solve", "run", "PROBES", "newton_options", "temperature_mode",
           "field_ramp", "history_dataset"]

log = logging.getLogger("rve.scenes.dynamic_wire")

#: probe name -> (long name, unit)
PROBES = {
    "y0": ("centroid y displacement at the centre, l = 0", "mm"),
    "z_half": ("centroid z displacement at l = 1/2", "mm"),
    "T_half": ("temperature change at l = 1/2", "K"),
    "V_half": ("electric potential at l = 1/2", "V"),
}


def temperature_mode(cfg) -> str:
    mat = _material(cfg)
    mode = cfg.couplings.temperature
    fb = feedback_from_temperature(mat, _couplings(cfg))
    if mode == "auto":
        return "coupled" if fb else "post"
    if mode == "post" and fb:
        raise ValueError("couplings.temperature = 'post' but T feeds back (alpha_mu or the Seebeck "
                         "coefficient is on): use 'coupled' or 'auto'")
    return mode


def _material(cfg) -> BeamMaterial:
    m = cfg.material
    return BeamMaterial(
        youngs_modulus=m.youngs_modulus, poisson_ratio=m.poisson_ratio, density=m.density, damping=m.damping,
        electrical_conductivity=m.electrical_conductivity, seebeck=m.seebeck, heat_capacity=m.heat_capacity,
        thermal_conductivity=m.thermal_conductivity, alpha_mu=m.alpha_mu)


def _couplings(cfg, with_T: bool = True) -> Couplings:
    c = cfg.couplings
    phi = cfg.load.field_angle
    B = cfg.load.field_magnitude * np.array([np.cos(phi), 0.0, np.sin(phi)])
    return Couplings(B=tuple(B), lorentz=c.lorentz, back_emf=c.back_emf, joule=c.joule and with_T,
                     seebeck=c.seebeck and with_T, thermal_softening=c.thermal_softening and with_T)


def setup(cfg, mode: str | None = None) -> BeamModel:
    """The model of the scene; ``mode`` 'coupled' (T dofs) or 'post' (no T dofs)."""
    mode = mode or temperature_mode(cfg)
    L = cfg.geometry.half_length
    R = cfg.fibril.radius
    mesh = fibril_mesh([straight_fibril([-L, 0, 0], [L, 0, 0], R, "wire")], cfg.mesh.elements, cfg.mesh.order)
    with_T = mode == "coupled"
    fields = ("mech", "T", "V") if with_T else ("mech", "V")
    n0, n1 = mesh.end_nodes(0)
    layout = DofLayout(mesh.n_nodes, fields)
    bcs = [DirichletBC(layout.dofs("r", n0), 0.0),
           DirichletBC(layout.dofs("r", n1), 0.0)]
    circuits = []
    if cfg.load.circuit_resistance is None:
        bcs.append(DirichletBC(layout.dofs("V", [n0, n1]),
                               np.array([cfg.load.voltage_left, cfg.load.voltage_right])))
    else:
        bcs.append(DirichletBC(layout.dofs("V", n0), cfg.load.voltage_left))
        circuits.append(CircuitBC.resistor(n1, cfg.load.circuit_resistance, cfg.load.voltage_right, np.pi * R**2))
    if with_T:
        bcs.append(DirichletBC(layout.dofs("T", [n0, n1]), cfg.load.end_temperature))
    return BeamModel(mesh, _material(cfg), disk_points=cfg.mesh.disk_points, axial_points=cfg.mesh.axial_points,
                     fields=fields, bcs=bcs, couplings=_couplings(cfg, with_T), circuits=circuits,
                     field_ramp=field_ramp(cfg.load.field_ramp_time))


def field_ramp(t_r: float):
    """The switch-on of B: 0 -> 1 over [0, t_r] by the C2 quintic s^3 (10 - 15 s + 6 s^2)
    (None for t_r = 0: a step, B on at t = 0 as in the thesis)."""
    if not t_r > 0:
        return None

    def ramp(t):
        s = min(max(t / t_r, 0.0), 1.0)
        return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)

    return ramp


def initial_state(model: BeamModel):
    x = np.zeros(model.n)
    w = np.zeros(model.n)
    model.nodal(x)[:, :9] = model.mesh.X0
    return x, w


def _probe_weights(model: BeamModel, s: float):
    """(nodes, weights) interpolating a nodal field at reference arc length s."""
    mesh = model.mesh
    h = mesh.elem_length[0]
    e = min(int(np.floor(s / h + 1e-12)), mesh.n_elements - 1)
    s0 = mesh.node_s[mesh.conn[e, 0]]
    t = 2.0 * (s - s0) / mesh.elem_length[e] - 1.0
    N, _ = lagrange_basis(mesh.order, np.array([t]))
    return mesh.conn[e], N[0]


class _Probes:
    def __init__(self, model: BeamModel, L: float):
        self.model = model
        self.c_nodes, self.c_w = _probe_weights(model, L)          # l = 0   (X1 = 0)
        self.q_nodes, self.q_w = _probe_weights(model, 1.5 * L)    # l = 1/2 (X1 = L/2)

    def __call__(self, x, w, T_nodal=None) -> dict:
        xn, wn = self.model.nodal(x), self.model.nodal(w)
        m = self.model
        out = {
            "y0": float(self.c_w @ (xn[self.c_nodes, 1] - m.mesh.X0[self.c_nodes, 1])),
            "z_half": float(self.q_w @ (xn[self.q_nodes, 2] - m.mesh.X0[self.q_nodes, 2])),
            "V_half": float(self.q_w @ wn[self.q_nodes, m.oV]),
        }
        if T_nodal is not None:
            out["T_half"] = float(self.q_w @ T_nodal[self.q_nodes])
        elif m.has_T:
            out["T_half"] = float(self.q_w @ wn[self.q_nodes, m.oT])
        return out


def probes(model: BeamModel, x, w, L: float = 1.0) -> dict:
    return _Probes(model, L)(x, w)


def newton_options(cfg) -> dict:
    return {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}


def _rates_summary(stage_residuals: list, floor: float = 1e-9) -> dict:
    """Observed Newton orders q_k = log(r_k/r_k-1)/log(r_k-1/r_k-2) over all stage solves,
    counting only triples whose last residual is above ``floor`` (the scaled residual has a
    rounding floor of ~1e-11..1e-10 that rises as 1/h: a rate that ends on it says nothing
    about the Newton iteration), and one example history (the longest)."""
    rates = []
    example = None
    for res in stage_residuals:
        r = np.asarray(res, float)
        for k in range(2, len(r)):
            if r[k] >= floor and 0 < r[k - 1] / r[k - 2] < 1 and r[k] < r[k - 1]:
                rates.append(float(np.log(r[k] / r[k - 1]) / np.log(r[k - 1] / r[k - 2])))
        if len(res) >= 3 and (example is None or len(res) > len(example)):
            example = list(res)
    return {
        "observed_orders_median": float(np.median(rates)) if rates else float("nan"),
        "observed_orders_min": float(np.min(rates)) if rates else float("nan"),
        "rates_counted": len(rates),
        "rate_floor": floor,
        "example_stage_residuals": example or [],
    }


class _History:
    """The probe history of a run (every ``every`` accepted steps and at t_max), the stage
    residuals and, for the temperature post-solve, the Joule heat of every accepted step."""

    def __init__(self, model, probe, mode, every: int, t_max: float, record: bool, x0, w0):
        self.model, self.probe, self.mode = model, probe, mode
        self.every, self.t_max, self.record = every, t_max, record
        self.p0 = p0 = probe(x0, w0)
        if mode == "post":
            p0["T_half"] = 0.0
        self.hist = {"t": [0.0], **{k: [p0[k]] for k in p0}, "current_mid": [], "h": [0.0], "newton_iterations": [0]}
        self.joule_t, self.joule_Q = [0.0], [model.joule_power(x0, w0, 0.0)] if mode == "post" else []
        self.mid_elem = model.mesh.n_elements // 2
        self.hist["current_mid"].append(float(model.axial_current(x0, w0, 0.0)[self.mid_elem - 1, -1]))
        self.stage_res: list = []
        self.count = 0

    def on_step(self, t, x, w, info) -> None:
        model, hist = self.model, self.hist
        self.stage_res.extend(info.stage_residuals)
        if self.mode == "post":
            self.joule_t.append(t)
            self.joule_Q.append(model.joule_power(x, w, t))
        self.count += 1
        if self.record and (self.count % self.every == 0 or t >= self.t_max * (1 - 1e-12)):
            for k, v in self.probe(x, w).items():
                hist[k].append(v)
            hist["t"].append(t)
            if self.mode == "post":
                hist["T_half"].append(np.nan)
            hist["current_mid"].append(float(model.axial_current(x, w, t)[self.mid_elem - 1, -1]))
            hist["h"].append(info.h)
            hist["newton_iterations"].append(info.newton_iterations)


def _failure(exc, model, hist, mode) -> SceneFailure:
    """The scene's failure for a failed integration (the last good state, the history)."""
    res = ", ".join(f"{r:.3e}" for r in exc.residuals)
    return SceneFailure(
        "dynamic_wire",
        f"time integration failed with step size h = {exc.h:.6g} ms; Newton residual history [{res}]. "
        f"Cause: {exc}",
        phase="time integration", time=exc.t, step=f"h = {exc.h:.6g} ms",
        state={"x": exc.x, "w": exc.w}, model=model,
        details={"h": exc.h, "residuals": [float(r) for r in exc.residuals], "history": hist,
                 "temperature_mode": mode,
                 "reason": exc.step_failure.reason if exc.step_failure is not None else str(exc)})


def _post_temperature(model, cfg, joule_t, joule_Q, steps, stages, nopts, fixed, iopts) -> dict:
    """T afterwards: the heat equation alone over the stored Joule history, same scheme and
    steps (``steps``, ``newton_iterations``, the final nodal ``T``)."""
    n0, n1 = model.mesh.end_nodes(0)
    tsys = ThermalPostSystem(model, np.asarray(joule_t), np.asarray(joule_Q), [n0, n1], cfg.load.end_temperature)
    Tsc = RowScaledSystem(tsys, 1.0 / np.asarray(abs(tsys.mass()).sum(axis=1)).ravel())
    T0 = np.zeros(tsys.n)
    tres = integrate(Tsc, np.zeros(tsys.n), T0, 0.0, cfg.time.t_max, steps, stages=stages, newton_opts=nopts,
                     consistent=False,
                     **integrator_options_of(max_cuts=cfg.time.max_cuts, fixed_step=fixed, **iopts))
    return {"steps": tres.steps, "newton_iterations": tres.newton_iterations, "T": tres.w}


def solve(cfg, *, stages: int | None = None, steps: int | None = None, fixed_step: bool | None = None,
          record: bool = True, progress: bool = False, integrator_options: dict | None = None) -> SceneResult:
    """Run the scene in memory. Raises ``SceneFailure`` (carrying the last good state).
    ``integrator_options`` go to ``rve.solvers.dirk.integrate`` (e.g. ``predictor_degree``,
    ``lazy_jacobian``: the solver variants compared by benchmarks/dirk_stage_cost.py)."""
    iopts = dict(integrator_options or {})
    t_start = time.perf_counter()
    stages = int(stages or cfg.time.stages)
    steps = int(steps or cfg.time.steps)
    fixed = (not cfg.time.step_control) if fixed_step is None else bool(fixed_step)
    mode = temperature_mode(cfg)
    model = setup(cfg, mode)
    L = cfg.geometry.half_length
    t_max = cfg.time.t_max
    h0 = t_max / steps
    nopts = newton_options(cfg)
    probe = _Probes(model, L)
    x0, w0 = initial_state(model)
    system = model.with_row_scale(model.row_scales(h0, x0, w0))
    w0, init_res = consistent_initialization(system, x0, w0, 0.0, nopts)
    rec = _History(model, probe, mode, cfg.time.history_every, t_max, record, x0, w0)
    p0, hist, joule_t, joule_Q, stage_res = rec.p0, rec.hist, rec.joule_t, rec.joule_Q, rec.stage_res
    t1 = time.perf_counter()
    try:
        res = integrate(system, x0, w0, 0.0, t_max, steps, stages=stages, newton_opts=nopts, on_step=rec.on_step,
                        progress=progress, consistent=False,
                        **integrator_options_of(max_cuts=cfg.time.max_cuts, fixed_step=fixed, **iopts))
    except IntegrationFailure as exc:
        raise _failure(exc, model, hist, mode) from exc
    t2 = time.perf_counter()
    x, w = res.x, res.w
    out_probes = probe(x, w)
    dofs = {"coupled_solve": model.dof_counts()}
    post = None
    if mode == "post":
        post = _post_temperature(model, cfg, joule_t, joule_Q, steps, stages, nopts, fixed, iopts)
        out_probes["T_half"] = float(probe.q_w @ post["T"][probe.q_nodes])
        dofs["thermal_post_solve"] = {"T": int(post["T"].size), "total": int(post["T"].size)}
    t3 = time.perf_counter()
    ends = model.end_currents(x, w, t_max)[0]
    out = {
        "probes": out_probes,
        "V_half_initial": p0["V_half"],
        "temperature_mode": mode,
        "fields": list(model.layout.fields),
        "dofs": dofs,
        "stages": stages,
        "steps_nominal": steps,
        "steps_accepted": res.steps,
        "steps_rejected": res.rejected,
        "h_nominal": h0,
        "h_min": res.h_min,
        "fixed_step": fixed,
        "newton_iterations": res.newton_iterations + (init_res.iterations if init_res is not None else 0),
        "newton_iterations_per_stage": res.newton_iterations / max(1, len(stage_res)),
        "newton": _rates_summary(stage_res),
        "end_currents_out": [float(ends[0]), float(ends[1])],
        "wall_time_s": {"setup": t1 - t_start, "integration": t2 - t1, "thermal_post": t3 - t2,
                        "total": t3 - t_start},
    }
    if record:
        out["history"] = {k: np.asarray(v, float) for k, v in hist.items()}
    state = {"x": x, "w": w}
    if post is not None:
        state["T"] = post["T"]
    return SceneResult(state=state, model=model, summary=out)


def history_dataset(hist: dict, attrs: dict | None = None):
    import xarray as xr

    t = np.asarray(hist["t"])
    data = {}
    for k, (long, unit) in PROBES.items():
        if k in hist and len(hist[k]) == len(t):
            data[k] = ("time", np.asarray(hist[k], float), {"long_name": long, "units": unit})
    if len(hist.get("current_mid", [])) == len(t):
        data["current_mid"] = ("time", np.asarray(hist["current_mid"]),
                               {"long_name": "current through the section next to the centre (along +e1)",
                                "units": "A"})
    data["h"] = ("time", np.asarray(hist["h"]), {"long_name": "accepted step size", "units": "ms"})
    data["newton_iterations"] = ("time", np.asarray(hist["newton_iterations"], float),
                                 {"long_name": "Newton iterations of the step (all stages)", "units": "1"})
    ds = xr.Dataset(data, coords={"time": ("time", t, {"long_name": "time", "units": "ms"})})
    ds.attrs.update(attrs or {})
    return ds


def _write_history(path: Path, hist: dict, attrs: dict) -> None:
    from ..io.atomic import atomic_path

    ds = history_dataset(hist, attrs)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp)


def run(cfg, out_dir: Path) -> dict:
    out_dir = Path(out_dir)
    attrs = {"scene": "dynamic_wire", "source": "rve.scenes.dynamic_wire"}
    try:
        out = solve(cfg, record=True).summary
    except SceneFailure as failure:
        failure.save(out_dir / "dynamic_wire_last_good_state.npz")
        hist = failure.details.get("history")
        if hist is not None and len(hist["t"]) > 1:
            coupled = failure.details.get("temperature_mode") == "coupled"
            hist = {k: v for k, v in hist.items() if k != "T_half" or coupled}
            _write_history(out_dir / "dynamic_wire_history.nc", hist, {**attrs, "status": "aborted"})
        log.error("%s", failure)
        raise
    hist = out.pop("history")
    if out["temperature_mode"] == "post":
        hist.pop("T_half", None)  # T is solved after the run; only its final value is known
    _write_history(out_dir / "dynamic_wire_history.nc", hist, attrs)
    out["history_file"] = str(out_dir / "dynamic_wire_history.nc")
    return out
