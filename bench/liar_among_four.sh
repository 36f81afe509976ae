#!/usr/bin/env bash
# One liar among four workers (issue 23): N jobs in a row through a coordinator with access
# tokens set up as docs/deploy.md does (every worker enrols for its own credential), three
# honest workers and one that returns plausible but wrong sums (the hidden --test-lie) and,
# each time it is caught, comes back under a new name (a new identity, on probation again).
# Counts the jobs whose image is not bit-identical to `tessera render` (aim: 0), the
# quarantines, and the checks' cost: COST_JOBS jobs of COST_SPP samples (default 8 of 256,
# ~2 s each here) on an honest farm with the default checks (--verify-fraction 0.01,
# --verify-first 4) and with none, alternating, REPEAT times (default 3).
# Usage: bench/liar_among_four.sh [N]   (default 30; the scene: scenes/cornell-spheres.dae)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-build/bin}
N=${1:-30}
SCENE=scenes/cornell-spheres.dae
BASE=(-r 96 72 --pass-spp 8 -m 4 --tile 16)
FLAGS=("${BASE[@]}" -s 32)  # 120 tasks a job
RUN=$(mktemp -d)
pids=()
stop_all() { for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; pids=(); }
trap 'stop_all; rm -rf "$RUN"' EXIT
(umask 077
 for who in enrol client viewer; do openssl rand -hex 24 >"$RUN/$who.token"; done
 printf 'enrol farm %s\nclient me %s\nviewer ops %s\n' "$(cat "$RUN/enrol.token")" "$(cat "$RUN/client.token")" \
   "$(cat "$RUN/viewer.token")" >"$RUN/tokens")
export TESSERA_TOKEN_FILE="$RUN/client.token"
auth="Authorization: Bearer $(cat "$RUN/viewer.token")"

coordinator() {  # extra flags; sets GRPC and HTTP
  rm -rf "$RUN/data"
  "$BIN/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$RUN/data" --tokens-file "$RUN/tokens" "$@" \
    >"$RUN/c.out" 2>"$RUN/c.err" &
  pids+=($!)
  for _ in $(seq 100); do grep -q '^http' "$RUN/c.out" 2>/dev/null && break; sleep 0.05; done
  GRPC=$(sed -n 's/^grpc listening on //p' "$RUN/c.out")
  HTTP=$(sed -n 's/^http listening on //p' "$RUN/c.out")
}
worker() {  # name, extra flags
  local name=$1; shift
  "$BIN/tessera-worker" --coordinator "$GRPC" --threads 1 --cache "$RUN/cache" --enrol-token-file "$RUN/enrol.token" \
    --name "$name" "$@" >/dev/null 2>>"$RUN/w-$name.err" &
  pids+=($!)
  LAST=$!
}
workers_up() {  # wait for N workers on the status page
  for _ in $(seq 200); do
    [ "$(curl -s -H "$auth" "http://$HTTP/api/status" | python3 -c 'import json,sys; print(len(json.load(sys.stdin)["workers"]))')" = "$1" ] && return
    sleep 0.05
  done
  echo "workers did not come up" >&2; exit 1
}
metric() { curl -s -H "$auth" "http://$HTTP/metrics" | awk -v m="$1" '$1 == m {print $2}'; }

# ---- the liar ----
wrong=0
coordinator
for h in 1 2 3; do worker "honest-$h"; done
lives=1
worker "liar-$lives" --test-lie
liar=$LAST
workers_up 4
for j in $(seq "$N"); do
  if ! kill -0 "$liar" 2>/dev/null; then  # caught and refused: back under a new name
    lives=$((lives + 1))
    worker "liar-$lives" --test-lie
    liar=$LAST
    workers_up 4
  fi
  "$BIN/tessera" render "$SCENE" "${FLAGS[@]}" --seed "$j" -q -f "$RUN/local.exr" >/dev/null 2>&1
  "$BIN/tessera" submit "$SCENE" "${FLAGS[@]}" --seed "$j" --coordinator "$GRPC" --wait -q -f "$RUN/farm.exr" >/dev/null 2>&1
  if ! "$BIN/tessera_compare" "$RUN/farm.exr" "$RUN/local.exr" | grep -q '"identical":true'; then wrong=$((wrong + 1)); fi
done
echo "liar among 4 workers: $wrong of $N images wrong; quarantined $(metric tessera_workers_quarantined_total) times" \
  "(the liar came back $((lives - 1)) times under new names); checks $(metric tessera_checks_issued_total)," \
  "mismatches $(metric tessera_check_mismatches_total), tiles rendered again $(metric tessera_tiles_rendered_again_total)"
stop_all

# ---- the checks' cost on an honest farm ----
now() { date +%s.%N; }
farm_time() {  # coordinator flags...; N jobs through 4 honest workers: sets SECONDS_TAKEN and CHECKS
  coordinator "$@"
  for h in 1 2 3 4; do worker "honest-$h"; done
  workers_up 4
  local t0; t0=$(now)
  for j in $(seq "${COST_JOBS:-8}"); do
    "$BIN/tessera" submit "$SCENE" "${BASE[@]}" -s "${COST_SPP:-256}" --seed "$j" --coordinator "$GRPC" --wait -q \
      -f "$RUN/farm.exr" >/dev/null 2>&1
  done
  local t1; t1=$(now)
  CHECKS=$(metric tessera_checks_issued_total)
  stop_all
  SECONDS_TAKEN=$(awk "BEGIN {print $t1 - $t0}")
}
with=(); without=()
for r in $(seq "${REPEAT:-3}"); do
  farm_time; with+=("$SECONDS_TAKEN"); checks=$CHECKS
  farm_time --verify-fraction 0; without+=("$SECONDS_TAKEN")
  echo "run $r: default checks $(printf %.2f "${with[-1]}") s ($checks checks of $((${COST_JOBS:-8} * 30 * ${COST_SPP:-256} / 8)) tasks)," \
    "none $(printf %.2f "${without[-1]}") s"
done
best() { printf '%s\n' "$@" | sort -g | head -1; }
bw=$(best "${with[@]}"); bo=$(best "${without[@]}")
echo "best of ${REPEAT:-3}: default checks $(printf %.2f "$bw") s, none $(printf %.2f "$bo") s, cost $(awk "BEGIN {printf \"%.1f\", 100 * ($bw / $bo - 1)}")%"
