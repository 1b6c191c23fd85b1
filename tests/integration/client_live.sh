# liblucent-client against real lucentd instances: basic requests and streams, a refused
# token, wss:// with a self-signed certificate, reconnect after a daemon restart.
. "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
LIVE="${LUCENT_BINARY_DIR}/tests/client_live"
if [ ! -x "$BIN/lucentd" ] || [ ! -x "$LIVE" ]; then echo "lucentd/client_live not built: skip"; exit 77; fi
PIDS=""
trap 'for p in $PIDS; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done; rm -rf "$TMP"' EXIT

# start_daemon NAME ARGS...: lib.sh's start_lucentd (state in $TMP/state-NAME); sets DPID and PORT.
start_daemon() {
  local name="$1"; shift
  if ! LUCENTD_START_TIMEOUT=15 start_lucentd "$TMP/state-$name" "$@"; then
    fail "lucentd ($name) did not start"
    finish
  fi
  DPID=$LUCENTD_PID
  PIDS="$PIDS $DPID"
  PORT=$LUCENTD_PORT
}

start_daemon plain
timeout 120 "$LIVE" basic "ws://127.0.0.1:$PORT/" || fail "basic"
kill "$DPID"; wait "$DPID" 2>/dev/null

printf '{"controller-tokens": ["good"]}\n' >"$TMP/tokens.json"
start_daemon tokens --config "$TMP/tokens.json"
timeout 60 "$LIVE" refused "ws://127.0.0.1:$PORT/" wrong || fail "refused"
kill "$DPID"; wait "$DPID" 2>/dev/null

if command -v openssl >/dev/null; then
  openssl req -x509 -newkey rsa:2048 -nodes -keyout "$TMP/key.pem" -out "$TMP/cert.pem" -days 1 \
    -subj /CN=127.0.0.1 -addext "subjectAltName=IP:127.0.0.1" >/dev/null 2>&1 || fail "openssl req"
  start_daemon tls --tls-cert "$TMP/cert.pem" --tls-key "$TMP/key.pem"
  timeout 60 "$LIVE" tls "wss://127.0.0.1:$PORT/" || fail "tls"
  # lucentctl over wss: refused certificate without --insecure (exit 3), fine with it or the CA
  timeout 20 "$BIN/lucentctl" --url "wss://127.0.0.1:$PORT/" ping >/dev/null 2>"$TMP/ctl.err"; rc=$?
  [ "$rc" = 3 ] || fail "lucentctl wss without --insecure exited $rc: $(cat "$TMP/ctl.err")"
  timeout 20 "$BIN/lucentctl" --url "wss://127.0.0.1:$PORT/" --insecure ping >/dev/null 2>"$TMP/ctl.err" \
    || fail "lucentctl --insecure over wss: $(cat "$TMP/ctl.err")"
  timeout 20 "$BIN/lucentctl" --url "wss://127.0.0.1:$PORT/" --ca-file "$TMP/cert.pem" state >/dev/null 2>"$TMP/ctl.err" \
    || fail "lucentctl --ca-file over wss: $(cat "$TMP/ctl.err")"
  kill "$DPID"; wait "$DPID" 2>/dev/null
else
  echo "openssl missing: wss part skipped"
fi

# reconnect: the same port after a kill -9 and restart (state kept)
start_daemon r1
RPORT="$PORT"
timeout 120 "$LIVE" reconnect "ws://127.0.0.1:$RPORT/" >"$TMP/live.out" 2>"$TMP/live.err" &
LPID=$!
wait_for 20 "the reconnect client printing READY" grep -q READY "$TMP/live.out" ||
  echo "client_live reconnect said: $(head -c 400 "$TMP/live.err")" >&2
kill -9 "$DPID"; wait "$DPID" 2>/dev/null
# the client has noticed the loss and retries against the closed port (client_live logs
# "connection event 2" = LC_CLIENT_RECONNECTING) before the daemon comes back
wait_for 20 "the client noticing the lost connection (connection event 2)" grep -q "connection event 2" "$TMP/live.err"
cp -r "$TMP/state-r1" "$TMP/state-r2"
start_daemon r2 --port "$RPORT"
wait "$LPID" || fail "reconnect: $(tail -c 600 "$TMP/live.err")"
finish
