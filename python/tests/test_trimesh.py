"""pyraypack.trimesh.RayMeshIntersector against trimesh's own intersectors on trimesh's
primitives: the same answers, except for rays through edges and vertices (counted)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from conftest import need, random_rays

trimesh = need("trimesh")
import pyraypack.trimesh  # noqa: E402  (needs trimesh)


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
    ours = pyraypack.trimesh.RayMeshIntersector(mesh)
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
    ours = pyraypack.trimesh.RayMeshIntersector(mesh)
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
    mesh.ray = pyraypack.trimesh.RayMeshIntersector(mesh)
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
    ours = pyraypack.trimesh.RayMeshIntersector(mesh).contains_points(pts)
    for ref_name, Ref in references().items():
        n = min(RAYS[ref_name], len(pts))
        ref = Ref(mesh).contains_points(pts[:n])
        assert (ours[:n] != ref).sum() <= 2, (name, ref_name, np.flatnonzero(ours[:n] != ref))


def test_scene_follows_the_mesh_and_copies():
    mesh = trimesh.creation.box()
    ray = pyraypack.trimesh.RayMeshIntersector(mesh, threads=1, quality="high")
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
    ours = pyraypack.trimesh.RayMeshIntersector(odd).intersects_first(o, d)
    plain = pyraypack.trimesh.RayMeshIntersector(mesh).intersects_first(o, d)
    assert np.array_equal(ours, np.where(plain >= 0, plain + 1, -1))


def box_face_rays(mesh):
    """Rays from points of each face of the axis-aligned box ``mesh`` (none on a diagonal or
    an edge, all exact in float32): along the face's outward normal, against it, and
    obliquely inward. Returns origins, directions and each origin's face normal."""
    lo, hi = mesh.bounds
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    origins, directions, normals = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            a, b = (axis + 1) % 3, (axis + 2) % 3
            for u, v in [(0.2, 0.6), (-0.4, 0.7), (0.54, -0.22)]:
                p = centre + n * half
                p[a] += u * half[a]
                p[b] += v * half[b]
                oblique = -n.copy()
                oblique[a] = 0.25
                for d in (n, -n, oblique):
                    origins.append(p)
                    directions.append(d)
                    normals.append(n)
    return np.array(origins), np.array(directions), np.array(normals)


def test_rays_from_a_face_count_it_as_trimeshs_intersectors_do():
    """A ray that starts on a face hits it at distance 0 and, with multiple hits, goes on past
    it to the faces beyond, as trimesh's embree and pure-numpy intersectors do (issue 70: the
    unit box from (0.1, 0.3, 0.5) on its top face, down and up, and rays from points of every
    face, out, in and oblique)."""
    mesh = trimesh.creation.box()
    ours = pyraypack.trimesh.RayMeshIntersector(mesh)
    o, d, n = box_face_rays(mesh)
    o = np.vstack([[[0.1, 0.3, 0.5]] * 2, o])
    d = np.vstack([[[0, 0, -1.0], [0, 0, 1.0]], d])
    n = np.vstack([[[0, 0, 1.0]] * 2, n])
    first = ours.intersects_first(o, d)
    # The first hit is the face the ray starts on (closed form: its normal), and any-hit agrees.
    assert np.allclose(mesh.face_normals[first], n)
    assert ours.intersects_any(o, d).all()
    tri, ray, loc = ours.intersects_id(o, d, multiple_hits=True, return_locations=True)
    assert np.array_equal(loc[np.searchsorted(ray, np.arange(len(o)))], o)
    for ref_name, Ref in references().items():
        ref = Ref(mesh)
        assert np.array_equal(first, ref.intersects_first(o, d)), ref_name
        assert np.array_equal(ours.intersects_any(o, d), ref.intersects_any(o, d)), ref_name
        rtri, rray, rloc = ref.intersects_id(o, d, multiple_hits=True, return_locations=True)
        assert sorted(zip(ray.tolist(), tri.tolist())) == sorted(zip(rray.tolist(), rtri.tolist())), ref_name
        order, rorder = np.lexsort((tri, ray)), np.lexsort((rtri, rray))
        assert np.allclose(loc[order], rloc[rorder], atol=1e-12), ref_name


@pytest.mark.parametrize("scale", [1e-4, 0.1, 1.0, 10.0, 1e4, 1e8])
def test_multiple_hits_from_a_surface_vertex_at_every_scale(scale):
    """trimesh's own ``test_embree_duplicate_hits``: a ray from the vertex at the centre of a
    subdivided box's top face, straight down, hits the box twice (where it starts and where it
    leaves), at every scale; so does trimesh's embree intersector."""
    mesh = trimesh.creation.box().subdivide().subdivide()
    mesh.apply_scale(scale)
    o, d = np.array([[0.0, 0.0, scale / 2]]), np.array([[0.0, 0.0, -1.0]])
    tri, _, loc = pyraypack.trimesh.RayMeshIntersector(mesh, scale_to_box=False).intersects_id(
        o, d, multiple_hits=True, return_locations=True
    )
    assert np.allclose(loc, [[0, 0, scale / 2], [0, 0, -scale / 2]], rtol=0, atol=1e-9 * scale)
    if trimesh.ray.has_embree:
        ref = trimesh.ray.ray_pyembree.RayMeshIntersector(mesh, scale_to_box=False)
        assert len(ref.intersects_id(o, d, multiple_hits=True)[0]) == len(tri)
