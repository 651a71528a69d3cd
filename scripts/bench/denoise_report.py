#!/usr/bin/env python3
"""Denoised error: OIDN on the four benchmark scenes at 4, 16 and 64 spp.

    .venv/denoise/bin/python scripts/bench/denoise_report.py [--yscene build/apps/yscene]
        [--scenes fur hair-locks ...] [--spp 4 16 64] [--reference-tag TAG]

Needs `bash scripts/setup.sh --denoise` (pyoidn, OpenImageIO and NumPy for
Python) and NVIDIA's FLIP (`.venv/denoise/bin/pip install flip-evaluator`).

Every scene of the efficiency report (scripts/bench/efficiency.py: the same
scene files, resolutions and settings) is rendered with `--aovs` at each spp
(one seed), then denoised by scripts/denoise.py four ways: not at all (the
noisy render), the beauty alone (--no-aux), with albedo and normal, with
albedo and the fibre tangents in place of the normals (--aux-normal
tangent), and with albedo and normal given to OIDN as they are, noisy
(--no-prefilter). Each is scored against the converged reference of the efficiency
report (four renders of 256 spp, cached in out/bench/efficiency/ under the
binary's hash, or --reference-tag's): the MSE minus the reference's own noise
(so that it is the image's alone), and the mean FLIP error (HDR, its default
exposure range; a perceptual error in [0, 1]) against the reference as it is.
The crops of the pictures (noisy | denoised | reference, nearest-neighbour
x2) are at 16 spp.

Writes docs/benchmark/denoise.md and docs/figures/denoise-SCENE.png; renders
and denoised images are cached in out/bench/denoise/.
"""

import argparse
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from run_bench import ROOT, log  # noqa: E402
from efficiency import SCENES, file_hash, reference, render, scene_path  # noqa: E402

try:
    import numpy as np
    import OpenImageIO as oiio
    import flip_evaluator
except ImportError as error:
    sys.exit(f"error: {error.name} is missing: run bash scripts/setup.sh --denoise, then "
             ".venv/denoise/bin/pip install flip-evaluator, and this script with "
             ".venv/denoise/bin/python")

CACHE = os.path.join(ROOT, "out/bench/denoise")
DENOISE = os.path.join(ROOT, "scripts/denoise.py")
# name, denoise.py arguments (None: the noisy render itself)
METHODS = [
    ("noisy", None),
    ("OIDN, beauty alone", ["--no-aux"]),
    ("OIDN, albedo + normal", []),
    ("OIDN, albedo + tangent", ["--aux-normal", "tangent"]),
    ("OIDN, albedo + normal, not prefiltered", ["--no-prefilter"]),
]
# Where each scene's crop is (left, top, size), in pixels of its render.
CROPS = {"fur": (96, 40, 80), "hair-locks": (56, 56, 80), "straight-hair": (24, 16, 64),
         "curly-hair": (32, 24, 64)}


def read_rgb(filename):
    image = oiio.ImageBuf(filename)
    if image.has_error:
        sys.exit(f"error: {filename}: {image.geterror()}")
    pixels = image.get_pixels(oiio.FLOAT)
    names = list(image.spec().channelnames)
    return pixels[:, :, [names.index(c) for c in ("R", "G", "B")]]


def to_srgb8(rgb):
    rgb = np.clip(rgb, 0, 1)
    srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    return (srgb * 255 + 0.5).astype(np.uint8)


def save_png(filename, rgb):
    pixels = np.ascontiguousarray(to_srgb8(rgb))
    os.makedirs(os.path.dirname(filename), exist_ok=True)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, oiio.UINT8)
    temporary = filename + ".tmp.png"
    output = oiio.ImageOutput.create(temporary)
    if not output or not output.open(temporary, spec) or not output.write_image(pixels) or \
            not output.close():
        sys.exit(f"error: {filename}: cannot write ({oiio.geterror()})")
    os.replace(temporary, filename)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--yscene", default=os.path.join(ROOT, "build/apps/yscene"))
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--spp", nargs="*", type=int, default=[4, 16, 64])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--reference-tag", default="",
                        help="binary hash of cached references (default: this binary's)")
    parser.add_argument("--out", default=os.path.join(ROOT, "docs/benchmark/denoise.md"))
    args = parser.parse_args()
    yscene = os.path.abspath(args.yscene)
    tag = file_hash(yscene)
    reference_tag = args.reference_tag or tag
    os.makedirs(CACHE, exist_ok=True)
    os.chdir(ROOT)
    rows, pictures = [], []
    for name in args.scenes:
        scene = scene_path(name, yscene)
        resolution = SCENES[name][1]
        log(f"{name}: reference ({reference_tag})")
        ref = reference(yscene, reference_tag, name, scene, resolution, 256,
                        [201, 202, 203, 204], args.threads,
                        os.path.join(ROOT, "out/bench/efficiency"))
        width, height = ref["size"]
        # PFM rows run bottom to top.
        truth = np.array(ref["mean"], dtype=np.float64).reshape(height, width, 3)[::-1]
        truth_noise = float(np.mean(np.array(ref["variance"])))
        for spp in args.spp:
            noisy = os.path.join(CACHE, f"{name}-{tag}-{spp}spp.exr")
            if not os.path.exists(noisy):
                log(f"  {name} {spp} spp")
                render(yscene, scene, noisy, spp, resolution, args.seed, args.threads,
                       ["--aovs"])
            images = {}
            for method, extra in METHODS:
                if extra is None:
                    images[method], seconds = read_rgb(noisy), 0.0
                else:
                    output = noisy[:-4] + "-" + "-".join(a.strip("-") for a in extra or
                                                         ["aux"]) + ".exr"
                    # The time of a cached one is kept beside it.
                    timing = output + ".seconds"
                    if not os.path.exists(output) or not os.path.exists(timing):
                        start = time.monotonic()
                        subprocess.run([sys.executable, DENOISE, noisy, "--output", output,
                                        "--quiet"] + extra, check=True)
                        with open(timing, "w") as f:
                            f.write(f"{time.monotonic() - start:.3f}\n")
                    with open(timing) as f:
                        seconds = float(f.read())
                    images[method] = read_rgb(output)
                image = images[method].astype(np.float64)
                mse = float(np.mean((image - truth) ** 2)) - truth_noise
                _, flip, _ = flip_evaluator.evaluate(
                    np.maximum(truth, 0).astype(np.float32),
                    np.maximum(image, 0).astype(np.float32), "HDR", applyMagma=False)
                rows.append((name, spp, method, mse, float(flip), seconds))
                log(f"    {spp:3d} spp {method:24s} MSE {mse:.3e} FLIP {flip:.4f}")
            if spp == 16:
                left, top, size = CROPS[name]
                size = min(size, height, width)
                left, top = min(left, width - size), min(top, height - size)
                crop = lambda rgb: np.repeat(np.repeat(
                    rgb[top:top + size, left:left + size], 2, axis=0), 2, axis=1)
                gap = np.ones((2 * size, 4, 3), dtype=np.float32)
                strip = np.concatenate([crop(images["noisy"]), gap,
                                        crop(images["OIDN, albedo + normal"]), gap,
                                        crop(truth.astype(np.float32))], axis=1)
                picture = os.path.join(ROOT, f"docs/figures/denoise-{name}.png")
                save_png(picture, strip)
                pictures.append((name, os.path.relpath(picture, os.path.dirname(args.out))))
    write_report(args, rows, pictures, tag, reference_tag)


def write_report(args, rows, pictures, tag, reference_tag):
    lines = ["# Denoised error (issue 21)", "",
             "Generated by `scripts/bench/denoise_report.py` (see its docstring for the method); "
             f"yscene `{tag}`, references `{reference_tag}` (4 x 256 spp). MSE is against the "
             "reference minus the reference's own noise; FLIP is the mean ꟻLIP error (HDR) "
             "against the reference. Denoising: OIDN's RT filter, quality high, aux layers "
             "prefiltered (`cleanAux`); seconds are the wall time of `scripts/denoise.py` "
             "(Python start-up and EXR IO included), 2 cores.", ""]
    scenes = list(dict.fromkeys(row[0] for row in rows))
    for name in scenes:
        lines += [f"## {name}", "", "| spp | method | MSE | × noisy | ꟻLIP | seconds |",
                  "|---:|---|---:|---:|---:|---:|"]
        for spp in args.spp:
            noisy = [r for r in rows if r[0] == name and r[1] == spp and r[2] == "noisy"][0]
            for row in [r for r in rows if r[0] == name and r[1] == spp]:
                ratio = row[3] / noisy[3] if noisy[3] > 0 else float("nan")
                lines.append(f"| {spp} | {row[2]} | {row[3]:.3e} | {ratio:.3f} | "
                             f"{row[4]:.4f} | {row[5]:.1f} |")
        lines.append("")
    lines += ["## Pictures (16 spp: noisy | OIDN with albedo + normal | reference)", ""]
    for name, picture in pictures:
        lines += [f"{name}:", "", f"![{name}]({picture})", ""]
    with open(args.out + ".tmp", "w") as f:
        f.write("\n".join(lines))
    os.replace(args.out + ".tmp", args.out)
    log(f"wrote {args.out}")


if __name__ == "__main__":
    main()
