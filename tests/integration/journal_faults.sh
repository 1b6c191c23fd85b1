# lucentd's journal under faults (issue 13, item 3), end to end with lucentctl:
#  (a) fdatasync fails (an LD_PRELOAD shim: EIO on the Nth call, then while a hold file
#      exists): the failing change gets `internal`, later ones are refused with `internal`
#      until the journal recovers (a snapshot succeeds once the hold file is gone), the
#      break and the recovery are logged once each; after kill -9 the restart holds every
#      acknowledged change and no refused one.
#  (b) a full disk (a 512 KiB tmpfs as the state dir; root only): changes on the full disk
#      are refused, not acknowledged; after space is freed they are acknowledged again;
#      after kill -9 the restart succeeds and holds exactly the acknowledged ones.
#  (c) a corrupt complete line in the middle: a plain start exits 1 naming the file, the
#      line and --recover; --recover starts with the valid prefix and reports what it
#      dropped; the next plain start is clean.
# A case that cannot run here (no cc, no root/mount, a shim the sanitizer runtime will not
# take) is skipped: the test then exits 77 after running the others (1 if any failed).
. "$(dirname "$0")/lib.sh"
BIN="${LUCENT_BINARY_DIR:?run through ctest}/bin"
CTL="$BIN/lucentctl"
if [ ! -x "$BIN/lucentd" ] || [ ! -x "$CTL" ]; then echo "lucentd/lucentctl not built: skip"; exit 77; fi
T="timeout 20"
MNT="$TMP/mnt"
MOUNTED=0
DPID=""
cleanup() {
  [ -n "$DPID" ] && kill -9 "$DPID" 2>/dev/null && wait "$DPID" 2>/dev/null
  [ "$MOUNTED" = 1 ] && umount "$MNT" 2>/dev/null
  rm -rf "$TMP"
}
trap cleanup EXIT
SKIPPED=""
skip_case() { echo "SKIP: $*"; SKIPPED="$SKIPPED ($*)"; }

ACKED=""
# set_light ID EXPECT: light.set through lucentctl; EXPECT ok (exit 0), refused (exit 1 with
# `internal`) or any (either; the outcome is recorded). Acknowledged ids go to $ACKED.
# Returns 0 when acknowledged.
set_light() {
  local id="$1" want="$2" rc=0
  $T "$CTL" light set "$id" --type point --position 0.2,0.4,0.3 --intensity 1 >"$TMP/set.out" 2>"$TMP/set.err" || rc=$?
  if [ "$rc" = 0 ]; then
    ACKED="$ACKED $id"
    [ "$want" = refused ] && fail "light '$id' was acknowledged, expected a refusal: $(head -c 300 "$TMP/set.out")"
    return 0
  fi
  if [ "$rc" != 1 ] || ! grep -q "server error internal" "$TMP/set.err"; then
    fail "light '$id': exit $rc, expected ok or an internal error: $(head -c 400 "$TMP/set.err")"
  elif [ "$want" = ok ]; then
    fail "light '$id' was refused, expected ok: $(head -c 400 "$TMP/set.err")"
  fi
  return 1
}
# check_state: the running lucentd's lights are exactly $ACKED (in any order) and its
# revision is their number (one change each).
check_state() {
  local what="$1"
  if ! $T "$CTL" state --json >"$TMP/state.json" 2>"$TMP/state.err"; then
    fail "$what: state failed: $(head -c 300 "$TMP/state.err")"
    return
  fi
  "$PY" - "$TMP/state.json" "$what" $ACKED <<'EOF' || FAILS=$((FAILS + 1))
import json, sys
j = json.load(open(sys.argv[1]))
what, want = sys.argv[2], sorted(sys.argv[3:])
got = sorted(l["id"] for l in j["lights"])
if got != want or j["revision"] != len(want):
    print("FAIL: %s: lights %s at revision %s, expected exactly the acknowledged %s at revision %d"
          % (what, got, j["revision"], want, len(want)), file=sys.stderr)
    sys.exit(1)
EOF
}
stop_hard() { kill -9 "$DPID" 2>/dev/null; wait "$DPID" 2>/dev/null; DPID=""; }
start() {
  start_lucentd "$@" || { fail "lucentd did not start (state dir $1)"; return 1; }
  DPID=$LUCENTD_PID
  export LUCENT_URL="ws://127.0.0.1:$LUCENTD_PORT/"
}

# --- (a) a failing fdatasync -------------------------------------------------------------
case_fsync() {
  if ! command -v cc >/dev/null; then skip_case "(a) fdatasync: no C compiler for the shim"; return; fi
  mkdir -p "$TMP/shim"
  cat >"$TMP/shim/shim.c" <<'EOF'
/* fdatasync fails with EIO on call SHIM_FAIL_AT, and on every later call while the file
 * SHIM_HOLD exists. Creates SHIM_MARK when loaded (the test checks the shim took). */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <sys/syscall.h>
#include <unistd.h>
static int shim_calls;
__attribute__((constructor)) static void shim_loaded(void) {
    const char *mark = getenv("SHIM_MARK");
    int fd = mark ? open(mark, O_WRONLY | O_CREAT | O_TRUNC, 0644) : -1;
    if (fd >= 0) close(fd);
}
int fdatasync(int fd) {
    const char *at = getenv("SHIM_FAIL_AT"), *hold = getenv("SHIM_HOLD");
    int n = __atomic_add_fetch(&shim_calls, 1, __ATOMIC_SEQ_CST), first = at ? atoi(at) : 0;
    if (first > 0 && (n == first || (n > first && hold && access(hold, F_OK) == 0))) {
        errno = EIO;
        return -1;
    }
    return (int)syscall(SYS_fdatasync, fd);
}
EOF
  if ! cc -shared -fPIC -o "$TMP/shim/shim.so" "$TMP/shim/shim.c" 2>"$TMP/shim/cc.err"; then
    skip_case "(a) fdatasync: the shim does not build: $(head -c 200 "$TMP/shim/cc.err")"
    return
  fi
  # A sanitizer runtime has to come first in LD_PRELOAD.
  local preload="$TMP/shim/shim.so" asan
  asan="$(ldd "$BIN/lucentd" 2>/dev/null | awk '/libasan/ {print $3; exit}')"
  [ -n "$asan" ] && preload="$asan:$preload"
  # Only lucentd gets the shim (not the shell tools start_lucentd runs): a wrapper that
  # start_lucentd takes for the binary. fdatasync call N = change N (--fsync always;
  # opening the journal makes none).
  mkdir -p "$TMP/wrap/bin"
  printf '#!/bin/sh\nSHIM_MARK="%s" SHIM_FAIL_AT=4 SHIM_HOLD="%s" LD_PRELOAD="%s" exec "%s" "$@"\n' \
    "$TMP/shim/loaded" "$TMP/hold" "$preload" "$BIN/lucentd" >"$TMP/wrap/bin/lucentd"
  chmod +x "$TMP/wrap/bin/lucentd"
  touch "$TMP/hold"
  ACKED=""
  LUCENT_BINARY_DIR="$TMP/wrap" start "$TMP/a" || return
  if [ ! -e "$TMP/shim/loaded" ]; then
    stop_hard
    skip_case "(a) fdatasync: the LD_PRELOAD shim did not load into lucentd${asan:+ (sanitizer build)}"
    return
  fi
  set_light a1 ok; set_light a2 ok; set_light a3 ok
  set_light b4 refused # its fdatasync fails
  echo "(a) the failing change: $(cat "$TMP/set.err")"
  for id in r5 r6 r7; do # the journal is broken: refused until a snapshot succeeds
    set_light $id refused
    grep -q "refused" "$TMP/set.err" || fail "refusal of '$id' does not say changes are refused: $(head -c 300 "$TMP/set.err")"
  done
  rm -f "$TMP/hold"
  wait_for 10 "(a) 'recovered' in the log after the disk healed" grep -q "recovered" "$TMP/a.err"
  set_light c1 ok; set_light c2 ok; set_light c3 ok
  [ "$(grep -c "refusing changes until" "$TMP/a.err")" = 1 ] ||
    fail "(a) the break is not logged exactly once: $(grep -c "refusing changes until" "$TMP/a.err")"
  [ "$(grep -c "recovered" "$TMP/a.err")" = 1 ] || fail "(a) the recovery is not logged exactly once"
  check_state "(a) before kill -9"
  stop_hard
  start "$TMP/a" || return
  check_state "(a) after kill -9 and restart"
  stop_hard
}

# --- (b) a full disk ---------------------------------------------------------------------
case_full_disk() {
  if [ "$(id -u)" != 0 ]; then skip_case "(b) full disk: needs root to mount a tmpfs"; return; fi
  mkdir -p "$MNT"
  if ! mount -t tmpfs -o size=512k lucent-journal-test "$MNT" 2>"$TMP/mount.err"; then
    skip_case "(b) full disk: mount -t tmpfs failed: $(head -c 200 "$TMP/mount.err")"
    return
  fi
  MOUNTED=1
  # The state dir on the tmpfs, its logs (start_lucentd writes DIR.out/.err) off it.
  mkdir "$MNT/state"
  ln -s "$MNT/state" "$TMP/b"
  ACKED=""
  start "$TMP/b" || return
  set_light d1 ok; set_light d2 ok
  dd if=/dev/zero of="$MNT/fill" bs=4k 2>/dev/null
  # The journal's last page still takes a few lines; then every append hits ENOSPC.
  local refused=0 n=0
  while [ "$refused" -lt 3 ] && [ "$n" -lt 80 ]; do
    n=$((n + 1))
    set_light "f$n" any || refused=$((refused + 1))
  done
  [ "$refused" = 3 ] || fail "(b) $n changes on a full disk, none refused"
  echo "(b) full disk: $((n - refused)) changes acknowledged (room left in the journal's last page), then refused"
  rm -f "$MNT/fill"
  set_light g1 ok; set_light g2 ok; set_light g3 ok
  check_state "(b) before kill -9"
  stop_hard
  start "$TMP/b" || return
  check_state "(b) after kill -9 and restart"
  stop_hard
  umount "$MNT" && MOUNTED=0
}

# --- (c) a corrupt middle line and --recover ---------------------------------------------
case_recover() {
  ACKED=""
  start "$TMP/c" || return
  set_light k1 ok; set_light k2 ok; set_light k3 ok; set_light k4 ok
  stop_hard
  "$PY" - "$TMP/c/journal.log" <<'EOF'
import sys
lines = open(sys.argv[1], "rb").read().split(b"\n")
lines[1] = b"x" * len(lines[1])
open(sys.argv[1], "wb").write(b"\n".join(lines))
EOF
  expect_exit 1 "$TMP/c/journal.log line 2: .*--recover" $T "$BIN/lucentd" --port 0 --state-dir "$TMP/c" --backend cpu
  ACKED=" k1"
  start "$TMP/c" --recover || return
  grep -q "line 2: not a journal record.*dropped it and the rest of the file: 3 lines .*revisions 3\.\.4" "$TMP/c.err" ||
    fail "(c) --recover does not report what it dropped: $(head -c 600 "$TMP/c.err")"
  ls "$TMP/c"/journal.dropped.* >/dev/null 2>&1 || fail "(c) --recover did not keep the dropped lines"
  check_state "(c) after --recover"
  stop_hard
  start "$TMP/c" || return
  check_state "(c) the next plain start"
  stop_hard
}

case_fsync
case_full_disk
case_recover
if [ "$FAILS" -ne 0 ]; then echo "$FAILS failure(s)" >&2; exit 1; fi
if [ -n "$SKIPPED" ]; then echo "the other cases passed; skipped:$SKIPPED"; exit 77; fi
finish
