# SIGTERM while a relight is in flight: the compute thread must be joined before the lws
# context is destroyed (its lws_cancel_service() read freed memory: issue 13 item 2). ASan
# cannot see that read (it is inside libwebsockets), so this runs lucentd under valgrind:
# a light change with --refine-passes 64 keeps relights going, SIGTERM once a few of them are
# published (lucent_relights_total), and valgrind must report no invalid access. Skips
# without valgrind or on a sanitizer build.
source "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
command -v valgrind >/dev/null || { echo "valgrind not installed: skip"; exit 77; }
if ldd "$BIN/lucentd" | grep -q libasan; then echo "sanitizer build (valgrind cannot run it): skip"; exit 77; fi
log="$TMP/vg.log"
LUCENTD_WRAP=(valgrind --error-exitcode=99 --leak-check=no --log-file="$log")
LUCENTD_START_TIMEOUT=120 start_lucentd "$TMP/state" --bake "$LUCENT_BINARY_DIR/cornell.lcb" --threads 2 \
  --refine-passes 64 --refine-delay 0 ||
  { echo "FAIL: lucentd under valgrind did not start: $(tail -c 600 "$log")"; kill -9 "$LUCENTD_PID" 2>/dev/null; exit 1; }
pid=$LUCENTD_PID port=$LUCENTD_PORT
trap 'kill -9 "$pid" 2>/dev/null; rm -rf "$TMP"' EXIT
"$BIN/lucentctl" --url "ws://127.0.0.1:$port/" light set key --type point --position 0.2,0.4,0.2 \
  --intensity 3 >/dev/null || fail "light set under valgrind"
# The change's relight and then its refinement passes (64, back to back) are running: three
# more published since the change's ok, so the next one is in flight when SIGTERM comes.
base="$(metric "$port" lucent_relights_total)"
wait_for 120 "relights running under valgrind (lucent_relights_total from ${base:-?} up by 3)" \
  metric_ge "$port" lucent_relights_total "$((${base:-0} + 3))"
kill -TERM "$pid"
rc=0
wait "$pid" || rc=$?
trap 'rm -rf "$TMP"' EXIT
[ "$rc" = 0 ] || fail "lucentd under valgrind exited $rc after SIGTERM (99 = valgrind found errors): $(grep -A12 -m1 'Invalid' "$log")"
grep -q "ERROR SUMMARY: 0 errors" "$log" || fail "valgrind: $(grep 'ERROR SUMMARY' "$log")"
finish
