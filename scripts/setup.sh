#!/usr/bin/env bash
# Installs the Debian 12 packages yocto-hair needs, only those missing, then
# configures and builds (Release) into build/. python3-distributed is Dask,
# for scripts/farm.py and its test; cpp-httplib is yscene serve's server, and
# Chromium with its driver and Selenium the real browser its page test drives. With --fuzz, also clang-14
# and libFuzzer, which scripts/fuzz.sh needs. With --denoise, also Debian's
# OpenImageIO and NumPy for Python and a venv, .venv/denoise, that sees them
# and holds pyoidn (Intel Open Image Denoise from PyPI) for scripts/denoise.py.
# With --usd, a venv .venv/usd that sees Debian's NumPy and holds Pixar's
# usd-core from PyPI, for yscene convert of USD files (scripts/usd_to_yocto.py).
set -euo pipefail
cd "$(dirname "$0")/.."
fuzz=0
denoise=0
usd=0
for option in "$@"; do
  case $option in
    --fuzz) fuzz=1 ;;
    --denoise) denoise=1 ;;
    --usd) usd=1 ;;
    *) echo "usage: bash scripts/setup.sh [--fuzz] [--denoise] [--usd]" >&2; exit 2 ;;
  esac
done

packages="cmake ninja-build g++ pkg-config libembree-dev libopenimageio-dev
  openimageio-tools libglm-dev nlohmann-json3-dev libtbb-dev libcli11-dev libgtest-dev
  libbenchmark-dev zlib1g-dev python3-distributed libcpp-httplib-dev
  chromium chromium-driver python3-selenium"
if [ $fuzz -eq 1 ]; then
  packages="$packages clang-14 libclang-rt-14-dev libfuzzer-14-dev"
fi
if [ $denoise -eq 1 ]; then
  packages="$packages python3-venv python3-numpy python3-openimageio"
fi
if [ $usd -eq 1 ]; then
  packages="$packages python3-venv python3-numpy"
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

# A venv NAME on Debian's python3 (the one the packages above are for, whatever
# python3 comes first on PATH) holding PACKAGE==VERSION; pip runs only when the
# venv lacks that exact version or cannot import MODULES.
pinned_venv() {
  local venv=.venv/$1 package=$2 version=$3 modules=$4
  local check="import importlib.metadata as m, sys, $modules; sys.exit(m.version('$package') != '$version')"
  if ! "$venv/bin/python" -c "$check" 2>/dev/null; then
    echo "installing: $package $version into $venv"
    /usr/bin/python3 -m venv --system-site-packages "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "$package==$version"
  fi
}
# OIDN for the denoiser; Pixar's usd-core for USD grooms (Debian has no USD).
if [ $denoise -eq 1 ]; then pinned_venv denoise pyoidn 2.5.1.0 pyoidn; fi
if [ $usd -eq 1 ]; then pinned_venv usd usd-core 26.11 "numpy, pxr.Usd"; fi

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j "$(nproc)"
bash scripts/make_scenes.sh
