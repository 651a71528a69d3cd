#!/usr/bin/python3
"""Renders one image on a Dask cluster: the samples are split into parts,
each part is rendered by `yscene render --sample-range` on some worker, and
the parts are added up by `yscene merge` into an image bit for bit equal to
a render on one machine.

Usage:
  scripts/farm.py render SCENE --output IMAGE --samples N --parts K
      [--scheduler ADDRESS] [--workers W] [--threads T] [--yscene PATH]
      [--retries R] [--exposure E] [--quiet] [-- FLAGS FOR yscene render]

  Everything after `--` is passed to every `yscene render` unchanged, e.g.
  `-- --resolution 64 --seed 3`. Samples 0..N-1 are split into K contiguous
  ranges as even as possible (the first N % K one sample larger).

Needs Dask (Debian: python3-distributed, importable by /usr/bin/python3).

On this machine only (no --scheduler): a LocalCluster of W worker processes
(default: 2, or 1 on a single core) of one task each, every yscene using T
threads (default: cores / W).

On several machines: start a scheduler and workers, then pass its address.
  host A:  dask scheduler            (or dask-scheduler; listens on :8786)
  hosts:   dask worker tcp://A:8786 --nworkers 1 --nthreads 1
           (or dask-worker ...; one part at a time per host, whose yscene
           uses all the host's cores: --threads defaults to 0 = all cores
           with --scheduler)
  client:  scripts/farm.py render SCENE ... --scheduler tcp://A:8786
The workers read the scene (and the files it refers to) by path and run the
yscene binary by path: both paths must be the same on every host, e.g. a
shared file system mounted at the same place. The scene path is made
absolute on the client. Parts come back to the client as bytes: no shared
output folder is needed.

Recovery: a part whose yscene fails is tried again (--retries, default 2);
a part whose worker dies is rescheduled by Dask (the nanny restarts the
worker; yscene dies with its worker). Exit status: 0 on success, 1 on an
error (one line `error: ...`, no image written), 130 on Ctrl-C, 2 on bad
usage. The image is written by yscene merge, atomically: complete or absent.
"""

import argparse
import hashlib
import logging
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

# Dask logs at INFO by default; only warnings and errors are of interest.
# Set before the import so the config, and the worker processes started
# from it, inherit it.
os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "warning")

# The LocalCluster's worker processes are spawned: each imports this file as
# __mp_main__ first. A Ctrl-C in the terminal reaches them too; they ignore
# it (else each prints a traceback), the client shuts them down instead.
if __name__ == "__mp_main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Options farm.py sets itself: passing them through would clash.
RESERVED = {
    "-o": "--output", "--output": "--output", "-s": "--samples", "--samples": "--samples",
    "-t": "--threads", "--threads": "--threads", "--sample-range": "--sample-range",
}
IMAGE_EXTENSIONS = (".exr", ".hdr", ".pfm", ".png", ".jpg", ".jpeg")


class FarmError(Exception):
    """An error reported as one line `error: ...` and exit status 1."""


# -----------------------------------------------------------------------------
# ON THE WORKERS
# -----------------------------------------------------------------------------

def render_part(yscene, scene, samples, start, stop, threads, extra):
    """Renders samples start..stop-1 of the samples-sample render of scene in a
    private temporary folder and returns the part file's bytes. Runs on a
    worker: this function is shipped to it by value (cloudpickle), so it
    imports what it needs."""
    import ctypes
    import shutil
    import signal
    import socket
    import subprocess
    import tempfile

    import distributed

    # The child must not outlive the worker (killed, or its nanny restarting
    # it): the kernel sends it SIGKILL when its parent dies. libc is loaded
    # here, before the fork: the child should call nothing but prctl.
    # PR_SET_PDEATHSIG fires when the parent *thread* ends; this thread waits
    # for the child, so it lives as long as yscene does.
    libc = ctypes.CDLL(None, use_errno=True)
    parent = os.getpid()

    def die_with_parent():
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the worker died before prctl
            os.kill(os.getpid(), signal.SIGKILL)

    host = socket.gethostname()
    if not os.access(yscene, os.X_OK):
        raise RuntimeError(f"{yscene}: no such executable on host {host}")
    # In the worker's own folder: if the worker is killed before the finally
    # below runs, Dask removes the folder with the worker's (at once when
    # the worker closes, or as a stale folder when the next one starts).
    try:
        base = distributed.get_worker().local_directory
    except ValueError:  # not on a worker
        base = None
    workdir = tempfile.mkdtemp(prefix="yscene-part-", dir=base)
    try:
        part = os.path.join(workdir, "part.exr")
        command = [yscene, "render", scene, *extra, "--output", part, "--samples", str(samples),
                   "--sample-range", f"{start}:{stop}", "--threads", str(threads), "--quiet"]
        # A process group of its own: a Ctrl-C in the worker's terminal would
        # make yscene save the samples done so far and succeed with a short
        # part. Not a session of its own: Linux's autogroup scheduling would
        # then give each yscene the CPU share of a whole login session.
        result = subprocess.run(command, stdin=subprocess.DEVNULL, capture_output=True,
                                text=True, errors="replace", preexec_fn=die_with_parent,
                                process_group=0)
        lines = [line.strip() for line in result.stderr.splitlines() if line.strip()]
        if result.returncode != 0:
            errors = [line for line in lines if line.startswith("error:")] or lines[-3:]
            message = " | ".join(line.removeprefix("error: ") for line in errors)
            if result.returncode < 0:
                how = f"killed by {signal.Signals(-result.returncode).name}"
            else:
                how = f"exit status {result.returncode}"
            raise RuntimeError(f"yscene render failed on host {host} ({how})"
                               + (f": {message}" if message else ""))
        if any(line.startswith("interrupted") for line in lines):
            raise RuntimeError(f"yscene render was interrupted on host {host}")
        with open(part, "rb") as file:
            return file.read()
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


# -----------------------------------------------------------------------------
# ON THE CLIENT
# -----------------------------------------------------------------------------

def split_samples(samples, parts):
    """[0, samples) as parts contiguous ranges (start, stop), the first
    samples % parts of them one sample larger."""
    size, larger = divmod(samples, parts)
    ranges, start = [], 0
    for i in range(parts):
        stop = start + size + (1 if i < larger else 0)
        ranges.append((start, stop))
        start = stop
    return ranges


def part_key(scene, samples, extra, start, stop):
    """A deterministic task key: a render's part has the same name in every
    run, so a scheduler shared by two runs of one render computes it once.
    The scene's size and time stamp keep an edited scene from matching."""
    status = os.stat(scene)
    identity = repr((scene, status.st_size, status.st_mtime_ns, samples, list(extra)))
    digest = hashlib.sha1(identity.encode()).hexdigest()[:12]
    return f"yscene-part-{digest}-{start}-{stop}"


def format_duration(seconds):
    seconds = int(seconds + 0.5)
    return f"{seconds // 3600:02d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def print_progress(done, total, started):
    """A progress line on stderr, redrawn in place (as yscene's)."""
    width = 30
    filled = done * width // total
    elapsed = time.monotonic() - started
    line = f"\r[{'#' * filled}{' ' * (width - filled)}] {done}/{total} parts  " \
           f"elapsed {format_duration(elapsed)}"
    if done > 0:
        line += f"  eta {format_duration(elapsed / done * (total - done))}"
    print(line + " ", end="", file=sys.stderr, flush=True)


def default_yscene():
    built = os.path.join(ROOT, "build", "apps", "yscene")
    return built if os.access(built, os.X_OK) else (shutil.which("yscene") or "yscene")


def check_arguments(args, extra):
    """Errors found before any work: a missing scene, a bad split, ..."""
    if args.samples < 1:
        raise FarmError(f"--samples {args.samples}: must be at least 1")
    if not 1 <= args.parts <= args.samples:
        raise FarmError(f"--parts {args.parts}: must be between 1 and --samples ({args.samples})")
    if args.workers is not None and args.workers < 1:
        raise FarmError(f"--workers {args.workers}: must be at least 1")
    if args.threads is not None and args.threads < 0:
        raise FarmError(f"--threads {args.threads}: must be 0 (all cores) or more")
    if args.retries < 0:
        raise FarmError(f"--retries {args.retries}: must be 0 or more")
    if not os.path.isfile(args.scene):
        raise FarmError(f"{args.scene}: scene not found")
    for flag in extra:
        name = flag.split("=", 1)[0]
        if name in RESERVED or (len(name) > 2 and name[:2] in ("-o", "-s", "-t")):
            raise FarmError(f"{flag}: farm.py sets {RESERVED.get(name, RESERVED.get(name[:2]))} "
                            f"itself; use its own option, not one after --")
    if not args.output.lower().endswith(IMAGE_EXTENSIONS):
        raise FarmError(f"{args.output}: unknown image extension (use exr, hdr, pfm, png or jpg)")
    if os.path.isdir(args.output):
        raise FarmError(f"{args.output}: is a directory, not a file")
    folder = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(folder):
        raise FarmError(f"{args.output}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise FarmError(f"{args.output}: folder {folder} is not writable")
    yscene = shutil.which(args.yscene)
    if yscene is None:
        raise FarmError(f"{args.yscene}: yscene not found (build it or pass --yscene)")
    return os.path.abspath(yscene)


def merge_parts(yscene, names, output, exposure):
    """Adds up the part files with yscene merge into output."""
    command = [yscene, "merge", *names, "--output", output, "--quiet"]
    if exposure is not None:
        command += ["--exposure", str(exposure)]
    result = subprocess.run(command, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                            errors="replace")
    if result.returncode != 0:
        lines = [line.strip() for line in result.stderr.splitlines() if line.strip()]
        message = " | ".join(line.removeprefix("error: ") for line in lines[-3:])
        raise FarmError(f"yscene merge failed: {message or f'exit status {result.returncode}'}")


def render_on(client, args, extra, yscene, scene):
    """Submits the parts, saves them as they come back (with progress) and
    merges them into the output."""
    from distributed import as_completed

    ranges = split_samples(args.samples, args.parts)
    futures = {}
    for start, stop in ranges:
        key = part_key(scene, args.samples, extra, start, stop)
        future = client.submit(render_part, yscene, scene, args.samples, start, stop,
                               args.threads, extra, key=key, retries=args.retries)
        futures[future] = (start, stop)
    started = time.monotonic()
    show = not args.quiet
    if show:
        print_progress(0, len(ranges), started)
    with tempfile.TemporaryDirectory(prefix="farm-parts-") as folder:
        names = []
        try:
            for future in as_completed(futures):
                start, stop = futures.pop(future)
                try:
                    data = future.result()
                except Exception as error:
                    message = " ".join(str(error).split()) or type(error).__name__
                    raise FarmError(f"part {start}:{stop}: {message}") from None
                # To disk at once: the client holds one part at a time.
                names.append(os.path.join(folder, f"part-{start}-{stop}.exr"))
                with open(names[-1], "wb") as file:
                    file.write(data)
                del future, data
                if show:
                    print_progress(len(names), len(ranges), started)
        finally:
            if show:
                print(file=sys.stderr)
            # On a shared cluster, a cancel keeps parts from starting but does
            # not stop running ones; closing a LocalCluster ends them all.
            client.cancel(list(futures))
        merge_parts(yscene, names, args.output, args.exposure)


def close_quietly(thing):
    """Closes a client or cluster; a failure to close is no render error."""
    try:
        thing.close()
    except Exception:
        pass


def run(args, extra):
    yscene = check_arguments(args, extra)
    scene = os.path.abspath(args.scene)
    import distributed  # here: a second to import, not needed for the checks above
    logging.getLogger("distributed").setLevel(logging.WARNING)

    started = time.monotonic()
    cluster = client = None
    try:
        if args.scheduler:
            # Each host's yscene uses all its cores unless told otherwise.
            args.threads = 0 if args.threads is None else args.threads
            try:
                client = distributed.Client(args.scheduler)
            except OSError as error:
                raise FarmError(f"cannot connect to the scheduler {args.scheduler}: "
                                + " ".join(str(error).split())) from None
            workers = len(client.scheduler_info().get("workers", {}))
            if workers == 0 and not args.quiet:
                print(f"farm: no workers at {args.scheduler} yet; waiting for some",
                      file=sys.stderr)
            where = f"the cluster at {args.scheduler}"
        else:
            cores = len(os.sched_getaffinity(0))
            workers = args.workers or min(2, cores)
            if args.threads is None:
                args.threads = max(1, cores // workers)
            # One task per worker process: each runs a multi-threaded yscene.
            # The scheduler's HTTP server (the dashboard, if bokeh is there)
            # on any free port: 8787 may be taken, by a `dask scheduler` say.
            # The workers' warnings (a failed part, each retry) are left out:
            # the error line says it all.
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1,
                                               processes=True, dashboard_address=":0",
                                               silence_logs=logging.ERROR)
            client = distributed.Client(cluster)
            where = f"{workers} local worker(s)"
        render_on(client, args, extra, yscene, scene)
    finally:
        if client is not None:
            close_quietly(client)
        if cluster is not None:
            close_quietly(cluster)
    if not args.quiet:
        print(f"farm: rendered {args.output}: {args.samples} samples in {args.parts} part(s) "
              f"on {where} (yscene --threads {args.threads}) in "
              f"{time.monotonic() - started:.1f}s")


def parse_arguments(argv):
    parser = argparse.ArgumentParser(
        prog="farm.py", description="Render one image's samples in parts on a Dask cluster "
        "and merge them (bit for bit the image of one render).",
        epilog="Flags after -- go to every yscene render, e.g. -- --resolution 64 --seed 3.")
    commands = parser.add_subparsers(dest="command", required=True)
    render = commands.add_parser("render", help="render a scene in parts and merge them",
                                 epilog="Flags after -- go to every yscene render.")
    render.add_argument("scene", help="scene (json, pbrt or hair), same path on every host")
    render.add_argument("-o", "--output", required=True, help="image (exr, hdr, pfm, png, jpg)")
    render.add_argument("-s", "--samples", type=int, required=True, help="samples per pixel")
    render.add_argument("-k", "--parts", type=int, required=True, help="parts (tasks), 1 ... N")
    render.add_argument("--scheduler", help="address of a running Dask scheduler "
                        "(default: a local cluster)")
    render.add_argument("-w", "--workers", type=int,
                        help="local worker processes (default: 2, or 1 on one core)")
    render.add_argument("-t", "--threads", type=int,
                        help="threads of each yscene (default: cores / workers locally, "
                        "0 = all cores with --scheduler)")
    render.add_argument("--yscene", default=default_yscene(),
                        help="yscene binary, same path on every host (default: %(default)s)")
    render.add_argument("--retries", type=int, default=2,
                        help="times a failed part is tried again (default: %(default)s)")
    render.add_argument("-e", "--exposure", type=float, help="exposure for png/jpg (stops)")
    render.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    return parser.parse_args(argv)


def main(argv):
    # Everything after the first "--" goes to yscene render unchanged.
    extra = []
    if "--" in argv:
        argv, extra = argv[:argv.index("--")], argv[argv.index("--") + 1:]
    args = parse_arguments(argv)
    try:
        run(args, extra)
        return 0
    except FarmError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("error: interrupted; nothing written", file=sys.stderr)
        return 130


if __name__ == "__main__":  # the guard keeps spawned worker processes from running main
    sys.exit(main(sys.argv[1:]))
