/* server: lucentd's libwebsockets service (one thread). Sessions, lucent/1 requests, state
 * changes (validated, journaled, acknowledged, broadcast, submitted to the compute thread),
 * frames out, /healthz and /metrics over HTTP on the same port.
 * Every function here runs on the service thread unless it says otherwise. */
#include "server.h"

#include <libwebsockets.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <strings.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>

#include "compute.h"
#include "journal.h"
#include "state.h"
#include "util/clock.h"
#include "util/half.h"
#include "util/log.h"

#define SERVER_OUTQ 1024 /* queued text messages per session (replies to a full request burst fit); past this the client is too slow */
/* What a socket may send before its hello is accepted: a hello is a client name and a token
 * (lucent_proto.h), so an unauthenticated peer never gets the full --max-message buffer. */
#define SERVER_HELLO_MAX 4096

enum { STREAMS = 4 }; /* index = lc_stream (1..3) */

typedef struct lc_server lc_server;

typedef struct lc_session {
    struct lws *wsi;
    lc_server *srv;
    struct lc_session *next;
    int authed, controller;
    char client[LC_PROTO_NAME_MAX + 1];
    char peer[64]; /* the peer's address, for the failed-hello throttle and the log */
    char *rx;
    size_t rx_len, rx_cap;
    size_t rx_limit; /* the bound of the message being received, fixed at its first fragment (SIGHUP may change the live one) */
    int rx_binary, rx_oversize;
    char *outq[SERVER_OUTQ];
    int outq_head, outq_n;
    size_t outq_bytes;         /* bytes in outq: over --max-queue-bytes the client is dropped */
    double stalled_since_ms;   /* since when output has waited without the client taking any (0 = none) */
    int closing, close_code;
    char close_reason[64];
    double connected_ms;
    double tokens, refill_ms; /* request rate limit (token bucket) */
    struct {
        int on, force;
        lc_encoding enc;
        int residual;          /* lightmap deltas as compressed residuals (PROTOCOL.md §6.2.1) */
        uint64_t sequence;     /* frames sent on this stream */
        uint64_t sent_pub_seq; /* publication last sent */
        double max_rate, last_ms;
    } stream[STREAMS];
    float *lm_sent;      /* per texel, the value the client's copy was encoded from (deltas compare against it) */
    size_t lm_sent_texels;
    uint8_t *lm_held;    /* residual subscribers: the encoded texels the client holds (lm_held_bytes) */
    size_t lm_held_bytes;
    uint64_t lm_held_state; /* names lm_held's content (lc_residual_memo) */
    lc_published *frame; /* newest result for this session (a reference) */
    uint64_t frame_seq;
    uint8_t *tx;
    size_t tx_cap;
} lc_session;

/* Failed hellos per peer address (see server_auth_peer_for). */
#define SERVER_AUTH_PEERS 256
#define SERVER_AUTH_BURST 10.0
#define SERVER_AUTH_PER_S 1.0
typedef struct server_auth_peer {
    char peer[64];
    double tokens, last_ms;
} server_auth_peer;

/* A publication's lightmap in one encoding (see lc_server.lm_encoded). */
typedef struct lc_encoded_lightmap {
    int valid;
    uint64_t pub_seq; /* the publication it encodes */
    uint8_t *words;   /* W*H texels as on the wire */
    size_t cap;
} lc_encoded_lightmap;

/* One residual delta: what takes a client copy in state `from_state` to publication
 * `pub_seq`. Two sessions in the same state hold bit-identical copies (the same keyframe,
 * then the same deltas), so they can share it. */
typedef struct lc_residual_memo {
    int valid, keyframe; /* keyframe: not smaller than one; send that instead */
    uint64_t from_state, pub_seq, to_state;
    uint32_t *tiles, n_tiles;
    uint32_t *moved, n_moved; /* the texels (y*W+x) that get their new value */
    uint8_t *payload;
    size_t payload_len;
} lc_residual_memo;

struct lc_server {
    lc_config *cfg; /* live copy: SIGHUP reloads its reloadable fields */
    int argc;
    char **argv;
    const lc_lcb *bake;
    const lc_lcb_view *v;
    lc_state state;
    lc_journal *journal;
    lc_compute *compute;
    struct lws_context *ctx;
    lc_session *sessions;
    uint32_t n_sessions;
    uint64_t pub_seq; /* compute publications seen */
    uint32_t tile;    /* lightmap delta tile side: --tile, or chosen from the lightmap size */
    /* The lightmap of one publication encoded once per encoding, shared by every session's
     * keyframes, tiles and residuals (100 clients: one encode per frame, not 100). */
    lc_encoded_lightmap lm_encoded[4]; /* index: lc_encoding */
    lc_residual_memo lm_residual[4];   /* the last residual delta computed per encoding */
    uint64_t residual_states;          /* ids handed to copies made by residual deltas */
    const char **asset_names, **material_names;
    lc_proto_limits limits;
    lws_sorted_usec_list_t tick;
    int port;
    uint32_t max_clients; /* --max-clients, lowered to what the descriptor limit allows */
    unsigned fd_budget;   /* descriptors the sockets may use (0 = unlimited) */
    /* metrics */
    uint64_t frames_sent, bytes_sent, messages_in, errors[32];
    char error_codes[32][32];
    uint64_t dropped_slow;      /* sessions dropped for not taking their output */
    uint64_t auth_failures;     /* hellos with an unknown token */
    uint64_t reloads;           /* SIGHUPs whose configuration was applied */
    server_auth_peer auth_peers[SERVER_AUTH_PEERS];
    uint64_t relight_failures_reported; /* compute failures already told to clients */
};

/* accept() failures seen in lws's log (server_lws_log); service thread only. */
static uint64_t server_accept_errors;      /* service thread only */
static int server_accept_failed;           /* service thread only: since the last loop turn */
static double server_accept_logged_ms;     /* service thread only */
static uint64_t server_accept_logged_count; /* service thread only */

static volatile sig_atomic_t server_stop_flag = 0;
static volatile sig_atomic_t server_reload_flag = 0;

static void server_on_signal(int sig) {
    if (sig == SIGHUP) server_reload_flag = 1;
    else server_stop_flag = 1;
}

/* --- outgoing ---------------------------------------------------------------------------------- */

static void server_count_error(lc_server *s, const char *code) {
    for (int i = 0; i < 32; i++) {
        if (!s->error_codes[i][0]) snprintf(s->error_codes[i], sizeof s->error_codes[i], "%s", code);
        if (!strcmp(s->error_codes[i], code)) {
            s->errors[i]++;
            return;
        }
    }
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
static void session_send(lc_session *ss, char *text) {
    if (!text) return;
    if (ss->closing == 2) {
        free(text);
        return;
    }
    size_t n = strlen(text);
    if (ss->outq_n >= SERVER_OUTQ ||
        (ss->outq_n > 0 && ss->outq_bytes + n > (size_t)ss->srv->cfg->max_queue_bytes)) {
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

static void session_error(lc_server *s, lc_session *ss, const lc_proto_id *id, const char *code, const char *pointer,
                          const char *message) {
    lc_proto_error e;
    snprintf(e.code, sizeof e.code, "%s", code);
    snprintf(e.pointer, sizeof e.pointer, "%s", pointer);
    snprintf(e.message, sizeof e.message, "%s", message);
    server_count_error(s, code);
    session_send(ss, lc_proto_build_error(id, &e));
}

static void session_close(lc_session *ss, int code, const char *reason) {
    if (ss->closing) return;
    ss->closing = 1;
    ss->close_code = code;
    snprintf(ss->close_reason, sizeof ss->close_reason, "%s", reason);
    session_want_write(ss);
}

static void encode_texel(lc_encoding enc, const float *t, uint8_t *o) {
    if (enc == LC_ENC_RGB9E5) {
        uint32_t v = lc_rgb9e5_encode(t);
        memcpy(o, &v, 4); /* little-endian hosts only (checked at start) */
    } else if (enc == LC_ENC_RGBA16F) {
        uint16_t hv[4] = {lc_half_from_float(t[0]), lc_half_from_float(t[1]), lc_half_from_float(t[2]), 0x3C00};
        memcpy(o, hv, 8);
    } else {
        memcpy(o, t, 12);
    }
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

/* The delta tile side: the configured one, or (0 = auto) the largest of 32, 16, 8 that still
 * cuts the lightmap into at least 64 tiles, so small lightmaps get deltas worth sending. */
static uint32_t server_tile_size(int configured, uint32_t w, uint32_t h) {
    if (configured > 0) return (uint32_t)configured;
    uint32_t t = 32;
    while (t > 8 && lc_tiles_count(w, h, t) < 64) t /= 2;
    return t;
}

/* 1 when texel i of `now` moved by more than thr (relative to the texel's brightest channel,
 * at least floor_v) from `sent`: a dim channel (the blue of a warm light) must not make a
 * texel dirty for changes nobody can see. */
static int texel_moved(const float *now, const float *sent, size_t i, float thr, float floor_v) {
    const float *a = now + 3 * i, *b = sent + 3 * i;
    float ref = fmaxf(fmaxf(fmaxf(a[0], a[1]), fmaxf(a[2], b[0])), fmaxf(fmaxf(b[1], b[2]), floor_v));
    for (int c = 0; c < 3; c++)
        if (fabsf(a[c] - b[c]) > thr * ref) return 1;
    return 0;
}

/* The lightmap of ss->frame in `enc` (W*H texels as on the wire), encoded on first use per
 * publication and kept until the next one. NULL when out of memory. */
static const uint8_t *server_lightmap_words(lc_server *s, const lc_session *ss, lc_encoding enc) {
    const lc_published *p = ss->frame;
    const size_t texels = (size_t)p->lm_w * p->lm_h, tb = lc_frame_texel_bytes(enc);
    lc_encoded_lightmap *e = &s->lm_encoded[enc];
    if (e->valid && e->pub_seq == ss->frame_seq) return e->words;
    if (texels * tb > e->cap) {
        uint8_t *n = realloc(e->words, texels * tb);
        if (!n) return NULL;
        e->words = n;
        e->cap = texels * tb;
    }
    for (size_t i = 0; i < texels; i++) encode_texel(enc, p->lightmap + 3 * i, e->words + i * tb);
    e->valid = 1;
    e->pub_seq = ss->frame_seq;
    return e->words;
}

/* The tiles where some texel of ss->frame moved by more than thr from ss->lm_sent, into tiles
 * (capacity: every tile); returns their count and the texels they cover in *texels_out. */
static uint32_t session_dirty_tiles(const lc_session *ss, uint32_t S, float thr, float floor_v, uint32_t *tiles,
                                    size_t *texels_out) {
    const lc_published *p = ss->frame;
    const uint32_t W = p->lm_w, H = p->lm_h, T = lc_tiles_count(W, H, S);
    uint32_t n = 0;
    *texels_out = 0;
    for (uint32_t t = 0; t < T; t++) {
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(W, H, S, t, &x0, &y0, &x1, &y1);
        int dirty = 0;
        for (uint32_t y = y0; y < y1 && !dirty; y++)
            for (uint32_t x = x0; x < x1 && !dirty; x++)
                dirty = texel_moved(p->lightmap, ss->lm_sent, (size_t)y * W + x, thr, floor_v);
        if (dirty) {
            tiles[n++] = t;
            *texels_out += (size_t)(x1 - x0) * (y1 - y0);
        }
    }
    return n;
}

/* Computes into m the residual delta (PROTOCOL.md §6.2.1) that takes a client holding
 * ss->lm_held to ss->frame: the dirty tiles; in them, texels that moved get their new value
 * (`words`), the others keep the client's (residual 0); zlib-compressed. m->keyframe when it
 * would not be smaller than a keyframe. The caller sets m's key fields. */
static int residual_compute(lc_residual_memo *m, const lc_session *ss, lc_encoding enc, const uint8_t *words,
                            uint32_t S, float thr, float floor_v) {
    const lc_published *p = ss->frame;
    const uint32_t W = p->lm_w, H = p->lm_h, T = lc_tiles_count(W, H, S);
    const size_t texels = (size_t)W * H, tb = lc_frame_texel_bytes(enc);
    m->valid = 0;
    uint32_t *tiles = realloc(m->tiles, (size_t)T * sizeof *tiles);
    if (!tiles) return -1;
    m->tiles = tiles;
    size_t delta_texels;
    m->n_tiles = session_dirty_tiles(ss, S, thr, floor_v, m->tiles, &delta_texels);
    const size_t raw_len = delta_texels * tb, table = 4 * (size_t)m->n_tiles;
    uint8_t *raw = malloc(raw_len ? raw_len : 1), *z = realloc(m->payload, lc_residual_deflate_bound(raw_len));
    uint32_t *moved = realloc(m->moved, (delta_texels ? delta_texels : 1) * sizeof *moved);
    if (moved) m->moved = moved;
    if (z) m->payload = z;
    if (!raw || !moved || !z) {
        free(raw);
        return -1;
    }
    size_t k = 0;
    m->n_moved = 0;
    for (uint32_t t = 0; t < m->n_tiles; t++) {
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(W, H, S, m->tiles[t], &x0, &y0, &x1, &y1);
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++, k++) {
                size_t i = (size_t)y * W + x;
                if (texel_moved(p->lightmap, ss->lm_sent, i, thr, floor_v)) {
                    lc_residual_make(enc, words + i * tb, ss->lm_held + i * tb, 1, raw + k * tb);
                    moved[m->n_moved++] = (uint32_t)i;
                } else {
                    memset(raw + k * tb, 0, tb);
                }
            }
    }
    m->payload_len = m->n_tiles ? lc_residual_deflate(raw, raw_len, z, lc_residual_deflate_bound(raw_len)) : 0;
    free(raw);
    m->keyframe = m->n_tiles && (m->payload_len == 0 || table + m->payload_len >= texels * tb);
    m->valid = 1;
    return 0;
}

/* Commits a residual delta to the session: the client will hold the moved texels' new values. */
static void session_commit_residual(lc_session *ss, const lc_residual_memo *m, const uint8_t *words, size_t tb) {
    const float *lightmap = ss->frame->lightmap;
    for (uint32_t k = 0; k < m->n_moved; k++) {
        size_t i = m->moved[k];
        memcpy(ss->lm_held + i * tb, words + i * tb, tb);
        memcpy(ss->lm_sent + 3 * i, lightmap + 3 * i, 3 * sizeof(float));
    }
    ss->lm_held_state = m->to_state;
}

/* Lightmap frame: a keyframe when forced, first, every keyframe_interval frames or when the
 * delta would not be smaller; otherwise a delta of the tiles where some texel moved by more
 * than delta_threshold (relative) from what this client last received: whole tiles, or
 * residuals when the client subscribed to them. Sessions holding the same copy (same state
 * id) share one residual computation per publication: subscribers in step cost one
 * compression per frame, not one each (100 clients: p50 228 -> 16 ms). */
static size_t session_encode_lightmap(lc_server *s, lc_session *ss, lc_frame_header *h, int force_key) {
    const lc_published *p = ss->frame;
    const uint32_t W = p->lm_w, H = p->lm_h, S = s->tile;
    const lc_encoding enc = (lc_encoding)h->encoding;
    const size_t texels = (size_t)W * H, tb = lc_frame_texel_bytes(enc);
    const int residual_sub = ss->stream[LC_STREAM_LIGHTMAP].residual;
    const uint8_t *words = server_lightmap_words(s, ss, enc);
    if (!words) return 0;
    int key = force_key || !ss->lm_sent || ss->lm_sent_texels != texels ||
              (residual_sub && ss->lm_held_bytes != texels * tb) ||
              (h->sequence - 1) % (uint64_t)s->cfg->keyframe_interval == 0;
    const uint32_t *tiles = NULL;
    uint32_t *own_tiles = NULL, n_tiles = 0;
    const uint8_t *residual = NULL;
    size_t delta_texels = 0, payload_len = texels * tb, n = 0;
    float peak = 0;
    for (size_t i = 0; !key && i < texels * 3; i++) peak = fmaxf(peak, p->lightmap[i]);
    const float thr = (float)s->cfg->delta_threshold, floor_v = 1e-3f * peak;
    if (!key && residual_sub) {
        lc_residual_memo *m = &s->lm_residual[enc];
        if (!(m->valid && m->from_state == ss->lm_held_state && m->pub_seq == ss->frame_seq)) {
            if (residual_compute(m, ss, enc, words, S, thr, floor_v) != 0) return 0;
            m->from_state = ss->lm_held_state;
            m->pub_seq = ss->frame_seq;
            m->to_state = ++s->residual_states;
        }
        key = m->keyframe;
        if (!key) {
            session_commit_residual(ss, m, words, tb);
            tiles = m->tiles;
            n_tiles = m->n_tiles;
            residual = m->payload;
            payload_len = m->payload_len;
        }
    } else if (!key) {
        own_tiles = malloc((size_t)lc_tiles_count(W, H, S) * sizeof *own_tiles);
        if (!own_tiles) return 0;
        n_tiles = session_dirty_tiles(ss, S, thr, floor_v, own_tiles, &delta_texels);
        tiles = own_tiles;
        payload_len = delta_texels * tb;
        key = payload_len + 4 * (size_t)n_tiles >= texels * tb; /* no smaller than a keyframe */
    }
    if (key) payload_len = texels * tb;
    size_t table = key ? 0 : 4 * (size_t)n_tiles;
    if (session_tx_reserve(ss, LWS_PRE + 2 * (LC_FRAME_HEADER_SIZE + table + payload_len) + 64) != 0) goto done;
    uint8_t *stage = ss->tx + LWS_PRE + LC_FRAME_HEADER_SIZE + table + payload_len + 32, *o = stage;
    if (key) {
        memcpy(stage, words, texels * tb);
        if (ss->lm_sent_texels != texels) {
            free(ss->lm_sent);
            ss->lm_sent = malloc(texels * 3 * sizeof(float));
            ss->lm_sent_texels = ss->lm_sent ? texels : 0;
        }
        if (ss->lm_sent) memcpy(ss->lm_sent, p->lightmap, texels * 3 * sizeof(float));
        if (residual_sub) {
            if (ss->lm_held_bytes != texels * tb) {
                free(ss->lm_held);
                ss->lm_held = malloc(texels * tb);
                ss->lm_held_bytes = ss->lm_held ? texels * tb : 0;
            }
            if (ss->lm_held) memcpy(ss->lm_held, words, texels * tb);
            /* a copy made from a keyframe is named by its publication and encoding */
            ss->lm_held_state = 1ull << 63 | ss->frame_seq << 2 | (uint64_t)enc;
        }
        h->flags = LC_FRAME_KEYFRAME;
        h->tile_count = 0;
    } else if (residual && n_tiles) {
        memcpy(stage, residual, payload_len);
        h->flags = LC_FRAME_DELTA | LC_FRAME_RESIDUAL;
        h->tile_count = n_tiles;
    } else { /* whole tiles (a residual subscriber's delta without tiles lands here too) */
        for (uint32_t k = 0; k < n_tiles; k++) {
            uint32_t x0, y0, x1, y1;
            lc_tile_rect(W, H, S, tiles[k], &x0, &y0, &x1, &y1);
            for (uint32_t y = y0; y < y1; y++, o += (size_t)(x1 - x0) * tb) {
                size_t i = (size_t)y * W + x0;
                memcpy(o, words + i * tb, (size_t)(x1 - x0) * tb);
                memcpy(ss->lm_sent + 3 * i, p->lightmap + 3 * i, (size_t)(x1 - x0) * 3 * sizeof(float));
            }
        }
        h->flags = LC_FRAME_DELTA;
        h->tile_count = n_tiles;
    }
    h->payload_length = (uint32_t)payload_len;
    n = lc_frame_write(h, key ? NULL : tiles, stage, ss->tx + LWS_PRE, LC_FRAME_HEADER_SIZE + table + payload_len);
done:
    free(own_tiles);
    return n;
}

/* Encodes the frame for `stream` from ss->frame into ss->tx (after LWS_PRE). Returns the
 * frame length, 0 on failure. */
static size_t session_encode(lc_server *s, lc_session *ss, int stream, int force_key) {
    const lc_published *p = ss->frame;
    lc_encoding enc = ss->stream[stream].enc;
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = (uint8_t)stream;
    h.encoding = (uint8_t)enc;
    h.flags = LC_FRAME_KEYFRAME;
    h.revision = p->revision;
    h.sequence = ss->stream[stream].sequence + 1;
    h.timestamp_us = p->timestamp_us;
    if (stream == LC_STREAM_LIGHTMAP) {
        h.width = p->lm_w;
        h.height = p->lm_h;
        h.depth = 1;
        h.tile_size = s->tile;
        return session_encode_lightmap(s, ss, &h, force_key);
    }
    size_t per = lc_frame_sh_value_bytes(enc), count, payload_len;
    if (stream == LC_STREAM_SHGRID) {
        h.width = p->grid_dims[0];
        h.height = p->grid_dims[1];
        h.depth = p->grid_dims[2];
        count = (size_t)h.width * h.height * h.depth;
        payload_len = count * 27 * per;
    } else {
        h.width = p->n_objects;
        h.height = h.depth = 1;
        count = p->n_objects;
        payload_len = count * (64 + 27 * per);
    }
    h.payload_length = (uint32_t)payload_len;
    if (session_tx_reserve(ss, LWS_PRE + 2 * (LC_FRAME_HEADER_SIZE + payload_len) + 64) != 0) return 0;
    /* The payload is staged after the frame area, then framed into place. */
    uint8_t *stage = ss->tx + LWS_PRE + LC_FRAME_HEADER_SIZE + payload_len + 32, *o = stage;
    const float *src = stream == LC_STREAM_SHGRID ? p->grid_sh : p->object_sh;
    for (size_t k = 0; k < count; k++) {
        if (stream == LC_STREAM_OBJECTS) {
            memset(o, 0, 64);
            memcpy(o, p->object_ids[k], strnlen(p->object_ids[k], 64));
            o += 64;
        }
        for (int j = 0; j < 27; j++, o += per) {
            float f = src[27 * k + j];
            if (per == 2) {
                uint16_t hv = lc_half_from_float(f);
                memcpy(o, &hv, 2);
            } else {
                memcpy(o, &f, 4);
            }
        }
    }
    return lc_frame_write(&h, NULL, stage, ss->tx + LWS_PRE, LC_FRAME_HEADER_SIZE + payload_len);
}

/* --- requests ------------------------------------------------------------------------------------ */

/* The failed-hello budget of the peer address (a token bucket of SERVER_AUTH_BURST, refilled
 * SERVER_AUTH_PER_S a second), kept for the SERVER_AUTH_PEERS most recent addresses. */
static server_auth_peer *server_auth_peer_for(lc_server *s, const char *peer) {
    double now = lc_clock_ms();
    server_auth_peer *oldest = &s->auth_peers[0];
    for (int i = 0; i < SERVER_AUTH_PEERS; i++) {
        server_auth_peer *a = &s->auth_peers[i];
        if (a->peer[0] && !strcmp(a->peer, peer)) {
            a->tokens = fmin(SERVER_AUTH_BURST, a->tokens + (now - a->last_ms) * 1e-3 * SERVER_AUTH_PER_S);
            a->last_ms = now;
            return a;
        }
        if (a->last_ms < oldest->last_ms) oldest = a;
    }
    snprintf(oldest->peer, sizeof oldest->peer, "%s", peer);
    oldest->tokens = SERVER_AUTH_BURST;
    oldest->last_ms = now;
    return oldest;
}

/* A session that joined after the last publication has no frame yet: give it the newest
 * result so subscribe/snapshot can send a keyframe on an idle server (PROTOCOL.md §4.1). */
static void session_take_latest(lc_server *s, lc_session *ss) {
    if (ss->frame) return;
    uint64_t seq = 0;
    ss->frame = lc_compute_take_newer(s->compute, &seq);
    ss->frame_seq = seq;
}

static void server_welcome(lc_server *s, lc_session *ss, const lc_proto_id *id) {
    lc_proto_welcome w;
    memset(&w, 0, sizeof w);
    w.server = "lucentd/" LUCENTD_VERSION;
    w.role = ss->controller ? "controller" : "viewer";
    w.revision = s->state.revision;
    w.lightmap_width = s->v->lightmap_width;
    w.lightmap_height = s->v->lightmap_height;
    w.tile = s->tile;
    memcpy(w.grid_origin, s->v->grid_origin, sizeof w.grid_origin);
    w.grid_cell = s->v->grid_cell;
    memcpy(w.grid_dims, s->v->grid_dims, sizeof w.grid_dims);
    w.bands = s->state.settings.bands;
    w.assets = s->asset_names;
    w.n_assets = s->v->n_assets;
    w.materials = s->material_names;
    w.n_materials = s->v->n_materials;
    w.limits = s->limits;
    w.max_lights = (uint32_t)s->cfg->max_lights;
    w.max_objects = (uint32_t)s->cfg->max_objects;
    w.rate = (uint32_t)s->cfg->rate;
    session_send(ss, lc_proto_build_welcome(id, &w));
}

static void server_change(lc_server *s, lc_session *ss, const lc_proto_request *req) {
    lc_state before;
    lc_proto_error e;
    char jerr[512];
    /* After a failed fsync the journal takes nothing until a snapshot succeeds: retry it
     * now (the tick retries once a second too); logged once by the journal, not per refusal. */
    if (lc_journal_broken(s->journal) && lc_journal_compact(s->journal, &s->state, jerr, sizeof jerr) != 0) {
        session_error(s, ss, &req->id, "internal", "",
                      "changes are refused: the journal's disk failed (the lucentd log says why); retry later");
        return;
    }
    if (lc_state_clone(&before, &s->state) != 0) {
        session_error(s, ss, &req->id, "internal", "", "out of memory");
        return;
    }
    if (lc_state_apply(&s->state, req->ops, req->n_ops, req->type == LC_REQ_BATCH, &e) != 0) {
        lc_state_release(&before);
        server_count_error(s, e.code);
        session_send(ss, lc_proto_build_error(&req->id, &e));
        return;
    }
    /* Relight while the journal fsyncs (~4 ms on a plain disk): the frames of this change
     * can only be sent after this function returns, i.e. after the change is durable. */
    uint64_t job = 0;
    if (lc_compute_submit(s->compute, &s->state, &job) != 0) lc_error("server", "out of memory submitting a relight");
    /* Durable before acknowledged: a failed append undoes the change and its relight. */
    if (lc_journal_append(s->journal, req->ops, req->n_ops, s->state.revision, jerr, sizeof jerr) != 0) {
        lc_error("server", "journal: %s; change refused", jerr);
        if (job) lc_compute_discard(s->compute, job);
        lc_state_release(&s->state);
        s->state = before;
        lc_compute_submit(s->compute, &s->state, NULL);
        session_error(s, ss, &req->id, "internal", "",
                      lc_journal_broken(s->journal)
                          ? "the change could not be stored, and the journal refuses changes until it recovers "
                            "(the lucentd log says why)"
                          : "the change could not be stored (journal write failed: disk full?); try again");
        return;
    }
    lc_state_release(&before);
    session_send(ss, lc_proto_build_ok(&req->id, s->state.revision));
    for (lc_session *o = s->sessions; o; o = o->next)
        if (o != ss && o->authed) session_send(o, lc_proto_build_changed(s->state.revision, ss->client, req->ops, req->n_ops));
    if (lc_journal_bytes(s->journal) > (uint64_t)s->cfg->compact_bytes &&
        lc_journal_compact(s->journal, &s->state, jerr, sizeof jerr) != 0)
        lc_error("server", "journal compaction failed: %s (will retry)", jerr);
}

static void server_request(lc_server *s, lc_session *ss, const char *text, size_t len) {
    s->messages_in++;
    lc_proto_request req;
    lc_proto_error e;
    if (lc_proto_parse_request(text, len, &s->limits, &req, &e) != 0) {
        server_count_error(s, e.code);
        session_send(ss, lc_proto_build_error(&req.id, &e));
        if (!ss->authed) session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "hello required");
        return;
    }
    if (!ss->authed) {
        if (req.type != LC_REQ_HELLO) {
            session_error(s, ss, &req.id, "hello_required", "/type", "the first message must be hello");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "hello required");
            goto done;
        }
        const lc_config *c = s->cfg;
        server_auth_peer *ap = c->controller_tokens[0] ? server_auth_peer_for(s, ss->peer) : NULL;
        if (ap && ap->tokens < 1) {
            /* Refused before the token is looked at, so guessing from this address is useless. */
            session_error(s, ss, &req.id, "rate_limited", "/token", "too many failed hellos from this address; wait and retry");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "rate limited");
            goto done;
        }
        if (!c->controller_tokens[0]) ss->controller = 1; /* no tokens configured: local, open server */
        else if (lc_config_token_in(c->controller_tokens, req.token)) ss->controller = 1;
        else if (lc_config_token_in(c->viewer_tokens, req.token)) ss->controller = 0;
        else {
            ap->tokens -= 1;
            s->auth_failures++;
            session_error(s, ss, &req.id, "unauthorized", "/token", "unknown token");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "unauthorized");
            lc_info("server", "refused client '%s' from %s: unknown token", req.client, ss->peer);
            goto done;
        }
        ss->authed = 1;
        snprintf(ss->client, sizeof ss->client, "%s", req.client);
        lc_info("server", "client '%s' connected as %s", ss->client, ss->controller ? "controller" : "viewer");
        server_welcome(s, ss, &req.id);
        goto done;
    }
    /* Token bucket: rate per second, burst 2x. */
    double now = lc_clock_ms();
    ss->tokens = fmin(2.0 * s->cfg->rate, ss->tokens + (now - ss->refill_ms) * 1e-3 * s->cfg->rate);
    ss->refill_ms = now;
    if (ss->tokens < 1) {
        session_error(s, ss, &req.id, "rate_limited", "", "too many requests; slow down");
        goto done;
    }
    ss->tokens -= 1;
    if (lc_proto_is_change(req.type) && !ss->controller) {
        session_error(s, ss, &req.id, "forbidden", "/type", "viewers cannot change the state");
        goto done;
    }
    switch (req.type) {
    case LC_REQ_HELLO:
        session_error(s, ss, &req.id, "invalid", "/type", "hello was already received");
        break;
    case LC_REQ_SUBSCRIBE: {
        if (req.stream == LC_STREAM_LIGHTMAP ? !lc_frame_texel_bytes(req.encoding)
                                             : !lc_frame_sh_value_bytes(req.encoding)) {
            session_error(s, ss, &req.id, "invalid", "/encoding", "this encoding is not available for the stream");
            break;
        }
        session_take_latest(s, ss);
        ss->stream[req.stream].on = 1;
        ss->stream[req.stream].force = 1;
        ss->stream[req.stream].enc = req.encoding;
        ss->stream[req.stream].max_rate = req.max_rate;
        ss->stream[req.stream].residual = req.residual;
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    }
    case LC_REQ_UNSUBSCRIBE:
        ss->stream[req.stream].on = 0;
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    case LC_REQ_SNAPSHOT:
        session_take_latest(s, ss);
        for (int k = 1; k < STREAMS; k++)
            if (ss->stream[k].on) ss->stream[k].force = 1;
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    case LC_REQ_STATE_GET: {
        lc_proto_state ps;
        lc_proto_material_state *mats = NULL;
        if (lc_state_to_proto(&s->state, &ps, &mats) == 0) session_send(ss, lc_proto_build_state(&req.id, &ps));
        free(mats);
        break;
    }
    case LC_REQ_PING: {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        session_send(ss, lc_proto_build_pong(&req.id, req.ping_t,
                                             (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u));
        break;
    }
    default:
        server_change(s, ss, &req);
        break;
    }
done:
    lc_proto_request_release(&req);
}

/* --- lws callbacks -------------------------------------------------------------------------------- */

static int session_wants_frame(const lc_session *ss) {
    if (!ss->frame) return 0;
    for (int k = 1; k < STREAMS; k++)
        if (ss->stream[k].on && (ss->stream[k].force || ss->stream[k].sent_pub_seq < ss->frame_seq)) return 1;
    return 0;
}

/* 1 when some stream has a frame to send now (its max_rate allows it). */
static int session_frame_due(const lc_session *ss, double now) {
    if (!ss->frame) return 0;
    for (int k = 1; k < STREAMS; k++) {
        if (!ss->stream[k].on || !(ss->stream[k].force || ss->stream[k].sent_pub_seq < ss->frame_seq)) continue;
        if (ss->stream[k].force || ss->stream[k].max_rate <= 0 ||
            now - ss->stream[k].last_ms >= 1000.0 / ss->stream[k].max_rate)
            return 1;
    }
    return 0;
}

/* Answers a WebSocket handshake with an HTTP error instead of a silent close, so a browser
 * or a script sees why (403 for a refused Origin). Returns 1: lws then drops the connection. */
static int server_refuse_http(struct lws *wsi, unsigned status, const char *body) {
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
static int server_origin_allowed(const lc_server *s, struct lws *wsi, char *why, size_t whylen) {
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
        if (o->authed) session_error(s, o, &none, "internal", "", msg);
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
            server_count_error(s, "origin_refused");
            return server_refuse_http(wsi, HTTP_STATUS_FORBIDDEN, "origin not allowed (see lucentd --help, --origins)\n");
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
    case LWS_CALLBACK_CLOSED: {
        if (!ss || !ss->wsi) return 0; /* refused before ESTABLISHED */
        for (lc_session **pp = &s->sessions; *pp; pp = &(*pp)->next)
            if (*pp == ss) {
                *pp = ss->next;
                break;
            }
        s->n_sessions--;
        if (ss->authed) lc_info("server", "client '%s' disconnected", ss->client);
        for (int i = 0; i < ss->outq_n; i++) free(ss->outq[(ss->outq_head + i) % SERVER_OUTQ]);
        lc_published_release(s->compute, ss->frame);
        free(ss->rx);
        free(ss->tx);
        free(ss->lm_sent);
        free(ss->lm_held);
        ss->wsi = NULL;
        return 0;
    }
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
        }
        if (!ss->rx_binary && !ss->rx_oversize) {
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
        if (ss->rx_binary) {
            session_error(s, ss, &none, "binary_not_allowed", "", "clients send text (JSON) messages only");
        } else if (ss->rx_oversize) {
            char msg[96];
            snprintf(msg, sizeof msg, "message over the size limit (%zu bytes%s)", ss->rx_limit,
                     ss->authed ? "" : " before hello");
            session_error(s, ss, &none, "too_large", "", msg);
            session_close(ss, LWS_CLOSE_STATUS_MESSAGE_TOO_LARGE, "too large");
        } else if (!lc_proto_utf8_valid(ss->rx, ss->rx_len)) {
            /* lws's own check would close with 1007 before saying why (PROTOCOL.md §5.2). */
            session_error(s, ss, &none, "bad_utf8", "", "the text message is not valid UTF-8");
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
            for (int k = 1; k < STREAMS; k++) {
                if (!ss->stream[k].on || !(ss->stream[k].force || ss->stream[k].sent_pub_seq < ss->frame_seq))
                    continue;
                double now = lc_clock_ms();
                if (!ss->stream[k].force && ss->stream[k].max_rate > 0 &&
                    now - ss->stream[k].last_ms < 1000.0 / ss->stream[k].max_rate)
                    continue; /* the tick re-arms writable */
                size_t n = session_encode(s, ss, k, ss->stream[k].force);
                if (n == 0) return -1;
                ss->stream[k].force = 0;
                ss->stream[k].sequence++;
                ss->stream[k].sent_pub_seq = ss->frame_seq;
                ss->stream[k].last_ms = now;
                if (lws_write(wsi, ss->tx + LWS_PRE, n, LWS_WRITE_BINARY) < (int)n) return -1;
                s->frames_sent++;
                s->bytes_sent += n;
                break;
            }
        }
        /* A stream held back by its max_rate is re-armed by the tick, not here (that would spin). */
        if (ss->outq_n > 0 || ss->closing || (ss->authed && session_frame_due(ss, lc_clock_ms())))
            session_want_write(ss);
        return 0;
    }
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED: {
        /* The compute thread published (or failed): hand every session the newest result. */
        if (!s) return 0;
        server_report_relight_failure(s);
        lc_published *p = lc_compute_take_newer(s->compute, &s->pub_seq);
        if (!p) return 0;
        for (lc_session *o = s->sessions; o; o = o->next) {
            lc_published_release(s->compute, o->frame); /* a newer frame replaces an unsent one */
            o->frame = lc_published_ref(s->compute, p);
            o->frame_seq = s->pub_seq;
            if (session_wants_frame(o)) session_want_write(o);
        }
        lc_published_release(s->compute, p);
        return 0;
    }
    default:
        return 0;
    }
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

/* /metrics: Prometheus text, base units (seconds, bytes), every metric with HELP. */
static int server_metrics(lc_server *s, char *body, size_t cap) {
    int n = 0;
    metric_u64(body, cap, &n, "lucent_clients", "gauge", "Connected WebSocket sessions.", s->n_sessions);
    metric_u64(body, cap, &n, "lucent_revision", "gauge", "Revision of the scene state.", s->state.revision);
    metric_u64(body, cap, &n, "lucent_frames_sent_total", "counter", "Binary frames sent to clients.",
               s->frames_sent);
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
               "Journal writes or fsyncs that failed (appends refused, or an everysec fsync).", lc_journal_failures(s->journal));
    metric_u64(body, cap, &n, "lucent_journal_broken", "gauge",
               "1 while changes are refused after a failed journal fsync (until a snapshot succeeds).",
               (uint64_t)lc_journal_broken(s->journal));
    metric_u64(body, cap, &n, "lucent_clients_dropped_total", "counter",
               "Clients dropped for not taking their output (slow or not reading).", s->dropped_slow);
    metric_u64(body, cap, &n, "lucent_auth_failures_total", "counter", "Hellos refused for an unknown token.",
               s->auth_failures);
    metric_u64(body, cap, &n, "lucent_config_reloads_total", "counter",
               "SIGHUP reloads whose configuration was applied (tests wait on it).", s->reloads);
    metric_u64(body, cap, &n, "lucent_accept_errors_total", "counter",
               "Failed accept() calls (e.g. out of file descriptors).", server_accept_errors);
    metric_head(body, cap, &n, "lucent_errors_total", "counter", "Error replies sent, by code.");
    for (int i = 0; i < 32 && s->error_codes[i][0]; i++)
        http_append(body, cap, &n, "lucent_errors_total{code=\"%s\"} %llu\n", s->error_codes[i],
                    (unsigned long long)s->errors[i]);
    return n;
}

/* /healthz: 200 "ok" while the service can take changes and relight them; 503 with the cause
 * when the journal refuses changes or the newest relight failed. */
static int server_health(lc_server *s, char *body, size_t cap, unsigned *status) {
    char why[256];
    uint64_t failed = lc_compute_failure(s->compute, NULL, why, sizeof why);
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

/* HTTP on the same port: /healthz, /metrics; everything else goes to the static mount. */
static int server_http_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_vhost *vh = lws_get_vhost(wsi);
    lc_server *s = vh ? lws_get_vhost_user(vh) : NULL;
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
    return lws_callback_http_dummy(wsi, reason, user, in, len);
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
            session_error(s, ss, &none, "hello_required", "", "no hello within the time limit");
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
    lws_sul_schedule(s->ctx, 0, &s->tick, server_tick, 250 * LWS_US_PER_MS);
}

static const struct lws_protocols server_protocols[] = {
    {"http", server_http_callback, 0, 0, 0, NULL, 0},
    {LC_PROTO_SUBPROTOCOL, server_ws_callback, sizeof(lc_session), 16384, 0, NULL, 0},
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

/* --- descriptors ------------------------------------------------------------------------------ */

/* What lucentd keeps for itself beyond the sockets: journal, snapshot writes, the bake, the
 * engine's and the log's files. */
#define SERVER_FD_RESERVE 32

/* Descriptors the sockets may use: the open-files limit (the soft limit is raised to the hard
 * one, as Redis does) minus what is open now and SERVER_FD_RESERVE. libwebsockets stops
 * accepting when its table is full, so this keeps accept() from failing with EMFILE, where it
 * would spin on the listening socket. 0 when unknown. */
static unsigned server_fd_budget(void) {
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
        lc_error("server", "cannot accept connections: %.*s (%llu times in the last interval; raise the "
                 "open-files limit or lower --max-clients)", (int)n, line,
                 (unsigned long long)(server_accept_errors - server_accept_logged_count));
        server_accept_logged_ms = now;
        server_accept_logged_count = server_accept_errors;
        return;
    }
    if (level & LLL_ERR) lc_error("lws", "%.*s", (int)n, line);
    else lc_warn("lws", "%.*s", (int)n, line);
}

/* SIGHUP: parse the configuration again and apply what can change while running. */
static void server_reload(lc_server *s) {
    static lc_config next;
    char err[512], restart[512];
    if (lc_config_load(&next, s->argc, s->argv, err, sizeof err) != 0) {
        lc_error("server", "SIGHUP: configuration not reloaded: %s", err);
        return;
    }
    lc_config_apply_reloadable(s->cfg, &next, restart, sizeof restart);
    s->reloads++;
    s->limits.max_message = (size_t)s->cfg->max_message;
    s->limits.max_depth = s->cfg->max_depth;
    s->limits.max_batch = (uint32_t)s->cfg->max_batch;
    s->max_clients = server_max_clients(s->cfg->max_clients, s->fd_budget);
    lc_log_set_level((lc_log_level)s->cfg->log_level);
    lc_info("server", "SIGHUP: configuration reloaded%s%s", restart[0] ? "; needs a restart to change: " : "",
            restart);
}

int lc_server_run(const lc_config *cfg_in, int argc, char **argv, const lc_lcb *bake, lc_server_ready_fn ready,
                  void *ready_arg) {
    lc_server s;
    memset(&s, 0, sizeof s);
    static lc_config cfg_live;
    cfg_live = *cfg_in;
    lc_config *cfg = &cfg_live;
    s.argc = argc;
    s.argv = argv;
    int rc = 1;
    char err[512];
    uint16_t probe = 1;
    if (*(uint8_t *)&probe != 1) {
        lc_error("server", "big-endian hosts are not supported (frames are written little-endian in place)");
        return 1;
    }
    s.cfg = cfg;
    s.bake = bake;
    s.v = lc_lcb_get(bake);
    s.tile = server_tile_size(s.cfg->tile, s.v->lightmap_width, s.v->lightmap_height);
    lc_proto_default_limits(&s.limits);
    s.limits.max_message = (size_t)cfg->max_message;
    s.limits.max_depth = cfg->max_depth;
    s.limits.max_batch = (uint32_t)cfg->max_batch;
    lc_state_limits sl = {(uint32_t)cfg->max_lights, (uint32_t)cfg->max_objects};
    if (lc_state_init(&s.state, bake, &sl) != 0) return 1;
    s.state.settings.bounces = (uint32_t)cfg->bounces; /* a restored snapshot's settings replace this */
    /* A fresh state dir starts with the bake's own lights (KHR_lights_punctual: the scene's
     * initial lights); from then on the snapshot holds what clients made of them. */
    const int fresh = server_state_dir_fresh(cfg->state_dir);
    if (fresh && lc_state_seed(&s.state, err, sizeof err) != 0) {
        lc_error("server", "%s", err);
        goto done;
    }
    /* --recover: the snapshot plus the journal's valid prefix; the journal reports what it drops. */
    s.journal = cfg->recover
                    ? lc_journal_recover(cfg->state_dir, (lc_fsync_mode)cfg->fsync_mode, &s.state, NULL, err, sizeof err)
                    : lc_journal_open(cfg->state_dir, (lc_fsync_mode)cfg->fsync_mode, &s.state, err, sizeof err);
    if (!s.journal) {
        lc_error("server", "%s", err);
        goto done;
    }
    lc_info("server", "state %s %s: revision %llu, %u lights, %u objects", fresh ? "created in" : "restored from",
            cfg->state_dir, (unsigned long long)s.state.revision, s.state.n_lights, s.state.n_objects);
    if (fresh && s.state.n_lights && lc_journal_compact(s.journal, &s.state, err, sizeof err) != 0) {
        lc_error("server", "writing the initial snapshot: %s", err);
        goto done;
    }
    s.asset_names = calloc(s.v->n_assets + 1, sizeof *s.asset_names);
    s.material_names = calloc(s.v->n_materials + 1, sizeof *s.material_names);
    if (!s.asset_names || !s.material_names) goto done;
    for (uint32_t i = 0; i < s.v->n_assets; i++) s.asset_names[i] = s.v->assets[i].name;
    for (uint32_t i = 0; i < s.v->n_materials; i++) s.material_names[i] = s.v->materials[i].name;

    lws_set_log_level(LLL_ERR | LLL_WARN, server_lws_log);
    s.fd_budget = server_fd_budget();
    s.max_clients = server_max_clients(cfg->max_clients, s.fd_budget);
    if (s.max_clients < (uint32_t)cfg->max_clients)
        lc_warn("server", "--max-clients %d lowered to %u: the open-files limit leaves %u descriptors (ulimit -n)",
                cfg->max_clients, s.max_clients, s.fd_budget);
    struct lws_http_mount mount;
    memset(&mount, 0, sizeof mount);
    mount.mountpoint = "/";
    mount.mountpoint_len = 1;
    mount.origin = cfg->www;
    mount.def = "index.html";
    mount.origin_protocol = LWSMPRO_FILE;
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = cfg->port;
    info.iface = cfg->listen;
    info.protocols = server_protocols;
    info.mounts = cfg->www[0] ? &mount : NULL;
    info.user = &s;
    /* UTF-8 is checked per message (the receive path), so the client hears `bad_utf8` before
     * the 1007 close instead of lws closing silently. */
    info.options = LWS_SERVER_OPTION_HTTP_HEADERS_SECURITY_BEST_PRACTICES_ENFORCE;
    info.pt_serv_buf_size = 65536;
    info.fd_limit_per_thread = s.fd_budget;
    if (cfg->tls_cert[0]) {
        info.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
        info.ssl_cert_filepath = cfg->tls_cert;
        info.ssl_private_key_filepath = cfg->tls_key;
        /* Browsers may pick HTTP/2 and run WebSockets over it, where one large frame write
         * breaks the stream: keep the port on HTTP/1.1. */
        info.alpn = "http/1.1";
    }
    s.ctx = lws_create_context(&info);
    if (!s.ctx) {
        lc_error("server", "cannot listen on %s:%d (port in use? see --listen/--port)", cfg->listen, cfg->port);
        goto done;
    }
    struct lws_vhost *vh = lws_get_vhost_by_name(s.ctx, "default");
    s.port = vh ? lws_get_vhost_listen_port(vh) : cfg->port;
    s.compute = lc_compute_start(bake, cfg->backend, cfg->threads, cfg->refine_passes, cfg->refine_delay,
                                  s.ctx, err, sizeof err);
    if (!s.compute) {
        lc_error("server", "%s", err);
        goto done;
    }
    lc_compute_submit(s.compute, &s.state, NULL); /* the first frame: the restored state */
    signal(SIGINT, server_on_signal);
    signal(SIGTERM, server_on_signal);
    signal(SIGHUP, server_on_signal);
    signal(SIGPIPE, SIG_IGN);
    lc_info("server", "lucentd %s listening on %s://%s:%d (subprotocol %s, backend %s)", LUCENTD_VERSION,
            cfg->tls_cert[0] ? "wss" : "ws", cfg->listen, s.port, LC_PROTO_SUBPROTOCOL, lc_compute_backend(s.compute));
    if (ready) ready(ready_arg, s.port);
    lws_sul_schedule(s.ctx, 0, &s.tick, server_tick, 250 * LWS_US_PER_MS);
    while (!server_stop_flag) {
        if (lws_service(s.ctx, 0) < 0) break;
        if (server_accept_failed) { /* out of descriptors: let the clients' sockets drain */
            server_accept_failed = 0;
            struct timespec pause = {0, 50 * 1000 * 1000};
            nanosleep(&pause, NULL);
        }
        if (server_reload_flag) {
            server_reload_flag = 0;
            server_reload(&s);
        }
    }
    lc_info("server", "shutting down: closing %u clients", s.n_sessions);
    for (lc_session *ss = s.sessions; ss; ss = ss->next) session_close(ss, LWS_CLOSE_STATUS_GOINGAWAY, "server stopping");
    for (int i = 0; i < 20 && s.n_sessions; i++) lws_service(s.ctx, 0);
    rc = 0;
done:
    /* The compute thread first: a relight in flight ends with lws_cancel_service(), which must
     * not touch a destroyed context. Sessions then release their frames as the context closes
     * them, and only then is the compute object freed. */
    lc_compute_stop(s.compute);
    if (s.ctx) {
        lws_sul_cancel(&s.tick);
        lws_context_destroy(s.ctx);
    }
    lc_compute_release(s.compute);
    if (s.journal && rc == 0) {
        if (lc_journal_compact(s.journal, &s.state, err, sizeof err) != 0) lc_error("server", "final snapshot: %s", err);
    }
    lc_journal_close(s.journal);
    lc_state_release(&s.state);
    for (int e = 0; e < 4; e++) {
        free(s.lm_encoded[e].words);
        free(s.lm_residual[e].tiles);
        free(s.lm_residual[e].moved);
        free(s.lm_residual[e].payload);
    }
    free(s.asset_names);
    free(s.material_names);
    return rc;
}
