# js.client: the JavaScript client's tests (client/js/test/*.test.mjs, Node's test runner)
# against this build's lucentd. Skips (77) without node >= 18 or without client/node_modules.
cd "${LUCENT_SOURCE_DIR:?run through ctest}/client" || exit 1
command -v node >/dev/null || { echo "node not installed: skip (client/js needs Node >= 18)"; exit 77; }
major=$(node -p 'process.versions.node.split(".")[0]')
[ "$major" -ge 18 ] || { echo "node $(node --version) is older than 18: skip"; exit 77; }
[ -d node_modules/ws ] || { echo "client/node_modules is missing: run npm ci in client/ (skip)"; exit 77; }
[ -x "${LUCENT_BINARY_DIR:?}/tests/replay_frames" ] || { echo "build the replay_frames target first" >&2; exit 1; }
exec node --test js/test/
