"""raypack against embreex (Embree 4) on the same numpy rays: CS184 meshes and generated ones.

Per ray: hit or miss, t within a few ulps, the same primitive where t is unique. A
disagreement is settled in float64, as the Rust cross-check does (tests/embree_crosscheck.rs):
where the ray passes within float tolerance of an edge of the triangle in question, both
answers are plausible and the ray is counted as an edge case; any other disagreement is a
mismatch. Mismatches fail the test; edge cases are printed and bounded."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import pyraypack
from conftest import grid, need, random_rays, scenes_dir, soup, uv_sphere

rtcore_scene = need("embreex.rtcore_scene")
mesh_construction = need("embreex.mesh_construction")

# t on the same triangle: Möller-Trumbore and Embree's test round differently. Most agree
# within T_ULPS ulps of t (printed); all within float tolerance: 1e-5 of t plus 64 ulps of the
# largest coordinate involved over the sine of the ray's angle to the plane (as in the Rust
# cross-check), since the rounding error of t grows with the coordinates' magnitude, not with t
# (rays leaving one surface for a nearby one have tiny t).
T_ULPS = 4
# Edge cases allowed per ray (a sanity bound: far-away meshes have a wide float tolerance).
EDGE_CASE_RATE = 2e-3


def embree_hits(vertices, faces, o, d, tfar, robust=False):
    scene = rtcore_scene.EmbreeScene(robust=robust)
    mesh_construction.TriangleMesh(scene, vertices.astype(np.float32), faces.astype(np.int32))
    out = scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), dists=tfar.astype(np.float32).copy(), output=True)
    prim = out["primID"].astype(np.int64)
    t = np.where(prim >= 0, out["tfar"], np.inf).astype(np.float32)
    return t, prim


def edge_margin(vertices, faces, prim, o, d):
    """Per ray: signed distance (relative to the triangle's size, positive inside) of the
    ray's float64 crossing with the plane of triangle ``prim`` to its nearest edge, and the
    tolerance within which that is float noise."""
    a, b, c = (vertices[faces[prim, k]].astype(np.float64) for k in range(3))
    o, d = o.astype(np.float64), d.astype(np.float64)
    n = np.cross(b - a, c - a)
    nlen = np.linalg.norm(n, axis=1)
    denom = np.einsum("ij,ij->i", n, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", n, a - o) / denom
        p = o + t[:, None] * d
        margins = []
        for u, v in ((a, b), (b, c), (c, a)):
            e = v - u
            margins.append(np.einsum("ij,ij->i", np.cross(e, p - u), n) / (np.linalg.norm(e, axis=1) * nlen))
        size = np.maximum.reduce([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1), np.linalg.norm(a - c, axis=1)])
        mag = np.abs(np.stack([a, b, c, o, p], 1)).max(axis=(1, 2))
        sin = np.maximum(np.abs(denom) / (nlen * np.linalg.norm(d, axis=1)), 1e-3)
        tol = 64 * np.finfo(np.float32).eps * mag / sin / size
    return np.min(margins, axis=0) / size, tol


def t_tolerance(vertices, faces, prim, o, d, t):
    """Float tolerance of t for a ray crossing triangle ``prim``."""
    corners = vertices[faces[prim]].astype(np.float64)
    o, d = o.astype(np.float64), d.astype(np.float64)
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    dlen = np.linalg.norm(d, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        sin = np.maximum(np.abs(np.einsum("ij,ij->i", n, d)) / (np.linalg.norm(n, axis=1) * dlen), 1e-3)
    mag = np.maximum(np.abs(corners).max(axis=(1, 2)), np.abs(o).max(axis=1))
    return 1e-5 * np.abs(t) + 64 * np.finfo(np.float32).eps * mag / (dlen * sin)


def compare(name, vertices, faces, o, d, tfar, robust=False):
    """Counts (rays, edge cases) and asserts no mismatch."""
    scene = pyraypack.Scene(vertices, faces)
    hits = scene.intersect(o, d, tfar=tfar)
    t_e, prim_e = embree_hits(vertices, faces, o, d, tfar, robust)
    t_r, prim_r = hits.t, hits.prim
    # Occlusion agrees with the closest hit of either.
    blocked = scene.occluded(o, d, tfar=tfar)
    assert np.array_equal(blocked, prim_r >= 0), name
    both = (prim_r >= 0) & (prim_e >= 0)
    with np.errstate(invalid="ignore"):
        ulps = np.abs(t_r - t_e) / np.spacing(np.maximum(np.abs(t_r), np.abs(t_e)))
    with np.errstate(invalid="ignore"):  # inf - inf where both miss
        close = both & (np.abs(t_r - t_e) <= t_tolerance(vertices, faces, np.where(both, prim_r, 0), o, d, t_e))
    agree = (prim_r == prim_e) & ((prim_r < 0) | close)
    agree |= close  # equal t on different triangles: t is not unique (a shared edge)
    bad = np.flatnonzero(~agree)
    edge = np.zeros(len(bad), bool)
    for prim in (prim_r[bad], prim_e[bad]):
        has = prim >= 0
        m, tol = edge_margin(vertices, faces, prim[has], o[bad][has], d[bad][has])
        edge[np.flatnonzero(has)] |= np.abs(m) <= tol
    # Same triangle, t beyond a few ulps: only slivers may do that (none in these meshes).
    mismatches = bad[~edge]
    same = ulps[both & (prim_r == prim_e)]
    within = (same <= T_ULPS).mean() if len(same) else 1.0
    print(
        f"{name}: {len(o)} rays, {both.sum()} hit by both; same triangle: t within {T_ULPS} ulps for "
        f"{100 * within:.2f}%, max {same.max() if len(same) else 0:.0f} ulps; {edge.sum()} edge cases, {len(mismatches)} mismatches"
    )
    detail = [(int(i), int(prim_r[i]), float(t_r[i]), int(prim_e[i]), float(t_e[i])) for i in mismatches[:5]]
    assert len(mismatches) == 0, f"{name}: (ray, raypack prim, t, embree prim, t): {detail}"
    assert edge.sum() <= EDGE_CASE_RATE * len(o) + 2, name
    return len(o), int(edge.sum())


def ray_sets(scene, width, height, seed):
    """The benchmark's sets (camera, diffuse, shadow; from the scene file's camera, if any)
    and random rays through the bounds."""
    sets = dict(pyraypack._raypack._ray_sets(scene, width, height, seed))
    o, d = random_rays(scene.bounds, 20_000, seed)
    sets["random"] = (o, d, np.full(len(o), np.inf, np.float32))
    return sets


def generated():
    ball_v, ball_f = uv_sphere(150, 200, radius=0.5, center=(0.1, -0.2, 0.55))
    ground_v, ground_f = grid(250)
    soup_v, soup_f = soup(150_000, 0.03, seed=1)
    far = np.array([1e6, -1e6, 5e5])
    return {
        "grid+sphere": (np.vstack([ground_v, ball_v]), np.vstack([ground_f, ball_f + len(ground_v)]), False),
        "soup 150k": (soup_v, soup_f, False),
        "far sphere (~1e6)": (ball_v * 600 + far, ball_f, True),
    }


@pytest.mark.parametrize("name", list(generated()))
def test_generated_meshes_agree_with_embree(name):
    v, f, robust = generated()[name]
    for set_name, (o, d, tfar) in ray_sets(pyraypack.Scene(v, f), 320, 240, 7).items():
        compare(f"{name} {set_name}", v, f, o, d, tfar, robust)


@pytest.mark.parametrize("name", ["meshedit/beetle.dae", "sky/CBbunny.dae", "meshedit/maxplanck.dae", "keenan/banana.dae"])
def test_cs184_meshes_agree_with_embree(name):
    path = scenes_dir() / "cs184" / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        loaded = pyraypack.load(path)
    v, f = loaded.vertices, loaded.faces
    for set_name, (o, d, tfar) in ray_sets(loaded, 320, 240, 7).items():
        compare(f"{name} {set_name}", v, f, o, d, tfar)
