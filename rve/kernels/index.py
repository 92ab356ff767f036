"""Compiled index kernels of the sparse structures (docs/kernels.md "Index kernels"): the
lookups and scatters that build a contact map's union pattern, put its matrices together
and map them onto PARDISO's analysed pattern.

Contract
--------
Every function returns exactly the integers (and, for the scatter, exactly the floating-
point sums, added in the same order) of the numpy expression named in its docstring:
they are pure speed-ups, never a change of arithmetic (tests/test_kernels.py compares
them with ``==``). Integer arrays are int64 unless stated; the callers
(``rve.fem.assembly``, ``rve.solvers.backends.pardiso``) take them only when
``rve.kernels.use_numba()`` and keep the numpy expressions as the reference path.

* ``sorted_positions(ref, keys)`` -> ``(pos, ok)``: ``ref`` sorted ascending (non-empty),
  ``keys`` int64. When ``keys`` is sorted ascending, ``ok`` is True and ``pos`` is
  ``np.minimum(np.searchsorted(ref, keys), ref.size - 1)`` (one merge pass, O(n + m));
  otherwise ``ok`` is False and ``pos`` is not to be used.
* ``upper_entries(indptr, indices, n)`` -> ``(keys, keep)``: the upper-triangle entries
  (col >= row) of a CSR structure: ``keys = row * n + col`` and their positions in the
  data array (``rve.solvers.backends.pardiso._upper_entries``).
* ``scatter_sum(nnz, slots, act, w, base_map, fx)`` -> ``out`` (nnz,) float64:
  ``out = np.bincount(slots[act].ravel(), weights=w.ravel(), minlength=nnz)`` followed by
  ``out[base_map] += fx`` (``base_map`` without repeats): the contact pairs' tangent and
  the elements' matrix on a union pattern, summed in that order.
* ``row_gather(Q, src, rowlen, indptr, out)``: ``out[indptr[r] + k] = Q[src[r] + k]`` for
  ``k < rowlen[r]`` (``Q[np.arange(total) + np.repeat(src - indptr[:-1], rowlen)]``).
* ``union_slots(rowstart, offc, mp, isbase, ci, out)``: ``out[p, i, c, j, c'] =
  rowstart[p, i, c] + offc[mp[p, i, j]] + (ci[c'] if isbase[mp[p, i, j]] else c')``
  (the pair elements' positions in a union's data array).
* ``union_columns(nodeJ, isbase, b, ci, Qc, Qo)``: the column patterns of the pair-component
  rows (``Qc``: b columns of a base block, ``ci`` of a pair-only one) and of the other rows
  (``Qo``: the base blocks only), in key order.
* ``copy_rows(src_indptr, src_indices, indptr, indices)`` -> ``pos``, ``csr_positions(indptr,
  indices, rows, cols)`` -> ``(pos, ok)``, ``rows_increasing(indptr, indices)`` -> bool: the
  impact system's union of the fabric, sphere-pair and projectile entries
  (``rve.model.projectile.ImpactSystem``) without its (nnz,) int64 key array.
* ``gather_axpy(out, data, c, gather)``, ``gather_axpy_masked(out, data, c, mask, indices,
  gather)``: ``out += c * data[gather]`` and ``out += (c * (data * mask[indices]))[gather]``,
  the stage matrix's restricted sum (``rve.solvers.system.FreeDofs.combine``) on the kept
  entries alone, without the (nnz,) temporaries.
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["sorted_positions", "upper_entries", "scatter_sum", "row_gather", "union_slots", "union_columns",
           "copy_rows", "csr_positions", "rows_increasing", "gather_axpy", "gather_axpy_masked"]


@njit(cache=True, nogil=True)
def _merge_positions(ref, keys, pos):
    n = ref.size
    j = 0
    for i in range(keys.size):
        k = keys[i]
        if i and k < keys[i - 1]:
            return False
        while j < n and ref[j] < k:
            j += 1
        pos[i] = j if j < n else n - 1
    return True


def sorted_positions(ref: np.ndarray, keys: np.ndarray):
    pos = np.empty(keys.size, np.int64)
    ok = _merge_positions(ref, keys, pos)
    return pos, bool(ok)


@njit(cache=True, nogil=True)
def _upper_entries(indptr, indices, n):
    m = 0
    for r in range(n):
        for q in range(indptr[r], indptr[r + 1]):
            if indices[q] >= r:
                m += 1
    keys = np.empty(m, np.int64)
    keep = np.empty(m, np.int64)
    m = 0
    for r in range(n):
        for q in range(indptr[r], indptr[r + 1]):
            c = indices[q]
            if c >= r:
                keys[m] = np.int64(r) * n + c
                keep[m] = q
                m += 1
    return keys, keep


def upper_entries(indptr: np.ndarray, indices: np.ndarray, n: int):
    return _upper_entries(indptr, indices, np.int64(n))


@njit(cache=True, nogil=True)
def _scatter_sum(out, slots, act, w, base_map, fx):
    q = slots.shape[1]
    for a in range(act.size):
        row = act[a]
        for k in range(q):
            out[slots[row, k]] += w[a * q + k]
    for e in range(base_map.size):
        out[base_map[e]] += fx[e]


def scatter_sum(nnz: int, slots, act, w, base_map, fx) -> np.ndarray:
    out = np.zeros(int(nnz))
    _scatter_sum(out, slots, np.ascontiguousarray(act, dtype=np.int64), np.ascontiguousarray(w).reshape(-1),
                 base_map, np.ascontiguousarray(fx, dtype=np.float64))
    return out


@njit(cache=True, nogil=True)
def row_gather(Q, src, rowlen, indptr, out):
    for r in range(rowlen.size):
        a, s = indptr[r], src[r]
        for k in range(rowlen[r]):
            out[a + k] = Q[s + k]


@njit(cache=True, nogil=True)
def union_slots(rowstart, offc, mp, isbase, ci, out):
    P, m, nC = rowstart.shape
    for p in range(P):
        for i in range(m):
            for j in range(m):
                e = mp[p, i, j]
                o = offc[e]
                base = isbase[e]
                for c in range(nC):
                    r0 = rowstart[p, i, c] + o
                    for c2 in range(nC):
                        out[p, i, c, j, c2] = r0 + (ci[c2] if base else c2)


@njit(cache=True, nogil=True)
def union_columns(nodeJ, isbase, b, ci, Qc, Qo):
    qc = 0
    qo = 0
    nC = ci.size
    for e in range(nodeJ.size):
        j0 = nodeJ[e] * b
        if isbase[e]:
            for c in range(b):
                Qc[qc + c] = j0 + c
                Qo[qo + c] = j0 + c
            qc += b
            qo += b
        else:
            for c in range(nC):
                Qc[qc + c] = j0 + ci[c]
            qc += nC


@njit(cache=True, nogil=True)
def _copy_rows(src_indptr, src_indices, indptr, indices, pos):
    for r in range(src_indptr.size - 1):
        a, b = src_indptr[r], src_indptr[r + 1]
        s = indptr[r] - a
        for k in range(a, b):
            pos[k] = s + k
            indices[s + k] = src_indices[k]


def copy_rows(src_indptr, src_indices, indptr, indices) -> np.ndarray:
    """The rows of a CSR structure (``src_indptr``, ``src_indices``) copied to the start of
    the same rows of a larger one (``indptr``: every row at least as long), returning their
    positions there: ``pos = np.arange(nnz) + (indptr[:m] - src_indptr[:m])[rows]`` (rows the
    row of every source entry, m the source's rows) and ``indices[pos] = src_indices``."""
    pos = np.empty(int(src_indptr[-1]), np.int64)
    _copy_rows(np.asarray(src_indptr, np.int64), src_indices, np.asarray(indptr, np.int64), indices, pos)
    return pos


@njit(cache=True, nogil=True)
def _csr_positions(indptr, indices, rows, cols, pos):
    for k in range(rows.size):
        r, c = rows[k], cols[k]
        lo, hi = indptr[r], indptr[r + 1]
        while lo < hi:
            mid = (lo + hi) // 2
            if indices[mid] < c:
                lo = mid + 1
            else:
                hi = mid
        if lo >= indptr[r + 1] or indices[lo] != c:
            return False
        pos[k] = lo
    return True


def csr_positions(indptr, indices, rows, cols):
    """``(pos, ok)``: the positions of the entries (rows, cols) in a CSR structure whose rows
    are sorted without repeats; ``ok`` False when one of them is not in it (``pos`` then not
    to be used). The same integers as ``np.searchsorted(keys, rows * n + cols)`` with
    ``keys = row * n + col`` of every stored entry (sorted: row-major)."""
    rows = np.ascontiguousarray(rows, np.int64)
    pos = np.empty(rows.size, np.int64)
    ok = _csr_positions(np.asarray(indptr, np.int64), indices, rows, np.ascontiguousarray(cols, np.int64), pos)
    return pos, bool(ok)


@njit(cache=True, nogil=True)
def rows_increasing(indptr, indices) -> bool:
    """True when every row of a CSR structure has strictly increasing columns
    (``np.all(np.diff(row * n + col) > 0)`` of the entries)."""
    for r in range(indptr.size - 1):
        for k in range(indptr[r] + 1, indptr[r + 1]):
            if indices[k] <= indices[k - 1]:
                return False
    return True


@njit(cache=True, nogil=True)
def gather_axpy(out, data, c, gather):
    """``out += c * data[gather]`` (the same products and sums, entry by entry)."""
    for j in range(gather.size):
        out[j] += c * data[gather[j]]


@njit(cache=True, nogil=True)
def gather_axpy_masked(out, data, c, mask, indices, gather):
    """``out += (c * (data * mask[indices]))[gather]`` (the same products and sums, entry by
    entry, for the gathered entries only)."""
    for j in range(gather.size):
        g = gather[j]
        out[j] += c * (data[g] * mask[indices[g]])
