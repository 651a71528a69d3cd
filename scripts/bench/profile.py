#!/usr/bin/env python3
"""Where a render's time goes: runs `perf record` on one yscene render (one
thread) and prints the share of samples per component (Embree, hair model,
fiber hit geometry, tracer, start-up and the rest) and the top symbols.

    python3 scripts/bench/profile.py [--yscene build/apps/yscene] SCENE [render args...]

Needs `perf` (linux-perf). Samples are CPU-clock samples of the whole process,
loading and BVH build included: use enough samples per pixel that rendering
dominates.
"""

import os
import re
import subprocess
import sys
import tempfile

# Component of a (dso, symbol) pair; the first match wins.
COMPONENTS = [
    ("Embree (ray queries and BVH)", lambda d, s: "embree" in d or s.startswith("rtc")),
    ("hair model (yocto_hair + libm)",
     lambda d, s: "libm" in d or re.search(r"hair|lobe|bessel|make_angles|demux", s)),
    ("fiber hit geometry (eval_fiber_point)", lambda d, s: "fiber_point" in s),
    ("tracer (trace_path, lights, environment, camera)",
     lambda d, s: re.search(r"trace|eval_texture|environment|light|camera|rng|surface", s)),
    ("start-up, loading, OS", lambda d, s: "ld-linux" in d or "[kernel" in d or "libc" in d
     or re.search(r"load|parse|ply|json", s)),
]


def main():
    args = sys.argv[1:]
    yscene = "build/apps/yscene"
    if args[:1] == ["--yscene"]:
        yscene, args = args[1], args[2:]
    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "perf.data")
        subprocess.run(["perf", "record", "-q", "-o", data, yscene, "render", args[0],
                        "-o", os.path.join(tmp, "out.pfm"), "-q", "-t", "1"] + args[1:],
                       check=True, stdout=subprocess.DEVNULL)
        report = subprocess.run(["perf", "report", "-i", data, "--no-children", "--stdio",
                                 "--sort", "dso,symbol"], capture_output=True, text=True,
                                check=True).stdout
    shares, symbols = {name: 0.0 for name, _ in COMPONENTS}, []
    shares["other"] = 0.0
    for line in report.splitlines():
        m = re.match(r"\s+([0-9.]+)%\s+(\S+)\s+\[.\]\s+(.*?)\s*$", line)
        if not m:
            m = re.match(r"\s+([0-9.]+)%\s+(\S+)\s+\[k\]\s+(.*?)\s*$", line)
            if not m:
                continue
        share, dso, symbol = float(m.group(1)), m.group(2), m.group(3)
        if line.find("[k]") >= 0:
            dso = "[kernel]"
        symbols.append((share, dso, symbol))
        for name, match in COMPONENTS:
            if match(dso, symbol):
                shares[name] += share
                break
        else:
            shares["other"] += share
    print("| component | share of CPU samples |\n|---|---:|")
    for name, share in shares.items():
        print(f"| {name} | {share:.1f}% |")
    print("\ntop symbols:")
    for share, dso, symbol in symbols[:15]:
        print(f"  {share:5.2f}%  {dso:24s} {symbol[:70]}")


if __name__ == "__main__":
    main()
