"""The temperature post-solve's contact heat-transfer matrix (rve.model.thermal_post) on every
contact geometry (chord, curve, smooth): it is the monolithic contact term's T block (the term
is linear in T), it conserves heat (a uniform T carries none), its fast path equals the
plain reference, and on straight, evenly meshed fibrils the smooth curve (then the chord
itself) gives the curve geometry's matrix exactly."""
from __future__ import annotations

import numpy as np
import pytest

R = 0.1


def _crossed(geometry, order=1, ne=4, noise=0.01, overlap=0.04):
    from rve.fem.mesh import fibril_mesh, straight_fibril
    from rve.model import BeamMaterial, BeamModel, ContactParams, ContactSystem

    fibs = [straight_fibril([-1, 0.03, 0], [1, 0.03, 0], R, "a"),
            straight_fibril([0.05, -1, -(2 * R - overlap)], [0.05, 1, -(2 * R - overlap)], R, "b")]
    mesh = fibril_mesh(fibs, ne, order)
    mat = BeamMaterial(1.26, density=1e-3, damping=0.01, electrical_conductivity=10.0,
                       heat_capacity=1.0, thermal_conductivity=1.0)
    base = BeamModel(mesh, mat, fields=("mech", "T", "V"))
    x = np.zeros(base.n)
    xn = base.nodal(x)
    xn[:, :9] = mesh.X0
    xn[:, :3] += np.random.default_rng(0).normal(scale=noise, size=(xn.shape[0], 3))
    params = ContactParams(penalty=50.0, heat_transfer=0.1, conductance=1.0, n_gp=4, margin=0.1,
                           geometry=geometry)
    return ContactSystem(base, params, x), x


CASES = [("chord", 1), ("curve", 1), ("curve", 2), ("smooth", 1), ("smooth", 2)]


@pytest.mark.parametrize("geometry,order", CASES)
def test_heat_block_is_the_monolithic_T_block_and_conserves_heat(geometry, order):
    from rve.model.thermal_post import ThermalOperators, _reference_heat_block, contact_heat_block

    sysm, x = _crossed(geometry, order)
    h_C = sysm.term.law_coef["T"]
    ops = ThermalOperators(sysm, h_C, np.zeros(0, np.int64))
    act = ops.active_pairs(x)
    assert act.size >= 1
    T = np.random.default_rng(1).uniform(0.0, 5.0, ops.n)
    w0 = np.zeros(sysm.n)
    w1 = w0.copy()
    sysm.nodal(w1)[:, sysm.layout.offset["T"]] = T
    oT = sysm.layout.offset["T"]
    dF = sysm.nodal(sysm.contact_terms(x, w1, jacobian=False)[0])[:, oT] \
        - sysm.nodal(sysm.contact_terms(x, w0, jacobian=False)[0])[:, oT]
    KcT = ops.contact_apply(x, T)
    assert np.abs(dF).max() > 0
    assert np.abs(KcT - dF).max() <= 1e-12 * np.abs(dF).max()
    # a uniform temperature has no jump: no heat crosses any contact
    assert np.abs(ops.contact(x) @ np.ones(ops.n)).max() <= 1e-13 * np.abs(ops.contact(x)).max()
    loc, Ju = contact_heat_block(sysm.term, sysm.base.mesh, x, act, h_C)
    loc_r, Ju_r = _reference_heat_block(sysm.term, sysm.base.mesh, x, act, h_C)
    assert np.array_equal(loc, loc_r) and np.abs(Ju - Ju_r).max() <= 1e-14 * np.abs(Ju_r).max()


@pytest.mark.parametrize("order", [1, 2])
def test_smooth_equals_curve_on_straight_fibrils(order):
    from rve.model.thermal_post import ThermalOperators

    K = {}
    for geometry in ("curve", "smooth"):
        sysm, x = _crossed(geometry, order, ne=5, noise=0.0)
        K[geometry] = ThermalOperators(sysm, 0.1, np.zeros(0, np.int64)).contact(x).toarray()
    assert np.abs(K["curve"]).max() > 0
    assert np.abs(K["smooth"] - K["curve"]).max() <= 1e-12 * np.abs(K["curve"]).max()
