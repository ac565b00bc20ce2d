"""Type stubs of the native module ``pyraypack._raypack`` (re-exported by ``pyraypack``)."""

from collections.abc import Iterator
import pathlib
from os import PathLike
from typing import Literal, Union, final

import numpy as np
import numpy.typing as npt

_Real = Union[float, int, np.floating, np.integer]
_Points = npt.ArrayLike  # (K, 3) real array, or (3,) for one point
_PerRay = Union[_Real, npt.ArrayLike]  # a number, or a (K,) real array
_Quality = Literal["fast", "medium", "high"]
_Integrator = Literal["global", "direct", "direct-only", "indirect-only", "bounce", "normals"]
_Path = Union[str, PathLike[str]]

__version__: str

__all__ = [
    "__version__",
    "isa",
    "Scene",
    "Hits",
    "load",
    "render",
    "tile_bounds",
    "_ray_sets",
    "_intersect_stream",
    "_plane_points",
    "_bvh_builds",
    "_load_for_render",
    "_scene_from_snapshot",
    "SceneWarning",
]

class SceneWarning(UserWarning):
    """A scene was loaded or committed with something left out (dropped faces, a BVH cache
    that could not be used, loader warnings)."""

@final
class Hits:
    """The closest hits of a ray query, one entry per ray.

    ``t`` float32 (``inf`` on a miss), ``prim`` int64 (``-1`` on a miss), ``u``, ``v`` float32
    barycentrics of the second and third vertex (0 on a miss), ``normal`` float32 ``(K, 3)``
    unit geometric normal ``(v1 - v0) x (v2 - v0)`` (zero on a miss). Unpacks as
    ``t, prim, u, v, normal = hits``.
    """

    @property
    def t(self) -> npt.NDArray[np.float32]: ...
    @property
    def prim(self) -> npt.NDArray[np.int64]: ...
    @property
    def u(self) -> npt.NDArray[np.float32]: ...
    @property
    def v(self) -> npt.NDArray[np.float32]: ...
    @property
    def normal(self) -> npt.NDArray[np.float32]: ...
    @property
    def hit(self) -> npt.NDArray[np.bool_]:
        """Whether each ray hit something (``prim >= 0``)."""
    def __iter__(self) -> Iterator[npt.NDArray[np.generic]]: ...
    def __len__(self) -> int: ...

@final
class Scene:
    """A committed scene: triangles (and the spheres of scene files) under raypack's BVH8.

    ``vertices`` is an ``(N, 3)`` array of positions (any real dtype, rounded to float32),
    ``faces`` an ``(M, 3)`` integer array of vertex indices; any memory layout. Faces that
    cannot be traced (NaN/Inf or huge coordinates, zero area, collinear corners) are dropped,
    counted in ``report`` and announced by a ``SceneWarning``; they are never hit, and
    ``prim`` ids and ``Scene.faces`` stay those of the faces given. ``quality`` is the BVH build effort, ``watertight`` selects the
    watertight triangle test (no ray slips through a shared edge), ``bvh_cache`` a directory
    where the BVH is saved and reloaded, ``threads`` the build's threads (default: all cores).

    Raises ``ValueError`` / ``TypeError`` naming the argument for a wrong shape or dtype and
    for indices out of range.
    """

    def __new__(
        cls,
        vertices: npt.ArrayLike,
        faces: npt.ArrayLike,
        *,
        quality: _Quality = "medium",
        watertight: bool = False,
        bvh_cache: _Path | None = None,
        threads: int | None = None,
    ) -> Scene: ...
    def intersect(
        self,
        origins: _Points,
        directions: _Points,
        tnear: _PerRay | None = None,
        tfar: _PerRay | None = None,
        *,
        threads: int | None = None,
    ) -> Hits:
        """Closest hit of each ray ``origin + t * direction`` over ``t`` in ``[tnear, tfar]``.
        Both ends count: a ray that starts on a surface (``tnear = 0``) hits it at ``t = 0``.

        ``origins`` and ``directions`` are ``(K, 3)`` real arrays (float32 and float64 are read
        in place whatever their strides; one ``(3,)`` point stands for all rays); ``tnear``
        (default 0) and ``tfar`` (default ``inf``) are numbers or ``(K,)`` arrays, and a value
        below zero is a ``ValueError`` naming the argument. Directions need not be unit length:
        ``t`` is measured in units of their length. Rays with a NaN/Inf component, a zero
        direction, a NaN ``tnear``/``tfar`` or ``tnear > tfar`` miss. Traced over ``threads``
        threads (default: all cores) with the GIL released, as 16-ray packets in the order
        given (keep coherent rays together).
        """
    def occluded(
        self,
        origins: _Points,
        directions: _Points,
        tnear: _PerRay | None = None,
        tfar: _PerRay | None = None,
        *,
        threads: int | None = None,
    ) -> npt.NDArray[np.bool_]:
        """Whether anything lies on each ray over ``[tnear, tfar]``: ``bool (K,)``. Arguments as
        for ``intersect``."""
    def intersect_all(
        self,
        origins: _Points,
        directions: _Points,
        tnear: _PerRay | None = None,
        tfar: _PerRay | None = None,
        *,
        max_hits: int = 100,
        min_step: float = 0.0,
        threads: int | None = None,
    ) -> tuple[
        npt.NDArray[np.int64],
        npt.NDArray[np.int64],
        npt.NDArray[np.float32],
        npt.NDArray[np.float32],
        npt.NDArray[np.float32],
    ]:
        """Every hit along each ray, at most ``max_hits`` per ray: ``(ray, prim, t, u, v)``
        arrays, ordered by ray, then by ``t``. After a hit at ``t`` the ray goes on from
        ``t + min_step / |direction|`` (``min_step`` is a distance), at least from the next
        float above ``t``; the first hit may be at ``t = tnear``."""
    @property
    def num_triangles(self) -> int:
        """Triangles the scene traces (after dropping the untraceable ones)."""
    @property
    def num_spheres(self) -> int:
        """Spheres the scene traces (scene files only)."""
    @property
    def bounds(self) -> npt.NDArray[np.float32]:
        """``(2, 3)`` float32 ``[min, max]`` (NaN for an empty scene)."""
    @property
    def report(self) -> dict[str, int]:
        """What the commit kept and dropped: ``triangles``, ``spheres``, ``dropped_non_finite``,
        ``dropped_degenerate``, ``dropped_spheres``."""
    @property
    def bvh_cache_file(self) -> pathlib.Path | None:
        """The BVH cache file of this scene (``None`` without ``bvh_cache=``)."""
    @property
    def bvh_cache_loaded(self) -> bool:
        """True when the BVH was read from the cache rather than built."""
    @property
    def vertices(self) -> npt.NDArray[np.float32]:
        """The vertex positions ``(N, 3)`` float32 (a copy)."""
    @property
    def faces(self) -> npt.NDArray[np.int64]:
        """The faces ``(M, 3)`` int64 (a copy) as given to ``Scene`` or as the file holds them
        (polygons as triangles), the dropped ones included: ``prim`` ids index these rows (a
        sphere's ``prim`` is ``M`` plus its index among the scene's spheres)."""
    def __dask_tokenize__(self) -> str:
        """A token of the scene's contents, for Dask."""
    def __reduce__(
        self,
    ) -> tuple[object, tuple[bytes, bytes | None, tuple[int, int, int, int, int], bytes | None]]:
        """Pickling: the scene travels whole, BVH included (about the BVH's size plus the
        geometry's), and is checked on unpickling as a cache file from another user is; an
        unpickled scene is never rebuilt."""

def load(
    path: _Path,
    *,
    quality: _Quality = "medium",
    watertight: bool = False,
    bvh_cache: _Path | None = None,
    threads: int | None = None,
) -> Scene:
    """Loads a scene file (``.dae``, ``.obj``, ``.ply``) and commits it. Raises
    ``FileNotFoundError`` for a missing file and ``ValueError`` naming the file and the line or
    element for a malformed one; loader warnings become ``SceneWarning``s. A file without
    lights gets the CLI's default light rig for ``render`` without a warning (ray casting
    does not use lights; ``render(path)`` says so)."""

def render(
    scene: Scene | _Path,
    *,
    spp: int = 1,
    max_depth: int = 1,
    light_samples: int = 1,
    width: int = 480,
    height: int = 360,
    seed: int = 0,
    sampler: Literal["sobol", "independent"] = "sobol",
    integrator: _Integrator = "global",
    hemisphere: bool = False,
    russian_roulette: bool = True,
    threads: int | None = None,
    quality: _Quality = "medium",
    watertight: bool = False,
    bvh_cache: _Path | None = None,
    crop_window: tuple[float, float, float, float] | None = None,
    pixel_bounds: tuple[int, int, int, int] | None = None,
) -> npt.NDArray[np.float32]:
    """Renders a scene (a ``Scene`` or a scene file's path) with raypack's path tracer, as
    ``raypack render`` does with the same settings, and returns the linear HDR image as
    float32 ``(height, width, 3)``, top row first. The image depends on the seed only, not on
    the thread count. ``sampler`` chooses the paths' random numbers: ``"sobol"`` (scrambled
    Sobol' points, less noise per sample) or ``"independent"``. ``quality``, ``watertight`` and
    ``bvh_cache`` apply when ``scene`` is a path.

    ``crop_window=(x0, x1, y0, y1)`` (fractions, as pbrt's ``--cropwindow``) or
    ``pixel_bounds=(x0, x1, y0, y1)`` (pixels, ends exclusive) render only that window and
    return its pixels ``(y1 - y0, x1 - x0, 3)``, each bit for bit its value in the whole
    image."""

def isa() -> str:
    """The instruction set the kernels run on in this process: ``"avx512"``, ``"avx2"`` or
    ``"sse2"`` (``"portable"`` off x86-64), the CPU's best unless ``RAYPACK_ISA`` names a
    lower tier (read once, when the first scene is made). Every ``Scene``'s ``repr`` shows it
    too."""

def tile_bounds(count: int, width: int, height: int) -> list[tuple[int, int, int, int]]:
    """The pixel bounds ``(x0, x1, y0, y1)`` of the ``count`` parts of a ``width x height``
    image, numbered as ``raypack render --tile I/N`` numbers them."""

# Not public API: helpers of tools/bench-python.py and the tests.
def _bvh_builds() -> int:
    """How many BVHs this process has built (cache and pickle loads do not count)."""

def _load_for_render(
    path: _Path, *, quality: _Quality = "medium", watertight: bool = False, bvh_cache: _Path | None = None
) -> Scene:
    """``load`` for a render elsewhere (``pyraypack.dask.render(path)``): also warns when the
    file has no lights, as ``render(path)`` does."""

def _scene_from_snapshot(
    snapshot: bytes, kept: bytes | None, report: tuple[int, int, int, int, int], dropped: bytes | None = None
) -> Scene:
    """Unpickles a ``Scene`` (``Scene.__reduce__``), checking the snapshot first."""

def _ray_sets(
    scene: Scene, width: int, height: int, seed: int = 1
) -> dict[str, tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.float32]]]:
    """`raypack bench`'s ray sets: ``{"camera" | "diffuse" | "shadow": (origins, directions, tfar)}``."""

def _intersect_stream(
    scene: Scene, origins: _Points, directions: _Points, tnear: float = 0.0, tfar: float = ...
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.float32]]:
    """The rays traced by the Rust API's ``Scene::intersect_stream``: ``(t, prim, u, v)``, the
    ``prim`` ids numbered as ``Scene.intersect`` numbers them."""

def _plane_points(
    vertices: npt.NDArray[np.float64],
    faces: npt.NDArray[np.int64],
    tri: npt.NDArray[np.int64],
    ray: npt.NDArray[np.int64],
    t: npt.NDArray[np.float32],
    origins: npt.NDArray[np.float64],
    directions: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """float64 hit locations for ``pyraypack.trimesh``: where each ray meets its triangle's plane."""
