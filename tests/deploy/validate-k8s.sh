#!/usr/bin/env bash
# CTest entry: installs the pinned validator packages (npm registry) into the build tree
# once, then checks deploy/k8s. Skips, saying why, where node or the registry is missing.
set -euo pipefail
src=$(cd "$(dirname "$0")" && pwd)
work=${1:?build directory}/k8s-validate
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "SKIP: node and npm are not installed (deploy/install-deps.sh installs them)"
  exit 77
fi
mkdir -p "$work"
cp "$src/package.json" "$src/package-lock.json" "$src/validate_k8s.mjs" "$work/"
if [ ! -d "$work/node_modules/kubernetes-models" ]; then
  if ! (cd "$work" && npm ci --no-audit --no-fund --loglevel=error >npm.log 2>&1); then
    echo "SKIP: cannot install the validator from the npm registry:"
    tail -5 "$work/npm.log"
    exit 77
  fi
fi
node "$work/validate_k8s.mjs" "$src/../../deploy/k8s"
# A pod that runs as a user other than root and mounts a secret others may not read
# (defaultMode 0440, ...0) reads it through its group alone: it needs fsGroup (the workers
# lacked it and could not read their enrol token: every pod crash-looped).
for f in "$src"/../../deploy/k8s/base/*.yaml; do
  if grep -q 'runAsUser:' "$f" && grep -qE 'defaultMode: 0[0-7][0-7]0' "$f" && ! grep -q 'fsGroup:' "$f"; then
    echo "FAIL: $f runs as a user and mounts a secret only its group may read, without fsGroup"
    exit 1
  fi
done
# The check itself: a misspelt field and a wrong type must each be found.
bad=$(mktemp -d)
trap 'rm -rf "$bad"' EXIT
cp -r "$src/../../deploy/k8s/." "$bad/"
sed -i 's/periodSeconds: 5/periodSecnds: 5/' "$bad/base/coordinator.yaml"
sed -i 's/^  replicas: 1$/  replicas: "one"/' "$bad/base/workers.yaml"
if out=$(node "$work/validate_k8s.mjs" "$bad" 2>&1); then
  echo "FAIL: the check passed broken manifests"
  exit 1
fi
for want in "V1Probe has no field 'periodSecnds'" "spec/replicas must be integer"; do
  grep -qF "$want" <<<"$out" || { echo "FAIL: the check missed: $want"; echo "$out"; exit 1; }
done
echo "the check finds a misspelt field and a wrong type"
