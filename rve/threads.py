"""The threads one job computes on (docs/engine.md "Two threads", docs/kernels.md).

Contract
--------
* ``solver_threads() -> int``: ``linear_threads(n)`` in effect (a context variable, so jobs
  run side by side in threads of one process do not mix), else ``$RVE_PARDISO_THREADS`` (a
  positive integer; another value raises ``ValueError`` naming the variable), else
  ``min(DEFAULT_THREADS, cores)``. Two things use it: the energy minimiser's PARDISO
  factorisations (MKL's reproducible mode: 1 and 2 threads give the same bits) and the
  compiled assembly kernels (``run_chunked``: per-element / per-pair outputs, the same bits
  on any thread count). The Snakefile sets 1 for every job but the relaxation, which
  declares two.
* ``linear_threads(n)``: a context manager setting it within the block (None: unchanged).
* ``run_chunked(n, fn, min_chunk)``: calls ``fn(a, b)`` on consecutive ranges covering
  ``range(n)``, on up to ``solver_threads()`` threads (the calling one included; ranges of
  at least ``min_chunk`` items), and returns when all are done. ``fn`` must write disjoint
  outputs per item and release the GIL (the numba kernels are ``nogil``).
"""
from __future__ import annotations

import contextlib
import contextvars
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Optional

__all__ = ["THREADS_ENV", "DEFAULT_THREADS", "solver_threads", "linear_threads", "run_chunked"]

#: environment variable: the job's compute threads (the minimiser's PARDISO factorisations
#: and the compiled kernels; the name is from when only PARDISO read it)
THREADS_ENV = "RVE_PARDISO_THREADS"
#: threads when neither ``linear_threads`` nor ``RVE_PARDISO_THREADS`` says: the two cores
#: the minimiser's results are reproducible on (MKL's CNR mode for up to 2 threads,
#: ``rve.solvers.backends.registry.CNR_THREADS``: 1 and 2 threads give the same bits)
DEFAULT_THREADS = 2
_THREADS = contextvars.ContextVar("rve_linear_threads", default=None)


def solver_threads() -> int:
    """Threads of this job (module docstring): ``linear_threads(n)`` in effect, else
    ``$RVE_PARDISO_THREADS``, else ``min(DEFAULT_THREADS, cores)``. A bad value of the
    variable raises ``ValueError`` naming it."""
    n = _THREADS.get()
    if n is not None:
        return n
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            n = 0
        if n < 1:
            raise ValueError(f"environment variable {THREADS_ENV}={env!r}: expected a positive integer (threads)")
        return n
    return max(1, min(DEFAULT_THREADS, os.cpu_count() or 1))


@contextlib.contextmanager
def linear_threads(n: Optional[int]):
    """Within the block, this job computes on ``n`` threads (None: unchanged); a context
    variable, so jobs run side by side in threads of one process do not mix."""
    if n is None:
        yield
        return
    n = int(n)
    if n < 1:
        raise ValueError(f"threads = {n}: expected a positive integer")
    token = _THREADS.set(n)
    try:
        yield
    finally:
        _THREADS.reset(token)


_POOL: Optional[ThreadPoolExecutor] = None


def _pool(workers: int) -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None or _POOL._max_workers < workers:
        _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="rve-kernel")
    return _POOL


def run_chunked(n: int, fn: Callable[[int, int], object], min_chunk: int = 256) -> None:
    """``fn(a, b)`` over consecutive ranges covering ``range(n)`` on up to ``solver_threads()``
    threads (module docstring); one call ``fn(0, n)`` when that is one thread."""
    t = min(solver_threads(), n // max(1, int(min_chunk)))
    if t <= 1:
        fn(0, n)
        return
    bounds = [n * i // t for i in range(t + 1)]
    futures = [_pool(t - 1).submit(fn, bounds[i], bounds[i + 1]) for i in range(1, t)]
    try:
        fn(bounds[0], bounds[1])
    finally:
        for f in futures:
            f.result()
