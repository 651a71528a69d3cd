#!/usr/bin/env python3
"""Measures every real scene file in ../shared/data with generated stand-in
geometry and prints the markdown of the "Real scene files" section of
docs/RESULTS.md (or, with --update FILE, replaces that section in FILE).

For each pbrt scene (pbrt-v3 and pbrt-v4) and each Yocto json scene: copies
its folder to a temporary directory, writes stand-ins at the missing include
and shape paths with `yscene hair` (the same placement rules as
tests/test_realscenes.cpp), converts pbrt scenes with `yscene convert` (timed
by yscene itself), renders the result with `yscene render` at the stated spp
and resolution (timed by yscene), and optionally keeps the renders as PNGs.
Then runs the realscenes native-vs-lines test and copies its figures.
Python 3 standard library only; needs a build with yscene and test_realscenes.

    scripts/realscenes_table.py [--build build] [--samples 16] [--resolution 256]
        [--images DIR] [--update docs/RESULTS.md]
"""

import argparse
import contextlib
import io
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "..", "shared", "data")

# Stand-in sizes for the table (larger than the test's, smaller than the real
# models: Cem Yuksel's straight and curly hair have 1.1M and 3.3M curves).
STRANDS = {"straight": 10000, "curly": 5000, "curls": 1500, "block": 10000}


def style_of(name):
    """The kind of hair a missing file stands for, from its name."""
    base = os.path.basename(name)
    for key, style in (("straight", "straight"), ("curly", "curly"), ("curl", "curls"),
                       ("block", "block")):
        if key in base:
            return style
    return None


def fit_arguments(scene, style, v4):
    """Placement of pbrt head stand-ins (see tests/test_realscenes.cpp): hair
    centred 25 units ahead of the camera (the v4 scenes' head sphere), filling
    0.70 (straight) or 0.80 (curly) of pbrt-v3's views as pbrt's renders
    show, 0.90 of v4's narrower views to keep the head sphere covered."""
    if style not in ("straight", "curly"):
        return []
    fraction = 0.90 if v4 else (0.70 if style == "straight" else 0.80)
    return ["--fit-camera", scene, "--fit-distance", "25", "--fit-fraction", str(fraction)]


def run(arguments):
    result = subprocess.run(arguments, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit("failed: " + " ".join(arguments) + "\n" + result.stdout + result.stderr)
    return result.stdout


def pbrt_includes(path):
    includes = []
    with open(path) as file:
        for line in file:
            line = line.split("#")[0]
            for match in re.finditer(r'\b(?:Include|Import)\s+"([^"]+)"', line):
                includes.append(match.group(1))
    return includes


def json_references(path):
    """Files a json scene refers to: uris, and 4.0 shapes/textures by name."""
    with open(path) as file:
        js = json.load(file)
    directory = os.path.dirname(path)

    def listed(group, name):
        elements = js.get(group, {})
        if isinstance(elements, dict):
            return name in elements
        return any(isinstance(e, dict) and e.get("name") == name for e in elements)

    files = []
    for group in ("shapes", "textures"):
        elements = js.get(group, [])
        for element in elements.values() if isinstance(elements, dict) else elements:
            if isinstance(element, dict) and "uri" in element:
                files.append(element["uri"])
    for group in ("objects", "instances"):
        elements = js.get(group, [])
        for element in elements.values() if isinstance(elements, dict) else elements:
            shape = element.get("shape") if isinstance(element, dict) else None
            if isinstance(shape, str) and not listed("shapes", shape):
                files.append("shapes/" + shape + ".ply")
    environments = js.get("environments", [])
    for element in environments.values() if isinstance(environments, dict) else environments:
        texture = element.get("emission_tex") if isinstance(element, dict) else None
        if isinstance(texture, str) and not listed("textures", texture):
            extensions = (".hdr", ".exr", ".png", ".jpg", ".jpeg", ".pfm")
            if not any(os.path.exists(os.path.join(directory, "textures", texture + e))
                       for e in extensions):
                files.append("textures/" + texture + ".hdr")
    return sorted(set(files))


def generate(yscene, style, output, extra=()):
    text = run([yscene, "hair", "--style", style, "--strands", str(STRANDS[style]),
                "--output", output, *extra])
    match = re.search(r"(\d+) strands, (\d+) Bezier segments", text)
    return int(match.group(1)), int(match.group(2))


def sky(yscene, output, work):
    """The generator's procedural sky, as the scene's missing sky.hdr."""
    scratch = os.path.join(work, "sky-scene", "sky.json")
    os.makedirs(os.path.dirname(scratch), exist_ok=True)
    run([yscene, "hair", "--style", "block", "--strands", "1", "--output", scratch])
    run(["oiiotool", os.path.join(os.path.dirname(scratch), "textures", "sky.exr"), "-o", output])


def measure(yscene, source, work, args):
    name = os.path.relpath(source, DATA)
    folder = os.path.join(work, "scene")
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(os.path.dirname(source), folder)
    scene = os.path.join(folder, os.path.basename(source))
    strands = segments = 0
    stand_ins = []
    if scene.endswith(".pbrt"):
        for include in pbrt_includes(scene):
            path = os.path.join(folder, include)
            if os.path.exists(path):
                continue
            style = style_of(include)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            count, curves = generate(yscene, style, path, fit_arguments(scene, style, "pbrt-v4" in source))
            strands, segments = strands + count, segments + curves
            stand_ins.append(style)
        converted = os.path.join(folder, "converted", "scene.json")
        os.makedirs(os.path.dirname(converted), exist_ok=True)
        text = run([yscene, "convert", scene, converted])
        convert_time = float(re.search(r" in ([0-9.]+)s", text).group(1))
        loaded = converted
    else:
        for reference in json_references(scene):
            path = os.path.join(folder, reference)
            if os.path.exists(path):
                continue
            os.makedirs(os.path.dirname(path), exist_ok=True)
            if reference.endswith(".ply"):
                style = style_of(reference)
                count, curves = generate(yscene, style, path)
                strands, segments = strands + count, segments + curves
                stand_ins.append(style)
            else:
                sky(yscene, path, work)
                stand_ins.append("sky")
        convert_time = None
        loaded = scene
    image = os.path.join(work, "render.png")
    text = run([yscene, "render", loaded, "--output", image, "--samples", str(args.samples),
                "--resolution", str(args.resolution), "--quiet"])
    match = re.search(r": (\d+)x(\d+), (\d+) spp in ([0-9.]+)s", text)
    width, height, render_time = int(match.group(1)), int(match.group(2)), float(match.group(4))
    if args.images:
        os.makedirs(args.images, exist_ok=True)
        shutil.copy(image, os.path.join(args.images, name.replace("/", "_").replace(
            ".pbrt", "").replace(".json", "") + ".png"))
    return dict(name=name, stand_ins=stand_ins, strands=strands, segments=segments,
                convert=convert_time, width=width, height=height, render=render_time)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--build", default=os.path.join(ROOT, "build"))
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--images", default="", help="keep the renders as PNGs here")
    parser.add_argument("--sheet", default="",
                        help="with --images: a contact sheet of the renders (needs oiiotool)")
    parser.add_argument("--update", default="",
                        help="replace the section '## Real scene files' of this markdown file")
    args = parser.parse_args()
    if args.update:
        # Print into a buffer, then put it in place of the old section.
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            report(args)
        replace_section(args.update, "## Real scene files", buffer.getvalue())
    else:
        report(args)


def replace_section(path, heading, text):
    """Replaces the markdown section starting at heading (up to the next
    heading of the same level) with text; written to a temporary file, then
    renamed."""
    with open(path) as f:
        lines = f.read().split("\n")
    start = lines.index(heading)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")),
               len(lines))
    updated = "\n".join(lines[:start]) + "\n" + text.rstrip("\n") + "\n\n" + \
        "\n".join(lines[end:])
    with open(path + ".tmp", "w") as f:
        f.write(updated)
    os.replace(path + ".tmp", path)


def report(args):
    # The render times depend on what else runs: the load is recorded with them.
    load_at_start = os.getloadavg()[0]
    yscene = os.path.join(args.build, "apps", "yscene")
    if not os.path.isdir(DATA):
        sys.exit(DATA + " is absent: no real scene files")
    sources = []
    for top in ("pbrt", "yocto"):
        for directory, _, files in os.walk(os.path.join(DATA, top)):
            sources += [os.path.join(directory, f) for f in files
                        if f.endswith(".pbrt" if top == "pbrt" else ".json")]
    rows = []
    with tempfile.TemporaryDirectory(prefix="yocto_realscenes_") as work:
        for source in sorted(sources):
            rows.append(measure(yscene, os.path.normpath(source), work, args))
            print("measured", rows[-1]["name"], file=sys.stderr)
    lines = run([os.path.join(args.build, "tests", "test_realscenes"),
                 "--gtest_filter=realscenes.native_curves_match_16_line_segments:"
                 "realscenes.pbrt_v3_hair_where_pbrt_shows_it"])
    rmse = [l for l in lines.splitlines() if l.startswith("native vs")]
    placement = [l for l in lines.splitlines() if "stand-in silhouette" in l]
    if args.images and args.sheet:
        # One row of pbrt scenes, one of json scenes, 256x128 cells.
        rows_files = []
        for prefix in ("pbrt_", "yocto_"):
            images = sorted(f for f in os.listdir(args.images) if f.startswith(prefix))
            row = os.path.join(args.images, "row-" + prefix + ".png")
            command = ["oiiotool"]
            for image in images:
                command += [os.path.join(args.images, image), "--fit", "256x128"]
            run(command + ["--mosaic", "%dx1" % len(images), "-o", row])
            rows_files.append(row)
        run(["oiiotool", *rows_files, "--mosaic", "1x2", "-o", args.sheet])

    print("## Real scene files\n")
    print("Every real scene file in `../shared/data/` with generated stand-in geometry at its "
          "missing include and shape paths (the real hair models are not available here; the "
          "strand and segment counts are the **stand-ins'** sizes, not the real models'). pbrt "
          "scenes are converted with `yscene convert` (time as yscene reports it: parsing the "
          "scene and its stand-in includes, writing json and PLYs); json scenes are loaded "
          "directly. Render time is `yscene render` at %d spp, largest side %d pixels, on %s "
          "(%d cores; load average %.1f before the run, %.1f after it, a two-thread render "
          "alone making about 2), as yscene reports it (rendering only, not loading).\n"
          % (args.samples, args.resolution, platform.machine(), os.cpu_count(),
             load_at_start, os.getloadavg()[0]))
    print("| scene file | stand-ins | strands | Bezier segments | convert (s) | "
          "resolution | render (s) |")
    print("|---|---|---:|---:|---:|---|---:|")
    for row in rows:
        convert = "%.2f" % row["convert"] if row["convert"] is not None else "— (json)"
        print("| `%s` | %s | %d | %d | %s | %dx%d | %.2f |" % (
            row["name"], ", ".join(row["stand_ins"]) or "none", row["strands"], row["segments"],
            convert, row["width"], row["height"], row["render"]))
    print("\nStrands and segments count each stand-in file once (the hair-curls scenes "
          "instance their lock four times). Placement: pbrt head stand-ins are fitted to the "
          "scene's camera (`yscene hair --fit-camera SCENE --fit-distance 25 --fit-fraction F`, "
          "F = 0.70 straight and 0.80 curly for pbrt-v3 as measured on pbrt's renders, 0.90 "
          "for pbrt-v4 so that its dark head sphere stays inside the hair); the block, the "
          "curls and the json scenes' hair use the generator's frames, which are the real "
          "models' frames.\n")
    print("### Placement against pbrt's renders\n")
    print("`realscenes.pbrt_v3_hair_where_pbrt_shows_it`: the box of image rows and columns "
          "where over 2% of camera rays (128x128 pixel centres) hit the stand-in's fibers, "
          "against the same box measured on pbrt-v3's renders of the real models "
          "(`images/*.png`, hair told from the sky by red > blue). The test asserts centres "
          "within 0.05 and tops within 0.08; the stand-ins are narrower than the real hair "
          "(their strands hang longer, so the fit to the taller axis leaves them narrower).\n")
    print("```")
    for line in placement:
        print(line)
    print("```\n")
    if args.sheet:
        print("Renders of the stand-in scenes (%d spp; top: the pbrt files in the table's "
              "order, bottom: the json files): `%s`.\n" % (args.samples,
              os.path.relpath(args.sheet, os.path.join(ROOT, "docs"))))
        print("![stand-in renders](%s)\n" % os.path.relpath(args.sheet,
              os.path.join(ROOT, "docs")))
    print("### Native curves against line segments\n")
    print("`tests/test_realscenes.cpp` (`realscenes.native_curves_match_16_line_segments`): the "
          "converted pbrt-v3 curly-hair scene (stand-in: 1500 strands of 24 Bezier segments) "
          "at 64 pixels and 16 spp, seed 1; the noise level is the RMSE between two native "
          "renders with seeds 1 and 2. The test asserts 16 segments < 0.6 of the noise level; "
          "2 and 4 segments are measured only.\n")
    print("```")
    for line in rmse:
        print(line)
    print("```\n")
    print("Regenerate (about 3 minutes on 2 cores): `scripts/realscenes_table.py --samples %d "
          "--resolution %d --images /tmp/realscenes --sheet docs/figures/realscenes.png "
          "--update docs/RESULTS.md`." % (args.samples, args.resolution))


if __name__ == "__main__":
    main()
