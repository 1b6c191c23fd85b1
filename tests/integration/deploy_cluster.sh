# The cluster deployment files deploy/ ships (lucentd --cluster; deploy/OPERATING.md), checked
# without Kubernetes:
#   deploy/k8s-cluster/: the manifests agree with each other (names, labels, Secret keys, the
#     cluster URL's host = the Redis StatefulSet's pod behind its headless Service, ports,
#     probes on /healthz, no volume for lucentd); `kubectl kustomize` builds them where kubectl
#     is installed. The ConfigMap merged with the Secret by the Deployment's own init-container
#     script (paths moved into a temp dir) passes `lucentd --check-config`, and the script
#     refuses the Secret's CHANGE-ME Redis password.
#   deploy/lucentd-cluster.example.json: refused as shipped (placeholder tokens), valid with
#     the tokens given as flags (flags override the file).
#   deploy/redis-lucent.conf and the StatefulSet's redis-server arguments: a redis-server
#     started with each (port, dir, bind and password overridden) reports appendonly yes,
#     appendfsync always, no-appendfsync-on-rewrite no, save "", maxmemory-policy noeviction;
#     the StatefulSet's readiness command passes with its password and fails without it.
#   A replica started with the merged k8s config (only the URL's host:port moved to the test's
#     Redis, the password as merged from the Secret) and one with the example config join
#     their Redis: /healthz 200, lucent_cluster_writable 1, KEY:bake set.
# The bake is this build's Cornell box; the delta-frame tuning keys hold lucentd's defaults
# (as tests/integration/deploy_configs.sh checks for deploy/k8s).
source "$(dirname "$0")/lib.sh"
LUCENTD="${LUCENT_BINARY_DIR:?run through ctest}/bin/lucentd"
[ -x "$LUCENTD" ] || { echo "lucentd not built: skip"; exit 77; }
for exe in redis-server redis-cli; do
  command -v "$exe" >/dev/null || { echo "FAIL: needs $exe (apt install redis-server; scripts/setup-deps.sh does)" >&2; exit 1; }
done
D="$SRC/deploy"
K="$D/k8s-cluster"
BAKEFILE="$LUCENT_BINARY_DIR/cornell.lcb"
TOKENS=(--controller-tokens "ctl-0123456789abcdef0123456789abcdef" --viewer-tokens "view-0123456789abcdef0123456789abcdef")
REDIS_PW="pw-0123456789abcdef0123456789abcdef"
PIDS=()
trap 'for p in ${PIDS[@]+"${PIDS[@]}"}; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done; rm -rf "$TMP"' EXIT

cluster_defaults_check() { # cluster_defaults_check NAME CONFIG
  defaults_check "$@"
  # a cluster config pins the backend (every replica must relight alike) and has a cluster URL
  json_check "$2" '"cluster" in j and j.get("backend") in ("cpu", "egl")'
}
free_port() { "$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
rcli() { REDISCLI_AUTH="$REDIS_PW" redis-cli --no-auth-warning -p "$1" "${@:2}"; }
redis_pong() { [ "$(rcli "$1" PING)" = PONG ]; }
# start_redis NAME PORT ARGS...: redis-server ARGS on PORT (started in $TMP/NAME); waits for PONG.
start_redis() {
  local name="$1" port="$2"; shift 2
  mkdir -p "$TMP/$name"
  (cd "$TMP/$name" && exec redis-server "$@") >"$TMP/$name.log" 2>&1 &
  PIDS+=($!)
  wait_for 10 "redis-server ($name) answering PING" redis_pong "$port" ||
    { echo "$name: $(tail -c 600 "$TMP/$name.log")" >&2; return 1; }
}
# redis_settings_check NAME PORT: the durability settings lucentd --cluster relies on.
redis_settings_check() {
  local name="$1" port="$2" kv want got
  for kv in "appendonly=yes" "appendfsync=always" "no-appendfsync-on-rewrite=no" "save=" "maxmemory-policy=noeviction"; do
    want="${kv#*=}"
    got="$(rcli "$port" --raw CONFIG GET "${kv%%=*}" | sed -n 2p)"
    [ "$got" = "$want" ] || fail "$name: CONFIG GET ${kv%%=*} says '$got', want '$want'"
  done
}
healthz() { # healthz PORT: prints "STATUS BODY"
  "$PY" -c 'import sys, urllib.request, urllib.error
try:
    r = urllib.request.urlopen("http://127.0.0.1:%s/healthz" % sys.argv[1], timeout=2); print(r.status, r.read().decode().strip())
except urllib.error.HTTPError as e:
    print(e.code, e.read().decode().strip())
except Exception as e:
    print(0, e)' "$1"
}
healthz_200() { case "$(healthz "$1")" in "200 "*) return 0 ;; esac; return 1; }
# replica_check NAME REDIS_PORT ARGS...: a replica started with ARGS joins the Redis on REDIS_PORT.
replica_check() {
  local name="$1" rport="$2"; shift 2
  mkdir -p "$TMP/$name"
  start_lucentd "$TMP/$name/state" --bake "$BAKEFILE" --listen 127.0.0.1 "$@" || { fail "$name: lucentd did not start"; return; }
  PIDS+=("$LUCENTD_PID")
  local port="$LUCENTD_PORT"
  if wait_for 30 "$name: /healthz 200" healthz_200 "$port"; then
    case "$(healthz "$port")" in "200 ok revision "*) ;; *) fail "$name: /healthz: $(healthz "$port")" ;; esac
    metric_ge "$port" lucent_cluster_writable 1 || fail "$name: lucent_cluster_writable is '$(metric "$port" lucent_cluster_writable)'"
    [ -n "$(rcli "$rport" GET lucent:bake)" ] || fail "$name: lucent:bake not set in Redis"
  else
    echo "$name: /healthz $(healthz "$port"); $(head -c 600 "$TMP/$name/state.err")" >&2
  fi
  [ -d "$TMP/$name/state" ] && fail "$name: a cluster replica created its --state-dir"
  kill "$LUCENTD_PID" 2>/dev/null
  wait "$LUCENTD_PID" 2>/dev/null
}

# --- Kubernetes manifests: extract, and check that they agree with each other -------------------
"$PY" - "$K" "$TMP/k8s" <<'EOF' || fail "k8s-cluster manifests (above)"
import glob, os, sys, urllib.parse, yaml, json
src, out = sys.argv[1], sys.argv[2]
os.makedirs(out, exist_ok=True)
bad = []
def check(cond, msg):
    if not cond: bad.append(msg)
docs = {}
for path in sorted(glob.glob(os.path.join(src, "*.yaml"))):
    for d in yaml.safe_load_all(open(path)):
        if d: docs.setdefault(d["kind"], []).append(d)
kust = docs.pop("Kustomization")[0]
files = {os.path.basename(p) for p in glob.glob(os.path.join(src, "*.yaml"))} - {"kustomization.yaml"}
check(set(kust["resources"]) == files, "kustomization.yaml resources %s != the files %s" % (sorted(kust["resources"]), sorted(files)))
one = lambda kind: docs[kind][0]
cm, secret, dep, sts, pdb = one("ConfigMap"), one("Secret"), one("Deployment"), one("StatefulSet"), one("PodDisruptionBudget")
svcs = {s["metadata"]["name"]: s for s in docs["Service"]}
labels_match = lambda sel, labels: all(labels.get(k) == v for k, v in sel.items())
# Secret, ConfigMap
sdata = secret["stringData"]
check({"tokens.json", "redis-password"} <= set(sdata), "Secret lacks tokens.json or redis-password")
conf = json.loads(cm["data"]["lucentd.json"])
for k in ("state-dir", "fsync", "compact-bytes"):
    check(k not in conf, "ConfigMap sets %s, which cluster mode does not use" % k)
# Deployment
spec, pod = dep["spec"], dep["spec"]["template"]["spec"]
plabels = dep["spec"]["template"]["metadata"]["labels"]
check(spec["replicas"] == 3, "Deployment replicas %s, want 3" % spec["replicas"])
check(spec["strategy"]["type"] == "RollingUpdate", "Deployment strategy is not RollingUpdate")
check(labels_match(spec["selector"]["matchLabels"], plabels), "Deployment selector does not match its pods")
vols = {v["name"]: v for v in pod["volumes"]}
check(not any("persistentVolumeClaim" in v for v in vols.values()), "Deployment mounts a PVC (replicas keep no local state)")
check(any(v.get("configMap", {}).get("name") == cm["metadata"]["name"] for v in vols.values()), "Deployment does not mount the ConfigMap")
check(any(v.get("secret", {}).get("secretName") == secret["metadata"]["name"] for v in vols.values()), "Deployment does not mount the Secret")
main = [c for c in pod["containers"] if c["name"] == "lucentd"][0]
check("--state-dir" not in main.get("args", []), "lucentd gets --state-dir")
for probe in ("startupProbe", "readinessProbe", "livenessProbe"):
    check(main.get(probe, {}).get("httpGet", {}).get("path") == "/healthz", "lucentd %s is not on /healthz" % probe)
wsport = [p for p in main["ports"] if p["name"] == "ws"][0]["containerPort"]
check(wsport == conf["port"], "containerPort %s != the ConfigMap's port %s" % (wsport, conf["port"]))
init = [c for c in pod["initContainers"] if c["name"] == "merge-config"][0]
check(init["command"][:2] == ["/bin/sh", "-ec"], "init command %s" % init["command"])
# Service, PDB
svc = svcs["lucentd"]
check(labels_match(svc["spec"]["selector"], plabels), "Service lucentd does not select the lucentd pods")
check(svc["spec"].get("sessionAffinity") == "None", "Service lucentd: sessionAffinity is not None")
check(svc["spec"]["ports"][0]["port"] == 7700, "Service lucentd: port is not 7700")
check(labels_match(pdb["spec"]["selector"]["matchLabels"], plabels), "PodDisruptionBudget does not select the lucentd pods")
# Redis
sspec, spod = sts["spec"], sts["spec"]["template"]["spec"]
rlabels = sspec["template"]["metadata"]["labels"]
check(sspec["replicas"] == 1, "Redis StatefulSet replicas is not 1")
headless = svcs.get(sspec["serviceName"])
check(headless is not None and headless["spec"].get("clusterIP") == "None", "Redis serviceName is not a headless Service")
check(headless is None or labels_match(headless["spec"]["selector"], rlabels), "the headless Service does not select Redis")
redis = spod["containers"][0]
check(redis["image"].startswith("redis:7"), "Redis image %s, want redis:7" % redis["image"])
args = redis["args"]
env = {e["name"]: e for e in redis.get("env", [])}
pw = env.get("REDIS_PASSWORD", {}).get("valueFrom", {}).get("secretKeyRef", {})
check(pw == {"name": secret["metadata"]["name"], "key": "redis-password"}, "REDIS_PASSWORD does not come from the Secret's redis-password")
check("--requirepass" in args and args[args.index("--requirepass") + 1] == "$(REDIS_PASSWORD)", "Redis args lack --requirepass $(REDIS_PASSWORD)")
datadir = args[args.index("--dir") + 1] if "--dir" in args else "/data"
vct = [t["metadata"]["name"] for t in sspec.get("volumeClaimTemplates", [])]
check(any(m["name"] in vct and m["mountPath"] == datadir for m in redis["volumeMounts"]), "Redis --dir %s is not on a volumeClaimTemplate" % datadir)
rcmd = redis.get("readinessProbe", {}).get("exec", {}).get("command", [])
check("redis-cli ping" in " ".join(rcmd), "Redis readiness is not redis-cli ping")
# the cluster URL names the StatefulSet's first pod behind its headless Service, on its port
u = urllib.parse.urlsplit(conf["cluster"])
check(u.scheme == "redis" and u.password == "PASSWORD", "cluster URL %s: want redis://:PASSWORD@..." % conf["cluster"])
check(u.hostname == "%s-0.%s" % (sts["metadata"]["name"], sspec["serviceName"]), "cluster URL host %s is not the Redis pod" % u.hostname)
check(headless is None or u.port == headless["spec"]["ports"][0]["port"], "cluster URL port %s is not Redis's Service port" % u.port)
# NetworkPolicy: Redis reachable from lucentd
for np in docs.get("NetworkPolicy", []):
    check(labels_match(np["spec"]["podSelector"]["matchLabels"], rlabels), "NetworkPolicy does not select Redis")
    check(any(labels_match(f["podSelector"]["matchLabels"], plabels) for r in np["spec"]["ingress"] for f in r["from"]),
          "NetworkPolicy does not let the lucentd pods in")
for m in bad: print("FAIL: k8s-cluster: " + m, file=sys.stderr)
open(os.path.join(out, "lucentd.json"), "w").write(cm["data"]["lucentd.json"])
open(os.path.join(out, "tokens.json"), "w").write(sdata["tokens.json"])
open(os.path.join(out, "redis-password.shipped"), "w").write(sdata["redis-password"])
open(os.path.join(out, "merge.sh"), "w").write(init["args"][0])
open(os.path.join(out, "redis-args"), "w").write("\n".join(args) + "\n")
open(os.path.join(out, "redis-ready.sh"), "w").write(rcmd[2] if rcmd[:2] == ["sh", "-c"] else "false")
sys.exit(1 if bad else 0)
EOF
if command -v kubectl >/dev/null; then
  kubectl kustomize "$K" >"$TMP/kustomized.yaml" 2>"$TMP/err" || fail "kubectl kustomize: $(head -c 600 "$TMP/err")"
  "$PY" -c 'import sys, yaml; kinds = sorted(d["kind"] for d in yaml.safe_load_all(open(sys.argv[1])) if d); print(" ".join(kinds))' \
    "$TMP/kustomized.yaml" >"$TMP/kinds" || fail "kubectl kustomize output is not YAML"
  for kind in ConfigMap Deployment PodDisruptionBudget Secret Service StatefulSet; do
    grep -qw "$kind" "$TMP/kinds" || fail "kubectl kustomize: no $kind"
  done
else
  echo "kubectl not installed: kustomize build not checked"
fi

# --- the init container's merge (ConfigMap + Secret) and --check-config ------------------------
if [ -f "$TMP/k8s/merge.sh" ]; then
  cluster_defaults_check configmap "$TMP/k8s/lucentd.json"
  # the image's lucentd, made to check the merged file against this build's bake, tokens replaced
  cat >"$TMP/k8s/lucentd" <<EOF
#!/bin/sh
exec "$LUCENTD" "\$@" --bake "$BAKEFILE" ${TOKENS[*]}
EOF
  chmod +x "$TMP/k8s/lucentd"
  mkdir -p "$TMP/k8s/run" "$TMP/k8s/secret"
  cp "$TMP/k8s/tokens.json" "$TMP/k8s/secret/tokens.json"
  sed -e "s|/etc/lucent/base/|$TMP/k8s/|g; s|/etc/lucent/secret/|$TMP/k8s/secret/|g; s|/run/lucent/|$TMP/k8s/run/|g" \
      -e "s|/usr/local/bin/lucentd|$TMP/k8s/lucentd|g" "$TMP/k8s/merge.sh" >"$TMP/k8s/merge.local.sh"
  # as shipped: the CHANGE-ME Redis password is refused
  cp "$TMP/k8s/redis-password.shipped" "$TMP/k8s/secret/redis-password"
  if /bin/sh -ec "$(cat "$TMP/k8s/merge.local.sh")" >"$TMP/out" 2>&1; then
    fail "k8s init container accepted the Secret's placeholder redis-password"
  else
    grep -q "placeholder" "$TMP/out" || fail "k8s init container, shipped Secret: $(head -c 400 "$TMP/out")"
  fi
  # a password with a character that would need percent-encoding is refused
  printf 'a/b@c\n' >"$TMP/k8s/secret/redis-password"
  /bin/sh -ec "$(cat "$TMP/k8s/merge.local.sh")" >"$TMP/out" 2>&1 && fail "k8s init container accepted the redis-password 'a/b@c'"
  # a real-looking password (with the trailing newline of `kubectl create secret --from-file`)
  printf '%s\n' "$REDIS_PW" >"$TMP/k8s/secret/redis-password"
  if /bin/sh -ec "$(cat "$TMP/k8s/merge.local.sh")" >"$TMP/out" 2>&1; then
    json_check "$TMP/k8s/run/lucentd.json" '"controller-tokens" in j and "viewer-tokens" in j and "port" in j'
    json_check "$TMP/k8s/run/lucentd.json" 'j["cluster"] == "redis://:'"$REDIS_PW"'@lucent-redis-0.lucent-redis:6379/lucent"'
  else
    fail "k8s init container (merge + --check-config): $(head -c 600 "$TMP/out")"
  fi
  # the bake the ConfigMap names is where the image puts it
  bake="$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["bake"])' "$TMP/k8s/lucentd.json")"
  grep -q "^COPY --from=build /src/build/share/lucent/ $(dirname "$bake")/\$" "$D/Containerfile" ||
    fail "configmap bake $bake: the Containerfile does not copy the bake to $(dirname "$bake")/"
fi

# --- the systemd replica's example config -----------------------------------------------------
EX="$D/lucentd-cluster.example.json"
rc=0
"$LUCENTD" --config "$EX" --bake "$BAKEFILE" --check-config >"$TMP/out" 2>&1 || rc=$?
[ "$rc" = 2 ] && grep -q placeholder "$TMP/out" || fail "$EX as shipped: --check-config exited $rc, want 2 (placeholder tokens): $(head -c 400 "$TMP/out")"
rc=0
"$LUCENTD" --config "$EX" --bake "$BAKEFILE" "${TOKENS[@]}" --check-config >"$TMP/out" 2>&1 || rc=$?
[ "$rc" = 2 ] && grep -q "Redis password is a placeholder" "$TMP/out" ||
  fail "$EX with real tokens: --check-config exited $rc, want 2 (the Redis password placeholder): $(head -c 400 "$TMP/out")"
rc=0
"$LUCENTD" --config "$EX" --bake "$BAKEFILE" "${TOKENS[@]}" --cluster "redis://:$REDIS_PW@10.0.0.10:6379/lucent" \
  --check-config >"$TMP/out" 2>&1 || rc=$?
[ "$rc" = 0 ] || fail "$EX: lucentd --check-config exited $rc: $(head -c 600 "$TMP/out")"
cluster_defaults_check example "$EX"
grep -q '"cluster": "redis://:CHANGE-ME-' "$EX" || fail "$EX: the cluster URL's password is not a CHANGE-ME placeholder"
grep -q '^requirepass CHANGE-ME-' "$D/redis-lucent.conf" || fail "redis-lucent.conf: requirepass is not a CHANGE-ME placeholder"

# --- Redis: deploy/redis-lucent.conf, and the StatefulSet's arguments -----------------------------
P1="$(free_port)"
if start_redis redis-conf "$P1" "$D/redis-lucent.conf" --port "$P1" --bind 127.0.0.1 --dir "$TMP/redis-conf" \
     --requirepass "$REDIS_PW"; then
  redis_settings_check redis-lucent.conf "$P1"
  replica_check example "$P1" --config "$EX" "${TOKENS[@]}" --cluster "redis://:$REDIS_PW@127.0.0.1:$P1/lucent"
  rcli "$P1" SHUTDOWN >/dev/null 2>&1
else
  fail "redis-server did not start with deploy/redis-lucent.conf"
fi
if [ -f "$TMP/k8s/redis-args" ]; then
  P2="$(free_port)"
  mapfile -t RARGS <"$TMP/k8s/redis-args"
  for i in "${!RARGS[@]}"; do
    [ "${RARGS[$i]}" = '$(REDIS_PASSWORD)' ] && RARGS[$i]="$REDIS_PW"
    [ "$i" -gt 0 ] && [ "${RARGS[$((i - 1))]}" = "--dir" ] && RARGS[$i]="$TMP/redis-sts"
  done
  if start_redis redis-sts "$P2" "${RARGS[@]}" --port "$P2" --bind 127.0.0.1; then
    redis_settings_check "StatefulSet args" "$P2"
    ready="$(sed "s|redis-cli|redis-cli -p $P2|" "$TMP/k8s/redis-ready.sh")"
    REDIS_PASSWORD="$REDIS_PW" sh -c "$ready" || fail "Redis readiness command failed with the password: $ready"
    REDIS_PASSWORD="wrong" sh -c "$ready" 2>/dev/null && fail "Redis readiness command passed with a wrong password: $ready"
    # the replica as merged from the ConfigMap and Secret, only the URL's host:port moved here
    if [ -f "$TMP/k8s/run/lucentd.json" ]; then
      url="$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["cluster"])' "$TMP/k8s/run/lucentd.json")"
      replica_check configmap "$P2" --config "$TMP/k8s/run/lucentd.json" "${TOKENS[@]}" \
        --cluster "${url/@lucent-redis-0.lucent-redis:6379\//@127.0.0.1:$P2/}"
    fi
    rcli "$P2" SHUTDOWN >/dev/null 2>&1
  else
    fail "redis-server did not start with the StatefulSet's arguments: ${RARGS[*]}"
  fi
fi
finish
