#!/bin/bash
# CTest entry (Blender.AddonInTheInterface): the add-on's interactive path (the modal
# operator, progress while Blender stays responsive, the Image Editor) in Debian's Blender
# with a window, on a virtual X display (xvfb-run; Mesa's software OpenGL). ui_test.py says
# what is checked. Skips (77) only where blender or xvfb-run is missing
# (deploy/install-deps.sh installs both). Usage: ui-test.sh BUILD_DIR
set -u
BUILD=$(cd "$1" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
for tool in blender xvfb-run xauth; do
  command -v $tool >/dev/null || { echo "SKIP: $tool is not installed (deploy/install-deps.sh installs it)"; exit 77; }
done
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
export HOME=$T XDG_CONFIG_HOME=$T/.config LIBGL_ALWAYS_SOFTWARE=1
unset TESSERA_COORDINATOR TESSERA_TOKEN TESSERA_TOKEN_FILE TESSERA_TLS_CA
timeout 240 xvfb-run -a -s "-screen 0 1280x800x24" blender --factory-startup \
  --python "$SRC/tests/blender/ui_test.py" -- "$BUILD/bin" "$BUILD" "$SRC" "$T/result.json" > "$T/blender.log" 2>&1
rc=$?
if [[ ! -s $T/result.json ]]; then
  echo "FAIL: Blender wrote no result (exit $rc); its log:"
  tail -40 "$T/blender.log"
  exit 1
fi
/usr/bin/python3 - "$T/result.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print("\n".join(r["log"]))
print("FAILED" if r["failures"] else "OK")
sys.exit(1 if r["failures"] else 0)
PY
