"""Mesh sequencing (rve.fem.transfer.interpolate_nodal): polynomials of degree <= p are
transferred exactly between meshes of any element count and order, and a relaxed fabric
prolonged to a finer mesh keeps its centroid curves (exactly on a nested mesh, to
interpolation accuracy otherwise)."""
import numpy as np
import pytest

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.fem.transfer import interpolate_nodal


def _two_fibrils():
    return [straight_fibril([0, 0, 0], [2.0, 0, 0], 0.1), straight_fibril([0, 1, 0], [0, 4.0, 1.0], 0.2)]


def _poly_field(s, degree):
    """(n, 3) field of polynomials of exactly ``degree`` in s (three different ones)."""
    cols = []
    for k, c0 in enumerate((0.3, -1.1, 0.7)):
        coef = np.array([c0 * (j + 1) * (-1) ** (j + k) for j in range(degree + 1)])
        cols.append(np.polynomial.polynomial.polyval(s, coef))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("src, dst", [((3, 1), (7, 1)), ((3, 2), (5, 3)), ((4, 3), (3, 4)), ((2, 4), (9, 2)),
                                      ((5, 2), (2, 2)), ((6, 4), (6, 4))])
def test_polynomials_of_degree_p_transfer_exactly(src, dst):
    fibs = _two_fibrils()
    ms, md = fibril_mesh(fibs, src[0], src[1]), fibril_mesh(fibs, dst[0], dst[1])
    p = src[1]
    for degree in range(p + 1):
        out = interpolate_nodal(ms, _poly_field(ms.node_s, degree), md)
        np.testing.assert_allclose(out, _poly_field(md.node_s, degree), rtol=0, atol=1e-12)


def test_degree_above_p_is_not_exact():
    fibs = _two_fibrils()
    ms, md = fibril_mesh(fibs, 3, 2), fibril_mesh(fibs, 4, 2)
    out = interpolate_nodal(ms, _poly_field(ms.node_s, 3), md)
    assert np.abs(out - _poly_field(md.node_s, 3)).max() > 1e-4


def test_fibril_count_must_match():
    fibs = _two_fibrils()
    with pytest.raises(ValueError, match="fibril count"):
        interpolate_nodal(fibril_mesh(fibs, 3, 2), np.zeros((2 * 7, 3)), fibril_mesh(fibs[:1], 3, 2))


# ----------------------------------------------------------------------------- a relaxed fabric
@pytest.fixture(scope="module")
def relaxed_weave(tmp_path_factory):
    """A 2 x 2 plain weave relaxed (energy minimum, contact) on 6 quadratic elements."""
    import yaml

    from rve.config import load_config
    from rve.scenes import fabric_relax
    from rve.solvers.relaxation import RelaxSettings, relax_to_equilibrium

    data = {"scene": "fabric_relax", "fabric": {"kind": "plain", "n_warp": 2, "n_weft": 2, "rows": [1]},
            "mesh": {"elements": 6, "order": 2}}
    p = tmp_path_factory.mktemp("weave") / "cfg.yaml"
    p.write_text(yaml.safe_dump(data))
    cfg = load_config(str(p))
    fab, system, x0 = fabric_relax.setup(cfg)
    settings = RelaxSettings(duration=1.0, steps=1, method="energy", onset_schedule=(float(system.params.onset),))
    res = relax_to_equilibrium(system, x0, np.zeros(system.n), settings)
    assert res.static_converged
    xn = system.nodal(res.x)[:, :9].copy()
    assert np.abs(xn[:, :3] - system.mesh.X0[:, :3]).max() > 1e-3  # it moved
    return fab, system.mesh, xn


def test_prolonged_relaxed_state_keeps_its_centroid_curve(relaxed_weave):
    fab, mc, xc = relaxed_weave
    sample = fab.mesh(240, 1)
    curve = interpolate_nodal(mc, xc, sample)[:, :3]
    R = float(mc.radius.max())
    # nested refinement (every coarse element split in two, same order): the same curve
    mf = fab.mesh(12, 2)
    xf = interpolate_nodal(mc, xc, mf)
    np.testing.assert_allclose(interpolate_nodal(mf, xf, sample)[:, :3], curve, rtol=0, atol=1e-12)
    # the coarse nodes are nodes of the nested mesh: their values are copied
    ends_c = np.concatenate([mc.fibril_nodes(f)[[0, -1]] for f in range(mc.n_fibrils)])
    ends_f = np.concatenate([mf.fibril_nodes(f)[[0, -1]] for f in range(mf.n_fibrils)])
    np.testing.assert_allclose(xf[ends_f], xc[ends_c], rtol=0, atol=1e-13)
    # non-nested meshes: the same curve to interpolation accuracy (the coarse curve is
    # only C0 at its element ends, so the error falls with h, but not at the smooth rate)
    errs = []
    for ne in (7, 14, 28):
        md = fab.mesh(ne, 2)
        xd = interpolate_nodal(mc, xc, md)
        errs.append(np.abs(interpolate_nodal(md, xd, sample)[:, :3] - curve).max())
    assert max(errs) < 0.02 * R, errs
    assert errs[0] > errs[1] > errs[2] and errs[2] < errs[0] / 4, errs
    # a higher destination order represents the coarse curve exactly where the elements
    # nest: 6 -> 6 elements of order 4 contain the quadratics
    m4 = fab.mesh(6, 4)
    np.testing.assert_allclose(interpolate_nodal(m4, interpolate_nodal(mc, xc, m4), sample)[:, :3], curve,
                               rtol=0, atol=1e-12)
