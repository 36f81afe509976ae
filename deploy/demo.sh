#!/usr/bin/env bash
# The README's first command: install, build, then render the default scene through a
# local farm: a coordinator and two workers on 127.0.0.1, the job submitted with the CLI,
# progress shown, the image written to out/cornell-spheres.exr and out/cornell-spheres.png,
# and everything stopped again. Extra arguments go to `tessera submit`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
BIN=build/bin
RUN=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$RUN"
}
trap cleanup EXIT

# Port 0: the system picks free ports; the coordinator prints them.
"$BIN/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$RUN/data" >"$RUN/coordinator.out" 2>"$RUN/coordinator.err" &
pids+=($!)
for _ in $(seq 100); do grep -q '^http listening' "$RUN/coordinator.out" 2>/dev/null && break; sleep 0.05; done
GRPC=$(sed -n 's/^grpc listening on //p' "$RUN/coordinator.out")
HTTP=$(sed -n 's/^http listening on //p' "$RUN/coordinator.out")
[ -n "$GRPC" ] || { cat "$RUN/coordinator.err" >&2; echo "demo: the coordinator did not start" >&2; exit 1; }
echo "coordinator on $GRPC; status page: http://$HTTP/"

THREADS=$(( $(nproc) > 1 ? $(nproc) / 2 : 1 ))
for i in 1 2; do
  "$BIN/tessera-worker" --coordinator "$GRPC" --threads "$THREADS" --cache "$RUN/cache$i" --name "worker$i" 2>"$RUN/worker$i.err" &
  pids+=($!)
done

mkdir -p out
"$BIN/tessera" submit scenes/cornell-spheres.dae -s 128 -m 16 --coordinator "$GRPC" --wait \
  -f out/cornell-spheres.exr -f out/cornell-spheres.png "$@"
