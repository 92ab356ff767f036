"""The projectile of thesis §8.4 and the coupled system fabric + projectile (docs/impact.md).

Contract
--------
``projectile_mesh(radius, length, bottom)``: ONE linear director-beam element along +z from
``bottom`` (its lower end node) to ``bottom + length e_z``, radius ``radius`` (its end nodes
are the centres of the hemispherical ends of §8.4).

``ImpactSystem(fabric, projectile, sphere)``: one ``DynamicSystem`` (``rve.solvers.system``)
of a fabric ``ContactSystem`` (its dofs first, 0 .. n_f-1) and a projectile ``BeamModel``
(dofs n_f .. n-1, its own material), coupled by the ``SphereContactTerm`` between the
projectile's end nodes and the fabric's fibril chords (mechanics only: sigma_C = 0 in
Table 8.2; no heat transfer to the projectile, see docs/impact.md).

* ``rebuild(x)``: rebuilds the fabric's contact map, the sphere pairs (within R_p + R_f +
  margin) and the union CSR structure of M, Fx, Fw (fabric union + a dense projectile
  block + the 9 x 9 blocks of every sphere pair): until the next rebuild ``mass()`` and
  ``evaluate`` return matrices on one structure (the solvers' fast path);
  ``structure_version`` counts the rebuilds.
* ``evaluate(x, w, t, jacobian)``: fabric + projectile + sphere contact, exact tangents;
  ``constraints(t)`` both parts' (projectile dofs shifted); ``admissible`` both.
* With friction at the sphere contact (``sphere.friction``): a pair's block couples the end
  node's directors as well (15 x 15: centre, d1, d2, a, b; ``sphere.n_local``), and
  ``frames(x)`` (2, 2, 3) are the end nodes' directors; ``sphere_local(x)`` the unknowns of
  every pair (for the friction driver's commit). Without it the pattern is the frictionless
  one, bit for bit.
* ``split(u)`` -> (u_fabric, u_projectile); ``row_scales(h, x, w)`` both parts';
  ``sphere_terms(x, jacobian)`` the sphere term alone (F (n,), act, K);
  ``sphere_forces(x)`` force on each end node (2, 3), N;
  ``max_displacement_since_rebuild(x)`` over fabric centroids and projectile end nodes.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..kernels import index_kernels

from ..fem.mesh import fibril_mesh, straight_fibril

__all__ = ["projectile_mesh", "ImpactSystem"]


def projectile_mesh(radius: float, length: float, bottom=(0.0, 0.0, 0.0)):
    """One linear element along +z (module docstring)."""
    b = np.asarray(bottom, float)
    fib = straight_fibril(b, b + np.array([0.0, 0.0, float(length)]), float(radius), name="projectile")
    return fibril_mesh([fib], 1, 1)


class ImpactSystem:
    def __init__(self, fabric, projectile, sphere, x=None):
        self.fabric, self.projectile, self.sphere = fabric, projectile, sphere
        self.nf, self.np_ = int(fabric.n), int(projectile.n)
        self.n = self.nf + self.np_
        self.mech = np.concatenate([np.asarray(fabric.mech, bool), np.asarray(projectile.mech, bool)])
        pm = projectile.mesh
        self.ends = np.array(pm.end_nodes(0), np.int64)  # projectile end nodes (bottom, top)
        lf, lp = fabric.layout, projectile.layout
        self._r_fab = lf.dofs("r").reshape(-1, 3)  # (n_nodes_f, 3)
        self._r_end = self.nf + lp.dofs("r", self.ends).reshape(-1, 3)  # (2, 3)
        self._g_end = self.nf + np.stack([lp.dofs("g1", self.ends).reshape(-1, 3),
                                          lp.dofs("g2", self.ends).reshape(-1, 3)], axis=1)  # (2, 2, 3)
        self.params = fabric.params
        self.structure_version = 0
        self.stats = {"sphere_s": 0.0, "sphere_rebuilds": 0, "compose_s": 0.0}
        self._maps = {}
        self._maps_content = {}
        self.rebuild(np.zeros(self.n) if x is None else x)

    # ------------------------------------------------------------------ helpers
    def split(self, u):
        u = np.asarray(u)
        return u[: self.nf], u[self.nf:]

    def positions(self, x):
        """(end-node centres (2, 3), fabric centroids (n_nodes_f, 3)) of a state."""
        x = np.asarray(x, float)
        return x[self._r_end], x[self._r_fab]

    def frames(self, x):
        """The end nodes' directors (2, 2, 3) of a state."""
        return np.asarray(x, float)[self._g_end]

    def sphere_local(self, x):
        """The local unknowns (P, n_local, 3) of every sphere pair at ``x``."""
        c, r = self.positions(x)
        return self.sphere.local(c, r, self.frames(x))

    @property
    def mesh(self):
        return self.fabric.mesh

    @property
    def layout(self):
        return self.fabric.layout

    def row_scales(self, t_ref, x, w):
        xf, xp = self.split(x)
        wf, wp = self.split(w)
        return np.concatenate([self.fabric.base.row_scales(t_ref, xf, wf), self.projectile.row_scales(t_ref, xp, wp)])

    # ------------------------------------------------------------------ structure
    def rebuild(self, x):
        x = np.asarray(x, float)
        xf, _ = self.split(x)
        self.fabric.rebuild(xf)
        t0 = time.perf_counter()
        c, r = self.positions(x)
        self.sphere.rebuild(c, r, self.frames(x))
        self.stats["sphere_rebuilds"] += 1
        self._x_rebuild = (c.copy(), r.copy())
        # sphere pair dofs: (centre r, [director 1, director 2,] node a r, node b r)
        sp_ = self.sphere
        own = [self._r_end[sp_.centre]]
        if sp_.n_local == 5:
            own += [self._g_end[sp_.centre, 0], self._g_end[sp_.centre, 1]]
        self.sphere_dofs = np.concatenate(own + [self._r_fab[sp_.node_a], self._r_fab[sp_.node_b]],
                                          axis=1)  # (P, 3 n_local)
        L = self.sphere_dofs.shape[1]
        Mf = sp.csr_matrix(self.fabric.mass())
        if not Mf.has_sorted_indices:  # the union needs sorted rows (the fabric's arrays stay as they are)
            Mf = Mf.copy()
            Mf.sort_indices()
        self._build_union(Mf)
        self._pos_sphere = self._positions_of(self.sphere_dofs.repeat(L, axis=1).ravel(),
                                              np.tile(self.sphere_dofs, (1, L)).ravel()).reshape(-1, L * L)
        Mp = sp.csr_matrix(self.projectile.mass())
        data = np.zeros(self.nnz)
        self._add(data, Mf, 0)
        self._add(data, Mp, self.nf)
        self._M = self._csr(data)
        self.structure_version += 1
        self.stats["sphere_s"] += time.perf_counter() - t0
        return self.fabric.map

    def _build_union(self, Mf):
        """Union CSR of the fabric pattern (rows < nf), the fabric-row x projectile-column
        entries of the sphere pairs (appended to their rows: columns >= nf keep the rows
        sorted) and the projectile rows (dense projectile block + sphere-pair columns),
        without sorting the fabric's entries again; the fabric pattern's positions in the
        union are recorded for ``_add``."""
        nf, n = self.nf, self.n
        sd = self.sphere_dofs
        m = sd.shape[1] - 6          # the projectile's dofs of a pair (3, or 9 with friction)
        pd = nf + np.arange(self.np_)
        # fabric rows x projectile columns: (fabric dof, end dof) of every pair
        fr = np.repeat(sd[:, m:], m, axis=1).ravel()
        fc = np.tile(sd[:, :m], (1, 6)).ravel()
        key = np.unique(fr.astype(np.int64) * n + fc)
        er, ec = key // n, key % n
        cnt_f = np.diff(Mf.indptr).astype(np.int64)
        cnt_e = np.bincount(er, minlength=nf).astype(np.int64)
        # projectile rows: all projectile dofs + the fabric dofs of the pairs (the end rows)
        p_rows, p_cols = [], []
        for i, d in enumerate(pd):
            extra = sd[(sd[:, :m] == d).any(axis=1), m:].ravel()
            cols = np.unique(np.concatenate([extra.astype(np.int64), pd]))
            p_rows.append(np.full(cols.size, d))
            p_cols.append(cols)
        cnt_p = np.array([c.size for c in p_cols], np.int64)
        counts = np.concatenate([cnt_f + cnt_e, cnt_p])
        indptr = np.concatenate([[0], np.cumsum(counts)])
        nnz = int(indptr[-1])
        indices = np.empty(nnz, np.int64)
        # the compiled index loops (rve.kernels.index) where they run: the same integers
        # without the (nnz,) int64 temporaries, whose fresh pages made this the costliest
        # part of a rebuild in the impact process (docs/engine.md "Dynamic scenes: rebuilds, page faults")
        ix = index_kernels()
        if ix is not None:
            pos_f = ix.copy_rows(Mf.indptr, Mf.indices, indptr, indices)
        else:
            rows_f = np.repeat(np.arange(nf), cnt_f)
            pos_f = np.arange(Mf.nnz) + (indptr[:-1][:nf] - Mf.indptr[:-1].astype(np.int64))[rows_f]
            indices[pos_f] = Mf.indices
        if er.size:
            start_e = indptr[er] + cnt_f[er]
            rank = np.arange(er.size) - np.concatenate([[0], np.cumsum(cnt_e)])[er]
            indices[start_e + rank] = ec
        off = indptr[nf]
        if cnt_p.size:
            indices[off:] = np.concatenate(p_cols)
        self.indptr = indptr.astype(np.int32) if nnz < 2**31 else indptr
        self.indices = indices.astype(np.int32)
        self.nnz = nnz
        self._maps = {id(Mf.indices): (Mf.indices, Mf.indptr, pos_f)}
        self._maps_content = {}
        if ix is not None:
            self._keys = None
            if not ix.rows_increasing(self.indptr, self.indices):  # pragma: no cover - construction invariant
                raise RuntimeError("ImpactSystem: the union pattern is not sorted / has duplicates")
            return
        rows = np.repeat(np.arange(n), counts)
        self._keys = rows * n + indices
        if np.any(np.diff(self._keys) <= 0):  # pragma: no cover - construction invariant
            raise RuntimeError("ImpactSystem: the union pattern is not sorted / has duplicates")

    def _positions_of(self, rows, cols):
        """Positions of the entries (rows, cols) in the union's data array (row-major sorted
        keys: a binary search per entry, within its row by the compiled loop)."""
        ix = index_kernels()
        if ix is not None:
            pos, ok = ix.csr_positions(self.indptr, self.indices, rows, cols)
        else:
            keys = np.asarray(rows, np.int64) * self.n + np.asarray(cols, np.int64)
            if self._keys is None:
                counts = np.diff(self.indptr)
                self._keys = np.repeat(np.arange(self.n, dtype=np.int64), counts) * self.n + self.indices
            pos = np.searchsorted(self._keys, keys)
            ok = not keys.size or (pos.max() < self.nnz and np.array_equal(self._keys[pos], keys))
        if not ok:
            raise RuntimeError("ImpactSystem: a matrix entry outside the union pattern (structure changed "
                               "without a rebuild)")
        return pos

    def _add(self, data, A, off):
        """data[union positions of A's entries] += A.data (A CSR, block at (off, off))."""
        if A is None or A.nnz == 0:
            return
        hit = self._maps.get(id(A.indices))
        if hit is None or hit[0] is not A.indices or hit[1] is not A.indptr:
            # a matrix with new index arrays on a structure seen before (the relaxation's
            # row-scaled constant damping operator is a new CSR at every evaluation): its
            # positions by the structure's content instead of a binary search of every entry
            # in the union's keys (measured: most of the relaxation's evaluations)
            ckey = (off, A.shape, A.nnz, hash(A.indptr.tobytes()), hash(A.indices.tobytes()))
            if hit is not None and hit[0].shape == A.indices.shape and np.array_equal(hit[0], A.indices) \
                    and np.array_equal(hit[1], A.indptr):
                pos = hit[2]
            elif ckey in self._maps_content:
                pos = self._maps_content[ckey]
            else:
                rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr)) + off
                pos = self._positions_of(rows, A.indices.astype(np.int64) + off)
                if len(self._maps_content) > 16:
                    self._maps_content.clear()
                self._maps_content[ckey] = pos
            if len(self._maps) > 16:
                self._maps.clear()
            hit = self._maps[id(A.indices)] = (A.indices, A.indptr, pos)
        data[hit[2]] += A.data

    def _csr(self, data):
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))

    # ------------------------------------------------------------------ DynamicSystem
    def mass(self):
        return self._M

    def constraints(self, t):
        i1, v1 = self.fabric.constraints(t)
        i2, v2 = self.projectile.constraints(t)
        return np.concatenate([np.asarray(i1, np.int64), np.asarray(i2, np.int64) + self.nf]), \
            np.concatenate([np.asarray(v1, float), np.asarray(v2, float)])

    def admissible(self, x) -> bool:
        xf, xp = self.split(x)
        return bool(self.fabric.admissible(xf) and self.projectile.admissible(xp))

    def sphere_terms(self, x, jacobian: bool = True):
        """The sphere contact alone: (F (n,), act, K (Pa, L, L) or None), L = 3 n_local."""
        c, r = self.positions(x)
        act, Fl, K = self.sphere.forms(c, r, jacobian, self.frames(x))
        F = np.zeros(self.n)
        if act.size:
            F = np.bincount(self.sphere_dofs[act].ravel(), weights=Fl.reshape(act.size, -1).ravel(),
                            minlength=self.n)
        return F, act, K

    def sphere_forces(self, x) -> np.ndarray:
        c, r = self.positions(x)
        return self.sphere.forces_on_centres(c, r, self.frames(x))

    def sphere_energy(self, x) -> float:
        c, r = self.positions(x)
        return self.sphere.energy(c, r)

    def evaluate(self, x, w, t, jacobian: bool = True):
        x = np.asarray(x, float)
        w = np.asarray(w, float)
        xf, xp = self.split(x)
        wf, wp = self.split(w)
        Ff, Fxf, Fwf = self.fabric.evaluate(xf, wf, t, jacobian)
        Fp, Fxp, Fwp = self.projectile.evaluate(xp, wp, t, jacobian)
        t0 = time.perf_counter()
        Fs, act, Ks = self.sphere_terms(x, jacobian)
        F = np.concatenate([Ff, Fp]) + Fs
        if not jacobian:
            self.stats["sphere_s"] += time.perf_counter() - t0
            return F, None, None
        dx = np.zeros(self.nnz)
        if act.size:
            dx += np.bincount(self._pos_sphere[act].ravel(), weights=Ks.ravel(), minlength=self.nnz)
        self.stats["sphere_s"] += time.perf_counter() - t0
        t1 = time.perf_counter()
        self._add(dx, sp.csr_matrix(Fxf), 0)
        self._add(dx, sp.csr_matrix(Fxp), self.nf)
        dw = np.zeros(self.nnz)
        if Fwf is not None:
            self._add(dw, sp.csr_matrix(Fwf), 0)
        if Fwp is not None:
            self._add(dw, sp.csr_matrix(Fwp), self.nf)
        out = F, self._csr(dx), self._csr(dw)
        self.stats["compose_s"] += time.perf_counter() - t1
        return out

    # ------------------------------------------------------------------ diagnostics
    def max_displacement_since_rebuild(self, x) -> float:
        c, r = self.positions(x)
        c0, r0 = self._x_rebuild
        dc = float(np.sqrt(((c - c0) ** 2).sum(axis=1)).max())
        dr = float(np.sqrt(((r - r0) ** 2).sum(axis=1)).max()) if r.size else 0.0
        return max(dc, dr)
