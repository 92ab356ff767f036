"""Dynamic wire scene (thesis §6.4): analytical checks that can fail, the decoupled-T path,
step control and failure handling, outputs."""
import logging

import numpy as np
import pytest

from rve.config.dynamic_wire import DynamicWireConfig
from rve.scenes.dynamic_wire import initial_state, run, setup, solve
from rve.scenes.protocol import SceneFailure
from rve.solvers.dirk import consistent_initialization


def config(**sections):
    cfg = DynamicWireConfig(scene="dynamic_wire")
    for dotted, value in sections.items():
        sec, key = dotted.split("__")
        setattr(getattr(cfg, sec), key, value)
    return cfg


def test_voltage_divider_at_rest():
    """t = 0, wire at rest, T = 0: V is linear, V(l = 1/2) = 2/5 * 3/4 - 1/5 = 0.1 V."""
    cfg = config()
    model = setup(cfg)
    x, w = initial_state(model)
    w, _ = consistent_initialization(model, x, w, 0.0, {"atol": 1e-14, "rtol": 1e-14})
    V = model.nodal(w)[:, model.oV]
    s = model.mesh.node_s
    assert np.allclose(V, -0.2 + 0.4 * s / 2.0, atol=1e-13)
    out = solve(cfg, steps=2, record=False, stages=1).summary
    assert abs(out["V_half_initial"] - 0.1) < 1e-12


def heated_rod_config():
    # B = 0: nothing moves; T still couples back (Seebeck, mu(T)), and the steady state of
    # the discrete problem is exact at the nodes (P1, uniform current => uniform Joule source)
    cfg = config(load__field_magnitude=0.0, time__stages=1, time__steps=40)
    m = cfg.material
    tau = m.density * m.heat_capacity * 4.0 / (np.pi**2 * m.thermal_conductivity)
    cfg.time.t_max = 60 * tau
    cfg.newton.atol = 1e-11  # the slowest thermal mode is ~400x weaker than the scaled residual
    return cfg


def test_resistively_heated_rod_reaches_the_parabola_and_ohms_law():
    cfg = heated_rod_config()
    result = solve(cfg, record=False)
    model, x, w = result.model, result.state["x"], result.state["w"]
    m = cfg.material
    Lw = 2.0 * cfg.geometry.half_length
    A = np.pi * cfg.fibril.radius**2
    dV = cfg.load.voltage_right - cfg.load.voltage_left
    E_field = dV / Lw
    s = model.mesh.node_s
    T_exact = m.electrical_conductivity * E_field**2 / (2 * m.thermal_conductivity) * s * (Lw - s)
    T = model.nodal(w)[:, model.oT]
    assert T_exact.max() > 0.5  # a real heating
    assert np.abs(T - T_exact).max() < 1e-8 * T_exact.max()
    # Ohm's law: I = dV sigma0 A / length (current along -e1: from +0.2 V at +L to -0.2 V)
    I = model.axial_current(x, w)
    assert np.allclose(I, -dV * m.electrical_conductivity * A / Lw, rtol=1e-9)
    # the Seebeck EMF bends V away from the straight line by -S (T - 0)
    V = model.nodal(w)[:, model.oV]
    assert np.allclose(V, -0.2 + dV * s / Lw - m.seebeck * T, atol=1e-10)
    # current in = current out
    ends = model.end_currents(x, w)[0]
    assert abs(ends[0] + ends[1]) < 1e-12 * abs(ends[0])


def test_current_in_equals_current_out_at_steady_state_with_a_circuit():
    """Moving wire with a resistor circuit at +L, damped to rest: the current entering at -L
    equals the current leaving at +L, the circuit current and the current everywhere, and
    equals (V_ext - V_left) / (R + R_wire) (the Seebeck EMF integrates to 0 with T(0) = T(L))."""
    R = 50.0  # ohm
    # near-critical damping of the swing (gamma / rho ~ 2 omega_1) and L-stable steps
    cfg = config(load__circuit_resistance=R, material__damping=5e-5, time__stages=1, time__steps=60)
    cfg.time.t_max = 0.015
    result = solve(cfg, record=False)
    out = result.summary
    model, x, w = result.model, result.state["x"], result.state["w"]
    assert np.abs(w[model.mech]).max() < 1e-4  # at rest (velocities while moving: ~100 mm/ms)
    m = cfg.material
    A = np.pi * cfg.fibril.radius**2
    R_wire = 2.0 / (m.electrical_conductivity * A)
    I_exact = (cfg.load.voltage_right - cfg.load.voltage_left) / (R + R_wire)
    ends = model.end_currents(x, w)[0]  # leaving through (-L, +L)
    assert abs(ends[0] + ends[1]) < 1e-9 * abs(ends[1])
    n1 = model.mesh.end_nodes(0)[1]
    V1 = model.nodal(w)[n1, model.oV]
    I_circuit = (V1 - cfg.load.voltage_right) / R  # leaving +L through the resistor
    assert np.isclose(ends[1], I_circuit, rtol=1e-9)
    # (a residual velocity v ~ 1e-4 mm/ms leaves a back-EMF ~ 1e-7 V/mm against 0.2 V/mm)
    assert np.allclose(model.axial_current(x, w), -I_exact, rtol=1e-5)
    assert np.isclose(ends[1], -I_exact, rtol=1e-5)
    # the wire is bent by the Lorentz force at steady state
    assert out["probes"]["y0"] > 1e-3


def test_newton_is_quadratic_within_a_stage(caplog):
    """Large steps (h = t_max / 6) make the stage solves long enough to see the rate: the
    observed orders log(r_k/r_k-1)/log(r_k-1/r_k-2) above the rounding floor are ~2."""
    cfg = config()
    with caplog.at_level(logging.INFO, logger="rve.newton"):
        out = solve(cfg, stages=2, steps=6, record=False).summary
    nw = out["newton"]
    assert nw["rates_counted"] >= 5
    assert 1.7 < nw["observed_orders_median"] < 3.5
    assert any("rate=" in r.getMessage() for r in caplog.records)
    res = nw["example_stage_residuals"]
    assert len(res) >= 3 and res[-1] < 1e-8


def test_decoupled_temperature_is_post_solved_with_fewer_dofs():
    """alpha_mu = S = 0: T does not feed back; 'auto' drops the T dofs and solves T after the
    run; the result matches the monolithic (mech, T, V) solve to the time-discretisation error."""
    kw = dict(material__alpha_mu=0.0, material__seebeck=0.0, time__steps=40)
    cfg = config(**kw)
    cfg.time.t_max = 1e-3
    post = solve(cfg, record=False).summary
    assert post["temperature_mode"] == "post"
    n = cfg.mesh.elements + 1
    assert post["dofs"]["coupled_solve"] == {"mech": 9 * n, "V": n, "total": 10 * n}
    assert post["dofs"]["thermal_post_solve"]["total"] == n
    cfg2 = config(**kw, couplings__temperature="coupled")
    cfg2.time.t_max = 1e-3
    mono = solve(cfg2, record=False).summary
    assert mono["dofs"]["coupled_solve"]["total"] == 11 * n
    for k in ("y0", "z_half", "V_half"):
        assert abs(post["probes"][k] - mono["probes"][k]) <= 1e-9 * max(1e-3, abs(mono["probes"][k]))
    assert abs(post["probes"]["T_half"] - mono["probes"]["T_half"]) < 2e-3 * abs(mono["probes"]["T_half"])


def test_post_mode_refused_when_T_feeds_back():
    cfg = config(couplings__temperature="post")
    with pytest.raises(ValueError, match="feeds back"):
        solve(cfg, steps=1).summary


def test_failed_fixed_step_run_saves_last_good_state(tmp_path):
    # backward Euler with 6 fixed steps cannot start the swing (see the stability benchmark)
    cfg = config(time__stages=1, time__steps=6, time__step_control=False, load__field_ramp_time=0.0)
    with pytest.raises(SceneFailure) as info:
        run(cfg, tmp_path)
    msg = str(info.value)
    assert "t = 0 ms" in msg and f"h = {cfg.time.t_max / 6:.6g} ms" in msg and "residual history" in msg
    data = np.load(tmp_path / "dynamic_wire_last_good_state.npz")
    assert data["x"].shape == data["w"].shape and float(data["t"]) == 0.0
    assert len(data["residuals"]) > 1
    assert info.value.phase == "time integration" and info.value.saved.endswith("last_good_state.npz")


def test_run_writes_history_and_summary(tmp_path):
    import xarray as xr

    cfg = config(time__steps=20)
    cfg.time.t_max = 2e-4
    out = run(cfg, tmp_path)
    assert out["dofs"]["coupled_solve"]["total"] == 11 * 41
    assert set(out["probes"]) == {"y0", "z_half", "T_half", "V_half"}
    ds = xr.open_dataset(tmp_path / "dynamic_wire_history.nc")
    assert ds.sizes["time"] == 21
    assert ds["V_half"].attrs["units"] == "V" and ds["T_half"].attrs["units"] == "K"
    assert abs(float(ds["V_half"][0]) - 0.1) < 1e-12
    assert np.isclose(float(ds["time"][-1]), 2e-4)
    ds.close()


def test_config_file_loads():
    from rve.config.loader import load_config

    cfg = load_config("configs/scenes/dynamic_wire.yaml")
    assert cfg.scene == "dynamic_wire"
    assert np.isclose(cfg.load.field_magnitude, 1e-3)
    assert np.isclose(cfg.material.damping, 1e-11)
    assert np.isclose(cfg.time.t_max, 2.1e-3)


def test_study_dataset_orders_and_plots(tmp_path):
    """The study's gather step on synthetic records with known orders, and one real point."""
    import xarray as xr

    from rve.studies.dynamic_wire import PROBE_NAMES, build_dataset, normalise_plan, run_point, write_study

    plan = normalise_plan({"series": {1: {"steps": [10, 20, 40], "fit": [10, 40]},
                                      3: {"steps": [10, 20, 40], "fit": [20, 40]}}})
    ref = {k: 1.0 + i for i, k in enumerate(PROBE_NAMES)}
    pts = []
    for s in (1, 3):
        for n in (10, 20, 40):
            pts.append({"stages": s, "steps": n, "wall_time_s": 0.1 * n * s, "newton_iterations": 2 * n * s,
                        "probes": {k: ref[k] + (-1) ** i * 3.0 * n ** (-s) for i, k in enumerate(PROBE_NAMES)}})
    reference = {"stages": 3, "steps": 1500, "probes": ref, "wall_time_s": 1.0, "t_max": 2.7e-3,
                 "V_half_initial": 0.1}
    ds = build_dataset(pts, reference, plan)
    for k in PROBE_NAMES:
        assert np.allclose(ds[f"order_{k}"].values, [1.0, 3.0], atol=1e-9)
        assert ds[k].attrs["units"] and ds[k].attrs["long_name"]
    assert ds.sizes == {"stages": 2, "steps": 3}
    write_study(ds, tmp_path / "dw.nc", tmp_path / "orders.md", tmp_path / "err.png", tmp_path / "wp.png")
    back = xr.open_dataset(tmp_path / "dw.nc")
    assert float(back["order_T_half"].sel(stages=3)) == pytest.approx(3.0)
    back.close()
    assert (tmp_path / "err.png").stat().st_size > 0 and "| 3 |" in (tmp_path / "orders.md").read_text()
    cfg = config()
    cfg.time.t_max = 1e-4
    rec = run_point(cfg, 2, 4)
    assert rec["steps"] == 4 and np.isfinite(rec["probes"]["V_half"])
    # the study passes integrator options to every run (no module patching)
    assert run_point(cfg, 2, 4, {"jacobian_reuse": False})["probes"] == rec["probes"]
    with pytest.raises(ValueError, match="predictor_degree"):
        run_point(cfg, 2, 4, {"predictor_degree": 7})
