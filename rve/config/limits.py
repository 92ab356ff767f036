"""Resource limits checked at validation time (docs/fault_tolerance.md): the
machine's available memory and a rough peak-memory model of a solve, so a mesh that cannot
fit is refused with the estimate before anything is allocated.

``estimate_mb(dofs, mb_per_dof)`` = ``BASE_MB + mb_per_dof * dofs``; ``available_mb()``
reads ``MemAvailable`` (Linux) or the free physical pages; ``RVE_MEMORY_LIMIT_MB`` in the
environment overrides it (tests, batch systems). The per-dof figures are upper bounds
rounded up from measured runs (docs/fault_tolerance.md "Mesh size against memory").
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

__all__ = ["BASE_MB", "WIRE_MB_PER_DOF", "SLENDER_RATIO", "estimate_mb", "available_mb", "wire_feasibility"]

#: interpreter, numpy/scipy/xarray and the solver libraries (~180 MB measured)
BASE_MB = 200.0
#: a wire's banded system (11 dofs per node with V and T), history and factorisation
WIRE_MB_PER_DOF = 0.01


def estimate_mb(dofs: int, mb_per_dof: float) -> float:
    return BASE_MB + float(mb_per_dof) * int(dofs)


def available_mb() -> Optional[float]:
    env = os.environ.get("RVE_MEMORY_LIMIT_MB")
    if env:
        try:
            return float(env)
        except ValueError:
            pass
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (ValueError, OSError, AttributeError):
        return None


#: a beam model needs a slender wire: R <= half_length / SLENDER_RATIO (the wire >= 4 diameters long)
SLENDER_RATIO = 4.0


def wire_feasibility(cfg, dofs_per_node: int):
    """Validation of a wire scene config (``geometry.half_length``, ``fibril.radius``,
    ``mesh.elements``/``order``): radius against length, the mesh against the available
    memory. Raises the loader's one-line error; returns ``cfg``."""
    from .fields import line_error

    R, L = cfg.fibril.radius, cfg.geometry.half_length
    if R > L / SLENDER_RATIO:
        raise line_error(f"fibril.radius = {R:.6g} mm: must be <= geometry.half_length / {SLENDER_RATIO:g} "
                         f"(= {L / SLENDER_RATIO:.6g} mm): a beam model needs a wire at least "
                         f"{SLENDER_RATIO:g} diameters long (here {L / R:.3g} radii of half length)")
    dofs = dofs_per_node * (cfg.mesh.elements * cfg.mesh.order + 1)
    need, avail = estimate_mb(dofs, WIRE_MB_PER_DOF), available_mb()
    if avail is not None and need > avail:
        most = int(max(1, (avail - BASE_MB) / (WIRE_MB_PER_DOF * dofs_per_node * cfg.mesh.order)))
        raise line_error(f"mesh.elements = {cfg.mesh.elements}: the solve would need ~{need:,.0f} MB "
                         f"({dofs:,} dofs), more than the available memory ({avail:,.0f} MB): use at most "
                         f"~{most:,} elements at order {cfg.mesh.order}")
    return cfg
