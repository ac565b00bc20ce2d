"""raypack on Dask: renders split into parts and ray batches split into chunks, on a
``dask.distributed`` cluster when a client is active (a ``LocalCluster`` on one machine,
``dask-jobqueue``'s ``SLURMCluster`` or ``PBSCluster`` on a batch system, ``dask-kubernetes``)
and on Dask's local scheduler otherwise. Install with ``pip install pyraypack[dask]``.

    >>> import pyraypack, pyraypack.dask
    >>> image = pyraypack.dask.render("CBbunny.dae", 480, 360, spp=64, max_depth=5, tiles=8)
    >>> hits = pyraypack.dask.intersect(scene, origins, directions)   # dask arrays
    >>> t = hits.t.compute()

The results do not depend on how the work is split: a render's parts are the pixels of
``pyraypack.render(..., pixel_bounds=part)``, each bit for bit its value in the whole image, and
a chunk's hits are ``Scene.intersect``'s for its rays.

The scene goes to each worker once: on a cluster it is registered as a worker plugin
(``Client.register_plugin``), which the scheduler sends to every worker, and to workers that
join later, exactly once; tasks name it, so no task carries it and Dask's active memory manager
cannot drop a worker's copy between calls (as it drops the extra replicas of scattered data).
Its pickle holds the BVH (``len(pickle.dumps(scene))`` bytes), so no worker builds it again.
The last few scenes stay registered for the client's session. A scene given as a path is
loaded (and its BVH built, or read from ``bvh_cache``) once, on the client.
"""

from __future__ import annotations

import os
import warnings
from typing import Any, Literal, NamedTuple

import numpy as np

from . import _raypack

__all__ = ["DaskHits", "intersect", "occluded", "render"]


def _modules() -> tuple[Any, Any]:
    """``dask`` and ``dask.array``, or an ImportError saying how to install them."""
    try:
        import dask
        import dask.array
    except ImportError as e:  # pragma: no cover - exercised without dask only
        raise ImportError("pyraypack.dask needs Dask: pip install pyraypack[dask] (or dask[array,distributed])") from e
    return dask, dask.array


def _active_client(client: Any = None) -> Any:
    """``client``, or the active ``dask.distributed`` client, or None (the local scheduler)."""
    if client is not None:
        return client
    try:
        from distributed import get_client
    except ImportError:
        return None
    try:
        return get_client()
    except ValueError:
        return None


def _task_threads() -> int | None:
    """Threads a task may use: the worker's (its tasks share one raypack thread pool of that
    size), or None (all cores) outside a ``dask.distributed`` worker."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return None
    state = getattr(worker, "state", None)
    n = getattr(state, "nthreads", None) or getattr(worker, "nthreads", None)
    return int(n) if n else None


try:
    from distributed import WorkerPlugin as _WorkerPlugin
except ImportError:  # pragma: no cover - dask without distributed: the local scheduler only
    _WorkerPlugin = object  # type: ignore[misc, assignment]


class _ScenePlugin(_WorkerPlugin):
    """A scene every worker of a cluster holds, under the plugin's name."""

    idempotent = True

    def __init__(self, scene: _raypack.Scene) -> None:
        self.scene = scene


class _OnWorkers(NamedTuple):
    """What a task gets for a scene held by the workers' plugin ``name``."""

    name: str


def _scene(scene: Any) -> _raypack.Scene:
    """The scene a task traces: ``scene`` itself, or the one its worker's plugin holds."""
    if isinstance(scene, _OnWorkers):
        from distributed import get_worker

        plugin: _ScenePlugin = get_worker().plugins[scene.name]  # type: ignore[assignment]
        return plugin.scene
    return scene


# Scenes on clusters: (the client's id, the scene's token) -> the name of the worker plugin
# that holds it, so that calls with the same scene send it only once. The last few are kept
# (each holds its scene in every worker's memory, and the scheduler's, until unregistered or
# the client closes).
_SHARED: dict[tuple[str, str], str] = {}
_SHARED_KEPT = 4


def _share(scene: _raypack.Scene, client: Any) -> Any:
    """What tasks take for the scene: on a cluster the name of a worker plugin holding it on
    every worker (sent once to each, and once per session), else the scene itself."""
    if client is None:
        return scene
    token = scene.__dask_tokenize__()
    key = (str(client.id), token)
    name = _SHARED.get(key)
    if name is None:
        name = f"pyraypack-scene-{token}"
        plugin = _ScenePlugin(scene)
        if hasattr(client, "register_plugin"):
            client.register_plugin(plugin, name=name)
        else:  # pragma: no cover - dask.distributed before 2023.9
            client.register_worker_plugin(plugin, name=name)
        _SHARED[key] = name
        while len(_SHARED) > _SHARED_KEPT:
            oldest = next(iter(_SHARED))
            if oldest[0] == key[0]:
                client.unregister_worker_plugin(_SHARED[oldest])
            del _SHARED[oldest]
    return _OnWorkers(name)


_Quality = Literal["fast", "medium", "high"]
_Integrator = Literal["global", "direct", "direct-only", "indirect-only", "bounce", "normals"]


def _load(scene: Any, quality: _Quality, watertight: bool, bvh_cache: Any) -> _raypack.Scene:
    """The scene, loaded for a render if it is a path (a file without lights says it gets the
    default rig); its warnings point at the line that called the public function that called
    this one."""
    if isinstance(scene, _raypack.Scene):
        return scene
    if isinstance(scene, (str, os.PathLike)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            loaded = _raypack._load_for_render(scene, quality=quality, watertight=watertight, bvh_cache=bvh_cache)
        for w in caught:
            warnings.warn(w.message, w.category, stacklevel=3)
        return loaded
    raise TypeError(f"scene: expected a pyraypack.Scene or a path to a scene file, got {type(scene).__name__}")


def _render_part(scene: Any, bounds: tuple[int, int, int, int], settings: dict[str, Any]) -> np.ndarray:
    return _raypack.render(_scene(scene), pixel_bounds=bounds, threads=_task_threads(), **settings)


def render(
    scene: Any,
    width: int = 480,
    height: int = 360,
    spp: int = 1,
    *,
    tiles: int | None = None,
    max_depth: int = 1,
    light_samples: int = 1,
    seed: int = 0,
    sampler: str = "sobol",
    integrator: _Integrator = "global",
    hemisphere: bool = False,
    russian_roulette: bool = True,
    quality: _Quality = "medium",
    watertight: bool = False,
    bvh_cache: Any = None,
    client: Any = None,
) -> np.ndarray:
    """Renders ``scene`` (a ``pyraypack.Scene`` or a scene file's path) in ``tiles`` parts, one
    task each, and returns the whole image: float32 ``(height, width, 3)``, bit for bit
    ``pyraypack.render``'s with the same settings. The parts are ``pyraypack.tile_bounds(tiles,
    width, height)`` (those of ``raypack render --tile I/N``); by default two per worker
    thread of the cluster, or one per core on the local scheduler. ``client`` defaults to the
    active ``dask.distributed`` client."""
    dask, _ = _modules()
    client = _active_client(client)
    if tiles is None:
        threads = sum(client.nthreads().values()) if client is not None else (os.cpu_count() or 1)
        tiles = max(1, 2 * threads) if client is not None else max(1, threads)
        # As many as the image allows, down to one pixel per part.
        tiles = min(tiles, width * height)
    bounds = _raypack.tile_bounds(tiles, width, height)
    settings = dict(
        width=width,
        height=height,
        spp=spp,
        max_depth=max_depth,
        light_samples=light_samples,
        seed=seed,
        sampler=sampler,
        integrator=integrator,
        hemisphere=hemisphere,
        russian_roulette=russian_roulette,
    )
    shared = _share(_load(scene, quality, watertight, bvh_cache), client)
    parts = [dask.delayed(_render_part, pure=True)(shared, b, settings) for b in bounds]
    computed = dask.compute(*parts) if client is None else client.compute(parts, sync=True)
    image = np.empty((height, width, 3), dtype=np.float32)
    for (x0, x1, y0, y1), pixels in zip(bounds, computed):
        image[y0:y1, x0:x1] = pixels
    return image


class DaskHits(NamedTuple):
    """``Scene.intersect``'s outputs as dask arrays, one chunk per chunk of rays: ``t``
    (float32, ``inf`` on a miss), ``prim`` (int64, ``-1``), ``u``, ``v`` (float32) and
    ``normal`` (float32 ``(K, 3)``)."""

    t: Any
    prim: Any
    u: Any
    v: Any
    normal: Any

    @property
    def hit(self) -> Any:
        """Whether each ray hit something: ``prim >= 0``."""
        return self.prim >= 0


def _rays(rays: tuple[Any, ...]) -> tuple[Any, ...]:
    """``(origins, directions, tnear, tfar)`` from a task's arguments: those four, or one
    tuple of them (a numpy chunk scattered whole)."""
    return rays[0] if len(rays) == 1 else rays


def _intersect_chunk(scene: Any, *rays: Any) -> tuple[np.ndarray, ...]:
    return tuple(_scene(scene).intersect(*_rays(rays), threads=_task_threads()))


def _occluded_chunk(scene: Any, *rays: Any) -> np.ndarray:
    return _scene(scene).occluded(*_rays(rays), threads=_task_threads())


def _chunks(
    origins: Any, directions: Any, tnear: Any, tfar: Any, chunk_rays: int, client: Any
) -> tuple[list[Any], list[int]]:
    """The rays as a list of chunks, the arguments of each chunk's task (``(origins,
    directions, tnear, tfar)``, delayed values or numbers, or one future or delayed value of
    that tuple), and the rays in each. numpy inputs are cut into chunks of ``chunk_rays``
    rays, on a cluster each chunk's arrays sent together once to one worker; dask arrays keep
    their row chunks (the other arrays are rechunked to them), and their blocks go to the
    tracing task directly, where they are (no task in between that would gather them onto
    one worker first)."""
    dask, da = _modules()
    if chunk_rays < 1:
        raise ValueError(f"chunk_rays: expected at least 1, got {chunk_rays}")
    per_ray = [(name, x) for name, x in (("tnear", tnear), ("tfar", tfar)) if x is not None and np.ndim(x) > 0]
    if isinstance(origins, da.Array) or isinstance(directions, da.Array):
        o = da.asarray(origins)
        if o.ndim != 2 or o.shape[1] != 3:
            raise ValueError(f"origins: expected shape (K, 3), got {o.shape}")
        o = o.rechunk({1: 3})
        rows = o.chunks[0]
        d = da.asarray(directions)
        if d.shape != o.shape:
            raise ValueError(f"directions: expected shape {o.shape} as origins, got {d.shape}")
        d = d.rechunk((rows, 3))
        extra = {name: da.asarray(x).rechunk((rows,)) for name, x in per_ray}
        o_blocks, d_blocks = o.to_delayed().ravel(), d.to_delayed().ravel()
        e_blocks = {name: x.to_delayed().ravel() for name, x in extra.items()}
        chunks = []
        for i in range(len(rows)):
            tn = e_blocks["tnear"][i] if "tnear" in e_blocks else tnear
            tf = e_blocks["tfar"][i] if "tfar" in e_blocks else tfar
            chunks.append((o_blocks[i], d_blocks[i], tn, tf))
        return chunks, list(rows)
    o, d = np.asarray(origins), np.asarray(directions)
    if o.ndim != 2 or o.shape[1] != 3:
        raise ValueError(f"origins: expected shape (K, 3), got {o.shape}")
    if d.shape != o.shape:
        raise ValueError(f"directions: expected shape {o.shape} as origins, got {d.shape}")
    arrays = {name: np.asarray(x) for name, x in per_ray}
    for name, x in arrays.items():
        if x.shape != (len(o),):
            raise ValueError(f"{name}: expected a number or shape ({len(o)},), got {x.shape}")
    pieces, rows = [], []
    for start in range(0, len(o), chunk_rays):
        end = min(start + chunk_rays, len(o))
        tn = arrays["tnear"][start:end] if "tnear" in arrays else tnear
        tf = arrays["tfar"][start:end] if "tfar" in arrays else tfar
        pieces.append((o[start:end], d[start:end], tn, tf))
        rows.append(end - start)
    if client is not None:
        # Each chunk's arrays straight to one worker together, rather than the whole arrays
        # into the graph.
        return [(f,) for f in client.scatter(pieces)], rows
    return [(dask.delayed(p, traverse=False),) for p in pieces], rows


def _prepare(scene: _raypack.Scene, origins: Any, directions: Any, tnear: Any, tfar: Any, chunk_rays: int, client: Any):
    """What ``intersect`` and ``occluded`` share: the dask modules, the scene shared with the
    workers, and the rays' chunks with their row counts."""
    dask, da = _modules()
    client = _active_client(client)
    shared = _share(scene, client)
    chunks, rows = _chunks(origins, directions, tnear, tfar, chunk_rays, client)
    return dask, da, shared, chunks, rows


def intersect(
    scene: _raypack.Scene,
    origins: Any,
    directions: Any,
    tnear: Any = None,
    tfar: Any = None,
    *,
    chunk_rays: int = 1 << 20,
    client: Any = None,
) -> DaskHits:
    """``scene.intersect(origins, directions, tnear, tfar)`` chunk by chunk, as dask arrays
    (compute them, or persist them on the cluster). ``origins`` and ``directions`` are ``(K,
    3)`` numpy or dask arrays; ``tnear`` and ``tfar`` numbers or ``(K,)`` arrays. Each chunk's
    hits are ``Scene.intersect``'s for its rays; the scene goes to each worker once."""
    dask, da, shared, chunks, rows = _prepare(scene, origins, directions, tnear, tfar, chunk_rays, client)
    outputs: list[list[Any]] = [[], [], [], [], []]
    specs = [((), np.float32), ((), np.int64), ((), np.float32), ((), np.float32), ((3,), np.float32)]
    for chunk, n in zip(chunks, rows):
        hits = dask.delayed(_intersect_chunk, pure=True, nout=5)(shared, *chunk)
        for k, (tail, dtype) in enumerate(specs):
            outputs[k].append(da.from_delayed(hits[k], shape=(n, *tail), dtype=dtype))
    return DaskHits(*(da.concatenate(o) for o in outputs))


def occluded(
    scene: _raypack.Scene,
    origins: Any,
    directions: Any,
    tnear: Any = None,
    tfar: Any = None,
    *,
    chunk_rays: int = 1 << 20,
    client: Any = None,
) -> Any:
    """``scene.occluded(...)`` chunk by chunk, as a dask bool array (see ``intersect``)."""
    dask, da, shared, chunks, rows = _prepare(scene, origins, directions, tnear, tfar, chunk_rays, client)
    blocks = [
        da.from_delayed(dask.delayed(_occluded_chunk, pure=True)(shared, *chunk), shape=(n,), dtype=bool)
        for chunk, n in zip(chunks, rows)
    ]
    return da.concatenate(blocks)
