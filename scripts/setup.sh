#!/usr/bin/env bash
# Installs the Debian 12 packages yocto-hair needs, only those missing, then
# configures and builds (Release) into build/.
set -euo pipefail
cd "$(dirname "$0")/.."

packages="cmake ninja-build g++ pkg-config libembree-dev libopenimageio-dev
  openimageio-tools libglm-dev nlohmann-json3-dev libtbb-dev libcli11-dev libgtest-dev
  libbenchmark-dev zlib1g-dev"
missing=""
for package in $packages; do
  dpkg -s "$package" >/dev/null 2>&1 || missing="$missing $package"
done
if [ -n "$missing" ]; then
  echo "installing:$missing"
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq $missing
fi

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
bash scripts/make_scenes.sh
