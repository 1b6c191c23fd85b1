# Shared helpers for integration tests (sourced). Provides $BAKE, $SRC, $SHARED, $TMP,
# fail/expect_exit helpers. Tests exit 0 pass, 77 skip, else fail.
set -u
SRC="${LUCENT_SOURCE_DIR:?run through ctest}"
BAKE="${LUCENT_BAKE:?run through ctest}"
SHARED="${LUCENT_SHARED_DIR:-$SRC/../shared}"
PY=/usr/bin/python3
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
FAILS=0
fail() { echo "FAIL: $*" >&2; FAILS=$((FAILS + 1)); }
# expect_exit CODE PATTERN cmd...: runs cmd, checks its exit code and that stderr matches PATTERN.
expect_exit() {
  local want="$1" pattern="$2"; shift 2
  local rc=0
  "$@" >"$TMP/out" 2>"$TMP/err" || rc=$?
  if [ "$rc" != "$want" ]; then fail "'$*' exited $rc, expected $want; stderr: $(head -c 400 "$TMP/err")"; return; fi
  if [ -n "$pattern" ] && ! grep -qiE -- "$pattern" "$TMP/err"; then
    fail "'$*' stderr lacks /$pattern/: $(head -c 400 "$TMP/err")"
  fi
}
finish() { if [ "$FAILS" -ne 0 ]; then echo "$FAILS failure(s)" >&2; exit 1; fi; echo "all checks passed"; exit 0; }
CORNELL="$SRC/scenes/cornell-box/cornell-box.obj"
# wait_for SECONDS WHAT CMD...: runs CMD every 50 ms until it succeeds (returns 0); after
# SECONDS it records "FAIL: WHAT did not happen within SECONDS s" and returns 1. The way to
# wait for an event (a log line, a file, a metric) instead of sleeping.
wait_for() {
  local secs="$1" what="$2"; shift 2
  local end=$(($(date +%s%N) / 1000000 + ${secs%.*} * 1000))
  until "$@" 2>/dev/null; do
    if [ "$(($(date +%s%N) / 1000000))" -ge "$end" ]; then fail "$what did not happen within $secs s"; return 1; fi
    sleep 0.05
  done
}
# metric PORT NAME: prints one /metrics sample of the lucentd on PORT (NAME with its labels),
# nothing when absent or unreachable. metric_ge PORT NAME N: the sample is >= N.
metric() {
  PYTHONPATH="$SRC/tests/lib" "$PY" -c 'import sys, lucent_testlib as lt
v = lt.metric(int(sys.argv[1]), sys.argv[2])
print("" if v is None else int(v) if v == int(v) else v)' "$1" "$2" 2>/dev/null
}
metric_ge() { local v; v="$(metric "$1" "$2")"; [ -n "$v" ] && "$PY" -c 'import sys; sys.exit(float(sys.argv[1]) < float(sys.argv[2]))' "$v" "$3"; }
# start_lucentd DIR [ARGS...]: starts "$LUCENT_BINARY_DIR/bin/lucentd" on a free port with its
# state in DIR (logs DIR.out, DIR.err); sets LUCENTD_PID and LUCENTD_PORT (ARGS may name a
# --port: the last one wins). LUCENTD_WRAP (an array, e.g. (valgrind --log-file=F)) goes
# before the binary; LUCENTD_START_TIMEOUT (default 10 s) bounds the wait for its
# "lucentd listening port=N" line. Returns 1 (and says why) when it does not come up. The
# caller kills LUCENTD_PID (the wrapper's pid when there is one).
start_lucentd() {
  local dir="$1"; shift
  ${LUCENTD_WRAP[@]+"${LUCENTD_WRAP[@]}"} "${LUCENT_BINARY_DIR:?run through ctest}/bin/lucentd" --port 0 \
    --state-dir "$dir" --backend cpu --log-level warn "$@" >"$dir.out" 2>"$dir.err" &
  LUCENTD_PID=$!
  LUCENTD_PORT=""
  local end=$(($(date +%s) + ${LUCENTD_START_TIMEOUT:-10}))
  while [ "$(date +%s)" -le "$end" ]; do
    LUCENTD_PORT="$(sed -n 's/^lucentd listening port=\([0-9]*\).*/\1/p' "$dir.out")"
    [ -n "$LUCENTD_PORT" ] && return 0
    kill -0 "$LUCENTD_PID" 2>/dev/null || break
    sleep 0.05
  done
  echo "FAIL: lucentd did not start within ${LUCENTD_START_TIMEOUT:-10} s: $(head -c 400 "$dir.err")" >&2
  return 1
}
# json_check FILE PYTHON_EXPR: evaluates the expression with `j` = the JSON in FILE (fails on
# False or an exception). E.g. json_check "$TMP/out" 'j["revision"] > 3'.
json_check() {
  if ! "$PY" -c 'import json, sys
j = json.load(open(sys.argv[1]))
sys.exit(0 if eval(sys.argv[2]) else 1)' "$1" "$2" 2>"$TMP/json_check.err"; then
    fail "JSON check failed: $2 on $(head -c 600 "$1") $(head -c 300 "$TMP/json_check.err")"
  fi
}
# lucentctl_setup: the common start of the lucentctl tests. Skips (77) when lucentd or
# lucentctl is not built; starts lucentd on a free port (state in $TMP/d, killed on exit);
# exports LUCENT_URL; sets BIN, CTL and DPID.
lucentctl_setup() {
  BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
  CTL="$BIN/lucentctl"
  if [ ! -x "$BIN/lucentd" ] || [ ! -x "$CTL" ]; then echo "lucentd/lucentctl not built: skip"; exit 77; fi
  start_lucentd "$TMP/d" || exit 1
  DPID=$LUCENTD_PID
  trap 'kill "$DPID" 2>/dev/null; wait "$DPID" 2>/dev/null; rm -rf "$TMP"' EXIT
  export LUCENT_URL="ws://127.0.0.1:$LUCENTD_PORT/"
}

# defaults_check NAME CONFIG: the delta-frame keys a shipped config sets hold lucentd's own
# defaults (as `lucentd --help` states them); needs LUCENTD, PY and TMP.
defaults_check() {
  [ -s "$TMP/lucentd-help" ] || "$LUCENTD" --help >"$TMP/lucentd-help" 2>&1 || fail "lucentd --help"
  local key want got
  for key in tile delta-threshold keyframe-interval; do
    want="$(sed -n "s/^  --$key [A-Z]* .*(default \([^)]*\)).*/\1/p" "$TMP/lucentd-help")"
    got="$("$PY" -c 'import json, sys; j = json.load(open(sys.argv[1])); print(j.get(sys.argv[2], ""))' "$2" "$key")" ||
      { fail "$1: not JSON"; return; }
    [ -z "$got" ] && continue
    "$PY" -c 'import sys; sys.exit(0 if float(sys.argv[1]) == float(sys.argv[2]) else 1)' "$got" "$want" ||
      fail "$1: \"$key\": $got, lucentd's default is $want"
  done
}
