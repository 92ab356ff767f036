"""rve/process.py: the exit-time freeze. Python's finalisation then skips its collections
over the objects still alive (the cyclic garbage left at exit is not finalised), files
written by the code are complete, and ``RVE_FAST_EXIT=0`` restores Python's own exit."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CODE = """
import sys
import rve  # installs the exit-time freeze
class Node:
    def __del__(self):
        sys.stdout.write("finalised\\n")
a, b = Node(), Node()
a.other, b.other = b, a      # a reference cycle: only the cyclic collector frees it
del a, b
with open(sys.argv[1], "w") as fh:
    fh.write("x" * 100000)
"""


@pytest.mark.parametrize("fast", ["1", "0"])
def test_exit_freeze_skips_the_final_collections_and_keeps_written_files(tmp_path, fast):
    out = tmp_path / "written.txt"
    env = dict(os.environ, RVE_FAST_EXIT=fast)
    # the child's collector is off while it runs, so the cycle is still there at exit
    res = subprocess.run([sys.executable, "-c", "import gc; gc.disable()\n" + CODE, str(out)], cwd=ROOT, env=env,
                         capture_output=True, text=True, check=True)
    assert out.read_text() == "x" * 100000
    finalised = res.stdout.count("finalised")
    assert finalised == (0 if fast == "1" else 2), res.stdout


def test_install_is_idempotent_and_can_be_turned_off(monkeypatch):
    from rve import process

    monkeypatch.setenv(process.FAST_EXIT_ENV, "0")
    assert process.install_fast_exit() is False
    monkeypatch.setenv(process.FAST_EXIT_ENV, "1")
    assert process.install_fast_exit() is True and process.install_fast_exit() is True


def test_keep_freed_memory_is_applied_on_glibc_and_can_be_turned_off(monkeypatch):
    """rve.process.keep_freed_memory sets glibc's mallopt parameters (True on Linux/glibc) in a
    fresh process, and does nothing with RVE_KEEP_FREED=0."""
    import platform
    import subprocess
    import sys

    code = "from rve.process import keep_freed_memory as k; print(k())"
    env = dict(__import__("os").environ)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert out.stdout.strip() == "True"
    env["RVE_KEEP_FREED"] = "0"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
