"""Which kernels a call uses: ``RVE_KERNELS`` = numpy | numba | auto (docs/kernels.md)."""
from __future__ import annotations

import importlib.util
import os

__all__ = ["kernels_mode", "numba_available", "use_numba", "index_kernels"]

_MODES = ("numpy", "numba", "auto")
_AVAILABLE = None


def numba_available() -> bool:
    """True when numba can be imported (checked once, without importing it)."""
    global _AVAILABLE
    if _AVAILABLE is None:
        _AVAILABLE = importlib.util.find_spec("numba") is not None
    return _AVAILABLE


def kernels_mode() -> str:
    """The requested mode (``RVE_KERNELS``, default ``auto``)."""
    mode = os.environ.get("RVE_KERNELS", "auto").strip().lower() or "auto"
    if mode not in _MODES:
        raise ValueError(f"RVE_KERNELS must be one of {_MODES}, got {mode!r}")
    return mode


def use_numba() -> bool:
    """True when the compiled kernels are to be used for this call."""
    mode = kernels_mode()
    if mode == "numpy":
        return False
    if mode == "numba":
        if not numba_available():
            raise ImportError("RVE_KERNELS=numba but numba is not installed")
        return True
    return numba_available()


def index_kernels():
    """``rve.kernels.index`` when this call uses the compiled kernels, else None (the caller
    takes the numpy expressions beside the call: the same integers and sums)."""
    if not use_numba():
        return None
    from . import index

    return index
