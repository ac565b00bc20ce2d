"""Tests of tools/bin/mitsuba_scene.rs (raypack scene -> Mitsuba 3 scene), without Mitsuba: the
written scene.xml is parsed back and its sensor, integrator, emitters and BSDFs checked against
what raypack loads (closed forms for the synthesized camera and light).

    python3 -m unittest discover -s tools -p 'test_*.py'
"""

import math
import os
import struct
import subprocess
import tempfile
import unittest
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CARGO = ["cargo", "run", "--quiet", "--release", "--features", "tools", "--bin", "mitsuba_scene", "--"]


def translate(*args):
    return subprocess.run(CARGO + [str(a) for a in args], cwd=ROOT, capture_output=True, text=True)


def floats(text):
    return [float(v) for v in text.replace(",", " ").split()]


def value(el, tag, name):
    return el.find(f"{tag}[@name='{name}']").get("value")


def ply_header(path):
    head = path.read_bytes().split(b"end_header\n")[0].decode()
    counts = {w[1]: int(w[2]) for w in (line.split() for line in head.splitlines()) if w[0] == "element"}
    return counts, "property float nx" in head


# A floor (two triangles, Kd 0.25 0.5 0.75) and an emissive triangle above it; no camera, no lights.
OBJ = """mtllib s.mtl
o floor
usemtl floor
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
f 1 2 3 4
o lamp
usemtl lamp
v -0.2 1 -0.2
v 0.2 1 -0.2
v 0 1 0.2
f 5 6 7
"""
MTL = "newmtl floor\nKd 0.25 0.5 0.75\nnewmtl lamp\nKd 0 0 0\nKe 2 3 4\n"


class Translator(unittest.TestCase):
    def setUp(self):
        tmp = tempfile.TemporaryDirectory()
        self.addCleanup(tmp.cleanup)
        self.dir = Path(tmp.name)

    def test_obj_scene(self):
        (self.dir / "s.obj").write_text(OBJ)
        (self.dir / "s.mtl").write_text(MTL)
        out = self.dir / "mi"
        p = translate(self.dir / "s.obj", out, "-r", 64, 48, "-s", 8, "-m", 5)
        self.assertEqual(p.returncode, 0, p.stderr)
        self.assertIn("emit on both sides", p.stderr)
        root = ET.parse(out / "scene.xml").getroot()
        integ = root.find("integrator")
        self.assertEqual(integ.get("type"), "path")
        self.assertEqual(value(integ, "integer", "max_depth"), "6", "raypack's -m 5 counts 6 path segments")
        sensor = root.find("sensor")
        self.assertEqual(value(sensor, "string", "fov_axis"), "y")
        self.assertAlmostEqual(float(value(sensor, "float", "fov")), 35.0, places=4)  # Camera::framing
        film = sensor.find("film")
        self.assertEqual((value(film, "integer", "width"), value(film, "integer", "height")), ("64", "48"))
        self.assertEqual(film.find("rfilter").get("type"), "box")
        self.assertEqual(value(sensor.find("sampler"), "integer", "sample_count"), "8")
        # The framing camera looks at the bounds' centre, (0, 0.5, 0): Mitsuba's +z column.
        m = floats(sensor.find("transform/matrix").get("value"))
        fwd, eye = [m[2], m[6], m[10]], [m[3], m[7], m[11]]
        to_centre = [c - e for c, e in zip([0, 0.5, 0], eye)]
        n = math.sqrt(sum(v * v for v in to_centre))
        self.assertAlmostEqual(sum(f * t / n for f, t in zip(fwd, to_centre)), 1.0, places=5)
        # No lights in the file: raypack's default rig, one point light of intensity pi d^2 at
        # d = 3 bounding radii from the centre (radius = half the diagonal of 2 x 1 x 2).
        points = root.findall("emitter[@type='point']")
        self.assertEqual(len(points), 1)
        d = 3 * 0.5 * math.sqrt(4 + 1 + 4)
        for v in floats(value(points[0], "rgb", "intensity")):
            self.assertAlmostEqual(v, math.pi * d * d, delta=1e-4 * v)
        pos = points[0].find("point[@name='position']")
        dist = math.dist([float(pos.get(k)) for k in "xyz"], [0, 0.5, 0])
        self.assertAlmostEqual(dist, d, delta=1e-4 * d)
        shapes = root.findall("shape[@type='ply']")
        self.assertEqual(len(shapes), 2, "one PLY per material")
        floor, lamp = sorted(shapes, key=lambda s: s.find("emitter") is not None)
        self.assertEqual(floor.find("bsdf").get("type"), "twosided")
        self.assertEqual(floats(value(floor.find("bsdf/bsdf"), "rgb", "reflectance")), [0.25, 0.5, 0.75])
        self.assertIsNone(floor.find("emitter"))
        self.assertEqual(floats(value(lamp.find("emitter[@type='area']"), "rgb", "radiance")), [2, 3, 4])
        floor_ply, lamp_ply = (out / value(s, "string", "filename") for s in (floor, lamp))
        self.assertEqual(ply_header(floor_ply), ({"vertex": 4, "face": 2}, True))
        self.assertEqual(ply_header(lamp_ply), ({"vertex": 3, "face": 1}, False), "emitters: face normals")
        self.assertEqual(value(lamp, "boolean", "face_normals"), "true")
        # The lamp's winding is kept: its face normal points down, as the OBJ gives it.
        data = lamp_ply.read_bytes().split(b"end_header\n")[1]
        a, b, c = (struct.unpack_from("<3f", data, 12 * i) for i in range(3))
        u, v = [b[i] - a[i] for i in range(3)], [c[i] - a[i] for i in range(3)]
        self.assertLess(u[2] * v[0] - u[0] * v[2], 0.0)

    def test_built_in_box_names_what_is_not_translated(self):
        p = translate("--default", self.dir / "mi", "-r", 64, 48, "-s", 8, "-m", 5)
        self.assertEqual(p.returncode, 2)
        self.assertIn('material "mirror"', p.stderr)
        self.assertIn("not translated", p.stderr)

    def test_usage_errors(self):
        p = translate(self.dir / "x.obj", self.dir / "mi", "-s", 8, "-m", 5)
        self.assertEqual(p.returncode, 2)
        self.assertIn("-r W H, -s SPP and -m DEPTH are required", p.stderr)
        p = translate(self.dir / "missing.obj", self.dir / "mi", "-r", 8, 8, "-s", 8, "-m", 5)
        self.assertEqual(p.returncode, 2)
        self.assertIn("missing.obj", p.stderr)

    @unittest.skipUnless(os.environ.get("RAYPACK_SCENES"), "RAYPACK_SCENES is not set: CS184's scenes SKIPPED")
    def test_cs184_area_light_is_one_rectangle(self):
        scene = Path(os.environ["RAYPACK_SCENES"]) / "cs184/sky/CBspheres_lambertian.dae"
        p = translate(scene, self.dir / "mi", "-r", 48, 36, "-s", 4, "-m", 1)
        self.assertEqual(p.returncode, 0, p.stderr)
        root = ET.parse(self.dir / "mi/scene.xml").getroot()
        self.assertEqual(value(root.find("integrator"), "integer", "max_depth"), "2")
        rects = root.findall("shape[@type='rectangle']")
        self.assertEqual(len(rects), 1)
        self.assertEqual(floats(value(rects[0].find("emitter"), "rgb", "radiance")), [10, 10, 10])
        m = floats(rects[0].find("transform/matrix").get("value"))
        # 0.6 x 0.8 at height 1.49, facing down (the rectangle faces its local +z column).
        self.assertEqual(sorted([abs(m[0]), abs(m[1]), abs(m[8]), abs(m[9])]), [0, 0, 0.3, 0.4])
        self.assertEqual(([m[2], m[6], m[10]], m[7]), ([0, -1, 0], 1.49))
        self.assertEqual(len(root.findall(".//emitter")), 1, "the stand-in quad is not a second emitter")
        spheres = root.findall("shape[@type='sphere']")
        self.assertEqual([float(value(s, "float", "radius")) for s in spheres], [0.3, 0.3])


if __name__ == "__main__":
    unittest.main()
