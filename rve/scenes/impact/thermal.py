"""The fabric's heat equation in the impact scene: the induced scene's thermal operators plus
the projectile as a heat sink through the sphere contact (thesis §8.4: "the massive
projectile acts as a thermal reservoir and cools the parts of the fabric it is in contact
with"; docs/impact.md "Temperature").

Contract
--------
``ImpactThermal(system, h_C, fixed_nodes, sink=True)``: a ``ThermalOperators`` of the fabric
(``rve.model.thermal_post``) whose ``contact(x)`` adds, for every active sphere pair,
the conductance ``G = h_C a(g) l_e`` to a reservoir at T = 0 (the projectile: 422 g against
the fabric's 1.3 g, its temperature rise is neglected), distributed to the chord's nodes as
``G beta beta^T`` with ``beta = (1 - s, s)`` (T at the closest point); ``a(g)`` the Hertz
width of the fibril line law with R* = R_f R_p / (R_f + R_p) (``hertz_width``, the fabric's
``g_eps``). ``x`` is the full ``ImpactSystem`` state or the fabric part; for the fabric part
the sphere centres of the last full state (``centres``, set by ``set_state``) are used.
``sink_heat(T, x)`` -> W, the heat flowing into the projectile.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...physics.contact_forms import effective_radius, hertz_kappa, hertz_width
from ...physics.sphere_contact_forms import sphere_segment_geometry
from ...model.thermal_post import ThermalOperators

__all__ = ["ImpactThermal"]


class ImpactThermal(ThermalOperators):
    def __init__(self, impact_system, h_C: float, fixed_nodes, sink: bool = True):
        super().__init__(impact_system.fabric, h_C, fixed_nodes)
        self.impact = impact_system
        self.sink = bool(sink) and h_C > 0
        fab = impact_system.fabric
        self.kappa_sphere = None
        self.centres = None
        self._E_star = float(fab.E_star)
        self._g_eps = float(fab.g_eps)

    def _split(self, x):
        x = np.asarray(x, float)
        if x.size == self.impact.n:
            c, _ = self.impact.positions(x)
            self.centres = c
            return x[: self.impact.nf]
        return x

    def set_state(self, x_full) -> None:
        self.centres = self.impact.positions(np.asarray(x_full, float))[0]

    def sink_matrix(self, x):
        """G beta beta^T of the active sphere pairs at the fabric state x (n_nodes, n_nodes)."""
        term = self.impact.sphere
        if not self.sink or term.n_pairs == 0 or self.centres is None:
            return sp.csr_matrix((self.n, self.n))
        r = self.impact.fabric.nodal(np.asarray(x, float))[:, :3]
        p, a, b = self.centres[term.centre], r[term.node_a], r[term.node_b]
        geo = sphere_segment_geometry(p, a, b, term.gap_radius)
        act = geo["g"] > 0
        if not act.any():
            return sp.csr_matrix((self.n, self.n))
        Rf = self.impact.mesh.radius[self.impact.mesh.elem_fibril[term.element[act]]]
        kap = hertz_kappa(effective_radius(Rf, term.radius), term.penalty, self._E_star)
        width, _ = hertz_width(geo["g"][act], kap, self._g_eps)
        G = self.h_C * width * self.impact.mesh.elem_length[term.element[act]]
        s = geo["s"][act]
        beta = np.stack([1.0 - s, s], axis=1)
        nodes = np.stack([term.node_a[act], term.node_b[act]], axis=1)
        vals = G[:, None, None] * beta[:, :, None] * beta[:, None, :]
        rows = np.repeat(nodes, 2, axis=1).ravel()
        cols = np.tile(nodes, (1, 2)).ravel()
        return sp.csr_matrix((vals.ravel(), (rows, cols)), shape=(self.n, self.n))

    def contact_triplets(self, x):
        """The fabric's contact triplets at the fabric part of x plus the sink's: every path of
        ``ThermalOperators`` (``contact``, ``contact_blocks``) goes through here, so the full
        ``ImpactSystem`` state is split once and the sink is never left out."""
        xf = self._split(x)
        r, c, v = super().contact_triplets(xf)
        if not self.sink:
            return r, c, v

        def compute():
            S = self.sink_matrix(xf).tocoo()
            if S.nnz == 0:
                return r, c, v
            return (np.concatenate([r, S.row.astype(np.int64)]), np.concatenate([c, S.col.astype(np.int64)]),
                    np.concatenate([v, S.data]))
        # memoised for the last (fabric state, sphere centres): the post-solve asks once per
        # refinement iteration (rve.model.thermal_post.ThermalPostSolver)
        centres = np.zeros(0) if self.centres is None else self.centres
        return self._memoised("contact_sink", (xf, centres), 0.0, compute,
                              (self.system.term.map, self.impact.sphere.centre))

    def joule(self, x, w, t):
        xf = self._split(x)
        w = np.asarray(w, float)
        wf = w[: self.impact.nf] if w.size == self.impact.n else w
        return super().joule(xf, wf, t)

    def sink_heat(self, T, x) -> float:
        """Heat flowing into the projectile (W) at fabric temperatures T and state x."""
        xf = self._split(x)
        if not self.sink:
            return 0.0
        return float((self.sink_matrix(xf) @ np.asarray(T, float)).sum())  # sum of G T(closest point)
