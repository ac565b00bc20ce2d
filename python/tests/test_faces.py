"""prim ids index the faces the caller gave or the file holds, and Scene.faces is those faces,
degenerate ones included; warnings point at the caller's line; loading a mesh to cast rays
does not warn about lights."""

from __future__ import annotations

import inspect
import pickle
import warnings

import numpy as np
import pytest

import pyraypack
from conftest import need

# A unit square of four triangles around its centre (fan), plus, between them, a face with
# zero area (repeated corner), one with collinear corners and one with a NaN corner.
V = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0], [2, 2, 0], [np.nan, 0, 0]],
    dtype=np.float64,
)
F = np.array([[0, 1, 4], [1, 1, 2], [1, 2, 4], [0, 4, 2], [2, 3, 4], [0, 6, 1], [3, 0, 4]])
GOOD = [0, 2, 4, 6]  # the faces that can be hit; 1, 3 and 5 are dropped


def centroids(vertices, faces):
    return vertices[faces].mean(axis=1)


def rays_down_through(points):
    origins = np.asarray(points, np.float64) + [0, 0, 1]
    return origins, np.array([0.0, 0.0, -1.0])


def check_faces_line_up(scene, vertices, faces, good):
    """Rays through each good face's centroid hit that face, and scene.faces[prim] is it."""
    assert scene.faces.tolist() == np.asarray(faces).tolist()
    assert scene.num_triangles == len(good) and scene.report["triangles"] == len(good)
    o, d = rays_down_through(centroids(np.asarray(vertices, np.float64), np.asarray(faces)[good]))
    hits = scene.intersect(o, d)
    assert hits.prim.tolist() == good
    assert scene.faces[hits.prim].tolist() == np.asarray(faces)[good].tolist()
    ray, prim, _, _, _ = scene.intersect_all(o, d)
    assert ray.tolist() == list(range(len(good))) and prim.tolist() == good


def test_arrays_with_degenerate_faces():
    with pytest.warns(pyraypack.SceneWarning, match=r"dropped 3 of 7 faces"):
        scene = pyraypack.Scene(V, F)
    check_faces_line_up(scene, V, F, GOOD)
    # A pickle keeps the numbering.
    check_faces_line_up(pickle.loads(pickle.dumps(scene)), V, F, GOOD)


def test_arrays_without_dropped_faces_are_unchanged():
    keep = [0, 2, 4, 6]
    scene = pyraypack.Scene(V, F[keep])
    check_faces_line_up(scene, V, F[keep], [0, 1, 2, 3])


def write_ply(path, vertices, faces):
    header = (
        f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    body = "".join(f"{x} {y} {z}\n" for x, y, z in vertices) + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces)
    path.write_text(header + body)


def test_a_ply_file_with_degenerate_faces(tmp_path):
    # PLY keeps the file's vertex order: faces compare index for index (no NaN corner: a
    # PLY reader takes "nan", but keep the file plain).
    keep = [0, 1, 2, 3, 4, 6]  # face 1 has a repeated corner, face 3 collinear corners
    v, f = V[:6], F[keep]
    ply = tmp_path / "square.ply"
    write_ply(ply, v, f)
    with pytest.warns(pyraypack.SceneWarning, match="dropped 0 triangles with NaN/Inf/huge coordinates, 2 zero-area"):
        scene = pyraypack.load(ply)
    assert scene.report["dropped_degenerate"] == 2
    check_faces_line_up(scene, v, f, [0, 2, 4, 5])


def test_an_obj_file_with_degenerate_faces(tmp_path):
    # A quad (two triangles when loaded) between a zero-area triangle and a good one: the
    # file holds four triangles as loaded, and prim ids number them in the file's order.
    obj = tmp_path / "square.obj"
    obj.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\n"
        "f 1 2 2\n"  # zero area
        "f 1 2 3 4\n"  # the unit square
        "f 2 5 3\n"  # a good triangle beside it
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        scene = pyraypack.load(obj)
    faces, vertices = scene.faces, scene.vertices.astype(np.float64)
    assert len(faces) == 4 and scene.num_triangles == 3
    # The first face is the zero-area one (two equal corners), the others its neighbours.
    assert len({tuple(vertices[i]) for i in faces[0]}) == 2
    o, d = rays_down_through([[0.2, 0.1, 0], [0.1, 0.8, 0], [1.5, 1.2, 0]])
    hits = scene.intersect(o, d)
    assert sorted(hits.prim.tolist()) == [1, 2, 3]
    # Each hit lies inside the face its prim names.
    for point, face in zip(o - [0, 0, 1], faces[hits.prim]):
        a, b, c = vertices[face]
        area = lambda p, q, r: abs(np.cross(q - p, r - p)[2])  # noqa: E731
        assert np.isclose(area(point, b, c) + area(a, point, c) + area(a, b, point), area(a, b, c))


def test_warnings_point_at_the_callers_line(tmp_path):
    with pytest.warns(pyraypack.SceneWarning) as caught:
        line = inspect.currentframe().f_lineno + 1
        pyraypack.Scene(V, F)
    assert [(w.filename, w.lineno) for w in caught] == [(__file__, line)]
    ply = tmp_path / "square.ply"
    write_ply(ply, V[:6], F[[0, 1, 2]])
    with pytest.warns(pyraypack.SceneWarning) as caught:
        line = inspect.currentframe().f_lineno + 1
        pyraypack.load(ply)
    assert [(w.filename, w.lineno) for w in caught] == [(__file__, line)]
    # render(path) announces the default light rig, at the caller's line too.
    with pytest.warns(pyraypack.SceneWarning) as caught:
        line = inspect.currentframe().f_lineno + 1
        pyraypack.render(ply, width=8, height=6)
    assert any("no lights in the file" in str(w.message) for w in caught)
    assert {(w.filename, w.lineno) for w in caught} == {(__file__, line)}


def test_loading_a_mesh_to_cast_rays_does_not_warn_about_lights(tmp_path):
    ply = tmp_path / "fan.ply"
    write_ply(ply, V[:6], F[[0, 2, 4, 6]])
    obj = tmp_path / "fan.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")
    for path in (ply, obj):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scene = pyraypack.load(path)
        assert [str(w.message) for w in caught] == [], path
        assert scene.num_triangles > 0


def test_dask_render_warns_at_the_callers_line(tmp_path):
    need("dask")
    import pyraypack.dask

    ply = tmp_path / "square.ply"
    write_ply(ply, V[:6], F[[0, 1, 2]])
    with pytest.warns(pyraypack.SceneWarning) as caught:
        line = inspect.currentframe().f_lineno + 1
        pyraypack.dask.render(ply, 8, 6, tiles=2)
    assert caught and {(w.filename, w.lineno) for w in caught} == {(__file__, line)}
