#!/usr/bin/env python3
"""raypack's Python module against embreex, Open3D's RaycastingScene and trimesh's pure-numpy
intersector, on the same numpy rays.

    RAYPACK_SCENES=../shared/scenes python tools/bench-python.py [--json out.json]

For each scene: camera rays in 4x4 pixel tiles (the image size chosen so that at least
--min-rays camera rays hit), one cosine-distributed diffuse bounce and one shadow ray (an
occlusion query toward a point light) per camera hit: the ray sets of `raypack bench`. Every
tracer gets the rays as numpy arrays (origins and directions (K, 3) float32, tfar (K,)) and
returns numpy arrays; the timings include every conversion in between:

* raypack: Scene.intersect (t, prim, u, v, normal) / Scene.occluded;
* embreex: EmbreeScene.run(output=True) (t, prim, u, v, Ng) and run() (prim only) /
  run(query="OCCLUDED"); embreex traces on the calling thread with the GIL released, so
  "all threads" splits the rays over a thread pool;
* Open3D: RaycastingScene.cast_rays / test_occlusions(nthreads=), rays stacked into (K, 6)
  (shadow rays: direction scaled to tfar, tfar = 1) and the outputs converted to numpy;
* trimesh: trimesh.ray.ray_triangle's intersects_first on the first --trimesh-rays rays
  only (it takes about a millisecond per ray), one thread.

Prints Mrays/s (median of --runs after a warm-up) and the ratio of raypack to the fastest of
embreex and Open3D on the same rays and threads; --json writes the same figures.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import statistics
import sys
import time
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import pyraypack

SCENES = ["cs184/meshedit/beetle.dae", "cs184/sky/CBbunny.dae", "models/stanford-dragon-871k.ply"]


def cpu_name() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def isa() -> str:
    try:
        flags = next(line for line in open("/proc/cpuinfo") if line.startswith("flags")).split()
    except (OSError, StopIteration):
        return "unknown"
    return "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"


def timed(f, runs: int) -> float:
    """Median wall time of `runs` calls after one warm-up call."""
    f()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def ray_sets(scene: pyraypack.Scene, min_rays: int, seed: int):
    """The camera, diffuse and shadow sets, at an image size with at least `min_rays` camera hits."""
    probe = pyraypack._raypack._ray_sets(scene, 160, 120, seed)
    fraction = max(len(probe["diffuse"][0]) / (160 * 120), 1e-3)
    pixels = max(min_rays / fraction * 1.02, min_rays)
    height = int(np.ceil(np.sqrt(pixels * 3 / 4) / 4) * 4)
    width = int(np.ceil(height * 4 / 3 / 4) * 4)
    return (width, height), pyraypack._raypack._ray_sets(scene, width, height, seed)


def split(n: int, parts: int):
    bounds = np.linspace(0, n, parts + 1).astype(int)
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


def tracers(scene, vertices, faces, threads: int, trimesh_rays: int):
    """name -> (closest-hit function, occlusion function or None), each taking (o, d, tfar)."""
    out = {}
    out["raypack"] = (
        lambda o, d, tf: scene.intersect(o, d, tfar=tf, threads=threads),
        lambda o, d, tf: scene.occluded(o, d, tfar=tf, threads=threads),
    )
    try:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        es = rtcore_scene.EmbreeScene()
        TriangleMesh(es, vertices.astype(np.float32), faces.astype(np.int32))

        def over_threads(run):
            def call(o, d, tf):
                if threads == 1:
                    return run(o, d, tf)
                with ThreadPoolExecutor(threads) as pool:
                    parts = list(pool.map(lambda s: run(o[s], d[s], tf[s]), split(len(o), threads)))
                if isinstance(parts[0], dict):
                    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
                return np.concatenate(parts)

            return call

        out["embreex"] = (
            over_threads(lambda o, d, tf: es.run(o, d, dists=tf.copy(), output=True)),
            over_threads(lambda o, d, tf: es.run(o, d, dists=tf.copy(), query="OCCLUDED") == 0),
        )
        out["embreex ids"] = (over_threads(lambda o, d, tf: es.run(o, d, dists=tf.copy())), None)
    except ImportError:
        print("bench-python: embreex is not installed: no embreex columns (pip install embreex)", file=sys.stderr)
    try:
        import open3d as o3d

        rc = o3d.t.geometry.RaycastingScene()
        rc.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32)))

        def o3d_cast(o, d, tf):
            r = rc.cast_rays(o3d.core.Tensor(np.hstack([o, d])), nthreads=threads)
            return {k: r[k].numpy() for k in ("t_hit", "primitive_ids", "primitive_uvs", "primitive_normals")}

        def o3d_occluded(o, d, tf):
            rays = o3d.core.Tensor(np.hstack([o, d * tf[:, None]]))
            return rc.test_occlusions(rays, tfar=1.0, nthreads=threads).numpy()

        out["open3d"] = (o3d_cast, o3d_occluded)
    except ImportError:
        print("bench-python: open3d is not installed: no Open3D column (pip install open3d-cpu)", file=sys.stderr)
    if threads == 1 and trimesh_rays > 0:
        try:
            import rtree  # noqa: F401  (ray_triangle needs it)
            import trimesh

            mesh = trimesh.Trimesh(vertices, faces, process=False)
            tri = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
            out["trimesh"] = (lambda o, d, tf: tri.intersects_first(o[:trimesh_rays], d[:trimesh_rays]), None)
        except ImportError:
            print("bench-python: trimesh or rtree is not installed: no trimesh column", file=sys.stderr)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help="scene files (default: beetle, CBbunny and the dragon under RAYPACK_SCENES)")
    ap.add_argument("--min-rays", type=int, default=1_000_000, help="camera hits (diffuse and shadow rays) per scene, at least")
    ap.add_argument("--runs", type=int, default=5, help="timed runs per figure (median)")
    ap.add_argument("--threads", type=int, nargs="+", default=[1, os.cpu_count() or 1])
    ap.add_argument("--trimesh-rays", type=int, default=2000, help="rays given to trimesh's pure-numpy intersector (0: none)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", type=pathlib.Path, help="write the figures as JSON here")
    args = ap.parse_args()

    paths = [pathlib.Path(p) for p in args.scenes]
    if not paths:
        root = os.environ.get("RAYPACK_SCENES")
        if not root:
            ap.error("give scene files or set RAYPACK_SCENES")
        paths = [pathlib.Path(root) / s for s in SCENES]

    machine = {"cpu": cpu_name(), "isa": isa(), "cores": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__}
    print(f"# {machine['cpu']} ({machine['isa']}), {machine['cores']} cores; Python {machine['python']}, numpy {machine['numpy']}")
    print("# Mrays/s, median of", args.runs, "runs, numpy arrays in and out (conversions included)")
    header = f"{'scene':<28} {'set':<8} {'rays':>9} {'thr':>3}  {'raypack':>8} {'embreex':>8} {'emb.ids':>8} {'open3d':>8} {'trimesh':>8}  {'ratio':>5}"
    print(header)
    rows = []
    for path in paths:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pyraypack.SceneWarning)
            scene = pyraypack.load(path)
        vertices, faces = scene.vertices, scene.faces
        (w, h), sets = ray_sets(scene, args.min_rays, args.seed)
        for threads in args.threads:
            by_name = tracers(scene, vertices, faces, threads, args.trimesh_rays)
            for set_name, (o, d, tf) in sets.items():
                occlusion = set_name == "shadow"
                rates = {}
                for name, (closest, occluded) in by_name.items():
                    f = occluded if occlusion else closest
                    if f is None:
                        continue
                    n = min(len(o), args.trimesh_rays) if name == "trimesh" else len(o)
                    runs = 1 if name == "trimesh" else args.runs
                    rates[name] = n / timed(lambda: f(o, d, tf), runs) / 1e6
                best_other = max((rates[k] for k in ("embreex", "embreex ids", "open3d") if k in rates), default=None)
                ratio = rates["raypack"] / best_other if best_other else None
                row = {"scene": path.name, "set": set_name, "image": [w, h], "rays": len(o), "threads": threads,
                       "query": "occluded" if occlusion else "intersect", "mrays_per_s": rates, "ratio_to_best": ratio}
                rows.append(row)
                cell = lambda k: f"{rates[k]:8.2f}" if k in rates else f"{'-':>8}"  # noqa: E731
                print(f"{path.name:<28} {set_name:<8} {len(o):>9} {threads:>3}  {cell('raypack')} {cell('embreex')} "
                      f"{cell('embreex ids')} {cell('open3d')} {cell('trimesh')}  {ratio if ratio is None else f'{ratio:5.2f}'}", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"machine": machine, "runs": args.runs, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
