"""Compiled (numba) versions of the hot assembly kernels, used when numba is importable
(docs/kernels.md: what is compiled, why, and the measured gains).

Contract
--------
The pure-numpy functions of ``rve.physics`` stay the reference: every compiled kernel here
computes the same arrays to rounding (tests/test_kernels.py: 1e-12 relative on random
inputs and on the 80-fibril weave) and the numpy path is bit-identical to the code before
the kernels existed. ``use_numba()`` says which path a call takes, read from the
environment variable ``RVE_KERNELS`` at every call: ``numpy`` (the reference), ``numba``
(compiled; an error if numba is missing), ``auto`` (default: numba when importable).
The kernels are compiled with ``cache=True`` (the JIT cost is paid once per machine, in
numba's ``__pycache__`` next to the sources).
"""
from __future__ import annotations

from .select import index_kernels, kernels_mode, numba_available, use_numba

__all__ = ["index_kernels", "kernels_mode", "numba_available", "use_numba"]
