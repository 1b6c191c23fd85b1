#!/usr/bin/env python3
"""No function longer than 150 lines in the shared code, the daemon, the protocol, the client or the tools (issue 14).

Usage: check_function_length.py [--max N] [--list] [PATH ...]

PATHs are files or directories (default: common/, daemon/, protocol/, client/ and tools/ under the source
root, LUCENT_SOURCE_DIR or this script's ../..). Every .c/.cpp found is scanned; directories
named build* or starting with a dot are skipped. A function's length is counted from the
line of its body's opening brace to the line of its closing brace, both included.

Braces are matched on the code with comments, string and character literals and
preprocessor lines blanked out, so the count does not depend on layout; the scan still
checks the style's promise that a multi-line body closes with a '}' in column 0, because a
body that does not (a macro or an #if with unbalanced braces) would mean the matching went
wrong. Exit 0 = all within the limit, 1 = some function is over it (each listed), 2 = a file
could not be parsed.
"""
import os
import re
import signal
import sys

MAX_LINES = 150
SOURCE_DIRS = ("common", "daemon", "protocol", "client", "tools")
EXTENSIONS = (".c", ".cpp")

# Keywords that can precede a parenthesis in a declaration without naming the function.
NOT_NAMES = {"__attribute__", "__declspec", "alignas", "_Alignas", "__typeof__", "typeof",
             "decltype", "noexcept", "if", "for", "while", "switch", "return", "sizeof"}
IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(?:::~?[A-Za-z_][A-Za-z0-9_]*)*$")


def blank_non_code(text):
    """The text with comments, literals and preprocessor lines replaced by spaces (newlines
    kept, so lines and columns stay where they were)."""
    out = list(text)
    i, n = 0, len(text)
    line_start = True  # only whitespace since the last newline

    def blank(a, b):
        for k in range(a, b):
            if out[k] != "\n":
                out[k] = " "

    while i < n:
        c = text[i]
        if c == "\n":
            line_start = True
            i += 1
            continue
        if line_start and c == "#":  # preprocessor line, with its continuations
            j = i
            while j < n and text[j] != "\n":
                if text.startswith("/*", j):  # a comment may run past the line's end
                    end = text.find("*/", j + 2)
                    j = n if end < 0 else end + 2
                    continue
                if text[j] == "\\" and j + 1 < n and text[j + 1] == "\n":
                    j += 2
                    continue
                j += 1
            blank(i, j)
            i = j
            continue
        if c in " \t\r\f\v":
            i += 1
            continue
        line_start = False
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            blank(i, j)
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            blank(i, j)
            i = j
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'R"([^()\\ ]{0,16})\(', text[i:])
            if not m:
                i += 1
                continue
            end = text.find(")" + m.group(1) + '"', i)
            j = n if end < 0 else end + len(m.group(1)) + 2
            blank(i + 1, j - 1)
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            blank(i + 1, j - 1)  # keep the quotes: `extern "C"` must still read as one
            i = j
        else:
            i += 1
    return "".join(out)


def function_name(head):
    """The name a function definition's head declares, or None when the head is not one
    (an initializer, a struct/enum body, a namespace)."""
    depth = 0
    for k, ch in enumerate(head):  # an initializer: `= {` at the top level
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == "=" and depth == 0:
            return None
    for m in re.finditer(r"\(", head):
        before = head[: m.start()].rstrip()
        word = re.search(r"[A-Za-z_][A-Za-z0-9_:~]*$", before)
        if not word:
            continue
        # Only a parenthesis at the top level starts a parameter list.
        if head[: m.start()].count("(") != head[: m.start()].count(")"):
            continue
        name = word.group(0)
        if name in NOT_NAMES or not IDENT.match(name):
            continue
        return name
    return None


def is_scope(head):
    """Heads whose braces enclose definitions rather than code: namespaces, extern "C"
    blocks and C++ class bodies."""
    h = " ".join(head.split())
    if re.search(r'\bextern\s*""\s*$', h.replace('"C"', '""')) or re.search(r'extern\s*"C"\s*$', h):
        return True
    if re.match(r"^(inline\s+)?namespace\b[^()]*$", h):
        return True
    if re.match(r"^(template\s*<.*>\s*)?(class|struct)\s+[A-Za-z_][\w:]*(\s+final)?(\s*:[^()]*)?$", h):
        return "class" in h.split()[0:3] or ":" in h  # plain C structs hold no functions
    return False


def scan(path, max_lines, every=False):
    """Returns ([(name, first_line, lines)] over max_lines, or every function, [parse errors])."""
    with open(path, encoding="utf-8", errors="replace") as f:
        text = f.read()
    code = blank_non_code(text)
    over, errors = [], []
    line = 1
    col = 0
    head_start = 0
    stack = []  # per open brace: ("scope" | "function" | "other", name, line, index)
    paren = 0
    for i, ch in enumerate(code):
        if ch == "\n":
            line += 1
            col = 0
            continue
        col += 1
        if ch == "(":
            paren += 1
        elif ch == ")":
            paren -= 1
        inside_code = any(kind != "scope" for kind, _, _, _ in stack)
        if ch == "{":
            if inside_code:
                stack.append(("other", None, line, i))
                continue
            head = code[head_start:i]
            if is_scope(head):
                stack.append(("scope", None, line, i))
            else:
                name = function_name(head)
                stack.append(("function" if name else "other", name, line, i))
            head_start = i + 1
        elif ch == "}":
            if not stack:
                errors.append("%s:%d: '}' without a matching '{'" % (path, line))
                return over, errors
            kind, name, first, _ = stack.pop()
            if kind == "function":
                lines = line - first + 1
                if lines > 1 and col != 1:
                    errors.append("%s:%d: the body of %s (from line %d) closes in column %d, not 0; "
                                  "braces may be unbalanced by the preprocessor" % (path, line, name, first, col - 1))
                if every or lines > max_lines:
                    over.append((name, first, lines))
            if not any(k != "scope" for k, _, _, _ in stack):
                head_start = i + 1
        elif ch == ";" and not inside_code and paren == 0:
            head_start = i + 1
    if stack:
        errors.append("%s:%d: '{' never closed" % (path, stack[-1][2]))
    return over, errors


# Layouts the scan must read right (name, first line, lines), checked by --self-test before
# every scan so a parser regression cannot pass the tree silently.
SELF_TEST = (r'''
static int
split_signature(int a,
                const char *b)
{
    return a;
}
__attribute__((target_clones("avx2", "default"))) static void
cloned(const float *restrict x, float acc[3][16]) {
    const char *s = "}{";  /* } */
    char c = '}';
#define OPEN {
    if (x) {
        acc[0][0] = *x;
    }
}
static const struct { int a, b; } table[] = {
    {1, 2},
};
typedef struct {
    int a;
} not_a_function;
static inline int one_liner(int x) { return x + 1; }
static const char *const *pointer_result(void) {
    static const char *const names[] = {"a", "b"};
    return names;
}
int label_block(int x) {
    if (x) goto out;
    return 0;
out: {
    x++;
    return x;
}
}
namespace {
void in_namespace(int x) {
    (void)x;
}
}  // namespace
extern "C" int in_extern_c(void) {
    return 0;
}
''', [("split_signature", 4, 3), ("cloned", 8, 8), ("one_liner", 22, 1), ("pointer_result", 23, 4),
        ("label_block", 27, 8), ("in_namespace", 36, 3), ("in_extern_c", 40, 3)])


def self_test():
    import tempfile
    text, want = SELF_TEST
    with tempfile.NamedTemporaryFile("w", suffix=".cpp", delete=False) as f:
        f.write(text.lstrip("\n"))
    try:
        got, errors = scan(f.name, 0, every=True)
    finally:
        os.unlink(f.name)
    if errors or got != want:
        print("check_function_length: self-test failed:\n  want %s\n  got  %s\n  %s" % (want, got, errors),
              file=sys.stderr)
        return False
    return True


def sources(paths):
    for p in paths:
        if os.path.isfile(p):
            yield p
            continue
        for root, dirs, files in os.walk(p):
            dirs[:] = sorted(d for d in dirs if not d.startswith(".") and not d.startswith("build"))
            for f in sorted(files):
                if f.endswith(EXTENSIONS):
                    yield os.path.join(root, f)


def main(argv):
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `--list | head` ends quietly
    max_lines = MAX_LINES
    list_all = False
    paths = []
    root = None
    args = iter(argv[1:])
    for a in args:
        if a == "--max":
            max_lines = int(next(args))
        elif a == "--list":  # every function with its length, longest first (for reviews)
            list_all = True
        elif a in ("-h", "--help"):
            print(__doc__.strip())
            return 0
        else:
            paths.append(a)
    if not paths:
        root = os.environ.get("LUCENT_SOURCE_DIR") or os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
        root = os.path.normpath(root)
        paths = [os.path.join(root, d) for d in SOURCE_DIRS]
        missing = [p for p in paths if not os.path.isdir(p)]
        if missing:
            print("check_function_length: no such directory: %s" % ", ".join(missing), file=sys.stderr)
            return 2
    if not self_test():
        return 2
    over, errors, n_files = [], [], 0
    for path in sources(paths):
        n_files += 1
        o, e = scan(path, max_lines, every=list_all)
        shown = os.path.relpath(path, root) if root else path  # source-relative, as the code is cited
        over += [(shown, name, first, lines) for name, first, lines in o]
        errors += e
    for e in errors:
        print("check_function_length: %s" % e, file=sys.stderr)
    if list_all:
        for path, name, first, lines in sorted(over, key=lambda r: -r[3]):
            print("%5d  %s:%d %s" % (lines, path, first, name))
        return 2 if errors else 0
    for path, name, first, lines in over:
        print("%s:%d: %s is %d lines (limit %d): split it along its seams into named static functions"
              % (path, first, name, lines, max_lines))
    if errors:
        return 2
    if over:
        print("check_function_length: %d function(s) over %d lines in %d files" % (len(over), max_lines, n_files))
        return 1
    print("check_function_length: %d files, every function within %d lines" % (n_files, max_lines))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
