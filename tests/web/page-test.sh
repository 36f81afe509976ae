#!/usr/bin/env bash
# CTest entry (Page.InAHeadlessBrowser): a coordinator with tokens and a worker on
# loopback, a job and a worker with hostile names, then page_test.mjs drives the live page
# in Debian's chromium (headless) through puppeteer-core (pinned, from the npm registry,
# installed into the build tree once). Skips, saying why, where chromium, node or the
# registry is missing.
set -euo pipefail
src=$(cd "$(dirname "$0")" && pwd)
build=${1:?build directory}
bin=$build/bin
work=$build/page-test
chromium=$(command -v chromium || command -v chromium-browser || true)
[ -n "$chromium" ] || { echo "SKIP: chromium is not installed (deploy/install-deps.sh installs it)"; exit 77; }
command -v node >/dev/null && command -v npm >/dev/null || { echo "SKIP: node and npm are not installed"; exit 77; }
mkdir -p "$work"
cp "$src/package.json" "$src/package-lock.json" "$src/page_test.mjs" "$work/"
if [ ! -d "$work/node_modules/puppeteer-core" ]; then
  if ! (cd "$work" && PUPPETEER_SKIP_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error >npm.log 2>&1); then
    echo "SKIP: cannot install puppeteer-core from the npm registry:"
    tail -5 "$work/npm.log"
    exit 77
  fi
fi
T=$(mktemp -d)
pids=()
# On a failure the coordinator's and the worker's last words are shown before their folder goes.
cleanup() {
  local rc=$?
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  if [ "$rc" -ne 0 ] && [ "$rc" -ne 77 ]; then
    for f in coord.err worker.err; do [ -f "$T/$f" ] && { echo "--- $f (last 40 lines)"; tail -40 "$T/$f"; }; done
  fi
  rm -rf "$T"
}
trap cleanup EXIT
alice=alice-$(openssl rand -hex 12) viewer=viewer-$(openssl rand -hex 12) admin=admin-$(openssl rand -hex 12)
worker=worker-$(openssl rand -hex 12)
printf 'client alice %s\nviewer ops %s\nadmin root %s\nworker farm %s\n' "$alice" "$viewer" "$admin" "$worker" >"$T/tokens"
chmod 600 "$T/tokens"
echo "$alice" >"$T/alice" && echo "$worker" >"$T/worker"
"$bin/tessera-coordinator" --listen 127.0.0.1:0 --http 127.0.0.1:0 --data "$T/data" --tokens-file "$T/tokens" \
  >"$T/coord.out" 2>"$T/coord.err" &
pids+=($!)
for _ in $(seq 100); do grep -q "http listening" "$T/coord.out" 2>/dev/null && break; sleep 0.1; done
grpc=$(sed -n 's/.*grpc listening on \(127\.0\.0\.1:[0-9]*\).*/\1/p' "$T/coord.out")
http=$(sed -n 's/.*http listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$T/coord.out")
[ -n "$grpc" ] && [ -n "$http" ] || { echo "FAIL: the coordinator did not start"; cat "$T/coord.err"; exit 1; }
# Hostile strings where users supply them: a job's name, a worker's name (and so events).
hostile='<img src=x id=pwned onerror=alert(1)><script>window.pwned=1</script>"'"'"'&'
"$bin/tessera-worker" --coordinator "$grpc" --token-file "$T/worker" --threads 1 --cache "$T/cache" \
  --name "w$hostile" 2>"$T/worker.err" &
pids+=($!)
# A job long enough to act on while it runs, and a small one that ends.
"$bin/tessera" submit "$src/../../scenes/cornell-spheres.dae" -r 64 48 -s 100000 --pass-spp 4 -q \
  --name "job$hostile" --coordinator "$grpc" --token-file "$T/alice" >"$T/job.id"
node "$work/page_test.mjs" "$chromium" "http://127.0.0.1:$http/" "$(cat "$T/job.id")" "$alice" "$viewer" "$admin"
