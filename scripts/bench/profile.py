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
                                 "--sort", "dso,symbol", "--show-nr-samples"],
                                capture_output=True, text=True, check=True).stdout
    # Shares from the sample counts: the printed percentages are rounded to
    # 0.01%, and Embree alone has thousands of unnamed addresses.
    counts, symbols = {name: 0 for name, _ in COMPONENTS}, []
    counts["other"] = 0
    for line in report.splitlines():
        m = re.match(r"\s+[0-9.]+%\s+([0-9]+)\s+(\S+)\s+\[(.)\]\s+(.*?)\s*$", line)
        if not m:
            continue
        samples, dso, symbol = int(m.group(1)), m.group(2), m.group(4)
        if m.group(3) == "k":
            dso = "[kernel]"
        symbols.append((samples, dso, symbol))
        for name, match in COMPONENTS:
            if match(dso, symbol):
                counts[name] += samples
                break
        else:
            counts["other"] += samples
    total = max(sum(counts.values()), 1)
    print(f"| component | share of CPU samples ({total} samples) |\n|---|---:|")
    for name, count in counts.items():
        print(f"| {name} | {100 * count / total:.1f}% |")
    print("\ntop symbols:")
    for samples, dso, symbol in sorted(symbols, reverse=True)[:15]:
        print(f"  {100 * samples / total:5.2f}%  {dso:24s} {symbol[:70]}")


if __name__ == "__main__":
    main()
