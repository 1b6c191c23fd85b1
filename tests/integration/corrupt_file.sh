# A real bake truncated at every section boundary or with random byte flips is rejected by
# `lucent-bake verify` with a message naming the section; never a crash (exit 1, not a signal).
. "$(dirname "$0")/lib.sh"
"$BAKE" bake "$CORNELL" -o "$TMP/good.lcb" --quality draft --quiet --surfels 2048 --links 16 || fail "bake"
$PY - "$BAKE" "$TMP/good.lcb" "$TMP" <<'PY' || fail "corruption checks"
import struct, subprocess, sys, random
bake, path, tmp = sys.argv[1:4]
data = open(path, "rb").read()
magic, vmaj, vmin, nsec, fsize, toff = struct.unpack_from("<8sHHIQQ", data, 0)
secs = []
for i in range(nsec):
    sid, rsz, off, size, count, crc = struct.unpack_from("<4sIQQQI", data, 64 + 48 * i)
    secs.append((sid.decode(), off, size))
def verify(blob, name):
    p = f"{tmp}/{name}.lcb"
    open(p, "wb").write(blob)
    r = subprocess.run([bake, "verify", p], capture_output=True, text=True)
    if r.returncode < 0 or r.returncode > 1:
        print(f"{name}: exit {r.returncode}: {r.stderr}"); sys.exit(1)
    return r
bad = 0
cuts = {0, 1, 63, 64, 65, len(data) - 1}
for sid, off, size in secs:
    cuts.update({off, off + 1, off + size - 1, off + size})
for cut in sorted(c for c in cuts if 0 <= c < len(data)):
    r = verify(data[:cut], f"cut{cut}")
    if r.returncode != 1:
        print(f"truncation at {cut} accepted"); bad += 1
    elif cut >= 64 + 48 * nsec and not any(s in r.stderr for s, o, z in secs) and "truncated" not in r.stderr:
        print(f"truncation at {cut}: message names no section: {r.stderr.strip()}"); bad += 1
rng = random.Random(1)
covered = [(0, 64 + 48 * nsec)] + [(o, o + z) for s, o, z in secs]
for k in range(60):  # the unit test flips 2000 bytes in-process; this checks the CLI path
    lo, hi = covered[rng.randrange(len(covered))]
    if hi <= lo: continue
    pos = rng.randrange(lo, hi)
    blob = bytearray(data); blob[pos] ^= 1 << rng.randrange(8)
    r = verify(bytes(blob), "flip")
    if r.returncode != 1:
        print(f"flip at {pos} accepted"); bad += 1
sys.exit(1 if bad else 0)
PY
finish
