"""pyraypack.Scene / load on closed forms, every array layout, and against the Rust API."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import pyraypack
from conftest import grid, random_rays, scenes_dir, soup, uv_sphere

TRI_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
TRI_F = np.array([[0, 1, 2]])


def test_one_triangle_closed_form():
    scene = pyraypack.Scene(TRI_V, TRI_F)
    hits = scene.intersect(np.array([[0.25, 0.5, 2.0], [2.0, 2.0, 2.0]]), np.array([[0, 0, -1.0], [0, 0, -1.0]]))
    assert hits.t.dtype == np.float32 and hits.prim.dtype == np.int64 and hits.normal.shape == (2, 3)
    assert hits.t.tolist() == [2.0, np.inf]
    assert hits.prim.tolist() == [0, -1]
    assert (hits.u.tolist(), hits.v.tolist()) == ([0.25, 0.0], [0.5, 0.0])
    assert hits.normal.tolist() == [[0, 0, 1], [0, 0, 0]]
    assert hits.hit.tolist() == [True, False]
    t, prim, u, v, normal = hits
    assert t is hits.t and normal is hits.normal
    assert "1 of 2 rays hit" in repr(hits)


def test_t_is_in_units_of_the_direction_and_the_interval_is_closed():
    scene = pyraypack.Scene(TRI_V, TRI_F)
    o = [0.25, 0.25, 2.0]
    assert scene.intersect(o, [[0, 0, -2.0]]).t.tolist() == [1.0]
    # [tnear, tfar]: a hit at exactly tfar counts, and one at exactly tnear too.
    assert scene.intersect(o, [[0, 0, -1.0]], tfar=2.0).prim.tolist() == [0]
    assert scene.intersect(o, [[0, 0, -1.0]], tfar=1.999).prim.tolist() == [-1]
    assert scene.intersect(o, [[0, 0, -1.0]], tnear=2.0).prim.tolist() == [0]
    assert scene.intersect(o, [[0, 0, -1.0]], tnear=np.nextafter(np.float32(2), np.float32(3))).prim.tolist() == [-1]
    assert scene.occluded(o, [[0, 0, -1.0], [0, 0, 1.0]]).tolist() == [True, False]
    assert scene.occluded(o, [[0, 0, -1.0]] * 2, tfar=np.array([2.5, 1.5])).tolist() == [True, False]
    assert scene.occluded(o, [[0, 0, -1.0]] * 2, tnear=np.array([2.0, 2.5], np.float32)).tolist() == [True, False]


def test_a_ray_starting_on_a_surface_hits_it_at_t_zero():
    # From a point of the triangle, either way (tnear = 0 counts): t = +0.0, the point's
    # barycentrics; occluded too. With tnear above 0 the ray leaves it behind.
    scene = pyraypack.Scene(TRI_V, TRI_F)
    o, d = [0.25, 0.5, 0.0], np.array([[0, 0, -1.0], [0, 0, 1.0], [0.3, -0.2, 1.0]])
    hits = scene.intersect(o, d)
    assert hits.prim.tolist() == [0, 0, 0] and hits.t.tolist() == [0.0] * 3
    assert not np.signbit(hits.t).any()
    assert (hits.u.tolist(), hits.v.tolist()) == ([0.25] * 3, [0.5] * 3)
    assert scene.occluded(o, d).tolist() == [True] * 3
    assert scene.intersect(o, d, tnear=1e-6).prim.tolist() == [-1] * 3
    assert scene.occluded(o, d, tnear=1e-6).tolist() == [False] * 3
    # -0.0 (and what rounds to it in float32) is zero, not negative: [0, 0] holds the hit.
    assert scene.intersect(o, d, tnear=-0.0, tfar=np.array([-0.0, 0.0, -1e-50])).t.tolist() == [0.0] * 3
    # Every hit along a ray from a surface: that surface first, then the others, each once
    # (a layer of two parallel triangles 1 apart), with min_step 0 too.
    two = pyraypack.Scene(np.vstack([TRI_V, TRI_V - [0, 0, 1]]), np.array([[0, 1, 2], [3, 4, 5]]))
    for step in (0.0, 1e-3):
        ray, prim, t, _, _ = two.intersect_all(o, [[0, 0, -1.0]], min_step=step)
        assert (ray.tolist(), prim.tolist(), t.tolist()) == ([0, 0], [0, 1], [0.0, 1.0])


def test_invalid_rays_miss():
    scene = pyraypack.Scene(TRI_V, TRI_F)
    o = np.array([[0.25, 0.25, 2.0]] * 4)
    d = np.array([[0, 0, -1.0], [0, 0, 0], [np.nan, 0, -1], [0, 0, -1]])
    hits = scene.intersect(o, d, tnear=np.array([0, 0, 0, 3.0]), tfar=np.array([9, 9, 9, 1.0]))
    assert hits.prim.tolist() == [0, -1, -1, -1]
    assert scene.occluded(o, d, tnear=np.array([0, 0, 0, 3.0]), tfar=np.array([9, 9, 9, 1.0])).tolist() == [True, False, False, False]


def test_sphere_distances():
    # A UV sphere of radius 1 lies between radii cos(pi/64) and 1: rays from a distance of 5
    # toward the centre hit at t in [4, 5 - cos(pi/64)].
    v, f = uv_sphere(64, 128)
    scene = pyraypack.Scene(v, f)
    rng = np.random.default_rng(3)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hits = scene.intersect(-5 * d, d)
    assert (hits.prim >= 0).all()
    assert (hits.t >= 4 - 1e-5).all() and (hits.t <= 5 - np.cos(np.pi / 64) + 1e-5).all()
    # Outward unit normals (faces wound counter-clockwise seen from outside).
    assert np.allclose(np.linalg.norm(hits.normal, axis=1), 1, atol=1e-6)
    assert (np.einsum("ij,ij->i", hits.normal, -d) > 0.99).all()
    # Barycentrics reproduce the hit point.
    corners = v[f[hits.prim]]
    p = corners[:, 0] * (1 - hits.u - hits.v)[:, None] + corners[:, 1] * hits.u[:, None] + corners[:, 2] * hits.v[:, None]
    assert np.allclose(p, -5 * d + hits.t[:, None] * d, atol=1e-5)


def layouts(origins: np.ndarray, directions: np.ndarray):
    """The same rays in every layout the module reads: (name, origins, directions)."""
    o32, d32 = origins.astype(np.float32), directions.astype(np.float32)
    yield "float32 C", o32, d32
    yield "float64 C", o32.astype(np.float64), d32.astype(np.float64)
    yield "Fortran", np.asfortranarray(o32), np.asfortranarray(d32.astype(np.float64))
    big_o, big_d = np.zeros((2 * len(o32), 5), np.float32), np.zeros((2 * len(o32), 4), np.float64)
    big_o[::2, 1:4], big_d[::2, :3] = o32, d32
    yield "strided views", big_o[::2, 1:4], big_d[::2, :3]
    yield "reversed twice", o32[::-1].copy()[::-1], d32[::-1].copy()[::-1]
    yield "big-endian", o32.astype(">f4"), d32.astype(">f8")
    packed = np.zeros(len(o32), dtype=[("flag", "u1"), ("o", "<f4", 3), ("d", "<f8", 3)])  # unaligned fields
    packed["o"], packed["d"] = o32, d32
    yield "unaligned records", packed["o"], packed["d"]
    yield "lists", o32.tolist(), d32.tolist()


def test_every_layout_gives_the_same_hits_as_the_rust_api():
    v, f = soup(20_000, 0.05, seed=1)
    scene = pyraypack.Scene(v, f)
    o, d = random_rays(scene.bounds, 20_000, seed=2)
    t, prim, u, v_, = pyraypack._raypack._intersect_stream(scene, o, d)
    assert (prim >= 0).sum() > 5000
    for name, lo, ld in layouts(o, d):
        for threads in (1, 2, None):
            hits = scene.intersect(lo, ld, threads=threads)
            for field, want in (("t", t), ("prim", prim), ("u", u), ("v", v_)):
                assert np.array_equal(getattr(hits, field), want), f"{name}, threads={threads}: {field}"
            assert np.array_equal(scene.occluded(lo, ld, threads=threads), prim >= 0), name
    # Negative strides: the rays in reverse order.
    assert np.array_equal(scene.intersect(o[::-1], d.astype(np.float64)[::-1]).t, t[::-1])


def test_one_origin_for_all_rays():
    v, f = uv_sphere(16, 32)
    scene = pyraypack.Scene(v, f)
    d = np.random.default_rng(0).normal(size=(3000, 3)).astype(np.float32)
    one = scene.intersect(np.zeros(3), d)
    many = scene.intersect(np.zeros((3000, 3)), d)
    assert np.array_equal(one.t, many.t) and np.array_equal(one.prim, many.prim)
    assert (one.prim >= 0).all()
    # One direction for all rays, too.
    o = np.random.default_rng(1).random((100, 3)) * 0.5
    assert np.array_equal(scene.intersect(o, [0, 0, 1]).prim, scene.intersect(o, np.tile([0, 0, 1.0], (100, 1))).prim)


def test_empty_rays_and_empty_scene():
    scene = pyraypack.Scene(TRI_V, TRI_F)
    hits = scene.intersect(np.zeros((0, 3)), np.zeros((0, 3)))
    assert hits.t.shape == (0,) and hits.normal.shape == (0, 3)
    assert scene.occluded(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)
    empty = pyraypack.Scene(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32))
    assert empty.num_triangles == 0 and np.isnan(empty.bounds).all()
    assert empty.intersect([0, 0, 0], [[1, 0, 0]]).prim.tolist() == [-1]


def test_dropped_faces_are_counted_and_ids_still_index_the_faces_given():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0], [2, 0, 0], [10, 0, 0], [11, 0, 0], [10, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4], [5, 6, 7]])  # NaN corner, collinear, fine
    with pytest.warns(pyraypack.SceneWarning, match=r"dropped 2 of 4 faces \(1 with NaN.*1 with zero area"):
        scene = pyraypack.Scene(v, f)
    assert scene.report == {"triangles": 2, "spheres": 0, "dropped_non_finite": 1, "dropped_degenerate": 1, "dropped_spheres": 0}
    hits = scene.intersect(np.array([[0.2, 0.2, 1], [10.2, 0.2, 1]]), [0, 0, -1])
    assert hits.prim.tolist() == [0, 3]
    every = scene.intersect_all(np.array([[0.2, 0.2, 1], [10.2, 0.2, 1]]), [0, 0, -1])
    assert every[1].tolist() == [0, 3]


def test_intersect_all_returns_every_layer_in_order():
    # Five parallel grids at z = 0 .. 4; rays straight down through all of them.
    parts = [grid(4, z=z) for z in range(5)]
    v = np.vstack([p[0] for p in parts])
    f = np.vstack([p[1] + i * len(parts[0][0]) for i, p in enumerate(parts)])
    scene = pyraypack.Scene(v, f)
    o = np.array([[0.13, 0.21, 10.0], [0.3, -0.4, 10.0], [5, 5, 10.0]])
    ray, prim, t, u, v_ = scene.intersect_all(o, [0, 0, -1])
    assert ray.tolist() == [0] * 5 + [1] * 5
    assert t.tolist() == [6, 7, 8, 9, 10] * 2
    assert (prim // len(parts[0][1])).tolist() == [4, 3, 2, 1, 0] * 2
    assert scene.intersect_all(o, [0, 0, -1], max_hits=2)[0].tolist() == [0, 0, 1, 1]
    # min_step is a distance: after the hit at distance 6, 1.5 skips the layer at 7.
    assert scene.intersect_all(o, [0, 0, -2.0], min_step=1.5)[2].tolist() == [3, 4, 5] * 2


def test_cs184_meshes_equal_the_rust_api():
    root = scenes_dir()
    for name in ["meshedit/beetle.dae", "meshedit/teapot.dae", "sky/CBbunny.dae", "sky/CBspheres.dae"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pyraypack.SceneWarning)
            scene = pyraypack.load(root / "cs184" / name)
        for set_name, (o, d, tfar) in pyraypack._raypack._ray_sets(scene, 96, 72, 5).items():
            t, prim, u, v = pyraypack._raypack._intersect_stream(scene, o, d)
            hits = scene.intersect(o.astype(np.float64), d)
            assert np.array_equal(hits.t, t) and np.array_equal(hits.prim, prim), (name, set_name)
            assert np.array_equal(hits.u, u) and np.array_equal(hits.v, v), (name, set_name)
            blocked = scene.occluded(o, d, tfar=tfar)
            assert np.array_equal(blocked, (prim >= 0) & (t <= tfar)), (name, set_name)
        if scene.num_spheres:
            assert (hits.prim >= scene.num_triangles).any()


def test_load_matches_arrays_and_the_bvh_cache(tmp_path):
    v, f = uv_sphere(12, 24)
    ply = tmp_path / "ball.ply"
    header = f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    body = "".join(f"{x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in v.astype(np.float32)) + "".join(f"3 {a} {b} {c}\n" for a, b, c in f)
    ply.write_text(header + body)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        loaded = pyraypack.load(ply, bvh_cache=tmp_path / "cache")
        again = pyraypack.load(str(ply), bvh_cache=tmp_path / "cache", quality="medium")
    assert not loaded.bvh_cache_loaded and again.bvh_cache_loaded and loaded.bvh_cache_file == again.bvh_cache_file
    assert loaded.faces.tolist() == f.tolist() and np.array_equal(loaded.vertices, v.astype(np.float32))
    scene = pyraypack.Scene(v, f)
    o, d = random_rays(scene.bounds, 5000, seed=4)
    for other in (loaded, again):
        assert np.array_equal(scene.intersect(o, d).t, other.intersect(o, d).t)


@pytest.mark.parametrize("quality", ["fast", "medium", "high"])
def test_build_options(quality):
    v, f = soup(3000, 0.1, seed=quality.__len__())
    o, d = random_rays([[-1, -1, -1], [1, 1, 1]], 4000, seed=5)
    ref = pyraypack.Scene(v, f)
    for watertight in (False, True):
        scene = pyraypack.Scene(v, f, quality=quality, watertight=watertight, threads=1)
        hits = scene.intersect(o, d)
        # The same closest hits whatever the tree; the triangle test may differ in the last
        # bits of t, never in which surface is hit first (no shared edges in a soup).
        assert np.array_equal(hits.prim, ref.intersect(o, d).prim)
        assert np.allclose(hits.t, ref.intersect(o, d).t, rtol=1e-5)
