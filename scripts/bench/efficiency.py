#!/usr/bin/env python3
"""Efficiency before and after: the same scenes rendered by two yscene binaries.

    python3 scripts/bench/efficiency.py --before OLD/yscene [--after build/apps/yscene]
        [--quick] [--scenes fur hair-locks ...] [--runs 3]

For every scene, references are rendered by both binaries with their default
settings, each as four independent renders (seeds 101-104 and 201-204) whose
spread gives the references' own per-pixel noise. The two references must
agree in expectation: the report gives the ratio of their squared difference
to the sum of their noise (about 1 when they agree, far above 1 when one is
biased) and the difference of their means in standard errors. The error of a
variant is its MSE against the mean of the two references minus the
references' own noise (so that it is the variant's alone); its efficiency is
1 / (MSE * CPU seconds) at 16, 64 and 256 spp (each its own render), where CPU seconds are the
render's CPU time (all threads, loading and BVH build excluded), the median
of --runs runs. Variants render on --threads threads (2: the machine).

Writes docs/benchmark/efficiency.md and efficiency.csv (or --out). Renders and
references are cached in out/bench/efficiency/, keyed by the binary's hash.
"""

import argparse
import csv
import hashlib
import math
import os
import statistics
import sys
import time
from array import array

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from run_bench import ROOT, log, parse_fields, read_pfm, run, load_average  # noqa: E402

# name, how the scene is made (yscene hair arguments, or a path in the tree),
# resolution. The fur ball is issue 11's: 20,000 straight strands on a grey
# sphere under a white constant sky.
SCENES = {
    "fur": (["--style", "fur", "--strands", "20000"], 256),
    "hair-locks": ("scenes/hair-locks/hair-locks.json", 192),
    "straight-hair": ("scenes/straight-hair/straight-hair.json", 128),
    "curly-hair": ("scenes/curly-hair/curly-hair.json", 128),
}

# name, binary ("before" or "after"), yscene render arguments. `before` is
# the previous default; each `after-...` variant turns one lever of the new
# default back (or changes the hair's random numbers, for the thesis's claim).
VARIANTS = [
    ("before", "before", []),
    ("after", "after", []),
    ("after-independent", "after", ["--sequence", "independent"]),
    ("after-roulette-1", "after", ["--roulette-threshold", "1"]),
    ("after-mixture-weight", "after", ["--hair-mixture-weight"]),
    ("after-lights-all", "after", ["--lights", "all"]),
    ("after-whole-curves", "after", ["--curve-pieces", "1"]),
    ("after-shadow-0", "after", ["--shadow-threshold", "0"]),
    ("after-split-1", "after", ["--split", "1"]),
    ("after-split-2", "after", ["--split", "2"]),
    ("after-no-adaptive", "after", ["--no-adaptive"]),
    ("after-no-roulette-cache", "after", ["--no-roulette-cache"]),
    ("after-roulette-bounce-1", "after", ["--roulette-bounce", "1"]),
    ("after-sobol-pairs", "after", ["--sequence", "sobol"]),
    ("after-demux", "after", ["--hair-demux"]),
    ("after-demux-independent", "after", ["--hair-demux", "--sequence", "independent"]),
]
# The two defaults are timed --headline-runs times, the levers --runs times.
HEADLINE = ["before", "after"]
# What each lever is, as the variant that turns it back (or, for the
# choices, the variant that always takes the other side: below 1, the
# choice paid).
LEVERS = [
    ("Sobol numbers (against independent ones)", "after-independent"),
    ("one global Sobol point (against shuffled Sobol pairs)", "after-sobol-pairs"),
    ("hair sampled with four numbers (against two demuxed into four)", "after-demux"),
    ("roulette threshold from the pilot (against 1, the previous roulette)", "after-roulette-1"),
    ("roulette by region and direction (against the pilot's one threshold)",
     "after-no-roulette-cache"),
    ("roulette from the first vertex (against from the second)", "after-roulette-bounce-1"),
    ("hair lobe weights where no MIS needs the pdf (against eval / pdf)", "after-mixture-weight"),
    ("light choice: constant sky to BSDF sampling, MIS compensation", "after-lights-all"),
    ("bent curves in exact pieces", "after-whole-curves"),
    ("shadow-ray roulette", "after-shadow-0"),
    ("each pixel's own split (against 1 path per camera ray, the rates still planned)",
     "after-split-1"),
    ("each pixel's own split (against 2 paths per camera ray everywhere)", "after-split-2"),
    ("the per-pixel plan, rates and splits (against uniform sampling)", "after-no-adaptive"),
]
CHECKPOINTS = [16, 64, 256]


def file_hash(path):
    with open(path, "rb") as f:
        return hashlib.sha1(f.read()).hexdigest()[:12]


def scene_path(name, yscene):
    how, _ = SCENES[name]
    if isinstance(how, str):
        return how
    path = f"out/bench/efficiency/scenes/{name}/{name}.json"
    if not os.path.exists(os.path.join(ROOT, path)):
        os.makedirs(os.path.dirname(os.path.join(ROOT, path)), exist_ok=True)
        run([yscene, "hair"] + how + ["--output", path])
    return path


def render(binary, scene, output, spp, resolution, seed, threads, args):
    """Renders and returns the stats fields."""
    stdout = run([binary, "render", scene, "--output", output, "--quiet", "--stats",
                  "--samples", str(spp), "--resolution", str(resolution), "--seed", str(seed),
                  "--threads", str(threads), "--bounces", "31", "--clamp", "0"] + args)
    stats = [parse_fields(line) for line in stdout.splitlines() if line.startswith("stats")]
    return stats[0]


def reference(binary, tag, name, scene, resolution, spp, seeds, threads, cache):
    """Mean image and per-pixel variance of that mean, from len(seeds) renders."""
    images = []
    for seed in seeds:
        output = os.path.join(cache, f"ref-{name}-{tag}-{resolution}-{spp}-{seed}.pfm")
        if not os.path.exists(output):
            log(f"  reference {name} {tag} seed {seed}: {spp} spp")
            render(binary, scene, output, spp, resolution, seed, threads, [])
        images.append(read_pfm(output))
    width, height = images[0][:2]
    count = len(images)
    mean, variance = array("d"), array("d")
    for values in zip(*[image[2] for image in images]):
        m = sum(values) / count
        mean.append(m)
        variance.append(sum((v - m) ** 2 for v in values) / (count - 1) / count)
    means = [sum(image[2]) / len(image[2]) for image in images]
    return {"size": (width, height), "mean": mean, "variance": variance, "means": means}


def compare_references(a, b):
    """Squared difference over summed noise, and the mean difference in standard errors."""
    squared = sum((x - y) ** 2 for x, y in zip(a["mean"], b["mean"]))
    noise = sum(a["variance"]) + sum(b["variance"])
    mean_a, mean_b = statistics.mean(a["means"]), statistics.mean(b["means"])
    se = math.sqrt(statistics.variance(a["means"]) / len(a["means"]) +
                   statistics.variance(b["means"]) / len(b["means"]))
    return squared / noise, (mean_a - mean_b) / se if se > 0 else 0.0, mean_a, mean_b


def variant_mse(filename, truth, truth_noise):
    width, height, pixels = read_pfm(filename)
    if (width, height) != truth["size"]:
        sys.exit(f"{filename}: size differs from the reference")
    squared = sum((x - r) ** 2 for x, r in zip(pixels, truth["mean"]))
    return squared / len(pixels) - truth_noise


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", required=True, help="yscene binary of the old default")
    parser.add_argument("--after", default="build/apps/yscene")
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--variants", nargs="*", default=[v[0] for v in VARIANTS])
    parser.add_argument("--reference-spp", type=int, default=1024,
                        help="spp of each reference (four renders of a quarter each)")
    parser.add_argument("--runs", type=int, default=1, help="timed runs per variant (median)")
    parser.add_argument("--headline-runs", type=int, default=3,
                        help="timed runs of `before` and `after` (median)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--quick", action="store_true",
                        help="quarter resolution, 256-spp references, one run")
    parser.add_argument("--resolution-scale", type=float, default=1,
                        help="scale of every scene's resolution")
    parser.add_argument("--out", default="docs/benchmark")
    parser.add_argument("--before-reference-only", action="store_true",
                        help="score against the before binary's reference alone (for quick "
                        "iterations: the after binary's reference is not rendered)")
    parser.add_argument("--reference-binary", default="",
                        help="with --before-reference-only: score against the cached reference "
                        "of this binary instead of --before's (the same image in expectation)")
    parser.add_argument("--commits", default="", help="'BEFORE AFTER' commit ids for the report")
    parser.add_argument("--report-only", action="store_true",
                        help="rewrite the report from --out's efficiency.csv, rendering nothing "
                        "(give the arguments of the run that wrote it)")
    args = parser.parse_args()
    if args.reference_binary and not args.before_reference_only:
        sys.exit("--reference-binary needs --before-reference-only")
    if args.report_only:
        with open(os.path.join(ROOT, args.out, "efficiency.csv"), newline="") as f:
            rows = [{k: (v if k in ("scene", "variant", "runs") else
                         int(v) if k == "spp" else float(v)) for k, v in row.items()}
                    for row in csv.DictReader(f)]
        binaries = {"before": args.before, "after": args.after}
        if args.reference_binary:
            binaries["reference"] = args.reference_binary
        write_report(args, rows, [], {k: file_hash(v) for k, v in binaries.items()})
        return
    if args.quick:
        args.reference_spp, args.runs, args.headline_runs = 256, 1, 1
    binaries = {"before": os.path.abspath(args.before), "after": os.path.abspath(args.after)}
    hashes = {k: file_hash(v) for k, v in binaries.items()}
    # Who made each reference: the binaries, or --reference-binary for `before`'s.
    makers, maker_hashes = dict(binaries), dict(hashes)
    if args.reference_binary:
        makers["before"] = os.path.abspath(args.reference_binary)
        maker_hashes["before"] = hashes["reference"] = file_hash(makers["before"])
    cache = os.path.join(ROOT, "out/bench/efficiency")
    os.makedirs(cache, exist_ok=True)
    os.chdir(ROOT)

    rows, checks = [], []
    for name in args.scenes:
        scene = scene_path(name, binaries["after"])
        resolution = int(SCENES[name][1] * args.resolution_scale) // (4 if args.quick else 1)
        log(f"{name}: references at {resolution} px")
        quarter = args.reference_spp // 4
        tags = ["before"] if args.before_reference_only else ["before", "after"]
        refs = {tag: reference(makers[tag], maker_hashes[tag], name, scene, resolution,
                               quarter, [seed + 100 * (i + 1) for seed in range(1, 5)], 0, cache)
                for i, tag in enumerate(tags)}
        if args.before_reference_only:
            truth = refs["before"]
            truth_noise = sum(truth["variance"]) / len(truth["mean"])
        else:
            ratio, z, mean_before, mean_after = compare_references(refs["before"], refs["after"])
            checks.append({"scene": name, "resolution": resolution, "ratio": ratio, "z": z,
                           "mean_before": mean_before, "mean_after": mean_after})
            truth = {"size": refs["before"]["size"],
                     "mean": array("d", [(x + y) / 2 for x, y in zip(refs["before"]["mean"],
                                                                      refs["after"]["mean"])])}
            truth_noise = (sum(refs["before"]["variance"]) +
                           sum(refs["after"]["variance"])) / 4 / len(truth["mean"])
        for variant, tag, flags in VARIANTS:
            if variant not in args.variants:
                continue
            times = {spp: [] for spp in CHECKPOINTS}
            outputs = {spp: os.path.join(cache, f"{name}-{variant}-{hashes[tag]}-{resolution}-"
                                         f"{spp:05d}spp.pfm") for spp in CHECKPOINTS}
            # One render per sample count (not checkpoints of the longest):
            # adaptive sampling plans its rates, and whether to use them, for
            # the render's sample count.
            for r in range(args.headline_runs if variant in HEADLINE else args.runs):
                for spp in CHECKPOINTS:
                    stats = render(binaries[tag], scene, outputs[spp], spp, resolution, 1,
                                   args.threads, flags)
                    times[spp].append(stats["render_cpu"])
            for spp in CHECKPOINTS:
                mse = variant_mse(outputs[spp], truth, truth_noise)
                cpu = statistics.median(times[spp])
                rows.append({"scene": name, "variant": variant, "spp": spp, "mse": mse,
                             "cpu_seconds": cpu, "cpu_per_spp": cpu / spp,
                             "efficiency": 1 / (mse * cpu) if mse > 0 else float("inf"),
                             "runs": " ".join(f"{t:.3f}" for t in times[spp]),
                             "load": load_average()})
            log(f"  {variant}: " + ", ".join(
                f"{r['spp']} spp mse {r['mse']:.3g} cpu {r['cpu_seconds']:.2f}"
                for r in rows if r["scene"] == name and r["variant"] == variant))
    write_report(args, rows, checks, hashes)


def equal_cpu_gain(table, name, spp):
    """The before render's MSE over the after binary's at the same CPU-s (see the report)."""
    if (name, "before", spp) not in table:
        return ""
    points = sorted((math.log(r["cpu_seconds"]), math.log(r["mse"]))
                    for k, r in table.items()
                    if k[0] == name and k[1] == "after" and r["mse"] > 0 and r["cpu_seconds"] > 0)
    if len(points) < 2 or table[(name, "before", spp)]["mse"] <= 0:
        return ""
    before = table[(name, "before", spp)]
    x = math.log(before["cpu_seconds"])
    inside = points[0][0] <= x <= points[-1][0]
    segment = 0
    while segment < len(points) - 2 and x > points[segment + 1][0]:
        segment += 1
    (x0, y0), (x1, y1) = points[segment], points[segment + 1]
    mse = math.exp(y0 + (y1 - y0) * (x - x0) / (x1 - x0)) if x1 > x0 else math.exp(y0)
    return f"{before['mse'] / mse:.2f} ({before['cpu_seconds']:.1f}){'' if inside else '*'}"


def write_report(args, rows, checks, hashes):
    out = os.path.join(ROOT, args.out)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "efficiency.csv"), "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    base = {(r["scene"], r["spp"]): r for r in rows if r["variant"] == "before"}
    lines = ["# Efficiency before and after", "",
             f"Generated by `python3 scripts/bench/efficiency.py --before OLD/yscene"
             f"{' --quick' if args.quick else ''}"
             f"{' --before-reference-only' if args.before_reference_only else ''}"
             f"{' --reference-binary REF/yscene' if args.reference_binary else ''}"
             f"{' --variants ' + ' '.join(args.variants) if len(args.variants) < len(VARIANTS) else ''}` on {time.strftime('%Y-%m-%d %H:%M')} "
             f"(2 cores; the load average is in efficiency.csv). Do not edit: rerun the command.",
             "", f"Binaries: before = {args.commits.split()[0] if args.commits else hashes['before']}, "
             f"after = {args.commits.split()[1] if args.commits else hashes['after']}. "
             f"Every render: 31 bounces, no clamp, seed 1, {args.threads} threads; CPU seconds "
             f"of the render (all threads, load and BVH build excluded), median of "
             f"{args.headline_runs} runs for `before` and `after`, {args.runs} for the others. MSE against "
             + ((f"the reference of an earlier binary ({hashes['reference']})"
                 if args.reference_binary else "the `before` binary's reference")
                if args.before_reference_only else "the mean of both binaries' references")
             + f" ({args.reference_spp} spp each, as four renders of different seeds), minus the "
             "references' own noise. Efficiency = 1 / (MSE · CPU-s); the ratio is against "
             "`before` at the same spp.", "",
             "## The image is unchanged in expectation", ""]
    if checks:
        lines += ["| scene | pixels | mean before | mean after | difference (standard errors) | "
                  "squared difference / summed noise |", "|---|---:|---:|---:|---:|---:|"]
        for c in checks:
            lines.append(f"| {c['scene']} | {c['resolution']} | {c['mean_before']:.5f} | "
                         f"{c['mean_after']:.5f} | {c['z']:+.2f} | {c['ratio']:.3f} |")
        lines += ["", "A ratio near 1 means the two references differ by their noise alone.", ""]
    else:
        lines += ["Not checked in this run (`--before-reference-only`: the `after` binary's "
                  "reference was not rendered).", ""]
    table = {(r["scene"], r["variant"], r["spp"]): r for r in rows}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))

    def gain(scene, a, b, spp):
        if (scene, a, spp) in table and (scene, b, spp) in table:
            return f"{table[(scene, a, spp)]['efficiency'] / table[(scene, b, spp)]['efficiency']:.2f}"
        return ""
    lines += ["## Summary: efficiency of the new default over the previous one", "",
              "| scene | 16 spp | 64 spp | 256 spp | CPU-s per spp before → after (64 spp) |",
              "|---|---:|---:|---:|---:|"]
    for name in scenes:
        cpu = ""
        if (name, "before", 64) in table and (name, "after", 64) in table:
            cpu = (f"{table[(name, 'before', 64)]['cpu_per_spp']:.3f} → "
                   f"{table[(name, 'after', 64)]['cpu_per_spp']:.3f}")
        lines.append(f"| {name} | " + " | ".join(gain(name, "after", "before", spp)
                                                 for spp in CHECKPOINTS) + f" | {cpu} |")
    lines += ["", "## At equal CPU", "",
              "A default that spends more CPU at the same `--samples` gains from its budget "
              "alone (every estimator's efficiency grows with it under Sobol points). Here the "
              "`after` binary's MSE at the `before` render's CPU-s, interpolated on log MSE "
              "against log CPU-s between its own 16, 64 and 256-spp renders (* extrapolated "
              "from the nearest two), over the `before` render's MSE: above 1 the new "
              "default is more efficient at the same CPU.", "",
              "| scene | 64 spp (before's CPU-s) | 256 spp (before's CPU-s) |", "|---|---:|---:|"]
    for name in scenes:
        cells = [equal_cpu_gain(table, name, spp) for spp in (64, 256)]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "## Each lever's share at 64 spp", "",
              "Efficiency of the new default over the default with one lever turned back "
              "(above 1: the lever pays).", "",
              "| lever | " + " | ".join(scenes) + " |", "|---|" + "---:|" * len(scenes)]
    for label, variant in LEVERS:
        if variant not in args.variants:
            continue
        lines.append(f"| {label} (`{variant}`) | " +
                     " | ".join(gain(name, "after", variant, 64) for name in scenes) + " |")
    demux = ["after-demux", "after", "after-demux-independent", "after-independent"]
    demux_rows = [(name, spp, [table.get((name, v, spp)) for v in demux])
                  for name in scenes for spp in CHECKPOINTS]
    demux_rows = [row for row in demux_rows if all(row[2])]
    # The thesis's claim only when its variants were run.
    if demux_rows:
        lines += ["", "## The thesis's claim: two Sobol numbers demuxed into four", "",
                  "MSE of the hair's direction sampled from two numbers demuxed into four (the "
                  "thesis's), from four Sobol dimensions (the default), and from independent "
                  "numbers everywhere (where the demux has nothing to preserve).", "",
                  "| scene | spp | demux, Sobol | four Sobol | demux, independent | four independent |",
                  "|---|---:|---:|---:|---:|---:|"]
        for name, spp, values in demux_rows:
            lines.append(f"| {name} | {spp} | " +
                         " | ".join(f"{v['mse']:.4g}" for v in values) + " |")
    lines.append("")
    for name in dict.fromkeys(r["scene"] for r in rows):
        lines += [f"## {name}", "",
                  "| variant | spp | CPU-s per spp | MSE | efficiency | × before |",
                  "|---|---:|---:|---:|---:|---:|"]
        for r in rows:
            if r["scene"] != name:
                continue
            b = base.get((name, r["spp"]))
            gain = f"{r['efficiency'] / b['efficiency']:.2f}" if b else ""
            lines.append(f"| {r['variant']} | {r['spp']} | {r['cpu_per_spp']:.4f} | "
                         f"{r['mse']:.4g} | {r['efficiency']:.4g} | {gain} |")
        lines.append("")
    with open(os.path.join(out, "efficiency.md"), "w") as f:
        f.write("\n".join(lines))
    log(f"wrote {os.path.join(args.out, 'efficiency.md')}")


if __name__ == "__main__":
    main()
