"""Run the reference CF checker on RVE lookup tables as the tests do (tests/test_tables.py):
on a copy whose Conventions is CF-1.8 (the newest the checker knows), with the local
standard-name stubs of tests/data/cf_tables (the checker would download them), UDUNITS-2
found through tests/cf_checker.py. Prints the error and warning counts of every file;
exit status 1 if any file has either.

    python benchmarks/cf_check_table.py results/rve/*/table.nc
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def check(path: Path, workdir: Path) -> tuple[str, str, int]:
    sys.path.insert(0, str(ROOT / "tests"))
    from cf_checker import cfchecks_command

    import netCDF4

    exe, env = cfchecks_command(workdir)
    if exe is None:
        raise SystemExit("the CF checker (pip cfchecker) is not installed")
    copy = workdir / path.name
    shutil.copy(path, copy)
    with netCDF4.Dataset(copy, "a") as f:
        f.Conventions = "CF-1.8"
    cft = ROOT / "tests" / "data" / "cf_tables"
    run = subprocess.run([exe, "-v", "1.8", "-s", str(cft / "standard_name_table.xml"), "-a",
                          str(cft / "area_type_table.xml"), "-r", str(cft / "region_names.xml"), str(copy)],
                         capture_output=True, text=True, timeout=300, env=env)
    lines = run.stdout.splitlines()
    errors = next((ln for ln in lines if "ERRORS detected" in ln), "ERRORS detected: ?")
    warnings = next((ln for ln in lines if "WARNINGS given" in ln), "WARNINGS given: ?")
    return errors.strip(), warnings.strip(), run.returncode


def main(paths) -> int:
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        for k, p in enumerate(map(Path, paths)):
            work = Path(tmp) / str(k)
            work.mkdir()
            errors, warnings, rc = check(p, work)
            print(f"{p}: {errors}, {warnings}")
            bad += int(rc != 0 or not errors.endswith(" 0") or not warnings.endswith(" 0"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
