"""SuperLU on the *nonzero* pattern with a Schur-complement border: the stage-matrix
backend of the impact scene (docs/impact.md "Cost").

Contract
--------
``PrunedSuperLU(symmetric=True, border=0)``: a ``LinearBackend`` (registry name
``"superlu_pruned"``, border 0; a scene that needs a border passes
``functools.partial(PrunedSuperLU, border=k)`` as the integrator's ``linear_backend``):
drops the explicit zeros of the stage matrix (the inactive candidate contact pairs of both
contact maps, the uncoupled field blocks: 24 % of the stored entries measured on a 16 x 16
impact weave), eliminates the last ``border`` unknowns (the projectile's free dofs) by a
Schur complement, then factorises the rest with SuperLU's minimum-degree ordering of A^T + A and
threshold pivoting (``DiagPivotThresh = 0.01``: diagonal pivots unless one is below 1 % of
its column, so the nearly symmetric but unsymmetric stage matrices of the Lorentz /
back-EMF couplings are factorised stably); a singular pivot falls back to COLAMD with
partial pivoting on the same pruned matrix. Measured (16 x 16 yarns, 40 elements, 12.9k
free dofs): 6.5 s with COLAMD on the stored pattern (the unsymmetric path of the
Newton solver) vs 0.06 s. Full size (51.4k fabric dofs, t = 0.025 ms, row-scaled
as the integrator solves it): threshold 0.1: 10.3 s, fill 23.8M (off-diagonal pivots);
0.01: 0.49 s, fill 3.6M; 0.0: 0.74 s, fill 3.6M.

``PardisoOrPruned(symmetric=False, border=0)`` (registry name ``"auto_pruned"``): PARDISO's
LU of the unsymmetric stage matrix (``rve.solvers.backends.pardiso.PardisoFactorization(symmetric=False)``:
mtype 11, explicit zeros dropped, nonsymmetric matching and scaling, the analysis reused
while the nonzero pattern lies in the analysed one, no Schur border: METIS orders the
projectile's dofs well) where MKL is available, ``PrunedSuperLU`` where it is not and for
a matrix PARDISO fails on (``kind`` says which factorised the last matrix). Measured on the
full-size stage matrices (docs/engine.md "Unsymmetric stage matrices").
"""
from __future__ import annotations

import logging

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .base import SingularFactorError
from .superlu import SuperLUBackend

__all__ = ["PrunedSuperLU", "PardisoOrPruned", "NAME", "NAME_AUTO"]

log = logging.getLogger("rve.solvers.backends.pruned")

NAME = "superlu_pruned"
NAME_AUTO = "auto_pruned"


def _splu(J):
    try:
        return spla.splu(J, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01, options=dict(SymmetricMode=True))
    except RuntimeError:
        try:
            return spla.splu(J, permc_spec="COLAMD")
        except RuntimeError as exc:
            raise SingularFactorError(str(exc)) from exc


class PrunedSuperLU(SuperLUBackend):
    """SuperLU on the nonzero pattern, with the last ``border`` unknowns (the projectile's
    free dofs) eliminated by a Schur complement: J = [[A, B], [C, D]], A (the fabric)
    factorised alone, S = D - C A^-1 B dense (border x border): the projectile's end nodes,
    coupled to every fibril node in sphere contact, stay out of the sparse factor (whose
    elimination of them would join all those nodes in one dense clique)."""

    name = NAME
    provides_inertia = False

    def __init__(self, symmetric: bool = True, border: int = 0):
        super().__init__(symmetric)
        #: unknowns at the end of the (restricted) matrix eliminated by the Schur complement
        self.border = int(border)

    def _factorize(self, A) -> None:
        J = sp.csc_matrix(A, copy=True)
        J.eliminate_zeros()
        k = int(self.border)
        n = J.shape[0]
        self.lu = None
        if k <= 0 or k >= n:
            self._k = 0
            self.lu = _splu(J)
            return
        m = n - k
        Jr = J.tocsr()
        Aff = sp.csc_matrix(Jr[:m][:, :m])
        B = Jr[:m][:, m:].toarray()
        self._C = sp.csr_matrix(Jr[m:][:, :m])
        D = Jr[m:][:, m:].toarray()
        self._lu_f = _splu(Aff)
        self._X = self._lu_f.solve(B) if B.any() else np.zeros_like(B)
        S = D - self._C @ self._X
        try:
            self._S = scipy.linalg.lu_factor(S, check_finite=True)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise SingularFactorError(str(exc)) from exc
        self._k, self._m = k, m
        self.lu = self._lu_f

    def solve(self, b) -> np.ndarray:
        if not self._k:
            return self.lu.solve(b)
        b = np.asarray(b, float)
        m = self._m
        y = self._lu_f.solve(b[:m])
        z = scipy.linalg.lu_solve(self._S, b[m:] - self._C @ y)
        return np.concatenate([y - self._X @ z, z])

    def _pivots(self) -> np.ndarray:  # pragma: no cover - no inertia from this backend
        raise ValueError("superlu_pruned gives no inertia")


class PardisoOrPruned:
    """PARDISO mtype 11 where MKL is available, else (and for a matrix PARDISO fails on)
    ``PrunedSuperLU`` (module docstring). No inertia."""

    name = NAME_AUTO
    provides_inertia = False
    symmetric = False

    def __init__(self, symmetric: bool = False, border: int = 0):
        from . import pardiso

        self.border = int(border)
        self._pardiso = pardiso.PardisoFactorization(symmetric=False) if pardiso.available() else None
        self._pruned = None
        self._active = None
        self.kind = None
        self.fallbacks = 0

    def factorize(self, A, inertia: bool = False) -> "PardisoOrPruned":
        if inertia:
            raise ValueError(f"{NAME_AUTO} gives no inertia")
        self._active = None
        if self._pardiso is not None:
            try:
                self._pardiso.factorize(A)
                self._active, self.kind = self._pardiso, "pardiso_unsym"
                return self
            except RuntimeError as exc:  # PardisoError, SingularFactorError
                self.fallbacks += 1
                log.info("PARDISO mtype 11 failed (%s): superlu_pruned", exc)
        if self._pruned is None:
            self._pruned = PrunedSuperLU(symmetric=False, border=self.border)
        self._pruned.factorize(A)
        self._active, self.kind = self._pruned, NAME
        return self

    def solve(self, b) -> np.ndarray:
        if self._active is None:
            raise RuntimeError("solve before factorize")
        return self._active.solve(b)

    @property
    def negative_pivots(self) -> int:
        raise ValueError(f"{NAME_AUTO} gives no inertia")

    def release(self) -> None:
        if self._pardiso is not None:
            self._pardiso.release()
