#!/usr/bin/env bash
# The whole CTest suite under AddressSanitizer + UndefinedBehaviorSanitizer (g++, -O1, any
# UB aborts the test): its own build in build-asan/, then every test but ContainerImage,
# whose image-size bound an instrumented binary exceeds by design. About 35 minutes of
# build and 12 of tests on 2 cores, so not part of deploy/test.sh; run it after changes to
# memory handling, threads or parsers.
#   deploy/sanitize.sh [ctest flags...]      (e.g. -R Gltf to run a part)
set -euo pipefail
cd "$(dirname "$0")/.."
B=${ASAN_BUILD_DIR:-build-asan}
if [ ! -f "$B/build.ninja" ]; then
  cmake -S . -B "$B" -G Ninja -DCMAKE_BUILD_TYPE=None \
    -DCMAKE_CXX_FLAGS="-O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=undefined" \
    -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined"
fi
cmake --build "$B" -j "$(nproc)"
cd "$B"
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1} UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}
ctest -j "$(nproc)" --output-on-failure -E '^ContainerImage$' "$@"
