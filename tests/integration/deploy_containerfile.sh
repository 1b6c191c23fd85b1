# deploy/Containerfile's build stage without a container engine: exactly the paths its COPY
# lines take from the build context are copied into an empty directory (the stage's
# WORKDIR), and the stage's cmake RUN command is run there as written (configure Release,
# build the targets it names: lucentd lucentctl cornell_bake, then lucentd --check-config
# on the default bake). So a COPY the build needs but the file lacks fails here.
# Also checked: every context path a COPY names (any stage) exists, and every shared library
# the built programs load comes from a package the runtime stage installs (or the base image
# has), when apt's package lists are present.
# Runs in Release builds only (scripts/test.sh's full suite): the stage builds the same way
# whatever this build is, and it costs minutes of one core, so the sanitizer build and other
# build types skip it.
source "$(dirname "$0")/lib.sh"
BUILD="${LUCENT_BINARY_DIR:?run through ctest}"
if ! grep -q '^CMAKE_BUILD_TYPE:[A-Z]*=Release$' "$BUILD/CMakeCache.txt" 2>/dev/null ||
   grep -q '^LUCENT_SANITIZE:BOOL=ON' "$BUILD/CMakeCache.txt" 2>/dev/null; then
  echo "not the Release build: the Release suite checks the Containerfile; skip"
  exit 77
fi
CF="$SRC/deploy/Containerfile"
CTX="$TMP/ctx"
mkdir -p "$CTX"

# Parse: the first stage's WORKDIR, COPY (source, destination) pairs and its RUN commands;
# context sources of every stage; the runtime stage's apt-get install list.
"$PY" - "$CF" "$TMP/plan" <<'EOF' || { fail "cannot parse $CF"; finish; }
import os, re, shlex, sys
cf, out = sys.argv[1], sys.argv[2]
lines, cur = [], ""
for raw in open(cf):
    s = raw.rstrip("\n")
    if not cur and (not s.strip() or s.lstrip().startswith("#")):
        continue
    if s.rstrip().endswith("\\"):
        cur += s.rstrip()[:-1] + " "
        continue
    if cur and s.lstrip().startswith("#"):
        continue  # a comment inside a continued instruction
    lines.append(cur + s)
    cur = ""
stages, st = [], None
for l in lines:
    word, _, rest = l.strip().partition(" ")
    word = word.upper()
    if word == "FROM":
        st = {"workdir": "/", "copies": [], "runs": []}
        stages.append(st)
    elif word == "WORKDIR":
        st["workdir"] = os.path.join(st["workdir"], rest.strip())
    elif word in ("COPY", "ADD"):
        args = shlex.split(rest)
        flags = [a for a in args if a.startswith("--")]
        paths = [a for a in args if not a.startswith("--")]
        st["copies"].append((any(f.startswith("--from") for f in flags), paths[:-1], paths[-1]))
    elif word == "RUN":
        st["runs"].append(rest.strip())
with open(out, "w") as f:
    build = stages[0]
    for i, stage in enumerate(stages):
        for from_stage, srcs, dest in stage["copies"]:
            if from_stage:
                for s in srcs:
                    f.write("built\t%s\n" % os.path.relpath(s, build["workdir"]))
                continue
            for s in srcs:
                f.write("exists\t%s\n" % s)
                if i == 0:
                    d = dest if dest.startswith("/") else os.path.join(stage["workdir"], dest)
                    rel = os.path.relpath(d, build["workdir"])
                    if dest.endswith("/") and not os.path.isdir(s):
                        rel = os.path.join(rel, os.path.basename(s))
                    f.write("copy\t%s\t%s\n" % (s, rel))
    for r in build["runs"]:
        if "cmake" in r:
            f.write("run\t%s\n" % r)
    m = re.search(r"apt-get install ([^&]*)", " ".join(stages[-1]["runs"]))
    pkgs = [p for p in (m.group(1).split() if m else []) if not p.startswith("-")]
    f.write("runtime\t%s\n" % " ".join(pkgs))
EOF

while IFS=$'\t' read -r kind a b; do
  case "$kind" in
    exists) [ -e "$SRC/$a" ] || fail "Containerfile COPY $a: not in the repository" ;;
    copy)
      if [ -d "$SRC/$a" ]; then
        mkdir -p "$CTX/$b" && cp -a "$SRC/$a/." "$CTX/$b/"
      else
        mkdir -p "$(dirname "$CTX/$b")" && cp -a "$SRC/$a" "$CTX/$b"
      fi ;;
  esac
done <"$TMP/plan"
[ "$FAILS" -eq 0 ] || finish

runs=$(grep -c $'^run\t' "$TMP/plan" || true)
[ "$runs" -ge 1 ] || { fail "no cmake RUN in the build stage"; finish; }
grep $'^run\t' "$TMP/plan" | cut -f2- | sed "s|/tmp/check|$TMP/check|g" >"$TMP/run.sh"
start=$(date +%s)
# nproc is 1 here: ctest gives this test one slot, and the other tests (some timing-sensitive)
# run beside it. Default compilers, as in the image.
if ! (cd "$CTX" && env -u CC -u CXX /bin/sh -ec "nproc() { echo 1; }
$(cat "$TMP/run.sh")") >"$TMP/build.log" 2>&1; then
  fail "the build stage's RUN failed in a context of only its COPY paths: $(grep -m 5 -iE 'error|not found|No such' "$TMP/build.log") $(tail -n 15 "$TMP/build.log")"
  finish
fi
echo "build stage: $(($(date +%s) - start)) s: $(cat "$TMP/run.sh")"
for f in build/bin/lucentd build/bin/lucentctl build/share/lucent/cornell.lcb $(sed -n 's/^built\t//p' "$TMP/plan"); do
  [ -e "$CTX/$f" ] || fail "the build stage did not produce $f (the runtime stage copies it)"
done

# The runtime stage's packages provide every library the copied programs load.
runtime=$(sed -n 's/^runtime\t//p' "$TMP/plan")
if ! apt-cache show libc6 >/dev/null 2>&1; then
  echo "no apt package lists: runtime library check skipped"
else
  # shellcheck disable=SC2086
  apt-cache depends --recurse --no-recommends --no-suggests --no-conflicts --no-breaks --no-replaces \
      --no-enhances apt $runtime 2>/dev/null | grep -v '^[ <]' | sort -u >"$TMP/have"
  dpkg-query -W -f '${Package} ${Priority}\n' | awk '$2 == "required" {print $1}' >>"$TMP/have"
  for exe in "$CTX"/build/bin/* "$CTX"/build/libexec/lucent/*; do
    [ -x "$exe" ] && [ -f "$exe" ] || continue
    ldd "$exe" | awk '/=> \// {print $3}' | while read -r lib; do
      real="$(readlink -f "$lib")" # through /etc/alternatives (libblas.so.3) to the package's file
      pkg=$(dpkg -S "$lib" 2>/dev/null || dpkg -S "/usr$lib" 2>/dev/null || dpkg -S "$real" 2>/dev/null ||
            dpkg -S "${real#/usr}" 2>/dev/null || true)
      pkg="${pkg%%:*}"
      [ -n "$pkg" ] || { echo "$(basename "$exe"): $lib: no package" >>"$TMP/libs.err"; continue; }
      grep -qx "$pkg" "$TMP/have" || echo "$(basename "$exe") loads $lib from $pkg, which the runtime stage does not install" >>"$TMP/libs.err"
    done
  done
  [ -s "$TMP/libs.err" ] && fail "runtime stage: $(sort -u "$TMP/libs.err" | head -n 10)"
fi
finish
