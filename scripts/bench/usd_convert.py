#!/usr/bin/env python3
"""Issue 38's bench line: `yscene convert` of a USD groom against the
equivalent pbrt file, 100k and 1M strands: wall time and peak memory.

    .venv/usd/bin/python scripts/bench/usd_convert.py [--yscene build/apps/yscene]
        [--strands 100000,1000000] [--segments 2] [--runs 3] [--work out/usd-bench]
        [--output docs/benchmark/usd_convert.md]

Each groom is strands of --segments cubic Bezier segments (3 s + 1 control
points, random walks from random roots, constant width 0.008), written twice
with the same control points: as a binary USD (.usdc) by usd-core (one
BasisCurves prim, cubic, bezier, nonperiodic, constant widths), and as pbrt
text the way real hair scenes are (one Shape "curve" per segment, 6
significant digits, "float width"). Each file is converted by `yscene
convert IN OUT.json --quiet` under /usr/bin/time -v: the median of --runs
runs (one run for grooms of a million strands or more), wall seconds and the
maximum resident set size (for USD the larger of yscene and its converter
child, which /usr/bin/time sees through wait4). Run under nice on a machine
others use: the ratio is what the issue asks for, the seconds depend on load.
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WIDTH = 0.008


def make_groom(strands, segments, seed=7):
    """Control points (strands x (3 segments + 1) x 3), float32 rounded to 6
    significant digits so that both files hold the same numbers."""
    rng = np.random.default_rng(seed)
    points = 3 * segments + 1
    steps = rng.uniform(-1, 1, (strands, points, 3)) * 0.05
    steps[:, :, 2] = 0.05
    steps[:, 0, :] = rng.uniform(-10, 10, (strands, 3))
    return round_significant(np.cumsum(steps, axis=1)).astype(np.float32)


def round_significant(values, digits=6):
    """Rounds to `digits` significant digits (as %g prints)."""
    magnitude = np.floor(np.log10(np.maximum(np.abs(values), 1e-30)))
    scale = 10.0 ** (digits - 1 - magnitude)
    return np.round(values * scale) / scale


def write_usd(filename, groom):
    from pxr import Usd, UsdGeom, Vt
    stage = Usd.Stage.CreateNew(filename)
    curves = UsdGeom.BasisCurves.Define(stage, "/groom/hair")
    curves.CreateTypeAttr("cubic")
    curves.CreateBasisAttr("bezier")
    curves.CreateWrapAttr("nonperiodic")
    strands, points, _ = groom.shape
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(groom.reshape(-1, 3)))
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(
        np.full(strands, points, dtype=np.int32)))
    curves.CreateWidthsAttr(Vt.FloatArray([WIDTH]))
    curves.SetWidthsInterpolation("constant")
    stage.GetRootLayer().Save()


def write_pbrt(filename, groom, chunk=20000):
    strands, points, _ = groom.shape
    segments = (points - 1) // 3
    with open(filename, "w") as file:
        file.write('WorldBegin\nAttributeBegin\nMaterial "hair" "float eumelanin" 1.3\n')
        form = ('Shape "curve" "point P" [ ' + " ".join(["%.6g"] * 12) +
                f' ] "float width" [ {WIDTH:g} ] "string type" [ "cylinder" ]\n')
        for first in range(0, strands, chunk):
            part = groom[first:first + chunk].astype(np.float64)
            rows = np.concatenate([part[:, 3 * k:3 * k + 4, :].reshape(len(part), 1, 12)
                                   for k in range(segments)], axis=1).reshape(-1, 12)
            file.write("".join(form % tuple(row) for row in rows))
        file.write("AttributeEnd\n")


def timed_convert(yscene, source, output):
    """(wall seconds, peak RSS in MB) of one conversion."""
    result = subprocess.run(["/usr/bin/time", "-v", yscene, "convert", source, output,
                             "--quiet"], capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"error: converting {source} failed:\n{result.stderr}")
    wall = re.search(r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)", result.stderr)
    hours, minutes, seconds = wall.groups()
    seconds = int(hours or 0) * 3600 + int(minutes) * 60 + float(seconds)
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", result.stderr).group(1))
    return seconds, rss / 1024


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--yscene", default=os.path.join(ROOT, "build", "apps", "yscene"))
    parser.add_argument("--strands", default="100000,1000000")
    parser.add_argument("--segments", type=int, default=2)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--work", default=os.path.join(ROOT, "out", "usd-bench"))
    parser.add_argument("--output", default=os.path.join(ROOT, "docs", "benchmark",
                                                         "usd_convert.md"))
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)
    rows = []
    for strands in [int(s) for s in args.strands.split(",")]:
        groom = make_groom(strands, args.segments)
        usd = os.path.join(args.work, f"groom-{strands}.usdc")
        pbrt = os.path.join(args.work, f"groom-{strands}.pbrt")
        start = time.perf_counter()
        write_usd(usd, groom)
        write_pbrt(pbrt, groom)
        print(f"{strands:,} strands: wrote {usd} ({os.path.getsize(usd) / 2**20:.0f} MB) and "
              f"{pbrt} ({os.path.getsize(pbrt) / 2**20:.0f} MB) in "
              f"{time.perf_counter() - start:.1f} s", flush=True)
        del groom
        runs = 1 if strands >= 1000000 else args.runs
        results = {}
        for kind, source in (("pbrt", pbrt), ("usd", usd)):
            output = os.path.join(args.work, f"out-{kind}-{strands}", "scene.json")
            samples = [timed_convert(args.yscene, source, output) for _ in range(runs)]
            results[kind] = (statistics.median(s[0] for s in samples),
                             max(s[1] for s in samples), [s[0] for s in samples])
            print(f"  {kind}: {' '.join(f'{s[0]:.2f}' for s in samples)} s, peak "
                  f"{results[kind][1]:.0f} MB", flush=True)
        rows.append((strands, results))
    lines = ["# USD groom conversion against pbrt", "",
             "`yscene convert` of the same groom (strands of "
             f"{args.segments} cubic Bezier segments, constant width) written as binary USD by "
             "usd-core and as pbrt text (one `Shape \"curve\"` per segment); wall seconds "
             "(median of the runs) and peak resident memory (/usr/bin/time -v; for USD the "
             "larger of yscene and its usd-core child). Made by:", "",
             "```sh", "nice -n 19 .venv/usd/bin/python scripts/bench/usd_convert.py "
             f"--strands {args.strands} --segments {args.segments} --runs {args.runs}", "```",
             "", "| strands | segments | runs | pbrt s | USD s | USD / pbrt | pbrt peak MB | "
             "USD peak MB |", "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for strands, results in rows:
        pbrt, usd = results["pbrt"], results["usd"]
        lines.append(f"| {strands:,} | {strands * args.segments:,} | {len(pbrt[2])} | "
                     f"{pbrt[0]:.2f} | {usd[0]:.2f} | {usd[0] / pbrt[0]:.2f}x | "
                     f"{pbrt[1]:.0f} | {usd[1]:.0f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    with open(args.output + ".tmp", "w") as file:
        file.write(text)
    os.replace(args.output + ".tmp", args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
