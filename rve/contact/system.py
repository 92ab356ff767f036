"""A ``DynamicSystem`` with contact between fibrils: the base model plus the contact terms.

Thesis §4.3, §4.4.6 (the contact integral of F), Algorithm 5.1 (two-element
contributions assembled into the one global system); SPEC §3. Forms:
``rve.physics.contact_forms``; choices and figures: docs/contact.md.

Contract
--------
``ContactSystem(base, params, x=None)`` wraps a ``BeamModel`` (or anything with its
``mesh``, ``layout``, ``nodal``, ``n``, ``mech``, ``mass``, ``evaluate``,
``constraints``, ``admissible`` and an ``ElementPattern`` ``pattern`` with full
node blocks) and implements the ``DynamicSystem`` protocol:

* ``rebuild(x)`` builds the contact map (``rve.contact.build_contact_map``: KD-tree
  candidates within ``cutoff = max(R+ + R-) + params.margin``, ``n_gp`` points per pair)
  and a **union sparsity pattern** of the base element pattern and every candidate pair's
  contact blocks. Until the next ``rebuild``, ``evaluate`` returns ``Fx``, ``Fw`` and
  ``mass()`` returns ``M`` on that one CSR structure, so the solvers' restriction fast
  path (``FreeDofs.combine``) applies. ``rebuild`` changes the structure: a solver that
  cached ``mass()`` (``DirkStepper``, i.e. one ``integrate`` call) must be restarted after
  it — the relaxation driver integrates in chunks of ``rebuild_every`` steps.
* Between rebuilds the *pairs* are fixed; on each pair the closest points ``s-`` are
  recomputed at every evaluation (``params.recompute_closest``, default) with their
  tangent, or frozen at the rebuild state.
* ``evaluate(x, w, t, jacobian)``: base terms + penalty (mechanics: chord end centroids),
  + ``h_C a [[T]]`` (if the layout has T and ``heat_transfer > 0``) + ``sigma_C a [[V]]``
  (if V and ``conductance > 0``), exact tangents.
* Diagnostics: ``contact_state(x)`` (overlaps, active pairs/points, widths) and
  ``fibril_contact_forces(x)`` (the contact force on every fibril, (n_fibrils, 3)).
* ``energy(x)``: the total potential of a mechanics-only system, beam strain energy
  (``beam_strain_energy``) + penalty energy (``contact_energy``); ``F(x, 0)`` is its exact
  gradient (the merit function of the static minimiser ``rve.contact.relax.minimize_energy``).
* ``onset`` (mm): width of the C² onset of the penalty law (``contact_forms.penalty_law``);
  ``params.onset`` gives it as a fraction of the smallest radius, ``set_onset(fraction)``
  changes it in place (a continuation parameter; the map and pattern stay).
* ``stats``: counts and accumulated wall times of rebuilds and contact assemblies.

Everything else (``mesh``, ``layout``, ``nodal``, ``end_currents``, ...) is forwarded
to the base model.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.sparse as sp

from ..physics.contact_forms import (
    chord_gaps, chord_geometry, effective_modulus, effective_radius, hertz_kappa, penalty_energy, penalty_forces,
    penalty_law, scalar_jump,
)
from .search import ContactMap, build_contact_map

__all__ = ["ContactParams", "ContactSystem", "beam_strain_energy"]


@dataclass(frozen=True)
class ContactParams:
    """Contact law and map settings (units: mm, N, MPa, W, A, V).

    ``penalty`` P*: line load per unit overlap (N/mm per mm = N/mm^2); the penalty force
    per unit length is P* g. ``youngs_modulus`` E* of the Hertz width (None: from the base
    material, 1/E* = 2 (1 - nu^2)/E). ``heat_transfer`` h_C (W/(mm^2 K)) and
    ``conductance`` sigma_C (A/(mm^2 V)) of the jump terms. ``n_gp`` points per pair;
    ``margin`` added to R+ + R- for the search cutoff (covers motion between rebuilds);
    ``g_eps`` the Hertz regularisation as a fraction of the smallest radius;
    ``recompute_closest`` recomputes s- at every evaluation (else frozen per rebuild);
    ``rebuild_every`` is advisory (drivers read it); ``onset`` the width of the C² onset
    of the penalty law as a fraction of the smallest radius (0: the linear law P* g)."""

    penalty: float
    youngs_modulus: Optional[float] = None
    heat_transfer: float = 0.0
    conductance: float = 0.0
    n_gp: int = 4
    margin: float = 0.1
    g_eps: float = 1e-3
    recompute_closest: bool = True
    rebuild_every: int = 5
    onset: float = 0.0

    def __post_init__(self):
        if not self.penalty > 0:
            raise ValueError(f"contact penalty must be > 0, got {self.penalty}")
        if self.heat_transfer < 0 or self.conductance < 0:
            raise ValueError("contact heat_transfer and conductance must be >= 0")
        if int(self.n_gp) < 1:
            raise ValueError(f"n_gp must be >= 1, got {self.n_gp}")
        if not self.margin >= 0:
            raise ValueError(f"margin must be >= 0, got {self.margin}")
        if not self.g_eps >= 0:
            raise ValueError(f"g_eps must be >= 0, got {self.g_eps}")
        if not self.onset >= 0:
            raise ValueError(f"onset must be >= 0, got {self.onset}")


def _timer(stats, key, t0):
    stats[key] = stats.get(key, 0.0) + (time.perf_counter() - t0)


class ContactSystem:
    def __init__(self, base, params: ContactParams, x=None):
        self.base = base
        self.params = params
        self.mesh = base.mesh
        self.layout = base.layout
        self.n = base.n
        self.mech = base.mech
        mesh = self.mesh
        mat = getattr(base, "material", None)
        if params.youngs_modulus is not None:
            self.E_star = float(params.youngs_modulus)
        elif mat is not None:
            self.E_star = float(effective_modulus(mat.youngs_modulus, mat.youngs_modulus,
                                                  mat.poisson_ratio, mat.poisson_ratio))
        else:
            raise ValueError("ContactParams.youngs_modulus is needed when the base model has no material")
        self.fields = [f for f in ("T", "V") if self.layout.has(f)]
        self.use_T = self.layout.has("T") and params.heat_transfer > 0
        self.use_V = self.layout.has("V") and params.conductance > 0
        self.scalar = [f for f, on in (("T", self.use_T), ("V", self.use_V)) if on]
        b = self.layout.block
        self.comps = np.array([0, 1, 2] + [self.layout.offset[f] for f in self.scalar], dtype=np.int64)
        self.nC = len(self.comps)
        self.g_eps = float(params.g_eps) * float(mesh.radius.min())
        self.onset = float(params.onset) * float(mesh.radius.min())
        #: > 0: the tangent (not the residual) also holds the normal penalty stiffness of the
        #: points whose separation is below this (mm), ramped to 0 at it: a model for Newton
        #: steps that close gaps (``minimize_energy`` sets it while far from the solution)
        self.tangent_near = 0.0
        self.cutoff = 2.0 * float(mesh.radius.max()) + float(params.margin)
        self.stats = {"rebuilds": 0, "evaluations": 0, "rebuild_s": 0.0, "contact_s": 0.0, "base_s": 0.0}
        self._b = b
        # base element pattern: node-level graph with full b x b blocks
        pat = base.pattern
        self._base_indptr = pat.indptr
        self._base_indices = pat.indices
        self._base_nnz = int(pat.nnz)
        conn = mesh.conn
        nn = conn.shape[1]
        Nn = mesh.n_nodes
        keys = (conn[:, :, None].astype(np.int64) * Nn + conn[:, None, :]).ravel()
        self._base_nodekeys = np.unique(keys)
        if self._base_nodekeys.size * b * b != self._base_nnz:
            raise ValueError("base pattern is not made of full node blocks; ContactSystem needs an ElementPattern")
        self._base_rowstart = np.searchsorted(self._base_nodekeys, np.arange(Nn, dtype=np.int64) * Nn)
        self._nn = nn
        self.map: Optional[ContactMap] = None
        self._matcache: dict = {}
        self.rebuild(np.zeros(self.n) if x is None else x)

    # ------------------------------------------------------------------ forwarding
    def __getattr__(self, name):
        if name == "base":  # not yet set (during construction)
            raise AttributeError(name)
        return getattr(self.base, name)

    def nodal(self, u):
        return self.layout.as_nodal(u)

    def mass(self):
        return self._M

    def constraints(self, t):
        return self.base.constraints(t)

    def admissible(self, x) -> bool:
        return self.base.admissible(x)

    # ------------------------------------------------------------------ map + pattern
    def rebuild(self, x):
        """Rebuild the contact map at state ``x`` and the union sparsity pattern."""
        t0 = time.perf_counter()
        mesh, b, nC = self.mesh, self._b, self.nC
        xn = self.nodal(np.asarray(x, float))
        cmap = build_contact_map(xn[:, :3], mesh, self.cutoff, self.params.n_gp)
        self.map = cmap
        conn = mesh.conn
        nn = self._nn
        ep, em = cmap.e_plus, cmap.e_minus
        P = ep.size
        if self.scalar:
            local = np.concatenate([conn[ep], conn[em]], axis=1)  # (P, 2nn)
            endpos = np.array([0, nn - 1, nn, 2 * nn - 1])
        else:
            local = np.concatenate([cmap.nodes_plus, cmap.nodes_minus], axis=1)  # (P, 4)
            endpos = np.arange(4)
        self._local = local
        self._endpos = endpos
        m = local.shape[1]
        self._m = m
        fp, fm = cmap.fibril_plus, cmap.fibril_minus
        R = mesh.radius
        self._gap_radius = R[fp] + R[fm]
        self._weight = mesh.elem_length[ep] / cmap.n_gp
        self._kappa = hertz_kappa(effective_radius(R[fp], R[fm]), self.params.penalty, self.E_star)
        self._gdofs = (local[:, :, None] * b + self.comps[None, None, :]).reshape(P, m * nC)
        # --- union CSR built at the node-block level (no global sort of the entries).
        # Node pairs: the base element blocks (full b x b) and the contact-only blocks
        # (components `comps` x `comps`). In a row of a contact component every neighbour
        # contributes its block's columns; in the other rows only the base neighbours do.
        Nn = mesh.n_nodes
        ci = self.comps
        isc = np.zeros(b, bool)
        isc[ci] = True
        nkey = (local[:, :, None].astype(np.int64) * Nn + local[:, None, :]).ravel()  # (P m m)
        bkeys = self._base_nodekeys
        dense = Nn * Nn <= 2 ** 25  # node-pair bitmap (<= 32 MB) instead of sorting the keys
        if dense:
            mark = np.zeros(Nn * Nn, np.int8)
            mark[nkey] = 2
            mark[bkeys] = 1
            keys = np.flatnonzero(mark)
            isbase = mark[keys] == 1
            lookup = np.empty(Nn * Nn, np.int32)
            lookup[keys] = np.arange(keys.size, dtype=np.int32)
            locate = lambda k: lookup[k]  # noqa: E731
        else:
            ukey = np.unique(nkey)
            pos = np.minimum(np.searchsorted(bkeys, ukey), bkeys.size - 1)
            ckeys = ukey[bkeys[pos] != ukey]
            keys = np.concatenate([bkeys, ckeys])
            order = np.argsort(keys, kind="stable")
            keys = keys[order]
            isbase = order < bkeys.size
            locate = lambda k: np.searchsorted(keys, k)  # noqa: E731
        nodeI = keys // Nn
        wc = np.where(isbase, b, nC).astype(np.int64)  # columns in a contact-component row
        wo = np.where(isbase, b, 0).astype(np.int64)  # columns in another row
        first = np.searchsorted(nodeI, np.arange(Nn + 1, dtype=np.int64))  # node -> merged range
        cwc = np.concatenate([[0], np.cumsum(wc)])
        cwo = np.concatenate([[0], np.cumsum(wo)])
        offc = cwc[:-1] - cwc[first[nodeI]]  # column offset of the block in its row
        offo = cwo[:-1] - cwo[first[nodeI]]
        lenc = cwc[first[1:]] - cwc[first[:-1]]  # (Nn,) row lengths
        leno = cwo[first[1:]] - cwo[first[:-1]]
        rowlen = np.where(isc[None, :], lenc[:, None], leno[:, None]).ravel()  # (n,)
        indptr = np.concatenate([[0], np.cumsum(rowlen)]).astype(np.int64)
        total = int(indptr[-1])
        # column patterns of one contact-component row / one other row of every node
        nodeJ = keys % Nn
        colc = np.where(isbase[:, None], nodeJ[:, None] * b + np.arange(b)[None, :],
                        np.pad(nodeJ[:, None] * b + ci[None, :], ((0, 0), (0, b - nC)), constant_values=-1))
        Qc = colc.ravel()[(np.arange(b)[None, :] < wc[:, None]).ravel()]
        Qo = (nodeJ[isbase, None] * b + np.arange(b)[None, :]).ravel()
        startc = cwc[first[:-1]]
        starto = cwo[first[:-1]] + Qc.size
        src = np.where(isc[None, :], startc[:, None], starto[:, None]).ravel()
        Q = np.concatenate([Qc, Qo])
        rep = np.repeat(src - indptr[:-1], rowlen)
        indices = Q[np.arange(total, dtype=np.int64) + rep].astype(np.int32)
        self._u_indptr = indptr.astype(np.int32) if total < 2**31 - 1 else indptr
        self._u_indices = indices
        self._u_nnz = total
        self._u_keys_cache = None
        # base entries -> union positions: per base node pair (I, J), entries (c, c')
        bI = bkeys // Nn
        kpos = np.arange(bkeys.size) - self._base_rowstart[bI]  # J's rank among I's base neighbours
        mpos = locate(bkeys)
        rows_b = bI[:, None] * b + np.arange(b)[None, :]  # (B, b)
        off_b = np.where(isc[None, :], offc[mpos][:, None], offo[mpos][:, None])  # (B, b)
        src_pos = (self._base_indptr[rows_b][:, :, None] + (kpos * b)[:, None, None]
                   + np.arange(b)[None, None, :])
        dst_pos = indptr[rows_b][:, :, None] + off_b[:, :, None] + np.arange(b)[None, None, :]
        base_map = np.empty(self._base_nnz, dtype=np.int64)
        base_map[src_pos.ravel()] = dst_pos.ravel()
        self._base_map = base_map
        # local slot layout (P, m, nC, m, nC): indptr[I b + c_i] + offset of block (I, J) + column
        mp = locate(nkey).reshape(P, m, m)
        rowstart = indptr[local[:, :, None].astype(np.int64) * b + ci[None, None, :]]  # (P, m, nC)
        colpos = np.where(isbase[mp][..., None], ci[None, None, None, :], np.arange(nC)[None, None, None, :])
        slots = (rowstart[:, :, :, None, None]
                 + (offc[mp][:, :, None, :, None] + colpos[:, :, None, :, :]))
        self._slots = slots.reshape(P, m * nC * m * nC)
        self._matcache = {}
        self._fw_cache = None
        self._M = self._to_union(self.base.mass())
        self._x_rebuild = np.array(xn[:, :3], copy=True)
        self.stats["rebuilds"] += 1
        _timer(self.stats, "rebuild_s", t0)
        return cmap

    def _csr(self, data):
        return sp.csr_matrix((data, self._u_indices, self._u_indptr), shape=(self.n, self.n))

    def _union_map(self, A):
        """Positions of the entries of CSR ``A`` in the union data array (cached)."""
        if A.indptr is self._base_indptr or (
                A.nnz == self._base_nnz and np.array_equal(A.indptr, self._base_indptr)
                and np.array_equal(A.indices, self._base_indices)):
            return self._base_map
        key = (A.nnz, hash(A.indptr.tobytes()), hash(A.indices.tobytes()))
        mp = self._matcache.get(key)
        if mp is None:
            rows = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(A.indptr))
            k = rows * self.n + A.indices
            if self._u_keys_cache is None:
                self._u_keys_cache = (np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self._u_indptr)) * self.n
                                      + self._u_indices)
            uk = self._u_keys_cache
            mp = np.searchsorted(uk, k)
            if np.any(uk[np.minimum(mp, self._u_nnz - 1)] != k):
                raise ValueError("a base matrix has entries outside its element pattern")
            if len(self._matcache) > 8:
                self._matcache.clear()
            self._matcache[key] = mp
        return mp

    def _union_data(self, A):
        """A's entries laid out on the union structure (zeros elsewhere)."""
        return self._union_add(np.zeros(self._u_nnz), A)

    def _union_add(self, data, A):
        """``data[union positions of A] += A.data`` (A on the base or the union structure)."""
        if A is None:
            return data
        A = A if isinstance(A, sp.csr_matrix) else sp.csr_matrix(A)
        if A.nnz:
            if not A.has_canonical_format:
                A = A.copy()
                A.sum_duplicates()
            data[self._union_map(A)] += A.data
        return data

    def _to_union(self, A):
        return self._csr(self._union_data(A))

    # ------------------------------------------------------------------ contact terms
    def set_onset(self, fraction: float) -> None:
        """Onset width of the penalty law as a fraction of the smallest radius (0: linear)."""
        if not fraction >= 0:
            raise ValueError(f"onset must be >= 0, got {fraction}")
        self.onset = float(fraction) * float(self.mesh.radius.min())

    def _ends(self, x, sel=None):
        r = self.nodal(np.asarray(x, float))[:, :3]
        npl, nmi = self.map.nodes_plus, self.map.nodes_minus
        if sel is not None:
            npl, nmi = npl[sel], nmi[sel]
        return r[npl[:, 0]], r[npl[:, 1]], r[nmi[:, 0]], r[nmi[:, 1]]

    def _geometry(self, x, sel=None):
        cmap = self.map
        sp_, sm, gr = cmap.s_plus, None if self.params.recompute_closest else cmap.s_minus, self._gap_radius
        if sel is not None:
            sp_, gr = sp_[sel], gr[sel]
            sm = None if sm is None else sm[sel]
        return chord_geometry(*self._ends(x, sel), sp_, gr, sm)

    def gaps(self, x) -> np.ndarray:
        """Overlaps g (n_pairs, n_gp) of every point of the map at ``x`` (no tangent data)."""
        cmap = self.map
        sm = None if self.params.recompute_closest else cmap.s_minus
        return chord_gaps(*self._ends(x), cmap.s_plus, self._gap_radius, sm)

    def active_pairs(self, x) -> np.ndarray:
        """Indices of the map's pairs with at least one overlapping point at ``x``."""
        if self.map.n_pairs == 0:
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero((self.gaps(x) > 0.0).any(axis=1))

    def contact_energy(self, x) -> float:
        """Penalty energy ``Σ w φ(g)`` (N mm) of the map's points at ``x``."""
        if self.map.n_pairs == 0:
            return 0.0
        return penalty_energy(self.gaps(x), self._weight, self.params.penalty, self.onset)

    def energy(self, x) -> float:
        """Total potential (N mm) of a mechanics-only system: beam strain energy + penalty
        energy; +inf where det F <= 0 somewhere. Its gradient is ``F(x, 0, t)``."""
        return beam_strain_energy(self.base, x) + self.contact_energy(x)

    def contact_terms(self, x, w, jacobian: bool = True):
        """Contact residual (n,) and local matrices on the active pairs.

        Returns ``(F, act, Kx, Kw)``: ``act`` the active pair indices, ``Kx``/``Kw``
        (len(act), m*nC*m*nC) local entries laid out as ``self._slots[act]``."""
        n, m, nC = self.n, self._m, self.nC
        F = np.zeros(n)
        if self.map.n_pairs == 0:
            return F, np.zeros(0, np.int64), None, None
        near = float(self.tangent_near) if (jacobian and not self.scalar) else 0.0
        if near > 0.0:
            act = np.flatnonzero((self.gaps(x) > -near).any(axis=1))
        else:
            act = self.active_pairs(x)
        if act.size == 0:
            return F, act, None, None
        geo = self._geometry(x, act)
        Pa = act.size
        wgt = self._weight[act]
        if not self.scalar:  # mechanics only: the local unknowns are the 4 chord ends x 3
            Rm, Km = penalty_forces(geo, wgt, self.params.penalty, jacobian, self.onset)
            F += np.bincount(self._gdofs[act].ravel(), weights=Rm.ravel(), minlength=n)
            if not jacobian:
                return F, act, None, None
            if near > 0.0:
                # model stiffness of the points about to touch (separation < near): the
                # normal penalty stiffness, ramped to 0 at the band's edge (tangent only)
                pts = (geo.g <= 0.0) & (geo.g > -near) & (geo.rho > 1e-300)
                kn = np.where(pts, wgt[:, None] * self.params.penalty * (1.0 + geo.g / near), 0.0)
                if np.any(kn > 0):
                    cn = geo.c[..., :, None] * geo.n[..., None, :]  # (Pa, G, 4, 3)
                    cn = cn.reshape(Pa, -1, 12)
                    Km = Km + np.matmul(np.swapaxes(cn * kn[..., None], 1, 2), cn).reshape(Km.shape)
            return F, act, Km.reshape(Pa, -1), None
        Rl = np.zeros((Pa, m, nC))
        Kx = np.zeros((Pa, m, nC, m, nC)) if jacobian else None
        Kw = np.zeros((Pa, m, nC, m, nC)) if jacobian else None
        Rm, Km = penalty_forces(geo, wgt, self.params.penalty, jacobian, self.onset)
        ep = self._endpos
        Rl[:, ep, 0:3] += Rm
        if jacobian:
            for k in range(4):
                for l in range(4):
                    Kx[:, ep[k], 0:3, ep[l], 0:3] += Km[:, k, :, l, :]
        if self.scalar:
            wn = self.nodal(np.asarray(w, float))
            conn = self.mesh.conn
            epair, mpair = self.map.e_plus[act], self.map.e_minus[act]
            for ic, f in enumerate(self.scalar):
                c = 3 + ic
                off = self.layout.offset[f]
                coef = self.params.heat_transfer if f == "T" else self.params.conductance
                u = wn[:, off]
                R, Ju, JX = scalar_jump(geo, self.mesh.order, u[conn[epair]], u[conn[mpair]], wgt, coef,
                                        self._kappa[act], self.g_eps, jacobian)
                Rl[:, :, c] += R
                if jacobian:
                    Kw[:, :, c, :, c] += Ju
                    for k in range(4):
                        Kx[:, :, c, ep[k], 0:3] += JX[:, :, k, :]
        F += np.bincount(self._gdofs[act].ravel(), weights=Rl.ravel(), minlength=n)
        if not jacobian:
            return F, act, None, None
        return F, act, Kx.reshape(Pa, -1), Kw.reshape(Pa, -1)

    # ------------------------------------------------------------------ DynamicSystem
    def evaluate(self, x, w, t, jacobian: bool = True):
        self.stats["evaluations"] += 1
        t0 = time.perf_counter()
        F, Fx, Fw = self.base.evaluate(x, w, t, jacobian)
        _timer(self.stats, "base_s", t0)
        t1 = time.perf_counter()
        Fc, act, Kx, Kw = self.contact_terms(x, w, jacobian)
        F = np.asarray(F, float) + Fc
        if not jacobian:
            _timer(self.stats, "contact_s", t1)
            return F, None, None
        if act.size:
            s = self._slots[act].ravel()
            dx = np.bincount(s, weights=Kx.ravel(), minlength=self._u_nnz)
            self._union_add(dx, Fx)
        else:
            dx = self._union_data(Fx)
        if not self.scalar and Fw is not None and Fw is getattr(self.base, "_C", None):
            # Fw is the base's constant damping matrix (a mechanics-only model): its union
            # copy is kept until the next rebuild (consumers do not modify matrices in place)
            if self._fw_cache is None:
                self._fw_cache = self._csr(self._union_data(Fw))
            Fw_u = self._fw_cache
        else:
            dw = self._union_data(Fw)
            if self.scalar and act.size:
                dw += np.bincount(s, weights=Kw.ravel(), minlength=self._u_nnz)
            Fw_u = self._csr(dw)
        out = F, self._csr(dx), Fw_u
        _timer(self.stats, "contact_s", t1)
        return out

    # ------------------------------------------------------------------ diagnostics
    def max_displacement_since_rebuild(self, x) -> float:
        r = self.nodal(np.asarray(x, float))[:, :3]
        return float(np.sqrt(((r - self._x_rebuild) ** 2).sum(axis=1)).max())

    def contact_state(self, x) -> dict:
        """Overlap statistics of the current map at ``x``.

        ``max_overlap`` (mm) and ``max_overlap_over_R`` (overlap / min(R+, R-)),
        ``pairs``, ``active_pairs``, ``active_points``, ``max_width`` (Hertz a, mm),
        ``total_normal_force`` (N; sum over points of w φ'(g), i.e. w P* g for the linear law)."""
        from ..physics.contact_forms import hertz_width

        out = {"pairs": int(self.map.n_pairs), "active_pairs": 0, "active_points": 0, "max_overlap": 0.0,
               "max_overlap_over_R": 0.0, "max_width": 0.0, "total_normal_force": 0.0}
        if self.map.n_pairs == 0:
            return out
        g = self.gaps(x)
        active = g > 0.0
        g = np.where(active, g, 0.0)
        R = self.mesh.radius
        rmin = np.minimum(R[self.map.fibril_plus], R[self.map.fibril_minus])
        a, _ = hertz_width(g, self._kappa[:, None], self.g_eps)
        out.update(active_pairs=int(active.any(axis=1).sum()), active_points=int(active.sum()),
                   max_overlap=float(g.max()), max_overlap_over_R=float((g / rmin[:, None]).max()),
                   max_width=float(a.max()),
                   total_normal_force=float((self._weight[:, None]
                                             * penalty_law(g, self.params.penalty, self.onset)[1]).sum()))
        return out

    def fibril_contact_forces(self, x) -> np.ndarray:
        """Contact force acting on every fibril (N), (n_fibrils, 3): minus the contact
        residual summed over the fibril's centroid dofs."""
        Fc, _, _, _ = self.contact_terms(x, np.zeros(self.n), jacobian=False)
        rn = self.nodal(Fc)[:, :3]
        out = np.zeros((self.mesh.n_fibrils, 3))
        np.add.at(out, self.mesh.node_fibril, -rn)
        return out

    def contact_conductance(self, x, field: str = "V") -> dict:
        """Discrete contact conductance between every pair of fibrils in contact:
        ``{(f+, f-): sum_points w c_C a(g)}`` (A/V for V, W/K for T)."""
        from ..physics.contact_forms import hertz_width

        coef = self.params.conductance if field == "V" else self.params.heat_transfer
        out: dict = {}
        if self.map.n_pairs == 0:
            return out
        geo = self._geometry(x)
        g = np.where(geo.active, geo.g, 0.0)
        a, _ = hertz_width(g, self._kappa[:, None], self.g_eps)
        Gp = (self._weight[:, None] * coef * a).sum(axis=1)
        nf = self.mesh.n_fibrils
        key = self.map.fibril_plus.astype(np.int64) * nf + self.map.fibril_minus
        uk, inv = np.unique(key, return_inverse=True)
        tot = np.bincount(inv, weights=Gp, minlength=uk.size)
        return {(int(k // nf), int(k % nf)): float(v) for k, v in zip(uk, tot) if v > 0}


def beam_strain_energy(base, x) -> float:
    """Neo-Hookean strain energy ``Σ_q W ψ(F)`` (N mm) of a ``BeamModel`` at state ``x``,
    ``ψ = μ/2 (tr C − 3) − μ ln J + λ/2 (ln J)²`` (the energy whose gradient is the model's
    mechanical residual); +inf where det F <= 0. Mechanics only: a model with a prescribed
    current (Lorentz force) or temperature-dependent μ has no such potential."""
    if getattr(base, "prescribed_current", None) is not None:
        raise ValueError("beam_strain_energy: the Lorentz load of a prescribed current has no potential")
    basis = base.basis
    Fg = basis.deformation_gradient(base.nodal(np.asarray(x, float)))
    a = Fg.reshape(Fg.shape[:-2] + (9,))
    A, B, C, D, E, F, G, H, I = np.moveaxis(a, -1, 0)
    det = A * (E * I - F * H) - B * (D * I - F * G) + C * (D * H - E * G)
    if not det.min() > 0.0:
        return float("inf")
    lnJ = np.log(det)
    mu, lam = float(base.mu), float(base.lam)
    psi = 0.5 * mu * ((a * a).sum(axis=-1) - 3.0) - mu * lnJ + 0.5 * lam * lnJ * lnJ
    return float((basis.W * psi).sum())
