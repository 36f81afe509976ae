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
