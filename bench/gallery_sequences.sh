#!/usr/bin/env bash
# Regenerates the gallery's sequences (docs/gallery.md), each rendered through a local farm
# (a coordinator and two workers on 127.0.0.1) as one sequence job:
#   CBspheres, max ray depth stepping 0..5 over frames 0-5 (a camera-path file keys max_depth)
#   CBdragon, a focus pull with lens radius 0.1: the plane in focus moves from the head
#   (F = 5.00) to the back wall (F = 5.80) over frames 1-12
# Each frame is stored 2x downsampled; the frames are joined into a strip and an animated
# GIF with Debian's python3-pil. Needs ../shared/scenes/cs184 and a built tree.
set -euo pipefail
cd "$(dirname "$0")/.."
SHARED=${SHARED:-../shared/scenes/cs184}
OUT=docs/gallery
mkdir -p "$OUT"
source deploy/local_farm.sh  # a coordinator and two workers on 127.0.0.1: BIN, RUN, GRPC

sequence() {  # name, frames, then tessera submit arguments
  local name=$1 frames=$2; shift 2
  echo "+ tessera submit $* --frames $frames" | tee -a "$RUN/log.txt" >&2
  local t0=$SECONDS
  "$BIN/tessera" submit "$@" --frames "$frames" --coordinator "$GRPC" --wait -q -f "$RUN/$name.####.png" \
    | tee -a "$RUN/log.txt"
  echo "  $((SECONDS - t0)) s through the farm" | tee -a "$RUN/log.txt"
  /usr/bin/python3 - "$RUN" "$OUT" "$name" <<'PY'
import glob, os, sys
from PIL import Image
run, out, name = sys.argv[1:]
frames = [Image.open(p).convert("RGB").reduce(2) for p in sorted(glob.glob(f"{run}/{name}.*.png"))]
w, h = frames[0].size
strip = Image.new("RGB", (w * len(frames), h))
for i, f in enumerate(frames):
    strip.paste(f, (i * w, 0))
strip.save(f"{out}/{name}-strip.jpg", quality=90)  # film grain: JPEG is a fifth of PNG
frames[0].save(f"{out}/{name}.gif", save_all=True, append_images=frames[1:], duration=400, loop=0)
PY
}

printf '{"keys": [%s]}' "$(for m in 0 1 2 3 4 5; do printf '%s{"frame": %d, "max_depth": %d}' "$([ $m -gt 0 ] && echo ,)" $m $m; done)" \
  > "$RUN/depth.json"
sequence cbspheres-depth 0-5 "$SHARED/CBspheres.dae" -s 64 -l 4 --camera-path "$RUN/depth.json"
printf '{"keys": [{"frame": 1, "focal_distance": 5.00}, {"frame": 12, "focal_distance": 5.80}]}' > "$RUN/pull.json"
sequence cbdragon-focus-pull 1-12 "$SHARED/CBdragon.dae" -s 64 -l 4 -m 8 -b 0.1 --camera-path "$RUN/pull.json"
cp "$RUN/log.txt" "$OUT/sequences-log.txt"
