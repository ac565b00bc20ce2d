#!/usr/bin/env python3
"""The race against Embree in rounds: `raypack bench SCENE --against embree` run several times
per ISA and scene, and the median over the rounds of each round's ratios, as the README's
speed tables give them.

    python3 tools/bench-embree.py --bin target/release/raypack --rounds 3 \\
        --scene cs184/meshedit/beetle.dae --scene models/stanford-dragon-871k.ply \\
        --isa avx2 avx512 --threads 1,2 --out /tmp/race
    python3 tools/bench-embree.py --summarize /tmp/race     # the tables again, from the reports

Scenes are paths under RAYPACK_SCENES (or absolute). Each run's JSON report is kept in `--out`
as `ISA-SCENE-ROUND.json`; the rounds go ISA by ISA and scene by scene, so that a slow minute
of a shared machine falls on one run of each, and each run times both tracers round-robin
(`raypack bench`'s own order). A ratio is always taken within one run, never across runs.

Per ISA, scene and thread count the table gives, as the median (lowest-highest) of the rounds:
the best raypack method over the best Embree call on camera, diffuse and shadow rays, each
tracer on its faster tree (each report's own summary, so a set whose hits disagree is left out
as the bench leaves it out); `Scene::intersect1` over `rtcIntersect1` on diffuse rays, each on
its faster tree (the issue's single-ray figure) and Medium over MEDIUM alone; and the build
line, raypack Medium's commit over Embree MEDIUM's. Both sides get the same choice of trees:
one raypack tree against the better of Embree's two would count Embree's luckier tree in
every round (the maximum of two noisy figures is biased upwards) and put the ratio a few
percent low.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

RAY_SETS = ("primary", "diffuse", "shadow")


def scene_path(scene):
    p = Path(scene)
    if p.is_absolute() or p.exists():
        return p
    root = os.environ.get("RAYPACK_SCENES")
    if not root:
        sys.exit(f"bench-embree: {scene} is relative and RAYPACK_SCENES is not set")
    return Path(root) / p


def label(path):
    return Path(path).stem


def quality_of(method):
    """`medium` from `Scene::intersect1 (medium)`; None when the method names no tree."""
    if method.endswith(")") and " (" in method:
        return method[method.rindex(" (") + 2 : -1]
    return None


def base_name(method):
    return method[: method.rindex(" (")] if quality_of(method) else method


def tree_quality(build):
    """`medium` from a raypack build's `bvh8 medium moller-trumbore` (or a bare `medium`); None
    when it names no build quality."""
    return next((w for w in build["quality"].split() if w in ("fast", "medium", "high")), None)


def round_ratios(report):
    """Per (threads, key) the ratio of one report, `key` being a ray set (the report's own
    summary: its best raypack method over its best Embree call, which the bench leaves out
    when their hits disagree), `single` (the single-ray calls on each tracer's faster tree),
    `single-medium` (Medium over MEDIUM) or `build` (raypack Medium's commit over Embree
    MEDIUM's, threads 0)."""
    out = {(s["threads"], s["rays"]): s["ratio"] for s in report.get("summary", []) if s["rays"] in RAY_SETS}
    builds = report.get("build", {}).values()
    raypack_builds = [b for b in builds if b["tracer"] == "raypack"]
    # With one raypack tree its methods carry no quality: the tree's build names it.
    only = tree_quality(raypack_builds[0]) if len(raypack_builds) == 1 else None
    for t in sorted({r["threads"] for r in report["results"]}):
        diffuse = [r for r in report["results"] if r["threads"] == t and r["rays"] == "diffuse"]
        single = {
            tracer: {quality_of(r["method"]) or only: r["mrays_per_s"] for r in diffuse if base_name(r["method"]) == name}
            for tracer, name in (("raypack", "Scene::intersect1"), ("embree", "rtcIntersect1"))
        }
        if single["raypack"] and single["embree"]:
            out[(t, "single")] = max(single["raypack"].values()) / max(single["embree"].values())
            if "medium" in single["raypack"] and "medium" in single["embree"]:
                out[(t, "single-medium")] = single["raypack"]["medium"] / single["embree"]["medium"]
    rp = [b["seconds"] for b in raypack_builds if tree_quality(b) == "medium"]
    em = [b["seconds"] for b in builds if b["tracer"] == "embree" and b["quality"] == "medium"]
    if rp and em:
        out[(0, "build")] = rp[0] / em[0]
    return out


def summarize(reports):
    """`{(isa, scene): {(threads, key): [ratio per round]}}` over `reports` (parsed JSON)."""
    table = {}
    for rep in reports:
        key = (rep["raypack"]["isa"], label(rep["scene"]))
        for k, v in round_ratios(rep).items():
            table.setdefault(key, {}).setdefault(k, []).append(v)
    return table


def cell(values):
    if not values:
        return "-"
    m = statistics.median(values)
    if len(values) == 1:
        return f"{m:.2f}"
    return f"{m:.2f} ({min(values):.2f}-{max(values):.2f})"


def markdown(table, scenes=None):
    lines = []
    tiers = ("sse", "avx2", "avx512")
    isas = sorted({isa for isa, _ in table}, key=lambda i: (tiers.index(i) if i in tiers else len(tiers), i))
    for isa in isas:
        names = [s for i, s in table if i == isa]
        if scenes:
            names = [s for s in scenes if s in names] + [s for s in names if s not in scenes]
        lines.append(f"**{isa}** (median of the rounds' ratios, lowest-highest; rounds: "
                     f"{max(len(v) for s in names for v in table[(isa, s)].values())})")
        lines.append("")
        lines.append("| scene | threads | camera | diffuse | shadow | diffuse, `Scene::intersect1` / `rtcIntersect1` "
                     "| the same, Medium / MEDIUM |")
        lines.append("|---|---|---|---|---|---|---|")
        for s in names:
            rows = table[(isa, s)]
            for t in sorted({t for t, _ in rows if t > 0}):
                c = [cell(rows.get((t, k), [])) for k in ("primary", "diffuse", "shadow", "single", "single-medium")]
                lines.append(f"| {s} | {t} | " + " | ".join(c) + " |")
        builds = [(s, table[(isa, s)].get((0, "build"), [])) for s in names]
        builds = [f"{s} {cell(v)}" for s, v in builds if v]
        if builds:
            lines.append("")
            lines.append("Build, raypack Medium over Embree MEDIUM (all threads): " + ", ".join(builds) + ".")
        lines.append("")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", default="target/release/raypack", help="raypack built with --features embree")
    ap.add_argument("--scene", action="append", default=[], help="a scene (repeat)")
    ap.add_argument("--isa", nargs="+", default=["avx2", "avx512"])
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--build-runs", type=int, default=3)
    ap.add_argument("--methods", help="passed to raypack bench --methods")
    ap.add_argument("--out", help="directory for the JSON reports (kept)")
    ap.add_argument("--summarize", metavar="DIR", help="only print the tables of the reports in DIR")
    a = ap.parse_args()

    if a.summarize:
        files = sorted(Path(a.summarize).glob("*.json"))
        if not files:
            sys.exit(f"bench-embree: no JSON reports in {a.summarize}")
        print(markdown(summarize(json.loads(f.read_text()) for f in files)))
        return
    if not a.scene or not a.out:
        sys.exit("bench-embree: give --scene (one or more) and --out, or --summarize DIR")
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    scenes = [scene_path(s) for s in a.scene]
    reports = []
    for r in range(1, a.rounds + 1):
        for isa in a.isa:
            for s in scenes:
                f = out / f"{isa}-{label(s)}-{r}.json"
                cmd = [a.bin, "bench", str(s), "--against", "embree", "--isa", isa, "--threads-list", a.threads,
                       "--runs", str(a.runs), "--build-runs", str(a.build_runs), "--json", str(f)]
                if a.methods:
                    cmd += ["--methods", a.methods]
                p = subprocess.run(cmd, capture_output=True, text=True)
                if p.returncode != 0:
                    sys.exit(f"bench-embree: {' '.join(cmd)} failed:\n{p.stderr}")
                reports.append(json.loads(f.read_text()))
                print(f"bench-embree: round {r} {isa} {label(s)} done", file=sys.stderr)
    print(markdown(summarize(reports), [label(s) for s in scenes]))


if __name__ == "__main__":
    main()
