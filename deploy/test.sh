#!/usr/bin/env bash
# The README's second command: install, build, run every test (CTest + GoogleTest).
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
cd "${BUILD_DIR:-build}"
ctest --output-on-failure -j "$(nproc)"
