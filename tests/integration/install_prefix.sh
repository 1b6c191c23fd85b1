# Installs this build with `cmake --install` into a temporary prefix, copies the prefix to
# another directory (a relocated install) and removes the original, then uses only what is
# in the copy: lucentd --help names the copy's share/lucent/cornell.lcb as the default bake,
# --check-config passes on it, the installed lucentd serves it and the installed lucentctl
# drives it (light set, state, snapshot), and a small C program is built against the
# installed liblucent-client through pkg-config and through find_package(lucent-client)
# and talks to that lucentd.
source "$(dirname "$0")/lib.sh"
BUILD="${LUCENT_BINARY_DIR:?run through ctest}"
cache_get() { sed -n "s/^$1:[A-Z]*=//p" "$BUILD/CMakeCache.txt"; }
CC_BUILD="$(cache_get CMAKE_C_COMPILER)"
CC_BUILD="${CC_BUILD:-cc}"

P="$TMP/prefix"
if ! cmake --install "$BUILD" --prefix "$P" >"$TMP/install.log" 2>&1; then
  fail "cmake --install: $(tail -n 5 "$TMP/install.log")"
  finish
fi
Q="$(mkdir -p "$TMP/moved" && cd "$TMP/moved" && pwd -P)/lucent"
cp -a "$P" "$Q" && rm -rf "$P" || { fail "cannot relocate the prefix"; finish; }

pc="$(find "$Q" -name lucent-client.pc | head -n 1)"
cfg="$(find "$Q" -name lucent-clientConfig.cmake | head -n 1)"
for f in bin/lucentd bin/lucentctl bin/lucent-bake bin/lucent-ref bin/lucent-bench libexec/lucent/lucent-bake-run \
         share/lucent/cornell.lcb share/lucent/cornell.glb include/lucent_client.h \
         share/doc/lucent/PROTOCOL.md share/doc/lucent/schema/hello.json; do
  [ -e "$Q/$f" ] || fail "not installed: $f"
done
[ -n "$pc" ] || fail "lucent-client.pc not installed"
[ -n "$cfg" ] || fail "lucent-clientConfig.cmake not installed"
[ -n "$(find "$Q" -name liblucent-client.a)" ] || fail "liblucent-client.a not installed"

# The default bake is the prefix's own, and is valid.
"$Q/bin/lucentd" --help >"$TMP/help" 2>&1 || fail "lucentd --help exited non-zero"
grep -qF -- "(default $Q/share/lucent/cornell.lcb)" "$TMP/help" ||
  fail "lucentd --help does not show the relocated default bake: $(grep -- '--bake' "$TMP/help")"
"$Q/bin/lucentd" --check-config --state-dir "$TMP/check" >"$TMP/out" 2>&1 ||
  fail "installed lucentd --check-config: $(head -c 400 "$TMP/out")"
"$Q/bin/lucent-bake" verify "$Q/share/lucent/cornell.lcb" >"$TMP/out" 2>&1 ||
  fail "installed lucent-bake verify: $(head -c 400 "$TMP/out")"
# The installed front finds its installed worker (libexec/lucent, relative to bin/).
"$Q/bin/lucent-bake" bake "$CORNELL" -o "$TMP/installed.lcb" --no-write-glb --quality draft --quiet \
  --surfels 1024 --links 16 >"$TMP/out" 2>&1 || fail "installed lucent-bake bake: $(head -c 400 "$TMP/out")"
"$Q/bin/lucent-bake" verify "$TMP/installed.lcb" >"$TMP/out" 2>&1 || fail "the installed bake's output does not verify"

# The installed lucentd on its default (installed) bake, driven by the installed lucentctl.
# (lib.sh's start_lucentd with the installed tree for LUCENT_BINARY_DIR: state in $TMP/d)
if ! LUCENT_BINARY_DIR="$Q" LUCENTD_START_TIMEOUT=20 start_lucentd "$TMP/d"; then
  kill "$LUCENTD_PID" 2>/dev/null
  fail "installed lucentd did not start: $(head -c 400 "$TMP/d.err")"
  finish
fi
DPID=$LUCENTD_PID port=$LUCENTD_PORT
trap 'kill "$DPID" 2>/dev/null; wait "$DPID" 2>/dev/null; rm -rf "$TMP"' EXIT
export LUCENT_URL="ws://127.0.0.1:$port/"
CTL="$Q/bin/lucentctl"
expect_exit 0 "" "$CTL" light set key --type point --position 0.28,0.4,0.28 --intensity 2
expect_exit 0 "" "$CTL" state --json
cp "$TMP/out" "$TMP/state.json"
json_check "$TMP/state.json" 'any(l["id"] == "key" for l in j["lights"])'
expect_exit 0 "" "$CTL" snapshot --out "$TMP/snap"
[ -n "$(find "$TMP/snap" -name 'lightmap*' -size +0 2>/dev/null)" ] || fail "snapshot wrote no lightmap: $(ls "$TMP/snap" 2>&1)"

# A program built against the installed client only (no source or build tree on its paths).
cat >"$TMP/consumer.c" <<'EOF'
#include <lucent_client.h>
#include <stdio.h>
#include <stdlib.h>

int main(int argc, char **argv) {
    char err[256];
    if (argc < 2) return 2;
    lc_client *c = lc_client_connect(argv[1], NULL, "install-test", 10000, err, sizeof err);
    if (!c) {
        fprintf(stderr, "connect: %s\n", err);
        return 3;
    }
    char *reply = NULL;
    int rc = lc_client_request(c, "{\"type\":\"ping\",\"t\":1}", &reply, 10000, err, sizeof err);
    if (rc == 0 && lc_client_subscribe(c, LC_CLIENT_LIGHTMAP, 0, 0, err, sizeof err) == 0) {
        lc_client_frame f;
        rc = lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, 0, 0, 20000, &f, err, sizeof err);
        if (rc == 0) printf("lightmap %ux%u\n", (unsigned)f.width, (unsigned)f.height);
    } else {
        rc = -1;
    }
    if (rc) fprintf(stderr, "request: %s\n", err);
    printf("%s\n", reply ? reply : "(no reply)");
    free(reply);
    lc_client_close(c);
    return rc ? 1 : 0;
}
EOF

# 1. pkg-config
pcdir="$(dirname "$pc")"
if flags="$(PKG_CONFIG_PATH="$pcdir" pkg-config --cflags --libs lucent-client 2>"$TMP/pc.err")"; then
  case "$flags" in *"$BUILD"*|*"$SRC"*) fail "pkg-config flags point into the build or source tree: $flags" ;; esac
  # shellcheck disable=SC2086
  if "$CC_BUILD" -std=c11 -Wall -Wextra -Werror -o "$TMP/consumer_pc" "$TMP/consumer.c" $flags >"$TMP/cc.log" 2>&1; then
    "$TMP/consumer_pc" "$LUCENT_URL" >"$TMP/out" 2>"$TMP/err" || fail "consumer (pkg-config) failed: $(head -c 400 "$TMP/err")"
    grep -q '"pong"' "$TMP/out" || fail "consumer (pkg-config) got no pong: $(head -c 300 "$TMP/out")"
  else
    fail "compiling against pkg-config lucent-client ($flags): $(head -c 800 "$TMP/cc.log")"
  fi
else
  fail "pkg-config lucent-client: $(cat "$TMP/pc.err")"
fi

# 2. find_package(lucent-client) -> lucent::client
mkdir -p "$TMP/cm"
cp "$TMP/consumer.c" "$TMP/cm/consumer.c"
cat >"$TMP/cm/CMakeLists.txt" <<'EOF'
cmake_minimum_required(VERSION 3.16)
project(lucent_consumer C)
find_package(lucent-client 0.1 REQUIRED)
add_executable(consumer consumer.c)
target_compile_options(consumer PRIVATE -Wall -Wextra -Werror)
target_link_libraries(consumer PRIVATE lucent::client)
EOF
if cmake -S "$TMP/cm" -B "$TMP/cm/build" -DCMAKE_C_COMPILER="$CC_BUILD" -DCMAKE_PREFIX_PATH="$Q" \
     >"$TMP/cm.log" 2>&1 && cmake --build "$TMP/cm/build" >>"$TMP/cm.log" 2>&1; then
  grep -rq -- "$BUILD\|$SRC/" "$TMP/cm/build/CMakeFiles/consumer.dir/flags.make" "$TMP/cm/build/CMakeFiles/consumer.dir/link.txt" &&
    fail "find_package build refers to the build or source tree"
  "$TMP/cm/build/consumer" "$LUCENT_URL" >"$TMP/out" 2>"$TMP/err" || fail "consumer (find_package) failed: $(head -c 400 "$TMP/err")"
  grep -q '"pong"' "$TMP/out" || fail "consumer (find_package) got no pong: $(head -c 300 "$TMP/out")"
else
  fail "find_package(lucent-client): $(tail -c 1500 "$TMP/cm.log")"
fi
finish
