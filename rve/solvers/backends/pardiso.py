"""PARDISO (Intel MKL) as a factorisation backend, through ctypes: supernodal LDLᵀ of real
symmetric indefinite matrices (``mtype = -2``), LU of real unsymmetric ones
(``symmetric=False``, ``mtype = 11``), and a Cholesky mode (``positive_definite=True``,
``mtype = 2``), the fill-reducing analysis reused per sparsity pattern. The full contract
(pattern policy, fast path, pivoting, threads, why not pypardiso's solver) and the
measurements: docs/engine.md, "The PARDISO backend in full" and "Supernodal backend
(measured)".

Contract
--------
* ``available() -> bool``, ``unavailable_reason() -> str``, ``mkl_library() -> str``: MKL
  is found on first use (never at import).
* ``PardisoFactorization(threads=1, matching=True, drop_zeros=True, refinement=0,
  check=False, ordering=2, reuse_subpattern=True, grow_limit=1.25, analyse_stored=False,
  symmetric=True, cnr=0, positive_definite=False)``: ``analyse(A)`` (phase 11), ``factorize(A,
  inertia=False)`` (phase 22, the analysis reused while the nonzero pattern lies in the
  analysed one), ``solve(b)`` (phase 33), ``negative_pivots`` / ``positive_pivots``
  (symmetric mode only), ``perturbed_pivots``, ``factor_nnz``, ``memory_kb``, the counters
  ``analyses``, ``factorizations``, ``solves``, ``subpattern_reuses``, ``stored_fast``;
  ``unsymmetric()`` and ``cholesky()`` companions of a symmetric instance; ``release()``
  (phase -1, also in ``__del__``).
* ``PardisoError`` (a ``RuntimeError``) on an MKL error code;
  ``NotPositiveDefiniteError`` from the Cholesky mode at the first pivot <= 0;
  ``SingularFactorError`` on a zero pivot.
"""
from __future__ import annotations

import ctypes
import logging
import platform
from typing import Optional

import numpy as np
import scipy.sparse as sp

from ...kernels import index_kernels as _index_kernels
from .base import NotPositiveDefiniteError, SingularFactorError
from .base import same_structure as _same_structure

__all__ = ["available", "unavailable_reason", "PardisoFactorization", "PardisoError", "mkl_library"]

log = logging.getLogger("rve.solvers.backends.pardiso")

#: MKL_DOMAIN_PARDISO of mkl_types.h
_MKL_DOMAIN_PARDISO = 4

_ERRORS = {
    -1: "input inconsistent", -2: "not enough memory", -3: "reordering problem",
    -4: "zero pivot, numerical factorization or iterative refinement problem",
    -5: "unclassified (internal) error", -6: "reordering failed", -7: "diagonal matrix is singular",
    -8: "32-bit integer overflow", -9: "not enough memory for out-of-core", -10: "error opening OOC files",
    -11: "read/write error with OOC files", -12: "pardiso_64 called from 32-bit library",
    -13: "interrupted", -15: "internal error",
}

_LIB = None          # (CDLL, pardiso function) once loaded
_REASON: Optional[str] = None


class PardisoError(RuntimeError):
    """PARDISO returned a non-zero error code."""

    def __init__(self, code: int, phase: int):
        self.code, self.phase = int(code), int(phase)
        super().__init__(f"PARDISO phase {phase} failed with error {code}: {_ERRORS.get(code, 'unknown')}")


def _mkl_rt_direct() -> str:
    """``mkl_rt`` where the MKL wheel puts it (``$PYPARDISO_MKL_RT``, else
    ``sys.prefix/lib/libmkl_rt.so*`` / ``.dylib`` / ``Library/bin/mkl_rt*.dll``), "" if not
    there. pypardiso's own search (``find_library``, which runs ldconfig/gcc, then a
    recursive glob of the whole environment) took 7 s of a 12-element relaxation on the
    loaded machine; this is the fast path, pypardiso's search the fallback."""
    import glob
    import os
    import sys

    env = os.environ.get("PYPARDISO_MKL_RT")
    if env:
        return env
    for pat in ("lib/libmkl_rt.so*", "lib/libmkl_rt*.dylib", "Library/bin/mkl_rt*.dll"):
        hits = sorted(glob.glob(os.path.join(sys.prefix, pat)), key=len)
        if hits:
            return hits[0]
    return ""


def _load():
    """Find mkl_rt the way pypardiso does and bind ``pardiso``; sets the reason on failure."""
    global _LIB, _REASON
    if _LIB is not None or _REASON is not None:
        return _LIB
    if platform.machine().lower() not in ("x86_64", "amd64", "i386", "i686", "x86"):
        _REASON = f"no MKL on {platform.machine()} (MKL is x86 only)"
        return None
    import importlib.util

    if importlib.util.find_spec("pypardiso") is None:
        _REASON = "pypardiso not importable: No module named 'pypardiso'"
        return None
    try:
        path = _mkl_rt_direct()
        if not path:  # pypardiso's own search (slow: find_library, a recursive glob)
            from pypardiso.pardiso_wrapper import PyPardisoSolver

            path = PyPardisoSolver().libmkl._name
    except Exception as exc:  # ImportError, or MKL missing at pypardiso's import
        _REASON = f"pypardiso not importable: {exc}"
        return None
    try:
        lib = ctypes.CDLL(path)  # a fresh CDLL object: our own function prototypes
        fn = lib.pardiso
    except Exception as exc:
        _REASON = f"mkl_rt not loadable: {exc}"
        return None
    i32p = ctypes.POINTER(ctypes.c_int32)
    fn.argtypes = [ctypes.c_void_p, i32p, i32p, i32p, i32p, i32p, ctypes.c_void_p, ctypes.c_void_p,
                   ctypes.c_void_p, ctypes.c_void_p, i32p, ctypes.c_void_p, i32p, ctypes.c_void_p,
                   ctypes.c_void_p, i32p]
    fn.restype = None
    try:
        lib.MKL_Domain_Set_Num_Threads.argtypes = [ctypes.c_int, ctypes.c_int]
        lib.MKL_Domain_Set_Num_Threads.restype = ctypes.c_int
    except AttributeError:
        pass
    _LIB = (lib, fn)
    return _LIB


def available() -> bool:
    """True when MKL's PARDISO can be called (see ``unavailable_reason`` otherwise)."""
    return _load() is not None


def unavailable_reason() -> str:
    """Why ``available()`` is False ("" when it is True)."""
    _load()
    return _REASON or ""


def mkl_library() -> str:
    """Path of the mkl_rt library in use ("" when unavailable)."""
    lib = _load()
    return "" if lib is None else lib[0]._name


def _sorted_unique(keys):
    """Sorted unique int64 keys (a sort and a mask: NumPy 2's hash-based ``np.unique`` was
    measured 10x slower on these ~10^5-10^6 keys). The keys come as a few sorted runs (the
    entries of a canonical matrix, the diagonal, the old pattern): timsort (``stable``) merges
    them in linear time where quicksort sorted them afresh (1.4 s of a 30-element
    relaxation's profile, docs/engine.md "The pattern bookkeeping")."""
    k = np.sort(keys, kind="stable")
    if k.size:
        k = k[np.concatenate(([True], k[1:] != k[:-1]))]
    return k


def _upper_entries(A):
    """``(keys, positions)`` of the upper-triangle entries of the canonical square CSR
    matrix ``A`` (CSC: of Aᵀ, the same pattern for a symmetric matrix): sorted keys
    ``row * n + col`` and their positions in ``A.data``."""
    n = A.shape[0]
    ix = _index_kernels()
    if ix is not None:
        return ix.upper_entries(A.indptr, A.indices, n)
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(A.indptr))
    cols = A.indices.astype(np.int64)
    keep = np.flatnonzero(cols >= rows)
    return rows[keep] * n + cols[keep], keep


def _clipped_positions(ak, keys):
    """``np.minimum(np.searchsorted(ak, keys), ak.size - 1)`` for sorted ``ak`` (non-empty):
    one merge pass when ``keys`` is sorted too and the compiled kernels are in use."""
    ix = _index_kernels()
    if ix is not None:
        pos, ok = ix.sorted_positions(ak, keys)
        if ok:
            return pos
    return np.minimum(np.searchsorted(ak, keys), ak.size - 1)


def _full_entries(A):
    """``(keys, positions)`` of all entries of the canonical square CSR or CSC matrix ``A``
    in its true orientation: keys ``row * n + col`` (sorted for CSR, column-major for CSC)
    and their positions in ``A.data``."""
    n = A.shape[0]
    major = np.repeat(np.arange(n, dtype=np.int64), np.diff(A.indptr))
    minor = A.indices.astype(np.int64)
    keys = major * n + minor if A.format == "csr" else minor * n + major
    return keys, np.arange(keys.size, dtype=np.int64)


class PardisoFactorization:
    """MKL PARDISO of a real sparse matrix: LDLᵀ of a symmetric indefinite one
    (``symmetric=True``, mtype -2) or LU of an unsymmetric one (``symmetric=False``,
    mtype 11); module docstring."""

    name = "pardiso"
    provides_inertia = True
    reuses_analysis = True

    def __init__(self, threads: Optional[int] = 1, matching: bool = True, drop_zeros: bool = True,
                 refinement: int = 0, check: bool = False, ordering: int = 2,
                 reuse_subpattern: bool = True, grow_limit: float = 1.25, analyse_stored: bool = False,
                 symmetric: bool = True, cnr: int = 0, positive_definite: bool = False):
        lib = _load()
        if lib is None:
            raise RuntimeError(f"PARDISO is not available: {_REASON}")
        self._lib, self._fn = lib
        self.threads = None if threads is None else int(threads)
        self.symmetric = bool(symmetric)
        self.positive_definite = bool(positive_definite)
        if self.positive_definite and not self.symmetric:
            raise ValueError("positive_definite=True needs symmetric=True (Cholesky of a symmetric matrix)")
        self.mtype = (2 if self.positive_definite else -2) if self.symmetric else 11
        self.provides_inertia = self.symmetric
        if not self.symmetric:
            self.name = "pardiso_unsym"
        elif self.positive_definite:
            self.name = "pardiso_spd"
            matching = False             # no pivoting in a Cholesky: nothing to match or scale for
        self._entries = _upper_entries if self.symmetric else _full_entries
        self._options = dict(threads=threads, matching=matching, drop_zeros=drop_zeros, refinement=refinement,
                             check=check, ordering=ordering, reuse_subpattern=reuse_subpattern,
                             grow_limit=grow_limit, analyse_stored=analyse_stored, cnr=cnr)
        self._unsym = None               # the mtype-11 companion (``unsymmetric()``)
        self._spd = None                 # the mtype-2 companion (``cholesky()``)
        self.pt = np.zeros(64, dtype=np.int64)  # PARDISO's internal handle (opaque pointers)
        self.iparm = np.zeros(64, dtype=np.int32)
        ip = self.iparm
        ip[0] = 1                        # iparm(1): no solver defaults, all set here
        ip[1] = int(ordering)            # iparm(2): 2 = METIS nested dissection, 0 = minimum degree
        ip[7] = int(refinement)          # iparm(8): max iterative refinement steps (0: auto, 2 if perturbed)
        ip[9] = 8 if self.symmetric else 13  # iparm(10): pivot perturbation 1e-8 (-2) / 1e-13 (11)
        ip[10] = 1 if matching else 0    # iparm(11): scaling
        ip[12] = 1 if matching else 0    # iparm(13): (symmetric / nonsymmetric) weighted matching
        ip[17] = -1                      # iparm(18): report factor nonzeros
        ip[20] = 1 if self.mtype == -2 else 0  # iparm(21): Bunch-Kaufman 1x1 and 2x2 pivoting (mtype -2 only)
        ip[23] = 0                       # iparm(24): classic factorisation (one thread)
        ip[26] = 1 if check else 0       # iparm(27): matrix checker
        ip[33] = int(cnr)                # iparm(34): CNR mode for up to this many threads (0: off)
        ip[34] = 1                       # iparm(35): zero-based indices
        self.matching = bool(matching)
        self.drop_zeros = bool(drop_zeros)
        self.reuse_subpattern = bool(reuse_subpattern)
        self.grow_limit = float(grow_limit)
        self.analyse_stored = bool(analyse_stored)
        self._stored = None
        self.n = 0
        self._pattern = None             # (shape, indptr, indices) of the input the plan maps
        self._plan = None                # (indptr, indices, src, n_missing) of the analysed upper pattern
        self._keys = None                # sorted keys row * n + col of the analysed upper pattern
        self.subpattern_reuses = 0
        self._stored_fast = None         # (format, indptr, indices, src, has_missing, outside, analyses) of a stored structure
        self.stored_fast = 0             # factorisations that took that fast path
        self._a = None                   # values handed to PARDISO (kept alive for phase 33)
        self._factored = False
        self._alive = False
        self.analyses = self.factorizations = self.solves = 0
        self.indefinite = 0              # Cholesky factorisations stopped at a pivot <= 0 (mtype 2)
        self.refinement_steps = 0
        self.inserted_diagonal = 0

    # ------------------------------------------------------------------ helpers
    def _call(self, phase: int, a=None, b=None, x=None, nrhs: int = 1) -> None:
        if self.threads is not None:
            try:
                self._lib.MKL_Domain_Set_Num_Threads(self.threads, _MKL_DOMAIN_PARDISO)
            except AttributeError:
                pass
        i32 = ctypes.c_int32
        err = i32(0)
        if self._plan is not None:
            ia, ja = self._plan[0], self._plan[1]
        else:
            ia = ja = np.zeros(1, dtype=np.int32)
        dummy = np.zeros(1)
        ptr = lambda v: (dummy if v is None else v).ctypes.data  # noqa: E731
        self._fn(self.pt.ctypes.data, ctypes.byref(i32(1)), ctypes.byref(i32(1)), ctypes.byref(i32(self.mtype)),
                 ctypes.byref(i32(phase)), ctypes.byref(i32(self.n)), ptr(a if a is not None else self._a),
                 ia.ctypes.data, ja.ctypes.data, ctypes.c_void_p(None), ctypes.byref(i32(nrhs)),
                 self.iparm.ctypes.data, ctypes.byref(i32(0)), ptr(b), ptr(x), ctypes.byref(err))
        if err.value != 0:
            raise PardisoError(err.value, phase)

    def _canonical(self, A):
        if not sp.issparse(A):
            raise TypeError(f"PARDISO needs a scipy sparse matrix, got {type(A).__name__}")
        if A.format not in ("csr", "csc"):
            A = A.tocsr()
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"matrix must be square, got shape {A.shape}")
        if not A.has_canonical_format:
            A = A.copy()
            A.sum_duplicates()
        self._stored = A                 # the stored pattern (analyse_stored)
        if self.drop_zeros and A.nnz and not np.all(A.data):
            A = A.copy()
            A.eliminate_zeros()
        return A

    def _same_pattern(self, A) -> bool:
        p = self._pattern
        if p is None or p[0] != A.shape:
            return False
        return ((A.indptr is p[1] or np.array_equal(A.indptr, p[1]))
                and (A.indices is p[2] or np.array_equal(A.indices, p[2])))

    def _values(self, A):
        src = self._plan[2]
        if self._plan[3]:
            a = np.where(src >= 0, A.data[np.maximum(src, 0)], 0.0)
        else:
            a = A.data[src]
        return np.ascontiguousarray(a, dtype=np.float64)

    def _set_map(self, A, src) -> None:
        """Map the analysed pattern onto the arrays of ``A`` (src = -1: a zero there)."""
        self._plan = (self._plan[0], self._plan[1], src, int(np.count_nonzero(src < 0)))
        self._pattern = (A.shape, A.indptr.copy(), A.indices.copy())

    def _map(self, A, keys, keep):
        """``src`` of ``A`` on the analysed pattern, or None when an entry of ``A`` is not in it."""
        ak = self._keys
        pos = _clipped_positions(ak, keys)
        if not np.array_equal(ak[pos], keys):
            return None
        src = np.full(ak.size, -1, dtype=np.int64)
        src[pos] = keep
        return src

    def _remember_stored(self) -> None:
        """Map the stored structure of the matrix just factorised onto the analysed pattern
        (the fast path of the next ``factorize`` with that structure): ``src`` for its
        entries in the analysed pattern and ``outside``, the positions of those that are not
        there (the candidate pairs of a rebuilt contact map the analysis has not seen: a
        call takes the fast path while they hold explicit zeros)."""
        S, old = self._stored, self._stored_fast
        if S is None or S.shape[0] != self.n or not (self.drop_zeros and self.reuse_subpattern):
            self._stored_fast = None
            return
        if (old is not None and old[6] == self.analyses and S.format == old[0]
                and _same_structure(S, old[1], old[2])):
            return  # already mapped onto this analysis
        keys, keep = self._entries(S)
        ak = self._keys
        pos = _clipped_positions(ak, keys)
        inside = ak[pos] == keys
        src = np.full(ak.size, -1, dtype=np.int64)
        src[pos[inside]] = keep[inside]
        self._stored_fast = (S.format, S.indptr, S.indices, src, bool(np.any(src < 0)), keep[~inside],
                             self.analyses)

    # ------------------------------------------------------------------ interface
    def analyse(self, A, _extra_keys=None) -> "PardisoFactorization":
        """Phase 11 on the pattern (and, with ``matching``, the values) of ``A`` (every
        diagonal entry included; ``_extra_keys``: more upper-triangle entries, as zeros)."""
        A = self._canonical(A)
        if self._alive:
            self.release()
        n = self.n = int(A.shape[0])
        keys, keep = self._entries(A)
        diag = np.arange(n, dtype=np.int64) * (n + 1)
        self.inserted_diagonal = int(n - np.count_nonzero(np.isin(diag, keys, assume_unique=True)))
        parts = [keys, diag] + ([] if _extra_keys is None else [_extra_keys])
        ukeys = _sorted_unique(np.concatenate(parts))
        indptr = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(np.bincount(ukeys // n, minlength=n), out=indptr[1:])
        self._keys = ukeys
        self._plan = (indptr, np.ascontiguousarray(ukeys % n, dtype=np.int32), None, 0)
        self._set_map(A, self._map(A, keys, keep))
        self._a = self._values(A)
        self._factored = False
        self._alive = True
        self._call(11)
        self.analyses += 1
        return self

    def factorize(self, A, inertia: bool = False) -> "PardisoFactorization":
        """Phase 22 of ``A``, reusing the analysis when ``A``'s pattern is the analysed one
        or (``reuse_subpattern``) lies in it (the missing entries factorised as zeros);
        otherwise phase 11 first, on the union of the two patterns when that is at most
        ``grow_limit`` times ``A``'s (contacts that come and go then stop costing
        analyses), else on ``A``'s; with ``analyse_stored`` on ``A``'s stored pattern
        (explicit zeros included) instead. The inertia counts are always there; ``inertia=True``
        (the layer's contract: a zero pivot raises) raises
        ``rve.solvers.linear.SingularFactorError`` when a pivot was perturbed (a
        near-singular matrix; the factorisation stays usable). A non-finite entry raises
        ``SingularFactorError`` too."""
        if inertia and not self.symmetric:
            raise ValueError("pardiso_unsym (mtype 11, LU) gives no inertia")
        fast = self._stored_fast
        if (self._alive and self.drop_zeros and self.reuse_subpattern and sp.issparse(A)
                and A.format in ("csr", "csc") and A.shape == (self.n, self.n) and A.has_canonical_format
                and not (fast is not None and fast[6] == self.analyses and A.format == fast[0]
                         and _same_structure(A, fast[1], fast[2]))):
            # a new stored structure (a rebuilt contact map): map it onto the analysis once;
            # its nonzeros then either lie there (the fast path below) or they do not (a new
            # analysis in the general path)
            self._stored = A
            self._remember_stored()
            fast = self._stored_fast
        if (fast is not None and self._alive and sp.issparse(A) and A.format == fast[0]
                and A.shape == (self.n, self.n) and fast[6] == self.analyses and _same_structure(A, fast[1], fast[2])
                and not (fast[5].size and np.any(A.data[fast[5]]))):
            # the stored structure of the last call, its nonzeros in the analysed pattern (the
            # entries outside it are explicit zeros): its values go straight onto the analysed
            # pattern (its explicit zeros are the zeros the nonzero pattern would leave
            # there): the same numbers as the general path
            if not np.all(np.isfinite(A.data)):
                self._factored = False
                raise SingularFactorError("non-finite matrix entry")
            self._stored = A
            src = fast[3]
            self._a = np.where(src >= 0, A.data[np.maximum(src, 0)], 0.0) if fast[4] else A.data[src]
            self.stored_fast += 1
            self._phase22()
            if inertia and self.perturbed_pivots:
                raise SingularFactorError(f"{self.perturbed_pivots} pivot(s) perturbed (near-singular matrix): "
                                          "the inertia is not SuperLU's")
            return self
        A = self._canonical(A)
        if not np.all(np.isfinite(A.data)):
            self._factored = False
            raise SingularFactorError("non-finite matrix entry")
        if not (self._alive and self._same_pattern(A)):
            src = None
            if self._alive and self.reuse_subpattern and A.shape[0] == self.n:
                keys, keep = self._entries(A)
                ak = self._keys
                pos = _clipped_positions(ak, keys)
                n_new = int(np.count_nonzero(ak[pos] != keys))
                if n_new == 0:
                    src = np.full(ak.size, -1, dtype=np.int64)
                    src[pos] = keep
                    self._set_map(A, src)
                    self.subpattern_reuses += 1
                elif self.analyse_stored and self._stored is not None and self._stored.nnz > A.nnz:
                    # analyse the stored pattern (explicit zeros included: e.g. the contact
                    # map's candidate pairs) so that later nonzero patterns lie in it
                    self.analyse(A, _extra_keys=self._entries(self._stored)[0])
                    src = True
                else:
                    grow = ak.size + n_new <= self.grow_limit * (keys.size + self.n)
                    self.analyse(A, _extra_keys=ak if grow else None)
                    src = True
            if src is None:
                stored = self._stored if self.analyse_stored and self._stored.nnz > A.nnz else None
                self.analyse(A, _extra_keys=None if stored is None else self._entries(stored)[0])
        self._a = self._values(A)
        try:
            self._phase22()
        finally:
            self._remember_stored()  # a failed Cholesky keeps the fast path for the next shift
        if inertia and self.perturbed_pivots:
            raise SingularFactorError(f"{self.perturbed_pivots} pivot(s) perturbed (near-singular matrix): "
                                      "the inertia is not SuperLU's")
        return self

    def _phase22(self) -> None:
        """The numeric factorisation of the values in ``self._a``. Cholesky (mtype 2) stops
        at the first pivot that is not positive with error -4: raised as
        ``NotPositiveDefiniteError`` (benchmarks/engine_speed.py ``pardiso_chol_t2``: on the
        12-element minimiser's first matrix, 739 negative eigenvalues, 1 ms against 8 ms for
        the LDL^T)."""
        self._factored = False
        self.factorizations += 1
        try:
            self._call(22)
        except PardisoError as exc:
            if self.mtype == 2 and exc.code == -4:
                self.indefinite += 1
                raise NotPositiveDefiniteError("PARDISO Cholesky met a pivot <= 0: the matrix is not positive "
                                               "definite") from exc
            raise
        self._factored = True

    def solve(self, b) -> np.ndarray:
        """Phase 33: x with A x = b for b of shape (n,) or (n, k)."""
        if not self._factored:
            raise RuntimeError("solve before factorize")
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.n:
            raise ValueError(f"right-hand side has {b.shape[0]} rows, the matrix {self.n}")
        bf = np.asfortranarray(b)
        x = np.zeros_like(bf, order="F")
        self._call(33, b=bf, x=x, nrhs=1 if b.ndim == 1 else int(b.shape[1]))
        self.solves += 1
        self.refinement_steps = int(self.iparm[6])
        return np.ascontiguousarray(x)

    def _no_inertia(self) -> None:
        if not self.symmetric:
            raise ValueError("pardiso_unsym (mtype 11, LU of an unsymmetric matrix) gives no inertia")
        if not self._factored:
            raise RuntimeError("no factorisation")

    @property
    def negative_pivots(self) -> int:
        """iparm(23): negative eigenvalues of the last factorised matrix (symmetric mode;
        0 after a Cholesky, which only succeeds on a positive definite matrix; ``ValueError``
        for mtype 11, whose pivots say nothing about eigenvalues)."""
        self._no_inertia()
        return 0 if self.positive_definite else int(self.iparm[22])

    @property
    def positive_pivots(self) -> int:
        """iparm(22): positive eigenvalues of the last factorised matrix (symmetric mode)."""
        self._no_inertia()
        return self.n if self.positive_definite else int(self.iparm[21])

    @property
    def perturbed_pivots(self) -> int:
        """iparm(14): pivots perturbed by the last factorisation."""
        return int(self.iparm[13])

    @property
    def factor_nnz(self) -> int:
        """iparm(18): nonzeros of the factor L (incl. its diagonal)."""
        return int(self.iparm[17])

    @property
    def memory_kb(self) -> dict:
        """PARDISO's memory: peak of the analysis and permanent + factorisation (KiB)."""
        return {"analysis_peak": int(self.iparm[14]), "factorization": int(self.iparm[15]) + int(self.iparm[16])}

    def stats(self) -> dict:
        return {"analyses": self.analyses, "factorizations": self.factorizations, "solves": self.solves,
                "indefinite": self.indefinite,
                "subpattern_reuses": self.subpattern_reuses, "stored_fast": self.stored_fast,
                "negative_pivots": (0 if self.positive_definite else int(self.iparm[22])) if self.symmetric else None, "perturbed_pivots": self.perturbed_pivots,
                "refinement_steps": self.refinement_steps, "factor_nnz": self.factor_nnz, **self.memory_kb}

    def unsymmetric(self) -> "PardisoFactorization":
        """The mtype-11 companion of a symmetric instance (created on the first call with
        the same options, then kept: its analysis is reused across the calls); ``self``
        when this instance is already unsymmetric. ``release`` frees it too."""
        if not self.symmetric:
            return self
        if self._unsym is None:
            self._unsym = PardisoFactorization(symmetric=False, **self._options)
        return self._unsym

    @property
    def total_analyses(self) -> int:
        """Analyses of this instance and of its companions (``unsymmetric``, ``cholesky``)."""
        return self.analyses + sum(c.analyses for c in (self._unsym, self._spd) if c is not None)

    def cholesky(self) -> "PardisoFactorization":
        """The mtype-2 (Cholesky) companion of a symmetric instance, with the same options
        (threads, CNR, pattern policy; no matching), created on the first call and kept so
        its analysis is reused; ``self`` when this instance is one. Its ``factorize`` raises
        ``NotPositiveDefiniteError`` at the first pivot <= 0: the energy minimiser's
        definiteness test (``rve.solvers.linear.factor_positive_definite``)."""
        if self.positive_definite:
            return self
        if not self.symmetric:
            raise ValueError("pardiso_unsym has no Cholesky companion (the matrix is not symmetric)")
        if self._spd is None:
            self._spd = PardisoFactorization(positive_definite=True, **self._options)
        return self._spd

    def release(self) -> None:
        """Phase -1: free all of this instance's MKL memory (and its companions')."""
        for comp in (getattr(self, "_unsym", None), getattr(self, "_spd", None)):
            if comp is not None:
                comp.release()
        if self._alive:
            self._alive = False
            self._factored = False
            try:
                self._call(-1)
            except PardisoError as exc:  # pragma: no cover
                log.warning("PARDISO release failed: %s", exc)
        self._pattern = None
        self._keys = None
        self._stored_fast = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    def __del__(self):
        try:
            self.release()
        except Exception:  # interpreter shutdown
            pass
