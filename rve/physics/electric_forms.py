"""Element forms of the fibril's quasistatic electrics (thesis §2.8-2.9, §4.2.2, §6.4).

Contract
--------
Everything is pushed back to the reference (natural) configuration and evaluated for ALL
elements at once (no Python loop over elements or quadrature points). At every quadrature
point q = (axial point g, disk point d) of the section the conduction "EMF per reference
length" is

    e_q = -V'(xi3) + (v_q x B) . a_q - S T'(xi3),       a_q = dx/dxi3 = F E3,

with v_q = vr + xi1 vg1 + xi2 vg2 the material velocity and a_q = r' + xi1 g1' + xi2 g2' the
deformed axial tangent at that point of the section (both vary across the section, so the
section integrals are done by the disk quadrature, never at the centroid only). The
conduction current per reference area is sigma0 e_q (along a_q), so that

* current per fibril:  I(xi3) = sigma0 * integral_A e dA;
* potential equation (current conservation, massless):
      R_V[a] = - sum_q W_q N_a'(q) sigma0 e_q            (+ circuit terms, in the model)
  i.e. R_V = -integral dV0 delta V' sigma0 e, so that dR_V/dV = sigma0 integral N_a' N_b'
  is symmetric positive semi-definite;
* Lorentz force per reference volume  J (calJ x B) = sigma0 e_q (a_q x B),  on the virtual
  displacement delta x = delta r + xi1 delta g1 + xi2 delta g2 (the residual gets minus it):
      R_L[(a,f), i] = - sum_q W_q Nx[q,(a,f)] sigma0 e_q (a_q x B)_i.

Arrays: U, Uv (E, nn*3, 3) nodal positions / velocities of the element's mechanical dofs in
the (a, f, i) order of ``rve.physics.beam_forms``; Te, Ve (E, nn) nodal temperature and
potential. Jacobian blocks are returned with the row layout of the residual first and the
column layout of the differentiated variable second: (E, nn, nn*3, 3) for d R_V / d U,
(E, nn*3, 3, nn) for d R_L / d V, and so on.

Switches (``EMFTerms``): ``back_emf`` (the v x B term), ``seebeck`` (the -S T' term). With
neither, e = -V' and the electrics decouple from the motion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fem.basis import BeamBasis
from .beam_forms import levi_civita

__all__ = ["SectionOps", "section_ops", "EMF", "emf", "potential_equation", "lorentz_force_field",
           "cross_matrix", "axial_current"]


def cross(a, b) -> np.ndarray:
    """a x b over the last axis (broadcasting), without np.cross's axis juggling."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def cross_matrix(B) -> np.ndarray:
    """C with C[i, m] = d (a x B)_i / d a_m (a x B = C a)."""
    return np.einsum("imk,k->im", levi_civita, np.asarray(B, float))


@dataclass(frozen=True)
class SectionOps:
    """Quadrature operators of a ``BeamBasis`` repeated over the disk points.

    Nq (nq, nn): N_a at q; dNq (E, nq, nn): N_a' at q; Nx (E, nq, nn*3): x = Nx u;
    Dx3 (E, nq, nn*3): a = dx/dxi3 = Dx3 u; W (E, nq): reference volume weights;
    Wg (E, ng) line weights; nd disk points per axial point."""

    Nq: np.ndarray
    dNq: np.ndarray
    Nx: np.ndarray
    Dx3: np.ndarray
    W: np.ndarray
    Wg: np.ndarray
    nd: int
    nn: int

    @property
    def WdN(self) -> np.ndarray:  # (E, nq, nn)
        return self.W[:, :, None] * self.dNq

    @property
    def WN(self) -> np.ndarray:  # (E, nq, nn)
        return self.W[:, :, None] * self.Nq[None]


def section_ops(basis: BeamBasis) -> SectionOps:
    nd = basis.nd
    nn = basis.nn
    E = basis.W.shape[0]
    Nq = np.repeat(basis.N, nd, axis=0)
    dNq = np.repeat(basis.dN, nd, axis=1)
    x1 = basis.xi12[:, :, 0:1]
    x2 = basis.xi12[:, :, 1:2]
    Dx3 = np.stack([dNq, dNq * x1, dNq * x2], axis=-1).reshape(E, basis.nq, nn * 3)
    return SectionOps(Nq=Nq, dNq=dNq, Nx=basis.Nx, Dx3=Dx3, W=basis.W, Wg=basis.Wg, nd=nd, nn=nn)


@dataclass
class EMF:
    """e at every quadrature point and what its partial derivatives are made of.

    e (E, nq); a (E, nq, 3) = dx/dxi3; c (E, nq, 3) = v x B (zero without back-EMF);
    Bxa (E, nq, 3) = B x a = d e / d v (zero without back-EMF); seebeck S (float)."""

    e: np.ndarray
    a: np.ndarray
    c: np.ndarray
    Bxa: np.ndarray
    seebeck: float
    back_emf: bool


def emf(ops: SectionOps, U, Uv, Te, Ve, B, seebeck: float = 0.0, back_emf: bool = True) -> EMF:
    B = np.asarray(B, float)
    a = np.matmul(ops.Dx3, U)  # (E, nq, 3)
    Vp = np.einsum("eqn,en->eq", ops.dNq, Ve)
    e = -Vp
    if seebeck:
        e = e - seebeck * np.einsum("eqn,en->eq", ops.dNq, Te)
    if back_emf:
        v = np.matmul(ops.Nx, Uv)  # (E, nq, 3)
        c = cross(v, B)
        e = e + np.einsum("eqi,eqi->eq", c, a)
        Bxa = cross(B, a)
    else:
        c = np.zeros_like(a)
        Bxa = c
    return EMF(e=e, a=a, c=c, Bxa=Bxa, seebeck=float(seebeck), back_emf=bool(back_emf))


def axial_current(ops: SectionOps, m: EMF, sigma0) -> np.ndarray:
    """Current I (A) through the section at every axial Gauss point: (E, ng)."""
    E, nq = m.e.shape
    s = _sig(sigma0, E)
    Iw = (s * m.e * ops.W).reshape(E, nq // ops.nd, ops.nd).sum(axis=2)
    return Iw / ops.Wg


def _outer_q(A, B, C):
    """sum_q A[e,q,a] B[e,q,b] C[e,q,j] -> (E, a, b, j), as one batched matmul."""
    E, nq, nb = B.shape
    BC = (B[:, :, :, None] * C[:, :, None, :]).reshape(E, nq, -1)
    return np.matmul(np.swapaxes(A, 1, 2), BC).reshape(E, A.shape[2], nb, C.shape[2])


def _outer_q2(A, B, X):
    """sum_q A[e,q,a] B[e,q,b] X[e,q,i,m] -> (E, a, i, b, m), as one batched matmul."""
    E, nq, nb = B.shape
    BX = (B[:, :, :, None, None] * X[:, :, None, :, :]).reshape(E, nq, -1)  # (E, q, b*i*m)
    K = np.matmul(np.swapaxes(A, 1, 2), BX).reshape(E, A.shape[2], nb, X.shape[2], X.shape[3])
    return K.transpose(0, 1, 3, 2, 4)


def _sig(sigma0, E):
    """sigma0 (scalar or per element) as an (E, 1) array."""
    return np.broadcast_to(np.asarray(sigma0, float).reshape(-1, 1), (E, 1))


def potential_equation(ops: SectionOps, m: EMF, sigma0, want_tangent: bool = True):
    """Current conservation R_V = -int delta V' sigma0 e dV0 and its partial Jacobians.

    Returns ``(R, J)``: R (E, nn); J a dict with 'V' (E, nn, nn), 'T' (E, nn, nn) or None,
    'x' (E, nn, nn*3, 3) or None, 'v' (E, nn, nn*3, 3) or None (None = identically zero)."""
    E = m.e.shape[0]
    s = _sig(sigma0, E)
    WdN = ops.WdN  # (E, nq, nn)
    R = -np.einsum("eqa,eq->ea", WdN, s * m.e)
    if not want_tangent:
        return R, None
    KVV = np.matmul(np.swapaxes(WdN, 1, 2), ops.dNq) * s[:, :, None]  # (E, nn, nn)
    J = {"V": KVV, "T": KVV * m.seebeck if m.seebeck else None, "x": None, "v": None}
    if m.back_emf:
        sW = -s[:, :, None] * WdN  # (E, nq, nn)
        # d e / d u[(b,h), j] = c_j Dx3[(b,h)]  (positions);  Bxa_j Nx[(b,h)]  (velocities)
        J["x"] = _outer_q(sW, ops.Dx3, m.c)
        J["v"] = _outer_q(sW, ops.Nx, m.Bxa)
    return R, J


def lorentz_force_field(ops: SectionOps, m: EMF, sigma0, B, want_tangent: bool = True):
    """Lorentz load of the conduction current, R_L = -int delta x . sigma0 e (a x B) dV0.

    Returns ``(R, J)``: R (E, nn*3, 3); J with 'x' (E, nn*3, 3, nn*3, 3), 'v' (same or None),
    'V' (E, nn*3, 3, nn), 'T' (E, nn*3, 3, nn) or None."""
    E, nq = m.e.shape
    s = _sig(sigma0, E)
    C = cross_matrix(B)
    L = np.einsum("im,eqm->eqi", C, m.a)  # a x B, (E, nq, 3)
    WNx = ops.W[:, :, None] * ops.Nx  # (E, nq, naf)
    se = s * m.e
    R = -np.einsum("eqa,eqi->eai", WNx, se[:, :, None] * L)
    if not want_tangent:
        return R, None
    # positions: -s W Nx_a Dx3_b [ (de/du) L_i + e C_im ] with de/du_m = c_m Dx3
    X = se[:, :, None, None] * C[None, None] + s[:, :, None, None] * (
        L[:, :, :, None] * m.c[:, :, None, :])  # (E, nq, i, m)
    Kx = -_outer_q2(WNx, ops.Dx3, X)
    J = {"x": Kx, "v": None, "T": None}
    sL = s[:, :, None] * L  # (E, nq, 3)
    # d e / dV_b = -dN_b  ->  +s W Nx_a L_i dN_b
    J["V"] = _outer_q(WNx, sL, ops.dNq)  # (E, a, i, b)
    if m.seebeck:
        J["T"] = J["V"] * m.seebeck
    if m.back_emf:
        Y = sL[:, :, :, None] * m.Bxa[:, :, None, :]  # (E, nq, i, m)
        J["v"] = -_outer_q2(WNx, ops.Nx, Y)
    return R, J


def coupled_forms(ops: SectionOps, m: EMF, sigma0, B, lorentz: bool = True, joule: bool = True,
                  want_tangent: bool = True):
    """All EMF-driven terms at once (what ``potential_equation``, ``lorentz_force_field`` and
    ``thermal_forms.joule_heating`` compute separately), the Jacobians by three batched
    matmuls over the quadrature points: every block is sum_q (row test function x column
    basis function)(q) x (coefficient)(q).

    Returns ``(R, J)``. R: 'V' (E, nn), 'T' (E, nn) Joule part or None, 'L' (E, naf, 3) or
    None. J (None without tangent), for the scalar rows S = [V rows; T rows if joule]
    (r = nn or 2 nn of them) and the mechanical rows L:
    'Sx', 'Sv' (E, r, naf, 3) (None without back-EMF), 'SV' (E, r, nn),
    'Lx' (E, naf, 3, naf, 3), 'Lv' (same, None without back-EMF), 'LV' (E, naf, 3, nn)
    (None without lorentz); the T columns are S times the V columns (de/dT_b = S de/dV_b)."""
    E, nq = m.e.shape
    nn = ops.nn
    naf = ops.Nx.shape[2]
    s = _sig(sigma0, E)
    sW = s * ops.W  # (E, nq)
    e = m.e
    rho = -sW[:, :, None] * ops.dNq  # V rows: R_V = -sum sW dN_a e
    if joule:
        rho = np.concatenate([rho, -2.0 * (sW * e)[:, :, None] * ops.Nq[None]], axis=2)  # d/de of -sW N_a e^2
    r = rho.shape[2]
    R = {"V": np.einsum("eqa,eq->ea", rho[:, :, :nn], e),
         "T": -np.einsum("qa,eq->ea", ops.Nq, sW * e * e) if joule else None, "L": None}
    if lorentz:
        L = cross(m.a, np.broadcast_to(np.asarray(B, float), m.a.shape))  # a x B
        rhoM = -sW[:, :, None] * ops.Nx  # (E, nq, naf)
        R["L"] = np.matmul(np.swapaxes(rhoM, 1, 2), e[:, :, None] * L)  # (E, naf, 3)
    if not want_tangent:
        return R, None
    J = {"Sx": None, "Sv": None, "SV": None, "Lx": None, "Lv": None, "LV": None}
    tr = lambda A: np.swapaxes(A, 1, 2)  # noqa: E731
    # V columns: d e / d V_b = -dN_b (scalar rows), -L_i dN_b (mechanical rows)
    if lorentz:
        left = np.concatenate([rho, rhoM], axis=2)  # (E, nq, r + naf)
        right = np.concatenate([-ops.dNq, (-L[:, :, :, None] * ops.dNq[:, :, None, :]).reshape(E, nq, 3 * nn)], axis=2)
        KV = np.matmul(tr(left), right)  # (E, r + naf, nn + 3 nn)
        J["SV"] = KV[:, :r, :nn]
        J["LV"] = KV[:, r:, nn:].reshape(E, naf, 3, nn)
        C = cross_matrix(B)
        X = e[:, :, None, None] * C[None, None]  # d(e L_i)/da_m at fixed e, (E, nq, i, m)
    else:
        J["SV"] = np.matmul(tr(rho), -ops.dNq)
    # x columns: d e / d u_(b,m) = c_m Dx3_b; v columns: Bxa_m Nx_b
    if m.back_emf:
        if lorentz:
            X = X + L[:, :, :, None] * m.c[:, :, None, :]
            PD = np.concatenate([(rho[:, :, :, None] * ops.Dx3[:, :, None, :]).reshape(E, nq, r * naf),
                                 (rhoM[:, :, :, None] * ops.Dx3[:, :, None, :]).reshape(E, nq, naf * naf)], axis=2)
            PN = np.concatenate([(rho[:, :, :, None] * ops.Nx[:, :, None, :]).reshape(E, nq, r * naf),
                                 (rhoM[:, :, :, None] * ops.Nx[:, :, None, :]).reshape(E, nq, naf * naf)], axis=2)
            Kx = np.matmul(tr(PD), np.concatenate([m.c, X.reshape(E, nq, 9)], axis=2))  # (E, r naf + naf^2, 12)
            Y = (L[:, :, :, None] * m.Bxa[:, :, None, :]).reshape(E, nq, 9)
            Kv = np.matmul(tr(PN), np.concatenate([m.Bxa, Y], axis=2))
            J["Sx"] = Kx[:, :r * naf, :3].reshape(E, r, naf, 3)
            J["Sv"] = Kv[:, :r * naf, :3].reshape(E, r, naf, 3)
            J["Lx"] = Kx[:, r * naf:, 3:].reshape(E, naf, naf, 3, 3).transpose(0, 1, 3, 2, 4)
            J["Lv"] = Kv[:, r * naf:, 3:].reshape(E, naf, naf, 3, 3).transpose(0, 1, 3, 2, 4)
        else:
            PD = (rho[:, :, :, None] * ops.Dx3[:, :, None, :]).reshape(E, nq, r * naf)
            PN = (rho[:, :, :, None] * ops.Nx[:, :, None, :]).reshape(E, nq, r * naf)
            J["Sx"] = np.matmul(tr(PD), m.c).reshape(E, r, naf, 3)
            J["Sv"] = np.matmul(tr(PN), m.Bxa).reshape(E, r, naf, 3)
    elif lorentz:
        PD = (rhoM[:, :, :, None] * ops.Dx3[:, :, None, :]).reshape(E, nq, naf * naf)
        J["Lx"] = np.matmul(tr(PD), X.reshape(E, nq, 9)).reshape(E, naf, naf, 3, 3).transpose(0, 1, 3, 2, 4)
    return R, J
