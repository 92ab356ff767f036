"""Friction on the curve and smooth contact geometries: the largest relative difference
between the exact tangent and central differences of the residual (h = 1e-7 mm) on the
crossing rows of tests/test_friction_curve.py (6 rows x 4 points, curved elements), in stick
and in slip, for the Lagrange curve at p = 1, 2, 3 and the smooth Hermite curve at p = 1, 2,
3; and the frozen potential's gradient and Hessian against differences of psi and of its
forces; and the slip tangent's asymmetry. Then the assembled crossing system
(tests/test_friction_curve_term.py: both half passes touch) in stick and in slip: the
columns of the slider's middle element and of the base against differences (h = 1e-7 mm).

    nice -n 10 python benchmarks/friction_curve_fd.py
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_friction_curve import CASES, _case, _forces, _frozen, _history, _loads_at  # noqa: E402
from test_friction_curve_term import CASES as SYSTEM_CASES  # noqa: E402
from test_friction_curve_term import _case as _system_case, _cols, _trial  # noqa: E402

from rve.testing import fd_jacobian, fd_nodes, rel_err  # noqa: E402


def main():
    print("geometry p  stick K   slip K    asym(slip)  frozen R  frozen K   (max |K - K_fd| / max |K|)")
    for kind, order in CASES:
        X, geo_fn = _case(kind, order)
        s_bar, anchor = _history(X, geo_fn)
        out = []
        for mu, ratio in ((1.5, 0.05), (0.2, 50.0)):
            _, K, _, _ = _forces(geo_fn, X, s_bar, anchor, mu, ratio)
            Kfd = fd_nodes(lambda Y: _forces(geo_fn, Y, s_bar, anchor, mu, ratio, False)[0], X)
            out.append(rel_err(K, Kfd))
        M = X.shape[1]
        A = K.reshape(K.shape[0], 3 * M, 3 * M)
        asym = np.abs(A - np.swapaxes(A, 1, 2)).max() / np.abs(A).max()
        f0, n0 = _loads_at(geo_fn(X + 0.003))
        wts = geo_fn(X + 0.003).material_weights
        _, R, Kz = _frozen(X, s_bar, anchor, 0.5, 2.0, f0, n0, wts)
        Rfd = fd_nodes(lambda Y: _frozen(Y, s_bar, anchor, 0.5, 2.0, f0, n0, wts, False)[0].sum(axis=1), X)
        Kzfd = fd_nodes(lambda Y: _frozen(Y, s_bar, anchor, 0.5, 2.0, f0, n0, wts, False)[1], X)
        print(f"{kind:8s} {order}  {out[0]:.2e}  {out[1]:.2e}  {asym:.2e}    {rel_err(R, Rfd):.2e}  {rel_err(Kz, Kzfd):.2e}")
    print("assembled crossing: geometry p  stick Fx  slip Fx  (max |Fx - Fx_fd| / max |Fx| over the columns)")
    for kind, order in SYSTEM_CASES:
        cfg, system, parts, x = _system_case(kind, order)
        cols = _cols(system, cfg)
        w = np.zeros(system.n)
        out = []
        for regime in ("stick", "slip"):
            y = _trial(parts, x, regime, order)
            assert getattr(system.term.friction.state(y), regime).sum() == 2
            A = system.evaluate(y, w, 0.0)[1].toarray()[:, cols]
            J = fd_jacobian(lambda v: system.evaluate(v, w, 0.0, jacobian=False)[0], y, cols, eps=1e-7)
            out.append(rel_err(A, J))
        print(f"  {kind:8s} {order}  {out[0]:.2e}  {out[1]:.2e}")


if __name__ == "__main__":
    main()
