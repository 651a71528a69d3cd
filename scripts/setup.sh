#!/usr/bin/env bash
# Installs the Debian 12 packages yocto-hair needs, only those missing, then
# configures and builds (Release) into build/. python3-distributed is Dask,
# for scripts/farm.py and its test. With --fuzz, also clang-14
# and libFuzzer, which scripts/fuzz.sh needs.
set -euo pipefail
cd "$(dirname "$0")/.."

packages="cmake ninja-build g++ pkg-config libembree-dev libopenimageio-dev
  openimageio-tools libglm-dev nlohmann-json3-dev libtbb-dev libcli11-dev libgtest-dev
  libbenchmark-dev zlib1g-dev python3-distributed"
if [ "${1:-}" = --fuzz ]; then
  packages="$packages clang-14 libclang-rt-14-dev libfuzzer-14-dev"
fi
missing=""
for package in $packages; do
  # Installed, not merely known (a removed package keeps "config-files").
  status=$(dpkg-query -W -f='${Status}' "$package" 2>/dev/null || true)
  [ "$status" = "install ok installed" ] || missing="$missing $package"
done
if [ -n "$missing" ]; then
  echo "installing:$missing"
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    if ! command -v sudo >/dev/null; then
      echo "error: missing packages and no sudo; as root run:" >&2
      echo "  apt-get update && apt-get install -y$missing" >&2
      exit 1
    fi
    sudo="sudo"
  fi
  $sudo apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing
fi

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
bash scripts/make_scenes.sh
