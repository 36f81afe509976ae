#!/bin/bash
# CTest entry (Blender.AddonAgainstALocalFarm): Debian's Blender, headless and with factory
# settings, installs the add-on from build/blender/tessera_blender.zip into a scratch HOME and
# renders on a loopback farm (addon_test.py says what is checked). deploy/install-deps.sh
# installs blender, so a fresh machine runs it; it skips (77) only where no blender is found.
# Usage: addon-test.sh BUILD_DIR
set -u
BUILD=$(cd "$1" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
command -v blender >/dev/null || { echo "SKIP: blender is not installed (deploy/install-deps.sh installs it)"; exit 77; }
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
export HOME=$T XDG_CONFIG_HOME=$T/.config
unset TESSERA_COORDINATOR TESSERA_TOKEN TESSERA_TOKEN_FILE TESSERA_TLS_CA
blender -b --factory-startup --python-exit-code 1 --python "$SRC/tests/blender/addon_test.py" \
  -- "$BUILD/bin" "$BUILD" "$SRC" 2>&1 | grep -v '^Read prefs\|^Blender quit'
exit "${PIPESTATUS[0]}"
