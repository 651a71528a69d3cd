#!/usr/bin/env bash
# Generates the thesis's three scenes and a varied groom into scenes/ (deterministic: the same
# files on every machine). Existing scenes are kept unless --force is given.
set -euo pipefail
cd "$(dirname "$0")/.."
yscene=build/apps/yscene
force=0
[ "${1:-}" = "--force" ] && force=1

make_scene() {
  local name=$1; shift
  if [ $force -eq 1 ] || [ ! -f "scenes/$name/$name.json" ]; then
    mkdir -p "scenes/$name"
    "$yscene" hair --output "scenes/$name/$name.json" "$@"
  fi
}

# Four locks of curls: black (eumelanin 8), red (pheomelanin 2), brown
# (eumelanin 1.3) and blonde (eumelanin 0.3).
make_scene hair-locks --style curls --strands 1500 --segments 32
# Straight brown hair (eumelanin 1.3) on a head-sized sphere.
make_scene straight-hair --style straight --strands 20000 --eumelanin 1.3
# Curly blonde hair (eumelanin 0.3).
make_scene curly-hair --style curly --strands 10000 --eumelanin 0.3
# The four locks as a groom that varies (issue 20): each strand's pigment
# and roughness spread by its own random value, and tips bleached from 40%
# of the length on.
make_scene varied-locks --style curls --strands 1500 --segments 32 --random-melanin 0.5 \
  --random-roughness 0.3 --tip-eumelanin 0.15 --tip-pheomelanin 0.3 --tip-start 0.4
