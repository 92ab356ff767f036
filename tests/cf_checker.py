"""The reference CF checker (pip ``cfchecker``) as the tests run it.

``cfchecker`` reads units through ``cfunits``, which loads the UDUNITS-2 C library with
``ctypes.util.find_library("udunits2")``: on a machine without Debian's libudunits2-0 that
fails, although the ``cf-units`` wheel (a test extra) bundles the same library and its XML
database. ``cfchecks_command()`` returns the checker and an environment in which it finds
that bundled copy (a ``libudunits2.so`` link on ``LIBRARY_PATH``/``LD_LIBRARY_PATH``, the
database on ``UDUNITS2_XML_PATH``), so the README's test line needs no system package; a
system library, where installed, is found first.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Optional, Tuple


def cfchecks_command(workdir: Path) -> Tuple[Optional[str], dict]:
    """(path of ``cfchecks`` or None, environment for the subprocess)."""
    exe = shutil.which("cfchecks")
    env = dict(os.environ)
    if exe is None:
        return None, env
    try:
        import cf_units
    except ImportError:
        return exe, env
    pkg = Path(cf_units.__file__).parent
    libs = sorted(pkg.parent.glob("cf_units.libs/libudunits2*.so*"))
    xml = pkg / "etc" / "share" / "udunits2.xml"
    if libs:
        link_dir = Path(workdir) / "udunits2_lib"
        link_dir.mkdir(parents=True, exist_ok=True)
        link = link_dir / "libudunits2.so"
        if not link.exists():
            link.symlink_to(libs[0])
        for key in ("LIBRARY_PATH", "LD_LIBRARY_PATH"):
            env[key] = os.pathsep.join(p for p in (env.get(key), str(link_dir), str(libs[0].parent)) if p)
    if xml.exists() and "UDUNITS2_XML_PATH" not in env:
        env["UDUNITS2_XML_PATH"] = str(xml)
    return exe, env
