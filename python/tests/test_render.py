"""pyraypack.render equals the CLI's image for the same settings and seed, whatever the thread
count; a Scene built from arrays renders as the same mesh loaded from a file."""

from __future__ import annotations

import subprocess
import warnings

import numpy as np
import pytest

import pyraypack
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
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        image = pyraypack.render(path, integrator=integrator, threads=1, **SETTINGS)
    assert image.dtype == np.float32 and image.shape == (48, 64, 3)
    assert image.max() > 0
    assert np.array_equal(image, want)


def test_the_built_in_sizes_and_threads():
    v, f = uv_sphere(16, 32)
    scene = pyraypack.Scene(v, f)
    one = pyraypack.render(scene, threads=1, **SETTINGS)
    two = pyraypack.render(scene, threads=2, **SETTINGS)
    assert np.array_equal(one, two)
    other_seed = pyraypack.render(scene, threads=2, **{**SETTINGS, "seed": 12})
    assert not np.array_equal(one, other_seed)


def test_the_sampler_is_the_clis(tmp_path):
    """``sampler=`` is the CLI's ``--sampler``: the same image for the same name, another for the
    other name, and an unknown name is a ValueError naming the argument."""
    path = scenes_dir() / "cs184" / "sky" / "CBspheres.dae"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        independent = pyraypack.render(path, sampler="independent", **SETTINGS)
        sobol = pyraypack.render(path, **SETTINGS)
        assert np.array_equal(independent, cli_render(path, tmp_path / "i.exr", "--sampler", "independent"))
        assert np.array_equal(sobol, cli_render(path, tmp_path / "s.exr"))
        assert not np.array_equal(sobol, independent)
        with pytest.raises(ValueError, match="sampler: unknown sampler \"halton\""):
            pyraypack.render(path, sampler="halton", **SETTINGS)


def test_scene_from_arrays_renders_as_the_same_ply(tmp_path):
    v, f = uv_sphere(20, 40)
    v = v.astype(np.float32)
    ply = tmp_path / "ball.ply"
    header = f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    ply.write_text(header + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in v.tolist()) + "".join(f"3 {a} {b} {c}\n" for a, b, c in f))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        from_file = pyraypack.render(ply, **SETTINGS)
    from_arrays = pyraypack.render(pyraypack.Scene(v, f), **SETTINGS)
    assert from_file.max() > 0 and np.array_equal(from_file, from_arrays)
    assert np.array_equal(from_file, cli_render(ply, tmp_path / "ball.exr"))


def test_windows_are_the_whole_image_s_pixels():
    """Any window's pixels are the whole image's, bit for bit: crop windows, pixel bounds and
    the parts of ``tile_bounds`` (which tile the image), at one and two threads."""
    v, f = uv_sphere(12, 24)
    scene = pyraypack.Scene(v, f)
    whole = pyraypack.render(scene, threads=2, **SETTINGS)
    w, h = SETTINGS["width"], SETTINGS["height"]
    for n in (1, 2, 7):
        parts = pyraypack.tile_bounds(n, w, h)
        assert len(parts) == n
        image = np.full_like(whole, np.nan)
        for i, (x0, x1, y0, y1) in enumerate(parts):
            assert np.isnan(image[y0:y1, x0:x1]).all(), "the parts overlap"
            image[y0:y1, x0:x1] = pyraypack.render(scene, pixel_bounds=(x0, x1, y0, y1), threads=1 + i % 2, **SETTINGS)
        assert np.array_equal(image, whole)
    crop = pyraypack.render(scene, crop_window=(0.25, 0.75, 0.5, 1.0), **SETTINGS)
    assert np.array_equal(crop, whole[h // 2 :, w // 4 : 3 * w // 4])


def test_bad_windows_name_the_argument():
    v, f = uv_sphere(8, 8)
    scene = pyraypack.Scene(v, f)
    for kwargs, says in [
        (dict(crop_window=(0.5, 0.5, 0.0, 1.0)), "crop_window"),
        (dict(crop_window=(0.0, 2.0, 0.0, 1.0)), "crop_window"),
        (dict(pixel_bounds=(0, 65, 0, 48)), "pixel_bounds"),
        (dict(pixel_bounds=(3, 3, 0, 48)), "pixel_bounds"),
        (dict(pixel_bounds=(0, 1, 0, 1), crop_window=(0.0, 1.0, 0.0, 1.0)), "not both"),
    ]:
        with pytest.raises(ValueError, match=says):
            pyraypack.render(scene, **kwargs, **SETTINGS)
    with pytest.raises(ValueError, match="cannot be split into 7 parts"):
        pyraypack.tile_bounds(7, 6, 6)
