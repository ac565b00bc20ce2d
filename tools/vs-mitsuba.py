#!/usr/bin/env python3
"""raypack against Mitsuba 3 (`llvm_ad_rgb`) on the same scenes: same camera, lights, materials,
path lengths and samples (issue 69). For each scene, tools/bin/mitsuba_scene.rs translates what
raypack's loader reads into a Mitsuba scene directory; then, per thread count, both renderers
render in turns (raypack, Mitsuba, raypack, ...), round i with seed i, and the script prints:

- the image means per channel of both and their difference (within 0.5 %: the check that the
  translation is exact), over all rounds' images of each renderer;
- the RMSE between the seed-0 and seed-1 images of each renderer (its noise, sqrt(2) sigma);
- samples per second of each (median, min-max) and the ratio of the medians.

raypack's figure is the one it prints (its own render clock); Mitsuba's is W*H*spp over the
`mi.render` call, timed after one warm-up render that compiles the kernels (its time is printed
too). Mitsuba's threads are Dr.Jit's pool: `drjit.set_thread_count(T)`, which counts the calling
thread (T - 1 workers; 1 runs everything on the calling thread).

`--isa avx2` runs both on AVX2 on an AVX-512 machine: raypack's kernels through `render --isa`,
Mitsuba's through Dr.Jit's LLVM target (`jit_llvm_set_target`: the host's CPU name, AVX2's
features without AVX-512's, 8 lanes), set before its first kernel is compiled.

The dragon scene (the Stanford dragon on a floor under one area light) is generated at run time
into the work directory from $RAYPACK_SCENES/models/stanford-dragon-871k.ply and CBbunny.dae.

Needs Mitsuba 3 and numpy in the Python that runs it, and the two binaries:
    cargo build --release --features cli,tools --bin raypack --bin mitsuba_scene
    RAYPACK_SCENES=/work/shared/scenes /tmp/venv-mitsuba/bin/python tools/vs-mitsuba.py --json vs-mitsuba.json
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = re.compile(r"([0-9.]+) million samples per second")
CS184 = {"CBbunny": "cs184/sky/CBbunny.dae", "CBspheres_lambertian": "cs184/sky/CBspheres_lambertian.dae"}
DRAGON_PLY = "models/stanford-dragon-871k.ply"
MEANS_TOLERANCE = 0.5  # per cent


def read_ascii_ply(path):
    """Vertices (n, 3) and triangles (m, 3) of an ASCII PLY holding only x y z and triangles."""
    text = Path(path).read_text()
    header, _, body = text.partition("end_header\n")
    counts = dict(re.findall(r"element (\w+) (\d+)", header))
    nv, nf = int(counts["vertex"]), int(counts["face"])
    if "format ascii" not in header or header.count("property float") != 3:
        sys.exit(f"vs-mitsuba: {path}: expected an ASCII PLY with x y z vertices only")
    values = np.array(body.split(), dtype=np.float64)
    verts = values[: 3 * nv].reshape(nv, 3)
    faces = values[3 * nv :].reshape(nf, 4)
    if not (faces[:, 0] == 3).all():
        sys.exit(f"vs-mitsuba: {path}: faces that are not triangles")
    return verts, faces[:, 1:].astype(np.int64)


def write_dragon_scene(scenes, out_dir):
    """CS184's CBbunny.dae with the dragon in place of the bunny and only the floor of the box:
    the dragon (1.5 units long, its feet on the floor) on a floor lit by CBbunny's one area light
    (and its emissive stand-in quad, which emits downwards only, as the light does), seen by
    CBbunny's camera. COLLADA, not OBJ: an OBJ's emissive quad is sampled as an area light too,
    but raypack's loaders add their default point light to any file without lights.
    """
    verts, tris = read_ascii_ply(Path(scenes) / DRAGON_PLY)
    lo, hi = verts.min(0), verts.max(0)
    centre = (lo + hi) / 2
    world = (verts - [centre[0], lo[1], centre[2]]) * (1.5 / (hi - lo)[0])  # y up, feet at y = 0
    zup = np.stack([world[:, 0], -world[:, 2], world[:, 1]], axis=1)  # the file is Z_UP: (x, y, z) -> (x, -z, y)
    positions = " ".join(f"{v:.7g}" for v in zup.ravel())
    geometry = (
        '<geometry id="Mesh-mesh" name="Mesh"><mesh><source id="Mesh-mesh-positions">'
        f'<float_array id="Mesh-mesh-positions-array" count="{zup.size}">{positions}</float_array>'
        f'<technique_common><accessor source="#Mesh-mesh-positions-array" count="{len(zup)}" stride="3">'
        '<param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>'
        '</accessor></technique_common></source><vertices id="Mesh-mesh-vertices">'
        '<input semantic="POSITION" source="#Mesh-mesh-positions"/></vertices>'
        f'<polylist material="Default-material" count="{len(tris)}">'
        '<input semantic="VERTEX" source="#Mesh-mesh-vertices" offset="0"/>'
        f'<vcount>{"3 " * len(tris)}</vcount><p>{" ".join(map(str, tris.ravel()))}</p></polylist></mesh></geometry>'
    )
    dae = (Path(scenes) / CS184["CBbunny"]).read_text()
    dae, n = re.subn(r'<geometry id="Mesh-mesh".*?</geometry>', lambda _: geometry, dae, flags=re.S)
    dae, m = re.subn(r'(<node id="Mesh".*?<matrix sid="transform">)[^<]*', r"\g<1>1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1", dae,
                     flags=re.S)
    dae, k = re.subn(r'<node id="(ceiling|leftWall|rightWall|backWall)".*?</node>', "", dae, flags=re.S)
    # The stand-in quad as large as the light (CBbunny's is the light turned by 90 degrees: Mitsuba,
    # which shows and samples one rectangle, would see a lamp of another shape).
    dae, q = re.subn(r'(<float_array id="light-mesh-positions-array" count="12">)[^<]*',
                     r"\g<1>0.3 1.49 -0.4 0.3 1.49 0.4 -0.3 1.49 0.4 -0.3 1.49 -0.4", dae)
    if (n, m, k, q) != (1, 1, 4, 1):
        sys.exit(f"vs-mitsuba: {CS184['CBbunny']} is not the CBbunny.dae the dragon scene is made from")
    (out_dir / "dragon.dae").write_text(dae)
    return out_dir / "dragon.dae"


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"vs-mitsuba: {' '.join(map(str, cmd))} failed:\n{p.stderr}")
    return p


def render_raypack(a, scene, threads, seed, out):
    cmd = [a.raypack, "render", scene, "-s", a.spp, "-m", a.depth, "-t", threads, "-r", *a.size]
    cmd += ["-f", out, "--seed", seed, "--bvh-cache", a.work / "bvh-cache"]
    cmd += ["--sampler", a.sampler] if a.sampler else []
    cmd += ["--isa", a.isa] if a.isa else []
    p = run([str(c) for c in cmd])
    m = SAMPLES.search(p.stderr)
    if not m:
        sys.exit(f"vs-mitsuba: no samples per second in raypack's output:\n{p.stderr}")
    return float(m.group(1)) * 1e6


def read_exr(mi, dr, path):
    """raypack's EXR image as an (H, W, 3) array. Mitsuba reads it, with Dr.Jit's pool at 2
    threads or more: with 1 thread, Mitsuba 3.9's EXR reader never returns."""
    threads = dr.thread_count()
    dr.set_thread_count(max(threads, 2))
    img = np.array(mi.Bitmap(str(path)), dtype=np.float64)[..., :3]
    dr.set_thread_count(threads)
    return img


# Dr.Jit's LLVM target for `--isa avx2`: what an AVX2 CPU of the Zen 3 or Haswell kind has.
AVX2_FEATURES = b"+sse4.2,+popcnt,+avx,+avx2,+fma,+f16c,+bmi,+bmi2,+lzcnt,+movbe,-avx512f"


def set_mitsuba_isa(dr, isa):
    """Makes Dr.Jit's LLVM backend compile for `isa` ('avx2': AVX2 features, 8 lanes) and
    returns (target CPU, vector width) as it then reports them. The setter is Dr.Jit's C++
    function `jit_llvm_set_target(cpu, features, width)` in libdrjit-core (no Python binding)."""
    import ctypes

    try:
        lib = ctypes.CDLL(str(Path(dr.__file__).parent / "libdrjit-core.so"))
        cpu = lib._Z19jit_llvm_target_cpuv
        width = lib._Z21jit_llvm_vector_widthv
        set_target = lib._Z19jit_llvm_set_targetPKcS0_j
    except (OSError, AttributeError) as e:
        if isa:
            sys.exit(f"vs-mitsuba: --isa {isa}: this Dr.Jit ({dr.__version__}) has no jit_llvm_set_target to call: {e}")
        return "unknown", 0
    cpu.restype = ctypes.c_char_p
    width.restype = ctypes.c_uint32
    if isa == "avx2":
        set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
        set_target(cpu(), AVX2_FEATURES, 8)
    return cpu().decode(), int(width())


def stats(values):
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "all": values}


def compare(a, mi, dr, name, scene_file):
    """Translates `scene_file`, renders it with both at each thread count, returns the results."""
    mi_dir = a.work / f"mitsuba-{name}"
    cmd = [a.translator, scene_file, mi_dir, "-r", *a.size, "-s", a.spp, "-m", a.depth]
    translated = run([str(c) for c in cmd])
    for line in translated.stderr.splitlines():
        print(f"  translator: {line}", file=sys.stderr)
    t = time.perf_counter()
    mi_scene = mi.load_file(str(mi_dir / "scene.xml"))
    load_s = time.perf_counter() - t
    w, h = a.size
    samples = w * h * a.spp
    results = []
    for threads in a.threads:
        dr.set_thread_count(threads)

        def render_mitsuba(seed):
            t = time.perf_counter()
            img = mi.render(mi_scene, seed=seed, spp=a.spp)
            dr.eval(img)
            dr.sync_thread()
            secs = time.perf_counter() - t
            return np.array(img, dtype=np.float64), secs

        _, warmup_s = render_mitsuba(0)
        rp_sps, mi_sps, rp_img, mi_img = [], [], [], []
        for r in range(a.rounds):
            exr = a.work / f"raypack-{name}-{threads}-{r}.exr"
            rp_sps.append(render_raypack(a, scene_file, threads, r, exr))
            rp_img.append(read_exr(mi, dr, exr))
            img, secs = render_mitsuba(r)
            mi_sps.append(samples / secs)
            mi_img.append(img)
            print(f"  {name} t={threads} round {r}: raypack {rp_sps[-1] / 1e6:.3f}, "
                  f"mitsuba {mi_sps[-1] / 1e6:.3f} Msamples/s", file=sys.stderr)
        rp_mean = np.mean([i.reshape(-1, 3).mean(0) for i in rp_img], axis=0)
        mi_mean = np.mean([i.reshape(-1, 3).mean(0) for i in mi_img], axis=0)
        diff = (mi_mean - rp_mean) / rp_mean * 100
        rmse = lambda imgs: float(np.sqrt(np.mean((imgs[0] - imgs[1]) ** 2)))
        results.append({
            "scene": name, "threads": threads, "width": w, "height": h, "spp": a.spp, "max_depth": a.depth,
            "raypack_sampler": a.sampler or "default", "isa": a.isa or "native",
            "mitsuba_target": a.mitsuba_target,
            "raypack_mean_rgb": rp_mean.tolist(), "mitsuba_mean_rgb": mi_mean.tolist(),
            "mean_difference_percent": diff.tolist(), "means_agree": bool(np.abs(diff).max() <= MEANS_TOLERANCE),
            "raypack_rmse_seeds": rmse(rp_img), "mitsuba_rmse_seeds": rmse(mi_img),
            "raypack_samples_per_s": stats(rp_sps), "mitsuba_samples_per_s": stats(mi_sps),
            "ratio": statistics.median(rp_sps) / statistics.median(mi_sps),
            "mitsuba_warmup_s": warmup_s, "mitsuba_load_s": load_s, "load_average_after": os.getloadavg(),
        })
    return results


def table(r):
    m = lambda s: f"{s['median'] / 1e6:.3f} ({s['min'] / 1e6:.3f}-{s['max'] / 1e6:.3f})"
    rgb = lambda v, fmt: " / ".join(fmt.format(x) for x in v)
    rows = [
        ("image mean R/G/B", rgb(r["raypack_mean_rgb"], "{:.5f}"), rgb(r["mitsuba_mean_rgb"], "{:.5f}")),
        ("mean difference (Mitsuba - raypack)", "", rgb(r["mean_difference_percent"], "{:+.3f} %")
         + (" ok" if r["means_agree"] else f" DIFFER (> {MEANS_TOLERANCE} %)")),
        ("RMSE between seeds 0 and 1", f"{r['raypack_rmse_seeds']:.5f}", f"{r['mitsuba_rmse_seeds']:.5f}"),
        ("Msamples/s, median (min-max)", m(r["raypack_samples_per_s"]), m(r["mitsuba_samples_per_s"])),
        ("raypack / Mitsuba", f"**{r['ratio']:.2f}x**", f"warm-up render {r['mitsuba_warmup_s']:.2f} s"),
    ]
    head = (f"### {r['scene']}, {r['threads']} thread{'s' if r['threads'] > 1 else ''} "
            f"({r['width']}x{r['height']}, {r['spp']} spp, -m {r['max_depth']}, "
            f"{len(r['raypack_samples_per_s']['all'])} rounds, ISA {r['isa']}; Mitsuba's target {r['mitsuba_target']})"
            "\n\n| | raypack | Mitsuba 3 llvm_ad_rgb |\n|---|---|---|\n")
    return head + "\n".join(f"| {a} | {b} | {c} |" for a, b, c in rows) + "\n"


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", nargs="+", default=["CBbunny", "CBspheres_lambertian", "dragon"],
                   help="CBbunny, CBspheres_lambertian, dragon, or a path to a scene file raypack reads")
    p.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    p.add_argument("--rounds", type=int, default=3, help="renders of each renderer, turn by turn (at least 2)")
    p.add_argument("-r", "--size", nargs=2, type=int, default=[480, 360], metavar=("W", "H"))
    p.add_argument("-s", "--spp", type=int, default=64)
    p.add_argument("-m", "--depth", type=int, default=5, help="raypack's -m (Mitsuba's max_depth is one more)")
    p.add_argument("--sampler", choices=["sobol", "independent"],
                   help="raypack's --sampler (default: raypack's own, Sobol'); Mitsuba's is always independent")
    p.add_argument("--isa", choices=["avx2"],
                   help="run both renderers on AVX2 (on an AVX-512 machine); default: each on the CPU's best")
    p.add_argument("--raypack", default=str(ROOT / "target/release/raypack"))
    p.add_argument("--translator", default=str(ROOT / "target/release/mitsuba_scene"))
    p.add_argument("--work", type=Path, help="keep the scenes and images here (default: a temporary directory)")
    p.add_argument("--json", type=Path, help="write the results here as JSON")
    a = p.parse_args()
    if a.rounds < 2:
        p.error("--rounds: at least 2 (the RMSE compares the seed-0 and seed-1 images)")
    for tool in (a.raypack, a.translator):
        if not os.access(tool, os.X_OK):
            p.error(f"{tool} not found: cargo build --release --features cli,tools --bin raypack --bin mitsuba_scene")
    scenes = os.environ.get("RAYPACK_SCENES")
    if not scenes and any(s in CS184 or s == "dragon" for s in a.scenes):
        p.error("set RAYPACK_SCENES (the directory tools/fetch-scenes fills)")
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    cpu, width = set_mitsuba_isa(dr, a.isa)
    a.mitsuba_target = f"{cpu}, {width} lanes"
    print(f"vs-mitsuba: Mitsuba's LLVM target {a.mitsuba_target}; raypack --isa {a.isa or 'native'}", file=sys.stderr)
    tmp = None if a.work else tempfile.TemporaryDirectory(prefix="vs-mitsuba-")
    a.work = a.work or Path(tmp.name)
    a.work.mkdir(parents=True, exist_ok=True)
    results = []
    for name in a.scenes:
        if name == "dragon":
            scene_file = write_dragon_scene(scenes, a.work)
        elif name in CS184:
            scene_file = Path(scenes) / CS184[name]
        else:
            scene_file, name = Path(name), Path(name).stem
        for r in compare(a, mi, dr, name, scene_file):
            print(table(r), flush=True)
            results.append(r)
    if a.json:
        a.json.write_text(json.dumps({"mitsuba": mi.__version__, "drjit": dr.__version__, "results": results}, indent=1))
    return 0 if all(r["means_agree"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
