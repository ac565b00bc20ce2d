"""raypack.render equals the CLI's image for the same settings and seed, whatever the thread
count; a Scene built from arrays renders as the same mesh loaded from a file."""

from __future__ import annotations

import subprocess
import warnings

import numpy as np
import pytest

import raypack
from conftest import cli, need, scenes_dir, uv_sphere

SETTINGS = dict(spp=4, max_depth=3, light_samples=2, width=64, height=48, seed=11)


def cli_render(scene_path, out, *extra):
    exe = cli()
    s = SETTINGS
    args = [str(exe), "render", str(scene_path), "-f", str(out), "-s", str(s["spp"]), "-m", str(s["max_depth"]),
            "-l", str(s["light_samples"]), "-r", str(s["width"]), str(s["height"]), "--seed", str(s["seed"]), *extra]
    done = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    exr = need("OpenEXR")
    with exr.File(str(out)) as f:
        rgb = f.channels()["RGB"].pixels
    return np.asarray(rgb, dtype=np.float32)


@pytest.mark.parametrize("name, integrator", [("sky/CBbunny.dae", "global"), ("sky/CBspheres.dae", "direct"), ("meshedit/beetle.dae", "normals")])
def test_render_equals_the_cli(tmp_path, name, integrator):
    path = scenes_dir() / "cs184" / name
    want = cli_render(path, tmp_path / "cli.exr", "--integrator", integrator, "-t", "2")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", raypack.SceneWarning)
        image = raypack.render(path, integrator=integrator, threads=1, **SETTINGS)
    assert image.dtype == np.float32 and image.shape == (48, 64, 3)
    assert image.max() > 0
    assert np.array_equal(image, want)


def test_the_built_in_sizes_and_threads():
    v, f = uv_sphere(16, 32)
    scene = raypack.Scene(v, f)
    one = raypack.render(scene, threads=1, **SETTINGS)
    two = raypack.render(scene, threads=2, **SETTINGS)
    assert np.array_equal(one, two)
    other_seed = raypack.render(scene, threads=2, **{**SETTINGS, "seed": 12})
    assert not np.array_equal(one, other_seed)


def test_scene_from_arrays_renders_as_the_same_ply(tmp_path):
    v, f = uv_sphere(20, 40)
    v = v.astype(np.float32)
    ply = tmp_path / "ball.ply"
    header = f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    ply.write_text(header + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in v.tolist()) + "".join(f"3 {a} {b} {c}\n" for a, b, c in f))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", raypack.SceneWarning)
        from_file = raypack.render(ply, **SETTINGS)
    from_arrays = raypack.render(raypack.Scene(v, f), **SETTINGS)
    assert from_file.max() > 0 and np.array_equal(from_file, from_arrays)
    assert np.array_equal(from_file, cli_render(ply, tmp_path / "ball.exr"))
