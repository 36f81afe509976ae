#!/usr/bin/env bash
# The coordinator's lock rules (server/coordinator.h), proved by clang's -Wthread-safety:
# every source of server/ and worker/ and core/util/ (and core/render/splats.cc, whose
# SplatFilm the coordinator shares too) is compiled (syntax only) with the
# analysis as an error, with the flags of the build in BUILD_DIR (its compile_commands.json).
# First it checks itself: tests/server/thread_safety/violation.cc must be refused, four
# times. Run by CTest (ThreadSafety.ClangProvesTheLockRules); skips if clang is absent.
#   deploy/thread-safety.sh [BUILD_DIR (default build)]
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-build}
if ! command -v clang++ >/dev/null; then
  echo "thread-safety: skipped: clang++ is not installed (deploy/install-deps.sh installs it)"
  exit 0
fi
FLAGS=(-std=c++20 -fsyntax-only -Wthread-safety -Werror=thread-safety -Wno-unknown-warning-option)
out=$(clang++ "${FLAGS[@]}" -I. tests/server/thread_safety/violation.cc 2>&1 || true)
found=$(grep -c "error: .*requires holding mutex" <<<"$out" || true)
if [ "$found" -ne 4 ]; then
  echo "thread-safety: the check is not alive: 4 violations expected, $found refused"
  echo "$out"
  exit 1
fi
python3 - "$B" <<'PY'
import json, os, shlex, subprocess, sys
from concurrent.futures import ThreadPoolExecutor
build = sys.argv[1]
root = os.getcwd()
entries = [e for e in json.load(open(os.path.join(build, "compile_commands.json")))
           if any(os.path.relpath(e["file"], root).startswith(d) for d in ("server/", "worker/", "core/util/", "core/render/splats.cc"))]
def check(e):
    args, skip, keep = shlex.split(e["command"])[1:], False, []
    for a in args:
        if skip: skip = False; continue
        if a == "-o": skip = True; continue
        if a in ("-c", e["file"]) or a.startswith("-fno-fast-math"): continue
        keep.append(a)
    cmd = ["clang++", "-fsyntax-only", "-Wthread-safety", "-Werror=thread-safety",
           "-Wno-unknown-warning-option"] + keep + [e["file"]]
    r = subprocess.run(cmd, cwd=e["directory"], capture_output=True, text=True)
    return e["file"], r.returncode, r.stderr
failed = 0
with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
    for f, rc, err in pool.map(check, entries):
        if rc != 0:
            failed += 1
            print(f"thread-safety: {os.path.relpath(f, root)}:\n{err}")
print(f"thread-safety: {len(entries) - failed} of {len(entries)} sources keep the lock rules")
sys.exit(1 if failed or not entries else 0)
PY
