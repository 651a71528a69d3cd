"""The main of a Python test that needs a venv of scripts/setup.sh: run as
`python3 tests/test_X.py YSCENE_PATH [unittest options]` by ctest, it runs
itself again under the venv's python, or exits 77 (ctest's skip) where the
venv cannot import what the test needs."""

import os
import subprocess
import sys
import unittest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_tests_in_venv(script, venv_name, probe, missing, set_yscene):
    """Runs the unittest cases of `script` (the __main__ module) under
    .venv/VENV_NAME, whose python must run `probe` (imports); `missing` names
    what to install for the skip message. set_yscene gets the yscene path."""
    venv = os.path.join(ROOT, ".venv", venv_name)
    python = os.path.join(venv, "bin", "python")
    if len(sys.argv) < 2:
        print(f"usage: python3 {os.path.relpath(script, ROOT)} YSCENE_PATH [unittest options]",
              file=sys.stderr)
        return 2
    if os.path.realpath(sys.prefix) != os.path.realpath(venv):
        if not os.path.isfile(python) or subprocess.run(
                [python, "-c", probe], capture_output=True, timeout=120).returncode != 0:
            print(f"skipped: {missing} not installed (bash scripts/setup.sh --{venv_name})")
            return 77
        os.execv(python, [python, os.path.abspath(script), *sys.argv[1:]])
    set_yscene(os.path.abspath(sys.argv[1]))
    program = unittest.main(argv=[sys.argv[0], *sys.argv[2:]], exit=False, verbosity=2)
    return 0 if program.result.wasSuccessful() else 1
