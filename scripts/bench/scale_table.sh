#!/usr/bin/env bash
# The scale table of docs/RESULTS.md (issue 22): straight grooms of 10k, 100k
# and 1M strands (4 Bezier segments each), for this build's yscene against
# Embree alone on the same curves (../shared/tools/embree_build.cpp: shared
# vertices, 2 threads). Per groom, medians of 3 runs: Embree's build time and
# bytes; yscene's BVH build, BVH bytes, peak memory and curve pieces (a
# render of --samples at 720x720, 2 threads, --stats); and the ray rates of
# `--embree-only` (the render's rays at 256x256, cast again through Embree
# alone, without shading). Prints a markdown table. Run it on an idle machine.
#
#   bash scripts/bench/scale_table.sh [--samples 4] [--strands "10000 100000 1000000"]
#       [--work out/scale]
set -euo pipefail
cd "$(dirname "$0")/../.."
yscene=$PWD/build/apps/yscene
samples=4 strands_list="10000 100000 1000000" work=$PWD/out/scale
while [ $# -gt 0 ]; do
  case $1 in
    --samples) samples=$2; shift 2 ;;
    --strands) strands_list=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    *) echo "scale_table.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$work"
tool=$(realpath -m ../shared/tools/embree_build.cpp)
[ -x "$work/embree_build" ] || g++ -O2 -o "$work/embree_build" "$tool" -lembree3 -ltbb
median() { sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
field() { tr ' ' '\n' | sed -n "s/^$1=//p"; }   # field NAME < "stats a=1 b=2"

echo "| strands | segments | Embree alone: build | bytes | yscene: BVH build | × Embree | BVH bytes | peak memory | curve pieces | rays/s: renderer | Embree |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
for strands in $strands_list; do
  json=$work/straight$strands/straight$strands.json
  [ -f "$json" ] || "$yscene" hair --style straight --strands "$strands" --segments 4 -o "$json" -q
  : > "$work/embree.txt"; : > "$work/render.txt"; : > "$work/rays.txt"
  for run in 1 2 3; do
    "$work/embree_build" "$(dirname "$json")/shapes/hair.ply" 2 >> "$work/embree.txt"
    "$yscene" render "$json" -o "$work/out.exr" -s "$samples" -t 2 --quiet --stats |
      grep '^stats' >> "$work/render.txt"
    "$yscene" render "$json" -o "$work/out.exr" -s "$samples" -r 256 -t 2 --embree-only 2>&1 |
      grep -E '^  (renderer|embree) .*rays/s' |
      awk '{v = $2 + 0; if ($2 ~ /k$/) v /= 1000; printf "%s=%s ", $1, v} END {print ""}' >> "$work/rays.txt"
  done
  of() { field "$2" < "$work/$1.txt" | median; }
  embree_s=$(of embree build_seconds) embree_b=$(of embree embree_bytes)
  bvh_s=$(of render bvh_seconds) bvh_b=$(of render bvh_bytes) peak=$(of render peak_memory)
  segments=$(of render segments) pieces=$(of render curve_pieces)
  awk -v n="$strands" -v seg="$segments" -v es="$embree_s" -v eb="$embree_b" -v s="$bvh_s" \
      -v b="$bvh_b" -v p="$peak" -v pc="$pieces" -v r="$(of rays renderer)" \
      -v e="$(of rays embree)" 'BEGIN {
    printf "| %d | %d | %.2f s | %.0f MB | %.2f s | %.2f | %.0f MB | %.0f MB | %d | %.2fM | %.2fM |\n",
      n, seg, es, eb / 1e6, s, s / es, b / 1e6, p / 1e6, pc, r, e }'
done
