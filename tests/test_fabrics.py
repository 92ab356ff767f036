"""Fabric generators: thesis plain weave, pattern weaves, knitted loops."""
from collections import Counter

import numpy as np
import pytest

from rve.fabrics import (
    CurveFrame,
    basket_weave,
    float_lengths,
    frenet_directors,
    hex_stack_offsets,
    knit,
    knit_curve,
    minimal_rotation,
    plain_weave,
    twill_weave,
    weave,
)

A = 0.525


@pytest.fixture(scope="module")
def plain():
    fab = plain_weave()
    mesh = fab.mesh(16, 2)
    return fab, mesh, fab.initial_state(mesh)


def _rowdot(u, v):
    return np.einsum("ij,ij->i", u, v)


def _check_frame(t, g1, g2, tol=1e-12):
    assert np.allclose(_rowdot(g1, g1), 1, atol=tol)
    assert np.allclose(_rowdot(g2, g2), 1, atol=tol)
    assert np.allclose(_rowdot(g1, g2), 0, atol=tol)
    assert np.allclose(_rowdot(g1, t), 0, atol=tol)
    assert np.allclose(_rowdot(g2, t), 0, atol=tol)
    assert np.allclose(np.cross(g1, g2), t, atol=tol)


def _fd_tangent(frame, s, h=1e-6):
    t = frame(s + h)[0] - frame(s - h)[0]
    return t / np.linalg.norm(t, axis=1, keepdims=True)


# ------------------------------------------------------------------ plain weave
def test_plain_weave_counts_and_positions(plain):
    fab, mesh, _ = plain
    assert fab.n_fibrils == 80 and mesh.n_fibrils == 80
    assert len(fab.yarns) == 8
    assert np.allclose(fab.half_widths[:2], [4.0, 4.0])
    warp = [y for y in fab.yarns if y.direction == "warp"]
    weft = [y for y in fab.yarns if y.direction == "weft"]
    assert [y.position for y in warp] == [-3.0, -1.0, 1.0, 3.0]
    assert [y.position for y in weft] == [-3.0, -1.0, 1.0, 3.0]
    assert all(len(y.fibrils) == 10 for y in fab.yarns)
    assert Counter(fab.fibril_direction) == {"warp": 40, "weft": 40}
    assert np.allclose(mesh.radius, 0.15)
    assert fab.yarn_at("warp", -1.0).name == "warp1"
    for f, y in enumerate(fab.fibril_yarn):
        assert f in fab.yarns[y].fibrils


def test_reference_is_straight_and_stack_does_not_overlap(plain):
    fab, mesh, _ = plain
    for yarn in fab.yarns:
        ends = []
        for f in yarn.fibrils:
            X = mesh.X0[mesh.fibril_nodes(f), :3]
            d = X[-1] - X[0]
            # straight, spanning -4..4 along the yarn
            assert np.allclose(np.cross(X - X[0], d), 0, atol=1e-12)
            axis = 0 if yarn.direction == "warp" else 1
            assert np.allclose(sorted([X[0, axis], X[-1, axis]]), [-4, 4])
            ends.append(X[0])
        ends = np.array(ends)
        dist = np.linalg.norm(ends[:, None] - ends[None], axis=-1)
        dist[np.diag_indices(len(ends))] = np.inf
        assert dist.min() >= 0.3 - 1e-12
        # centred on the yarn line, rows 3-4-3 stacked in z
        lat = 1 if yarn.direction == "warp" else 0
        assert np.isclose(ends[:, lat].mean(), yarn.position)
        assert np.isclose(ends[:, 2].mean(), 0.0, atol=1e-12)
        assert sorted(Counter(np.round(ends[:, 2], 9)).values()) == [3, 3, 4]


def test_crimp_amplitude_and_alternating_sign(plain):
    fab, _, _ = plain
    s = np.linspace(0, 8, 401)
    signs = {}
    for yarn in fab.yarns:
        c = yarn.centreline(s)
        along = c[:, 0] if yarn.direction == "warp" else c[:, 1]
        ref = A * np.sin(np.pi * along / 2.0)
        sign = np.sign(c[np.argmax(np.abs(ref)), 2] * ref[np.argmax(np.abs(ref))])
        assert np.allclose(c[:, 2], sign * ref, atol=1e-12)
        assert np.isclose(np.abs(c[:, 2]).max(), A)
        signs.setdefault(yarn.direction, []).append(sign)
    for d in ("warp", "weft"):
        assert all(a == -b for a, b in zip(signs[d], signs[d][1:]))
    # warp and weft in opposite phase: warp j and weft j have opposite signs
    assert all(a == -b for a, b in zip(signs["warp"], signs["weft"]))


def test_warp_and_weft_interlace_at_every_crossing(plain):
    fab, _, _ = plain
    top = fab.params["warp_on_top"]
    assert np.array_equal(top, np.indices((4, 4)).sum(0) % 2 == 0)
    for j, wy in enumerate(fab.params["warp_y"]):
        for i, wx in enumerate(fab.params["weft_x"]):
            zw = fab.yarns[j].centreline(np.array([wx + 4.0]))[0]
            zf = fab.yarns[4 + i].centreline(np.array([wy + 4.0]))[0]
            assert np.allclose(zw[:2], [wx, wy]) and np.allclose(zf[:2], [wx, wy])
            expect = 2 * A if top[j, i] else -2 * A
            assert np.isclose(zw[2] - zf[2], expect)


def test_initial_state_displaced_and_directors(plain):
    fab, mesh, x = plain
    assert x.shape == (mesh.n_nodes, 9)
    assert not np.allclose(x[:, 2], mesh.X0[:, 2])  # stressed: displaced from reference
    assert np.allclose(x[:, 0:2][mesh.node_fibril < 40][:, 1],
                       mesh.X0[mesh.node_fibril < 40][:, 1])  # warp stays in its y plane
    for f in (0, 5, 13, 47, 79):
        s = mesh.node_s[mesh.fibril_nodes(f)]
        t = _fd_tangent(fab.designed[f], s)
        r, g1, g2 = fab.designed[f](s)
        _check_frame(t, g1, g2, tol=1e-8)
    # stack packing kept perpendicular to the crimped axis: neighbours stay >= d apart
    for yarn in fab.yarns[:2]:
        s = np.linspace(0, 8, 161)
        P = np.array([fab.designed[f](s)[0] for f in yarn.fibrils])  # (10, n, 3)
        d = np.linalg.norm(P[:, None] - P[None], axis=-1)
        d[np.arange(10), np.arange(10)] = np.inf
        assert d.min() >= 0.3 * (1 - 1e-3)


def test_end_tags_on_boundaries(plain):
    fab, mesh, x = plain
    assert len(fab.end_tags) == 2 * fab.n_fibrils
    want = {"x-": (0, -4.0), "x+": (0, 4.0), "y-": (1, -4.0), "y+": (1, 4.0)}
    for tag in fab.end_tags:
        comp, val = want[tag.side]
        assert np.isclose(x[tag.node(mesh), comp], val)
        assert np.isclose(mesh.X0[tag.node(mesh), comp], val)
        direction = fab.yarns[tag.yarn].direction
        assert tag.side[0] == ("x" if direction == "warp" else "y")
        assert fab.fibril_yarn[tag.fibril] == tag.yarn
    assert len(fab.tags("x+", yarn=1)) == 10
    assert len(fab.end_nodes(mesh, "y-")) == 40


# ------------------------------------------------------------------ other weaves
def _warp_states(fab):
    """warp-on-top matrix measured from the designed centrelines at the crossings."""
    nw, nf = fab.params["n_warp"], fab.params["n_weft"]
    st = np.zeros((nw, nf), int)
    for j in range(nw):
        for i, wx in enumerate(fab.params["weft_x"]):
            zw = fab.yarns[j].centreline(np.array([wx + fab.half_widths[0]]))[0, 2]
            zf = fab.yarns[nw + i].centreline(
                np.array([fab.params["warp_y"][j] + fab.half_widths[1]]))[0, 2]
            assert np.isclose(abs(zw - zf), 2 * A)
            st[j, i] = zw > zf
    return st


def test_twill_float_lengths():
    fab = twill_weave(2, 1)  # 6 x 6
    st = _warp_states(fab)
    for j in range(6):
        runs = float_lengths(st[j])
        over = [r for r, v in zip(runs, _run_values(st[j])) if v == 1]
        under = [r for r, v in zip(runs, _run_values(st[j])) if v == 0]
        assert over == [2, 2] and under == [1, 1]
    # diagonal: warp j+1 is warp j shifted by one weft
    for j in range(5):
        assert np.array_equal(st[j + 1], np.roll(st[j], 1))
    # weft floats: under 2, over 1
    for i in range(6):
        assert sorted(float_lengths(st[:, i])) == [1, 1, 2, 2]
    st22 = _warp_states(twill_weave(2, 2, n_warp=4, n_weft=8))
    assert all(float_lengths(row) == [2, 2, 2, 2] for row in st22)


def _run_values(row):
    row = np.asarray(row)
    change = np.flatnonzero(row != np.roll(row, 1))
    return [row[c] for c in np.sort(change)]


def test_basket_and_plain_from_same_code_path():
    st = _warp_states(basket_weave())
    assert np.array_equal(st, [[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 1], [0, 0, 1, 1]])
    assert float_lengths([1, 1, 0, 0]) == [2, 2]
    assert float_lengths([1, 0, 1, 1, 0, 1]) == [1, 2, 1, 2]  # cyclic: last 1 joins first
    p = weave([[1, 0], [0, 1]], n_warp=2, n_weft=2, rows=(1,))
    assert p.n_fibrils == 4 and np.allclose(p.half_widths[:2], [2, 2])
    # a flat float stays at +-A between crossings
    fab = basket_weave(rows=(1,))
    z = fab.yarns[0].centreline(np.linspace(1.0, 3.0, 11))[:, 2]
    assert np.allclose(z, A)


def test_hex_stack_offsets_and_minimal_rotation():
    for rows in [(3, 4, 3), (1, 2), (3, 3), (2, 3, 2)]:
        o = hex_stack_offsets(rows, 0.3)
        assert np.allclose(o.mean(0), 0)
        d = np.linalg.norm(o[:, None] - o[None], axis=-1)
        d[np.diag_indices(len(o))] = np.inf
        assert np.isclose(d.min(), 0.3)
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3)); a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = a + 0.7 * rng.normal(size=(50, 3)); b /= np.linalg.norm(b, axis=1, keepdims=True)
    v = rng.normal(size=(50, 3))
    assert np.allclose(minimal_rotation(a, b, a), b)
    assert np.allclose(np.linalg.norm(minimal_rotation(a, b, v), axis=1),
                       np.linalg.norm(v, axis=1))
    ax = np.cross(a, b)
    assert np.allclose(minimal_rotation(a, b, ax), ax)


# ------------------------------------------------------------------ knit
def _angle_steps(g):
    return np.arccos(np.clip(_rowdot(g[1:], g[:-1]), -1, 1))


def _curve(**kw):
    par = dict(A1=0.0, A2=0.0, B=0.0, C=0.0, p=np.pi)
    par.update(kw)
    d1 = lambda s: knit_curve(s, **par)[1]
    d2 = lambda s: knit_curve(s, **par)[2]
    return d1, d2


@pytest.mark.parametrize("kw", [
    dict(A1=0.8, A2=0.4, B=0.5),      # the loop: curvature never vanishes
    dict(A1=0.8),                     # planar sine: y'' = 0 at inflections
    dict(A2=0.3, B=0.2),              # planar, inflections where cos(p X3) = -B p
    dict(),                           # straight: y'' = 0 everywhere
    dict(B=0.2),                      # straight, non-uniform speed: y'' || y'
])
def test_curve_frame_orthonormal_continuous(kw):
    d1, d2 = _curve(**kw)
    fr = CurveFrame(d1, d2, -4.0, 4.0)
    s = np.linspace(-4.0, 4.0, 3001)
    # hit the inflection points exactly
    s = np.sort(np.concatenate([s, [-3.0, -1.0, 1.0, 3.0, -2.5, -0.5, 0.5]]))
    T, g1, g2 = fr(s)
    _check_frame(T, g1, g2)
    assert np.allclose(T, d1(s) / np.linalg.norm(d1(s), axis=1, keepdims=True))
    ds = np.diff(s).max()
    # continuity: no jumps (the frame turns by at most a few curvature * ds per step)
    assert _angle_steps(g1).max() < 0.1 and _angle_steps(g2).max() < 0.1
    # Frenet where the curvature is well defined: G1 = +-binormal, G2 = +-(-normal)
    _, b, mn, kap = frenet_directors(d1(s), d2(s))
    good = kap > 1e-3 * max(kap.max(), 1e-300)
    if good.any():
        c1 = _rowdot(g1[good], b[good])
        c2 = _rowdot(g2[good], mn[good])
        assert np.allclose(np.abs(c1), 1, atol=1e-10) and np.allclose(c1, c2, atol=1e-10)
    else:
        assert np.allclose(g1, g1[0])  # straight line: constant fallback frame
    assert ds < 0.01


def test_knit_sine_flip_absorbed():
    # planar sine in the e1-e3 plane: the Frenet binormal flips sign at every
    # inflection; the continuous frame keeps one orientation (perpendicular to the plane)
    d1, d2 = _curve(A1=0.8)
    fr = CurveFrame(d1, d2, -4.0, 4.0)
    _, g1, _ = fr(np.linspace(-4, 4, 801))
    assert np.allclose(np.abs(g1[:, 1]), 1) and np.all(np.sign(g1[:, 1]) == np.sign(g1[0, 1]))


@pytest.fixture(scope="module")
def knitted():
    fab = knit()
    mesh = fab.mesh(64, 2)
    return fab, mesh


def test_knit_fabric(knitted):
    fab, mesh = knitted
    assert fab.n_fibrils == 9 and len(fab.yarns) == 3
    assert set(fab.fibril_direction) == {"loop"}
    x = fab.initial_state(mesh)
    assert np.array_equal(x, mesh.X0)  # the curve is the natural configuration
    hx = fab.half_widths[0]
    for tag in fab.end_tags:
        assert tag.side in ("x-", "x+")
        # the yarn axis ends on the box faces; fibrils within the stack reach of it
        sign = -1 if tag.side == "x-" else 1
        assert abs(x[tag.node(mesh), 0] - sign * hx) < 0.35
    for yarn in fab.yarns:
        ends = yarn.centreline(np.array([0.0, fab.fibrils[0].length]))
        assert np.allclose(ends[:, 0], [-hx, hx])
    # directors orthonormal, perpendicular to each fibril's tangent, right-handed
    s = np.linspace(0, fab.fibrils[0].length, 1501)
    for f in range(fab.n_fibrils):
        r, g1, g2 = fab.fibrils[f].frame(s)
        t = _fd_tangent(fab.fibrils[f].frame, s, h=1e-5)
        _check_frame(t, g1, g2, tol=1e-6)
        assert _angle_steps(g1).max() < 0.2


def test_knit_yarn_axis_frenet_and_spacing(knitted):
    fab, _ = knitted
    s = np.linspace(0, fab.fibrils[0].length, 2001)
    fr = fab.params["frames"][0]
    T, g1, g2 = fr(s)
    _check_frame(T, g1, g2)
    _, b, mn, kap = frenet_directors(fr.d1(s), fr.d2(s))
    assert kap.min() > 0  # this loop has no inflection
    assert np.allclose(np.abs(_rowdot(g1, b)), 1, atol=1e-10)

def test_knit_courses_do_not_interpenetrate():
    # fibrils of different courses stay more than a diameter apart in the reference
    from rve.contact import build_contact_map
    fab = knit(n_rows=4)
    mesh = fab.mesh(200, 1)
    cmap = build_contact_map(mesh.X0, mesh, cutoff=0.3, n_gp=1)
    yp, ym = fab.fibril_yarn[cmap.fibril_plus], fab.fibril_yarn[cmap.fibril_minus]
    assert np.all(yp == ym)


def test_knit_straight_fallback_and_bad_offsets():
    fab = knit(A1=0.0, A2=0.0, B=0.0, n_rows=1, rows=(1, 2))
    mesh = fab.mesh(8, 1)
    X = mesh.X0
    _check_frame(np.tile([1.0, 0, 0], (mesh.n_nodes, 1)), X[:, 3:6], X[:, 6:9])
    with pytest.raises(ValueError):
        knit(B=2.0, rows=(3, 4, 3))
    with pytest.raises(ValueError):
        knit(row_phase=0.3)
