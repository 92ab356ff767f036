"""Factorisation backends of the sparse solves: ``base`` (errors, the ``LinearBackend``
interface, ``same_structure``), ``superlu``, ``banded``, ``pardiso`` (MKL through ctypes) and
``registry`` (names, the default choice, ``run_backend``). The backends import nothing
of ``rve.solvers`` outside this package; ``rve.solvers.linear`` builds the solves on them.
"""
from .base import LinearBackend, NotBandedError, NotPositiveDefiniteError, SingularFactorError, same_structure
from .registry import BACKENDS, get_backend, register_backend, resolve_backend, run_backend

__all__ = ["LinearBackend", "NotBandedError", "NotPositiveDefiniteError", "SingularFactorError", "same_structure",
           "BACKENDS", "get_backend", "register_backend", "resolve_backend", "run_backend"]
