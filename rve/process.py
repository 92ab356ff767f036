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

``keep_freed_memory() -> bool`` (called first in the dynamic scenes' Snakemake jobs,
workflow/rules/impact.smk and induced_deformation.smk, and by the benchmarks that profile
them): glibc's allocator keeps the
memory the process frees for its next allocations (``mallopt``: blocks up to 32 MiB from the
heap instead of fresh ``mmap`` regions, the heap's top returned to the system only beyond
1 GiB free, 64 MiB of padding per heap growth). Every time step of these scenes allocates and
frees arrays of 1-50 MB (stage matrices, union structures, tangents); with glibc's defaults
each of them comes back as fresh pages whose first touch is a page fault, and on the shared
machine those faults cost the processes a fifth of their CPU time as system time (measured:
the impact's first 40 steps, ~210k minor faults and 2.6-5.8 s system time of 15-19 s CPU,
against ~90k and 1.1-1.9 s with these settings; docs/engine.md "Dynamic scenes: rebuilds, page faults").
No arithmetic changes. Linux/glibc only (False elsewhere, and with ``RVE_KEEP_FREED=0``).
"""
from __future__ import annotations

import atexit
import gc
import os

__all__ = ["install_fast_exit", "FAST_EXIT_ENV", "keep_freed_memory", "KEEP_FREED_ENV"]

#: environment variable: "0" keeps Python's full collections at exit
FAST_EXIT_ENV = "RVE_FAST_EXIT"

_installed = False

#: environment variable: "0" leaves glibc's allocator at its defaults
KEEP_FREED_ENV = "RVE_KEEP_FREED"

# mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3


def install_fast_exit() -> bool:
    """Register the exit-time freeze once (module contract); False when ``RVE_FAST_EXIT=0``."""
    global _installed
    if os.environ.get(FAST_EXIT_ENV, "1").strip() == "0":
        return False
    if not _installed:
        atexit.register(gc.freeze)
        _installed = True
    return True


def keep_freed_memory() -> bool:
    """glibc's allocator set to reuse freed memory (module contract); True when applied."""
    if os.environ.get(KEEP_FREED_ENV, "1").strip() == "0":
        return False
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        ok = libc.mallopt(_M_MMAP_THRESHOLD, 32 * 2**20) == 1
        ok &= libc.mallopt(_M_TRIM_THRESHOLD, 2**30) == 1
        ok &= libc.mallopt(_M_TOP_PAD, 64 * 2**20) == 1
        return bool(ok)
    except (OSError, AttributeError):
        return False
