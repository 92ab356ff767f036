"""Macro demo (docs/macro_export.md §5): the table's exports in a scikit-fem macro model.

Run: ``python examples/macro_demo.py TABLE [--out DIR] [--predictor secant|tangent|none]`` (default: the CI fixture
tests/data/table_v1_ci.nc); ``tests/test_macro_demo.py`` runs the checks.

Electrics. A two-potential sheet: warp potential phi_w conducting along the warp with the
warp layer's sheet conductance g_w, weft potential phi_f along the weft with g_f, exchange
c (phi_w - phi_f) per reference area (the table's ``yarn_sheet_conductance`` per yarn,
``contact_exchange_conductance``); electrodes act on phi_w. On a deformed mesh the
conductance is pushed forward, G = F G0 F^T / J (and c / J). It is compared with the sparse
resistor network of the same patch (``network_resistance``, the cell of
rve.homogenisation.network) built from the same network fit as g and c
(``rve.tables.macro.sheet_network_parameters``: R_yw, R_yf, R_c of the warp/weft fit where
the table has it, four probes; else the two-resistor fit R_y, R_c for both families):

1. uniform strain, bus-bar electrodes: equal to round-off at every stored strain, on the
   reference and on the deformed mesh (without the push-forward: off by the stretch);
2. pads on 4 of 16 warp ends of a 16 x 16-cell patch: the two-potential model within 5 %
   of the network, a one-potential sheet (G = g_w e1 e1 + g_f e2 e2) far off;
3. the network of the RVE from the fitted parameters gives the stored probe resistances to
   the fit residual.

Mechanics. A total-Lagrangian membrane with the decoupled fabric law of the exported
curves (``rve.tables.formats.fabric_curves``, the data of every export, as monotone cubic
Hermite splines in their own strain measure: warp N(eps_warp), weft N(eps_weft), shear
N(theta); pretension removed; energy density the integrals of the curves, tangent by
complex-step differentiation of the first Piola force of the same splines, exact): a strip
pulled along the warp gives the reaction per reference width = the table's N_xx at every
stored strain. Each step starts from a secant predictor (the tangent predictor on the first
step) and Newton converges quadratically (its residual and correction history is printed;
``strip_reactions``). Then a strip with a hole: its warp strain field feeds g_w, g_f, c
(eps) into the sheet model, the resistance change of the stretched sensor patch, checked
against its uniform-strain limit (no hole); a PNG of the strain and potential fields.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import NamedTuple, Optional, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

ROOT = Path(__file__).resolve().parents[1]


# ============================================================================ electrics
def network_resistance(nx: int, ny: int, Ry, Rc: float, plus_warps: Sequence[int],
                       minus_warps: Sequence[int]) -> float:
    """Resistance of the sparse network of an nx x ny-cell patch (nx cells along the warp x,
    ny warp yarns): every cell the four-terminal cell of rve.homogenisation.network (one
    warp and one weft yarn resistor, four R_c). ``Ry``: one R_y for both families or
    (R_yw, R_yf), warp and weft; 1 V on the x- ends of ``plus_warps``, 0 V on the x+ ends
    of ``minus_warps``, every other boundary insulating."""
    Ryw, Ryf = np.broadcast_to(np.asarray(Ry, float), (2,))

    def W(j, i):
        return j * (nx + 1) + i

    def F(i, j):
        return ny * (nx + 1) + i * (ny + 1) + j

    n = ny * (nx + 1) + nx * (ny + 1)
    jj, ii = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    jj, ii = jj.ravel(), ii.ravel()
    a_y = np.concatenate([W(jj, ii), F(ii, jj)])
    b_y = np.concatenate([W(jj, ii + 1), F(ii, jj + 1)])
    a_c = np.concatenate([W(jj, ii), W(jj, ii), W(jj, ii + 1), W(jj, ii + 1)])
    b_c = np.concatenate([F(ii, jj), F(ii, jj + 1), F(ii, jj), F(ii, jj + 1)])
    a = np.concatenate([a_y, a_c])
    b = np.concatenate([b_y, b_c])
    g = np.concatenate([np.full(jj.size, 1.0 / Ryw), np.full(jj.size, 1.0 / Ryf), np.full(a_c.size, 1.0 / Rc)])
    L = sp.coo_matrix((np.concatenate([g, g, -g, -g]), (np.concatenate([a, b, a, b]), np.concatenate([a, b, b, a]))),
                      shape=(n, n)).tocsr()
    fixed = np.array([W(j, 0) for j in plus_warps] + [W(j, nx) for j in minus_warps])
    fv = np.array([1.0] * len(plus_warps) + [0.0] * len(minus_warps))
    return 1.0 / _dirichlet_power(L, fixed, fv)[0]


def _dirichlet_power(K, fixed, fv) -> tuple:
    """(u^T K u, u) of the solution of K u = 0 on the free dofs with u = fv on ``fixed``."""
    n = K.shape[0]
    free = np.setdiff1d(np.arange(n), fixed)
    u = np.zeros(n)
    u[fixed] = fv
    u[free] = spla.spsolve(K[free][:, free].tocsc(), -(K[free][:, fixed] @ fv))
    return float(u @ (K @ u)), u


def sheet_resistance(mesh, g_warp, g_weft, c0, electrode_plus, electrode_minus, F=None, push_forward: bool = True,
                     one_potential: bool = False, return_fields: bool = False):
    """Resistance between two electrodes (node index arrays, on phi_w) of the two-potential
    sheet on the scikit-fem quad ``mesh`` (reference coordinates, mm). ``g_warp``,
    ``g_weft``: the reference sheet conductances (S) of the warp layer (conducting along
    e1) and the weft layer (along e2); ``c0``: the exchange (S mm-2); scalars or one value
    per element. ``F``: a uniform in-plane deformation gradient (2, 2): the model is solved
    on the deformed mesh x = F X with G = F G0 F^T / J (``push_forward``; else G0 as if the
    mesh were undeformed) and c / J. ``one_potential``: a single potential with the
    conductance of both layers, G = g_warp e1 e1 + g_weft e2 e2 (pushed forward; isotropic
    when g_warp = g_weft)."""
    from skfem import Basis, BilinearForm, ElementQuad1, asm
    from skfem.helpers import dot, grad

    F = np.eye(2) if F is None else np.asarray(F, float)
    J = float(np.linalg.det(F))
    m = mesh if np.allclose(F, np.eye(2)) else type(mesh)(F @ mesh.p, mesh.t)
    basis = Basis(m, ElementQuad1())
    ne = m.t.shape[1]
    gw, gf, c0 = (np.broadcast_to(np.asarray(v, float), (ne,)) for v in (g_warp, g_weft, c0))
    Fw = F if push_forward else np.eye(2)
    Jw = J if push_forward else 1.0
    # the warp conducts along e1, the weft along e2 (reference), pushed forward
    layers = [np.outer(Fw[:, d], Fw[:, d]) / Jw for d in (0, 1)]

    @BilinearForm
    def conduction(u, v, w):
        return w["gw"] * dot(np.einsum("ij,j...->i...", layers[0], grad(u)), grad(v)) \
            + w["gf"] * dot(np.einsum("ij,j...->i...", layers[1], grad(u)), grad(v))

    def layer(d):
        @BilinearForm
        def form(u, v, w):
            return w["g"] * dot(np.einsum("ij,j...->i...", layers[d], grad(u)), grad(v))
        return form

    @BilinearForm
    def mass(u, v, w):
        return w["c"] * u * v

    nq = basis.interpolate(np.zeros(basis.N)).shape  # the quadrature shape (elements, points)

    def q(values):
        return np.broadcast_to(values[:, None], nq)

    if one_potential:
        K = asm(conduction, basis, gw=q(gw), gf=q(gf)).tocsr()
    else:
        Kw = asm(layer(0), basis, g=q(gw))
        Kf = asm(layer(1), basis, g=q(gf))
        M = asm(mass, basis, c=q(c0 / Jw))
        K = sp.bmat([[Kw + M, -M], [-M, Kf + M]]).tocsr()
    fixed = np.concatenate([electrode_plus, electrode_minus])
    fv = np.concatenate([np.ones(len(electrode_plus)), np.zeros(len(electrode_minus))])
    P, u = _dirichlet_power(K, fixed, fv)
    if return_fields:
        return 1.0 / P, u
    return 1.0 / P


def patch_mesh(nx: int, ny: int, a: float, refine: int = 2):
    """Quad mesh of an nx x ny-cell patch of cell size ``a`` (mm), ``refine`` elements per cell."""
    from skfem import MeshQuad

    return MeshQuad.init_tensor(np.linspace(0, nx * a, nx * refine + 1), np.linspace(0, ny * a, ny * refine + 1))


def electrodes(mesh, nx: int, a: float, ylo: float, yhi: float):
    """Node indices on x = 0 and x = nx a with ylo <= y <= yhi."""
    x, y = mesh.p
    tol = 1e-9 * max(1.0, nx * a)
    on = (y >= ylo - tol) & (y <= yhi + tol)
    return np.nonzero(on & (np.abs(x) < tol))[0], np.nonzero(on & (np.abs(x - nx * a) < tol))[0]


def table_sheet(ds, mode: str = "uniaxial") -> dict:
    """The sheet model's parameters of ``mode`` at its stored strains, one network fit for
    the sheet and the network (``rve.tables.macro.sheet_network_parameters``: the warp/weft
    fit where the table has it, else the two-resistor fit for both families):
    {"strain", "R_y" (n, 2) warp/weft, "R_c", "g" (n, 2) warp/weft, "c", "network_fit"}."""
    from rve.tables.macro import sheet_network_parameters

    net = sheet_network_parameters(ds)
    s, n = ds.sel(mode=mode), net.sel(mode=mode)
    Ry = n["yarn_resistance"].transpose("strain", "yarn").values
    Rc = n["contact_resistance"].values
    ok = np.isfinite(Rc) & np.isfinite(Ry).all(axis=1)
    return {"strain": s["strain"].values[ok], "R_y": Ry[ok], "R_c": Rc[ok],
            "g": s["yarn_sheet_conductance"].transpose("strain", "yarn").values[ok],
            "c": s["contact_exchange_conductance"].values[ok], "network_fit": net.attrs["network_fit"]}


def check_busbar(ds, n: int = 4, refine: int = 1) -> dict:
    """Check 1: max relative difference macro vs network at every stored strain of the
    uniaxial mode (reference mesh, deformed mesh with push-forward, and without it)."""
    a = float(ds["yarn_pitch"])
    t = table_sheet(ds)
    m = patch_mesh(n, n, a, refine)
    ep, em = electrodes(m, n, a, 0.0, n * a)
    out = {"reference": 0.0, "deformed": 0.0, "no_push_forward": 0.0, "network_fit": t["network_fit"]}
    for k, e in enumerate(t["strain"]):
        Rn = network_resistance(n, n, t["R_y"][k], t["R_c"][k], range(n), range(n))
        F = np.diag([1.0 + e, 1.0])
        for key, kw in (("reference", {}), ("deformed", {"F": F}), ("no_push_forward", {"F": F, "push_forward": False})):
            R = sheet_resistance(m, t["g"][k, 0], t["g"][k, 1], t["c"][k], ep, em, **kw)
            out[key] = max(out[key], abs(R / Rn - 1.0))
    return out


def check_pads(ds, strain: float = 0.0, n: int = 16, pads=range(6, 10), refine: int = 4) -> dict:
    """Check 2: pads on warp ends ``pads`` of an n x n patch: relative error of the two- and
    one-potential models against the network."""
    a = float(ds["yarn_pitch"])
    t = table_sheet(ds)
    k = int(np.argmin(np.abs(t["strain"] - strain)))
    Rn = network_resistance(n, n, t["R_y"][k], t["R_c"][k], pads, pads)
    m = patch_mesh(n, n, a, refine)
    ep, em = electrodes(m, n, a, min(pads) * a, (max(pads) + 1) * a)
    gw, gf, c = t["g"][k, 0], t["g"][k, 1], t["c"][k]
    R2 = sheet_resistance(m, gw, gf, c, ep, em)
    R1 = sheet_resistance(m, gw, gf, c, ep, em, one_potential=True)
    return {"network": Rn, "two_potential": R2 / Rn - 1.0, "one_potential": R1 / Rn - 1.0,
            "transfer_length_mm": float(np.sqrt(gw / (2 * c))), "network_fit": t["network_fit"]}


def check_probes(ds) -> float:
    """Check 3: max over states of |rms log misfit of the RVE network's probe resistances -
    the fit residual| for the network fit the sheet model uses (the warp/weft fit with
    ``network_fit_residual_warp_weft``, else the two-resistor fit with
    ``network_fit_residual``)."""
    import json

    from rve.homogenisation.network import YarnNetwork
    from rve.tables.macro import sheet_network_parameters

    fab = json.loads(ds.attrs["fabric"])
    net = YarnNetwork(int(fab["n_warp"]), int(fab["n_weft"]))
    terms = {}
    for p, txt in zip(ds["probe"].values, ds["probe_terminals"].values):
        if txt:
            terms[str(p)] = tuple(_terminal(t.strip()) for t in str(txt).split("|"))
    pars = sheet_network_parameters(ds)
    worst = 0.0
    for mode in ds["mode"].values:
        for e in ds["strain"].values:
            s, q = ds.sel(mode=mode, strain=e), pars.sel(mode=mode, strain=e)
            (ryw, ryf), rc = q["yarn_resistance"].values, float(q["contact_resistance"])
            if not np.isfinite([ryw, ryf, rc]).all():
                continue
            model = dict(zip(terms, net.solve_pairs3(list(terms.values()), ryw, ryf, rc)[0]))
            meas = {p: float(s["probe_resistance"].sel(probe=p)) for p in terms}
            rms = np.sqrt(np.mean([np.log(model[p] / meas[p]) ** 2 for p in terms]))
            resid = s["network_fit_residual_warp_weft"] if bool(q["warp_weft_fit"]) else s["network_fit_residual"]
            worst = max(worst, abs(rms - float(resid)))
    return worst


def _terminal(text: str):
    d = "warp" if text.startswith("warp") else "weft"
    return d, int(text[len(d):-1]), text[-1]


# ============================================================================ mechanics
class FabricLaw:
    """Decoupled fabric law of the exported Hermite curves (rve.tables.formats.hermite_eval):
    energy density W(F) = int N_warp d eps_warp + int N_weft d eps_weft + int N_shear d theta,
    eps = |F e_i| - 1, theta = asin(a.b / |a||b|) the angle drop; first Piola P = dW/dF
    (N mm-1), tangent by complex-step differentiation of P (exact to round-off)."""

    def __init__(self, entries: dict):
        self.e = entries

    @staticmethod
    def _h(entry, x):
        """Hermite value and slope at (possibly complex) x, linear extension outside."""
        t, p, m = (np.asarray(entry[k], float) for k in ("t", "p", "m"))
        xr = np.real(x)
        i = np.clip(np.searchsorted(t, xr, side="right") - 1, 0, len(t) - 2)
        h = t[i + 1] - t[i]
        s = (x - t[i]) / h
        val = ((1 + 2 * s) * (1 - s) ** 2 * p[i] + s * (1 - s) ** 2 * h * m[i]
               + s * s * (3 - 2 * s) * p[i + 1] + s * s * (s - 1) * h * m[i + 1])
        lo, hi = xr < t[0], xr > t[-1]
        val = np.where(lo, p[0] + m[0] * (x - t[0]), val)
        val = np.where(hi, p[-1] + m[-1] * (x - t[-1]), val)
        return val

    def piola(self, F):
        """P (2, 2, ...) of F (2, 2, ...)."""
        a, b = F[:, 0], F[:, 1]
        la, lb = np.sqrt(np.sum(a * a, axis=0)), np.sqrt(np.sum(b * b, axis=0))
        na, nb = self._h(self.e["warp"], la - 1.0), self._h(self.e["weft"], lb - 1.0)
        P = np.zeros_like(F)
        P[:, 0] = na * a / la
        P[:, 1] = nb * b / lb
        if "shear" in self.e:
            cosang = np.sum(a * b, axis=0) / (la * lb)
            ns = self._h(self.e["shear"], np.arcsin(cosang))
            dth = ns / np.sqrt(1.0 - cosang ** 2)  # d theta / d cos = 1 / sqrt(1 - cos^2)
            P[:, 0] += dth * (b / (la * lb) - cosang * a / la ** 2)
            P[:, 1] += dth * (a / (la * lb) - cosang * b / lb ** 2)
        return P

    def tangent(self, F):
        """dP/dF (2, 2, 2, 2, ...) by complex step."""
        h = 1e-30
        A = np.zeros((2, 2) + F.shape)
        for k in range(2):
            for L in range(2):
                Fc = F.astype(complex)
                Fc[k, L] += 1j * h
                A[:, :, k, L] = np.imag(self.piola(Fc)) / h
        return A


class StripResult(NamedTuple):
    """What :func:`strip_reactions` returns: the reaction per reference width at x = L of
    every step, the Newton iterations of every step (tangent solves, the predictor's
    included), the residual history of every step (|R_free| of the predictor and of every
    iterate, N), the norms of the Newton corrections of every step (mm; the predictor's
    solve not included) and the last state (mesh, basis, u, law)."""
    reaction: np.ndarray
    iterations: list
    residuals: list
    corrections: list
    state: tuple


def strip_reactions(entries: dict, strains, L: float = 20.0, W: float = 8.0, n: int = 8, hole: float = 0.0,
                    rtol: float = 1e-12, max_iter: int = 25, predictor: str = "secant",
                    law: Optional[FabricLaw] = None, verbose: bool = False) -> StripResult:
    """Total-Lagrangian membrane strip [0, L] x [0, W] (a hole of radius ``hole`` at the
    centre): x = 0 held in x (one node in y), x = L moved to L (1 + eps) in x, eps through
    ``strains`` in turn from the undeformed strip.

    Each step starts from a predictor: the secant extrapolation of the last two converged
    states, u_n + (eps - eps_n) / (eps_n - eps_{n-1}) (u_n - u_{n-1}) (exact for the
    uniform strip), or, with one converged state only (the first step), the tangent
    predictor u_n + du, K(u_n) du = -R(u_n) with du = (eps - eps_n) L on x = L (one tangent
    solve, counted as an iteration). ``predictor``: "secant" (that), "tangent" (the tangent
    predictor at every step) or "none" (the previous state with x = L moved: what the demo
    did first; the boundary column of elements, width h, then starts each step at a strain
    of about (eps - eps_n) L / h, 0.5 for the default table's steps, outside the table, and
    Newton spends its first iterations pulling it back: 6 iterations per step on the
    default table). Newton with the exact tangent (complex step of the
    first Piola force of the same Hermite curves) then converges when
    |R_free| <= rtol |R_fixed| (the reactions: relative to the step's force scale, in no
    particular unit) or |R_free| = 0. ``law``: the material (default FabricLaw(entries)).
    ``verbose``: print each step's residual and correction history (quadratic convergence:
    |du_k+1| / |du_k|^2 bounded)."""
    from skfem import Basis, BilinearForm, ElementQuad1, ElementVector, LinearForm, MeshQuad, asm

    if predictor not in ("secant", "tangent", "none"):
        raise ValueError(f"predictor must be 'secant', 'tangent' or 'none', got {predictor!r}")
    m = MeshQuad.init_tensor(np.linspace(0, L, int(n * L / W) + 1), np.linspace(0, W, n + 1))
    if hole > 0:
        c = m.p[:, m.t].mean(axis=1)
        m = m.remove_elements(np.nonzero(np.hypot(c[0] - L / 2, c[1] - W / 2) < hole)[0])
    basis = Basis(m, ElementVector(ElementQuad1()))
    law = FabricLaw(entries) if law is None else law
    left = basis.get_dofs(lambda x: np.isclose(x[0], 0.0))
    right = basis.get_dofs(lambda x: np.isclose(x[0], L))
    lx, rx = left.nodal["u^1"], right.nodal["u^1"]
    # the node at (0, 0) held in y: the rigid translation in y (a facet test, get_dofs(lambda),
    # never holds at a corner: no facet midpoint is there)
    corner = basis.nodal_dofs[1, m.nodes_satisfying(lambda x: np.isclose(x[0], 0.0) & np.isclose(x[1], 0.0))]
    if corner.size != 1:
        raise RuntimeError(f"expected one corner node at (0, 0), found {corner.size}")
    D = np.concatenate([lx, rx, corner])
    free = np.setdiff1d(np.arange(basis.N), D)

    # the law is evaluated once per assembly at the quadrature points (not per local dof pair)
    @LinearForm
    def residual(v, w):
        return np.einsum("ij...,ij...->...", w["P"], v.grad)

    @BilinearForm
    def jacobian(du, v, w):
        return np.einsum("ijkl...,kl...,ij...->...", w["A"], du.grad, v.grad)

    def forces(u):
        """(F at the quadrature points, the nodal force vector R(u))."""
        Fq = np.eye(2)[:, :, None, None] + basis.interpolate(u).grad
        return Fq, asm(residual, basis, P=law.piola(Fq))

    def stiffness(Fq):
        return asm(jacobian, basis, A=law.tangent(Fq)).tocsr()

    def solve(K, rhs):
        return spla.spsolve(K[free][:, free].tocsc(), rhs)

    history = [(0.0, np.zeros(basis.N))]  # converged (strain, u); the undeformed strip first
    reactions, iters, residuals, corrections = [], [], [], []
    for e in strains:
        (e1, u1) = history[-1]
        solves = 0
        if predictor == "secant" and len(history) >= 2 and history[-1][0] != history[-2][0]:
            e0, u0 = history[-2]
            u = u1 + (e - e1) / (e1 - e0) * (u1 - u0)
        else:
            u = u1.copy()
            if predictor != "none" and e != e1:  # the Dirichlet increment spread through K(u_n)
                Fq, R = forces(u)
                K = stiffness(Fq)
                du = np.zeros(basis.N)
                du[rx] = (e - e1) * L
                u[free] += solve(K, -(R[free] + K[free] @ du))
                u[rx] += du[rx]
                solves = 1
        u[rx], u[lx], u[corner] = e * L, 0.0, 0.0
        hist, steps = [], []
        while True:
            Fq, R = forces(u)
            r = float(np.linalg.norm(R[free]))
            hist.append(r)
            if r == 0.0 or r <= rtol * float(np.linalg.norm(R[D])):
                break
            if solves >= max_iter:
                raise RuntimeError(f"Newton did not converge at strain {e}: |R_free| history {hist}")
            du = solve(stiffness(Fq), R[free])
            u[free] -= du
            steps.append(float(np.linalg.norm(du)))
            solves += 1
        if verbose:
            print(f"  strain {e:.4g}: {solves} iterations; |R_free| [N] = " + ", ".join(f"{h:.2e}" for h in hist)
                  + "; Newton corrections |du| [mm] = " + (", ".join(f"{h:.2e}" for h in steps) or "none")
                  + (f" (|du_k+1| / |du_k|^2 = {', '.join(f'{q:.3g}' for q in quadratic_ratios(steps))} mm-1)"
                     if len(steps) > 1 else ""))
        history.append((float(e), u.copy()))
        iters.append(solves)
        residuals.append(hist)
        corrections.append(steps)
        reactions.append(R[rx].sum() / W)
    return StripResult(np.array(reactions), iters, residuals, corrections, (m, basis, u, law))


def quadratic_ratios(corrections) -> list:
    """|du_k+1| / |du_k|^2 of the Newton corrections of a step (mm-1): bounded as du -> 0
    under quadratic convergence, growing like 1 / |du_k| under linear convergence."""
    d = np.asarray(corrections, float)
    return [float(d[k + 1] / d[k] ** 2) for k in range(len(d) - 1) if d[k] > 0]


def warp_strain_field(m, basis, u):
    """Element mean of the warp yarn strain |F e1| - 1 of the displacement ``u``."""
    uw = basis.interpolate(u)
    Fq = np.eye(2)[:, :, None, None] + uw.grad
    return (np.sqrt(Fq[0, 0] ** 2 + Fq[1, 0] ** 2) - 1.0).mean(axis=1)


def sensor_patch(ds, entries, strain: float, hole: float, L: float = 20.0, W: float = 8.0, n: int = 8,
                 max_step: float = 0.025, predictor: str = "secant", verbose: bool = False):
    """Resistance change R(strain)/R(0) - 1 of a bus-bar sensor patch (the strip, warp along
    x, pulled through the table's stored strains up to ``strain``, each interval cut into
    steps of at most ``max_step``, the default run's strain step), the strip's warp strain
    field fed into g_warp(eps), g_weft(eps), c(eps) of the table (uniaxial mode at the local
    warp strain, linear between the stored strains), solved on the reference configuration
    (the pull-back of the pushed-forward model). Returns (relative change, fields for the
    figure and the strip's StripResult under "strip")."""
    t = table_sheet(ds)
    eps_t, g_t, c_t = t["strain"], t["g"], t["c"]
    knots = [0.0] + [float(e) for e in eps_t if 0.0 < e < strain] + [float(strain)]
    path = [float(x) for a, b in zip(knots[:-1], knots[1:])
            for x in np.linspace(a, b, max(1, int(np.ceil((b - a) / max_step - 1e-9))) + 1)[1:]]
    strip = strip_reactions(entries, path, L=L, W=W, n=n, hole=hole, predictor=predictor, verbose=verbose)
    m, basis, u, law = strip.state
    ew = warp_strain_field(m, basis, u)
    gw, gf = np.interp(ew, eps_t, g_t[:, 0]), np.interp(ew, eps_t, g_t[:, 1])
    c = np.interp(ew, eps_t, c_t)
    ep, em = electrodes(m, int(round(L)), 1.0, 0.0, W)
    R, phi = sheet_resistance(m, gw, gf, c, ep, em, return_fields=True)
    R0 = sheet_resistance(m, *(np.interp(0.0, eps_t, v) for v in (g_t[:, 0], g_t[:, 1], c_t)), ep, em)
    return R / R0 - 1.0, {"mesh": m, "warp_strain": ew, "phi_w": phi[:m.p.shape[1]], "u": u, "basis": basis,
                          "strip": strip}


def figure(fields, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    m = fields["mesh"]
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), constrained_layout=True)
    polys = m.p.T[m.t.T]
    pc = PolyCollection(polys, array=fields["warp_strain"], cmap="viridis")
    axes[0].add_collection(pc)
    fig.colorbar(pc, ax=axes[0], label="warp yarn strain [1]")
    tri = np.hstack([m.t[[0, 1, 2]], m.t[[0, 2, 3]]]).T
    tc = axes[1].tripcolor(m.p[0], m.p[1], fields["phi_w"], triangles=tri, shading="gouraud", cmap="plasma")
    fig.colorbar(tc, ax=axes[1], label="warp potential phi_w [V]")
    for ax, title in zip(axes, ("strip with a hole: warp strain (reference configuration)",
                                "bus-bar sensor patch: warp potential")):
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(title)
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def hermite_law_entries(ds) -> dict:
    """The fabric curves of the table as Hermite entries (``rve.tables.formats``), keyed
    warp / weft / shear, abscissa = the curve's strain measure (warp / weft strain; the
    angle drop for the shear curve)."""
    from rve.tables.formats import _pchip_slopes, fabric_curves, select_params

    return {c.key: {"t": c.x.tolist(), "p": c.y.tolist(), "m": _pchip_slopes(c.x, c.y).tolist()}
            for c in fabric_curves(select_params(ds))}


def main(argv: Optional[Sequence[str]] = None) -> int:
    from rve.tables import open_table

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("table", nargs="?", default=str(ROOT / "tests" / "data" / "table_v1_ci.nc"))
    p.add_argument("--out", default="results/macro_demo")
    p.add_argument("--predictor", choices=("secant", "tangent", "none"), default="secant",
                   help="the strips' Newton predictor (strip_reactions; 'none': the first version's)")
    args = p.parse_args(argv)
    ds = open_table(args.table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print("table:", args.table, "| network fit of the sheet model and the network:", table_sheet(ds)["network_fit"])
    print("check 1 (bus-bar, max rel. diff):", check_busbar(ds))
    print("check 2 (pads):", check_pads(ds))
    print("check 3 (probes, |rms - fit residual|):", check_probes(ds))
    entries = hermite_law_entries(ds)
    strains = [float(e) for e in ds["strain"].values]
    N = ds["membrane_force"].sel(mode="uniaxial", edge="x", component="x").values
    N = N - float(ds["membrane_force_at_zero_strain"].sel(mode="uniaxial", edge="x", component="x"))
    print("strip (Newton per step):")
    strip = strip_reactions(entries, strains, predictor=args.predictor, verbose=True)
    print("strip: reaction / width", strip.reaction, "\n  max |reaction/width - N_xx| / max |N_xx| =",
          float(np.max(np.abs(strip.reaction - N)) / np.max(np.abs(N))), "\n  Newton iterations", strip.iterations)
    print("strip with a hole (Newton per step):")
    dR, fields = sensor_patch(ds, entries, strains[-1], hole=2.0, predictor=args.predictor, verbose=True)
    print("strip with a hole: Newton iterations", fields["strip"].iterations)
    dR0, _ = sensor_patch(ds, entries, strains[-1], hole=0.0)
    print(f"sensor patch: dR/R = {dR:.6g} with the hole, {dR0:.6g} uniform")
    print("figure:", figure(fields, out / "macro_demo_fields.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
