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
