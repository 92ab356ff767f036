"""Files that prove themselves: a SHA-256 trailer on every state and table, checked before
HDF5 reads a byte, and a bounded-time open for files that carry none (docs/fault_tolerance.md).

Contract
--------
* ``seal(path)`` appends the trailer ``b"\\nRVE-SHA256:" + 64 hex digits + b"\\n"`` (77
  bytes): the SHA-256 of every byte before it. netCDF-4/HDF5 ignores bytes after its
  end-of-file address, so a sealed file opens in every netCDF tool as before; ``seal`` is
  called by the writers on the temporary file, before the atomic rename.
* ``verify(path) -> Seal``: reads the file, checks the trailer; raises
  :class:`CorruptFileError` (a ``ValueError`` naming the file and what failed) on a
  mismatch; returns ``Seal(sealed=False)`` for a file without a trailer (written by an
  older rve or by another tool).
* ``open_netcdf(path, ..., timeout=OPEN_TIMEOUT_S)``: the dataset loaded into memory. A
  sealed file whose digest matches is opened in-process (its bytes are exactly the ones
  written, which HDF5 read back when they were written). A file without a valid trailer
  is first opened in a child process with a time limit (one corrupted byte was seen to
  spin HDF5 at 100 % CPU forever, docs/fault_tolerance.md "Measured"): a child that does
  not finish within ``timeout`` seconds is killed and the open is a
  :class:`CorruptFileError` ("opening did not finish within ..."). A file whose
  attributes say it was sealed (``rve_checksum``) but that has no valid trailer is
  refused.
* ``quarantine(path)`` renames a failing file to ``<name>.corrupt`` (replacing an older
  one), so Snakemake sees the output missing and reruns the job that produced it.
* ``quarantine_failing(paths, require_seal)`` does that for every file of a list that
  fails :func:`verify` (trailer only, no HDF5): ``workflow/rules/integrity.smk`` runs it
  over the pipeline's states and tables before Snakemake builds its DAG, so a damaged or
  truncated output is rebuilt by the next ``snakemake`` call instead of "Nothing to be done".
* Fletcher-32 (``FLETCHER32``): the writers also ask HDF5 for a per-chunk Fletcher-32
  checksum on every variable (``encoding={"fletcher32": True}``); HDF5 checks it on every
  read, also in other tools (ncdump, h5dump).

Imports no other rve layer.
"""
from __future__ import annotations

import hashlib
import logging
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

__all__ = ["TRAILER_MAGIC", "TRAILER_SIZE", "CHECKSUM_ATTR", "CHECKSUM_ATTR_VALUE", "OPEN_TIMEOUT_S",
           "FLETCHER32", "CorruptFileError", "Seal", "seal", "verify", "open_netcdf", "quarantine",
           "file_digest", "quarantine_failing"]

log = logging.getLogger("rve.io.checksum")

PathLike = Union[str, os.PathLike]

TRAILER_MAGIC = b"\nRVE-SHA256:"
TRAILER_SIZE = len(TRAILER_MAGIC) + 64 + 1
#: global attribute of every sealed netCDF file: its absence of a trailer is then an error
CHECKSUM_ATTR = "rve_checksum"
CHECKSUM_ATTR_VALUE = "sha256 trailer (rve.io.checksum) + HDF5 fletcher32 on every variable"
#: seconds an unsealed file may take to open (in a child process) before it is refused
OPEN_TIMEOUT_S = float(os.environ.get("RVE_OPEN_TIMEOUT_S", "20"))
#: the encoding entry that turns on HDF5's per-chunk checksum of a variable
FLETCHER32 = {"fletcher32": True}


class CorruptFileError(ValueError):
    """A file failed its check. ``path``: the file; ``what``: what failed; str() is one line
    naming both and what to do."""

    def __init__(self, path: PathLike, what: str, hint: Optional[str] = None):
        self.path = str(path)
        self.what = what
        self.hint = hint if hint is not None else (
            "the file is not used; delete it (or run `rve check --quarantine PATH`) so the job that wrote it reruns")
        super().__init__(f"{self.path}: {what}" + (f"; {self.hint}" if self.hint else ""))


@dataclass(frozen=True)
class Seal:
    """Outcome of :func:`verify`: ``sealed`` (a valid trailer was found and matched),
    ``digest`` (hex SHA-256 of the payload), ``payload_size`` (bytes before the trailer)."""

    sealed: bool
    digest: str = ""
    payload_size: int = 0


def file_digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def seal(path: PathLike) -> str:
    """Append the SHA-256 trailer to ``path`` (in place, fsynced); returns the digest.
    A file that already ends in a trailer is first stripped of it (re-sealing is idempotent)."""
    path = Path(path)
    data = path.read_bytes()
    if _parse_trailer(data) is not None:
        data = data[:-TRAILER_SIZE]
        with open(path, "r+b") as fh:
            fh.truncate(len(data))
    digest = file_digest(data)
    with open(path, "ab") as fh:
        fh.write(TRAILER_MAGIC + digest.encode("ascii") + b"\n")
        fh.flush()
        os.fsync(fh.fileno())
    return digest


def _parse_trailer(data: bytes) -> Optional[str]:
    if len(data) < TRAILER_SIZE:
        return None
    tail = data[-TRAILER_SIZE:]
    if not tail.startswith(TRAILER_MAGIC) or not tail.endswith(b"\n"):
        return None
    hexd = tail[len(TRAILER_MAGIC):-1]
    try:
        text = hexd.decode("ascii")
        int(text, 16)
    except (UnicodeDecodeError, ValueError):
        return ""   # a trailer whose digest is damaged
    return text if len(text) == 64 else ""


def _looks_like_trailer(data: bytes) -> bool:
    """A trailer with one damaged byte still has most of its magic in place."""
    tail = data[-TRAILER_SIZE:] if len(data) >= TRAILER_SIZE else b""
    head = tail[: len(TRAILER_MAGIC)]
    same = sum(a == b for a, b in zip(head, TRAILER_MAGIC))
    return same >= len(TRAILER_MAGIC) - 1


def verify(path: PathLike, data: Optional[bytes] = None) -> Seal:
    """Check the trailer of ``path`` (module docstring). Raises ``FileNotFoundError`` for a
    missing file and :class:`CorruptFileError` for a mismatch or a damaged trailer."""
    path = Path(path)
    if data is None:
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            raise
        except OSError as exc:
            raise CorruptFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    stored = _parse_trailer(data)
    if stored is None:
        if _looks_like_trailer(data):
            raise CorruptFileError(path, "its SHA-256 trailer is damaged")
        return Seal(False, "", len(data))
    if stored == "":
        raise CorruptFileError(path, "its SHA-256 trailer is damaged")
    payload = data[:-TRAILER_SIZE]
    actual = file_digest(payload)
    if actual != stored:
        raise CorruptFileError(path, f"SHA-256 mismatch (stored {stored[:12]}..., content {actual[:12]}...): "
                                     "the file changed after it was written")
    return Seal(True, stored, len(payload))


_CHILD = r"""
import sys, netCDF4
with netCDF4.Dataset(sys.argv[1]) as ds:
    def walk(g):
        for v in g.variables.values():
            v.set_auto_mask(False)
            v[...]
        for sub in g.groups.values():
            walk(sub)
    walk(ds)
print("ok")
"""

def _probe_open(path: Path, timeout: float) -> None:
    """Open and read ``path`` in a child process; raise CorruptFileError if it fails or
    does not finish within ``timeout`` s (the child is killed)."""
    try:
        proc = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True, text=True,
                              timeout=timeout, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    except subprocess.TimeoutExpired:
        raise CorruptFileError(path, f"opening it did not finish within {timeout:g} s (HDF5 stuck on a damaged "
                                     "file; the reader was killed)") from None
    if proc.returncode != 0 or "ok" not in proc.stdout:
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        raise CorruptFileError(path, f"HDF5/netCDF cannot read it ({last[:300]})")


def open_netcdf(path: PathLike, *, timeout: Optional[float] = None, require_seal: bool = False,
                engine: str = "netcdf4"):
    """The xarray Dataset of ``path``, loaded into memory and closed (module docstring).
    Every failure is a :class:`CorruptFileError` naming the file; ``FileNotFoundError``
    for a missing file. ``require_seal``: refuse a file without a trailer. The returned
    dataset's ``encoding["rve_sealed"]`` says whether the trailer was verified; the
    ``rve_checksum`` attribute is dropped (a write/open round trip is identical)."""
    import xarray as xr

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no file at {path}")
    st = verify(path)
    if not st.sealed:
        if require_seal:
            raise CorruptFileError(path, "it has no SHA-256 trailer (not written by this rve, or truncated)")
        _probe_open(path, OPEN_TIMEOUT_S if timeout is None else float(timeout))
    try:
        with xr.open_dataset(path, engine=engine) as ds:
            ds = ds.load()
    except Exception as exc:  # noqa: BLE001 - HDF5 raises many types (RuntimeError, OSError, KeyError...)
        raise CorruptFileError(path, f"HDF5/netCDF cannot read it ({type(exc).__name__}: {exc})") from None
    marked = ds.attrs.pop(CHECKSUM_ATTR, None)   # file-level metadata: not part of the content
    if not st.sealed:
        if marked:
            raise CorruptFileError(path, "it was written with a SHA-256 trailer that is now missing "
                                         "(truncated or rewritten by another tool)")
        log.warning("%s: no checksum (written before rve checked its files, or by another tool): "
                    "used unverified", path)
    ds.encoding["rve_sealed"] = st.sealed
    return ds


def quarantine(path: PathLike) -> Optional[Path]:
    """Rename ``path`` to ``<path>.corrupt`` (so a Snakemake rerun rebuilds it); returns the
    new path, or None if the file could not be moved (it is then left as it is)."""
    path = Path(path)
    dest = path.with_name(path.name + ".corrupt")
    try:
        os.replace(path, dest)
    except OSError as exc:
        log.error("%s: could not be moved aside (%s)", path, exc)
        return None
    log.error("%s: moved to %s so the job that wrote it reruns", path, dest)
    return dest


def quarantine_failing(paths, require_seal: bool = False) -> list:
    """Move every file of ``paths`` that fails :func:`verify` (or, with ``require_seal``, has
    no trailer) to ``<name>.corrupt``; returns ``[(path, what failed, new path)]``."""
    moved = []
    for p in paths:
        p = Path(p)
        try:
            st = verify(p)
            if st.sealed or not require_seal:
                continue
            what = "no SHA-256 trailer (truncated, or written before rve checked its files)"
        except FileNotFoundError:
            continue
        except CorruptFileError as exc:
            what = exc.what
        dest = quarantine(p)
        moved.append((str(p), what, str(dest) if dest else None))
    return moved
