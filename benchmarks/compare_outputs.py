"""Bit-for-bit comparison of the dynamic scenes' and the RVE table's outputs between two
commits (the acceptance check of a refactoring that must not change a result).

    nice -n 10 python benchmarks/compare_outputs.py make OUT [--only impact,induced,table]
    python benchmarks/compare_outputs.py compare REF OUT

``make`` runs, with the code on ``PYTHONPATH``:

* ``impact``: the impact scene on the reduced weave of tests/test_impact.py (8 x 8 yarns,
  16 elements, projectile radius 4.5 mm) to t = 0.1 ms (200 nominal steps; relaxation,
  impact, checkpoints and outputs as ``rve run`` does them), under ``OUT/impact``;
* ``induced``: the induced deformation, orientation B2 of configs/scenes/induced_deformation.yaml
  shortened to t = 1 ms (200 steps, the config's step size), under ``OUT/induced``;
* ``induced_full`` (not in the default set: minutes): orientation B2 over the config's
  whole 15 ms (3000 steps), under ``OUT/induced_full``;
* ``dynamic_wire`` (not in the default set): the dynamic wire of configs/scenes/dynamic_wire.yaml
  on 40 steps, coupled temperature, and ``dynamic_wire_post``: the same with S = alpha_mu = 0
  (the temperature post-solved afterwards), under ``OUT/dynamic_wire[_post]``;
* ``table``: the CI RVE table (configs/tests/pipeline_ci.yaml, run ``ci``) through Snakemake
  in a copy of the workflow, copied to ``OUT/table.nc``.

Both scenes run with ``newton.jacobian_reuse=true`` instead of the configs' ``auto``: the
cost rule of ``auto`` weighs measured wall times, so two runs of one commit can take
different Newton paths (states equal to the Newton tolerance, not bit for bit); the
contraction rule alone is deterministic.

``compare`` compares every variable of every netCDF file (values and dtypes, NaN equal to
NaN), every array of every ``.npz`` output except the resumable checkpoint (its format is
not a result), every VTK file byte for byte and every summary entry except wall times,
memory and paths. It prints one line per file and ends with ``IDENTICAL`` or
``DIFFERENCES FOUND`` (exit status 1).
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

IMPACT = ["geometry.n_warp=8", "geometry.n_weft=8", "geometry.span=12.7 mm", "mesh.elements=16",
          "projectile.radius=4.5 mm", "time.t_end=0.1 ms", "time.steps=200", "output.png=false",
          "newton.jacobian_reuse=true"]
INDUCED = ["field.orientation=B2", "time.adaptive.enabled=false", "time.t_end=1 ms", "time.steps=200", "output.png=false",
           "newton.jacobian_reuse=true"]
INDUCED_FULL = ["field.orientation=B2", "time.adaptive.enabled=false", "output.png=false", "newton.jacobian_reuse=true"]
DYNAMIC_WIRE = ["time.steps=40"]
DYNAMIC_WIRE_POST = ["time.steps=40", "material.alpha_mu=0 MPa/K", "material.seebeck=0 V/K"]

#: summary keys that measure the machine, not the result
UNSTABLE = {"wall_time_s", "peak_rss_MiB", "peak_memory_MiB", "loaded_from", "files", "history_file", "wall_s",
            "elapsed_s", "rss_MiB"}
SKIP_FILES = {"checkpoint.npz", "checkpoint.nc"}
#: summary counters that the refactoring corrected (printed, not counted as a difference):
#: the impact's per-chunk integrator calls dropped the factorisation, linear-solve and
#: rejection counts of every chunk that an early contact rebuild ended; the counts now
#: cover every accepted step (as the induced scene's always did)
CORRECTED = {"/factorizations", "/factorizations_per_stage", "/linear_solves", "/steps_rejected",
             "/relaxation/rejected", "info/rejected"}


def _scene(config: str, overrides: list[str], out: Path) -> None:
    from rve.config.loader import load_config
    from rve.io.provenance import to_jsonable
    from rve.scenes.registry import run_scene

    cfg = load_config(ROOT / config, overrides)
    summary = run_scene(cfg, out)
    (out / "summary.json").write_text(json.dumps(to_jsonable(summary), indent=2, default=str, sort_keys=True))


def _table(out: Path) -> None:
    sys.path.insert(0, str(ROOT / "tests"))
    from workflow_copy import workflow_copy

    with tempfile.TemporaryDirectory() as tmp:
        work = workflow_copy(Path(tmp))
        subprocess.run([sys.executable, "-m", "snakemake", "-j2", "results/rve/ci/table.nc", "--configfile",
                        "configs/tests/pipeline_ci.yaml"], cwd=work, check=True, capture_output=True)
        shutil.copy2(work / "results/rve/ci/table.nc", out / "table.nc")


def make(out: Path, only: set[str]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    if "impact" in only:
        _scene("configs/scenes/impact.yaml", IMPACT, out / "impact")
    if "induced" in only:
        _scene("configs/scenes/induced_deformation.yaml", INDUCED, out / "induced")
    if "induced_full" in only:
        _scene("configs/scenes/induced_deformation.yaml", INDUCED_FULL, out / "induced_full")
    if "dynamic_wire" in only:
        _scene("configs/scenes/dynamic_wire.yaml", DYNAMIC_WIRE, out / "dynamic_wire")
        _scene("configs/scenes/dynamic_wire.yaml", DYNAMIC_WIRE_POST, out / "dynamic_wire_post")
    if "table" in only:
        _table(out)


def _strip(d):
    if isinstance(d, dict):
        return {k: _strip(v) for k, v in d.items() if k not in UNSTABLE}
    if isinstance(d, list):
        return [_strip(v) for v in d]
    return d


def _diff_json(a, b, path=""):
    if isinstance(a, dict) and isinstance(b, dict):
        out = [f"{path}/{k}: only in one" for k in sorted(set(a) ^ set(b))]
        for k in sorted(set(a) & set(b)):
            out += _diff_json(a[k], b[k], f"{path}/{k}")
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [e for i, (x, y) in enumerate(zip(a, b)) for e in _diff_json(x, y, f"{path}[{i}]")]
    return [] if a == b or (a != a and b != b) else [f"{path}: {a!r} != {b!r}"]


def _same_array(x, y) -> bool:
    x, y = np.asarray(x), np.asarray(y)
    if x.dtype != y.dtype or x.shape != y.shape:
        return False
    return bool(np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"))


def _compare_nc(a: Path, b: Path) -> list[str]:
    import xarray as xr

    with xr.open_dataset(a, decode_times=False) as da, xr.open_dataset(b, decode_times=False) as db:
        bad = [f"{v}: only in one" for v in sorted(set(da.variables) ^ set(db.variables))]
        for v in sorted(set(da.variables) & set(db.variables)):
            if not _same_array(da[v].values, db[v].values) or da[v].dims != db[v].dims:
                bad.append(f"{v}: different")
        return bad


def _compare_npz(a: Path, b: Path) -> list[str]:
    with np.load(a, allow_pickle=False) as da, np.load(b, allow_pickle=False) as db:
        bad = [f"{v}: only in one" for v in sorted(set(da.files) ^ set(db.files))]
        for v in sorted(set(da.files) & set(db.files)):
            x, y = da[v], db[v]
            if x.dtype.kind == "U" and x.ndim == 0 and str(x).startswith("{"):  # a JSON record (e.g. run info)
                bad += [f"{v}{e}" for e in _diff_json(_strip(json.loads(str(x))), _strip(json.loads(str(y))))]
            elif not _same_array(x, y):
                bad.append(f"{v}: different")
        return bad


def compare(ref: Path, new: Path) -> int:
    files = sorted(p.relative_to(ref) for p in ref.rglob("*") if p.is_file() and p.name not in SKIP_FILES)
    if not files:
        print(f"no reference outputs under {ref}")
        return 2
    same = True
    for rel in files:
        a, b = ref / rel, new / rel
        if not b.exists():
            print(f"{rel}: MISSING")
            same = False
            continue
        if rel.suffix == ".nc":
            bad = _compare_nc(a, b)
        elif rel.suffix == ".npz":
            bad = _compare_npz(a, b)
        elif rel.suffix == ".json":
            bad = _diff_json(_strip(json.loads(a.read_text())), _strip(json.loads(b.read_text())))
        elif rel.suffix == ".png":
            continue
        else:
            bad = [] if a.read_bytes() == b.read_bytes() else ["bytes differ"]
        known = [e for e in bad if e.split(":")[0] in CORRECTED]
        bad = [e for e in bad if e not in known]
        print(f"{str(rel):50s} {'identical' if not bad else 'DIFFERENT'}"
              + (f" ({len(known)} corrected counters)" if known else ""))
        for line in bad[:20]:
            print(f"    {line}")
        for line in known:
            print(f"    corrected: {line}")
        same &= not bad
    extra = sorted(p.relative_to(new) for p in new.rglob("*") if p.is_file() and p.name not in SKIP_FILES
                   and not (ref / p.relative_to(new)).exists())
    for rel in extra:
        print(f"{rel}: only in {new}")
    print("IDENTICAL" if same else "DIFFERENCES FOUND")
    return 0 if same else 1


def main(argv: list[str]) -> int:
    if len(argv) >= 2 and argv[0] == "make":
        only = {"impact", "induced", "table"}
        if "--only" in argv:
            only = set(argv[argv.index("--only") + 1].split(","))
        make(Path(argv[1]), only)
        return 0
    if len(argv) == 3 and argv[0] == "compare":
        return compare(Path(argv[1]), Path(argv[2]))
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
