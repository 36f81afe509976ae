#!/usr/bin/env bash
# CTest entry: builds the OCI image (deploy/container/build-image.sh) and runs what is in
# it from the image's own file system (a container made, mounted and chroot'ed into; no
# container runtime has to start): --help of the three executables, a render that must
# equal the host build's bit for bit, and a farm (coordinator, worker, client) on
# loopback. Checks the image stays under its size bound. Skips, saying why, where podman
# is missing or cannot build an image on this machine.
set -euo pipefail
build=$(cd "${1:?build directory}" && pwd)
root=$(cd "$(dirname "$0")/../.." && pwd)
max_bytes=$((150 * 1000 * 1000))  # docs/deploy.md: 81 MB when this was written
if ! command -v podman >/dev/null; then
  echo "SKIP: podman is not installed (deploy/install-deps.sh installs it)"
  exit 77
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "SKIP: mounting an image's file system and chroot need root"
  exit 77
fi
work=$(mktemp -d)
tag="localhost/tessera-test:$$"
cid=""
pids=()
cleanup() {
  set +e
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done
  [ -n "$cid" ] && { podman umount "$cid" >/dev/null; podman rm -f "$cid" >/dev/null; }
  podman rmi -f "$tag" "localhost/tessera-probe:$$" >/dev/null 2>&1
  rm -rf "$work"
}
trap cleanup EXIT
# Can this machine build an image at all? (storage driver, permissions)
printf 'FROM scratch\nCOPY probe /probe\n' >"$work/Containerfile"
echo probe >"$work/probe"
if ! probe=$(podman build --quiet --tag "localhost/tessera-probe:$$" "$work" 2>&1); then
  echo "SKIP: podman cannot build an image on this machine: $probe"
  exit 77
fi
bash "$root/deploy/container/build-image.sh" "$build" "$tag"
size=$(podman image inspect --format '{{.Size}}' "$tag")
echo "image size: $size bytes (bound $max_bytes)"
[ "$size" -le "$max_bytes" ] || { echo "FAIL: the image grew past its bound"; exit 1; }
cid=$(podman create "$tag")
mnt=$(podman mount "$cid")
as_user() { chroot --userspec=65532:65532 "$mnt" "$@"; }
for b in tessera tessera-coordinator tessera-worker; do
  as_user "/usr/bin/$b" --help >"$work/$b.help" || { echo "FAIL: $b --help in the image"; exit 1; }
  grep -q -- "--" "$work/$b.help"
done
# A render from the image's own files equals the host build's.
flags=(-r 32 24 -s 4 --seed 7)
as_user /usr/bin/tessera render /usr/share/tessera/scenes/cornell-spheres.dae "${flags[@]}" -q -f /tmp/image.exr
"$build/bin/tessera" render "$root/scenes/cornell-spheres.dae" "${flags[@]}" -q -f "$work/host.exr"
"$build/bin/tessera_compare" "$mnt/tmp/image.exr" "$work/host.exr" | tee "$work/compare.json"
grep -q '"identical":true' "$work/compare.json" || { echo "FAIL: the image's render differs from the host's"; exit 1; }
# A farm from the image: coordinator, worker and client, on loopback.
chroot --userspec=65532:65532 "$mnt" /usr/bin/tessera-coordinator --listen 127.0.0.1:0 --http 127.0.0.1:0 --data /tmp/data >"$work/coord.out" 2>"$work/coord.err" &
pids+=($!)
for _ in $(seq 100); do grep -q "grpc listening" "$work/coord.out" && break; sleep 0.1; done
addr=$(sed -n 's/^grpc listening on \([^ ]*\).*/\1/p' "$work/coord.out")
[ -n "$addr" ] || { echo "FAIL: the coordinator from the image did not start"; cat "$work/coord.err"; exit 1; }
chroot --userspec=65532:65532 "$mnt" /usr/bin/tessera-worker --coordinator "$addr" --threads 1 --cache /tmp/cache >/dev/null 2>"$work/worker.err" &
pids+=($!)
as_user /usr/bin/tessera submit /usr/share/tessera/scenes/cornell-spheres.dae "${flags[@]}" --coordinator "$addr" \
  --wait -q -f /tmp/farm.exr
"$build/bin/tessera_compare" "$mnt/tmp/farm.exr" "$work/host.exr" | tee "$work/compare-farm.json"
grep -q '"identical":true' "$work/compare-farm.json" || { echo "FAIL: the image's farm render differs"; exit 1; }
echo "PASS: image $size bytes; help, render and farm from the image's file system"
