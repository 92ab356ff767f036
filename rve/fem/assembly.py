"""Node-interleaved dof layout and fast sparse assembly of element arrays.

Contract
--------
``DofLayout(n_nodes, fields)``: every node carries the same block of components, in the
order given by ``fields`` (a subset of ``("mech", "T", "V")``; "mech" is the 9 components
r, g1, g2). Global dof of (node, comp) = node * block + comp (SPEC §4: node-interleaved
ordering keeps the bandwidth of the beam systems small).

Dof indices are asked of the layout, never computed by hand: ``layout.dofs(name, nodes,
comp)`` with ``name`` a field ("mech", "T", "V") or a part of the mechanical block ("r"
the centroid, "g1", "g2" the directors), ``comp`` one component of it (0, 1, 2 = x, y, z)
or all; ``layout.offset_of(name)`` is the position of that part within the node block.

``ElementPattern(layout, conn)`` precomputes, for element connectivity ``conn`` (E, nn),
the CSR structure of the global matrix and the position of every element-matrix entry in
its ``data`` array. ``assemble_matrix(Ke)`` with Ke (E, nn*block, nn*block) is then one
``np.bincount``; ``assemble_vector(Re)`` likewise; ``assemble_csr(Ke)`` returns the same
matrix as a shallow copy of a template (no structure validation per call: the model's fast
path, every call's matrices share the pattern's index arrays).

``UnionPattern(pattern, local, comps)``: the union CSR structure of an element pattern (full
node blocks) and a second group of "pair elements" ``local`` (P, m) nodes whose entries
touch only the components ``comps`` of each node (the contact pairs). ``base_map`` places
the pattern's data in the union, ``slots`` (P, (m nC)^2) and ``gdofs`` (P, m nC) the pair
elements' entries; ``add(data, A)`` adds a CSR matrix on the pattern (or the union) into
union data; ``csr(data)`` wraps union data (every matrix shares the union's index
arrays; after ``restrict(keep)`` those of the kept entries, the structural zeros of the pair
elements left out). Used by ``rve.model.assembler`` (docs/contact.md).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..kernels import index_kernels as _index_kernels

__all__ = ["DofLayout", "ElementPattern", "UnionPattern"]

_FIELD_SIZE = {"mech": 9, "T": 1, "V": 1}

#: parts of the mechanical block: (offset within the block, size)
_MECH_PARTS = {"r": (0, 3), "g1": (3, 3), "g2": (6, 3)}


class DofLayout:
    def __init__(self, n_nodes: int, fields=("mech",)):
        fields = tuple(fields)
        for f in fields:
            if f not in _FIELD_SIZE:
                raise ValueError(f"unknown field {f!r}; allowed: {sorted(_FIELD_SIZE)}")
        if "mech" not in fields or fields[0] != "mech":
            raise ValueError("the mechanical field must come first in the dof layout")
        self.n_nodes = int(n_nodes)
        self.fields = fields
        self.offset = {}
        o = 0
        for f in fields:
            self.offset[f] = o
            o += _FIELD_SIZE[f]
        self.block = o
        self.n = self.n_nodes * self.block
        mech = np.zeros(self.block, bool)
        mech[:9] = True
        self.mech = np.tile(mech, self.n_nodes)

    def has(self, field: str) -> bool:
        return field in self.offset

    def dof(self, nodes, comp) -> np.ndarray:
        """Global dof index of component ``comp`` (int within the block) at ``nodes``."""
        return np.asarray(nodes) * self.block + comp

    def field_dofs(self, field: str, nodes=None) -> np.ndarray:
        nodes = np.arange(self.n_nodes) if nodes is None else np.asarray(nodes)
        o = self.offset[field]
        k = _FIELD_SIZE[field]
        return (nodes[:, None] * self.block + o + np.arange(k)[None, :]).ravel()

    def offset_of(self, name: str) -> int:
        """Position of field or mechanical part ``name`` within the node block."""
        if name in _MECH_PARTS:
            return _MECH_PARTS[name][0]
        if name not in self.offset:
            raise ValueError(f"the layout has no {name!r} dofs (fields {self.fields}; parts {sorted(_MECH_PARTS)})")
        return self.offset[name]

    def dofs(self, name: str, nodes=None, comp=None) -> np.ndarray:
        """Global dofs of field or mechanical part ``name`` ("mech", "T", "V", "r", "g1",
        "g2") at ``nodes`` (all nodes if None), node-major: all components of a node, or
        only component ``comp`` (an int or a sequence of ints within the part)."""
        o = self.offset_of(name)
        size = _MECH_PARTS[name][1] if name in _MECH_PARTS else _FIELD_SIZE[name]
        comps = np.arange(size) if comp is None else np.atleast_1d(np.asarray(comp, dtype=np.int64))
        if comps.size and (comps.min() < 0 or comps.max() >= size):
            raise ValueError(f"component {comp!r} out of range for {name!r} (0..{size - 1})")
        nodes = np.arange(self.n_nodes) if nodes is None else np.atleast_1d(np.asarray(nodes, dtype=np.int64))
        return (nodes[:, None] * self.block + o + comps[None, :]).ravel()

    def as_nodal(self, u: np.ndarray) -> np.ndarray:
        return u.reshape(self.n_nodes, self.block)


class ElementPattern:
    def __init__(self, layout: DofLayout, conn: np.ndarray):
        conn = np.asarray(conn)
        E, nn = conn.shape
        b = layout.block
        self.conn = conn
        self.block = b
        self.n_nodes = layout.n_nodes
        self.n = layout.n
        self.nloc = nn * b
        edofs = (conn[:, :, None] * b + np.arange(b)[None, None, :]).reshape(E, nn * b)
        self.edofs = edofs
        rows = np.repeat(edofs, self.nloc, axis=1).ravel()
        cols = np.tile(edofs, (1, self.nloc)).ravel()
        # unique (row, col) pairs in CSR order
        key = rows.astype(np.int64) * self.n + cols
        uniq, inv = np.unique(key, return_inverse=True)
        self.slot = inv
        self.nnz = uniq.size
        ur = uniq // self.n
        self.indices = (uniq % self.n).astype(np.int32)
        self.indptr = np.zeros(self.n + 1, np.int64)
        np.add.at(self.indptr, ur + 1, 1)
        self.indptr = np.cumsum(self.indptr)
        self._template = None

    def assemble_vector(self, Re: np.ndarray) -> np.ndarray:
        return np.bincount(self.edofs.ravel(), weights=Re.reshape(-1), minlength=self.n)

    def assemble_matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        data = np.bincount(self.slot, weights=Ke.reshape(-1), minlength=self.nnz)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))

    def assemble_csr(self, Ke: np.ndarray) -> sp.csr_matrix:
        """``assemble_matrix(Ke)`` as a shallow copy of a template CSR matrix with new data
        (building a csr_matrix validates its structure every time, which costs more than the sum)."""
        import copy

        if self._template is None:
            self._template = self.assemble_matrix(np.zeros(self.slot.size))
        data = np.bincount(self.slot, weights=Ke.reshape(-1), minlength=self.nnz)
        A = copy.copy(self._template)
        A.data = data
        return A

    def node_keys(self):
        """(sorted node-pair keys I * n_nodes + J of the pattern, first key of every node row)."""
        if getattr(self, "_node_keys", None) is None:
            Nn, b = self.n_nodes, self.block
            conn = self.conn
            keys = np.unique((conn[:, :, None].astype(np.int64) * Nn + conn[:, None, :]).ravel())
            if keys.size * b * b != self.nnz:  # pragma: no cover - an ElementPattern has full blocks
                raise ValueError("the pattern is not made of full node blocks")
            self._node_keys = keys, np.searchsorted(keys, np.arange(Nn, dtype=np.int64) * Nn)
        return self._node_keys


def _base_map(pattern, bkeys, base_rowstart, isc, offc, offo, mpos, indptr) -> np.ndarray:
    """Union positions of the base pattern's entries: per base node pair (I, J), entries (c, c')."""
    b, Nn = pattern.block, pattern.n_nodes
    bI = bkeys // Nn
    kpos = np.arange(bkeys.size) - base_rowstart[bI]  # J's rank among I's base neighbours
    rows_b = bI[:, None] * b + np.arange(b)[None, :]  # (B, b)
    off_b = np.where(isc[None, :], offc[mpos][:, None], offo[mpos][:, None])  # (B, b)
    src_pos = (pattern.indptr[rows_b][:, :, None] + (kpos * b)[:, None, None]
               + np.arange(b)[None, None, :])
    dst_pos = indptr[rows_b][:, :, None] + off_b[:, :, None] + np.arange(b)[None, None, :]
    base_map = np.empty(pattern.nnz, dtype=np.int64)
    base_map[src_pos.ravel()] = dst_pos.ravel()
    return base_map


def _local_slots(local, ci, indptr, offc, mp, isbase, b: int, total: int, ix) -> np.ndarray:
    """The union positions of every pair element's local (m nC) x (m nC) matrix, (P, (m nC)^2):
    indptr[I b + c_i] + offset of block (I, J) + column."""
    P, m = local.shape
    nC = ci.size
    rowstart = indptr[local[:, :, None].astype(np.int64) * b + ci[None, None, :]]  # (P, m, nC)
    # column of (J, c') within row (I, c): offset of block (I, J) + c' (pair-only block)
    # or + comps[c'] (base block); one broadcast sum into the (P, m, nC, m, nC) slots
    idx = np.int32 if total < 2**31 - 1 else np.int64
    slots = np.empty((P, m, nC, m, nC), idx)
    if ix is not None:
        ix.union_slots(rowstart, offc, mp, isbase, ci, slots)
    else:
        shift = np.stack([np.arange(nC), ci]).astype(idx)  # [isbase, c']
        colpos = offc.astype(idx)[mp][..., None] + shift[isbase.astype(np.int8)[mp]]  # (P, m, m, nC)
        np.add(rowstart.astype(idx)[:, :, :, None, None], colpos[:, :, None, :, :], out=slots)
    return slots.reshape(P, m * nC * m * nC)


class UnionPattern:
    """Union CSR structure of an ``ElementPattern`` and pair elements (module docstring)."""

    #: node-pair tables (int8 + 2 int32 per node pair, allocated lazily: only the touched
    #: pages cost) while n_nodes^2 <= this; beyond, sorted keys and binary search. Equal to
    #: ``keep_tables_limit``: tables made afresh for every union (n_nodes^2 beyond that
    #: limit) cost far more than the sort in a long-running process. Measured in the impact
    #: (5,184 nodes: 27M node pairs, 240 MB of tables per build), first 40 steps: 2.5 s per
    #: union build with fresh tables against 0.05 s sorted, the rebuilds 5.8 -> 1.7 s CPU of
    #: 18.8 s (docs/engine.md "Dynamic scenes: rebuilds, page faults"); in a fresh small process the
    #: tables took 0.02 s, so the cost is the first touch of fresh pages in a big process.
    dense_limit = 2 ** 23

    def __init__(self, pattern: ElementPattern, local: np.ndarray, comps: np.ndarray):
        b, Nn = pattern.block, pattern.n_nodes
        self.n = n = pattern.n
        self.pattern = pattern
        local = np.asarray(local)
        ci = np.asarray(comps, dtype=np.int64)
        nC = ci.size
        P, m = local.shape
        self.gdofs = (local[:, :, None] * b + ci[None, None, :]).reshape(P, m * nC)
        # union CSR built at the node-block level (no global sort of the entries).
        # Node pairs: the base element blocks (full b x b) and the pair-only blocks
        # (components `comps` x `comps`). In a row of a pair component every neighbour
        # contributes its block's columns; in the other rows only the base neighbours do.
        bkeys, base_rowstart = pattern.node_keys()
        isc = np.zeros(b, bool)
        isc[ci] = True
        nkey = (local[:, :, None].astype(np.int64) * Nn + local[:, None, :]).ravel()  # (P m m)
        keys, isbase, locate = self._union_keys(pattern, bkeys, nkey, Nn)
        nodeI = keys // Nn
        wc = np.where(isbase, b, nC).astype(np.int64)  # columns in a pair-component row
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
        # column patterns of one pair-component row / one other row of every node
        nodeJ = keys % Nn
        ix = _index_kernels()  # the compiled loops (rve.kernels.index), else the numpy reference
        if ix is not None:
            Qc, Qo = np.empty(int(cwc[-1]), np.int64), np.empty(int(cwo[-1]), np.int64)
            ix.union_columns(nodeJ, isbase, b, ci, Qc, Qo)
        else:
            colc = np.where(isbase[:, None], nodeJ[:, None] * b + np.arange(b)[None, :],
                            np.pad(nodeJ[:, None] * b + ci[None, :], ((0, 0), (0, b - nC)), constant_values=-1))
            Qc = colc.ravel()[(np.arange(b)[None, :] < wc[:, None]).ravel()]
            Qo = (nodeJ[isbase, None] * b + np.arange(b)[None, :]).ravel()
        startc = cwc[first[:-1]]
        starto = cwo[first[:-1]] + Qc.size
        src = np.where(isc[None, :], startc[:, None], starto[:, None]).ravel()
        Q = np.concatenate([Qc, Qo])
        if ix is not None:
            self.indices = np.empty(total, np.int32)
            ix.row_gather(Q, src, rowlen, indptr, self.indices)
        else:
            rep = np.repeat(src - indptr[:-1], rowlen)
            self.indices = Q[np.arange(total, dtype=np.int64) + rep].astype(np.int32)
        self.indptr = indptr.astype(np.int32) if total < 2**31 - 1 else indptr
        self.nnz = total
        self.base_map = _base_map(pattern, bkeys, base_rowstart, isc, offc, offo, locate(bkeys), indptr)
        self.slots = _local_slots(local, ci, indptr, offc, locate(nkey).reshape(P, m, m), isbase, b, total, ix)
        self._matcache: dict = {}
        self._keys = None
        self._template = None
        #: ``restrict``: the union data positions the matrices are handed out on (None: all)
        self.keep = None
        self._kept_template = None

    def restrict(self, keep) -> None:
        """Hand out ``csr`` matrices on the union entries ``keep`` (bool over the union data)
        only: the pair elements' entries that their forms never fill (structural zeros, e.g.
        the components of a block widened for one node of the pair) are left out, so a
        solver that analyses the stored pattern does not order them. The data arrays stay
        on the whole union; None: every entry."""
        self.keep, self._kept_template = None, None
        if keep is None or bool(np.all(keep)):
            return
        self.csr(np.zeros(self.nnz))   # the union's template first: its index arrays
        self.keep = np.flatnonzero(keep)
        rows = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.indptr))[self.keep]
        indptr = np.zeros(self.n + 1, dtype=np.int64)
        np.cumsum(np.bincount(rows, minlength=self.n), out=indptr[1:])
        self._kept_template = sp.csr_matrix((np.zeros(self.keep.size), self.indices[self.keep],
                                             indptr.astype(self.indptr.dtype)), shape=(self.n, self.n))

    def _union_keys(self, pattern, bkeys, nkey, Nn: int):
        """``(keys, isbase, locate)``: the sorted node-pair keys of the union (the base
        pattern's and the pair-only ones), which of them are base keys, and the position of
        a key among them."""
        if Nn * Nn <= self.dense_limit:  # node-pair tables instead of searching sorted keys
            # O(P) de-duplication on lazily zeroed node-pair tables (no O(Nn^2) scan): the
            # pair-only keys are those not in the base pattern, first occurrences kept
            mark, first, lookup = self._tables(pattern, Nn)
            mark[bkeys] = 1
            extra = nkey[mark[nkey] == 0]
            mark[bkeys] = 0  # all zero again for the next union on these tables
            rank = np.arange(extra.size, dtype=np.int32)
            first[extra] = rank  # one of the repeated writes wins: exactly one copy matches
            extra = np.sort(extra[first[extra] == rank])
            keys = np.concatenate([bkeys, extra])
            order = np.argsort(keys, kind="stable")
            keys = keys[order]
            lookup[keys] = np.arange(keys.size, dtype=np.int32)  # only entries written here are read
            return keys, order < bkeys.size, lambda k: lookup[k]
        ukey = np.unique(nkey)
        pos = np.minimum(np.searchsorted(bkeys, ukey), bkeys.size - 1)
        keys = np.concatenate([bkeys, ukey[bkeys[pos] != ukey]])
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        return keys, order < bkeys.size, lambda k: np.searchsorted(keys, k)

    #: the node-pair tables are kept on the element pattern (reused by every rebuild of the
    #: union: their pages are touched once, not at every rebuild; a line profile at 30
    #: el/fibril put half of a union build in the first-touch page faults of the lookup) while
    #: n_nodes^2 <= this (9 bytes per node pair: 55 MB at 30 el/fibril); beyond, fresh per build
    keep_tables_limit = 2 ** 23

    @classmethod
    def _tables(cls, pattern, Nn: int):
        """``(mark, first, lookup)`` node-pair tables of length Nn^2: ``mark`` all zero (the
        caller leaves it so), the others scratch (every entry read is written first). Not
        shared between threads: a pattern belongs to one system."""
        size = Nn * Nn
        if size > cls.keep_tables_limit:
            return np.zeros(size, np.int8), np.empty(size, np.int32), np.empty(size, np.int32)
        tables = pattern.__dict__.get("_union_tables")
        if tables is None or tables[0].size != size:
            tables = (np.zeros(size, np.int8), np.empty(size, np.int32), np.empty(size, np.int32))
            pattern._union_tables = tables
        return tables

    def csr(self, data) -> sp.csr_matrix:
        """Union ``data`` as a CSR matrix sharing the union's index arrays (a shallow copy of
        a template: no structure validation per call, and every matrix on the union has the
        very same ``indices``/``indptr`` objects, which solvers compare by identity first)."""
        import copy

        if self._template is None:
            self._template = sp.csr_matrix((np.zeros(self.nnz), self.indices, self.indptr), shape=(self.n, self.n))
            self.indices, self.indptr = self._template.indices, self._template.indptr
        if self.keep is not None:   # ``restrict``: the kept entries' own index arrays
            A = copy.copy(self._kept_template)
            A.data = np.asarray(data, dtype=float)[self.keep]
            return A
        A = copy.copy(self._template)
        A.data = np.asarray(data, dtype=float)
        return A

    def positions(self, A) -> np.ndarray:
        """Positions of the entries of CSR ``A`` (on the pattern or any sub-structure of the
        union) in the union data array (cached per structure)."""
        pat = self.pattern
        if A.indptr is pat.indptr or (
                A.nnz == pat.nnz and np.array_equal(A.indptr, pat.indptr) and np.array_equal(A.indices, pat.indices)):
            return self.base_map
        key = (A.nnz, hash(A.indptr.tobytes()), hash(A.indices.tobytes()))
        mp = self._matcache.get(key)
        if mp is None:
            rows = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(A.indptr))
            k = rows * self.n + A.indices
            if self._keys is None:
                self._keys = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.indptr)) * self.n + self.indices
            uk = self._keys
            ix = _index_kernels()
            mp, ok = ix.sorted_positions(uk, k) if ix is not None and uk.size else (None, False)
            if not ok:
                mp = np.searchsorted(uk, k)
            if np.any(uk[np.minimum(mp, self.nnz - 1)] != k):
                raise ValueError("a matrix has entries outside the union pattern")
            if len(self._matcache) > 8:
                self._matcache.clear()
            self._matcache[key] = mp
        return mp

    def add(self, data, A):
        """``data[union positions of A] += A.data`` (A on the pattern or the union structure)."""
        if A is None:
            return data
        A = A if isinstance(A, sp.csr_matrix) else sp.csr_matrix(A)
        if A.nnz:
            if not A.has_canonical_format:
                A = A.copy()
                A.sum_duplicates()
            data[self.positions(A)] += A.data
        return data

    def pair_data(self, act, K, A=None) -> np.ndarray:
        """``add(np.bincount(slots[act].ravel(), weights=K.ravel(), minlength=nnz), A)``: the
        pair elements ``act`` (indices) with their matrices ``K`` (len(act), (m nC)^2 entries
        each) and then ``A`` on the union, in one compiled pass when ``A`` lies on the base
        pattern (the same sums in the same order; rve.kernels.index.scatter_sum)."""
        ix = _index_kernels() if np.asarray(act).dtype.kind in "iu" and isinstance(A, sp.csr_matrix) \
            and A.has_canonical_format else None
        if ix is not None and self.positions(A) is self.base_map:
            return ix.scatter_sum(self.nnz, self.slots, act, K, self.base_map, A.data)
        return self.add(np.bincount(self.slots[act].ravel(), weights=np.asarray(K).ravel(), minlength=self.nnz), A)

    def data_of(self, A) -> np.ndarray:
        """A's entries laid out on the union structure (zeros elsewhere)."""
        return self.add(np.zeros(self.nnz), A)
