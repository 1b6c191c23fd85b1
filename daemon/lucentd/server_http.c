/* server_http: plain HTTP on lucentd's port — /healthz, /metrics (Prometheus text), the
 * --www mount's symlink check — and who may open a WebSocket (Origin policy, HTTP refusals).
 * Service thread. */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include "server_internal.h"
#include "util/clock.h"
#include "util/log.h"

/* Answers a WebSocket handshake with an HTTP error instead of a silent close, so a browser
 * or a script sees why (403 for a refused Origin). Returns 1: lws then drops the connection. */
int server_refuse_http(struct lws *wsi, unsigned status, const char *body) {
    unsigned char buf[LWS_PRE + 512], *start = buf + LWS_PRE, *p = start, *end = buf + sizeof buf;
    size_t n = strlen(body);
    if (lws_add_http_common_headers(wsi, status, "text/plain", (lws_filepos_t)n, &p, end) == 0 &&
        lws_finalize_write_http_header(wsi, start, &p, end) == 0 && (size_t)(end - p) >= n) {
        memcpy(p, body, n);
        lws_write(wsi, p, n, LWS_WRITE_HTTP_FINAL);
    }
    return 1;
}

/* The host[:port] part of an Origin ("https://h:1" -> "h:1"); NULL when it has no scheme. */
static const char *origin_authority(const char *origin, int *https) {
    if (!strncmp(origin, "http://", 7)) {
        *https = 0;
        return origin + 7;
    }
    if (!strncmp(origin, "https://", 8)) {
        *https = 1;
        return origin + 8;
    }
    return NULL;
}

/* 1 when authority (host[:port]) names this machine's loopback: localhost, 127.x, [::1]. */
static int authority_is_loopback(const char *a) {
    size_t host_len = strlen(a);
    if (a[0] == '[') {
        const char *rb = strchr(a, ']');
        if (!rb) return 0;
        return (size_t)(rb - a) == 4 && !strncmp(a, "[::1]", 5) && (rb[1] == 0 || rb[1] == ':');
    }
    const char *colon = strchr(a, ':');
    if (colon) host_len = (size_t)(colon - a);
    if (host_len == 9 && !strncmp(a, "localhost", 9)) return 1;
    if (host_len >= 4 && !strncmp(a, "127.", 4)) {
        for (size_t i = 4; i < host_len; i++)
            if (!(a[i] == '.' || (a[i] >= '0' && a[i] <= '9'))) return 0;
        return 1;
    }
    return 0;
}

/* Which browser pages may open a session (PROTOCOL.md §1.1). Clients without an Origin
 * header (native clients, lucentctl) always pass; tokens are their gate. A page passes when
 * it is lucentd's own (its origin is the Host it connected to: the --www pages), when it is
 * in --origins, or — with no --origins — when it is served from this machine's loopback.
 * Anything else (a site the local user happens to open) is refused with 403. */
int server_origin_allowed(const lc_server *s, struct lws *wsi, char *why, size_t whylen) {
    char origin[256], host[256];
    int olen = lws_hdr_copy(wsi, origin, sizeof origin, WSI_TOKEN_ORIGIN);
    if (olen <= 0) {
        if (lws_hdr_total_length(wsi, WSI_TOKEN_ORIGIN) > 0) {
            snprintf(why, whylen, "Origin header too long");
            return 0;
        }
        return 1;
    }
    if (s->cfg->origins[0] && lc_config_has_token(s->cfg->origins, origin)) return 1;
    int https = 0;
    const char *auth = origin_authority(origin, &https);
    if (auth && lws_hdr_copy(wsi, host, sizeof host, WSI_TOKEN_HOST) > 0 && https == (s->cfg->tls_cert[0] != 0) &&
        !strcasecmp(auth, host))
        return 1; /* same origin: a page lucentd served itself */
    if (!s->cfg->origins[0] && auth && authority_is_loopback(auth)) return 1;
    snprintf(why, whylen, "Origin '%.160s' is %s", origin,
             s->cfg->origins[0] ? "not in --origins" : "not this server's nor a localhost page (see --origins)");
    return 0;
}

/* Appends to a fixed buffer, never past its end (output is cut instead). */
static void http_append(char *buf, size_t cap, int *n, const char *fmt, ...) __attribute__((format(printf, 4, 5)));
static void http_append(char *buf, size_t cap, int *n, const char *fmt, ...) {
    if (*n < 0 || (size_t)*n >= cap - 1) return;
    va_list ap;
    va_start(ap, fmt);
    int w = vsnprintf(buf + *n, cap - (size_t)*n, fmt, ap);
    va_end(ap);
    if (w > 0) *n = (size_t)(*n + w) >= cap ? (int)cap - 1 : *n + w;
}

/* One metric's HELP and TYPE lines (Prometheus text format 0.0.4). */
static void metric_head(char *buf, size_t cap, int *n, const char *name, const char *type, const char *help) {
    http_append(buf, cap, n, "# HELP %s %s\n# TYPE %s %s\n", name, help, name, type);
}

static void metric_u64(char *buf, size_t cap, int *n, const char *name, const char *type, const char *help,
                       uint64_t v) {
    metric_head(buf, cap, n, name, type, help);
    http_append(buf, cap, n, "%s %llu\n", name, (unsigned long long)v);
}

/* Cluster mode's part of /metrics (PROTOCOL.md §9). Returns the new length. */
static int server_cluster_metrics(lc_server *s, char *body, size_t cap, int n) {
    lc_cluster_stats cs;
    lc_cluster_get_stats(s->cluster, &cs);
    metric_u64(body, cap, &n, "lucent_cluster_writable", "gauge",
               "1 while this replica can append changes to its log (connected and caught up).",
               (uint64_t)lc_cluster_writable(s->cluster));
    metric_u64(body, cap, &n, "lucent_cluster_entries_applied_total", "counter", "Log entries applied to the state.",
               s->cluster_applied);
    metric_u64(body, cap, &n, "lucent_cluster_entries_skipped_total", "counter",
               "Log entries that no longer applied when their turn came (skipped on every replica).",
               s->cluster_skipped);
    metric_u64(body, cap, &n, "lucent_cluster_appends_total", "counter", "Changes this replica appended to the log.",
               cs.appended);
    metric_u64(body, cap, &n, "lucent_cluster_append_failures_total", "counter",
               "Appends that Redis did not confirm (refused to the client as read_only).", cs.append_failures);
    metric_u64(body, cap, &n, "lucent_cluster_pending", "gauge", "Appends waiting to be read back from the log.",
               s->n_cluster_pending);
    metric_u64(body, cap, &n, "lucent_cluster_connects_total", "counter", "Connections the log reader made to Redis.",
               cs.reconnects);
    metric_u64(body, cap, &n, "lucent_cluster_snapshots_loaded_total", "counter",
               "Snapshots of the state loaded from Redis.", cs.snapshots_loaded);
    metric_u64(body, cap, &n, "lucent_cluster_snapshots_written_total", "counter",
               "Snapshots of the state this replica stored in Redis.", cs.snapshots_written);
    metric_u64(body, cap, &n, "lucent_cluster_snapshot_failures_total", "counter",
               "Snapshots Redis refused to store (the log is then not trimmed; see the log line).",
               cs.snapshot_failures);
    metric_head(body, cap, &n, "lucent_cluster_append_seconds", "gauge", "Redis round trip of the last append.");
    http_append(body, cap, &n, "lucent_cluster_append_seconds %.6f\n", cs.last_append_ms * 1e-3);
    return n;
}

/* /metrics: Prometheus text, base units (seconds, bytes), every metric with HELP. */
static int server_metrics(lc_server *s, char *body, size_t cap) {
    int n = 0;
    metric_u64(body, cap, &n, "lucent_clients", "gauge", "Connected WebSocket sessions.", s->n_sessions);
    metric_u64(body, cap, &n, "lucent_revision", "gauge", "Revision of the scene state.", s->state.revision);
    metric_u64(body, cap, &n, "lucent_frames_sent_total", "counter", "Binary frames sent to clients.", s->frames_sent);
    metric_u64(body, cap, &n, "lucent_sent_bytes_total", "counter", "Bytes of WebSocket payload sent to clients.",
               s->bytes_sent);
    metric_u64(body, cap, &n, "lucent_messages_received_total", "counter", "Text messages received from clients.",
               s->messages_in);
    metric_u64(body, cap, &n, "lucent_relights_total", "counter", "Relights published by the compute thread.",
               lc_compute_count(s->compute));
    uint64_t failures = 0;
    lc_compute_failure(s->compute, &failures, NULL, 0);
    metric_u64(body, cap, &n, "lucent_relight_failures_total", "counter",
               "Relights that failed (reported to clients as error events).", failures);
    uint64_t hist[LC_COMPUTE_BUCKETS];
    double sum_ms;
    lc_compute_histogram(s->compute, hist, &sum_ms);
    metric_head(body, cap, &n, "lucent_relight_seconds", "histogram", "Time of one relight.");
    for (int b = 0; b < LC_COMPUTE_BUCKETS - 1; b++)
        http_append(body, cap, &n, "lucent_relight_seconds_bucket{le=\"%g\"} %llu\n", lc_compute_bucket_ms[b] * 1e-3,
                    (unsigned long long)hist[b]);
    http_append(body, cap, &n,
                "lucent_relight_seconds_bucket{le=\"+Inf\"} %llu\nlucent_relight_seconds_sum %.6f\n"
                "lucent_relight_seconds_count %llu\n",
                (unsigned long long)hist[LC_COMPUTE_BUCKETS - 1], sum_ms * 1e-3,
                (unsigned long long)hist[LC_COMPUTE_BUCKETS - 1]);
    metric_u64(body, cap, &n, "lucent_journal_failures_total", "counter",
               "Journal writes or fsyncs that failed (appends refused, or an everysec fsync).",
               lc_journal_failures(s->journal));
    metric_u64(body, cap, &n, "lucent_journal_broken", "gauge",
               "1 while changes are refused after a failed journal fsync (until a snapshot succeeds).",
               (uint64_t)lc_journal_broken(s->journal));
    metric_u64(body, cap, &n, "lucent_clients_dropped_total", "counter",
               "Clients dropped for not taking their output (slow or not reading).", s->dropped_slow);
    metric_u64(body, cap, &n, "lucent_origins_refused_total", "counter",
               "WebSocket handshakes refused with 403 for their Origin.", s->origins_refused);
    metric_u64(body, cap, &n, "lucent_auth_failures_total", "counter", "Hellos refused for an unknown token.",
               s->auth_failures);
    metric_u64(body, cap, &n, "lucent_config_reloads_total", "counter",
               "SIGHUP reloads whose configuration was applied (tests wait on it).", s->reloads);
    metric_u64(body, cap, &n, "lucent_accept_errors_total", "counter",
               "Failed accept() calls (e.g. out of file descriptors).", server_accept_errors_total());
    metric_u64(body, cap, &n, "lucent_reserve_closed_total", "counter",
               "Connections closed at accept: their descriptor was in lucentd's own reserve.", s->fd_ceiling_refused);
    uint64_t mr_processed = 0, mr_replaced = 0;
    if (s->mrw) lc_mrw_counts(s->mrw, &mr_processed, &mr_replaced);
    uint32_t mr_sessions = 0;
    for (uint32_t k = 0; k < LC_MRW_SLOTS; k++) mr_sessions += s->mr_slots[k] != NULL;
    metric_u64(body, cap, &n, "lucent_mr_sessions", "gauge", "Open MR sessions (PROTOCOL.md §8).", mr_sessions);
    metric_u64(body, cap, &n, "lucent_mr_frames_received_total", "counter", "MR upload frames accepted.",
               s->mr_frames_in);
    metric_u64(body, cap, &n, "lucent_mr_received_bytes_total", "counter", "Bytes of accepted MR upload frames.",
               s->mr_bytes_in);
    metric_u64(body, cap, &n, "lucent_mr_frames_processed_total", "counter", "MR frames the worker processed.",
               mr_processed);
    metric_u64(body, cap, &n, "lucent_mr_frames_replaced_total", "counter",
               "MR frames dropped unprocessed because a newer one arrived (latest wins).", mr_replaced);
    lc_clw_counts cc = lc_clw_counts_get(s->clw);
    metric_u64(body, cap, &n, "lucent_clutter_objects", "gauge",
               "Objects whose clutter operators apply (PROTOCOL.md §5.5).", s->n_announced);
    metric_u64(body, cap, &n, "lucent_clutter_builds_total", "counter", "Clutter operator builds finished.", cc.built);
    metric_u64(body, cap, &n, "lucent_clutter_builds_cancelled_total", "counter",
               "Clutter operator builds abandoned because the object moved, left or changed mode.", cc.cancelled);
    metric_u64(body, cap, &n, "lucent_clutter_builds_failed_total", "counter", "Clutter operator builds that failed.",
               cc.failed);
    metric_u64(body, cap, &n, "lucent_clutter_builds_queued", "gauge", "Clutter operator builds waiting or running.",
               (uint64_t)cc.queued + (uint64_t)cc.building);
    if (s->cluster) n = server_cluster_metrics(s, body, cap, n);
    metric_head(body, cap, &n, "lucent_errors_total", "counter", "Error replies sent, by code.");
    for (int i = 0; i < LC_ERR_COUNT; i++)
        http_append(body, cap, &n, "lucent_errors_total{code=\"%s\"} %llu\n",
                    lc_proto_errcode_name((lc_proto_errcode)i), (unsigned long long)s->errors[i]);
    return n;
}

/* /healthz: 200 "ok" while the service can take changes and relight them; 503 with the cause
 * when the journal refuses changes or the newest relight failed. */
static int server_health(lc_server *s, char *body, size_t cap, unsigned *status) {
    char why[256];
    uint64_t failed = lc_compute_failure(s->compute, NULL, why, sizeof why);
    int n = s->cluster ? server_cluster_health(s, body, cap, status) : 0;
    if (n) return n;
    *status = HTTP_STATUS_SERVICE_UNAVAILABLE;
    if (lc_journal_broken(s->journal))
        return snprintf(body, cap, "unavailable revision %llu: the journal refuses changes after a failed fsync\n",
                        (unsigned long long)s->state.revision);
    if (failed)
        return snprintf(body, cap, "degraded revision %llu: relight of revision %llu failed: %.200s\n",
                        (unsigned long long)s->state.revision, (unsigned long long)failed, why);
    *status = HTTP_STATUS_OK;
    return snprintf(body, cap, "ok revision %llu\n", (unsigned long long)s->state.revision);
}

/* --www: 1 when the file a request maps to lies inside the root once symlinks are resolved
 * (a link under the root must not publish /etc). Missing files pass: lws answers 404. */
static int server_www_path_allowed(const lc_server *s, const char *uri) {
    char root[PATH_MAX], path[PATH_MAX * 2], real[PATH_MAX];
    if (!realpath(s->cfg->www, root)) return 0;
    snprintf(path, sizeof path, "%s/%s", s->cfg->www, uri[0] == '/' ? uri + 1 : uri);
    if (!realpath(path, real)) return errno == ENOENT || errno == ENOTDIR;
    size_t rl = strlen(root);
    return !strcmp(real, root) || (!strncmp(real, root, rl) && real[rl] == '/');
}

/* The bake's geometry (the /scene.glb and /assets mounts hand their requests here). The
 * whole path comes from the request line: lws passes callback mounts only what follows the
 * mount point. Returns the callback's result, or 2 when the path is not a geometry mount's. */
static int server_http_geometry(lc_server *s, struct lws *wsi, server_http_tx *tx) {
    char uri[512];
    if (lws_hdr_copy(wsi, uri, sizeof uri, WSI_TOKEN_GET_URI) <= 0) return 2;
    if (strcmp(uri, "/scene.glb") && strncmp(uri, "/assets/", 8) && strcmp(uri, "/assets")) return 2;
    const server_glb *g = server_geometry_find(s, uri);
    if (!g) {
        lws_return_http_status(wsi, HTTP_STATUS_NOT_FOUND,
                               "no such asset in the bake (see welcome.scene.asset_geometry)");
        return lws_http_transaction_completed(wsi) ? -1 : 0;
    }
    return server_geometry_start(s, wsi, tx, g) ? -1 : 0;
}

/* HTTP on the same port: /healthz, /metrics, the bake's geometry; everything else goes to
 * the static mount. */
int server_http_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_vhost *vh = lws_get_vhost(wsi);
    lc_server *s = vh ? lws_get_vhost_user(vh) : NULL;
    if (reason == LWS_CALLBACK_FILTER_NETWORK_CONNECTION && s && s->fd_ceiling) {
        /* The descriptors above the ceiling are lucentd's own reserve (journal, snapshots,
         * the engine's files): a connection that got one is closed before it is read. */
        int fd = (int)(lws_intptr_t)in;
        if (fd >= 0 && (unsigned)fd >= s->fd_ceiling) {
            if (s->fd_ceiling_refused++ % 1000 == 0)
                lc_warn("server",
                        "closing a new connection: descriptor %d is in lucentd's reserve (%llu closed so far; "
                        "raise the open-files limit or lower --max-clients)",
                        fd, (unsigned long long)s->fd_ceiling_refused);
            return 1;
        }
        return 0;
    }
    if (reason == LWS_CALLBACK_FILTER_PROTOCOL_CONNECTION) {
        /* A WebSocket upgrade that did not ask for lucent.v1 lands on the default (http)
         * protocol: refuse it (PROTOCOL.md §1.1). */
        lc_info("server", "refusing a WebSocket handshake without subprotocol %s", LC_PROTO_SUBPROTOCOL);
        return 1;
    }
    if (reason == LWS_CALLBACK_FILTER_HTTP_CONNECTION && s && s->cfg->www[0]) {
        const char *uri = in;
        if (strcmp(uri, "/healthz") && strcmp(uri, "/metrics") && !server_www_path_allowed(s, uri)) {
            lc_warn("server", "refusing %s: it resolves outside --www", uri);
            server_refuse_http(wsi, HTTP_STATUS_FORBIDDEN, "forbidden\n");
            return 1;
        }
        return 0;
    }
    if (reason == LWS_CALLBACK_HTTP && s) {
        const char *uri = in;
        static unsigned char out[LWS_PRE + 16384]; /* service thread only */
        char *body = (char *)out + LWS_PRE;
        const size_t cap = sizeof out - LWS_PRE;
        int n = -1;
        unsigned status = HTTP_STATUS_OK;
        int g = server_http_geometry(s, wsi, user);
        if (g != 2) return g;
        if (!strcmp(uri, "/healthz")) n = server_health(s, body, cap, &status);
        else if (!strcmp(uri, "/metrics")) n = server_metrics(s, body, cap);
        if (n >= 0) {
            unsigned char buf[LWS_PRE + 512], *start = buf + LWS_PRE, *p = start, *end = buf + sizeof buf;
            if (lws_add_http_common_headers(wsi, status, "text/plain; version=0.0.4", (lws_filepos_t)n, &p, end) ||
                lws_finalize_write_http_header(wsi, start, &p, end))
                return 1;
            if (lws_write(wsi, (unsigned char *)body, (size_t)n, LWS_WRITE_HTTP_FINAL) != n) return 1;
            return lws_http_transaction_completed(wsi) ? -1 : 0;
        }
    }
    if (reason == LWS_CALLBACK_HTTP_WRITEABLE && s && user && ((server_http_tx *)user)->data)
        return server_geometry_write(wsi, user);
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}
