"""RVE lookup tables: per-state probe and reaction records -> a CF-style xarray Dataset.

The RVE pipeline (thesis ch. 7, Algorithm 7.1; SPEC §5-§6) relaxes a fabric, strains it
step by step (uniaxial and simple shear) and, on every stored state, runs decoupled probe
solves: a test voltage across a probe's two terminals gives the terminal currents, then
the Joule heating gives a temperature field with T = 0 on the boundary. This module is
the layer those results go into; it knows nothing about the physics.

Contract
========

Input: a list of **records**, one per stored state (and per point of a parameter sweep)::

    {
      "mode": "uniaxial",                 # or "shear"
      "strain": 0.05,                     # engineering strain (uniaxial) / shear strain
      "params": {"fibril_radius": 0.15},  # swept parameter values (optional; alias "swept")
      "reaction_force": {                 # N, per box side (alias "reactions"):
          "warp-": [fx, fy, fz],          #   sides warp-/warp+/weft-/weft+ or x-/x+/y-/y+,
          "warp+": {"x": .., "y": .., "z": ..},   # a list/tuple of 3 or a dict x/y/z
          ...},
      "contact_count": 412,               # active contact points of the state
      "equilibrium_residual": 3e-10,      # N, |F| on the free dofs (or "state": {"residual_N": ..})
      "probes": {
          "probe1": {"voltage": 1.0,                  # V, + terminal; - terminal at 0 V
                     "current": {"+": 0.52, "-": -0.52},
                     "temperature_max": 0.8,          # K above the boundary (T = 0 there)
                     "temperature_mean": 0.1},
          ...},
    }

Terminal currents are the current flowing **into the fabric** through each terminal (A),
so a conserving solve has I(+) = -I(-) > 0; a scalar ``"current": I`` means I(+) = I,
I(-) = -I. Currents of opposite sign convention are rejected. Records may omit any
quantity (it becomes NaN); strains are rounded to 12 decimals so that 0.1 + 0.2 and 0.3
are the same level.

Output of :func:`build_table`: an :class:`xarray.Dataset` with dimensions ``mode``,
``strain``, one per swept parameter (in ``swept`` order, after ``strain``), ``probe``,
``side``, ``component``, ``terminal`` and the variables

=========================  =====================================  ======
reaction_force             (mode, strain, *swept, side, component)  N
contact_count              (mode, strain, *swept)                  1
equilibrium_residual       (mode, strain, *swept)                  N
probe_voltage              (mode, strain, *swept, probe)           V
probe_current              (mode, strain, *swept, probe, terminal) A
probe_resistance           (mode, strain, *swept, probe)           ohm
temperature_rise_max       (mode, strain, *swept, probe)           K
temperature_rise_mean      (mode, strain, *swept, probe)           K
yarn_resistance            (mode, strain, *swept)                  ohm
contact_resistance         (mode, strain, *swept)                  ohm
network_fit_residual       (mode, strain, *swept)                  1
=========================  =====================================  ======

``probe_resistance = V / I`` with I = (I(+) - I(-))/2; the internal units are V and A, so
this is in ohm directly. ``yarn_resistance`` R_y and ``contact_resistance`` R_c are the
two resistors of the network model of thesis Fig. 7.2.1 as read here (:class:`YarnNetwork`,
docs/lookup_tables.md): each yarn crossing is a network cell with one warp and one weft
yarn resistor R_y and four contact resistors R_c joining each warp terminal of the cell to
each weft terminal (16 x 2 yarn and 16 x 4 contact resistors in the 4 x 4 RVE). They are
fitted to the probe resistances (least squares on log R over the probes the model knows;
two probes determine them exactly, the third is a check reported by
``network_fit_residual``). Every variable and coordinate has ``units`` and ``long_name``;
the global attributes hold the provenance (config and fabric as JSON, rve version,
creation date, source).

Other entry points: :func:`write_table` / :func:`open_table` (netCDF, atomic, zlib),
:func:`interpolate` (linear or PCHIP in strain and numeric swept parameters, exact at
stored points, ValueError outside the table), :func:`export_table` (csv, json, dat) and
:func:`read_table_csv`, :func:`summarize`, :func:`plot_table`, and the network model
(:class:`YarnNetwork`, :func:`fit_network`).
"""
from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional, Sequence, Union

import numpy as np
import xarray as xr

from .io.atomic import atomic_path, atomic_write_text
from .io.provenance import to_jsonable
from .io.provenance import package_version

__all__ = [
    "MODES",
    "TABLE_FORMAT",
    "EXPORT_FORMATS",
    "YarnNetwork",
    "default_probe_terminals",
    "fit_network",
    "build_table",
    "write_table",
    "open_table",
    "interpolate",
    "export_table",
    "read_table_csv",
    "to_json_dict",
    "summarize",
    "plot_table",
    "package_version",
]

log = logging.getLogger("rve.tables")

PathLike = Union[str, os.PathLike]

TABLE_FORMAT = "rve-lookup-table/1"
MODES = ("uniaxial", "shear")
TERMINALS = ("+", "-")
COMPONENTS = ("x", "y", "z")
_SIDE_ORDER = ("warp-", "warp+", "weft-", "weft+", "x-", "x+", "y-", "y+")
EXPORT_FORMATS = ("csv", "json", "dat")
_DIMLESS = "1"
_STRAIN_DECIMALS = 12

# ----------------------------------------------------------------------------- metadata
_COORD_ATTRS = {
    "mode": {"units": _DIMLESS, "long_name": "deformation mode of the strain path "
             "(uniaxial: stretch along the warp direction x; shear: simple shear, "
             "displacement along y proportional to x)"},
    "strain": {"units": _DIMLESS, "long_name": "engineering strain of the applied deformation "
               "(uniaxial: elongation / initial length along x; shear: engineering shear "
               "strain gamma = displacement along y / initial length along x)"},
    "probe": {"units": _DIMLESS, "long_name": "electrical probe (pair of terminals a test "
              "voltage is applied across)"},
    "side": {"units": _DIMLESS, "long_name": "side of the RVE box the clamped fibril ends "
             "are on (warp-/warp+ = x-/x+, the warp yarn ends; weft-/weft+ = y-/y+)"},
    "component": {"units": _DIMLESS, "long_name": "Cartesian component (x warp, y weft, "
                  "z out of plane)"},
    "terminal": {"units": _DIMLESS, "long_name": "probe terminal (+: at the test voltage, "
                 "-: at 0 V)"},
    "probe_terminals": {"units": _DIMLESS, "long_name": "yarn ends the probe connects in the "
                        "network model (+ terminal | - terminal), empty if not modelled"},
}

# name: (dims after (mode, strain, *swept), units, long_name, extra attrs)
_VARIABLES: dict[str, tuple[tuple[str, ...], str, str, dict]] = {
    "reaction_force": (("side", "component"), "N",
                       "total reaction force of the clamped fibril ends on one side of the RVE",
                       {}),
    "contact_count": ((), _DIMLESS, "number of active fibril-fibril contacts", {}),
    "equilibrium_residual": ((), "N",
                             "norm of the out-of-balance force on the free dofs of the stored "
                             "state (static equilibrium: ~0; NaN if not recorded)", {}),
    "probe_voltage": (("probe",), "V", "test voltage applied across the probe terminals", {}),
    "probe_current": (("probe", "terminal"), "A",
                      "electric current into the fabric through the probe terminal", {}),
    "probe_resistance": (("probe",), "ohm",
                         "effective electrical resistance between the probe terminals "
                         "(test voltage / mean terminal current)", {}),
    "temperature_rise_max": (("probe",), "K",
                             "maximum Joule-heating temperature rise above the boundary "
                             "temperature during the probe solve",
                             {"units_metadata": "temperature: difference"}),
    "temperature_rise_mean": (("probe",), "K",
                              "mean Joule-heating temperature rise above the boundary "
                              "temperature during the probe solve",
                              {"units_metadata": "temperature: difference"}),
    "yarn_resistance": ((), "ohm",
                        "network-model yarn resistance R_y of one yarn across one cell "
                        "(one crossing) of the RVE", {}),
    "contact_resistance": ((), "ohm",
                           "network-model contact resistance R_c, one of the four warp-weft "
                           "contact resistors of a cell", {}),
    "network_fit_residual": ((), _DIMLESS,
                             "RMS of log(model / measured probe resistance) of the network "
                             "fit (0: the probes are consistent with the network model)", {}),
}

# known swept parameters: name -> (units, long_name)
KNOWN_PARAMETERS: dict[str, tuple[str, str]] = {
    "fibril_radius": ("mm", "fibril radius R"),
    "fibril_diameter": ("mm", "fibril diameter"),
    "contact_conductance": ("A mm-2 V-1", "electrical contact conductance sigma_C"),
    "thermal_contact_conductance": ("W mm-2 K-1", "thermal contact conductance h_C"),
    "contact_penalty": ("N mm-1", "contact penalty stiffness P*"),
    "conductivity": ("S mm-1", "fibril electrical conductivity sigma"),
    "thermal_conductivity": ("W mm-1 K-1", "fibril thermal conductivity k"),
    "youngs_modulus": ("MPa", "fibril Young's modulus E"),
    "spacing": ("mm", "yarn spacing"),
    "amplitude": ("mm", "crimp amplitude"),
    "weave": (_DIMLESS, "weave pattern"),
}


# ============================================================================= network
Terminal = tuple[str, int, str]  # (direction 'warp'|'weft', yarn index, end '-'|'+')


def default_probe_terminals(n_warp: int = 4, n_weft: int = 4) -> dict[str, tuple[Terminal, Terminal]]:
    """The three thesis probes (SPEC §5) as (+ terminal, - terminal) yarn ends.

    With yarns 2 mm apart and centred, warp ``n_warp//2 - 1`` is the one at y = -1,
    ``n_warp//2`` at y = +1 and weft ``n_weft//2 - 1`` at x = -1:

    * probe1: the y = -1 warp yarn end to end (x+ end | x- end);
    * probe2: its x = +4 end to the x = -4 end of the y = +1 warp yarn (parallel yarns);
    * probe3: its x = +4 end to the y = +4 end of the x = -1 weft yarn (crossing yarns).
    """
    if n_warp < 2 or n_weft < 2:
        raise ValueError("the thesis probes need at least 2 warp and 2 weft yarns")
    j1, j2, i1 = n_warp // 2 - 1, n_warp // 2, n_weft // 2 - 1
    return {
        "probe1": (("warp", j1, "+"), ("warp", j1, "-")),
        "probe2": (("warp", j1, "+"), ("warp", j2, "-")),
        "probe3": (("warp", j1, "+"), ("weft", i1, "+")),
    }


def _terminal_text(t: Terminal) -> str:
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
        U = np.zeros((n, len(pairs)))
        for k, (plus, minus) in enumerate(pairs):
            a, b = self.terminal_node(plus), self.terminal_node(minus)
            if a == b:
                raise ValueError(f"probe {k}: the two terminals are the same yarn end")
            U[a, k], U[b, k] = 1.0, -1.0
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


# ============================================================================= build
def _jsonable(obj: Any) -> Any:
    if obj is None:
        return None
    try:
        return to_jsonable(obj)
    except TypeError:
        return repr(obj)


def _fabric_description(fabric: Any) -> tuple[dict, int, int]:
    """JSON-able description of ``fabric`` and its (n_warp, n_weft)."""
    n_warp = n_weft = 4
    if fabric is None:
        return {}, n_warp, n_weft
    if isinstance(fabric, str):
        return {"kind": fabric}, n_warp, n_weft
    if isinstance(fabric, Mapping):
        desc = dict(fabric)
    else:  # rve.fabrics.Fabric (or anything with kind/params)
        desc = {"kind": getattr(fabric, "kind", type(fabric).__name__)}
        params = dict(getattr(fabric, "params", {}) or {})
        desc.update(params)
        for attr in ("n_fibrils", "half_widths"):
            if hasattr(fabric, attr):
                desc[attr] = getattr(fabric, attr)
        yarns = getattr(fabric, "yarns", None)
        if yarns is not None:
            n_warp = sum(1 for y in yarns if getattr(y, "direction", None) == "warp") or n_warp
            n_weft = sum(1 for y in yarns if getattr(y, "direction", None) == "weft") or n_weft
    n_warp = int(desc.get("n_warp", n_warp))
    n_weft = int(desc.get("n_weft", n_weft))
    return _jsonable(desc), n_warp, n_weft


def _param_meta(swept) -> tuple[list[str], dict[str, dict]]:
    """Names and attrs of the swept parameters from ``swept`` (None, names, or a dict)."""
    if swept is None:
        return [], {}
    if isinstance(swept, str):
        swept = [swept]
    names: list[str] = []
    meta: dict[str, dict] = {}
    items = swept.items() if isinstance(swept, Mapping) else ((n, None) for n in swept)
    for name, spec in items:
        name = str(name)
        units, long_name = KNOWN_PARAMETERS.get(name, (None, name.replace("_", " ")))
        extra: dict = {}
        if isinstance(spec, str):
            units = spec
        elif isinstance(spec, Mapping):
            extra = {k: v for k, v in spec.items() if k not in ("units", "long_name")}
            units = spec.get("units", units)
            long_name = spec.get("long_name", long_name)
        if units is None:
            log.warning("swept parameter %r has no units given; writing units '1'", name)
            units = _DIMLESS
        names.append(name)
        meta[name] = {"units": str(units), "long_name": str(long_name), **extra}
    return names, meta


def _record_params(rec: Mapping) -> Mapping:
    params = rec.get("params", rec.get("swept", {}))
    return params or {}


def _sorted_unique(values: list) -> list:
    uniq = list(dict.fromkeys(values))
    if all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
           for v in uniq):
        return sorted(float(v) for v in uniq)
    if all(isinstance(v, str) for v in uniq):
        return sorted(uniq)
    raise ValueError(f"swept values must be all numbers or all strings, got {uniq!r}")


def _vector3(value, where: str) -> np.ndarray:
    if isinstance(value, Mapping):
        try:
            return np.array([float(value[c]) for c in COMPONENTS])
        except KeyError as exc:
            raise ValueError(f"{where}: needs components x, y, z, got {sorted(value)}") from exc
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.size != 3:
        raise ValueError(f"{where}: a force needs 3 components, got {arr.size}")
    return arr


def _terminal_currents(value, where: str) -> tuple[float, float]:
    if isinstance(value, Mapping):
        aliases = {"+": ("+", "plus", "pos", "positive"), "-": ("-", "minus", "neg", "negative")}
        out = []
        for t in TERMINALS:
            key = next((k for k in aliases[t] if k in value), None)
            if key is None:
                raise ValueError(f"{where}: current needs terminals '+' and '-', got {sorted(value)}")
            out.append(float(value[key]))
        ip, im = out
    else:
        ip = float(value)
        im = -ip
    if ip * im > 0:
        raise ValueError(f"{where}: terminal currents {ip} and {im} have the same sign; give the "
                         "current flowing into the fabric through each terminal (I+ = -I-)")
    return ip, im


def _side_order(sides: Iterable[str]) -> list[str]:
    sides = list(dict.fromkeys(sides))
    known = [s for s in _SIDE_ORDER if s in sides]
    return known + sorted(s for s in sides if s not in _SIDE_ORDER)


def build_table(records: Sequence[Mapping], *, fabric: Any, config: Any,
                swept: Union[None, Sequence[str], Mapping[str, Any]] = None,
                network_probes: Optional[Mapping[str, tuple[Terminal, Terminal]]] = None,
                title: Optional[str] = None, source: Optional[str] = None) -> xr.Dataset:
    """Build the lookup-table Dataset from per-state ``records`` (module docstring).

    ``fabric``: an ``rve.fabrics.Fabric``, a dict or a name, described in the ``fabric``
    attribute (its warp/weft counts size the network model). ``config``: the run's
    configuration (dict or pydantic model), stored as JSON in the ``config`` attribute.
    ``swept``: the swept parameter names (list) or ``{name: units}`` /
    ``{name: {"units": .., "long_name": ..}}``; None takes the names found in the records'
    ``params`` (known names get their units, KNOWN_PARAMETERS). ``network_probes``: the
    probes the network fit uses, name -> (+ terminal, - terminal), default
    :func:`default_probe_terminals`. Missing combinations are NaN; a repeated
    (mode, strain, params) state is an error.
    """
    records = list(records)
    if not records:
        raise ValueError("build_table: no records")
    fabric_desc, n_warp, n_weft = _fabric_description(fabric)

    # --- swept parameters
    if swept is None:
        found: list[str] = []
        for rec in records:
            for k in _record_params(rec):
                if k not in found:
                    found.append(str(k))
        swept = found
    pnames, pmeta = _param_meta(swept)
    pvalues: dict[str, list] = {}
    for name in pnames:
        vals = []
        for n, rec in enumerate(records):
            params = _record_params(rec)
            if name not in params:
                raise ValueError(f"record {n}: missing swept parameter {name!r}")
            vals.append(params[name])
        pvalues[name] = _sorted_unique(vals)

    # --- modes, strains, probes, sides
    modes, strains, probes, sides = [], [], [], []
    for n, rec in enumerate(records):
        mode = rec.get("mode")
        if mode not in MODES:
            raise ValueError(f"record {n}: mode must be one of {MODES}, got {mode!r}")
        modes.append(mode)
        try:
            s = round(float(rec["strain"]), _STRAIN_DECIMALS)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"record {n}: needs a numeric 'strain'") from exc
        if not math.isfinite(s):
            raise ValueError(f"record {n}: strain {s} is not finite")
        strains.append(s + 0.0)  # -0.0 -> 0.0
        for p in (rec.get("probes") or {}):
            if str(p) not in probes:
                probes.append(str(p))
        sides.extend(str(s_) for s_ in (rec.get("reaction_force", rec.get("reactions")) or {}))
    mode_coord = [m for m in MODES if m in modes]
    strain_coord = sorted(set(strains))
    sides = _side_order(sides) or list(_SIDE_ORDER[:4])
    if not probes:
        probes = list(default_probe_terminals(max(n_warp, 2), max(n_weft, 2)))

    shape0 = (len(mode_coord), len(strain_coord)) + tuple(len(pvalues[p]) for p in pnames)
    lead = ("mode", "strain") + tuple(pnames)
    sizes = {"probe": len(probes), "side": len(sides), "component": 3, "terminal": 2}
    data = {name: np.full(shape0 + tuple(sizes[d] for d in dims), np.nan)
            for name, (dims, *_rest) in _VARIABLES.items()}
    filled = np.zeros(shape0, dtype=bool)

    pidx = {p: i for i, p in enumerate(probes)}
    sidx = {s: i for i, s in enumerate(sides)}
    for n, rec in enumerate(records):
        params = _record_params(rec)
        idx = (mode_coord.index(rec["mode"]), strain_coord.index(strains[n])) + tuple(
            pvalues[p].index(float(params[p]) if not isinstance(params[p], str) else params[p])
            for p in pnames)
        if filled[idx]:
            raise ValueError(f"record {n}: state mode={rec['mode']}, strain={strains[n]}"
                             f"{''.join(f', {p}={params[p]}' for p in pnames)} given twice")
        filled[idx] = True
        where = f"record {n} ({rec['mode']}, strain {strains[n]})"
        for side, vec in (rec.get("reaction_force", rec.get("reactions")) or {}).items():
            data["reaction_force"][idx + (sidx[str(side)],)] = _vector3(vec, f"{where}, side {side}")
        if rec.get("contact_count") is not None:
            data["contact_count"][idx] = float(rec["contact_count"])
        resid = rec.get("equilibrium_residual", (rec.get("state") or {}).get("residual_N"))
        if resid is not None:
            data["equilibrium_residual"][idx] = float(resid)
        for pname, pr in (rec.get("probes") or {}).items():
            k = idx + (pidx[str(pname)],)
            pw = f"{where}, probe {pname}"
            if pr.get("voltage") is not None:
                data["probe_voltage"][k] = float(pr["voltage"])
            if pr.get("current") is not None:
                ip, im = _terminal_currents(pr["current"], pw)
                data["probe_current"][k] = (ip, im)
                i_mean = 0.5 * (ip - im)
                if pr.get("voltage") is not None:
                    data["probe_resistance"][k] = (float(pr["voltage"]) / i_mean
                                                   if i_mean != 0 else math.inf)
            for key in ("max", "mean"):
                val = pr.get(f"temperature_{key}", pr.get(f"temperature_rise_{key}"))
                if val is not None:
                    data[f"temperature_rise_{key}"][k] = float(val)

    # --- network model
    network = YarnNetwork(n_warp, n_weft)
    try:
        net_probes = (dict(network_probes) if network_probes is not None
                      else default_probe_terminals(n_warp, n_weft))
    except ValueError:
        net_probes = {}
    usable = [p for p in net_probes if p in pidx]
    cache: dict = {}
    if len(usable) >= 2:
        for idx in zip(*np.nonzero(filled)):
            measured = {p: data["probe_resistance"][idx + (pidx[p],)] for p in usable}
            ry, rc, res = fit_network(measured, network, {p: net_probes[p] for p in usable},
                                      _grid_cache=cache)
            data["yarn_resistance"][idx] = ry
            data["contact_resistance"][idx] = rc
            data["network_fit_residual"][idx] = res
    else:
        log.warning("build_table: records have fewer than two of the network probes %s; "
                    "yarn_resistance and contact_resistance are NaN", list(net_probes))

    # --- assemble
    coords: dict[str, Any] = {
        "mode": ("mode", np.array(mode_coord, dtype=object), dict(_COORD_ATTRS["mode"])),
        "strain": ("strain", np.array(strain_coord, dtype=float), dict(_COORD_ATTRS["strain"])),
        "probe": ("probe", np.array(probes, dtype=object), dict(_COORD_ATTRS["probe"])),
        "side": ("side", np.array(sides, dtype=object), dict(_COORD_ATTRS["side"])),
        "component": ("component", np.array(COMPONENTS, dtype=object), dict(_COORD_ATTRS["component"])),
        "terminal": ("terminal", np.array(TERMINALS, dtype=object), dict(_COORD_ATTRS["terminal"])),
        "probe_terminals": ("probe", np.array(
            [" | ".join(_terminal_text(t) for t in net_probes[p]) if p in net_probes else ""
             for p in probes], dtype=object), dict(_COORD_ATTRS["probe_terminals"])),
    }
    for p in pnames:
        vals = pvalues[p]
        arr = np.array(vals, dtype=object if isinstance(vals[0], str) else float)
        coords[p] = (p, arr, dict(pmeta[p]))
    data_vars = {}
    for name, (dims, units, long_name, extra) in _VARIABLES.items():
        attrs = {"units": units, "long_name": long_name, **extra}
        data_vars[name] = (lead + dims, data[name], attrs)
    ds = xr.Dataset(data_vars, coords=coords)
    ds["strain"].attrs["axis"] = "X"
    ds["yarn_resistance"].attrs["comment"] = ds["contact_resistance"].attrs["comment"] = (
        "fitted to the probe resistances under the network model of docs/lookup_tables.md "
        f"({n_warp} x {n_weft} cells, probes {', '.join(usable) or 'none'})")
    ds["probe_resistance"].attrs["comment"] = ("V / I with I = (I(+) - I(-)) / 2; internal "
                                               "units are V and A, so ohm directly")

    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    version = package_version()
    ds.attrs.update({
        "title": title or "RVE lookup table: reaction forces, probe resistances and Joule "
                          "temperature rises of a textile unit cell vs applied strain",
        "Conventions": "CF-1.10",
        "rve_table_format": TABLE_FORMAT,
        "institution": "rve",
        "source": source or f"rve {version} RVE pipeline (rve.tables.build_table)",
        "references": "Queiruga (2015), ch. 7 (Algorithm 7.1, Figs. 7.2.1, 7.4.3-7.4.4); "
                      "docs/lookup_tables.md",
        "rve_version": version,
        "date_created": now,
        "history": f"{now}: rve.tables.build_table from {len(records)} records",
        "config": json.dumps(_jsonable(config), sort_keys=True),
        "fabric": json.dumps(fabric_desc, sort_keys=True),
        "network_model": (f"YarnNetwork(n_warp={n_warp}, n_weft={n_weft}): per crossing 2 yarn "
                          "resistors R_y and 4 warp-weft contact resistors R_c"),
        "swept_parameters": " ".join(pnames),
        "internal_units": "mm, ms, g, N, MPa, K, A, mC, V (ohm = V/A)",
    })
    return ds


# ============================================================================= netCDF
def _encoding(ds: xr.Dataset) -> dict:
    enc = {}
    for name, var in ds.variables.items():
        if var.dtype.kind in "fiu":
            e: dict = {"zlib": True, "complevel": 4, "shuffle": True}
            if name in ds.coords:
                e["_FillValue"] = None  # CF: coordinate variables have no missing values
            enc[name] = e
    return enc


def write_table(ds: xr.Dataset, path: PathLike) -> Path:
    """Write ``ds`` atomically as netCDF-4 (zlib level 4 on numeric variables)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=_encoding(ds))
    return path


def open_table(path: PathLike) -> xr.Dataset:
    """Open a table written by :func:`write_table`, loaded into memory (file closed)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no lookup table at {path}")
    with xr.open_dataset(path, engine="netcdf4") as ds:
        ds = ds.load()
    for name in ("mode", "strain"):
        if name not in ds.dims:
            raise ValueError(f"{path} is not an rve lookup table (no {name!r} dimension)")
    return ds


# ============================================================================= interpolation
def _interp_axis(x: np.ndarray, y: np.ndarray, xq: np.ndarray, axis: int, method: str) -> np.ndarray:
    """Interpolate ``y`` (sampled at increasing ``x`` along ``axis``) to ``xq``; points of
    ``xq`` equal to a sample return that sample exactly. ``xq`` must lie in [x0, x_-1]."""
    y = np.moveaxis(np.asarray(y, dtype=float), axis, 0)
    n = len(x)
    out = np.empty((len(xq),) + y.shape[1:])
    exact = np.searchsorted(x, xq)
    is_exact = (exact < n) & (x[np.minimum(exact, n - 1)] == xq)
    if n == 1:
        out[:] = y[0]
    elif method == "linear" or n == 2:
        i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, n - 2)
        t = ((xq - x[i]) / (x[i + 1] - x[i])).reshape((-1,) + (1,) * (y.ndim - 1))
        with np.errstate(invalid="ignore"):  # 0 * inf at a stored point: overwritten below
            out[:] = (1.0 - t) * y[i] + t * y[i + 1]
    elif method == "cubic":
        from scipy.interpolate import PchipInterpolator

        # PCHIP needs finite samples: series with a NaN or inf (a quantity not recorded, an
        # open circuit's infinite resistance) are interpolated linearly instead
        y2 = y.reshape(n, -1)
        o2 = out.reshape(len(xq), -1)
        ok = np.isfinite(y2).all(axis=0)
        if ok.any():
            o2[:, ok] = PchipInterpolator(x, y2[:, ok], axis=0, extrapolate=False)(xq)
        if not ok.all():
            o2[:, ~ok] = _interp_axis(x, y2[:, ~ok], xq, 0, "linear")
    else:
        raise ValueError(f"method must be 'linear' or 'cubic', got {method!r}")
    out[is_exact] = y[exact[is_exact]]
    return np.moveaxis(out, 0, axis)


def _interp_dim(ds: xr.Dataset, dim: str, values, method: str, valid: Optional[np.ndarray] = None,
                context: str = "") -> xr.Dataset:
    """Interpolate every variable of ``ds`` having ``dim`` to ``values`` along it."""
    x_all = np.asarray(ds[dim].values, dtype=float)
    keep = np.ones(len(x_all), bool) if valid is None else np.asarray(valid, bool)
    x = x_all[keep]
    if x.size == 0:
        raise ValueError(f"no stored {dim} values{context}")
    scalar = np.ndim(values) == 0
    xq = np.atleast_1d(np.asarray(values, dtype=float))
    if not np.all(np.isfinite(xq)):
        raise ValueError(f"{dim} values must be finite, got {values!r}")
    lo, hi = float(x.min()), float(x.max())
    bad = xq[(xq < lo) | (xq > hi)]
    if bad.size:
        raise ValueError(f"{dim} {bad[0]:g} is outside the table range [{lo:g}, {hi:g}]{context}")
    out = xr.Dataset(attrs=ds.attrs)
    sub = ds.isel({dim: np.nonzero(keep)[0]})
    for name, var in sub.data_vars.items():
        if dim in var.dims:
            ax = var.dims.index(dim)
            vals = _interp_axis(x, var.values, xq, ax, method)
            out[name] = xr.Variable(var.dims, vals, attrs=var.attrs)
        else:
            out[name] = var.variable
    for name, c in sub.coords.items():
        if dim not in c.dims:
            out.coords[name] = c.variable
    out.coords[dim] = xr.Variable((dim,), xq, attrs=ds[dim].attrs)
    if scalar:
        out = out.isel({dim: 0})
    return out


def interpolate(ds: xr.Dataset, strain, mode: Optional[str] = None, method: str = "linear",
                **params) -> xr.Dataset:
    """Table values at arbitrary ``strain`` (a number or a sequence) for ``mode`` (None:
    every mode of the table, each checked against its own strain range).

    ``method``: ``"linear"`` (piecewise linear) or ``"cubic"`` (monotone piecewise cubic
    Hermite, PCHIP: no overshoot between samples). Only the strains at which a mode has
    a state are used. Stored strains return the stored values exactly. ``params`` select
    swept parameters: a string (or any value of a string-valued dimension) selects that
    entry; a number of a numeric dimension is interpolated with the same ``method``
    (exact at stored values). A strain or parameter outside the table raises ValueError
    naming the range. Returns a Dataset with the table's variables, ``strain`` (and each
    numeric ``params``) as a dimension, or a scalar coordinate if a scalar was given.
    """
    if method not in ("linear", "cubic"):
        raise ValueError(f"method must be 'linear' or 'cubic', got {method!r}")
    for name in params:
        if name not in ds.dims or name in ("mode", "strain", "probe", "side", "component", "terminal"):
            swept = [d for d in ds.dims if d not in ("mode", "strain", "probe", "side",
                                                     "component", "terminal")]
            raise ValueError(f"{name!r} is not a swept parameter of the table (swept: {swept})")
    sel = ds
    for name, value in params.items():
        if sel[name].dtype.kind in "OSU":
            values = list(sel[name].values)
            wanted = [value] if np.ndim(value) == 0 else list(value)
            missing = [v for v in wanted if v not in values]
            if missing:
                raise ValueError(f"{name} {missing[0]!r} is not in the table ({values})")
            sel = sel.sel({name: value})
        else:
            sel = _interp_dim(sel, name, value, method, context=f" of {name}")
    modes = list(sel["mode"].values)
    if mode is not None:
        if mode not in modes:
            raise ValueError(f"mode {mode!r} is not in the table (modes: {modes})")
        modes = [mode]
    parts = []
    state_vars = [v for v in sel.data_vars if "strain" in sel[v].dims]
    for m in modes:
        one = sel.sel(mode=m)
        # a strain level is a state of this mode if any variable has a value there
        present = np.zeros(one.sizes["strain"], bool)
        for v in state_vars:
            arr = one[v].transpose("strain", ...).values.reshape(one.sizes["strain"], -1)
            present |= np.isfinite(arr).any(axis=1)
        parts.append(_interp_dim(one, "strain", strain, method, valid=present,
                                 context=f" of mode {m!r}"))
    if mode is not None:
        out = parts[0]
    else:
        out = xr.concat(parts, dim="mode", data_vars="all", coords="minimal",
                        compat="override", join="override", combine_attrs="override")
        out["mode"].attrs = ds["mode"].attrs
    out.attrs = dict(ds.attrs)
    out.attrs["interpolation"] = f"{method} in strain" + (
        f" and {', '.join(params)}" if params else "")
    return out


# ============================================================================= export
_LABEL_DIMS = ("probe", "side", "component", "terminal")


def _lead_dims(ds: xr.Dataset) -> list[str]:
    return [d for d in ds.dims if d not in _LABEL_DIMS]


def _fmt_num(x: float) -> str:
    return repr(float(x)) if math.isfinite(x) else ("nan" if math.isnan(x) else repr(float(x)))


def export_table(ds: xr.Dataset, path: PathLike, fmt: str) -> list[Path]:
    """Export ``ds`` for macroscale codes; returns the written paths (all atomic).

    * ``"csv"``: one long (tidy) table, one row per value: columns ``variable``,
      ``units``, the leading coordinates with units in the header (``strain [1]``,
      ``fibril_radius [mm]``, ...), the label coordinates ``probe``, ``side``,
      ``component``, ``terminal`` (empty where a variable has no such dimension) and
      ``value``; ``#`` comment lines first (title, provenance, variable units).
      :func:`read_table_csv` reads it back into the Dataset.
    * ``"json"``: ``xarray.Dataset.to_dict`` layout (``coords``, ``data_vars`` with
      ``dims``, ``attrs`` and ``data``; missing values as null) plus ``"format"``.
    * ``"dat"``: one whitespace-separated lookup file per mode (and per value of a
      string-valued swept parameter), ``<stem>.<mode>[.<name>-<value>]<suffix>``: ``#``
      header lines numbering every column with its units and meaning, then one row per
      strain (numeric swept parameters as leading columns, strain varying fastest).
    """
    fmt = fmt.lower()
    path = Path(path)
    if fmt == "csv":
        atomic_write_text(path, _csv_text(ds))
        return [path]
    if fmt == "json":
        atomic_write_text(path, json.dumps(to_json_dict(ds), indent=1, allow_nan=False) + "\n")
        return [path]
    if fmt in ("dat", "txt", "table"):
        return _export_dat(ds, path)
    raise ValueError(f"unknown export format {fmt!r} (known: {', '.join(EXPORT_FORMATS)})")


def _csv_text(ds: xr.Dataset) -> str:
    import csv
    import io

    lead = _lead_dims(ds)
    header = ["variable", "units"] + [
        d if ds[d].dtype.kind in "OSU" else f"{d} [{ds[d].attrs.get('units', '')}]" for d in lead
    ] + list(_LABEL_DIMS) + ["value"]
    buf = io.StringIO()
    buf.write(f"# rve lookup table, {TABLE_FORMAT} long csv: one row per value; an empty "
              "label cell = not a dimension of the variable\n")
    for key in ("title", "Conventions", "rve_version", "date_created", "source",
                "swept_parameters"):
        if key in ds.attrs:
            buf.write(f"# {key}: {ds.attrs[key]}\n")
    for name, var in ds.data_vars.items():
        buf.write(f"# variable {name} [{var.attrs.get('units', '')}] dims ({', '.join(var.dims)}): "
                  f"{var.attrs.get('long_name', '')}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for name, var in ds.data_vars.items():
        dims = var.dims
        coords = [ds[d].values for d in dims]
        units = var.attrs.get("units", "")
        for index in np.ndindex(var.shape):
            label = dict(zip(dims, (c[i] for c, i in zip(coords, index))))
            row = [name, units]
            for d in lead:
                v = label.get(d, "")
                row.append(_fmt_num(v) if isinstance(v, (float, np.floating)) else str(v))
            row += [str(label.get(d, "")) for d in _LABEL_DIMS]
            row.append(_fmt_num(var.values[index]))
            w.writerow(row)
    return buf.getvalue()


def read_table_csv(path: PathLike) -> xr.Dataset:
    """Read a ``csv`` export back into a Dataset (values, coordinates, units, long names;
    global attributes only those in the comment header)."""
    import csv

    comments, rows = [], []
    with open(path, newline="", encoding="utf-8") as fh:
        lines = []
        for line in fh:
            (comments if line.startswith("#") else lines).append(line)
        rows = list(csv.reader(lines))
    header, body = rows[0], rows[1:]
    col = {h: k for k, h in enumerate(header)}
    lead, lead_units = [], {}
    for h in header[2:header.index(_LABEL_DIMS[0])]:
        name, _, unit = h.partition(" [")
        lead.append(name)
        lead_units[name] = unit.rstrip("]")
    var_meta: dict[str, dict] = {}
    attrs: dict[str, str] = {}
    for c in comments:
        text = c[1:].strip()
        if text.startswith("variable "):
            rest = text[len("variable "):]
            name, rest = rest.split(" [", 1)
            units, rest = rest.split("] dims (", 1)
            dims, long_name = rest.split("): ", 1)
            var_meta[name] = {"units": units, "long_name": long_name,
                              "dims": tuple(d for d in dims.split(", ") if d)}
        elif ": " in text and not text.startswith("rve lookup table,"):
            k, v = text.split(": ", 1)
            attrs[k] = v
    # coordinate values, in order of first appearance (numeric ones sorted)
    coord_vals: dict[str, list] = {}
    for d in lead + list(_LABEL_DIMS):
        key = col[d] if d in col else col[d + f" [{lead_units[d]}]"]
        seen = list(dict.fromkeys(r[key] for r in body if r[key] != ""))
        coord_vals[d] = seen
    numeric = {}
    for d in lead:
        try:
            numeric[d] = sorted(float(v) for v in coord_vals[d])
        except ValueError:
            numeric[d] = None
    ds = xr.Dataset(attrs=attrs)
    lead_col = {d: col[next(h for h in header if h.partition(" [")[0] == d)] for d in lead}
    for name, meta in var_meta.items():
        dims = meta["dims"]
        shape = tuple(len(coord_vals[d]) for d in dims)
        arr = np.full(shape, np.nan)
        for r in body:
            if r[0] != name:
                continue
            index = []
            for d in dims:
                v = r[lead_col[d]] if d in lead_col else r[col[d]]
                if d in numeric and numeric[d] is not None:
                    index.append(numeric[d].index(float(v)))
                else:
                    index.append(coord_vals[d].index(v))
            arr[tuple(index)] = float(r[col["value"]]) if r[col["value"]] != "" else np.nan
        ds[name] = xr.Variable(dims, arr, attrs={"units": meta["units"], "long_name": meta["long_name"]})
    for d in coord_vals:
        if d not in ds.dims:
            continue
        vals = np.array(numeric[d], dtype=float) if numeric.get(d) is not None \
            else np.array(coord_vals[d], dtype=object)
        attrs_d = {"units": lead_units.get(d) or _DIMLESS}
        ds.coords[d] = xr.Variable((d,), vals, attrs=attrs_d)
    return ds


def _json_clean(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _json_clean(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_json_clean(v) for v in obj]
    return obj


def to_json_dict(ds: xr.Dataset) -> dict:
    """``ds`` as a JSON-able dict (``xarray.Dataset.to_dict`` layout, NaN -> None, plus
    ``"format"``); what the ``json`` export writes."""
    d = to_jsonable(ds.to_dict(data="list"))
    d = _json_clean(d)
    d["format"] = TABLE_FORMAT
    return d


def _export_dat(ds: xr.Dataset, path: Path) -> list[Path]:
    lead = [d for d in _lead_dims(ds) if d not in ("mode", "strain")]
    str_dims = [d for d in lead if ds[d].dtype.kind in "OSU"]
    num_dims = [d for d in lead if d not in str_dims]
    written = []
    import itertools

    for mode in ds["mode"].values:
        for combo in itertools.product(*(list(ds[d].values) for d in str_dims)):
            sub = ds.sel(mode=mode, **dict(zip(str_dims, combo)))
            # columns: numeric swept params, strain, then every variable flattened
            columns: list[tuple[str, str, str]] = [
                (d, sub[d].attrs.get("units", ""), sub[d].attrs.get("long_name", ""))
                for d in num_dims + ["strain"]]
            blocks = []
            for name, var in sub.data_vars.items():
                other = [d for d in var.dims if d not in num_dims and d != "strain"]
                v = var.transpose(*(num_dims + ["strain"] + other))
                nrow = int(np.prod([sub.sizes[d] for d in num_dims + ["strain"]]))
                blocks.append(v.values.reshape(nrow, -1))
                for labels in itertools.product(*(list(sub[d].values) for d in other)):
                    tag = f"{name}[{','.join(str(x) for x in labels)}]" if labels else name
                    columns.append((tag, var.attrs.get("units", ""), var.attrs.get("long_name", "")))
            grids = np.meshgrid(*(sub[d].values.astype(float) for d in num_dims + ["strain"]),
                                indexing="ij")
            table = np.hstack([np.column_stack([g.reshape(-1) for g in grids])] + blocks)
            suffix = "".join(f".{d}-{v}" for d, v in zip(str_dims, combo))
            out = path.with_name(f"{path.stem}.{mode}{suffix}{path.suffix or '.dat'}")
            lines = [f"# rve lookup table ({TABLE_FORMAT}), mode: {mode}"
                     + "".join(f", {d}: {v}" for d, v in zip(str_dims, combo)),
                     f"# {ds.attrs.get('title', '')}",
                     f"# rve {ds.attrs.get('rve_version', '?')}, created {ds.attrs.get('date_created', '?')}",
                     f"# {table.shape[0]} rows ({' x '.join(f'{d} {sub.sizes[d]}' for d in num_dims + ['strain'])},"
                     " last varies fastest), "
                     f"{table.shape[1]} columns; nan = no value",
                     "# column  name  [units]  meaning"]
            for k, (tag, units, long_name) in enumerate(columns, start=1):
                lines.append(f"# {k:4d}  {tag}  [{units}]  {long_name}")
            lines.append("# " + " ".join(tag for tag, _, _ in columns))
            for row in table:
                lines.append(" ".join(f"{x: .12e}" if math.isfinite(x) else "nan" for x in row))
            atomic_write_text(out, "\n".join(lines) + "\n")
            written.append(out)
    return written


# ============================================================================= summary
def _rng(a) -> str:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return "n/a"
    return f"{a.min():.6g} .. {a.max():.6g}"


def summarize(ds: xr.Dataset) -> str:
    """Human-readable summary: dims, strain range per mode, swept values, per-probe
    resistance range, network resistances and the reaction forces at zero strain."""
    lines = [f"rve lookup table: {ds.attrs.get('title', '(untitled)')}"]
    lines.append(f"  created {ds.attrs.get('date_created', '?')} by rve {ds.attrs.get('rve_version', '?')}"
                 f" ({ds.attrs.get('rve_table_format', '?')})")
    lines.append("  dims: " + ", ".join(f"{d}={n}" for d, n in ds.sizes.items()))
    for m in ds["mode"].values:
        one = ds.sel(mode=m)
        present = np.isfinite(one["probe_resistance"].transpose("strain", ...).values
                              .reshape(one.sizes["strain"], -1)).any(axis=1) | \
            np.isfinite(one["reaction_force"].transpose("strain", ...).values
                        .reshape(one.sizes["strain"], -1)).any(axis=1)
        s = one["strain"].values[present]
        lines.append(f"  mode {m}: strain {_rng(s)} ({s.size} levels)")
    for d in _lead_dims(ds):
        if d in ("mode", "strain"):
            continue
        vals = ", ".join(str(v) for v in ds[d].values)
        lines.append(f"  swept {d} [{ds[d].attrs.get('units', '')}]: {vals}")
    lines.append("  probe resistance [ohm] (min .. max over strains and sweeps):")
    for p in ds["probe"].values:
        per_mode = "; ".join(f"{m} {_rng(ds['probe_resistance'].sel(probe=p, mode=m).values)}"
                             for m in ds["mode"].values)
        term = str(ds["probe_terminals"].sel(probe=p).values) if "probe_terminals" in ds.coords else ""
        lines.append(f"    {p}{f' ({term})' if term else ''}: {per_mode}")
    for name, sym in (("yarn_resistance", "R_y"), ("contact_resistance", "R_c")):
        if name in ds:
            lines.append(f"  network {sym} [ohm]: " + "; ".join(
                f"{m} {_rng(ds[name].sel(mode=m).values)}" for m in ds["mode"].values))
    if "network_fit_residual" in ds:
        lines.append(f"  network fit residual (rms log): max {_rng(ds['network_fit_residual'].values).split(' .. ')[-1]}")
    if "equilibrium_residual" in ds and np.isfinite(ds["equilibrium_residual"].values).any():
        r = ds["equilibrium_residual"].values
        lines.append(f"  equilibrium residual [N]: max {np.nanmax(r):.3g} over {int(np.isfinite(r).sum())} table entries")
    # reactions at the smallest |strain|
    k = int(np.argmin(np.abs(ds["strain"].values)))
    s0 = float(ds["strain"].values[k])
    rf = ds["reaction_force"].isel(strain=k)
    extra = [d for d in rf.dims if d not in ("mode", "side", "component")]
    if extra:
        rf = rf.isel({d: 0 for d in extra})
        note = " (" + ", ".join(f"{d}={ds[d].values[0]}" for d in extra) + ")"
    else:
        note = ""
    lines.append(f"  reaction force [N] at strain {s0:g}{note}:")
    lines.append("    " + f"{'mode':10s} {'side':6s}" + "".join(f"{c:>13s}" for c in ds["component"].values))
    for m in ds["mode"].values:
        for side in ds["side"].values:
            vals = rf.sel(mode=m, side=side).values
            lines.append("    " + f"{m:10s} {side:6s}" + "".join(f"{v:13.5g}" for v in vals))
    return "\n".join(lines) + "\n"


# ============================================================================= plots
def _select_first(ds: xr.Dataset, select: Optional[Mapping]) -> tuple[xr.Dataset, str]:
    extra = [d for d in _lead_dims(ds) if d not in ("mode", "strain")]
    select = dict(select or {})
    for d in extra:
        select.setdefault(d, ds[d].values[0])
    note = ", ".join(f"{d} = {select[d]}" for d in extra)
    return (ds.sel({d: select[d] for d in extra}) if extra else ds), note


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120)
    return path


def plot_table(ds: xr.Dataset, out_png_prefix: PathLike, select: Optional[Mapping] = None) -> list[Path]:
    """Figures in the manner of thesis Figs. 7.4.3-7.4.4, written atomically (Agg):

    * ``<prefix>_reaction_force.png``: reaction force components vs strain, one panel
      per mode and side;
    * ``<prefix>_probe_resistance.png``: probe resistance vs strain, one panel per
      probe, one line per mode, plus a panel of the network R_y and R_c;
    * ``<prefix>_temperature_rise.png``: max (solid) and mean (dashed) Joule
      temperature rise vs strain per probe.

    Swept parameters are fixed at ``select`` (default: their first values). Returns the paths.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    prefix = str(out_png_prefix)
    sub, note = _select_first(ds, select)
    modes = list(sub["mode"].values)
    sides = list(sub["side"].values)
    probes = list(sub["probe"].values)
    strain = sub["strain"].values
    paths = []
    styles = {"uniaxial": "-", "shear": "--"}
    marks = {"x": "o", "y": "s", "z": "^"}

    def new(nrows, ncols, w=3.2, h=2.6):
        fig = Figure(figsize=(w * ncols, h * nrows + 0.5))
        FigureCanvasAgg(fig)
        axes = np.atleast_2d(fig.subplots(nrows, ncols, squeeze=False))
        # fixed margins (constrained layout costs seconds on many panels)
        fig.subplots_adjust(left=0.75 / (w * ncols), right=1 - 0.15 / (w * ncols),
                            bottom=0.5 / (h * nrows + 0.5), top=1 - 0.75 / (h * nrows + 0.5),
                            wspace=0.45, hspace=0.55)
        return fig, axes

    # reaction forces
    fig, axes = new(len(modes), len(sides))
    for r, m in enumerate(modes):
        for c, side in enumerate(sides):
            ax = axes[r, c]
            for comp in sub["component"].values:
                y = sub["reaction_force"].sel(mode=m, side=side, component=comp).values
                ax.plot(strain, y, marker=marks.get(comp, "."), ms=3, label=str(comp))
            ax.set_title(f"{m}, side {side}", fontsize=9)
            ax.set_xlabel("strain [1]")
            ax.set_ylabel("reaction force [N]")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Reaction forces vs strain" + (f" ({note})" if note else ""))
    paths.append(_save(fig, Path(prefix + "_reaction_force.png")))

    # probe resistances (+ network)
    fig, axes = new(1, len(probes) + 1)
    for c, p in enumerate(probes):
        ax = axes[0, c]
        for m in modes:
            ax.plot(strain, sub["probe_resistance"].sel(mode=m, probe=p).values,
                    styles.get(m, ":"), marker="o", ms=3, label=m)
        ax.set_title(f"{p}", fontsize=9)
        ax.set_xlabel("strain [1]")
        ax.set_ylabel("resistance [ohm]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    ax = axes[0, -1]
    for m in modes:
        ax.plot(strain, sub["yarn_resistance"].sel(mode=m).values, styles.get(m, ":"),
                marker="o", ms=3, label=f"R_y {m}")
        ax.plot(strain, sub["contact_resistance"].sel(mode=m).values, styles.get(m, ":"),
                marker="s", ms=3, label=f"R_c {m}")
    ax.set_title("network model", fontsize=9)
    ax.set_xlabel("strain [1]")
    ax.set_ylabel("resistance [ohm]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle("Probe resistance vs strain" + (f" ({note})" if note else ""))
    paths.append(_save(fig, Path(prefix + "_probe_resistance.png")))

    # temperature rises
    fig, axes = new(1, len(probes))
    for c, p in enumerate(probes):
        ax = axes[0, c]
        for k, m in enumerate(modes):
            color = f"C{k}"
            ax.plot(strain, sub["temperature_rise_max"].sel(mode=m, probe=p).values, "-",
                    color=color, marker="o", ms=3, label=f"max, {m}")
            ax.plot(strain, sub["temperature_rise_mean"].sel(mode=m, probe=p).values, "--",
                    color=color, label=f"mean, {m}")
        ax.set_title(f"{p}", fontsize=9)
        ax.set_xlabel("strain [1]")
        ax.set_ylabel("temperature rise [K]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Joule temperature rise vs strain" + (f" ({note})" if note else ""))
    paths.append(_save(fig, Path(prefix + "_temperature_rise.png")))
    return paths
