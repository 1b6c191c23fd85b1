# Bakes the shared test scenes at the moderate preset (each skipped when absent) and checks
# each file validates. Prints bake time and peak memory per scene (the benchmark proper is
# tests/bench/bake_bench.sh).
. "$(dirname "$0")/lib.sh"
ran=0
bake_scene() {
  local name="$1" file="$2"; shift 2
  if [ ! -f "$file" ]; then echo "skip $name: $file absent"; return; fi
  ran=$((ran + 1))
  if ! "$BAKE" bake "$file" -o "$TMP/$name.lcb" --quality moderate --quiet --stats-json "$TMP/$name.json" "$@"; then
    fail "$name: bake failed"; return
  fi
  "$BAKE" verify "$TMP/$name.lcb" >/dev/null || fail "$name: verify failed"
  $PY -c "import json,sys; s=json.load(open(sys.argv[1])); print('%-16s %7.1f s  %7.0f MiB peak  %6.1f MiB file  %d caches' % (sys.argv[2], s['total_s'], s['peak_rss_mib'], s['file_bytes']/2**20, s['caches']))" "$TMP/$name.json" "$name"
  rm -f "$TMP/$name.lcb"
}
bake_scene cornell-mcguire "$SHARED/scenes/cornell-box/mcguire/CornellBox-Original.obj"
bake_scene sponza-dabrovic "$SHARED/scenes/sponza-dabrovic/sponza.obj"
bake_scene sibenik "$SHARED/scenes/sibenik/sibenik.obj"
bake_scene conference-room "$SHARED/scenes/conference-room/conference.obj" --scale 0.003
[ "$ran" -eq 0 ] && { echo "SKIP: no shared scenes in $SHARED/scenes"; exit 77; }
finish
