/* lucentctl load: many lucent/1 viewers in one process, to load a server and measure it.
 *
 * Every viewer connection and the controller live on ONE libwebsockets client context,
 * serviced by this thread alone (lws_service loop; a 1 ms sul tick drives the schedule:
 * connect pacing, the controller's updates, phase changes, progress). A viewer is a small
 * struct (load_conn, ~150 bytes) given to lws as the connection's opaque user data. The
 * controller is an ordinary lws WebSocket client; the viewers are raw lws connections that
 * frame RFC 6455 themselves (why: above load_ws_send) and speak the minimal protocol: hello
 * -> welcome -> subscribe -> binary frames. No pixel is decoded: per frame the first 32
 * bytes of the 64-byte header (magic, flags, revision, sequence) are kept, whatever reads
 * they straddle, and the message's payload bytes counted. lc_client is not used for the
 * viewers because it is one context (and one poll loop) per connection.
 *
 * Latency bookkeeping (what "first frame of that revision" means without per-frame logs):
 * revisions in a stream never decrease, so a frame of revision r tells a viewer "every
 * revision up to r is here". The run keeps one row per revision after the warm-up's
 * (rev_base): row[v - rev_base - 1][client] = arrival of that client's first frame with a
 * revision >= v, as uint32 microseconds since the load started (+1; 0 = not yet). A frame
 * of a new revision fills the rows it covers for that client (usually one). Rows are keyed
 * by revision, not by update, so a frame that arrives before its update's `ok` is recorded
 * all the same; once the ok names the revision, latency = row entry - send time. At the end
 * every (acknowledged update, measured client) pair is folded into a log-linear histogram
 * (128 sub-buckets per octave: percentiles within 0.8 %, max exact) and the rows freed; a
 * pair whose entry is still 0 after the settle period is `missing`. Memory: rows are
 * allocated as revisions appear, at most (updates + LOAD_REV_MARGIN) x clients x 4 bytes
 * (10 000 clients x 100 updates: 6.6 MB); runs whose worst case passes LOAD_MATRIX_MAX are
 * refused up front (shorten --duration or lower --rate). Per client otherwise: the last
 * revision and sequence, the frame count, the frame parser's state and a 32-byte header
 * prefix; the text buffer exists only during the handshake.
 *
 * Times: send = when lws_write handed the request to the kernel; arrival = when the frame's
 * last byte was read (the frame is complete, as lc_client's client_time_us). */
#include <cjson/cJSON.h>
#include <libwebsockets.h>
#include <math.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "ctl.h"
#include "util/sigflag.h"
#include "lucent_proto.h"

#define LOAD_POLL_NS_PER_CLIENT 250       /* service turns at least N x this apart (load_serve) */
#define LOAD_POLL_MAX_US 10000            /* ... and at most this (arrival times err late by <= this) */
#define LOAD_TICK_US 1000                 /* schedule granularity (µs) */
#define LOAD_TEXT_MAX (1u << 20)          /* largest text message reassembled (handshake, controller) */
#define LOAD_REV_MARGIN 64                /* revisions beyond the updates' (other clients' changes) */
#define LOAD_MATRIX_MAX ((size_t)1 << 30) /* bytes of arrival rows at most */
#define LOAD_MAX_REASONS 16               /* distinct failure reasons kept (the rest: "other") */
#define LOAD_REASON_LEN 120
#define LOAD_HDR_KEEP 32u /* header bytes kept: magic .. sequence */
#define LOAD_CTL_QUEUE 64 /* controller requests waiting for a write */
#define LOAD_HIST_SUB 128 /* histogram: exact below, then 64 buckets per octave */
#define LOAD_HIST_N (LOAD_HIST_SUB + 26 * 64)
#define LOAD_CTL_IDX UINT32_MAX
#define LOAD_WARMUP_SEEN_S 30.0 /* the warm-up revision must reach every viewer within this */
#define LOAD_ACK_WAIT_S 10.0    /* oks of the last updates: this + --settle */

static lc_sigflag load_stop;

static void load_on_signal(int sig) {
    (void)sig;
    load_stop = 1;
}

/* --- options ------------------------------------------------------------------------- */

typedef struct load_opts {
    long long clients;
    double rate, duration, connect_rate, warmup, settle;
    const char *stream, *encoding, *json, *light;
} load_opts;

static void load_usage(FILE *o) {
    fprintf(o,
            "usage: lucentctl load --clients N --rate R --duration S [options]\n"
            "Connects N viewers (one libwebsockets context, one thread) subscribed to a stream and one\n"
            "controller that moves a point light around the scene centre R times a second for S\n"
            "seconds; times each update from sending its light.set to each viewer's first frame of\n"
            "the revision its ok names. Prints clients connected/failed (per reason), updates sent and\n"
            "acknowledged, latency p50/p90/p99/max over all (update, viewer) pairs, pairs never seen\n"
            "(missing), frames and bytes per client per second, the fraction of viewers on the final\n"
            "revision after --settle, and this process's CPU seconds and peak RSS. Needs a controller\n"
            "token; the viewers use the same --token.\n"
            "options:\n"
            "  --clients N          viewers, 1..100000 (needs N+16 descriptors: the open-files limit\n"
            "                       is raised to its hard limit)\n"
            "  --rate R             light.set updates per second, (0, 1000] (the server's default\n"
            "                       limit is 100 requests/s per connection)\n"
            "  --duration S         seconds of updates, (0, 3000]\n"
            "  --connect-rate C     new viewer connections per second (default 500)\n"
            "  --warmup SEC         pause after the warm-up update reached every viewer (default 1)\n"
            "  --settle SEC         at most this long for every viewer to show the final revision\n"
            "                       (default 5)\n"
            "  --stream lightmap|shgrid|objects   (default lightmap)\n"
            "  --encoding rgb9e5|rgba16f|f32      (default: rgb9e5 for the lightmap, f32 otherwise)\n"
            "  --light ID           the orbiting light's id (default load-orbit; removed at the end)\n"
            "  --json FILE          also write the report as JSON to FILE (global --json before the\n"
            "                       command: the report as JSON on stdout instead of the table)\n"
            "  --url URL, --token T as for every command\n"
            "Progress goes to stderr once a second. Exit: 0 every viewer connected and the run\n"
            "completed; 3 some viewers could not connect, or the controller's connection failed\n"
            "(the report says why, per reason); 1 the server refused the controller (token, role).\n");
}

/* Value of a flag at argv[*i] ("--flag V" or "--flag=V"), advancing *i; NULL when missing. */
static const char *load_flag_value(int argc, char **argv, int *i, const char *name) {
    size_t n = strlen(name);
    const char *a = argv[*i];
    if (a[n] == '=') return a + n + 1;
    if (*i + 1 >= argc) return NULL;
    return argv[++*i];
}

static int load_number(const char *flag, const char *v, double lo_excl, double hi, int lo_incl, double *out) {
    double d;
    if (ctl_parse_double(v, &d) != 0 || (lo_incl ? d < lo_excl : d <= lo_excl) || d > hi)
        return ctl_usage_error("load: %s '%s': expected a number in %s%g, %g]", flag, v, lo_incl ? "[" : "(", lo_excl,
                               hi);
    *out = d;
    return 0;
}

static int load_parse_one(const char *k, const char *v, load_opts *o) {
    if (!strcmp(k, "--clients")) {
        if (ctl_parse_int(v, 1, 100000, &o->clients) != 0)
            return ctl_usage_error("load: --clients '%s': expected a whole number in 1..100000", v);
        return 0;
    }
    if (!strcmp(k, "--rate")) return load_number(k, v, 0, 1000, 0, &o->rate);
    if (!strcmp(k, "--duration")) return load_number(k, v, 0, 3000, 0, &o->duration);
    if (!strcmp(k, "--connect-rate")) return load_number(k, v, 0, 100000, 0, &o->connect_rate);
    if (!strcmp(k, "--warmup")) return load_number(k, v, 0, 600, 1, &o->warmup);
    if (!strcmp(k, "--settle")) return load_number(k, v, 0, 600, 1, &o->settle);
    if (!strcmp(k, "--stream")) {
        if (strcmp(v, "lightmap") && strcmp(v, "shgrid") && strcmp(v, "objects"))
            return ctl_usage_error("load: --stream '%s' is not lightmap, shgrid or objects", v);
        o->stream = v;
        return 0;
    }
    if (!strcmp(k, "--encoding")) {
        if (strcmp(v, "rgb9e5") && strcmp(v, "rgba16f") && strcmp(v, "f32"))
            return ctl_usage_error("load: --encoding '%s' is not rgb9e5, rgba16f or f32", v);
        o->encoding = v;
        return 0;
    }
    if (!strcmp(k, "--json")) {
        if (!*v) return ctl_usage_error("load: --json needs a file name");
        o->json = v;
        return 0;
    }
    if (!strcmp(k, "--light")) {
        if (!*v || strlen(v) > LC_PROTO_ID_MAX) return ctl_usage_error("load: --light '%s' must be 1..64 bytes", v);
        for (const char *p = v; *p; p++)
            if (*p == '"' || *p == '\\' || (unsigned char)*p < 0x20)
                return ctl_usage_error("load: --light '%s': no quotes, backslashes or control characters", v);
        o->light = v;
        return 0;
    }
    return ctl_usage_error("load: unknown option '%s'", k);
}

/* CTL_EXIT_OK, or CTL_EXIT_USAGE with the error printed (naming the flag). */
static int load_parse(int argc, char **argv, load_opts *o) {
    memset(o, 0, sizeof *o);
    o->connect_rate = 500, o->warmup = 1, o->settle = 5;
    o->stream = "lightmap", o->light = "load-orbit";
    static const char *const flags[] = {"--clients", "--rate",   "--duration", "--connect-rate", "--warmup",
                                        "--settle",  "--stream", "--encoding", "--json",         "--light"};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *k = NULL;
        for (size_t f = 0; f < sizeof flags / sizeof flags[0]; f++) {
            size_t n = strlen(flags[f]);
            if (!strncmp(a, flags[f], n) && (a[n] == 0 || a[n] == '=')) k = flags[f];
        }
        if (!k) return ctl_usage_error("load: unknown option '%s'", a);
        const char *v = load_flag_value(argc, argv, &i, k);
        if (!v) return ctl_usage_error("load: %s needs a value", k);
        if (load_parse_one(k, v, o) != 0) return CTL_EXIT_USAGE;
    }
    if (!o->clients) return ctl_usage_error("load: --clients N is required");
    if (o->rate <= 0) return ctl_usage_error("load: --rate R is required");
    if (o->duration <= 0) return ctl_usage_error("load: --duration S is required");
    int lightmap = !strcmp(o->stream, "lightmap");
    if (!o->encoding) o->encoding = lightmap ? "rgb9e5" : "f32";
    if (!lightmap && !strcmp(o->encoding, "rgb9e5"))
        return ctl_usage_error("load: --encoding rgb9e5 is for the lightmap only (%s: rgba16f or f32)", o->stream);
    double updates = floor(o->rate * o->duration + 0.5);
    if (updates < 1) return ctl_usage_error("load: --rate x --duration must give at least one update");
    if ((updates + LOAD_REV_MARGIN) * (double)o->clients * 4 > (double)LOAD_MATRIX_MAX)
        return ctl_usage_error("load: --clients %lld x %.0f updates (--rate x --duration) need more than %zu MiB "
                               "of arrival records; shorten --duration or lower --rate",
                               o->clients, updates, LOAD_MATRIX_MAX >> 20);
    return CTL_EXIT_OK;
}

/* --- the run ------------------------------------------------------------------------- */

enum {
    LOAD_IDLE,
    LOAD_CONNECTING,
    LOAD_UPGRADING,
    LOAD_WELCOME_WAIT,
    LOAD_SUBSCRIBING,
    LOAD_STREAMING,
    LOAD_FAILED,
    LOAD_DROPPED
};
enum { LOAD_TX_UPGRADE = 1, LOAD_TX_HELLO = 2, LOAD_TX_SUBSCRIBE = 4, LOAD_TX_PONG = 8 }; /* viewer writes due */
enum { LOAD_P_CONNECT, LOAD_P_WARMUP, LOAD_P_RUN, LOAD_P_ACKWAIT, LOAD_P_SETTLE, LOAD_P_CLEANUP, LOAD_P_DONE };
/* controller queue entries: update indices, or one of these */
#define LOAD_Q_HELLO 0xFFFFFFF0u
#define LOAD_Q_WARMUP 0xFFFFFFF1u
#define LOAD_Q_REMOVE 0xFFFFFFF2u

typedef struct load_conn {
    struct lws *wsi;
    uint32_t idx;    /* viewer index, LOAD_CTL_IDX for the controller */
    uint8_t state;   /* LOAD_IDLE .. LOAD_DROPPED */
    uint8_t tx;      /* LOAD_TX_* bits: writes due (viewers) */
    uint8_t in_msg;  /* inside a (fragmented) message */
    uint8_t binary;  /* the current message is binary */
    uint8_t hdr_len; /* bytes of hdr filled */
    uint8_t measured;
    uint8_t fh_len, fh_need; /* the WebSocket frame header being read (viewers) */
    uint8_t fh[14];
    uint8_t opcode, fin, ctrl_len;
    uint8_t hdr[LOAD_HDR_KEEP]; /* a message's first bytes: the frame header, a text's type */
    uint32_t frames, last_seq;
    uint64_t remain;     /* payload bytes left in the current WebSocket frame */
    uint64_t last_rev;   /* highest revision seen */
    uint64_t msg_bytes;  /* the current message so far */
    char *text;          /* text being reassembled (handshake and controller only) */
    unsigned char *ctrl; /* a control frame's payload (close reason, ping), allocated when one comes */
    uint32_t text_len, text_cap;
} load_conn;

typedef struct load_reasons {
    char what[LOAD_MAX_REASONS][LOAD_REASON_LEN];
    uint32_t count[LOAD_MAX_REASONS];
    uint32_t other;
    int n;
} load_reasons;

typedef struct load_hist {
    uint64_t count[LOAD_HIST_N];
    uint64_t n, max_us;
    double sum_us;
} load_hist;

typedef struct load_run {
    const load_opts *o;
    struct lws_context *ctx;
    lws_sorted_usec_list_t tick;
    char host[256], path[256], origin[300];
    int port, tls;
    char *hello;   /* the viewers' hello (one text for all) */
    char sub[256]; /* the viewers' subscribe */
    load_conn *conns, ctl;
    uint32_t n, next_connect;
    int phase;
    uint64_t t0, connect_start, phase_t, run_start, run_end, last_progress, last_scan;
    uint32_t n_pending, n_streaming, n_failed, n_dropped, n_refused, n_measured, ever_streaming;
    load_reasons fails, drops;
    /* viewers' traffic (total, and within the measured window) */
    uint64_t frames, bytes, frames_win, bytes_win, keyframes, deltas, texts, changed, error_msgs, bad_frames, seq_gaps;
    /* the controller */
    uint32_t q[LOAD_CTL_QUEUE], q_head, q_len;
    double centre[3], radius, height;
    int ctl_ready;
    uint64_t warm_rev, remove_acked;
    uint32_t n_updates, n_sent, n_acked, n_errors;
    uint64_t *send_us, *ack_us, *rev;
    load_reasons ctl_errors;
    /* arrival rows (see the top of the file) */
    uint64_t rev_base; /* 0: not recording */
    int recording, oom;
    uint32_t **rows, n_rows;
    uint64_t final_rev;
    uint32_t on_final;
    double settle_s, connect_s;
    int rc, interrupted;
    uint64_t turns, serve_us; /* service loop turns, and the time they took */
    char fatal[300];
    unsigned long nofile;
} load_run;

static uint64_t load_now_us(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (uint64_t)t.tv_sec * 1000000u + (uint64_t)t.tv_nsec / 1000u;
}

static uint64_t load_be(const uint8_t *p, int n) {
    uint64_t v = 0;
    for (int i = 0; i < n; i++) v = v << 8 | p[i];
    return v;
}

static uint64_t load_le(const uint8_t *p, int n) {
    uint64_t v = 0;
    for (int i = n - 1; i >= 0; i--) v = v << 8 | p[i];
    return v;
}

static void load_reason_add(load_reasons *rs, const char *why) {
    for (int i = 0; i < rs->n; i++)
        if (!strcmp(rs->what[i], why)) {
            rs->count[i]++;
            return;
        }
    if (rs->n == LOAD_MAX_REASONS) {
        rs->other++;
        return;
    }
    snprintf(rs->what[rs->n], LOAD_REASON_LEN, "%s", why);
    rs->count[rs->n++] = 1;
}

static void load_fatal(load_run *r, int rc, const char *fmt, const char *arg) {
    if (r->fatal[0]) return;
    snprintf(r->fatal, sizeof r->fatal, fmt, arg);
    r->rc = rc;
}

/* A viewer leaves: before its first frame it failed, after it it dropped. */
static void load_conn_lost(load_run *r, load_conn *c, const char *why) {
    if (c->idx == LOAD_CTL_IDX) {
        if (r->phase < LOAD_P_CLEANUP) load_fatal(r, CTL_EXIT_CONN, "controller connection: %s", why);
        c->state = LOAD_FAILED;
        c->wsi = NULL;
        return;
    }
    if (c->state == LOAD_STREAMING) {
        c->state = LOAD_DROPPED;
        r->n_streaming--;
        r->n_dropped++;
        load_reason_add(&r->drops, why);
    } else if (c->state != LOAD_FAILED && c->state != LOAD_DROPPED) {
        if (c->state != LOAD_IDLE) r->n_pending--;
        c->state = LOAD_FAILED;
        r->n_failed++;
        load_reason_add(&r->fails, why);
    }
    free(c->text);
    c->text = NULL;
    c->text_len = c->text_cap = 0;
}

/* --- arrival rows and the histogram ---------------------------------------------------- */

/* Client c's first frame of a revision up to rev came at t: fills the rows it covers. */
static void load_record(load_run *r, load_conn *c, uint64_t rev, uint64_t t) {
    if (!r->recording || !r->rev_base || !c->measured || rev <= r->rev_base) return;
    uint64_t from = c->last_rev > r->rev_base ? c->last_rev - r->rev_base : 0; /* rows [from, to) */
    uint64_t to = rev - r->rev_base;
    if (to > r->n_rows) to = r->n_rows;
    uint64_t rel = t - r->t0 + 1;
    uint32_t val = rel > UINT32_MAX ? UINT32_MAX : (uint32_t)rel;
    for (uint64_t v = from; v < to; v++) {
        if (!r->rows[v] && !(r->rows[v] = calloc(r->n, sizeof **r->rows))) {
            r->oom = 1;
            continue;
        }
        r->rows[v][c->idx] = val;
    }
}

static int load_hist_index(uint64_t v) {
    if (v < LOAD_HIST_SUB) return (int)v;
    int m = 63 - __builtin_clzll(v); /* >= 7 */
    if (m > 32) m = 32, v = UINT32_MAX;
    int shift = m - 6;
    return LOAD_HIST_SUB + (m - 7) * 64 + (int)((v >> shift) - 64);
}

/* The middle of bucket i, in µs. */
static double load_hist_value(int i) {
    if (i < LOAD_HIST_SUB) return i;
    int m = 7 + (i - LOAD_HIST_SUB) / 64, rr = (i - LOAD_HIST_SUB) % 64 + 64, shift = m - 6;
    return ((double)((uint64_t)rr << shift) + (double)((uint64_t)(rr + 1) << shift)) / 2 - 0.5;
}

static void load_hist_add(load_hist *h, uint64_t us) {
    h->count[load_hist_index(us)]++;
    h->n++;
    h->sum_us += (double)us;
    if (us > h->max_us) h->max_us = us;
}

/* The p-quantile in ms (the bucket holding rank p x (n-1)); the maximum is exact. */
static double load_hist_ms(const load_hist *h, double p) {
    if (!h->n) return 0;
    uint64_t rank = (uint64_t)floor(p * (double)(h->n - 1)), seen = 0;
    for (int i = 0; i < LOAD_HIST_N; i++) {
        seen += h->count[i];
        if (seen > rank) return fmin(load_hist_value(i), (double)h->max_us) / 1000.0;
    }
    return (double)h->max_us / 1000.0;
}

/* Folds every (acknowledged update, measured viewer) pair into h; returns the missing. */
static uint64_t load_fold(load_run *r, load_hist *h) {
    uint64_t missing = 0;
    for (uint32_t k = 0; k < r->n_sent; k++) {
        if (!r->rev[k]) continue;
        uint64_t v = r->rev[k] > r->rev_base ? r->rev[k] - r->rev_base - 1 : UINT64_MAX;
        const uint32_t *row = v < r->n_rows ? r->rows[v] : NULL;
        for (uint32_t c = 0; c < r->n; c++) {
            if (!r->conns[c].measured) continue;
            if (!row || !row[c]) {
                missing++;
                continue;
            }
            uint64_t at = r->t0 + row[c] - 1;
            load_hist_add(h, at > r->send_us[k] ? at - r->send_us[k] : 0);
        }
    }
    return missing;
}

/* Viewers with a frame of revision rev or later. */
static uint32_t load_count_at(const load_run *r, uint64_t rev) {
    uint32_t k = 0;
    for (uint32_t i = 0; i < r->n; i++)
        if (r->conns[i].state == LOAD_STREAMING && r->conns[i].last_rev >= rev) k++;
    return k;
}

/* --- messages -------------------------------------------------------------------------- */

/* Appends a text fragment (capped: a longer message is cut and then fails to parse). */
static void load_text_append(load_conn *c, const void *in, size_t len) {
    if (c->text_len + len + 1 > c->text_cap) {
        size_t want = (size_t)c->text_len + len + 1;
        if (want > LOAD_TEXT_MAX) return;
        size_t cap = c->text_cap ? c->text_cap : 1024;
        while (cap < want) cap *= 2;
        char *t = realloc(c->text, cap);
        if (!t) return;
        c->text = t;
        c->text_cap = (uint32_t)cap;
    }
    memcpy(c->text + c->text_len, in, len);
    c->text_len += (uint32_t)len;
    c->text[c->text_len] = 0;
}

/* "CODE: message" of an `error` reply, into buf. */
static void load_error_text(const cJSON *m, char *buf, size_t n) {
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(m, "code");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(m, "message");
    snprintf(buf, n, "%s: %.60s", cJSON_IsString(code) ? code->valuestring : "?",
             cJSON_IsString(msg) ? msg->valuestring : "");
}

/* A complete binary frame at viewer c. */
static void load_on_frame(load_run *r, load_conn *c, uint64_t t) {
    r->frames++;
    r->bytes += c->msg_bytes;
    if (r->recording) {
        r->frames_win++;
        r->bytes_win += c->msg_bytes;
    }
    if (c->hdr_len < LOAD_HDR_KEEP || load_le(c->hdr, 4) != LC_FRAME_MAGIC) {
        r->bad_frames++;
        return;
    }
    unsigned flags = (unsigned)load_le(c->hdr + 8, 2);
    if (flags & 1) r->keyframes++;
    else r->deltas++;
    uint64_t rev = load_le(c->hdr + 16, 8);
    uint32_t seq = (uint32_t)load_le(c->hdr + 24, 8);
    if (c->last_seq && seq != c->last_seq + 1) r->seq_gaps++;
    c->last_seq = seq;
    c->frames++;
    if (c->state == LOAD_SUBSCRIBING) { /* the first frame: this viewer is in */
        c->state = LOAD_STREAMING;
        r->n_pending--;
        r->n_streaming++;
        r->ever_streaming++;
        free(c->text);
        c->text = NULL;
        c->text_len = c->text_cap = 0;
    }
    if (rev > c->last_rev) {
        load_record(r, c, rev, t);
        c->last_rev = rev;
    }
}

/* A complete text message at viewer c. Returns -1 to close the connection. */
static int load_viewer_text(load_run *r, load_conn *c) {
    r->texts++;
    if (c->state == LOAD_STREAMING) {
        /* streaming: counted by the type lucentd writes first, not parsed (100k changed/s at
         * 10 000 viewers and 10 updates/s) */
        if (c->hdr_len >= 15 && !memcmp(c->hdr, "{\"type\":\"error\"", 15)) r->error_msgs++;
        else if (c->hdr_len >= 17 && !memcmp(c->hdr, "{\"type\":\"changed\"", 17)) r->changed++;
        return 0;
    }
    cJSON *m = cJSON_Parse(c->text ? c->text : "");
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(m, "type");
    const char *ty = cJSON_IsString(type) ? type->valuestring : "";
    char why[LOAD_REASON_LEN];
    int rc = 0;
    if (!strcmp(ty, "error")) {
        char e[100];
        load_error_text(m, e, sizeof e);
        snprintf(why, sizeof why, "%s refused: %s", c->state == LOAD_WELCOME_WAIT ? "hello" : "subscribe", e);
        if (c->state == LOAD_WELCOME_WAIT) r->n_refused++;
        load_conn_lost(r, c, why);
        rc = -1;
    } else if (c->state == LOAD_WELCOME_WAIT && !strcmp(ty, "welcome")) {
        c->state = LOAD_SUBSCRIBING;
        c->tx |= LOAD_TX_SUBSCRIBE;
        lws_callback_on_writable(c->wsi);
    } else if (!strcmp(ty, "changed")) r->changed++;
    cJSON_Delete(m);
    c->text_len = 0;
    return rc;
}

/* The orbit (as tests/bench/latency_bench.py): around the middle of the welcome's SH grid,
 * radius 0.3 x the smaller horizontal extent, at 3/4 of its height. */
static void load_orbit_from_welcome(load_run *r, const cJSON *w) {
    const cJSON *g = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(w, "scene"), "grid");
    const cJSON *org = cJSON_GetObjectItemCaseSensitive(g, "origin"),
                *cell = cJSON_GetObjectItemCaseSensitive(g, "cell"),
                *dims = cJSON_GetObjectItemCaseSensitive(g, "dims");
    double ext[3] = {1, 1, 1}, lo[3] = {-0.5, 0, -0.5};
    if (cJSON_GetArraySize(org) == 3 && cJSON_IsNumber(cell) && cJSON_GetArraySize(dims) == 3)
        for (int k = 0; k < 3; k++) {
            lo[k] = cJSON_GetArrayItem(org, k)->valuedouble;
            ext[k] = cell->valuedouble * (cJSON_GetArrayItem(dims, k)->valuedouble - 1);
        }
    for (int k = 0; k < 3; k++) r->centre[k] = lo[k] + ext[k] / 2;
    r->radius = 0.3 * fmin(ext[0], ext[2]);
    r->height = lo[1] + 0.75 * ext[1];
}

/* The controller's ok / error for one of its requests (id "w", "x" or "u<k>"). */
static void load_ctl_reply(load_run *r, const cJSON *m, int ok, uint64_t t) {
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(m, "id");
    const cJSON *rv = cJSON_GetObjectItemCaseSensitive(m, "revision");
    uint64_t rev = cJSON_IsNumber(rv) && rv->valuedouble > 0 ? (uint64_t)rv->valuedouble : 0;
    const char *s = cJSON_IsString(id) ? id->valuestring : "";
    char e[100] = "";
    if (!ok) load_error_text(m, e, sizeof e);
    if (!strcmp(s, "w")) {
        if (ok && rev) r->warm_rev = rev;
        else load_fatal(r, CTL_EXIT_REFUSED, "the warm-up light.set was refused: %s", e);
    } else if (!strcmp(s, "x")) {
        r->remove_acked = 1;
    } else if (s[0] == 'u') {
        char *end;
        unsigned long k = strtoul(s + 1, &end, 10);
        if (*end || k >= r->n_sent) return;
        if (ok && rev) {
            r->rev[k] = rev;
            r->ack_us[k] = t;
            r->n_acked++;
        } else {
            r->n_errors++;
            load_reason_add(&r->ctl_errors, e);
        }
    } else if (!ok) load_reason_add(&r->ctl_errors, e); /* no id: e.g. a failed relight (internal) */
}

/* A complete text message at the controller. */
static void load_ctl_text(load_run *r, uint64_t t) {
    cJSON *m = cJSON_Parse(r->ctl.text ? r->ctl.text : "");
    r->ctl.text_len = 0;
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(m, "type");
    const char *ty = cJSON_IsString(type) ? type->valuestring : "";
    if (!r->ctl_ready) {
        const cJSON *role = cJSON_GetObjectItemCaseSensitive(m, "role");
        char e[100];
        if (!strcmp(ty, "welcome") && cJSON_IsString(role) && !strcmp(role->valuestring, "controller")) {
            r->ctl_ready = 1;
            load_orbit_from_welcome(r, m);
        } else if (!strcmp(ty, "welcome"))
            load_fatal(r, CTL_EXIT_REFUSED, "the token has the %s role; load needs a controller token (--token)",
                       cJSON_IsString(role) ? role->valuestring : "?");
        else if (!strcmp(ty, "error")) {
            load_error_text(m, e, sizeof e);
            load_fatal(r, CTL_EXIT_REFUSED, "the server refused the controller's hello: %s", e);
        }
    } else if (!strcmp(ty, "ok") || !strcmp(ty, "error")) load_ctl_reply(r, m, !strcmp(ty, "ok"), t);
    cJSON_Delete(m);
}

/* Writes the controller's next queued request; stamps an update's send time. */
static int load_ctl_write(load_run *r, struct lws *wsi) {
    unsigned char buf[LWS_PRE + 1024];
    char *p = (char *)buf + LWS_PRE;
    size_t cap = sizeof buf - LWS_PRE;
    if (!r->q_len) return 0;
    uint32_t what = r->q[r->q_head];
    r->q_head = (r->q_head + 1) % LOAD_CTL_QUEUE;
    r->q_len--;
    int n;
    if (what == LOAD_Q_HELLO) {
        cJSON *h = cJSON_CreateObject();
        cJSON_AddStringToObject(h, "type", "hello");
        cJSON_AddStringToObject(h, "id", "h");
        cJSON_AddStringToObject(h, "client", "lucentctl-load-controller");
        cJSON_AddStringToObject(h, "token", ctl_token);
        char *t = cJSON_PrintUnformatted(h);
        cJSON_Delete(h);
        n = snprintf(p, cap, "%s", t ? t : "{}");
        free(t);
    } else if (what == LOAD_Q_REMOVE) {
        n = snprintf(p, cap, "{\"type\":\"light.remove\",\"id\":\"x\",\"light_id\":\"%s\"}", r->o->light);
    } else {
        /* update k moves the light by one step of a 20 s orbit; the warm-up places it at 0 */
        double step = 2 * M_PI / (20.0 * r->o->rate), a = what == LOAD_Q_WARMUP ? 0 : (what + 1) * step;
        char id[16];
        if (what == LOAD_Q_WARMUP) snprintf(id, sizeof id, "w");
        else snprintf(id, sizeof id, "u%u", what);
        n = snprintf(p, cap,
                     "{\"type\":\"light.set\",\"id\":\"%s\",\"light\":{\"id\":\"%s\",\"type\":\"point\","
                     "\"intensity\":0.5,\"color\":[1,0.9,0.8],\"position\":[%.6f,%.6f,%.6f]}}",
                     id, r->o->light, r->centre[0] + r->radius * cos(a), r->height, r->centre[2] + r->radius * sin(a));
    }
    if (n < 0 || (size_t)n >= cap) return -1;
    uint64_t t = load_now_us();
    if (lws_write(wsi, (unsigned char *)p, (size_t)n, LWS_WRITE_TEXT) < n) return -1;
    if (what < LOAD_Q_HELLO) r->send_us[what] = t;
    if (r->q_len) lws_callback_on_writable(wsi);
    return 0;
}

static void load_ctl_push(load_run *r, uint32_t what) {
    if (r->q_len == LOAD_CTL_QUEUE || !r->ctl.wsi) return; /* cannot happen at <= 1000 updates/s */
    r->q[(r->q_head + r->q_len) % LOAD_CTL_QUEUE] = what;
    r->q_len++;
    lws_callback_on_writable(r->ctl.wsi);
}

/* --- the controller: an ordinary lws WebSocket ----------------------------------------- */

/* One received chunk of the controller's (a message may come in many). */
static int load_ctl_rx(load_run *r, struct lws *wsi, const void *in, size_t len) {
    load_conn *c = &r->ctl;
    if (!c->in_msg) {
        c->in_msg = 1;
        c->binary = (uint8_t)lws_frame_is_binary(wsi);
        c->text_len = 0;
    }
    if (!c->binary) load_text_append(c, in, len);
    if (!lws_is_final_fragment(wsi)) return 0;
    c->in_msg = 0;
    if (!c->binary) load_ctl_text(r, load_now_us());
    return 0;
}

static int load_ctl_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_context *ctx = lws_get_context(wsi);
    load_run *r = ctx ? lws_context_user(ctx) : NULL;
    if (!r || lws_get_opaque_user_data(wsi) != &r->ctl) return lws_callback_http_dummy(wsi, reason, user, in, len);
    char why[LOAD_REASON_LEN];
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        snprintf(why, sizeof why, "cannot connect: %.100s", in ? (const char *)in : "(unknown error)");
        load_conn_lost(r, &r->ctl, why);
        return 0;
    case LWS_CALLBACK_CLIENT_ESTABLISHED: lws_callback_on_writable(wsi); break; /* the hello is queued */
    case LWS_CALLBACK_CLIENT_WRITEABLE: return load_ctl_write(r, wsi);
    case LWS_CALLBACK_CLIENT_RECEIVE: return load_ctl_rx(r, wsi, in, len);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        if (in && len >= 2) {
            const unsigned char *p = in;
            snprintf(why, sizeof why, "closed by the server (%d%s%.*s)", (p[0] << 8) | p[1], len > 2 ? ": " : "",
                     (int)(len - 2 < 60 ? len - 2 : 60), (const char *)p + 2);
            load_conn_lost(r, &r->ctl, why);
        }
        break;
    case LWS_CALLBACK_CLIENT_CLOSED: load_conn_lost(r, &r->ctl, "connection closed"); break;
    default: break;
    }
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}

/* --- the viewers: raw sockets with our own RFC 6455 framing ----------------------------- */

/* Why not lws's WebSocket client for the viewers: libwebsockets 4.1 (Debian 12) parses a
 * client's incoming frames one byte at a time; at 1 000 viewers that parser was 58 % of
 * this process's CPU, which then could not keep up (a full core, the latencies its own).
 * A raw lws connection (method "RAW") keeps lws's socket handling, descriptor tables and
 * service loop, and leaves the bytes to us: the upgrade request, frame headers, and the
 * payload skipped except for a frame's first 32 bytes. Reads go into lws's per-thread
 * buffer (pt_serv_buf_size), so a viewer has no receive buffer of its own. */

/* The RFC 6455 example key: every viewer sends it, so the accept value is a constant. */
#define LOAD_WS_KEY "dGhlIHNhbXBsZSBub25jZQ=="
#define LOAD_WS_ACCEPT "s3pPLMBiTxaQ9kYGzzhZRbK+xOo="
#define LOAD_HANDSHAKE_MAX 4096

/* Sends one masked client frame (text, or pong). 0 or -1. */
static int load_ws_send(struct lws *wsi, int opcode, const void *data, size_t n) {
    static uint32_t seed = 0x9e3779b9u; /* masking defeats proxy cache poisoning: any key is fine here */
    unsigned char buf[LWS_PRE + 8 + 1024];
    unsigned char *f = buf + LWS_PRE;
    size_t h = 0;
    if (n > 1024) return -1;
    f[h++] = (unsigned char)(0x80 | opcode);
    if (n < 126) f[h++] = (unsigned char)(0x80 | n);
    else f[h++] = 0x80 | 126, f[h++] = (unsigned char)(n >> 8), f[h++] = (unsigned char)n;
    seed ^= seed << 13, seed ^= seed >> 17, seed ^= seed << 5;
    unsigned char *key = f + h;
    memcpy(key, &seed, 4);
    h += 4;
    for (size_t i = 0; i < n; i++) f[h + i] = ((const unsigned char *)data)[i] ^ key[i & 3];
    return lws_write(wsi, f, h + n, LWS_WRITE_RAW) < (int)(h + n) ? -1 : 0;
}

/* The next pending write of a viewer: upgrade request, hello, subscribe, pong. */
static int load_viewer_write(load_run *r, load_conn *c, struct lws *wsi) {
    int rc = 0;
    if (c->tx & LOAD_TX_UPGRADE) {
        char req[LWS_PRE + 700];
        char *p = req + LWS_PRE;
        int n = snprintf(p, sizeof req - LWS_PRE,
                         "GET %s HTTP/1.1\r\nHost: %s\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                         "Sec-WebSocket-Key: " LOAD_WS_KEY "\r\nSec-WebSocket-Version: 13\r\n"
                         "Sec-WebSocket-Protocol: " LC_PROTO_SUBPROTOCOL "\r\n\r\n",
                         r->path, r->origin);
        c->tx &= (uint8_t)~LOAD_TX_UPGRADE;
        rc = n > 0 && (size_t)n < sizeof req - LWS_PRE &&
                lws_write(wsi, (unsigned char *)p, (size_t)n, LWS_WRITE_RAW) == n
            ? 0
            : -1;
    } else if (c->tx & LOAD_TX_HELLO) {
        c->tx &= (uint8_t)~LOAD_TX_HELLO;
        rc = load_ws_send(wsi, 1, r->hello, strlen(r->hello));
    } else if (c->tx & LOAD_TX_SUBSCRIBE) {
        c->tx &= (uint8_t)~LOAD_TX_SUBSCRIBE;
        rc = load_ws_send(wsi, 1, r->sub, strlen(r->sub));
    } else if (c->tx & LOAD_TX_PONG) {
        c->tx &= (uint8_t)~LOAD_TX_PONG;
        rc = load_ws_send(wsi, 10, c->ctrl, c->ctrl_len);
    }
    if (rc != 0) load_conn_lost(r, c, "write failed");
    else if (c->tx) lws_callback_on_writable(wsi);
    return rc;
}

/* The server's answer to the upgrade, up to its blank line. Returns the bytes it used of
 * p, or -1 (the connection fails; the reason recorded). */
static long load_handshake_rx(load_run *r, load_conn *c, const uint8_t *p, size_t len) {
    uint32_t before = c->text_len;
    load_text_append(c, p, len < LOAD_HANDSHAKE_MAX ? len : LOAD_HANDSHAKE_MAX);
    char *end = c->text ? strstr(c->text, "\r\n\r\n") : NULL;
    if (!end) {
        if (c->text_len >= LOAD_HANDSHAKE_MAX || c->text_len == before) {
            load_conn_lost(r, c, "handshake: no end of the HTTP response within 4 KiB");
            return -1;
        }
        return (long)len;
    }
    size_t used = (size_t)(end + 4 - c->text) - before;
    end[2] = 0;
    char why[LOAD_REASON_LEN];
    int status = 0;
    if (sscanf(c->text, "HTTP/1.%*d %d", &status) != 1 || status != 101) {
        snprintf(why, sizeof why, "handshake: HTTP %d (lucentd answers 503 over --max-clients)", status);
        load_conn_lost(r, c, why);
        return -1;
    }
    if (!strstr(c->text, LOAD_WS_ACCEPT) || !strstr(c->text, LC_PROTO_SUBPROTOCOL)) {
        load_conn_lost(r, c, "handshake: 101 without the right Sec-WebSocket-Accept or subprotocol");
        return -1;
    }
    c->text_len = 0;
    c->state = LOAD_WELCOME_WAIT;
    c->tx |= LOAD_TX_HELLO;
    lws_callback_on_writable(c->wsi);
    return (long)used;
}

/* Payload bytes of the current frame. */
static void load_ws_payload(load_conn *c, const uint8_t *p, size_t n) {
    if (c->opcode >= 8) { /* control: close code and reason, or a ping's payload to echo */
        size_t k = n < 125u - c->ctrl_len ? n : 125u - c->ctrl_len;
        if (!c->ctrl && !(c->ctrl = malloc(125))) return;
        memcpy(c->ctrl + c->ctrl_len, p, k);
        c->ctrl_len = (uint8_t)(c->ctrl_len + k);
        return;
    }
    c->msg_bytes += n;
    if (c->hdr_len < LOAD_HDR_KEEP) { /* the header (or a text's start) may straddle reads */
        size_t k = LOAD_HDR_KEEP - c->hdr_len < n ? LOAD_HDR_KEEP - c->hdr_len : n;
        memcpy(c->hdr + c->hdr_len, p, k);
        c->hdr_len = (uint8_t)(c->hdr_len + k);
    }
    if (!c->binary && c->state != LOAD_STREAMING) load_text_append(c, p, n);
}

/* The end of a frame: a complete message, a close or a ping. -1 closes. */
static int load_ws_frame_end(load_run *r, load_conn *c) {
    if (c->opcode == 8) {
        char why[LOAD_REASON_LEN];
        int code = c->ctrl_len >= 2 ? (c->ctrl[0] << 8) | c->ctrl[1] : 0;
        if (code)
            snprintf(why, sizeof why, "closed by the server (%d%s%.*s)", code, c->ctrl_len > 2 ? ": " : "",
                     c->ctrl_len > 62 ? 60 : c->ctrl_len - 2, c->ctrl + 2);
        else snprintf(why, sizeof why, "closed by the server");
        load_conn_lost(r, c, why);
        return -1;
    }
    if (c->opcode == 9) {
        c->tx |= LOAD_TX_PONG;
        lws_callback_on_writable(c->wsi);
        return 0;
    }
    if (c->opcode == 10 || !c->fin) return 0; /* a pong; or more fragments follow */
    c->in_msg = 0;
    if (c->binary) {
        load_on_frame(r, c, load_now_us());
        return 0;
    }
    return load_viewer_text(r, c);
}

/* A frame header is complete in c->fh: where its payload goes. -1 on a protocol error. */
static int load_ws_header(load_run *r, load_conn *c) {
    int op = c->fh[0] & 0x0f, len7 = c->fh[1] & 0x7f;
    if (c->fh[1] & 0x80) { /* servers never mask */
        load_conn_lost(r, c, "protocol: a masked frame from the server");
        return -1;
    }
    c->fin = c->fh[0] >> 7;
    c->opcode = (uint8_t)op;
    c->remain = len7 == 126 ? load_be(c->fh + 2, 2) : len7 == 127 ? load_be(c->fh + 2, 8) : (uint64_t)len7;
    if (op >= 8) {
        c->ctrl_len = 0;
        return 0;
    }
    if (op == 1 || op == 2) { /* a new message */
        if (c->in_msg) r->bad_frames++;
        c->in_msg = 1;
        c->binary = op == 2;
        c->hdr_len = 0;
        c->msg_bytes = 0;
        c->text_len = 0;
    } else if (op != 0 || !c->in_msg) {
        load_conn_lost(r, c, "protocol: unexpected WebSocket opcode");
        return -1;
    }
    return 0;
}

/* Bytes from a viewer's socket: the handshake's answer, then WebSocket frames. */
static int load_viewer_rx(load_run *r, load_conn *c, const uint8_t *p, size_t len) {
    if (c->state == LOAD_UPGRADING) {
        long used = load_handshake_rx(r, c, p, len);
        if (used < 0) return -1;
        p += used, len -= (size_t)used;
    }
    while (len) {
        if (c->fh_len < c->fh_need || c->fh_need == 0) {
            if (!c->fh_need) c->fh_need = 2;
            c->fh[c->fh_len++] = *p++, len--;
            if (c->fh_len == 2) {
                int len7 = c->fh[1] & 0x7f;
                c->fh_need = (uint8_t)(2 + (len7 == 126 ? 2 : len7 == 127 ? 8 : 0) + (c->fh[1] & 0x80 ? 4 : 0));
            }
            if (c->fh_len < c->fh_need) continue;
            if (load_ws_header(r, c) != 0) return -1;
            if (c->remain) continue;
        } else {
            size_t k = c->remain < len ? (size_t)c->remain : len;
            load_ws_payload(c, p, k);
            p += k, len -= k, c->remain -= k;
            if (c->remain) continue;
        }
        c->fh_len = c->fh_need = 0; /* the frame is over */
        if (load_ws_frame_end(r, c) != 0) return -1;
    }
    return 0;
}

static int load_viewer_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_context *ctx = lws_get_context(wsi);
    load_run *r = ctx ? lws_context_user(ctx) : NULL;
    load_conn *c = lws_get_opaque_user_data(wsi);
    if (!r || !c || c == &r->ctl) return lws_callback_http_dummy(wsi, reason, user, in, len);
    char why[LOAD_REASON_LEN];
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        snprintf(why, sizeof why, "connect: %.100s", in ? (const char *)in : "(unknown error)");
        load_conn_lost(r, c, why);
        c->wsi = NULL;
        return 0;
    case LWS_CALLBACK_RAW_CONNECTED:
        c->state = LOAD_UPGRADING;
        c->tx |= LOAD_TX_UPGRADE;
        lws_callback_on_writable(wsi);
        return 0;
    case LWS_CALLBACK_RAW_WRITEABLE:
        if (c->state == LOAD_FAILED || c->state == LOAD_DROPPED) return -1;
        return load_viewer_write(r, c, wsi);
    case LWS_CALLBACK_RAW_RX:
        if (c->state == LOAD_FAILED || c->state == LOAD_DROPPED) return -1;
        return load_viewer_rx(r, c, in, len);
    case LWS_CALLBACK_RAW_CLOSE:
        if (r->phase < LOAD_P_DONE)
            load_conn_lost(r, c,
                           c->state == LOAD_UPGRADING ? "connection closed during the handshake"
                                                      : "connection closed (no close frame)");
        c->wsi = NULL;
        return 0;
    default: break;
    }
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}

static const struct lws_protocols load_protocols[] = {
    {LC_PROTO_SUBPROTOCOL, load_ctl_callback, 0, 65536, 0, NULL, 0},
    {"lucent-load-raw", load_viewer_callback, 0, 0, 0, NULL, 0},
    {NULL, NULL, 0, 0, 0, NULL, 0},
};

/* Starts one connection: the controller (WebSocket) or a viewer (raw). */
static void load_connect(load_run *r, load_conn *c) {
    struct lws_client_connect_info ci;
    memset(&ci, 0, sizeof ci);
    ci.context = r->ctx;
    ci.address = r->host;
    ci.port = r->port;
    ci.path = r->path;
    ci.host = r->origin;
    ci.origin = r->origin;
    ci.pwsi = &c->wsi;
    ci.opaque_user_data = c;
    if (c->idx == LOAD_CTL_IDX) ci.protocol = LC_PROTO_SUBPROTOCOL;
    else {
        ci.method = "RAW";
        ci.local_protocol_name = "lucent-load-raw";
        r->n_pending++;
    }
    if (r->tls) {
        ci.ssl_connection = LCCSCF_USE_SSL;
        ci.alpn = "http/1.1";
        if (ctl_insecure)
            ci.ssl_connection |= LCCSCF_ALLOW_SELFSIGNED | LCCSCF_SKIP_SERVER_CERT_HOSTNAME_CHECK |
                LCCSCF_ALLOW_EXPIRED | LCCSCF_ALLOW_INSECURE;
    }
    c->state = LOAD_CONNECTING;
    if (!lws_client_connect_via_info(&ci)) {
        c->wsi = NULL;
        /* a connection error reported inside the call has been counted already */
        if (c->state == LOAD_CONNECTING) load_conn_lost(r, c, "cannot start the connection (descriptors?)");
    }
}

/* Connect pacing: --connect-rate per second, and not too many handshakes at once. */
static void load_connect_some(load_run *r, uint64_t now) {
    double allowed = (double)(now - r->connect_start) * r->o->connect_rate / 1e6 + 1;
    uint32_t max_pending = r->o->connect_rate > 64 ? (uint32_t)r->o->connect_rate : 64;
    while (r->next_connect < r->n && r->next_connect < allowed && r->n_pending < max_pending)
        load_connect(r, &r->conns[r->next_connect++]);
}

/* --- the schedule ---------------------------------------------------------------------- */

static void load_enter(load_run *r, int phase, uint64_t now) {
    r->phase = phase;
    r->phase_t = now;
}

/* Connecting: the controller first (its welcome says the server takes us and has the scene's
 * bounds), then the viewers at --connect-rate until each has its first frame or failed. */
static void load_step_connect(load_run *r, uint64_t now) {
    if (!r->ctl_ready) {
        if (now - r->t0 > (uint64_t)CTL_TIMEOUT_MS * 1000)
            load_fatal(r, CTL_EXIT_CONN, "the controller had no welcome within 5 s (%s)", ctl_url);
        return;
    }
    if (!r->connect_start) r->connect_start = now;
    load_connect_some(r, now);
    /* N / C seconds of connecting, then 30 s for the last handshakes and first frames */
    double limit = (double)r->n / r->o->connect_rate + 30;
    int late = (double)(now - r->connect_start) / 1e6 > limit;
    if (!(r->next_connect == r->n && r->n_pending == 0) && !late) return;
    for (uint32_t i = 0; late && i < r->n; i++) {
        load_conn *c = &r->conns[i];
        if (c->state == LOAD_IDLE || c->state == LOAD_CONNECTING || c->state == LOAD_UPGRADING ||
            c->state == LOAD_WELCOME_WAIT || c->state == LOAD_SUBSCRIBING) {
            load_conn_lost(r, c,
                           c->state == LOAD_IDLE              ? "not started within the connect time"
                               : c->state == LOAD_SUBSCRIBING ? "no first frame within the connect time"
                                                              : "no welcome within the connect time");
            if (c->wsi) lws_set_timeout(c->wsi, PENDING_TIMEOUT_USER_OK, LWS_TO_KILL_ASYNC);
        }
    }
    r->connect_s = (double)(now - r->connect_start) / 1e6;
    fprintf(stderr, "lucentctl: load: %u/%u viewers connected in %.1f s (%u failed)\n", r->n_streaming, r->n,
            r->connect_s, r->n_failed);
    if (!r->n_streaming) {
        load_fatal(r, r->n_refused ? CTL_EXIT_REFUSED : CTL_EXIT_CONN, "no viewer could connect to %s", ctl_url);
        return;
    }
    load_enter(r, LOAD_P_WARMUP, now);
    load_ctl_push(r, LOAD_Q_WARMUP);
}

/* Warm-up: the light placed once, shown by every viewer, then --warmup seconds of quiet. */
static void load_step_warmup(load_run *r, uint64_t now) {
    if (!r->warm_rev) {
        if ((double)(now - r->phase_t) / 1e6 > LOAD_ACK_WAIT_S)
            load_fatal(r, CTL_EXIT_CONN, "the warm-up light.set had no reply within 10 s%s", "");
        return;
    }
    if (!r->rev_base) { /* the ok came: wait until every viewer shows it */
        if (now - r->last_scan < 10000) return;
        r->last_scan = now;
        int timeout = (double)(now - r->phase_t) / 1e6 > LOAD_WARMUP_SEEN_S;
        uint32_t on = load_count_at(r, r->warm_rev);
        if (on < r->n_streaming && !timeout) return;
        if (on < r->n_streaming)
            fprintf(stderr, "lucentctl: load: only %u/%u viewers showed the warm-up revision within %.0f s\n", on,
                    r->n_streaming, LOAD_WARMUP_SEEN_S);
        r->rev_base = r->warm_rev;
        r->phase_t = now; /* the pause starts now */
        return;
    }
    if ((double)(now - r->phase_t) / 1e6 < r->o->warmup) return;
    for (uint32_t i = 0; i < r->n; i++)
        if (r->conns[i].state == LOAD_STREAMING) r->conns[i].measured = 1, r->n_measured++;
    r->recording = 1;
    r->run_start = now;
    load_enter(r, LOAD_P_RUN, now);
}

static uint64_t load_max_acked(const load_run *r) {
    uint64_t m = 0;
    for (uint32_t k = 0; k < r->n_sent; k++)
        if (r->rev[k] > m) m = r->rev[k];
    return m;
}

static void load_begin_cleanup(load_run *r, uint64_t now) {
    r->run_end = now;
    r->recording = 0;
    r->on_final = r->final_rev ? load_count_at(r, r->final_rev) : 0;
    load_enter(r, LOAD_P_CLEANUP, now);
    load_ctl_push(r, LOAD_Q_REMOVE);
}

/* Updates at --rate, the last oks, then up to --settle for the final revision everywhere. */
static void load_step_run(load_run *r, uint64_t now) {
    double since = (double)(now - r->phase_t) / 1e6;
    if (r->phase == LOAD_P_RUN) {
        while (r->n_sent < r->n_updates && now >= r->run_start + (uint64_t)(r->n_sent * 1e6 / r->o->rate))
            load_ctl_push(r, r->n_sent++);
        if (r->n_sent == r->n_updates) load_enter(r, LOAD_P_ACKWAIT, now);
    } else if (r->phase == LOAD_P_ACKWAIT) {
        if (r->n_acked + r->n_errors < r->n_sent && since < LOAD_ACK_WAIT_S + r->o->settle) return;
        r->final_rev = load_max_acked(r);
        load_enter(r, LOAD_P_SETTLE, now);
    } else if (r->phase == LOAD_P_SETTLE) {
        if (now - r->last_scan < 10000) return;
        r->last_scan = now;
        r->final_rev = load_max_acked(r); /* oks that came after the wait still move the target */
        if (r->final_rev && load_count_at(r, r->final_rev) < r->n_streaming && since < r->o->settle) return;
        r->settle_s = since;
        load_begin_cleanup(r, now);
    }
}

/* One status line a second on stderr. */
static void load_progress(load_run *r, uint64_t now) {
    if (now - r->last_progress < 1000000) return;
    r->last_progress = now;
    if (r->phase == LOAD_P_CONNECT && r->ctl_ready)
        fprintf(stderr, "lucentctl: load: connected %u/%u (%u failed, %u connecting)\n", r->n_streaming, r->n,
                r->n_failed, r->n_pending);
    else if (r->phase == LOAD_P_WARMUP)
        fprintf(stderr, "lucentctl: load: warm-up: revision %llu on %u/%u viewers\n", (unsigned long long)r->warm_rev,
                r->warm_rev ? load_count_at(r, r->warm_rev) : 0, r->n_streaming);
    else if (r->phase >= LOAD_P_RUN && r->phase <= LOAD_P_SETTLE) {
        uint64_t latest = load_max_acked(r);
        fprintf(stderr, "lucentctl: load: %.1f s: sent %u/%u, acked %u, revision %llu on %u/%u viewers, %u dropped\n",
                (double)(now - r->run_start) / 1e6, r->n_sent, r->n_updates, r->n_acked, (unsigned long long)latest,
                latest ? load_count_at(r, latest) : 0, r->n_streaming, r->n_dropped);
    }
}

static void load_tick(lws_sorted_usec_list_t *sul) {
    load_run *r = lws_container_of(sul, load_run, tick);
    uint64_t now = load_now_us();
    if (load_stop && !r->interrupted && r->phase < LOAD_P_CLEANUP) {
        r->interrupted = 1;
        fprintf(stderr, "lucentctl: load: interrupted; reporting what was measured\n");
        if (r->phase >= LOAD_P_RUN) r->final_rev = load_max_acked(r);
        if (r->phase < LOAD_P_RUN) r->phase = LOAD_P_DONE;
        else load_begin_cleanup(r, now);
    }
    if (r->phase == LOAD_P_CONNECT) load_step_connect(r, now);
    else if (r->phase == LOAD_P_WARMUP) load_step_warmup(r, now);
    else if (r->phase >= LOAD_P_RUN && r->phase <= LOAD_P_SETTLE) load_step_run(r, now);
    else if (r->phase == LOAD_P_CLEANUP && (r->remove_acked || now - r->phase_t > 2000000)) r->phase = LOAD_P_DONE;
    if (r->fatal[0]) r->phase = LOAD_P_DONE;
    load_progress(r, now);
    /* also when done: lws runs the tick before its poll, whose wait is bounded by the next one */
    lws_sul_schedule(r->ctx, 0, &r->tick, load_tick, LOAD_TICK_US);
}

/* --- the report ------------------------------------------------------------------------ */

static cJSON *load_reasons_json(const load_reasons *rs) {
    cJSON *o = cJSON_CreateObject();
    for (int i = 0; i < rs->n; i++) cJSON_AddNumberToObject(o, rs->what[i], rs->count[i]);
    if (rs->other) cJSON_AddNumberToObject(o, "other", rs->other);
    return o;
}

static double load_round(double v, double unit) { return floor(v / unit + 0.5) * unit; }

/* The update -> ok times (ms), sorted into p50/p99/max. */
static void load_ack_json(const load_run *r, cJSON *into) {
    double *v = malloc((r->n_sent ? r->n_sent : 1) * sizeof *v);
    int n = 0;
    for (uint32_t k = 0; v && k < r->n_sent; k++)
        if (r->rev[k] && r->ack_us[k] >= r->send_us[k]) v[n++] = (double)(r->ack_us[k] - r->send_us[k]) / 1000.0;
    for (int i = 1; i < n; i++) /* insertion sort: at most R x S values, nearly sorted */
        for (int j = i; j > 0 && v[j - 1] > v[j]; j--) {
            double t = v[j];
            v[j] = v[j - 1], v[j - 1] = t;
        }
    cJSON *a = cJSON_AddObjectToObject(into, "ack_ms");
    cJSON_AddNumberToObject(a, "p50", n ? load_round(v[(n - 1) / 2], 0.001) : 0);
    cJSON_AddNumberToObject(a, "p99", n ? load_round(v[(int)floor(0.99 * (n - 1))], 0.001) : 0);
    cJSON_AddNumberToObject(a, "max", n ? load_round(v[n - 1], 0.001) : 0);
    free(v);
}

static void load_traffic_json(const load_run *r, cJSON *j, double win) {
    uint32_t fmin = UINT32_MAX, fmax = 0;
    for (uint32_t i = 0; i < r->n; i++)
        if (r->conns[i].measured) {
            if (r->conns[i].frames < fmin) fmin = r->conns[i].frames;
            if (r->conns[i].frames > fmax) fmax = r->conns[i].frames;
        }
    double per = r->n_measured && win > 0 ? 1.0 / ((double)r->n_measured * win) : 0;
    cJSON *f = cJSON_AddObjectToObject(j, "frames");
    cJSON_AddNumberToObject(f, "total", (double)r->frames);
    cJSON_AddNumberToObject(f, "window", (double)r->frames_win);
    cJSON_AddNumberToObject(f, "per_client_per_s", load_round((double)r->frames_win * per, 0.001));
    cJSON_AddNumberToObject(f, "per_client_min", r->n_measured ? fmin : 0);
    cJSON_AddNumberToObject(f, "per_client_max", fmax);
    cJSON_AddNumberToObject(f, "keyframes", (double)r->keyframes);
    cJSON_AddNumberToObject(f, "deltas", (double)r->deltas);
    cJSON_AddNumberToObject(f, "bad", (double)r->bad_frames);
    cJSON_AddNumberToObject(f, "seq_gaps", (double)r->seq_gaps);
    cJSON *b = cJSON_AddObjectToObject(j, "bytes");
    cJSON_AddNumberToObject(b, "total", (double)r->bytes);
    cJSON_AddNumberToObject(b, "window", (double)r->bytes_win);
    cJSON_AddNumberToObject(b, "per_client_per_s", load_round((double)r->bytes_win * per, 0.1));
    cJSON *t = cJSON_AddObjectToObject(j, "texts");
    cJSON_AddNumberToObject(t, "total", (double)r->texts);
    cJSON_AddNumberToObject(t, "changed", (double)r->changed);
    cJSON_AddNumberToObject(t, "errors", (double)r->error_msgs);
}

/* Everything measured, as one JSON object (the table is printed from it). */
static cJSON *load_report(load_run *r) {
    static load_hist h; /* 14 KB: one per process */
    memset(&h, 0, sizeof h);
    uint64_t missing = load_fold(r, &h);
    double win = r->run_end > r->run_start ? (double)(r->run_end - r->run_start) / 1e6 : 0;
    cJSON *j = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "url", ctl_url);
    cJSON_AddStringToObject(j, "stream", r->o->stream);
    cJSON_AddStringToObject(j, "encoding", r->o->encoding);
    cJSON_AddNumberToObject(j, "rate", r->o->rate);
    cJSON_AddNumberToObject(j, "duration", r->o->duration);
    cJSON_AddNumberToObject(j, "connect_rate", r->o->connect_rate);
    cJSON_AddBoolToObject(j, "interrupted", r->interrupted);
    if (r->fatal[0]) cJSON_AddStringToObject(j, "error", r->fatal);
    cJSON *c = cJSON_AddObjectToObject(j, "clients");
    cJSON_AddNumberToObject(c, "requested", r->n);
    cJSON_AddNumberToObject(c, "connected", r->ever_streaming);
    cJSON_AddNumberToObject(c, "failed", r->n_failed);
    cJSON_AddNumberToObject(c, "dropped", r->n_dropped);
    cJSON_AddNumberToObject(c, "measured", r->n_measured);
    cJSON_AddNumberToObject(c, "connect_s", load_round(r->connect_s, 0.001));
    cJSON_AddItemToObject(c, "failures", load_reasons_json(&r->fails));
    cJSON_AddItemToObject(c, "drops", load_reasons_json(&r->drops));
    cJSON *u = cJSON_AddObjectToObject(j, "updates");
    cJSON_AddNumberToObject(u, "planned", r->n_updates);
    cJSON_AddNumberToObject(u, "sent", r->n_sent);
    cJSON_AddNumberToObject(u, "acknowledged", r->n_acked);
    cJSON_AddNumberToObject(u, "errors", r->n_errors);
    cJSON_AddItemToObject(u, "error_codes", load_reasons_json(&r->ctl_errors));
    cJSON_AddNumberToObject(u, "warmup_revision", (double)r->rev_base);
    cJSON_AddNumberToObject(u, "final_revision", (double)r->final_rev);
    load_ack_json(r, u);
    cJSON *l = cJSON_AddObjectToObject(j, "latency_ms");
    cJSON_AddNumberToObject(l, "pairs", (double)(h.n + missing));
    cJSON_AddNumberToObject(l, "samples", (double)h.n);
    cJSON_AddNumberToObject(l, "missing", (double)missing);
    const double q[4] = {0.5, 0.9, 0.99, 1.0};
    const char *qn[4] = {"p50", "p90", "p99", "max"};
    for (int i = 0; i < 4; i++) cJSON_AddNumberToObject(l, qn[i], load_round(load_hist_ms(&h, q[i]), 0.001));
    cJSON_AddNumberToObject(l, "mean", h.n ? load_round(h.sum_us / (double)h.n / 1000.0, 0.001) : 0);
    cJSON_AddStringToObject(l, "resolution", "log buckets, 128 per octave (0.8%); max exact");
    cJSON_AddBoolToObject(l, "out_of_memory", r->oom);
    load_traffic_json(r, j, win);
    cJSON *f = cJSON_AddObjectToObject(j, "final");
    cJSON_AddNumberToObject(f, "revision", (double)r->final_rev);
    cJSON_AddNumberToObject(f, "on_final", r->on_final);
    cJSON_AddNumberToObject(f, "fraction", r->n_measured ? load_round((double)r->on_final / r->n_measured, 1e-6) : 0);
    cJSON_AddNumberToObject(f, "settle_s", load_round(r->settle_s, 0.001));
    cJSON_AddNumberToObject(j, "window_s", load_round(win, 0.001));
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    double us = (double)ru.ru_utime.tv_sec + ru.ru_utime.tv_usec / 1e6,
           sy = (double)ru.ru_stime.tv_sec + ru.ru_stime.tv_usec / 1e6;
    cJSON *me = cJSON_AddObjectToObject(j, "load_client");
    cJSON_AddNumberToObject(me, "cpu_s", load_round(us + sy, 0.001));
    cJSON_AddNumberToObject(me, "user_s", load_round(us, 0.001));
    cJSON_AddNumberToObject(me, "sys_s", load_round(sy, 0.001));
    cJSON_AddNumberToObject(me, "max_rss_kb", (double)ru.ru_maxrss);
    cJSON_AddNumberToObject(me, "nofile_limit", (double)r->nofile);
    cJSON_AddNumberToObject(me, "turn_us", r->turns ? load_round((double)r->serve_us / (double)r->turns, 1) : 0);
    return j;
}

static double load_num(const cJSON *o, const char *a, const char *b) {
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, a);
    if (b) x = cJSON_GetObjectItemCaseSensitive(x, b);
    return cJSON_IsNumber(x) ? x->valuedouble : 0;
}

static void load_print_reasons(const char *what, const cJSON *o) {
    for (const cJSON *c = o ? o->child : NULL; c; c = c->next)
        printf("  %-12s %6.0f  %s\n", what, c->valuedouble, c->string);
}

static void load_print(const cJSON *j) {
    const cJSON *cl = cJSON_GetObjectItemCaseSensitive(j, "clients");
    printf("clients      requested %.0f, connected %.0f, failed %.0f, dropped %.0f (connecting took %.1f s)\n",
           load_num(j, "clients", "requested"), load_num(j, "clients", "connected"), load_num(j, "clients", "failed"),
           load_num(j, "clients", "dropped"), load_num(j, "clients", "connect_s"));
    load_print_reasons("failed:", cJSON_GetObjectItemCaseSensitive(cl, "failures"));
    load_print_reasons("dropped:", cJSON_GetObjectItemCaseSensitive(cl, "drops"));
    printf("updates      sent %.0f/%.0f, acknowledged %.0f, errors %.0f; ok after p50 %.2f ms, max %.2f ms\n",
           load_num(j, "updates", "sent"), load_num(j, "updates", "planned"), load_num(j, "updates", "acknowledged"),
           load_num(j, "updates", "errors"), load_num(cJSON_GetObjectItemCaseSensitive(j, "updates"), "ack_ms", "p50"),
           load_num(cJSON_GetObjectItemCaseSensitive(j, "updates"), "ack_ms", "max"));
    load_print_reasons("error:",
                       cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(j, "updates"), "error_codes"));
    printf("latency ms   p50 %.2f  p90 %.2f  p99 %.2f  max %.2f  (%.0f pairs, %.0f missing)\n",
           load_num(j, "latency_ms", "p50"), load_num(j, "latency_ms", "p90"), load_num(j, "latency_ms", "p99"),
           load_num(j, "latency_ms", "max"), load_num(j, "latency_ms", "pairs"), load_num(j, "latency_ms", "missing"));
    printf("frames       %.2f per client per s (%.0f in the %.1f s window; per client %.0f..%.0f), %.0f bad, "
           "%.0f sequence gaps\n",
           load_num(j, "frames", "per_client_per_s"), load_num(j, "frames", "window"), load_num(j, "window_s", NULL),
           load_num(j, "frames", "per_client_min"), load_num(j, "frames", "per_client_max"),
           load_num(j, "frames", "bad"), load_num(j, "frames", "seq_gaps"));
    printf("bytes        %.0f per client per s, %.0f in total\n", load_num(j, "bytes", "per_client_per_s"),
           load_num(j, "bytes", "total"));
    printf("final        %.0f of %.0f measured viewers on revision %.0f (%.1f%%) after %.2f s\n",
           load_num(j, "final", "on_final"), load_num(j, "clients", "measured"), load_num(j, "final", "revision"),
           100 * load_num(j, "final", "fraction"), load_num(j, "final", "settle_s"));
    printf("load client  %.2f CPU s (user %.2f, sys %.2f), peak RSS %.1f MB\n", load_num(j, "load_client", "cpu_s"),
           load_num(j, "load_client", "user_s"), load_num(j, "load_client", "sys_s"),
           load_num(j, "load_client", "max_rss_kb") / 1024);
    fflush(stdout);
}

/* --- setup ----------------------------------------------------------------------------- */

/* ws://host[:port][/path] or wss://...; 0 or -1 (printed). */
static int load_parse_url(load_run *r, const char *url) {
    const char *p = url;
    if (!strncmp(p, "ws://", 5)) p += 5;
    else if (!strncmp(p, "wss://", 6)) p += 6, r->tls = 1;
    else return ctl_usage_error("load: unsupported URL '%s' (expected ws://host:port/ or wss://host:port/)", url);
    const char *e = p;
    if (*e == '[')
        while (*e && *e++ != ']') {
        }
    while (*e && *e != ':' && *e != '/') e++;
    size_t hl = (size_t)(e - p);
    if (!hl || hl >= sizeof r->host) return ctl_usage_error("load: bad host in URL '%s'", url);
    memcpy(r->host, p, hl);
    r->host[hl] = 0;
    r->port = r->tls ? 443 : 80;
    if (*e == ':') {
        long long port;
        char num[8];
        size_t n = strcspn(e + 1, "/");
        if (n >= sizeof num) return ctl_usage_error("load: bad port in URL '%s'", url);
        memcpy(num, e + 1, n);
        num[n] = 0;
        if (ctl_parse_int(num, 1, 65535, &port) != 0) return ctl_usage_error("load: bad port in URL '%s'", url);
        r->port = (int)port;
        e += 1 + n;
    }
    snprintf(r->path, sizeof r->path, "%s", *e ? e : "/");
    snprintf(r->origin, sizeof r->origin, "%s:%d", r->host, r->port);
    return 0;
}

/* Raises the open-files limit to its hard limit; says so when N viewers cannot fit. */
static unsigned long load_raise_nofile(long long clients) {
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) != 0) return 1024;
    rlim_t want = rl.rlim_max;
    if (want == RLIM_INFINITY || want > (1u << 20)) want = 1u << 20; /* fs.nr_open's default */
    if (rl.rlim_cur < want) {
        struct rlimit nl = {want, rl.rlim_max};
        if (setrlimit(RLIMIT_NOFILE, &nl) == 0) rl.rlim_cur = want;
    }
    unsigned long have = (unsigned long)rl.rlim_cur;
    if ((unsigned long long)clients + 16 > have)
        fprintf(stderr,
                "lucentctl: load: --clients %lld needs %lld descriptors, but the open-files limit is %lu (its hard "
                "limit): at most %lu viewers can connect; raise the hard limit (ulimit -Hn as root, systemd "
                "LimitNOFILE=)\n",
                clients, clients + 16, have, have > 16 ? have - 16 : 0);
    return have;
}

/* The viewers' hello and subscribe texts, the tables; 0 or -1 (out of memory). */
static int load_alloc(load_run *r) {
    const load_opts *o = r->o;
    cJSON *h = cJSON_CreateObject(), *enc = cJSON_CreateArray();
    cJSON_AddStringToObject(h, "type", "hello");
    cJSON_AddNumberToObject(h, "id", 1);
    cJSON_AddStringToObject(h, "client", "lucentctl-load");
    cJSON_AddStringToObject(h, "token", ctl_token);
    cJSON_AddItemToArray(enc, cJSON_CreateString(o->encoding));
    cJSON_AddItemToObject(h, "encodings", enc);
    r->hello = cJSON_PrintUnformatted(h);
    cJSON_Delete(h);
    snprintf(r->sub, sizeof r->sub, "{\"type\":\"subscribe\",\"id\":\"s\",\"stream\":\"%s\",\"encoding\":\"%s\"}",
             o->stream, o->encoding);
    r->n = (uint32_t)o->clients;
    r->n_updates = (uint32_t)floor(o->rate * o->duration + 0.5);
    r->n_rows = r->n_updates + LOAD_REV_MARGIN;
    r->conns = calloc(r->n, sizeof *r->conns);
    r->rows = calloc(r->n_rows, sizeof *r->rows);
    r->send_us = calloc(r->n_updates, sizeof *r->send_us);
    r->ack_us = calloc(r->n_updates, sizeof *r->ack_us);
    r->rev = calloc(r->n_updates, sizeof *r->rev);
    if (!r->hello || !r->conns || !r->rows || !r->send_us || !r->ack_us || !r->rev) return -1;
    if (strlen(r->hello) > 900) return -1; /* cannot happen: token <= 256 bytes */
    for (uint32_t i = 0; i < r->n; i++) r->conns[i].idx = i;
    r->ctl.idx = LOAD_CTL_IDX;
    return 0;
}

static void load_free(load_run *r) {
    if (r->ctx) {
        lws_sul_cancel(&r->tick);
        lws_context_destroy(r->ctx);
    }
    for (uint32_t i = 0; r->conns && i < r->n; i++) free(r->conns[i].text), free(r->conns[i].ctrl);
    for (uint32_t v = 0; r->rows && v < r->n_rows; v++) free(r->rows[v]);
    free(r->ctl.text);
    free(r->rows);
    free(r->conns);
    free(r->send_us);
    free(r->ack_us);
    free(r->rev);
    free(r->hello);
    free(r);
}

/* lws's own errors go to stderr, at most 20 of them (a descriptor storm must not flood it). */
static void load_lws_log(int level, const char *line) {
    static int shown;
    (void)level;
    if (shown++ < 20) fprintf(stderr, "lucentctl: load: libwebsockets: %s", line);
}

static struct lws_context *load_context(load_run *r) {
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = load_protocols;
    info.user = r;
    info.timeout_secs = 20; /* handshakes: a loaded server may take a while to accept */
    info.gid = -1;
    info.uid = -1;
    /* fd_limit_per_thread stays 0: below the open-files limit lws 4.1 finds the connection of
     * every ready descriptor by a linear scan of its table (wsi_from_fd); 0 = the limit (raised
     * above), and a direct lookup */
    info.pt_serv_buf_size = 65536; /* the one read buffer of all viewers (raw reads land here) */
    if (r->tls) {
        info.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
        info.client_ssl_ca_filepath = ctl_ca_file;
    }
    lws_set_log_level(LLL_ERR, load_lws_log);
    return lws_create_context(&info);
}

/* The service loop. poll() costs O(descriptors) per call (57 ns per socket at 1 000 viewers on
 * this VM, more at 10 000: cache misses) and lws calls it once per turn, so turns are spaced
 * three times the last turn's cost apart (an average), at least LOAD_POLL_NS_PER_CLIENT x N
 * and at most LOAD_POLL_MAX_US: ready sockets gather and polling stays about a quarter of
 * this thread (unspaced, at 1 000 viewers, sock_poll/tcp_poll were 60 % of its profile).
 * Arrival times are read after the wait, so they err late by up to one spacing; the report
 * gives the mean spacing (load_client.turn_us). */
static void load_serve(load_run *r) {
    uint64_t floor_us = (uint64_t)r->n * LOAD_POLL_NS_PER_CLIENT / 1000;
    double cost = 0;
    while (r->phase != LOAD_P_DONE) {
        uint64_t t = load_now_us();
        if (lws_service(r->ctx, 0) < 0) break;
        uint64_t spent = load_now_us() - t;
        cost = 0.9 * cost + 0.1 * (double)spent;
        uint64_t gap = (uint64_t)(3 * cost);
        if (gap < floor_us) gap = floor_us;
        if (gap > LOAD_POLL_MAX_US) gap = LOAD_POLL_MAX_US;
        if (spent < gap) {
            struct timespec ts = {0, (long)(gap - spent) * 1000};
            nanosleep(&ts, NULL);
        }
        r->turns++;
    }
    r->serve_us = load_now_us() - r->t0;
}

static int load_write_json(const char *path, const cJSON *rep) {
    char *t = cJSON_Print(rep);
    FILE *f = t ? fopen(path, "w") : NULL;
    int bad = !f || fputs(t, f) < 0 || fputc('\n', f) < 0;
    if (f && fclose(f) != 0) bad = 1;
    free(t);
    if (bad) fprintf(stderr, "lucentctl: load: cannot write %s\n", path);
    return bad ? -1 : 0;
}

int ctl_cmd_load(int argc, char **argv) {
    if (ctl_wants_help(argc, argv)) {
        load_usage(stdout);
        return CTL_EXIT_OK;
    }
    load_opts o;
    int rc = load_parse(argc, argv, &o);
    if (rc != CTL_EXIT_OK) return rc;
    load_run *r = calloc(1, sizeof *r);
    if (!r) goto oom;
    r->o = &o;
    if (load_parse_url(r, ctl_url) != 0) {
        free(r);
        return CTL_EXIT_USAGE;
    }
    r->nofile = load_raise_nofile(o.clients);
    if (load_alloc(r) != 0) goto oom;
    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = load_on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    if (!(r->ctx = load_context(r))) {
        fprintf(stderr, "lucentctl: load: cannot create the libwebsockets context\n");
        rc = CTL_EXIT_CONN;
        goto out;
    }
    r->t0 = r->last_progress = load_now_us();
    load_enter(r, LOAD_P_CONNECT, r->t0);
    r->q[0] = LOAD_Q_HELLO, r->q_len = 1; /* written once the controller is connected */
    load_connect(r, &r->ctl);
    lws_sul_schedule(r->ctx, 0, &r->tick, load_tick, LOAD_TICK_US);
    load_serve(r);
    cJSON *rep = load_report(r);
    if (!rep) goto oom;
    if (r->fatal[0]) fprintf(stderr, "lucentctl: load: %s\n", r->fatal);
    if (ctl_json) {
        char *t = cJSON_PrintUnformatted(rep);
        printf("%s\n", t ? t : "{}");
        free(t);
    } else if (r->ever_streaming || r->n_failed) load_print(rep); /* not when the controller never got in */
    if (o.json && load_write_json(o.json, rep) != 0) rc = CTL_EXIT_USAGE;
    cJSON_Delete(rep);
    if (r->fatal[0]) rc = r->rc;
    else if (rc == CTL_EXIT_OK && r->ever_streaming < r->n) {
        fprintf(stderr, "lucentctl: load: only %u of %u viewers connected (see the failures above)\n",
                r->ever_streaming, r->n);
        rc = CTL_EXIT_CONN;
    }
out:
    load_free(r);
    return rc;
oom:
    fprintf(stderr, "lucentctl: load: out of memory\n");
    if (r) load_free(r);
    return CTL_EXIT_CONN;
}
