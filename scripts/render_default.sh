#!/usr/bin/env bash
# Installs what is missing, builds, and renders the default scene.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
mkdir -p out
build/apps/yscene render scenes/hair-locks/hair-locks.json --output out/default.png "$@"
echo "image: $(pwd)/out/default.png"
