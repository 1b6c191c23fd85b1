# lucent-bake's command line: usage errors, bad input, help — each a clear message and the
# documented exit code (0 ok, 1 bad input, 2 usage, 3 cannot write output); never a crash.
. "$(dirname "$0")/lib.sh"

expect_exit 0 "" "$BAKE" --help
grep -q -- "--surfels" "$TMP/out" || fail "--help does not list --surfels"
expect_exit 0 "" "$BAKE" --version
expect_exit 2 "" "$BAKE"
expect_exit 2 "unknown command" "$BAKE" frobnicate
expect_exit 2 "exactly one SCENE" "$BAKE" bake
expect_exit 2 "unknown option --frob" "$BAKE" bake "$CORNELL" --frob 3
expect_exit 2 "--surfels.*out of range" "$BAKE" bake "$CORNELL" --surfels 2
expect_exit 2 "--scale.*finite" "$BAKE" bake "$CORNELL" --scale nan
expect_exit 2 "--quality.*draft\|moderate\|high\|ultra" "$BAKE" bake "$CORNELL" --quality extreme
expect_exit 2 "--links.*needs a value" "$BAKE" bake "$CORNELL" --links
expect_exit 2 "--links 1000 exceeds" "$BAKE" bake "$CORNELL" --surfels 64 --links 1000
expect_exit 2 "--asset: expected NAME=PATH" "$BAKE" bake "$CORNELL" --asset chair
expect_exit 2 "--atlas-size.*out of range" "$BAKE" bake "$CORNELL" --atlas-size 100000

# Bad input files: each a message naming the file, exit 1.
expect_exit 1 "nonexistent" "$BAKE" bake "$TMP/nonexistent.obj" -o "$TMP/x.lcb" --quiet
echo "hello" > "$TMP/notes.txt"
expect_exit 1 "notes.txt" "$BAKE" bake "$TMP/notes.txt" -o "$TMP/x.lcb" --quiet
: > "$TMP/empty.obj"
expect_exit 1 "empty.obj" "$BAKE" bake "$TMP/empty.obj" -o "$TMP/x.lcb" --quiet
printf 'v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n' > "$TMP/degenerate.obj"
expect_exit 1 "triangle" "$BAKE" bake "$TMP/degenerate.obj" -o "$TMP/x.lcb" --quiet
printf 'v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n' > "$TMP/nan.obj"
expect_exit 1 "triangle" "$BAKE" bake "$TMP/nan.obj" -o "$TMP/x.lcb" --quiet
expect_exit 1 "asset chair" "$BAKE" bake "$CORNELL" -o "$TMP/x.lcb" --quality draft --quiet --asset chair="$TMP/none.glb"
[ -e "$TMP/x.lcb" ] && fail "a failed bake left an output file"

# Output not writable: exit 3, nothing half-written.
expect_exit 3 "" "$BAKE" bake "$CORNELL" -o "$TMP/no/such/dir/x.lcb" --quality draft --quiet

# info/verify on garbage.
head -c 1000 /dev/urandom > "$TMP/garbage.lcb"
expect_exit 1 "garbage.lcb" "$BAKE" verify "$TMP/garbage.lcb"
expect_exit 1 "" "$BAKE" info "$TMP/missing.lcb"
expect_exit 2 "" "$BAKE" info

# The front links only the bake file reader: info, verify and --help load none of the bake's
# dependencies (they live in the worker, libexec/lucent/lucent-bake-run).
needed="$(readelf -d "$BAKE" | grep NEEDED)"
echo "$needed" | grep -qiE "embree|assimp|OpenImageIO" && fail "lucent-bake links the bake's dependencies: $needed"
readelf -d "$(dirname "$BAKE")/../libexec/lucent/lucent-bake-run" | grep -q "embree" ||
  fail "the bake worker does not link Embree (is it built beside bin/?)"
# Without its worker the front says which file it looked for.
mkdir -p "$TMP/lonely/bin" && cp "$BAKE" "$TMP/lonely/bin/"
expect_exit 1 "cannot run the bake worker .*lucent-bake-run" "$TMP/lonely/bin/lucent-bake" bake "$CORNELL" --quiet
finish
