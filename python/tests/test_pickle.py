"""A pickled Scene comes back whole, BVH included: the same hits and the same renders, without
a build; damaged or forged pickles raise ValueError instead of giving wrong answers."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest

import pyraypack
from conftest import random_rays, scenes_dir, uv_sphere


def same_hits(a, b, origins, directions):
    ha, hb = a.intersect(origins, directions), b.intersect(origins, directions)
    for x, y in zip(ha, hb):
        assert np.array_equal(x, y)
    assert np.array_equal(a.occluded(origins, directions), b.occluded(origins, directions))
    return ha


def test_pickled_scenes_trace_the_same_without_a_build():
    v, f = uv_sphere(24, 48)
    # A dropped face: the face map travels with the scene.
    f = np.vstack([f, [[0, 0, 1]]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        scene = pyraypack.Scene(v, f, quality="high", watertight=True)
    data = pickle.dumps(scene)
    builds = pyraypack._raypack._bvh_builds()
    back = pickle.loads(data)
    assert pyraypack._raypack._bvh_builds() == builds, "unpickling built a BVH"
    assert isinstance(back, pyraypack.Scene)
    assert back.report == scene.report
    # The faces as given, the dropped one included, and prim ids numbered by them.
    assert back.faces.tolist() == scene.faces.tolist() == f.tolist()
    origins, directions = random_rays(scene.bounds, 20000, seed=3)
    hits = same_hits(scene, back, origins, directions)
    assert hits.hit.sum() > 1000
    # And again: a scene unpickled pickles to the same bytes.
    assert pickle.dumps(back) == data


def test_pickled_scene_files_render_the_same():
    path = scenes_dir() / "cs184" / "sky" / "CBspheres.dae"
    scene = pyraypack.load(path)
    back = pickle.loads(pickle.dumps(scene))
    settings = dict(spp=2, max_depth=3, width=40, height=30, seed=5)
    assert np.array_equal(pyraypack.render(back, **settings), pyraypack.render(scene, **settings))
    assert back.num_spheres == scene.num_spheres > 0


def test_damaged_pickles_are_refused():
    v, f = uv_sphere(8, 16)
    scene = pyraypack.Scene(v, f)
    function, (snapshot, prim_map, report, dropped) = scene.__reduce__()
    assert prim_map is None and dropped is None
    for at in (0, 100, len(snapshot) // 2, len(snapshot) - 1):
        bad = bytearray(snapshot)
        bad[at] ^= 0x08
        with pytest.raises(ValueError, match="cannot unpickle"):
            function(bytes(bad), prim_map, report)
    with pytest.raises(ValueError, match="cannot unpickle"):
        function(snapshot[:-8], prim_map, report)
    with pytest.raises(ValueError, match="report does not fit"):
        function(snapshot, prim_map, (1, 2, 3, 4, 5))
    with pytest.raises(ValueError, match="face map"):
        function(snapshot, b"\x00\x00\x00\x00", report)
    with pytest.raises(ValueError, match="dropped faces without a face map"):
        function(snapshot, None, report, b"\x00" * 12)
    # A scene that dropped a face: its map and dropped faces are checked against the scene.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pyraypack.SceneWarning)
        dropping = pyraypack.Scene(v, np.vstack([[[0, 0, 1]], f]))
    function, (snapshot, kept, report, dropped) = dropping.__reduce__()
    assert np.frombuffer(kept, "<u4").tolist() == list(range(1, len(f) + 1))
    assert np.frombuffer(dropped, "<u4").tolist() == [0, 0, 1]
    assert function(snapshot, kept, report, dropped).faces.tolist() == dropping.faces.tolist()
    for bad_kept, bad_dropped in [
        (kept, None),  # the dropped face missing: index len(f) is past the faces
        (kept, np.array([0, 0, len(v)], "<u4").tobytes()),  # a corner past the vertices
        (kept, dropped[:-1]),  # not whole faces
        (np.frombuffer(kept, "<u4")[::-1].tobytes(), dropped),  # not increasing
        (kept[:-4], dropped),  # one triangle short
    ]:
        with pytest.raises(ValueError, match="face map"):
            function(snapshot, bad_kept, report, bad_dropped)
