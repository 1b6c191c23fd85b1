/* proto_parse: lucent/1 client requests and `state` messages -> validated C structs
 * (PROTOCOL.md §2-5). Order of checks: size, nesting depth (bracket scan), strict JSON
 * grammar (RFC 8259; cJSON alone is lax: trailing garbage, BOM, control characters), cJSON
 * tree, request id, type, then every field with its RFC 6901 pointer. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_proto.h"
#include "lucent_upload.h"
#include "util/limits.h"
#include "util/utf8.h"

#define PROTO_STR_MAX 256   /* §1.3: string length */
#define PROTO_DEPTH_CAP 512 /* below cJSON's own nesting limit (1000) */
#define PROTO_PTR_MAX 160   /* sizeof lc_proto_error.pointer */
#define PROTO_QUOTE_MAX 64  /* bytes of client text quoted in an error message */
#define PROTO_TWO_53 9007199254740992.0
#define PROTO_HALF_PI 1.5707963267948966
#define PROTO_ANGLE_SLACK 1e-6 /* float(π/2) printed by a builder is a little above π/2 */

/* proto_scan_json flags: a string with ill-formed UTF-8; a \u0000 in any string; a \u0000
 * in the request id (the root's first member named "id", in its name or string value). */
enum { PROTO_SCAN_BAD_UTF8 = 1, PROTO_SCAN_NUL_ESCAPE = 2, PROTO_SCAN_NUL_IN_ID = 4 };

static const char *const proto_type_names[LC_REQ_COUNT] = {
    "hello",         "subscribe",    "unsubscribe",     "light.set",    "light.remove", "object.set",
    "object.remove", "material.set", "environment.set", "settings.set", "batch",        "state.get",
    "snapshot",      "ping",         "mr.begin",        "mr.end"};
static const char *const proto_stream_names[] = {"lightmap", "shgrid", "objects", "mr.vpl"};
static const char *const proto_capability_names[LC_CAP_COUNT] = {"mr"};
static const char *const proto_depth_names[] = {"u16mm", "f16m"};              /* LC_DEPTH_* - 1 */
static const char *const proto_color_names[] = {"rgb8_srgb", "rgb16f_linear"}; /* LC_COLOR_* - 1 */
static const char *const proto_mr_light_names[] = {"replace", "add"};
static const char *const proto_encoding_names[] = {"rgb9e5", "rgba16f", "f32"};
static const char *const proto_delta_names[] = {"tiles", "residual"};
static const char *const proto_light_type_names[] = {"point", "spot", "directional", "area"};
static const char *const proto_shape_names[] = {"quad", "disc"};
static const char *const proto_mode_names[] = {"dynamic", "clutter", "auto"}; /* LC_OBJECT_MODE_* */
static const char *const proto_env_names[] = {"none", "constant", "sh"};
static const char *const proto_solver_names[LC_PROTO_SOLVER_COUNT] = {"pic", "probes"};

const char *lc_proto_solver_name(int solver) {
    return solver >= 0 && solver < LC_PROTO_SOLVER_COUNT ? proto_solver_names[solver] : NULL;
}

const char *lc_proto_type_name(lc_req_type t) { return (unsigned)t < LC_REQ_COUNT ? proto_type_names[t] : "unknown"; }

int lc_proto_is_change(lc_req_type t) { return t >= LC_REQ_LIGHT_SET && t <= LC_REQ_BATCH; }

const char *lc_proto_stream_name(lc_stream s) {
    return s >= LC_STREAM_LIGHTMAP && s <= LC_STREAM_MAX ? proto_stream_names[s - 1] : "unknown";
}

const char *lc_proto_capability_name(uint32_t cap_bit) {
    for (int k = 0; k < LC_CAP_COUNT; k++)
        if (cap_bit == 1u << k) return proto_capability_names[k];
    return NULL;
}

const char *lc_proto_encoding_name(lc_encoding e) {
    return e >= LC_ENC_RGB9E5 && e <= LC_ENC_F32 ? proto_encoding_names[e - 1] : "unknown";
}

void lc_proto_default_limits(lc_proto_limits *lim) {
    lim->max_message = LC_LIMIT_MESSAGE;
    lim->max_depth = LC_LIMIT_DEPTH;
    lim->max_batch = LC_LIMIT_BATCH;
}

/* --- errors and pointers ---------------------------------------------------------------- */

static const struct {
    const char *code, *meaning, *connection;
} proto_errors[LC_ERR_COUNT] = {
#define PROTO_ERROR_ROW(id, code, meaning, connection) {code, meaning, connection},
    LC_PROTO_ERRORS(PROTO_ERROR_ROW)
#undef PROTO_ERROR_ROW
};

const char *lc_proto_errcode_name(lc_proto_errcode c) {
    return (unsigned)c < LC_ERR_COUNT ? proto_errors[c].code : proto_errors[LC_ERR_INTERNAL].code;
}

const char *lc_proto_errcode_meaning(lc_proto_errcode c) {
    return (unsigned)c < LC_ERR_COUNT ? proto_errors[c].meaning : "";
}

const char *lc_proto_errcode_connection(lc_proto_errcode c) {
    return (unsigned)c < LC_ERR_COUNT ? proto_errors[c].connection : "";
}

int lc_proto_errcode_find(const char *code) {
    for (int i = 0; i < LC_ERR_COUNT; i++)
        if (!strcmp(proto_errors[i].code, code)) return i;
    return -1;
}

void lc_proto_error_set_code(lc_proto_error *err, lc_proto_errcode code) {
    snprintf(err->code, sizeof err->code, "%s", lc_proto_errcode_name(code));
}

/* Fills err. Messages quote client text only through proto_quote(). */
static void proto_error(lc_proto_error *err, lc_proto_errcode code, const char *ptr, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void proto_error(lc_proto_error *err, lc_proto_errcode code, const char *ptr, const char *fmt, ...) {
    lc_proto_error_set_code(err, code);
    if (snprintf(err->pointer, sizeof err->pointer, "%s", ptr) < 0) err->pointer[0] = 0;
    va_list ap;
    va_start(ap, fmt);
    if (vsnprintf(err->message, sizeof err->message, fmt, ap) < 0) err->message[0] = 0;
    va_end(ap);
}

/* proto_error(), then -1. A macro so the -1 is visible where it is returned: a variadic
 * function is never inlined, and with an opaque return value the optimiser must assume
 * that a failed required field (proto_missing) can return 0 without writing the output
 * (GCC -O3: -Wmaybe-uninitialized on the callers' outputs). */
#define proto_fail(...) (proto_error(__VA_ARGS__), -1)

/* dst = base "/" key (keys are our own ASCII names: no RFC 6901 escaping needed). */
static void proto_ptr(char dst[PROTO_PTR_MAX], const char *base, const char *key) {
    if (snprintf(dst, PROTO_PTR_MAX, "%s/%s", base, key) >= PROTO_PTR_MAX) dst[PROTO_PTR_MAX - 1] = 0;
}

static void proto_ptr_index(char dst[PROTO_PTR_MAX], const char *base, int i) {
    if (snprintf(dst, PROTO_PTR_MAX, "%s/%d", base, i) >= PROTO_PTR_MAX) dst[PROTO_PTR_MAX - 1] = 0;
}

/* --- byte-level checks ------------------------------------------------------------------ */

int lc_proto_utf8_valid(const char *s, size_t len) { return (s || !len) && lc_utf8_valid(s, len); }

size_t lc_proto_utf8_cut(const char *s, size_t len, size_t max) { return s ? lc_utf8_cut(s, len, max) : 0; }

size_t lc_proto_utf8_sanitize(char *dst, size_t cap, const char *s, size_t len, unsigned flags) {
    if (!dst || !cap) return 0;
    if (!s) len = 0;
    return lc_utf8_sanitize(dst, cap, s ? s : "", len, flags & LC_PROTO_UTF8_NO_CONTROLS ? LC_UTF8_NO_CONTROLS : 0);
}

/* Client text quoted into an error message: at most PROTO_QUOTE_MAX bytes, cut on a
 * character boundary, ill-formed bytes and control characters shown as U+FFFD (the message
 * must be valid UTF-8 for the client's WebSocket, and one line for the server's log), "..."
 * when it was cut. */
static const char *proto_quote(char dst[PROTO_QUOTE_MAX + 4], const char *s) {
    size_t n = strlen(s);
    size_t used = lc_utf8_sanitize(dst, PROTO_QUOTE_MAX + 1, s, n, LC_UTF8_NO_CONTROLS);
    if (used < n) strcat(dst, "...");
    return dst;
}

/* Nesting depth of containers, ignoring brackets inside strings; > max -> 1. Runs before
 * any tree is built so a deep message costs nothing. */
static int proto_too_deep(const char *text, size_t len, int max_depth) {
    int depth = 0, in_str = 0;
    for (size_t i = 0; i < len; i++) {
        char c = text[i];
        if (in_str) {
            if (c == '\\') i++;
            else if (c == '"') in_str = 0;
        } else if (c == '"') {
            in_str = 1;
        } else if (c == '{' || c == '[') {
            if (++depth > max_depth) return 1;
        } else if (c == '}' || c == ']') {
            depth--;
        }
    }
    return 0;
}

static size_t proto_ws(const unsigned char *s, size_t n, size_t i) {
    while (i < n && (s[i] == ' ' || s[i] == '\t' || s[i] == '\n' || s[i] == '\r')) i++;
    return i;
}

static int proto_hex(unsigned char c) {
    return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || (c >= 'A' && c <= 'F');
}

/* String starting at s[i] == '"'; returns the index after the closing quote or 0. */
static size_t proto_scan_string(const unsigned char *s, size_t n, size_t i, int *flags) {
    i++;
    while (i < n) {
        unsigned char c = s[i];
        if (c == '"') return i + 1;
        if (c < 0x20) return 0;
        if (c == '\\') {
            if (i + 1 >= n) return 0;
            c = s[i + 1];
            if (c == 'u') {
                if (i + 5 >= n) return 0;
                for (int k = 2; k < 6; k++)
                    if (!proto_hex(s[i + k])) return 0;
                if (!memcmp(s + i + 2, "0000", 4)) *flags |= PROTO_SCAN_NUL_ESCAPE;
                i += 6;
            } else if (strchr("\"\\/bfnrt", c) && c) {
                i += 2;
            } else {
                return 0;
            }
        } else if (c < 0x80) {
            i++;
        } else {
            size_t k = lc_utf8_seq(s + i, n - i);
            if (!k) {
                *flags |= PROTO_SCAN_BAD_UTF8; /* reported as `invalid`, with the field if known */
                k = 1;
            }
            i += k;
        }
    }
    return 0;
}

/* Number per RFC 8259 at s[i]; returns the index after it or 0. */
static size_t proto_scan_number(const unsigned char *s, size_t n, size_t i) {
    if (i < n && s[i] == '-') i++;
    if (i >= n) return 0;
    if (s[i] == '0') {
        i++;
    } else if (s[i] >= '1' && s[i] <= '9') {
        while (i < n && s[i] >= '0' && s[i] <= '9') i++;
    } else {
        return 0;
    }
    if (i < n && s[i] == '.') {
        i++;
        if (i >= n || s[i] < '0' || s[i] > '9') return 0;
        while (i < n && s[i] >= '0' && s[i] <= '9') i++;
    }
    if (i < n && (s[i] == 'e' || s[i] == 'E')) {
        i++;
        if (i < n && (s[i] == '+' || s[i] == '-')) i++;
        if (i >= n || s[i] < '0' || s[i] > '9') return 0;
        while (i < n && s[i] >= '0' && s[i] <= '9') i++;
    }
    return i;
}

/* Whether the member name s[i0, i1) (quotes included, grammar already checked) is "id" as
 * cJSON sees it: escapes decoded, up to its first NUL (where cJSON's copy ends); *nul = 1
 * when it holds a \u0000 there. */
static int proto_key_is_id(const unsigned char *s, size_t i0, size_t i1, int *nul) {
    static const char lit[] = "id";
    size_t pos = 0;
    *nul = 0;
    for (size_t j = i0 + 1; j + 1 < i1;) {
        unsigned ch = s[j];
        if (ch == '\\') {
            unsigned char e = s[j + 1];
            if (e == 'u') {
                ch = 0;
                for (int k = 2; k < 6; k++) {
                    unsigned h = s[j + k];
                    ch = ch * 16 + (h <= '9' ? h - '0' : (h | 0x20) - 'a' + 10);
                }
                j += 6;
            } else {
                ch = e == 'b' ? '\b' : e == 'f' ? '\f' : e == 'n' ? '\n' : e == 'r' ? '\r' : e == 't' ? '\t' : e;
                j += 2;
            }
        } else {
            j++;
        }
        if (ch == 0) {
            *nul = 1;
            break;
        }
        if (pos >= sizeof lit - 1 || (unsigned char)lit[pos] != ch) return 0;
        pos++;
    }
    return pos == sizeof lit - 1;
}

/* A member name at s[i] (depth: of the object it is in); returns the index after it or 0.
 * For the root object, tracks whether this member is the request id (*id_member). */
static size_t proto_scan_key(const unsigned char *s, size_t n, size_t i, int depth, int *flags, int *id_member,
                             int *id_seen) {
    size_t i0 = i;
    if (i >= n || s[i] != '"' || !(i = proto_scan_string(s, n, i, flags))) return 0;
    if (depth == 1) {
        int nul = 0;
        *id_member = !*id_seen && proto_key_is_id(s, i0, i, &nul);
        if (*id_member) {
            *id_seen = 1; /* cJSON finds the first member of that name */
            if (nul) *flags |= PROTO_SCAN_NUL_IN_ID;
        }
    }
    return i;
}

/* Strict RFC 8259 check of the whole text (one value, whitespace around). Iterative; the
 * depth was bounded by proto_too_deep. Returns 0 or -1. */
static int proto_scan_json(const char *text, size_t len, int *flags) {
    const unsigned char *s = (const unsigned char *)text;
    unsigned char stack[PROTO_DEPTH_CAP + 1];
    int depth = 0, id_member = 0, id_seen = 0;
    size_t i = proto_ws(s, len, 0);
    int want_value = 1;
    for (;;) {
        if (want_value) {
            if (i >= len) return -1;
            unsigned char c = s[i];
            if (c == '{' || c == '[') {
                if (depth >= PROTO_DEPTH_CAP) return -1;
                stack[depth++] = c;
                i = proto_ws(s, len, i + 1);
                if (i < len && s[i] == (c == '{' ? '}' : ']')) {
                    depth--;
                    i++;
                    want_value = 0;
                    continue;
                }
                if (c == '{') {
                    if (!(i = proto_scan_key(s, len, i, depth, flags, &id_member, &id_seen))) return -1;
                    i = proto_ws(s, len, i);
                    if (i >= len || s[i] != ':') return -1;
                    i = proto_ws(s, len, i + 1);
                }
                continue;
            }
            if (c == '"') {
                int f = 0;
                if (!(i = proto_scan_string(s, len, i, &f))) return -1;
                if (depth == 1 && id_member && (f & PROTO_SCAN_NUL_ESCAPE)) f |= PROTO_SCAN_NUL_IN_ID;
                *flags |= f;
            } else if (c == '-' || (c >= '0' && c <= '9')) {
                if (!(i = proto_scan_number(s, len, i))) return -1;
            } else if (len - i >= 4 && !memcmp(s + i, "true", 4)) {
                i += 4;
            } else if (len - i >= 5 && !memcmp(s + i, "false", 5)) {
                i += 5;
            } else if (len - i >= 4 && !memcmp(s + i, "null", 4)) {
                i += 4;
            } else {
                return -1;
            }
            want_value = 0;
            continue;
        }
        i = proto_ws(s, len, i);
        if (depth == 0) return i == len ? 0 : -1;
        if (i >= len) return -1;
        unsigned char top = stack[depth - 1];
        if (s[i] == ',') {
            i = proto_ws(s, len, i + 1);
            if (top == '{') {
                if (!(i = proto_scan_key(s, len, i, depth, flags, &id_member, &id_seen))) return -1;
                i = proto_ws(s, len, i);
                if (i >= len || s[i] != ':') return -1;
                i = proto_ws(s, len, i + 1);
            }
            want_value = 1;
        } else if (s[i] == (top == '{' ? '}' : ']')) {
            depth--;
            i++;
        } else {
            return -1;
        }
    }
}

/* Depth, grammar, tree; the root must be an object. */
static int proto_load(const char *text, size_t len, int max_depth, cJSON **root, int *flags, lc_proto_error *err) {
    *root = NULL;
    *flags = 0;
    if (max_depth < 1) max_depth = 1;
    if (max_depth > PROTO_DEPTH_CAP) max_depth = PROTO_DEPTH_CAP;
    if (!text) return proto_fail(err, LC_ERR_BAD_JSON, "", "empty message");
    if (proto_too_deep(text, len, max_depth))
        return proto_fail(err, LC_ERR_TOO_DEEP, "", "nesting deeper than %d", max_depth);
    if (proto_scan_json(text, len, flags) < 0) return proto_fail(err, LC_ERR_BAD_JSON, "", "not valid JSON");
    *root = cJSON_ParseWithLength(text, len);
    if (!*root) return proto_fail(err, LC_ERR_BAD_JSON, "", "not valid JSON");
    if (!cJSON_IsObject(*root)) return proto_fail(err, LC_ERR_BAD_JSON, "", "message is not a JSON object");
    return 0;
}

/* --- field readers: 0 absent (and optional), 1 read, -1 error ---------------------------- */

static int proto_missing(int required, const char *p, lc_proto_error *err) {
    return required ? proto_fail(err, LC_ERR_INVALID, p, "%s is required", p) : 0;
}

static int proto_num_item(const cJSON *it, const char *p, double lo, double hi, double *out, lc_proto_error *err) {
    if (!cJSON_IsNumber(it)) return proto_fail(err, LC_ERR_INVALID, p, "%s must be a number", p);
    double v = it->valuedouble;
    if (!isfinite(v)) return proto_fail(err, LC_ERR_OUT_OF_RANGE, p, "%s is not a finite number", p);
    if (v < lo || v > hi) return proto_fail(err, LC_ERR_OUT_OF_RANGE, p, "%s must be in [%g, %g]", p, lo, hi);
    *out = v;
    return 1;
}

static int proto_num(const cJSON *obj, const char *key, const char *base, int required, double lo, double hi,
                     double *out, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, base, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it) return proto_missing(required, p, err);
    return proto_num_item(it, p, lo, hi, out, err);
}

static int proto_uint(const cJSON *obj, const char *key, const char *base, int required, uint32_t lo, uint32_t hi,
                      uint32_t *out, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, base, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it) return proto_missing(required, p, err);
    if (!cJSON_IsNumber(it)) return proto_fail(err, LC_ERR_INVALID, p, "%s must be an integer", p);
    double v = it->valuedouble;
    if (!isfinite(v)) return proto_fail(err, LC_ERR_OUT_OF_RANGE, p, "%s is not a finite number", p);
    if (v != floor(v)) return proto_fail(err, LC_ERR_INVALID, p, "%s must be an integer", p);
    if (v < lo || v > hi) return proto_fail(err, LC_ERR_OUT_OF_RANGE, p, "%s must be in [%u, %u]", p, lo, hi);
    *out = (uint32_t)v;
    return 1;
}

static int proto_bool(const cJSON *obj, const char *key, const char *base, int required, int *out,
                      lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, base, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it) return proto_missing(required, p, err);
    if (!cJSON_IsBool(it)) return proto_fail(err, LC_ERR_INVALID, p, "%s must be a boolean", p);
    *out = cJSON_IsTrue(it) ? 1 : 0;
    return 1;
}

static int proto_str_item(const cJSON *it, const char *p, size_t minlen, size_t maxlen, char *out, size_t cap,
                          lc_proto_error *err) {
    if (!cJSON_IsString(it) || !it->valuestring) return proto_fail(err, LC_ERR_INVALID, p, "%s must be a string", p);
    size_t n = strlen(it->valuestring);
    if (!lc_utf8_valid(it->valuestring, n)) return proto_fail(err, LC_ERR_INVALID, p, "%s is not valid UTF-8", p);
    if (n < minlen || n > maxlen)
        return proto_fail(err, LC_ERR_INVALID, p, "%s must be %zu..%zu bytes long", p, minlen, maxlen);
    if (out) {
        if (n >= cap) return proto_fail(err, LC_ERR_INVALID, p, "%s is too long", p);
        memcpy(out, it->valuestring, n + 1);
    }
    return 1;
}

static int proto_str(const cJSON *obj, const char *key, const char *base, int required, size_t minlen, size_t maxlen,
                     char *out, size_t cap, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, base, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it) return proto_missing(required, p, err);
    return proto_str_item(it, p, minlen, maxlen, out, cap, err);
}

static int proto_enum_item(const cJSON *it, const char *p, const char *const *names, int n, int *out,
                           lc_proto_error *err) {
    char buf[PROTO_STR_MAX + 1];
    if (proto_str_item(it, p, 0, PROTO_STR_MAX, buf, sizeof buf, err) < 0) return -1;
    for (int k = 0; k < n; k++)
        if (!strcmp(buf, names[k])) {
            *out = k;
            return 1;
        }
    char list[160] = ""; /* the allowed values, so the client sees what it may send */
    size_t used = 0;
    for (int k = 0; k < n && used < sizeof list; k++)
        used += (size_t)snprintf(list + used, sizeof list - used, "%s%s", k ? ", " : "", names[k]);
    return proto_fail(err, LC_ERR_INVALID, p, "%s: unknown value (one of: %s)", p, list);
}

static int proto_enum(const cJSON *obj, const char *key, const char *base, int required, const char *const *names,
                      int n, int *out, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, base, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it) return proto_missing(required, p, err);
    return proto_enum_item(it, p, names, n, out, err);
}

/* Array of exactly n numbers in [lo, hi]. */
static int proto_vec(const cJSON *obj, const char *key, const char *base, int required, int n, double lo, double hi,
                     double *out, lc_proto_error *err) {
    char p[PROTO_PTR_MAX], pe[PROTO_PTR_MAX];
    proto_ptr(p, base, key);
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!it) return proto_missing(required, p, err);
    if (!cJSON_IsArray(it) || cJSON_GetArraySize(it) != n)
        return proto_fail(err, LC_ERR_INVALID, p, "%s must be an array of %d numbers", p, n);
    int i = 0;
    for (const cJSON *e = it->child; e; e = e->next, i++) {
        proto_ptr_index(pe, p, i);
        if (proto_num_item(e, pe, lo, hi, &out[i], err) < 0) return -1;
    }
    return 1;
}

/* Normalises v[n] (finite) in place; 0 when it is the zero vector. Scales first so tiny or
 * huge components neither underflow nor overflow. */
static int proto_normalise(double *v, int n) {
    double m = 0, orig[4];
    memcpy(orig, v, (size_t)n * sizeof *v);
    for (int i = 0; i < n; i++) m = fmax(m, fabs(v[i]));
    if (!(m > 0)) return 0;
    double s = 0;
    for (int i = 0; i < n; i++) {
        v[i] /= m;
        s += v[i] * v[i];
    }
    s = sqrt(s);
    /* already unit to float precision: keep the client's values, so that re-parsing what a
     * builder wrote gives the same floats back */
    if (fabs(s * m - 1) <= 4e-7) {
        memcpy(v, orig, (size_t)n * sizeof *v);
        return 1;
    }
    for (int i = 0; i < n; i++) v[i] /= s;
    return 1;
}

static void proto_copy3(float *dst, const double *src) {
    for (int i = 0; i < 3; i++) dst[i] = (float)src[i];
}

/* Reads a required-object field; *out NULL when absent and optional. */
static int proto_object(const cJSON *obj, const char *key, const char *base, int required, const cJSON **out,
                        char p[PROTO_PTR_MAX], lc_proto_error *err) {
    proto_ptr(p, base, key);
    *out = cJSON_GetObjectItemCaseSensitive(obj, key);
    if (!*out) return proto_missing(required, p, err);
    if (!cJSON_IsObject(*out)) return proto_fail(err, LC_ERR_INVALID, p, "%s must be an object", p);
    return 1;
}

/* --- message parts ---------------------------------------------------------------------- */

/* §4.3 */
static int proto_parse_light(const cJSON *o, const char *p, lc_proto_light *L, lc_proto_error *err) {
    char q[PROTO_PTR_MAX];
    double v[3], d;
    int k, r;
    memset(L, 0, sizeof *L);
    if (proto_str(o, "id", p, 1, 1, LC_PROTO_ID_MAX, L->id, sizeof L->id, err) < 0) return -1;
    if (proto_enum(o, "type", p, 1, proto_light_type_names, 4, &k, err) < 0) return -1;
    L->type = (lc_proto_light_type)k;
    if ((r = proto_vec(o, "color", p, 0, 3, 0, 1e6, v, err)) < 0) return -1;
    if (r) proto_copy3(L->color, v);
    else L->color[0] = L->color[1] = L->color[2] = 1;
    d = 1;
    if (proto_num(o, "intensity", p, 0, 0, 1e9, &d, err) < 0) return -1;
    L->intensity = (float)d;
    d = 0;
    if (proto_num(o, "range", p, 0, 0, 1e6, &d, err) < 0) return -1;
    L->range = (float)d;
    if ((r = proto_vec(o, "position", p, L->type != LC_PLIGHT_DIRECTIONAL, 3, -1e6, 1e6, v, err)) < 0) return -1;
    if (r) proto_copy3(L->position, v);
    if ((r = proto_vec(o, "direction", p, L->type != LC_PLIGHT_POINT, 3, -1e300, 1e300, v, err)) < 0) return -1;
    if (r) {
        proto_ptr(q, p, "direction");
        if (!proto_normalise(v, 3)) return proto_fail(err, LC_ERR_OUT_OF_RANGE, q, "%s must not be zero", q);
        proto_copy3(L->direction, v);
    }
    double inner = 0, outer;
    if (proto_num(o, "innerConeAngle", p, 0, 0, PROTO_HALF_PI + PROTO_ANGLE_SLACK, &inner, err) < 0) return -1;
    inner = fmin(inner, PROTO_HALF_PI);
    outer = fmax(PROTO_HALF_PI / 2, inner); /* default π/4, or the inner angle when that is wider */
    if (proto_num(o, "outerConeAngle", p, 0, inner, PROTO_HALF_PI + PROTO_ANGLE_SLACK, &outer, err) < 0) return -1;
    L->inner_cone = (float)inner;
    L->outer_cone = (float)fmin(outer, PROTO_HALF_PI);
    k = 0;
    if (proto_enum(o, "shape", p, 0, proto_shape_names, 2, &k, err) < 0) return -1;
    L->shape = k;
    int n_size = L->shape == 1 ? 1 : 2;
    if ((r = proto_vec(o, "size", p, L->type == LC_PLIGHT_AREA, n_size, -INFINITY, INFINITY, v, err)) < 0) return -1;
    if (r) {
        for (int i = 0; i < n_size; i++) {
            proto_ptr(q, p, "size");
            char qe[PROTO_PTR_MAX];
            proto_ptr_index(qe, q, i);
            if (!(v[i] > 0 && v[i] <= 1e4))
                return proto_fail(err, LC_ERR_OUT_OF_RANGE, qe, "%s must be in (0, 1e4]", qe);
        }
        L->size[0] = (float)v[0];
        L->size[1] = n_size == 2 ? (float)v[1] : 0;
    } else {
        L->size[0] = 1;
        L->size[1] = n_size == 2 ? 1 : 0;
    }
    if ((r = proto_vec(o, "tangent", p, 0, 3, -1e300, 1e300, v, err)) < 0) return -1;
    if (r && proto_normalise(v, 3)) proto_copy3(L->tangent, v); /* zero = "any perpendicular" */
    return 0;
}

/* §4.5 */
static int proto_parse_object(const cJSON *o, const char *p, lc_proto_object *O, lc_proto_error *err) {
    char q[PROTO_PTR_MAX], qe[PROTO_PTR_MAX];
    double v[4];
    int r;
    memset(O, 0, sizeof *O);
    if (proto_str(o, "id", p, 1, 1, LC_PROTO_ID_MAX, O->id, sizeof O->id, err) < 0) return -1;
    if (proto_str(o, "asset", p, 1, 1, LC_PROTO_ID_MAX, O->asset, sizeof O->asset, err) < 0) return -1;
    if ((r = proto_vec(o, "translation", p, 0, 3, -1e6, 1e6, v, err)) < 0) return -1;
    if (r) proto_copy3(O->translation, v);
    if ((r = proto_vec(o, "rotation", p, 0, 4, -1e300, 1e300, v, err)) < 0) return -1;
    if (r) {
        proto_ptr(q, p, "rotation");
        if (!proto_normalise(v, 4)) return proto_fail(err, LC_ERR_OUT_OF_RANGE, q, "%s must not be zero", q);
        for (int i = 0; i < 4; i++) O->rotation[i] = (float)v[i];
    } else {
        O->rotation[3] = 1;
    }
    if ((r = proto_vec(o, "scale", p, 0, 3, -1e4, 1e4, v, err)) < 0) return -1;
    if (r) {
        proto_ptr(q, p, "scale");
        for (int i = 0; i < 3; i++) {
            proto_ptr_index(qe, q, i);
            if (fabs(v[i]) < 1e-6) return proto_fail(err, LC_ERR_OUT_OF_RANGE, qe, "|%s| must be in [1e-6, 1e4]", qe);
        }
        proto_copy3(O->scale, v);
    } else {
        O->scale[0] = O->scale[1] = O->scale[2] = 1;
    }
    O->visible = 1;
    if (proto_bool(o, "visible", p, 0, &O->visible, err) < 0) return -1;
    O->dnrt = 1;
    if (proto_bool(o, "dnrt", p, 0, &O->dnrt, err) < 0) return -1;
    O->mode = LC_OBJECT_MODE_DYNAMIC;
    if (proto_enum(o, "mode", p, 0, proto_mode_names, 3, &O->mode, err) < 0) return -1;
    return 0;
}

/* §4.8 */
static int proto_parse_environment(const cJSON *o, const char *p, lc_proto_environment *E, lc_proto_error *err) {
    double v[27];
    int r, k;
    memset(E, 0, sizeof *E);
    if (proto_enum(o, "type", p, 1, proto_env_names, 3, &k, err) < 0) return -1;
    E->kind = k;
    if ((r = proto_vec(o, "color", p, 0, 3, 0, 1e6, v, err)) < 0) return -1;
    if (r) proto_copy3(E->color, v);
    else E->color[0] = E->color[1] = E->color[2] = 1;
    if ((r = proto_vec(o, "sh", p, E->kind == 2, 27, -1e7, 1e7, v, err)) < 0) return -1;
    if (r)
        for (int i = 0; i < 27; i++) E->sh[i] = (float)v[i];
    double d = 1;
    if (proto_num(o, "intensity", p, 0, 0, 1e7, &d, err) < 0) return -1;
    E->intensity = (float)d;
    return 0;
}

/* §4.9 */
static int proto_parse_settings(const cJSON *o, const char *p, lc_proto_settings *S, lc_proto_error *err) {
    int r;
    memset(S, 0, sizeof *S);
    if ((r = proto_uint(o, "bounces", p, 0, 0, 16, &S->bounces, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_BOUNCES;
    if ((r = proto_uint(o, "bands", p, 0, 1, 8, &S->bands, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_BANDS;
    if ((r = proto_bool(o, "progressive", p, 0, &S->progressive, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_PROGRESSIVE;
    if ((r = proto_bool(o, "chroma_compression", p, 0, &S->chroma_compression, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_CHROMA;
    uint32_t hi = (S->present & (1u << LC_SET_BANDS)) ? S->bands : 8; /* else the server checks */
    if ((r = proto_uint(o, "chroma_bands", p, 0, 1, hi, &S->chroma_bands, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_CHROMA_BANDS;
    if ((r = proto_bool(o, "dnrt", p, 0, &S->dnrt, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_DNRT;
    if ((r = proto_bool(o, "dnrt_blockers", p, 0, &S->dnrt_blockers, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_DNRT_BLOCKERS;
    /* which solvers the bake offers is the server's check (welcome.scene.solvers) */
    if ((r = proto_enum(o, "solver", p, 0, proto_solver_names, LC_PROTO_SOLVER_COUNT, &S->solver, err)) < 0) return -1;
    if (r) S->present |= 1u << LC_SET_SOLVER;
    return 0;
}

/* §3.2 hello; §8.1 capabilities. */
static int proto_parse_hello(const cJSON *m, lc_proto_request *out, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    if (proto_str(m, "client", "", 1, 1, LC_PROTO_NAME_MAX, out->client, sizeof out->client, err) < 0) return -1;
    if (proto_str(m, "token", "", 0, 0, LC_PROTO_TOKEN_MAX, out->token, sizeof out->token, err) < 0) return -1;
    const cJSON *enc = cJSON_GetObjectItemCaseSensitive(m, "encodings");
    if (enc) {
        if (!cJSON_IsArray(enc)) return proto_fail(err, LC_ERR_INVALID, "/encodings", "/encodings must be an array");
        int i = 0;
        for (const cJSON *e = enc->child; e; e = e->next, i++) {
            proto_ptr_index(p, "/encodings", i);
            if (proto_str_item(e, p, 0, PROTO_STR_MAX, NULL, 0, err) < 0) return -1;
            for (int k = 0; k < 3; k++) /* unknown names are ignored: newer clients list more */
                if (!strcmp(e->valuestring, proto_encoding_names[k])) out->encodings |= 1u << (k + 1);
        }
    }
    const cJSON *caps = cJSON_GetObjectItemCaseSensitive(m, "capabilities");
    if (!caps) return 0;
    if (!cJSON_IsArray(caps)) return proto_fail(err, LC_ERR_INVALID, "/capabilities", "/capabilities must be an array");
    int n = cJSON_GetArraySize(caps);
    if (n > LC_PROTO_CAPS_MAX)
        return proto_fail(err, LC_ERR_INVALID, "/capabilities", "/capabilities has %d names, at most %d", n,
                          LC_PROTO_CAPS_MAX);
    int i = 0;
    for (const cJSON *e = caps->child; e; e = e->next, i++) {
        proto_ptr_index(p, "/capabilities", i);
        if (proto_str_item(e, p, 1, LC_PROTO_CAP_NAME_MAX, NULL, 0, err) < 0) return -1;
        for (int k = 0; k < LC_CAP_COUNT; k++) /* unknown names are ignored (§8.1) */
            if (!strcmp(e->valuestring, proto_capability_names[k])) out->capabilities |= 1u << k;
    }
    return 0;
}

/* §8.2 mr.begin "session": objects (1..16 distinct ids), image size and encodings, tuning. */
static int proto_parse_mr_session(const cJSON *o, const char *p, lc_proto_mr_session *S, lc_proto_error *err) {
    char q[PROTO_PTR_MAX], qe[PROTO_PTR_MAX];
    int k;
    memset(S, 0, sizeof *S);
    proto_ptr(q, p, "objects");
    const cJSON *objs = cJSON_GetObjectItemCaseSensitive(o, "objects");
    if (!objs) return proto_fail(err, LC_ERR_INVALID, q, "%s is required", q);
    int n = cJSON_IsArray(objs) ? cJSON_GetArraySize(objs) : -1;
    if (n < 1 || n > LC_PROTO_MR_OBJECTS_MAX)
        return proto_fail(err, LC_ERR_INVALID, q, "%s must be an array of 1..%d object ids", q,
                          LC_PROTO_MR_OBJECTS_MAX);
    int i = 0;
    for (const cJSON *e = objs->child; e; e = e->next, i++) {
        proto_ptr_index(qe, q, i);
        if (proto_str_item(e, qe, 1, LC_PROTO_ID_MAX, S->objects[i], sizeof S->objects[i], err) < 0) return -1;
        for (int j = 0; j < i; j++)
            if (!strcmp(S->objects[j], S->objects[i]))
                return proto_fail(err, LC_ERR_INVALID, qe, "%s repeats %s/%d", qe, q, j);
        S->n_objects = (uint32_t)i + 1;
    }
    if (proto_uint(o, "width", p, 1, LC_PROTO_MR_SIDE_MIN, LC_PROTO_MR_SIDE_MAX, &S->width, err) < 0) return -1;
    if (proto_uint(o, "height", p, 1, LC_PROTO_MR_SIDE_MIN, LC_PROTO_MR_SIDE_MAX, &S->height, err) < 0) return -1;
    if ((uint64_t)S->width * S->height > LC_PROTO_MR_PIXELS_MAX) {
        proto_ptr(q, p, "height");
        return proto_fail(err, LC_ERR_OUT_OF_RANGE, q, "%s: width * height must be at most %u", q,
                          LC_PROTO_MR_PIXELS_MAX);
    }
    if (proto_enum(o, "depth", p, 1, proto_depth_names, 2, &k, err) < 0) return -1;
    S->depth_encoding = k + 1;
    if (proto_enum(o, "color", p, 1, proto_color_names, 2, &k, err) < 0) return -1;
    S->color_encoding = k + 1;
    S->max_rate = 10;
    if (proto_num(o, "max_rate", p, 0, 0.1, 60, &S->max_rate, err) < 0) return -1;
    S->glossy = 1;
    if (proto_bool(o, "glossy", p, 0, &S->glossy, err) < 0) return -1;
    S->specular_exponent = 16;
    if (proto_num(o, "specular_exponent", p, 0, 1, 10000, &S->specular_exponent, err) < 0) return -1;
    S->min_confidence = 0.5;
    if (proto_num(o, "min_confidence", p, 0, 0, 1, &S->min_confidence, err) < 0) return -1;
    S->smoothing = 0;
    if (proto_num(o, "smoothing", p, 0, 0, 0.99, &S->smoothing, err) < 0) return -1;
    k = 0;
    if (proto_enum(o, "light", p, 0, proto_mr_light_names, 2, &k, err) < 0) return -1;
    S->light_add = k;
    return 0;
}

/* One change (§4.3-4.9) from message or batch op m; base "" or "/ops/i". */
static int proto_parse_op(const cJSON *m, const char *base, lc_req_type t, lc_proto_op *op, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    const cJSON *sub;
    double v[3];
    memset(op, 0, sizeof *op);
    op->type = t;
    switch (t) {
    case LC_REQ_LIGHT_SET:
        if (proto_object(m, "light", base, 1, &sub, p, err) < 0) return -1;
        if (proto_parse_light(sub, p, &op->light, err) < 0) return -1;
        memcpy(op->target, op->light.id, sizeof op->target);
        return 0;
    case LC_REQ_LIGHT_REMOVE:
        return proto_str(m, "light_id", base, 1, 1, LC_PROTO_ID_MAX, op->target, sizeof op->target, err) < 0 ? -1 : 0;
    case LC_REQ_OBJECT_SET:
        if (proto_object(m, "object", base, 1, &sub, p, err) < 0) return -1;
        if (proto_parse_object(sub, p, &op->object, err) < 0) return -1;
        memcpy(op->target, op->object.id, sizeof op->target);
        return 0;
    case LC_REQ_OBJECT_REMOVE:
        return proto_str(m, "object_id", base, 1, 1, LC_PROTO_ID_MAX, op->target, sizeof op->target, err) < 0 ? -1 : 0;
    case LC_REQ_MATERIAL_SET:
        if (proto_str(m, "material", base, 1, 1, LC_PROTO_ID_MAX, op->target, sizeof op->target, err) < 0) return -1;
        if (proto_vec(m, "emission", base, 1, 3, 0, 1e7, v, err) < 0) return -1;
        proto_copy3(op->emission, v);
        return 0;
    case LC_REQ_ENVIRONMENT_SET:
        if (proto_object(m, "environment", base, 1, &sub, p, err) < 0) return -1;
        return proto_parse_environment(sub, p, &op->environment, err);
    case LC_REQ_SETTINGS_SET:
        if (proto_object(m, "settings", base, 1, &sub, p, err) < 0) return -1;
        return proto_parse_settings(sub, p, &op->settings, err);
    default: return proto_fail(err, LC_ERR_INVALID, base, "not a change request");
    }
}

static int proto_type_of(const char *s, lc_req_type *t) {
    for (int k = 0; k < LC_REQ_COUNT; k++)
        if (!strcmp(s, proto_type_names[k])) {
            *t = (lc_req_type)k;
            return 0;
        }
    return -1;
}

/* `type` of message / op m: unknown_type when missing, not a string or unknown. */
static int proto_read_type(const cJSON *m, const char *base, lc_req_type *t, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, base, "type");
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(m, "type");
    if (!cJSON_IsString(it) || !it->valuestring) return proto_fail(err, LC_ERR_UNKNOWN_TYPE, p, "missing type");
    if (proto_type_of(it->valuestring, t) < 0) {
        char q[PROTO_QUOTE_MAX + 4];
        return proto_fail(err, LC_ERR_UNKNOWN_TYPE, p, "unknown type \"%s\"", proto_quote(q, it->valuestring));
    }
    return 0;
}

/* §2.5 request id. */
static int proto_read_id(const cJSON *m, lc_proto_id *id, lc_proto_error *err) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(m, "id");
    memset(id, 0, sizeof *id);
    if (!it) return 0;
    if (cJSON_IsString(it)) {
        if (proto_str_item(it, "/id", 1, LC_PROTO_ID_MAX, id->str, sizeof id->str, err) < 0) return -1;
        id->kind = 1;
        return 0;
    }
    if (!cJSON_IsNumber(it)) return proto_fail(err, LC_ERR_INVALID, "/id", "/id must be a string or an integer");
    double v = it->valuedouble;
    if (isfinite(v) && v != floor(v)) return proto_fail(err, LC_ERR_INVALID, "/id", "/id must be an integer");
    if (!(v >= 0 && v < PROTO_TWO_53)) return proto_fail(err, LC_ERR_OUT_OF_RANGE, "/id", "/id must be in [0, 2^53)");
    id->kind = 2;
    id->num = (int64_t)v;
    return 0;
}

/* --- requests --------------------------------------------------------------------------- */

static int proto_parse_body(const cJSON *m, const lc_proto_limits *lim, lc_proto_request *out, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    int k, r;
    switch (out->type) {
    case LC_REQ_HELLO: return proto_parse_hello(m, out, err);
    case LC_REQ_SUBSCRIBE:
    case LC_REQ_UNSUBSCRIBE:
        if (proto_enum(m, "stream", "", 1, proto_stream_names, LC_STREAM_MAX, &k, err) < 0) return -1;
        out->stream = (lc_stream)(k + 1);
        out->encoding = out->stream == LC_STREAM_LIGHTMAP ? LC_ENC_RGB9E5 : LC_ENC_F32;
        if (out->type == LC_REQ_UNSUBSCRIBE) return 0;
        if ((r = proto_enum(m, "encoding", "", 0, proto_encoding_names, 3, &k, err)) < 0) return -1;
        if (r) {
            if (k == 0 && out->stream != LC_STREAM_LIGHTMAP)
                return proto_fail(err, LC_ERR_INVALID, "/encoding", "rgb9e5 is for the lightmap stream only");
            out->encoding = (lc_encoding)(k + 1);
        }
        if (proto_num(m, "max_rate", "", 0, 0.1, 120, &out->max_rate, err) < 0) return -1;
        if ((r = proto_enum(m, "delta", "", 0, proto_delta_names, 2, &k, err)) < 0) return -1;
        if (r && out->stream != LC_STREAM_LIGHTMAP)
            return proto_fail(err, LC_ERR_INVALID, "/delta", "delta is for the lightmap stream only");
        out->residual = r && k == 1;
        return 0;
    case LC_REQ_BATCH: {
        const cJSON *ops = cJSON_GetObjectItemCaseSensitive(m, "ops");
        if (!ops) return proto_fail(err, LC_ERR_INVALID, "/ops", "/ops is required");
        if (!cJSON_IsArray(ops)) return proto_fail(err, LC_ERR_INVALID, "/ops", "/ops must be an array");
        int n = cJSON_GetArraySize(ops);
        if (n < 1) return proto_fail(err, LC_ERR_INVALID, "/ops", "a batch needs at least one op");
        if ((uint32_t)n > lim->max_batch)
            return proto_fail(err, LC_ERR_LIMIT_EXCEEDED, "/ops", "%d ops, at most %u per batch", n, lim->max_batch);
        out->ops = calloc((size_t)n, sizeof *out->ops);
        if (!out->ops) return proto_fail(err, LC_ERR_INTERNAL, "", "out of memory");
        int i = 0;
        for (const cJSON *op = ops->child; op; op = op->next, i++) {
            char base[PROTO_PTR_MAX];
            lc_req_type t;
            proto_ptr_index(base, "/ops", i);
            if (!cJSON_IsObject(op)) return proto_fail(err, LC_ERR_INVALID, base, "%s must be an object", base);
            if (proto_read_type(op, base, &t, err) < 0) return -1;
            if (!lc_proto_is_change(t) || t == LC_REQ_BATCH) {
                proto_ptr(p, base, "type");
                return proto_fail(err, LC_ERR_INVALID, p, "%s: %s is not allowed in a batch", p, proto_type_names[t]);
            }
            if (proto_parse_op(op, base, t, &out->ops[i], err) < 0) return -1;
            out->n_ops = (uint32_t)i + 1;
        }
        return 0;
    }
    case LC_REQ_MR_BEGIN: {
        const cJSON *sub;
        if (proto_object(m, "session", "", 1, &sub, p, err) < 0) return -1;
        return proto_parse_mr_session(sub, p, &out->mr, err);
    }
    case LC_REQ_STATE_GET:
    case LC_REQ_SNAPSHOT:
    case LC_REQ_MR_END: return 0;
    case LC_REQ_PING: return proto_num(m, "t", "", 1, -INFINITY, INFINITY, &out->ping_t, err) < 0 ? -1 : 0;
    default:
        out->ops = calloc(1, sizeof *out->ops);
        if (!out->ops) return proto_fail(err, LC_ERR_INTERNAL, "", "out of memory");
        if (proto_parse_op(m, "", out->type, &out->ops[0], err) < 0) return -1;
        out->n_ops = 1;
        return 0;
    }
}

int lc_proto_parse_request(const char *text, size_t len, const lc_proto_limits *lim, lc_proto_request *out,
                           lc_proto_error *err) {
    lc_proto_error scratch;
    lc_proto_limits deflim;
    cJSON *root = NULL;
    int flags;
    if (!err) err = &scratch;
    memset(err, 0, sizeof *err);
    memset(out, 0, sizeof *out);
    if (!lim) {
        lc_proto_default_limits(&deflim);
        lim = &deflim;
    }
    if (len > lim->max_message) {
        proto_error(err, LC_ERR_TOO_LARGE, "", "message of %zu bytes, at most %zu", len, lim->max_message);
        goto err;
    }
    if (proto_load(text, len, lim->max_depth, &root, &flags, err) < 0) goto err;
    /* cJSON ends a string at its first NUL: an id with a \u0000 would be echoed cut short */
    if (flags & PROTO_SCAN_NUL_IN_ID) {
        proto_error(err, LC_ERR_INVALID, "/id", "/id must not contain \\u0000");
        goto err;
    }
    if (proto_read_id(root, &out->id, err) < 0) goto err;
    if (flags & PROTO_SCAN_NUL_ESCAPE) { /* after the id, so the error echoes it */
        proto_error(err, LC_ERR_INVALID, "", "strings must not contain \\u0000");
        goto err;
    }
    if (proto_read_type(root, "", &out->type, err) < 0) goto err;
    if (proto_parse_body(root, lim, out, err) < 0) goto err;
    if (flags & PROTO_SCAN_BAD_UTF8) {
        proto_error(err, LC_ERR_INVALID, "", "a string is not valid UTF-8");
        goto err;
    }
    cJSON_Delete(root);
    return 0;
err:
    cJSON_Delete(root);
    lc_proto_request_release(out); /* keeps out->id so the error can echo it */
    return -1;
}

void lc_proto_request_release(lc_proto_request *r) {
    if (!r) return;
    free(r->ops);
    r->ops = NULL;
    r->n_ops = 0;
}

/* --- state (snapshot file, §5.4) ------------------------------------------------------- */

/* Array field `key` of root; returns its size or -1. */
static int proto_array(const cJSON *root, const char *key, const cJSON **arr, lc_proto_error *err) {
    char p[PROTO_PTR_MAX];
    proto_ptr(p, "", key);
    *arr = cJSON_GetObjectItemCaseSensitive(root, key);
    if (!cJSON_IsArray(*arr)) return proto_fail(err, LC_ERR_INVALID, p, "%s must be an array", p);
    return cJSON_GetArraySize(*arr);
}

int lc_proto_parse_state(const char *text, size_t len, lc_proto_parsed_state *out, lc_proto_error *err) {
    lc_proto_error scratch;
    cJSON *root = NULL;
    const cJSON *arr, *sub, *it;
    char p[PROTO_PTR_MAX], q[PROTO_PTR_MAX];
    int flags, n, i;
    double rev;
    if (!err) err = &scratch;
    memset(err, 0, sizeof *err);
    memset(out, 0, sizeof *out);
    if (proto_load(text, len, 16, &root, &flags, err) < 0) goto err;
    if (flags & PROTO_SCAN_NUL_ESCAPE) {
        proto_error(err, LC_ERR_INVALID, "", "strings must not contain \\u0000");
        goto err;
    }
    it = cJSON_GetObjectItemCaseSensitive(root, "type");
    if (!cJSON_IsString(it) || strcmp(it->valuestring, "state")) {
        proto_error(err, LC_ERR_UNKNOWN_TYPE, "/type", "not a state message");
        goto err;
    }
    if (proto_num(root, "revision", "", 1, 0, PROTO_TWO_53 - 1, &rev, err) < 0) goto err;
    if (rev != floor(rev)) {
        proto_error(err, LC_ERR_INVALID, "/revision", "/revision must be an integer");
        goto err;
    }
    out->revision = (uint64_t)rev;

    if ((n = proto_array(root, "lights", &arr, err)) < 0) goto err;
    if (n && !(out->lights = calloc((size_t)n, sizeof *out->lights))) goto oom;
    i = 0;
    for (it = arr->child; it; it = it->next, i++) {
        proto_ptr_index(p, "/lights", i);
        if (!cJSON_IsObject(it)) {
            proto_error(err, LC_ERR_INVALID, p, "%s must be an object", p);
            goto err;
        }
        if (proto_parse_light(it, p, &out->lights[i], err) < 0) goto err;
        if (i && strcmp(out->lights[i - 1].id, out->lights[i].id) >= 0) { /* sorted, unique */
            proto_ptr(q, p, "id");
            proto_error(err, LC_ERR_INVALID, q, "lights must be sorted by id without duplicates");
            goto err;
        }
        out->n_lights = (uint32_t)i + 1;
    }

    if ((n = proto_array(root, "objects", &arr, err)) < 0) goto err;
    if (n && !(out->objects = calloc((size_t)n, sizeof *out->objects))) goto oom;
    i = 0;
    for (it = arr->child; it; it = it->next, i++) {
        proto_ptr_index(p, "/objects", i);
        if (!cJSON_IsObject(it)) {
            proto_error(err, LC_ERR_INVALID, p, "%s must be an object", p);
            goto err;
        }
        if (proto_parse_object(it, p, &out->objects[i], err) < 0) goto err;
        if (i && strcmp(out->objects[i - 1].id, out->objects[i].id) >= 0) {
            proto_ptr(q, p, "id");
            proto_error(err, LC_ERR_INVALID, q, "objects must be sorted by id without duplicates");
            goto err;
        }
        out->n_objects = (uint32_t)i + 1;
    }

    if ((n = proto_array(root, "materials", &arr, err)) < 0) goto err;
    if (n && !(out->material_names = calloc((size_t)n, sizeof *out->material_names))) goto oom;
    if (n && !(out->material_emission = calloc((size_t)n, sizeof *out->material_emission))) goto oom;
    i = 0;
    for (it = arr->child; it; it = it->next, i++) {
        double v[3];
        proto_ptr_index(p, "/materials", i);
        if (!cJSON_IsObject(it)) {
            proto_error(err, LC_ERR_INVALID, p, "%s must be an object", p);
            goto err;
        }
        if (proto_str(it, "name", p, 1, 1, LC_PROTO_ID_MAX, out->material_names[i], LC_PROTO_ID_MAX + 1, err) < 0)
            goto err;
        if (proto_vec(it, "emission", p, 1, 3, 0, 1e7, v, err) < 0) goto err;
        proto_copy3(out->material_emission[i], v);
        out->n_materials = (uint32_t)i + 1;
    }

    if (proto_object(root, "environment", "", 1, &sub, p, err) < 0) goto err;
    if (proto_parse_environment(sub, p, &out->environment, err) < 0) goto err;
    if (proto_object(root, "settings", "", 1, &sub, p, err) < 0) goto err;
    if (proto_parse_settings(sub, p, &out->settings, err) < 0) goto err;
    if (flags & PROTO_SCAN_BAD_UTF8) {
        proto_error(err, LC_ERR_INVALID, "", "a string is not valid UTF-8");
        goto err;
    }
    cJSON_Delete(root);
    return 0;
oom:
    proto_error(err, LC_ERR_INTERNAL, "", "out of memory");
err:
    cJSON_Delete(root);
    lc_proto_parsed_state_free(out);
    return -1;
}

void lc_proto_parsed_state_free(lc_proto_parsed_state *s) {
    if (!s) return;
    free(s->lights);
    free(s->objects);
    free(s->material_names);
    free(s->material_emission);
    memset(s, 0, sizeof *s);
}
