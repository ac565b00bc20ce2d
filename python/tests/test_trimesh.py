"""raypack.trimesh.RayMeshIntersector against trimesh's own intersectors on trimesh's
primitives: the same answers, except for rays through edges and vertices (counted)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from conftest import need, random_rays

trimesh = need("trimesh")
import raypack.trimesh  # noqa: E402  (needs trimesh)


def primitives():
    c = trimesh.creation
    far = c.icosphere(subdivisions=3)
    far.apply_translation([1e6, -2e6, 5e5])
    return {
        "icosphere": c.icosphere(subdivisions=3),
        "box": c.box(extents=[1, 2, 3]),
        "capsule": c.capsule(height=2, radius=0.5),
        "cylinder": c.cylinder(radius=1, height=3, sections=40),
        "annulus": c.annulus(r_min=0.5, r_max=1, height=1),
        "torus": c.torus(major_radius=1, minor_radius=0.3),
        "far icosphere": far,
    }


# The pure-numpy intersector is slow (about 1 ms per ray): it gets the first rays only.
RAYS = {"ray_pyembree": 20_000, "ray_triangle": 1500}


def references():
    """trimesh's own intersectors that can run here: embree (embreex) and the pure-numpy one
    (needs rtree)."""
    refs = {}
    if trimesh.ray.has_embree:
        refs["ray_pyembree"] = trimesh.ray.ray_pyembree.RayMeshIntersector
    try:
        import rtree  # noqa: F401

        refs["ray_triangle"] = trimesh.ray.ray_triangle.RayMeshIntersector
    except ImportError:
        pass
    if not refs:
        pytest.skip("SKIPPED: neither embreex nor rtree is installed: trimesh has no intersector to compare with")
    return refs


def near_edge(mesh, tri, points, tol):
    """True where ``points`` (on the plane of triangle ``tri``) lie within ``tol`` (relative
    to the triangle's size) of one of its edges: where a non-watertight test may go either way."""
    corners = np.asarray(mesh.triangles)[tri]
    bary = trimesh.triangles.points_to_barycentric(corners, points)
    return (np.abs(bary) <= tol).any(axis=1) | (np.abs(bary - 1) <= tol).any(axis=1)


def rays_for(mesh, n=20_000, seed=0):
    o, d = random_rays(mesh.bounds, n, seed)
    return o.astype(np.float64), d.astype(np.float64)


@pytest.mark.parametrize("name", list(primitives()))
def test_first_and_any_hits_match(name):
    mesh = primitives()[name]
    ours = raypack.trimesh.RayMeshIntersector(mesh)
    o_all, d_all = rays_for(mesh)
    first_all = ours.intersects_first(o_all, d_all)
    assert first_all.dtype == np.int64 and first_all.shape == (len(o_all),)
    assert (first_all >= 0).sum() > len(o_all) // 4
    for ref_name, Ref in references().items():
        o, d, first = o_all[: RAYS[ref_name]], d_all[: RAYS[ref_name]], first_all[: RAYS[ref_name]]
        ref = Ref(mesh).intersects_first(o, d)
        differ = np.flatnonzero(first != ref)
        print(f"{name}: {len(differ)} of {len(o)} first hits differ from {ref_name}'s (at edges)")
        if len(differ) == 0:
            continue
        # A disagreement is a ray through an edge: both faces hit at the same distance, or a
        # hit near the edge of its face where the other tracer missed.
        loc_ours, ray_ours, tri_ours = ours.intersects_location(o[differ], d[differ], multiple_hits=False)
        edge = np.zeros(len(differ), bool)
        edge[ray_ours] = near_edge(mesh, tri_ours, loc_ours, 1e-4)
        ref_loc, ref_ray, ref_tri = Ref(mesh).intersects_location(o[differ], d[differ], multiple_hits=False)
        edge[ref_ray] |= near_edge(mesh, ref_tri, ref_loc, 1e-4)
        assert edge.all(), f"{name}: rays {differ[~edge][:5]} differ from {ref_name} away from any edge"
        assert len(differ) <= 1e-3 * len(o)
    for ref_name, Ref in references().items():
        # Any-hit answers differ at most where the first hits do (edge rays).
        o, d, first = o_all[: RAYS[ref_name]], d_all[: RAYS[ref_name]], first_all[: RAYS[ref_name]]
        ref_first = Ref(mesh).intersects_first(o, d)
        any_differ = np.flatnonzero(ours.intersects_any(o, d) != Ref(mesh).intersects_any(o, d))
        assert np.isin(any_differ, np.flatnonzero(first != ref_first)).all(), (name, ref_name)


@pytest.mark.parametrize("name", list(primitives()))
def test_multiple_hits_and_locations_match(name):
    mesh = primitives()[name]
    ours = raypack.trimesh.RayMeshIntersector(mesh)
    o, d = rays_for(mesh, 5000, seed=1)
    tri, ray, loc = ours.intersects_id(o, d, multiple_hits=True, return_locations=True)
    assert tri.dtype == np.int64 and ray.dtype == np.int64 and loc.shape == (len(tri), 3)
    # Ordered by ray, then along it.
    assert (np.diff(ray) >= 0).all()
    dist = np.einsum("ij,ij->i", loc - o[ray], d[ray])
    same_ray = ray[1:] == ray[:-1]
    assert (np.diff(dist)[same_ray] > 0).all()
    # Locations lie on their triangles.
    corners = np.asarray(mesh.triangles)[tri]
    bary = trimesh.triangles.points_to_barycentric(corners, loc)
    assert (bary > -1e-5).all() and (bary < 1 + 1e-5).all()
    scale = mesh.scale
    for ref_name, Ref in references().items():
        n = min(RAYS[ref_name], len(o))
        keep = ray < n
        tri, ray, loc, dist = tri[keep], ray[keep], loc[keep], dist[keep]
        rtri, rray, rloc = Ref(mesh).intersects_id(o[:n], d[:n], multiple_hits=True, return_locations=True)
        ours_set = set(zip(ray.tolist(), tri.tolist()))
        ref_set = set(zip(rray.tolist(), rtri.tolist()))
        only = ours_set ^ ref_set
        print(f"{name}: {len(ours_set)} hits, {len(only)} differ from {ref_name}'s")
        # Differences only at edges: the ray's hits elsewhere agree.
        bad_rays = {r for r, _ in only}
        assert len(bad_rays) <= 2e-3 * len(o), (name, ref_name, sorted(bad_rays)[:5])
        for r in bad_rays:
            ours_d = np.sort(dist[ray == r])
            ref_d = np.sort(np.einsum("ij,j->i", rloc[rray == r] - o[r], d[r]))
            # Each hit of one is matched in distance by the other, or is near an edge.
            mine = np.flatnonzero(ray == r)
            edge = near_edge(mesh, tri[mine], loc[mine], 1e-4)
            for k, x in enumerate(ours_d):
                assert edge[np.argsort(dist[mine])[k]] or np.isclose(ref_d, x, atol=1e-6 * scale).any(), (name, r)
        # Where both found the same (ray, face), the same point.
        key = lambda r, t: r * (len(mesh.faces) + 1) + t  # noqa: E731
        common, ia, ib = np.intersect1d(key(ray, tri), key(rray, rtri), return_indices=True)
        assert np.allclose(loc[ia], rloc[ib], atol=1e-9 * max(scale, np.abs(mesh.bounds).max()))


def test_trimesh_readme_example_and_the_one_line_swap():
    mesh = trimesh.creation.icosphere()
    ref_locations, ref_index_ray, ref_index_tri = mesh.ray.intersects_location(
        ray_origins=[[0, 0, -5], [2, 2, -10]], ray_directions=[[0, 0, 1], [0, 0, 1]]
    )
    mesh.ray = raypack.trimesh.RayMeshIntersector(mesh)
    locations, index_ray, index_tri = mesh.ray.intersects_location(
        ray_origins=[[0, 0, -5], [2, 2, -10]], ray_directions=[[0, 0, 1], [0, 0, 1]]
    )
    assert sorted(map(tuple, locations.round(12))) == sorted(map(tuple, ref_locations.round(12)))
    assert index_ray.tolist() == sorted(ref_index_ray.tolist())
    # mesh.contains goes through mesh.ray.contains_points.
    pts = np.random.default_rng(2).random((2000, 3)) * 2.4 - 1.2
    inside = mesh.contains(pts)
    r = np.linalg.norm(pts, axis=1)
    clear = (r < 0.98) | (r > 1.0)
    assert np.array_equal(inside[clear], r[clear] < 0.98)


@pytest.mark.parametrize("name", ["icosphere", "box", "torus", "annulus"])
def test_contains_points_matches(name):
    mesh = primitives()[name]
    pts = np.random.default_rng(3).random((5000, 3)) * (mesh.extents * 1.2) + mesh.bounds[0] - 0.1 * mesh.extents
    ours = raypack.trimesh.RayMeshIntersector(mesh).contains_points(pts)
    for ref_name, Ref in references().items():
        n = min(RAYS[ref_name], len(pts))
        ref = Ref(mesh).contains_points(pts[:n])
        assert (ours[:n] != ref).sum() <= 2, (name, ref_name, np.flatnonzero(ours[:n] != ref))


def test_scene_follows_the_mesh_and_copies():
    mesh = trimesh.creation.box()
    ray = raypack.trimesh.RayMeshIntersector(mesh, threads=1, quality="high")
    o, d = np.array([[0, 0, 5.0]]), np.array([[0, 0, -1.0]])
    assert ray.intersects_location(o, d, multiple_hits=False)[0].tolist() == [[0, 0, 0.5]]
    mesh.apply_translation([0, 0, 1])
    assert ray.intersects_location(o, d, multiple_hits=False)[0].tolist() == [[0, 0, 1.5]]
    for other in (copy.copy(ray), copy.deepcopy(ray), pickle.loads(pickle.dumps(ray))):
        assert other.intersects_location(o, d, multiple_hits=False)[0].tolist() == [[0, 0, 1.5]]


def test_degenerate_faces_keep_their_ids():
    mesh = trimesh.creation.box()
    faces = np.vstack([[[0, 0, 1]], mesh.faces, [[2, 2, 2]]])
    odd = trimesh.Trimesh(mesh.vertices, faces, process=False)
    o, d = rays_for(odd, 2000, seed=4)
    ours = raypack.trimesh.RayMeshIntersector(odd).intersects_first(o, d)
    plain = raypack.trimesh.RayMeshIntersector(mesh).intersects_first(o, d)
    assert np.array_equal(ours, np.where(plain >= 0, plain + 1, -1))
