#!/bin/bash
# CTest entry (Cli.AovLayersReadByExrheaderAndBlender): `tessera render --aov all` writes the
# AOV channels under the names docs/aov.md gives; OpenEXR's exrheader lists them, and
# Debian's Blender reads the file as a multilayer image whose compositor Image node offers
# each layer. An unknown AOV is a usage error (exit 2) naming it. (Through the farm:
# tests/integration/farm_aov_test.cc.)
# Usage: aov_layers.sh BUILD_DIR
set -u
BIN=$(cd "$1/bin" && pwd)
SRC=$(cd "$(dirname "$0")/../.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail=0
"$BIN/tessera" render "$SRC/scenes/cornell-spheres.gltf" -s 4 -r 32 24 --aov all -f "$T/a.exr" -q 2>/dev/null || {
  echo "FAIL: tessera render --aov all"; exit 1; }
if command -v exrheader >/dev/null; then
  got=$(exrheader "$T/a.exr" | sed -n '/^channels/,/^[a-z]/p' | grep -o '^    [^,]*' | tr -d ' ' | tr '\n' ' ')
  want="A B G R albedo.B albedo.G albedo.R depth.Z id.V normal.X normal.Y normal.Z spp variance "
  if [[ $got == "$want" ]]; then echo "ok    exrheader: $got"; else echo "FAIL: exrheader lists '$got', not '$want'"; fail=1; fi
else
  echo "FAIL: exrheader is not installed (deploy/install-deps.sh installs openexr)"; fail=1
fi
if command -v blender >/dev/null; then
  out=$(HOME=$T blender -b --factory-startup --python-expr "
import bpy
im = bpy.data.images.load('$T/a.exr')
s = bpy.context.scene; s.use_nodes = True
n = s.node_tree.nodes.new('CompositorNodeImage'); n.image = im
print('OUTPUTS', ' '.join(o.name + ':' + o.type for o in n.outputs))" 2>&1 | grep '^OUTPUTS')
  want="OUTPUTS Combined:RGBA Alpha:VALUE albedo:RGBA depth:VALUE id:VALUE normal:RGBA"
  if [[ $out == "$want" ]]; then echo "ok    Blender's compositor: ${out#OUTPUTS }"; else echo "FAIL: Blender reads '$out', not '$want'"; fail=1; fi
else
  echo "FAIL: blender is not installed (deploy/install-deps.sh installs it)"; fail=1
fi
msg=$("$BIN/tessera" render "$SRC/scenes/cornell-spheres.gltf" --aov albedo,zdepth -f "$T/b.exr" 2>&1)
rc=$?
if [[ $rc -eq 2 && $msg == *"'zdepth' is not an AOV"* ]]; then echo "ok    an unknown AOV: exit 2, $msg"
else echo "FAIL: --aov zdepth: exit $rc: $msg"; fail=1; fi
[[ $fail -eq 0 ]] && echo OK || echo FAILED
exit $fail
