#!/usr/bin/env python3
"""Mean hair brightness of renders, for before/after figures (docs/RESULTS.md).

  hair_brightness.py mask SCENE.json OUTDIR
      writes OUTDIR/<same name>.json: the scene with every hair material made
      black and emitting 1, every other material black, no sky and no lights.
      Its render (one bounce is enough) holds in each pixel the share of the
      pixel's samples that see hair.
  hair_brightness.py stats MASK.pfm IMAGE.pfm [IMAGE.pfm ...]
      prints, for each image, the mean brightness over hair pixels (mask above
      0.5), over the central 60 % square, over hair pixels in that square and
      over the whole image, each also relative to the first image.
"""
import json
import os
import struct
import sys


def write_mask_scene(scene, folder):
    data = json.load(open(scene))
    os.makedirs(folder, exist_ok=True)
    # The mask scene reads the same shapes and textures through links.
    for sub in ("shapes", "textures"):
        source = os.path.join(os.path.dirname(os.path.abspath(scene)), sub)
        target = os.path.join(folder, sub)
        if os.path.isdir(source) and not os.path.lexists(target):
            os.symlink(source, target)
    for material in data.get("materials", []):
        hair = material.get("type") == "hair"
        name = material.get("name")
        material.clear()
        if name is not None:
            material["name"] = name
        material.update({"type": "matte", "color": [0, 0, 0],
                         "emission": [1, 1, 1] if hair else [0, 0, 0]})
    for environment in data.get("environments", []):
        environment["emission"] = [0, 0, 0]
        environment.pop("emission_tex", None)
    data.pop("distant_lights", None)
    with open(os.path.join(folder, os.path.basename(scene)), "w") as out:
        json.dump(data, out, indent=1)


def load_pfm(filename):
    data = open(filename, "rb").read()
    header = data.split(b"\n", 3)
    if header[0] != b"PF":
        sys.exit(f"{filename}: not a colour PFM")
    width, height = map(int, header[1].split())
    order = "<" if float(header[2]) < 0 else ">"
    values = struct.unpack(f"{order}{width * height * 3}f", header[3][: width * height * 12])
    means = [(values[3 * i] + values[3 * i + 1] + values[3 * i + 2]) / 3
             for i in range(width * height)]
    return width, height, means


def print_stats(mask_file, images):
    width, height, mask = load_pfm(mask_file)
    hair = [value > 0.5 for value in mask]
    centre = [0.2 * width <= i % width < 0.8 * width and
              0.2 * height <= i // width < 0.8 * height for i in range(width * height)]
    regions = {"hair": hair, "centre": centre,
               "hair in centre": [h and c for h, c in zip(hair, centre)],
               "whole": [True] * (width * height)}
    print(f"{mask_file}: {sum(hair)} hair pixels of {width * height}")
    first = None
    for image in images:
        size = load_pfm(image)
        if size[:2] != (width, height):
            sys.exit(f"{image}: {size[0]}x{size[1]}, the mask is {width}x{height}")
        means = {}
        for name, region in regions.items():
            count = sum(region)
            means[name] = sum(v for v, r in zip(size[2], region) if r) / max(count, 1)
        first = first or means
        print(image + ": " + ", ".join(
            f"{name} {means[name]:.5f} ({100 * (means[name] / first[name] - 1):+.2f}%)"
            if first[name] else f"{name} {means[name]:.5f}" for name in regions))


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "mask":
        write_mask_scene(sys.argv[2], sys.argv[3])
    elif len(sys.argv) >= 4 and sys.argv[1] == "stats":
        print_stats(sys.argv[2], sys.argv[3:])
    else:
        sys.exit(__doc__)
