"""Fault injection: the full set of issue 15's faults, with counts (docs/fault_tolerance.md).

    python benchmarks/fault_injection.py                  # everything below (~5 min on 2 loaded cores)
    python benchmarks/fault_injection.py flips            # 300 single-byte flips of a state and of a table
    python benchmarks/fault_injection.py flips --loader raw --strip   # today's main: plain files, plain open
    python benchmarks/fault_injection.py moved-node       # one node moved by 2.6 % of R, checksum valid
    python benchmarks/fault_injection.py livelock         # dynamic wire at +-200 V and alpha_mu = -100 MPa/K
    python benchmarks/fault_injection.py inputs kills     # the bad-input tests and the SIGKILL/SIGTERM resume tests

``flips``: a CI state (fabric + relax of ``configs/tests/pipeline_ci.yaml``, made in a
temporary folder) and a table (``tests/data/records_v1_ci`` through ``build_table`` and
``write_table``); for each of ``--n`` flips (one random byte XOR a random non-zero value,
seeded) a worker process loads the damaged copy with ``rve.homogenisation.checkpoint.load_state``
or ``rve.tables.open_table`` and the outcome is classed as *identical* (every array and
attribute equal to the undamaged file's), *named error* (an exception whose message
names the file), *unnamed error*, *crash* (the reading process died), *silently different* or *hang* (no
answer within ``--timeout`` s: the worker is killed). Acceptance: silently different =
hang = crash = unnamed = 0.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


# ----------------------------------------------------------------------------- files
def make_state(folder: Path) -> Path:
    """The relaxed CI state (fabric + relax jobs of the CI run), written by the package."""
    import yaml

    from rve.homogenisation.jobs import fabric_job, relax_job

    spec = yaml.safe_load((ROOT / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    fabric_job(folder / "initial.nc", None, spec, "base")
    relax_job(folder / "initial.nc", folder / "relaxed.nc", None, spec, "base")
    return folder / "relaxed.nc"


def make_table(folder: Path) -> Path:
    from rve.tables import build_table, write_table
    from rve.tables.jobs import gather_records

    recs = sorted((ROOT / "tests/data/records_v1_ci").glob("*.json"))
    ds = build_table(gather_records(recs, ["uniaxial", "shear"]), fabric={"kind": "plain weave"}, config={})
    path = folder / "table.nc"
    write_table(ds, path)
    return path


# ----------------------------------------------------------------------------- loading
def _fingerprint(kind: str, path: str, loader: str):
    """Everything the reader hands on, as comparable plain data."""
    if loader == "raw":
        import xarray as xr

        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    elif kind == "state":
        from rve.homogenisation.checkpoint import load_state

        st = load_state(path)
        return {k: (np.asarray(v).tobytes() if isinstance(v, np.ndarray) else json.dumps(v, sort_keys=True,
                                                                                              default=str))
                for k, v in vars(st).items()}
    else:
        from rve.tables import open_table

        ds = open_table(path)
    out = {"attrs": json.dumps({k: str(v) for k, v in ds.attrs.items()}, sort_keys=True)}
    for name, var in ds.variables.items():
        vals = var.values
        out[name] = (str(var.dims), vals.tobytes() if vals.dtype.kind in "biufc" else repr(vals.tolist()))
    return out


def _worker(conn, kind: str, loader: str):
    import logging

    logging.disable(logging.WARNING)
    while True:
        msg = conn.recv()
        if msg is None:
            return
        path = msg
        try:
            conn.send(("ok", _fingerprint(kind, path, loader)))
        except Exception as exc:  # noqa: BLE001 - every failure is classed
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


class Reader:
    """A worker process that loads files one at a time; killed and restarted on a hang."""

    def __init__(self, kind: str, loader: str):
        self.kind, self.loader = kind, loader
        self._start()

    def _start(self):
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, self.kind, self.loader), daemon=True)
        self.proc.start()

    def load(self, path: str, timeout: float):
        self.conn.send(path)
        if self.conn.poll(timeout):
            try:
                return self.conn.recv()
            except EOFError:   # the reader died (e.g. a segfault inside HDF5)
                self.proc.join()
                code = self.proc.exitcode
                self._start()
                return ("crash", f"the reading process died (exit code {code})")
        self.proc.kill()
        self.proc.join()
        self._start()
        return ("hang", f"no answer within {timeout:g} s")

    def close(self):
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.proc.join(2)
        if self.proc.is_alive():
            self.proc.kill()


def flip_campaign(kind: str, original: Path, n: int, seed: int, timeout: float, loader: str, work: Path) -> dict:
    data = original.read_bytes()
    rng = np.random.default_rng(seed)
    reader = Reader(kind, loader)
    ref = reader.load(str(original), 60)
    if ref[0] != "ok":
        raise SystemExit(f"the undamaged {kind} file does not load: {ref[1]}")
    counts = {"identical": 0, "named error": 0, "unnamed error": 0, "crash": 0, "silently different": 0, "hang": 0}
    slow = 0.0
    examples: dict = {}
    damaged = work / f"damaged_{kind}{original.suffix}"
    for i in range(n):
        pos = int(rng.integers(len(data)))
        buf = bytearray(data)
        buf[pos] ^= int(rng.integers(1, 256))
        damaged.write_bytes(bytes(buf))
        t0 = time.perf_counter()
        status, payload = reader.load(str(damaged), timeout)
        dt = time.perf_counter() - t0
        slow = max(slow, dt)
        if status == "ok":
            cls = "identical" if payload == ref[1] else "silently different"
        elif status == "hang":
            cls = "hang"
        elif status == "crash":
            cls = "crash"
        else:
            cls = "named error" if str(damaged) in payload else "unnamed error"
        counts[cls] += 1
        examples.setdefault(cls, f"byte {pos}: {str(payload)[:160]}" if status != "ok" else f"byte {pos}")
    reader.close()
    return {"file": str(original), "bytes": len(data), "flips": n, "counts": counts, "slowest_s": slow,
            "examples": examples}


def strip_protection(kind: str, path: Path) -> Path:
    """Rewrite ``path`` as today's main wrote it: no Fletcher-32, no trailer, no attribute."""
    import xarray as xr

    from rve.io.checksum import CHECKSUM_ATTR

    out = path.with_name(f"plain_{path.name}")
    with xr.open_dataset(path, engine="netcdf4") as ds:
        ds = ds.load()
    ds.attrs.pop(CHECKSUM_ATTR, None)
    if kind == "table":
        from rve.tables.io import _encoding, from_cf, to_cf

        disk = to_cf(from_cf(ds))
        disk.attrs.pop(CHECKSUM_ATTR, None)
        for v in disk.variables.values():
            v.encoding = {}
        disk.to_netcdf(out, engine="netcdf4", format="NETCDF4", encoding=_encoding(disk))
    else:
        for v in ds.variables.values():
            v.encoding = {}
        ds.to_netcdf(out, engine="netcdf4", format="NETCDF4")
    return out


def run_flips(args) -> bool:
    ok = True
    with tempfile.TemporaryDirectory(prefix="rve_faults_") as tmp:
        work = Path(tmp)
        files = {"state": make_state(work), "table": make_table(work)}
        if args.strip:
            files = {k: strip_protection(k, v) for k, v in files.items()}
        for kind, path in files.items():
            r = flip_campaign(kind, path, args.n, args.seed, args.timeout, args.loader, work)
            c = r["counts"]
            print(f"{kind} file ({r['bytes']} bytes, {'unprotected, ' if args.strip else ''}loader {args.loader}): {r['flips']} single-byte flips -> "
                  + ", ".join(f"{k} {v}" for k, v in c.items()) + f"; slowest answer {r['slowest_s']:.2f} s")
            for k, v in r["examples"].items():
                print(f"    e.g. {k}: {v}")
            bad = c["silently different"] + c["hang"] + c["unnamed error"] + c["crash"]
            ok &= bad == 0 and r["slowest_s"] <= args.timeout
    print(f"flips: {'PASS' if ok else 'FAIL'} (none used silently, each answer within {args.timeout:g} s)")
    return ok


# ----------------------------------------------------------------------------- pytest parts
def run_pytest(expr: str, label: str) -> bool:
    cmd = [sys.executable, "-m", "pytest", "-q", "-m", "faults", "-k", expr, "tests/", "-p", "no:cacheprovider"]
    print(f"{label}: {' '.join(cmd[1:])}")
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    tail = [ln for ln in proc.stdout.strip().splitlines() if ln.strip()][-1:]
    print(f"    {tail[0] if tail else proc.stderr[-500:]} ({time.perf_counter() - t0:.0f} s)")
    return proc.returncode == 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("parts", nargs="*", default=[],
                    help="flips, moved-node, livelock, inputs, kills (default: all)")
    ap.add_argument("--n", type=int, default=300, help="flips per file")
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds a load may take")
    ap.add_argument("--loader", choices=["rve", "raw"], default="rve",
                    help="rve: the package's verified readers; raw: xarray.open_dataset (today's main)")
    ap.add_argument("--strip", action="store_true",
                    help="flip files rewritten without Fletcher-32 and trailer (as today's main wrote them)")
    args = ap.parse_args(argv)
    parts = args.parts or ["flips", "moved-node", "livelock", "inputs", "kills"]
    results = {}
    for p in parts:
        if p == "flips":
            results[p] = run_flips(args)
        elif p == "moved-node":
            results[p] = run_pytest("moved_node", "state with one node moved by 2.6 % of R (valid checksum)")
        elif p == "livelock":
            results[p] = run_pytest("livelock", "dynamic wire at +-200 V and alpha_mu = -100 MPa/K")
        elif p == "inputs":
            results[p] = run_pytest("bad_input or config_fault", "bad-input classes")
        elif p == "kills":
            results[p] = run_pytest("kill or corrupt_resume", "SIGKILL/SIGTERM at every stage, resume")
        else:
            ap.error(f"unknown part {p!r}")
    print("summary: " + ", ".join(f"{k} {'PASS' if v else 'FAIL'}" for k, v in results.items()))
    return 0 if all(results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
