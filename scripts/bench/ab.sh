#!/usr/bin/env bash
# A/B timing of yscene render command lines: runs each variant N times,
# interleaved, on one thread, and prints the median CPU time (user + system)
# of each whole process with the load average. CPU time, because the machine
# is shared and wall time then measures the other jobs too; use enough
# samples that rendering dominates loading.
# Usage: scripts/bench/ab.sh N SCENE "ARGS A" "ARGS B" ...
# ARGS may start with a yscene binary (a path containing "yscene"); the
# default is build/apps/yscene.
set -euo pipefail
cd "$(dirname "$0")/../.."
runs=$1; scene=$2; shift 2
variants=("$@")
declare -A times
for ((r = 0; r < runs; r++)); do
  for variant in "${variants[@]}"; do
    read -r -a args <<< "$variant"
    binary=build/apps/yscene
    case "${args[0]}" in *yscene*) binary=${args[0]}; args=("${args[@]:1}") ;; esac
    TIMEFORMAT='%U %S'
    cpu=$( { time "$binary" render "$scene" -o out/bench/ab.pfm -q -t 1 "${args[@]}" \
      > /dev/null 2>&1; } 2>&1 )
    seconds=$(echo "$cpu" | awk '{printf "%.2f", $1 + $2}')
    times[$variant]="${times[$variant]:-} $seconds"
  done
done
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
for variant in "${variants[@]}"; do
  median=$(echo ${times[$variant]} | tr ' ' '\n' | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
  echo "$median s  [$variant]  (runs:${times[$variant]})"
done
