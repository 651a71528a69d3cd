#!/usr/bin/env python3
"""A/B of estimators: variance between seeds times rays, and a check of the mean.

    python3 scripts/bench/ab_variance.py SCENE.json \\
        --variant "guide=build/apps/yscene" --variant "no-guide=build/apps/yscene --lobe-guide 0" \\
        [--seeds 3 4 5 6 7] [--samples 64] [--resolution 256] [--threads 2] [--out FILE.md]

Each variant is a name, '=', a yscene binary and its extra render flags. Every
variant renders the scene once per seed (interleaved: seed by seed, variant by
variant), with --bounces 31 --clamp 0 as the peers' comparison does. Per
variant: the per-pixel variance between the seeds (averaged over pixels and
channels), the mean rays and the median render CPU-s (yscene's --stats), and
against the first variant:
- variance x rays, which does not move with this machine's CPU readings
  (single renders of the same work spread by +-13 %), so that it is the
  steadier yardstick of an estimator's change at a fixed cost per ray;
- efficiency, 1 / (variance x CPU-s), which does;
- the difference of the image means in standard errors (the pixels' variances
  between seeds over the seeds, pixels taken as independent): an unbiased
  change stays within a few. Check this first: a biased draft can look cheap.

Renders are cached in out/bench/ab_variance/ by variant name, seed, samples and
resolution (delete them after changing a binary).
"""

import argparse
import json
import math
import os
import shlex
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from efficiency import render  # noqa: E402
from run_bench import ROOT, log, read_pfm  # noqa: E402


def parse_variant(text):
    name, sep, command = text.partition("=")
    words = shlex.split(command)
    if not sep or not name or not words:
        sys.exit(f"ab_variance.py: --variant '{text}': expected NAME=BINARY [FLAGS]")
    return name, words[0], words[1:]


def render_cached(scene, binary, flags, seed, args, output):
    """Renders one seed with efficiency.py's render (or reuses its cached
    files); returns its stats fields."""
    stats_file = output + ".json"
    if not (os.path.exists(output) and os.path.exists(stats_file)):
        stats = render(binary, scene, output + ".tmp.pfm", args.samples, args.resolution, seed,
                       args.threads, flags)
        with open(stats_file + ".tmp", "w") as f:
            json.dump(stats, f)
        os.replace(output + ".tmp.pfm", output)
        os.replace(stats_file + ".tmp", stats_file)
    with open(stats_file) as f:
        return json.load(f)


def pixel_moments(images):
    """Per value: the mean over the images and the unbiased variance between them."""
    n = len(images)
    means, variances = [], []
    for values in zip(*images):
        mean = sum(values) / n
        means.append(mean)
        variances.append(sum((v - mean) ** 2 for v in values) / (n - 1))
    return means, variances


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scene")
    parser.add_argument("--variant", action="append", required=True)
    parser.add_argument("--seeds", type=int, nargs="+", default=[3, 4, 5, 6, 7])
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", help="also write the table to this markdown file")
    args = parser.parse_args()
    if len(args.seeds) < 2:
        sys.exit("ab_variance.py: at least two seeds are needed for a variance")
    variants = [parse_variant(text) for text in args.variant]
    if len({name for name, _, _ in variants}) != len(variants):
        sys.exit("ab_variance.py: variant names must differ")
    scene = os.path.abspath(args.scene)
    cache = os.path.join(ROOT, "out", "bench", "ab_variance")
    os.makedirs(cache, exist_ok=True)

    images = {name: [] for name, _, _ in variants}
    stats = {name: [] for name, _, _ in variants}
    for seed in args.seeds:
        for name, binary, flags in variants:
            output = os.path.join(cache, f"{name}-{seed}-{args.samples}-{args.resolution}.pfm")
            log(f"{name}, seed {seed}")
            stats[name].append(render_cached(scene, binary, flags, seed, args, output))
            images[name].append(read_pfm(output)[2])

    rows = []
    for name, _, _ in variants:
        means, variances = pixel_moments(images[name])
        count = len(means)
        row = {
            "name": name,
            "variance": sum(variances) / count,
            "rays": statistics.mean(s["rays"] for s in stats[name]),
            "cpu": statistics.median(s["render_cpu"] for s in stats[name]),
            "mean": sum(means) / count,
            "means": means,
            "variances": variances,
        }
        rows.append(row)
    first = rows[0]
    n = len(args.seeds)
    lines = [
        f"`ab_variance.py {os.path.relpath(scene, ROOT)}`: {args.resolution} pixels wide, "
        f"{args.samples} spp, seeds {' '.join(map(str, args.seeds))}, {args.threads} threads; "
        f"ratios against {first['name']}.",
        "",
        "| variant | variance | rays | CPU-s | variance x rays | efficiency | mean | "
        "mean difference (SE) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in rows:
        product = row["variance"] * row["rays"] / (first["variance"] * first["rays"])
        efficiency = (first["variance"] * first["cpu"]) / (row["variance"] * row["cpu"])
        error = math.sqrt(sum((a + b) / n for a, b in zip(row["variances"], first["variances"])))
        error /= len(row["means"])
        difference = row["mean"] - first["mean"]
        deviations = difference / error if error > 0 else 0.0
        lines.append(
            f"| {row['name']} | {row['variance']:.4g} | {row['rays']:.4g} | {row['cpu']:.2f} | "
            f"{product:.3f} | {efficiency:.3f} | {row['mean']:.5f} | {deviations:+.1f} |")
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out:
        with open(args.out + ".tmp", "w") as f:
            f.write(text)
        os.replace(args.out + ".tmp", args.out)


if __name__ == "__main__":
    main()
