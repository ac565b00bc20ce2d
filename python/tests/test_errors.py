"""Bad input raises ValueError / TypeError / FileNotFoundError naming the argument, its shape
or dtype and what was expected; nothing crashes the interpreter."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import pyraypack

V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float32)
F = np.array([[0, 1, 2]])
O = np.zeros((4, 3))
D = np.tile([0, 0, 1.0], (4, 1))


@pytest.fixture(scope="module")
def scene():
    return pyraypack.Scene(V, F)


@pytest.mark.parametrize(
    "vertices, faces, error, message",
    [
        (V[:, :2], F, ValueError, r"vertices: expected shape \(N, 3\), got \(3, 2\)"),
        (V.ravel(), F, ValueError, r"vertices: expected shape \(N, 3\), got \(9,\)"),
        (V.astype(complex), F, TypeError, r"vertices: expected an array of real numbers .*got dtype complex128"),
        (np.array([["a", "b", "c"]] * 3), F, TypeError, r"vertices: .*got dtype <U1"),
        (V.astype(bool), F, TypeError, r"vertices: .*got dtype bool"),
        (V, np.array([[0, 1, 2, 0]]), ValueError, r"faces: expected shape \(M, 3\), got \(1, 4\)"),
        (V, np.array([[0, 1, 2.0]]), TypeError, r"faces: expected an array of integers, got dtype float64"),
        (V, np.array([[0, 1, 3]]), ValueError, r"faces\[0\] = \[0, 1, 3\]: index 3 out of range for 3 vertices"),
        (V, np.array([[0, 1, 2], [0, -1, 2]]), ValueError, r"faces\[1\] = \[0, -1, 2\]: index -1 out of range"),
        (V, np.array([[0, 1, 2**40]], dtype=np.uint64), ValueError, r"faces\[0\].*out of range for 3 vertices"),
        (V, "faces", TypeError, r"faces: expected an array of integers"),
        (None, F, TypeError, r"vertices: expected an array of real numbers"),
    ],
)
def test_bad_meshes(vertices, faces, error, message):
    with pytest.raises(error, match=message):
        pyraypack.Scene(vertices, faces)


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        ({"quality": "best"}, ValueError, r"quality: expected 'fast', 'medium' or 'high', got 'best'"),
        ({"threads": 0}, ValueError, r"threads: expected None \(all cores\) or 1 to \d+ threads \(8 per logical CPU; .*\), got 0"),
        ({"threads": -1}, ValueError, r"threads: expected None \(all cores\) or 1 to \d+ threads \(8 per logical CPU; .*\), got -1"),
    ],
)
def test_bad_build_options(kwargs, error, message):
    with pytest.raises(error, match=message):
        pyraypack.Scene(V, F, **kwargs)


@pytest.mark.parametrize(
    "args, kwargs, error, message",
    [
        ((O[:, :2], D), {}, ValueError, r"origins: expected shape \(K, 3\) or \(3,\), got \(4, 2\)"),
        ((O, D[:3]), {}, ValueError, r"origins and directions: expected as many rows, got 4 origins and 3 directions"),
        ((O, D.reshape(4, 3, 1)), {}, ValueError, r"directions: expected shape \(K, 3\) or \(3,\), got \(4, 3, 1\)"),
        ((O, D.astype(np.complex64)), {}, TypeError, r"directions: .*got dtype complex64"),
        ((O, D), {"tnear": np.zeros(3)}, ValueError, r"tnear: expected a number or shape \(4,\) \(one per ray\), got \(3,\)"),
        ((O, D), {"tfar": np.ones((4, 1))}, ValueError, r"tfar: expected a number or shape \(4,\) \(one per ray\), got \(4, 1\)"),
        ((O, D), {"tfar": True}, TypeError, r"tfar: expected a number or an array of numbers, got a bool"),
        ((O, D), {"tfar": "far"}, TypeError, r"tfar: .*got dtype <U3"),
        ((O, D), {"tnear": -1e-6}, ValueError, r"tnear: expected values >= 0 \(t is measured from each ray's origin.*got -0\.000001$"),
        ((O, D), {"tnear": np.array([0, 1, -0.5, 2])}, ValueError, r"tnear: expected values >= 0 .*got -0\.5 for ray 2$"),
        ((O, D), {"tnear": np.float32(-np.inf)}, ValueError, r"tnear: expected values >= 0 .*got -inf$"),
        ((O, D), {"tfar": -1}, ValueError, r"tfar: expected values >= 0 .*got -1$"),
        ((O, D), {"tfar": np.array([1, 2, 3, -4], np.float32)}, ValueError, r"tfar: expected values >= 0 .*got -4 for ray 3$"),
        ((O, D), {"threads": 0}, ValueError, r"threads: expected None \(all cores\) or 1 to \d+ threads \(8 per logical CPU; .*\), got 0"),
    ],
)
def test_bad_rays(scene, args, kwargs, error, message):
    for query in (scene.intersect, scene.occluded, scene.intersect_all):
        with pytest.raises(error, match=message):
            query(*args, **kwargs)


def test_bad_intersect_all_step(scene):
    with pytest.raises(ValueError, match=r"min_step: expected a finite distance >= 0, got -1"):
        scene.intersect_all(O, D, min_step=-1.0)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"no/such/scene.obj"):
        pyraypack.load(tmp_path / "no/such/scene.obj")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises(ValueError, match=r"bad.obj:line 4"):
        pyraypack.load(bad)
    other = tmp_path / "scene.stl"
    other.write_text("solid")
    with pytest.raises(ValueError, match=r"scene.stl: unsupported scene format \(expected .dae, .obj or .ply\)"):
        pyraypack.load(other)
    with pytest.raises(FileNotFoundError, match=r"missing.dae"):
        pyraypack.render(tmp_path / "missing.dae")


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        ({"width": 0}, ValueError, r"width, height: expected 1 to 32768 pixels each, got 0 x 360"),
        ({"spp": 0}, ValueError, r"spp, light_samples: expected at least 1 each, got spp=0"),
        ({"integrator": "photons"}, ValueError, r"integrator: expected 'global', .* got 'photons'"),
        ({"threads": 0}, ValueError, r"threads: expected None"),
    ],
)
def test_bad_render_settings(scene, kwargs, error, message):
    with pytest.raises(error, match=message):
        pyraypack.render(scene, **kwargs)


def test_render_needs_a_scene_or_a_path():
    with pytest.raises(TypeError, match=r"scene: expected a pyraypack.Scene or a path to a scene file, got int"):
        pyraypack.render(3)


def test_hostile_values_do_not_crash(scene):
    # NaN, Inf and huge values anywhere: rays miss, vertices are dropped, the process lives.
    code = """
import numpy as np, pyraypack, warnings
warnings.simplefilter("ignore")
rng = np.random.default_rng(0)
vals = np.array([np.nan, np.inf, -np.inf, 1e38, -1e38, 0.0, 1e-45, 3.0e38])
v = rng.choice(vals, size=(300, 3)); v[::3] = rng.random((100, 3))
f = rng.integers(0, 300, size=(500, 3))
s = pyraypack.Scene(v, f)
o = rng.choice(vals, size=(5000, 3)); d = rng.choice(vals, size=(5000, 3))
# Negative tnear / tfar are a ValueError (test_bad_rays); NaN and Inf go through.
h = s.intersect(o, d, tnear=np.abs(rng.choice(vals, 5000)), tfar=np.abs(rng.choice(vals, 5000)))
s.occluded(o, d); s.intersect_all(o, d, max_hits=3)
print("alive", s.report["dropped_non_finite"] > 0)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "alive True"
