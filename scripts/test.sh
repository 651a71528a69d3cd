#!/usr/bin/env bash
# Installs what is missing (with the denoiser's and the USD reader's venvs,
# for their tests), builds,
# and runs the whole test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --denoise --usd
ctest --test-dir build --output-on-failure -j "$(nproc)"
