#!/usr/bin/python3
"""Tests USD import: yscene convert GROOM.usda OUT.json through
scripts/usd_to_yocto.py and Pixar's usd-core. Hand-written stages (made here
from text) for each basis, wrap and width interpolation, a transformed, an
instanced and a point-instanced groom: the converted Bezier control points
and radii equal the ones computed here, segment by segment, from the
schema's definitions (within 1e-5), and the segment counts equal usd-core's
ComputeSegmentCounts. Malformed stages fail with one line naming the prim,
a non-zero exit and no output. A converted groom renders to a finite image.

Usage: python3 tests/test_usd.py YSCENE_PATH [unittest options]

Runs itself under .venv/usd/bin/python (bash scripts/setup.sh --usd, which
scripts/test.sh runs); without it, prints why it is skipped and exits 77.
"""

import json
import math
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import unittest

import venv_main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
YSCENE = None  # set from the command line
TOLERANCE = 1e-5


def read_ply(filename):
    """Vertex columns by name and the list element (name, rows) of a binary
    little-endian PLY as yscene writes it."""
    with open(filename, "rb") as file:
        data = file.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").split("\n")
    assert header[1] == "format binary_little_endian 1.0", header[1]
    elements, current = [], None
    for line in header:
        words = line.split()
        if words and words[0] == "element":
            current = [words[1], int(words[2]), []]
            elements.append(current)
        elif words and words[0] == "property":
            current[2].append(words[1:])
    offset, vertices, lists = end, {}, None
    for name, count, properties in elements:
        if name == "vertex":
            assert all(p[0] == "float" for p in properties), properties
            size = len(properties)
            values = struct.unpack_from(f"<{count * size}f", data, offset)
            offset += 4 * count * size
            for k, p in enumerate(properties):
                vertices[p[1]] = values[k::size]
        else:
            rows = []
            for _ in range(count):
                n = data[offset]
                rows.append(struct.unpack_from(f"<{n}i", data, offset + 1))
                offset += 1 + 4 * n
            lists = (name, rows)
    return vertices, lists


def read_pfm(filename):
    with open(filename, "rb") as file:
        kind = file.readline().strip()
        width, height = map(int, file.readline().split())
        scale = float(file.readline())
        channels = 3 if kind == b"PF" else 1
        fmt = "<" if scale < 0 else ">"
        values = struct.unpack(f"{fmt}{width * height * channels}f", file.read())
    return width, height, values


def vec(a, b, s=1.0):
    return [a[i] + s * b[i] for i in range(3)]


def combo(weights, points):
    return [sum(w * p[i] for w, p in zip(weights, points)) for i in range(3)]


def bezier_of(basis, p0, p1, p2, p3):
    """The Bezier control points of one segment, from the standard basis
    functions (bspline: uniform cubic B-spline; catmullRom: tension 1/2)."""
    if basis == "bezier":
        return [p0, p1, p2, p3]
    if basis == "bspline":
        return [combo([1 / 6, 4 / 6, 1 / 6], [p0, p1, p2]), combo([4 / 6, 2 / 6], [p1, p2]),
                combo([2 / 6, 4 / 6], [p1, p2]), combo([1 / 6, 4 / 6, 1 / 6], [p1, p2, p3])]
    # catmullRom: tangent at p1 is (p2 - p0) / 2, a third of it to the handle.
    return [p1, vec(p1, vec(p2, p0, -1), 1 / 6), vec(p2, vec(p3, p1, -1), -1 / 6), p2]


def schema_segments(basis, wrap, points):
    """The four control points of each segment of one curve, per the
    UsdGeomBasisCurves schema (pinned: the phantom points 2 P0 - P1 and
    2 Pn-1 - Pn-2)."""
    n = len(points)
    if wrap == "pinned" and basis != "bezier":
        first = [2 * points[0][i] - points[1][i] for i in range(3)]
        last = [2 * points[-1][i] - points[-2][i] for i in range(3)]
        points, n = [first] + points + [last], n + 2
    step = 3 if basis == "bezier" else 1
    if wrap == "periodic":
        return [[points[(k * step + j) % n] for j in range(4)] for k in range(n // step)]
    return [[points[k * step + j] for j in range(4)] for k in range((n - 4) // step + 1)]


def format_points(points):
    return ", ".join(f"({p[0]!r}, {p[1]!r}, {p[2]!r})" for p in points)


def curves_stage(counts, points, kind="cubic", basis="bezier", wrap="nonperiodic",
                 widths=None, interpolation="vertex", extra="", xform=""):
    prim = curves_prim("hair", counts, points, kind, basis, wrap, widths, interpolation, extra)
    return "\n".join(["#usda 1.0", 'def Xform "groom"', "{", xform, prim, "}"]) + "\n"


def curves_prim(name, counts, points, kind="cubic", basis="bezier", wrap="nonperiodic",
                widths=None, interpolation="vertex", extra=""):
    lines = [f'    def BasisCurves "{name}"', "    {",
             f'        uniform token type = "{kind}"', f'        uniform token basis = "{basis}"',
             f'        uniform token wrap = "{wrap}"',
             f"        int[] curveVertexCounts = {list(counts)}",
             f"        point3f[] points = [{format_points(points)}]"]
    if widths is not None:
        lines.append(f"        float[] widths = {list(widths)} (interpolation = \"{interpolation}\")")
    lines += [extra, "    }"]
    return "\n".join(lines)


def camera_and_sky(position):
    """A camera at position looking along -z and a white sky of 1."""
    return (f'def Camera "camera" {{\n  double3 xformOp:translate = {tuple(position)}\n'
            '  uniform token[] xformOpOrder = ["xformOp:translate"]\n}\n'
            'def DomeLight "sky" {\n float inputs:intensity = 1\n}\n')


def test_points(counts, seed=1):
    """Deterministic, irregular points (a little LCG: no random module)."""
    state, out = seed, []
    for _ in range(sum(counts)):
        p = []
        for _ in range(3):
            state = (state * 1103515245 + 12345) % 2 ** 31
            p.append(round(state / 2 ** 31 * 4 - 2, 4))
        out.append(p)
    return out


class UsdTest(unittest.TestCase):
    def setUp(self):
        self.folder = tempfile.TemporaryDirectory()
        self.dir = self.folder.name

    def tearDown(self):
        self.folder.cleanup()

    def write(self, name, text):
        path = os.path.join(self.dir, name)
        with open(path, "w") as file:
            file.write(text)
        return path

    def convert(self, text, name="groom.usda", *options):
        source = self.write(name, text) if text is not None else os.path.join(self.dir, name)
        output = os.path.join(self.dir, "out", "scene.json")
        result = subprocess.run([YSCENE, "convert", source, output, *options],
                                capture_output=True, text=True, timeout=60)
        return source, output, result

    def converted(self, text, *options):
        source, output, result = self.convert(text, "groom.usda", *options)
        self.assertEqual(result.returncode, 0, result.stderr)
        with open(output) as file:
            scene = json.load(file)
        shapes = [read_ply(os.path.join(os.path.dirname(output), s["uri"]))
                  for s in scene["shapes"]]
        return source, scene, shapes

    def usd_segment_count(self, source, path="/groom/hair"):
        from pxr import Usd, UsdGeom
        stage = Usd.Stage.Open(source)
        curves = UsdGeom.BasisCurves(stage.GetPrimAtPath(path))
        return int(sum(curves.ComputeSegmentCounts(Usd.TimeCode.Default())))

    def assert_close(self, actual, expected, what):
        self.assertEqual(len(actual), len(expected), what)
        for k, (a, e) in enumerate(zip(actual, expected)):
            for i in range(len(e)):
                self.assertLess(abs(a[i] - e[i]), TOLERANCE,
                                f"{what}: point {k}: {a} != {e}")

    def check_cubic(self, source, shape, name, basis, wrap, counts):
        points = test_points(counts)
        widths = [0.01 + 0.001 * k for k in range(len(points))]
        vertices, (element, rows) = shape
        self.assertEqual(element, "curve")
        self.assertEqual(len(rows), self.usd_segment_count(source, "/groom/" + name))
        expected, expected_radii, offset = [], [], 0
        for n in counts:
            curve = points[offset:offset + n]
            radii = [[w / 2, 0, 0] for w in widths[offset:offset + n]]
            for segment, radius in zip(schema_segments(basis, wrap, curve),
                                       schema_segments(basis, wrap, radii)):
                expected += bezier_of(basis, *segment)
                expected_radii += [r[0] for r in bezier_of(basis, *radius)]
            offset += n
        xyz = list(zip(vertices["x"], vertices["y"], vertices["z"]))
        actual = [xyz[i] for row in rows for i in row]
        self.assert_close(actual, expected, f"{basis} {wrap}")
        actual_radii = [(vertices["radius"][i],) for row in rows for i in row]
        self.assert_close(actual_radii, [(r,) for r in expected_radii], f"{basis} {wrap} radii")

    def test_bases_and_wraps(self):
        cases = (("bezier", "nonperiodic", [4, 7, 10]),
                                    ("bezier", "pinned", [7, 4]),
                                    ("bezier", "periodic", [6, 9]),
                                    ("bspline", "nonperiodic", [4, 5, 9]),
                                    ("bspline", "pinned", [2, 3, 6]),
                                    ("bspline", "periodic", [3, 5]),
                                    ("catmullRom", "nonperiodic", [4, 6]),
                                    ("catmullRom", "pinned", [2, 5, 8]),
                                    ("catmullRom", "periodic", [4, 7]))
        prims = []
        for k, (basis, wrap, counts) in enumerate(cases):
            points = test_points(counts)
            widths = [0.01 + 0.001 * k for k in range(len(points))]
            prims.append(curves_prim(f"c{k}", counts, points, "cubic", basis, wrap, widths))
        text = "\n".join(["#usda 1.0", 'def Xform "groom"', "{", *prims, "}", ""])
        source, scene, shapes = self.converted(text)
        self.assertEqual(len(shapes), len(cases))
        for k, ((basis, wrap, counts), shape) in enumerate(zip(cases, shapes)):
            with self.subTest(basis=basis, wrap=wrap):
                self.check_cubic(source, shape, f"c{k}", basis, wrap, counts)

    def test_linear_curves_are_lines(self):
        for wrap in ("nonperiodic", "periodic"):
            with self.subTest(wrap=wrap):
                counts = [2, 5, 3] if wrap == "nonperiodic" else [3, 5, 4]
                points = test_points(counts, seed=7)
                widths = [0.02 * (k + 1) for k in range(len(points))]
                text = curves_stage(counts, points, "linear", "bezier", wrap, widths, "varying")
                source, scene, shapes = self.converted(text)
                (vertices, (element, rows)), = shapes
                self.assertEqual(element, "line")
                self.assertEqual(len(rows), self.usd_segment_count(source))
                xyz = list(zip(vertices["x"], vertices["y"], vertices["z"]))
                expected, radii, offset = [], [], 0
                for n in counts:
                    ends = [(k, (k + 1) % n) for k in range(n if wrap == "periodic" else n - 1)]
                    for a, b in ends:
                        expected += [points[offset + a], points[offset + b]]
                        radii += [(widths[offset + a] / 2,), (widths[offset + b] / 2,)]
                    offset += n
                self.assert_close([xyz[i] for row in rows for i in row], expected, wrap)
                self.assert_close([(vertices["radius"][i],) for row in rows for i in row],
                                  radii, wrap + " radii")

    def test_width_interpolations(self):
        counts = [5, 4]  # bspline nonperiodic: 2 and 1 segments
        points = test_points(counts, seed=3)
        segments = [2, 1]
        cases = {"constant": [0.04], "uniform": [0.02, 0.06],
                 "varying": [0.01, 0.02, 0.05, 0.03, 0.07]}
        prims = [curves_prim(name, counts, points, "cubic", "bspline", "nonperiodic", widths,
                             name) for name, widths in cases.items()]
        text = "\n".join(["#usda 1.0", 'def Xform "groom"', "{", *prims, "}", ""])
        _, _, shapes = self.converted(text)
        for (interpolation, widths), shape in zip(cases.items(), shapes):
            with self.subTest(interpolation=interpolation):
                vertices, (_, rows) = shape
                expected, varying = [], 0
                for curve, s in enumerate(segments):
                    for k in range(s):
                        if interpolation == "constant":
                            ends = (widths[0], widths[0])
                        elif interpolation == "uniform":
                            ends = (widths[curve], widths[curve])
                        else:  # linear from the segment's start to its end
                            ends = (widths[varying + k], widths[varying + k + 1])
                        expected += [((ends[0] * (3 - j) + ends[1] * j) / 3 / 2,) for j in range(4)]
                    varying += s + 1
                actual = [(vertices["radius"][i],) for row in rows for i in row]
                self.assert_close(actual, expected, interpolation)

    def test_no_widths_takes_the_default(self):
        points = test_points([4])
        text = curves_stage([4], points, "cubic", "bezier", "nonperiodic")
        source, output, result = self.convert(text)
        self.assertEqual(result.returncode, 0, result.stderr)
        self.assertIn("curves without widths (width 0.01 used): 1 (first: /groom/hair)",
                      result.stderr)
        vertices, _ = read_ply(os.path.join(os.path.dirname(output), "shapes",
                                            os.listdir(os.path.join(self.dir, "out",
                                                                    "shapes"))[0]))
        self.assertTrue(all(abs(r - 0.005) < 1e-9 for r in vertices["radius"]))

    def test_transformed_groom(self):
        # Scale 2, then rotate 90 degrees about z, then translate (1, 2, 3):
        # (x, y, z) -> (-2 y + 1, 2 x + 2, 2 z + 3); radii double.
        xform = ('    double3 xformOp:translate = (1, 2, 3)\n'
                 '    float3 xformOp:rotateXYZ = (0, 0, 90)\n'
                 '    float3 xformOp:scale = (2, 2, 2)\n'
                 '    uniform token[] xformOpOrder = ["xformOp:translate", '
                 '"xformOp:rotateXYZ", "xformOp:scale"]')
        points = test_points([4], seed=5)
        text = curves_stage([4], points, "cubic", "bezier", "nonperiodic", [0.1], "constant",
                            xform=xform)
        _, _, shapes = self.converted(text)
        (vertices, (_, rows)), = shapes
        expected = [(-2 * p[1] + 1, 2 * p[0] + 2, 2 * p[2] + 3) for p in points]
        xyz = list(zip(vertices["x"], vertices["y"], vertices["z"]))
        self.assert_close([xyz[i] for i in rows[0]], expected, "transformed")
        self.assert_close([(vertices["radius"][i],) for i in rows[0]], [(0.1,)] * 4, "radii")

    def test_instanced_groom(self):
        points = test_points([4], seed=9)
        text = "\n".join([
            "#usda 1.0",
            'def Xform "proto" {', 'def BasisCurves "hair" {',
            '    uniform token type = "cubic"', '    uniform token basis = "bezier"',
            "    int[] curveVertexCounts = [4]",
            f"    point3f[] points = [{format_points(points)}]",
            "    float[] widths = [0.02] (interpolation = \"constant\")", "}", "}",
            'def Xform "a" (', "instanceable = true", "references = </proto>", ") {",
            "    double3 xformOp:translate = (10, 0, 0)",
            '    uniform token[] xformOpOrder = ["xformOp:translate"]', "}",
            'def Xform "b" (', "instanceable = true", "references = </proto>", ") {",
            "    double3 xformOp:translate = (0, 0, -5)",
            '    uniform token[] xformOpOrder = ["xformOp:translate"]', "}",
            'def PointInstancer "scatter" {',
            "    int[] protoIndices = [0, 0]", "    point3f[] positions = [(0, 7, 0), (0, 9, 0)]",
            "    rel prototypes = [</scatter/protos/lock>]",
            '    def Scope "protos" {', 'def Xform "lock" (', "references = </proto>", ") {", "}",
            "}", "}",
            ""])
        _, scene, shapes = self.converted(text)
        offsets = {"proto_hair": (0, 0, 0), "a_hair": (10, 0, 0), "b_hair": (0, 0, -5)}
        names = [s["name"] for s in scene["shapes"]]
        self.assertEqual(len(shapes), 5, names)
        for name, (vertices, (_, rows)) in zip(names, shapes):
            if name in offsets:
                d = offsets[name]
            else:  # the point instancer's two instances, in order
                d = (0, 7 if "[0]" in name or name.endswith("_0") else 9, 0)
            xyz = list(zip(vertices["x"], vertices["y"], vertices["z"]))
            self.assert_close([xyz[i] for i in rows[0]], [vec(p, d) for p in points], name)
        instanced = sorted(n for n in names if n not in offsets)
        self.assertEqual(len(instanced), 2, names)

    def test_hair_primvars_and_display_color(self):
        points = test_points([4, 4])
        extra = ("        float primvars:eumelanin = 0.8 (interpolation = \"constant\")\n"
                 "        float primvars:roughness = 0.45 (interpolation = \"constant\")")
        _, scene, _ = self.converted(curves_stage([4, 4], points, widths=[0.01], interpolation="constant",
                                                  extra=extra))
        material = scene["materials"][0]
        self.assertEqual(material["type"], "hair")
        self.assertAlmostEqual(material["eumelanin"], 0.8, places=6)
        self.assertAlmostEqual(material["beta_m"], 0.45, places=6)
        extra = "        color3f[] primvars:displayColor = [(0.6, 0.4, 0.2)]"
        _, scene, _ = self.converted(curves_stage([4, 4], points, widths=[0.01], interpolation="constant",
                                                  extra=extra))
        self.assertEqual([round(c, 6) for c in scene["materials"][0]["color"]], [0.6, 0.4, 0.2])
        # --hair-material wins over displayColor.
        material_file = self.write("look.json", json.dumps(
            {"materials": [{"name": "look", "type": "hair", "eumelanin": 4.0}]}))
        _, scene, _ = self.converted(curves_stage([4, 4], points, widths=[0.01], interpolation="constant",
                                                  extra=extra), "--hair-material", material_file)
        self.assertEqual(scene["materials"][0]["eumelanin"], 4.0)
        self.assertNotIn("color", scene["materials"][0])

    def render_converted(self, text, resolution, samples):
        """Converts a stage and renders it: the image's width, height and
        values (PFM)."""
        _, output, result = self.convert(text)
        self.assertEqual(result.returncode, 0, result.stderr)
        image = os.path.join(self.dir, "image.pfm")
        result = subprocess.run([YSCENE, "render", output, "--resolution", str(resolution),
                                 "--samples", str(samples), "--output", image, "--quiet"],
                                capture_output=True, text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stderr)
        return read_pfm(image)

    def assert_melanin_colors(self, output, vertices, rows, expected, what):
        """Each point's colour gives, under the material's beta_n through the
        renderer's mapping (Chiang et al. 2016 eq. 9, colours clamped to
        [FLT_MIN, 1], as hair_sigma_a_from_color), the sigma_a of its
        expected (eumelanin, pheomelanin) (d'Eon et al. 2011): 1e-4 relative.
        The mapping written here is checked against the renderer's own on
        the material's colour, through yscene info --json."""
        result = subprocess.run([YSCENE, "info", "--json", output], capture_output=True,
                                text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stderr)
        material = json.loads(result.stdout)["materials"][0]
        self.assertEqual(material["type"], "hair")
        self.assertEqual(material["sigma_a_from"], "color")  # so per-point colours count
        b = min(max(material["beta_n"], 0.01), 1.0)
        d = 5.969 - 0.215 * b + 2.532 * b ** 2 - 10.73 * b ** 3 + 5.574 * b ** 4 + 0.245 * b ** 5
        floor = 2.0 ** -126
        for c, sigma_a in zip(material["color"], material["sigma_a"]):
            self.assertLess(abs((math.log(max(c, floor)) / d) ** 2 - sigma_a), 1e-5 * sigma_a)
        indices = [i for row in rows for i in row]
        self.assertEqual(len(indices), len(expected), what)
        for i, (eumelanin, pheomelanin) in zip(indices, expected):
            wanted = [max(eumelanin, 0) * e + max(pheomelanin, 0) * p
                      for e, p in zip((0.419, 0.697, 1.37), (0.187, 0.4, 1.05))]
            for channel, name in enumerate(("red", "green", "blue")):
                color = vertices[name][i]
                self.assertTrue(floor <= color <= 1, f"{what}: vertex {i}: colour {color}")
                sigma_a = (math.log(color) / d) ** 2
                self.assertLess(abs(sigma_a - wanted[channel]), 1e-4 * wanted[channel],
                                f"{what}: vertex {i} {name}: sigma_a {sigma_a} != "
                                f"{wanted[channel]}")

    def test_per_curve_melanin_becomes_colors(self):
        """A uniform eumelanin (0.2, 1, 3 on three curves) with a constant
        pheomelanin and roughness: every point of a curve carries the curve's
        absorption exactly, as a colour under beta_n = the roughness."""
        counts = [4, 4, 4]  # catmullRom pinned: 3 segments each
        points = test_points(counts, seed=11)
        extra = ("        float[] primvars:eumelanin = [0.2, 1, 3] (interpolation = \"uniform\")\n"
                 "        float primvars:pheomelanin = 0.25 (interpolation = \"constant\")\n"
                 "        float primvars:roughness = 0.4 (interpolation = \"constant\")")
        text = curves_stage(counts, points, "cubic", "catmullRom", "pinned", [0.02], "constant",
                            extra=extra)
        _, output, result = self.convert(text)
        self.assertEqual(result.returncode, 0, result.stderr)
        self.assertNotIn("primvars:eumelanin", result.stderr)  # no "mean" warning
        with open(output) as file:
            scene = json.load(file)
        vertices, (_, rows) = read_ply(os.path.join(os.path.dirname(output),
                                                    scene["shapes"][0]["uri"]))
        self.assertAlmostEqual(scene["materials"][0]["beta_n"], 0.4, places=6)
        self.assertEqual(len(rows), 9)
        expected = [(m, 0.25) for m in (0.2, 1.0, 3.0) for _ in range(3 * 4)]
        self.assert_melanin_colors(output, vertices, rows, expected, "per curve")
        # Black hair (eumelanin 8) is carried too; past (ln FLT_MIN / d)^2 a
        # warning and the darkest colour.
        text = curves_stage(counts, points, "cubic", "catmullRom", "pinned", [0.02], "constant",
                            extra=extra.replace("[0.2, 1, 3]", "[8, 1, 500]"))
        _, output, result = self.convert(text)
        self.assertEqual(result.returncode, 0, result.stderr)
        self.assertIn("points darker than a colour can carry", result.stderr)
        with open(output) as file:
            scene = json.load(file)
        vertices, (_, rows) = read_ply(os.path.join(os.path.dirname(output),
                                                    scene["shapes"][0]["uri"]))
        expected = [(m, 0.25) for m in (8.0, 1.0) for _ in range(3 * 4)]
        self.assert_melanin_colors(output, vertices, rows[:6], expected, "black hair")
        self.assertEqual({vertices["blue"][i] for row in rows[6:] for i in row}, {2.0 ** -126})
        # A count that does not match the interpolation is an error.
        shutil.rmtree(os.path.join(self.dir, "out"))
        text = curves_stage(counts, points, "cubic", "catmullRom", "pinned", [0.02], "constant",
                            extra=extra.replace("[0.2, 1, 3]", "[0.2, 1]"))
        self.assert_fails(text, "/groom/hair", "primvars:eumelanin has 2 elements",
                          "uniform interpolation needs 3")

    def test_per_vertex_melanin_becomes_colors(self):
        """A vertex eumelanin and pheomelanin: on linear curves each point's
        own; on cubic (catmullRom, pinned) curves the values the curve's basis
        gives its Bezier control points (exact on the curve at segment ends,
        where the renderer reads per-point colours)."""
        counts = [5, 3]
        eumelanin = [0.2, 1.0, 3.0, 2.0, 0.5, 0.1, 4.0, 0.7]
        pheomelanin = [0.0, 0.3, 0.1, 0.0, 0.6, 0.2, 0.0, 0.4]
        extra = (f"        float[] primvars:eumelanin = {eumelanin} (interpolation = \"vertex\")\n"
                 f"        float[] primvars:pheomelanin = {pheomelanin} "
                 f"(interpolation = \"vertex\")")
        points = test_points(counts, seed=13)
        for kind in ("linear", "cubic"):
            with self.subTest(kind=kind):
                text = curves_stage(counts, points, kind, "catmullRom", "pinned", [0.02],
                                    "constant", extra=extra)
                _, scene, shapes = self.converted(text)
                (vertices, (element, rows)), = shapes
                self.assertEqual(element, "line" if kind == "linear" else "curve")
                self.assertAlmostEqual(scene["materials"][0]["beta_n"], 0.3, places=6)
                expected, offset = [], 0
                for n in counts:
                    values = [[eumelanin[k], pheomelanin[k], 0]
                              for k in range(offset, offset + n)]
                    if kind == "linear":
                        expected += [(v[0], v[1]) for a, b in zip(values[:-1], values[1:])
                                     for v in (a, b)]
                    else:
                        for segment in schema_segments("catmullRom", "pinned", values):
                            expected += [(v[0], v[1])
                                         for v in bezier_of("catmullRom", *segment)]
                    offset += n
                output = os.path.join(self.dir, "out", "scene.json")
                self.assert_melanin_colors(output, vertices, rows, expected, kind)

    def test_render_of_varying_melanin(self):
        """Two strands, eumelanin 0.2 (left) and 3 (right) in one prim, under
        a white sky: the right half of the image is the darker (64 px, 4 spp)."""
        points = [[x, y, 0.0] for x in (-0.3, 0.3) for y in (-0.5, -0.1, 0.2, 0.5)]
        extra = "        float[] primvars:eumelanin = [0.2, 3] (interpolation = \"uniform\")"
        text = curves_stage([4, 4], points, "cubic", "catmullRom", "pinned", [0.12],
                            "constant", extra=extra) + camera_and_sky((0, 0, 3))
        width, height, values = self.render_converted(text, 64, 4)
        halves = [[], []]
        for y in range(height):
            for x in range(width):
                pixel = values[3 * (y * width + x):3 * (y * width + x) + 3]
                halves[0 if x < width // 2 else 1].append(sum(pixel) / 3)
        light, dark = (sum(h) / len(h) for h in halves)
        # The sky fills the same area of both halves (1 each): the strands differ.
        self.assertLess(dark, light - 0.05, (light, dark))  # measured: 0.95 against 0.83

    def test_render_and_info_convert_on_the_fly(self):
        """render and info take a USD stage directly: converted into a
        temporary folder (under TMPDIR, empty again afterwards) as convert
        does, the same image as a render of convert's output, the same
        materials in info; a bad stage fails as convert does."""
        points = [[x, y, 0.0] for x in (-0.3, 0.3) for y in (-0.5, -0.1, 0.2, 0.5)]
        extra = "        float[] primvars:eumelanin = [0.2, 3] (interpolation = \"uniform\")"
        text = curves_stage([4, 4], points, "cubic", "catmullRom", "pinned", [0.12],
                            "constant", extra=extra) + camera_and_sky((0, 0, 3))
        source, output, result = self.convert(text)
        self.assertEqual(result.returncode, 0, result.stderr)
        temporary = os.path.join(self.dir, "tmp")
        os.mkdir(temporary)
        environment = dict(os.environ, TMPDIR=temporary)
        images = []
        for scene in (output, source):
            images.append(os.path.join(self.dir, f"image{len(images)}.pfm"))
            result = subprocess.run([YSCENE, "render", scene, "--resolution", "32", "--samples",
                                     "2", "--output", images[-1], "--quiet"], env=environment,
                                    capture_output=True, text=True, timeout=60)
            self.assertEqual(result.returncode, 0, result.stderr)
        self.assertEqual(read_pfm(images[0]), read_pfm(images[1]))
        infos = []
        for scene in (output, source):
            result = subprocess.run([YSCENE, "info", "--json", scene], env=environment,
                                    capture_output=True, text=True, timeout=60)
            self.assertEqual(result.returncode, 0, result.stderr)
            infos.append(json.loads(result.stdout))
        self.assertEqual(infos[0]["materials"], infos[1]["materials"])
        self.assertEqual(infos[1]["materials"][0]["sigma_a_from"], "color")
        self.assertEqual(os.listdir(temporary), [])
        # Errors as convert gives them, the stage named; nothing left behind.
        bad = self.write("bad.usda", curves_stage([4, 5], points))
        for command in (["render", bad, "--output", os.path.join(self.dir, "x.png")],
                        ["info", bad], ["render", source, "--camera", "nowhere", "--output",
                                        os.path.join(self.dir, "x.png")]):
            result = subprocess.run([YSCENE, *command], env=environment, capture_output=True,
                                    text=True, timeout=60)
            self.assertEqual(result.returncode, 1, command)
            lines = [l for l in result.stderr.splitlines() if l.startswith("error:")]
            self.assertEqual(len(lines), 1, result.stderr)
            self.assertIn("error: " + (bad + ": /groom/hair: curveVertexCounts add up to 9"
                                       if command[1] == bad else source + ": no camera named"),
                          lines[0])
            self.assertFalse(os.path.exists(os.path.join(self.dir, "x.png")))
            self.assertEqual(os.listdir(temporary), [])

    def assert_fails(self, text, *needles, name="groom.usda"):
        source, output, result = self.convert(text, name)
        self.assertNotEqual(result.returncode, 0, result.stdout)
        lines = [l for l in result.stderr.splitlines() if l.startswith("error:")]
        self.assertEqual(len(lines), 1, result.stderr)
        for needle in needles:
            self.assertIn(needle, lines[0])
        self.assertIn("Traceback" if False else "error:", lines[0])
        self.assertNotIn("Traceback", result.stderr)
        self.assertFalse(os.path.exists(output), "an output was left")
        self.assertFalse(os.path.exists(os.path.dirname(output)), "the output folder was left")

    def test_malformed_stages(self):
        points = test_points([4, 4])
        self.assert_fails(curves_stage([4, 5], points), "/groom/hair", "add up to 9",
                          "points has 8")
        self.assert_fails(curves_stage([4, 4], points).replace(
            "point3f[] points", "point3f[] unused"), "/groom/hair", "no points")
        nan = [list(p) for p in points]
        nan[5][1] = float("nan")
        self.assert_fails(curves_stage([4, 4], nan).replace("nan", "nan"), "/groom/hair",
                          "points[5]")
        self.assert_fails(curves_stage([4, 4], points, widths=[0.1, -0.2], interpolation="uniform"),
                          "/groom/hair", "widths[1] is negative")
        self.assert_fails(curves_stage([4, 4], points, widths=[0.1, 0.2, 0.3],
                                       interpolation="uniform"), "/groom/hair", "widths has 3")
        self.assert_fails(curves_stage([5, 3], points, basis="bezier"), "/groom/hair",
                          "curveVertexCounts[")
        self.assert_fails("#usda 1.0\n", "no curves or meshes")
        self.assert_fails("this is not a USD file\n", "groom.usda", "not a readable USD stage")
        self.assert_fails("garbage", "groom.usdc", "not a readable USD stage", name="groom.usdc")
        self.assert_fails(curves_stage([4, 4], points), "groom.txt", name="groom.txt")

    def test_blender_groom(self):
        """Blender 5.0's own export (scripts/usd/make_blender_groom.py): every
        segment usd-core counts is one of ours, and every control point is
        the one the schema makes of the points Blender reports (1e-5)."""
        data = os.path.join(ROOT, "tests", "data", "usd")
        with open(os.path.join(data, "blender-groom.json")) as file:
            blender = json.load(file)
        source = os.path.join(data, "blender-groom.usda")
        output = os.path.join(self.dir, "out", "scene.json")
        result = subprocess.run([YSCENE, "convert", source, output], capture_output=True,
                                text=True, timeout=60)
        self.assertEqual(result.returncode, 0, result.stderr)
        with open(output) as file:
            scene = json.load(file)
        shapes = {s["name"]: read_ply(os.path.join(self.dir, "out", s["uri"]))
                  for s in scene["shapes"]}
        # Particle hair: linear curves, no widths (the default, 0.01).
        vertices, (element, rows) = shapes["root_scalp_fur"]
        self.assertEqual(element, "line")
        self.assertEqual(len(rows), self.usd_segment_count(source, "/root/scalp/fur"))
        xyz = list(zip(vertices["x"], vertices["y"], vertices["z"]))
        expected = [p for strand in blender["particle_hair"]
                    for a, b in zip(strand[:-1], strand[1:]) for p in (a, b)]
        self.assert_close([xyz[i] for row in rows for i in row], expected, "particle hair")
        self.assertTrue(all(abs(r - 0.005) < 1e-9 for r in vertices["radius"]))
        # Hair curves: cubic Catmull-Rom, pinned, widths per vertex.
        vertices, (element, rows) = shapes["root_lock_lock"]
        self.assertEqual(element, "curve")
        self.assertEqual(len(rows), self.usd_segment_count(source, "/root/lock/lock"))
        xyz = list(zip(vertices["x"], vertices["y"], vertices["z"]))
        expected, radii = [], []
        for strand, strand_radii in zip(blender["hair_curves"], blender["hair_curves_radius"]):
            for segment in schema_segments("catmullRom", "pinned", strand):
                expected += bezier_of("catmullRom", *segment)
            for segment in schema_segments("catmullRom", "pinned",
                                           [[r, 0, 0] for r in strand_radii]):
                radii += [(r[0],) for r in bezier_of("catmullRom", *segment)]
        self.assert_close([xyz[i] for row in rows for i in row], expected, "hair curves")
        self.assert_close([(vertices["radius"][i],) for row in rows for i in row], radii,
                          "hair curves radii")
        # The camera and the sun come across.
        camera, = scene["cameras"]
        self.assert_close([camera["frame"][9:12]], [blender["camera"]["location"]], "camera")
        fov = 2 * math.atan(camera["film"] / 2 / camera["lens"])
        expected_fov = 2 * math.atan(blender["camera"]["sensor_width_mm"] / 2 /
                                     blender["camera"]["lens_mm"])
        self.assertAlmostEqual(fov, expected_fov, places=5)
        light, = scene["distant_lights"]
        self.assert_close([light["direction"]], [blender["sun"]["direction"]], "sun")
        # Blender writes its 3 W/m^2 sun as intensity 0.75; read back as 3.
        self.assert_close([light["emission"]], [[blender["sun"]["energy"]] * 3], "sun strength")
        self.assertIn("Blender's suns (intensity x 4", result.stderr)

    def test_sun_intensity_and_width_option(self):
        """A DistantLight's intensity is its irradiance (times 2^exposure) in
        a stage not written by Blender; --width sets the width of curves that
        author none, and only USD inputs take it."""
        points = test_points([4])
        sun = ('def DistantLight "sun" {\n float inputs:intensity = 2\n'
               ' float inputs:exposure = 1\n float inputs:angle = 0\n}\n')
        text = curves_stage([4], points, "cubic", "bezier", "nonperiodic") + sun
        source, output, result = self.convert(text, "groom.usda", "--width", "0.04")
        self.assertEqual(result.returncode, 0, result.stderr)
        self.assertIn("curves without widths (width 0.04 used)", result.stderr)
        self.assertNotIn("Blender", result.stderr)
        with open(output) as file:
            scene = json.load(file)
        self.assert_close([scene["distant_lights"][0]["emission"]], [[4.0] * 3], "sun")
        vertices, _ = read_ply(os.path.join(os.path.dirname(output), scene["shapes"][0]["uri"]))
        self.assertTrue(all(abs(r - 0.02) < 1e-9 for r in vertices["radius"]))
        other = os.path.join(self.dir, "other.json")
        with open(other, "w") as file:
            json.dump({"asset": {"version": "4.2"}}, file)
        result = subprocess.run([YSCENE, "convert", other, os.path.join(self.dir, "x.json"),
                                 "--width", "0.04"], capture_output=True, text=True, timeout=60)
        self.assertNotEqual(result.returncode, 0)
        self.assertIn("--width are for USD inputs", result.stderr)

    def test_render_of_a_converted_groom(self):
        points = [[x * 0.1, 0.0, z] for x in range(-3, 4) for z in (0.0, 0.3, 0.6, 1.0)]
        counts = [4] * 7
        text = curves_stage(counts, points, "cubic", "catmullRom", "pinned", [0.05],
                            "constant") + camera_and_sky((0, -0.2, 4))
        width, height, values = self.render_converted(text, 32, 2)
        self.assertEqual(max(width, height), 32)
        self.assertTrue(all(v == v and abs(v) < 1e30 for v in values))
        self.assertGreater(max(values), 0)


def set_yscene(path):
    global YSCENE
    YSCENE = path


def main():
    return venv_main.run_tests_in_venv(
        __file__, "usd", "import numpy, pxr.Usd", "usd-core", set_yscene)


if __name__ == "__main__":
    sys.exit(main())
