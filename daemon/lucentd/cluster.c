/* cluster: the change log in a Redis stream (see cluster.h). */
#include "cluster.h"

#include <errno.h>
#include <fcntl.h>
#include <hiredis/hiredis.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "util/clock.h"
#include "util/log.h"

#define CLUSTER_BLOCK_MS 500         /* XREAD BLOCK: also how soon the reader sees a stop */
#define CLUSTER_READ_COUNT 512       /* entries per XREAD */
#define CLUSTER_ENTRY_MAX (4u << 20) /* one change (the journal's line limit) */
#define CLUSTER_SNAPSHOT_MAX (64u << 20)
#define CLUSTER_BACKOFF_MIN_MS 100
#define CLUSTER_BACKOFF_MAX_MS 5000

/* One queued append (service thread -> writer). */
typedef struct cluster_append {
    struct cluster_append *next;
    uint64_t local;
    int batch;
    char client[128];
    char *ops;
} cluster_append;

struct lc_cluster {
    lc_cluster_config cfg;
    char bake_id[64];
    char limits[64]; /* "lights=N,objects=M": KEY:limits */
    char id[LC_CLUSTER_ID_LEN + 1];
    lc_cluster_wake_fn wake;
    void *wake_arg;
    pthread_t reader, writer;
    int reader_started, writer_started;
    uint64_t from; /* reader only: the last entry delivered */
    /* reader only: who wrote entry `from` (its origin and local number; origin "" after a
     * snapshot): on reconnect the entry at that position must still be the same one. */
    char from_origin[LC_CLUSTER_ID_LEN + 1];
    uint64_t from_local;
    /* cluster.lock guards everything below */
    pthread_mutex_t lock;
    pthread_cond_t cond; /* appends/snapshots queued, or stop */
    int stop;
    lc_cluster_item *items, *items_tail;
    cluster_append *out, *out_tail;
    char *snap; /* the newest snapshot not yet written (an older one is replaced) */
    uint64_t snap_rev;
    int reader_up, writer_up, caught_up, fatal;
    uint64_t reader_connects; /* the writer reconnects when the reader did (Redis restarted) */
    char reader_why[640], writer_why[640];
    lc_cluster_stats stats;
};

/* --- URL -------------------------------------------------------------------------------------- */

static int cluster_hex(int ch) {
    if (ch >= '0' && ch <= '9') return ch - '0';
    if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
    if (ch >= 'A' && ch <= 'F') return ch - 'A' + 10;
    return -1;
}

/* Percent-decodes s[0..n) into out (cap bytes with the NUL). 0 or -1. */
static int cluster_decode(const char *s, size_t n, char *out, size_t cap) {
    size_t o = 0;
    for (size_t i = 0; i < n; i++) {
        int ch = (unsigned char)s[i];
        if (ch == '%') {
            if (i + 2 >= n) return -1;
            int hi = cluster_hex(s[i + 1]), lo = cluster_hex(s[i + 2]);
            if (hi < 0 || lo < 0) return -1;
            ch = hi * 16 + lo;
            i += 2;
        }
        if (ch == 0 || o + 1 >= cap) return -1;
        out[o++] = (char)ch;
    }
    out[o] = 0;
    return 0;
}

int lc_cluster_parse_url(const char *url, size_t len, lc_cluster_url *out, char *err, size_t errlen) {
    memset(out, 0, sizeof *out);
    out->port = 6379;
    static const char scheme[] = "redis://";
    if (len >= 9 && memcmp(url, "rediss://", 9) == 0) {
        lc_set_err(err, errlen,
                   "cluster: rediss:// (TLS) is not available: Debian 12's hiredis 0.14 has no TLS; reach Redis "
                   "over a TLS tunnel on loopback (stunnel, spiped) and give redis://127.0.0.1:PORT/KEY");
        return -1;
    }
    if (len < sizeof scheme - 1 || memcmp(url, scheme, sizeof scheme - 1) != 0) {
        lc_set_err(err, errlen,
                   "cluster: the URL must start with redis:// (redis://[[USER]:PASSWORD@]HOST[:PORT]/KEY)");
        return -1;
    }
    const char *p = url + sizeof scheme - 1, *end = url + len;
    const char *slash = memchr(p, '/', (size_t)(end - p));
    if (!slash) {
        lc_set_err(err, errlen, "cluster: the URL names no key (redis://HOST:PORT/KEY)");
        return -1;
    }
    const char *at = NULL;
    for (const char *q = p; q < slash; q++)
        if (*q == '@') at = q;
    if (!at && memchr(slash, '@', (size_t)(end - slash))) { /* a key never holds '@' */
        lc_set_err(err, errlen,
                   "cluster: the URL has '@' after its first '/': a password holding '/' must be "
                   "percent-encoded ('/' as %%2F, '@' as %%40, ':' as %%3A)");
        return -1;
    }
    if (at) {
        const char *colon = memchr(p, ':', (size_t)(at - p));
        if (!colon) {
            lc_set_err(err, errlen, "cluster: the URL's credentials must be [USER]:PASSWORD@");
            return -1;
        }
        if (cluster_decode(p, (size_t)(colon - p), out->user, sizeof out->user) != 0 ||
            cluster_decode(colon + 1, (size_t)(at - colon - 1), out->password, sizeof out->password) != 0) {
            lc_set_err(err, errlen, "cluster: the URL's user or password is too long or badly percent-encoded");
            return -1;
        }
        p = at + 1;
    }
    const char *host_end = slash, *port_at = NULL;
    if (p < slash && *p == '[') { /* [IPv6] */
        const char *close = memchr(p, ']', (size_t)(slash - p));
        if (!close) {
            lc_set_err(err, errlen, "cluster: the URL's host has '[' without ']'");
            return -1;
        }
        if (close + 1 < slash) {
            if (close[1] != ':') {
                lc_set_err(err, errlen, "cluster: unexpected text after the URL's ']'");
                return -1;
            }
            port_at = close + 2;
        }
        p++;
        host_end = close;
    } else {
        const char *colon = memchr(p, ':', (size_t)(slash - p));
        if (colon) {
            port_at = colon + 1;
            host_end = colon;
        }
    }
    size_t hl = (size_t)(host_end - p);
    if (hl == 0 || hl >= sizeof out->host) {
        lc_set_err(err, errlen, "cluster: the URL's host is %s", hl ? "too long" : "missing");
        return -1;
    }
    for (size_t i = 0; i < hl; i++) {
        char ch = p[i];
        if (!((ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '.' ||
              ch == '-' || ch == ':' || ch == '_')) {
            lc_set_err(err, errlen, "cluster: the URL's host has a character that is not allowed ('%c')", ch);
            return -1;
        }
    }
    memcpy(out->host, p, hl);
    if (port_at) {
        long port = 0;
        if (port_at == slash) port = -1;
        for (const char *q = port_at; q < slash && port >= 0; q++)
            port = *q >= '0' && *q <= '9' && port <= 65535 ? port * 10 + (*q - '0') : -1;
        if (port < 1 || port > 65535) {
            lc_set_err(err, errlen, "cluster: the URL's port must be 1..65535");
            return -1;
        }
        out->port = (int)port;
    }
    if (cluster_decode(slash + 1, (size_t)(end - slash - 1), out->key, sizeof out->key) != 0 || !out->key[0]) {
        lc_set_err(err, errlen, "cluster: the URL's key is %s",
                   slash + 1 == end ? "missing" : "too long or badly encoded");
        return -1;
    }
    for (const char *q = out->key; *q; q++) {
        char ch = *q;
        if (!((ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '.' ||
              ch == '-' || ch == ':' || ch == '_' || ch == '/' || ch == '{' || ch == '}')) {
            lc_set_err(err, errlen, "cluster: the key may hold only letters, digits and . - _ : / { } (got '%c')", ch);
            return -1;
        }
    }
    return 0;
}

/* --- shared helpers ------------------------------------------------------------------------- */

/* Under cluster.lock: appends an item for the service thread. */
static void cluster_push_locked(lc_cluster *c, lc_cluster_item *it) {
    it->next = NULL;
    if (c->items_tail) c->items_tail->next = it;
    else c->items = it;
    c->items_tail = it;
}

/* Any cluster thread: delivers an item with a copy of text (n bytes; NULL for none) and wakes
 * the service thread. 0, or -1 when out of memory (then nothing is delivered). */
static int cluster_deliver(lc_cluster *c, lc_cluster_item_kind kind, uint64_t seq, const char *text, size_t n,
                           lc_cluster_item *proto) {
    lc_cluster_item *it = calloc(1, sizeof *it);
    if (!it) return -1;
    if (proto) *it = *proto;
    it->kind = kind;
    it->seq = seq;
    it->text = NULL;
    if (text) {
        it->text = malloc(n + 1);
        if (!it->text) {
            free(it);
            return -1;
        }
        memcpy(it->text, text, n);
        it->text[n] = 0;
        it->len = n;
    }
    pthread_mutex_lock(&c->lock);
    cluster_push_locked(c, it);
    pthread_mutex_unlock(&c->lock);
    c->wake(c->wake_arg);
    return 0;
}

static void cluster_fail(lc_cluster *c, const char *why) {
    lc_error("cluster", "%s", why);
    pthread_mutex_lock(&c->lock);
    c->fatal = 1;
    snprintf(c->reader_why, sizeof c->reader_why, "%s", why);
    pthread_mutex_unlock(&c->lock);
    if (cluster_deliver(c, LC_CLUSTER_FATAL, 0, why, strlen(why), NULL) != 0) lc_error("cluster", "out of memory");
}

/* Waits up to ms unless stopping. Returns 1 when stopping. */
static int cluster_sleep(lc_cluster *c, int ms) {
    struct timespec until;
    clock_gettime(CLOCK_REALTIME, &until);
    until.tv_sec += ms / 1000;
    until.tv_nsec += (long)(ms % 1000) * 1000000L;
    if (until.tv_nsec >= 1000000000L) {
        until.tv_sec++;
        until.tv_nsec -= 1000000000L;
    }
    pthread_mutex_lock(&c->lock);
    while (!c->stop && pthread_cond_timedwait(&c->cond, &c->lock, &until) != ETIMEDOUT) {
    }
    int stop = c->stop;
    pthread_mutex_unlock(&c->lock);
    return stop;
}

static int cluster_stopping(lc_cluster *c) {
    pthread_mutex_lock(&c->lock);
    int stop = c->stop;
    pthread_mutex_unlock(&c->lock);
    return stop;
}

/* A connection: TCP with the timeout, AUTH when the URL has a password, then PING. NULL with
 * why. */
static redisContext *cluster_connect(lc_cluster *c, int extra_ms, char *why, size_t whylen) {
    const lc_cluster_url *u = &c->cfg.url;
    struct timeval tv = {c->cfg.timeout_ms / 1000, (c->cfg.timeout_ms % 1000) * 1000};
    redisContext *r = redisConnectWithTimeout(u->host, u->port, tv);
    if (!r || r->err) {
        snprintf(why, whylen, "cannot connect to Redis at %s:%d: %s", u->host, u->port,
                 r ? r->errstr : "out of memory");
        if (r) redisFree(r);
        return NULL;
    }
    int total = c->cfg.timeout_ms + extra_ms;
    struct timeval rt = {total / 1000, (total % 1000) * 1000};
    redisSetTimeout(r, rt);
    redisReply *rep = NULL;
    if (u->password[0])
        rep =
            u->user[0] ? redisCommand(r, "AUTH %s %s", u->user, u->password) : redisCommand(r, "AUTH %s", u->password);
    else rep = redisCommand(r, "PING");
    if (!rep || rep->type == REDIS_REPLY_ERROR) {
        snprintf(why, whylen, "Redis at %s:%d refused us: %s", u->host, u->port,
                 rep                ? rep->str
                     : r->errstr[0] ? r->errstr
                                    : "no reply");
        if (rep) freeReplyObject(rep);
        redisFree(r);
        return NULL;
    }
    freeReplyObject(rep);
    return r;
}

/* "0-N" -> N; 0 when it is not such an id. */
static uint64_t cluster_parse_id(const char *s, size_t n) {
    if (n < 3 || s[0] != '0' || s[1] != '-') return 0;
    uint64_t v = 0;
    for (size_t i = 2; i < n; i++) {
        if (s[i] < '0' || s[i] > '9' || v > (UINT64_MAX - 9) / 10) return 0;
        v = v * 10 + (uint64_t)(s[i] - '0');
    }
    return v;
}

/* The stream's last-generated id's N (0 when the stream does not exist), or -1 with why. */
static int cluster_last_generated(lc_cluster *c, redisContext *r, uint64_t *out, char *why, size_t whylen) {
    redisReply *rep = redisCommand(r, "XINFO STREAM %s", c->cfg.url.key);
    *out = 0;
    if (!rep) {
        snprintf(why, whylen, "Redis: XINFO STREAM: %s", r->errstr);
        return -1;
    }
    int rc = 0;
    if (rep->type == REDIS_REPLY_ERROR) { /* "ERR no such key": a new cluster */
        if (!strstr(rep->str, "no such key")) {
            snprintf(why, whylen, "Redis: XINFO STREAM %s: %s", c->cfg.url.key, rep->str);
            rc = -1;
        }
    } else if (rep->type == REDIS_REPLY_ARRAY) {
        for (size_t i = 0; i + 1 < rep->elements; i += 2) {
            redisReply *k = rep->element[i], *v = rep->element[i + 1];
            if (k->type == REDIS_REPLY_STRING && strcmp(k->str, "last-generated-id") == 0 &&
                v->type == REDIS_REPLY_STRING)
                *out = cluster_parse_id(v->str, v->len);
        }
    }
    freeReplyObject(rep);
    return rc;
}

/* --- reader ------------------------------------------------------------------------------------ */

static void cluster_reader_down(lc_cluster *c, const char *why) {
    pthread_mutex_lock(&c->lock);
    int was = c->reader_up;
    c->reader_up = c->caught_up = 0;
    snprintf(c->reader_why, sizeof c->reader_why, "%s", why);
    pthread_mutex_unlock(&c->lock);
    if (was) lc_warn("cluster", "reader: %s; serving the last state read-only, reconnecting", why);
}

/* The newest snapshot, delivered when newer than the last entry delivered. 0, or -1 with why
 * (connection lost, or a snapshot that is not one). */
static int cluster_load_snapshot(lc_cluster *c, redisContext *r, char *why, size_t whylen) {
    redisReply *rep = redisCommand(r, "HMGET %s:snapshot revision state", c->cfg.url.key);
    if (!rep) {
        snprintf(why, whylen, "Redis: reading the snapshot: %s", r->errstr);
        return -1;
    }
    int rc = 0;
    if (rep->type != REDIS_REPLY_ARRAY || rep->elements != 2) {
        snprintf(why, whylen, "Redis: %s:snapshot is not a lucent snapshot (%s)", c->cfg.url.key,
                 rep->type == REDIS_REPLY_ERROR ? rep->str : "not a hash");
        rc = -2;
    } else if (rep->element[0]->type == REDIS_REPLY_STRING && rep->element[1]->type == REDIS_REPLY_STRING) {
        uint64_t rev = 0;
        const redisReply *rv = rep->element[0], *st = rep->element[1];
        for (size_t i = 0; i < rv->len && rev < UINT64_MAX / 10; i++)
            rev = rv->str[i] >= '0' && rv->str[i] <= '9' ? rev * 10 + (uint64_t)(rv->str[i] - '0') : UINT64_MAX;
        if (rev == 0 || rev >= (1ull << 53) || st->len > CLUSTER_SNAPSHOT_MAX) {
            snprintf(why, whylen, "Redis: %s:snapshot has a bad revision or is over %u MiB", c->cfg.url.key,
                     CLUSTER_SNAPSHOT_MAX >> 20);
            rc = -2;
        } else if (rev > c->from) {
            if (cluster_deliver(c, LC_CLUSTER_SNAPSHOT, rev, st->str, st->len, NULL) == 0) {
                lc_info("cluster", "loaded the snapshot of revision %" PRIu64 " (%zu bytes)", rev, st->len);
                c->from = rev;
                c->from_origin[0] = 0;
                pthread_mutex_lock(&c->lock);
                c->stats.snapshots_loaded++;
                pthread_mutex_unlock(&c->lock);
            } else {
                snprintf(why, whylen, "out of memory loading the snapshot");
                rc = -1;
            }
        }
    }
    freeReplyObject(rep);
    return rc;
}

/* One entry's fields into an ENTRY item. */
static void cluster_entry_fields(const redisReply *f, lc_cluster_item *it, const redisReply **ops) {
    *ops = NULL;
    for (size_t i = 0; f->type == REDIS_REPLY_ARRAY && i + 1 < f->elements; i += 2) {
        const redisReply *k = f->element[i], *v = f->element[i + 1];
        if (k->type != REDIS_REPLY_STRING || v->type != REDIS_REPLY_STRING) continue;
        if (strcmp(k->str, "origin") == 0 && v->len <= LC_CLUSTER_ID_LEN) memcpy(it->origin, v->str, v->len);
        else if (strcmp(k->str, "local") == 0) it->local = strtoull(v->str, NULL, 10);
        else if (strcmp(k->str, "batch") == 0) it->batch = strcmp(v->str, "1") == 0;
        else if (strcmp(k->str, "client") == 0 && v->len < sizeof it->client) memcpy(it->client, v->str, v->len);
        else if (strcmp(k->str, "ops") == 0 && v->len <= CLUSTER_ENTRY_MAX) *ops = v;
    }
}

/* An XREAD reply's entries, delivered in order. 0; 1 when entries before the first are gone
 * (trimmed: load the snapshot); -1 out of memory; -2 not a lucent log (why). */
static int cluster_read_entries(lc_cluster *c, const redisReply *rep, char *why, size_t whylen) {
    if (rep->type != REDIS_REPLY_ARRAY || rep->elements < 1) return 0;
    const redisReply *s = rep->element[0];
    if (s->type != REDIS_REPLY_ARRAY || s->elements != 2 || s->element[1]->type != REDIS_REPLY_ARRAY) return 0;
    const redisReply *entries = s->element[1];
    uint64_t n = 0;
    for (size_t e = 0; e < entries->elements; e++) {
        const redisReply *en = entries->element[e];
        if (en->type != REDIS_REPLY_ARRAY || en->elements != 2 || en->element[0]->type != REDIS_REPLY_STRING) continue;
        uint64_t seq = cluster_parse_id(en->element[0]->str, en->element[0]->len);
        if (!seq) {
            snprintf(why, whylen, "Redis: %s holds the entry %s, which lucent did not write (ids are 0-N)",
                     c->cfg.url.key, en->element[0]->str);
            return -2;
        }
        if (seq <= c->from) continue;
        if (seq > c->from + 1) return 1;
        lc_cluster_item proto;
        memset(&proto, 0, sizeof proto);
        const redisReply *ops;
        cluster_entry_fields(en->element[1], &proto, &ops);
        /* An entry without ops still takes its place in the log: the state skips it. */
        if (cluster_deliver(c, LC_CLUSTER_ENTRY, seq, ops ? ops->str : NULL, ops ? ops->len : 0, &proto) != 0)
            return -1;
        c->from = seq;
        memcpy(c->from_origin, proto.origin, sizeof c->from_origin);
        c->from_local = proto.local;
        n++;
    }
    pthread_mutex_lock(&c->lock);
    c->stats.entries_read += n;
    pthread_mutex_unlock(&c->lock);
    return 0;
}

/* One XREAD from the last entry delivered (block_ms < 0: do not block). 1 when it read
 * entries, 0 none, -1 connection lost, -2 fatal (why). A gap loads the snapshot. */
static int cluster_read_once(lc_cluster *c, redisContext *r, int block_ms, char *why, size_t whylen) {
    char from[32], count[16], block[16];
    snprintf(from, sizeof from, "0-%" PRIu64, c->from);
    snprintf(count, sizeof count, "%d", CLUSTER_READ_COUNT);
    snprintf(block, sizeof block, "%d", block_ms);
    const char *argv[] = {"XREAD", "COUNT", count, "BLOCK", block, "STREAMS", c->cfg.url.key, from};
    const char *argv_nb[] = {"XREAD", "COUNT", count, "STREAMS", c->cfg.url.key, from};
    redisReply *rep = block_ms >= 0 ? redisCommandArgv(r, 8, argv, NULL) : redisCommandArgv(r, 6, argv_nb, NULL);
    if (!rep) {
        snprintf(why, whylen, "Redis: XREAD: %s", r->errstr);
        return -1;
    }
    int rc = 0;
    if (rep->type == REDIS_REPLY_ERROR) {
        snprintf(why, whylen, "Redis: XREAD %s: %s", c->cfg.url.key, rep->str);
        rc = -2;
    } else if (rep->type == REDIS_REPLY_ARRAY) {
        uint64_t before = c->from;
        rc = cluster_read_entries(c, rep, why, whylen);
        if (rc == 1) { /* entries after c->from were trimmed: a snapshot must cover them */
            uint64_t had = c->from;
            rc = cluster_load_snapshot(c, r, why, whylen);
            if (rc == 0 && c->from == had) {
                snprintf(why, whylen,
                         "Redis: the log's entries after revision %" PRIu64 " are gone and no snapshot covers them",
                         had);
                rc = -2;
            }
        } else if (rc == -1) snprintf(why, whylen, "out of memory reading the log");
        if (rc >= 0) rc = c->from != before;
    }
    freeReplyObject(rep);
    return rc;
}

/* KEY:SUFFIX names what every replica of the cluster must share (the first replica sets it):
 * 0 when this replica's `mine` is the same, -2 when not (why names both), -1 connection lost. */
static int cluster_check_same(lc_cluster *c, redisContext *r, const char *suffix, const char *mine, const char *what,
                              const char *needs, char *why, size_t whylen) {
    const char *key = c->cfg.url.key;
    redisReply *rep = redisCommand(r, "SET %s:%s %s NX", key, suffix, mine);
    if (rep) freeReplyObject(rep);
    rep = rep ? redisCommand(r, "GET %s:%s", key, suffix) : NULL;
    if (!rep) {
        snprintf(why, whylen, "Redis: %s", r->errstr);
        return -1;
    }
    int same = rep->type == REDIS_REPLY_STRING && strcmp(rep->str, mine) == 0;
    if (!same)
        snprintf(why, whylen, "the cluster %s serves %s %s and this replica has %s: every replica needs %s", key, what,
                 rep->type == REDIS_REPLY_STRING ? rep->str : "(not a string)", mine, needs);
    freeReplyObject(rep);
    return same ? 0 : -2;
}

/* On reconnect: is the log's entry at `from` still the one this replica applied? Redis that
 * lost entries (started without its AOF) and was refilled by other replicas past `from` holds
 * another history there, and reading on from it would diverge silently. 0 (same, or trimmed
 * behind a snapshot, or nothing to compare), -1 connection lost, -2 diverged (why). */
static int cluster_check_history(lc_cluster *c, redisContext *r, char *why, size_t whylen) {
    if (!c->from || !c->from_origin[0]) return 0;
    char id[32];
    snprintf(id, sizeof id, "0-%" PRIu64, c->from);
    const char *argv[] = {"XRANGE", c->cfg.url.key, id, id};
    redisReply *rep = redisCommandArgv(r, 4, argv, NULL);
    if (!rep) {
        snprintf(why, whylen, "Redis: XRANGE: %s", r->errstr);
        return -1;
    }
    int rc = 0;
    if (rep->type == REDIS_REPLY_ARRAY && rep->elements == 1 && rep->element[0]->type == REDIS_REPLY_ARRAY &&
        rep->element[0]->elements == 2) {
        lc_cluster_item there;
        memset(&there, 0, sizeof there);
        const redisReply *ops;
        cluster_entry_fields(rep->element[0]->element[1], &there, &ops);
        if (strcmp(there.origin, c->from_origin) != 0 || there.local != c->from_local) {
            snprintf(why, whylen,
                     "Redis's log %s holds another entry at revision %" PRIu64 " than the one this replica applied "
                     "(from %s, not %s): Redis lost acknowledged entries and others appended after them; restart "
                     "this replica to load the cluster's state",
                     c->cfg.url.key, c->from, there.origin[0] ? there.origin : "(none)", c->from_origin);
            rc = -2;
        }
    }
    freeReplyObject(rep);
    return rc;
}

/* One connection's life: checks, snapshot, catch-up, then blocking reads. Returns when the
 * connection is lost (-1), on a fatal condition (-2) or when stopping (0). */
static int cluster_reader_session(lc_cluster *c, redisContext *r, char *why, size_t whylen) {
    const char *key = c->cfg.url.key;
    int rc = cluster_check_same(c, r, "bake", c->bake_id, "the bake", "the same bake file", why, whylen);
    if (rc == 0)
        rc = cluster_check_same(c, r, "limits", c->limits, "the state limits",
                                "the same --max-lights and --max-objects (a change that fits one replica's "
                                "limits but not another's would be applied on one and skipped on the other)",
                                why, whylen);
    if (rc != 0) return rc;
    uint64_t last = 0;
    if (cluster_last_generated(c, r, &last, why, whylen) != 0) return -1;
    if (last < c->from) {
        snprintf(why, whylen,
                 "Redis's log %s ends at revision %" PRIu64 " but this replica applied %" PRIu64
                 ": Redis lost acknowledged entries (started without its AOF?); restart the replicas",
                 key, last, c->from);
        return -2;
    }
    if ((rc = cluster_check_history(c, r, why, whylen)) != 0) return rc;
    pthread_mutex_lock(&c->lock);
    snprintf(c->reader_why, sizeof c->reader_why, "catching up with the log from revision %" PRIu64, c->from);
    pthread_mutex_unlock(&c->lock);
    rc = cluster_load_snapshot(c, r, why, whylen);
    while (rc >= 0 && !cluster_stopping(c)) {
        rc = cluster_read_once(c, r, -1, why, whylen);
        if (rc == 0) break;
    }
    if (rc < 0) return rc;
    pthread_mutex_lock(&c->lock);
    c->reader_up = c->caught_up = 1;
    c->reader_why[0] = 0;
    pthread_mutex_unlock(&c->lock);
    if (cluster_deliver(c, LC_CLUSTER_CAUGHT_UP, c->from, NULL, 0, NULL) != 0) {
        snprintf(why, whylen, "out of memory");
        return -1;
    }
    lc_info("cluster", "caught up with %s at revision %" PRIu64, key, c->from);
    while (!cluster_stopping(c))
        if ((rc = cluster_read_once(c, r, CLUSTER_BLOCK_MS, why, whylen)) < 0) return rc;
    return 0;
}

static void *cluster_reader_main(void *arg) {
    lc_cluster *c = arg;
    int backoff = CLUSTER_BACKOFF_MIN_MS;
    char why[512];
    while (!cluster_stopping(c)) {
        redisContext *r = cluster_connect(c, CLUSTER_BLOCK_MS, why, sizeof why);
        int rc = -1;
        if (r) {
            backoff = CLUSTER_BACKOFF_MIN_MS;
            pthread_mutex_lock(&c->lock);
            c->stats.reconnects++;
            c->reader_connects++;
            pthread_mutex_unlock(&c->lock);
            rc = cluster_reader_session(c, r, why, sizeof why);
            redisFree(r);
        }
        if (rc == -2) {
            cluster_fail(c, why);
            break;
        }
        if (rc == 0) break; /* stopping */
        cluster_reader_down(c, why);
        if (cluster_sleep(c, backoff)) break;
        backoff = backoff * 2 < CLUSTER_BACKOFF_MAX_MS ? backoff * 2 : CLUSTER_BACKOFF_MAX_MS;
    }
    return NULL;
}

/* --- writer ------------------------------------------------------------------------------------ */

/* Stores a snapshot only when newer than the cluster's, moves the old one to :previous and
 * trims the stream behind the previous one (its entries are then in both snapshots). */
static const char cluster_snapshot_script[] =
    "local cur = tonumber(redis.call('HGET', KEYS[1], 'revision') or '0')\n"
    "local rev = tonumber(ARGV[1])\n"
    "if rev <= cur then return 0 end\n"
    "if cur > 0 then redis.call('RENAME', KEYS[1], KEYS[2]) end\n"
    "redis.call('HSET', KEYS[1], 'revision', ARGV[1], 'state', ARGV[2])\n"
    "if cur > 0 then redis.call('XTRIM', KEYS[3], 'MINID', '0-' .. string.format('%d', cur + 1)) end\n"
    "return 1\n";

static void cluster_writer_down(lc_cluster *c, const char *why) {
    pthread_mutex_lock(&c->lock);
    int was = c->writer_up;
    c->writer_up = 0;
    snprintf(c->writer_why, sizeof c->writer_why, "%s", why);
    pthread_mutex_unlock(&c->lock);
    if (was) lc_warn("cluster", "writer: %s; changes are refused until it reconnects", why);
}

static void cluster_append_failed(lc_cluster *c, cluster_append *a, const char *why) {
    lc_cluster_item proto;
    memset(&proto, 0, sizeof proto);
    proto.local = a->local;
    if (cluster_deliver(c, LC_CLUSTER_APPEND_FAILED, 0, why, strlen(why), &proto) != 0)
        lc_error("cluster", "out of memory reporting a failed append");
    pthread_mutex_lock(&c->lock);
    c->stats.append_failures++;
    pthread_mutex_unlock(&c->lock);
}

/* XADD of one change. 0; 1 refused by Redis (why); -1 connection lost (why). */
static int cluster_xadd(lc_cluster *c, redisContext *r, const cluster_append *a, char *why, size_t whylen) {
    char local[24];
    snprintf(local, sizeof local, "%" PRIu64, a->local);
    const char *argv[] = {"XADD",  c->cfg.url.key,       "0-*",    "origin",  c->id, "local", local,
                          "batch", a->batch ? "1" : "0", "client", a->client, "ops", a->ops};
    double t0 = lc_clock_ms();
    redisReply *rep = redisCommandArgv(r, 13, argv, NULL);
    if (!rep) {
        snprintf(why, whylen,
                 "Redis went away during the append (%s): the change may or may not be in the log; `changed` "
                 "events will tell",
                 r->errstr);
        return -1;
    }
    int rc = 0;
    if (rep->type == REDIS_REPLY_ERROR) {
        snprintf(why, whylen, "Redis refused the append: %s", rep->str);
        rc = 1;
    }
    freeReplyObject(rep);
    pthread_mutex_lock(&c->lock);
    if (!rc) c->stats.appended++;
    c->stats.last_append_ms = lc_clock_ms() - t0;
    pthread_mutex_unlock(&c->lock);
    return rc;
}

/* 0 written (or older than the cluster's), -1 connection lost. */
static int cluster_write_snapshot(lc_cluster *c, redisContext *r, uint64_t rev, const char *text) {
    char k1[LC_CLUSTER_KEY_MAX + 32], k2[LC_CLUSTER_KEY_MAX + 32], revs[24];
    snprintf(k1, sizeof k1, "%s:snapshot", c->cfg.url.key);
    snprintf(k2, sizeof k2, "%s:snapshot:previous", c->cfg.url.key);
    snprintf(revs, sizeof revs, "%" PRIu64, rev);
    const char *argv[] = {"EVAL", cluster_snapshot_script, "3", k1, k2, c->cfg.url.key, revs, text};
    redisReply *rep = redisCommandArgv(r, 8, argv, NULL);
    if (!rep) return -1;
    if (rep->type == REDIS_REPLY_ERROR) {
        /* e.g. an ACL without EVAL or HSET: the log still works, but it is never trimmed and
         * new replicas replay it from the start (lucent_cluster_snapshot_failures_total). */
        lc_warn("cluster", "snapshot of revision %s not stored: %s", revs, rep->str);
        pthread_mutex_lock(&c->lock);
        c->stats.snapshot_failures++;
        pthread_mutex_unlock(&c->lock);
    } else if (rep->type == REDIS_REPLY_INTEGER && rep->integer == 1) {
        lc_debug("cluster", "stored the snapshot of revision %s", revs);
        pthread_mutex_lock(&c->lock);
        c->stats.snapshots_written++;
        pthread_mutex_unlock(&c->lock);
    }
    freeReplyObject(rep);
    return 0;
}

/* Fails everything queued (Redis is unreachable: nothing was sent). */
static void cluster_fail_queued(lc_cluster *c, const char *why) {
    pthread_mutex_lock(&c->lock);
    cluster_append *a = c->out;
    c->out = c->out_tail = NULL;
    pthread_mutex_unlock(&c->lock);
    char msg[640];
    snprintf(msg, sizeof msg, "not stored: %s", why);
    while (a) {
        cluster_append *next = a->next;
        cluster_append_failed(c, a, msg);
        free(a->ops);
        free(a);
        a = next;
    }
}

/* Waits for work; an idle connection is checked with PING every second, and one made before
 * the reader's latest (re)connection is replaced (Redis restarted: the first append on the
 * stale socket would fail for nothing). Returns 1 when stopping. */
static int cluster_writer_wait(lc_cluster *c, redisContext **r, uint64_t *seen_connects) {
    struct timespec until;
    clock_gettime(CLOCK_REALTIME, &until);
    until.tv_sec += 1;
    pthread_mutex_lock(&c->lock);
    int timed_out = 0;
    while (!c->stop && !c->out && !c->snap && *r && !timed_out && c->reader_connects == *seen_connects)
        timed_out = pthread_cond_timedwait(&c->cond, &c->lock, &until) == ETIMEDOUT;
    int stop = c->stop, stale = c->reader_connects != *seen_connects;
    *seen_connects = c->reader_connects;
    pthread_mutex_unlock(&c->lock);
    if (stop) return 1;
    if (*r && (stale || timed_out)) {
        redisReply *rep = stale ? NULL : redisCommand(*r, "PING");
        if (!rep || rep->type == REDIS_REPLY_ERROR) {
            redisFree(*r);
            *r = NULL;
        }
        if (rep) freeReplyObject(rep);
    }
    return 0;
}

static void *cluster_writer_main(void *arg) {
    lc_cluster *c = arg;
    redisContext *r = NULL;
    int backoff = CLUSTER_BACKOFF_MIN_MS;
    uint64_t seen_connects = 0;
    char why[512];
    while (!cluster_writer_wait(c, &r, &seen_connects)) {
        if (!r) { /* connect at once, and again after losing it: writable needs both threads up */
            if (!(r = cluster_connect(c, 0, why, sizeof why))) {
                cluster_writer_down(c, why);
                cluster_fail_queued(c, why);
                if (cluster_sleep(c, backoff)) break;
                backoff = backoff * 2 < CLUSTER_BACKOFF_MAX_MS ? backoff * 2 : CLUSTER_BACKOFF_MAX_MS;
                continue;
            }
            backoff = CLUSTER_BACKOFF_MIN_MS;
            pthread_mutex_lock(&c->lock);
            c->writer_up = 1;
            c->writer_why[0] = 0;
            pthread_mutex_unlock(&c->lock);
            c->wake(c->wake_arg); /* writable may have changed */
        }
        pthread_mutex_lock(&c->lock);
        cluster_append *a = c->out;
        if (a && !(c->out = a->next)) c->out_tail = NULL;
        char *snap = a ? NULL : c->snap;
        uint64_t snap_rev = c->snap_rev;
        if (snap) c->snap = NULL;
        pthread_mutex_unlock(&c->lock);
        int lost = 0;
        if (a) {
            int rc = cluster_xadd(c, r, a, why, sizeof why);
            if (rc != 0) cluster_append_failed(c, a, why);
            lost = rc < 0;
            free(a->ops);
            free(a);
        } else if (snap) {
            lost = cluster_write_snapshot(c, r, snap_rev, snap) != 0;
            if (lost) snprintf(why, sizeof why, "Redis: writing a snapshot: %s", r->errstr);
            free(snap);
        }
        if (lost) {
            redisFree(r);
            r = NULL;
            cluster_writer_down(c, why);
        }
    }
    if (r) redisFree(r);
    return NULL;
}

/* --- API ---------------------------------------------------------------------------------------- */

lc_cluster *lc_cluster_start(const lc_cluster_config *cfg, uint64_t from_revision, lc_cluster_wake_fn wake,
                             void *wake_arg, char *err, size_t errlen) {
    lc_cluster *c = calloc(1, sizeof *c);
    if (!c) {
        lc_set_err(err, errlen, "cluster: out of memory");
        return NULL;
    }
    c->cfg = *cfg;
    snprintf(c->bake_id, sizeof c->bake_id, "%s", cfg->bake_id ? cfg->bake_id : "");
    c->cfg.bake_id = c->bake_id;
    snprintf(c->limits, sizeof c->limits, "lights=%u,objects=%u", cfg->max_lights, cfg->max_objects);
    c->from = from_revision;
    c->wake = wake;
    c->wake_arg = wake_arg;
    /* A new id at every start: entries of an earlier life are never taken for this one's. */
    uint64_t rnd = 0;
    int fd = open("/dev/urandom", O_RDONLY | O_CLOEXEC);
    if (fd < 0 || read(fd, &rnd, sizeof rnd) != (ssize_t)sizeof rnd)
        rnd = (uint64_t)lc_clock_ms() * 1000003u ^ (uint64_t)getpid() << 32;
    if (fd >= 0) close(fd);
    snprintf(c->id, sizeof c->id, "%016" PRIx64, rnd);
    snprintf(c->reader_why, sizeof c->reader_why, "connecting to Redis at %s:%d", cfg->url.host, cfg->url.port);
    snprintf(c->writer_why, sizeof c->writer_why, "%s", c->reader_why);
    pthread_mutex_init(&c->lock, NULL);
    pthread_cond_init(&c->cond, NULL);
    c->reader_started = pthread_create(&c->reader, NULL, cluster_reader_main, c) == 0;
    c->writer_started = c->reader_started && pthread_create(&c->writer, NULL, cluster_writer_main, c) == 0;
    if (!c->writer_started) {
        lc_set_err(err, errlen, "cluster: cannot start its threads");
        lc_cluster_stop(c);
        return NULL;
    }
    return c;
}

void lc_cluster_stop(lc_cluster *c) {
    if (!c) return;
    pthread_mutex_lock(&c->lock);
    c->stop = 1;
    pthread_cond_broadcast(&c->cond);
    pthread_mutex_unlock(&c->lock);
    if (c->reader_started) pthread_join(c->reader, NULL);
    if (c->writer_started) pthread_join(c->writer, NULL);
    lc_cluster_item_free(c->items);
    for (cluster_append *a = c->out, *next; a; a = next) {
        next = a->next;
        free(a->ops);
        free(a);
    }
    free(c->snap);
    pthread_cond_destroy(&c->cond);
    pthread_mutex_destroy(&c->lock);
    free(c);
}

int lc_cluster_append(lc_cluster *c, uint64_t local, int batch, const char *client, const char *ops_json) {
    cluster_append *a = calloc(1, sizeof *a);
    if (!a || !(a->ops = strdup(ops_json))) {
        free(a);
        return -1;
    }
    a->local = local;
    a->batch = batch;
    snprintf(a->client, sizeof a->client, "%s", client);
    pthread_mutex_lock(&c->lock);
    if (c->out_tail) c->out_tail->next = a;
    else c->out = a;
    c->out_tail = a;
    pthread_cond_broadcast(&c->cond);
    pthread_mutex_unlock(&c->lock);
    return 0;
}

void lc_cluster_snapshot(lc_cluster *c, uint64_t revision, const char *state_json) {
    char *copy = strdup(state_json);
    if (!copy) {
        lc_warn("cluster", "out of memory: snapshot of revision %" PRIu64 " skipped", revision);
        return;
    }
    pthread_mutex_lock(&c->lock);
    free(c->snap);
    c->snap = copy;
    c->snap_rev = revision;
    pthread_cond_broadcast(&c->cond);
    pthread_mutex_unlock(&c->lock);
}

lc_cluster_item *lc_cluster_take(lc_cluster *c) {
    pthread_mutex_lock(&c->lock);
    lc_cluster_item *it = c->items;
    c->items = c->items_tail = NULL;
    pthread_mutex_unlock(&c->lock);
    return it;
}

void lc_cluster_item_free(lc_cluster_item *it) {
    while (it) {
        lc_cluster_item *next = it->next;
        free(it->text);
        free(it);
        it = next;
    }
}

int lc_cluster_writable(lc_cluster *c) {
    pthread_mutex_lock(&c->lock);
    int w = c->reader_up && c->caught_up && c->writer_up && !c->fatal;
    pthread_mutex_unlock(&c->lock);
    return w;
}

void lc_cluster_status(lc_cluster *c, char *why, size_t len) {
    pthread_mutex_lock(&c->lock);
    if (c->fatal || !c->reader_up || !c->caught_up)
        snprintf(why, len, "%s", c->reader_why[0] ? c->reader_why : "catching up with the log");
    else if (!c->writer_up) snprintf(why, len, "%s", c->writer_why);
    else if (len) why[0] = 0;
    pthread_mutex_unlock(&c->lock);
}

const char *lc_cluster_replica_id(const lc_cluster *c) { return c->id; }

void lc_cluster_get_stats(lc_cluster *c, lc_cluster_stats *out) {
    pthread_mutex_lock(&c->lock);
    *out = c->stats;
    pthread_mutex_unlock(&c->lock);
}
