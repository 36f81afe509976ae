#!/bin/bash
# CTest entry (Cli.DenoiseOnRenderAndAsACommand): `tessera render --denoise` writes the
# denoised image with the noisy one and the denoising layers beside it (no temporary left,
# a PNG alone too), `tessera denoise IN OUT` denoises a file rendered with --aov denoising,
# and refuses one without those layers (exit 1) naming the channels it lacks, and a file that
# is not an EXR (exit 1, naming it).
# Usage: denoise_cli.sh BUILD_DIR
set -u
BIN=$(cd "$1/bin" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail=0
ok() { echo "ok    $*"; }
bad() { echo "FAIL: $*"; fail=1; }
scene="$SRC/scenes/cornell-spheres.gltf"
channels() { exrheader "$1" | sed -n '/^channels/,/^[a-z]/p' | grep -o '^    [^,]*' | tr -d ' ' | tr '\n' ' '; }

out=$("$BIN/tessera" render "$scene" -s 8 -r 64 48 --denoise -f "$T/d.exr" -f "$T/d.png" 2>&1) || bad "render --denoise: $out"
[[ $out == *"denoised in"* ]] && ok "render --denoise says: ${out##*, denoised}" || bad "render --denoise output: $out"
want="B G R albedo.B albedo.G albedo.R depth.Z even.B even.G even.R noisy.B noisy.G noisy.R normal.X normal.Y normal.Z odd.B odd.G odd.R spp variance "
got=$(channels "$T/d.exr")
[[ $got == "$want" ]] && ok "the denoised EXR's channels: $got" || bad "channels '$got', not '$want'"
[[ -s $T/d.png ]] && ok "the PNG" || bad "no PNG"
"$BIN/tessera" render "$scene" -s 4 -r 32 24 --denoise -f "$T/only.png" -q || bad "render --denoise -f only.png"
left=$(ls "$T" | grep -c noisy)
[[ -s $T/only.png && $left -eq 0 ]] && ok "a PNG alone, no temporary left" || bad "only.png: $(ls "$T")"

"$BIN/tessera" render "$scene" -s 8 -r 64 48 --aov denoising -f "$T/n.exr" -q || bad "render --aov denoising"
out=$("$BIN/tessera" denoise "$T/n.exr" "$T/n-denoised.exr" 2>&1) || bad "tessera denoise: $out"
[[ $out == *"64x48 denoised in"* ]] && ok "tessera denoise: $out" || bad "tessera denoise said: $out"
[[ $(channels "$T/n-denoised.exr") == "$want" ]] && ok "its channels" || bad "its channels: $(channels "$T/n-denoised.exr")"
cmp -s <(channels "$T/n.exr") <(echo -n "${want//noisy.B noisy.G noisy.R /}") && ok "--aov denoising's channels" ||
  bad "--aov denoising's channels: $(channels "$T/n.exr")"

"$BIN/tessera" render "$scene" -s 2 -r 16 12 --aov albedo -f "$T/p.exr" -q || bad "render --aov albedo"
msg=$("$BIN/tessera" denoise "$T/p.exr" "$T/p2.exr" 2>&1)
rc=$?
if [[ $rc -eq 1 && $msg == *"even.R"* && $msg == *"depth.Z"* && $msg == *"--aov denoising"* && ! -e $T/p2.exr ]]; then
  ok "without the layers: exit 1, $msg"
else bad "without the layers: exit $rc: $msg"; fi
head -c 3000 /dev/urandom > "$T/junk.exr"
msg=$("$BIN/tessera" denoise "$T/junk.exr" "$T/j2.exr" 2>&1)
rc=$?
if [[ $rc -eq 1 && $msg == *"junk.exr: cannot read EXR"* && ! -e $T/j2.exr ]]; then ok "a file that is not an EXR: exit 1, $msg"
else bad "a file that is not an EXR: exit $rc: $msg"; fi
msg=$("$BIN/tessera" denoise "$T/none.exr" "$T/x.exr" 2>&1)
rc=$?
[[ $rc -eq 2 ]] && ok "a missing input: exit 2, $msg" || bad "a missing input: exit $rc: $msg"
[[ $fail -eq 0 ]] && echo OK || echo FAILED
exit $fail
