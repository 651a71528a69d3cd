#!/usr/bin/env bash
# Checks that two yscene binaries give the same outputs byte for byte: a
# refactor's proof that behaviour did not change.
#
#   scripts/check_identical.sh OLD_YSCENE NEW_YSCENE
#
# Each binary runs the same commands in a folder of its own: `hair` (json
# scenes with their PLY and sky, .pbrt, .pbrt.gz, .hair and .ply strands,
# stand-ins placed with --fit-camera on the real pbrt scenes in
# ../shared/data, and --fit-camera's errors), `render` (two generated
# scenes, exr and png, with --aovs, a pbrt scene with stand-ins, and a
# render split into two parts by --sample-range and merged), `convert` (pbrt
# to json and PLY, with native curves and as lines, a .hair model to json)
# and `info` (text and json). Then every file of the two folders is compared
# with cmp, and every command's stdout (timings masked), stderr and exit
# status. EXR files carry metadata that differ between any two runs or
# builds: OpenImageIO's DateTime (the time of writing) and, in render parts,
# the renderer's source hash (in yocto:settings) with the checksum over it.
# An EXR that cmp finds different passes if its bytes are the same once
# those values are masked (idiff's pixel comparison is reported beside).
# Exits 1 on any other difference, 2 on bad usage.
set -uo pipefail
if [ $# -ne 2 ] || [ ! -x "$1" ] || [ ! -x "$2" ]; then
  echo "usage: scripts/check_identical.sh OLD_YSCENE NEW_YSCENE" >&2
  exit 2
fi
old=$(realpath "$1")
new=$(realpath "$2")
shared=$(realpath -m "${YOCTO_SHARED_DIR:-$(dirname "$0")/../../shared}")/data
if [ ! -d "$shared/pbrt" ]; then
  echo "error: no real scene files in $shared (set YOCTO_SHARED_DIR)" >&2
  exit 2
fi
work=$(mktemp -d "${TMPDIR:-/tmp}/check-identical.XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/old" "$work/new" "$work/logs"
failures=0
steps=0

# run NAME ARGS...: yscene ARGS in each binary's folder (relative paths, so
# messages name the same files); stdout, stderr and status kept for later.
run() {
  local name=$1
  shift
  steps=$((steps + 1))
  for side in old new; do
    local binary=$old
    [ $side = new ] && binary=$new
    (cd "$work/$side" && "$binary" "$@" >"$work/logs/$name.$side.out" \
      2>"$work/logs/$name.$side.err"; echo $? >"$work/logs/$name.$side.status")
    # Timings vary from run to run: "in 0.12s", "1.5 s".
    sed -i -E 's/[0-9]+(\.[0-9]+)? ?s\b/Ns/g' "$work/logs/$name.$side.out"
  done
  for stream in out err status; do
    if ! cmp -s "$work/logs/$name.old.$stream" "$work/logs/$name.new.$stream"; then
      echo "DIFFERENT $name: $stream"
      diff "$work/logs/$name.old.$stream" "$work/logs/$name.new.$stream" | head -10
      failures=$((failures + 1))
    fi
  done
}

# Files both sides start from: the real pbrt scenes (their geometry is
# missing; the stand-ins below fill it in) and inputs for --fit-camera's
# errors.
for side in old new; do
  cp -r "$shared/pbrt/pbrt-v3/hair" "$work/$side/pbrt-v3"
  cp -r "$shared/pbrt/pbrt-v4/hair" "$work/$side/pbrt-v4"
  mkdir -p "$work/$side/bad"
  printf 'Camera "perspective" "float fov" [ 30 ]\n' >"$work/$side/bad/noworld.pbrt"
  printf 'LookAt 0 0 5 0 0 0 0 1 0\nCamera "perspective" "float fov" [ x ]\nWorldBegin\n' \
    >"$work/$side/bad/syntax.pbrt"
done

# hair: scenes and strands in every format.
run hair-locks hair --output scenes/hair-locks/hair-locks.json --style curls --strands 1500 \
  --segments 32
run varied-locks hair --output scenes/varied-locks/varied-locks.json --style curls \
  --strands 1500 --segments 32 --random-melanin 0.5 --random-roughness 0.3 \
  --tip-eumelanin 0.15 --tip-pheomelanin 0.3 --tip-start 0.4
run fur hair --output scenes/fur/fur.json --style fur --strands 3000
for extension in pbrt pbrt.gz hair ply; do
  run "strands-$extension" hair --output "strands/curly.$extension" --style curly --strands 300
done
# hair --fit-camera: pbrt scenes whose world Includes are missing, a json
# scene, and errors that must name the user's file.
run fit-v3-straight hair --style straight --strands 2000 \
  --output pbrt-v3/models/straight-hair.pbrt --fit-camera pbrt-v3/straight-hair.pbrt \
  --fit-distance 25 --fit-fraction 0.7
run fit-v3-curly hair --style curly --strands 1000 --output pbrt-v3/models/curly-hair.pbrt \
  --fit-camera pbrt-v3/curly-hair.pbrt --fit-distance 25 --fit-fraction 0.8
run fit-v4-straight hair --style straight --strands 2000 \
  --output pbrt-v4/geometry/straight-hair.pbrt.gz --fit-camera pbrt-v4/hair-eumel-0.3.pbrt \
  --fit-distance 25 --fit-fraction 0.9
run fit-json hair --style curly --strands 200 --output strands/fit-json.ply \
  --fit-camera scenes/hair-locks/hair-locks.json
run fit-no-world hair --output strands/x.pbrt --fit-camera bad/noworld.pbrt
run fit-syntax hair --output strands/x.pbrt --fit-camera bad/syntax.pbrt
run fit-missing hair --output strands/x.pbrt --fit-camera bad/missing.pbrt

# render: exr and png, AOVs, a pbrt scene, and two parts merged.
common=(--samples 4 --resolution 128 --threads 2 --quiet)
run render-locks render scenes/hair-locks/hair-locks.json -o renders/hair-locks.exr "${common[@]}"
run render-varied render scenes/varied-locks/varied-locks.json -o renders/varied-locks.exr \
  "${common[@]}"
run render-varied-png render scenes/varied-locks/varied-locks.json \
  -o renders/varied-locks.png "${common[@]}"
run render-aovs render scenes/hair-locks/hair-locks.json -o renders/hair-locks-aovs.exr --aovs \
  "${common[@]}"
run render-pbrt render pbrt-v3/straight-hair.pbrt -o renders/straight-hair.exr --samples 2 \
  --resolution 96 --threads 2 --quiet
run part-a render scenes/varied-locks/varied-locks.json -o parts/a.exr --sample-range 0:2 \
  "${common[@]}"
run part-b render scenes/varied-locks/varied-locks.json -o parts/b.exr --sample-range 2:4 \
  "${common[@]}"
run merge merge parts/b.exr parts/a.exr -o parts/merged.exr
run merge-png merge parts/a.exr parts/b.exr -o parts/merged.png

# convert: pbrt to json (curves, lines), a v4 scene (warnings), a .hair model.
run convert-v3 convert pbrt-v3/straight-hair.pbrt converted/straight/straight.json
run convert-lines convert pbrt-v3/curly-hair.pbrt converted/curly-lines/curly.json \
  --curves lines --segments 3
run convert-v4 convert pbrt-v4/hair-eumel-0.3.pbrt converted/v4/v4.json
run convert-hair convert strands/curly.hair converted/hair/curly.json

# info, as text and json.
for scene in scenes/varied-locks/varied-locks.json pbrt-v3/straight-hair.pbrt \
  pbrt-v4/hair-eumel-0.3.pbrt strands/curly.hair; do
  name=$(basename "$scene")
  run "info-$name" info "$scene"
  run "info-json-$name" info --json "$scene"
done

# Every file of both folders, byte for byte.
(cd "$work/old" && find . -type f | sort) >"$work/logs/files.old"
(cd "$work/new" && find . -type f | sort) >"$work/logs/files.new"
if ! cmp -s "$work/logs/files.old" "$work/logs/files.new"; then
  echo "DIFFERENT file lists:"
  diff "$work/logs/files.old" "$work/logs/files.new"
  failures=$((failures + 1))
fi
# What may differ in an EXR besides its pixels: OpenImageIO's DateTime (the
# time of writing), and in a part the renderer's source hash in
# yocto:settings and the checksum that covers it. Masked (same lengths, so
# the pixel data stays where it was) before comparing bytes again. OpenEXR
# stores DateTime as its capDate attribute.
mask_exr() {
  perl -0777 -pe '
    s/(capDate\x00string\x00.{4})\d{4}:\d\d:\d\d \d\d:\d\d:\d\d/${1}YYYY:MM:DD hh:mm:ss/gs;
    s/(renderer=)[0-9a-f]{16}/${1}RRRRRRRRRRRRRRRR/g;
    s/(yocto:checksum\x00string\x00.{4})[0-9a-f]{16}/${1}CCCCCCCCCCCCCCCC/gs' "$1" >"$2"
}
same=0
masked=0
while read -r file; do
  [ -f "$work/new/$file" ] || continue
  if cmp -s "$work/old/$file" "$work/new/$file"; then
    same=$((same + 1))
    continue
  fi
  if [[ "$file" == *.exr ]]; then
    mask_exr "$work/old/$file" "$work/logs/masked.old"
    mask_exr "$work/new/$file" "$work/logs/masked.new"
    pixels="idiff: pixels differ"
    idiff -q -fail 0 -failpercent 0 -warn 0 "$work/old/$file" "$work/new/$file" >/dev/null 2>&1 &&
      pixels="idiff: pixels identical"
    if cmp -s "$work/logs/masked.old" "$work/logs/masked.new"; then
      what=()
      for pattern in '[0-9]{4}:[0-9]{2}:[0-9]{2} [0-9]{2}:[0-9]{2}:[0-9]{2}' 'renderer=[0-9a-f]{16}'; do
        [ "$(grep -aoE "$pattern" "$work/old/$file" | head -1)" = \
          "$(grep -aoE "$pattern" "$work/new/$file" | head -1)" ] && continue
        case $pattern in
          renderer*) what+=("the renderer's source hash and the part checksum over it") ;;
          *) what+=("DateTime") ;;
        esac
      done
      echo "same bytes but for $(IFS=,; echo "${what[*]}" | sed 's/,/ and /'): $file ($pixels)"
      same=$((same + 1))
      masked=$((masked + 1))
      continue
    fi
    echo "DIFFERENT $file: $pixels, bytes differ beyond DateTime and the renderer hash"
  else
    echo "DIFFERENT $file"
  fi
  failures=$((failures + 1))
done <"$work/logs/files.old"
hashes=$(grep -aoh 'renderer=[0-9a-f]*' "$work/old/parts/a.exr" "$work/new/parts/a.exr" | tr '\n' ' ')
echo "parts' renderer hashes (old new): $hashes"

echo "$steps commands run by both binaries (stdout, stderr, status compared)," \
  "$(wc -l <"$work/logs/files.old") files written: $same the same ($((same - masked)) byte" \
  "for byte, $masked but for EXR metadata), $failures differences"
[ $failures -eq 0 ]
