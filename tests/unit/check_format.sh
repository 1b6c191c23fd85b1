# The C sources follow .clang-format (checked, not rewritten): prints each file that differs
# and how to fix it. Skips (77) when clang-format is not installed.
cd "${LUCENT_SOURCE_DIR:?run through ctest}" || exit 1
command -v clang-format >/dev/null || { echo "clang-format not installed: skip"; exit 77; }
bad=0
while IFS= read -r f; do
  if ! clang-format --style=file --dry-run -Werror "$f" >/dev/null 2>&1; then
    echo "not formatted: $f" >&2
    bad=1
  fi
done < <(git ls-files '*.c' '*.h' '*.cpp' 2>/dev/null | grep -v '^tests/fuzz/corpus/' || find common daemon protocol client tools tests -name '*.[ch]' -o -name '*.cpp')
if [ "$bad" -ne 0 ]; then echo "run: clang-format -i --style=file FILE (the style is .clang-format)" >&2; exit 1; fi
echo "every C source follows .clang-format"
