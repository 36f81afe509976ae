#!/bin/bash
# CTest entry (SystemdUnitsVerify): the systemd units in deploy/systemd are ones systemd
# accepts, and their ExecStart lines use only options our binaries have (docs/deploy.md
# installs them; the docs test cannot, it would need root and a running systemd).
#   1. `systemd-analyze verify` on each unit (the worker's template as an instance), with
#      /usr/local/bin/ pointing at this build's binaries: no warning about our units.
#   2. Each ExecStart's options (continuation lines joined) are in that binary's --help.
# Skips (77) where systemd-analyze is absent. Usage: systemd-units.sh BUILD_DIR
set -u
BIN=$(cd "$1/bin" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
command -v systemd-analyze >/dev/null || { echo "SKIP: systemd-analyze is not installed"; exit 77; }
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail=0
for unit in "$SRC"/deploy/systemd/*.service; do
  name=$(basename "$unit")
  [[ $name == *@.service ]] && name=${name/@.service/@coordinator.example.service}
  sed "s#/usr/local/bin/#$BIN/#g" "$unit" > "$T/$name"
  out=$(cd "$T" && systemd-analyze verify --man=no "$T/$name" 2>&1)
  rc=$?
  # Lines about other units (the host's own) are not ours to judge.
  ours=$(grep -F "$name" <<<"$out" || true)
  if [[ $rc -ne 0 || -n $ours ]]; then
    echo "FAIL: systemd-analyze verify $name (exit $rc):"
    echo "$out" | sed 's/^/    /'
    fail=1
  else
    echo "ok    systemd-analyze verify $name"
  fi
  # ExecStart with its continuation lines joined.
  exec_line=$(sed -n '/^ExecStart=/,/[^\\]$/p' "$unit" | sed 's/\\$//' | tr '\n' ' ' | sed 's/^ExecStart=//')
  binary=$(basename "$(awk '{print $1}' <<<"$exec_line")")
  help=$("$BIN/$binary" --help 2>&1)
  for opt in $(grep -oE '(^| )--[a-z][-a-z0-9]*' <<<"$exec_line" | tr -d ' '); do
    if grep -qE "(^|[ ,])$opt([ ,=]|$)" <<<"$help"; then
      echo "ok    $name: $binary $opt"
    else
      echo "FAIL: $name: $binary has no option $opt (its --help)"
      fail=1
    fi
  done
done
[[ $fail -eq 0 ]] && echo OK || echo FAILED
exit $fail
