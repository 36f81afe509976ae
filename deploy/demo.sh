#!/usr/bin/env bash
# The README's first command: install, build, then render the default scene through a
# local farm: a coordinator and two workers on 127.0.0.1, the job submitted with the CLI,
# progress shown, the image written to out/cornell-spheres.exr and out/cornell-spheres.png,
# and everything stopped again. Extra arguments go to `tessera submit`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
BIN=build/bin
source deploy/local_farm.sh  # a coordinator and two workers on 127.0.0.1: RUN, GRPC, HTTP
echo "coordinator on $GRPC; status page: http://$HTTP/"

mkdir -p out
# -s 128 -m 16 unless the arguments give their own (CLI11 refuses a flag given twice).
defaults=()
[[ " $* " == *" -s "* ]] || defaults+=(-s 128)
[[ " $* " == *" -m "* ]] || defaults+=(-m 16)
"$BIN/tessera" submit scenes/cornell-spheres.dae "${defaults[@]}" --coordinator "$GRPC" --wait \
  -f out/cornell-spheres.exr -f out/cornell-spheres.png "$@"
