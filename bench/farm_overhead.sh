#!/usr/bin/env bash
# The farm's overhead: the same frame rendered locally (tessera render, 2 threads) and
# through a coordinator with two workers of one thread each, on this machine, alternating,
# REPEAT times. Prints each time and the ratio of the medians (farm / local).
# Usage: bench/farm_overhead.sh [SCENE] [render flags...]   (default: our Cornell box, 64 spp)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-build/bin}
SCENE=${1:-scenes/cornell-spheres.dae}
shift || true
FLAGS=${*:--s 64 -r 480 360}
REPEAT=${REPEAT:-3}
RUN=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$RUN"; }
trap cleanup EXIT

"$BIN/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$RUN/data" >"$RUN/c.out" 2>/dev/null &
pids+=($!)
for _ in $(seq 100); do grep -q '^http' "$RUN/c.out" 2>/dev/null && break; sleep 0.05; done
GRPC=$(sed -n 's/^grpc listening on //p' "$RUN/c.out")
for i in 1 2; do "$BIN/tessera-worker" --coordinator "$GRPC" --threads 1 --cache "$RUN/cache$i" 2>/dev/null & pids+=($!); done

now() { date +%s.%N; }
local_t=(); farm_t=()
for r in $(seq "$REPEAT"); do
  t0=$(now); "$BIN/tessera" render "$SCENE" $FLAGS -t 2 -q -f "$RUN/local.exr" >/dev/null; t1=$(now)
  "$BIN/tessera" submit "$SCENE" $FLAGS --coordinator "$GRPC" --wait -q -f "$RUN/farm.exr" >/dev/null 2>&1; t2=$(now)
  local_t+=("$(awk "BEGIN {print $t1 - $t0}")"); farm_t+=("$(awk "BEGIN {print $t2 - $t1}")")
  echo "run $r: local $(printf %.2f "${local_t[-1]}") s, farm $(printf %.2f "${farm_t[-1]}") s"
done
median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
ml=$(median "${local_t[@]}"); mf=$(median "${farm_t[@]}")
echo "median: local $(printf %.2f "$ml") s, farm $(printf %.2f "$mf") s, farm/local $(awk "BEGIN {printf \"%.3f\", $mf / $ml}")"
