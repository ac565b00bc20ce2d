"""The module against a hostile (or careless) caller: sizes that cannot fit, arrays resized or
replaced by another thread while a query runs without the GIL, absurd thread counts, a bad
``RAYPACK_ISA``, and build arguments that would be ignored. Each is a Python exception naming
the argument; nothing takes the interpreter down. Risky cases run in a subprocess."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

import pyraypack

V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
F = np.array([[0, 1, 2]])


def run(code: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    full = dict(os.environ, **(env or {}))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, env=full)


def test_sizes_that_cannot_fit_are_memory_errors_not_aborts():
    # Under an 8 GiB address-space limit the answer is the same on every machine; before, the
    # render aborted the interpreter (SIGABRT) after allocating what it could.
    code = """
import resource, numpy as np, pyraypack
resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))
s = pyraypack.Scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
for call in (lambda: pyraypack.render(s, width=32768, height=32768),
             lambda: pyraypack._raypack._ray_sets(s, 32768, 32768)):
    try:
        call()
        print("no error")
    except MemoryError as e:
        print("MemoryError:", e)
try:
    pyraypack._raypack._ray_sets(s, 65536, 65536)
except ValueError as e:
    print("ValueError:", e)
"""
    out = run(code)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert len(lines) == 3, out.stdout
    assert lines[0].startswith("MemoryError: width, height: 32768 x 32768: needs about"), lines[0]
    assert "ulimit -v" in lines[0] and "use a smaller size, such as width=" in lines[0], lines[0]
    assert lines[1].startswith("MemoryError: width, height: 32768 x 32768: needs about"), lines[1]
    assert lines[2] == "ValueError: width, height: expected 1 to 32768 rays each, got 65536 x 65536", lines[2]


@pytest.mark.parametrize("attack", ["o.resize((1, 3), refcheck=False)", "o.__setstate__(np.ones((2, 3), np.float32).__reduce__()[2])"])
def test_arrays_freed_by_another_thread_during_a_query_do_not_crash(attack):
    # Before, either attack freed the memory the kernels were reading: SIGSEGV.
    code = f"""
import threading, time, numpy as np, pyraypack
s = pyraypack.Scene(np.array([[-9, -9, 0], [9, -9, 0], [0, 9, 0]]), np.array([[0, 1, 2]]))
n = 2_000_000
for query in ("intersect", "occluded", "intersect_all"):
    o = np.zeros((n, 3), np.float32); o[:, 2] = 5.0
    d = np.zeros((n, 3), np.float32); d[:, 2] = -1.0
    def attack():
        time.sleep(0.01)
        {attack}
    t = threading.Thread(target=attack); t.start()
    try:
        out = getattr(s, query)(o, d, threads=2)
        hits = out.prim if query == "intersect" else out if query == "occluded" else out[1]
        # Every ray read before the attack hit the triangle; any read after saw the new data.
        print(query, "done", len(hits))
    except ValueError as e:
        print(query, "ValueError:", e)
    t.join()
"""
    out = run(code)
    assert out.returncode == 0, f"exit {out.returncode}: {out.stderr[-2000:]}"
    lines = out.stdout.splitlines()
    assert [l.split()[0] for l in lines] == ["intersect", "occluded", "intersect_all"], out.stdout
    for l in lines:
        assert "done" in l or "an array was resized while the query ran" in l, l


def test_thread_counts_are_capped():
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    too_many = 8 * cpus + 1
    s = pyraypack.Scene(V, F)
    message = rf"threads: expected None \(all cores\) or 1 to {8 * cpus} threads \(8 per logical CPU; this machine has {cpus}\), got {too_many}"
    for call in (
        lambda: pyraypack.Scene(V, F, threads=too_many),
        lambda: s.intersect(V, V, threads=too_many),
        lambda: s.occluded(V, V, threads=too_many),
        lambda: pyraypack.render(s, width=4, height=4, threads=too_many),
    ):
        with pytest.raises(ValueError, match=message):
            call()
    s.intersect(V, V, threads=8 * cpus)


@pytest.mark.parametrize(
    "value, error",
    [(-1, ValueError), (0, ValueError), (2**70, ValueError), (-(2**70), ValueError), ("2", TypeError), (2.0, TypeError), (True, TypeError)],
)
def test_thread_arguments_that_are_not_positive_ints_name_the_argument(value, error):
    # Not the conversion's bare OverflowError or TypeError: every entry point names `threads`.
    s = pyraypack.Scene(V, F)
    message = rf"threads: expected None \(all cores\) or 1 to \d+ threads \(8 per logical CPU; .*\), got {re.escape(repr(value))}"
    for call in (
        lambda: pyraypack.Scene(V, F, threads=value),
        lambda: s.intersect(V, V, threads=value),
        lambda: s.occluded(V, V, threads=value),
        lambda: s.intersect_all(V, V, threads=value),
        lambda: pyraypack.render(s, width=4, height=4, threads=value),
    ):
        with pytest.raises(error, match=message):
            call()


@pytest.mark.parametrize("value", [b"fastest", b"avx\xff"])
def test_raypack_isa_is_checked_as_the_cli_checks_it(value):
    # Before, the module ignored a garbage (or non-UTF-8) RAYPACK_ISA silently.
    code = """
import numpy as np, pyraypack
try:
    pyraypack.Scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    print("accepted")
except ValueError as e:
    print(e)
"""
    env = dict(os.environb)
    env[b"RAYPACK_ISA"] = value
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    shown = "`fastest`" if value == b"fastest" else '`"avx\\xFF"`'
    want = f"RAYPACK_ISA: unknown ISA {shown}: expected sse, avx2 or avx512"
    assert out.stdout.decode().strip() == want


def test_build_arguments_that_would_be_ignored_or_misread_are_errors(tmp_path, monkeypatch):
    s = pyraypack.Scene(V, F)
    # Before, "ultra" was accepted and ignored, as was a quality for a scene built already.
    with pytest.raises(ValueError, match=r"quality: expected 'fast', 'medium' or 'high', got 'ultra'"):
        pyraypack.render(s, width=4, height=4, quality="ultra")
    with pytest.raises(ValueError, match=r"quality, watertight, bvh_cache: they build a scene from a file"):
        pyraypack.render(s, width=4, height=4, quality="high")
    # Before, bvh_cache="" wrote the cache file into the current directory.
    monkeypatch.chdir(tmp_path)
    for call in (lambda: pyraypack.Scene(V, F, bvh_cache=""), lambda: pyraypack.load(tmp_path / "x.obj", bvh_cache="")):
        with pytest.raises(ValueError, match=r"bvh_cache: expected a directory, got an empty path"):
            call()
    assert list(tmp_path.iterdir()) == []
