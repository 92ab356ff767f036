"""rve: textiles simulated fibril by fibril, and the lookup tables built from them.

The package is layered (docs/architecture.md): ``io``, ``fem``, ``physics``, ``contact``
(search), ``model`` (the assembled system as a sum of terms), ``solvers``, ``fabrics``,
``config``, ``scenes``, ``homogenisation``, ``tables``, ``studies``, and the ``rve``
command (``rve.cli``). Subpackages are imported on demand; nothing is re-exported here.
"""
__all__ = ["io", "fem", "physics", "contact", "model", "solvers", "fabrics", "config", "scenes",
           "homogenisation", "tables", "studies", "analytic", "cli"]

from .process import install_fast_exit as _install_fast_exit

_install_fast_exit()  # the exit-time freeze (rve/process.py: ~0.4 s of every process's finalisation)
