"""The augmented Lagrangian in the RVE relaxation and strain steps (pinned and periodic cells):
the overlap after a strain step is below ``contact.al_tolerance``, the face force does not
depend on P* (while the penalty's does), and the multipliers go through the checkpoint so a
resumed step is bit-identical."""
import numpy as np
import pytest

TOL = 1e-4
#: the pinned 2x2 cell's dynamics phases take ~15 s for the four runs: slow
BOUNDARIES = [pytest.param("pinned", marks=pytest.mark.slow), "periodic"]


def _cfg(boundary, enforcement, penalty, steps=1):
    from rve.config.rve import RVEConfig

    return RVEConfig(scene="rve", boundary=boundary, fabric={"kind": "plain", "rows": [1]}, mesh={"elements": 6},
                     contact={"onset": 0.05, "enforcement": enforcement, "penalty": penalty, "al_tolerance": TOL},
                     strain={"total": 0.05 * steps, "steps": steps})


def _relax_and_step(cfg):
    from rve.fabrics.setup import clamp_reactions, fabric_and_mesh
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import relax_fabric, strain_step

    fab, mesh = fabric_and_mesh(cfg)
    x0, sys0, info0 = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info0["converged"]
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "uniaxial", 1, multipliers=multiplier_record(sys0))
    assert info["converged"]
    reac = info.get("reaction_force") or clamp_reactions(fab, system, x)
    return fab, mesh, x0, sys0, x, system, info, np.array(reac["x+"][0])


@pytest.mark.parametrize("boundary", BOUNDARIES)
def test_strain_step_overlap_below_tolerance_and_force_independent_of_the_penalty(boundary):
    force = {}
    for enforcement in ("penalty", "augmented_lagrangian"):
        for penalty in (50.0, 150.0):
            *_, x, system, info, fx = _relax_and_step(_cfg(boundary, enforcement, penalty))
            force[enforcement, penalty] = fx
            if enforcement == "augmented_lagrangian":
                assert system.max_penetration(x.reshape(-1)) <= TOL
                assert info["static"]["augmented_lagrangian"]["met"]
            else:
                assert "augmented_lagrangian" not in info["static"]
    pen = abs(force["penalty", 150.0] / force["penalty", 50.0] - 1.0)
    al = abs(force["augmented_lagrangian", 150.0] / force["augmented_lagrangian", 50.0] - 1.0)
    assert al <= TOL
    assert pen > TOL   # the penalty's own dependence on P* exceeds it, so the test above can fail


@pytest.mark.parametrize("boundary", BOUNDARIES)
def test_multipliers_through_the_checkpoint_give_a_bit_identical_next_step(boundary, tmp_path):
    from rve.homogenisation.checkpoint import State, load_state, write_state
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import strain_step

    cfg = _cfg(boundary, "augmented_lagrangian", 50.0, steps=2)
    fab, mesh, x0, _, x1, sys1, _, _ = _relax_and_step(cfg)
    rec = multiplier_record(sys1)
    assert rec is not None and np.any(rec[1] > 0)
    path = write_state(tmp_path / "s1.nc", State(x=x1, w=np.zeros_like(x1), origin=x0, kind="strained",
                                                  mode="uniaxial", step=1, multipliers=rec), fab, mesh)
    back = load_state(path)
    assert np.array_equal(back.multipliers[0], rec[0]) and np.array_equal(back.multipliers[1], rec[1])
    xa, _, _ = strain_step(cfg, fab, mesh, x1, x0, "uniaxial", 2, multipliers=rec)
    xb, _, _ = strain_step(cfg, fab, mesh, back.x, back.origin, "uniaxial", 2, multipliers=back.multipliers)
    assert np.array_equal(xa, xb)
    # without them the step starts from zero multipliers: another state (the test can fail)
    xc, _, _ = strain_step(cfg, fab, mesh, x1, x0, "uniaxial", 2)
    assert not np.array_equal(xa, xc)


def test_penalty_state_has_no_multipliers(tmp_path):
    import xarray as xr

    from rve.homogenisation.checkpoint import State, write_state
    from rve.homogenisation.multipliers import multiplier_record

    cfg = _cfg("periodic", "penalty", 50.0)
    fab, mesh, x0, sys0, *_ = _relax_and_step(cfg)
    assert multiplier_record(sys0) is None
    path = write_state(tmp_path / "s0.nc", State(x=x0, w=np.zeros_like(x0), origin=x0, kind="relaxed",
                                                  multipliers=multiplier_record(sys0)), fab, mesh)
    with xr.open_dataset(path) as ds:
        assert "contact_multiplier" not in ds and "contact_multiplier_key" not in ds


def _relaxed_probes(boundary, enforcement, penalty):
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.probes import solve_probes
    from rve.homogenisation.strain import relax_fabric

    cfg = _cfg(boundary, enforcement, penalty)
    fab, mesh = fabric_and_mesh(cfg)
    x0, sys0, info0 = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info0["converged"]
    rec = multiplier_record(sys0)
    return cfg, fab, mesh, x0, rec, solve_probes(cfg, fab, mesh, x0, multipliers=rec)


def _probe_figures(results):
    return np.array([[r.resistance, r.temperature_max] for _, r in sorted(results.items())])


@pytest.mark.parametrize("boundary", BOUNDARIES)
def test_probes_of_an_augmented_state_do_not_depend_on_the_penalty(boundary):
    """The probes' contact widths and conductances come from the multipliers' line load: the
    resistances and Joule temperatures of the relaxed cell at P* = 50 and 150 agree to
    10 al_tolerance (the overlap left), while the penalty's differ by more."""
    figs = {(e, p): _probe_figures(_relaxed_probes(boundary, e, p)[-1])
            for e in ("penalty", "augmented_lagrangian") for p in (50.0, 150.0)}
    al = np.abs(figs["augmented_lagrangian", 150.0] / figs["augmented_lagrangian", 50.0] - 1.0).max()
    pen = np.abs(figs["penalty", 150.0] / figs["penalty", 50.0] - 1.0).max()
    assert al <= 10 * TOL
    assert pen > 10 * TOL


@pytest.mark.parametrize("boundary", BOUNDARIES)
def test_probe_job_of_a_stored_augmented_state(boundary, tmp_path):
    """The probe job on the written state: its residual check and probes use the stored
    multipliers (bit-identical to the probes of the state in memory); without them the
    residual of the same state is far above the tolerance and the probes differ."""
    from rve.config import config_as_dict
    from rve.homogenisation.checkpoint import State, write_state
    from rve.homogenisation.jobs import probe_record, recomputed_residual
    from rve.homogenisation.probes import solve_probes

    cfg, fab, mesh, x0, rec, results = _relaxed_probes(boundary, "augmented_lagrangian", 50.0)
    assert rec is not None and np.any(rec[1] > 0)
    res = recomputed_residual(cfg, fab, mesh, x0, rec)
    assert res <= cfg.relaxation.static_atol
    assert recomputed_residual(cfg, fab, mesh, x0) > 1e3 * cfg.relaxation.static_atol
    path = write_state(tmp_path / "s0.nc", State(x=x0, w=np.zeros_like(x0), origin=x0, kind="relaxed",
                                                  solver={"residual_N": res, "converged": True},
                                                  multipliers=rec), fab, mesh)
    out = probe_record(path, {"scene": config_as_dict(cfg)})
    for name, r in results.items():
        got, want = dict(out["probes"][name]), r.record()
        got.pop("wall_s"), want.pop("wall_s")
        assert got == want
    # (the resistances only: the bare Joule solve of the onset law's weak contacts is at its
    # round-off floor, above the probes' 1e-12 tolerance)
    no_heat = cfg.model_copy(update={"probe_solver": cfg.probe_solver.model_copy(update={"temperature": False})})
    bare = _probe_figures(solve_probes(no_heat, fab, mesh, x0))[:, 0]
    assert not np.array_equal(bare, _probe_figures(results)[:, 0])
