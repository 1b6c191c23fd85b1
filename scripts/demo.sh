#!/usr/bin/env bash
# The main job on the embedded default scene: bake the Cornell box (the build does it) and
# print what the bake file holds. Until the daemon lands this is the product's front door.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
bash "$root/scripts/build.sh"
build="${LUCENT_BUILD_DIR:-$root/build}"
"$build/bin/lucent-bake" bake "$root/scenes/cornell-box/cornell-box.obj" \
    -o "$build/cornell.lcb" --glb "$build/cornell.glb" --quality moderate --atlas-size 64 \
    --grid-max-samples 1024 --seed 1  # the same settings as the build's bake (CMakeLists.txt)
"$build/bin/lucent-bake" info "$build/cornell.lcb"
