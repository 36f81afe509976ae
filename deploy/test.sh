#!/usr/bin/env bash
# The README's second command: install, build, run every test (CTest + GoogleTest), then
# a short fuzzing run of each libFuzzer target.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/build.sh
cd "${BUILD_DIR:-build}"
ctest --output-on-failure -j "$(nproc)"
cd - >/dev/null
# A short libFuzzer run of every target (clang, sanitizers; its own build in build-fuzz/).
bash deploy/fuzz.sh "${FUZZ_SECONDS:-20}" -seed=1  # a fixed seed: the same inputs every run
