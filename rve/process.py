"""Process-level settings of every process that imports ``rve``.

Contract
--------
``install_fast_exit()`` (called once by ``rve/__init__.py``): at interpreter exit (an
``atexit`` handler; the others run as usual before or after it, since freezing stops no
code) the objects still alive are frozen out of the cyclic garbage collector (``gc.freeze``).
Python's finalisation then skips its full collections over them: with numba's type
system, pint's registry and the model objects (~1.6e5 tracked objects) those passes took
0.4-0.5 s at the end of every process, a tenth of a 12-element relaxation and of many
short Snakemake jobs (docs/engine.md, "the fixed costs of a process"). What is not collected at exit is
reference-cycle garbage, whose finalisers Python does not promise to run at exit anyway;
files are closed and flushed by the code that writes them (``rve.io.atomic``), logging
by its own ``atexit`` handler. ``RVE_FAST_EXIT=0`` turns it off.
"""
from __future__ import annotations

import atexit
import gc
import os

__all__ = ["install_fast_exit", "FAST_EXIT_ENV"]

#: environment variable: "0" keeps Python's full collections at exit
FAST_EXIT_ENV = "RVE_FAST_EXIT"

_installed = False


def install_fast_exit() -> bool:
    """Register the exit-time freeze once (module contract); False when ``RVE_FAST_EXIT=0``."""
    global _installed
    if os.environ.get(FAST_EXIT_ENV, "1").strip() == "0":
        return False
    if not _installed:
        atexit.register(gc.freeze)
        _installed = True
    return True
