#!/usr/bin/env bash
# lucentd under many viewers: `lucentctl load` (one process, one libwebsockets context) against
# a lucentd started here for each client count (Cornell bake, CPU backend, --max-clients
# 12000, a fresh temporary state dir), 10 light updates/s for 10 s. Per count it writes
# OUT/load-N.json (lucentctl's report plus "daemon": lucentd's VmHWM and the CPU seconds it
# used during the load, utime+stime from /proc/PID/stat) and prints a table.
#
#   bench/load.sh [--build DIR] [--clients 1000,3000,10000] [--out DIR] [--rate 10] [--duration 10]
#
# Both processes run on this machine and share its cores: the latencies are those of a
# lucentd that also competes with its clients. Needs jq.
set -euo pipefail

BUILD=build CLIENTS=1000,3000,10000 OUT="" RATE=10 DURATION=10
while [ $# -gt 0 ]; do
  case "$1" in
    --build) BUILD="$2"; shift 2 ;;
    --clients) CLIENTS="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --rate) RATE="$2"; shift 2 ;;
    --duration) DURATION="$2"; shift 2 ;;
    -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "load.sh: unknown option '$1' (see --help)" >&2; exit 2 ;;
  esac
done
BIN="$BUILD/bin"
LCB="$BUILD/cornell.lcb"
for f in "$BIN/lucentd" "$BIN/lucentctl" "$LCB"; do
  [ -e "$f" ] || { echo "load.sh: $f is missing (build lucentd, lucentctl and cornell_bake in $BUILD)" >&2; exit 2; }
done
command -v jq >/dev/null || { echo "load.sh: needs jq" >&2; exit 2; }
[ -n "$OUT" ] || OUT="$(mktemp -d /tmp/lucent-load-XXXXXX)"
mkdir -p "$OUT"
WORK="$(mktemp -d /tmp/lucent-load-state-XXXXXX)"
DPID=""
cleanup() { [ -n "$DPID" ] && kill "$DPID" 2>/dev/null && wait "$DPID" 2>/dev/null; rm -rf "$WORK"; }
trap cleanup EXIT

# Both lucentd and lucentctl need a descriptor per client: the soft limit up to the hard one.
ulimit -n "$(ulimit -Hn)"
echo "open-files limit: $(ulimit -n) (hard $(ulimit -Hn)); results in $OUT" >&2

# cpu_s PID: utime + stime of a live process in seconds (fields 14 and 15 of /proc/PID/stat)
cpu_s() { awk -v tck="$(getconf CLK_TCK)" '{ sub(/^.*\) /, ""); print ($12 + $13) / tck }' "/proc/$1/stat"; }
hwm_kb() { awk '/^VmHWM:/ { print $2 }' "/proc/$1/status"; }

IFS=, read -r -a counts <<<"$CLIENTS"
for n in "${counts[@]}"; do
  state="$WORK/state-$n"
  "$BIN/lucentd" --bake "$LCB" --backend cpu --listen 127.0.0.1 --port 0 --state-dir "$state" \
    --max-clients 12000 --log-level warn >"$state.out" 2>"$state.err" &
  DPID=$!
  port=""
  for _ in $(seq 200); do
    port="$(sed -n 's/^lucentd listening port=\([0-9]*\).*/\1/p' "$state.out" 2>/dev/null)"
    [ -n "$port" ] && break
    kill -0 "$DPID" 2>/dev/null || break
    sleep 0.05
  done
  [ -n "$port" ] || { echo "load.sh: lucentd did not start: $(head -c 400 "$state.err")" >&2; exit 1; }
  cpu0="$(cpu_s "$DPID")"
  rc=0
  timeout 600 "$BIN/lucentctl" --url "ws://127.0.0.1:$port/" load --clients "$n" --rate "$RATE" \
    --duration "$DURATION" --json "$OUT/lucentctl-$n.json" >"$OUT/lucentctl-$n.txt" 2>"$OUT/lucentctl-$n.err" || rc=$?
  cpu1="$(cpu_s "$DPID")"
  hwm="$(hwm_kb "$DPID")"
  kill "$DPID"; wait "$DPID" 2>/dev/null || true; DPID=""
  warn="$(grep -c . "$state.err" || true)"
  cp "$state.err" "$OUT/lucentd-$n.log"
  if [ -s "$OUT/lucentctl-$n.json" ]; then
    jq --argjson hwm "${hwm:-0}" --argjson c0 "$cpu0" --argjson c1 "$cpu1" --argjson rc "$rc" --argjson w "$warn" \
      '. + {lucentctl_exit: $rc, daemon: {vmhwm_kb: $hwm, cpu_s: (($c1 - $c0) * 100 | round / 100), log_lines: $w}}' \
      "$OUT/lucentctl-$n.json" >"$OUT/load-$n.json"
  else
    echo "load.sh: N=$n: lucentctl exited $rc without a report: $(tail -c 400 "$OUT/lucentctl-$n.err")" >&2
  fi
  echo "N=$n done (lucentctl exit $rc)" >&2
done

printf '\nlucentd under load: Cornell bake, CPU backend, %s updates/s for %s s, lightmap rgb9e5; %s cores shared\n' \
  "$RATE" "$DURATION" "$(nproc)"
printf '%6s %6s %6s %9s %9s %9s %8s %11s %9s %8s %10s %9s %8s\n' N conn failed "p50 ms" "p99 ms" "max ms" missing \
  "frames/cl/s" "KB/cl/s" "on final" "lucentd MB" "lucentd s" "ctl s"
for n in "${counts[@]}"; do
  f="$OUT/load-$n.json"
  [ -s "$f" ] || { printf '%6s (no report)\n' "$n"; continue; }
  jq -r '[.clients.requested, .clients.connected, .clients.failed, .latency_ms.p50, .latency_ms.p99,
          .latency_ms.max, .latency_ms.missing, .frames.per_client_per_s, (.bytes.per_client_per_s / 1000),
          (.final.fraction * 100), (.daemon.vmhwm_kb / 1024), .daemon.cpu_s, .load_client.cpu_s] | @tsv' "$f" |
    awk -F'\t' '{ printf "%6d %6d %6d %9.1f %9.1f %9.1f %8d %11.2f %9.1f %7.1f%% %10.1f %9.2f %8.2f\n",
                  $1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13 }'
done
