"""Mesh sequencing of the periodic cell's relaxation (``relaxation.coarse_elements``,
``rve.homogenisation.periodic.periodic_relax``): the target mesh starts from the coarse
cell's relaxed minimum, interpolated, and ends at an equilibrium of its own; a coarse mesh
equal to the target is no sequencing at all."""
from __future__ import annotations

import numpy as np
import pytest


def _spec(elements, coarse=None):
    relaxation = {} if coarse is None else {"coarse_elements": coarse}
    return {"scene_config": None, "overrides": [],
            "scene": {"scene": "rve", "boundary": "periodic", "fabric": {"kind": "plain", "rows": [1]},
                      "mesh": {"elements": elements}, "output": {"pictures": False}, "relaxation": relaxation,
                      "strain": {"modes": ["uniaxial"], "total": 0.05, "steps": 1}}}


def _setup(spec):
    from rve.fabrics.setup import fabric_and_mesh
    from rve.homogenisation.sweeps import load_run_config

    cfg = load_run_config(spec, "base")
    fab, mesh = fabric_and_mesh(cfg)
    return cfg, fab, mesh


def test_the_target_mesh_starts_from_the_interpolated_coarse_minimum(monkeypatch):
    from rve.fem.transfer import interpolate_nodal
    from rve.homogenisation import periodic

    ccfg, cfab, cmesh = _setup(_spec(3))
    xc, _, cinfo = periodic.periodic_relax(ccfg, cfab, cmesh, cfab.initial_state(cmesh))
    assert cinfo["converged"]

    cfg, fab, mesh = _setup(_spec(6, coarse=3))
    starts = []
    relax_cell = periodic._relax_cell

    def spy(cfg_, fab_, mesh_, x0, settings):
        starts.append((mesh_.n_elements, np.array(x0, float).reshape(mesh_.n_nodes, -1)))
        return relax_cell(cfg_, fab_, mesh_, x0, settings)

    monkeypatch.setattr(periodic, "_relax_cell", spy)
    x, system, info = periodic.periodic_relax(cfg, fab, mesh, fab.initial_state(mesh))
    # the coarse stage, then the target mesh from the coarse minimum carried onto it
    assert [n for n, _ in starts] == [cmesh.n_elements, mesh.n_elements]
    carried = interpolate_nodal(cmesh, np.asarray(xc).reshape(cmesh.n_nodes, -1), mesh)
    assert np.array_equal(starts[1][1], carried)
    assert info["coarse_stage"]["elements_per_fibril"] == 3 and info["coarse_stage"]["converged"]
    assert info["converged"] and info["residual_N"] <= cfg.relaxation.static_atol
    # the designed state is not where the target's relaxation started
    assert not np.allclose(starts[1][1], fab.initial_state(mesh).reshape(mesh.n_nodes, -1))


def test_a_coarse_mesh_equal_to_the_target_is_no_sequencing():
    from rve.homogenisation.periodic import periodic_relax

    plain = _setup(_spec(4))
    same = _setup(_spec(4, coarse=4))
    xa, _, ia = periodic_relax(*plain, plain[1].initial_state(plain[2]))
    xb, _, ib = periodic_relax(*same, same[1].initial_state(same[2]))
    assert np.array_equal(xa, xb) and "coarse_stage" not in ib


def test_the_periodic_config_takes_coarse_elements():
    cfg, _, _ = _setup(_spec(6, coarse=3))
    assert cfg.boundary == "periodic" and cfg.relaxation.coarse_elements == 3


@pytest.mark.parametrize("coarse", [0, -2])
def test_a_bad_coarse_mesh_names_the_key(coarse):
    with pytest.raises(Exception, match="coarse_elements"):
        _setup(_spec(6, coarse=coarse))
