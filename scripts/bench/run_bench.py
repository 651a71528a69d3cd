#!/usr/bin/env python3
"""Speed against error: the yocto-hair benchmark.

One command renders every benchmark scene with every variant, measures time,
samples/s, rays/s, peak memory and the error against a converged reference,
and writes a CSV, log-log plots and a markdown report to docs/benchmark/:

    python3 scripts/bench/run_bench.py            # full run, 10-15 minutes
    python3 scripts/bench/run_bench.py --quick    # small images, a few minutes,
                                                  # into out/bench/quick-report

Needs build/apps/yscene (bash scripts/setup.sh) and python3-matplotlib for
the plots. Generated scenes, references and renders are cached under
out/bench/ (git-ignored); references are rendered once per scene, resolution,
sample count and yscene binary (a rebuilt renderer renders them again), with a
seed different from the variants' so that their noise is independent.

Timing: the machine may be shared, so single-thread variants are timed by
render CPU time (what yscene reports as render_cpu) and the two-thread variant
by wall time; the load average is recorded with every measurement. A full run
renders every variant twice, in opposite orders, and keeps the faster time of
each checkpoint.
"""

import argparse
import csv
import hashlib
import json
import math
import os
import shutil
import struct
import subprocess
import sys
import time
from array import array

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))

# The thesis's three scenes (scripts/make_scenes.sh) and a 1M-strand scene.
SCENES = [
    ("hair-locks", "scenes/hair-locks/hair-locks.json"),
    ("straight-hair", "scenes/straight-hair/straight-hair.json"),
    ("curly-hair", "scenes/curly-hair/curly-hair.json"),
    ("straight-1m", "out/bench/scenes/straight-1m/straight-1m.json"),
]
# References have config["reference_spp"] samples per pixel times this factor
# (the lock of curls is a small image that converges fast); variants stop at an
# eighth of their reference's spp, so that the reference's own noise stays
# below a ninth of the error measured.
REFERENCE_FACTOR = {"hair-locks": 4}
# The 1M-strand scene: 1M strands of 4 Bezier segments.
HAIR_1M = ["--style", "straight", "--strands", "1000000", "--segments", "4"]

# name, yscene render arguments, threads. Everything runs on one thread but
# path-2t; geometry variants are compared with the native reference.
VARIANTS = [
    ("path", [], 1),
    ("naive", ["--sampler", "naive"], 1),
    ("lines-2", ["--curves", "lines", "--segments", "2"], 1),
    ("lines-4", ["--curves", "lines", "--segments", "4"], 1),
    ("lines-8", ["--curves", "lines", "--segments", "8"], 1),
    ("flat", ["--flat-curves"], 1),
    ("four-numbers", ["--hair-four-numbers"], 1),
    ("per-hit", ["--hair-per-hit"], 1),
    ("per-hit-fast-pow", ["--hair-per-hit", "--hair-fast-pow"], 1),
    ("path-2t", [], 2),
]
# The 1M scene pays a long BVH build per run: only the main comparisons.
VARIANTS_1M = ["path", "naive", "lines-4", "path-2t"]

SCALE_STRANDS = [10000, 100000, 1000000]


def log(message):
    print(message, file=sys.stderr, flush=True)


def load_average():
    with open("/proc/loadavg") as f:
        return float(f.read().split()[0])


def run(command):
    """Runs a command; returns its stdout, or exits with its output."""
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    if result.returncode != 0:
        log("command failed: " + " ".join(command))
        log(result.stdout + result.stderr)
        sys.exit(1)
    return result.stdout


def parse_fields(line):
    """key=value pairs of a yscene stats or checkpoint line."""
    fields = {}
    for item in line.split()[1:]:
        key, _, value = item.partition("=")
        try:
            fields[key] = float(value)
        except ValueError:
            fields[key] = value
    return fields


def read_pfm(filename):
    """A PFM image as (width, height, flat array of floats)."""
    with open(filename, "rb") as f:
        data = f.read()
    parts, offset = [], 0
    while len(parts) < 4:  # magic, width, height, scale
        while data[offset : offset + 1].isspace():
            offset += 1
        end = offset
        while not data[end : end + 1].isspace():
            end += 1
        parts.append(data[offset:end].decode())
        offset = end
    offset += 1  # the single whitespace after the scale
    width, height, scale = int(parts[1]), int(parts[2]), float(parts[3])
    channels = 3 if parts[0] == "PF" else 1
    pixels = array("f")
    pixels.frombytes(data[offset : offset + width * height * channels * 4])
    if (scale < 0) != (sys.byteorder == "little"):
        pixels.byteswap()
    return width, height, pixels


def image_errors(filename, reference):
    """RMSE and relative MSE (mean of (x - r)^2 / (r^2 + 0.01)) of an image."""
    width, height, pixels = read_pfm(filename)
    if (width, height) != reference[:2]:
        sys.exit(f"{filename}: size {width}x{height} differs from the reference")
    ref = reference[2]
    squared, relative = 0.0, 0.0
    for x, r in zip(pixels, ref):
        d = (x - r) * (x - r)
        squared += d
        relative += d / (r * r + 0.01)
    return math.sqrt(squared / len(ref)), relative / len(ref)


# -----------------------------------------------------------------------------
# SCENES AND REFERENCES
# -----------------------------------------------------------------------------


def generate_scene(yscene, path, arguments):
    """Generates a scene with `yscene hair ARGUMENTS` unless the scene there
    was generated with exactly these arguments (a stamp file beside it)."""
    stamp = os.path.join(os.path.dirname(path), "generated-with.txt")
    wanted = " ".join(arguments)
    if os.path.exists(path) and os.path.exists(stamp):
        with open(stamp) as f:
            if f.read().strip() == wanted:
                return path
    log(f"generating {os.path.relpath(path, ROOT)}: yscene hair {wanted}")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    run([yscene, "hair"] + arguments + ["--output", path])
    with open(stamp, "w") as f:
        f.write(wanted + "\n")
    return path


def scene_fingerprint(path, yscene):
    """What a cached reference depends on: the renderer (a digest of the yscene
    binary), the scene file and the sizes and modification times of the files
    it references (shapes, textures)."""
    with open(yscene, "rb") as f:
        parts = ["yscene:" + hashlib.sha1(f.read()).hexdigest()[:16]]
    directory = os.path.dirname(path)
    for sub in ("", "shapes", "textures"):
        folder = os.path.join(directory, sub)
        if not os.path.isdir(folder):
            continue
        for name in sorted(os.listdir(folder)):
            file = os.path.join(folder, name)
            if os.path.isfile(file) and not name.endswith(".txt"):
                info = os.stat(file)
                parts.append(f"{sub}/{name}:{info.st_size}:{int(info.st_mtime)}")
    return ";".join(parts)


def make_scenes(yscene):
    log("the thesis scenes (scripts/make_scenes.sh keeps existing ones)")
    run(["bash", "scripts/make_scenes.sh"])
    generate_scene(yscene, os.path.join(ROOT, SCENES[3][1]), HAIR_1M)


def scale_scene(yscene, strands):
    path = os.path.join(ROOT, f"out/bench/scenes/scale-{strands}/scale-{strands}.json")
    return generate_scene(yscene, path, ["--style", "straight", "--strands", str(strands),
                                         "--segments", "4"])


def reference_spp(name, config):
    return config["reference_spp"] * REFERENCE_FACTOR.get(name, 1)


def reference(yscene, name, path, config):
    """The converged reference of a scene: rendered once, then cached."""
    directory = os.path.join(ROOT, "out/bench/references")
    os.makedirs(directory, exist_ok=True)
    spp = reference_spp(name, config)
    stem = f"{name}-r{config['resolution']}-{spp}spp"
    image, meta = os.path.join(directory, stem + ".pfm"), os.path.join(directory, stem + ".json")
    fingerprint = scene_fingerprint(path, yscene)
    cached = os.path.exists(image) and os.path.exists(meta)
    if cached:
        with open(meta) as f:
            cached = json.load(f).get("scene_fingerprint") == fingerprint
    if not cached:
        log(f"{name}: rendering the reference at {spp} spp")
        load = load_average()
        output = run([yscene, "render", path, "--output", image, "--quiet", "--stats",
                      "--resolution", str(config["resolution"]),
                      "--samples", str(spp), "--seed", "1",
                      "--threads", "0"])
        stats = parse_fields([l for l in output.splitlines() if l.startswith("stats")][0])
        stats["load"] = load
        stats["scene_fingerprint"] = fingerprint
        with open(meta, "w") as f:
            json.dump(stats, f, indent=1)
    with open(meta) as f:
        return image, json.load(f)


# -----------------------------------------------------------------------------
# VARIANTS
# -----------------------------------------------------------------------------


def render_variant(yscene, name, path, variant, config, ref_image):
    """Renders one variant at 1, 2, 4, ... spp up to the time budget; returns
    one row per checkpoint."""
    vname, args, threads = variant
    directory = os.path.join(ROOT, "out/bench/runs", name)
    os.makedirs(directory, exist_ok=True)
    output = os.path.join(directory, vname + ".pfm")
    load = load_average()
    stdout = run([yscene, "render", path, "--output", output, "--quiet", "--stats",
                  "--checkpoints", "--time-budget", str(config["budget"]),
                  "--samples", str(reference_spp(name, config) // 8),
                  "--resolution", str(config["resolution"]),
                  "--threads", str(threads)] + args)
    load = (load + load_average()) / 2
    stats = parse_fields([l for l in stdout.splitlines() if l.startswith("stats")][0])
    reference_image = read_pfm(ref_image)
    rows = []
    pixels = stats["width"] * stats["height"]
    for line in stdout.splitlines():
        if not line.startswith("checkpoint"):
            continue
        point = parse_fields(line)
        rmse, rel_mse = image_errors(point["file"], reference_image)
        os.remove(point["file"])
        # One thread: CPU time; two threads: wall time (see the module doc).
        seconds = point["cpu_seconds"] if threads == 1 else point["seconds"]
        rows.append({
            "scene": name, "variant": vname, "threads": threads, "spp": int(point["spp"]),
            "seconds": seconds, "wall_seconds": point["seconds"],
            "cpu_seconds": point["cpu_seconds"], "rays": int(point["rays"]),
            "samples_per_s": pixels * point["spp"] / seconds,
            "rays_per_s": point["rays"] / seconds,
            "peak_memory": int(stats["peak_memory"]), "bvh_bytes": int(stats["bvh_bytes"]),
            "rmse": rmse, "rel_mse": rel_mse, "load": round(load, 2)})
    if os.path.exists(output):
        os.remove(output)
    log(f"{name} {vname}: {rows[-1]['spp']} spp in {rows[-1]['seconds']:.2f}s, "
        f"rmse {rows[-1]['rmse']:.4g} (load {load:.1f})")
    return rows


def fastest_runs(runs):
    """One row per checkpoint that every run reached: the run with the least
    time there (the renders are deterministic, so the errors are the same;
    interference from other jobs only adds time). The load is the mean."""
    spps = set.intersection(*[{r["spp"] for r in run} for run in runs])
    rows = []
    for spp in sorted(spps):
        candidates = [r for run in runs for r in run if r["spp"] == spp]
        best = dict(min(candidates, key=lambda r: r["seconds"]))
        best["runs"] = len(candidates)
        best["load"] = round(sum(r["load"] for r in candidates) / len(candidates), 2)
        rows.append(best)
    return rows


def time_to_error(rows, target):
    """Seconds to reach an RMSE, interpolated log-log between checkpoints; past
    the last one, extrapolated by the Monte Carlo law MSE ~ 1/t only if the last
    two checkpoints follow it (slope of log MSE against log t in [-1.3, -0.7]).
    Returns (seconds, extrapolated) or (None, False)."""
    points = [(r["seconds"], r["rmse"]) for r in rows if r["seconds"] > 0 and r["rmse"] > 0]
    for (t0, e0), (t1, e1) in zip(points, points[1:]):
        if e0 >= target >= e1 and e0 != e1:
            a = math.log(target / e0) / math.log(e1 / e0)
            return math.exp(math.log(t0) + a * math.log(t1 / t0)), False
    if points and points[0][1] <= target:
        return points[0][0], False
    if len(points) >= 2:
        (t0, e0), (t1, e1) = points[-2], points[-1]
        slope = 2 * math.log(e1 / e0) / math.log(t1 / t0)
        if -1.3 <= slope <= -0.7:
            return t1 * (e1 / target) ** 2, True
    return None, False


# -----------------------------------------------------------------------------
# THE LIMIT, SCALE AND POW
# -----------------------------------------------------------------------------


def measure_limit(yscene, name, path, config):
    """Renderer rays/s against Embree alone on the same rays, median of runs
    (one run for the 1M scene: its BVH build dominates; yscene itself takes the
    median of three replays)."""
    rows = []
    for _ in range(1 if name == "straight-1m" else config["repeats"]):
        load = load_average()
        stdout = run([yscene, "render", path, "--output", "/tmp/unused.pfm", "--quiet",
                      "--embree-only", "--stats", "--threads", "1",
                      "--resolution", str(config["resolution"]),
                      "--samples", str(config["limit_spp"])])
        s = parse_fields([l for l in stdout.splitlines() if l.startswith("stats")][0])
        rows.append({"scene": name, "rays": int(s["rays"]),
                     "renderer_rays_per_s": s["rays"] / s["render_cpu"],
                     "embree_rays_per_s": s["rays"] / s["embree_cpu"],
                     "ratio": s["embree_cpu"] / s["render_cpu"], "load": load})
    rows.sort(key=lambda r: r["ratio"])
    median = rows[len(rows) // 2]
    log(f"{name}: renderer/embree {median['ratio']:.3f}")
    return median


def measure_scale(yscene, config):
    rows = []
    for strands in config["scale_strands"]:
        path = scale_scene(yscene, strands)
        for geometry, args in [("native", []), ("native-compact", ["--bvh-compact"]),
                               ("lines-4", ["--curves", "lines", "--segments", "4"])]:
            load = load_average()
            stdout = run([yscene, "render", path, "--output", "/tmp/unused.pfm", "--quiet",
                          "--stats", "--threads", "1", "--resolution",
                          str(config["resolution"]), "--samples", str(config["scale_spp"])] + args)
            s = parse_fields([l for l in stdout.splitlines() if l.startswith("stats")][0])
            rows.append({"strands": strands, "geometry": geometry,
                         "segments": int(s["segments"]), "bvh_seconds": s["bvh_seconds"],
                         "bvh_bytes": int(s["bvh_bytes"]),
                         "bytes_per_segment": s["bvh_bytes"] / s["segments"],
                         "spp": int(s["spp"]), "render_cpu": s["render_cpu"],
                         "peak_memory": int(s["peak_memory"]), "load": load})
            log(f"scale {strands} {geometry}: bvh {s['bvh_seconds']:.2f}s "
                f"{s['bvh_bytes'] / s['segments']:.0f} B/segment, render {s['render_cpu']:.2f}s")
    return rows


def measure_pow(config):
    """The micro-benchmark of the fast integer power (tests/bench_pow.cpp)."""
    binary = os.path.join(ROOT, config["build"], "tests", "bench_pow")
    if not os.path.exists(binary):
        log(f"{binary} not built: skipping the pow micro-benchmark")
        return []
    stdout = run([binary, "--benchmark_format=json", "--benchmark_repetitions=5",
                  "--benchmark_report_aggregates_only=true"])
    rows = []
    for b in json.loads(stdout)["benchmarks"]:
        if b.get("aggregate_name") == "median":
            rows.append({"benchmark": b["run_name"], "ns": b["cpu_time"]})
    return rows


# -----------------------------------------------------------------------------
# REPORT
# -----------------------------------------------------------------------------


def read_csv(filename):
    """Rows of a CSV written by write_csv, numbers converted back."""
    def convert(value):
        for kind in (int, float):
            try:
                return kind(value)
            except ValueError:
                pass
        return value
    with open(filename, newline="") as f:
        return [{k: convert(v) for k, v in row.items()} for row in csv.DictReader(f)]


def write_csv(filename, rows):
    with open(filename, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v)
                             for k, v in row.items()})


def plot(out, name, rows, target):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log("matplotlib missing (apt-get install python3-matplotlib): no plots")
        return None
    figure, axes = plt.subplots(figsize=(7, 5))
    for variant in dict.fromkeys(r["variant"] for r in rows):
        points = [(r["seconds"], r["rmse"]) for r in rows if r["variant"] == variant]
        label = variant + (" (wall)" if variant.endswith("2t") else "")
        axes.plot(*zip(*points), marker="o", markersize=3, label=label)
    axes.axhline(target, color="gray", linestyle=":", linewidth=1, label="fixed RMSE")
    axes.set_xscale("log")
    axes.set_yscale("log")
    axes.set_xlabel("render time (s; CPU time on 1 thread, wall time on 2)")
    axes.set_ylabel("RMSE against the reference")
    axes.set_title(f"{name}: error against time")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8)
    filename = f"error_{name}.png"
    figure.tight_layout()
    figure.savefig(os.path.join(out, filename), dpi=100)
    plt.close(figure)
    return filename


def fmt(value, digits=3):
    return "–" if value is None else f"{value:.{digits}g}"


def write_report(out, config, results, limits, scales, pows, plots, command):
    lines = ["# Speed against error", "",
             f"Generated by `{command}` on {time.strftime('%Y-%m-%d %H:%M')} "
             f"({os.cpu_count()} cores, shared: load averages recorded per measurement). "
             "Do not edit: rerun the command.", "",
             f"Images {config['resolution']} pixels on the largest side; references at "
             "the spp given below (seed 1, all threads); every variant renders at 1, 2, 4, "
             "... spp up to an eighth of the reference's spp (so that the reference's own "
             "noise stays below a ninth of the measured MSE), or stops earlier, at the first "
             f"power of two reached after {config['budget']} s. Every variant runs "
             f"{config['runs']} time(s), the variant order reversed on every other run; "
             "each checkpoint keeps the fastest run (the renders are deterministic, so "
             "only the time differs). Times are render CPU seconds "
             "for one-thread variants and wall seconds for `path-2t`; loading and the BVH "
             "build are not included. Geometry variants (`lines-N`, `flat`) are compared "
             "with the native-curve reference, so their error includes the geometric "
             "difference and stops falling where it dominates.", "",
             "Variants: `path` = path tracing with MIS (light and BSDF sampling), native "
             "round Bezier curves, two random numbers demuxed into four (Morton), hair "
             "material terms once per material; `naive` = BSDF sampling only; `lines-N` = "
             "N line segments per Bezier segment; `flat` = ray-facing flat curves; "
             "`four-numbers` = four independent numbers instead of the demux; `per-hit` = "
             "the hair material terms (with its two std::pow calls) computed at every hit "
             "as the thesis did; `per-hit-fast-pow` = the same with the fast integer power "
             "instead of std::pow; `path-2t` = `path` on two threads.", ""]
    for name, data in results.items():
        rows, target, ref_meta = data["rows"], data["target"], data["reference"]
        lines += [f"## {name}", ""]
        if name in plots and plots[name]:
            lines += [f"![{name}]({plots[name]})", ""]
        lines += [f"Reference: {int(ref_meta['spp'])} spp ({ref_meta['render_seconds']:.0f} s "
                  f"wall, load {ref_meta['load']:.1f}). Fixed RMSE = {target:.4g} (what `path` "
                  f"reaches at {config['target_spp']} spp).", "",
                  "| variant | time to fixed RMSE (s) | efficiency 1/(MSE·s) | last spp | "
                  "RMSE | relMSE | samples/s | rays/s | peak memory (MB) | load |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        by_variant = {}
        for r in rows:
            by_variant.setdefault(r["variant"], []).append(r)
        for variant, vrows in by_variant.items():
            last = vrows[-1]
            seconds, extrapolated = time_to_error(vrows, target)
            efficiency = 1 / (last["rmse"] ** 2 * last["seconds"])
            lines.append(
                f"| {variant} | {('~' if extrapolated else '') + fmt(seconds)} | "
                f"{fmt(efficiency)} | {last['spp']} | {last['rmse']:.4g} | "
                f"{last['rel_mse']:.4g} | {last['samples_per_s'] / 1e3:.1f}k | "
                f"{last['rays_per_s'] / 1e3:.0f}k | {last['peak_memory'] / 2**20:.0f} | "
                f"{last['load']:.1f} |")
        lines.append("")
    lines += ["## Summary per scene", "",
              "Best variant = the one-thread variant with the shortest time to the fixed RMSE "
              "(`~`: extrapolated by MSE ~ 1/t); `path` and `path-2t` are given beside it. "
              "Scaling = samples/s of `path-2t` (wall time) over `path` (one thread, "
              "CPU time): the speed-up over one uncontended core, which other jobs on the "
              "machine lower (see the load column). "
              "Renderer/Embree = the renderer's rays/s over Embree's rays/s casting the same "
              "rays without shading (one thread, CPU time, median of "
              f"{config['repeats']}). Bytes per segment = Embree's memory over the fiber "
              "segments (native curves).", "",
              "| scene | fixed RMSE | best variant | its time (s) | `path` (s) | `path-2t` (s) | "
              "renderer / Embree | 2-thread scaling | bytes per segment |",
              "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for name, data in results.items():
        rows = data["rows"]
        best, times = None, {}
        for variant in dict.fromkeys(r["variant"] for r in rows):
            vrows = [r for r in rows if r["variant"] == variant]
            seconds, extrapolated = time_to_error(vrows, data["target"])
            times[variant] = ("~" if extrapolated else "") + fmt(seconds)
            if vrows[0]["threads"] != 1:
                continue
            if seconds is not None and (best is None or seconds < best[1]):
                best = (variant, seconds, extrapolated)
        one = [r for r in rows if r["variant"] == "path"][-1]
        two = [r for r in rows if r["variant"] == "path-2t"]
        scaling = two[-1]["samples_per_s"] / one["samples_per_s"] if two else None
        limit = limits.get(name)
        lines.append(
            f"| {name} | {data['target']:.4g} | {best[0] if best else '–'} | "
            f"{(('~' if best[2] else '') + fmt(best[1])) if best else '–'} | "
            f"{times.get('path', '–')} | {times.get('path-2t', '–')} | "
            f"{fmt(limit['ratio'] if limit else None, 2)} | {fmt(scaling, 2)} | "
            f"{one['bvh_bytes'] / data['segments']:.0f} |")
    lines += ["", "## The limit: Embree alone", "",
              "`yscene render SCENE --embree-only` renders, records every ray of the same "
              "render (camera, bounce and shadow rays; the render is deterministic) and casts "
              "them through `intersect_scene_bvh` / `intersect_scene_bvh_any` without shading. "
              f"{config['limit_spp']} spp, one thread, CPU time.", "",
              "| scene | rays | renderer rays/s | Embree rays/s | renderer / Embree | "
              "shading share | load |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in limits.items():
        lines.append(f"| {name} | {r['rays']} | {r['renderer_rays_per_s'] / 1e3:.0f}k | "
                     f"{r['embree_rays_per_s'] / 1e3:.0f}k | {r['ratio']:.2f} | "
                     f"{100 * (1 - r['ratio']):.0f}% | {r['load']:.1f} |")
    lines += ["", "## Scale", "",
              "Straight hair, 4 Bezier segments per strand: native curves, native curves in "
              "Embree's compact BVH (`--bvh-compact`) and 4 line segments per curve "
              "(`--curves lines --segments 4`; bytes per line segment). BVH build on all threads "
              f"(wall), render {config['scale_spp']} spp on one thread (CPU).", "",
              "| strands | geometry | segments | BVH build (s) | BVH memory (MB) | bytes per "
              "segment | render (s) | peak memory (MB) | load |",
              "|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in scales:
        lines.append(f"| {r['strands']} | {r['geometry']} | {r['segments']} | "
                     f"{r['bvh_seconds']:.2f} | {r['bvh_bytes'] / 2**20:.1f} | "
                     f"{r['bytes_per_segment']:.0f} | {r['render_cpu']:.2f} | "
                     f"{r['peak_memory'] / 2**20:.0f} | {r['load']:.1f} |")
    if pows:
        lines += ["", "## The fast integer power", "",
                  "`tests/bench_pow.cpp`, median of 5 repetitions. The hair library calls "
                  "`std::pow(beta, 20)` and `std::pow(beta, 22)` in `make_hair_precomputed`, "
                  "once per material per render; only the `per-hit` variants (the thesis's "
                  "layout) pay them at every hit, `per-hit-fast-pow` with the fast power "
                  "(`--hair-fast-pow`).", "",
                  "| benchmark | ns per call |", "|---|---:|"]
        for r in pows:
            if "agreement" in r["benchmark"]:
                continue  # a correctness check, not a timing
            lines.append(f"| {r['benchmark']} | {r['ns']:.2f} |")
    lines.append("")
    with open(os.path.join(out, "README.md"), "w") as f:
        f.write("\n".join(lines))


# -----------------------------------------------------------------------------
# MAIN
# -----------------------------------------------------------------------------


def report_only(out, config, command):
    """The report and plots again from the CSVs (and cached reference data)."""
    all_rows = read_csv(os.path.join(out, "results.csv"))
    limits = {r["scene"]: r for r in read_csv(os.path.join(out, "limit.csv"))}
    scales = read_csv(os.path.join(out, "scale.csv"))
    pow_file = os.path.join(out, "pow.csv")
    pows = read_csv(pow_file) if os.path.exists(pow_file) else measure_pow(config)
    if pows and not os.path.exists(pow_file):
        write_csv(pow_file, pows)
    results, plots = {}, {}
    for name in dict.fromkeys(r["scene"] for r in all_rows):
        rows = [r for r in all_rows if r["scene"] == name]
        stem = f"{name}-r{config['resolution']}-{reference_spp(name, config)}spp.json"
        with open(os.path.join(ROOT, "out/bench/references", stem)) as f:
            ref_meta = json.load(f)
        path_rows = [r for r in rows if r["variant"] == "path"]
        at = [r for r in path_rows if r["spp"] <= config["target_spp"]]
        target = (at or path_rows)[-1]["rmse"]
        results[name] = {"rows": rows, "target": target, "reference": ref_meta,
                         "segments": int(ref_meta["segments"])}
        plots[name] = plot(out, name, rows, target)
    write_report(out, config, results, limits, scales, pows, plots, command)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="small images and budgets, no 1M-strand scene (a few minutes)")
    parser.add_argument("--build", default="build", help="build directory (default build)")
    parser.add_argument("--out", default="",
                        help="report directory (default docs/benchmark, out/bench/quick-report "
                        "with --quick)")
    parser.add_argument("--scenes", nargs="*", help="only these scenes")
    parser.add_argument("--report-only", action="store_true",
                        help="rewrite the report and plots from the CSVs of the last run")
    args = parser.parse_args()
    yscene = os.path.join(ROOT, args.build, "apps", "yscene")
    if not os.path.exists(yscene):
        sys.exit(f"{yscene} not found: build first (bash scripts/setup.sh)")
    if args.quick:
        config = {"resolution": 64, "reference_spp": 256, "budget": 0.5, "target_spp": 4,
                  "limit_spp": 2, "repeats": 3, "scale_strands": [10000, 100000],
                  "scale_spp": 2, "scenes": 3, "runs": 1}
    else:
        config = {"resolution": 160, "reference_spp": 256, "budget": 8, "target_spp": 8,
                  "limit_spp": 2, "repeats": 3, "scale_strands": SCALE_STRANDS,
                  "scale_spp": 4, "scenes": 4, "runs": 2}
    config["build"] = args.build
    # A quick run never overwrites the committed report.
    out = os.path.join(ROOT, args.out or ("out/bench/quick-report" if args.quick
                                          else "docs/benchmark"))
    os.makedirs(out, exist_ok=True)
    command = "bash scripts/bench/run.sh" + (" --quick" if args.quick else "")
    start = time.time()

    if args.report_only:
        report_only(out, config, command)
        return
    make_scenes(yscene)
    scenes = SCENES[: config["scenes"]]
    if args.scenes:
        scenes = [s for s in scenes if s[0] in args.scenes]
    results, limits, plots, all_rows = {}, {}, {}, []
    for name, path in scenes:
        ref_image, ref_meta = reference(yscene, name, path, config)
        variants = [v for v in VARIANTS
                    if name != "straight-1m" or v[0] in VARIANTS_1M]
        # Every variant runs config["runs"] times, the order reversed on every
        # other run, so that a slow spell of the shared machine or the order
        # itself does not favour one variant; fastest_runs keeps the fastest.
        runs = {v[0]: [] for v in variants}
        for run_index in range(config["runs"]):
            for variant in (variants if run_index % 2 == 0 else variants[::-1]):
                runs[variant[0]].append(
                    render_variant(yscene, name, path, variant, config, ref_image))
        rows = []
        for variant in variants:
            rows += fastest_runs(runs[variant[0]])
        path_rows = [r for r in rows if r["variant"] == "path"]
        at = [r for r in path_rows if r["spp"] <= config["target_spp"]]
        target = (at or path_rows)[-1]["rmse"]
        segments = int(ref_meta["segments"])
        results[name] = {"rows": rows, "target": target, "reference": ref_meta,
                         "segments": segments}
        limits[name] = measure_limit(yscene, name, path, config)
        plots[name] = plot(out, name, rows, target)
        all_rows += rows
    scales = measure_scale(yscene, config)
    pows = measure_pow(config)

    write_csv(os.path.join(out, "results.csv"), all_rows)
    write_csv(os.path.join(out, "limit.csv"), list(limits.values()))
    write_csv(os.path.join(out, "scale.csv"), scales)
    if pows:
        write_csv(os.path.join(out, "pow.csv"), pows)
    write_report(out, config, results, limits, scales, pows, plots, command)
    log(f"done in {time.time() - start:.0f}s: {os.path.relpath(out, ROOT)}/README.md")


if __name__ == "__main__":
    main()
