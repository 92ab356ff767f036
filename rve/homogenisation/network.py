"""The resistor-network model of a woven RVE and its fit to probe resistances.

Thesis Fig. 7.2.1 as read in docs/lookup_tables.md (§3 "Network model and the derivation
of R_y and R_c"): every yarn crossing
is a cell with one warp and one weft yarn resistor R_y and four warp-weft contact
resistors R_c. This module owns the physics of that reading; the table builder
(``rve.tables.build``) calls :func:`fit_network` once per stored state.

Contract
--------
* :class:`YarnNetwork` ``(n_warp, n_weft)``: topology (nodes, yarn and contact edges,
  yarn-end terminal nodes) and batched two-terminal solves
  (:meth:`YarnNetwork.solve_pairs` -> resistances and Joule power fractions).
* :func:`default_probe_terminals` ``(n_warp, n_weft)``: the three thesis probes as
  (+ terminal, - terminal) yarn ends ``(direction, index, end)``.
* :func:`fit_network` ``(measured, network, probes)``: (R_y, R_c, rms log residual) by
  least squares on log R; NaNs with fewer than two usable probes.
* :meth:`YarnNetwork.solve_pairs3` and :func:`fit_network3` ``(measured, network, probes)``:
  the same with separate warp and weft yarn resistances, (R_yw, R_yf, R_c, rms log
  residual); needs four usable probes (three unknowns, one probe left over as a check:
  docs/macro_export.md §2), NaNs otherwise.
* :func:`network_probes` ``(cfg, fab)``: the probes of an ``RVEConfig`` as yarn-end
  terminals of the model ({} for a knit or a probe that is not a warp/weft end).

Depends on numpy and scipy only (no other rve module): ``rve.tables`` imports it, never
the other way round (docs/rve_pipeline.md "Where it lives").
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Mapping, Optional, Sequence

import numpy as np

__all__ = ["TERMINALS", "Terminal", "YarnNetwork", "default_probe_terminals", "fit_network", "fit_network3",
           "network_probes", "terminal_text"]

log = logging.getLogger("rve.homogenisation.network")

#: the two ends of a probe: + at the test voltage, - at 0 V
TERMINALS = ("+", "-")

Terminal = tuple[str, int, str]  # (direction 'warp'|'weft', yarn index, end '-'|'+')


def default_probe_terminals(n_warp: int = 4, n_weft: int = 4,
                            weft_probe: bool = False) -> dict[str, tuple[Terminal, Terminal]]:
    """The three thesis probes (thesis Fig. 7.2.2; docs/rve_pipeline.md "Probe definitions")
    as (+ terminal, - terminal) yarn ends.

    With yarns 2 mm apart and centred, warp ``n_warp//2 - 1`` is the one at y = -1,
    ``n_warp//2`` at y = +1 and weft ``n_weft//2 - 1`` at x = -1:

    * probe1: the y = -1 warp yarn end to end (x+ end | x- end);
    * probe2: its x = +4 end to the x = -4 end of the y = +1 warp yarn (parallel yarns);
    * probe3: its x = +4 end to the y = +4 end of the x = -1 weft yarn (crossing yarns);
    * probe4 (``weft_probe``): the x = -1 weft yarn end to end (y+ end | y- end), so warp
      and weft yarn resistances are fitted separately (docs/macro_export.md §2).
    """
    if n_warp < 2 or n_weft < 2:
        raise ValueError("the thesis probes need at least 2 warp and 2 weft yarns")
    j1, j2, i1 = n_warp // 2 - 1, n_warp // 2, n_weft // 2 - 1
    out = {
        "probe1": (("warp", j1, "+"), ("warp", j1, "-")),
        "probe2": (("warp", j1, "+"), ("warp", j2, "-")),
        "probe3": (("warp", j1, "+"), ("weft", i1, "+")),
    }
    if weft_probe:
        out["probe4"] = (("weft", i1, "+"), ("weft", i1, "-"))
    return out


def terminal_text(t: Terminal) -> str:
    """``('warp', 1, '+')`` -> ``'warp1+'``."""
    return f"{t[0]}{t[1]}{t[2]}"


@dataclass(frozen=True)
class YarnNetwork:
    """Resistor network of a woven RVE with ``n_warp`` warp yarns (along x) and ``n_weft``
    weft yarns (along y), our reading of thesis Fig. 7.2.1.

    Every crossing (cell) of warp j and weft i is a four-terminal cell: the warp yarn
    enters it at node W[j, i] and leaves at W[j, i+1], the weft at F[i, j] and F[i, j+1].
    The cell holds two yarn resistors R_y (W[j,i]-W[j,i+1], F[i,j]-F[i,j+1]) and four
    contact resistors R_c (each of W[j,i], W[j,i+1] to each of F[i,j], F[i,j+1]).
    Neighbouring cells share their edge nodes, so a yarn is a chain of R_y and the RVE
    has n_warp*n_weft*2 yarn and n_warp*n_weft*4 contact resistors. Yarn ends are the
    nodes W[j, 0] (warp, '-', x-), W[j, n_weft] ('+', x+), F[i, 0] (weft, '-', y-) and
    F[i, n_warp] ('+', y+); all other boundaries are insulating.

    A probe resistance is homogeneous of degree one in (R_y, R_c):
    ``R_probe = R_y * f(R_c / R_y)``; ``d log R_probe / d log R_c`` is the fraction of the
    probe's Joule power dissipated in the contact resistors.
    """

    n_warp: int = 4
    n_weft: int = 4

    def __post_init__(self):
        if self.n_warp < 1 or self.n_weft < 1:
            raise ValueError("need at least one warp and one weft yarn")

    # ----------------------------------------------------------------- topology
    @property
    def n_nodes(self) -> int:
        return self.n_warp * (self.n_weft + 1) + self.n_weft * (self.n_warp + 1)

    def warp_node(self, j: int, i: int) -> int:
        return j * (self.n_weft + 1) + i

    def weft_node(self, i: int, j: int) -> int:
        return self.n_warp * (self.n_weft + 1) + i * (self.n_warp + 1) + j

    def terminal_node(self, terminal: Terminal) -> int:
        """Node of a yarn end ``(direction, index, end)``, e.g. ``('warp', 1, '+')``."""
        direction, index, end = terminal
        if end not in TERMINALS:
            raise ValueError(f"terminal end must be '+' or '-', got {end!r}")
        if direction == "warp":
            if not 0 <= index < self.n_warp:
                raise ValueError(f"warp index {index} outside 0..{self.n_warp - 1}")
            return self.warp_node(index, self.n_weft if end == "+" else 0)
        if direction == "weft":
            if not 0 <= index < self.n_weft:
                raise ValueError(f"weft index {index} outside 0..{self.n_weft - 1}")
            return self.weft_node(index, self.n_warp if end == "+" else 0)
        raise ValueError(f"terminal direction must be 'warp' or 'weft', got {direction!r}")

    @cached_property
    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(yarn edges (n, 2), contact edges (m, 2)) as node index pairs."""
        yarn, contact = [], []
        for j in range(self.n_warp):
            for i in range(self.n_weft):
                w0, w1 = self.warp_node(j, i), self.warp_node(j, i + 1)
                f0, f1 = self.weft_node(i, j), self.weft_node(i, j + 1)
                yarn += [(w0, w1), (f0, f1)]
                contact += [(w0, f0), (w0, f1), (w1, f0), (w1, f1)]
        return np.array(yarn, dtype=int), np.array(contact, dtype=int)

    def _laplacian(self, edges: np.ndarray) -> np.ndarray:
        L = np.zeros((self.n_nodes, self.n_nodes))
        a, b = edges[:, 0], edges[:, 1]
        np.add.at(L, (a, a), 1.0)
        np.add.at(L, (b, b), 1.0)
        np.add.at(L, (a, b), -1.0)
        np.add.at(L, (b, a), -1.0)
        return L

    @cached_property
    def _laplacians(self) -> tuple[np.ndarray, np.ndarray]:
        ye, ce = self.edges
        return self._laplacian(ye), self._laplacian(ce)

    # ----------------------------------------------------------------- solves
    def solve_pairs(self, pairs: Sequence[tuple[Terminal, Terminal]], R_y, R_c):
        """Batched two-terminal solves.

        ``pairs``: (+ terminal, - terminal) per probe; ``R_y``, ``R_c``: scalars or arrays
        of one shape S. Returns ``(R, p_yarn, p_contact)``, each of shape S + (n_pairs,):
        the resistances and the fractions of the Joule power dissipated in the yarn and in
        the contact resistors (= d log R / d log R_y and d log R / d log R_c; they sum to 1).

        The potentials for 1 A injected at + and drawn at - are ``L^+ (e_+ - e_-)``,
        computed as ``(L + s 1 1^T / n)^-1 (e_+ - e_-)`` (exact for right-hand sides
        orthogonal to the constants, which the network's connectedness makes invertible).
        """
        R_y = np.asarray(R_y, dtype=float)
        R_c = np.asarray(R_c, dtype=float)
        shape = np.broadcast_shapes(R_y.shape, R_c.shape)
        ry = np.broadcast_to(R_y, shape).reshape(-1)
        rc = np.broadcast_to(R_c, shape).reshape(-1)
        if not (np.all(ry > 0) and np.all(rc > 0) and np.all(np.isfinite(ry))
                and np.all(np.isfinite(rc))):
            raise ValueError("R_y and R_c must be positive and finite")
        n = self.n_nodes
        U = self._terminal_incidence(pairs)
        Ly, Lc = self._laplacians
        gy, gc = 1.0 / ry, 1.0 / rc
        s = (gy + gc)[:, None, None] / n
        A = Ly[None] * gy[:, None, None] + Lc[None] * gc[:, None, None] + s
        V = np.linalg.solve(A, np.broadcast_to(U, (len(ry),) + U.shape))  # (m, n, P)
        R = np.einsum("np,mnp->mp", U, V)
        ye, ce = self.edges
        dy = V[:, ye[:, 0], :] - V[:, ye[:, 1], :]
        dc = V[:, ce[:, 0], :] - V[:, ce[:, 1], :]
        py = np.einsum("mep,mep->mp", dy, dy) * gy[:, None] / R
        pc = np.einsum("mep,mep->mp", dc, dc) * gc[:, None] / R
        out = shape + (len(pairs),)
        return R.reshape(out), py.reshape(out), pc.reshape(out)

    def _terminal_incidence(self, pairs) -> np.ndarray:
        """(n_nodes, n_pairs): +1 at each probe's first terminal node, -1 at its second."""
        U = np.zeros((self.n_nodes, len(pairs)))
        for k, (plus, minus) in enumerate(pairs):
            a, b = self.terminal_node(plus), self.terminal_node(minus)
            if a == b:
                raise ValueError(f"probe {k}: the two terminals are the same yarn end")
            U[a, k], U[b, k] = 1.0, -1.0
        return U

    @cached_property
    def _laplacians3(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ye, ce = self.edges
        return self._laplacian(ye[0::2]), self._laplacian(ye[1::2]), self._laplacian(ce)

    def solve_pairs3(self, pairs: Sequence[tuple[Terminal, Terminal]], R_yw: float, R_yf: float, R_c: float):
        """Two-terminal solves with separate warp (``R_yw``) and weft (``R_yf``) yarn
        resistances (scalars). Returns ``(R, p_warp, p_weft, p_contact)``, each (n_pairs,):
        resistances and Joule power fractions (= d log R / d log of each resistance)."""
        vals = np.array([R_yw, R_yf, R_c], dtype=float)
        if not (np.all(vals > 0) and np.all(np.isfinite(vals))):
            raise ValueError("R_yw, R_yf and R_c must be positive and finite")
        n = self.n_nodes
        U = self._terminal_incidence(pairs)
        g = 1.0 / vals
        Ls = self._laplacians3
        A = sum(gi * L for gi, L in zip(g, Ls)) + g.sum() / n
        V = np.linalg.solve(A, U)
        R = np.einsum("np,np->p", U, V)
        fr = [np.einsum("np,nm,mp->p", V, L, V) * gi / R for gi, L in zip(g, Ls)]
        return R, fr[0], fr[1], fr[2]

    def resistance(self, plus: Terminal, minus: Terminal, R_y: float, R_c: float) -> float:
        """Two-terminal resistance between yarn ends ``plus`` and ``minus``."""
        return float(self.solve_pairs([(plus, minus)], R_y, R_c)[0][0])

    def probe_resistances(self, R_y: float, R_c: float,
                          probes: Optional[Mapping[str, tuple[Terminal, Terminal]]] = None
                          ) -> dict[str, float]:
        """Forward model: resistance of each probe (default: the three thesis probes)."""
        probes = default_probe_terminals(self.n_warp, self.n_weft) if probes is None else probes
        R = self.solve_pairs(list(probes.values()), R_y, R_c)[0]
        return {name: float(r) for name, r in zip(probes, R)}


_RHO_GRID = np.logspace(-12.0, 12.0, 241)  # R_c / R_y start grid of the fit


def fit_network(measured: Mapping[str, float], network: Optional[YarnNetwork] = None,
                probes: Optional[Mapping[str, tuple[Terminal, Terminal]]] = None,
                _grid_cache: Optional[dict] = None) -> tuple[float, float, float]:
    """R_y, R_c from measured probe resistances under :class:`YarnNetwork`.

    ``measured`` maps probe names to resistances (ohm); the probes used are those of
    ``probes`` (default: :func:`default_probe_terminals`) with a positive finite value.
    Minimises sum_p (log R_p(R_y, R_c) - log R_p^measured)^2 over (log R_y, log R_c):
    a scan of R_c / R_y over 1e-12..1e12 (for a given ratio the best log R_y is
    explicit, since R_p = R_y f_p(R_c/R_y)) followed by Levenberg-Marquardt with the exact
    Jacobian (power fractions; trust-region reflective, log R_y and log R_c within 35 of
    the measured log R). With two probes the fit is an exact inversion.

    Returns ``(R_y, R_c, rms_log_residual)``; NaNs when fewer than two probes are usable.
    """
    from scipy.optimize import least_squares

    network = network or YarnNetwork()
    probes = default_probe_terminals(network.n_warp, network.n_weft) if probes is None else probes
    names = [n for n in probes
             if n in measured and np.isfinite(measured[n]) and float(measured[n]) > 0]
    nan = (math.nan, math.nan, math.nan)
    if len(names) < 2:
        return nan
    logm = np.log(np.array([float(measured[n]) for n in names]))

    pairs = [probes[n] for n in names]
    # start: f_p(rho) = R_p(1, rho) on a grid of rho = R_c / R_y (cached per probe set)
    key = (network, tuple(pairs))
    cache = _grid_cache if _grid_cache is not None else {}
    if key not in cache:
        cache[key] = np.log(network.solve_pairs(pairs, 1.0, _RHO_GRID)[0])
    logf = cache[key]  # (n_rho, n_probes)
    logRy = np.mean(logm[None, :] - logf, axis=1)
    res = logf + logRy[:, None] - logm[None, :]
    k = int(np.argmin(np.sum(res ** 2, axis=1)))
    x0 = np.array([logRy[k], logRy[k] + math.log(_RHO_GRID[k])])

    def fun(x):
        return np.log(network.solve_pairs(pairs, math.exp(x[0]), math.exp(x[1]))[0]) - logm

    def jac(x):
        _, py, pc = network.solve_pairs(pairs, math.exp(x[0]), math.exp(x[1]))
        return np.column_stack([py, pc])

    try:
        # bounds keep an inconsistent set of probes from driving exp() out of range
        lo, hi = float(logm.min()) - 35.0, float(logm.max()) + 35.0
        x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
        sol = least_squares(fun, x0, jac=jac, method="trf", bounds=([lo, lo], [hi, hi]),
                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=100)
        x = sol.x
        resid = fun(x)
    except (np.linalg.LinAlgError, ValueError, OverflowError) as exc:  # pragma: no cover
        log.warning("network fit failed: %s", exc)
        return nan
    return float(math.exp(x[0])), float(math.exp(x[1])), float(np.sqrt(np.mean(resid ** 2)))



def fit_network3(measured: Mapping[str, float], network: Optional[YarnNetwork] = None,
                 probes: Optional[Mapping[str, tuple[Terminal, Terminal]]] = None) -> tuple[float, float, float, float]:
    """R_yw, R_yf, R_c from measured probe resistances (separate warp and weft yarn
    resistors): least squares on log R over (log R_yw, log R_yf, log R_c), started from the
    two-resistor fit (:func:`fit_network`), Levenberg-Marquardt with the exact Jacobian
    (power fractions). Needs four usable probes (one left over as a check) that involve
    warp and weft yarns; returns ``(R_yw, R_yf, R_c, rms_log_residual)`` or NaNs."""
    from scipy.optimize import least_squares

    network = network or YarnNetwork()
    probes = default_probe_terminals(network.n_warp, network.n_weft, weft_probe=True) if probes is None else probes
    names = [n for n in probes if n in measured and np.isfinite(measured[n]) and float(measured[n]) > 0]
    nan = (math.nan,) * 4
    if len(names) < 4:
        return nan
    dirs = {t[0] for n in names for t in probes[n]}
    if dirs != {"warp", "weft"}:
        return nan
    logm = np.log(np.array([float(measured[n]) for n in names]))
    pairs = [probes[n] for n in names]
    ry, rc, _ = fit_network(measured, network, {n: probes[n] for n in names})
    if not (np.isfinite(ry) and np.isfinite(rc)):
        return nan
    x0 = np.log([ry, ry, rc])

    def fun(x):
        return np.log(network.solve_pairs3(pairs, *np.exp(x))[0]) - logm

    def jac(x):
        _, pw, pf, pc = network.solve_pairs3(pairs, *np.exp(x))
        return np.column_stack([pw, pf, pc])

    lo, hi = float(logm.min()) - 35.0, float(logm.max()) + 35.0
    try:
        sol = least_squares(fun, np.clip(x0, lo + 1e-9, hi - 1e-9), jac=jac, method="trf",
                            bounds=([lo] * 3, [hi] * 3), xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
        resid = fun(sol.x)
    except (np.linalg.LinAlgError, ValueError, OverflowError) as exc:  # pragma: no cover
        log.warning("network fit (warp/weft) failed: %s", exc)
        return nan
    rw, rf, rc = (float(v) for v in np.exp(sol.x))
    return rw, rf, rc, float(np.sqrt(np.mean(resid ** 2)))


def network_probes(cfg, fab) -> dict:
    """Probes of ``cfg`` expressed as yarn-end terminals of the network model
    (:class:`YarnNetwork`): {name: ((dir, index, '+'|'-'), ...)}; {} unless the
    fabric is a weave and every terminal is a warp or weft end."""
    if fab.kind == "knit":
        return {}
    index = {}
    for d in ("warp", "weft"):
        ys = sorted((y for y in fab.yarns if y.direction == d), key=lambda y: y.position)
        index.update({(d, round(y.position, 9)): k for k, y in enumerate(ys)})
    out = {}
    for p in cfg.probes:
        if getattr(p, "field", None) is not None:  # a periodic cell's field probe: no yarn ends
            return {}
        terms = []
        for t in p.terminals:
            key = (t.yarn, round(t.position, 9))
            if key not in index:
                return {}
            sign = "+" if t.end.endswith("+") else "-"
            axis_ok = (t.yarn == "warp" and t.end[0] == "x") or (t.yarn == "weft" and t.end[0] == "y")
            if not axis_ok:
                return {}
            terms.append((t.yarn, index[key], sign))
        out[p.name] = tuple(terms)
    return out
