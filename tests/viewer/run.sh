#!/bin/bash
# Runs one of the viewer's browser tests (tests/viewer/NAME.mjs) with node; exit 77 (skip)
# when node is missing (the .mjs files skip themselves when client/node_modules, chromium,
# lucentd, the bake or the viewer bundle are missing).
set -u
name=${1:?usage: run.sh TEST_NAME}
if ! command -v node >/dev/null 2>&1; then
  echo "SKIP: node not found (apt-get install nodejs npm)"
  exit 77
fi
exec node "$(dirname "$0")/$name.mjs"
