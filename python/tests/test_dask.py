"""pyraypack.dask: renders split over a Dask cluster (2 worker processes) and on the local
scheduler equal pyraypack.render bit for bit; ray batches in chunks equal Scene.intersect; the
scene goes to each worker once and no worker builds its BVH."""

from __future__ import annotations

import inspect
import pickle
import time

import numpy as np
import pytest

import pyraypack
from conftest import need, random_rays, scenes_dir, uv_sphere

dask = need("dask")
distributed = need("distributed")
import pyraypack.dask  # noqa: E402


# First, before the cluster's client exists: Dask's local scheduler.
def test_local_scheduler_gives_the_same():
    v, f = uv_sphere(16, 32)
    scene = pyraypack.Scene(v, f)
    settings = dict(spp=2, max_depth=2, seed=1)
    want = pyraypack.render(scene, width=40, height=30, **settings)
    assert np.array_equal(pyraypack.dask.render(scene, 40, 30, tiles=7, **settings), want)
    origins, directions = random_rays(scene.bounds, 5000, seed=2)
    hits = pyraypack.dask.intersect(scene, origins, directions, tnear=0.5, chunk_rays=999)
    assert hits.t.numblocks == (6,)
    for a, b in zip(hits, scene.intersect(origins, directions, 0.5)):
        assert np.array_equal(a.compute(), b)


def test_render_of_a_path_says_the_file_has_no_lights_at_the_callers_line(tmp_path):
    # As pyraypack.render(path) does: the default light rig is announced, not silently added.
    obj = tmp_path / "triangle.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.warns(pyraypack.SceneWarning) as caught:
        line = inspect.currentframe().f_lineno + 1
        image = pyraypack.dask.render(obj, 8, 6, tiles=2)
    assert any("no lights in the file" in str(w.message) for w in caught)
    assert {(w.filename, w.lineno) for w in caught} == {(__file__, line)}
    with pytest.warns(pyraypack.SceneWarning, match="no lights in the file"):
        assert np.array_equal(image, pyraypack.render(obj, width=8, height=6))


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of two single-thread worker processes, its active memory manager (which
    drops extra replicas of data) running every 50 ms instead of 2 s."""
    with dask.config.set({"distributed.scheduler.active-memory-manager.interval": "50ms"}):
        cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


def bunny():
    return scenes_dir() / "cs184" / "sky" / "CBbunny.dae"


SETTINGS = dict(spp=4, max_depth=5, light_samples=1, seed=3)


def test_cluster_render_of_cbbunny_in_4_tiles_equals_render(client):
    want = pyraypack.render(bunny(), width=96, height=72, **SETTINGS)
    got = pyraypack.dask.render(bunny(), 96, 72, tiles=4, **SETTINGS)
    assert got.dtype == np.float32 and got.shape == (72, 96, 3)
    assert np.array_equal(got, want)
    # Both workers rendered, neither built a BVH (the scene came pickled, BVH included).
    builds = client.run(pyraypack._raypack._bvh_builds)
    assert len(builds) == 2 and all(n == 0 for n in builds.values()), builds


def test_cluster_intersect_of_2m_rays_in_8_chunks_equals_intersect(client):
    v, f = uv_sphere(64, 128)
    scene = pyraypack.Scene(v, f)
    origins, directions = random_rays(scene.bounds, 2_000_000, seed=1)
    want = scene.intersect(origins, directions)
    hits = pyraypack.dask.intersect(scene, origins, directions, chunk_rays=250_000)
    assert hits.t.numblocks == (8,)
    got = pyraypack.dask.DaskHits(*client.compute(list(hits), sync=True))
    for name, a, b in zip(pyraypack.dask.DaskHits._fields, got, want):
        assert np.array_equal(a, b), name
    assert got.hit.sum() > 100_000
    # The scene is on each worker once, however many calls used it, and stays there: Dask's
    # active memory manager (here every 50 ms) drops extra replicas of data, not plugins.
    token = scene.__dask_tokenize__()
    assert token == pickle.loads(pickle.dumps(scene)).__dask_tokenize__()

    def copies(dask_worker):
        held = [p.scene for p in dask_worker.plugins.values() if isinstance(getattr(p, "scene", None), pyraypack.Scene)]
        in_data = [v for v in dask_worker.data.values() if isinstance(v, pyraypack.Scene)]
        return [id(s) for s in held if s.__dask_tokenize__() == token], len(in_data)

    before = client.run(copies)
    assert [(len(ids), n) for ids, n in before.values()] == [(1, 0), (1, 0)], before
    time.sleep(0.3)
    pyraypack.dask.intersect(scene, origins[:1000], directions[:1000], chunk_rays=100).t.compute()
    assert client.run(copies) == before
    # As dask arrays in (chunked differently), with per-ray tfar: the same.
    da = pytest.importorskip("dask.array")
    origins, directions = origins[:200_000], directions[:200_000]
    o, d = da.from_array(origins, chunks=(50_000, 3)), da.from_array(directions, chunks=(30_000, 3))
    tfar = np.full(len(origins), 3.0, np.float32)
    occ = pyraypack.dask.occluded(scene, o, d, tfar=da.from_array(tfar, chunks=40_000))
    assert occ.numblocks == (4,)
    assert np.array_equal(occ.compute(), scene.occluded(origins, directions, tfar=tfar))


def test_bad_arguments_name_themselves():
    v, f = uv_sphere(8, 8)
    scene = pyraypack.Scene(v, f)
    with pytest.raises(ValueError, match="origins: expected shape"):
        pyraypack.dask.intersect(scene, np.zeros((4, 2)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="tfar: expected"):
        pyraypack.dask.intersect(scene, np.zeros((4, 3)), np.ones((4, 3)), tfar=np.ones(3))
    with pytest.raises(ValueError, match="chunk_rays"):
        pyraypack.dask.intersect(scene, np.zeros((4, 3)), np.ones((4, 3)), chunk_rays=0)
    with pytest.raises(TypeError, match="scene: expected"):
        pyraypack.dask.render(42, 8, 8)
