#!/usr/bin/env bash
# Installs every Debian package Tessera's build, tests and tools need.
# Idempotent: packages already present are skipped, so a second run is a no-op.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build ccache pkg-config git
  libembree-dev libopenexr-dev libimath-dev libpugixml-dev libtinygltf-dev
  libgrpc++-dev libprotobuf-dev protobuf-compiler protobuf-compiler-grpc
  libcli11-dev libspdlog-dev libfmt-dev nlohmann-json3-dev libcpp-httplib-dev
  libzstd-dev libxxhash-dev libstb-dev libpng-dev libsqlite3-dev libmeshoptimizer-dev libdraco-dev libwebp-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-numpy python3-matplotlib
  iproute2 libssl-dev openssl
  clang libclang-rt-14-dev
  podman slurm-wlm munge curl
  chromium  # the live page's browser test (tests/web)
  systemd   # systemd-analyze: the units' check (tests/deploy/systemd-units.sh)
  python3-grpcio python3-protobuf python3-xxhash  # the Python client (client/python)
  openexr   # exrheader: the AOV layers' check (tests/cli/aov_layers.sh)
  # The add-on's tests (tests/blender): Debian's Blender 3.4, and a virtual display for its
  # interface (xvfb-run needs xauth, only recommended; Mesa's software OpenGL for Blender).
  blender xvfb xauth libgl1-mesa-dri
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

# The Kubernetes manifest check runs on Node.js: Debian's, unless a node with npm is there.
command -v npm >/dev/null || missing+=(nodejs npm)

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
