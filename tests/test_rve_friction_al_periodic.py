"""Friction with the augmented Lagrangian and in the periodic cell (docs/contact.md "Friction
with the augmented Lagrangian and the periodic cell"): a frictional step's Uzawa re-solves all
start from the step's held history, which is committed once per sub-increment after the loop;
the state is a root of the exact frictional residual at its multipliers; the multipliers and the
history go through the checkpoint (a resumed step bit for bit); a periodic cell's history of a
pair across a cell face is carried by its lattice key; mu = 0 is the frictionless path bit for
bit."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from test_rve_friction import _job  # one job in its own process, as Snakemake runs it

TOL = 1e-5   # al_tolerance: tight enough that the strain steps below need Uzawa updates
ATOL = 1e-9


#: yarns of two rows of two fibrils, which touch along their length, so that pairs in contact
#: cross the faces of a periodic cell (a lattice translation in their keys; with one fibril per
#: yarn, or one row of two, no neighbours across a face touch)
STACKED = [2, 2]


def _scene(boundary, enforcement, mu, substeps=2, rows=(1,), frame=None, geometry="chord", order=1, **strain):
    scene = {"scene": "rve", "boundary": boundary, "fabric": {"kind": "plain", "rows": list(rows)},
             "mesh": {"elements": 6, "order": order},
             "contact": {"onset": 0.05, "penalty": 50.0, "enforcement": enforcement, "al_tolerance": TOL,
                         "geometry": geometry},
             "relaxation": {"static_atol": ATOL},
             "strain": {"modes": ["shear"], "total": 0.1, "steps": 2, "static_atol": ATOL, "follow_branch": False,
                        "path": "quasi_static", "substeps": substeps, **strain},
             "output": {"pictures": False}}
    if mu is not None:
        scene["friction"] = {"coefficient": mu}
        if frame is not None:
            scene["friction"]["frame"] = frame
    return scene


def _cfg(*args, **kw):
    from rve.config import validate_config

    return validate_config(_scene(*args, **kw))


_RELAXED = {}


def _relaxed(cfg):
    """(fab, mesh, x0, multipliers, friction record) of the relaxed cell (cached per config)."""
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import friction_start, relax_fabric

    key = json.dumps(cfg.model_dump(mode="json"), sort_keys=True, default=str)
    if key not in _RELAXED:
        fab, mesh = fabric_and_mesh(cfg)
        x0, sys0, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
        assert info["converged"]
        _RELAXED[key] = (fab, mesh, x0, multiplier_record(sys0), friction_start(cfg, fab, mesh, x0))
    return _RELAXED[key]


def section_frame_cell_off_its_step(seed: int):
    """The pinned AL cell with ``friction.frame: section`` after a frictional shear step, its
    map rebuilt at a trial state 3e-5 mm (random, ``seed``) off the step's state: ``(system,
    y)``."""
    from rve.homogenisation.strain import strain_step

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=1, frame="section")
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x1, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    assert info["converged"]
    y = np.asarray(x1, float).reshape(-1) + np.random.default_rng(seed).normal(size=system.n) * 3e-5
    system.rebuild(y)
    return system, y


def _fresh_residual(cfg, fab, mesh, x, multipliers, friction):
    from rve.homogenisation.jobs import recomputed_residual

    return recomputed_residual(cfg, fab, mesh, x, multipliers, friction)


def _fresh_dissipation(cfg, fab, mesh, x, multipliers, friction):
    """The return map's dissipation at ``x`` from the history ``friction`` (a record), on a
    system built from scratch at ``x`` (summed over its points)."""
    from rve.homogenisation.multipliers import seed_multipliers
    from rve.homogenisation.strain import mech_system, seed_friction
    from rve.solvers.system import friction_of

    xf = np.asarray(x, float).reshape(-1)
    if cfg.boundary == "periodic":
        from rve.homogenisation.periodic import cell_gradient, periodic_system

        system = periodic_system(cfg, fab, mesh, xf, cell_gradient(fab, mesh, xf), friction=True)
        xs = system.restrict(xf)
    else:
        system, xs = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf), xf
    seed_multipliers(system, multipliers)
    seed_friction(system, friction, xs)
    return float(friction_of(system).state(xs).dissipation.sum())


class _Commits:
    """Counts ``FrictionTerm.commit`` calls (monkeypatched)."""

    def __init__(self, monkeypatch):
        from rve.model.terms.friction import FrictionTerm

        self.n = 0
        original = FrictionTerm.commit

        def counted(term, x):
            self.n += 1
            return original(term, x)

        monkeypatch.setattr(FrictionTerm, "commit", counted)


# --------------------------------------------------------------------------- the augmented Lagrangian
@pytest.mark.parametrize("boundary, frame", [("pinned", "chord"), ("periodic", "chord"), ("periodic", "section")])
def test_al_step_with_friction_is_a_frictional_root_at_the_tolerance(boundary, frame, monkeypatch):
    """One quasi-static shear step (one sub-increment, so the held history is the input's):
    converged with Uzawa updates, the largest overlap below al_tolerance, the state a root of
    the exact frictional residual from the held history and from the committed one (the
    commit changes no force), the history committed exactly once although the loop re-solved,
    and the step's dissipation > 0 equal to the return map's from the held history at the
    state, recomputed on a system built from scratch."""
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import friction_record, strain_step

    cfg = _cfg(boundary, "augmented_lagrangian", 0.3, substeps=1, frame=frame)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    commits = _Commits(monkeypatch)
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    al = info["static"]["augmented_lagrangian"]
    # the provisional re-solves, then the full solve at the multipliers that met the tolerance
    assert info["converged"] and al["met"] and al["updates"] >= 1 and al["provisional_solves"] >= 1
    assert al["solves"] == al["updates"] + 2
    assert commits.n == 1
    assert system.max_penetration(x.reshape(-1)) <= TOL
    lam, fr1 = multiplier_record(system), friction_record(system)
    assert np.any(lam[1] > 0)
    assert _fresh_residual(cfg, fab, mesh, x, lam, fr0) <= ATOL          # the equation solved
    assert _fresh_residual(cfg, fab, mesh, x, lam, fr1) <= ATOL          # after the commit
    assert _fresh_residual(cfg, fab, mesh, x, lam, None) > 1e3 * ATOL    # friction holds the state
    d = info["friction"]["step_dissipated"]
    assert d > 0 and d == pytest.approx(info["static"]["dissipated"], rel=1e-12)
    assert d == pytest.approx(_fresh_dissipation(cfg, fab, mesh, x, lam, fr0), rel=1e-9)


def test_every_sub_increment_is_committed_once(monkeypatch):
    """With two sub-increments and an Uzawa loop in each: two commits, and the dissipation
    accumulated over them."""
    from rve.homogenisation.strain import strain_step

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=2)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    commits = _Commits(monkeypatch)
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    assert info["converged"] and info["static"]["augmented_lagrangian"]["solves"] >= 2
    assert commits.n == 2
    assert info["friction"]["dissipated"] > info["static"]["dissipated"] > 0


@pytest.mark.parametrize("boundary", ["pinned", "periodic"])
@pytest.mark.parametrize("provisional", [True, False])
def test_uzawa_re_solves_take_the_predictor_in_rounds(boundary, provisional, monkeypatch):
    """The first solve of a step refreezes the loads at every accepted iterate; the Uzawa
    re-solves at updated multipliers (and raised P*) take the predictor in rounds of converged
    minimisations at fixed loads (``fr.resolving``; the refreezing predictor diverges there on
    the periodic weave, docs/contact.md "Friction with the augmented Lagrangian and the
    periodic cell") and with the law's stage alone (``RESOLVE_SMOOTHING``). With provisional
    re-solves (``multipliers.PROVISIONAL_RESOLVES``) the first solve is its smoothed stage
    alone and every provisional re-solve one round of the law; the full solves after them
    take the rounds. The flags are cleared after the loop."""
    import rve.homogenisation.multipliers as multipliers
    import rve.solvers.frictional as frictional
    from rve.homogenisation.strain import strain_step
    from rve.solvers.system import friction_of

    monkeypatch.setattr(multipliers, "PROVISIONAL_RESOLVES", provisional)
    cfg = _cfg(boundary, "augmented_lagrangian", 0.3, substeps=1)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    modes = []
    original = frictional._predictor

    def spied(system, fr, x, t, out, ptol, rtol, max_iter, refreeze, max_rounds, *args, **kw):
        eta = args[4] if len(args) > 4 else kw.get("eta", 0.0)
        modes.append((bool(fr.resolving), bool(fr.provisional), bool(refreeze), int(max_rounds), float(eta)))
        return original(system, fr, x, t, out, ptol, rtol, max_iter, refreeze, max_rounds, *args, **kw)

    monkeypatch.setattr(frictional, "_predictor", spied)
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    al = info["static"]["augmented_lagrangian"]
    assert info["converged"] and al["met"] and al["updates"] >= 1
    full = [m for m in modes if m[0] and not m[1]]
    # the full re-solves start next to an equilibrium: the law's stage alone, no smoothed stage
    # (after the provisional ones, a start within direct_atol may go to the corrector alone)
    assert (full or provisional) and all(m == (True, False, False, frictional.RESOLVE_ROUNDS, 0.0) for m in full)
    if provisional:
        assert modes[0] == (False, True, True, 1, 1.0)
        ahead = [m for m in modes if m[1] and m[0]]
        assert ahead and all(m == (True, True, False, 1, 0.0) for m in ahead)
        assert al["provisional_solves"] == 1 + len(ahead)
    else:
        assert modes[0] == (False, False, True, 4, 1.0) and modes[1] == (False, False, True, 4, 0.0)
        assert not any(m[1] for m in modes) and al["provisional_solves"] == 0
    fr = friction_of(system)
    assert fr.resolving is False and fr.provisional is False


#: the solver-path comparisons: the position-based law on the pinned cell (with the section
#: frame there the unmodified rounds need a cut, and the provisional and full loops end at
#: neighbouring equilibria 11 al_tolerance R apart: docs/contact.md "Provisional re-solves"),
#: the section frame on the periodic cell
PATHS = [("pinned", "chord"), ("periodic", "section")]


@pytest.mark.parametrize("boundary, frame", PATHS)
def test_re_solves_from_the_held_loads_with_blended_rounds_find_the_unmodified_root(boundary, frame, monkeypatch):
    """The re-solves' first round frozen at the last converged solve's loads, the later
    rounds' normal forces blended with the previous round's and the law's stage alone
    (``RESOLVE_HELD``, ``RESOLVE_BLEND``, ``RESOLVE_SMOOTHING``) reach the equilibrium the
    unmodified rounds reach (the first round at the committed loads, the loads at the round's
    start alone, the smoothed stage first): both exact roots at the same multipliers, the
    same state, the same dissipation."""
    import rve.homogenisation.multipliers as multipliers
    import rve.solvers.frictional as frictional
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import strain_step
    from rve.model.terms.friction import FrictionTerm

    cfg = _cfg(boundary, "augmented_lagrangian", 0.3, substeps=1, frame=frame)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    held = []
    original = FrictionTerm.freeze_held

    def spied(term):
        held.append(original(term))
        return held[-1]

    monkeypatch.setattr(FrictionTerm, "freeze_held", spied)
    runs = {}
    monkeypatch.setattr(multipliers, "PROVISIONAL_RESOLVES", False)
    for name, h, b, sm in (("new", True, 0.5, ()), ("unmodified", False, 1.0, None)):
        monkeypatch.setattr(frictional, "RESOLVE_HELD", h)
        monkeypatch.setattr(frictional, "RESOLVE_BLEND", b)
        monkeypatch.setattr(frictional, "RESOLVE_SMOOTHING", sm)
        x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
        assert info["converged"] and info["static"]["augmented_lagrangian"]["met"]
        lam = multiplier_record(system)
        assert _fresh_residual(cfg, fab, mesh, x, lam, fr0) <= ATOL
        runs[name] = (np.asarray(x, float).reshape(-1), info["static"]["dissipated"])
    assert held and all(held)          # the new path froze the kept loads at every re-solve
    (xn, dn), (xu, du) = runs["new"], runs["unmodified"]
    assert np.abs(xn - xu).max() <= 1e-6 * np.abs(xu).max()
    assert dn == pytest.approx(du, rel=1e-5)


@pytest.mark.parametrize("boundary, frame", PATHS)
def test_provisional_re_solves_end_at_an_exact_root_of_the_full_loop(boundary, frame, monkeypatch):
    """With and without provisional re-solves (``multipliers.PROVISIONAL_RESOLVES``): both
    states exact frictional roots at their multipliers with every overlap below
    al_tolerance, and they agree to the tolerance's scale (ten times al_tolerance R in the
    state, ten times al_tolerance relative in the dissipation): the provisional solves change
    the way to the multipliers, not the equilibrium. At al_tolerance 1e-6 (the module's 1e-5
    leaves the two dissipations of the periodic step 1e-3 apart, each as far from those at
    1e-6 and 1e-7, which agree to 2e-6)."""
    import rve.homogenisation.multipliers as multipliers
    from rve.config import validate_config
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import strain_step

    scene = _scene(boundary, "augmented_lagrangian", 0.3, substeps=1, frame=frame)
    tol = scene["contact"]["al_tolerance"] = 0.1 * TOL
    cfg = validate_config(scene)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    runs = {}
    for on in (True, False):
        monkeypatch.setattr(multipliers, "PROVISIONAL_RESOLVES", on)
        x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
        al = info["static"]["augmented_lagrangian"]
        assert info["converged"] and al["met"] and (al["provisional_solves"] > 0) is on
        assert system.max_penetration(np.asarray(x, float).reshape(-1)) <= tol
        assert _fresh_residual(cfg, fab, mesh, x, multiplier_record(system), fr0) <= ATOL
        runs[on] = (np.asarray(x, float).reshape(mesh.n_nodes, 9), info["static"]["dissipated"])
    radius = float(mesh.radius.min())
    (xp, dp), (xf, df) = runs[True], runs[False]
    assert np.abs(xp[:, :3] - xf[:, :3]).max() <= 10 * tol * radius
    assert dp == pytest.approx(df, rel=10 * tol)


def test_stalled_provisional_re_solves_go_on_in_full_to_the_tolerance():
    """With the section frame on the pinned cell at al_tolerance 1e-6 R the provisional
    states' own error sets an overlap floor above the tolerance (1e-5 to 1.5e-4 R from the
    eighth update on, so 20 provisional updates ended at 8.4e-6 R, not met): the provisional
    solves stall (``provisional_stalled``) and full re-solves take the overlap below the
    tolerance, at an exact root of the held history."""
    from rve.config import validate_config
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import strain_step

    scene = _scene("pinned", "augmented_lagrangian", 0.3, substeps=1, frame="section")
    tol = scene["contact"]["al_tolerance"] = 0.1 * TOL
    cfg = validate_config(scene)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    al = info["static"]["augmented_lagrangian"]
    assert info["converged"] and al["met"] and al["provisional_stalled"]
    assert 0 < al["provisional_solves"] < al["solves"] and al["updates"] < 20
    assert system.max_penetration(np.asarray(x, float).reshape(-1)) <= tol
    assert _fresh_residual(cfg, fab, mesh, x, multiplier_record(system), fr0) <= ATOL


class _Loop:
    """The history and penalties of an ``AugmentedLagrangian`` after its updates."""

    def __init__(self, overlaps, penalties, penalty0=50.0):
        self.history = list(enumerate(overlaps))
        self.penalties = list(penalties)
        self.penalty0 = penalty0


def test_provisional_stall_counts_the_updates_at_the_final_penalty_only():
    """``provisional_stalled``: three solves at the current P* without a new smallest overlap
    there stall the provisional solves; rises while P* still grew do not count, and a new
    smallest overlap among the last three does not stall."""
    from rve.homogenisation.multipliers import provisional_stalled

    # P* grew for the solves 1-3 (their overlaps rise and fall), then stays at 800
    grow = ([8e-3, 1.6e-3, 4e-3, 2e-3], [200.0, 800.0, 800.0, 800.0])
    assert not provisional_stalled(_Loop(*grow))
    # at 800: 2e-3 (solve 3, the first at 800), 5e-4, 1.7e-5, then 1.3e-4, 6e-5, 1.5e-4
    stalled = ([8e-3, 1.6e-3, 4e-3, 2e-3, 5e-4, 1.7e-5, 1.3e-4, 6e-5, 1.5e-4],
               [200.0] + [800.0] * 8)
    assert provisional_stalled(_Loop(*stalled))
    assert not provisional_stalled(_Loop(stalled[0][:-1], stalled[1][:-1]))     # only two after the minimum
    assert not provisional_stalled(_Loop(stalled[0][:-1] + [1e-5], stalled[1]))  # a new minimum
    # the same overlaps while P* still grew at every update: no stall
    assert not provisional_stalled(_Loop(stalled[0], [50.0 * 2 ** k for k in range(1, 10)]))


def test_held_loads_freeze_by_key_and_blend_as_the_mean():
    """``hold_loads(x)`` then ``freeze_held()`` freezes the loads ``loads_at(x)`` (after a
    rebuild at the same state, by point key); ``blend_frozen`` with weight 1/2 gives the mean
    of the frozen normal forces and the given ones, point by point."""
    from rve.homogenisation.multipliers import seed_multipliers
    from rve.homogenisation.strain import mech_system, seed_friction
    from rve.solvers.system import friction_of

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=1)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    xf = np.asarray(x0, float).reshape(-1)
    system = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf)
    seed_multipliers(system, lam0)
    seed_friction(system, fr0, xf)
    fr = friction_of(system)
    assert fr.freeze_held() is False and not fr.frozen
    fr.hold_loads(xf)
    want = fr.loads_at(xf)
    system.rebuild(xf + 1e-9)
    assert fr.freeze_held() and fr.frozen
    got = fr.frozen_loads()
    assert np.any(want["f0"] > 0)
    for k in ("f0", "n0", "s_bar", "anchor"):
        np.testing.assert_allclose(got[k], want[k], rtol=0, atol=1e-12)
    other = np.linspace(0.0, 1.0, got["f0"].size)
    fr.blend_frozen(np.array(fr.keys), other, 0.5)
    np.testing.assert_allclose(fr.frozen_loads()["f0"].reshape(-1), 0.5 * (got["f0"].reshape(-1) + other),
                               rtol=1e-14, atol=0)
    fr.unfreeze()


def test_eps_t_is_the_configured_penalty_while_the_loop_raises_it():
    """The Uzawa loop's penalty increase changes the normal law's P*, not the friction law's
    tangential stiffness: the friction forces at a state are the same before and after a
    set_penalty that keeps the line loads (the loop's return to the configured P*)."""
    from rve.homogenisation.multipliers import seed_multipliers
    from rve.homogenisation.strain import friction_record, mech_system, seed_friction, strain_step
    from rve.solvers.system import friction_of

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=1)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x, system, _ = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    xf = x.reshape(-1)
    fresh = mech_system(fab, mesh, cfg, cfg.strain.relax_damping, xf)
    seed_multipliers(fresh, (system.term.multiplier_record()))
    seed_friction(fresh, fr0, xf)
    fr = friction_of(fresh)
    t0 = fr.state(xf).t
    assert np.abs(t0).max() > 0
    fresh.set_penalty(16.0 * fresh.penalty, xf)    # line loads kept at xf
    np.testing.assert_allclose(fr.state(xf).t, t0, rtol=0, atol=1e-12 * np.abs(t0).max())
    assert fr.penalty == cfg.contact.penalty


@pytest.mark.parametrize("frame", ["chord", "section"])
def test_al_multipliers_and_history_through_the_checkpoint_give_a_bit_identical_step(tmp_path, frame):
    """Step 2 from the stored step 1 (multipliers and friction history read from the file)
    equals step 2 from the in-memory records bit for bit; without the history it differs."""
    from rve.homogenisation.checkpoint import State, load_state, write_state
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import friction_record, strain_step

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, frame=frame)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x1, sys1, _ = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    lam1, fr1 = multiplier_record(sys1), friction_record(sys1)
    path = write_state(tmp_path / "s1.nc", State(x=x1, w=np.zeros_like(x1), origin=x0, kind="strained", mode="shear",
                                                  step=1, multipliers=lam1, friction=fr1), fab, mesh)
    back = load_state(path)
    for k in ("keys", "s_bar", "anchor", "d_ref") + (("m_ref",) if frame == "section" else ()):
        np.testing.assert_array_equal(back.friction[k], fr1[k])
    assert (back.friction["m_ref"] is None) == (frame == "chord")
    assert back.friction["dissipated"] == fr1["dissipated"]
    np.testing.assert_array_equal(back.multipliers[1], lam1[1])
    xa, sa, ia = strain_step(cfg, fab, mesh, x1, x0, "shear", 2, multipliers=lam1, friction=fr1)
    xb, sb, ib = strain_step(cfg, fab, mesh, back.x, back.origin, "shear", 2, multipliers=back.multipliers,
                             friction=back.friction)
    assert ia["converged"]
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(multiplier_record(sa)[1], multiplier_record(sb)[1])
    ra, rb = friction_record(sa), friction_record(sb)
    for k in ("keys", "s_bar", "anchor") + (("m_ref",) if frame == "section" else ()):
        np.testing.assert_array_equal(ra[k], rb[k])
    assert ra["dissipated"] == rb["dissipated"]
    xc, _, _ = strain_step(cfg, fab, mesh, x1, x0, "shear", 2, multipliers=lam1, friction=None)
    assert np.abs(xc - xa).max() > 1e-9


# --------------------------------------------------------------------------- the periodic cell
def _image_points(record):
    return np.flatnonzero((np.asarray(record["keys"])[:, 3:5] != 0).any(axis=1))


def test_a_periodic_cell_on_the_smooth_curve_starts_its_history_with_no_elastic_gap():
    """A periodic system built at a state starts every point's friction history there with
    no elastic gap, so no point carries a friction force at that state. On the C¹ curve the
    wraps join the curves across the seams, so a history from the plain cell's first map
    (before the wraps) would hold other closest points near the fibril ends (with either
    law: the start is the law's history at its state)."""
    from rve.homogenisation.periodic import periodic_system
    from rve.solvers.system import friction_of

    cfg = _cfg("periodic", "penalty", 0.3, rows=STACKED, **CURVES[1])
    fab, mesh, x0, _, _ = _relaxed(cfg)
    psys = periodic_system(cfg, fab, mesh, x0, np.eye(3), friction=True)
    st = friction_of(psys).state(psys.restrict(x0.reshape(-1)))
    assert (st.normal > 0).sum() > 100
    assert np.abs(st.t).max() <= 1e-12 * st.normal.max()


def test_periodic_history_of_a_pair_across_a_cell_face_is_carried_by_key():
    """After a periodic shear step with friction some points of pairs with a periodic image
    (a lattice translation in the key) carry a friction force; a system built from scratch
    at the stored state and macro gradient (other shifts in mm: the gradient moved the
    images) seeded by key gives those points the same force, and a map rebuild at the
    state keeps their history bit for bit."""
    from rve.homogenisation.periodic import macro_gradient, periodic_system
    from rve.homogenisation.strain import friction_record, seed_friction, strain_step
    from rve.model.terms.friction import match_rows
    from rve.solvers.system import friction_of

    # whether fibrils touch across a cell face depends on the packing the (frictionless,
    # nonconvex) relaxation lands in, and that on rounding (the MKL build, the kernel path):
    # the first of these cells whose step leaves points of image pairs carrying a force
    for rows in (STACKED, [3, 2], [2, 1]):
        cfg = _cfg("periodic", "penalty", 0.3, rows=rows)
        fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
        assert _image_points(fr0).size > 0
        x1, full1, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, friction=fr0)
        assert info["converged"] and info["residual_N"] <= ATOL
        rec = friction_record(full1)
        t1 = full1.term.friction.last.t.reshape(-1, 3)
        img = _image_points(rec)
        loaded = img[np.linalg.norm(t1[img], axis=1) > 0]
        if loaded.size:
            break
    assert loaded.size > 0
    xf = x1.reshape(-1)
    psys = periodic_system(cfg, fab, mesh, xf, macro_gradient("shear", info["strain"]), friction=True)
    xr = psys.restrict(xf)
    seed_friction(psys, rec, xr)
    fr = friction_of(psys)
    at = match_rows(rec["keys"][loaded], fr.keys)
    assert np.all(at >= 0)
    np.testing.assert_array_equal(fr.s_bar.reshape(-1)[at], rec["s_bar"][loaded])
    np.testing.assert_array_equal(fr.anchor.reshape(-1, 3)[at], rec["anchor"][loaded])
    t2 = fr.state(xr).t.reshape(-1, 3)
    # the committed anchor is e - j with |j| ~ the fibrils' distance and e ~ t/kT far smaller:
    # the trial gap anchor + j is known to the rounding of positions, a few ulp of max |x|
    kt = fr.law.stiffness * fr.penalty * float(np.max(fr.contact.weight))
    np.testing.assert_allclose(t2[at], t1[loaded], rtol=0, atol=16 * np.finfo(float).eps * kt * np.abs(xf).max())
    s_bar, anchor = fr.s_bar.copy(), fr.anchor.copy()
    psys.rebuild(xr)
    at2 = match_rows(rec["keys"][loaded], fr.keys)
    np.testing.assert_array_equal(fr.s_bar.reshape(-1)[at2], s_bar.reshape(-1)[at])
    np.testing.assert_array_equal(fr.anchor.reshape(-1, 3)[at2], anchor.reshape(-1, 3)[at])




@pytest.mark.long
@pytest.mark.slow
def test_periodic_al_friction_jobs_resume_bit_identical(tmp_path):
    """The periodic cell with the augmented Lagrangian and friction through the jobs: the
    relaxed state carries the history of the image pairs too, both steps are stored
    equilibria with their multipliers and history (the probe job's recomputed residual), and
    step 2 rerun in a new process from the stored step 1 (a killed run resumed) is the same
    file content bit for bit."""
    from rve.homogenisation.checkpoint import load_state
    from rve.homogenisation.jobs import recomputed_residual
    from rve.homogenisation.sweeps import load_run_config
    from rve.fabrics.setup import fabric_and_mesh

    spec = {"scene_config": None, "overrides": [],
            "scene": _scene("periodic", "augmented_lagrangian", 0.3, substeps=1, rows=STACKED)}
    a = tmp_path / "a"
    a.mkdir()
    _job("fabric", spec, "", a / "initial.nc")
    _job("relax", spec, a / "initial.nc", a / "relaxed.nc")
    _job("strain", spec, a / "relaxed.nc", a / "shear_01.nc", 1)
    _job("strain", spec, a / "shear_01.nc", a / "shear_02.nc", 2)
    cfg = load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    relaxed = load_state(a / "relaxed.nc")
    assert relaxed.friction["dissipated"] == 0.0 and _image_points(relaxed.friction).size > 0
    d = 0.0
    for i in (1, 2):
        st = load_state(a / f"shear_{i:02d}.nc")
        assert st.solver["converged"] and st.solver["static"]["augmented_lagrangian"]["met"]
        assert recomputed_residual(cfg, fab, mesh, st.x, st.multipliers, st.friction) <= ATOL
        assert st.friction["dissipated"] > d
        d = st.friction["dissipated"]
    b = tmp_path / "b"
    b.mkdir()
    shutil.copy(a / "shear_01.nc", b / "shear_01.nc")
    _job("strain", spec, b / "shear_01.nc", b / "shear_02.nc", 2)
    sa, sb = load_state(a / "shear_02.nc"), load_state(b / "shear_02.nc")
    np.testing.assert_array_equal(sa.x, sb.x)
    for k in ("keys", "s_bar", "anchor"):
        np.testing.assert_array_equal(sa.friction[k], sb.friction[k])
    assert sa.friction["dissipated"] == sb.friction["dissipated"]
    np.testing.assert_array_equal(sa.multipliers[1], sb.multipliers[1])
    assert sa.reaction_force == sb.reaction_force


def _rotation(mu, theta=0.05, frame=None, solve=True, **geometry):
    """The relaxed periodic cell turned rigidly by ``theta`` about z (F = R, the affine map
    about the held node), friction from the relaxed history; ``(P0, R, P at the turned
    state, P after the static solve (None without ``solve``), the friction force there)``
    (``geometry``: the contact geometry and mesh order, ``_scene``'s keys)."""
    from rve.homogenisation.cell_statics import static_minimize
    from rve.homogenisation.multipliers import equilibrium
    from rve.homogenisation.periodic import _affine_predictor, periodic_system
    from rve.homogenisation.strain import seed_friction
    from rve.solvers.system import friction_of

    cfg = _cfg("periodic", "penalty", mu, rows=STACKED, frame=frame, **geometry)
    fab, mesh, x0, _, fr0 = _relaxed(cfg)
    p0 = periodic_system(cfg, fab, mesh, x0, np.eye(3))
    P0 = p0.macro_stress(p0.restrict(x0.reshape(-1)))
    c, s = np.cos(theta), np.sin(theta)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    held = int(mesh.node_offsets[0])
    xt = _affine_predictor(x0, R, x0[held, :3])
    psys = periodic_system(cfg, fab, mesh, xt, R, friction=True)
    xr = psys.restrict(xt.reshape(-1))
    seed_friction(psys, fr0, xr)
    fr = friction_of(psys)
    t_pred = 0.0 if fr is None else float(np.abs(fr.state(xr).t).max())
    P_pred = psys.macro_stress(xr)
    if not solve:
        return P0, R, P_pred, None, t_pred
    xs, info = equilibrium(psys, lambda v: static_minimize(psys, v, ATOL, 400, commit=False), xr)
    assert info["converged"]
    return P0, R, P_pred, psys.macro_stress(xs), t_pred


def test_rigid_rotation_without_friction_is_objective():
    """The rigidly turned relaxed cell without friction is an equilibrium with P = R P0 (the
    check of the rotation below)."""
    P0, R, P_pred, P_solved, t_pred = _rotation(0.0)
    scale = np.abs(P0).max()
    assert t_pred == 0.0
    assert np.abs(P_pred - R @ P0).max() <= 1e-12 * scale
    assert np.abs(P_solved - R @ P0).max() <= 1e-10 * scale


@pytest.mark.xfail(strict=True, reason="the position-based law's trial gap is objective under rotations across the - "
                                       "chord only: a rotation about z has a twist part about the crimped, tilted "
                                       "chords, which positions cannot tell from sliding around the - fibril, so "
                                       "the points slip and the solved cell keeps friction forces (docs/contact.md "
                                       "'Rigid rotation': 2 % of |P0| at 0.05 rad)")
def test_rigid_rotation_with_friction_gives_the_frictionless_macro_stress():
    """Friction (the position-based law, ``friction.frame: chord``) from the relaxed history: the
    turned cell should carry no friction force and P = R P0 (the friction forces of pairs across
    the faces enter P as the normal forces of those pairs do, so any spurious slip shows
    there)."""
    P0, R, _, P_solved, t_pred = _rotation(0.3, frame="chord")
    assert t_pred > 0
    assert np.abs(P_solved - R @ P0).max() <= 1e-6 * np.abs(P0).max()


#: the contact geometries and mesh orders the section frame is checked on beyond the chords at p = 1
CURVES = [{"geometry": "curve", "order": 2}, {"geometry": "smooth", "order": 2}]


@pytest.mark.parametrize("theta, geometry", [(0.05, {}), (0.3, {}), (0.3, CURVES[1])])
def test_rigid_rotation_with_the_section_frame_gives_the_frictionless_macro_stress(theta, geometry):
    """With the anchor carried by the - cross-section's frame (``friction.frame: section``)
    the rigidly turned cell has no friction force, before or after the solve, and P = R P0 to
    round-off, the twist about the tilted chords included (on the C¹ curve at p = 2 too)."""
    P0, R, P_pred, P_solved, t_pred = _rotation(0.3, theta, frame="section", **geometry)
    t_chord = _rotation(0.3, theta, frame="chord", solve=False, **geometry)[4]   # the chord law's slip force
    scale = np.abs(P0).max()
    assert t_pred <= 1e-9 * t_chord
    assert np.abs(P_pred - R @ P0).max() <= 1e-10 * scale
    assert np.abs(P_solved - R @ P0).max() <= 1e-10 * scale


def _tangent_matches_differences(system, x, nodes, eps):
    """The assembled tangent at ``x``'s columns of the centroids and first directors of
    ``nodes`` against central differences of the residual (step ``eps``); the tangent, dense."""
    from rve.testing import fd_jacobian

    cols = np.concatenate([system.layout.dofs("r", nodes), system.layout.dofs("g1", nodes)])
    w = np.zeros(system.n)
    K = system.evaluate(x, w, 0.0)[1].toarray()
    J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], x, cols, eps=eps)
    np.testing.assert_allclose(K[:, cols], J, rtol=1e-5, atol=1e-6 * np.abs(K[:, cols]).max())
    return K


def test_section_frame_tangent_of_the_assembled_system():
    """The pinned cell's system after a frictional step with ``friction.frame: section``, at a
    trial state off it (points in stick and in slip): the assembled tangent's columns of the
    centroids and first directors of the - sections in contact match differences of the
    residual, and the section frame's blocks couple the directors with the other fibril."""
    system, x = section_frame_cell_off_its_step(3)
    fr = system.term.friction
    st = fr.state(x)
    assert st.stick.any() and st.slip.any()
    act = np.flatnonzero((st.stick | st.slip).any(axis=1))[:4]
    nodes = np.unique(np.concatenate([system.term.map.nodes_minus[act, 0], system.term.map.nodes_plus[act, 0]]))
    K = _tangent_matches_differences(system, x, nodes, eps=1e-7)
    g1 = system.layout.dofs("g1", system.term.map.nodes_minus[act, 0])
    other = system.layout.dofs("r", system.term.map.nodes_plus[act, 0])
    assert np.abs(K[np.ix_(other, g1)]).max() > 0


@pytest.mark.parametrize("boundary, geometry", [("pinned", CURVES[0]), ("periodic", CURVES[1])])
def test_section_frame_tangent_on_the_curves(boundary, geometry):
    """The section frame on the curve geometries at p = 2 (the section node the - element's
    middle one): after a frictional step, at a trial state off it with points in stick and in
    slip, the assembled tangent's columns of the centroids and g1 of the local nodes of rows
    in contact match central differences (their error falls as eps²: 1e-8 here), and the
    section node's g1 couples to the other side."""
    from rve.homogenisation.strain import strain_step

    cfg = _cfg(boundary, "augmented_lagrangian", 0.3, substeps=1, frame="section", **geometry)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x1, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    assert info["converged"]
    xs = np.asarray(x1, float).reshape(-1)
    x = xs + np.random.default_rng(3).normal(size=xs.size) * 1e-5
    fr, term = system.term.friction, system.term
    system.rebuild(x)
    st = fr.state(x)
    assert st.stick.any() and st.slip.any()
    rows = np.flatnonzero((st.stick | st.slip).any(axis=1))[:4]
    ps, conn = term.passes, mesh.conn
    a_nodes, b_nodes = ps.side_nodes(conn, ps.a_elem[rows]), ps.side_nodes(conn, ps.b_elem[rows])
    nodes = np.unique(np.concatenate([a_nodes.ravel(), b_nodes.ravel()]))
    K = _tangent_matches_differences(system, x, nodes, eps=1e-8)
    section = conn[ps.b_elem[rows], fr.section_node()]
    g1, other = system.layout.dofs("g1", section), system.layout.dofs("r", a_nodes.ravel())
    assert np.abs(K[np.ix_(other, g1)]).max() > 0


def test_section_frame_term_with_no_pair_in_contact():
    """The section frame's widened blocks with no pair in contact (the map built at the relaxed
    cell, the fibrils then moved apart across the plane): the residual and tangent are the
    frictionless system's, no contact force at all."""
    from rve.homogenisation.strain import mech_system

    cfg = _cfg("pinned", "penalty", 0.3, frame="section")
    fab, mesh, x0, _, _ = _relaxed(cfg)
    xf = np.asarray(x0, float).reshape(-1)
    far = np.asarray(x0, float).copy()
    far[:, 2] *= 4.0                      # the crossings' gaps opened fourfold
    far = far.reshape(-1)
    with_friction = mech_system(fab, mesh, cfg, 0.0, xf)
    frictionless = mech_system(fab, mesh, cfg, 0.0, xf, friction=False)
    assert with_friction.term.map.n_pairs > 0 and with_friction.term.friction.frame
    w = np.zeros(with_friction.n)
    for jac in (False, True):
        F, Fx, _ = with_friction.evaluate(far, w, 0.0, jacobian=jac)
        F0, Fx0, _ = frictionless.evaluate(far, w, 0.0, jacobian=jac)
        np.testing.assert_allclose(F, F0, rtol=0, atol=1e-12 * np.abs(F0).max())
        if jac:
            assert abs(Fx - Fx0).max() <= 1e-12 * abs(Fx0).max()


@pytest.mark.parametrize("boundary, geometry", [("pinned", {}), ("periodic", {}), ("periodic", CURVES[1])])
def test_section_frame_matrices_leave_out_only_the_structural_zeros(boundary, geometry):
    """With ``friction.frame: section`` the contact blocks widened by g1 are handed out on the
    entries the forms can fill (``ContactTerm.local_sparsity``, ``UnionPattern.restrict``):
    the tangent equals the one on the whole widened union entry by entry (nothing filled was
    left out), with the exact law and at frozen loads, on fewer stored entries."""
    from rve.homogenisation.strain import strain_step

    cfg = _cfg(boundary, "augmented_lagrangian", 0.3, substeps=1, frame="section", **geometry)
    fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
    x1, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=fr0)
    assert info["converged"]
    x = np.asarray(x1, float).reshape(-1) + np.random.default_rng(5).normal(size=system.n) * 3e-5
    system.rebuild(x)
    fr = system.term.friction
    union = system.assembler.union
    w = np.zeros(system.n)
    for frozen in (False, True):
        if frozen:
            fr.freeze(x)
        y = x + np.random.default_rng(6).normal(size=system.n) * 1e-5
        kept = system.evaluate(y, w, 0.0)[1]
        keep = union.keep
        assert keep is not None
        union.restrict(None)
        whole = system.evaluate(y, w, 0.0)[1]
        union.restrict(np.isin(np.arange(union.nnz), keep))
        assert kept.nnz < whole.nnz
        assert (kept.toarray() == whole.toarray()).all()
    fr.unfreeze()


# --------------------------------------------------------------------------- mu = 0
@pytest.mark.parametrize("boundary, enforcement", [("pinned", "augmented_lagrangian"),
                                                   ("periodic", "augmented_lagrangian"), ("periodic", "penalty")])
def test_mu_zero_is_the_frictionless_path_bit_for_bit(boundary, enforcement):
    """friction.coefficient: 0 with the augmented Lagrangian / in the periodic cell builds no
    friction term: the step's state and multipliers equal those of the config without the
    section, bit for bit, and carry no history."""
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import friction_record, strain_step

    out = []
    for mu in (0.0, None):
        cfg = _cfg(boundary, enforcement, mu)
        assert not cfg.has_friction
        fab, mesh, x0, lam0, fr0 = _relaxed(cfg)
        assert fr0 is None
        x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=None)
        assert "friction" not in info and friction_record(system) is None
        out.append((x0, x, multiplier_record(system), info.get("reaction_force")))
    (a0, a, la, ra), (b0, b, lb, rb) = out
    np.testing.assert_array_equal(a0, b0)
    np.testing.assert_array_equal(a, b)
    if la is not None:
        np.testing.assert_array_equal(la[1], lb[1])
    assert ra == rb


def test_frictional_steps_of_the_periodic_cell_pass_the_one_path_test():
    """``strain.follow_branch`` with friction on the periodic cell of stacked yarns on the
    quasi-static path (two sub-increments a step): the two shear steps are tested by their energy balance with the dissipation
    (``rve.homogenisation.friction_path``; the Hill-Mandel work rate with the friction
    forces of the committed history), step 1 after its start-up, step 2 from step 1's
    history; both pass without a detection. The stacked yarns have contact pairs across the
    cell faces, whose friction forces are part of the face forces: the work rate with the
    history not seeded differs."""
    from types import SimpleNamespace

    from rve.homogenisation.friction_path import frictional_energy
    from rve.homogenisation.multipliers import multiplier_record
    from rve.homogenisation.strain import friction_record, strain_step

    fab, mesh, x0, lam0, rec0 = _relaxed(_cfg("periodic", "penalty", 0.3, rows=STACKED))
    cfg = _cfg("periodic", "penalty", 0.3, rows=STACKED, follow_branch=True)
    x1, s1, i1 = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=rec0)
    x2, s2, i2 = strain_step(cfg, fab, mesh, x1, x0, "shear", 2, multipliers=multiplier_record(s1),
                             friction=friction_record(s1))
    for info in (i1, i2):
        b = info["branch"]
        assert info["converged"] and not b.get("untested") and b["checks"] and b["detections"] == 0, b
        assert abs(b["checks"][0]["mismatch"]) < b["checks"][0]["tolerance"]
    assert i1["branch"]["start_up"] is not None and i2["branch"]["start_up"] is None
    cell = SimpleNamespace(periodic=True, fab=fab, mesh=mesh, origin=x0, mode="shear")
    rec2 = friction_record(s2)
    with_fr = frictional_energy(cfg, cell, None, x2, 0.1, multiplier_record(s2), rec2)
    without = frictional_energy(cfg, cell, None, x2, 0.1, multiplier_record(s2), {**rec2, "keys": rec2["keys"][:0],
                                                                                   "s_bar": rec2["s_bar"][:0],
                                                                                   "anchor": rec2["anchor"][:0],
                                                                                   "d_ref": rec2["d_ref"][:0]})
    assert with_fr[0] == without[0]
    assert abs(with_fr[1] - without[1]) > 0.05 * abs(with_fr[1])
    # one increment a step (off the quasi-static path): solved once, marked untested
    single = _cfg("periodic", "penalty", 0.3, rows=STACKED, follow_branch=True, path="algorithm_7_1")
    _, _, i1 = strain_step(single, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=rec0)
    assert i1["converged"] and i1["branch"]["untested"] == "friction" and not i1["branch"].get("checks")


def test_a_failed_periodic_step_is_cut_and_solved_again_from_its_start(monkeypatch):
    """A frictional step of the periodic cell whose one-increment solve fails is solved again
    from its start in two sub-increments (``strain.max_cuts``): the multipliers and friction
    history of the start are seeded afresh, so the state, multipliers and history equal those
    of the step run in two sub-increments directly, bit for bit, and the record names the cut.
    With ``max_cuts: 0`` the failure stands."""
    import rve.homogenisation.periodic as periodic
    from rve.homogenisation.strain import friction_record, strain_step

    real = periodic.equilibrium
    calls = []

    def failing_once(psys, static, xr):
        xs, info = real(psys, static, xr)
        calls.append(info["converged"])
        if len(calls) == 1:   # the one-increment solve: reported failed
            info = dict(info, converged=False)
        return xs, info

    out = {}
    for name, substeps, cuts in (("cut", 1, 2), ("direct", 2, 2), ("none", 1, 0)):
        cfg = _cfg("periodic", "penalty", 0.3, substeps=substeps, rows=STACKED, max_cuts=cuts)
        fab, mesh, x0, lam0, rec0 = _relaxed(_cfg("periodic", "penalty", 0.3, rows=STACKED))
        calls.clear()
        if name != "direct":
            monkeypatch.setattr(periodic, "equilibrium", failing_once)
        x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=rec0)
        monkeypatch.setattr(periodic, "equilibrium", real)
        out[name] = (x, info, friction_record(system))
    x, info, rec = out["cut"]
    xd, infod, recd = out["direct"]
    assert info["converged"] and info["cuts"][0]["substeps"] == 1 and len(info["substeps"]) == 2
    np.testing.assert_array_equal(x, xd)
    for key in ("s_bar", "anchor", "d_ref"):
        np.testing.assert_array_equal(rec[key], recd[key])
    assert info["friction"]["dissipated"] == infod["friction"]["dissipated"]
    assert not out["none"][1]["converged"] and "cuts" not in out["none"][1]


def test_a_try_that_can_still_be_cut_bounds_the_fallback(monkeypatch):
    """The frictional solves of a try that ``strain.max_cuts`` can still cut bound their
    capped-Newton fallback (``CUT_STALL_WINDOW``, down to ``frictional_solve``); the last try
    has all of it, and so does a step with ``max_cuts: 0``."""
    import rve.homogenisation.cell_statics as statics
    import rve.homogenisation.periodic as periodic
    from rve.homogenisation.strain import strain_step

    real_eq, real_solve = periodic.equilibrium, statics.frictional_solve
    tries, bounds = [], []

    def failing_first(psys, static, xr):
        xs, info = real_eq(psys, static, xr)
        tries.append(len(bounds))
        return xs, (dict(info, converged=False) if len(tries) == 1 else info)

    def recording(*a, **k):
        bounds.append(k["fallback_stall"])
        return real_solve(*a, **k)

    monkeypatch.setattr(statics, "frictional_solve", recording)
    seen = {}
    for cuts in (1, 0):
        cfg = _cfg("periodic", "penalty", 0.3, rows=STACKED, max_cuts=cuts)
        fab, mesh, x0, lam0, rec0 = _relaxed(_cfg("periodic", "penalty", 0.3, rows=STACKED))
        tries.clear()
        bounds.clear()
        monkeypatch.setattr(periodic, "equilibrium", failing_first)
        _, _, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=rec0)
        monkeypatch.setattr(periodic, "equilibrium", real_eq)
        seen[cuts] = (info, list(tries), list(bounds))
    info, tries1, b = seen[1]
    assert info["converged"] and len(info["cuts"]) == 1
    assert tries1[0] and b[:tries1[0]] == [statics.CUT_STALL_WINDOW] * tries1[0]
    assert len(b) > tries1[0] and all(v is None for v in b[tries1[0]:])
    info0, _, b0 = seen[0]
    assert not info0["converged"] and b0 and all(v is None for v in b0)


def test_a_failed_pinned_step_is_cut_into_parts_chained_from_its_start(monkeypatch):
    """A frictional step of the pinned cell whose solve fails is solved again from its start
    in two parts (``strain.max_cuts``), the second from the first's state, multipliers and
    committed friction history: the state and history equal those of the two parts run one
    after the other directly, bit for bit; the record names the cut and the parts, and its
    step dissipation is the two parts' sum; the first try ends a stalled frictional fallback
    early (``CUT_STALL_WINDOW``), the last one has all of it. With ``max_cuts: 0`` the failure
    stands."""
    import rve.homogenisation.strain as strain
    from rve.homogenisation.cell_statics import CUT_STALL_WINDOW
    from rve.homogenisation.strain import friction_record, multiplier_record, strain_step

    real = strain._quasi_static_step
    calls, stalls = [], []

    def failing_once(*a, **k):
        x, system, info = real(*a, **k)
        calls.append(info["converged"])
        stalls.append(k["fallback_stall"])
        return x, system, (dict(info, converged=False) if len(calls) == 1 else info)

    cfg = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=1, max_cuts=2)
    fab, mesh, x0, lam0, rec0 = _relaxed(cfg)
    monkeypatch.setattr(strain, "_quasi_static_step", failing_once)
    x, system, info = strain_step(cfg, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=rec0)
    monkeypatch.setattr(strain, "_quasi_static_step", real)
    eps = strain.strain_levels(cfg)[1]
    x1, s1, i1 = real(cfg, fab, mesh, x0, x0, "shear", 1, 0.0, eps / 2, multipliers=lam0, friction=rec0)
    x2, s2, i2 = real(cfg, fab, mesh, x1, x0, "shear", 1, eps / 2, eps, multipliers=multiplier_record(s1),
                      friction=friction_record(s1))
    assert info["converged"] and info["cuts"][0]["substeps"] == 1 and len(info["parts"]) == 2
    assert stalls == [CUT_STALL_WINDOW] * 3      # the two-part try could still be cut to four
    assert info["strain"] == eps and info["strain_increment"] == eps
    np.testing.assert_array_equal(x, x2)
    rec, rec2 = friction_record(system), friction_record(s2)
    for key in ("s_bar", "anchor", "d_ref"):
        np.testing.assert_array_equal(rec[key], rec2[key])
    assert info["friction"]["step_dissipated"] == pytest.approx(
        i1["friction"]["step_dissipated"] + i2["friction"]["step_dissipated"], rel=1e-12)
    assert info["friction"]["dissipated"] == i2["friction"]["dissipated"]
    calls.clear()
    stalls.clear()
    none = _cfg("pinned", "augmented_lagrangian", 0.3, substeps=1, max_cuts=0)
    monkeypatch.setattr(strain, "_quasi_static_step", failing_once)
    _, _, info0 = strain_step(none, fab, mesh, x0, x0, "shear", 1, multipliers=lam0, friction=rec0)
    assert not info0["converged"] and "cuts" not in info0 and len(calls) == 1 and stalls == [None]
