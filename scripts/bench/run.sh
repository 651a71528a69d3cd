#!/usr/bin/env bash
# The speed-against-error benchmark in one command: builds yscene and
# bench_pow (Release, in build/ or $BUILD), then runs run_bench.py, which
# writes docs/benchmark/ (README.md, CSVs, plots). Arguments go to
# run_bench.py: --quick for a run of a few minutes.
#   bash scripts/bench/run.sh [--quick]
set -euo pipefail
cd "$(dirname "$0")/../.."
build=${BUILD:-build}
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release > /dev/null
cmake --build "$build" --target yscene bench_pow -j "$(nproc)"
# Debian's matplotlib lives in the system python.
python=python3
if ! python3 -c "import matplotlib" 2> /dev/null; then
  if /usr/bin/python3 -c "import matplotlib" 2> /dev/null; then
    python=/usr/bin/python3
  else
    echo "note: no matplotlib (apt-get install python3-matplotlib): no plots" >&2
  fi
fi
exec "$python" scripts/bench/run_bench.py --build "$build" "$@"
