"""The compiled curve-contact kernel (rve.kernels.contact_curve) against the numpy reference
(rve.physics.contact_curve): residual and tangent to 1e-12 relative for p = 1, 2, 3 (interior,
clamped and handed-on closest points, with multipliers and an onset), and the term's
compiled path equal to its numpy path."""
import numpy as np
import pytest

pytest.importorskip("numba")

from rve.kernels.contact_curve import curve_penalty_rows
from rve.model.terms.contact_pairs import HalfPasses
from rve.physics.contact_curve import (
    END_SNAP, curve_basis, curve_geometry, curve_penalty_forces, gauss_legendre_01, lagrange_monomials,
)


def _rows(order, P=40, seed=0):
    rng = np.random.default_rng(seed)
    nn = order + 1
    u = np.linspace(0.0, 1.0, nn)
    Xa = np.zeros((P, nn, 3))
    Xb = np.zeros((P, nn, 3))
    Xa[..., 0] = -0.35 + 0.7 * u
    Xa[..., 2] = -0.08 * u * (1 - u) * (order > 1)
    Xb[..., 1] = -0.35 + 0.7 * u
    Xb[..., 2] = -0.26 + 0.06 * u * (1 - u) * (order > 1)
    Xa += rng.normal(size=Xa.shape) * 0.03
    Xb += rng.normal(size=Xb.shape) * 0.03
    Xb[: P // 2, :, 1] -= rng.uniform(0.0, 0.5, P // 2)[:, None]  # closest points at b's end
    t_next = rng.normal(size=(P, 3))
    has_next = rng.random(P) < 0.7
    has_prev = rng.random(P) < 0.7
    return Xa, Xb, t_next, has_next, has_prev


@pytest.mark.parametrize("order", [1, 2, 3])
@pytest.mark.parametrize("onset", [0.0, 0.01])
def test_curve_kernel_matches_reference(order, onset):
    Xa, Xb, tn, hn, hp = _rows(order, P=2200, seed=order)  # > 2 x MIN_CHUNK pairs: split over threads
    P = Xa.shape[0]
    s, W = gauss_legendre_01(4)
    rng = np.random.default_rng(7)
    gr = 0.3 + rng.uniform(0.0, 0.01, (P, 4))  # per-point radii: multipliers
    w = np.broadcast_to(0.1 * W, (P, 4))
    geo = curve_geometry(order, Xa, Xb, s, gr, hn, tn, hp)
    R0, K0 = curve_penalty_forces(geo, w, 50.0, True, onset)
    basis = (lagrange_monomials(order), curve_basis(order, s)[0], END_SNAP)
    act, R1, K1 = curve_penalty_rows(order, *basis, Xa, Xb, tn, hn, hp, s, gr, w, 50.0, onset, True)
    # the kernel folds rows i and P/2 + i into pair i
    R0 = HalfPasses.fold(R0, order + 1)
    K0 = HalfPasses.fold(K0, order + 1, axes=(1, 3))
    assert act.sum() > P // 8 and np.any(geo.active & (geo.s_b >= 1.0))
    np.testing.assert_array_equal(act, geo.active.any(axis=1).reshape(2, -1).any(axis=0))
    np.testing.assert_allclose(R1, R0, rtol=0, atol=1e-12 * np.abs(R0).max())
    np.testing.assert_allclose(K1, K0, rtol=0, atol=1e-12 * np.abs(K0).max())
    _, R2, K2 = curve_penalty_rows(order, *basis, Xa, Xb, tn, hn, hp, s, gr, w, 50.0, onset, False)
    assert K2 is None
    np.testing.assert_array_equal(R2, R1)


@pytest.mark.parametrize("order", [1, 2, 3])
def test_term_compiled_path_equals_numpy(order, monkeypatch):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_contact_curve_system import _crossed

    sysm, x, w = _crossed(order, fields=("mech",), geometry="curve")
    out = {}
    for mode in ("numpy", "numba"):
        monkeypatch.setenv("RVE_KERNELS", mode)
        out[mode] = sysm.term.forms(x, w, True)
    np.testing.assert_array_equal(out["numba"][0], out["numpy"][0])
    for k in (1, 2):
        ref = out["numpy"][k]
        np.testing.assert_allclose(out["numba"][k], ref, rtol=0, atol=1e-12 * np.abs(ref).max())
