"""What a job records about how it ran: its log file and the package version.

Contract
--------
* ``logging_to(log_path)``: context manager sending the ``rve`` loggers and Python
  warnings to ``log_path`` (created, overwritten) for the block; an exception escaping the
  block is logged with its traceback and re-raised; ``None`` logs nowhere. Every Snakemake
  rule body (studies, RVE pipeline) runs inside one.
* ``package_version()``: the installed ``rve`` distribution's version, stamped into every
  dataset and checkpoint; ``'unknown'`` when running from a source tree without install.
* ``to_jsonable(obj)``: numpy scalars/arrays, paths, sets, tuples and pydantic models as
  plain JSON types (the one JSON-safe conversion of the package).
* ``cf_attributes(title, source, references, history=None, **extra)``: the global
  attributes every netCDF product carries (CF ``Conventions``, title, institution,
  source, references, rve version, creation date, history), the one place they are spelt.
"""
from __future__ import annotations

import contextlib
import logging
import datetime as _dt
import os
from pathlib import Path
from typing import Any, Iterator, Optional, Union

__all__ = ["logging_to", "package_version", "to_jsonable", "cf_attributes", "CF_CONVENTIONS"]

#: the CF version the netCDF products declare
CF_CONVENTIONS = "CF-1.10"

PathLike = Union[str, os.PathLike]


@contextlib.contextmanager
def logging_to(log_path: Optional[PathLike], level: int = logging.INFO) -> Iterator[None]:
    """Send the ``rve`` loggers and Python warnings to ``log_path`` for the block."""
    if log_path is None:
        yield
        return
    Path(log_path).parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(log_path, mode="w", encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logger = logging.getLogger("rve")
    wlogger = logging.getLogger("py.warnings")
    old_level = logger.level
    logger.addHandler(handler)
    wlogger.addHandler(handler)
    logger.setLevel(min(level, old_level) if old_level else level)
    logging.captureWarnings(True)
    try:
        yield
    except Exception:
        logger.exception("failed")
        raise
    finally:
        logging.captureWarnings(False)
        logger.removeHandler(handler)
        wlogger.removeHandler(handler)
        logger.setLevel(old_level)
        handler.close()


def package_version() -> str:
    """The installed ``rve`` distribution's version (importlib.metadata), else 'unknown'."""
    try:
        from importlib.metadata import version

        return version("rve")
    except Exception:  # noqa: BLE001 - running from a source tree without install
        return "unknown"


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, paths, sets and tuples to plain JSON types.
    Non-finite floats are kept (written as NaN/Infinity, which Python's json reads)."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, (str, bool, int, type(None))):
        return obj
    if isinstance(obj, float):
        return obj
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    tolist = getattr(obj, "tolist", None)  # numpy arrays and scalars
    if callable(tolist):
        return to_jsonable(tolist())
    item = getattr(obj, "item", None)
    if callable(item):
        return to_jsonable(item())
    dump = getattr(obj, "model_dump", None)  # pydantic models
    if callable(dump):
        return to_jsonable(dump(mode="json"))
    raise TypeError(f"cannot write {type(obj).__name__} as JSON: {obj!r}")


def cf_attributes(title: str, source: str, references: str, history: Optional[str] = None, **extra: Any) -> dict:
    """Global attributes of a netCDF product: CF ``Conventions``, ``title``,
    ``institution``, ``source``, ``references``, ``rve_version``, ``date_created`` (UTC,
    ISO 8601) and ``history`` (``"<date>: <history>"`` when given); ``extra`` is added
    last (e.g. ``rve_table_format``)."""
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    attrs = {
        "title": title,
        "Conventions": CF_CONVENTIONS,
        "institution": "rve",
        "source": source,
        "references": references,
        "rve_version": package_version(),
        "date_created": now,
    }
    if history is not None:
        attrs["history"] = f"{now}: {history}"
    attrs.update(extra)
    return attrs
