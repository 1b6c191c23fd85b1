# SIGTERM while a relight is in flight: the compute thread must be joined before the lws
# context is destroyed (its lws_cancel_service() read freed memory: issue 13 item 2). ASan
# cannot see that read (it is inside libwebsockets), so this runs lucentd under valgrind:
# a light change with --refine-passes 64 keeps relights going, SIGTERM 3 s later, and
# valgrind must report no invalid access. Skips without valgrind or on a sanitizer build.
source "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
command -v valgrind >/dev/null || { echo "valgrind not installed: skip"; exit 77; }
if ldd "$BIN/lucentd" | grep -q libasan; then echo "sanitizer build (valgrind cannot run it): skip"; exit 77; fi
log="$TMP/vg.log"
valgrind --error-exitcode=99 --leak-check=no --log-file="$log" "$BIN/lucentd" --bake "$LUCENT_BINARY_DIR/cornell.lcb" \
  --port 0 --state-dir "$TMP/state" --backend cpu --threads 2 --refine-passes 64 --refine-delay 0 --log-level warn \
  >"$TMP/out" 2>"$TMP/err" &
pid=$!
trap 'kill -9 "$pid" 2>/dev/null; rm -rf "$TMP"' EXIT
port=""
for _ in $(seq 1 1200); do
  port="$(sed -n 's/^lucentd listening port=\([0-9]*\).*/\1/p' "$TMP/out")"
  [ -n "$port" ] && break
  kill -0 "$pid" 2>/dev/null || break
  sleep 0.1
done
[ -n "$port" ] || { echo "FAIL: lucentd under valgrind did not start: $(tail -c 600 "$TMP/err") $(tail -c 600 "$log")"; exit 1; }
"$BIN/lucentctl" --url "ws://127.0.0.1:$port/" light set key --type point --position 0.2,0.4,0.2 \
  --intensity 3 >/dev/null || fail "light set under valgrind"
sleep 3
kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
trap 'rm -rf "$TMP"' EXIT
[ "$rc" = 0 ] || fail "lucentd under valgrind exited $rc after SIGTERM (99 = valgrind found errors): $(grep -A12 -m1 'Invalid' "$log")"
grep -q "ERROR SUMMARY: 0 errors" "$log" || fail "valgrind: $(grep 'ERROR SUMMARY' "$log")"
finish
