"""Fault injection, files: checksummed states and tables. Byte flips and
truncations of a real CI state and a table are each a named error (the file and what
failed) or identical data; an open that hangs is bounded; a state with one node moved by
2.6 % of R and a *valid* checksum is refused by the probe job because its recomputed
residual is far above the recorded one; non-equilibria are not stored as equilibria.
The full 300-flip campaign is ``python benchmarks/fault_injection.py flips``."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from rve.homogenisation.checkpoint import load_state, non_final_path
from rve.io.checksum import TRAILER_SIZE, CorruptFileError, open_netcdf, verify

pytestmark = pytest.mark.faults

ROOT = Path(__file__).resolve().parents[1]


def _ci_spec(**scene):
    spec = yaml.safe_load((ROOT / "configs/tests/pipeline_ci.yaml").read_text())["rve"]["runs"]["ci"]
    for section, values in scene.items():
        spec["scene"].setdefault(section, {}).update(values)
    return spec


@pytest.fixture(scope="module")
def ci_states(tmp_path_factory):
    """The CI run's designed and relaxed states, written by the jobs."""
    from rve.homogenisation.jobs import fabric_job, relax_job

    d = tmp_path_factory.mktemp("faults_states")
    spec = _ci_spec()
    fabric_job(d / "initial.nc", None, spec, "base")
    relax_job(d / "initial.nc", d / "relaxed.nc", None, spec, "base")
    return d, spec


@pytest.fixture(scope="module")
def table_file(tmp_path_factory):
    from rve.tables import build_table, write_table
    from rve.tables.jobs import gather_records

    recs = sorted((ROOT / "tests/data/records_v1_ci").glob("*.json"))
    ds = build_table(gather_records(recs, ["uniaxial", "shear"]), fabric={"kind": "plain weave"}, config={})
    path = tmp_path_factory.mktemp("faults_table") / "table.nc"
    write_table(ds, path)
    return path, ds


def _flip(src: Path, dst: Path, pos: int, mask: int = 0x01) -> Path:
    data = bytearray(src.read_bytes())
    data[pos] ^= mask
    dst.write_bytes(bytes(data))
    return dst


# --------------------------------------------------------------------------- checksums
def test_states_and_tables_are_sealed_and_read_back_exactly(ci_states, table_file):
    d, _ = ci_states
    for p in (d / "initial.nc", d / "relaxed.nc", table_file[0]):
        assert verify(p).sealed
    ds = open_netcdf(d / "relaxed.nc")
    numeric = [v for v in ds.variables.values() if v.ndim and v.dtype.kind in "fiu"]
    assert numeric and all(v.encoding.get("fletcher32") for v in numeric), "fletcher32 on every numeric variable"
    # checksums change no number: the table reads back identical (also tests/test_tables.py)
    from rve.tables import open_table
    import xarray as xr

    xr.testing.assert_identical(open_table(table_file[0]), table_file[1])


@pytest.mark.parametrize("kind", ["state", "table"])
def test_byte_flips_are_named_errors_or_identical(kind, ci_states, table_file, tmp_path):
    """40 seeded random flips (the benchmark does 300): every one is caught by the SHA-256
    trailer before HDF5 sees the file, with the file named, in milliseconds."""
    from rve.tables import open_table

    src = ci_states[0] / "relaxed.nc" if kind == "state" else table_file[0]
    reader = load_state if kind == "state" else open_table
    rng = np.random.default_rng(15)
    size = src.stat().st_size
    dst = tmp_path / f"damaged_{kind}.nc"
    named = 0
    for _ in range(40):
        _flip(src, dst, int(rng.integers(size)), int(rng.integers(1, 256)))
        t0 = time.perf_counter()
        with pytest.raises(CorruptFileError) as ei:
            reader(dst)
        assert time.perf_counter() - t0 < 10
        assert str(dst) in str(ei.value)
        named += 1
    assert named == 40


def test_truncation_and_a_stripped_trailer_are_refused(ci_states, tmp_path):
    src = ci_states[0] / "relaxed.nc"
    data = src.read_bytes()
    for cut in (0, 100, len(data) // 2, len(data) - TRAILER_SIZE, len(data) - 1):
        p = tmp_path / f"cut_{cut}.nc"
        p.write_bytes(data[:cut])
        with pytest.raises((CorruptFileError, FileNotFoundError)) as ei:
            load_state(p)
        assert str(p) in str(ei.value)
    # the exact payload without its trailer: a valid HDF5 file that says it was sealed
    p = tmp_path / "stripped.nc"
    p.write_bytes(data[:-TRAILER_SIZE])
    with pytest.raises(CorruptFileError, match="no SHA-256 trailer"):
        load_state(p)
    from rve.tables import open_table

    with pytest.raises(CorruptFileError, match="trailer that is now missing"):
        open_table(p)   # the table reader accepts unsealed files, but not one that lost its seal


def test_corrupt_input_is_quarantined_so_the_producing_job_reruns(ci_states, tmp_path):
    src = ci_states[0] / "relaxed.nc"
    p = _flip(src, tmp_path / "relaxed.nc", 5000)
    with pytest.raises(CorruptFileError, match="moved to relaxed.nc.corrupt"):
        load_state(p, quarantine=True)
    assert not p.exists() and (tmp_path / "relaxed.nc.corrupt").exists()


def test_a_hanging_open_is_bounded(ci_states, tmp_path, monkeypatch):
    """A file without a trailer is opened in a child process first; one that spins HDF5
    (simulated: the child sleeps) is killed after the timeout and named."""
    import rve.io.checksum as C

    p = tmp_path / "legacy.nc"
    p.write_bytes((ci_states[0] / "relaxed.nc").read_bytes()[:-TRAILER_SIZE])
    monkeypatch.setattr(C, "_CHILD", "import time; time.sleep(60)")
    t0 = time.perf_counter()
    with pytest.raises(CorruptFileError, match="did not finish within 1 s") as ei:
        C.open_netcdf(p, timeout=1.0)
    assert time.perf_counter() - t0 < 10 and str(p) in str(ei.value)


def test_legacy_table_without_checksum_still_opens():
    from rve.tables import open_table

    ds = open_table(ROOT / "tests/data/table_v1_ci.nc")
    assert ds.encoding["rve_sealed"] is False and "mode" in ds.dims


# --------------------------------------------------------------------------- equilibrium
def test_moved_node_with_valid_checksum_is_refused_by_the_probe_job(ci_states, tmp_path):
    """One node moved by 2.6 % of R and the file re-sealed (a valid file holding a wrong
    state): the probe job recomputes |F| and refuses it (the file is moved aside)."""
    from rve.homogenisation.jobs import StateRefused, probe_record
    from rve.io.atomic import atomic_netcdf

    d, spec = ci_states
    ds = open_netcdf(d / "relaxed.nc")
    x = ds["state"].values.copy()
    ends = set(ds["end_node"].values.tolist())
    node = [n for n in range(x.shape[0]) if n not in ends][x.shape[0] // 3]
    R = float(ds["radius"].values[ds["node_fibril"].values[node]])
    x[node, 0] += 0.026 * R
    ds["state"] = (ds["state"].dims, x, ds["state"].attrs)
    bad = tmp_path / "relaxed.nc"
    atomic_netcdf(ds, bad)
    assert verify(bad).sealed                     # the checksum is valid
    good = probe_record(d / "relaxed.nc", spec, "base")
    assert good["state"]["residual_N"] <= 10 * max(good["state"]["residual_N_recorded"], 1e-9)
    with pytest.raises(StateRefused) as ei:
        probe_record(bad, spec, "base")
    msg = str(ei.value)
    assert str(bad) in msg and "recomputed" in msg and "records" in msg
    assert not bad.exists() and (tmp_path / "relaxed.nc.corrupt").exists()


def test_moved_node_is_refused_by_rve_check(ci_states, tmp_path):
    from rve.cli import main
    from rve.io.atomic import atomic_netcdf

    d, _ = ci_states
    assert main(["check", str(d / "relaxed.nc"), str(d / "initial.nc")]) == 0
    ds = open_netcdf(d / "relaxed.nc")
    x = ds["state"].values.copy()
    x[x.shape[0] // 2, 1] += 0.026 * float(ds["radius"].values[0])
    ds["state"] = (ds["state"].dims, x, ds["state"].attrs)
    atomic_netcdf(ds, tmp_path / "moved.nc")
    _flip(d / "relaxed.nc", tmp_path / "flipped.nc", 4000)
    assert main(["check", str(tmp_path / "moved.nc"), str(tmp_path / "flipped.nc")]) == 1
    assert (tmp_path / "moved.nc").exists()       # rve check moves files only with --quarantine
    assert main(["check", "--quarantine", str(tmp_path / "flipped.nc")]) == 1
    assert (tmp_path / "flipped.nc.corrupt").exists()


def test_unconverged_relaxation_fails_and_keeps_the_state_under_a_non_final_name(ci_states, tmp_path):
    from rve.homogenisation.jobs import NotAnEquilibrium, relax_job

    d, _ = ci_states
    spec = _ci_spec(relaxation={"static_max_iter": 3, "static_atol": 1e-20})
    out = tmp_path / "relaxed.nc"
    with pytest.raises(NotAnEquilibrium) as ei:
        relax_job(d / "initial.nc", out, None, spec, "base")
    assert "not an equilibrium" in str(ei.value) and "keep_unconverged" in str(ei.value)
    assert not out.exists()
    kept = non_final_path(out)
    assert kept.name == "relaxed.unconverged.nc" and load_state(kept).solver["converged"] is False


def test_kept_unconverged_states_are_flagged_in_the_table_and_listed_first(ci_states, tmp_path):
    from rve.homogenisation.jobs import probe_job, relax_job
    from rve.tables import build_table, summarize
    from rve.tables.jobs import gather_records

    d, _ = ci_states
    spec = _ci_spec(relaxation={"static_max_iter": 3, "static_atol": 1e-20}, checks={"keep_unconverged": True})
    out = tmp_path / "relaxed.nc"
    st = relax_job(d / "initial.nc", out, None, spec, "base")
    assert out.exists() and st.solver["converged"] is False
    rec = probe_job(out, tmp_path / "relaxed.json", None, spec, "base")
    assert rec["state"]["converged"] is False
    ds = build_table(gather_records([tmp_path / "relaxed.json"], ["uniaxial"]), fabric=None, config={})
    assert float(ds["converged"].sel(mode="uniaxial", strain=0.0)) == 0.0
    text = summarize(ds)
    assert text.startswith("NOT CONVERGED: 1 table entry") and "uniaxial strain 0" in text.splitlines()[1]


def test_converged_states_are_flagged_one(ci_states, tmp_path):
    from rve.homogenisation.jobs import probe_job
    from rve.tables import build_table, summarize
    from rve.tables.jobs import gather_records

    d, spec = ci_states
    probe_job(d / "relaxed.nc", tmp_path / "relaxed.json", None, spec, "base")
    ds = build_table(gather_records([tmp_path / "relaxed.json"], ["uniaxial"]), fabric=None, config={})
    assert float(ds["converged"].sel(mode="uniaxial", strain=0.0)) == 1.0
    assert not summarize(ds).startswith("NOT CONVERGED")
