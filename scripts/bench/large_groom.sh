#!/usr/bin/env bash
# Issue 22's figures: a large groom's BVH build, BVH bytes and peak memory
# against Embree alone on the same curves, for this build's yscene and,
# optionally, a previous one. Runs each line three times, in turn.
#
#   bash scripts/bench/large_groom.sh [--previous OLD_YSCENE] [--samples N]
#       [--scene curly50k|straight1m|straight100k] [--work DIR]
#
# The scenes are generated once under DIR (default out/large): the curly
# stand-in of Yuksel's wCurly (50,000 strands of 66 segments, 3.3M) and the
# benchmark's straight grooms. Embree alone is ../shared/tools/embree_build.cpp,
# compiled once into DIR. Run it on an otherwise idle machine.
set -euo pipefail
cd "$(dirname "$0")/../.."
yscene=$PWD/build/apps/yscene
previous="" samples=1 scene=curly50k work=$PWD/out/large
while [ $# -gt 0 ]; do
  case $1 in
    --previous) previous=$(realpath "$2"); shift 2 ;;
    --samples) samples=$2; shift 2 ;;
    --scene) scene=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
done
mkdir -p "$work"
case $scene in
  curly50k) args="--style curly --strands 50000 --segments 66" ;;
  straight1m) args="--style straight --strands 1000000 --segments 4" ;;
  straight100k) args="--style straight --strands 100000 --segments 4" ;;
  *) echo "unknown scene $scene" >&2; exit 2 ;;
esac
json=$work/$scene/$scene.json
[ -f "$json" ] || "$yscene" hair $args -o "$json" -q
tool=$(realpath -m ../shared/tools/embree_build.cpp)
[ -x "$work/embree_build" ] || g++ -O2 -o "$work/embree_build" "$tool" -lembree3 -ltbb
for run in 1 2 3; do
  "$work/embree_build" "$work/$scene/shapes/hair.ply" 2
  for binary in $previous $yscene; do
    echo -n "$binary ${samples}spp: "
    /usr/bin/time -f "wall=%e" "$binary" render "$json" -o "$work/out.exr" -s "$samples" \
        --stats 2>&1 | grep -o "bvh_seconds=[0-9.]*\|bvh_bytes=[0-9]*\|curve_pieces=[0-9]*\|peak_memory=[0-9]*\|wall=[0-9.]*" | tr '\n' ' '
    echo
  done
done
