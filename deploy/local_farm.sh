# Sourced, not run: starts a local farm for the scripts that render through one
# (deploy/demo.sh, bench/gallery_sequences.sh): a coordinator on 127.0.0.1 (port 0: the
# system picks free ports; the coordinator prints them) with its data in a temporary
# folder, and two workers sharing this machine's cores. Sets BIN, RUN, GRPC and HTTP; an
# EXIT trap stops everything and removes the folder.
BIN=${BIN:-build/bin}
RUN=$(mktemp -d)
pids=()
local_farm_stop() {
  for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  # And what the script was running in the foreground (a `tessera submit --wait` went on
  # reconnecting for 5 minutes to the coordinator stopped here).
  pkill -TERM -P $$ 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$RUN"
}
trap local_farm_stop EXIT

"$BIN/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$RUN/data" >"$RUN/coordinator.out" 2>"$RUN/coordinator.err" &
pids+=($!)
for _ in $(seq 100); do grep -q '^http listening' "$RUN/coordinator.out" 2>/dev/null && break; sleep 0.05; done
GRPC=$(sed -n 's/^grpc listening on //p' "$RUN/coordinator.out")
HTTP=$(sed -n 's/^http listening on //p' "$RUN/coordinator.out")
[ -n "$GRPC" ] || { cat "$RUN/coordinator.err" >&2; echo "local farm: the coordinator did not start" >&2; exit 1; }

THREADS=$(( $(nproc) > 1 ? $(nproc) / 2 : 1 ))
for i in 1 2; do
  "$BIN/tessera-worker" --coordinator "$GRPC" --threads "$THREADS" --cache "$RUN/cache$i" --name "worker$i" 2>"$RUN/worker$i.err" &
  pids+=($!)
done
