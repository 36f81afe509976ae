#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, AddressSanitizer + UndefinedBehaviorSanitizer) into
# build-fuzz/ and runs each on its seed corpus (our scenes, and the CS184 scenes in
# ../shared when present) plus the inputs of earlier findings (tests/fuzz/regressions/).
#   deploy/fuzz.sh [SECONDS_PER_TARGET (default 20)] [more libFuzzer flags...]
# deploy/test.sh runs the short default; tests/fuzz/README.md records long runs.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-20}
shift || true
if ! command -v clang++ >/dev/null; then
  echo "fuzz: skipped: clang++ is not installed (deploy/install-deps.sh installs it)"
  exit 0
fi
B=${FUZZ_BUILD_DIR:-build-fuzz}
if [ ! -f "$B/build.ninja" ]; then
  CXX=clang++ cmake -S . -B "$B" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTESSERA_FUZZ=ON \
    -DTESSERA_BUILD_TESTS=OFF -DTESSERA_BUILD_BENCH=OFF
fi
targets=${FUZZ_TARGETS:-collada gltf bundle result}
cmake --build "$B" -j "$(nproc)" --target fuzz_collada fuzz_gltf fuzz_bundle fuzz_result
corpus="$B/corpus"
for t in collada gltf bundle result; do mkdir -p "$corpus/$t" "tests/fuzz/regressions/$t"; done  # (every seed set: FUZZ_TARGETS may name fewer)
cp scenes/*.dae "$corpus/collada/"
cp tests/fuzz/seeds/gltf/* "$corpus/gltf/"  # small: scenes/*.gltf carry 0.5 MB of buffers each
if [ -d ../shared/scenes/cs184 ]; then
  find ../shared/scenes/cs184 -name '*.dae' -size -2M -exec cp {} "$corpus/collada/" \;
fi
TESSERA_FUZZ_SEEDS="$corpus/bundle" "$B/bin/fuzz_bundle"
TESSERA_FUZZ_SEEDS="$corpus/result" "$B/bin/fuzz_result"
for t in $targets; do
  echo "fuzz: fuzz_$t for ${secs}s"
  ASAN_OPTIONS=detect_leaks=0 "$B/bin/fuzz_$t" "$corpus/$t" "tests/fuzz/regressions/$t" \
    -max_total_time="$secs" -timeout=10 -rss_limit_mb=4096 -print_final_stats=1 \
    -artifact_prefix="$B/" "$@" 2>"$B/fuzz_$t.log" || {  # (crash-* files in build-fuzz/, not the checkout's root)
    tail -50 "$B/fuzz_$t.log"
    echo "fuzz: fuzz_$t found a problem: the input is in the $B/crash-* file named above; keep it in" \
      "tests/fuzz/regressions/$t/ once fixed"
    exit 1
  }
  grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$B/fuzz_$t.log" | sed "s/^/fuzz: fuzz_$t /"
done
