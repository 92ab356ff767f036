"""Contact search: KD-tree candidate pairs vs an all-pairs brute force; closest points."""
import numpy as np
import pytest

from rve.contact import (
    build_contact_map,
    candidate_pairs,
    closest_points,
    gauss_fractions,
    segment_distance,
)
from rve.fem.mesh import fibril_mesh, straight_fibril


# ------------------------------------------------------------- independent reference
def _point_seg(p, a, b):
    d = b - a
    dd = np.einsum("...i,...i", d, d)
    t = np.where(dd > 0, np.einsum("...i,...i", p - a, d) / np.where(dd > 0, dd, 1), 0)
    t = np.clip(t, 0, 1)
    return np.linalg.norm(p - (a + t[..., None] * d), axis=-1)


def _seg_seg_reference(p0, p1, q0, q1):
    """min of a convex quadratic on the unit square: interior critical point or an edge."""
    cands = [_point_seg(p0, q0, q1), _point_seg(p1, q0, q1),
             _point_seg(q0, p0, p1), _point_seg(q1, p0, p1)]
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    M11 = np.einsum("...i,...i", d1, d1)
    M22 = np.einsum("...i,...i", d2, d2)
    M12 = -np.einsum("...i,...i", d1, d2)
    r1 = -np.einsum("...i,...i", d1, r)
    r2 = np.einsum("...i,...i", d2, r)
    det = M11 * M22 - M12 ** 2
    good = det > 1e-12 * np.maximum(M11 * M22, 1e-300)
    dets = np.where(good, det, 1)
    s = (r1 * M22 - M12 * r2) / dets
    t = (M11 * r2 - M12 * r1) / dets
    inside = good & (s > 0) & (s < 1) & (t > 0) & (t < 1)
    gap = p0 + s[..., None] * d1 - q0 - t[..., None] * d2
    cands.append(np.where(inside, np.linalg.norm(gap, axis=-1), np.inf))
    return np.min(cands, axis=0)


def _bruteforce(A, B, cutoff, fib, idx, k):
    S = len(A)
    I, J = np.triu_indices(S, 1)
    d = _seg_seg_reference(A[I], B[I], A[J], B[J])
    keep = d <= cutoff
    same = fib[I] == fib[J]
    if k is None:
        keep &= ~same
    else:
        keep &= ~(same & (np.abs(idx[I] - idx[J]) <= k))
    return {(int(i), int(j)) for i, j in zip(I[keep], J[keep])}, dict(zip(zip(I, J), d))


def _random_segments(seed):
    """Random-walk chains (fibrils) plus loose segments of very different lengths."""
    rng = np.random.default_rng(seed)
    A, B, fib, idx = [], [], [], []
    n_chains = rng.integers(5, 12)
    for f in range(n_chains):
        n = rng.integers(3, 25)
        step = rng.normal(size=(n, 3))
        step /= np.linalg.norm(step, axis=1, keepdims=True)
        pts = rng.uniform(-3, 3, 3) + np.vstack([np.zeros(3), np.cumsum(0.6 * step, 0)])
        A.append(pts[:-1]); B.append(pts[1:])
        fib += [f] * n; idx += list(range(n))
    m = 60
    a = rng.uniform(-4, 4, (m, 3))
    lengths = rng.choice([0.0, 0.1, 0.5, 1.0, 6.0], size=m)
    d = rng.normal(size=(m, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    A.append(a); B.append(a + lengths[:, None] * d)
    fib += list(range(n_chains, n_chains + m)); idx += [0] * m
    # some exactly parallel / collinear pairs
    base = rng.uniform(-2, 2, (5, 3))
    A.append(base); B.append(base + [1.0, 0, 0])
    A.append(base + [0, 0.3, 0]); B.append(base + [1.7, 0.3, 0])
    A.append(base + [1.2, 0, 0]); B.append(base + [2.0, 0, 0])
    fib += list(range(n_chains + m, n_chains + m + 15)); idx += [0] * 15
    return np.vstack(A), np.vstack(B), np.array(fib), np.array(idx)


# ------------------------------------------------------------------------- tests
@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("k", [None, 0, 1, 3])
def test_candidate_pairs_match_bruteforce(seed, k):
    A, B, fib, idx = _random_segments(seed)
    cutoff = [0.2, 0.5, 1.0][seed % 3]
    got = candidate_pairs(A, B, cutoff, fib, idx, exclude_neighbours=k)
    assert got.ndim == 2 and got.shape[1] == 2
    assert np.all(got[:, 0] < got[:, 1])
    got_set = {tuple(map(int, p)) for p in got}
    assert len(got_set) == len(got)  # each unordered pair once
    ref, dist = _bruteforce(A, B, cutoff, fib, idx, k)
    diff = got_set ^ ref
    # identical, up to pairs sitting on the cutoff within rounding
    assert all(abs(dist[p] - cutoff) < 1e-10 for p in diff), sorted(diff)[:5]
    assert len(ref) > 10


def test_segment_distance_matches_reference():
    rng = np.random.default_rng(7)
    P = rng.normal(size=(4, 5000, 3))
    P[1, :500] = P[0, :500]  # zero-length first segments
    P[3, 500:1000] = P[2, 500:1000] + 2 * (P[1, 500:1000] - P[0, 500:1000])  # parallel
    d, s, t = segment_distance(*P)
    assert np.allclose(d, _seg_seg_reference(*P), atol=1e-12)
    pts = P[0] + s[:, None] * (P[1] - P[0]) - P[2] - t[:, None] * (P[3] - P[2])
    assert np.allclose(np.linalg.norm(pts, axis=1), d, atol=1e-12)
    assert np.all((s >= 0) & (s <= 1) & (t >= 0) & (t <= 1))


def test_closest_points_vs_dense_sampling():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(100, 3, 3)) * 2
    a = rng.normal(size=(100, 1, 3))
    b = a + rng.normal(size=(100, 1, 3))
    s = closest_points(p, a, b)
    assert s.shape == (100, 3)
    assert np.all((s >= 0) & (s <= 1))
    assert np.any(s == 0) and np.any(s == 1) and np.any((s > 0) & (s < 1))
    grid = np.linspace(0, 1, 4001)
    line = a[:, :, None, :] + grid[None, None, :, None] * (b - a)[:, :, None, :]
    dense = np.linalg.norm(p[:, :, None, :] - line, axis=-1)
    ours = np.linalg.norm(p - (a + s[..., None] * (b - a)), axis=-1)
    assert np.all(ours <= dense.min(axis=-1) + 1e-12)
    assert np.allclose(s, grid[np.argmin(dense, axis=-1)], atol=2e-4)
    # degenerate chord
    assert closest_points(np.ones(3), np.zeros(3), np.zeros(3)) == 0.0


def _crossing_mesh(order=2):
    fibs = [straight_fibril([-2, 0, 0], [2, 0, 0], 0.1, "a"),
            straight_fibril([0, -2, 0.15], [0, 2, 0.15], 0.1, "b"),
            straight_fibril([-2, 1.0, 1.0], [2, 1.0, 1.0], 0.1, "far")]
    return fibril_mesh(fibs, 8, order)


def test_build_contact_map_crossing():
    mesh = _crossing_mesh(order=2)
    x = mesh.X0.copy()
    cmap = build_contact_map(x, mesh, cutoff=0.25, n_gp=5)
    # a crossing at the origin: element chords meeting at a node -> 2x2 element pairs
    assert cmap.n_pairs == 4
    assert set(cmap.fibril_plus) == {0} and set(cmap.fibril_minus) == {1}
    assert np.all(cmap.e_plus < cmap.e_minus)
    assert np.allclose(cmap.s_plus[0], gauss_fractions(5))
    assert np.allclose(cmap.distance, 0.15)
    # nodes of the chord: end nodes of the element
    assert np.array_equal(cmap.nodes_plus[:, 0], mesh.conn[cmap.e_plus, 0])
    assert np.array_equal(cmap.nodes_minus[:, 1], mesh.conn[cmap.e_minus, -1])
    # the - points are the closest points on the - chords: all on x = 0 of fibril b
    rm = cmap.minus_points(x)
    assert np.allclose(rm[..., 0], 0.0) and np.allclose(rm[..., 2], 0.15)
    assert np.allclose(cmap.recompute_s_minus(x), cmap.s_minus)
    # move fibril b: frozen s_minus stays, recomputed follows
    x2 = x.copy()
    x2[mesh.fibril_nodes(1), 0] += 0.1
    assert np.allclose(cmap.minus_points(x2)[..., 0], 0.1)
    ref = cmap.refreshed(x2)
    assert np.array_equal(ref.e_plus, cmap.e_plus)
    assert np.allclose(ref.minus_points(x2)[..., 1], cmap.plus_points(x2)[..., 1], atol=1e-12)
    jump = cmap.jump(x)
    assert jump.shape == (4, 5, 3)


def test_build_contact_map_self_contact_exclusion():
    # a hairpin: one fibril folded back on itself at distance 0.2
    mesh = fibril_mesh([straight_fibril([0, 0, 0], [4, 0, 0], 0.05)], 8, 1)
    x = mesh.X0.copy()
    # fold the second half back at y = 0.2
    r = x[:, :3]
    back = r[:, 0] > 2
    r[back, 1] = 0.2
    r[back, 0] = 4 - r[back, 0]
    none = build_contact_map(x, mesh, 0.25, 3, exclude_neighbours=None)
    assert none.n_pairs == 0
    k1 = build_contact_map(x, mesh, 0.25, 3, exclude_neighbours=1)
    assert k1.n_pairs > 0
    idx = np.abs(k1.e_plus - k1.e_minus)
    assert idx.min() >= 2
