# The configs deploy/ ships pass `lucentd --check-config`:
#   deploy/lucentd.example.json (systemd), deploy/lucentd.container.json (the image's), and
#   the Kubernetes ConfigMap merged with the Secret by deployment.yaml's own init-container
#   script (run here with its paths moved into a temp dir).
# The example and the Secret hold CHANGE-ME placeholder tokens, which must be replaced before
# use (lucentd refuses placeholders), so those are checked with real-looking tokens given as
# flags, which override the file. The bake is this build's Cornell box (the configs name the
# installed path, /usr/local/share/lucent/cornell.lcb, which the image provides).
# Also: the delta-frame tuning keys (tile, delta-threshold, keyframe-interval), where set,
# hold lucentd's defaults (a non-default tile/threshold once shipped turned deltas off).
source "$(dirname "$0")/lib.sh"
LUCENTD="${LUCENT_BINARY_DIR:?run through ctest}/bin/lucentd"
[ -x "$LUCENTD" ] || { echo "lucentd not built: skip"; exit 77; }
D="$SRC/deploy"
BAKEFILE="$LUCENT_BINARY_DIR/cornell.lcb"
TOKENS=(--controller-tokens "ctl-0123456789abcdef0123456789abcdef" --viewer-tokens "view-0123456789abcdef0123456789abcdef")

check() { # check NAME CONFIG [extra flags]
  local name="$1" cfg="$2"; shift 2
  local rc=0
  "$LUCENTD" --config "$cfg" --bake "$BAKEFILE" --state-dir "$TMP/state-$name" "$@" --check-config \
    >"$TMP/out" 2>&1 || rc=$?
  [ "$rc" = 0 ] || fail "$name: lucentd --check-config exited $rc: $(head -c 600 "$TMP/out")"
}


# systemd example
check example "$D/lucentd.example.json" "${TOKENS[@]}"
defaults_check example "$D/lucentd.example.json"
# container image config (no tokens)
check container "$D/lucentd.container.json"
defaults_check container "$D/lucentd.container.json"

# Kubernetes: ConfigMap + Secret, merged by the init container's script.
"$PY" - "$D/k8s" "$TMP/k8s" <<'EOF' || fail "cannot extract the k8s config (python3-yaml?)"
import os, sys, yaml
src, out = sys.argv[1], sys.argv[2]
os.makedirs(out, exist_ok=True)
cm = yaml.safe_load(open(os.path.join(src, "configmap.yaml")))
secret = yaml.safe_load(open(os.path.join(src, "secret.yaml")))
dep = yaml.safe_load(open(os.path.join(src, "deployment.yaml")))
open(os.path.join(out, "lucentd.json"), "w").write(cm["data"]["lucentd.json"])
open(os.path.join(out, "tokens.json"), "w").write(secret["stringData"]["tokens.json"])
init = [c for c in dep["spec"]["template"]["spec"]["initContainers"] if c["name"] == "merge-config"][0]
assert init["command"][:2] == ["/bin/sh", "-ec"], init["command"]
open(os.path.join(out, "merge.sh"), "w").write(init["args"][0])
EOF
if [ -f "$TMP/k8s/merge.sh" ]; then
  defaults_check configmap "$TMP/k8s/lucentd.json"
  # the image's lucentd, made to check the merged file against this build's bake, tokens replaced
  cat >"$TMP/k8s/lucentd" <<EOF
#!/bin/sh
exec "$LUCENTD" "\$@" --bake "$BAKEFILE" ${TOKENS[*]}
EOF
  chmod +x "$TMP/k8s/lucentd"
  mkdir -p "$TMP/k8s/run" "$TMP/k8s/state"
  sed -e "s|/etc/lucent/base/|$TMP/k8s/|g; s|/etc/lucent/secret/|$TMP/k8s/|g; s|/run/lucent/|$TMP/k8s/run/|g" \
      -e "s|/usr/local/bin/lucentd|$TMP/k8s/lucentd|g; s|/var/lib/lucent|$TMP/k8s/state|g" \
      "$TMP/k8s/merge.sh" >"$TMP/k8s/merge.local.sh"
  if /bin/sh -ec "$(cat "$TMP/k8s/merge.local.sh")" >"$TMP/out" 2>&1; then
    json_check "$TMP/k8s/run/lucentd.json" '"controller-tokens" in j and "viewer-tokens" in j and "port" in j'
  else
    fail "k8s init container (merge + --check-config): $(head -c 600 "$TMP/out")"
  fi
  # the bake the ConfigMap names is where the image puts it
  bake="$("$PY" -c 'import json, sys; print(json.load(open(sys.argv[1]))["bake"])' "$TMP/k8s/lucentd.json")"
  grep -q "^COPY --from=build /src/build/share/lucent/ $(dirname "$bake")/\$" "$D/Containerfile" ||
    fail "configmap bake $bake: the Containerfile does not copy the bake to $(dirname "$bake")/"
fi
grep -q '"bake": "/usr/local/share/lucent/cornell.lcb"' "$D/lucentd.container.json" ||
  fail "lucentd.container.json: bake is not /usr/local/share/lucent/cornell.lcb"
finish
