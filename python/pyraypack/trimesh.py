"""A drop-in for trimesh's ray queries, traced by raypack.

    >>> import trimesh, pyraypack.trimesh
    >>> mesh = trimesh.creation.icosphere()
    >>> mesh.ray = pyraypack.trimesh.RayMeshIntersector(mesh)
    >>> locations, index_ray, index_tri = mesh.ray.intersects_location(
    ...     ray_origins=[[0, 0, -5], [2, 2, -10]], ray_directions=[[0, 0, 1], [0, 0, 1]])
    >>> index_ray
    array([0, 0])

``RayMeshIntersector`` has the methods, signatures and return conventions of trimesh's own
intersectors (``trimesh.ray.ray_pyembree`` and ``trimesh.ray.ray_triangle``):
``intersects_first``, ``intersects_any``, ``intersects_id`` (with ``multiple_hits`` and
``return_locations``), ``intersects_location`` and ``contains_points``. As in trimesh's
engines, a ray that starts on a face hits it (at distance 0), and with ``multiple_hits=True``
goes on past it to the faces beyond. Differences from trimesh's embree intersector:

* ``multiple_hits=True`` results are ordered by ray, then by distance along it (trimesh's
  embree intersector orders them by hit depth first); the same hits otherwise. After a hit a
  ray goes on from ``max(1e-8, mesh.scale * 1e-6)`` past it, as trimesh's embree intersector
  does, so a ray crossing a shared edge counts one hit.
* ``intersects_first`` returns int64 face indices (trimesh's embree intersector int32, its
  pure-numpy one int64).
* Where a ray meets an edge or a vertex, or starts within float32 rounding of a face, either
  of two equally valid answers may come out, and not always trimesh's: raypack traces in
  float32 in the mesh's own frame (moved to the origin only when it lies far from it), trimesh's
  embree intersector in float32 after moving the mesh's lowest corner to the origin and scaling
  it to about 100 units, so the two round differently (``watertight=True`` makes raypack's
  own answer at an edge a hit on one of its faces, never a miss between them).
* A hit on a face the ray runs almost along (``|cos|`` of the angle between the direction and
  the face's normal at most 1e-5) is kept, located where the ray meets the face's plane (at
  ``origin + t * direction`` when it runs along it); trimesh's embree intersector drops it
  when locations or multiple hits are asked for, and that ray stops there.
* Directions need not be unit length (trimesh normalises them; the hits are the same).
* The scene is rebuilt when the mesh changes (trimesh's cache), with ``quality=``,
  ``watertight=`` and ``threads=`` as given to the constructor.

trimesh is an optional dependency of raypack: this module imports it.
"""

from __future__ import annotations

import numpy as np
from trimesh import caching
from trimesh.ray.ray_util import contains_points as _contains_points

from . import Scene
from ._raypack import _plane_points

__all__ = ["RayMeshIntersector"]

# As trimesh's embree intersector: how far past a hit a ray continues (multiple hits).
_RAY_OFFSET_FACTOR = 1e-6
_RAY_OFFSET_FLOOR = 1e-8


class RayMeshIntersector:
    """Ray queries on a ``trimesh.Trimesh``, traced by raypack.

    Parameters
    ----------
    geometry : trimesh.Trimesh
      The mesh to trace.
    scale_to_box : bool
      Accepted for compatibility with trimesh's embree intersector. raypack moves the mesh to
      the origin when it lies far from it (as trimesh does, for float32 precision), but does
      not scale it: scaling changes no float32 hit.
    quality, watertight, threads
      The build options of ``pyraypack.Scene``; ``threads`` also applies to every query.
    """

    def __init__(
        self,
        geometry,
        scale_to_box: bool = True,
        *,
        quality: str = "medium",
        watertight: bool = False,
        threads: int | None = None,
    ):
        self.mesh = geometry
        self._scale_to_box = scale_to_box
        self._options = {"quality": quality, "watertight": watertight, "threads": threads}
        self._cache = caching.Cache(id_function=self.mesh.__hash__)

    @caching.cache_decorator
    def _traced(self):
        """(scene, shift): the raypack scene of ``mesh.vertices - shift``."""
        vertices = np.asarray(self.mesh.vertices, dtype=np.float64)
        shift = None
        if len(vertices):
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
            center = (lo + hi) / 2
            # float32 keeps ~7 digits of |coordinate|: move meshes that lie far from the
            # origin relative to their size.
            if np.abs(center).max() > (hi - lo).max():
                shift = center
                vertices = vertices - shift
        import warnings

        with warnings.catch_warnings():
            # Degenerate faces are common in real meshes and are never hit, as in trimesh.
            warnings.simplefilter("ignore", category=UserWarning)
            scene = Scene(vertices, self.mesh.faces, **self._options)
        return scene, shift

    def _rays(self, ray_origins, ray_directions):
        """Origins and directions as arrays (origins float64, shifted with the mesh)."""
        origins = np.asarray(ray_origins, dtype=np.float64)
        directions = np.asarray(ray_directions)
        if origins.shape != directions.shape:
            raise ValueError(
                f"ray_origins and ray_directions: expected the same shape (n, 3), "
                f"got {origins.shape} and {directions.shape}"
            )
        shift = self._traced[1]
        return origins, (origins if shift is None else origins - shift), directions

    def intersects_id(
        self,
        ray_origins,
        ray_directions,
        multiple_hits: bool = True,
        max_hits: int = 100,
        return_locations: bool = False,
    ):
        """Find the triangles hit by a list of rays, including optionally multiple hits
        along a single ray.

        Parameters
        ----------
        ray_origins : (n, 3) float
          Origins of rays
        ray_directions : (n, 3) float
          Direction (vector) of rays
        multiple_hits : bool
          If True will return every hit along the ray
          If False will only return first hit
        max_hits : int
          Maximum number of hits per ray
        return_locations : bool
          Should we return hit locations or not

        Returns
        ---------
        index_tri : (m,) int
          Indexes of mesh.faces
        index_ray : (m,) int
          Indexes of ray
        locations : (m, 3) float
          Intersection points, only returned if return_locations
        """
        origins, traced_origins, directions = self._rays(ray_origins, ray_directions)
        scene = self._traced[0]
        threads = self._options["threads"]
        if multiple_hits:
            step = max(_RAY_OFFSET_FLOOR, float(self.mesh.scale) * _RAY_OFFSET_FACTOR)
            index_ray, index_tri, t, _, _ = scene.intersect_all(
                traced_origins, directions, max_hits=int(max_hits), min_step=step, threads=threads
            )
        else:
            hits = scene.intersect(traced_origins, directions, threads=threads)
            index_ray = np.flatnonzero(hits.prim >= 0)
            index_tri = hits.prim[index_ray]
            t = hits.t[index_ray]
        if not return_locations:
            return index_tri, index_ray
        return index_tri, index_ray, self._locations(origins, directions, index_ray, index_tri, t)

    def _locations(self, origins, directions, index_ray, index_tri, t):
        """Hit points in float64, as trimesh computes them: where each ray meets the plane of
        the (float64) triangle it hit; ``origin + t * direction`` (t in float32) where the ray
        runs along that plane (computed in Rust over all cores)."""
        return _plane_points(
            np.ascontiguousarray(self.mesh.vertices, dtype=np.float64),
            np.ascontiguousarray(self.mesh.faces, dtype=np.int64),
            index_tri,
            index_ray,
            np.ascontiguousarray(t, dtype=np.float32),
            np.ascontiguousarray(origins, dtype=np.float64),
            np.ascontiguousarray(directions, dtype=np.float64),
        )

    def intersects_location(self, ray_origins, ray_directions, multiple_hits: bool = True):
        """Return the location of where a ray hits a surface.

        Parameters
        ----------
        ray_origins : (n, 3) float
          Origins of rays
        ray_directions : (n, 3) float
          Direction (vector) of rays
        multiple_hits : bool
          Every hit along each ray, or only the first

        Returns
        ---------
        locations : (m, 3) float
          Intersection points
        index_ray : (m,) int
          Indexes of ray
        index_tri : (m,) int
          Indexes of mesh.faces
        """
        index_tri, index_ray, locations = self.intersects_id(
            ray_origins, ray_directions, multiple_hits=multiple_hits, return_locations=True
        )
        return locations, index_ray, index_tri

    def intersects_first(self, ray_origins, ray_directions):
        """Find the index of the first triangle a ray hits.

        Parameters
        ----------
        ray_origins : (n, 3) float
          Origins of rays
        ray_directions : (n, 3) float
          Direction (vector) of rays

        Returns
        ----------
        triangle_index : (n,) int
          Index of triangle ray hit, or -1 if not hit
        """
        return self._query("intersect", ray_origins, ray_directions).prim

    def intersects_any(self, ray_origins, ray_directions):
        """Check if a list of rays hits the surface.

        Parameters
        -----------
        ray_origins : (n, 3) float
          Origins of rays
        ray_directions : (n, 3) float
          Direction (vector) of rays

        Returns
        ----------
        hit : (n,) bool
          Did each ray hit the surface
        """
        return self._query("occluded", ray_origins, ray_directions)

    def _query(self, query, ray_origins, ray_directions):
        """``Scene.intersect`` or ``Scene.occluded`` on the traced mesh, with the rays checked
        and moved as ``_rays`` does."""
        _, traced_origins, directions = self._rays(ray_origins, ray_directions)
        return getattr(self._traced[0], query)(traced_origins, directions, threads=self._options["threads"])

    def contains_points(self, points):
        """Check if a mesh contains a list of points, using ray tests (trimesh's own parity
        test, on raypack's ``intersects_location``).

        If the point is on the surface of the mesh, behavior is undefined.

        Parameters
        ---------
        points: (n, 3) points in space

        Returns
        ---------
        contains: (n,) bool
          Whether point is inside mesh or not
        """
        return _contains_points(self, points)

    def __getstate__(self):
        state = self.__dict__.copy()
        # The scene is rebuilt on demand, never pickled.
        state.pop("_cache", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._cache = caching.Cache(id_function=self.mesh.__hash__)

    def __deepcopy__(self, *args):
        return self.__copy__()

    def __copy__(self, *args):
        return type(self)(self.mesh, self._scale_to_box, **self._options)
