"""What a job records about how it ran: its log file and the package version.

Contract
--------
* ``logging_to(log_path)``: context manager sending the ``rve`` loggers and Python
  warnings to ``log_path`` (created, overwritten) for the block; an exception escaping the
  block is logged with its traceback and re-raised; ``None`` logs nowhere. Every Snakemake
  rule body (studies, RVE pipeline) runs inside one.
* ``package_version()``: the installed ``rve`` distribution's version, stamped into every
  dataset and checkpoint; ``'unknown'`` when running from a source tree without install.
"""
from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path
from typing import Iterator, Optional, Union

__all__ = ["logging_to", "package_version"]

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
