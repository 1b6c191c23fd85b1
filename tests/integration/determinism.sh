# Same input and seed → the same bytes, for any thread count; another seed → other bytes.
. "$(dirname "$0")/lib.sh"
common=(--quality draft --quiet --surfels 4096 --links 32)
"$BAKE" bake "$CORNELL" -o "$TMP/a.lcb" --seed 7 --threads 2 "${common[@]}" || fail "bake a"
"$BAKE" bake "$CORNELL" -o "$TMP/b.lcb" --seed 7 --threads 1 "${common[@]}" || fail "bake b"
"$BAKE" bake "$CORNELL" -o "$TMP/c.lcb" --seed 8 --threads 2 "${common[@]}" || fail "bake c"
cmp -s "$TMP/a.lcb" "$TMP/b.lcb" || fail "same seed, different bytes (threads 2 vs 1)"
cmp -s "$TMP/a.lcb" "$TMP/c.lcb" && fail "different seeds gave identical files"
finish
