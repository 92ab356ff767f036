"""Weakened insulation (thesis §8.2; docs/contact.md, "Weakened insulation"): pull-down resistors on unwired fibrils.

A fibril that touches no Dirichlet potential and no circuit has an undetermined constant
mode in the quasistatic potential whenever it is not in contact with a wired fibril: the
global matrix is singular. The thesis replaces its insulated ends with the mixed circuit
condition of eq. 2.8.2 through a large external resistor ``R_ext`` to a reference
potential ``V_ref`` (a pull-down). An isolated fibril then sits at ``V_ref``; a fibril in
contact leaks at most ``|V - V_ref| / R_ext`` through it.

``pull_down_circuits(mesh, sigma0, wired_nodes, factor=1e6, V_ref=0.0, ends="both")``
returns ``CircuitBC`` objects (``rve.model``) for the ends of every fibril none of whose
nodes is in ``wired_nodes`` (Dirichlet V nodes and circuit nodes). ``R_ext = factor *
R_fibril`` with ``R_fibril = length / (sigma0 pi R^2)`` the fibril's own end-to-end
resistance, so the leakage relative to the fibril's conduction is ``1/factor``. ``ends``:
``"both"`` (default: symmetric, each end gets ``2 R_ext`` so the pair is ``R_ext`` in
parallel) or ``"start"`` (the thesis: one end).
"""
from __future__ import annotations

import numpy as np

__all__ = ["pull_down_circuits", "unwired_fibrils"]


def unwired_fibrils(mesh, wired_nodes) -> np.ndarray:
    """Fibrils none of whose nodes is in ``wired_nodes``."""
    wired = np.zeros(mesh.n_fibrils, bool)
    nodes = np.asarray(list(wired_nodes), dtype=np.int64)
    if nodes.size:
        wired[np.unique(mesh.node_fibril[nodes])] = True
    return np.flatnonzero(~wired)


def pull_down_circuits(mesh, sigma0: float, wired_nodes=(), factor: float = 1e6, V_ref: float = 0.0,
                       ends: str = "both"):
    """``CircuitBC`` pull-downs for every unwired fibril (module docstring)."""
    from .materials import CircuitBC

    if not sigma0 > 0:
        raise ValueError(f"sigma0 must be > 0, got {sigma0}")
    if not factor > 0:
        raise ValueError(f"factor must be > 0, got {factor}")
    if ends not in ("both", "start"):
        raise ValueError(f"ends must be 'both' or 'start', got {ends!r}")
    out = []
    lengths = np.bincount(mesh.elem_fibril, weights=mesh.elem_length, minlength=mesh.n_fibrils)
    for f in unwired_fibrils(mesh, wired_nodes):  # one object per fibril end (few)
        area = float(np.pi * mesh.radius[f] ** 2)
        R_ext = factor * float(lengths[f]) / (sigma0 * area)
        n0, n1 = mesh.end_nodes(int(f))
        if ends == "both":
            out += [CircuitBC.resistor(n0, 2 * R_ext, V_ref, area), CircuitBC.resistor(n1, 2 * R_ext, V_ref, area)]
        else:
            out.append(CircuitBC.resistor(n0, R_ext, V_ref, area))
    return out
