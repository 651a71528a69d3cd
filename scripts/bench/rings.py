#!/usr/bin/env python3
"""Where the error is: each render's MSE in rings about the image centre, scored as score.py
scores whole images (against its renderer's own reference, less the reference's noise, in each
ring), MSE averaged over the runs of one NAME.

    rings.py "NAME RUN REF" ...   (RUN.exr; REF-A.exr, REF-B.exr)

Prints the ring bounds, the pixels in each ring, then one line per NAME: its MSE in each ring.
The rings are fractions of the image's half width: on the peers' hair ball the first is the
ball's centre (strands seen end on, light reaching them through many fibres) and the last the
sky about it. Runs with the peers' venv (score.py's numpy and Mitsuba, which reads the EXRs;
score.py runs as a script, so its reader is not imported)."""
import sys

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")

RINGS = [0.0, 0.3, 0.55, 0.7, 0.8, 0.87, 2.0]


def read(path):
    bmp = mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32)
    return np.array(bmp, dtype=np.float64)[..., :3]


def ring_masks(shape):
    height, width = shape[:2]
    y, x = np.mgrid[0:height, 0:width]
    radius = np.hypot(y + 0.5 - height / 2, x + 0.5 - width / 2) / (width / 2)
    return [(radius >= lo) & (radius < hi) for lo, hi in zip(RINGS, RINGS[1:])]


def main():
    refs, runs, names = {}, {}, []
    for arg in sys.argv[1:]:
        name, run, ref = arg.split()
        if ref not in refs:
            a, b = read(ref + "-A.exr"), read(ref + "-B.exr")
            refs[ref] = ((a + b) / 2, ((a - b) ** 2) / 4)
        mean, noise = refs[ref]
        image = read(run + ".exr")
        if image.shape != mean.shape:
            sys.exit(f"rings.py: {run}.exr is {image.shape}, its reference {mean.shape}")
        error = (image - mean) ** 2 - noise
        masks = ring_masks(image.shape)
        if name not in runs:
            names.append(name)
        runs.setdefault(name, []).append([float(error[m].mean()) for m in masks])
    print("rings " + " ".join(f"{lo:g}-{hi:g}" for lo, hi in zip(RINGS, RINGS[1:])))
    print("pixels " + " ".join(str(int(m.sum())) for m in masks))
    for name in names:
        print(name + " " + " ".join(f"{v:.6g}" for v in np.mean(runs[name], axis=0)))


if __name__ == "__main__":
    main()
