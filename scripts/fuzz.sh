#!/usr/bin/env bash
# Builds the libFuzzer targets (clang-14, into build-fuzz/) and runs them.
#
#   scripts/fuzz.sh TARGET SECONDS   fuzz one target (json, ply, pbrt, hair,
#                                    image) or all of them, SECONDS each
#   scripts/fuzz.sh replay           run every target once over its saved
#                                    corpus, regressions and saved crashes
#
# A run starts from fuzz/corpus/TARGET/ (and the real files in
# ../shared/data when present) and writes the new inputs it finds to a
# scratch folder, removed at the end: the saved corpus changes only by hand.
# Crashes, leaks, timeouts and out-of-memory inputs go to
# fuzz/crashes/TARGET/; once fixed, move them to fuzz/regressions/TARGET/
# so that replay keeps them fixed. Exits 1 if anything crashed.
set -euo pipefail
cd "$(dirname "$0")/.."

targets="json ply pbrt hair image"
usage="usage: scripts/fuzz.sh TARGET SECONDS | all SECONDS | replay (targets: $targets)"
command=${1:-}
seconds=${2:-}
case "$command" in
  replay) ;;
  all) ;;
  json | ply | pbrt | hair | image) ;;
  *) echo "$usage" >&2; exit 2 ;;
esac
if [ "$command" != replay ] && ! [[ "$seconds" =~ ^[1-9][0-9]*$ ]]; then
  echo "$usage" >&2
  exit 2
fi
[ "$command" = all ] || [ "$command" = replay ] || targets=$command

if ! command -v clang++-14 >/dev/null; then
  echo "error: clang++-14 not found (bash scripts/setup.sh installs it)" >&2
  exit 1
fi
CC=clang-14 CXX=clang++-14 cmake -S . -B build-fuzz -G Ninja \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo -DYOCTO_FUZZ=ON -DYOCTO_TESTS=OFF \
  -DYOCTO_BENCHMARKS=OFF >/dev/null
cmake --build build-fuzz -j "$(nproc)" --target $(printf 'fuzz_%s ' $targets)

# Leaks inside system libraries are suppressed (see the file); undefined
# behaviour already aborts (-fno-sanitize-recover).
export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp"
export UBSAN_OPTIONS="print_stacktrace=1"
# The suppressions name library frames, which only the slow unwinder sees.
# It makes the json target 4 times slower, so fuzzing uses it only where a
# suppressed leak is reachable: OpenImageIO's PNG error path, in the image
# target (the others read only the valid images they make themselves).
slow_unwind="fast_unwind_on_malloc=0"
unwind_options() {
  if [ "$1" = image ] || [ "$command" = replay ]; then echo "$slow_unwind"; fi
}

# Everything a run writes besides crashes: the targets' input files (they
# make their own folder under TMPDIR) and the new corpus entries.
base=/tmp
[ -d /dev/shm ] && [ -w /dev/shm ] && base=/dev/shm
scratch=$(mktemp -d "$base/yocto-fuzz.XXXXXX")
trap 'rm -rf "$scratch"' EXIT
export TMPDIR="$scratch"

# The fuzzed bytes of a target's input for a file, on stdout: the pbrt
# target takes a flag byte first (0: plain main file, no include), the
# image target a byte choosing the extension (see fuzz/fuzz_image.cpp).
input_from_file() {
  local target=$1 file=$2
  case "$target" in
    pbrt) printf '\0'; cat "$file" ;;
    image)
      local index
      case "${file,,}" in
        *.png) index=0 ;; *.jpg | *.jpeg) index=1 ;; *.exr) index=2 ;;
        *.hdr) index=3 ;; *.pfm) index=4 ;; *.ppm) index=5 ;; *.tga) index=6 ;;
      esac
      printf "\\$(printf '%03o' "$index")"
      cat "$file"
      ;;
    *) cat "$file" ;;
  esac
}

# Extra seeds from the real scene files, when they are beside the project.
shared_seeds() {
  local target=$1 folder=$scratch/seeds/$target n=0
  mkdir -p "$folder"
  if [ -d ../shared/data ]; then
    # Small files only: big ones would be cut to -max_len anyway.
    while IFS= read -r -d '' file; do
      case "$target:${file,,}" in
        json:*.json | ply:*.ply | pbrt:*.pbrt | hair:*.hair) ;;
        image:*.png | image:*.jpg | image:*.exr | image:*.hdr | image:*.pfm) ;;
        *) continue ;;
      esac
      n=$((n + 1))
      input_from_file "$target" "$file" >"$folder/shared-$n"
    done < <(find ../shared/data -type f -size -64k -print0)
  fi
  echo "$folder"
}

# Seconds one input may take: nothing of 64 KB needs seconds, even
# sanitized. libFuzzer checks every timeout/2 + 1 seconds and also runs an
# input twice when looking for leaks, so with 10 an input taking 11 s twice
# passed; 5 catches anything over about 6 s.
unit_timeout=5

failed=0
for target in $targets; do
  fuzzer=build-fuzz/fuzz/fuzz_$target
  crashes=fuzz/crashes/$target
  log=build-fuzz/logs/$command-$target.log
  mkdir -p build-fuzz/logs
  if [ "$command" = replay ]; then
    # Every saved input once: the corpus must load cleanly, regressions and
    # saved crashes must stay fixed.
    inputs=()
    for folder in fuzz/corpus/$target fuzz/regressions/$target $crashes; do
      [ -d "$folder" ] || continue
      while IFS= read -r -d '' file; do inputs+=("$file"); done \
        < <(find "$folder" -type f ! -name '.*' -print0 | sort -z)
    done
    echo "== replay $target: ${#inputs[@]} inputs"
    [ ${#inputs[@]} -gt 0 ] || continue
    if ! ASAN_OPTIONS=$(unwind_options "$target") \
      "$fuzzer" -rss_limit_mb=2048 -timeout=$unit_timeout "${inputs[@]}" >"$log" 2>&1; then
      tail -n 40 "$log" >&2
      echo "replay $target: FAILED (see above and $log)" >&2
      failed=1
    fi
    continue
  fi
  corpus=$scratch/corpus/$target
  mkdir -p "$corpus"
  seeds=$(shared_seeds "$target")
  mkdir -p "$crashes"
  before=$(find "$crashes" -type f | wc -l)
  touch "$scratch/start-$target"
  echo "== fuzz $target for $seconds s"
  # Keep going after a crash (fork mode), so that one run reports every
  # kind it finds; each is saved under fuzz/crashes/TARGET/.
  ASAN_OPTIONS=$(unwind_options "$target") \
    "$fuzzer" -fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
      -max_total_time="$seconds" -timeout=$unit_timeout -rss_limit_mb=2048 -max_len=65536 \
      -artifact_prefix="$crashes/" -print_final_stats=1 \
      "$corpus" "fuzz/corpus/$target" "$seeds" >"$log" 2>&1 || true
  grep -E '^#[0-9]+: cov' "$log" | tail -n 1 || true
  after=$(find "$crashes" -type f | wc -l)
  if [ "$after" -gt "$before" ]; then
    echo "fuzz $target: $((after - before)) new crashing inputs in $crashes/ (log: $log):" >&2
    # What each one does, from a replay of the first few.
    find "$crashes" -type f -newer "$scratch/start-$target" | head -n 10 | while read -r file; do
      output=$(ASAN_OPTIONS=$(unwind_options "$target") \
        timeout 120 "$fuzzer" -timeout=$unit_timeout -rss_limit_mb=2048 "$file" 2>&1 || true)
      what=$(grep -m 1 -E 'what\(\)|ERROR: (Address|Leak|libFuzzer)|runtime error|ALARM|out-of-memory' \
        <<<"$output" || echo "did not crash again")
      echo "  $file: $what" >&2
    done
    failed=1
  else
    # Nothing new: drop the empty folder so that git stays clean.
    rmdir "$crashes" fuzz/crashes 2>/dev/null || true
  fi
done
exit $failed
