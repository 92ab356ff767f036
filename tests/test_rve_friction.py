"""Friction through the RVE pipeline (docs/contact.md "Friction in the RVE pipeline"):
the config section and its refusals, the history through the phases, steps and
checkpoints of the strain path (resume bit for bit), the table's friction variables."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rve.config import ConfigError, validate_config

#: a tiny cell: 2 x 2 plain weave, one fibril per yarn, 8 elements (8 contact points)
TINY = {"scene": "rve", "fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]}, "mesh": {"elements": 8},
        "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2, "static_atol": 1e-9,
                       "static_max_iter": 40},
        "strain": {"modes": ["shear"], "total": 0.1, "steps": 2, "static_atol": 1e-9, "static_max_iter": 40,
                   "follow_branch": False},
        "output": {"pictures": False}}


def _spec(mu: float, **strain) -> dict:
    scene = {**TINY, "friction": {"coefficient": mu}, "strain": {**TINY["strain"], **strain}}
    return {"scene_config": None, "overrides": [], "scene": scene}


# --------------------------------------------------------------------------- config
def test_friction_is_off_by_default_and_the_section_validates():
    cfg = validate_config({"scene": "rve"})
    assert cfg.friction.coefficient == 0 and not cfg.has_friction
    on = validate_config({**TINY, "friction": {"coefficient": 0.3, "pairs": {"warp-weft": 0.2}}})
    assert on.has_friction and on.friction.law_args() == (0.3, 1.0, (("warp", "weft", 0.2),))
    with pytest.raises(ConfigError, match=r"friction.coefficient = 2.5: must be >= 0 and <= 2"):
        validate_config({**TINY, "friction": {"coefficient": 2.5}})
    with pytest.raises(ConfigError, match=r"friction.pairs\['warp-weft'\] = 3.0 must be in \[0, 2.0\]"):
        validate_config({**TINY, "friction": {"pairs": {"warp-weft": 3.0}}})


@pytest.mark.parametrize("extra", [
    {"contact": {"geometry": "curve"}, "mesh": {"elements": 8, "order": 2}},
    {"contact": {"geometry": "smooth"}, "mesh": {"elements": 8, "order": 2}},
    {"contact": {"enforcement": "augmented_lagrangian"}},
    {"boundary": "periodic", "fabric": {"kind": "plain", "rows": [1]}},
    {"strain": {**TINY["strain"], "follow_branch": True}},
])
def test_friction_is_accepted_with_every_contact_option_and_cell(extra):
    cfg = validate_config({**TINY, "friction": {"coefficient": 0.2}, **extra})
    assert cfg.has_friction


# --------------------------------------------------------------------------- the strain path
_JOB = """
import json, sys
from rve.homogenisation.jobs import fabric_job, relax_job, strain_job
kind, spec, a, b, step = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3], sys.argv[4], int(sys.argv[5])
if kind == "fabric":
    fabric_job(b, None, spec)
elif kind == "relax":
    relax_job(a, b, None, spec)
else:
    strain_job(a, b, None, spec, "base", "shear", step)
"""


def _job(kind, spec, a, b, step=0):
    """One job in its own process, as Snakemake runs it (a job's bits depend on its input file
    only; within one process the linear solvers' reused analyses may move the last bit)."""
    proc = subprocess.run([sys.executable, "-c", _JOB, kind, json.dumps(spec), str(a), str(b), str(step)],
                          capture_output=True, text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1",
                                                               "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]


def _chain(spec, out, steps=(1, 2), start=None):
    """fabric, relax and the shear steps ``steps`` as jobs, each in its own process from the
    file of the one before; returns the stored states."""
    from rve.homogenisation.checkpoint import load_state

    out.mkdir(parents=True, exist_ok=True)
    if start is None:
        _job("fabric", spec, "", out / "initial.nc")
        _job("relax", spec, out / "initial.nc", out / "relaxed.nc")
    states = {}
    prev = out / ("relaxed.nc" if steps[0] == 1 else f"shear_{steps[0] - 1:02d}.nc")
    for i in steps:
        _job("strain", spec, prev, out / f"shear_{i:02d}.nc", i)
        prev = out / f"shear_{i:02d}.nc"
        states[i] = load_state(prev)
    return states


@pytest.fixture(scope="module")
def frictional_chain(tmp_path_factory):
    out = tmp_path_factory.mktemp("rve_friction")
    return out, _chain(_spec(0.3), out)


def test_steps_with_friction_are_equilibria_with_their_history_in_the_checkpoint(frictional_chain):
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import recomputed_residual
    from rve.homogenisation.sweeps import load_run_config
    from rve.fabrics.setup import fabric_and_mesh

    out, states = frictional_chain
    cfg = load_run_config(_spec(0.3))
    fab, mesh = fabric_and_mesh(cfg)
    relaxed = load_state(out / "relaxed.nc")
    # the relaxation is frictionless: its history has no elastic gap and nothing dissipated
    assert relaxed.friction is not None and relaxed.friction["dissipated"] == 0.0
    d_prev = 0.0
    for i in (1, 2):
        st = load_state(out / f"shear_{i:02d}.nc")
        assert st.friction is not None and len(st.friction["keys"]) > 0
        assert st.solver["converged"] and st.solver["residual_N"] <= 1e-9
        # the stored state is an equilibrium with its friction forces (recomputed from the file) ...
        assert recomputed_residual(cfg, fab, mesh, st.x, friction=st.friction) <= 1e-9
        # ... and not without them: friction holds the sheared crossings
        assert recomputed_residual(cfg, fab, mesh, st.x, friction=None) > 1e-6
        fr = st.solver["friction"]
        assert fr["friction_force"] > 0 and fr["stick"] + fr["slip"] > 0
        # dissipation accumulates along the path (each step's share is >= 0)
        assert st.friction["dissipated"] == pytest.approx(d_prev + fr["step_dissipated"], rel=1e-12, abs=1e-18)
        assert fr["step_dissipated"] >= 0.0
        d_prev = st.friction["dissipated"]


def test_resume_from_a_mid_run_checkpoint_is_bit_identical(frictional_chain, tmp_path):
    """Step 2 of a run resumed from the stored step 1 (a new process that reads only that file)
    equals the uninterrupted run's step 2 bit for bit; step 2 from the same state without its
    friction history is another state (the history matters)."""
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.strain import strain_step
    from rve.homogenisation.sweeps import load_run_config
    from rve.fabrics.setup import fabric_and_mesh

    out, _ = frictional_chain
    resumed = tmp_path / "resumed"
    resumed.mkdir()
    shutil.copy(out / "shear_01.nc", resumed / "shear_01.nc")
    _chain(_spec(0.3), resumed, steps=(2,), start="shear_01")
    a, b = load_state(out / "shear_02.nc"), load_state(resumed / "shear_02.nc")
    np.testing.assert_array_equal(a.x, b.x)
    for k in ("keys", "s_bar", "anchor"):
        np.testing.assert_array_equal(a.friction[k], b.friction[k])
    assert a.friction["dissipated"] == b.friction["dissipated"]
    assert a.reaction_force == b.reaction_force
    # without the history (every contact restarted with no elastic gap): not the same step
    cfg = load_run_config(_spec(0.3))
    fab, mesh = fabric_and_mesh(cfg)
    prev = load_state(out / "shear_01.nc")
    x_forgot, _, _ = strain_step(cfg, fab, mesh, prev.x, prev.origin, "shear", 2, friction=None)
    assert np.abs(x_forgot - a.x).max() > 1e-9


def test_a_frictionless_run_refuses_a_frictional_state_and_vice_versa(frictional_chain, tmp_path):
    from rve.homogenisation.jobs import strain_job

    out, _ = frictional_chain
    with pytest.raises(ValueError, match="carries a friction history but the config has friction.coefficient = 0"):
        strain_job(out / "shear_01.nc", tmp_path / "x.nc", None, _spec(0.0), "base", "shear", 2)


def test_mu_zero_path_is_the_frictionless_path_bit_for_bit(tmp_path):
    """friction.coefficient: 0 builds no friction term: the states equal those of a config
    without the section, bit for bit, and carry no history."""
    from rve.homogenisation.checkpoint import load_state

    spec0 = _spec(0.0)
    plain = {"scene_config": None, "overrides": [], "scene": {k: v for k, v in spec0["scene"].items()
                                                               if k != "friction"}}
    _chain(spec0, tmp_path / "a", steps=(1,))
    _chain(plain, tmp_path / "b", steps=(1,))
    a, b = load_state(tmp_path / "a" / "shear_01.nc"), load_state(tmp_path / "b" / "shear_01.nc")
    np.testing.assert_array_equal(a.x, b.x)
    assert a.friction is None and b.friction is None


def test_probe_records_and_table_carry_the_friction(frictional_chain):
    from rve.homogenisation.jobs import probe_record
    from rve.tables.build import build_table
    from rve.tables.jobs import gather_records

    out, _ = frictional_chain
    spec = _spec(0.3)
    recs = [probe_record(out / f"{n}.nc", spec) for n in ("relaxed", "shear_01", "shear_02")]
    assert recs[0]["friction"]["dissipated_energy"] == 0.0
    assert recs[2]["friction"]["dissipated_energy"] > recs[1]["friction"]["dissipated_energy"] > 0
    ds = build_table(gather_records(recs, ["shear"]), fabric="plain", config={}, swept=None)
    d = ds["friction_dissipated_energy"].sel(mode="shear").values
    assert d[0] == 0.0 and np.all(np.diff(d) > 0)
    for v in ("friction_dissipated_energy", "friction_force", "friction_stick_points", "friction_slip_points"):
        assert ds[v].attrs["units"] and ds[v].attrs["long_name"]
    # a table without friction in its records has none of these variables
    plain = [{k: v for k, v in r.items() if k != "friction"} for r in recs]
    assert "friction_force" not in build_table(gather_records(plain, ["shear"]), fabric="plain", config={})


# --------------------------------------------------------------------------- loading-unloading cycles
def _cycle(mu: float, n: int, out):
    """The shear cycle of the tiny cell on the quasi-static path, n steps per leg, in this
    process (energies, not bits): ``(strain, work_rate, energy, dissipated)`` per cycle step."""
    from rve.homogenisation.jobs import cycle_job, fabric_job, relax_job

    spec = _spec(mu, path="quasi_static", cycle_modes=["shear"], cycle_steps=n)
    out.mkdir(parents=True, exist_ok=True)
    fabric_job(out / "initial.nc", None, spec)
    relax_job(out / "initial.nc", out / "relaxed.nc", None, spec)
    prev, rows = out / "relaxed.nc", []
    for i in range(1, 2 * n + 1):
        st = cycle_job(prev, out / f"shear_cycle_{i:02d}.nc", None, spec, "base", "shear", i)
        prev = out / f"shear_cycle_{i:02d}.nc"
        c = st.solver["cycle"]
        if i == 1:
            rows.append((c["start"]["strain"], c["start"]["work_rate"], c["start"]["energy"], 0.0))
        rows.append((c["strain"], c["work_rate"], c["energy"], (st.friction or {}).get("dissipated", 0.0)))
    return np.array(rows)


def _loop_balance(rows):
    """(work of the clamps over the loop by the trapezoid rule, potential change, dissipation)."""
    eps, rate = rows[:, 0], rows[:, 1]
    work = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(eps)))
    return work, float(rows[-1, 2] - rows[0, 2]), float(rows[-1, 3] - rows[0, 3])


def test_frictionless_cycle_unloads_on_the_loading_curve_and_dissipates_nothing(tmp_path):
    rows = _cycle(0.0, 4, tmp_path)
    assert np.all(rows[:, 3] == 0.0)
    rate = rows[:, 1]
    scale = np.abs(rate).max()
    # the same strain on the way up and on the way down: the same equilibrium, to what the
    # static tolerance (1e-9 N on forces of ~1e-3 N) leaves
    np.testing.assert_allclose(rate[5:], rate[3::-1], rtol=0, atol=1e-6 * scale)
    work, dpi, _ = _loop_balance(rows)
    assert abs(work) <= 1e-6 * scale * rows[:, 0].max()
    assert abs(dpi) <= 1e-6 * rows[:, 2].max()


def test_frictional_cycle_dissipates_what_the_return_map_dissipates(tmp_path):
    """With mu = 0.3 the loop is open (unloading below loading) and the clamps' work over the
    closed cycle minus the stored energy change converges to the friction term's accumulated
    return-map dissipation as the steps are refined (the trapezoid rule's error: first order
    at the turning point, where the response switches from stick to slip)."""
    errors = []
    for n in (4, 16):
        rows = _cycle(0.3, n, tmp_path / f"n{n}")
        assert rows[-1, 0] == 0.0 and rows[n, 0] == pytest.approx(0.1)   # back at strain 0
        rate = rows[:, 1]
        assert np.all(rate[n + 1:] < rate[n - 1::-1])       # unloading below loading at every strain
        work, dpi, dissipated = _loop_balance(rows)
        assert dissipated > 0 and work > 0
        errors.append(abs(work - dpi - dissipated) / dissipated)
    assert errors[1] < 0.6 * errors[0]
    assert errors[1] < 0.1


def test_frictional_cycle_steps_start_up_at_the_start_and_at_the_turning_point(tmp_path):
    """With the one-path test on, the cycle's frictional steps are tested; the first step
    takes a start-up of ``START_UP`` of the step (a loading start), the step after the turning
    point one of ``START_UP_REVERSAL`` (the friction forces turn over), the others none."""
    from rve.homogenisation.friction_path import START_UP, START_UP_REVERSAL
    from rve.homogenisation.jobs import cycle_job, fabric_job, relax_job

    n = 2
    spec = _spec(0.3, path="quasi_static", cycle_modes=["shear"], cycle_steps=n, follow_branch=True)
    fabric_job(tmp_path / "initial.nc", None, spec)
    relax_job(tmp_path / "initial.nc", tmp_path / "relaxed.nc", None, spec)
    prev, d = tmp_path / "relaxed.nc", 0.1 / n
    for i in range(1, 2 * n + 1):
        st = cycle_job(prev, tmp_path / f"shear_cycle_{i:02d}.nc", None, spec, "base", "shear", i)
        prev = tmp_path / f"shear_cycle_{i:02d}.nc"
        b = st.solver["branch"]
        assert not b.get("untested") and b["checks"], (i, b)
        up = b["start_up"]
        if i == 1:
            assert up["strain"] == pytest.approx(START_UP * d)
        elif i == n + 1:
            assert up["strain"] == pytest.approx(n * d - START_UP_REVERSAL * d)
        else:
            assert up is None


# --------------------------------------------------------------------------- through Snakemake
@pytest.mark.slow
def test_friction_sweep_and_cycle_tables_through_snakemake(tmp_path):
    """The CI config's ci_friction run (mu = 0, 0.3; 2 shear steps; a 2 + 2 step shear cycle) and
    its ci_pullout run (the pull-out curve per mu):
    a friction_coefficient dimension with CF attributes, the friction and cycle variables, the
    loops' figure; at mu = 0 nothing is dissipated and the cycle unloads on its loading curve,
    at mu = 0.3 the loop encloses the work its friction dissipated; the table passes the CF
    checker."""
    import netCDF4
    from PIL import Image

    from rve.homogenisation import layout as L
    from rve.tables import open_table
    from workflow_copy import workflow_copy

    pytest.importorskip("snakemake")
    (tmp_path / "wf").mkdir()
    work = workflow_copy(tmp_path / "wf")
    table = L.table_outputs("ci_friction")["table"]
    loops = L.cycle_report_outputs("ci_friction")["loops"]
    pull = L.pullout_outputs("ci_pullout")
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-j2", table, loops, pull["table"], pull["curve"],
                           "--configfile", "configs/tests/pipeline_ci.yaml"], cwd=work, capture_output=True, text=True,
                          timeout=1200)
    assert proc.returncode == 0, proc.stderr[-4000:]
    t = open_table(work / table)
    assert list(t["friction_coefficient"].values) == [0.0, 0.3]
    assert t["friction_coefficient"].attrs["units"] == "1" and "friction" in t["friction_coefficient"].attrs["long_name"]
    assert t["reaction_force"].dims == ("mode", "strain", "friction_coefficient", "side", "component")
    for name in list(t.data_vars) + list(t.coords):
        assert "units" in t[name].attrs and "long_name" in t[name].attrs, name
    d = t["friction_dissipated_energy"].sel(mode="shear")
    assert np.all(d.sel(friction_coefficient=0.0).values == 0.0)
    assert np.all(np.diff(d.sel(friction_coefficient=0.3).values) > 0)
    rate = t["cycle_work_rate"].sel(cycle_mode="shear")
    r0, r3 = rate.sel(friction_coefficient=0.0).values, rate.sel(friction_coefficient=0.3).values
    scale = np.abs(r0).max()
    assert abs(r0[1] - r0[3]) <= 1e-6 * scale and abs(r0[4] - r0[0]) <= 1e-6 * scale
    assert r3[3] < r3[1] and r3[4] < r3[0]
    c = t.sel(cycle_mode="shear")
    assert float(c["cycle_dissipated_energy"].sel(friction_coefficient=0.0)) == 0.0
    assert float(c["cycle_dissipated_energy"].sel(friction_coefficient=0.3)) > 0
    assert float(c["cycle_work"].sel(friction_coefficient=0.3)) > 0
    assert float(c["cycle_strain"].sel(friction_coefficient=0.3).isel(cycle_step=-1)) == 0.0
    img = np.asarray(Image.open(work / loops).convert("L"), float)
    assert img.std() > 5   # not blank
    # the pull-out (ci_pullout: mu = 0, 0.3) through its rules: the curve per mu, peak and sliding force
    from rve.io.checksum import open_netcdf

    po = open_netcdf(work / pull["table"], require_seal=True)
    assert po["pullout_force"].dims == ("pullout_step", "friction_coefficient")
    for name in list(po.data_vars) + list(po.coords):
        assert "units" in po[name].attrs and "long_name" in po[name].attrs, name
    f = po["pullout_force"]
    assert bool((f.sel(friction_coefficient=0.3).isel(pullout_step=slice(1, None))
                 > f.sel(friction_coefficient=0.0).isel(pullout_step=slice(1, None))).all())
    assert float(po["pullout_sliding_force"].sel(friction_coefficient=0.3)) > float(
        po["pullout_sliding_force"].sel(friction_coefficient=0.0))
    assert (work / pull["csv"]).read_text().startswith("pullout_step,friction_coefficient,")
    assert np.asarray(Image.open(work / pull["curve"]).convert("L"), float).std() > 5
    # the CF checker (as tests/test_tables.py) on the friction table
    sys.path.insert(0, str(Path(__file__).parent))
    from cf_checker import cfchecks_command

    exe, env = cfchecks_command(tmp_path)
    if exe is None:
        pytest.skip("the CF checker (pip cfchecker) is not installed")
    path = tmp_path / "check.nc"
    shutil.copy(work / table, path)
    with netCDF4.Dataset(path, "a") as f:
        f.Conventions = "CF-1.8"
    cft = Path(__file__).parent / "data" / "cf_tables"
    run = subprocess.run([exe, "-v", "1.8", "-s", str(cft / "standard_name_table.xml"), "-a",
                          str(cft / "area_type_table.xml"), "-r", str(cft / "region_names.xml"), str(path)],
                         capture_output=True, text=True, timeout=300, env=env)
    assert "ERRORS detected: 0" in run.stdout and "WARNINGS given: 0" in run.stdout, run.stdout[-3000:]


# --------------------------------------------------------------------------- yarn pull-out
def _pullout(mu: float, out):
    """The warp yarn at y = -1 mm of the tiny cell pulled 0.1 mm in 2 steps (in this process)."""
    from rve.homogenisation.jobs import fabric_job, pullout_job, relax_job

    spec = _spec(mu, static_max_iter=400)
    spec["scene"]["pullout"] = {"yarn": "warp", "position": "-1 mm", "displacement": "0.1 mm", "steps": 2}
    out.mkdir(parents=True, exist_ok=True)
    fabric_job(out / "initial.nc", None, spec)
    relax_job(out / "initial.nc", out / "relaxed.nc", None, spec)
    prev, states = out / "relaxed.nc", []
    for i in (1, 2):
        states.append(pullout_job(prev, out / f"pullout_{i:02d}.nc", None, spec, "base", i))
        prev = out / f"pullout_{i:02d}.nc"
    return states


def test_pullout_moves_the_pulled_ends_and_friction_resists_the_sliding(tmp_path):
    """The pulled ends land on u; the released ends slide along x (the yarn comes out); every
    state is an equilibrium whose supports' axial forces sum to zero (the pull force is the
    reaction that balances the others); friction raises the pull force at every step above the
    frictionless one and dissipates energy as the yarn slides; the table has the curve, the
    peak and the sliding force with their units."""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.sweeps import load_run_config
    from rve.tables.pullout import plot_pullout, pullout_curve

    curves = {}
    for mu in (0.0, 0.3):
        states = _pullout(mu, tmp_path / f"mu{mu}")
        cfg = load_run_config(_spec(mu))
        fab, mesh = fabric_and_mesh(cfg)
        yarn = fab.yarn_at("warp", -1.0, tol=1e-6)
        plus, minus = fab.end_nodes(mesh, "x+", yarn.index), fab.end_nodes(mesh, "x-", yarn.index)
        for k, st in enumerate(states, start=1):
            po = st.solver["pullout"]
            assert st.solver["converged"] and st.solver["residual_N"] <= 1e-9
            np.testing.assert_allclose(st.x[plus, 0] - st.origin[plus, 0], 0.05 * k, rtol=0, atol=1e-12)
            np.testing.assert_array_equal(st.x[minus, 1:3], st.origin[minus, 1:3])   # held across the axis
            assert abs(po["balance"]) <= 1e-8 * max(1e-3, abs(po["force"]))
        curves[mu] = [s.solver["pullout"] for s in states]
        ds = pullout_curve(states)
        assert ds["pullout_force"].attrs["units"] == "N" and ds["pullout_peak_force"].attrs["long_name"]
        assert float(ds["pullout_peak_force"]) == pytest.approx(float(ds["pullout_force"].max()))
        plot_pullout(ds, tmp_path / f"pullout_{mu}.png")
        assert (tmp_path / f"pullout_{mu}.png").stat().st_size > 1000
    for k in range(2):
        assert curves[0.3][k]["force"] > curves[0.0][k]["force"] + 1e-4
        assert curves[0.3][k]["released_displacement"] > 0.05   # the yarn slid out at its free end
        assert curves[0.0][k]["dissipated"] == 0.0
    assert 0 < curves[0.3][0]["dissipated"] < curves[0.3][1]["dissipated"]


def test_pullout_past_the_contact_entering_the_map_converges(tmp_path):
    """The tiny cell's yarn pulled 0.4 mm in 4 steps at mu = 0.3: past u = 0.135 mm a contact
    pair enters the map while the yarn slides; every step ends on an equilibrium
    (|F| <= 1e-9 N), the pulled ends on their targets, the dissipation growing."""
    from rve.homogenisation.jobs import fabric_job, pullout_job, relax_job

    spec = _spec(0.3, static_max_iter=400)
    spec["scene"]["pullout"] = {"yarn": "warp", "position": "-1 mm", "displacement": "0.4 mm", "steps": 4}
    fabric_job(tmp_path / "initial.nc", None, spec)
    relax_job(tmp_path / "initial.nc", tmp_path / "relaxed.nc", None, spec)
    prev, dissipated = tmp_path / "relaxed.nc", 0.0
    for i in range(1, 5):
        st = pullout_job(prev, tmp_path / f"pullout_{i:02d}.nc", None, spec, "base", i)
        po = st.solver["pullout"]
        assert st.solver["converged"] and st.solver["residual_N"] <= 1e-9
        assert po["dissipated"] > dissipated
        dissipated = po["dissipated"]
        prev = tmp_path / f"pullout_{i:02d}.nc"
    assert po["released_displacement"] > 0.3      # the yarn came out at its free end


@pytest.mark.long
@pytest.mark.slow
def test_killed_frictional_run_resumes_with_an_identical_table(tmp_path):
    """ci_friction killed (SIGKILL of the whole process group, jobs in flight) once the first
    frictional state after the relaxed one is on disk, unlocked and re-run: the table (the
    friction and cycle variables included) is identical to the uninterrupted run's, bit for bit."""
    import signal

    from rve.homogenisation import layout as L
    from rve.tables import open_table
    from workflow_copy import workflow_copy

    pytest.importorskip("snakemake")
    table = L.table_outputs("ci_friction")["table"]
    cmd = [sys.executable, "-m", "snakemake", "-j2", table, "--configfile", "configs/tests/pipeline_ci.yaml"]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a, b = workflow_copy(tmp_path / "a"), workflow_copy(tmp_path / "b")
    proc = subprocess.run(cmd, cwd=a, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-4000:]
    states = b / "results" / "rve" / "ci_friction" / "friction_coefficient-0.3" / "states"
    run = subprocess.Popen(cmd, cwd=b, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        import time

        t0 = time.time()
        while not (list(states.glob("shear_01.nc")) or list(states.glob("shear_cycle_01.nc"))):
            if run.poll() is not None or time.time() - t0 > 600:
                pytest.fail(f"snakemake ended ({run.returncode}) before a frictional step was written")
            time.sleep(0.2)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
        run.wait()
    assert not (b / table).exists()
    relaxed = (states / "relaxed.nc").stat().st_mtime_ns
    subprocess.run([sys.executable, "-m", "snakemake", "--unlock", "--configfile", "configs/tests/pipeline_ci.yaml"],
                   cwd=b, capture_output=True, timeout=120, check=True)
    proc = subprocess.run(cmd + ["--rerun-incomplete"], cwd=b, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert (states / "relaxed.nc").stat().st_mtime_ns == relaxed   # resumed, not redone
    ta, tb = open_table(a / table), open_table(b / table)
    assert set(ta.data_vars) == set(tb.data_vars) and "cycle_dissipated_energy" in ta
    for k in list(ta.data_vars) + list(ta.coords):
        if ta[k].dtype.kind == "f":
            np.testing.assert_array_equal(ta[k].values, tb[k].values, err_msg=k)
        else:
            assert list(ta[k].values.ravel()) == list(tb[k].values.ravel()), k


# --------------------------------------------------------------------------- one equilibrium path
def test_frictional_step_follows_one_path_by_its_energy_balance_with_the_dissipation():
    """``strain.follow_branch`` with friction on the quasi-static path: the step is tested by
    the balance W = (Pi + D)(b) - (Pi + D)(a) (``rve.homogenisation.friction_path``). Step 1
    starts a loading: an untested start-up of 1/32 of the step holds the friction's stick
    transient, and the test runs from its end; step 2 goes on from step 1's history without
    one. Why the start-up: from the relaxed state itself the trapezoid of the clamps' work
    rate misses the balance by more than twice the test's tolerance (the clamp force rises
    steeply while the contacts stick, up to ~1.5e-3 strain on this cell), from the
    start-up's end by less than it. Algorithm 7.1's driven phase slips on a dynamic
    path of its own: its frictional step stays untested."""
    from types import SimpleNamespace

    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.friction_path import START_UP, frictional_energy
    from rve.homogenisation.strain import (friction_record, friction_start, mech_system, pinned_energy, relax_fabric,
                                           strain_step)

    def cfg_of(mu, **strain):
        return validate_config({**TINY, "friction": {"coefficient": mu},
                                "strain": {**TINY["strain"], "follow_branch": True, "path": "quasi_static", **strain}})

    cfg = cfg_of(0.3)
    fab, mesh = fabric_and_mesh(cfg)
    x0, _, _ = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    rec0 = friction_start(cfg, fab, mesh, x0)
    x1, s1, info1 = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, friction=rec0)
    b1 = info1["branch"]
    assert info1["converged"] and not b1.get("untested") and b1["checks"] and b1["detections"] == 0
    assert b1["start_up"]["strain"] == pytest.approx(START_UP * 0.05) and b1["checks"][0]["eps"][0] == b1["start_up"]["strain"]
    assert info1["friction"]["step_dissipated"] == pytest.approx(friction_record(s1)["dissipated"] - rec0["dissipated"])
    x2, s2, info2 = strain_step(cfg, fab, mesh, x1, x0, "shear", 2, friction=friction_record(s1))
    b2 = info2["branch"]
    assert info2["converged"] and b2["start_up"] is None and b2["checks"][0]["eps"] == [0.05, 0.1]
    assert b2["detections"] == 0
    # the balance from the relaxed state and from the start-up's end, two step sizes
    cell = SimpleNamespace(periodic=False, fab=fab, mesh=mesh, origin=x0, mode="shear",
                           system=lambda xf: mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf),
                           energy=lambda system, xf, e: pinned_energy(fab, mesh, system, xf, x0, "shear", e))
    e0 = frictional_energy(cfg, cell, None, x0, 0.0, None, rec0)
    tol = cfg.strain.branch_energy_rtol
    for d in (0.05, 0.04):
        up = START_UP * d
        xu, su, _ = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, friction=rec0, levels=(0.0, up))
        xb, sb, _ = strain_step(cfg, fab, mesh, xu, x0, "shear", 1, friction=friction_record(su), levels=(up, d))
        eu = frictional_energy(cfg, cell, su, xu, up, None, None)
        eb = frictional_energy(cfg, cell, sb, xb, d, None, None)
        miss = [abs(0.5 * (ea[1] + eb[1]) * (d - a) - (eb[0] - ea[0])) / abs(0.5 * (ea[1] + eb[1]) * (d - a))
                for ea, a in ((e0, 0.0), (eu, up))]
        assert miss[0] > 2 * tol and miss[1] < tol, (d, miss)
    cfg7 = validate_config({**TINY, "friction": {"coefficient": 0.3},
                            "strain": {**TINY["strain"], "follow_branch": True, "path": "algorithm_7_1"}})
    _, _, info7 = strain_step(cfg7, fab, mesh, x0, x0, "shear", 1, friction=rec0)
    assert info7["branch"]["untested"] == "friction" and not info7["branch"].get("checks")

def test_cycle_table_records_each_steps_path_test():
    """``cycle_branch_jumps`` / ``cycle_branch_limit_points``: the equilibrium-path test of
    every cycle state (its record's ``branch``), NaN for an untested (frictional) step and for
    the relaxed start, per swept combination."""
    from types import SimpleNamespace

    import xarray as xr

    from rve.tables.cycles import add_cycle_variables

    def state(mu, step, branch):
        cyc = {"steps": 2, "strain": 0.05 * (2 - abs(2 - step)), "work_rate": 1.0, "energy": 0.1}
        if step == 1:
            cyc["start"] = {"strain": 0.0, "work_rate": 0.0, "energy": 0.0, "dissipated": 0.0}
        return SimpleNamespace(kind="cycle", mode="shear", step=step, params={"friction_coefficient": mu},
                               solver={"cycle": cyc, "converged": True, "branch": branch}, friction=None,
                               reaction_force={})

    tested = {"branch_jumps": 1, "limit_points": 2, "detections": 4}
    untested = {"branch_jumps": 0, "limit_points": 0, "untested": "friction"}
    ds = xr.Dataset(coords={"friction_coefficient": ("friction_coefficient", [0.0, 0.3]),
                            "side": ["x-", "x+", "y-", "y+"]}, attrs={"swept_parameters": "friction_coefficient"})
    out = add_cycle_variables(ds, [state(0.0, 1, {"branch_jumps": 0, "limit_points": 0}), state(0.0, 2, tested),
                                   state(0.3, 1, untested), state(0.3, 2, untested)])
    j = out["cycle_branch_jumps"].sel(cycle_mode="shear")
    lp = out["cycle_branch_limit_points"].sel(cycle_mode="shear")
    np.testing.assert_array_equal(j.sel(friction_coefficient=0.0).values, [np.nan, 0.0, 1.0])
    np.testing.assert_array_equal(lp.sel(friction_coefficient=0.0).values, [np.nan, 0.0, 2.0])
    assert np.isnan(j.sel(friction_coefficient=0.3).values).all()
    assert out["cycle_branch_jumps"].attrs["units"] == "1"
