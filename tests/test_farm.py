#!/usr/bin/python3
"""Tests scripts/farm.py, the Dask render farm driver: its image is bit for
bit the image of one render, also when a worker is killed in the middle of a
part, and its errors leave no image.

Usage: /usr/bin/python3 tests/test_farm.py YSCENE_PATH

Needs Dask (Debian: python3-distributed, importable by /usr/bin/python3).
Exit status 0 when every test passes.
"""

import logging
import os
import signal
import subprocess
import sys
import tempfile
import time
import unittest
import warnings

try:
    import distributed
except ImportError:
    distributed = None

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FARM = os.path.join(ROOT, "scripts", "farm.py")
YSCENE = None  # set from the command line

# A tiny render for the comparisons and the errors.
SAMPLES, RESOLUTION, PARTS = 12, 48, 3
# The worker-kill render: parts long enough (about a second on one core) to
# catch one running.
KILL_SAMPLES, KILL_RESOLUTION, KILL_PARTS = 144, 96, 3


def step(text):
    print(f"[test_farm] {text}", file=sys.stderr, flush=True)


def run(command, timeout=120):
    """Runs a command, its output captured; fails the test on a timeout."""
    return subprocess.run(command, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=timeout)


def farm_command(scene, output, samples, parts, *options, extra=()):
    return [sys.executable, FARM, "render", scene, "--output", output, "--samples",
            str(samples), "--parts", str(parts), "--yscene", YSCENE, *options, "--", *extra]


def running_parts(parents):
    """(pid, parent pid, command line) of the yscene render --sample-range
    processes whose parent is one of parents, from /proc."""
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat") as file:
                fields = file.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{name}/cmdline", "rb") as file:
                argv = file.read().decode(errors="replace").split("\0")
        except OSError:  # gone meanwhile
            continue
        state, ppid = fields[0], int(fields[1])
        if (ppid in parents and state != "Z" and os.path.basename(argv[0]) == "yscene"
                and "render" in argv and "--sample-range" in argv):
            found.append((int(name), ppid, argv))
    return found


def is_dead(pid):
    """True if pid is gone or a zombie (dead, not yet reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as file:
            return file.read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


class FarmTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.folder = tempfile.TemporaryDirectory(prefix="test-farm-")
        cls.tmp = cls.folder.name
        cls.scene = os.path.join(cls.tmp, "scene.json")
        step(f"generating the scene {cls.scene}")
        result = run([YSCENE, "hair", "--style", "curly", "-n", "200", "-o", cls.scene])
        if result.returncode != 0:
            cls.folder.cleanup()
            raise RuntimeError(f"yscene hair failed: {result.stderr.strip()}")
        cls.reference = os.path.join(cls.tmp, "ref.pfm")
        cls.render_reference(cls.reference, SAMPLES, RESOLUTION)

    @classmethod
    def tearDownClass(cls):
        cls.folder.cleanup()

    @classmethod
    def render_reference(cls, output, samples, resolution):
        step(f"reference: one yscene render of {samples} samples at resolution {resolution}")
        result = run([YSCENE, "render", cls.scene, "--output", output, "--samples", str(samples),
                      "--resolution", str(resolution), "-q"])
        if result.returncode != 0:
            raise RuntimeError(f"yscene render failed: {result.stderr.strip()}")

    def assertSameFile(self, path, reference):
        with open(path, "rb") as file:
            data = file.read()
        with open(reference, "rb") as file:
            expected = file.read()
        if data != expected:
            first = next((i for i, (a, b) in enumerate(zip(data, expected)) if a != b),
                         min(len(data), len(expected)))
            self.fail(f"{path} ({len(data)} bytes) differs from {reference} "
                      f"({len(expected)} bytes) from byte {first}")

    def assertFarmOk(self, result, output):
        self.assertEqual(result.returncode, 0,
                         f"farm.py failed (exit {result.returncode}):\n{result.stderr}")
        self.assertTrue(os.path.isfile(output), f"farm.py wrote no {output}")

    def test_1_local_cluster(self):
        output = os.path.join(self.tmp, "farm.pfm")
        step(f"farm.py on its own LocalCluster of 2 workers: {SAMPLES} samples in {PARTS} parts")
        result = run(farm_command(self.scene, output, SAMPLES, PARTS, "--workers", "2",
                                  "--threads", "1", extra=["--resolution", str(RESOLUTION)]))
        self.assertFarmOk(result, output)
        step(f"  {result.stdout.strip()}")
        step("  its image is byte for byte the reference")
        self.assertSameFile(output, self.reference)

    def test_2_worker_killed(self):
        reference = os.path.join(self.tmp, "kill-ref.pfm")
        self.render_reference(reference, KILL_SAMPLES, KILL_RESOLUTION)
        output = os.path.join(self.tmp, "kill.pfm")
        log = os.path.join(self.tmp, "kill.log")
        step("starting a LocalCluster of 2 worker processes with nannies")
        with warnings.catch_warnings():
            # Tornado 6.2 deprecates what Dask 2022.12 calls when it starts.
            warnings.filterwarnings("ignore", "make_current is deprecated", DeprecationWarning)
            cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1,
                                               processes=True, dashboard_address=":0")
        with cluster, distributed.Client(cluster) as client:
            workers = set(client.run(os.getpid).values())
            step(f"  worker pids {sorted(workers)}; farm.py renders {KILL_SAMPLES} samples in "
                 f"{KILL_PARTS} parts on it (--scheduler {cluster.scheduler_address})")
            command = farm_command(self.scene, output, KILL_SAMPLES, KILL_PARTS, "--scheduler",
                                   cluster.scheduler_address, "--threads", "1",
                                   extra=["--resolution", str(KILL_RESOLUTION)])
            with open(log, "w") as log_file:
                farm = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=log_file,
                                        stderr=subprocess.STDOUT)
                try:
                    killed = self.kill_a_working_worker(farm, workers)
                    step("  waiting for farm.py to finish")
                    returncode = farm.wait(timeout=90)
                finally:
                    if farm.poll() is None:
                        farm.kill()
                        farm.wait()
        with open(log) as file:
            text = file.read()
        self.assertIsNotNone(killed, "no worker was ever seen running a yscene part, so none "
                             f"was killed; farm.py said:\n{text}")
        self.assertEqual(returncode, 0, f"farm.py failed (exit {returncode}):\n{text}")
        self.assertTrue(os.path.isfile(output), f"farm.py wrote no {output}:\n{text}")
        step("  farm.py succeeded; its image is byte for byte the reference")
        self.assertSameFile(output, reference)

    def kill_a_working_worker(self, farm, workers):
        """Polls /proc until a worker runs a yscene part, SIGKILLs that worker
        (not its nanny) and checks that the yscene child dies too. Returns
        (worker pid, yscene pid), or None if farm.py ended first."""
        deadline = time.monotonic() + 60
        seen = {}  # yscene pid -> when first seen running
        while farm.poll() is None and time.monotonic() < deadline:
            now = time.monotonic()
            for child, worker, argv in running_parts(workers):
                seen.setdefault(child, now)
                # Well into the part (loading takes a fraction of this), if
                # still running.
                if now - seen[child] < 0.3:
                    continue
                part = argv[argv.index("--sample-range") + 1]
                step(f"  worker {worker} runs yscene {child} (samples {part}): SIGKILL to "
                     f"the worker")
                os.kill(worker, signal.SIGKILL)
                # prctl(PR_SET_PDEATHSIG) in farm.py: the kernel kills the child.
                until = time.monotonic() + 10
                while not is_dead(child) and time.monotonic() < until:
                    time.sleep(0.02)
                self.assertTrue(is_dead(child), f"yscene {child} outlived its worker {worker}")
                step(f"  the yscene child {child} died with its worker")
                return worker, child
            time.sleep(0.02)
        return None

    def test_3_missing_scene(self):
        scene = os.path.join(self.tmp, "no-such-scene.json")
        output = os.path.join(self.tmp, "missing.pfm")
        step("farm.py with a missing scene: exit 1, one error line naming it, no image")
        result = run(farm_command(scene, output, SAMPLES, PARTS,
                                  extra=["--resolution", str(RESOLUTION)]))
        self.assertEqual(result.returncode, 1, f"exit {result.returncode}:\n{result.stderr}")
        lines = result.stderr.strip().splitlines()
        self.assertEqual(len(lines), 1, f"expected one line:\n{result.stderr}")
        self.assertTrue(lines[0].startswith("error:"), lines[0])
        self.assertIn(scene, lines[0])
        self.assertFalse(os.path.exists(output), f"{output} was written")

    def test_4_bad_parts(self):
        output = os.path.join(self.tmp, "parts.pfm")
        for parts in (0, SAMPLES + 1):
            step(f"farm.py with --parts {parts} of {SAMPLES} samples: an error, no image")
            result = run(farm_command(self.scene, output, SAMPLES, parts,
                                      extra=["--resolution", str(RESOLUTION)]))
            self.assertNotEqual(result.returncode, 0, f"--parts {parts} was accepted")
            self.assertIn("error", result.stderr)
            self.assertFalse(os.path.exists(output), f"{output} was written")


def main():
    global YSCENE
    if len(sys.argv) < 2:
        print("usage: /usr/bin/python3 tests/test_farm.py YSCENE_PATH [unittest options]",
              file=sys.stderr)
        return 2
    YSCENE = os.path.abspath(sys.argv.pop(1))
    if not os.access(YSCENE, os.X_OK):
        print(f"test_farm.py: {YSCENE}: no yscene executable there", file=sys.stderr)
        return 1
    if distributed is None:
        print(f"test_farm.py: Dask is not importable by {sys.executable} "
              "(Debian: apt-get install python3-distributed; run with /usr/bin/python3)",
              file=sys.stderr)
        return 1
    # Dask's INFO lines (workers starting) are noise; warnings stay.
    logging.getLogger("distributed").setLevel(logging.WARNING)
    started = time.monotonic()
    program = unittest.main(exit=False, verbosity=2)
    step(f"done in {time.monotonic() - started:.1f}s")
    return 0 if program.result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
