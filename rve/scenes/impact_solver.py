"""The linear-solver backend of the impact scene: SuperLU on the *nonzero* pattern
(docs/impact.md "Cost").

Contract
--------
``PrunedSuperLU(symmetric=True)``: a ``rve.solvers.linear.LinearBackend`` (registry name
``"superlu_pruned"``, added by ``register()`` through the public ``register_backend``):
drops the explicit zeros of the stage matrix (the inactive candidate contact pairs of both
contact maps, the uncoupled field blocks: 24 % of the stored entries measured on a 16 x 16
impact weave), eliminates the last ``border`` unknowns (the projectile's free dofs, set by ``register``) by a
Schur complement, then factorises the rest with SuperLU's minimum-degree ordering of A^T + A and
threshold pivoting (``DiagPivotThresh = 0.01``: diagonal pivots unless one is below 1 % of
its column, so the nearly symmetric but unsymmetric stage matrices of the Lorentz /
back-EMF couplings are factorised stably); a singular pivot falls back to COLAMD with
partial pivoting on the same pruned matrix. Measured (16 x 16 yarns, 40 elements, 12.9k
free dofs): 6.5 s with COLAMD on the stored pattern (what the unsymmetric path of the
Newton solver does today) vs 0.06 s. Full size (51.4k fabric dofs, t = 0.025 ms, row-scaled
as the integrator solves it): threshold 0.1: 10.3 s, fill 23.8M (off-diagonal pivots);
0.01: 0.49 s, fill 3.6M; 0.0: 0.74 s, fill 3.6M.

``PardisoOrPruned`` (registry name ``"auto_pruned"``, added by ``register()`` too): PARDISO's
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

from ..solvers.linear import BACKENDS, SingularFactorError, SuperLUBackend, register_backend

__all__ = ["PrunedSuperLU", "PardisoOrPruned", "register", "NAME", "NAME_AUTO"]

log = logging.getLogger("rve.scenes.impact_solver")

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
    #: unknowns at the end of the (restricted) matrix eliminated by the Schur complement
    border = 0

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

    def __init__(self, symmetric: bool = False):
        from ..solvers.backends import pardiso

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
            self._pruned = PrunedSuperLU(symmetric=False)
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


def register(border: int = 0) -> str:
    """Make the backends available by name (idempotent: ``superlu_pruned`` with ``border``
    trailing unknowns eliminated by the Schur complement, and ``auto_pruned``); returns
    the name of the first."""
    if NAME not in BACKENDS:
        register_backend(NAME, PrunedSuperLU)
    if NAME_AUTO not in BACKENDS:
        register_backend(NAME_AUTO, PardisoOrPruned)
    PrunedSuperLU.border = int(border)
    return NAME
