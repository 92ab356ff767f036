"""The stated accuracy of a lookup table, from its convergence study (
docs/table_accuracy.md).

The convergence study (``rve.studies.table_convergence``, target ``rve_table_convergence``)
takes hours, so the default job cannot run it; it writes ``accuracy.json`` (the default
run's error against the finest mesh and against the stiffest penalty, per table quantity).
That file, copied into the repository next to the run's config
(``configs/rve/plain_weave_accuracy.json``) and named by the run spec's ``accuracy`` key,
is the table's stated accuracy: the gather job writes it into the table's attributes.

Contract
--------
A work-precision study's file (``method: work_precision``, ``rve.studies.work_precision``)
has the same ``default``, ``mesh`` and ``penalty`` keys (so it reads the same way) and its
own ``stated_relative_error`` (the default run against the study's one reference, range
measure) and ``stated_relative_error_by_mode``: those become ``estimated_relative_error``
and ``estimated_relative_error_<mode>``, without a mesh / penalty split; the default's
``mesh_order``, ``contact_n_gp``, ``boundary`` and ``cell_repeat`` are checked too where the
table's config records them.

``read_accuracy(path) -> dict``: the study's ``accuracy.json`` (``default``, ``mesh`` and
``penalty`` with ``estimated_relative_error`` per quantity); a missing or malformed file is
a ``ValueError`` naming the file and the key.

``annotate_accuracy(ds, accuracy, mesh_elements, contact_penalty, source) -> list[str]``:
when the table's run is the study's default (the same elements per fibril and the same
penalty P*, N/mm²), writes on every quantity ``v`` the study assessed (``QUANTITIES`` of
the study) the attributes

* ``estimated_relative_error_mesh``: the study's ``stated_relative_error`` of the mesh (max
  relative difference to the finest mesh plus the finest mesh's own estimated error) where
  the file has it, else the plain difference ``estimated_relative_error``,
* ``estimated_relative_error_penalty``: max relative difference to the stiffest penalty,
* ``estimated_relative_error``: their sum (the bound a user should read),
* ``estimated_relative_error_<mode>``: the same sum from the per-mode maxima (``by_mode``,
  ``reference_error_by_mode``), where the file has them (the shear mode's errors are larger than the uniaxial ones),

and the global attributes ``accuracy_source`` (the study: references, date, commit) and a
line of ``comment``. Returns the annotated variable names. A table of another mesh or
penalty is not annotated (returns ``[]``, logs why): the study says nothing about it.
"""
from __future__ import annotations

import json
import logging
import os
from typing import Optional, Union

import xarray as xr

__all__ = ["read_accuracy", "annotate_accuracy"]

log = logging.getLogger("rve.tables.accuracy")

PathLike = Union[str, os.PathLike]


def read_accuracy(path: PathLike) -> dict:
    """The convergence study's accuracy file (see the module docstring)."""
    try:
        with open(path, encoding="utf-8") as fh:
            acc = json.load(fh)
    except FileNotFoundError:
        raise ValueError(f"accuracy: file {path} not found (write it with "
                         "`python benchmarks/table_convergence.py --write-accuracy {path}`)") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"accuracy: {path} is not JSON ({exc})") from None
    for key in ("default", "mesh", "penalty"):
        if key not in acc:
            raise ValueError(f"accuracy: {path} has no key {key!r} (a convergence study's accuracy.json has "
                             "'default', 'mesh' and 'penalty')")
    for key in ("mesh_elements", "contact_penalty"):
        if key not in acc["default"]:
            raise ValueError(f"accuracy: {path}: default.{key} missing")
    return acc


def annotate_accuracy(ds: xr.Dataset, accuracy: dict, mesh_elements: int, contact_penalty: float,
                      source: str = "") -> list:
    """Write the study's errors into ``ds``'s attributes (module docstring)."""
    if accuracy.get("method") == "work_precision":
        return _annotate_work_precision(ds, accuracy, mesh_elements, contact_penalty, source)
    d = accuracy["default"]
    if int(d["mesh_elements"]) != int(mesh_elements) or abs(float(d["contact_penalty"]) - float(contact_penalty)) > \
            1e-9 * max(1.0, abs(float(contact_penalty))):
        log.warning("accuracy %s is of %s elements and P* = %s N/mm^2, this table's run has %s and %s: not annotated",
                    source, d["mesh_elements"], d["contact_penalty"], mesh_elements, contact_penalty)
        return []
    mesh = accuracy["mesh"].get("stated_relative_error") or accuracy["mesh"].get("estimated_relative_error", {})
    pen = accuracy["penalty"].get("estimated_relative_error", {})
    ref_err = accuracy["mesh"].get("reference_error") or {}
    by_m, by_p = accuracy["mesh"].get("by_mode") or {}, accuracy["penalty"].get("by_mode") or {}
    ref_m = accuracy["mesh"].get("reference_error_by_mode") or {}
    done = []
    for name in sorted(set(mesh) | set(pen)):
        if name not in ds:
            continue
        em, ep = mesh.get(name), pen.get(name)
        if em is None and ep is None:
            continue
        a = ds[name].attrs
        if em is not None:
            a["estimated_relative_error_mesh"] = float(em)
        if ep is not None:
            a["estimated_relative_error_penalty"] = float(ep)
        a["estimated_relative_error"] = float((em or 0.0) + (ep or 0.0))
        for mode in sorted(set(by_m.get(name) or {}) | set(by_p.get(name) or {})):
            bm = ((by_m.get(name) or {}).get(mode) or {}).get("max")
            bp = ((by_p.get(name) or {}).get(mode) or {}).get("max")
            if bm is None and bp is None:
                continue
            rm = (ref_m.get(name) or {}).get(mode, ref_err.get(name)) if bm is not None else None
            a[f"estimated_relative_error_{mode}"] = float((bm or 0.0) + (rm or 0.0) + (bp or 0.0))
        done.append(name)
    refs = (f"finest mesh {accuracy['mesh'].get('reference')} elements per fibril, "
            f"stiffest penalty P* = {accuracy['penalty'].get('reference')} N/mm^2")
    prov = accuracy.get("provenance", {})
    ds.attrs["accuracy_source"] = (f"{source}: table convergence study (rve_table_convergence) of this run's "
                                   f"configuration; references: {refs}"
                                   + (f"; run {prov.get('date', '?')} at commit {prov.get('commit', '?')}" if prov else ""))
    line = ("estimated_relative_error on " + ", ".join(done) + " = max relative difference over strains and labels "
            "to the finest mesh" + (" plus that mesh's own estimated error" if ref_err else "")
            + " (…_mesh) plus to the stiffest penalty (…_penalty)")
    ds.attrs["comment"] = (ds.attrs.get("comment", "") + "\n" + line).strip()
    return done


def _same_default(accuracy: dict, ds: xr.Dataset, mesh_elements: int, contact_penalty: float) -> Optional[str]:
    """None when the table's run is the study's default, else what differs."""
    d = accuracy["default"]
    if int(d["mesh_elements"]) != int(mesh_elements) or abs(float(d["contact_penalty"]) - float(contact_penalty)) > \
            1e-9 * max(1.0, abs(float(contact_penalty))):
        return (f"{d['mesh_elements']} elements and P* = {d['contact_penalty']} N/mm^2, this table's run has "
                f"{mesh_elements} and {contact_penalty}")
    try:
        scene = json.loads(ds.attrs.get("config", "{}")).get("scene") or {}
    except (TypeError, ValueError):
        scene = {}
    for key, path in (("mesh_order", ("mesh", "order")), ("contact_n_gp", ("contact", "n_gp")),
                      ("cell_repeat", ("cell", "repeat"))):
        have = (scene.get(path[0]) or {}).get(path[1])
        if key in d and have is not None and int(have) != int(d[key]):
            return f"{key} = {d[key]}, this table's run has {have}"
    # a key the table's config does not spell out has the config's default
    for key, have in (("boundary", scene.get("boundary", "pinned")),
                      ("contact_geometry", (scene.get("contact") or {}).get("geometry", "chord")),
                      ("contact_enforcement", (scene.get("contact") or {}).get("enforcement", "penalty"))):
        if key in d and str(have) != str(d[key]):
            return f"{key} = {d[key]}, this table's run has {have}"
    return None


def _annotate_work_precision(ds: xr.Dataset, accuracy: dict, mesh_elements: int, contact_penalty: float,
                             source: str) -> list:
    """A work-precision study's file (``method: work_precision``): ``stated_relative_error``
    (the default run against the study's one reference, on the file's ``measure``) as
    ``estimated_relative_error`` and ``stated_relative_error_by_mode`` as
    ``estimated_relative_error_<mode>``; no mesh / penalty split (the reference differs in
    every lever at once)."""
    differs = _same_default(accuracy, ds, mesh_elements, contact_penalty)
    if differs:
        log.warning("accuracy %s is of %s: not annotated", source, differs)
        return []
    stated = accuracy.get("stated_relative_error") or {}
    by_mode = accuracy.get("stated_relative_error_by_mode") or {}
    done = []
    for name in sorted(stated):
        if name not in ds or stated[name] is None:
            continue
        a = ds[name].attrs
        a["estimated_relative_error"] = float(stated[name])
        for mode, e in sorted((by_mode.get(name) or {}).items()):
            if (e or {}).get("max") is not None:
                a[f"estimated_relative_error_{mode}"] = float(e["max"])
        done.append(name)
    prov = accuracy.get("provenance", {})
    ds.attrs["accuracy_source"] = (f"{source}: work-precision study {accuracy.get('study', '?')} of this run's "
                                   f"configuration; reference: run {accuracy.get('reference', '?')}"
                                   + (f"; run {prov.get('date', '?')} at commit {prov.get('commit', '?')}" if prov else ""))
    line = ("estimated_relative_error on " + ", ".join(done) + " = max over strains, labels and modes of the difference "
            "to the study's reference relative to the reference's range over the strain path (floored at "
            f"{accuracy.get('range_floor', '?')} of the quantity's scale)")
    ds.attrs["comment"] = (ds.attrs.get("comment", "") + "\n" + line).strip()
    return done
