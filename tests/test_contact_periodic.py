"""Periodic images in the contact map (docs/contact.md "Periodic images"): a pair with a
shifted - side is the same contact as the pair of the two fibrils placed where the image
is; the wrap of a fibril into its own image; the element neighbour table with a wrap."""
import numpy as np
import pytest

from rve.contact import build_contact_map, element_neighbours
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem

R = 0.15
T = np.array([0.0, 3.0, 0.0])  # the lattice translation of the image


def _crossed(offset, order=1, ne=6):
    """Fibril a along x at z = R - 0.01, fibril b along y at z = -R, b moved by ``offset``."""
    fibs = [straight_fibril([-1, 0.1, R - 0.01], [1, 0.1, R - 0.01], R, "a"),
            straight_fibril(np.array([0.2, -1, -R]) + offset, np.array([0.2, 1, -R]) + offset, R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    base = BeamModel(mesh, BeamMaterial(126.0, density=1e-3))
    x = np.zeros(base.n)
    base.nodal(x)[:, :9] = mesh.X0
    return base, x


@pytest.mark.parametrize("kernels", ["numpy", "numba"])
@pytest.mark.parametrize("geometry", ["chord"])
def test_image_pair_equals_the_pair_in_place(monkeypatch, kernels, geometry):
    monkeypatch.setenv("RVE_KERNELS", kernels)
    params = ContactParams(penalty=50.0, geometry=geometry)
    base0, x0 = _crossed(np.zeros(3), order=2)
    ref = ContactSystem(base0, params, x0)
    base1, x1 = _crossed(-T, order=2)  # b sits one lattice vector away: only its image touches a
    per = ContactSystem(base1, params, x1)
    assert per.map.n_pairs == 0
    per.set_periodic(images=[T, -T], x=x1)
    assert per.map.n_pairs == ref.map.n_pairs > 0
    np.testing.assert_array_equal(per.map.shifts, np.broadcast_to(T, (per.map.n_pairs, 3)))
    w = np.zeros(base0.n)
    F0, _, _, _ = ref.contact_terms(x0, w)
    F1, _, _, _ = per.contact_terms(x1, w)
    assert np.abs(F0).max() > 1e-4
    np.testing.assert_allclose(F1, F0, rtol=0, atol=1e-12 * np.abs(F0).max())
    # the assembled tangents (beams + contact): the same to round-off of the beam terms
    K0 = ref.evaluate(x0, w, 0.0)[1].toarray()
    K1 = per.evaluate(x1, w, 0.0)[1].toarray()
    np.testing.assert_allclose(K1, K0, rtol=0, atol=1e-9 * np.abs(K0).max())
    np.testing.assert_allclose(per.fibril_contact_forces(x1), ref.fibril_contact_forces(x0),
                               atol=1e-12 * np.abs(F0).max())
    per.set_periodic(x=x1)  # back to a plain cell
    assert per.map.n_pairs == 0


def test_no_images_gives_no_shift():
    base, x = _crossed(np.zeros(3))
    cmap = build_contact_map(base.nodal(x)[:, :3], base.mesh, 0.4)
    assert cmap.shift is None and cmap.n_pairs > 0
    np.testing.assert_array_equal(cmap.shifts, 0.0)


def test_wrap_excludes_the_fibril_continuation():
    """A fibril along x with period L: its own images at +-L are itself (no pairs); a
    parallel fibril's image across y is a different fibril (pairs, with the shift)."""
    L = 2.0
    fibs = [straight_fibril([0, 0, 0], [L, 0, 0], R, "a"), straight_fibril([0, 0.8, 0], [L, 0.8, 0], R, "b")]
    mesh = fibril_mesh(fibs, 4, 1)
    r = mesh.X0[:, :3]
    Ty = np.array([0.0, 1.08, 0.0])  # b's image at y = -0.28 lies 0.28 from a
    Tx = np.array([L, 0.0, 0.0])
    images = [Tx, -Tx, Ty, -Ty]
    cmap = build_contact_map(r, mesh, 0.4, images=images, wrap={0: Tx, 1: Tx})
    assert cmap.n_pairs > 0
    assert np.all(cmap.fibril_plus != cmap.fibril_minus)
    np.testing.assert_allclose(np.abs(cmap.shifts[:, 1]), Ty[1])
    # each physical contact once: b's image below a, not also a's image above b
    keys = {(int(p), int(m)) for p, m in zip(cmap.e_plus, cmap.e_minus)}
    assert len(keys) == cmap.n_pairs
    # without the wrap, a fibril's end elements pair with their own image across x
    cm2 = build_contact_map(r, mesh, 0.4, images=images)
    assert np.any(cm2.fibril_plus == cm2.fibril_minus)


def test_element_neighbours_with_wrap():
    L = np.array([2.0, 0.0, 0.0])
    fibs = [straight_fibril([0, 0, 0], [2, 0, 0], R), straight_fibril([0, 1, 0], [2, 1, 0], R)]
    mesh = fibril_mesh(fibs, 3, 2)
    nb = element_neighbours(mesh)
    np.testing.assert_array_equal(nb.next, [1, 2, -1, 4, 5, -1])
    np.testing.assert_array_equal(nb.prev, [-1, 0, 1, -1, 3, 4])
    nw = element_neighbours(mesh, wrap={1: L})
    np.testing.assert_array_equal(nw.next, [1, 2, -1, 4, 5, 3])
    np.testing.assert_array_equal(nw.prev, [-1, 0, 1, 5, 3, 4])
    np.testing.assert_array_equal(nw.next_shift[5], L)
    np.testing.assert_array_equal(nw.prev_shift[3], -L)
    assert not nw.next_shift[:5].any() and not nw.prev_shift[[0, 1, 2, 4, 5]].any()
    # the wrapped neighbour continues the fibril: its first node, shifted, is the last node
    r = mesh.X0[:, :3]
    np.testing.assert_allclose(r[mesh.conn[nw.next[5], 0]] + nw.next_shift[5], r[mesh.conn[5, -1]])
