"""Atomic file output: a file either keeps its old content or gets the complete new one.

Every writer goes to a temporary file in the destination's directory (so the final
``os.replace`` is a rename on one filesystem, atomic on POSIX and Windows) and renames it
over the destination only when writing succeeded. A killed run therefore never leaves a
truncated ``summary.json``, netCDF table or PNG behind, which is what lets Snakemake and
checkpoint/resume logic trust any file that exists.

``atomic_netcdf(ds, path, encoding)`` is the one writer of the netCDF files the pipeline
reads back (states, tables): Fletcher-32 on every variable, the ``rve_checksum``
attribute, and the SHA-256 trailer of ``rve.io.checksum`` appended to the temporary file
before the rename, so a file that exists is complete *and* proves it
(docs/fault_tolerance.md).
"""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator, Optional, Union

from .checksum import CHECKSUM_ATTR, CHECKSUM_ATTR_VALUE, FLETCHER32, seal
from .provenance import to_jsonable

__all__ = ["atomic_path", "atomic_write_text", "atomic_write_bytes", "atomic_write_json", "atomic_netcdf",
           "unwritable_reason"]

PathLike = Union[str, os.PathLike]


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path to write ``path``'s content to; on normal exit of the block it
    is moved onto ``path`` (``os.replace``), on an exception it is deleted and ``path`` is
    left untouched. Parent directories are created.

    The temporary path lives in a fresh hidden directory next to ``path`` and has the same
    file name, so writers that pick the format from the suffix (matplotlib, xarray) work::

        with atomic_path("out/table.nc") as tmp:
            ds.to_netcdf(tmp)
    """
    path = Path(path)
    parent = path.parent
    parent.mkdir(parents=True, exist_ok=True)
    tmpdir = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent))
    tmp = tmpdir / path.name
    try:
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"atomic_path: nothing was written to {tmp} for {path}")
        if tmp.is_dir():
            raise IsADirectoryError(f"atomic_path: {tmp} is a directory; only files are supported")
        os.replace(tmp, path)
        _fsync_dir(parent)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def _fsync_dir(directory: Path) -> None:
    # Make the rename durable; not possible (nor needed) on every platform.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (flushed and fsynced before the rename)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def atomic_write_text(path: PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode(encoding))


def atomic_write_json(path: PathLike, obj: Any, indent: int = 2, sort_keys: bool = False) -> Path:
    """Write ``obj`` as JSON to ``path`` atomically (numpy types are converted)."""
    text = json.dumps(to_jsonable(obj), indent=indent, sort_keys=sort_keys) + "\n"
    return atomic_write_text(path, text)


def atomic_netcdf(ds, path: PathLike, encoding: Optional[dict] = None) -> Path:
    """Write the xarray Dataset ``ds`` as netCDF-4 to ``path`` atomically, with HDF5
    Fletcher-32 on every variable (merged into ``encoding``), the global attribute
    ``rve_checksum`` and the SHA-256 trailer (``rve.io.checksum.seal``) sealed before the
    rename. The stored numbers are those of ``ds`` (checksums only add bytes)."""
    enc = {name: dict(FLETCHER32) for name in ds.variables}
    for name, e in (encoding or {}).items():
        enc[name] = {**enc.get(name, {}), **e}
    out = ds.copy()
    out.attrs[CHECKSUM_ATTR] = CHECKSUM_ATTR_VALUE
    with atomic_path(path) as tmp:
        out.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=enc)
        seal(tmp)
    return Path(path)


def unwritable_reason(folder: PathLike) -> Optional[str]:
    """None if files can be created in ``folder`` (created on demand: its nearest existing
    ancestor must be a writable folder), else why not (one phrase). Checked before a
    computation so an unwritable output folder is not found only at the end."""
    probe = Path(folder).resolve()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        return f"{probe} is not a folder"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"{probe} is not writable"
    return None
