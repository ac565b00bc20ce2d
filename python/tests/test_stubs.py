"""The type stubs match the module (mypy's stubtest) and type-check the Python sources."""

from __future__ import annotations

import subprocess
import sys

from conftest import REPO, need


def test_stubs_match_the_runtime_module():
    need("mypy")
    done = subprocess.run([sys.executable, "-m", "mypy.stubtest", "pyraypack._raypack"], capture_output=True, text=True, cwd="/")
    assert done.returncode == 0, done.stdout + done.stderr


def test_package_type_checks():
    need("mypy")
    sources = [str(REPO / "python" / "pyraypack" / name) for name in ("__init__.py", "trimesh.py", "dask.py")]
    done = subprocess.run([sys.executable, "-m", "mypy", "--ignore-missing-imports", *sources], capture_output=True, text=True, cwd="/")
    assert done.returncode == 0, done.stdout + done.stderr
