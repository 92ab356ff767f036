"""The backends by name, and the backend one solver run keeps.

Contract
--------
* ``BACKENDS``: name -> factory ``(symmetric=...) -> backend``; ``register_backend(name,
  factory)`` adds one. ``resolve_backend(name=None, symmetric=True) -> str``: the argument,
  else ``$RVE_LINEAR_BACKEND``, else ``DEFAULT_BACKEND = "auto"`` (PARDISO when available
  and symmetric, else SuperLU); an unknown name raises ``ValueError`` listing the allowed
  ones. ``get_backend(name=None, symmetric=True)``: a fresh instance.
* ``run_backend(backend=None, keep_pattern=True, pardiso_options=None)``: a context manager
  giving the one symmetric backend instance a solver run factorises with (an instance is
  used as is and not released; a name or None makes a fresh one, released at the end).
  A PARDISO instance gets the run's threads (``rve.threads.solver_threads``), MKL's
  reproducible mode for at least ``CNR_THREADS`` threads, explicit zeros kept when
  ``keep_pattern`` (the minimiser factorises on the contact map's stored pattern) and
  ``pardiso_options`` (``PardisoFactorization`` keywords; ``PARDISO_RUN_OPTIONS`` when None).
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Callable, Dict, Optional

from ...threads import solver_threads
from .banded import BandedBackend
from .base import LinearBackend
from .pruned import PardisoOrPruned, PrunedSuperLU
from .superlu import SuperLUBackend

__all__ = ["BACKENDS", "DEFAULT_BACKEND", "BACKEND_ENV", "register_backend", "resolve_backend", "get_backend",
           "PardisoBackend", "PardisoUnsymBackend", "run_backend", "CNR_THREADS", "PARDISO_RUN_OPTIONS"]


def PardisoBackend(symmetric: bool = True, **options):
    """The ``"pardiso"`` backend: a fresh ``rve.solvers.backends.pardiso.PardisoFactorization``
    (one MKL thread, weighted matching, explicit zeros dropped; ``options`` go to it):
    LDLᵀ of a symmetric matrix (mtype -2) or, ``symmetric=False``, LU of an unsymmetric one
    (mtype 11, no inertia). A symmetric instance's ``unsymmetric()`` is its mtype-11
    companion (``StageFactorisation`` sends the unsymmetric stage matrices there).
    ``RuntimeError`` with the reason when MKL is unavailable."""
    from . import pardiso

    if not pardiso.available():
        raise RuntimeError(f"linear-solver backend 'pardiso' is not available: {pardiso.unavailable_reason()}")
    return pardiso.PardisoFactorization(symmetric=symmetric, **options)


def PardisoUnsymBackend(symmetric: bool = False, **options):
    """The ``"pardiso_unsym"`` backend: PARDISO's LU (mtype 11) whatever ``symmetric`` says
    (an explicit choice for matrices known to be unsymmetric: the dynamic scenes' stage
    matrices). ``RuntimeError`` with the reason when MKL is unavailable."""
    from . import pardiso

    if not pardiso.available():
        raise RuntimeError(f"linear-solver backend 'pardiso_unsym' is not available: {pardiso.unavailable_reason()}")
    return pardiso.PardisoFactorization(symmetric=False, **options)


#: backend classes by name
BACKENDS: Dict[str, Callable[..., LinearBackend]] = {"superlu": SuperLUBackend, "banded": BandedBackend,
                                                     "pardiso": PardisoBackend, "pardiso_unsym": PardisoUnsymBackend,
                                                     "superlu_pruned": PrunedSuperLU, "auto_pruned": PardisoOrPruned}

#: the backend used when neither a ``backend=`` argument nor ``RVE_LINEAR_BACKEND`` names one
DEFAULT_BACKEND = "auto"

#: environment variable overriding the default backend (superlu | pardiso | pardiso_unsym | auto)
BACKEND_ENV = "RVE_LINEAR_BACKEND"


def register_backend(name: str, cls: Callable[..., LinearBackend]) -> None:
    """Make ``cls`` (a ``LinearBackend`` subclass) available as ``factorize(..., backend=name)``."""
    BACKENDS[str(name)] = cls


def _allowed() -> str:
    return ", ".join(["auto", *sorted(BACKENDS)])


def resolve_backend(name: Optional[str] = None, symmetric: bool = True) -> str:
    """The registry name that ``name`` (else ``$RVE_LINEAR_BACKEND``, else
    ``DEFAULT_BACKEND``) stands for; ``"auto"``: pardiso when available and ``symmetric``,
    else superlu. Raises ``ValueError`` for an unknown name."""
    source = "backend argument"
    if name is None:
        env = os.environ.get(BACKEND_ENV, "").strip()
        name, source = (env, f"environment variable {BACKEND_ENV}") if env else (DEFAULT_BACKEND, "default")
    key = str(name).strip().lower()
    if key == "auto":
        from . import pardiso

        return "pardiso" if symmetric and pardiso.available() else "superlu"
    if key not in BACKENDS:
        raise ValueError(f"unknown linear-solver backend {name!r} (from the {source}; allowed: {_allowed()})")
    return key


def get_backend(name: Optional[str] = None, symmetric: bool = True) -> LinearBackend:
    """A fresh instance of the backend ``name`` (``resolve_backend``: argument, else
    ``$RVE_LINEAR_BACKEND``, else ``"auto"``)."""
    return BACKENDS[resolve_backend(name, symmetric)](symmetric=symmetric)


#: MKL's conditional numerical reproducibility for up to this many threads (iparm(34)):
#: the minimiser's factorisations give the same bits on 1 and 2 threads, so a Snakemake job
#: scaled down from 2 threads to 1 (``-j1``) computes the same table (docs/engine.md "Two
#: threads"). More threads than this (``RVE_PARDISO_THREADS`` > 2) set CNR for that many:
#: reproducible run to run, but other rounding than on 1-2 threads.
CNR_THREADS = 2

#: the PARDISO instance a solver run keeps: explicit zeros dropped from the values, the
#: stored pattern analysed (docs/engine.md, "Backend choice")
PARDISO_RUN_OPTIONS = {"drop_zeros": True, "analyse_stored": True}


def run_instance(backend=None, keep_pattern: bool = True, pardiso_options: Optional[dict] = None):
    """``(instance, owned)`` of ``run_backend`` (module docstring); ``owned``: the caller
    releases it."""
    if backend is not None and not isinstance(backend, str):
        return backend, False
    name = resolve_backend(backend, symmetric=True)
    if name == "pardiso":
        from .pardiso import PardisoFactorization

        threads = solver_threads()
        extra = PARDISO_RUN_OPTIONS if pardiso_options is None else pardiso_options
        opts = {"drop_zeros": not keep_pattern, "threads": threads, "cnr": max(CNR_THREADS, threads), **extra}
        return PardisoFactorization(**opts), True
    return get_backend(name, symmetric=True), True


@contextmanager
def run_backend(backend=None, keep_pattern: bool = True, pardiso_options: Optional[dict] = None):
    """The backend instance of one solver run (module docstring)."""
    solver, owned = run_instance(backend, keep_pattern, pardiso_options)
    try:
        yield solver
    finally:
        if owned and hasattr(solver, "release"):
            solver.release()
