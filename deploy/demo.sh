#!/usr/bin/env bash
# The README's first command: install, build, render the default scene.
# Writes out/cornell-spheres.exr (linear float RGB + spp + variance) and out/cornell-spheres.png.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
mkdir -p out
./build/bin/tessera render scenes/cornell-spheres.dae -s 128 -m 16 \
  -f out/cornell-spheres.exr -f out/cornell-spheres.png "$@"
