"""Probe solves (rve.homogenisation.probes) on networks with known answers: a straight
fibril (I = V sigma A / L, parabolic Joule temperature), the same fibril stretched (the
thesis §7.4 pull-back: the current does not change), two crossing fibrils in contact
(series resistance through the contact conductance), floating fibrils under weakened
insulation, and charge conservation on a small woven RVE."""
from __future__ import annotations

import numpy as np
import pytest

from rve.model import ContactParams
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.homogenisation.probes import electric_solve, temperature_solve
from rve.model import BeamMaterial

R = 0.15
SIGMA = 10.0  # S/mm
K = 1.0  # W/(mm K)
AREA = np.pi * R**2
MAT = BeamMaterial(1.26, electrical_conductivity=SIGMA, thermal_conductivity=K)


def _straight(L=2.0, elements=8):
    return fibril_mesh([straight_fibril([0, 0, 0], [L, 0, 0], R, "a")], elements, 1)


def test_straight_fibril_current_and_joule_temperature():
    L = 2.0
    mesh = _straight(L)
    a0, a1 = mesh.end_nodes(0)
    el = electric_solve(mesh, mesh.X0, MAT, None, [[a0], [a1]], [1.0, 0.0])
    exact = 1.0 * SIGMA * AREA / L
    assert el.currents[0] == pytest.approx(exact, rel=1e-12)  # into the fabric at +, positive
    assert el.currents[1] == pytest.approx(-exact, rel=1e-12)
    assert el.leak == 0.0 and el.pull_downs == 0
    # V linear along the fibril
    s = mesh.node_s
    np.testing.assert_allclose(el.V, 1.0 - s / L, atol=1e-12)
    # Joule heating q = I V / L per length, T = 0 at both ends: T_max = q L^2 / (8 k A)
    T, res = temperature_solve(mesh, mesh.X0, el.V, MAT, None, [a0, a1])
    assert res.converged and res.iterations == 1
    q = exact * 1.0 / L
    assert T.max() == pytest.approx(q * L**2 / (8 * K * AREA), rel=1e-10)
    np.testing.assert_allclose(T[[a0, a1]], 0.0, atol=1e-14)
    np.testing.assert_allclose(T, q * s * (L - s) / (2 * K * AREA), rtol=1e-9, atol=1e-12)  # nodally exact


def test_stretched_fibril_keeps_its_current():
    """Thesis §7.4: with the constant (reference) conductivity the current through an
    insulated fibril pulls back to the reference configuration: stretching changes nothing."""
    L = 2.0
    mesh = _straight(L)
    x = mesh.X0.copy()
    x[:, 0] *= 1.2  # stretched by 20 %
    a0, a1 = mesh.end_nodes(0)
    el = electric_solve(mesh, x, MAT, None, [[a0], [a1]], [1.0, 0.0])
    assert el.currents[0] == pytest.approx(SIGMA * AREA / L, rel=1e-10)


def _crossing(gap_overlap=0.01, elements=20):
    fibs = [straight_fibril([-1, 0, 0], [1, 0, 0], R, "a"),
            straight_fibril([0, -1, 2 * R - gap_overlap], [0, 1, 2 * R - gap_overlap], R, "b")]
    return fibril_mesh(fibs, elements, 1)


def test_two_crossing_fibrils_series_resistance_and_conservation():
    mesh = _crossing()
    a0, a1 = mesh.end_nodes(0)
    b0, b1 = mesh.end_nodes(1)
    cp = ContactParams(penalty=50.0, conductance=1.0, heat_transfer=0.1)
    el = electric_solve(mesh, mesh.X0, MAT, cp, [[a0], [b1]], [1.0, 0.0])
    ip, im = el.currents
    assert ip > 0 > im
    assert abs(ip + im) <= 1e-12 * ip  # both fibrils wired: no pull-down, exact conservation
    G = el.system.contact_conductance(el.x)
    assert list(G) == [(0, 1)]
    half = 1.0 / (SIGMA * AREA)  # each half fibril, 1 mm
    series = half + 1.0 / G[(0, 1)] + half
    # current enters the contact over a few elements around the crossing, not at a point
    assert 1.0 / ip == pytest.approx(series, rel=1e-2)
    # the Joule temperature is positive inside and zero at the ends
    T, _ = temperature_solve(mesh, mesh.X0, el.V, MAT, cp, [a0, a1, b0, b1])
    assert T.max() > 0 and T.min() >= -1e-12


def test_no_contact_conductance_means_no_current():
    mesh = _crossing()
    a0, _ = mesh.end_nodes(0)
    _, b1 = mesh.end_nodes(1)
    cp = ContactParams(penalty=50.0, conductance=0.0)
    el = electric_solve(mesh, mesh.X0, MAT, cp, [[a0], [b1]], [1.0, 0.0])
    assert abs(el.currents[0]) < 1e-14


def test_weakened_insulation_defines_floating_fibrils():
    """A third fibril touching nothing and a fourth touching the wired fibril: both get
    pull-downs; the solve is well posed, the isolated one sits at V_ref = 0, and the
    terminal currents balance up to the pull-down leak (~1/factor)."""
    fibs = [straight_fibril([-1, 0, 0], [1, 0, 0], R, "a"),
            straight_fibril([-1, 3, 0], [1, 3, 0], R, "isolated"),
            straight_fibril([0, -1, 2 * R - 0.01], [0, 1, 2 * R - 0.01], R, "touching")]
    mesh = fibril_mesh(fibs, 20, 1)
    a0, a1 = mesh.end_nodes(0)
    cp = ContactParams(penalty=50.0, conductance=1.0)
    factor = 1e6
    el = electric_solve(mesh, mesh.X0, MAT, cp, [[a0], [a1]], [1.0, 0.0], insulation_factor=factor)
    assert el.pull_downs == 4  # both ends of the two unwired fibrils
    iso = mesh.fibril_nodes(1)
    np.testing.assert_allclose(el.V[iso], 0.0, atol=1e-12)
    touch = mesh.fibril_nodes(2)
    assert 0.3 < el.V[touch].mean() < 0.7  # floats at the potential of the crossing (~0.5 V)
    ip, im = el.currents
    assert abs(ip + im + el.leak) <= 1e-10 * ip  # conservation including the leak
    assert abs(el.leak) < 10.0 / factor * ip


@pytest.fixture(scope="module")
def small_weave():
    from rve.homogenisation.sweeps import load_run_config
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.strain import relax_fabric

    spec = {"scene": {"fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]}, "mesh": {"elements": 8},
                      "relaxation": {"duration": "2 ms", "steps": 4, "rebuild_every": 2}}}
    cfg = load_run_config(spec)
    fab, mesh = fabric_and_mesh(cfg)
    x, _, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info["converged"] and info["residual_N"] < 1e-8
    return cfg, fab, mesh, x


def test_thesis_probes_on_a_small_weave(small_weave):
    from rve.homogenisation.probes import solve_probes, terminal_nodes

    cfg, fab, mesh, x = small_weave
    res = solve_probes(cfg, fab, mesh, x, with_fields=True)
    assert list(res) == ["probe1", "probe2", "probe3", "probe4"]  # the thesis probes + a weft yarn end to end
    for name, r in res.items():
        assert r.current_plus > 0 > r.current_minus, name
        assert r.conservation_error < 1e-9, name  # I+ + I- + I_leak = 0
        assert abs(r.current_plus + r.current_minus) < 1e-9 * r.current_plus  # leak ~ 1/insulation_factor
        ends = [t.node(mesh) for t in fab.end_tags]
        np.testing.assert_allclose(r.T[ends], 0.0, atol=1e-14)
        assert r.temperature_max > r.temperature_mean > 0
        plus = terminal_nodes(fab, mesh, cfg.probes[[p.name for p in cfg.probes].index(name)].terminals[0])
        np.testing.assert_allclose(r.V[plus], 1.0)
    # along one yarn is the lowest resistance (thesis §7.4)
    assert res["probe1"].resistance < min(res["probe2"].resistance, res["probe3"].resistance)
    # probe 1 is essentially the warp fibril's own resistance (contacts add parallel paths)
    L = 2 * fab.half_widths[0]
    assert res["probe1"].resistance <= L / (SIGMA * AREA) * (1 + 1e-9)
    # probe 4 is the weft twin of probe 1 (the symmetric 2 x 2 weave): the same bound
    assert res["probe4"].resistance <= 2 * fab.half_widths[1] / (SIGMA * AREA) * (1 + 1e-9)
