/* lucentctl script: replays a JSON Lines file of lucent/1 messages on a schedule.
 *
 * Each non-blank line that does not start with '#' is one client message (light.set, batch,
 * ...) with an optional top-level "at": seconds from the start of the script (finite, >= 0,
 * never decreasing; a line without it is due with the line before). "at" is removed before
 * sending. The whole file is validated before connecting, so a typo on line 900 does not
 * leave a half-played animation behind. Messages go out at t0 + at / speed on the monotonic
 * clock: each is due at an absolute time, so a late send does not shift the ones after it. */
#include "ctl.h"
#include "util/sigflag.h"

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define CTL_SCRIPT_LINE_MAX (1u << 20)    /* bytes per line; far above any server's message limit */
#define CTL_SCRIPT_MSGS_MAX 1000000u      /* messages per file */
#define CTL_SCRIPT_BYTES_MAX (256u << 20) /* kept message text per file */
#define CTL_SCRIPT_AT_MAX 1e9             /* seconds; keeps at/speed well inside a timespec */
#define CTL_SCRIPT_SPEED_MIN 1e-3
#define CTL_SCRIPT_SPEED_MAX 1e6
#define CTL_SCRIPT_ERRORS_SHOWN 100 /* malformed lines reported before "... and N more" */

typedef struct ctl_script_msg {
    char *text;    /* compact JSON, "at" removed */
    double at;     /* seconds from the start of the script */
    long line;     /* 1-based line number in the file */
    char what[96]; /* "light.set key" for progress lines */
} ctl_script_msg;

typedef struct ctl_script {
    const char *name; /* as shown in messages: the path, or "<stdin>" */
    ctl_script_msg *msgs;
    size_t n, cap, bytes;
    long errors;
} ctl_script;

typedef struct ctl_script_opts {
    double speed;
    long long loops; /* 0 = forever */
    int keep_going, dry_run, verbose;
} ctl_script_opts;

static lc_sigflag ctl_script_stop;

static void ctl_script_on_signal(int sig) {
    (void)sig;
    ctl_script_stop = 1;
    signal(SIGINT, SIG_DFL); /* a second Ctrl-C ends it at once */
}

static void ctl_script_usage(FILE *f) {
    fprintf(f,
            "usage: lucentctl script FILE|- [--speed F] [--loop [N]] [--keep-going] [--dry-run] [--verbose]\n"
            "\n"
            "Replays JSON Lines: each non-blank line is one lucent/1 message (light.set, object.set,\n"
            "batch, ...; PROTOCOL.md §4) with an optional top-level \"at\": seconds from the start\n"
            "of the script (finite, >= 0, never decreasing), removed before sending. A line without\n"
            "\"at\" is sent right after the line before it. Lines starting with '#' are comments.\n"
            "The whole file is checked before connecting; malformed lines are reported as\n"
            "FILE:LINE: message (all of them, exit 2).\n"
            "\n"
            "  --speed F      time scale, > 0 (2 = twice as fast; default 1)\n"
            "  --loop [N]     play N times (default: forever); the clock restarts each time\n"
            "  --keep-going   report refused messages and go on; exit 1 at the end if any failed\n"
            "  --dry-run      only check the file (JSON, \"type\", \"at\"); no connection\n"
            "  --verbose, -v  one line per message sent (the default when stderr is a terminal)\n"
            "  --json         print every reply as a JSON line on stdout (summary on stderr)\n"
            "\n"
            "Stops at the first refused message (exit 1, FILE:LINE: server error ...) unless\n"
            "--keep-going; a lost connection ends it with exit 3 (FILE:LINE: connection lost: ...).\n"
            "Messages over the server's size limit (welcome limits.max_message) are reported\n"
            "before anything is sent (exit 2).\n"
            "Ctrl-C stops after the current message, prints the summary and exits 130.\n"
            "\n"
            "example line: {\"at\": 0.5, \"type\": \"light.set\", \"light\": {\"id\": \"k\", \"type\": \"point\",\n"
            "              \"position\": [0.28, 0.4, 0.28], \"intensity\": 0.5}}\n");
}

/* --- loading and validation ------------------------------------------------------------- */

static void ctl_script_error(ctl_script *s, long line, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static void ctl_script_error(ctl_script *s, long line, const char *fmt, ...) {
    if (s->errors++ >= CTL_SCRIPT_ERRORS_SHOWN) return;
    va_list ap;
    va_start(ap, fmt);
    fprintf(stderr, "%s:%ld: ", s->name, line);
    vfprintf(stderr, fmt, ap);
    fputc('\n', stderr);
    va_end(ap);
}

static const char *ctl_json_str(const cJSON *o, const char *key) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, key);
    return cJSON_IsString(it) ? it->valuestring : NULL;
}

/* "light.set key", "batch (3 ops)", ... for progress lines. */
static void ctl_script_describe(const cJSON *o, const char *type, char *buf, size_t len) {
    const char *id = NULL;
    const cJSON *body;
    if ((body = cJSON_GetObjectItemCaseSensitive(o, "light")) || (body = cJSON_GetObjectItemCaseSensitive(o, "object")))
        id = ctl_json_str(body, "id");
    if (!id) id = ctl_json_str(o, "light_id");
    if (!id) id = ctl_json_str(o, "object_id");
    if (!id) id = ctl_json_str(o, "material");
    const cJSON *ops = cJSON_GetObjectItemCaseSensitive(o, "ops");
    if (cJSON_IsArray(ops)) snprintf(buf, len, "%.40s (%d ops)", type, cJSON_GetArraySize(ops));
    else if (id) snprintf(buf, len, "%.40s %.48s", type, id);
    else snprintf(buf, len, "%.40s", type);
}

/* Checks one line and, when valid, appends its message. prev_at carries the last "at". */
static int ctl_script_line(ctl_script *s, char *line, size_t len, long lineno, double *prev_at) {
    cJSON *o = NULL;
    char *text = NULL;
    const char *end = NULL;
    o = cJSON_ParseWithLengthOpts(line, len, &end, 0);
    if (!o) {
        const char *e = cJSON_GetErrorPtr();
        long col = e && e >= line && e <= line + len ? (long)(e - line) + 1 : 0;
        ctl_script_error(s, lineno, "not valid JSON (near column %ld)", col);
        goto bad;
    }
    while (end && end < line + len && (*end == ' ' || *end == '\t')) end++;
    if (end && end < line + len) {
        ctl_script_error(s, lineno, "text after the JSON value (column %ld); one message per line",
                         (long)(end - line) + 1);
        goto bad;
    }
    if (!cJSON_IsObject(o)) {
        ctl_script_error(s, lineno, "expected a JSON object (one lucent/1 message)");
        goto bad;
    }
    const char *type = ctl_json_str(o, "type");
    if (!type || !*type) {
        ctl_script_error(s, lineno, "missing \"type\" (a string such as \"light.set\" or \"batch\")");
        goto bad;
    }
    double at = *prev_at;
    const cJSON *jat = cJSON_GetObjectItemCaseSensitive(o, "at");
    if (jat) {
        if (!cJSON_IsNumber(jat) || !isfinite(jat->valuedouble) || jat->valuedouble < 0 ||
            jat->valuedouble > CTL_SCRIPT_AT_MAX) {
            ctl_script_error(s, lineno, "\"at\" must be a finite number of seconds in [0, %g]", CTL_SCRIPT_AT_MAX);
            goto bad;
        }
        at = jat->valuedouble;
        if (at < *prev_at) {
            ctl_script_error(s, lineno, "\"at\" %g is before %g of an earlier line; times must not decrease", at,
                             *prev_at);
            goto bad;
        }
        while (cJSON_GetObjectItemCaseSensitive(o, "at")) cJSON_DeleteItemFromObjectCaseSensitive(o, "at");
    }
    *prev_at = at;
    if (s->n >= CTL_SCRIPT_MSGS_MAX) {
        ctl_script_error(s, lineno, "more than %u messages; split the script", CTL_SCRIPT_MSGS_MAX);
        goto bad;
    }
    text = cJSON_PrintUnformatted(o);
    if (!text) goto oom;
    size_t tl = strlen(text);
    if (s->bytes + tl > CTL_SCRIPT_BYTES_MAX) {
        ctl_script_error(s, lineno, "the script holds more than %u MiB of messages; split it",
                         CTL_SCRIPT_BYTES_MAX >> 20);
        goto bad;
    }
    if (s->n == s->cap) {
        size_t cap = s->cap ? s->cap * 2 : 64;
        ctl_script_msg *m = realloc(s->msgs, cap * sizeof *m);
        if (!m) goto oom;
        s->msgs = m;
        s->cap = cap;
    }
    ctl_script_msg *m = &s->msgs[s->n++];
    m->text = text;
    m->at = at;
    m->line = lineno;
    ctl_script_describe(o, type, m->what, sizeof m->what);
    s->bytes += tl;
    cJSON_Delete(o);
    return 0;
oom:
    fprintf(stderr, "lucentctl: out of memory reading %s\n", s->name);
    free(text);
    cJSON_Delete(o);
    return -1;
bad:
    free(text);
    cJSON_Delete(o);
    return 0;
}

/* Reads and validates the whole file. Returns 0 (s->errors counts malformed lines) or -1
 * when the file cannot be read (reported). */
static void ctl_script_release(ctl_script *s);

/* Reads and validates every line of f into s (malformed lines counted in s->errors and
 * reported as NAME:LINE: on stderr). Returns 0, or -1 when f cannot be read. */
static int ctl_script_read(FILE *f, ctl_script *s) {
    char *line = NULL;
    size_t cap = 0;
    ssize_t n;
    long lineno = 0;
    double prev_at = 0;
    int rc = 0;
    while ((n = getline(&line, &cap, f)) >= 0) {
        lineno++;
        size_t len = (size_t)n;
        while (len > 0 && (line[len - 1] == '\n' || line[len - 1] == '\r')) len--;
        line[len] = 0;
        size_t lead = strspn(line, " \t");
        if (lead == len || line[lead] == '#') continue; /* blank or comment */
        if (len > CTL_SCRIPT_LINE_MAX) {
            ctl_script_error(s, lineno, "line longer than %u bytes", CTL_SCRIPT_LINE_MAX);
            continue;
        }
        if (strlen(line) != len) { /* a NUL byte would cut the message short */
            ctl_script_error(s, lineno, "NUL byte in the line");
            continue;
        }
        if (ctl_script_line(s, line + lead, len - lead, lineno, &prev_at) != 0) {
            rc = -1;
            break;
        }
    }
    if (rc == 0 && ferror(f)) {
        fprintf(stderr, "lucentctl: script: cannot read %s: %s\n", s->name, strerror(errno));
        rc = -1;
    }
    free(line);
    return rc;
}

static int ctl_script_load(const char *path, ctl_script *s) {
    FILE *f = strcmp(path, "-") == 0 ? stdin : fopen(path, "r");
    s->name = f == stdin ? "<stdin>" : path;
    if (!f) {
        fprintf(stderr, "lucentctl: script: cannot open %s: %s\n", path, strerror(errno));
        return -1;
    }
    int rc = ctl_script_read(f, s);
    if (f != stdin) fclose(f);
    return rc;
}

int ctl_script_validate(FILE *f, const char *name, size_t *messages, long *errors) {
    ctl_script s;
    memset(&s, 0, sizeof s);
    s.name = name;
    int rc = ctl_script_read(f, &s);
    if (messages) *messages = s.n;
    if (errors) *errors = s.errors;
    ctl_script_release(&s);
    return rc;
}

static void ctl_script_release(ctl_script *s) {
    for (size_t i = 0; i < s->n; i++) free(s->msgs[i].text);
    free(s->msgs);
}

/* --- playing ---------------------------------------------------------------------------- */

static double ctl_ts_seconds(const struct timespec *t) { return (double)t->tv_sec + (double)t->tv_nsec * 1e-9; }

/* t0 + seconds, as an absolute monotonic time. */
static struct timespec ctl_ts_add(struct timespec t0, double seconds) {
    double whole = floor(seconds);
    long long ns = t0.tv_nsec + (long long)llround((seconds - whole) * 1e9);
    t0.tv_sec += (time_t)whole + (time_t)(ns / 1000000000LL);
    t0.tv_nsec = (long)(ns % 1000000000LL);
    return t0;
}

/* Sleeps until `due` (absolute, CLOCK_MONOTONIC). Returns -1 when interrupted by Ctrl-C. */
static int ctl_sleep_until(const struct timespec *due) {
    int r;
    while ((r = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, due, NULL)) == EINTR)
        if (ctl_script_stop) return -1;
    return ctl_script_stop ? -1 : 0;
}

typedef struct ctl_script_run {
    long long sent, failed, final_revision;
    double max_lag;
    struct timespec start;
} ctl_script_run;

static void ctl_script_summary(const ctl_script *s, const ctl_script_run *r) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    FILE *out = ctl_json ? stderr : stdout; /* stdout stays pure JSON lines with --json */
    char rev[32] = "none";
    if (r->final_revision >= 0) snprintf(rev, sizeof rev, "%lld", r->final_revision);
    fprintf(out, "%s: %lld message%s sent, %lld failed, %.3f s, final revision %s, max lag %.1f ms\n", s->name, r->sent,
            r->sent == 1 ? "" : "s", r->failed, ctl_ts_seconds(&now) - ctl_ts_seconds(&r->start), rev,
            r->max_lag * 1e3);
    fflush(out);
}

/* Sends every message once, on schedule from a fresh t0. Returns an exit code, or -1 to go on. */
static int ctl_script_pass(lc_client *c, const ctl_script *s, const ctl_script_opts *o, ctl_script_run *r, int progress,
                           long long pass) {
    struct timespec t0, now;
    char err[512], buf[1024];
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (size_t i = 0; i < s->n; i++) {
        const ctl_script_msg *m = &s->msgs[i];
        struct timespec due = ctl_ts_add(t0, m->at / o->speed);
        if (ctl_sleep_until(&due) != 0) return 130;
        clock_gettime(CLOCK_MONOTONIC, &now);
        double lag = ctl_ts_seconds(&now) - ctl_ts_seconds(&due);
        if (lag > r->max_lag) r->max_lag = lag;
        char *reply = NULL;
        int q = lc_client_request(c, m->text, &reply, CTL_TIMEOUT_MS, err, sizeof err);
        if (q < 0) {
            free(reply);
            fprintf(stderr, "%s:%ld: connection lost: %s\n", s->name, m->line, err);
            return CTL_EXIT_CONN;
        }
        r->sent++;
        long long rev = ctl_reply_revision(reply);
        if (rev >= 0) r->final_revision = rev;
        if (ctl_json && reply) {
            printf("%s\n", reply);
            fflush(stdout);
        }
        if (q == 1) {
            r->failed++;
            ctl_format_server_error(reply, buf, sizeof buf);
            fprintf(stderr, "%s:%ld: %s\n", s->name, m->line, buf);
        } else if (progress) {
            char loop[32] = "";
            if (o->loops != 1) snprintf(loop, sizeof loop, " [loop %lld]", pass + 1);
            char revs[40] = "";
            if (rev >= 0) snprintf(revs, sizeof revs, " (revision %lld)", rev);
            fprintf(stderr, "%9.3f s %s:%ld %s: ok%s%s\n", ctl_ts_seconds(&now) - ctl_ts_seconds(&r->start), s->name,
                    m->line, m->what, revs, loop);
        }
        free(reply);
        if (q == 1 && !o->keep_going) return CTL_EXIT_REFUSED;
        if (ctl_script_stop) return 130;
    }
    return -1;
}

/* The server's limits.max_message from the welcome, or 0 when it does not say. */
static double ctl_welcome_max_message(lc_client *c) {
    cJSON *w = cJSON_Parse(lc_client_welcome(c) ? lc_client_welcome(c) : "");
    const cJSON *lim = cJSON_GetObjectItemCaseSensitive(w, "limits");
    const cJSON *mm = cJSON_GetObjectItemCaseSensitive(lim, "max_message");
    double v = cJSON_IsNumber(mm) ? mm->valuedouble : 0;
    cJSON_Delete(w);
    return v;
}

static int ctl_script_play(const ctl_script *s, const ctl_script_opts *o) {
    int rc = CTL_EXIT_OK;
    ctl_script_run r = {0, 0, -1, 0, {0, 0}};
    struct sigaction sa, old_sa;
    lc_client *c = ctl_connect(NULL, &rc);
    if (!c) return rc;
    /* a message over the server's size limit would close the connection mid-script: refuse
     * it before anything is sent */
    double max = ctl_welcome_max_message(c);
    long too_big = 0;
    for (size_t i = 0; max > 0 && i < s->n; i++)
        if ((double)strlen(s->msgs[i].text) > max) {
            if (too_big++ < CTL_SCRIPT_ERRORS_SHOWN)
                fprintf(stderr, "%s:%ld: message of %zu bytes is over the server's limit of %.0f bytes\n", s->name,
                        s->msgs[i].line, strlen(s->msgs[i].text), max);
        }
    if (too_big) {
        fprintf(stderr, "%s: %ld message(s) too large; nothing sent\n", s->name, too_big);
        lc_client_close(c);
        return CTL_EXIT_USAGE;
    }
    int progress = o->verbose || isatty(STDERR_FILENO);
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = ctl_script_on_signal; /* no SA_RESTART: the sleep wakes up at once */
    sigemptyset(&sa.sa_mask);
    ctl_script_stop = 0;
    sigaction(SIGINT, &sa, &old_sa);
    clock_gettime(CLOCK_MONOTONIC, &r.start);
    int q = -1;
    for (long long pass = 0; q < 0 && (o->loops == 0 || pass < o->loops); pass++)
        q = ctl_script_pass(c, s, o, &r, progress, pass);
    sigaction(SIGINT, &old_sa, NULL);
    if (q == 130) fprintf(stderr, "%s: interrupted\n", s->name);
    rc = q >= 0 ? q : (r.failed ? CTL_EXIT_REFUSED : CTL_EXIT_OK);
    ctl_script_summary(s, &r);
    lc_client_close(c);
    return rc;
}

/* --- the command ------------------------------------------------------------------------ */

static int ctl_script_parse_args(int argc, char **argv, ctl_script_opts *o, const char **file) {
    *file = NULL;
    int flags_done = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (flags_done || a[0] != '-' || strcmp(a, "-") == 0) {
            if (*file) return ctl_usage_error("script: one FILE only (got '%s' and '%s')", *file, a);
            *file = a;
        } else if (strcmp(a, "--") == 0) {
            flags_done = 1;
        } else if (strcmp(a, "--speed") == 0 || strncmp(a, "--speed=", 8) == 0) {
            const char *v = a[7] == '=' ? a + 8 : (i + 1 < argc ? argv[++i] : NULL);
            if (!v) return ctl_usage_error("script: --speed needs a value (F > 0)");
            if (ctl_parse_double(v, &o->speed) != 0 || o->speed < CTL_SCRIPT_SPEED_MIN ||
                o->speed > CTL_SCRIPT_SPEED_MAX)
                return ctl_usage_error("script: --speed '%s': expected a number in [%g, %g]", v, CTL_SCRIPT_SPEED_MIN,
                                       CTL_SCRIPT_SPEED_MAX);
        } else if (strcmp(a, "--loop") == 0 || strncmp(a, "--loop=", 7) == 0) {
            /* the count is optional: take the next argument only when it is a number */
            const char *v = a[6] == '=' ? a + 7 : NULL;
            long long n;
            if (!v && i + 1 < argc && argv[i + 1][0] >= '0' && argv[i + 1][0] <= '9') v = argv[++i];
            if (!v) o->loops = 0;
            else if (ctl_parse_int(v, 1, 1000000000LL, &n) == 0) o->loops = n;
            else return ctl_usage_error("script: --loop '%s': expected a whole number of times >= 1", v);
        } else if (strcmp(a, "--keep-going") == 0 || strcmp(a, "-k") == 0) {
            o->keep_going = 1;
        } else if (strcmp(a, "--dry-run") == 0 || strcmp(a, "-n") == 0) {
            o->dry_run = 1;
        } else if (strcmp(a, "--verbose") == 0 || strcmp(a, "-v") == 0) {
            o->verbose = 1;
        } else {
            return ctl_usage_error("script: unknown option '%s'", a);
        }
    }
    if (!*file) return ctl_usage_error("script: missing FILE (or '-' for stdin)");
    return 0;
}

int ctl_cmd_script(int argc, char **argv) {
    ctl_script_opts o = {1.0, 1, 0, 0, 0};
    ctl_script s;
    const char *file;
    int rc;
    if (ctl_wants_help(argc, argv)) {
        ctl_script_usage(stdout);
        return CTL_EXIT_OK;
    }
    if ((rc = ctl_script_parse_args(argc, argv, &o, &file)) != 0) return rc;
    memset(&s, 0, sizeof s);
    if (ctl_script_load(file, &s) != 0) {
        rc = CTL_EXIT_USAGE;
        goto done;
    }
    if (s.errors) {
        if (s.errors > CTL_SCRIPT_ERRORS_SHOWN)
            fprintf(stderr, "%s: ... and %ld more\n", s.name, s.errors - CTL_SCRIPT_ERRORS_SHOWN);
        fprintf(stderr, "%s: %ld malformed line%s; nothing sent\n", s.name, s.errors, s.errors == 1 ? "" : "s");
        rc = CTL_EXIT_USAGE;
        goto done;
    }
    if (s.n == 0) {
        fprintf(stderr, "%s: no messages (only blank lines and comments)\n", s.name);
        rc = CTL_EXIT_USAGE;
        goto done;
    }
    if (o.dry_run) {
        double dur = s.msgs[s.n - 1].at / o.speed;
        if (ctl_json) {
            cJSON *j = cJSON_CreateObject();
            cJSON_AddStringToObject(j, "file", s.name);
            cJSON_AddNumberToObject(j, "messages", (double)s.n);
            cJSON_AddNumberToObject(j, "duration_s", dur);
            char *t = cJSON_PrintUnformatted(j);
            if (t) printf("%s\n", t);
            free(t);
            cJSON_Delete(j);
        } else printf("%s: %zu message%s over %.3f s: ok\n", s.name, s.n, s.n == 1 ? "" : "s", dur);
        rc = CTL_EXIT_OK;
        goto done;
    }
    rc = ctl_script_play(&s, &o);
done:
    ctl_script_release(&s);
    return rc;
}
