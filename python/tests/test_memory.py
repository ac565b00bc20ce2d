"""Tracing adds no more memory than its output arrays: rays are copied a pass at a time
(2 MiB), never whole (Linux: peak RSS from /proc/self/status)."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import pytest

SCRIPT = r"""
import numpy as np, pyraypack, sys
from conftest import uv_sphere

def peak():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024

def reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")

k = int(sys.argv[1])
scene = pyraypack.Scene(*uv_sphere(32, 64))
rng = np.random.default_rng(0)
o = (rng.random((k, 3), dtype=np.float32) - 0.5) * 4
d = rng.random((k, 3), dtype=np.float32) - 0.5
scene.intersect(o[:100_000], d[:100_000])  # start the threads
for name, query in (("intersect", scene.intersect), ("occluded", scene.occluded)):
    reset_peak()
    before = peak()
    out = query(o, d)
    added = peak() - before
    size = sum(a.nbytes for a in out) if name == "intersect" else out.nbytes
    print(name, added, size, int(np.count_nonzero(out.prim >= 0 if name == "intersect" else out)))
    del out
"""


def test_ten_million_rays_add_one_copy_of_the_outputs():
    if not pathlib.Path("/proc/self/clear_refs").exists():
        pytest.skip("SKIPPED: needs Linux /proc/self/clear_refs to measure peak memory")
    k = 10_000_000
    here = pathlib.Path(__file__).parent
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(k)], capture_output=True, text=True, cwd=here, timeout=600)
    assert done.returncode == 0, done.stderr
    for line in done.stdout.splitlines():
        name, added, size, hits = line.split()
        added, size, hits = int(added), int(size), int(hits)
        print(f"{name}: {k} rays, outputs {size / 2**20:.1f} MiB, peak RSS grew {added / 2**20:.1f} MiB")
        assert hits > k // 10
        # The outputs, plus per-thread buffers and thread stacks (a few MiB).
        assert added <= size + 16 * 2**20, f"{name}: peak RSS grew {added} bytes for {size} bytes of output"
