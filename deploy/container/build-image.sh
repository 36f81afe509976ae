#!/usr/bin/env bash
# Builds the OCI image with podman from a release build: the three executables, every
# shared library `ldd` says they load (and the loader), a passwd entry for the unprivileged
# user 65532, name-service files, and the default scene. No base image, no registry.
#   deploy/container/build-image.sh [BUILD_DIR (build)] [TAG (tessera:latest)]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
tag=${2:-tessera:latest}
ctx=$(mktemp -d)
trap 'rm -rf "$ctx"' EXIT
rootfs="$ctx/rootfs"
mkdir -p "$rootfs/usr/bin" "$rootfs/etc" "$rootfs/tmp" "$rootfs/usr/share/tessera/scenes" "$rootfs/var/lib/tessera"
chmod 1777 "$rootfs/tmp"
bins=(tessera tessera-coordinator tessera-worker)
for b in "${bins[@]}"; do
  install -m 0755 "$build/bin/$b" "$rootfs/usr/bin/$b"
  strip --strip-unneeded "$rootfs/usr/bin/$b" 2>/dev/null || true
done
# Every library the executables load, at the path the loader finds it (symlinks resolved).
# (Paths read whole, spaces and all: "name => PATH (0x...)" or "PATH (0x...)".)
while IFS= read -r lib; do
  mkdir -p "$rootfs$(dirname "$lib")"
  cp -L "$lib" "$rootfs$lib"
done < <(for b in "${bins[@]}"; do ldd "$build/bin/$b"; done |
  sed -n -e 's/^.* => \(\/.*\) (0x[0-9a-f]*)$/\1/p' -e 's/^[[:space:]]*\(\/.*\) (0x[0-9a-f]*)$/\1/p' | sort -u)
printf 'root:x:0:0:root:/:/sbin/nologin\ntessera:x:65532:65532:tessera:/tmp:/sbin/nologin\n' >"$rootfs/etc/passwd"
printf 'root:x:0:\ntessera:x:65532:\n' >"$rootfs/etc/group"
printf 'hosts: files dns\n' >"$rootfs/etc/nsswitch.conf"
printf '127.0.0.1 localhost\n::1 localhost\n' >"$rootfs/etc/hosts"
# The data folder is the image user's. Rootless podman maps that uid in its user namespace
# (a plain chown needs root: a non-root build stopped here).
if [ "$(id -u)" = 0 ]; then
  chown 65532:65532 "$rootfs/var/lib/tessera"
else
  podman unshare chown 65532:65532 "$rootfs/var/lib/tessera"
fi
cp "$root/scenes/cornell-spheres.dae" "$rootfs/usr/share/tessera/scenes/"
cp "$here/Containerfile" "$ctx/"
podman build --quiet --tag "$tag" "$ctx" >/dev/null
echo "built $tag: $(podman image inspect --format '{{.Size}}' "$tag") bytes"
