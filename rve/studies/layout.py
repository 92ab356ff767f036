"""File layout of the verification studies' Snakemake targets (workflow/rules/common.smk,
verification.smk, dynamic_wire.smk): every path those rules name comes from here, as the
scenes' come from ``rve.scenes.layout``. Data and string functions only: importing it
imports no study (the rule files read it at parse time; the study modules are imported in
the rule bodies).

Contract
--------
* static wire: ``STATIC_WIRE_DIR``, ``STATIC_WIRE_NC``, ``STATIC_WIRE_RADIUS_PNG``,
  ``STATIC_WIRE_CONVERGENCE_PNG``, ``STATIC_WIRE_ORDERS_CSV``, ``STATIC_WIRE_ORDERS_MD``,
  ``STATIC_WIRE_OUTPUTS``; ``static_wire_point(order, elements, radius)`` the record of one
  solve (strings or wildcards such as ``"{order}"``); ``radius_token``, ``point_name`` and
  ``study_points(study)`` (every solve ``(p, N, R)`` of a ``verification.static_wire``
  section);
* dynamic wire: ``DYNAMIC_WIRE_DIR``, ``DYNAMIC_WIRE_NC``, ``DYNAMIC_WIRE_ORDERS_MD``,
  ``DYNAMIC_WIRE_ERRORS_PNG``, ``DYNAMIC_WIRE_WORK_PNG``, ``DYNAMIC_WIRE_OUTPUTS``;
  ``dynamic_wire_reference()`` and ``dynamic_wire_series(stages)``, the job records;
* ``log_path(study, name)`` (``results/logs/verification/<study>/<name>.log``) and
  ``benchmark_path(study, name)`` (``results/benchmarks/verification/<study>/<name>.tsv``).
"""
from __future__ import annotations

from typing import Mapping

__all__ = ["VERIFICATION_DIR", "STATIC_WIRE_DIR", "STATIC_WIRE_NC", "STATIC_WIRE_RADIUS_PNG",
           "STATIC_WIRE_CONVERGENCE_PNG", "STATIC_WIRE_ORDERS_CSV", "STATIC_WIRE_ORDERS_MD", "STATIC_WIRE_OUTPUTS",
           "static_wire_point", "radius_token", "point_name", "study_points", "DYNAMIC_WIRE_DIR", "DYNAMIC_WIRE_NC",
           "DYNAMIC_WIRE_ORDERS_MD", "DYNAMIC_WIRE_ERRORS_PNG", "DYNAMIC_WIRE_WORK_PNG", "DYNAMIC_WIRE_OUTPUTS",
           "dynamic_wire_reference", "dynamic_wire_series", "log_path", "benchmark_path"]

VERIFICATION_DIR = "results/verification"

STATIC_WIRE_DIR = f"{VERIFICATION_DIR}/static_wire"
STATIC_WIRE_NC = f"{VERIFICATION_DIR}/static_wire.nc"
STATIC_WIRE_RADIUS_PNG = f"{VERIFICATION_DIR}/static_wire_radius.png"
STATIC_WIRE_CONVERGENCE_PNG = f"{VERIFICATION_DIR}/static_wire_convergence.png"
STATIC_WIRE_ORDERS_CSV = f"{VERIFICATION_DIR}/static_wire_orders.csv"
STATIC_WIRE_ORDERS_MD = f"{VERIFICATION_DIR}/static_wire_orders.md"
STATIC_WIRE_OUTPUTS = [STATIC_WIRE_NC, STATIC_WIRE_RADIUS_PNG, STATIC_WIRE_CONVERGENCE_PNG, STATIC_WIRE_ORDERS_CSV,
                       STATIC_WIRE_ORDERS_MD]

DYNAMIC_WIRE_DIR = f"{VERIFICATION_DIR}/dynamic_wire"
DYNAMIC_WIRE_NC = f"{VERIFICATION_DIR}/dynamic_wire.nc"
DYNAMIC_WIRE_ORDERS_MD = f"{VERIFICATION_DIR}/dynamic_wire_orders.md"
DYNAMIC_WIRE_ERRORS_PNG = f"{VERIFICATION_DIR}/dynamic_wire_errors.png"
DYNAMIC_WIRE_WORK_PNG = f"{VERIFICATION_DIR}/dynamic_wire_work_precision.png"
DYNAMIC_WIRE_OUTPUTS = [DYNAMIC_WIRE_NC, DYNAMIC_WIRE_ORDERS_MD, DYNAMIC_WIRE_ERRORS_PNG, DYNAMIC_WIRE_WORK_PNG]


def radius_token(radius) -> str:
    """The radius (mm) as it appears in file names and wildcards: ``0.02``, ``0.005``."""
    return format(float(radius), "g")


def point_name(order, elements, radius) -> str:
    """File stem of one solve: ``p2_N40_R0.02``."""
    return f"p{int(order)}_N{int(elements)}_R{radius_token(radius)}"


def static_wire_point(order: str, elements: str, radius: str) -> str:
    """The record of one static-wire solve; the arguments as they stand in the file name."""
    return f"{STATIC_WIRE_DIR}/points/p{order}_N{elements}_R{radius}.json"


def study_points(study: Mapping) -> list[tuple[int, int, float]]:
    """Every solve ``(order, elements, radius_mm)`` of the study (radius sweep and
    convergence series), without duplicates, sorted by radius (descending), p, N."""
    points: dict[tuple[int, int, str], tuple[int, int, float]] = {}

    def add(p, n, r):
        points.setdefault((int(p), int(n), radius_token(r)), (int(p), int(n), float(r)))

    sweep = study.get("radius_sweep")
    if sweep:
        for r in sweep["radii_mm"]:
            add(sweep["order"], sweep["elements"], r)
    conv = study.get("convergence")
    if conv:
        for series in conv["series"]:
            for n in series["elements"]:
                add(series["order"], n, conv["radius_mm"])
    return sorted(points.values(), key=lambda t: (-t[2], t[0], t[1]))


def dynamic_wire_reference() -> str:
    return f"{DYNAMIC_WIRE_DIR}/reference.json"


def dynamic_wire_series(stages) -> str:
    """The records of one SDIRK scheme's series (``stages`` 1-3 or ``"{dw_stages}"``)."""
    return f"{DYNAMIC_WIRE_DIR}/series_s{stages}.json"


def log_path(study: str, name: str) -> str:
    return f"results/logs/verification/{study}/{name}.log"


def benchmark_path(study: str, name: str) -> str:
    return f"results/benchmarks/verification/{study}/{name}.tsv"
