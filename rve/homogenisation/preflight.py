"""Input checked before compute: what a validated RVEConfig can still get wrong, found before
the first job computes anything (docs/fault_tolerance.md "Input checks").

``preflight(cfg, outputs=()) -> (fabric, mesh)`` raises one ``rve.config.ConfigError`` with
one line per problem, each naming the key and the allowed range:

* ``mesh.elements``: the estimated peak memory of a job (``estimate_memory_mb``, checked
  *before* the mesh is allocated) against ``checks.memory_limit_mb`` or the machine's
  available memory;
* ``fabric.fibril_diameter``: fibrils of different yarns overlapping at the designed state
  by more than ``checks.max_design_overlap`` of the diameter (``design_overlap``);
* ``probes[i].terminals[j]``: a terminal that matches no yarn end of the fabric;
* an output folder that cannot be written.

``fabric_job`` (the first job of every chain) calls it; ``rve check CONFIG`` too.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, Optional

import numpy as np

__all__ = ["preflight", "estimate_memory_mb", "design_overlap", "available_memory_mb", "fibril_count",
           "MB_PER_DOF", "BASE_MB"]

#: peak memory model of a job: BASE_MB + MB_PER_DOF x mechanical dofs. Measured on the
#: default plain weave (80 fibrils x 13 nodes x 9 = 9360 dofs: 410 MB peak RSS, ~180 MB of
#: it the interpreter and libraries, docs/rve_pipeline.md "Measured"), rounded up.
MB_PER_DOF = 0.03
BASE_MB = 200.0


def fibril_count(cfg) -> int:
    f = cfg.fabric
    per_yarn = int(sum(f.rows))
    yarns = f.knit_rows if f.kind == "knit" else f.n_warp + f.n_weft
    return int(yarns * per_yarn)


def estimate_memory_mb(cfg) -> float:
    nodes = fibril_count(cfg) * (cfg.mesh.elements * cfg.mesh.order + 1)
    return BASE_MB + MB_PER_DOF * 9 * nodes


def available_memory_mb() -> Optional[float]:
    from ..config.limits import available_mb

    return available_mb()


def design_overlap(fab, mesh, x0, samples: int = 8) -> tuple[float, str]:
    """Largest overlap (2R - d) / 2R of two fibrils of *different yarns* at the state ``x0``
    (n_nodes, 9), the centrelines sampled ``samples`` points per element (linear between
    nodes), and the pair where it is (text)."""
    from scipy.spatial import cKDTree

    r = np.asarray(x0, float).reshape(mesh.n_nodes, 9)[:, :3]
    pts, fib = [], []
    t = np.linspace(0.0, 1.0, samples, endpoint=False)[:, None]
    for e in range(mesh.conn.shape[0]):
        a, b = mesh.conn[e, 0], mesh.conn[e, -1]
        pts.append(r[a] + t * (r[b] - r[a]))
        fib.append(np.full(samples, mesh.node_fibril[a]))
    pts = np.concatenate(pts)
    fib = np.concatenate(fib)
    radius = np.asarray(mesh.radius, float)
    yarn = np.asarray(fab.fibril_yarn)
    dmax = 2.0 * float(radius.max())
    pairs = cKDTree(pts).query_pairs(dmax, output_type="ndarray")
    if pairs.size == 0:
        return 0.0, ""
    i, j = pairs[:, 0], pairs[:, 1]
    keep = yarn[fib[i]] != yarn[fib[j]]
    i, j = i[keep], j[keep]
    if i.size == 0:
        return 0.0, ""
    d = np.linalg.norm(pts[i] - pts[j], axis=1)
    contact = radius[fib[i]] + radius[fib[j]]
    frac = (contact - d) / contact
    k = int(np.argmax(frac))
    names = mesh.names
    return float(max(frac[k], 0.0)), f"{names[fib[i[k]]]} and {names[fib[j[k]]]}"


def _writable(folder: Path) -> Optional[str]:
    from ..io.atomic import unwritable_reason

    return unwritable_reason(folder)


def preflight(cfg, outputs: Iterable = ()):
    """The checks of the module docstring; returns ``(fabric, mesh)`` of ``cfg``."""
    from ..config import ConfigError
    from ..fabrics.setup import fabric_and_mesh
    from .probes import terminal_nodes

    errors = []
    for out in outputs:
        why = _writable(Path(out).parent)
        if why:
            errors.append(f"output {out}: cannot be written ({why})")
    need = estimate_memory_mb(cfg)
    limit = cfg.checks.memory_limit_mb
    avail = float(limit) if limit is not None else available_memory_mb()
    if avail is not None and need > avail:
        src = "checks.memory_limit_mb" if limit is not None else "the available memory"
        errors.append(f"mesh.elements = {cfg.mesh.elements}: the job would need ~{need:,.0f} MB "
                      f"({fibril_count(cfg)} fibrils x {cfg.mesh.elements} elements, order {cfg.mesh.order}), "
                      f"more than {src} ({avail:,.0f} MB): use fewer elements or fibrils")
    if errors:
        raise ConfigError(errors)
    fab, mesh = fabric_and_mesh(cfg)
    x0 = fab.initial_state(mesh)
    over, where = design_overlap(fab, mesh, x0)
    allowed = float(cfg.checks.max_design_overlap)
    if over > allowed:
        errors.append(f"fabric.fibril_diameter = {cfg.fabric.fibril_diameter:g} mm: fibrils of different yarns "
                      f"overlap by {100 * over:.0f} % of the diameter at the designed state ({where}; spacing "
                      f"{cfg.fabric.spacing:g} mm); allowed: <= {100 * allowed:.0f} % (checks.max_design_overlap)")
    for i, p in enumerate(cfg.probes):
        for j, term in enumerate(p.terminals):
            try:
                terminal_nodes(fab, mesh, term)
            except (ValueError, KeyError, LookupError) as exc:
                yarns = sorted({f"{y.direction} {y.position:g}" for y in fab.yarns})
                errors.append(f"probes[{i}].terminals[{j}] ({p.name}: {term.yarn} yarn at {term.position:g} mm, "
                              f"end {term.end}): matches no yarn end ({exc}); yarns: {', '.join(yarns)}")
    if errors:
        raise ConfigError(errors)
    return fab, mesh
