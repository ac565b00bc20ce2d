"""pyraypack.__version__ is the crates' and the installed distribution's version, and
pyraypack.isa() names the kernels' instruction set: the CPU's best (read from /proc/cpuinfo
here, independently of the module's detection) unless RAYPACK_ISA lowers it."""

from __future__ import annotations

import importlib.metadata
import os
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

import pyraypack
from conftest import REPO


def package_version(cargo_toml: pathlib.Path) -> str:
    text = cargo_toml.read_text()
    package = text.split("[package]", 1)[1].split("\n[", 1)[0]
    found = re.search(r'^version\s*=\s*"([^"]+)"', package, flags=re.M)
    assert found, f"{cargo_toml}: no [package] version"
    return found.group(1)


def test_version_is_the_crates_and_the_distributions():
    assert pyraypack.__version__ == importlib.metadata.version("pyraypack")
    # The binding crate's version (what maturin gives the wheel) follows the library's.
    if (REPO / "python" / "Cargo.toml").exists():
        assert pyraypack.__version__ == package_version(REPO / "python" / "Cargo.toml")
        assert pyraypack.__version__ == package_version(REPO / "Cargo.toml")


def cpu_best() -> str:
    """The best tier by the CPU's flags: x86-64-v4's AVX-512 subsets, x86-64-v3, else SSE2."""
    try:
        text = pathlib.Path("/proc/cpuinfo").read_text()
    except OSError:
        pytest.skip("SKIPPED: no /proc/cpuinfo to check the ISA against")
    if not re.search(r"^flags\s*:", text, flags=re.M):
        pytest.skip("SKIPPED: /proc/cpuinfo has no x86 flags")
    flags = set(re.search(r"^flags\s*:(.*)$", text, flags=re.M).group(1).split())
    v3 = {"avx", "avx2", "fma", "bmi1", "bmi2", "abm", "popcnt", "movbe", "f16c"}
    v4 = v3 | {"avx512f", "avx512vl", "avx512dq", "avx512bw", "avx512cd"}
    return "avx512" if v4 <= flags else "avx2" if v3 <= flags else "sse2"


def isa_in_a_fresh_process(value: str | None) -> tuple[str, str, str]:
    """(isa(), repr of a scene, stderr) in a new interpreter with RAYPACK_ISA=value."""
    env = {k: v for k, v in os.environ.items() if k != "RAYPACK_ISA"}
    if value is not None:
        env["RAYPACK_ISA"] = value
    code = (
        "import warnings, numpy as np, pyraypack\n"
        "warnings.simplefilter('always')\n"
        "s = pyraypack.Scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))\n"
        "print(pyraypack.isa()); print(repr(s))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd="/")
    assert done.returncode == 0, done.stderr
    isa, rep = done.stdout.splitlines()
    return isa, rep, done.stderr


def test_isa_is_the_cpus_best_unless_raypack_isa_lowers_it():
    best = cpu_best()
    tiers = ["sse2", "avx2", "avx512"]
    isa, rep, _ = isa_in_a_fresh_process(None)
    assert isa == best
    assert rep == f"<pyraypack.Scene: 1 triangles, 0 spheres, isa={best}>"
    for asked in ["sse", "avx2", "avx512"]:
        want = tiers[min(tiers.index("sse2" if asked == "sse" else asked), tiers.index(best))]
        isa, rep, stderr = isa_in_a_fresh_process(asked)
        assert (isa, rep.endswith(f"isa={want}>")) == (want, True), asked
        # A tier above the CPU's is a warning naming the one used.
        assert ("this CPU's best is" in stderr) == (tiers.index(want) < tiers.index("sse2" if asked == "sse" else asked))


def test_isa_refuses_an_unknown_raypack_isa(monkeypatch):
    monkeypatch.setenv("RAYPACK_ISA", "avx9000")
    with pytest.raises(ValueError, match="RAYPACK_ISA: unknown ISA `avx9000`"):
        pyraypack.isa()


def test_isa_is_what_scenes_use():
    scene = pyraypack.Scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    assert repr(scene).endswith(f"isa={pyraypack.isa()}>")
