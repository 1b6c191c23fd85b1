#!/usr/bin/python3
"""The spec states lucentd's defaults: protocol/PROTOCOL.md (§1.3 and the welcome example)
and protocol/asyncapi.yaml (the port) must say what `lucentd --help` says, which comes from
the option table fed by common/limits.h. Fails on any drift.
usage: check_spec_limits.py LUCENTD SOURCE_DIR"""
import json
import re
import subprocess
import sys


def main():
    lucentd, src = sys.argv[1], sys.argv[2]
    help_text = subprocess.run([lucentd, "--help"], capture_output=True, text=True, check=True).stdout
    defaults = {m.group(1): int(m.group(2)) for m in re.finditer(r"--([a-z-]+) N .*\(default (\d+)\)", help_text)}
    need = ["port", "max-message", "max-depth", "max-batch", "max-lights", "max-objects", "rate"]
    fails = [f"lucentd --help shows no default for --{k}" for k in need if k not in defaults]
    if fails:
        print("\n".join(fails))
        return 1
    spec = open(f"{src}/protocol/PROTOCOL.md").read()
    num = lambda s: int(s.replace(" ", "").replace("\u202f", ""))
    m = re.search(r"1\.3\. Limits.*?message size ([\d ]+) bytes, JSON nesting depth\s+(\d+),.*?"
                  r"([\d ]+) lights, ([\d ]+) objects, (\d+) ops per batch,\s+(\d+) requests per second", spec, re.S)
    if not m:
        fails.append("PROTOCOL.md §1.3: the limits sentence is not in the expected form")
    else:
        stated = dict(zip(["max-message", "max-depth", "max-lights", "max-objects", "max-batch", "rate"],
                          [num(g) for g in m.groups()]))
        for k, v in stated.items():
            if v != defaults[k]:
                fails.append(f"PROTOCOL.md §1.3 says {k} {v}, lucentd's default is {defaults[k]}")
        m2 = re.search(r"\(burst (\d+)\)", spec[m.start():m.end() + 40])
        if not m2 or int(m2.group(1)) != 2 * defaults["rate"]:
            fails.append("PROTOCOL.md §1.3: the burst must be twice the rate")
    w = re.search(r'"limits": (\{[^}]*\})', spec)
    if not w:
        fails.append("PROTOCOL.md: the welcome example has no limits object")
    else:
        lim = json.loads(w.group(1))
        for key, opt in [("max_message", "max-message"), ("max_lights", "max-lights"),
                         ("max_objects", "max-objects"), ("max_batch", "max-batch"), ("rate", "rate")]:
            if lim.get(key) != defaults[opt]:
                fails.append(f"PROTOCOL.md welcome example: {key} {lim.get(key)}, lucentd's default {defaults[opt]}")
    api = open(f"{src}/protocol/asyncapi.yaml").read()
    p = re.search(r"port:\s*\n\s*default: '(\d+)'", api)
    if not p or int(p.group(1)) != defaults["port"]:
        fails.append(f"asyncapi.yaml: port default {p and p.group(1)}, lucentd's is {defaults['port']}")
    if fails:
        print("\n".join("FAIL: " + f for f in fails))
        return 1
    print("spec limits agree with lucentd:", {k: defaults[k] for k in need})
    return 0


if __name__ == "__main__":
    sys.exit(main())
