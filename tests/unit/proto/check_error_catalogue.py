#!/usr/bin/python3
"""The error catalogue (protocol/lucent_errors.h, dumped by `dump_samples --errors`) is the
one source of lucent/1's error codes: the JSON Schema's errorCode enum (schema/defs.json)
and the table in PROTOCOL.md §5.2 must list exactly its codes, the table with the
catalogue's meaning and connection columns, in its order. Also fails when a producer in
the C sources names a code as a string literal outside the catalogue.
usage: check_error_catalogue.py DUMP_SAMPLES SOURCE_DIR"""
import json
import pathlib
import re
import subprocess
import sys


def main():
    dump, src = sys.argv[1], pathlib.Path(sys.argv[2])
    rows = [json.loads(line) for line in subprocess.run([dump, "--errors"], capture_output=True, text=True,
                                                       check=True).stdout.splitlines()]
    codes = [r["code"] for r in rows]
    fails = []
    if len(set(codes)) != len(codes):
        fails.append("the catalogue lists a code twice")
    schema = json.load(open(src / "protocol/schema/defs.json"))["$defs"]["errorCode"]["enum"]
    if schema != codes:
        fails.append(f"schema/defs.json errorCode {schema} != catalogue {codes}")
    spec = (src / "protocol/PROTOCOL.md").read_text()
    m = re.search(r"\| code \| meaning \| connection \|\n\|---\|---\|---\|\n((?:\|.*\|\n)+)", spec)
    if not m:
        fails.append("PROTOCOL.md: no error table (| code | meaning | connection |)")
    else:
        table = []
        for line in m.group(1).splitlines():
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            table.append({"code": cells[0].strip("`"), "meaning": cells[1], "connection": cells[2]})
        if [t["code"] for t in table] != codes:
            fails.append(f"PROTOCOL.md table codes {[t['code'] for t in table]} != catalogue {codes}")
        for t, r in zip(table, rows):
            if t != r:
                fails.append(f"PROTOCOL.md row {t} != catalogue {r}")
    # Producers take codes from the catalogue: no "code" string literal passed to the error
    # helpers (proto_error/proto_fail/state_err/session_error) in the sources.
    pat = re.compile(r"\b(proto_error|proto_fail|state_err|session_error)\([^;]*?\"(" + "|".join(codes) + r")\"")
    for f in list((src / "daemon").rglob("*.c")) + list((src / "protocol").rglob("*.c")):
        text = f.read_text(errors="replace")
        for hit in pat.finditer(text):
            fails.append(f"{f.relative_to(src)}: {hit.group(1)} names \"{hit.group(2)}\" as a literal; use LC_ERR_*")
    if fails:
        print("\n".join("FAIL: " + f for f in fails))
        return 1
    print(f"error catalogue: {len(codes)} codes agree with the schema and PROTOCOL.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
