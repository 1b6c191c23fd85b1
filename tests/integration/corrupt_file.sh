# `lucent-bake verify` on a real bake and a dozen representative broken copies: exit 0 and
# "valid" for the good file; exit 1 (never a signal) with a message naming what is wrong for
# each broken one; exit 2 without a FILE. Every truncation point and thousands of byte flips
# are checked in-process by tests/unit/lcb/test_lcb.c (the synthetic bake at every length,
# the build's cornell.lcb around every section boundary and with 300 flips): this test covers
# the command line's path (open, stat, mmap, the message format and the exit code) only:
# each verify loads all of lucent-bake's libraries, so the cases here are few.
. "$(dirname "$0")/lib.sh"
GOOD="${LUCENT_BINARY_DIR:-}/cornell.lcb"
if [ ! -s "$GOOD" ]; then
  GOOD="$TMP/good.lcb"
  "$BAKE" bake "$CORNELL" -o "$GOOD" --quality draft --quiet --surfels 2048 --links 16 || { fail "bake"; finish; }
fi
# The broken copies: each file name is the case; the table of sections is read from the file.
$PY - "$GOOD" "$TMP" <<'PY' || fail "cannot write the broken copies"
import struct, sys, zlib
data, out = open(sys.argv[1], "rb").read(), sys.argv[2]
nsec = struct.unpack_from("<I", data, 12)[0]
secs = {}
for i in range(nsec):
    sid, rsz, off, size, count, crc = struct.unpack_from("<4sIQQQI", data, 64 + 48 * i)
    secs[sid.decode()] = (i, off, size)
def put(name, blob):
    open("%s/%s.lcb" % (out, name), "wb").write(blob)
def flip(pos, bit=0x10):
    b = bytearray(data)
    b[pos] ^= bit
    return bytes(b)
def surf_offset_plus(k):  # the SURF entry's offset moved by k bytes, every CRC recomputed
    b = bytearray(data)
    e = 64 + 48 * secs["SURF"][0]
    struct.pack_into("<Q", b, e + 8, secs["SURF"][1] + k)
    struct.pack_into("<I", b, 32, zlib.crc32(bytes(b[64:64 + 48 * nsec])))
    struct.pack_into("<I", b, 60, zlib.crc32(bytes(b[:60])))
    return bytes(b)
put("zero_length", b"")
put("trunc_header", data[:40])
put("trunc_table", data[:64 + 48 * 2])
i, o, z = secs["SURF"]
put("trunc_SURF", data[:o + z // 2])
put("trunc_last_byte", data[:-1])
put("bad_magic", flip(0, 0x20))
put("table_crc", flip(64 + 48 * 3 + 20))
put("table_misaligned_SURF", surf_offset_plus(4))
for s in ("META", "LINK"):
    i, o, z = secs[s]
    put("crc_" + s, flip(o + z // 2))
PY

# verify FILE WANT_EXIT PATTERN: the exit code (1 = invalid, never a signal) and the message
verify() { expect_exit "$2" "$3" "$BAKE" verify "$1"; }
"$BAKE" verify "$GOOD" >"$TMP/ok.out" 2>"$TMP/ok.err" || fail "the good bake does not verify: $(head -c 300 "$TMP/ok.err")"
grep -q "valid lucent bake file" "$TMP/ok.out" || fail "verify of the good bake printed: $(head -c 300 "$TMP/ok.out")"
verify "$TMP/zero_length.lcb" 1 "header: truncated: file is 0 bytes"
verify "$TMP/trunc_header.lcb" 1 "header: truncated: file is 40 bytes, smaller than the 64-byte header"
verify "$TMP/trunc_table.lcb" 1 "section table: truncated: file is 160 bytes"
verify "$TMP/trunc_SURF.lcb" 1 "truncated: .*section SURF and later are missing"
verify "$TMP/trunc_last_byte.lcb" 1 "truncated: file is [0-9]+ bytes, header says [0-9]+"
verify "$TMP/bad_magic.lcb" 1 "header: bad magic"
verify "$TMP/table_crc.lcb" 1 "section table: CRC mismatch"
verify "$TMP/table_misaligned_SURF.lcb" 1 "SURF.*not a multiple of 64"
for s in META LINK; do verify "$TMP/crc_$s.lcb" 1 "$s: CRC mismatch"; done
verify "$TMP" 1 "is not a regular file"
verify "$TMP/missing.lcb" 1 "cannot open .*missing.lcb.*No such file"
expect_exit 2 "verify needs a FILE" "$BAKE" verify
finish
