/* server: lucentd's libwebsockets service (one thread). Sessions, lucent/1 requests, state
 * changes (validated, journaled, acknowledged, broadcast, submitted to the compute thread),
 * frames out, /healthz and /metrics over HTTP on the same port.
 * Every function here runs on the service thread unless it says otherwise. */
#include "server.h"

#include <dirent.h>
#include <errno.h>
#include <libwebsockets.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>

#include "server_internal.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/sigflag.h"

/* accept() failures seen in lws's log (server_lws_log); service thread only. */
static uint64_t server_accept_errors;       /* service thread only */
static int server_accept_failed;            /* service thread only: since the last loop turn */
static double server_accept_logged_ms;      /* service thread only */
static uint64_t server_accept_logged_count; /* service thread only */

uint64_t server_accept_errors_total(void) { return server_accept_errors; }

static lc_sigflag server_stop_flag;
static lc_sigflag server_reload_flag;

static void server_on_signal(int sig) {
    if (sig == SIGHUP) server_reload_flag = 1;
    else server_stop_flag = 1;
}

/* --- outgoing ---------------------------------------------------------------------------------- */

void server_count_error(lc_server *s, const char *code) {
    int i = lc_proto_errcode_find(code);
    if (i < 0) { /* every producer takes its code from the catalogue: a bug if it did not */
        lc_warn("server", "error code '%s' is not in the catalogue (lucent_errors.h); counted as internal", code);
        i = LC_ERR_INTERNAL;
    }
    s->errors[i]++;
}

/* Asks lws for a WRITEABLE callback; until it comes the session counts as stalled (its
 * socket is full: the client is not reading). */
static void session_want_write(lc_session *ss) {
    if (ss->stalled_since_ms == 0) ss->stalled_since_ms = lc_clock_ms();
    lws_callback_on_writable(ss->wsi);
}

/* Drops a session that does not take its output, without a close handshake it would not
 * read anyway; what it queued is freed at once, so a client that never reads cannot pin
 * memory. */
static void session_drop(lc_session *ss, const char *why) {
    if (ss->closing == 2) return;
    lc_warn("server", "client '%s' %s; dropping it (1008)", ss->client, why);
    for (int i = 0; i < ss->outq_n; i++) free(ss->outq[(ss->outq_head + i) % SERVER_OUTQ]);
    ss->outq_n = 0;
    ss->outq_bytes = 0;
    ss->closing = 2; /* 2: dropped, nothing more is queued or sent */
    ss->stalled_since_ms = 0;
    ss->srv->dropped_slow++;
    lws_close_reason(ss->wsi, LWS_CLOSE_STATUS_POLICY_VIOLATION, (unsigned char *)"too slow", 8);
    lws_set_timeout(ss->wsi, PENDING_TIMEOUT_USER_OK, LWS_TO_KILL_ASYNC);
}

/* Queues text (takes ownership). Past SERVER_OUTQ messages or --max-queue-bytes (one
 * message always fits) the client is too slow: dropped. */
void session_send(lc_session *ss, char *text) {
    if (!text) return;
    if (ss->closing == 2) {
        free(text);
        return;
    }
    size_t n = strlen(text);
    if (ss->outq_n >= SERVER_OUTQ || (ss->outq_n > 0 && ss->outq_bytes + n > (size_t)ss->srv->cfg->max_queue_bytes)) {
        free(text);
        char why[96];
        snprintf(why, sizeof why, "left %d messages (%zu bytes) unread", ss->outq_n, ss->outq_bytes);
        session_drop(ss, why);
        return;
    }
    ss->outq[(ss->outq_head + ss->outq_n++) % SERVER_OUTQ] = text;
    ss->outq_bytes += n;
    session_want_write(ss);
}

void session_error(lc_server *s, lc_session *ss, const lc_proto_id *id, lc_proto_errcode code, const char *pointer,
                   const char *message) {
    lc_proto_error e;
    lc_proto_error_set_code(&e, code);
    snprintf(e.pointer, sizeof e.pointer, "%s", pointer);
    snprintf(e.message, sizeof e.message, "%s", message);
    server_count_error(s, e.code);
    session_send(ss, lc_proto_build_error(id, &e));
}

void session_close(lc_session *ss, int code, const char *reason) {
    if (ss->closing) return;
    ss->closing = 1;
    ss->close_code = code;
    snprintf(ss->close_reason, sizeof ss->close_reason, "%s", reason);
    session_want_write(ss);
}

/* Grows the receive buffer to hold need bytes (need <= rx_limit + 1): a message gets the
 * memory it uses, not --max-message up front. */
static int session_rx_reserve(lc_session *ss, size_t need) {
    if (need <= ss->rx_cap) return 0;
    size_t cap = ss->rx_cap ? ss->rx_cap : 1024;
    while (cap < need) cap *= 2;
    if (cap > ss->rx_limit + 1) cap = ss->rx_limit + 1;
    if (cap < need) cap = need;
    char *nb = realloc(ss->rx, cap);
    if (!nb) return -1;
    ss->rx = nb;
    ss->rx_cap = cap;
    return 0;
}

static void session_rx_shrink(lc_session *ss) {
    free(ss->rx);
    ss->rx = NULL;
    ss->rx_cap = 0;
}

static int session_tx_reserve(lc_session *ss, size_t need) {
    if (need <= ss->tx_cap) return 0;
    uint8_t *nb = realloc(ss->tx, need);
    if (!nb) return -1;
    ss->tx = nb;
    ss->tx_cap = need;
    return 0;
}

/* --- lws callbacks -------------------------------------------------------------------------------- */

/* 1 when stream k has something newer than the client got (or a forced keyframe). The MR
 * light (server_mr.c) changes the objects stream between publications and is all mr.vpl carries. */
static int session_stream_pending(const lc_session *ss, int k) {
    const lc_server *s = ss->srv;
    if (!ss->stream[k].on) return 0;
    /* a result without the whole grid: the next one has it (server_update_grid) */
    if (k == LC_STREAM_SHGRID && ss->frame && !ss->frame->grid_complete) return 0;
    if (ss->stream[k].force) return 1;
    if (k == LC_STREAM_MR_VPL) return ss->stream[k].sent_mr_seq < s->mr_seq;
    if (ss->stream[k].sent_pub_seq < ss->frame_seq) return 1;
    return k == LC_STREAM_OBJECTS && ss->stream[k].sent_mr_seq < s->mr_seq;
}

void server_update_grid(lc_server *s) {
    int want = s->cfg->grid == 1;
    for (const lc_session *o = s->sessions; o && !want; o = o->next) want = o->stream[LC_STREAM_SHGRID].on;
    if (want == s->grid_wanted) return;
    s->grid_wanted = want;
    lc_compute_want_grid(s->compute, want);
}

int session_wants_frame(const lc_session *ss) {
    if (!ss->frame) return 0;
    for (int k = 1; k < STREAMS; k++)
        if (session_stream_pending(ss, k)) return 1;
    return 0;
}

/* 1 when some stream has a frame to send now (its max_rate allows it). */
static int session_frame_due(const lc_session *ss, double now) {
    if (!ss->frame) return 0;
    for (int k = 1; k < STREAMS; k++) {
        if (!session_stream_pending(ss, k)) continue;
        if (ss->stream[k].force || ss->stream[k].max_rate <= 0 ||
            now - ss->stream[k].last_ms >= 1000.0 / ss->stream[k].max_rate)
            return 1;
    }
    return 0;
}

/* The objects stream's MR light for an object (lc_frames_job.mr_light). */
static const float *session_mr_light(void *ctx, const char *id, int *add) {
    const lc_server *s = ctx;
    for (uint32_t i = 0; i < s->n_mr_entries; i++)
        if (!strcmp(s->mr_entries[i].id, id)) {
            *add = s->mr_entries[i].add;
            return s->mr_entries[i].sh;
        }
    return NULL;
}

/* The compute thread could not relight a state that clients were told `ok` about: say so
 * once per failure to every client (an `error` event, no id) and in /healthz. */
static void server_report_relight_failure(lc_server *s) {
    uint64_t failures = 0;
    char why[256];
    uint64_t rev = lc_compute_failure(s->compute, &failures, why, sizeof why);
    if (!rev || failures == s->relight_failures_reported) return;
    s->relight_failures_reported = failures;
    char msg[256];
    snprintf(msg, sizeof msg, "relight of revision %llu failed: %.200s", (unsigned long long)rev, why);
    lc_proto_id none = {0};
    for (lc_session *o = s->sessions; o; o = o->next)
        if (o->authed) session_error(s, o, &none, LC_ERR_INTERNAL, "", msg);
}

/* 1 when some session still waits for publication pub_seq's lightmap as a keyframe or
 * whole-tile delta (cheap to write: the encoding is shared). */
static int server_plain_lightmap_pending(const lc_server *s, uint64_t pub_seq) {
    for (const lc_session *o = s->sessions; o; o = o->next)
        if (o->authed && o->frame_seq == pub_seq && !o->stream[LC_STREAM_LIGHTMAP].residual &&
            session_stream_pending(o, LC_STREAM_LIGHTMAP))
            return 1;
    return 0;
}

/* One WRITEABLE's frame: the first subscribed stream with a newer publication (or a forced
 * keyframe) that its max_rate lets through, encoded from the session's copy and written.
 * -1 closes the connection. */
static int session_write_frame(lc_server *s, lc_session *ss, struct lws *wsi) {
    for (int k = 1; k < STREAMS; k++) {
        if (!session_stream_pending(ss, k)) continue;
        double now = lc_clock_ms();
        if (!ss->stream[k].force && ss->stream[k].max_rate > 0 &&
            now - ss->stream[k].last_ms < 1000.0 / ss->stream[k].max_rate)
            continue; /* the tick re-arms writable */
        lc_frames_job job = {.frame = ss->frame,
                             .pub_seq = ss->frame_seq,
                             .stream = k,
                             .enc = ss->stream[k].enc,
                             .residual = ss->stream[k].residual,
                             .sequence = ss->stream[k].sequence + 1,
                             .force_key = ss->stream[k].force,
                             .tile = s->tile,
                             .keyframe_interval = s->cfg->keyframe_interval,
                             .delta_threshold = s->cfg->delta_threshold,
                             .pre = LWS_PRE,
                             .mr_light = s->n_mr_entries ? session_mr_light : NULL,
                             .mr_ctx = s};
        /* A residual delta deflates the dirty tiles on this thread (milliseconds): the sessions
         * in the same poll round that only need a shared keyframe or tile delta go first. Once
         * per publication, so it never waits for a client that does not read. */
        if (ss->deferred_seq != ss->frame_seq && lc_frames_would_deflate(s->frames, &ss->copy, &job) &&
            server_plain_lightmap_pending(s, ss->frame_seq)) {
            ss->deferred_seq = ss->frame_seq;
            return 0; /* still pending: the caller re-arms writable */
        }
        size_t n = k == LC_STREAM_MR_VPL ? server_mr_encode_vpl(s, ss, job.enc, job.sequence)
                                         : lc_frames_encode(s->frames, &ss->copy, &job);
        if (n == 0) return -1;
        ss->stream[k].force = 0;
        ss->stream[k].sequence++;
        ss->stream[k].sent_pub_seq = ss->frame_seq;
        ss->stream[k].sent_mr_seq = s->mr_seq;
        ss->stream[k].last_ms = now;
        if (lws_write(wsi, ss->copy.out + LWS_PRE, n, LWS_WRITE_BINARY) < (int)n) return -1;
        s->frames_sent++;
        s->bytes_sent += n;
        return 0;
    }
    return 0;
}

/* A session's connection closed: out of the list, its resources freed. Service thread. */
static void session_closed(lc_server *s, lc_session *ss) {
    for (lc_session **pp = &s->sessions; *pp; pp = &(*pp)->next)
        if (*pp == ss) {
            *pp = ss->next;
            break;
        }
    s->n_sessions--;
    if (ss->authed) lc_info("server", "client '%s' disconnected", ss->client);
    for (int i = 0; i < ss->outq_n; i++) free(ss->outq[(ss->outq_head + i) % SERVER_OUTQ]);
    server_mr_end(s, ss);
    server_cluster_session_gone(s, ss);
    server_update_grid(s); /* it is out of s->sessions */
    lc_published_release(s->compute, ss->frame);
    free(ss->rx);
    free(ss->tx);
    lc_frames_copy_release(&ss->copy);
    ss->wsi = NULL;
}

static int server_ws_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_vhost *vh = lws_get_vhost(wsi);
    lc_server *s = vh ? lws_get_vhost_user(vh) : NULL;
    lc_session *ss = user;
    switch (reason) {
    case LWS_CALLBACK_FILTER_PROTOCOL_CONNECTION: {
        if (!s) return 1;
        if (s->n_sessions >= (uint32_t)s->max_clients) {
            lc_warn("server", "refusing a connection: %u clients is the limit", s->n_sessions);
            return server_refuse_http(wsi, HTTP_STATUS_SERVICE_UNAVAILABLE, "too many clients\n");
        }
        char why[320];
        if (!server_origin_allowed(s, wsi, why, sizeof why)) {
            lc_warn("server", "refusing a WebSocket handshake: %s", why);
            s->origins_refused++;
            return server_refuse_http(wsi, HTTP_STATUS_FORBIDDEN,
                                      "origin not allowed (see lucentd --help, --origins)\n");
        }
        return 0;
    }
    case LWS_CALLBACK_ESTABLISHED:
        memset(ss, 0, sizeof *ss);
        ss->wsi = wsi;
        ss->srv = s;
        ss->connected_ms = ss->refill_ms = lc_clock_ms();
        ss->tokens = 2.0 * s->cfg->rate;
        snprintf(ss->client, sizeof ss->client, "(before hello)");
        lws_get_peer_simple(wsi, ss->peer, sizeof ss->peer);
        ss->next = s->sessions;
        s->sessions = ss;
        s->n_sessions++;
        return 0;
    case LWS_CALLBACK_CLOSED:
        if (ss && ss->wsi) session_closed(s, ss); /* else refused before ESTABLISHED */
        return 0;
    case LWS_CALLBACK_RECEIVE: {
        if (ss->closing) return 0; /* a closing session's requests are not served */
        if (lws_is_first_fragment(wsi)) {
            ss->rx_len = 0;
            ss->rx_oversize = 0;
            ss->rx_binary = lws_frame_is_binary(wsi);
            /* The bound is fixed for the whole message: a SIGHUP that raises --max-message
             * mid-message must not outgrow the buffer. Before hello only a hello fits. */
            size_t live = (size_t)s->cfg->max_message;
            ss->rx_limit = ss->authed || live < SERVER_HELLO_MAX ? live : SERVER_HELLO_MAX;
            /* An MR session's upload frames (PROTOCOL.md §8.4) are kept up to --mr-max-frame;
             * every other binary message is discarded as it arrives. */
            if (ss->rx_binary && ss->mr) ss->rx_limit = (size_t)s->cfg->mr_max_frame;
        }
        if ((!ss->rx_binary || ss->mr) && !ss->rx_oversize) {
            if (len > ss->rx_limit - ss->rx_len) {
                ss->rx_oversize = 1;
            } else {
                if (session_rx_reserve(ss, ss->rx_len + len + 1) != 0) return -1;
                if (len) memcpy(ss->rx + ss->rx_len, in, len);
                ss->rx_len += len;
            }
        }
        if (!lws_is_final_fragment(wsi)) return 0;
        lc_proto_id none = {0};
        if (ss->rx_binary && !ss->mr_granted) {
            session_error(s, ss, &none, LC_ERR_BINARY_NOT_ALLOWED, "", "clients send text (JSON) messages only");
        } else if (ss->rx_binary && !ss->mr) {
            server_mr_frame(s, ss, NULL, 0); /* answered: outside an MR session */
        } else if (ss->rx_binary && ss->rx_oversize) {
            char msg[96];
            snprintf(msg, sizeof msg, "upload frame over the session's max_frame (%zu bytes)", ss->rx_limit);
            session_error(s, ss, &none, LC_ERR_FRAME_TOO_LARGE, "/frame/length", msg);
        } else if (ss->rx_binary) {
            server_mr_frame(s, ss, (const uint8_t *)ss->rx, ss->rx_len);
        } else if (ss->rx_oversize) {
            char msg[96];
            snprintf(msg, sizeof msg, "message over the size limit (%zu bytes%s)", ss->rx_limit,
                     ss->authed ? "" : " before hello");
            session_error(s, ss, &none, LC_ERR_TOO_LARGE, "", msg);
            session_close(ss, LWS_CLOSE_STATUS_MESSAGE_TOO_LARGE, "too large");
        } else if (!lc_proto_utf8_valid(ss->rx, ss->rx_len)) {
            /* lws's own check would close with 1007 before saying why (PROTOCOL.md §5.2). */
            session_error(s, ss, &none, LC_ERR_BAD_UTF8, "", "the text message is not valid UTF-8");
            session_close(ss, LWS_CLOSE_STATUS_INVALID_PAYLOAD, "bad utf-8");
        } else {
            ss->rx[ss->rx_len] = 0;
            server_request(s, ss, ss->rx, ss->rx_len);
        }
        if (ss->rx_cap > SERVER_HELLO_MAX) session_rx_shrink(ss); /* one large message does not pin its buffer */
        return 0;
    }
    case LWS_CALLBACK_SERVER_WRITEABLE: {
        ss->stalled_since_ms = 0; /* the socket takes data: the client reads */
        if (ss->closing == 2) return -1;
        if (ss->outq_n > 0) {
            char *text = ss->outq[ss->outq_head];
            size_t n = strlen(text);
            if (session_tx_reserve(ss, LWS_PRE + n + 1) != 0) return -1;
            memcpy(ss->tx + LWS_PRE, text, n);
            free(text);
            ss->outq_head = (ss->outq_head + 1) % SERVER_OUTQ;
            ss->outq_n--;
            ss->outq_bytes -= n;
            if (lws_write(wsi, ss->tx + LWS_PRE, n, LWS_WRITE_TEXT) < (int)n) return -1;
            s->bytes_sent += n;
        } else if (ss->closing) {
            lws_close_reason(wsi, (enum lws_close_status)ss->close_code, (unsigned char *)ss->close_reason,
                             strlen(ss->close_reason));
            return -1;
        } else if (ss->authed && session_wants_frame(ss)) {
            if (session_write_frame(s, ss, wsi) != 0) return -1;
        }
        /* A stream held back by its max_rate is re-armed by the tick, not here (that would spin). */
        if (ss->outq_n > 0 || ss->closing || (ss->authed && session_frame_due(ss, lc_clock_ms())))
            session_want_write(ss);
        return 0;
    }
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED: {
        /* The compute thread published (or failed): hand every session the newest result. */
        if (!s) return 0;
        server_cluster_collect(s); /* log entries: state changes (a relight), acks, `changed` */
        server_mr_collect(s);
        server_report_relight_failure(s);
        lc_published *p = lc_compute_take_newer(s->compute, &s->pub_seq);
        if (!p) return 0;
        server_clutter_published(s, p); /* object.transport events go out before the frames */
        for (lc_session *o = s->sessions; o; o = o->next) {
            lc_published_release(s->compute, o->frame); /* a newer frame replaces an unsent one */
            o->frame = lc_published_ref(s->compute, p);
            o->frame_seq = s->pub_seq;
            if (session_wants_frame(o)) session_want_write(o);
        }
        lc_published_release(s->compute, p);
        return 0;
    }
    default: return 0;
    }
}

/* Every 250 ms: hello timeouts, sessions that stopped reading, everysec fsync, rate-limited
 * streams. */
static void server_tick(lws_sorted_usec_list_t *sul) {
    lc_server *s = lws_container_of(sul, lc_server, tick);
    double now = lc_clock_ms();
    for (lc_session *ss = s->sessions; ss; ss = ss->next) {
        if (ss->closing == 2) continue;
        if (!ss->authed && !ss->closing && now - ss->connected_ms > s->cfg->hello_timeout * 1000.0) {
            lc_proto_id none = {0};
            session_error(s, ss, &none, LC_ERR_HELLO_REQUIRED, "", "no hello within the time limit");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "hello timeout");
        }
        /* A client that takes none of its output (replies or frames: its socket stays full)
         * must not hold memory or the others back: past --slow-timeout it is dropped. */
        if (ss->stalled_since_ms > 0 && now - ss->stalled_since_ms > s->cfg->slow_timeout * 1000.0) {
            char why[96];
            snprintf(why, sizeof why, "took no output for %d s", s->cfg->slow_timeout);
            session_drop(ss, why);
            continue;
        }
        if (ss->authed && session_frame_due(ss, now)) session_want_write(ss);
    }
    lc_journal_tick(s->journal, &s->state);
    server_cluster_tick(s);
    server_clutter_tick(s);
    lws_sul_schedule(s->ctx, 0, &s->tick, server_tick, 250 * LWS_US_PER_MS);
}

/* LC_PROTO_WS_TX_PACKET_MAX: a 600 KiB lightmap frame left in 40 pieces before; with ten
 * clients (conference room) its relight-to-client time was 14-15 ms, now 7-8. */
static const struct lws_protocols server_protocols[] = {
    {"http", server_http_callback, sizeof(server_http_tx), 0, 0, NULL, 0},
    {LC_PROTO_SUBPROTOCOL, server_ws_callback, sizeof(lc_session), 16384, 0, NULL, LC_PROTO_WS_TX_PACKET_MAX},
    {NULL, NULL, 0, 0, 0, NULL, 0},
};

/* --- run ------------------------------------------------------------------------------------------ */

/* 1 when the state dir holds no state yet: no snapshot and an absent or empty journal. */
static int server_state_dir_fresh(const char *dir) {
    char path[LC_CONFIG_PATH_MAX + 32];
    struct stat st;
    snprintf(path, sizeof path, "%.1024s/snapshot.json", dir);
    if (stat(path, &st) == 0) return 0;
    snprintf(path, sizeof path, "%.1024s/journal.log", dir);
    return stat(path, &st) != 0 || st.st_size == 0;
}

/* Compute thread: a relight was published (or failed); wake the service loop. */
static void server_wake(void *ctx) { lws_cancel_service(ctx); }

/* --- descriptors ------------------------------------------------------------------------------ */

/* What lucentd keeps for itself beyond the sockets: journal, snapshot writes, the bake, the
 * engine's and the log's files. */
#define SERVER_FD_RESERVE 32

/* Descriptors the sockets may use: the open-files limit (the soft limit is raised to the hard
 * one, as Redis does) minus what is open now and SERVER_FD_RESERVE; *ceiling = the lowest
 * descriptor number a connection may not have (the limit minus the reserve; accept() gives
 * the lowest free number, so a socket at or above it means the reserve is being eaten: it is
 * closed at once, see server_http_callback). 0 when unknown / unlimited. */
static unsigned server_fd_budget(unsigned *ceiling) {
    *ceiling = 0;
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl) != 0) return 0;
    if (rl.rlim_cur < rl.rlim_max) {
        struct rlimit want = rl;
        want.rlim_cur = rl.rlim_max == RLIM_INFINITY || rl.rlim_max > 1048576 ? 1048576 : rl.rlim_max;
        if (setrlimit(RLIMIT_NOFILE, &want) == 0) rl = want;
    }
    unsigned open_now = 0;
    DIR *d = opendir("/proc/self/fd");
    if (d) {
        for (struct dirent *e; (e = readdir(d));)
            if (e->d_name[0] != '.') open_now++;
        closedir(d);
    }
    if (rl.rlim_cur == RLIM_INFINITY) return 0;
    *ceiling = rl.rlim_cur > 2 * SERVER_FD_RESERVE ? (unsigned)rl.rlim_cur - SERVER_FD_RESERVE : (unsigned)rl.rlim_cur;
    if (rl.rlim_cur <= open_now + SERVER_FD_RESERVE + 16) return 16;
    return (unsigned)rl.rlim_cur - open_now - SERVER_FD_RESERVE;
}

/* --max-clients, lowered to what the descriptor budget allows (a few sockets are lws's own:
 * the listener, its wake-up pipe, HTTP requests). */
static uint32_t server_max_clients(int configured, unsigned fd_budget) {
    uint32_t n = (uint32_t)configured;
    if (fd_budget && n > fd_budget - 8) n = fd_budget > 9 ? fd_budget - 8 : 1;
    return n;
}

/* lws logs through here (service thread). accept() failures are counted and logged once per
 * 10 s, and make the loop back off (server_accept_backoff) instead of spinning. */
static void server_lws_log(int level, const char *line) {
    size_t n = strlen(line);
    while (n && (line[n - 1] == '\n' || line[n - 1] == '\r')) n--;
    if (strstr(line, "accept:")) {
        server_accept_errors++;
        server_accept_failed = 1;
        double now = lc_clock_ms();
        if (now - server_accept_logged_ms < 10000) return;
        lc_error("server",
                 "cannot accept connections: %.*s (%llu times in the last interval; raise the "
                 "open-files limit or lower --max-clients)",
                 (int)n, line, (unsigned long long)(server_accept_errors - server_accept_logged_count));
        server_accept_logged_ms = now;
        server_accept_logged_count = server_accept_errors;
        return;
    }
    if (level & LLL_ERR) lc_error("lws", "%.*s", (int)n, line);
    else lc_warn("lws", "%.*s", (int)n, line);
}

/* SIGHUP: parse the configuration again and apply what can change while running. */
static void server_reload(lc_server *s) {
    char err[512], restart[512];
    lc_config *next = &s->cfg_reload;
    if (lc_config_load(next, s->argc, s->argv, err, sizeof err) != 0) {
        lc_error("server", "SIGHUP: configuration not reloaded: %s", err);
        return;
    }
    lc_config_apply_reloadable(s->cfg, next, restart, sizeof restart);
    s->reloads++;
    s->limits.max_message = (size_t)s->cfg->max_message;
    s->limits.max_depth = s->cfg->max_depth;
    s->limits.max_batch = (uint32_t)s->cfg->max_batch;
    s->max_clients = server_max_clients(s->cfg->max_clients, s->fd_budget);
    lc_log_set_level((lc_log_level)s->cfg->log_level);
    lc_info("server", "SIGHUP: configuration reloaded%s%s", restart[0] ? "; needs a restart to change: " : "", restart);
}

/* The state: from the bake (and its lights, on a fresh state dir), then the snapshot and
 * the journal. Returns 0 or -1 (logged). */
static int server_open_state(lc_server *s) {
    const lc_config *cfg = s->cfg;
    char err[512];
    lc_state_limits sl = {(uint32_t)cfg->max_lights, (uint32_t)cfg->max_objects};
    if (lc_state_init(&s->state, s->bake, &sl) != 0) {
        lc_error("server", "out of memory creating the state");
        return -1;
    }
    s->state.settings.bounces = (uint32_t)cfg->bounces; /* a restored snapshot's settings replace this */
    if (cfg->cluster[0]) { /* the bake's state at revision 0, as on every replica; the log does the rest */
        if (lc_state_seed(&s->state, err, sizeof err) != 0) {
            lc_error("server", "%s", err);
            return -1;
        }
        return 0;
    }
    /* A fresh state dir starts with the bake's own lights (KHR_lights_punctual: the scene's
     * initial lights); from then on the snapshot holds what clients made of them. */
    const int fresh = server_state_dir_fresh(cfg->state_dir);
    if (fresh && lc_state_seed(&s->state, err, sizeof err) != 0) {
        lc_error("server", "%s", err);
        return -1;
    }
    /* --recover: the snapshot plus the journal's valid prefix; the journal reports what it drops. */
    s->journal = cfg->recover
        ? lc_journal_recover(cfg->state_dir, (lc_fsync_mode)cfg->fsync_mode, &s->state, NULL, err, sizeof err)
        : lc_journal_open(cfg->state_dir, (lc_fsync_mode)cfg->fsync_mode, &s->state, err, sizeof err);
    if (!s->journal) {
        lc_error("server", "%s", err);
        return -1;
    }
    lc_info("server", "state %s %s: revision %llu, %u lights, %u objects", fresh ? "created in" : "restored from",
            cfg->state_dir, (unsigned long long)s->state.revision, s->state.n_lights, s->state.n_objects);
    if (fresh && s->state.n_lights && lc_journal_compact(s->journal, &s->state, err, sizeof err) != 0) {
        lc_error("server", "writing the initial snapshot: %s", err);
        return -1;
    }
    return 0;
}

/* The lws context: the port, TLS, the --www mount, the descriptor budget. Returns 0 or -1
 * (logged). */
static int server_listen(lc_server *s) {
    const lc_config *cfg = s->cfg;
    lws_set_log_level(LLL_ERR | LLL_WARN, server_lws_log);
    s->fd_budget = server_fd_budget(&s->fd_ceiling);
    s->max_clients = server_max_clients(cfg->max_clients, s->fd_budget);
    if (s->max_clients < (uint32_t)cfg->max_clients)
        lc_warn("server", "--max-clients %d lowered to %u: the open-files limit leaves %u descriptors (ulimit -n)",
                cfg->max_clients, s->max_clients, s->fd_budget);
    /* Mounts: the bake's geometry (answered by the http protocol's callback, so a file of
     * the same name under --www cannot shadow it), then the --www folder at /. */
    /* lws knows neither: scene geometry, and lucent-ref's heat maps for the viewer's overlay */
    static const struct lws_protocol_vhost_options exr_mime = {NULL, NULL, ".exr", "image/x-exr"};
    static const struct lws_protocol_vhost_options glb_mime = {&exr_mime, NULL, ".glb", "model/gltf-binary"};
    memset(&s->mount, 0, sizeof s->mount);
    s->mount.mountpoint = "/";
    s->mount.mountpoint_len = 1;
    s->mount.origin = cfg->www;
    s->mount.def = "index.html";
    s->mount.origin_protocol = LWSMPRO_FILE;
    s->mount.extra_mimetypes = &glb_mime;
    memset(&s->mount_scene, 0, sizeof s->mount_scene);
    s->mount_scene.mountpoint = "/scene.glb";
    s->mount_scene.mountpoint_len = (unsigned char)strlen(s->mount_scene.mountpoint);
    s->mount_scene.origin = "http";
    s->mount_scene.origin_protocol = LWSMPRO_CALLBACK;
    s->mount_assets = s->mount_scene;
    s->mount_assets.mountpoint = "/assets";
    s->mount_assets.mountpoint_len = (unsigned char)strlen(s->mount_assets.mountpoint);
    s->mount_scene.mount_next = &s->mount_assets;
    s->mount_assets.mount_next = cfg->www[0] ? &s->mount : NULL;
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = cfg->port;
    info.iface = cfg->listen;
    info.protocols = server_protocols;
    info.mounts = &s->mount_scene;
    info.user = s;
    /* UTF-8 is checked per message (the receive path), so the client hears `bad_utf8` before
     * the 1007 close instead of lws closing silently. */
    info.options = LWS_SERVER_OPTION_HTTP_HEADERS_SECURITY_BEST_PRACTICES_ENFORCE;
    info.pt_serv_buf_size = 65536;
    /* No info.fd_limit_per_thread: below the open-files limit it makes lws 4.1 look each
     * socket up by scanning its whole table (half of lucentd's CPU at 10 000 clients). The
     * reserve is kept by the descriptor ceiling at accept instead. */
    if (cfg->tls_cert[0]) {
        info.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
        info.ssl_cert_filepath = cfg->tls_cert;
        info.ssl_private_key_filepath = cfg->tls_key;
        /* Browsers may pick HTTP/2 and run WebSockets over it, where one large frame write
         * breaks the stream: keep the port on HTTP/1.1. */
        info.alpn = "http/1.1";
    }
    s->ctx = lws_create_context(&info);
    if (!s->ctx) {
        lc_error("server", "cannot listen on %s:%d (port in use? see --listen/--port)", cfg->listen, cfg->port);
        return -1;
    }
    struct lws_vhost *vh = lws_get_vhost_by_name(s->ctx, "default");
    s->port = vh ? lws_get_vhost_listen_port(vh) : cfg->port;
    return 0;
}

/* Serves until SIGINT/SIGTERM; SIGHUP reloads between loop turns. */
static void server_loop(lc_server *s) {
    while (!server_stop_flag) {
        if (lws_service(s->ctx, 0) < 0) break;
        if (server_accept_failed) { /* out of descriptors: let the clients' sockets drain */
            server_accept_failed = 0;
            struct timespec pause = {0, 50 * 1000 * 1000};
            nanosleep(&pause, NULL);
        }
        if (server_reload_flag) {
            server_reload_flag = 0;
            server_reload(s);
        }
    }
    lc_info("server", "shutting down: closing %u clients", s->n_sessions);
    for (lc_session *ss = s->sessions; ss; ss = ss->next)
        session_close(ss, LWS_CLOSE_STATUS_GOINGAWAY, "server stopping");
    /* Up to 2 s for the close frames to go out (20 bare loop turns were not enough on a
     * loaded machine: clients saw 1006 instead of 1001). */
    for (double until = lc_clock_ms() + 2000; s->n_sessions && lc_clock_ms() < until;)
        if (lws_service(s->ctx, 0) < 0) break;
}

/* Frees everything; after a clean stop (clean = 1) the state goes into a final snapshot. */
static void server_release(lc_server *s, int clean) {
    char err[512];
    /* The compute thread first: a relight in flight ends with a wake (lws_cancel_service),
     * which must not touch a destroyed context. Sessions then release their frames as the
     * context closes them, and only then is the compute object freed. */
    lc_compute_stop(s->compute);
    server_clutter_stop(s); /* its deliveries go to the compute object */
    server_mr_stop(s);      /* the MR worker's wake too */
    server_cluster_stop(s); /* and the log's threads' */
    if (s->ctx) {
        lws_sul_cancel(&s->tick);
        lws_context_destroy(s->ctx);
    }
    lc_compute_release(s->compute);
    if (s->journal && clean && lc_journal_compact(s->journal, &s->state, err, sizeof err) != 0)
        lc_error("server", "final snapshot: %s", err);
    lc_journal_close(s->journal);
    lc_state_release(&s->state);
    lc_frames_release(s->frames);
    free(s->asset_names);
    free(s->material_names);
    server_geometry_release(s);
    free(s);
}

int lc_server_run(const lc_config *cfg_in, int argc, char **argv, const lc_lcb *bake, lc_server_ready_fn ready,
                  void *ready_arg) {
    uint16_t probe = 1;
    if (*(uint8_t *)&probe != 1) {
        lc_error("server", "big-endian hosts are not supported (frames are written little-endian in place)");
        return 1;
    }
    lc_server *s = calloc(1, sizeof *s);
    if (!s) {
        lc_error("server", "out of memory");
        return 1;
    }
    atomic_store(&server_stop_flag, 0); /* a second run in one process starts afresh */
    atomic_store(&server_reload_flag, 0);
    int rc = 1;
    char err[512];
    s->cfg_live = *cfg_in;
    s->cfg = &s->cfg_live;
    s->argc = argc;
    s->argv = argv;
    s->bake = bake;
    s->v = lc_lcb_get(bake);
    s->tile = lc_frames_tile_size(s->cfg->tile, s->v->lightmap_width, s->v->lightmap_height);
    s->frames = lc_frames_create();
    lc_proto_default_limits(&s->limits);
    s->limits.max_message = (size_t)s->cfg->max_message;
    s->limits.max_depth = s->cfg->max_depth;
    s->limits.max_batch = (uint32_t)s->cfg->max_batch;
    s->asset_names = calloc(s->v->n_assets + 1, sizeof *s->asset_names);
    s->material_names = calloc(s->v->n_materials + 1, sizeof *s->material_names);
    if (!s->frames || !s->asset_names || !s->material_names) {
        lc_error("server", "out of memory");
        goto done;
    }
    for (uint32_t i = 0; i < s->v->n_assets; i++) s->asset_names[i] = s->v->assets[i].name;
    for (uint32_t i = 0; i < s->v->n_materials; i++) s->material_names[i] = s->v->materials[i].name;
    if (server_geometry_build(s) != 0 || server_open_state(s) != 0 || server_listen(s) != 0) goto done;
    const lc_config *cfg = s->cfg;
    lc_compute_refinement refine = {cfg->refine_passes, cfg->refine_delay, cfg->refine_tolerance, cfg->cluster[0] != 0};
    s->compute = lc_compute_start(bake, cfg->backend, cfg->threads, &refine, server_wake, s->ctx, err, sizeof err);
    if (!s->compute) {
        lc_error("server", "%s", err);
        goto done;
    }
    if (server_mr_start(s, err, sizeof err) != 0 || server_clutter_start(s, err, sizeof err) != 0 ||
        server_cluster_start(s, err, sizeof err) != 0) {
        lc_error("server", "%s", err);
        goto done;
    }
    lc_state_set_backend(&s->state, lc_compute_backend_kind(s->compute)); /* settings.solver: what it runs */
    server_update_grid(s);                                                /* --grid always: from the first */
    lc_compute_submit(s->compute, &s->state, NULL);                       /* the first frame: the restored state */
    signal(SIGINT, server_on_signal);
    signal(SIGTERM, server_on_signal);
    signal(SIGHUP, server_on_signal);
    signal(SIGPIPE, SIG_IGN);
    lc_info("server", "lucentd %s listening on %s://%s:%d (subprotocol %s, backend %s)", LUCENTD_VERSION,
            cfg->tls_cert[0] ? "wss" : "ws", cfg->listen, s->port, LC_PROTO_SUBPROTOCOL,
            lc_compute_backend(s->compute));
    if (ready) ready(ready_arg, s->port);
    lws_sul_schedule(s->ctx, 0, &s->tick, server_tick, 250 * LWS_US_PER_MS);
    server_loop(s);
    rc = 0;
done:
    server_release(s, rc == 0);
    return rc;
}
