#!/usr/bin/env bash
# Builds everything with AddressSanitizer and UndefinedBehaviorSanitizer
# (-DYOCTO_SANITIZE=ON) into build-sanitize/ and runs the whole test suite
# there; `scripts/sanitize.sh clang` does the same with clang-14 into
# build-sanitize-clang/. Needs the scenes of scripts/make_scenes.sh (made
# by scripts/setup.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
build=build-sanitize
compilers=()
if [ "${1:-}" = clang ]; then
  build=build-sanitize-clang
  compilers=(-DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14)
fi
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DYOCTO_SANITIZE=ON \
  "${compilers[@]}" >/dev/null
cmake --build "$build" -j "$(nproc)"
# The tests carry LSAN_OPTIONS (suppressions for system libraries) from
# CMake; stack traces make a UBSan failure findable.
export UBSAN_OPTIONS="print_stacktrace=1"
ctest --test-dir "$build" --output-on-failure -j "$(nproc)"
