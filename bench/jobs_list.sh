#!/usr/bin/env bash
# Many small jobs (N, default 2000) through a local farm (a coordinator and one worker on
# 127.0.0.1), then how long `tessera jobs` (pages of 500), `--json` and `status` take to go
# through them, and the coordinator's RSS. Run from the repository root; BIN=build/bin.
set -u
cd "$(dirname "$0")/.."
BIN=${BIN:-build/bin}; D=$(mktemp -d); CP=; WP=
# (Stopped or interrupted, the coordinator and worker go too: they were left running.)
trap 'kill $WP $CP 2>/dev/null; wait; rm -rf "$D"' EXIT
trap 'exit 130' INT TERM
"$BIN/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$D/data" --max-jobs-per-client 100000 >"$D/c.out" 2>"$D/c.err" &
CP=$!
for _ in $(seq 100); do grep -q '^http' "$D/c.out" 2>/dev/null && break; sleep 0.05; done
G=$(sed -n 's/^grpc listening on //p' "$D/c.out")
"$BIN/tessera-worker" --coordinator "$G" --threads 1 --cache "$D/cache" >/dev/null 2>&1 &
WP=$!
secs() { local ns=$(( $(date +%s%N) - $1 )); printf "%d.%03d" $((ns / 1000000000)) $((ns / 1000000 % 1000)); }
N=${N:-2000}
start=$(date +%s%N)
for i in $(seq $N); do $BIN/tessera submit scenes/cornell-spheres.dae -r 8 8 -s 1 --coordinator $G >/dev/null || echo fail; done
echo "submitted $N in $(secs $start) s"
grep VmRSS /proc/$CP/status
for k in 1 2 3; do s=$(date +%s%N); $BIN/tessera jobs --coordinator $G > $D/jobs.txt; echo "tessera jobs: $(wc -l < $D/jobs.txt) lines in $(secs $s) s"; done
s=$(date +%s%N); $BIN/tessera jobs --json --coordinator $G > $D/jobs.json; echo "tessera jobs --json: $(stat -c %s $D/jobs.json) bytes in $(secs $s) s"
s=$(date +%s%N); $BIN/tessera status --coordinator $G > /dev/null; echo "tessera status (all): $(secs $s) s"
grep -E "VmRSS|VmHWM" /proc/$CP/status
# (the EXIT trap stops them)
