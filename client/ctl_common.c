/* lucentctl helpers shared by the command files: number parsing, the flag table, connecting,
 * requests and the server-error messages (see ctl.h). */
#include "ctl.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

/* Global options (ctl.h): defaults here, set by main before dispatch. */
const char *ctl_url = "ws://127.0.0.1:7700/";
const char *ctl_token = "";
int ctl_insecure = 0;
const char *ctl_ca_file = NULL;
int ctl_json = 0;

#define CTL_ERR_MAX 512
#define CTL_STRING_MAX 256 /* PROTOCOL.md §1.3: longest string field */

int ctl_usage_error(const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    char msg[1024];
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    /* messages start with the command ("light set: ..."): point at that command's help */
    size_t n = strcspn(msg, ":");
    int is_cmd = msg[n] == ':' && n > 0 && n < 32;
    for (size_t i = 0; is_cmd && i < n; i++)
        if (!((msg[i] >= 'a' && msg[i] <= 'z') || msg[i] == ' ')) is_cmd = 0;
    if (is_cmd) fprintf(stderr, "lucentctl: %s\n(see 'lucentctl %.*s --help')\n", msg, (int)n, msg);
    else fprintf(stderr, "lucentctl: %s\n(see 'lucentctl --help')\n", msg);
    return CTL_EXIT_USAGE;
}

int ctl_wants_help(int argc, char **argv) {
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--") == 0) return 0; /* after "--" everything is an operand */
        if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) return 1;
    }
    return 0;
}

/* --- numbers ---------------------------------------------------------------------------- */

int ctl_parse_double(const char *s, double *out) {
    /* strtod skips leading blanks and accepts "inf"/"nan": be stricter than that */
    if (!s || !*s || *s == ' ' || *s == '\t' || *s == '\n') return -1;
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end || !isfinite(v)) return -1;
    if (errno == ERANGE && fabs(v) > 1) return -1; /* overflow; underflow to ~0 is fine */
    *out = v;
    return 0;
}

int ctl_parse_int(const char *s, long long lo, long long hi, long long *out) {
    if (!s || !*s || !(*s == '-' || *s == '+' || (*s >= '0' && *s <= '9'))) return -1;
    char *end;
    errno = 0;
    long long v = strtoll(s, &end, 10);
    if (end == s || *end || errno == ERANGE || v < lo || v > hi) return -1;
    *out = v;
    return 0;
}

int ctl_parse_bool(const char *s, int *out) {
    static const char *const yes[] = {"true", "1", "yes", "on"};
    static const char *const no[] = {"false", "0", "no", "off"};
    if (!s) return -1;
    for (int i = 0; i < 4; i++) {
        if (strcmp(s, yes[i]) == 0) {
            *out = 1;
            return 0;
        }
        if (strcmp(s, no[i]) == 0) {
            *out = 0;
            return 0;
        }
    }
    return -1;
}

int ctl_parse_float_list(const char *s, double *out, int max, int *n) {
    char buf[64];
    int k = 0;
    if (!s || !*s) return -1;
    for (const char *p = s;;) {
        const char *comma = strchr(p, ',');
        size_t len = comma ? (size_t)(comma - p) : strlen(p);
        if (k >= max || len == 0 || len >= sizeof buf) return -1;
        memcpy(buf, p, len);
        buf[len] = 0;
        if (ctl_parse_double(buf, &out[k]) != 0) return -1;
        k++;
        if (!comma) break;
        p = comma + 1;
    }
    *n = k;
    return 0;
}

int ctl_parse_floats(const char *s, double *out, int n) {
    int got;
    if (n < 1 || ctl_parse_float_list(s, out, n, &got) != 0 || got != n) return -1;
    return 0;
}

/* --- server errors ---------------------------------------------------------------------- */

/* One hint per stable code of PROTOCOL.md §5.2 (what to do about it, not what it means). */
static const struct {
    const char *code, *hint;
} ctl_hints[] = {
    {"bad_json", "the message is not a JSON object; check the quoting (wrap JSON in single quotes in a shell)"},
    {"bad_utf8", "the text is not valid UTF-8; fix the file's encoding (the server closed the connection)"},
    {"too_large",
     "the message is over the server's size limit (welcome limits.max_message); split it, e.g. a batch into "
     "several (the server closed the connection)"},
    {"too_deep", "the JSON nests deeper than the server allows (16 levels); flatten the message"},
    {"hello_required", "the server expected hello first; is this URL a lucent/1 server? (the connection closed)"},
    {"unauthorized", "the server does not know this token; pass a valid one with --token or LUCENT_TOKEN"},
    {"unknown_type", "\"type\" is missing or not a lucent/1 message type; see PROTOCOL.md §4"},
    {"invalid",
     "the field at the pointer is missing, has the wrong type, is too long or names something the server does "
     "not offer (a solver not in welcome scene.solvers); see PROTOCOL.md §4 for its form"},
    {"out_of_range", "the number at the pointer is not finite or outside its range; see PROTOCOL.md §4 for ranges"},
    {"forbidden", "this token has the viewer role; use a controller token (--token / LUCENT_TOKEN)"},
    {"unknown_id", "no light or object has that id; 'lucentctl state' lists them"},
    {"unknown_asset",
     "the scene has no such asset; the welcome lists scene.assets (lucent-bake --asset NAME=FILE adds one)"},
    {"unknown_material", "the scene has no such material; 'lucentctl state' lists the materials"},
    {"limit_exceeded", "too many lights, objects or batch ops (welcome limits); remove some first or split the batch"},
    {"rate_limited",
     "over the server's request rate (welcome limits.rate per second); slow down (script --speed) or raise "
     "lucentd --rate"},
    {"binary_not_allowed", "clients must send JSON as text frames, never binary frames"},
    {"internal", "the server failed (see its log); retry, and report it if it persists"},
    {"frame_invalid",
     "the upload frame breaks PROTOCOL.md §8.4 at the pointer (header field, plane size, zlib stream or CRC); "
     "check the recording's files"},
    {"frame_too_large",
     "the upload frame is over the session's max_frame (mr.begin's reply); compress the planes "
     "(--zlib) or record at a smaller size"},
    {"mr_not_enabled",
     "the server grants MR sessions to controllers only, with lucentd --mr on and a bake with sparse points "
     "(lucent-bake --mr-points); send mr.begin before upload frames"},
};

const char *ctl_error_hint(const char *code) {
    for (size_t i = 0; code && i < sizeof ctl_hints / sizeof ctl_hints[0]; i++)
        if (strcmp(code, ctl_hints[i].code) == 0) return ctl_hints[i].hint;
    return "an error code this lucentctl does not know; see PROTOCOL.md §5.2 of the server's version";
}

void ctl_format_server_error(const char *reply_json, char *buf, size_t buflen) {
    if (!buf || !buflen) return;
    cJSON *o = reply_json ? cJSON_Parse(reply_json) : NULL;
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(o, "code");
    const cJSON *ptr = cJSON_GetObjectItemCaseSensitive(o, "pointer");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(o, "message");
    const char *c = cJSON_IsString(code) ? code->valuestring : "?";
    const char *p = cJSON_IsString(ptr) ? ptr->valuestring : "";
    /* "" points at the whole message (RFC 6901); say so rather than print nothing */
    snprintf(buf, buflen, "server error %s at %s: %s (hint: %s)", c, *p ? p : "\"\" (the whole message)",
             cJSON_IsString(msg) ? msg->valuestring : "(no message)", ctl_error_hint(c));
    cJSON_Delete(o);
}

void ctl_print_server_error(const char *reply_json) {
    char buf[1024];
    ctl_format_server_error(reply_json, buf, sizeof buf);
    fprintf(stderr, "lucentctl: %s\n", buf);
}

long long ctl_reply_revision(const char *reply_json) {
    cJSON *o = reply_json ? cJSON_Parse(reply_json) : NULL;
    const cJSON *r = cJSON_GetObjectItemCaseSensitive(o, "revision");
    long long rev = -1;
    if (cJSON_IsNumber(r) && r->valuedouble >= 0 && r->valuedouble < 9007199254740992.0)
        rev = (long long)r->valuedouble;
    cJSON_Delete(o);
    return rev;
}

/* --- connection and requests ------------------------------------------------------------ */

lc_client *ctl_connect(const lc_client_options *opts, int *rc) {
    char err[CTL_ERR_MAX];
    lc_client *c;
    lc_client_options o;
    if (opts) o = *opts;
    else lc_client_options_init(&o);
    if (!o.url) o.url = ctl_url;
    if (!o.token) o.token = ctl_token;
    if (!o.name) o.name = "lucentctl";
    if (ctl_insecure) o.insecure = 1;
    if (!o.ca_file) o.ca_file = ctl_ca_file;
    if (!opts) o.timeout_ms = CTL_TIMEOUT_MS;
    c = lc_client_open(&o, err, sizeof err);
    if (c) return c;
    /* the library reports a refused hello as "server error CODE: message" */
    if (strncmp(err, "server error ", 13) == 0) {
        char code[64];
        size_t n = strcspn(err + 13, ": ");
        if (n >= sizeof code) n = sizeof code - 1;
        memcpy(code, err + 13, n);
        code[n] = 0;
        fprintf(stderr, "lucentctl: %s refused the connection: %s (hint: %s)\n", ctl_url, err, ctl_error_hint(code));
        *rc = CTL_EXIT_REFUSED;
    } else {
        if (strstr(err, ctl_url)) fprintf(stderr, "lucentctl: cannot connect: %s\n", err);
        else fprintf(stderr, "lucentctl: cannot connect to %s: %s\n", ctl_url, err);
        *rc = CTL_EXIT_CONN;
    }
    return NULL;
}

int ctl_request(lc_client *c, const char *json, char **reply) {
    char err[CTL_ERR_MAX];
    char *text = NULL;
    if (reply) *reply = NULL;
    int r = lc_client_request(c, json, &text, CTL_TIMEOUT_MS, err, sizeof err);
    if (r < 0) {
        fprintf(stderr, "lucentctl: %s: %s\n", ctl_url, err);
        free(text);
        return CTL_EXIT_CONN;
    }
    if (r == 1) {
        ctl_print_server_error(text);
        if (ctl_json && text) printf("%s\n", text);
        free(text);
        return CTL_EXIT_REFUSED;
    }
    if (reply) *reply = text;
    else free(text);
    return CTL_EXIT_OK;
}

/* Indented JSON with 2 spaces; arrays of scalars stay on one line (vectors, SH). */
static void ctl_pretty(const cJSON *it, int depth, FILE *out) {
    if (cJSON_IsObject(it) || cJSON_IsArray(it)) {
        int obj = cJSON_IsObject(it), flat = !obj;
        for (const cJSON *c = it->child; c && flat; c = c->next)
            if (cJSON_IsObject(c) || cJSON_IsArray(c)) flat = 0;
        if (!it->child || flat) {
            fputc(obj ? '{' : '[', out);
            for (const cJSON *c = it->child; c; c = c->next) {
                ctl_pretty(c, depth + 1, out);
                if (c->next) fputs(", ", out);
            }
            fputc(obj ? '}' : ']', out);
            return;
        }
        fputs(obj ? "{\n" : "[\n", out);
        for (const cJSON *c = it->child; c; c = c->next) {
            fprintf(out, "%*s", 2 * (depth + 1), "");
            if (obj) {
                cJSON *key = cJSON_CreateString(c->string ? c->string : "");
                char *k = key ? cJSON_PrintUnformatted(key) : NULL;
                fprintf(out, "%s: ", k ? k : "\"\"");
                free(k);
                cJSON_Delete(key);
            }
            ctl_pretty(c, depth + 1, out);
            fputs(c->next ? ",\n" : "\n", out);
        }
        fprintf(out, "%*s%c", 2 * depth, "", obj ? '}' : ']');
        return;
    }
    /* scalars: cJSON's own formatting (escapes, shortest round-trip numbers); printing a
     * detached copy keeps an object member's key out of it */
    cJSON *copy = cJSON_Duplicate(it, 0);
    char *t = copy ? cJSON_PrintUnformatted(copy) : NULL;
    fputs(t ? t : "null", out);
    free(t);
    cJSON_Delete(copy);
}

void ctl_print_json(const char *json, int compact) {
    cJSON *o = (ctl_json || compact) ? NULL : cJSON_Parse(json);
    if (!o) {
        printf("%s\n", json);
        return;
    }
    ctl_pretty(o, 0, stdout);
    fputc('\n', stdout);
    cJSON_Delete(o);
}

/* --- flag tables ------------------------------------------------------------------------ */

static const char *ctl_flag_kind_hint(const ctl_flag *f) {
    switch (f->kind) {
    case CTL_FLAG_NUM: return "a number";
    case CTL_FLAG_INT: return "an integer";
    case CTL_FLAG_BOOL: return "true or false";
    case CTL_FLAG_CHOICE: return f->choices;
    default: return f->metavar ? f->metavar : "a value";
    }
}

/* Converts one flag value into a JSON item, or NULL after printing the usage error. */
static cJSON *ctl_flag_value(const char *cmd, const ctl_flag *f, const char *val) {
    double v[32];
    long long iv;
    int b, n;
    switch (f->kind) {
    case CTL_FLAG_NUM:
        if (ctl_parse_double(val, &v[0]) == 0) return cJSON_CreateNumber(v[0]);
        break;
    case CTL_FLAG_INT:
        /* ±2^53: the integers a JSON number carries exactly; the server checks the range */
        if (ctl_parse_int(val, -9007199254740991LL, 9007199254740991LL, &iv) == 0)
            return cJSON_CreateNumber((double)iv);
        break;
    case CTL_FLAG_BOOL:
        if (ctl_parse_bool(val, &b) == 0) return cJSON_CreateBool(b);
        break;
    case CTL_FLAG_LIST:
        if (ctl_parse_float_list(val, v, 32, &n) == 0 && (f->counts >> n & 1ul)) {
            int max = 0;
            for (int k = 0; k < 32; k++)
                if (f->counts >> k & 1ul) max = k;
            if (f->expand && n == 1)
                for (n = 1; n < max; n++) v[n] = v[0];
            return cJSON_CreateDoubleArray(v, n);
        }
        {
            char counts[64] = "";
            size_t used = 0;
            for (int k = 1; k < 32; k++)
                if (f->counts >> k & 1ul)
                    used += (size_t)snprintf(counts + used, sizeof counts - used, "%s%d", used ? " or " : "", k);
            ctl_usage_error("%s: %s '%.80s': expected %s comma-separated numbers without spaces (%s)", cmd, f->name,
                            val, counts, f->metavar);
        }
        return NULL;
    case CTL_FLAG_CHOICE: {
        size_t len = strlen(val);
        for (const char *p = f->choices; *p;) {
            size_t n2 = strcspn(p, "|");
            if (n2 == len && strncmp(p, val, len) == 0) return cJSON_CreateString(val);
            p += n2;
            if (*p) p++;
        }
        break;
    }
    case CTL_FLAG_STRING:
        if (*val && strlen(val) <= CTL_STRING_MAX) return cJSON_CreateString(val);
        ctl_usage_error("%s: %s '%.64s': expected 1..%d bytes", cmd, f->name, val, CTL_STRING_MAX);
        return NULL;
    case CTL_FLAG_SWITCH: return cJSON_CreateTrue();
    }
    ctl_usage_error("%s: %s '%s': expected %s", cmd, f->name, val, ctl_flag_kind_hint(f));
    return NULL;
}

int ctl_parse_flags(const char *cmd, const ctl_flag *table, int argc, char **argv, int start, cJSON *into,
                    char **positional, int max_pos, int *n_pos) {
    int np = 0, flags_done = 0;
    for (int i = start; i < argc; i++) {
        const char *a = argv[i];
        if (flags_done || a[0] != '-' || a[1] == 0 || (a[1] != '-' && ((a[1] >= '0' && a[1] <= '9') || a[1] == '.'))) {
            /* operands: anything not a flag, "-", and negative numbers */
            if (np >= max_pos) return ctl_usage_error("%s: unexpected argument '%s'", cmd, a);
            positional[np++] = argv[i];
            continue;
        }
        if (strcmp(a, "--") == 0) {
            flags_done = 1;
            continue;
        }
        const char *eq = strchr(a, '=');
        size_t nlen = eq ? (size_t)(eq - a) : strlen(a);
        const ctl_flag *f = NULL;
        for (const ctl_flag *t = table; t && t->name; t++)
            if (strlen(t->name) == nlen && strncmp(t->name, a, nlen) == 0) f = t;
        if (!f) return ctl_usage_error("%s: unknown option '%.*s'", cmd, (int)nlen, a);
        const char *val;
        if (f->kind == CTL_FLAG_SWITCH) {
            if (eq) return ctl_usage_error("%s: %s takes no value", cmd, f->name);
            val = "";
        } else if (eq) {
            val = eq + 1;
        } else {
            if (i + 1 >= argc)
                return ctl_usage_error("%s: %s needs a value (%s)", cmd, f->name, f->metavar ? f->metavar : "");
            val = argv[++i];
        }
        if (cJSON_GetObjectItemCaseSensitive(into, f->key)) return ctl_usage_error("%s: %s given twice", cmd, f->name);
        cJSON *item = ctl_flag_value(cmd, f, val);
        if (!item) return CTL_EXIT_USAGE;
        cJSON_AddItemToObject(into, f->key, item);
    }
    *n_pos = np;
    return 0;
}

void ctl_print_flags(const ctl_flag *table, FILE *out) {
    for (const ctl_flag *f = table; f && f->name; f++) {
        char left[64];
        snprintf(left, sizeof left, "%s%s%s", f->name, f->kind == CTL_FLAG_SWITCH ? "" : " ",
                 f->kind == CTL_FLAG_SWITCH ? "" : (f->metavar ? f->metavar : ""));
        fprintf(out, "  %-28s %s\n", left, f->help);
    }
}
