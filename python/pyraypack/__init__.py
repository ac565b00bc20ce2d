"""pyraypack: raypack, a data-oriented SIMD ray tracer (BVH8, ray packets) for numpy rays.

    >>> import numpy as np, pyraypack
    >>> scene = pyraypack.Scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    >>> hits = scene.intersect(origins=[0.25, 0.25, 1.0], directions=np.array([[0, 0, -1.0]]))
    >>> hits.t, hits.prim
    (array([1.], dtype=float32), array([0]))

``pyraypack.isa()`` names the kernels' instruction set (also in ``repr(scene)``) and
``pyraypack.__version__`` the package's version. ``Scene`` builds a scene from vertex and face arrays, ``load`` reads a scene file,
``Scene.intersect`` / ``Scene.occluded`` trace numpy rays over all cores with the GIL
released, ``render`` runs the path tracer (on the whole image or a window of it),
``pyraypack.trimesh.RayMeshIntersector`` is a drop-in for trimesh's ray queries, and
``pyraypack.dask`` spreads renders and ray batches over a Dask cluster (``pip install
pyraypack[dask]``). Scenes pickle with their BVH, which is never rebuilt.
"""

from ._raypack import Hits, Scene, SceneWarning, __version__, isa, load, render, tile_bounds

__all__ = ["Hits", "Scene", "SceneWarning", "__version__", "isa", "load", "render", "tile_bounds"]
