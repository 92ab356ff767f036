"""Precomputed quadrature and kinematic operators for director beams (all elements at once).

Contract
--------
``BeamBasis(mesh, disk_points=4, axial_points=None)`` precomputes, for every element e of
every fibril, axial Gauss point g and disk point d (flattened to q = g*n_disk + d):

* ``N`` (ng, nn), ``dN`` (E, ng, nn): Lagrange values and d/dxi3 (physical reference length);
* ``xi12`` (E, nq, 2): section coordinates (xi1, xi2) = R * disk point of the element's fibril;
* ``W`` (E, nq): volume weights of the natural configuration: w_g * h/2 * w_d * R^2 * det J0;
* ``D`` (E, nq, 3, nn*3): the linear map from the element's nodal mechanical values
  u[a, f, i] (node a, field f in {r, g1, g2}, component i) to the deformation gradient,
  F[i, j] = sum_{a,f} D[j, (a,f)] u[(a,f), i];
* ``Nx`` (E, nq, nn*3): the map to the position itself, x[i] = sum_{a,f} Nx[(a,f)] u[(a,f), i]
  (used for the mass matrix and body loads);
* ``Wg`` (E, ng): line weights w_g * h/2 for integrals along the axis only.

The natural configuration X0 = R0 + xi1 G1 + xi2 G2 may be curved (SPEC §2):
F = (dx/dxi)(dX0/dxi)^-1 with dx/dxi = [g1 | g2 | r' + xi1 g1' + xi2 g2'].
Nothing here depends on the deformed state, so it is built once per mesh.
"""
from __future__ import annotations

import numpy as np

from .disk_quadrature import disk_rule
from .lagrange import lagrange_basis
from .mesh import FibrilMesh
from .small_matrix import det3

__all__ = ["BeamBasis"]


def _ref_gradient(basis_N, basis_dN, xi12, U):
    """dX/dxi for nodal fields U (E, nn, 9) -> (E, nq, 3, 3) (columns: d/dxi1, d/dxi2, d/dxi3)."""
    E, ng, nn = basis_dN.shape
    nd = xi12.shape[1] // ng
    r_p = np.einsum("egn,eni->egi", basis_dN, U[:, :, 0:3])
    g1 = np.einsum("gn,eni->egi", basis_N, U[:, :, 3:6])
    g2 = np.einsum("gn,eni->egi", basis_N, U[:, :, 6:9])
    g1_p = np.einsum("egn,eni->egi", basis_dN, U[:, :, 3:6])
    g2_p = np.einsum("egn,eni->egi", basis_dN, U[:, :, 6:9])
    rep = lambda a: np.repeat(a, nd, axis=1)  # noqa: E731  (E, ng, 3) -> (E, nq, 3)
    x1 = xi12[:, :, 0:1]
    x2 = xi12[:, :, 1:2]
    col3 = rep(r_p) + x1 * rep(g1_p) + x2 * rep(g2_p)
    return np.stack([rep(g1), rep(g2), col3], axis=-1)


class BeamBasis:
    def __init__(self, mesh: FibrilMesh, disk_points: int = 4, axial_points: int | None = None):
        p = mesh.order
        ng = int(axial_points) if axial_points else p + 1
        tg, wg = np.polynomial.legendre.leggauss(ng)
        dpts, dw = disk_rule(disk_points)
        nd = len(dw)
        E = mesh.n_elements
        nn = p + 1
        self.mesh = mesh
        self.ng, self.nd, self.nq, self.nn = ng, nd, ng * nd, nn
        N, dNt = lagrange_basis(p, tg)
        h = mesh.elem_length
        self.N = N
        self.dN = dNt[None, :, :] * (2.0 / h)[:, None, None]
        self.Wg = wg[None, :] * (h / 2.0)[:, None]
        R = mesh.radius[mesh.elem_fibril]  # (E,)
        xi12 = np.tile(dpts, (ng, 1))[None, :, :] * R[:, None, None]  # (E, nq, 2)
        self.xi12 = xi12
        wq = (wg[:, None] * dw[None, :]).ravel()  # (nq,)
        # natural configuration
        U0 = mesh.X0[mesh.conn]  # (E, nn, 9)
        J0 = _ref_gradient(N, self.dN, xi12, U0)
        det0 = np.linalg.det(J0)
        if np.any(det0 <= 0):
            raise ValueError("natural configuration has det(dX0/dxi) <= 0: directors must be right-handed with the tangent")
        J0inv = np.linalg.inv(J0)  # (E, nq, 3, 3) [k, j]
        self.W = wq[None, :] * (h / 2.0)[:, None] * (R**2)[:, None] * det0
        # c[e, q, k, a, f]: d(dx/dxi)[:, k] / d u[a, f, :]
        Nq = np.repeat(N, nd, axis=0)  # (nq, nn)
        dNq = np.repeat(self.dN, nd, axis=1)  # (E, nq, nn)
        c = np.zeros((E, self.nq, 3, nn, 3))
        c[:, :, 0, :, 1] = Nq[None]
        c[:, :, 1, :, 2] = Nq[None]
        c[:, :, 2, :, 0] = dNq
        c[:, :, 2, :, 1] = dNq * xi12[:, :, 0:1]
        c[:, :, 2, :, 2] = dNq * xi12[:, :, 1:2]
        self.D = np.einsum("eqkaf,eqkj->eqjaf", c, J0inv).reshape(E, self.nq, 3, nn * 3)
        Nx = np.empty((E, self.nq, nn, 3))
        Nx[:, :, :, 0] = Nq[None]
        Nx[:, :, :, 1] = Nq[None] * xi12[:, :, 0:1]
        Nx[:, :, :, 2] = Nq[None] * xi12[:, :, 1:2]
        self.Nx = Nx.reshape(E, self.nq, nn * 3)

    def element_values(self, x: np.ndarray) -> np.ndarray:
        """Nodal mechanical values (n_nodes, >=9) -> element arrays U (E, nn*3, 3)."""
        U = x[:, :9][self.mesh.conn]  # (E, nn, 9)
        return U.reshape(U.shape[0], self.nn * 3, 3)

    def deformation_gradient(self, x: np.ndarray) -> np.ndarray:
        """F (E, nq, 3, 3) at every quadrature point for the nodal state x (n_nodes, >=9)."""
        U = self.element_values(x)
        # F[i, j] = sum_af D[j, af] U[af, i]  ->  (D @ U)[j, i]
        return np.swapaxes(np.matmul(self.D, U[:, None, :, :]), -1, -2)

    def min_det_F(self, x: np.ndarray) -> float:
        return float(det3(self.deformation_gradient(x)).min())
