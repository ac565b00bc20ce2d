#!/usr/bin/env python3
"""The renderer's benchmark: samples per second (and rays per second by kind, thread time by
phase) of one or more `raypack` binaries on the same renders, run interleaved.

    python3 tools/bench-render.py --bin before=/path/raypack-old --bin after=target/release/raypack \\
        --scene cs184/sky/CBbunny.dae --scene models/stanford-dragon-871k.ply \\
        --depth 1 5 --threads 1 2 --isa avx512 avx2 --rounds 3 --spp 64 --json out.json

A `--bin` may carry render flags of its own (`--bin "octant=raypack --bounce-order octant"`).
Scenes are paths under RAYPACK_SCENES (or absolute). Every configuration (scene, -m, -t, ISA)
is run `--rounds` times per binary, the binaries in turn, and the median (with min and max)
of the samples per second the render reports is printed as a Markdown table with the ratio of
each binary to the first. Run it under `flock -x /work/.cpu.lock` on a shared machine. The BVH
is cached (`--bvh-cache`), so the loads do not count; the render's own clock is used.
"""

import argparse
import json
import os
import re
import shlex
import statistics
import subprocess
import sys
import tempfile

SAMPLES = re.compile(r"([0-9.]+) million samples per second")
RAYS = re.compile(r"\]\s+(camera|shadow|bounce)\s+(\d+) rays,\s+([0-9.]+) Mrays/s")
PHASES = re.compile(r"Thread time by phase: (.*)\.$", re.M)
PHASE = re.compile(r"([a-z ]+) ([0-9.]+)s \(([0-9.]+)%\)")


def run(command, scene, depth, threads, isa, spp, size, cache, out, extra):
    cmd = [command[0], "render", scene, "-s", str(spp), "-m", str(depth), "-t", str(threads)]
    cmd += ["-r", str(size[0]), str(size[1]), "-f", out, "--bvh-cache", cache, "--isa", isa] + command[1:] + extra
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"bench-render: {' '.join(cmd)} failed:\n{p.stderr}")
    m = SAMPLES.search(p.stderr)
    if not m:
        sys.exit(f"bench-render: no samples per second in the output of {' '.join(cmd)}:\n{p.stderr}")
    result = {"samples_per_s": float(m.group(1)) * 1e6}
    result["rays"] = {k: {"rays": int(n), "mrays_per_s": float(r)} for k, n, r in RAYS.findall(p.stderr)}
    ph = PHASES.search(p.stderr)
    if ph:
        result["phases"] = {name.strip(): {"s": float(s), "pct": float(pct)} for name, s, pct in PHASE.findall(ph.group(1))}
    return result


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", action="append", required=True, metavar="LABEL=PATH [FLAGS]",
                    help="a binary to time, with render flags of its own")
    ap.add_argument("--scene", action="append", required=True)
    ap.add_argument("--depth", type=int, nargs="+", default=[1, 5])
    ap.add_argument("--threads", type=int, nargs="+", default=[1])
    ap.add_argument("--isa", nargs="+", default=["avx512"])
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--size", type=int, nargs=2, default=[480, 360])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", help="write every run here")
    ap.add_argument("extra", nargs="*", help="more render flags (after --)")
    a = ap.parse_args()
    bins = [(label, shlex.split(cmd)) for label, cmd in (b.split("=", 1) for b in a.bin)]
    root = os.environ.get("RAYPACK_SCENES", "")
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        cache, out = os.path.join(tmp, "cache"), os.path.join(tmp, "out.png")
        os.mkdir(cache)
        print("| scene | `-m` | threads | ISA | " + " | ".join(f"{l} (M samples/s)" for l, _ in bins)
              + "".join(f" | {l} / {bins[0][0]}" for l, _ in bins[1:]) + " |")
        print("|---|---|---|---|" + "---|" * (2 * len(bins) - 1))
        for scene in a.scene:
            path = scene if os.path.isabs(scene) else os.path.join(root, scene)
            for depth in a.depth:
                for threads in a.threads:
                    for isa in a.isa:
                        got = {l: [] for l, _ in bins}
                        for _ in range(a.rounds):
                            for label, binary in bins:
                                r = run(binary, path, depth, threads, isa, a.spp, a.size, cache, out, a.extra)
                                got[label].append(r)
                                runs.append({"scene": scene, "depth": depth, "threads": threads, "isa": isa,
                                             "bin": label, **r})
                        med = {l: statistics.median(x["samples_per_s"] for x in v) / 1e6 for l, v in got.items()}
                        cells = []
                        for l, v in got.items():
                            xs = sorted(x["samples_per_s"] / 1e6 for x in v)
                            cells.append(f"{med[l]:.2f} [{xs[0]:.2f}, {xs[-1]:.2f}]")
                        ratios = [f"{med[l] / med[bins[0][0]]:.2f}x" for l, _ in bins[1:]]
                        name = os.path.basename(scene)
                        print(f"| {name} | {depth} | {threads} | {isa} | " + " | ".join(cells + ratios) + " |",
                              flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(runs, f, indent=1)


if __name__ == "__main__":
    main()
