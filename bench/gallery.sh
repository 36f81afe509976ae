#!/usr/bin/env bash
# Regenerates docs/gallery/*.png: the two series that define this renderer.
#   CBspheres at max ray depth 0 1 2 3 4 5 100 (64 spp, 4 samples per light)
#   CBdragon, lens radius 0.1 focused at nose / middle / tail / back wall, then lens
#   radius 0.05 0.10 0.15 0.20 focused on its middle.
#   scenes/material-spheres.gltf under scenes/sky.hdr, and Cycles' image of it (Blender).
# Renders at 480x360 (CS184 framing fills the frame at that size) and stores 2x
# box-downsampled PNGs. Needs ../shared/scenes/cs184 and a built tree (deploy/build.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
SHARED=${SHARED:-../shared/scenes/cs184}
BIN=${BIN:-build/bin/tessera}
OUT=docs/gallery
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
mkdir -p "$OUT"

shrink() {  # full-size PNG -> half-size PNG (box filter), via Debian's python3-pil
  /usr/bin/python3 -c "import sys; from PIL import Image; Image.open(sys.argv[1]).reduce(2).save(sys.argv[2], optimize=True)" "$1" "$2"
}
render() {  # name, then tessera render arguments
  local name=$1; shift
  echo "+ tessera render $*" >&2
  "$BIN" render "$@" -q -f "$TMP/$name.png" | tee -a "$TMP/log.txt"
  shrink "$TMP/$name.png" "$OUT/$name.png"
}

for m in 0 1 2 3 4 5 100; do
  render "cbspheres-m$m" "$SHARED/CBspheres.dae" -s 64 -l 4 -m "$m"
done
for focus in nose:5.00 middle:4.80 tail:4.53 wall:5.80; do
  render "cbdragon-b0.1-${focus%%:*}" "$SHARED/CBdragon.dae" -s 64 -l 4 -m 8 -b 0.1 -d "${focus##*:}"
done
for b in 0.05 0.10 0.15 0.20; do
  render "cbdragon-b$b-middle" "$SHARED/CBdragon.dae" -s 64 -l 4 -m 8 -b "$b" -d 4.80
done
# The caustics converging (issue 28, docs/light-tracing.md): the path tracer alone at 16,
# 64 and 256 spp, and with the light tracer at 12, 48 and 192 (about the same times on 2
# cores), the lower right quarter at full size: the caustic under the glass sphere, the
# light the spheres throw on the walls.
crop() {  # full-size PNG -> its lower right quarter
  /usr/bin/python3 -c "import sys; from PIL import Image; im = Image.open(sys.argv[1]); w, h = im.size; im.crop((w // 2, h // 2, w, h)).save(sys.argv[2], optimize=True)" "$1" "$2"
}
for spp in 16:12 64:48 256:192; do
  for lt in off on; do
    s=${spp%%:*}
    [ "$lt" = on ] && s=${spp##*:}
    echo "+ tessera render $SHARED/CBspheres.dae -s $s -m 16 --light-tracer $lt" >&2
    "$BIN" render "$SHARED/CBspheres.dae" -s "$s" -m 16 -t 2 --light-tracer "$lt" -q -f "$TMP/c.png" | tee -a "$TMP/log.txt"
    crop "$TMP/c.png" "$OUT/cbspheres-caustics-$lt-$s.png"
  done
done
# glTF's material model under scenes/sky.hdr; with Blender installed, Cycles' image of the
# same file (as Blender imports it: bench/cycles/gltf_to_cycles.py) beside it.
render material-spheres scenes/material-spheres.gltf --env scenes/sky.hdr -s 256 -m 16
if command -v blender >/dev/null; then
  echo "+ blender gltf_to_cycles.py scenes/material-spheres.gltf (256 spp)" | tee -a "$TMP/log.txt" >&2
  env -u PYENV_VERSION PATH="$(echo "$PATH" | tr ':' '\n' | grep -v pyenv | paste -sd:)" \
    blender -b --factory-startup --python bench/cycles/gltf_to_cycles.py -- scenes/material-spheres.gltf \
    "$TMP/cycles.exr" --env scenes/sky.hdr --spp 256 --png "$TMP/material-spheres-cycles.png" | grep gltf_to_cycles |
    tee -a "$TMP/log.txt"
  shrink "$TMP/material-spheres-cycles.png" "$OUT/material-spheres-cycles.png"
fi
cp "$TMP/log.txt" "$OUT/render-log.txt"
