#!/usr/bin/env bash
# Installs the Debian 12 packages lucent builds and tests with, if missing.
# Runs `apt-get update` at most once; safe to run repeatedly.
#   --build   only what building needs (deploy/Containerfile's build stage)
set -euo pipefail

packages=(
  build-essential cmake pkg-config
  libembree-dev libassimp-dev libopenimageio-dev openimageio-tools
  libcjson-dev libwebsockets-dev libssl-dev libpng-dev zlib1g-dev
  libepoxy-dev libegl-dev libegl1-mesa-dev libgl1-mesa-dri libgl-dev
  liblapacke-dev libblas-dev libhiredis-dev
)
# The browser viewer's bundle (npm: three.js, esbuild): Debian's node and npm, unless a node
# is already installed (another distribution of it brings its own npm).
command -v node >/dev/null || packages+=(nodejs)
command -v npm >/dev/null || packages+=(npm)
if [ "${1:-}" != "--build" ]; then
  packages+=(
    python3-websockets python3-pytest python3-jsonschema python3-yaml jq
    # bench/fidelity.sh: a bake's wall time and peak memory
    time
    # scripts/fuzz.sh: clang + its libFuzzer/sanitizer runtimes, llvm-symbolizer for the reports
    clang libclang-rt-14-dev llvm
    # lucentd --cluster's tests start their own Redis
    redis-server
    # promtool (checks lucentd's /metrics text)
    prometheus
    # the style check (.clang-format), the shutdown test under valgrind, TLS test certificates
    clang-format valgrind openssl
    # the viewer's browser tests (playwright-core drives it headless)
    chromium
  )
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "setup-deps: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "setup-deps: need root or sudo to install: ${missing[*]}" >&2; exit 1; }
  SUDO=sudo
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
