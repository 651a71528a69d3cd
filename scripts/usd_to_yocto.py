#!/usr/bin/env python3
"""Converts a USD stage (.usd, .usda, .usdc, .usdz) into a yocto-hair json
scene in a folder: FOLDER/scene.json and FOLDER/shapes/*.ply.

Run by `yscene convert GROOM.usd OUT.json`, which loads the folder as a json
scene (checking it) and saves it atomically as OUT.json; run it by hand only
to look at the intermediate. Needs Pixar's usd-core and NumPy
(bash scripts/setup.sh --usd makes .venv/usd with both).

What is read (the UsdGeomBasisCurves schema's semantics):
- BasisCurves, type linear (-> line segments) or cubic with basis bezier,
  bspline or catmullRom (-> one cubic Bezier segment per schema segment, by an
  exact change of basis), wrap nonperiodic, pinned (phantom end points
  P[-1] = 2 P[0] - P[1], P[n] = 2 P[n-1] - P[n-2], as the schema defines them)
  or periodic. widths are diameters (radius = width / 2) with constant,
  uniform, varying (linear along each segment) or vertex (the curve's basis)
  interpolation; where none is authored, --width (default DEFAULT_WIDTH):
  Blender writes none for particle hair, which Cycles renders at the particle
  settings' radius_scale x root_radius (tapering to tip_radius).
- points at the default time or --time; composed world transforms baked into
  the points (radii scaled by the cube root of the transform's determinant);
  instance proxies and PointInstancers of curves and meshes.
- primvars:eumelanin, primvars:pheomelanin, primvars:roughness (-> beta_m and
  beta_n) on a curves prim: its hair material's values. A pigment that varies
  (uniform, varying or vertex) is carried exactly as a colour per point: the
  material is given by color, and each point's colour is the one whose
  absorption under the material's beta_n (Chiang et al. 2016 eq. 9, the
  renderer's hair_sigma_a_from_color) is the sigma_a of its melanin (d'Eon et
  al. 2011, hair_sigma_a_from_melanin), see melanin_colors. A roughness that
  varies takes its mean, with a warning (no per-strand carrier). Otherwise
  --hair-material's material, else primvars:displayColor (constant -> color;
  uniform, varying or vertex -> a colour per point), else the default:
  eumelanin 1.3, beta_m = beta_n = 0.3. Per-point quantities of cubic curves
  follow the points: the curve's basis takes them to the Bezier control
  points, and the renderer blends the colours of each segment's two end
  points linearly (so a vertex or varying pigment is exact at segment ends).
- Mesh (triangulated, smooth normals unless vertex normals are authored; matte
  in its constant displayColor or grey 0.5), Camera (perspective), DistantLight
  (-> distant light of irradiance colour * intensity * 2^exposure), DomeLight
  (-> environment: the same emission, with its lat-long texture if any). A
  stage Blender wrote (its root layer's doc "Blender v...") has its sun's
  intensity read times BLENDER_SUN_SCALE: Blender's exporter writes a sun of
  strength S W/m^2 as intensity S / 4, which its importer reads back as S.
Anything else is named in one warning line per kind (what, count, first prim).
Errors are one line "error: FILE: PRIM: message", exit status 1.
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np

DEFAULT_WIDTH = 0.01  # scene units, where a curves prim authors no widths
DEFAULT_HAIR = {"type": "hair", "eumelanin": 1.3, "pheomelanin": 0.0, "beta_m": 0.3,
                "beta_n": 0.3, "alpha": 2.0, "eta": 1.55}
BLENDER_SUN_SCALE = 4.0  # Blender exports sun strength / 4 (its usd_writer_light)
# Absorption of unit eumelanin and pheomelanin (d'Eon et al. 2011), as the
# renderer's hair_sigma_a_from_melanin (libs/yocto_hair/yocto_hair.cpp).
EUMELANIN_SIGMA_A = np.array([0.419, 0.697, 1.37])
PHEOMELANIN_SIGMA_A = np.array([0.187, 0.4, 1.05])
# The darkest colour hair_sigma_a_from_color takes (it clamps colours to
# [FLT_MIN, 1]): it stands for sigma_a = (ln FLT_MIN / d(beta_n))^2, over 200.
DARKEST_COLOR = float(np.finfo(np.float32).tiny)
CHUNK_CURVES = 65536  # curves converted at a time (bounds the working memory)

# Change of basis to Bezier: rows are the Bezier control points of one
# segment as combinations of the segment's four schema control points.
BSPLINE_TO_BEZIER = np.array([[1, 4, 1, 0], [0, 4, 2, 0], [0, 2, 4, 0], [0, 1, 4, 1]]) / 6.0
CATMULLROM_TO_BEZIER = np.array([[0, 6, 0, 0], [-1, 6, 1, 0], [0, 1, 6, -1], [0, 0, 6, 0]]) / 6.0
BEZIER_TO_BEZIER = np.eye(4)
# A quantity linear along a segment, from a (t = 0) to b (t = 1), as Bezier values.
LINEAR_TO_BEZIER = np.array([[3, 0], [2, 1], [1, 2], [0, 3]]) / 3.0


class ConvertError(Exception):
    pass


class Context:
    """What the conversion gathers: warnings by kind, and the scene's parts."""

    def __init__(self, filename, output, quiet, default_width=DEFAULT_WIDTH):
        self.filename, self.output, self.quiet = filename, output, quiet
        self.default_width = default_width
        self.blender = False  # the stage was written by Blender's exporter
        self.warnings = {}  # kind -> [count, first prim path]
        self.shapes, self.materials, self.instances = [], [], []
        self.cameras, self.environments, self.lights, self.textures = [], [], [], []
        self.names = set()
        self.progress_time = time.monotonic()

    def fail(self, path, message):
        raise ConvertError(f"{self.filename}: {path}: {message}")

    def warn(self, kind, path):
        entry = self.warnings.setdefault(kind, [0, str(path)])
        entry[0] += 1

    def unique_name(self, path):
        base = str(path).strip("/").replace("/", "_") or "root"
        name, k = base, 1
        while name in self.names:
            k += 1
            name = f"{base}_{k}"
        self.names.add(name)
        return name

    def progress(self, text):
        now = time.monotonic()
        if not self.quiet and now - self.progress_time > 1.0:
            print(f"usd: {text}", file=sys.stderr, flush=True)
            self.progress_time = now


# -----------------------------------------------------------------------------
# VALUES
# -----------------------------------------------------------------------------

def attribute_value(ctx, attribute, timecode):
    """An attribute's value at timecode; at the default time, an attribute
    with time samples only gives its first sample (with a warning)."""
    from pxr import Usd
    if not attribute or not attribute.HasValue():
        return None
    value = attribute.Get(timecode)
    if value is None and timecode.IsDefault() and attribute.GetNumTimeSamples() > 0:
        ctx.warn("attributes with time samples only, read at their first sample",
                 attribute.GetPath())
        value = attribute.Get(Usd.TimeCode(attribute.GetTimeSamples()[0]))
    return value


def primvar_value(ctx, primvar, timecode):
    """A primvar's flattened values (indices applied) and interpolation."""
    if not primvar or not primvar.HasValue():
        return None, None
    value = primvar.ComputeFlattened(timecode)
    if value is None and timecode.IsDefault() and primvar.GetAttr().GetNumTimeSamples() > 0:
        from pxr import Usd
        ctx.warn("attributes with time samples only, read at their first sample",
                 primvar.GetAttr().GetPath())
        value = primvar.ComputeFlattened(Usd.TimeCode(primvar.GetAttr().GetTimeSamples()[0]))
    if value is None:
        return None, None
    return np.asarray(value, dtype=np.float64), primvar.GetInterpolation()


def checked_finite(ctx, path, name, values):
    bad = ~np.isfinite(values)
    if bad.any():
        index = int(np.argwhere(bad.reshape(len(values), -1).any(axis=1))[0][0])
        ctx.fail(path, f"{name}[{index}] is not a finite number")
    return values


def world_matrix(xform_cache, prim):
    return np.array(xform_cache.GetLocalToWorldTransform(prim), dtype=np.float64)


def transform_points(matrix, points):
    """USD matrices act on row vectors: p' = p M."""
    return points @ matrix[:3, :3] + matrix[3, :3]


def radius_scale(ctx, path, matrix):
    """The factor a transform scales radii by: the cube root of its determinant
    (exact for uniform scales; a warning for others)."""
    linear = matrix[:3, :3]
    scale = abs(np.linalg.det(linear)) ** (1.0 / 3.0)
    lengths = np.linalg.norm(linear, axis=1)
    if scale > 0 and np.abs(lengths / scale - 1).max() > 1e-4:
        ctx.warn("curves under a non-uniform scale (radii scaled by its mean)", path)
    return scale


def frame_from_matrix(matrix):
    """A Yocto frame (x, y, z, o as 12 numbers) from a USD matrix, its axes
    normalised."""
    axes = [matrix[i, :3] / max(np.linalg.norm(matrix[i, :3]), 1e-30) for i in range(3)]
    return [float(v) for axis in axes for v in axis] + [float(v) for v in matrix[3, :3]]


# -----------------------------------------------------------------------------
# PLY OUTPUT
# -----------------------------------------------------------------------------

def ply_header(vertex_properties, vertices, element, elements):
    lines = ["ply", "format binary_little_endian 1.0", "comment Written by usd_to_yocto.py",
             f"element vertex {vertices}"]
    lines += [f"property float {name}" for name in vertex_properties]
    lines += [f"element {element} {elements}", "property list uchar int vertex_indices",
              "end_header"]
    return ("\n".join(lines) + "\n").encode("ascii")


def index_rows(indices):
    """Rows of a PLY list element: a count byte and the indices (int32 LE)."""
    size = indices.shape[1]
    rows = np.empty(len(indices), dtype=np.dtype([("n", "u1"), ("i", "<i4", (size,))]))
    rows["n"] = size
    rows["i"] = indices
    return rows


def vertex_rows(columns):
    """Vertex rows of float32 columns, interleaved."""
    return np.ascontiguousarray(np.column_stack(columns).astype("<f4"))


# -----------------------------------------------------------------------------
# CURVES
# -----------------------------------------------------------------------------

class Topology:
    """Segments of a BasisCurves prim per the schema: for each curve its
    vertex count, offset and segment count, and the basis matrix."""

    def __init__(self, ctx, path, counts, kind, basis, wrap, num_points):
        self.kind, self.basis, self.wrap = kind, basis, wrap
        self.counts = counts
        self.offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        if kind == "linear":
            minimum = 3 if wrap == "periodic" else 2
            self.vstep = 1
        elif basis == "bezier":
            minimum, self.vstep = (3 if wrap == "periodic" else 4), 3
        else:
            minimum, self.vstep = (3 if wrap == "periodic" else 2 if wrap == "pinned" else 4), 1
        if len(counts) and counts.min() < minimum:
            index = int(np.argmax(counts < minimum))
            ctx.fail(path, f"curveVertexCounts[{index}] is {int(counts[index])}: a {kind} "
                     f"{'' if kind == 'linear' else basis + ' '}{wrap} curve needs at least "
                     f"{minimum} vertices")
        total = int(counts.sum())
        if total != num_points:
            ctx.fail(path, f"curveVertexCounts add up to {total} but points has {num_points} "
                     f"elements")
        n = counts
        pinned = wrap == "pinned" and kind == "cubic" and basis != "bezier"
        if kind == "linear":
            segments = n if wrap == "periodic" else n - 1
        elif wrap == "periodic":
            segments = n // self.vstep
        elif pinned:
            segments = n - 1
        else:
            segments = (n - 4) // self.vstep + 1
        if kind == "cubic" and basis == "bezier":
            bad = (n % 3 != 0) if wrap == "periodic" else ((n - 4) % 3 != 0)
            if bad.any():
                index = int(np.argmax(bad))
                ctx.fail(path, f"curveVertexCounts[{index}] is {int(n[index])}: a bezier "
                         f"{wrap} curve needs {'3k' if wrap == 'periodic' else '3k + 1'} vertices")
        self.pinned = pinned
        self.segments = segments.astype(np.int64)
        self.periodic = wrap == "periodic"
        # Varying values per curve: segment ends (the schema's table).
        self.varying = self.segments if self.periodic else self.segments + 1
        self.matrix = {"bezier": BEZIER_TO_BEZIER, "bspline": BSPLINE_TO_BEZIER,
                       "catmullRom": CATMULLROM_TO_BEZIER}.get(basis, BEZIER_TO_BEZIER)

    def segment_indices(self, first, last):
        """For curves first..last-1: the (segments x 4) point indices of each
        cubic segment, into the points array extended with two phantom
        points per curve when pinned (see extended_points); and the curve of
        each segment relative to first."""
        counts = self.counts[first:last]
        segments = self.segments[first:last]
        curve = np.repeat(np.arange(last - first), segments)
        start = np.concatenate([[0], np.cumsum(segments)[:-1]])
        k = np.arange(int(segments.sum())) - np.repeat(start, segments)  # segment in curve
        offsets = self.offsets[first:last] - self.offsets[first]
        if self.pinned:
            offsets = offsets + 2 * np.arange(last - first)
            counts = counts + 2
        j = np.arange(4)
        local = k[:, None] * self.vstep + j[None, :]
        if self.periodic:
            local = local % counts[curve][:, None]
        return offsets[curve][:, None] + local, curve

    def extended(self, values, first, last):
        """Values of curves first..last-1 (a slice starting at the first
        curve's first vertex), with the pinned phantoms P[-1] = 2 P[0] - P[1]
        and P[n] = 2 P[n-1] - P[n-2] added to each curve."""
        if not self.pinned:
            return values
        counts = self.counts[first:last]
        offsets = self.offsets[first:last] - self.offsets[first]
        ends = offsets + counts - 1
        number = last - first
        # Position of each authored value in the extended array.
        positions = np.arange(len(values)) + 2 * np.repeat(np.arange(number), counts) + 1
        out = np.empty((len(values) + 2 * number,) + values.shape[1:], dtype=values.dtype)
        out[positions] = values
        out[offsets + 2 * np.arange(number)] = 2 * values[offsets] - values[offsets + 1]
        out[ends + 2 * np.arange(number) + 2] = 2 * values[ends] - values[ends - 1]
        return out


def per_curve_values(topology, values, interpolation, first, last, segment_curve,
                     segment_index):
    """A quantity on the Bezier control points (segments x 4 x d) from
    its authored values with the given interpolation."""
    d = values.shape[1]
    if interpolation == "constant":
        return np.broadcast_to(values[0], (len(segment_curve), 4, d))
    if interpolation == "uniform":
        return np.broadcast_to(values[first + segment_curve][:, None, :],
                               (len(segment_curve), 4, d))
    if interpolation == "varying":
        varying = topology.varying
        start = int(varying[:first].sum())
        curve_start = np.concatenate([[0], np.cumsum(varying[first:last])[:-1]]) + start
        segments = topology.segments[first:last]
        seg_start = np.concatenate([[0], np.cumsum(segments)[:-1]])
        k = np.arange(len(segment_curve)) - seg_start[segment_curve]
        a = curve_start[segment_curve] + k
        b = k + 1
        if topology.periodic:
            b = b % segments[segment_curve]
        b = curve_start[segment_curve] + b
        ends = np.stack([values[a], values[b]], axis=1)  # segments x 2 x d
        return np.einsum("ij,sjd->sid", LINEAR_TO_BEZIER, ends)
    # vertex: the curve's own basis.
    chunk = values[topology.offsets[first]:topology.offsets[first] + int(
        topology.counts[first:last].sum())]
    chunk = topology.extended(chunk, first, last)
    return np.einsum("ij,sjd->sid", topology.matrix, chunk[segment_index])


def expected_size(topology, interpolation, num_points):
    return {"constant": 1, "uniform": len(topology.counts), "varying": int(topology.varying.sum()),
            "vertex": num_points}.get(interpolation)


def color_denominator(beta_n):
    """d(beta_n) of Chiang et al. 2016 eq. 9, sigma_a = (ln c / d)^2, with
    beta_n made usable as the renderer does (clamped to [0.01, 1])."""
    b = min(max(beta_n, 0.01), 1.0)
    return 5.969 - 0.215 * b + 2.532 * b ** 2 - 10.73 * b ** 3 + 5.574 * b ** 4 + 0.245 * b ** 5


def melanin_colors(ctx, path, pigments, beta_n, warn=True):
    """Colours (n x 3) whose absorption under beta_n is that of the melanin
    pairs (n x 2: eumelanin, pheomelanin): per channel the inverse of
    sigma_a = (ln c / d)^2, c = exp(-sqrt(sigma_a) d). Darker than the
    darkest colour the renderer takes (sigma_a above (ln FLT_MIN / d)^2):
    that colour, with a warning."""
    pigments = np.maximum(pigments, 0)  # as hair_sigma_a_from_melanin
    sigma_a = pigments[:, :1] * EUMELANIN_SIGMA_A + pigments[:, 1:2] * PHEOMELANIN_SIGMA_A
    colors = np.exp(-np.sqrt(sigma_a) * color_denominator(beta_n))
    if warn and (colors < DARKEST_COLOR).any():
        ctx.warn(f"points darker than a colour can carry (sigma_a above "
                 f"{(math.log(DARKEST_COLOR) / color_denominator(beta_n)) ** 2:.4g}: "
                 f"clamped to it)", path)
    return np.clip(colors, DARKEST_COLOR, 1.0)


class PointColors:
    """A colour per point of a curves prim: authored quantities (primvar
    name, values as rows, interpolation), each taken to the points as the
    points are, then made colours by to_colors (rows of all quantities side
    by side -> rows of red, green, blue)."""

    def __init__(self, quantities, to_colors):
        self.quantities, self.to_colors = quantities, to_colors


def read_curves_material(ctx, prim, path, timecode, base_material):
    """The hair material of a curves prim (see the module's doc) and its
    PointColors where a pigment or displayColor varies (else None)."""
    from pxr import UsdGeom
    api = UsdGeom.PrimvarsAPI(prim)
    material = dict(base_material[1])
    hair_values, varying = {}, {}
    for name in ("eumelanin", "pheomelanin", "roughness"):
        values, interpolation = primvar_value(ctx, api.GetPrimvar(name), timecode)
        if values is None:
            continue
        values = checked_finite(ctx, path, f"primvars:{name}", values.reshape(-1))
        if len(values) == 0:
            continue
        if values.min() < 0:
            ctx.fail(path, f"primvars:{name} has a negative value ({values.min():g})")
        if values.max() != values.min():
            if name == "roughness":
                ctx.warn("primvars:roughness varying along the groom (its mean is used: "
                         "roughness has no per-strand carrier)", path)
            else:
                varying[name] = (name, values.reshape(-1, 1), interpolation)
        hair_values[name] = float(values.mean())
    if "roughness" in hair_values:
        material["beta_m"] = material["beta_n"] = min(max(hair_values["roughness"], 0.0), 1.0)
    colors = None
    if varying:
        # Pigments as colours per point under the material's beta_n.
        beta_n = material.get("beta_n", DEFAULT_HAIR["beta_n"])
        beta_n = beta_n if beta_n == beta_n else DEFAULT_HAIR["beta_n"]  # NaN, as the renderer
        material["beta_n"] = beta_n
        unused = [key for key in ("tip_eumelanin", "tip_pheomelanin", "tip_color", "tip_sigma_a")
                  if key in material]
        if unused:
            ctx.warn(f"--hair-material {', '.join(unused)} with varying pigment primvars (not "
                     f"used: the pigment is carried as colours per point)", path)
        for key in ("eumelanin", "pheomelanin", "sigma_a", "tint", *unused):
            material.pop(key, None)
        quantities = [varying.get(name, (name, np.array([[hair_values.get(name, 0.0)]]),
                                         "constant"))
                      for name in ("eumelanin", "pheomelanin")]
        mean = np.array([[hair_values.get("eumelanin", 0.0), hair_values.get("pheomelanin", 0.0)]])
        material["color"] = [float(v) for v in melanin_colors(ctx, path, mean, beta_n, False)[0]]
        colors = PointColors(quantities, lambda rows: melanin_colors(ctx, path, rows, beta_n))
    elif "eumelanin" in hair_values or "pheomelanin" in hair_values:
        for key in ("color", "sigma_a", "tint"):
            material.pop(key, None)
        material["eumelanin"] = hair_values.get("eumelanin", 0.0)
        material["pheomelanin"] = hair_values.get("pheomelanin", 0.0)
    elif base_material[0] == "default":
        values, interpolation = primvar_value(ctx, api.GetPrimvar("displayColor"), timecode)
        if values is not None and len(values):
            values = checked_finite(ctx, path, "primvars:displayColor", values.reshape(-1, 3))
            values = np.clip(values, 0, 1)
            for key in ("eumelanin", "pheomelanin", "sigma_a"):
                material.pop(key, None)
            if interpolation == "constant" or len(values) == 1:
                material["color"] = [float(v) for v in values[0]]
            else:
                material["color"] = [float(v) for v in values.mean(axis=0)]
                colors = PointColors([("displayColor", values, interpolation)],
                                     lambda rows: np.clip(rows, 0, 1))
    elif api.GetPrimvar("displayColor").HasValue():
        ctx.warn("primvars:displayColor of curves with --hair-material (not used)", path)
    return material, colors


def convert_curves(ctx, prim, path, matrix, timecode, base_material):
    from pxr import UsdGeom
    curves = UsdGeom.BasisCurves(prim)
    kind = curves.GetTypeAttr().Get() or "cubic"
    basis = curves.GetBasisAttr().Get() or "bezier"
    wrap = curves.GetWrapAttr().Get() or "nonperiodic"
    if kind not in ("linear", "cubic"):
        ctx.fail(path, f"type {kind} is not linear or cubic")
    if basis not in ("bezier", "bspline", "catmullRom"):
        ctx.fail(path, f"basis {basis} is not bezier, bspline or catmullRom")
    if wrap not in ("nonperiodic", "pinned", "periodic"):
        ctx.fail(path, f"wrap {wrap} is not nonperiodic, pinned or periodic")
    points = attribute_value(ctx, curves.GetPointsAttr(), timecode)
    if points is None or len(points) == 0:
        ctx.fail(path, "no points")
    points = checked_finite(ctx, path, "points", np.asarray(points, dtype=np.float64))
    counts = attribute_value(ctx, curves.GetCurveVertexCountsAttr(), timecode)
    if counts is None or len(counts) == 0:
        ctx.fail(path, "no curveVertexCounts")
    counts = np.asarray(counts, dtype=np.int64)
    topology = Topology(ctx, path, counts, kind, basis, wrap, len(points))

    # Widths: diameters, as radii.
    widths = attribute_value(ctx, curves.GetWidthsAttr(), timecode)
    if widths is None or len(widths) == 0:
        ctx.warn(f"curves without widths (width {ctx.default_width:g} used)", path)
        radii, radii_interpolation = np.array([[ctx.default_width / 2]]), "constant"
    else:
        widths = checked_finite(ctx, path, "widths", np.asarray(widths, dtype=np.float64))
        if widths.min() < 0:
            index = int(np.argmax(widths < 0))
            ctx.fail(path, f"widths[{index}] is negative ({widths[index]:g})")
        radii_interpolation = curves.GetWidthsInterpolation()
        size = expected_size(topology, radii_interpolation, len(points))
        if size is None or len(widths) != size:
            ctx.fail(path, f"widths has {len(widths)} elements, {radii_interpolation} "
                     f"interpolation needs {size}")
        radii = (widths / 2).reshape(-1, 1)
    material, colors = read_curves_material(ctx, prim, path, timecode, base_material)
    if colors is not None:
        for name, values, interpolation in colors.quantities:
            size = expected_size(topology, interpolation, len(points))
            if size is None or len(values) != size:
                ctx.fail(path, f"primvars:{name} has {len(values)} elements, {interpolation} "
                         f"interpolation needs {size}")
    for name, what in (("normals", "curve normals (ribbons; rendered as tubes)"),
                       ("velocities", "curve velocities (no motion blur)"),
                       ("accelerations", "curve accelerations (no motion blur)"),
                       ("primvars:displayOpacity", "curve displayOpacity")):
        attribute = prim.GetAttribute(name)
        if attribute and attribute.HasValue():
            ctx.warn(what, path)

    points = transform_points(matrix, points)
    radii = radii * radius_scale(ctx, path, matrix)
    name = ctx.unique_name(path)
    filename = os.path.join(ctx.output, "shapes", name + ".ply")
    if kind == "linear":
        write_lines(ctx, filename, topology, points, radii, radii_interpolation, colors)
    else:
        write_curves(ctx, filename, topology, points, radii, radii_interpolation, colors, path)
    add_instance(ctx, name, material)


def add_instance(ctx, name, material):
    ctx.shapes.append({"name": name, "uri": f"shapes/{name}.ply"})
    ctx.materials.append(dict(material, name=name))
    ctx.instances.append({"name": name, "shape": len(ctx.shapes) - 1,
                          "material": len(ctx.materials) - 1})


def write_lines(ctx, filename, topology, points, radii, radii_interpolation, colors):
    """Linear curves: the points as vertices, one line per segment. Varying
    and vertex values are both per point for linear curves."""
    counts, offsets = topology.counts, topology.offsets
    curve_of_point = np.repeat(np.arange(len(counts)), counts)
    columns = [points[:, 0], points[:, 1], points[:, 2]]
    columns.append(radii[:, 0] if radii_interpolation in ("vertex", "varying") else
                   radii[curve_of_point, 0] if radii_interpolation == "uniform" else
                   np.full(len(points), radii[0, 0]))
    names = ["x", "y", "z", "radius"]
    if colors is not None:
        per_point = np.concatenate([
            values if interpolation in ("vertex", "varying") else
            values[curve_of_point] if interpolation == "uniform" else
            np.broadcast_to(values[0], (len(points), values.shape[1]))
            for _, values, interpolation in colors.quantities], axis=1)
        columns += list(colors.to_colors(per_point).T)
        names += ["red", "green", "blue"]
    segments = topology.segments
    curve = np.repeat(np.arange(len(counts)), segments)
    start = np.concatenate([[0], np.cumsum(segments)[:-1]])
    k = np.arange(int(segments.sum())) - np.repeat(start, segments)
    a = offsets[curve] + k
    b = offsets[curve] + (k + 1) % counts[curve]
    with open(filename, "wb") as file:
        file.write(ply_header(names, len(points), "line", len(a)))
        file.write(vertex_rows(columns).tobytes())
        file.write(index_rows(np.stack([a, b], axis=1)).tobytes())


def write_curves(ctx, filename, topology, points, radii, radii_interpolation, colors, path):
    """Cubic curves: each schema segment as one Bezier segment. A curve of s
    segments writes 3 s + 1 vertices (segments share their end points), in
    chunks of curves, then one curve element of 4 consecutive indices each."""
    segments = topology.segments
    num_curves = len(segments)
    num_vertices = int((3 * segments + 1).sum())
    num_segments = int(segments.sum())
    names = ["x", "y", "z", "radius"] + (["red", "green", "blue"] if colors is not None else [])
    negative = 0
    with open(filename, "wb") as file:
        file.write(ply_header(names, num_vertices, "curve", num_segments))
        for first in range(0, num_curves, CHUNK_CURVES):
            last = min(first + CHUNK_CURVES, num_curves)
            ctx.progress(f"{path}: curves {first:,} of {num_curves:,}")
            begin = topology.offsets[first]
            end = begin + int(topology.counts[first:last].sum())
            chunk = topology.extended(points[begin:end], first, last)
            index, curve = topology.segment_indices(first, last)
            control = np.einsum("ij,sjd->sid", topology.matrix, chunk[index])
            quantities = [control,
                          per_curve_values(topology, radii, radii_interpolation, first, last,
                                           curve, index)]
            if colors is not None:
                authored = np.concatenate([
                    per_curve_values(topology, values, interpolation, first, last, curve, index)
                    for _, values, interpolation in colors.quantities], axis=2)
                quantities.append(colors.to_colors(authored.reshape(
                    -1, authored.shape[2])).reshape(len(curve), 4, 3))
            # Each curve's first control point, then every segment's last three.
            seg_start = np.concatenate([[0], np.cumsum(segments[first:last])[:-1]])
            columns = []
            for quantity in quantities:
                tail = quantity[:, 1:4, :].reshape(-1, quantity.shape[2])
                heads = quantity[seg_start, 0, :]
                columns.append(np.insert(tail, 3 * seg_start, heads, axis=0))
            negative += int((columns[1] < 0).sum())
            columns[1] = np.maximum(columns[1], 0)
            file.write(vertex_rows([c for column in columns for c in column.T]).tobytes())
        for first in range(0, num_curves, CHUNK_CURVES):
            last = min(first + CHUNK_CURVES, num_curves)
            counts = segments[first:last]
            base = int((3 * segments[:first] + 1).sum())
            vertex_start = np.concatenate([[0], np.cumsum(3 * counts + 1)[:-1]]) + base
            seg_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
            k = np.arange(int(counts.sum())) - np.repeat(seg_start, counts)
            starts = np.repeat(vertex_start, counts) + 3 * k
            file.write(index_rows(starts[:, None] + np.arange(4)[None, :]).tobytes())
    if negative:
        ctx.warn("curves whose interpolated widths go below 0 (clamped to 0)", path)


# -----------------------------------------------------------------------------
# MESHES, CAMERAS, LIGHTS
# -----------------------------------------------------------------------------

def convert_mesh(ctx, prim, path, matrix, timecode):
    from pxr import UsdGeom
    mesh = UsdGeom.Mesh(prim)
    points = attribute_value(ctx, mesh.GetPointsAttr(), timecode)
    counts = attribute_value(ctx, mesh.GetFaceVertexCountsAttr(), timecode)
    indices = attribute_value(ctx, mesh.GetFaceVertexIndicesAttr(), timecode)
    if points is None or len(points) == 0:
        ctx.fail(path, "no points")
    if counts is None or indices is None or len(counts) == 0:
        ctx.fail(path, "no faceVertexCounts or faceVertexIndices")
    points = checked_finite(ctx, path, "points", np.asarray(points, dtype=np.float64))
    counts = np.asarray(counts, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    if counts.min() < 3:
        ctx.fail(path, f"faceVertexCounts[{int(np.argmax(counts < 3))}] is below 3")
    if int(counts.sum()) != len(indices):
        ctx.fail(path, f"faceVertexCounts add up to {int(counts.sum())} but faceVertexIndices "
                 f"has {len(indices)} elements")
    if indices.min() < 0 or indices.max() >= len(points):
        ctx.fail(path, f"faceVertexIndices reach outside the {len(points)} points")
    if (mesh.GetSubdivisionSchemeAttr().Get() or "catmullClark") != "none":
        ctx.warn("subdivision meshes (rendered as their control mesh)", path)
    holes = mesh.GetHoleIndicesAttr().Get()
    if holes is not None and len(holes):
        ctx.warn("mesh holeIndices (holes filled)", path)
    # Fans: face f with c corners from offset o gives (o, o + j, o + j + 1).
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    fans = counts - 2
    face = np.repeat(np.arange(len(counts)), fans)
    fan_start = np.concatenate([[0], np.cumsum(fans)[:-1]])
    j = np.arange(int(fans.sum())) - np.repeat(fan_start, fans) + 1
    triangles = np.stack([indices[offsets[face]], indices[offsets[face] + j],
                          indices[offsets[face] + j + 1]], axis=1)
    if mesh.GetOrientationAttr().Get() == "leftHanded":
        triangles = triangles[:, [0, 2, 1]]
    points = transform_points(matrix, points)
    if np.linalg.det(matrix[:3, :3]) < 0:
        triangles = triangles[:, [0, 2, 1]]
    normals = attribute_value(ctx, mesh.GetNormalsAttr(), timecode)
    if normals is not None and len(normals) == len(points) and \
            mesh.GetNormalsInterpolation() in ("vertex", "varying"):
        normals = np.asarray(normals, dtype=np.float64) @ np.linalg.inv(matrix[:3, :3]).T
    else:
        if normals is not None and len(normals):
            ctx.warn("mesh normals that are not per vertex (smooth normals computed)", path)
        p = points[triangles]
        face_normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # area weighted
        normals = np.zeros_like(points)
        for corner in range(3):
            np.add.at(normals, triangles[:, corner], face_normals)
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(lengths > 0, normals / np.maximum(lengths, 1e-30), [0, 0, 1])
    name = ctx.unique_name(path)
    with open(os.path.join(ctx.output, "shapes", name + ".ply"), "wb") as file:
        file.write(ply_header(["x", "y", "z", "nx", "ny", "nz"], len(points), "face",
                              len(triangles)))
        file.write(vertex_rows([*points.T, *normals.T]).tobytes())
        file.write(index_rows(triangles).tobytes())
    color = [0.5, 0.5, 0.5]
    values, _ = primvar_value(ctx, UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor"), timecode)
    if values is not None and len(values):
        color = [float(v) for v in np.clip(values.reshape(-1, 3).mean(axis=0), 0, 1)]
    add_instance(ctx, name, {"type": "matte", "color": color})


def convert_camera(ctx, prim, path, matrix, timecode):
    from pxr import UsdGeom
    camera = UsdGeom.Camera(prim)
    get = lambda attribute: attribute_value(ctx, attribute, timecode)
    if get(camera.GetProjectionAttr()) == "orthographic":
        ctx.warn("orthographic cameras (read as perspective)", path)
    focal = get(camera.GetFocalLengthAttr()) or 50.0
    horizontal = get(camera.GetHorizontalApertureAttr()) or 20.955
    vertical = get(camera.GetVerticalApertureAttr()) or 15.2908
    if focal <= 0 or horizontal <= 0 or vertical <= 0:
        ctx.fail(path, "focalLength and apertures must be positive")
    if (get(camera.GetHorizontalApertureOffsetAttr()) or 0) != 0 or \
            (get(camera.GetVerticalApertureOffsetAttr()) or 0) != 0:
        ctx.warn("camera aperture offsets (ignored)", path)
    if camera.GetClippingRangeAttr().HasAuthoredValue():
        ctx.warn("camera clippingRange (the renderer does not clip)", path)
    # Lens and film as Yocto keeps them (metres, from the schema's millimetres:
    # only their ratio, the field of view, matters); the lens opening in
    # scene units (the schema's lengths are tenths of a scene unit).
    element = {"name": ctx.unique_name(path), "frame": frame_from_matrix(matrix),
               "orthographic": False, "lens": focal * 0.001,
               "film": max(horizontal, vertical) * 0.001, "aspect": horizontal / vertical}
    f_stop = get(camera.GetFStopAttr()) or 0
    focus = get(camera.GetFocusDistanceAttr()) or 0
    if f_stop > 0 and focus > 0:
        element["aperture"] = focal * 0.1 / f_stop
        element["focus"] = focus
    ctx.cameras.append(element)


def light_emission(ctx, light, timecode):
    get = lambda attribute: attribute_value(ctx, attribute, timecode)
    color = np.array(get(light.GetColorAttr()) or (1, 1, 1), dtype=np.float64)
    intensity = get(light.GetIntensityAttr())
    exposure = get(light.GetExposureAttr()) or 0
    if get(light.GetEnableColorTemperatureAttr()):
        ctx.warn("light colour temperatures (ignored)", light.GetPath())
    scale = (1.0 if intensity is None else intensity) * 2.0 ** exposure
    return [float(v) for v in color * scale]


def convert_distant_light(ctx, prim, path, matrix, timecode):
    from pxr import UsdLux
    light = UsdLux.DistantLight(prim)
    # The light shines along its -Z: the direction towards it is +Z.
    direction = matrix[2, :3] / max(np.linalg.norm(matrix[2, :3]), 1e-30)
    angle = attribute_value(ctx, light.GetAngleAttr(), timecode)
    if angle:
        ctx.warn("distant light angles (a sharp sun is rendered)", path)
    emission = light_emission(ctx, light, timecode)
    if ctx.blender:
        ctx.warn(f"Blender's suns (intensity x {BLENDER_SUN_SCALE:g}: Blender exports its sun "
                 f"strength in W/m^2 / {BLENDER_SUN_SCALE:g})", path)
        emission = [v * BLENDER_SUN_SCALE for v in emission]
    ctx.lights.append({"name": ctx.unique_name(path), "direction": [float(v) for v in direction],
                       "emission": emission})


def convert_dome_light(ctx, prim, path, matrix, timecode):
    from pxr import UsdLux
    light = UsdLux.DomeLight(prim)
    element = {"name": ctx.unique_name(path), "frame": frame_from_matrix(matrix),
               "emission": light_emission(ctx, light, timecode)}
    texture = attribute_value(ctx, light.GetTextureFileAttr(), timecode)
    if texture is not None and texture.path:
        resolved = texture.resolvedPath or texture.path
        if not os.path.isfile(resolved):
            ctx.fail(path, f"inputs:texture:file {texture.path} not found")
        ctx.textures.append({"name": element["name"], "uri": os.path.abspath(resolved)})
        element["emission_tex"] = len(ctx.textures) - 1
    if ctx.environments:
        ctx.warn("dome lights after the first (the renderer has one environment)", path)
        return
    ctx.environments.append(element)


# -----------------------------------------------------------------------------
# STAGE
# -----------------------------------------------------------------------------

STRUCTURE = {"", "Xform", "Scope", "GeomSubset"}


def convert_stage(ctx, stage, timecode, base_material):
    from pxr import Usd, UsdGeom, UsdLux
    xform_cache = UsdGeom.XformCache(timecode)
    predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
    iterator = iter(Usd.PrimRange.Stage(stage, predicate))
    for prim in iterator:
        path = prim.GetPath()
        type_name = str(prim.GetTypeName())
        imageable = UsdGeom.Imageable(prim)
        if imageable and imageable.ComputeVisibility(timecode) == "invisible":
            ctx.warn("invisible prims (skipped with what is below them)", path)
            iterator.PruneChildren()
            continue
        if imageable and imageable.GetPurposeAttr().Get() in ("proxy", "guide"):
            ctx.warn("proxy and guide prims (skipped)", path)
            iterator.PruneChildren()
            continue
        if prim.IsA(UsdGeom.BasisCurves):
            convert_curves(ctx, prim, path, world_matrix(xform_cache, prim), timecode,
                           base_material)
        elif prim.IsA(UsdGeom.Mesh):
            convert_mesh(ctx, prim, path, world_matrix(xform_cache, prim), timecode)
        elif prim.IsA(UsdGeom.Camera):
            convert_camera(ctx, prim, path, world_matrix(xform_cache, prim), timecode)
        elif prim.IsA(UsdLux.DistantLight):
            convert_distant_light(ctx, prim, path, world_matrix(xform_cache, prim), timecode)
        elif prim.IsA(UsdLux.DomeLight):
            convert_dome_light(ctx, prim, path, world_matrix(xform_cache, prim), timecode)
        elif prim.IsA(UsdGeom.PointInstancer):
            convert_point_instancer(ctx, prim, path, xform_cache, timecode, base_material)
            iterator.PruneChildren()  # prototypes are drawn only through it
        elif type_name in ("Material", "Shader", "NodeGraph"):
            ctx.warn("UsdShade materials (not read: curves take the hair material, meshes "
                     "their displayColor)", path)
            iterator.PruneChildren()
        elif type_name not in STRUCTURE:
            ctx.warn(f"prims of type {type_name or 'untyped'} (not supported)", path)


def convert_point_instancer(ctx, prim, path, xform_cache, timecode, base_material):
    """Every instance of every prototype's curves and meshes, baked."""
    from pxr import Usd, UsdGeom
    instancer = UsdGeom.PointInstancer(prim)
    transforms = instancer.ComputeInstanceTransformsAtTime(timecode, timecode)
    indices = attribute_value(ctx, instancer.GetProtoIndicesAttr(), timecode)
    targets = instancer.GetPrototypesRel().GetTargets()
    if indices is None or transforms is None:
        ctx.fail(path, "no protoIndices or positions")
    instancer_world = world_matrix(xform_cache, prim)
    stage = prim.GetStage()
    for instance, proto_index in enumerate(indices):
        if proto_index < 0 or proto_index >= len(targets):
            ctx.fail(path, f"protoIndices[{instance}] is {proto_index}: there are "
                     f"{len(targets)} prototypes")
        root = stage.GetPrimAtPath(targets[proto_index])
        # A prototype's own transform counts; its parents' do not.
        instance_world = np.array(transforms[instance], dtype=np.float64) @ instancer_world
        root_parent = world_matrix(xform_cache, root.GetParent())
        for child in Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
            local = world_matrix(xform_cache, child) @ np.linalg.inv(root_parent)
            matrix = local @ instance_world
            child_path = f"{path}[{instance}]{child.GetPath()}"
            if child.IsA(UsdGeom.BasisCurves):
                convert_curves(ctx, child, child_path, matrix, timecode, base_material)
            elif child.IsA(UsdGeom.Mesh):
                convert_mesh(ctx, child, child_path, matrix, timecode)
            elif str(child.GetTypeName()) not in STRUCTURE:
                ctx.warn(f"point-instanced prims of type {child.GetTypeName()} (not supported)",
                         child.GetPath())


def load_hair_material(ctx, filename):
    """The first hair material of a json scene (yscene checked the file)."""
    try:
        with open(filename) as file:
            scene = json.load(file)
    except (OSError, ValueError) as error:
        raise ConvertError(f"{filename}: {error}")
    materials = scene.get("materials", []) if isinstance(scene, dict) else []
    if isinstance(materials, dict):  # the 4.0 layout: keyed by name
        materials = list(materials.values())
    for material in materials:
        if isinstance(material, dict) and material.get("type") == "hair":
            return {k: v for k, v in material.items() if k != "name"}
    raise ConvertError(f"{filename}: no hair material in it")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("input", help="a .usd, .usda, .usdc or .usdz file")
    parser.add_argument("output", help="an empty folder for scene.json and shapes/")
    parser.add_argument("--time", type=float, default=None, help="time code (default: default)")
    parser.add_argument("--hair-material", default="", help="json scene with a hair material")
    parser.add_argument("--width", type=float, default=DEFAULT_WIDTH,
                        help=f"width of curves that author none (default {DEFAULT_WIDTH})")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args()
    ctx = Context(args.input, args.output, args.quiet, args.width)
    try:
        extension = os.path.splitext(args.input)[1].lower()
        if extension not in (".usd", ".usda", ".usdc", ".usdz"):
            raise ConvertError(f"{args.input}: not a USD file (.usd, .usda, .usdc or .usdz)")
        if not os.path.isfile(args.input):
            raise ConvertError(f"{args.input}: no such file")
        from pxr import Usd, Tf
        base_material = ("default", DEFAULT_HAIR)
        if args.hair_material:
            base_material = ("file", load_hair_material(ctx, args.hair_material))
        try:
            stage = Usd.Stage.Open(args.input)
        except Tf.ErrorException as error:
            message = " ".join(str(error).split())
            raise ConvertError(f"{args.input}: not a readable USD stage ({message})")
        if stage is None:
            raise ConvertError(f"{args.input}: not a readable USD stage")
        if not (args.width > 0 and math.isfinite(args.width)):
            raise ConvertError(f"{args.input}: --width {args.width:g} is not a positive width")
        ctx.blender = stage.GetRootLayer().documentation.startswith("Blender v")
        timecode = Usd.TimeCode.Default() if args.time is None else Usd.TimeCode(args.time)
        os.makedirs(os.path.join(args.output, "shapes"), exist_ok=True)
        convert_stage(ctx, stage, timecode, base_material)
        if not ctx.shapes:
            raise ConvertError(f"{args.input}: {stage.GetPseudoRoot().GetPath()}: the stage has "
                               f"no curves or meshes to render")
    except ConvertError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    for kind, (count, first) in sorted(ctx.warnings.items()):
        print(f"warning: {args.input}: {kind}: {count} (first: {first})", file=sys.stderr)
    scene = {"asset": {"version": "4.2", "generator": "usd_to_yocto.py"}}
    for key, values in (("cameras", ctx.cameras), ("environments", ctx.environments),
                        ("distant_lights", ctx.lights), ("textures", ctx.textures),
                        ("shapes", ctx.shapes), ("materials", ctx.materials),
                        ("instances", ctx.instances)):
        if values:
            scene[key] = values
    with open(os.path.join(args.output, "scene.json"), "w") as file:
        json.dump(scene, file, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
