#!/usr/bin/env python3
"""Renders the five parameter sweeps of the thesis's chapter 4 and assembles
them into labelled contact sheets in docs/figures/.

Usage: python3 scripts/make_figures.py [--samples N] [--resolution R]
                                       [--style straight|curly|curls]

Needs the build (bash scripts/setup.sh) and python3-matplotlib. Each image is
a generated scene (yscene hair) rendered with yscene render; the renders are
cached in out/figures/ by their parameters and the yscene binary (a rebuilt
renderer renders them again).
"""

import argparse
import hashlib
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
YSCENE = os.path.join(ROOT, "build", "apps", "yscene")

# The thesis's sweeps: (name, title, [(label, yscene hair arguments)]).
# Hair not given a pigment keeps eumelanin 1.3 with the defaults
# beta_m = 0.3, beta_n = 0.3, alpha = 2 degrees.
SWEEPS = [
    ("eumelanin", "Eumelanin concentration", [
        ("eumelanin 8", ["--eumelanin", "8"]),
        ("eumelanin 1.3", ["--eumelanin", "1.3"]),
        ("eumelanin 0.3", ["--eumelanin", "0.3"]),
    ]),
    ("sigma_a", "Absorption coefficient sigma_a", [
        ("sigma_a (3.35, 5.58, 10.96)", ["--sigma-a", "3.35", "5.58", "10.96"]),
        ("sigma_a (0.84, 1.39, 2.74)", ["--sigma-a", "0.84", "1.39", "2.74"]),
        ("sigma_a (0.06, 0.10, 0.20)", ["--sigma-a", "0.06", "0.10", "0.20"]),
    ]),
    ("alpha", "Scale tilt alpha (blonde, eumelanin 0.3)", [
        ("alpha 0 deg", ["--eumelanin", "0.3", "--alpha", "0"]),
        ("alpha 2 deg", ["--eumelanin", "0.3", "--alpha", "2"]),
    ]),
    ("beta_m", "Longitudinal roughness beta_m", [
        ("beta_m 0.1", ["--beta-m", "0.1"]),
        ("beta_m 0.3", ["--beta-m", "0.3"]),
        ("beta_m 0.6", ["--beta-m", "0.6"]),
    ]),
    ("beta_n", "Azimuthal roughness beta_n", [
        ("beta_n 0.3", ["--beta-n", "0.3"]),
        ("beta_n 0.6", ["--beta-n", "0.6"]),
        ("beta_n 0.9", ["--beta-n", "0.9"]),
    ]),
]


def run(arguments):
    result = subprocess.run(arguments, capture_output=True, text=True)
    if result.returncode != 0:
        sys.exit("failed: " + " ".join(arguments) + "\n" + result.stdout + result.stderr)
    return result.stdout


def binary_digest():
    with open(YSCENE, "rb") as f:
        return hashlib.sha1(f.read()).hexdigest()[:12]


def render(style, strands, hair_args, samples, resolution, workdir):
    key = "-".join([style, str(strands), str(samples), str(resolution)] + hair_args +
                   [binary_digest()])
    key = key.replace(" ", "").replace("--", "")
    image = os.path.join(workdir, key + ".png")
    if os.path.exists(image):
        return image
    scene = os.path.join(workdir, "scene-" + key, "scene.json")
    os.makedirs(os.path.dirname(scene), exist_ok=True)
    run([YSCENE, "hair", "--style", style, "--strands", str(strands), "--output", scene] + hair_args)
    summary = run([YSCENE, "render", scene, "--output", image, "--samples", str(samples),
                   "--resolution", str(resolution), "--quiet"])
    print(summary.strip())
    return image


def contact_sheet(title, labelled_images, output):
    count = len(labelled_images)
    figure, axes = plt.subplots(1, count, figsize=(3.2 * count, 3.6), dpi=150)
    if count == 1:
        axes = [axes]
    for axis, (label, image) in zip(axes, labelled_images):
        axis.imshow(mpimg.imread(image))
        axis.set_title(label, fontsize=10)
        axis.axis("off")
    figure.suptitle(title, fontsize=12)
    figure.tight_layout()
    temporary = output + ".tmp.png"
    figure.savefig(temporary)
    plt.close(figure)
    os.replace(temporary, output)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=64)
    parser.add_argument("--resolution", type=int, default=320)
    parser.add_argument("--style", default="straight", choices=["straight", "curly", "curls"])
    parser.add_argument("--strands", type=int, default=20000)
    options = parser.parse_args()
    if not os.path.exists(YSCENE):
        sys.exit("build first: bash scripts/setup.sh")
    workdir = os.path.join(ROOT, "out", "figures")
    docs = os.path.join(ROOT, "docs", "figures")
    os.makedirs(workdir, exist_ok=True)
    os.makedirs(docs, exist_ok=True)
    for name, title, variants in SWEEPS:
        images = [(label, render(options.style, options.strands, args, options.samples,
                                 options.resolution, workdir)) for label, args in variants]
        sheet = os.path.join(docs, "sweep-" + name + ".png")
        contact_sheet(title, images, sheet)
        print("wrote", os.path.relpath(sheet, ROOT))


if __name__ == "__main__":
    main()
