#!/usr/bin/env bash
# Renders the default scene 3 times and prints the median render time,
# samples/s, rays/s and peak memory (the figures in docs/RESULTS.md).
# Usage: bash scripts/measure_default.sh [scene.json] [extra render args]
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:-scenes/hair-locks/hair-locks.json}
shift || true
[ $# -gt 0 ] || set -- --samples 16 --resolution 640
mkdir -p out
for run in 1 2 3; do
  # Not --quiet: the summary line is what is measured (progress goes to stderr).
  build/apps/yscene render "$scene" --output out/measure.exr "$@"
done | tee out/measure.log
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg)"
/usr/bin/python3 - <<'PY'
import re, statistics
lines = open("out/measure.log").read().splitlines()
def values(pattern):
    return [float(m.group(1)) * {"": 1, "k": 1e3, "M": 1e6, "G": 1e9}[m.group(2)]
            for m in (re.search(pattern, l) for l in lines) if m]
time = statistics.median(values(r"in ([0-9.]+)()s"))
samples = statistics.median(values(r"\(([0-9.]+)([kMG]?) samples/s"))
rays = statistics.median(values(r"([0-9.]+)([kMG]?) rays/s"))
memory = statistics.median(values(r"peak memory ([0-9.]+)([kMG]?) bytes"))
print(f"median of 3: {time:.2f} s, {samples/1e3:.1f}k samples/s, {rays/1e6:.2f}M rays/s, "
      f"peak memory {memory/1e6:.0f} MB")
PY
