#!/usr/bin/env python3
"""What splitting work over Dask costs, against one process on the same machine, same run.

    RAYPACK_SCENES=../shared/scenes python tools/bench-split.py [--rounds 3]

Needs the package (`pip install .`) with dask (`pip install pyraypack[dask]`). Starts a Dask
`LocalCluster` of 2 single-thread worker processes and measures, in interleaved rounds (one
process, then the cluster, round after round):

* render: CBbunny at 480x360, 64 spp, max depth 5: `pyraypack.render(path, threads=2)` against
  `pyraypack.dask.render(path, tiles=4)` on the cluster, both from the scene's path (load and
  BVH build included); samples per second;
* rays: 10M diffuse bounces on the 871k-triangle Stanford dragon (ten 1M-ray sets of
  `raypack bench`'s diffuse rays with different seeds) through `Scene.intersect(threads=2)`
  against `pyraypack.dask.intersect` in 1M-ray chunks: (a) numpy arrays in and out (rays
  scattered from this process, every output gathered back), (b) rays already on the workers
  and hits left there (persisted), the cluster's own throughput; Mrays/s;
* the bytes of the scene each worker receives (its pickle, sent once per worker).

Prints medians and ranges over the rounds and each round's ratio; the pixels and hits of the
two sides are checked equal first.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import pickle
import platform
import statistics
import time
import warnings

import numpy as np


def cpu() -> str:
    model, flags = platform.processor() or "?", set()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name") and model in ("?", ""):
                model = line.split(":", 1)[1].strip()
            if line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
                break
    except OSError:
        pass
    isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"
    return f"{model}, {os.cpu_count()} logical CPUs, best ISA {isa} (RAYPACK_ISA={os.environ.get('RAYPACK_ISA', 'unset')})"


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):.3f} ({min(values):.3f}-{max(values):.3f})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--scenes", default=os.environ.get("RAYPACK_SCENES"), help="the third-party scenes (RAYPACK_SCENES)")
    ap.add_argument("--rays-million", type=int, default=10)
    args = ap.parse_args()
    if not args.scenes:
        raise SystemExit("bench-split: set RAYPACK_SCENES (or --scenes) to the third-party scenes")
    import pyraypack
    import pyraypack.dask
    from dask.distributed import Client, LocalCluster, wait

    scenes = pathlib.Path(args.scenes)
    bunny = scenes / "cs184" / "sky" / "CBbunny.dae"
    dragon = scenes / "models" / "stanford-dragon-871k.ply"
    warnings.simplefilter("ignore", pyraypack.SceneWarning)
    print(f"machine: {cpu()}")
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    print(f"cluster: {len(client.nthreads())} workers x {set(client.nthreads().values())} thread(s)")

    # Render.
    w, h, spp = 480, 360, 64
    settings = dict(spp=spp, max_depth=5, light_samples=1, seed=0)
    samples = w * h * spp
    one, split, ratios = [], [], []
    for r in range(args.rounds):
        t = time.perf_counter()
        whole = pyraypack.render(bunny, width=w, height=h, threads=2, **settings)
        a = time.perf_counter() - t
        t = time.perf_counter()
        parts = pyraypack.dask.render(bunny, w, h, tiles=4, **settings)
        b = time.perf_counter() - t
        if r == 0:
            assert np.array_equal(whole, parts), "the split render differs from the whole one"
        one.append(samples / a / 1e6)
        split.append(samples / b / 1e6)
        ratios.append(a / b)
        print(f"  render round {r}: one process {a:.2f} s, 4 parts over the cluster {b:.2f} s, ratio {a / b:.3f}")
    print(f"render CBbunny {w}x{h} {spp} spp -m 5: one process (2 threads) {spread(one)} Msamples/s; "
          f"4 parts over 2x1-thread workers {spread(split)} Msamples/s; ratio {spread(ratios)}")

    # Rays.
    scene = pyraypack.load(dragon)
    sets = [pyraypack._raypack._ray_sets(scene, 2100, 2100, seed=s)["diffuse"] for s in range(args.rays_million)]
    n_each = min(len(s[0]) for s in sets)
    origins = np.concatenate([s[0][:n_each] for s in sets])
    directions = np.concatenate([s[1][:n_each] for s in sets])
    n = len(origins)
    size = len(pickle.dumps(scene))
    print(f"rays: {n / 1e6:.2f}M diffuse rays on the dragon ({n_each} per set); the scene's pickle is {size / 1e6:.1f} MB, "
          f"sent once to each of {len(client.nthreads())} workers")
    chunk = 1 << 20
    ref = scene.intersect(origins, directions, threads=2)
    hits = pyraypack.dask.intersect(scene, origins, directions, chunk_rays=chunk)
    got = client.compute(list(hits), sync=True)
    assert all(np.array_equal(x, y) for x, y in zip(got, ref)), "the chunked hits differ"
    # The rays on the workers, for (b).
    import dask.array as da

    # Origins and directions made together, each chunk's on one worker, as a graph that
    # generates rays there would leave them.
    on_workers = client.persist(da.from_array(np.concatenate([origins, directions], axis=1), chunks=(chunk, 6)))
    wait(on_workers)
    o_on, d_on = on_workers[:, :3], on_workers[:, 3:]
    one, inout, onw, r_inout, r_onw = [], [], [], [], []
    for r in range(args.rounds):
        t = time.perf_counter()
        scene.intersect(origins, directions, threads=2)
        a = time.perf_counter() - t
        t = time.perf_counter()
        client.compute(list(pyraypack.dask.intersect(scene, origins, directions, chunk_rays=chunk)), sync=True)
        b = time.perf_counter() - t
        t = time.perf_counter()
        kept = client.persist(list(pyraypack.dask.intersect(scene, o_on, d_on)))
        wait(kept)
        c = time.perf_counter() - t
        del kept
        one.append(n / a / 1e6)
        inout.append(n / b / 1e6)
        onw.append(n / c / 1e6)
        r_inout.append(a / b)
        r_onw.append(a / c)
        print(f"  rays round {r}: Scene.intersect {a:.3f} s, dask numpy in/out {b:.3f} s (ratio {a / b:.3f}), "
              f"dask on the workers {c:.3f} s (ratio {a / c:.3f})")
    print(f"rays: Scene.intersect (2 threads) {spread(one)} Mrays/s; pyraypack.dask.intersect in 1M-ray chunks: "
          f"numpy in and out {spread(inout)} Mrays/s (ratio {spread(r_inout)}), "
          f"rays and hits on the workers {spread(onw)} Mrays/s (ratio {spread(r_onw)})")
    client.close()
    cluster.close()


if __name__ == "__main__":
    main()
