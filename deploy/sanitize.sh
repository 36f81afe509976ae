#!/usr/bin/env bash
# The tests under the sanitizers, each in its own build (g++, -O1):
#   deploy/sanitize.sh [ctest flags...]   the whole CTest suite under AddressSanitizer +
#       UndefinedBehaviorSanitizer (any UB aborts the test), in build-asan/, but
#       ContainerImage, whose image-size bound an instrumented binary exceeds by design.
#       About 35 minutes of build and 12 of tests on 2 cores, so not in deploy/test.sh.
#   deploy/sanitize.sh thread             the core, coordinator and worker unit tests under
#       ThreadSanitizer, in build-tsan/, with tests/tsan.supp (Debian's Embree, TBB and gRPC
#       are uninstrumented: TSan cannot see their synchronisation). About 20 minutes.
# Run it after changes to memory handling, threads or parsers.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
if [ "${1:-}" = thread ]; then
  B=${TSAN_BUILD_DIR:-build-tsan}
  if [ ! -f "$B/build.ninja" ]; then
    cmake -S . -B "$B" -G Ninja -DCMAKE_BUILD_TYPE=None -DCMAKE_CXX_FLAGS="-O1 -g -fsanitize=thread" \
      -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=thread"
  fi
  tests=(tessera_core_tests tessera_server_tests tessera_worker_tests)
  cmake --build "$B" -j "$(nproc)" --target "${tests[@]}"
  export TSAN_OPTIONS="suppressions=$root/tests/tsan.supp halt_on_error=0 exitcode=66"
  rc=0
  for t in "${tests[@]}"; do
    echo "== $t"
    "$B/bin/$t" --gtest_brief=1 || rc=$?
  done
  exit $rc
fi
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
