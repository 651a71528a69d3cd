#!/usr/bin/env bash
# Installs what is missing, builds, generates the scenes and renders the
# default scene (the thesis's four hair locks). Extra arguments go to render.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
build/apps/yscene render scenes/hair-locks/hair-locks.json --output out/default.png \
  --samples 16 --resolution 640 "$@"
echo "image: $(pwd)/out/default.png"
