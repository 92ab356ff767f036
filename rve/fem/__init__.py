"""Finite-element layer of the fibrils (docs/engine.md): meshes, the 1D Lagrange basis,
the disk quadrature (docs/disk_quadrature.md), precomputed kinematic operators, the dof
layout and sparse assembly, batched 3x3 algebra, mesh-to-mesh transfer. It imports no
other rve layer. The modules are the API (imported on demand)."""
__all__ = ["mesh", "lagrange", "basis", "disk_quadrature", "assembly", "small_matrix", "transfer"]
