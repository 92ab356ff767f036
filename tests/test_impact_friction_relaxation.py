"""The impact's relaxation with the fibril friction (``relaxation.friction``;
rve.scenes.impact.relaxation; docs/impact.md "Relaxation with friction"): the option is
validated and off by default (the frictionless relaxation bit for bit, the relaxed state's
digest unchanged), on it starts the history with no elastic gap, commits it after every
accepted step, saves it with the relaxed state and seeds the impact with it; the
relaxation's mechanical balance closes with the friction work; friction holds the
straight-reference weave that slides without it.

The cases are the 4 x 4 weave of the impact tests with the straight natural state of §8.3
(the crimp curves 0.02 mm into each other: the crossings are loaded at the start)."""
import numpy as np
import pytest

from rve.config import ConfigError
from rve.config.loader import load_config
from rve.scenes import impact
from rve.scenes.dynamic_friction import DynamicFriction
from rve.scenes.impact import scene
from rve.scenes.rebuild import ChunkedRebuild
from rve.model import RowScaledSystem
from rve.solvers.dirk import integrate, sdirk

IMPACT = "configs/scenes/impact.yaml"
TINY = ["geometry.n_warp=4", "geometry.n_weft=4", "geometry.span=6.35 mm", "mesh.elements=8",
        "projectile.radius=2 mm", "time.t_end=0.02 ms", "time.steps=40", "relaxation.steps=5",
        "relaxation.t_end=0.2 ms", "newton.jacobian_reuse=false", "time.checkpoint_every=10"]
STRAIGHT = TINY + ["geometry.reference=straight", "geometry.crimp_clearance=-0.02 mm"]
#: the frictional relaxation of the straight weave
FRICTIONAL = STRAIGHT + ["friction.coefficient=0.3", "relaxation.friction=true"]


def _cfg(extra=()):
    return load_config(IMPACT, list(extra))


def test_option_validated_default_off_and_in_the_digest():
    cfg = _cfg(TINY)
    assert cfg.relaxation.friction is False
    with pytest.raises(ConfigError, match=r"relaxation.friction = 'maybe'"):
        _cfg(TINY + ["relaxation.friction=maybe"])
    base = impact.config_digest(cfg)
    # off (or on with every mu = 0: the same relaxation): the digests the relaxed states had
    assert impact.config_digest(_cfg(TINY + ["relaxation.friction=false", "friction.coefficient=0.3"])) == base
    assert impact.config_digest(_cfg(TINY + ["relaxation.friction=true"])) == base
    on = impact.config_digest(_cfg(TINY + ["relaxation.friction=true", "friction.coefficient=0.3"]))
    assert on != base
    # on, the fibrils' law is part of it; the projectile's mu_p is not (the relaxation holds it clear)
    assert impact.config_digest(_cfg(TINY + ["relaxation.friction=true", "friction.coefficient=0.2"])) != on
    assert impact.config_digest(_cfg(TINY + ["relaxation.friction=true", "friction.coefficient=0.3",
                                             "friction.projectile=0.2"])) == on
    # the relaxation's system carries the friction term only with the option
    assert impact.setup(_cfg(FRICTIONAL), "relax").friction.term.law.coefficient == 0.3
    assert impact.setup(_cfg(STRAIGHT + ["friction.coefficient=0.3"]), "relax").friction is None


def _frictionless_relaxation(cfg):
    """The relaxation as the scene ran it before the option: no on-step hook, no recorder."""
    problem = impact.setup(cfg, "relax")
    sysm, r = problem.system, cfg.relaxation
    nopts = {"atol": cfg.newton.atol, "rtol": cfg.newton.rtol, "max_iter": cfg.newton.max_iter}
    x = problem.x0.copy()
    scale = sysm.row_scales(r.t_end / r.steps, x, np.zeros(sysm.n))
    w, _ = scene._initial_w(sysm, x, scale, nopts)
    hook = ChunkedRebuild(sysm, r.t_end, r.steps, cfg.contact.rebuild_every, 0.5 * cfg.contact.margin)
    hook.rebuild(x)
    res = integrate(RowScaledSystem(sysm, scale), x, w, 0.0, r.t_end, r.steps, stages=sdirk(cfg.time.stages).stages,
                    newton_opts=nopts, consistent=False, rebuild=hook, **scene._integrator_options(cfg, sysm))
    return res.x, res.w


def test_option_off_is_the_frictionless_relaxation_bit_for_bit():
    # the straight weave moves (a relaxation that stays at rest would compare nothing); mu > 0
    # in the config, the option off: the relaxation ignores it
    cfg = _cfg(STRAIGHT + ["friction.coefficient=0.3"])
    x_ref, w_ref = _frictionless_relaxation(cfg)
    x, info = impact.relax(cfg)
    assert info["max_centroid_drift_mm"] > 0.1
    assert np.array_equal(x, x_ref)
    assert info.friction is None and info["with_friction"] is False


def test_history_starts_without_gap_and_is_committed_every_step(monkeypatch):
    cfg = _cfg(FRICTIONAL)
    # the start: the first map rebuild gives every point its material point at the start
    # state, so no point carries a tangential force there although the crossings are loaded
    # (with the section frame the anchor is taken apart in the section's frame and put back
    # together: its rounding, a few eps of the anchor, the jump -j of ~2R, is left)
    p = impact.setup(cfg, "relax")
    ChunkedRebuild(p.system, 1.0, 1, 5, 0.15).rebuild(p.x0)
    st = p.friction.term.state(p.system.split(p.x0)[0])
    assert st.normal.max() > 0 and p.friction.term.frame
    assert np.abs(st.e).max() <= 64 * np.finfo(float).eps * np.abs(st.anchor).max()
    committed = []
    real = DynamicFriction.commit

    def counting(self, x):
        committed.append(np.array(x, copy=True))
        return real(self, x)

    monkeypatch.setattr(DynamicFriction, "commit", counting)
    x, info = impact.relax(cfg)
    assert info["with_friction"] is True
    assert len(committed) == info["steps"] >= 5
    assert np.array_equal(committed[-1], x)
    h = info.friction
    assert h is not None and h["friction/keys"].shape[0] > 0 and float(h["friction/dissipated"]) > 0
    pts = info["friction_points"]
    assert pts["stick"] + pts["slip"] > 0


@pytest.fixture(scope="module")
def relaxed(tmp_path_factory):
    """The frictional relaxation of the straight weave over 1 ms, saved."""
    cfg = _cfg(FRICTIONAL + ["relaxation.t_end=1 ms", "relaxation.steps=100", "field.magnitude=0 kT"])
    f = tmp_path_factory.mktemp("relax") / "relaxed_state.npz"
    x, info = impact.load_or_relax(cfg, f)
    return cfg, f, x, info


def test_relaxed_state_saves_the_history_and_the_impact_starts_from_it(relaxed, monkeypatch):
    cfg, f, x, info = relaxed
    # saved with the state, loaded back as it was
    x2, info2 = impact.load_or_relax(cfg, f)
    assert info2["loaded_from"] == str(f) and np.array_equal(x2, x)
    assert set(info2.friction) == set(info.friction)
    for k, v in info.friction.items():
        assert np.array_equal(info2.friction[k], v), k
    # the impact seeds its first map with the relaxed history (by point key)
    seeded = {}
    real = scene.seed_impact_friction

    def spy(friction, x_, arrays):
        real(friction, x_, arrays)
        seeded.update(friction.term.record())

    monkeypatch.setattr(scene, "seed_impact_friction", spy)
    # B off: before the projectile arrives (0.2 mm at 30 mm/ms: 6.7 µs) only the relaxed
    # fabric's own forces act
    kw = dict(x_start=x, record=False, t_end=0.004, steps=8)
    carried = impact.solve(cfg, relax_info=info2, **kw)
    keys, rk = seeded["keys"], info.friction["friction/keys"]
    from rve.model.terms.friction import match_rows

    idx = match_rows(keys, rk)
    hit = idx >= 0
    assert hit.sum() > 0.5 * len(rk)
    assert np.array_equal(seeded["s_bar"][hit], info.friction["friction/s_bar"][idx[hit]])
    assert np.array_equal(seeded["anchor"][hit], info.friction["friction/anchor"][idx[hit]])
    assert seeded["dissipated"] == 0.0          # the impact counts its own dissipation
    # without the history (every point afresh at the relaxed state) the stick springs let go
    # and the relaxed fabric moves; with it, it stays (nearly) at rest
    monkeypatch.setattr(scene, "seed_impact_friction", lambda *a: None)
    fresh = impact.solve(cfg, relax_info=info2, **kw)
    sysm = carried.model

    def fabric_speed(res):
        return float(np.abs(sysm.fabric.base.nodal(sysm.split(res.state["w"])[0])[:, 0:3]).max())

    v_carried, v_fresh = fabric_speed(carried), fabric_speed(fresh)
    assert v_carried < 0.2 * v_fresh, (v_carried, v_fresh)
    # a relaxation info without the history cannot start a run that needs it
    with pytest.raises(ValueError, match="friction history"):
        impact.solve(cfg, relax_info=dict(info), **kw)


def test_relaxation_energy_balance_closes_with_the_friction_work():
    """Resolved steps (2 µs, as the dynamic scenes' balance tests): ΔE_mech + W_d + W_f = 0
    closes to a few percent; without W_f it misses by the friction's share."""
    cfg = _cfg(FRICTIONAL + ["relaxation.steps=100"])
    _, info = impact.relax(cfg)
    e = info["energies_mJ"]
    dE, Wd, Wf = e["delta_mechanical_energy_mJ"], e["damping_mJ"], e["friction_work_mJ"]
    assert dE < 0 and Wf > 0
    assert info["mechanical_balance"] <= 0.03
    without = abs(dE + Wd) / abs(dE)
    assert without >= 10 * info["mechanical_balance"], (without, info["mechanical_balance"])
    # the return maps' dissipated work plus the springs' energy estimates the same work
    assert e["friction_dissipated_mJ"] + e["friction_elastic_energy_mJ"] == pytest.approx(Wf, rel=0.3)


def test_friction_holds_the_straight_weave_that_slides_without_it():
    """1 ms of damped relaxation: without friction the straight weave slides off its
    crossings and is still moving; with mu = 0.3 it drifts far less and comes to rest."""
    out = {}
    for mu in (0.0, 0.3):
        cfg = _cfg(STRAIGHT + [f"friction.coefficient={mu}", "relaxation.friction=true", "relaxation.t_end=1 ms",
                               "relaxation.steps=100"])
        _, out[mu] = impact.relax(cfg)
    free, held = out[0.0], out[0.3]
    assert free["max_centroid_drift_mm"] > 0.3
    assert held["max_centroid_drift_mm"] < 0.5 * free["max_centroid_drift_mm"]
    assert held["max_centroid_speed_mm_per_ms"] < 0.1 * free["max_centroid_speed_mm_per_ms"]
    assert held["friction_points"]["stick"] > held["friction_points"]["slip"]


def test_impact_from_the_frictional_relaxation_resumes_bit_for_bit(relaxed, tmp_path, monkeypatch):
    """Killed and resumed, the impact continues from its checkpoint's history (which grew from
    the relaxed one), not from the relaxed state's again: the same bits as the run through."""
    from rve.scenes.protocol import SceneFailure

    cfg, _, x, info = relaxed
    kw = dict(x_start=x, relax_info=info, record=False, t_end=0.01, steps=20)
    ref = impact.solve(cfg, **kw)
    ck = tmp_path / "checkpoint.npz"
    with pytest.raises(SceneFailure):
        impact.solve(cfg, checkpoint=ck, stop_after_steps=10, **kw)
    seeds = []
    real = scene.seed_impact_friction
    monkeypatch.setattr(scene, "seed_impact_friction", lambda *a: (seeds.append(1), real(*a)))
    res = impact.solve(cfg, checkpoint=ck, **kw)
    assert res.summary["resumed_from_ms"] > 0 and not seeds
    for k in ("x", "w", "T"):
        assert np.array_equal(res.state[k], ref.state[k]), k
