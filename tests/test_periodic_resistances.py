"""R_y and R_c of the periodic cell (rve.homogenisation.periodic_resistances): closed forms.

(a) straight parallel fibrils: the yarn layer's sheet resistance is W / (sigma A n) and the
    network resistor R_y = a / (sigma A n_f) exactly (one yarn across one pitch);
(b) a single crossing: as sigma -> infinity the exchange resistance per area over the cell
    area tends to the inverse of the contact conductance, measured independently by a
    Dirichlet solve (every warp node at 1 V, every weft node at 0 V); with finite sigma the
    fibrils' spreading lies below the point-contact closed form (L_w + L_f) / (12 sigma A);
(c) a 1 x 1 and a 2 x 2 repeat of the same state give the same R_y and R_c.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from rve.config.rve import RVEConfig
from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.homogenisation.periodic_probes import CONDUCTION_GRAPH
from rve.homogenisation.periodic_resistances import cell_resistances as _cell_resistances, exchange_resistance as _exchange
from rve.homogenisation.periodic_resistances import family_mesh
from rve.homogenisation.probes import electric_solve
from rve.fabrics.setup import contact_params
from rve.homogenisation.probe_result import conduction_material

RADIUS, SIGMA = 0.15, 10.0


def cell_resistances(cfg, fab, mesh, x, family):
    return _cell_resistances(cfg, fab, mesh, x, family, CONDUCTION_GRAPH)


def exchange_resistance(cfg, fab, mesh, x):
    return _exchange(cfg, fab, mesh, x, CONDUCTION_GRAPH)


def _cfg(sigma=SIGMA):
    return RVEConfig(scene="rve", boundary="periodic", fabric={"kind": "plain", "rows": [1]},
                     material={"electrical_conductivity": f"{sigma} S/mm"}, mesh={"elements": 4},
                     contact={"conductance": "1 A/(mm^2*V)"}, probe_solver={"temperature": False})


def _fab(mesh, L, W, directions, yarns):
    """What the resistances read of a fabric: the cell's half widths, every fibril's family,
    the yarns' families (their counts give the pitches)."""
    return SimpleNamespace(half_widths=np.array([L / 2, W / 2, 1.0]), fibril_direction=tuple(directions),
                           yarns=[SimpleNamespace(direction=d) for d in yarns])


def _straight_weave(n_warp=2, n_weft=3, per_yarn=2, L=6.0, W=4.0):
    """Straight warp yarns along x (``per_yarn`` fibrils side by side in z, touching nothing
    across yarns) and straight weft yarns along y one layer up, not touching the warp."""
    fibs, dirs = [], []
    for k in range(n_warp):
        y = (k + 0.5) * W / n_warp - W / 2
        for m in range(per_yarn):
            fibs.append(straight_fibril([-L / 2, y, 0.4 * m], [L / 2, y, 0.4 * m], RADIUS))
            dirs.append("warp")
    for k in range(n_weft):
        x = (k + 0.5) * L / n_weft - L / 2
        for m in range(per_yarn):
            fibs.append(straight_fibril([x, -W / 2, 2.0 + 0.4 * m], [x, W / 2, 2.0 + 0.4 * m], RADIUS))
            dirs.append("weft")
    mesh = fibril_mesh(fibs, 4, 1)
    return mesh, _fab(mesh, L, W, dirs, ["warp"] * n_warp + ["weft"] * n_weft)


def test_straight_fibrils_give_the_closed_form_yarn_resistance():
    n_warp, n_weft, per_yarn, L, W = 2, 3, 2, 6.0, 4.0
    mesh, fab = _straight_weave(n_warp, n_weft, per_yarn, L, W)
    cfg = _cfg()
    x = mesh.X0.copy()
    A = np.pi * RADIUS ** 2
    a_x, a_y = L / n_weft, W / n_warp
    warp = cell_resistances(cfg, fab, mesh, x, "warp")
    weft = cell_resistances(cfg, fab, mesh, x, "weft")
    # the layer's sheet resistance: W over sigma A times the fibrils of the family in the cell
    assert warp["layer_sheet_resistance_ohm"] == pytest.approx(W / (SIGMA * A * n_warp * per_yarn), rel=1e-10)
    assert weft["layer_sheet_resistance_ohm"] == pytest.approx(L / (SIGMA * A * n_weft * per_yarn), rel=1e-10)
    # one yarn across one pitch along it: the pinned network's R_y
    assert warp["yarn_resistance_ohm"] == pytest.approx(a_x / (SIGMA * A * per_yarn), rel=1e-10)
    assert weft["yarn_resistance_ohm"] == pytest.approx(a_y / (SIGMA * A * per_yarn), rel=1e-10)
    # no contact between the families: no exchange
    assert warp["exchange_resistance_ohm_mm2"] == np.inf


def _crossing(repeat=1, L=2.0, z=0.26, elements=16):
    """``repeat`` x ``repeat`` copies of one crossing inside the cell: a warp fibril along x
    at y = 0 and a weft fibril along y at x = 0 pressed on it (z < 2 R)."""
    n, cell = int(repeat), int(repeat) * L
    lo = -L / 2
    fibs = [straight_fibril([lo, k * L, 0.0], [lo + cell, k * L, 0.0], RADIUS) for k in range(n)]
    fibs += [straight_fibril([k * L, lo, z], [k * L, lo + cell, z], RADIUS) for k in range(n)]
    mesh = fibril_mesh(fibs, elements * n, 1)
    fab = _fab(mesh, cell, cell, ["warp"] * n + ["weft"] * n, ["warp"] * n + ["weft"] * n)
    return mesh, fab, mesh.X0.copy()


def _dirichlet_contact_conductance(cfg, mesh, fab, x):
    """Every warp node at 1 V, every weft node at 0 V, no ties: the current is the contact
    conductance of the cell (the fibrils are equipotential)."""
    d = np.asarray(fab.fibril_direction)
    warp = np.flatnonzero(d[mesh.node_fibril] == "warp")
    weft = np.flatnonzero(d[mesh.node_fibril] == "weft")
    cparams = contact_params(cfg.contact, rebuild_every=cfg.strain.rebuild_every, conduction=True)
    el = electric_solve(mesh, x, conduction_material(cfg), cparams, [warp, weft], [1.0, 0.0])
    return el.currents[0]


def test_exchange_of_near_ideal_fibrils_extrapolates_to_the_contact_conductance():
    """sigma = 1e4 and 2e4 S/mm: the exchange resistance is 1/G + c1/sigma + O(1/sigma^2)
    (the fibrils' spreading, 1.6e-4 of 1/G here, its square far below 1e-6): the
    extrapolation 2 r(2 sigma) - r(sigma) is 1/G."""
    L = 2.0
    mesh, fab, x = _crossing()
    G = _dirichlet_contact_conductance(_cfg(sigma=1e4), mesh, fab, x)
    assert G > 0
    r = {}
    for sigma in (1e4, 2e4):
        ex = exchange_resistance(_cfg(sigma=sigma), fab, mesh, x)
        assert ex["layer_potential_drop_V"] > 0      # the warp, into which the current goes, is higher
        assert ex["reference_current_A"] < 1e-9 * ex["injected_A"]
        r[sigma] = ex["exchange_resistance_ohm_mm2"] / (L * L)
    assert r[1e4] > r[2e4] > 1.0 / G
    assert 2.0 * r[2e4] - r[1e4] == pytest.approx(1.0 / G, rel=1e-6)


def test_exchange_spreading_is_below_the_point_contacts():
    """Finite sigma: the fibrils add a spreading resistance to 1/G; the contact zone has a
    length, so it lies below a point contact's L_w / (12 sigma A) + L_f / (12 sigma A) (the
    mean potential of a uniformly fed fibril over its contact point) and above half of it
    (the zone is ~0.2 mm of the 2 mm period)."""
    cfg = _cfg()
    mesh, fab, x = _crossing()
    G = _dirichlet_contact_conductance(cfg, mesh, fab, x)
    ex = exchange_resistance(cfg, fab, mesh, x)
    L = 2.0
    point = 2.0 * L / (12.0 * SIGMA * np.pi * RADIUS ** 2)
    spread = ex["exchange_resistance_ohm_mm2"] / (L * L) - 1.0 / G
    assert 0.5 * point < spread < point


def test_one_and_two_repeats_give_the_same_resistances():
    cfg = _cfg()
    out = []
    for repeat in (1, 2):
        mesh, fab, x = _crossing(repeat)
        out.append([cell_resistances(cfg, fab, mesh, x, fam)[k] for fam in ("warp", "weft")
                    for k in ("layer_sheet_resistance_ohm", "yarn_resistance_ohm", "exchange_resistance_ohm_mm2",
                              "contact_resistance_ohm")])
    assert np.all(np.isfinite(out[0]))
    assert np.allclose(out[1], out[0], rtol=1e-9, atol=0)


def test_family_mesh_keeps_the_fibrils_nodes_and_elements():
    mesh, fab = _straight_weave()
    sub, nodes = family_mesh(mesh, [1, 3])
    assert sub.n_fibrils == 2 and np.array_equal(sub.X0, mesh.X0[nodes])
    assert np.array_equal(nodes[sub.conn], mesh.conn[np.r_[mesh.elem_offsets[1]:mesh.elem_offsets[2],
                                                             mesh.elem_offsets[3]:mesh.elem_offsets[4]]])


def _plain_cell_resistances(repeat):
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.probes import solve_probes
    from rve.homogenisation.strain import relax_fabric

    cfg = RVEConfig(scene="rve", boundary="periodic", cell={"repeat": repeat}, fabric={"kind": "plain", "rows": [1]},
                    mesh={"elements": 6 * repeat}, probe_solver={"temperature": False})
    fab, mesh = fabric_and_mesh(cfg)
    x, _, info = relax_fabric(cfg, fab, mesh, fab.initial_state(mesh))
    assert info["converged"], info["residual_N"]
    probes = solve_probes(cfg, fab, mesh, x)
    return (probes["field_x"].record(), probes["field_y"].record()), fab


def test_plain_weave_one_and_two_repeats_and_the_table():
    """The relaxed plain weave as a 1 x 1 and a 2 x 2 cell (the same element length): the
    field probes carry the same R_y and R_c, and the table takes them as the network's
    resistors (warp from the x probe, weft from the y probe)."""
    from rve.tables.build import build_table

    (one, fab), (two, _) = _plain_cell_resistances(1), _plain_cell_resistances(2)
    keys = ("layer_sheet_resistance_ohm", "yarn_resistance_ohm", "exchange_resistance_ohm_mm2", "contact_resistance_ohm")
    for a, b in zip(one, two):
        assert np.all(np.isfinite([a[k] for k in keys]))
        assert np.allclose([b[k] for k in keys], [a[k] for k in keys], rtol=1e-6, atol=0)
    assert one[0]["yarn_family"] == "warp" and one[1]["yarn_family"] == "weft"
    rec = {"mode": "uniaxial", "strain": 0.0, "params": {}, "probes": {"field_x": one[0], "field_y": one[1]}}
    ds = build_table([rec], fabric=fab, config={})
    assert float(ds["yarn_resistance_warp"].values.ravel()[0]) == one[0]["yarn_resistance_ohm"]
    assert float(ds["yarn_resistance_weft"].values.ravel()[0]) == one[1]["yarn_resistance_ohm"]
    assert float(ds["contact_resistance"].values.ravel()[0]) == one[0]["contact_resistance_ohm"]
    assert ds["contact_resistance"].attrs["units"] == "ohm" and "periodic" in ds["contact_resistance"].attrs["comment"]
    # the sheet model's exchange conductance per area is 1 / r_c
    assert float(ds["contact_exchange_conductance"].values.ravel()[0]) == pytest.approx(
        1.0 / one[0]["exchange_resistance_ohm_mm2"], rel=1e-12)
