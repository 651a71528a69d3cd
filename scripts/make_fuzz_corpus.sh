#!/usr/bin/env bash
# Regenerates the fuzz targets' seed corpus, fuzz/corpus/TARGET/, from the
# project's own tools and small hand-written files (each well under 64 KB).
# Needs build/apps/yscene (bash scripts/setup.sh) and oiiotool. The corpus
# is committed; run this only to change it.
set -euo pipefail
cd "$(dirname "$0")/.."
yscene=build/apps/yscene
corpus=fuzz/corpus
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
rm -rf "$corpus"
mkdir -p "$corpus"/{json,ply,pbrt,hair,image}

# --- generated hair in every output format, a few strands each ---
for style in straight curly curls block fur; do
  "$yscene" hair --style "$style" --strands 3 --segments 4 --output "$work/$style.json" >/dev/null
  "$yscene" hair --style "$style" --strands 3 --segments 4 --output "$work/$style.pbrt" >/dev/null
  "$yscene" hair --style "$style" --strands 3 --segments 4 --output "$work/$style.hair" >/dev/null
  "$yscene" hair --style "$style" --strands 3 --segments 4 --output "$work/$style.ply" >/dev/null
  cp "$work/$style.json" "$corpus/json/generated-$style.json"
  cp "$work/$style.hair" "$corpus/hair/generated-$style.hair"
  cp "$work/$style.ply" "$corpus/ply/generated-$style.ply"
  { printf '\0'; cat "$work/$style.pbrt"; } >"$corpus/pbrt/generated-$style"
done
# The same hair with its header's default thickness and no arrays but points.
"$yscene" hair --style curly --strands 1 --segments 2 --output "$work/one.hair" >/dev/null
cp "$work/one.hair" "$corpus/hair/generated-one-strand.hair"
# The json names shapes/hair.ply, shapes/head.ply and textures/sky.exr, as
# the scenes of scripts/make_scenes.sh do: the fuzz target provides small
# files of those names.

# --- json: the 4.0 layout (objects keyed by name) and every element kind ---
cat >"$corpus/json/layout-40.json" <<'EOF'
{
  "asset": {"copyright": "hand-written"},
  "cameras": {"default": {"lens": 0.05, "aperture": 0.01, "aspect": 1.5,
                          "lookat": [0, 1, 5, 0, 1, 0, 0, 1, 0]}},
  "environments": {"sky": {"emission": [2, 2, 2], "emission_tex": "sky",
                           "frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]}},
  "objects": {
    "head": {"frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], "shape": "head",
             "material": "skin"},
    "hair": {"lookat": [0, 0, 0, 0, 1, 0, 0, 0, 1], "shape": "hair", "material": "hair"}
  },
  "materials": {
    "skin": {"color": [0.8, 0.4, 0.05]},
    "hair": {"eumelanin": 1.3, "betaM": 0.25, "betaN": 0.3, "alpha": 2}
  }
}
EOF
cat >"$corpus/json/all-elements.json" <<'EOF'
{
  "asset": {"version": "4.2", "copyright": "hand-written"},
  "cameras": [{"name": "cam", "frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 4],
               "orthographic": false, "lens": 0.05, "film": 0.036, "aspect": 1,
               "focus": 4, "aperture": 0}],
  "environments": [{"name": "sky", "emission": [1, 1, 1], "emission_tex": 0}],
  "textures": [{"name": "sky", "uri": "textures/sky.hdr"},
               {"name": "skin", "uri": "textures/sky.png"}],
  "shapes": [{"name": "head", "uri": "shapes/head.ply"},
             {"name": "hair", "uri": "shapes/hair.ply"},
             {"name": "lines", "uri": "shapes/lines.ply"}],
  "materials": [
    {"name": "skin", "type": "glossy", "color": [0.5, 0.5, 0.5], "roughness": 0.3,
     "color_tex": 1},
    {"name": "light", "type": "matte", "emission": [10, 10, 10]},
    {"name": "hair", "type": "hair", "sigma_a": [0.1, 0.2, 0.3], "beta_m": 0.3,
     "beta_n": 0.3, "alpha": 2, "eta": 1.55},
    {"name": "blonde", "type": "hair", "color": [0.8, 0.6, 0.3]}
  ],
  "instances": [
    {"name": "head", "shape": 0, "material": 0},
    {"name": "light", "lookat": [3, 3, 3, 0, 0, 0, 0, 1, 0], "shape": 0, "material": 1},
    {"name": "hair", "shape": 1, "material": 2},
    {"name": "lines", "frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0], "shape": 2,
     "material": 3}
  ],
  "distant_lights": [{"name": "sun", "direction": [0, 1, 1], "emission": [3, 3, 3]}],
  "settings": {"resolution": 64, "samples": 4, "bounces": 8}
}
EOF

# --- ply: each element kind, ascii and both binary byte orders ---
cat >"$corpus/ply/triangles-ascii.ply" <<'EOF'
ply
format ascii 1.0
comment a quad and a triangle with normals and texcoords
element vertex 5
property float x
property float y
property float z
property float nx
property float ny
property float nz
property float u
property float v
element face 2
property list uchar int vertex_indices
end_header
0 0 0 0 0 1 0 0
1 0 0 0 0 1 1 0
1 1 0 0 0 1 1 1
0 1 0 0 0 1 0 1
0.5 0.5 1 0 0 1 0.5 0.5
4 0 1 2 3
3 0 2 4
EOF
cat >"$corpus/ply/lines-ascii.ply" <<'EOF'
ply
format ascii 1.0
element vertex 4
property double x
property double y
property double z
property float radius
element line 1
property list uchar uint vertex_indices
end_header
0 0 0 0.01
0 1 0 0.01
0 2 1 0.008
+1 3 1e-1 0.005
4 0 1 2 3
EOF
cat >"$corpus/ply/curves-ascii.ply" <<'EOF'
ply
format ascii 1.0
element vertex 4
property float x
property float y
property float z
property float radius
element curve 1
property list uchar int vertex_indices
element extra 2
property short unused
end_header
0 0 0 .01
0 1 0 .01
1 2 0 .01
1 3 1 .005
4 0 1 2 3
7
-7
EOF
cat >"$corpus/ply/empty-vertex.ply" <<'EOF'
ply
format binary_little_endian 1.0
element vertex 0
property float x
property float y
property float z
element face 0
property list uchar int vertex_indices
end_header
EOF
# Binary of both byte orders, every property type, from the ascii ones.
for order in little big; do
  {
    printf 'ply\nformat binary_%s_endian 1.0\nelement vertex 3\n' "$order"
    printf 'property float x\nproperty double y\nproperty int z\nproperty uchar s\n'
    printf 'property ushort t\nelement face 1\nproperty list uint short vertex_indices\n'
    printf 'end_header\n'
    if [ "$order" = little ]; then
      printf '\x00\x00\x80\x3f''\x00\x00\x00\x00\x00\x00\xf0\x3f''\x01\x00\x00\x00''\x01''\x02\x00'
      printf '\x00\x00\x00\x00''\x00\x00\x00\x00\x00\x00\x00\x00''\x00\x00\x00\x00''\x00''\x00\x00'
      printf '\x00\x00\x00\x40''\x00\x00\x00\x00\x00\x00\x08\x40''\xff\xff\xff\xff''\x03''\x04\x00'
      printf '\x03\x00\x00\x00''\x00\x00''\x01\x00''\x02\x00'
    else
      printf '\x3f\x80\x00\x00''\x3f\xf0\x00\x00\x00\x00\x00\x00''\x00\x00\x00\x01''\x01''\x00\x02'
      printf '\x00\x00\x00\x00''\x00\x00\x00\x00\x00\x00\x00\x00''\x00\x00\x00\x00''\x00''\x00\x00'
      printf '\x40\x00\x00\x00''\x40\x08\x00\x00\x00\x00\x00\x00''\xff\xff\xff\xff''\x03''\x00\x04'
      printf '\x00\x00\x00\x03''\x00\x00''\x00\x01''\x00\x02'
    fi
  } >"$corpus/ply/types-$order-endian.ply"
done

# --- pbrt: a flag byte, the main file, NUL, the included file ---
# (see fuzz/fuzz_pbrt.cpp; flag 1 gzips the main file)
pbrt_seed() {  # NAME FLAG MAIN [INCLUDED]
  local name=$1 flag=$2 main=$3 included=${4-}
  {
    printf "\\$(printf '%03o' "$flag")"
    printf '%s' "$main"
    if [ -n "${4+set}" ]; then printf '\0'; printf '%s' "$included"; fi
  } >"$corpus/pbrt/$name"
}
v3_scene='LookAt 0 1 5  0 1 0  0 1 0
Camera "perspective" "float fov" [ 30 ] "float lensradius" .01 "float focaldistance" 5
Film "image" "integer xresolution" [ 64 ] "integer yresolution" [ 48 ] "string filename" "out.exr"
Sampler "halton" "integer pixelsamples" 16
Integrator "path" "integer maxdepth" 10
WorldBegin
AttributeBegin
  Rotate -90 1 0 0
  LightSource "infinite" "string mapname" "textures/sky.exr" "rgb L" [ 1 1 1 ]
AttributeEnd
LightSource "distant" "point from" [ 0 10 0 ] "point to" [ 0 0 0 ] "rgb L" [ 2 2 2 ]
MakeNamedMaterial "floor" "string type" "matte" "rgb Kd" [ .5 .5 .5 ]
NamedMaterial "floor"
Shape "trianglemesh" "point P" [ -5 0 -5 5 0 -5 5 0 5 -5 0 5 ] "integer indices" [ 0 1 2 0 2 3 ]
AttributeBegin
  Translate 0 1 0
  Material "hair" "float eumelanin" 1.3 "float beta_m" .25 "float beta_n" .3 "float alpha" 2
  Shape "curve" "point P" [ 0 0 0 0 .3 0 .1 .6 0 .1 1 .1 ] "float width0" .02 "float width1" .01 "string type" "cylinder"
  Shape "curve" "point P" [ .1 1 .1 .1 1.3 .2 .2 1.6 .2 .2 2 .3 ] "float width" .01
AttributeEnd
AttributeBegin
  Scale .5 .5 .5
  Material "plastic" "rgb Kd" [ .2 .3 .4 ] "float roughness" .1
  Shape "sphere" "float radius" 1
  Shape "plymesh" "string filename" "shapes/head.ply"
AttributeEnd
WorldEnd
'
pbrt_seed v3-scene 0 "$v3_scene"
pbrt_seed v3-scene-gzip 1 "$v3_scene"
v4_scene='LookAt 0 1 5  0 1 0  0 1 0
Camera "perspective" "float fov" 40
Film "rgb" "integer xresolution" 64 "integer yresolution" 64 "string filename" "out.exr"
WorldBegin
AttributeBegin
  LightSource "infinite" "string filename" "textures/sky.exr" "float scale" 2
AttributeEnd
Texture "grey" "spectrum" "constant" "rgb value" [ .25 .5 .75 ]
MakeNamedMaterial "coat" "string type" "coateddiffuse" "float roughness" .0625 "texture reflectance" "grey"
MakeNamedMaterial "hair" "string type" "hair" "float eumelanin" .3 "rgb sigma_a" [ .1 .2 .3 ]
NamedMaterial "coat"
AttributeBegin
  AreaLightSource "diffuse" "blackbody L" [ 6500 ] "bool twosided" true
  Translate 0 4 0
  Shape "disk" "float radius" .5
AttributeEnd
Shape "sphere" "float radius" .5 "float zmax" .25
NamedMaterial "hair"
Shape "curve" "point3 P" [ 0 0 0 0 .5 0 0 1 0 0 1.5 0 ] "float width" .02 "integer splitdepth" 2
TransformBegin
  Transform [ 1 0 0 0 0 1 0 0 0 0 1 0 .5 0 0 1 ]
  ConcatTransform [ 1 0 0 0 0 1 0 0 0 0 1 0 0 .1 0 1 ]
  Shape "curve" "point3 P" [ 0 0 0 0 .5 0 0 1 0 0 1.5 0 ] "float width" .02
TransformEnd
'
pbrt_seed v4-scene 0 "$v4_scene"
pbrt_seed include-plain 0 'Camera "perspective" "float fov" 45
WorldBegin
Include "include.pbrt"
AttributeBegin
  CoordinateSystem "here"
  Import "include.pbrt"
AttributeEnd
' 'Material "hair" "float pheomelanin" 2
Shape "curve" "point P" [ 0 0 0 0 1 0 0 2 0 0 3 0 ] "float width" .1
LightSource "infinite" "rgb L" [ .5 .5 .5 ]
'
pbrt_seed include-gzip 1 'LookAt 0 0 5 0 0 0 0 1 0
Camera "perspective"
WorldBegin
Include "include.pbrt.gz"
' 'Shape "curve" "point P" [ 0 0 0 0 1 0 0 2 0 0 3 0 ] "float width" .1 "string type" "flat"
Shape "plymesh" "string filename" "shapes/hair.ply"
'
# The second part as raw .gz bytes (flag 2): a real gzip stream.
{
  printf '\2'
  printf 'Camera "perspective"\nWorldBegin\nInclude "include.pbrt.gz"\n'
  printf '\0'
  printf 'Shape "sphere" "float radius" 2\n' | gzip -9n
} >"$corpus/pbrt/include-raw-gzip"

# --- images: a selector byte (fuzz/fuzz_image.cpp), then the file ---
"$yscene" hair --style curls --strands 20 --output "$work/render/scene.json" >/dev/null
index=0
for extension in png jpg exr hdr pfm; do
  "$yscene" render "$work/render/scene.json" --output "$work/render.$extension" \
    --samples 1 --resolution 12 >/dev/null 2>&1
  { printf "\\$(printf '%03o' $index)"; cat "$work/render.$extension"; } \
    >"$corpus/image/render-$extension"
  index=$((index + 1))
done
oiiotool "$work/render.png" -o "$work/render.ppm"
oiiotool "$work/render.png" -o "$work/render.tga"
oiiotool "$work/render.png" --ch R -o "$work/grey.png"
oiiotool "$work/render.png" --ch R,G,B,A=1.0 -d uint16 -o "$work/rgba16.png"
oiiotool "$work/render.exr" -d half -o "$work/half.exr"
{ printf '\5'; cat "$work/render.ppm"; } >"$corpus/image/render-ppm"
{ printf '\6'; cat "$work/render.tga"; } >"$corpus/image/render-tga"
{ printf '\0'; cat "$work/grey.png"; } >"$corpus/image/grey-png"
{ printf '\0'; cat "$work/rgba16.png"; } >"$corpus/image/rgba16-png"
{ printf '\2'; cat "$work/half.exr"; } >"$corpus/image/half-exr"

# Every seed must be small: fuzzing slows down with big inputs.
big=$(find "$corpus" -type f -size +64k)
if [ -n "$big" ]; then
  echo "error: seeds over 64 KB: $big" >&2
  exit 1
fi
for target in json ply pbrt hair image; do
  echo "$target: $(ls "$corpus/$target" | wc -l) seeds, $(du -sk "$corpus/$target" | cut -f1) KB"
done
