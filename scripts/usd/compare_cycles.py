#!/usr/bin/python3
"""Renders Blender's groom with Cycles and, through Blender's own USD export
and `yscene convert`, with yscene; compares the mean over the hair's pixels
and writes the side-by-side figure (ours | Cycles | difference).

    /usr/bin/python3 scripts/usd/compare_cycles.py [--resolution 256] [--samples 64]
        [--batches 4] [--bounces 31] [--out out/usd-cycles]
        [--figure docs/figures/usd-blender-cycles.png] [--yscene build-usd/apps/yscene]
        [--bpy-python /work/.venv-bpy/bin/python] [--check 0.02]

Exits 77 (skipped) where --bpy-python cannot import bpy.

The driver runs under Debian's Python (OpenImageIO, NumPy, matplotlib); it
runs this same file under Blender 5.0 as a Python module (PyPI's bpy 5.0.1,
--bpy-python, or YOCTO_BPY_PYTHON) for the Cycles half, which:
- builds the groom of make_blender_groom.py (particle hair on a sphere, a
  hair-curves lock, its camera and its 3 W/m^2 sun), square (Blender 5.0.1
  places the particle hair differently from run to run, seed or not: each run
  compares the groom it made), with
  - one hair material on both: Principled Hair BSDF, Chiang model, by
    absorption coefficient, sigma_a of eumelanin 1.3 as ours computes it,
    roughness 0.3, radial roughness 0.3, no coat, IOR 1.55, offset 2 degrees,
    no randomness;
  - the particle hair at a constant width (root = tip, no closed tip; Cycles
    renders particle hair at a width of radius_scale x root_radius, the panel's
    "Diameter Root" and "Scale", tapering to tip_radius): Blender's USD export
    writes no widths for particle hair, so the converter is told that width
    (--width; the converter's default 0.01 is Blender's default root width);
  - the sphere Lambertian grey 0.5, smooth (the converter's mesh default);
  - a constant white world of strength 1 (exported as a DomeLight), a sharp
    sun (angle 0);
- renders it with Cycles (CPU, box filter 1 px, no clamping, no denoising, no
  adaptive sampling, Standard view, max bounces = --bounces), --batches
  times at --samples / --batches samples with different seeds (the spread of
  the batches gives the noise of the means);
- exports the scene with bpy.ops.wm.usd_export(export_hair=True).
The driver then converts the USD (yscene convert, --hair-material with the
same sigma_a, --width), renders it --batches times (yscene render --aovs, the
same seeds, resolution, samples and bounces, --clamp 0), and takes hair
pixels as those where our `coverage` AOV (the fraction of samples whose first
hit is hair) is at least 0.5. It writes the figure and its numbers (the
figure's name with .json) and prints the per-channel hair-pixel means, their
relative differences and standard errors, and exits 1 if --check is given and a channel
differs by more than it.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))

EUMELANIN = 1.3
EUMELANIN_SIGMA_A = (0.419, 0.697, 1.37)  # libs/yocto_hair: hair_sigma_a_from_melanin
HAIR = {"beta_m": 0.3, "beta_n": 0.3, "alpha": 2.0, "eta": 1.55}
# Particle hair's width here: Blender's "Diameter Root" (root_radius, despite
# its name a diameter) times its scale (radius_scale); root = tip, so constant.
PARTICLE_WIDTH = 0.02
SPHERE_ALBEDO = 0.5


def sigma_a():
    return [EUMELANIN * s for s in EUMELANIN_SIGMA_A]


# -----------------------------------------------------------------------------
# CYCLES HALF (under bpy)
# -----------------------------------------------------------------------------

def node_tree(block):
    if block.node_tree is None:  # Blender 5 makes node trees; older ones need asking
        block.use_nodes = True
    return block.node_tree


def hair_material(bpy):
    material = bpy.data.materials.new("hair")
    tree = node_tree(material)
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new("ShaderNodeBsdfHairPrincipled")
    node.model = "CHIANG"
    node.parametrization = "ABSORPTION"
    values = {"Absorption Coefficient": sigma_a(), "Roughness": HAIR["beta_m"],
              "Radial Roughness": HAIR["beta_n"], "Coat": 0.0, "IOR": HAIR["eta"],
              "Offset": math.radians(HAIR["alpha"]), "Random Roughness": 0.0}
    sockets = {socket.name: socket for socket in node.inputs}
    for name, value in values.items():
        sockets[name].default_value = value
    tree.links.new(node.outputs["BSDF"], output.inputs["Surface"])
    return material


def diffuse_material(bpy):
    material = bpy.data.materials.new("sphere")
    tree = node_tree(material)
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new("ShaderNodeBsdfDiffuse")
    node.inputs["Color"].default_value = (SPHERE_ALBEDO, SPHERE_ALBEDO, SPHERE_ALBEDO, 1.0)
    node.inputs["Roughness"].default_value = 0.0  # Lambert
    tree.links.new(node.outputs["BSDF"], output.inputs["Surface"])
    return material


def build_cycles_scene(bpy, args):
    sys.path.insert(0, HERE)
    import make_blender_groom
    sphere, lock, camera, sun = make_blender_groom.build_scene()
    scene = bpy.context.scene
    hair = hair_material(bpy)
    sphere.data.materials.append(diffuse_material(bpy))
    sphere.data.materials.append(hair)
    sphere.data.polygons.foreach_set("use_smooth", [True] * len(sphere.data.polygons))
    settings = sphere.particle_systems[0].settings
    settings.material_slot = hair.name
    settings.root_radius = settings.tip_radius = 1.0
    settings.radius_scale = PARTICLE_WIDTH
    settings.shape = 0.0
    settings.use_close_tip = False
    lock.data.materials.append(hair)
    sun.data.angle = 0.0
    world = bpy.data.worlds.new("sky")
    scene.world = world
    background = node_tree(world).nodes.get("Background")
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    background.inputs["Strength"].default_value = 1.0
    render = scene.render
    render.engine = "CYCLES"
    render.resolution_x = render.resolution_y = args.resolution
    render.resolution_percentage = 100
    render.film_transparent = False
    render.use_compositing = render.use_sequencer = False
    render.threads_mode = "FIXED"
    render.threads = args.threads
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = args.samples // args.batches
    cycles.use_adaptive_sampling = cycles.use_denoising = False
    cycles.use_animated_seed = False
    cycles.time_limit = 0.0
    cycles.max_bounces = cycles.diffuse_bounces = cycles.glossy_bounces = args.bounces
    cycles.transmission_bounces = cycles.transparent_max_bounces = args.bounces
    cycles.volume_bounces = 0
    cycles.caustics_reflective = cycles.caustics_refractive = True
    cycles.blur_glossy = 0.0
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0
    cycles.light_sampling_threshold = 0.0
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    cycles.film_exposure = 1.0
    scene.cycles_curves.shape = "THICK"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    layer = scene.view_layers[0]
    layer.use_pass_combined = True
    image = scene.render.image_settings
    image.media_type = "MULTI_LAYER_IMAGE"
    image.file_format = "OPEN_EXR_MULTILAYER"
    image.color_depth = "32"
    image.exr_codec = "ZIP"
    return {"sun_strength_w_m2": sun.data.energy, "particle_width": PARTICLE_WIDTH,
            "camera_lens_mm": camera.data.lens, "sensor_width_mm": camera.data.sensor_width}


def cycles_half(args):
    import bpy
    os.makedirs(args.out, exist_ok=True)
    info = build_cycles_scene(bpy, args)
    usd = os.path.join(args.out, "groom.usda")
    bpy.ops.wm.usd_export(filepath=os.path.abspath(usd), export_hair=True,
                          export_materials=False)
    info["batches"], info["render_seconds"] = [], []
    for batch in range(args.batches):
        bpy.context.scene.cycles.seed = batch + 1
        start = time.perf_counter()
        bpy.ops.render.render(write_still=False)
        info["render_seconds"].append(time.perf_counter() - start)
        name = os.path.join(args.out, f"cycles-{batch}.exr")
        bpy.data.images["Render Result"].save_render(os.path.abspath(name),
                                                     scene=bpy.context.scene)
        info["batches"].append(name)
    info["blender"] = bpy.app.version_string
    with open(os.path.join(args.out, "cycles.json"), "w") as file:
        json.dump(info, file, indent=1)


# -----------------------------------------------------------------------------
# DRIVER
# -----------------------------------------------------------------------------

def run(command):
    print("+ " + " ".join(command), flush=True)
    start = time.perf_counter()
    subprocess.run(command, check=True)
    return time.perf_counter() - start


def read_exr(filename, wanted):
    """The channels named (suffixes of the EXR's channel names) as an
    H x W x len(wanted) array, rows top to bottom."""
    import numpy as np
    import OpenImageIO as oiio
    image = oiio.ImageInput.open(filename)
    if image is None:
        raise SystemExit(f"error: {filename}: {oiio.geterror()}")
    spec = image.spec()
    pixels = image.read_image(0, 0, 0, spec.nchannels, "float")
    image.close()
    names = list(spec.channelnames)
    columns = []
    for suffix in wanted:
        matches = [k for k, name in enumerate(names) if name == suffix or
                   name.endswith("." + suffix)]
        if not matches:
            raise SystemExit(f"error: {filename}: no channel {suffix} in {names}")
        columns.append(pixels[:, :, matches[0]])
    return np.stack(columns, axis=2).astype(np.float64)


def srgb(linear):
    import numpy as np
    x = np.clip(linear, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def write_figure(filename, ours, cycles, mask, summary):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    difference = (ours - cycles).mean(axis=2)
    limit = max(float(np.percentile(np.abs(difference), 99.5)), 1e-3)
    figure, axes = plt.subplots(1, 3, figsize=(12, 4.4))
    axes[0].imshow(srgb(ours))
    axes[0].set_title("yscene (USD via yscene convert)")
    axes[1].imshow(srgb(cycles))
    axes[1].set_title(f"Cycles, Blender {summary['blender']}")
    shown = axes[2].imshow(difference, cmap="RdBu_r", vmin=-limit, vmax=limit)
    axes[2].contour(mask, levels=[0.5], colors="k", linewidths=0.3)
    axes[2].set_title("yscene - Cycles (mean of RGB); hair mask outlined")
    figure.colorbar(shown, ax=axes[2], fraction=0.046)
    for axis in axes:
        axis.set_xticks([])
        axis.set_yticks([])
    means = ", ".join(f"{100 * d:+.2f}%" for d in summary["relative_difference"])
    figure.suptitle(f"Blender groom exported to USD: hair-pixel mean yscene / Cycles - 1 = "
                    f"{means} (R, G, B); {summary['resolution']}², {summary['samples']} spp",
                    fontsize=10)
    figure.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(filename)), exist_ok=True)
    temporary = filename + ".tmp.png"
    figure.savefig(temporary, dpi=100)
    os.replace(temporary, filename)


def driver(args):
    import numpy as np
    if not os.path.isfile(args.bpy_python) or subprocess.run(
            [args.bpy_python, "-c", "import bpy"], capture_output=True).returncode != 0:
        print(f"skipped: no Blender Python module (bpy 5.0.1) in {args.bpy_python}")
        return 77
    os.makedirs(args.out, exist_ok=True)
    cpu_start = os.times()
    run(["nice", "-n", "19", args.bpy_python, os.path.abspath(__file__), "--cycles-half",
         "--out", args.out, "--resolution", str(args.resolution), "--samples", str(args.samples),
         "--batches", str(args.batches), "--bounces", str(args.bounces),
         "--threads", str(args.threads)])
    with open(os.path.join(args.out, "cycles.json")) as file:
        info = json.load(file)
    material = os.path.join(args.out, "hair.json")
    with open(material, "w") as file:
        json.dump({"asset": {"version": "4.2"}, "materials": [
            dict({"name": "hair", "type": "hair", "sigma_a": sigma_a()}, **HAIR)]}, file)
    scene = os.path.join(args.out, "groom.json")
    run([args.yscene, "convert", os.path.join(args.out, "groom.usda"), scene,
         "--hair-material", material, "--width", repr(info["particle_width"])])
    ours_batches, ours_seconds = [], []
    for batch in range(args.batches):
        image = os.path.join(args.out, f"ours-{batch}.exr")
        ours_seconds.append(run(["nice", "-n", "19", args.yscene, "render", scene, "--output",
                                 image, "--aovs", "--samples", str(args.samples // args.batches),
                                 "--resolution", str(args.resolution), "--bounces",
                                 str(args.bounces), "--clamp", "0", "--seed", str(batch + 1),
                                 "--threads", str(args.threads), "--quiet"]))
        ours_batches.append(image)
    cpu_end = os.times()
    ours = [read_exr(f, ["R", "G", "B"]) for f in ours_batches]
    coverage = np.mean([read_exr(f, ["coverage.Y"])[:, :, 0] for f in ours_batches], axis=0)
    cycles = [read_exr(f, ["Combined.R", "Combined.G", "Combined.B"]) for f in info["batches"]]
    if ours[0].shape != cycles[0].shape:
        raise SystemExit(f"error: image sizes differ: {ours[0].shape} and {cycles[0].shape}")
    mask = coverage >= 0.5
    if not mask.any():
        raise SystemExit("error: no hair pixels (coverage >= 0.5)")
    # Per batch hair-pixel means, then their mean and standard error.
    ours_means = np.array([image[mask].mean(axis=0) for image in ours])
    cycles_means = np.array([image[mask].mean(axis=0) for image in cycles])
    k = args.batches
    error = lambda means: means.std(axis=0, ddof=1) / math.sqrt(k) if k > 1 else means[0] * 0
    ours_mean, cycles_mean = ours_means.mean(axis=0), cycles_means.mean(axis=0)
    relative = ours_mean / cycles_mean - 1
    relative_error = np.sqrt((error(ours_means) / ours_mean) ** 2 +
                             (error(cycles_means) / cycles_mean) ** 2)
    summary = {
        "blender": info["blender"], "resolution": args.resolution, "samples": args.samples,
        "batches": k, "bounces": args.bounces, "hair_pixels": int(mask.sum()),
        "ours_mean": ours_mean.tolist(), "cycles_mean": cycles_mean.tolist(),
        "relative_difference": relative.tolist(),
        "relative_standard_error": relative_error.tolist(),
        "ours_standard_error": (error(ours_means) / ours_mean).tolist(),
        "cycles_standard_error": (error(cycles_means) / cycles_mean).tolist(),
        "image_mean_relative_difference": (np.mean(ours, axis=(0, 1, 2)) /
                                           np.mean(cycles, axis=(0, 1, 2)) - 1).tolist(),
        "cycles_render_seconds": info["render_seconds"], "ours_render_seconds": ours_seconds,
        "cpu_seconds_children": (cpu_end.children_user + cpu_end.children_system) -
                                (cpu_start.children_user + cpu_start.children_system),
    }
    write_figure(args.figure, np.mean(ours, axis=0), np.mean(cycles, axis=0), mask, summary)
    summary_file = os.path.splitext(args.figure)[0] + ".json"
    with open(summary_file + ".tmp", "w") as file:
        json.dump(summary, file, indent=1)
    os.replace(summary_file + ".tmp", summary_file)
    fmt = lambda values: " ".join(f"{v:.4f}" for v in values)
    pct = lambda values: " ".join(f"{100 * v:+.2f}%" for v in values)
    print(f"hair pixels: {summary['hair_pixels']} of {args.resolution ** 2} "
          f"(our coverage >= 0.5)")
    print(f"hair-pixel mean RGB  yscene {fmt(ours_mean)}  Cycles {fmt(cycles_mean)}")
    print(f"yscene / Cycles - 1: {pct(relative)}  (standard error {pct(relative_error)}; "
          f"from {k} batches)")
    print(f"whole image yscene / Cycles - 1: {pct(summary['image_mean_relative_difference'])}")
    print(f"wrote {args.figure} and {summary_file}")
    if args.check and np.abs(relative).max() > args.check:
        print(f"error: a hair-pixel mean differs by more than {100 * args.check:g}%",
              file=sys.stderr)
        return 1
    return 0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=256)
    parser.add_argument("--samples", type=int, default=64, help="per pixel, over all batches")
    parser.add_argument("--batches", type=int, default=4)
    parser.add_argument("--bounces", type=int, default=31)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(ROOT, "out", "usd-cycles"))
    parser.add_argument("--figure", default=os.path.join(ROOT, "docs", "figures",
                                                         "usd-blender-cycles.png"))
    parser.add_argument("--yscene", default=os.path.join(ROOT, "build", "apps", "yscene"))
    parser.add_argument("--bpy-python", default=os.environ.get(
        "YOCTO_BPY_PYTHON", "/work/.venv-bpy/bin/python"))
    parser.add_argument("--check", type=float, default=0.0,
                        help="exit 1 if a hair-pixel mean differs by more than this fraction")
    parser.add_argument("--cycles-half", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.samples % args.batches:
        parser.error("--samples must be a multiple of --batches")
    args.out = os.path.abspath(args.out)
    if args.cycles_half:
        cycles_half(args)
        return 0
    return driver(args)


if __name__ == "__main__":
    sys.exit(main())
