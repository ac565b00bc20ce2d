#!/usr/bin/env python3
"""raypack's trimesh adapter against trimesh's own embree intersector (embreex), on trimesh's
README example (two rays at an icosphere: time per call, mostly call overhead) and on 1M rays
along +z through the Stanford dragon (median of 5 runs; 3 for multiple hits).

    RAYPACK_SCENES=../shared/scenes python tools/bench-trimesh.py

Needs trimesh and embreex beside raypack (pip install trimesh embreex).
"""

import os
import time

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector as EmbreeIntersector

import pyraypack.trimesh


def per_call(f, n):
    f()
    t = time.perf_counter()
    for _ in range(n):
        f()
    return (time.perf_counter() - t) / n


def median_time(f, runs=5):
    f()
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return sorted(ts)[len(ts) // 2]


def main():
    mesh = trimesh.creation.icosphere()
    o, d = [[0, 0, -5], [2, 2, -10]], [[0, 0, 1], [0, 0, 1]]
    for name, rmi in [("raypack", pyraypack.trimesh.RayMeshIntersector(mesh)), ("trimesh embree", EmbreeIntersector(mesh))]:
        mesh.ray = rmi
        loc, ir, _ = mesh.ray.intersects_location(ray_origins=o, ray_directions=d)
        us = per_call(lambda: mesh.ray.intersects_location(ray_origins=o, ray_directions=d), 2000) * 1e6
        print(f"{name:15s} icosphere example: locations {np.round(loc, 6).tolist()} index_ray {ir.tolist()}, {us:.0f} us per call")
    dragon = trimesh.load(os.environ["RAYPACK_SCENES"] + "/models/stanford-dragon-871k.ply")
    b = dragon.bounds
    rng = np.random.default_rng(1)
    n = 1_000_000
    org = np.column_stack([rng.uniform(b[0, 0], b[1, 0], n), rng.uniform(b[0, 1], b[1, 1], n), np.full(n, b[0, 2] - 1)])
    dirs = np.tile([0.0, 0.0, 1.0], (n, 1))
    for name, rmi in [("raypack", pyraypack.trimesh.RayMeshIntersector(dragon)), ("trimesh embree", EmbreeIntersector(dragon))]:
        first = median_time(lambda: rmi.intersects_first(org, dirs))
        loc = median_time(lambda: rmi.intersects_location(org, dirs, multiple_hits=False))
        multi = median_time(lambda: rmi.intersects_id(org, dirs, multiple_hits=True), runs=3)
        print(
            f"{name:15s} dragon, 1M rays along +z: intersects_first {first:.3f} s, "
            f"intersects_location {loc:.3f} s, intersects_id(multiple_hits=True) {multi:.3f} s"
        )


if __name__ == "__main__":
    main()
