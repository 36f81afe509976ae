#!/usr/bin/env bash
# The farm across distances, on one machine: one coordinator on loopback, workers reaching
# it through tessera-wan-proxy (bench/wan/wan_link.h: a fixed delay each way and a
# bottleneck rate each way; this kernel has no netem). Each row renders the same frame
# through the farm and checks the image bit for bit against `tessera render`.
#
# Each row's runs are paired with runs of the same workers on loopback just before them,
# and the ratio of each pair is reported (median over REPEAT pairs).
# Rows (ROWS, space-separated; default the table in docs/performance.md):
#   RTT_MS/MBIT          one worker of THREADS threads behind such a link (0/0: no proxy)
#   RTT_MS/MBIT+RTT_MS/MBIT   two workers of THREADS/2 threads each (a near and a far one)
# Usage: bench/farm_wan.sh [SCENE] [render flags...]
#   (default: our Cornell spheres, -r 1280 720 -s 32 -m 5, as issue 30 measured)
#   REPEAT=N runs each row N times and keeps the median; EXTRA_WORKER_FLAGS are passed on.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-build/bin}
SCENE=${1:-scenes/cornell-spheres.dae}
shift || true
FLAGS=${*:--r 1280 720 -s 32 -m 5}
THREADS=${THREADS:-2}
REPEAT=${REPEAT:-1}
ROWS=${ROWS:-"0/0 20/100 50/100 150/100 150/10 0/0+150/100"}
RUN=$(mktemp -d)
pids=()
stop_all() { for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; pids=(); }
cleanup() { stop_all; rm -rf "$RUN"; }
trap cleanup EXIT

wait_line() {  # FILE PATTERN: waits up to 10 s for a line of FILE to match
  for _ in $(seq 200); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.05; done
  echo "timed out waiting for '$2' in $1" >&2; return 1
}

t0=$(date +%s.%N)
"$BIN/tessera" render "$SCENE" $FLAGS -t "$THREADS" -q -f "$RUN/local.exr" >/dev/null 2>&1
local_s=$(awk "BEGIN {print $(date +%s.%N) - $t0}")

# Starts a worker of $2 threads behind a link of spec $1 (RTT_MS/MBIT) to $GRPC.
start_worker() {
  local rtt=${1%/*} mbit=${1#*/} threads=$2 n=$3 addr=$GRPC
  if [ "$rtt" != 0 ] || [ "$mbit" != 0 ]; then
    "$BIN/tessera-wan-proxy" --to "$GRPC" --rtt-ms "$rtt" --mbit "$mbit" >"$RUN/p$n.out" 2>"$RUN/p$n.err" &
    pids+=($!)
    wait_line "$RUN/p$n.out" '^listening'
    addr=$(sed -n 's/^listening on //p' "$RUN/p$n.out")
  fi
  "$BIN/tessera-worker" --coordinator "$addr" --threads "$threads" --cache "$RUN/cache$n" \
    ${EXTRA_WORKER_FLAGS:-} >/dev/null 2>"$RUN/w$n.err" &
  pids+=($!)
}

run_row() {  # ROW: prints seconds, or fails
  local row=$1
  rm -rf "$RUN/data"
  "$BIN/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$RUN/data" >"$RUN/c.out" 2>"$RUN/c.err" &
  pids+=($!)
  wait_line "$RUN/c.out" '^http'
  GRPC=$(sed -n 's/^grpc listening on //p' "$RUN/c.out")
  if [[ $row == *+* ]]; then
    start_worker "${row%+*}" $((THREADS / 2)) 1
    start_worker "${row#*+}" $((THREADS - THREADS / 2)) 2
  else
    start_worker "$row" "$THREADS" 1
  fi
  # Let the workers register (and warm their scene caches with a tiny job), then time.
  "$BIN/tessera" submit "$SCENE" -r 32 32 -s 1 --coordinator "$GRPC" --wait -q -f "$RUN/warm.exr" >/dev/null 2>&1
  local t0 t1
  t0=$(date +%s.%N)
  "$BIN/tessera" submit "$SCENE" $FLAGS --coordinator "$GRPC" --wait -q -f "$RUN/farm.exr" >/dev/null 2>"$RUN/s.err"
  t1=$(date +%s.%N)
  "$BIN/tessera_compare" "$RUN/farm.exr" "$RUN/local.exr" | grep -q '"identical": *true' ||
    { echo "row $row: the farm's image differs from tessera render's" >&2; return 1; }
  stop_all
  # What crossed the links (both proxies, warm-up job included), in MB.
  local up=0 down=0
  for f in "$RUN"/p*.err; do
    [ -f "$f" ] || continue
    read -r u d < <(sed -n 's/^relayed \([0-9]*\) bytes up, \([0-9]*\) down.*/\1 \2/p' "$f")
    up=$((up + ${u:-0})); down=$((down + ${d:-0}))
  done
  rm -f "$RUN"/p*.err
  awk "BEGIN {printf \"%.3f %.1f %.1f\\n\", $t1 - $t0, $up / 1e6, $down / 1e6}"
}

median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
echo "scene $SCENE, $FLAGS, $THREADS threads in all; local render $(printf %.2f "$local_s") s"
echo "| link (round trip / Mbit/s) | farm wall time | loopback, same workers | ratio (median of pairs) | MB to / from the coordinator |"
echo "|---|---|---|---|---|"
for row in $ROWS; do
  # Each run is paired with a run of the same workers on loopback just before it: this
  # machine's speed drifts more between minutes than the links cost.
  base_row=0/0; [[ $row == *+* ]] && base_row=0/0+0/0
  times=(); bases=(); ratios=()
  for _ in $(seq "$REPEAT"); do
    # (In this shell, not a process substitution: a row that fails ends the script, and the
    # EXIT trap stops what it started; in a subshell its processes outlived it and the
    # read waited on their output for ever.)
    run_row "$base_row" >"$RUN/row.out"
    read -r b _ _ <"$RUN/row.out"
    run_row "$row" >"$RUN/row.out"
    read -r t up down <"$RUN/row.out"
    times+=("$t"); bases+=("$b"); ratios+=("$(awk "BEGIN {print $t / $b}")")
  done
  label=$(echo "$row" | sed -e 's#0/0#loopback#g' -e 's#/\([0-9]*\)# ms / \1#g' -e 's#+# + #')
  echo "| $label | $(printf %.2f "$(median "${times[@]}")") s | $(printf %.2f "$(median "${bases[@]}")") s |" \
    "$(printf %.2fx "$(median "${ratios[@]}")") | $up / $down |"
done
