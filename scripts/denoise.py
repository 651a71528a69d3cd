#!/usr/bin/env python3
"""Denoises a rendered image with Intel Open Image Denoise (OIDN), through
the pyoidn wheel of PyPI, which ships the OIDN library.

Usage:
  .venv/denoise/bin/python scripts/denoise.py IMAGE.exr --output OUT
      [--no-aux] [--aux-normal normal|tangent] [--no-prefilter] [--quality high|balanced|fast]
      [--exposure E] [--quiet]

IMAGE is an OpenEXR image of `yscene render` (or of `yscene merge`; never a
part, which holds a fraction of the samples). Its beauty, channels R, G, B,
is linear radiance: OIDN's RT filter denoises it as HDR. With the auxiliary
layers of `yscene render --aovs` (the default), the filter is guided by the
albedo (albedo.R, .G, .B) and by a normal layer: normal.X, .Y, .Z, or with
--aux-normal tangent the fibre tangents, tangent.X, .Y, .Z. Both are noisy
too (averages of the pixel's samples), so each is first denoised by an RT
filter of its own, then the beauty's filter is told they are clean
(cleanAux): OIDN's recommendation for final frames. --no-aux denoises the
beauty alone.

OUT by extension: .exr, .hdr, .pfm linear float (R, G, B only: the input's
AOVs are noisy estimates that no longer add up to the denoised beauty, they
stay in the input), .png, .jpg sRGB 8-bit, clamped, after scaling by
2^exposure (as `yscene render` writes them). OUT is written to a temporary
file beside it and renamed when complete: it is complete or absent.

Needs pyoidn, OpenImageIO and NumPy for Python: `bash scripts/setup.sh
--denoise` installs them into .venv/denoise. Exit status: 0 on success,
1 on an error (one line `error: FILE: what is wrong` on stderr, no output
written), 2 on bad usage, 130 on Ctrl-C.
"""

import argparse
import os
import sys
import tempfile
import time

INSTALL = "bash scripts/setup.sh --denoise, then run .venv/denoise/bin/python scripts/denoise.py"
LINEAR_EXTENSIONS = (".exr", ".hdr", ".pfm")
SRGB_EXTENSIONS = (".png", ".jpg", ".jpeg")
BEAUTY = ("R", "G", "B")
ALBEDO = ("albedo.R", "albedo.G", "albedo.B")
NORMALS = {"normal": ("normal.X", "normal.Y", "normal.Z"),
           "tangent": ("tangent.X", "tangent.Y", "tangent.Z")}


# Imported by import_modules(): a missing one is a one-line error.
np = oiio = pyoidn = None


class Failure(Exception):
    """An error about one file (or module), printed as `error: WHAT: message`."""

    def __init__(self, what, message):
        super().__init__(f"{what}: {message}")


def parse_args():
    parser = argparse.ArgumentParser(
        description="Denoises an OpenEXR render with Intel Open Image Denoise (RT filter, HDR).")
    parser.add_argument("image", help="OpenEXR image of yscene render (R, G, B and, unless "
                        "--no-aux, the albedo and normal layers of --aovs)")
    parser.add_argument("--output", "-o", required=True,
                        help="denoised image: exr, hdr, pfm (linear) or png, jpg (sRGB)")
    parser.add_argument("--no-aux", action="store_true",
                        help="denoise the beauty alone, without the albedo and normal layers")
    parser.add_argument("--aux-normal", choices=sorted(NORMALS), default="normal",
                        help="the layer given to OIDN as normals (default: normal)")
    parser.add_argument("--no-prefilter", action="store_true",
                        help="give OIDN the aux layers as they are (noisy), not denoised first")
    parser.add_argument("--quality", choices=("high", "balanced", "fast"), default="high",
                        help="OIDN's filter quality (default: high, for final frames)")
    parser.add_argument("--exposure", "-e", type=float, default=0.0,
                        help="exposure for png/jpg (stops)")
    parser.add_argument("--quiet", "-q", action="store_true", help="print nothing on success")
    return parser.parse_args()


def one_line(text):
    return " ".join(str(text).split()) or "unknown error"


def import_modules():
    global np, oiio, pyoidn
    try:
        import numpy as np
        import OpenImageIO as oiio
        import pyoidn
    except ImportError as error:
        raise Failure(error.name or "import", f"cannot be imported by {sys.executable}; "
                      f"install it with {INSTALL}") from None
    except OSError as error:  # the wheel's OIDN library did not load
        raise Failure("pyoidn", f"cannot load OIDN: {one_line(error)}; reinstall it with "
                      f"{INSTALL}") from None


def output_extension(path):
    """The output's extension, if one this script writes."""
    extension = os.path.splitext(path)[1].lower()
    if extension not in LINEAR_EXTENSIONS + SRGB_EXTENSIONS:
        raise Failure(path, f'unknown image extension "{extension}" (use exr, hdr, pfm, png '
                      "or jpg)")
    if os.path.isdir(path):
        raise Failure(path, "is a folder")
    return extension


def read_exr(path):
    """The image's spec and pixels (height x width x channels, float32)."""
    if not os.path.isfile(path):
        raise Failure(path, "not a file" if os.path.exists(path) else "no such file")
    image = oiio.ImageInput.open(path)
    if image is None:
        raise Failure(path, f"cannot read: {one_line(oiio.geterror())}")
    try:
        if image.format_name() != "openexr":
            raise Failure(path, f"not an OpenEXR image (it is {image.format_name()}); denoise "
                          "the .exr of yscene render --aovs")
        spec = image.spec()
        if spec.getattribute("yocto:part") is not None:
            raise Failure(path, f"a part of a split render (samples "
                          f"{spec.getattribute('yocto:range')}): denoise the image that "
                          "yscene merge makes of all the parts")
        pixels = image.read_image(0, 0, 0, spec.nchannels, "float")
        if pixels is None:
            raise Failure(path, f"cannot read its pixels: {one_line(image.geterror())}")
    finally:
        image.close()
    return spec, np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width,
                                                              spec.nchannels)


def layer(spec, pixels, path, name, channels):
    """One layer's three channels as a contiguous height x width x 3 image,
    or a failure naming the layer and the channels it lacks."""
    names = list(spec.channelnames)
    missing = [channel for channel in channels if channel not in names]
    if missing:
        hint = ("not a yscene render" if name == "beauty" else
                "render it with yscene render --aovs, or denoise with --no-aux")
        raise Failure(path, f"no {name} layer (channels {', '.join(missing)} missing): {hint}")
    image = np.ascontiguousarray(pixels[:, :, [names.index(c) for c in channels]])
    bad = np.count_nonzero(~np.isfinite(image))
    if bad:
        raise Failure(path, f"{bad} values of the {name} layer are not finite")
    return image


def check(device, path, what):
    """Fails with OIDN's message if the device reports an error (which also
    clears it)."""
    message = device.get_error()
    if message is not None:
        raise Failure(path, f"OIDN cannot {what}: {one_line(message)}")


def run_filter(device, path, images, quality, hdr=False, clean_aux=False):
    """Runs one RT filter on images (OIDN image name -> height x width x 3
    float32) and returns its output, a new image."""
    what = " + ".join(images)
    output = np.zeros_like(next(iter(images.values())))
    # Not `with`: pyoidn 2.5.1.0's Filter.__exit__ returns a true value,
    # which would swallow a failure raised inside.
    rt = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT)
    try:
        check(device, path, f"create the RT filter of {what}")
        # The arrays are shared with OIDN, not copied: they outlive the filter.
        for name, image in images.items():
            rt.set_image(name, image, pyoidn.OIDN_FORMAT_FLOAT3)
        rt.set_image(pyoidn.OIDN_IMAGE_OUTPUT, output, pyoidn.OIDN_FORMAT_FLOAT3)
        rt.set_bool("hdr", hdr)
        rt.set_bool("cleanAux", clean_aux)
        rt.set_quality(quality)
        rt.commit()
        check(device, path, f"set up the RT filter of {what}")
        rt.execute()
        check(device, path, f"filter {what}")
    finally:
        rt.release()
    return output


def denoise(device, path, beauty, albedo, normal, quality, prefilter=True):
    """The denoised beauty. The auxiliary images, if given, are denoised
    first, each by a filter of its own, and then given as clean (OIDN's
    prefiltering, for final frames); without prefilter they are given as
    they are, noisy (OIDN then filters them with the beauty)."""
    if albedo is None:
        return run_filter(device, path, {"color": beauty}, quality, hdr=True)
    if not prefilter:
        return run_filter(device, path, {"color": beauty, "albedo": albedo, "normal": normal},
                          quality, hdr=True)
    albedo = run_filter(device, path, {"albedo": albedo}, quality)
    normal = run_filter(device, path, {"normal": normal}, quality)
    return run_filter(device, path, {"color": beauty, "albedo": albedo, "normal": normal},
                      quality, hdr=True, clean_aux=True)


def to_srgb8(rgb, exposure):
    """sRGB 8-bit of linear rgb times 2^exposure, clamped (as yscene's png)."""
    linear = np.clip(rgb * np.float32(2.0 ** exposure), 0, 1)
    srgb = np.where(linear <= 0.0031308, 12.92 * linear,
                    1.055 * np.power(linear, 1 / 2.4) - 0.055)
    return np.floor(srgb * 255 + 0.5).astype(np.uint8)


def create_temporary(path, extension):
    """An empty file beside path, of a name no one else has, that takes the
    image before it is renamed over path."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        descriptor, temporary = tempfile.mkstemp(
            prefix=f".{os.path.basename(path)}.", suffix=extension, dir=folder)
    except OSError as error:
        raise Failure(path, f"cannot create a file in {folder}: {error.strerror}") from None
    os.close(descriptor)
    return temporary


def write_pfm(temporary, path, rgb):
    """Portable float map: a text header, then little-endian float rows from
    the bottom one up (the -1 scale says little-endian)."""
    height, width = rgb.shape[:2]
    try:
        with open(temporary, "wb") as file:
            file.write(f"PF\n{width} {height}\n-1\n".encode("ascii"))
            file.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())
    except OSError as error:
        raise Failure(path, f"cannot write: {error.strerror}") from None


def write_with_oiio(temporary, path, extension, rgb, exposure, note):
    """exr, hdr: linear float; png, jpg: sRGB 8-bit."""
    height, width = rgb.shape[:2]
    if extension in SRGB_EXTENSIONS:
        spec = oiio.ImageSpec(width, height, 3, "uint8")
        spec.attribute("oiio:ColorSpace", "sRGB")
        data = to_srgb8(rgb, exposure)
    else:
        spec = oiio.ImageSpec(width, height, 3, "float")
        spec.attribute("compression", "zip")
        data = rgb
    spec.attribute("yocto:denoised", note)
    image = oiio.ImageOutput.create(temporary)
    if image is None:
        raise Failure(path, f"cannot write: {one_line(oiio.geterror())}")
    written = image.open(temporary, spec) and image.write_image(data)
    closed = image.close()
    if not (written and closed):
        raise Failure(path, f"cannot write: {one_line(image.geterror())}")


def write_image(temporary, path, extension, rgb, exposure, note):
    """Writes rgb into temporary, flushes it to disk and renames it to path."""
    if extension == ".pfm":  # OpenImageIO 2.4 reads PFM but has no writer for it
        write_pfm(temporary, path, rgb)
    else:
        write_with_oiio(temporary, path, extension, rgb, exposure, note)
    try:
        with open(temporary, "rb+") as file:
            os.fsync(file.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # mkstemp made it private
        os.replace(temporary, path)
    except OSError as error:
        raise Failure(path, f"cannot write: {error.strerror}") from None


def main():
    args = parse_args()
    start = time.monotonic()
    temporary = None
    try:
        extension = output_extension(args.output)
        import_modules()
        spec, pixels = read_exr(args.image)
        beauty = layer(spec, pixels, args.image, "beauty", BEAUTY)
        albedo = normal = None
        if not args.no_aux:
            albedo = np.clip(layer(spec, pixels, args.image, "albedo", ALBEDO), 0, 1)
            normal = layer(spec, pixels, args.image, args.aux_normal, NORMALS[args.aux_normal])
        del pixels
        temporary = create_temporary(args.output, extension)
        quality = getattr(pyoidn, f"OIDN_QUALITY_{args.quality.upper()}")
        device = pyoidn.Device(pyoidn.OIDN_DEVICE_TYPE_CPU)
        try:
            check(device, args.image, "create a CPU device")
            device.commit()
            check(device, args.image, "start its CPU device")
            version = ".".join(str(device.get_int(f"version{part}"))
                               for part in ("Major", "Minor", "Patch"))
            threads = device.get_int("numThreads") or os.cpu_count()
            filter_start = time.monotonic()
            result = denoise(device, args.image, beauty, albedo, normal, quality,
                             not args.no_prefilter)
            filter_seconds = time.monotonic() - filter_start
        finally:
            device.release()
        guides = "no aux" if args.no_aux else f"albedo + {args.aux_normal}" + (
            ", not prefiltered" if args.no_prefilter else ", prefiltered")
        note = f"OIDN {version} RT, hdr, quality {args.quality}, {guides}"
        write_image(temporary, args.output, extension, result, args.exposure, note)
        temporary = None
    except Failure as failure:
        print(f"error: {failure}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted; nothing written", file=sys.stderr)
        return 130
    except Exception as error:  # one line, never a traceback
        print(f"error: {args.image}: {type(error).__name__}: {one_line(error)}", file=sys.stderr)
        return 1
    finally:
        if temporary is not None:
            try:
                os.remove(temporary)
            except OSError:
                pass
    if not args.quiet:
        print(f"denoised {args.image} ({spec.width}x{spec.height}, {guides}, quality "
              f"{args.quality}) with OIDN {version} on the CPU ({threads} threads) in "
              f"{filter_seconds:.2f} s ({time.monotonic() - start:.2f} s in all): {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
