/* server_cluster: lucentd as one replica of a cluster (--cluster, PROTOCOL.md §9; the Redis
 * side is cluster.c). A change a client sends is validated against the state as this replica
 * has it, then appended to the log; it is applied, and `ok` sent, only when the replica reads
 * its own entry back in log order, exactly as every other replica applies it. An entry that
 * no longer applies (two replicas raced on the same light) is skipped everywhere alike and its
 * submitter gets the error. The revision is the entry's position in the log, skipped ones
 * included. All functions run on the service thread. */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "cluster.h"
#include "server_internal.h"
#include "util/clock.h"
#include "util/log.h"

#define CLUSTER_ACK_TIMEOUT_MS 10000.0 /* an append not read back by then is reported unknown */

struct server_cluster_pending {
    uint64_t local;
    lc_session *ss; /* NULL once the session closed */
    lc_proto_id id;
    double since_ms;
};

/* A cluster thread: the service thread collects what it delivered (LWS_CALLBACK_EVENT_WAIT_CANCELLED). */
static void server_cluster_wake(void *ctx) { lws_cancel_service(ctx); }

int server_cluster_start(lc_server *s, char *err, size_t errlen) {
    const lc_config *cfg = s->cfg;
    if (!cfg->cluster[0]) return 0;
    lc_cluster_config cc;
    memset(&cc, 0, sizeof cc);
    if (lc_cluster_parse_url(cfg->cluster, strlen(cfg->cluster), &cc.url, err, errlen) != 0) return -1;
    cc.timeout_ms = cfg->cluster_timeout;
    cc.bake_id = s->bake_id;
    cc.max_lights = (uint32_t)cfg->max_lights;
    cc.max_objects = (uint32_t)cfg->max_objects;
    s->cluster = lc_cluster_start(&cc, s->state.revision, server_cluster_wake, s->ctx, err, errlen);
    if (!s->cluster) return -1;
    lc_info("cluster", "replica %s of redis://%s:%d/%s (the state comes from the log; --state-dir is not used)",
            lc_cluster_replica_id(s->cluster), cc.url.host, cc.url.port, cc.url.key);
    /* The journal's options mean nothing here: say so rather than ignore them silently (the
     * container images always pass --state-dir, so that one is only in the line above). */
    if (cfg->fsync_mode != 0)
        lc_warn("cluster",
                "--fsync is ignored with --cluster: a change is durable when Redis has it (its "
                "appendfsync, deploy/redis-lucent.conf)");
    if (cfg->recover)
        lc_warn("cluster", "--recover is ignored with --cluster: there is no local journal to recover from");
    return 0;
}

void server_cluster_stop(lc_server *s) {
    lc_cluster_stop(s->cluster);
    s->cluster = NULL;
    free(s->cluster_pending);
    s->cluster_pending = NULL;
    s->n_cluster_pending = 0;
}

static void server_cluster_refuse(lc_server *s, lc_session *ss, const lc_proto_id *id, const char *why) {
    char msg[640];
    snprintf(msg, sizeof msg,
             "this replica cannot take changes now (%s); reads and frames keep working: retry later or on another "
             "replica",
             why);
    session_error(s, ss, id, LC_ERR_READ_ONLY, "", msg);
}

void server_cluster_change(lc_server *s, lc_session *ss, const lc_proto_request *req) {
    char why[512];
    if (!lc_cluster_writable(s->cluster)) {
        lc_cluster_status(s->cluster, why, sizeof why);
        server_cluster_refuse(s, ss, &req->id, why[0] ? why : "not connected");
        return;
    }
    /* Validated here, so a bad change is refused at once with the usual error; it can still
     * fail when applied, if another replica's entry came first. */
    lc_state trial;
    lc_proto_error e;
    if (lc_state_clone(&trial, &s->state) != 0) {
        session_error(s, ss, &req->id, LC_ERR_INTERNAL, "", "out of memory");
        return;
    }
    int bad = lc_state_apply(&trial, req->ops, req->n_ops, req->type == LC_REQ_BATCH, &e);
    lc_state_release(&trial);
    if (bad) {
        server_count_error(s, e.code);
        session_send(ss, lc_proto_build_error(&req->id, &e));
        return;
    }
    size_t len;
    char *ops = lc_journal_record(req->ops, req->n_ops, 0, &len);
    if (s->n_cluster_pending == s->cap_cluster_pending) {
        uint32_t cap = s->cap_cluster_pending ? 2 * s->cap_cluster_pending : 64;
        struct server_cluster_pending *grown = realloc(s->cluster_pending, cap * sizeof *grown);
        if (grown) {
            s->cluster_pending = grown;
            s->cap_cluster_pending = cap;
        }
    }
    uint64_t local = ++s->cluster_local;
    if (!ops || s->n_cluster_pending == s->cap_cluster_pending ||
        lc_cluster_append(s->cluster, local, req->type == LC_REQ_BATCH, ss->client, ops) != 0) {
        free(ops);
        session_error(s, ss, &req->id, LC_ERR_INTERNAL, "", "out of memory");
        return;
    }
    free(ops);
    s->cluster_pending[s->n_cluster_pending++] = (struct server_cluster_pending){local, ss, req->id, lc_clock_ms()};
}

/* The pending append `local` (removed from the table into *out), or 0. */
static int server_cluster_take_pending(lc_server *s, uint64_t local, struct server_cluster_pending *out) {
    for (uint32_t i = 0; i < s->n_cluster_pending; i++)
        if (s->cluster_pending[i].local == local) {
            *out = s->cluster_pending[i];
            memmove(s->cluster_pending + i, s->cluster_pending + i + 1,
                    (s->n_cluster_pending - i - 1) * sizeof *s->cluster_pending);
            s->n_cluster_pending--;
            return 1;
        }
    return 0;
}

void server_cluster_session_gone(lc_server *s, lc_session *ss) {
    for (uint32_t i = 0; i < s->n_cluster_pending; i++)
        if (s->cluster_pending[i].ss == ss) s->cluster_pending[i].ss = NULL;
}

/* One log entry, in order: applied, or skipped when it no longer applies. Returns 1 when the
 * state changed. */
static int server_cluster_apply(lc_server *s, const lc_cluster_item *it) {
    struct server_cluster_pending mine = {0};
    int have =
        strcmp(it->origin, lc_cluster_replica_id(s->cluster)) == 0 && server_cluster_take_pending(s, it->local, &mine);
    lc_proto_request req;
    lc_proto_error e = {0};
    int parsed = 0, ok = 0;
    if (it->seq != s->state.revision + 1)
        lc_warn("cluster", "entry %" PRIu64 " after revision %" PRIu64 " (expected the next)", it->seq,
                s->state.revision);
    if (it->text) {
        lc_proto_limits lim;
        lc_proto_default_limits(&lim);
        lim.max_message = 4u << 20;
        lim.max_batch = 1u << 20;
        parsed = lc_proto_parse_request(it->text, it->len, &lim, &req, &e) == 0;
        if (parsed && req.type != LC_REQ_BATCH) {
            lc_proto_error_set_code(&e, LC_ERR_INVALID);
            snprintf(e.message, sizeof e.message, "the log entry is not a batch");
        } else if (parsed) {
            s->state.revision = it->seq - 1;
            ok = lc_state_apply(&s->state, req.ops, req.n_ops, it->batch, &e) == 0;
        }
    } else {
        lc_proto_error_set_code(&e, LC_ERR_INVALID);
        snprintf(e.message, sizeof e.message, "the log entry holds no change");
    }
    s->state.revision = it->seq; /* applied or skipped, the entry takes its place */
    if (ok) {
        s->cluster_applied++;
        for (lc_session *o = s->sessions; o; o = o->next)
            if (o->authed && (!have || o != mine.ss))
                session_send(o, lc_proto_build_changed(it->seq, it->client, req.ops, req.n_ops));
        if (have && mine.ss) session_send(mine.ss, lc_proto_build_ok(&mine.id, it->seq));
    } else {
        s->cluster_skipped++;
        lc_info("cluster", "entry %" PRIu64 " from %s skipped: %s at %s: %s", it->seq, it->client, e.code, e.pointer,
                e.message);
        if (have && mine.ss) {
            server_count_error(s, e.code);
            session_send(mine.ss, lc_proto_build_error(&mine.id, &e));
        }
    }
    if (parsed) lc_proto_request_release(&req);
    /* Every replica offers the same snapshots; the first one stored wins (cluster.c). */
    if (s->cfg->cluster_snapshot_every && it->seq % (uint64_t)s->cfg->cluster_snapshot_every == 0) {
        char *text = lc_journal_state_text(&s->state);
        if (text) lc_cluster_snapshot(s->cluster, it->seq, text);
        free(text);
    }
    return ok;
}

/* A snapshot replaces the state (a new replica, or one that fell behind the trimmed log). */
static int server_cluster_restore(lc_server *s, const lc_cluster_item *it) {
    lc_proto_parsed_state ps;
    lc_proto_error e;
    if (lc_proto_parse_state(it->text, it->len, &ps, &e) != 0) {
        lc_error("cluster", "the snapshot of revision %" PRIu64 " is unreadable: %s at %s: %s", it->seq, e.code,
                 e.pointer, e.message);
        return 0;
    }
    int rc = lc_state_restore(&s->state, &ps, &e);
    lc_proto_parsed_state_free(&ps);
    if (rc != 0) {
        lc_error("cluster", "the snapshot of revision %" PRIu64 " does not fit this bake: %s", it->seq, e.message);
        return 0;
    }
    s->state.revision = it->seq;
    for (lc_session *o = s->sessions; o; o = o->next) /* a jump: clients fetch the state again */
        if (o->authed) session_send(o, lc_proto_build_changed(it->seq, "cluster", NULL, 0));
    return 1;
}

void server_cluster_collect(lc_server *s) {
    if (!s->cluster) return;
    lc_cluster_item *items = lc_cluster_take(s->cluster);
    const uint64_t before = s->state.revision;
    int changed = 0;
    for (lc_cluster_item *it = items; it; it = it->next) {
        struct server_cluster_pending p;
        switch (it->kind) {
        case LC_CLUSTER_ENTRY: changed |= server_cluster_apply(s, it); break;
        case LC_CLUSTER_SNAPSHOT: changed |= server_cluster_restore(s, it); break;
        case LC_CLUSTER_CAUGHT_UP:
            if (!s->cluster_ready)
                lc_info("cluster", "ready: caught up with the log at revision %" PRIu64, s->state.revision);
            s->cluster_ready = 1;
            break;
        case LC_CLUSTER_APPEND_FAILED:
            if (server_cluster_take_pending(s, it->local, &p) && p.ss) server_cluster_refuse(s, p.ss, &p.id, it->text);
            break;
        case LC_CLUSTER_FATAL:
            snprintf(s->cluster_fatal, sizeof s->cluster_fatal, "%s", it->text ? it->text : "?");
            break;
        }
    }
    lc_cluster_item_free(items);
    /* Skipped entries move the revision too: frames of it follow (the light is unchanged, but
     * a client waiting for the revision it saw in `changed` or `ok` must get one). */
    if (changed || s->state.revision != before) lc_compute_submit(s->compute, &s->state, NULL);
    if (changed) server_clutter_sync(s);
}

void server_cluster_tick(lc_server *s) {
    if (!s->cluster) return;
    double now = lc_clock_ms();
    for (uint32_t i = 0; i < s->n_cluster_pending;) {
        struct server_cluster_pending *p = &s->cluster_pending[i];
        if (now - p->since_ms < CLUSTER_ACK_TIMEOUT_MS) {
            i++;
            continue;
        }
        if (p->ss)
            server_cluster_refuse(s, p->ss, &p->id,
                                  "the append was not read back within 10 s: it may or may not be in the log; "
                                  "`changed` events will tell");
        *p = s->cluster_pending[--s->n_cluster_pending];
    }
}

int server_cluster_health(lc_server *s, char *body, size_t cap, unsigned *status) {
    char why[512];
    if (s->cluster_fatal[0]) {
        *status = HTTP_STATUS_SERVICE_UNAVAILABLE;
        return snprintf(body, cap, "unavailable revision %" PRIu64 ": %s\n", s->state.revision, s->cluster_fatal);
    }
    if (!s->cluster_ready) {
        lc_cluster_status(s->cluster, why, sizeof why);
        *status = HTTP_STATUS_SERVICE_UNAVAILABLE;
        return snprintf(body, cap, "starting revision %" PRIu64 ": not caught up with the log yet (%s)\n",
                        s->state.revision, why);
    }
    if (!lc_cluster_writable(s->cluster)) {
        lc_cluster_status(s->cluster, why, sizeof why);
        *status = HTTP_STATUS_OK; /* reads and frames still work */
        return snprintf(body, cap, "ok revision %" PRIu64 " read-only: %s\n", s->state.revision, why);
    }
    return 0;
}
