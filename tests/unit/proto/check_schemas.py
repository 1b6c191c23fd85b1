#!/usr/bin/python3
"""Checks protocol/schema/*.json: each is a valid draft 2020-12 schema with the expected
$id, there is one per lucent/1 message type, and the sample messages printed by
dump_samples (built by liblucent-proto, or checked by its parser) validate -- or, for the
samples labelled invalid, do not -- against the schema named by their "type".
Usage: check_schemas.py DUMP_SAMPLES SCHEMA_DIR"""
import json
import os
import subprocess
import sys
import warnings

try:
    import jsonschema
    from jsonschema import Draft202012Validator
except ImportError:  # pragma: no cover
    print("python3-jsonschema is not installed: skipping")
    sys.exit(77)

BASE = "https://lucent.example/schema/"
CLIENT = ["hello", "subscribe", "unsubscribe", "light.set", "light.remove", "object.set", "object.remove",
          "material.set", "environment.set", "settings.set", "batch", "state.get", "snapshot", "ping",
          "mr.begin", "mr.end"]
SERVER = ["welcome", "ok", "error", "changed", "state", "pong", "mr.ack"]


def check_asyncapi(path, schema_dir, failures):
    """asyncapi.yaml: every client message under publish, every server message under subscribe,
    each payload a $ref to an existing schema file; a binary frame as octet-stream in each
    direction (the data frame to the client, the MR upload frame from it, §8.4)."""
    try:
        import yaml
    except ImportError:
        print("python3-yaml missing: asyncapi.yaml not checked")
        return
    with open(path, encoding="utf-8") as f:
        doc = yaml.safe_load(f)
    if not str(doc.get("asyncapi", "")).startswith("2.6"):
        failures.append("asyncapi.yaml: not AsyncAPI 2.6")
    msgs = doc["components"]["messages"]
    channel = next(iter(doc["channels"].values()))
    for op, types in (("publish", CLIENT), ("subscribe", SERVER)):
        refs = [m["$ref"].rsplit("/", 1)[1] for m in channel[op]["message"]["oneOf"]]
        names = {msgs[r]["name"]: msgs[r] for r in refs}
        for t in types:
            m = names.get(t)
            if not m:
                failures.append(f"asyncapi.yaml: {t} missing under {op}")
                continue
            target = m["payload"]["$ref"]
            if not os.path.exists(os.path.join(schema_dir, os.path.basename(target))):
                failures.append(f"asyncapi.yaml: {t} payload {target} does not exist")
    for op in ("publish", "subscribe"):
        refs = [m["$ref"].rsplit("/", 1)[1] for m in channel[op]["message"]["oneOf"]]
        if not any(msgs[r].get("contentType") == "application/octet-stream" for r in refs):
            failures.append(f"asyncapi.yaml: no binary frame message under {op}")


def main():
    dump, schema_dir = sys.argv[1], sys.argv[2]
    failures = []
    schemas = {}
    for name in sorted(os.listdir(schema_dir)):
        if not name.endswith(".json"):
            continue
        with open(os.path.join(schema_dir, name), encoding="utf-8") as f:
            s = json.load(f)
        try:
            Draft202012Validator.check_schema(s)
        except jsonschema.exceptions.SchemaError as e:
            failures.append(f"{name}: not a valid 2020-12 schema: {e.message}")
        if s.get("$schema") != "https://json-schema.org/draft/2020-12/schema":
            failures.append(f"{name}: $schema is not draft 2020-12")
        if s.get("$id") != BASE + name:
            failures.append(f"{name}: $id {s.get('$id')} != {BASE + name}")
        schemas[name[:-5]] = s
    for t in CLIENT + SERVER + ["defs"]:
        if t not in schemas:
            failures.append(f"missing schema {t}.json")

    store = {s["$id"]: s for s in schemas.values() if "$id" in s}

    def validator(t):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            resolver = jsonschema.RefResolver(base_uri=schemas[t]["$id"], referrer=schemas[t], store=store)
            return Draft202012Validator(schemas[t], resolver=resolver)

    out = subprocess.run([dump], stdout=subprocess.PIPE, stderr=subprocess.PIPE, check=False)
    if out.returncode != 0:
        failures.append(f"dump_samples failed ({out.returncode}): {out.stderr.decode(errors='replace')}")
    seen, n_valid, n_invalid = set(), 0, 0
    for line in out.stdout.decode("utf-8").splitlines():
        label, _, text = line.partition("\t")
        msg = json.loads(text)
        t = msg.get("type")
        if t not in schemas:
            failures.append(f"no schema for sample type {t!r}: {text}")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            errors = list(validator(t).iter_errors(msg))
        if label == "valid":
            n_valid += 1
            seen.add(t)
            for e in errors:
                failures.append(f"valid {t} sample fails its schema at /{'/'.join(map(str, e.absolute_path))}: "
                                f"{e.message}\n    {text}")
        elif label == "invalid":
            n_invalid += 1
            if not errors:
                failures.append(f"invalid {t} sample passes its schema:\n    {text}")
        else:
            failures.append(f"bad sample line: {line}")
    for t in CLIENT + SERVER:
        if t not in seen:
            failures.append(f"no valid sample of {t}")
    check_asyncapi(os.path.join(schema_dir, "..", "asyncapi.yaml"), schema_dir, failures)
    for f in failures:
        print("FAIL", f)
    print(f"{len(schemas)} schemas, {n_valid} valid and {n_invalid} invalid samples, {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
