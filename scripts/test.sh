#!/usr/bin/env bash
# Installs what is missing (with the denoiser's venv, for its test), builds,
# and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --denoise
ctest --test-dir build --output-on-failure -j "$(nproc)"
