"""Tests of tools/bench-embree.py's summary, on made-up `raypack bench --json` reports (no
raypack or Embree run).

    python3 -m unittest discover -s tools -p 'test_*.py'
"""

import importlib.util
import statistics
import unittest
from pathlib import Path

_spec = importlib.util.spec_from_file_location("bench_embree", Path(__file__).resolve().parent / "bench-embree.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def result(tracer, method, rays, threads, mrays):
    return {"tracer": tracer, "method": method, "rays": rays, "threads": threads, "mrays_per_s": mrays}


def report(isa, scene, rp_medium, rp_high, em_medium, em_high, threads=1, build=(0.2, 0.25)):
    """A report whose diffuse single-ray figures are the four given; the packets are slower,
    and a reference row is fastest of all (it must not count). Its summary pairs camera rays
    only (as the bench does when Embree's hits on the other sets disagree)."""
    rows = [
        result("raypack", "Scene::intersect1 (medium)", "diffuse", threads, rp_medium),
        result("raypack", "Scene::intersect1 (high)", "diffuse", threads, rp_high),
        result("raypack", "Scene::intersect8 (medium)", "diffuse", threads, 0.5),
        result("raypack", "bvh2 reference intersect1 (medium)", "diffuse", threads, 99.0),
        result("embree", "rtcIntersect1 (medium)", "diffuse", threads, em_medium),
        result("embree", "rtcIntersect1 (high)", "diffuse", threads, em_high),
        result("embree", "rtcIntersect8 (medium)", "diffuse", threads, 0.5),
        result("raypack", "Scene::intersect_stream (medium)", "primary", threads, 30.0),
        result("embree", "rtcIntersect16 (high)", "primary", threads, 20.0),
    ]
    builds = {
        "raypack bvh8 medium moller-trumbore": {"tracer": "raypack", "quality": "bvh8 medium moller-trumbore", "seconds": build[0]},
        "raypack bvh8 high moller-trumbore": {"tracer": "raypack", "quality": "bvh8 high moller-trumbore", "seconds": 9.0},
        "embree medium": {"tracer": "embree", "quality": "medium", "seconds": build[1]},
        "embree high": {"tracer": "embree", "quality": "high", "seconds": 0.01},
    }
    summary = [{"rays": "primary", "threads": threads, "ratio": 1.4}]
    return {"raypack": {"isa": isa}, "scene": f"/scenes/{scene}.ply", "results": rows, "build": builds, "summary": summary}


class Summary(unittest.TestCase):
    def test_single_rays_take_each_tracers_faster_tree(self):
        r = bench.round_ratios(report("avx2", "dragon", 3.0, 2.8, 2.5, 2.7))
        self.assertAlmostEqual(r[(1, "single")], 3.0 / 2.7)
        self.assertAlmostEqual(r[(1, "single-medium")], 3.0 / 2.5)
        # The ray sets' ratios are the report's own summary: pairs it left out stay out.
        self.assertEqual(r[(1, "primary")], 1.4)
        self.assertNotIn((1, "diffuse"), r)
        self.assertNotIn((1, "shadow"), r)
        # raypack Medium's build over Embree MEDIUM's, whatever the other trees took.
        self.assertAlmostEqual(r[(0, "build")], 0.2 / 0.25)

    def test_one_raypack_tree_is_its_own_best(self):
        rep = report("avx2", "beetle", 3.0, 2.8, 2.5, 2.7)
        rep["results"] = [x for x in rep["results"] if "(high)" not in x["method"] or x["tracer"] == "embree"]
        del rep["build"]["raypack bvh8 high moller-trumbore"]
        for x in rep["results"]:
            if x["method"] == "Scene::intersect1 (medium)":
                x["method"] = "Scene::intersect1"
        r = bench.round_ratios(rep)
        self.assertAlmostEqual(r[(1, "single")], 3.0 / 2.7)
        self.assertAlmostEqual(r[(1, "single-medium")], 3.0 / 2.5)
        # A lone High tree is not compared with MEDIUM.
        rep["build"]["raypack bvh8 medium moller-trumbore"]["quality"] = "bvh8 high moller-trumbore"
        r = bench.round_ratios(rep)
        self.assertAlmostEqual(r[(1, "single")], 3.0 / 2.7)
        self.assertNotIn((1, "single-medium"), r)
        self.assertNotIn((0, "build"), r)

    def test_rounds_give_the_median_of_their_ratios(self):
        figures = [(3.0, 2.9, 2.5, 2.6), (2.2, 2.3, 2.4, 2.0), (3.3, 3.1, 2.9, 3.0)]
        reps = [report("avx2", "knot", *f) for f in figures] + [report("avx512", "knot", 4.0, 4.0, 2.0, 2.0)]
        table = bench.summarize(reps)
        ratios = table[("avx2", "knot")][(1, "single")]
        self.assertEqual(len(ratios), 3)
        want = statistics.median(max(a, b) / max(c, d) for a, b, c, d in figures)
        self.assertAlmostEqual(statistics.median(ratios), want)
        self.assertEqual(table[("avx512", "knot")][(1, "single")], [2.0])
        text = bench.markdown(table)
        single = bench.cell(ratios)
        self.assertIn(f"| knot | 1 | 1.40 (1.40-1.40) | - | - | {single} |", text)
        self.assertLess(text.index("**avx2**"), text.index("**avx512**"))
        self.assertIn("Build, raypack Medium over Embree MEDIUM (all threads): knot 0.80 (0.80-0.80).", text)

    def test_cells_without_figures_are_dashes(self):
        self.assertEqual(bench.cell([]), "-")
        self.assertEqual(bench.cell([1.234]), "1.23")


if __name__ == "__main__":
    unittest.main()
