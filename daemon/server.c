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
#include <time.h>

#include "compute.h"
#include "journal.h"
#include "state.h"
#include "util/clock.h"
#include "util/half.h"
#include "util/log.h"

#define SERVER_OUTQ 1024 /* queued text messages per session (replies to a full request burst fit); past this the client is too slow */

enum { STREAMS = 4 }; /* index = lc_stream (1..3) */

typedef struct lc_session {
    struct lws *wsi;
    struct lc_session *next;
    int authed, controller;
    char client[LC_PROTO_NAME_MAX + 1];
    char *rx;
    size_t rx_len;
    int rx_binary, rx_oversize;
    char *outq[SERVER_OUTQ];
    int outq_head, outq_n;
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
    double behind_since_ms; /* since when a frame has waited for this client (0 = none) */
    uint8_t *tx;
    size_t tx_cap;
} lc_session;

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

typedef struct lc_server {
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
    /* metrics */
    uint64_t frames_sent, bytes_sent, messages_in, errors[32];
    char error_codes[32][32];
} lc_server;

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

/* Queues text (takes ownership). A client whose queue is full is too slow: dropped (1008). */
static void session_send(lc_session *ss, char *text) {
    if (!text) return;
    if (ss->outq_n >= SERVER_OUTQ) {
        free(text);
        if (!ss->closing) {
            lc_warn("server", "client '%s' fell %d messages behind; closing (1008)", ss->client, SERVER_OUTQ);
            ss->closing = 1;
            ss->close_code = LWS_CLOSE_STATUS_POLICY_VIOLATION;
            snprintf(ss->close_reason, sizeof ss->close_reason, "too slow");
        }
    } else {
        ss->outq[(ss->outq_head + ss->outq_n++) % SERVER_OUTQ] = text;
    }
    lws_callback_on_writable(ss->wsi);
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
    ss->closing = 1;
    ss->close_code = code;
    snprintf(ss->close_reason, sizeof ss->close_reason, "%s", reason);
    lws_callback_on_writable(ss->wsi);
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
        if (!c->controller_tokens[0]) ss->controller = 1; /* no tokens configured: local, open server */
        else if (lc_config_has_token(c->controller_tokens, req.token)) ss->controller = 1;
        else if (lc_config_has_token(c->viewer_tokens, req.token)) ss->controller = 0;
        else {
            session_error(s, ss, &req.id, "unauthorized", "/token", "unknown token");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "unauthorized");
            lc_info("server", "refused client '%s': unknown token", req.client);
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

static int server_ws_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_vhost *vh = lws_get_vhost(wsi);
    lc_server *s = vh ? lws_get_vhost_user(vh) : NULL;
    lc_session *ss = user;
    switch (reason) {
    case LWS_CALLBACK_FILTER_PROTOCOL_CONNECTION: {
        if (s && s->n_sessions >= (uint32_t)s->cfg->max_clients) {
            lc_warn("server", "refusing a connection: %u clients is the limit", s->n_sessions);
            return 1;
        }
        char origin[256];
        if (s && s->cfg->origins[0] && lws_hdr_copy(wsi, origin, sizeof origin, WSI_TOKEN_ORIGIN) > 0 &&
            !lc_config_has_token(s->cfg->origins, origin)) {
            lc_warn("server", "refusing Origin '%s' (not in --origins)", origin);
            return 1;
        }
        return 0;
    }
    case LWS_CALLBACK_ESTABLISHED:
        memset(ss, 0, sizeof *ss);
        ss->wsi = wsi;
        ss->connected_ms = ss->refill_ms = lc_clock_ms();
        ss->tokens = 2.0 * s->cfg->rate;
        snprintf(ss->client, sizeof ss->client, "(before hello)");
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
        if (lws_is_first_fragment(wsi)) {
            ss->rx_len = 0;
            ss->rx_oversize = 0;
            ss->rx_binary = lws_frame_is_binary(wsi);
        }
        if (!ss->rx_binary && !ss->rx_oversize) {
            if (ss->rx_len + len > (size_t)s->cfg->max_message) {
                ss->rx_oversize = 1;
            } else {
                if (!ss->rx) ss->rx = malloc((size_t)s->cfg->max_message + 1);
                if (!ss->rx) return -1;
                if (len) memcpy(ss->rx + ss->rx_len, in, len);
                ss->rx_len += len;
            }
        }
        if (!lws_is_final_fragment(wsi)) return 0;
        lc_proto_id none = {0};
        if (ss->rx_binary) {
            session_error(s, ss, &none, "binary_not_allowed", "", "clients send text (JSON) messages only");
        } else if (ss->rx_oversize) {
            session_error(s, ss, &none, "too_large", "", "message over the size limit");
            session_close(ss, LWS_CLOSE_STATUS_MESSAGE_TOO_LARGE, "too large");
        } else {
            server_request(s, ss, ss->rx, ss->rx_len);
        }
        return 0;
    }
    case LWS_CALLBACK_SERVER_WRITEABLE: {
        if (ss->outq_n > 0) {
            char *text = ss->outq[ss->outq_head];
            size_t n = strlen(text);
            if (ss->tx_cap < LWS_PRE + n) {
                uint8_t *nb = realloc(ss->tx, LWS_PRE + n + 1);
                if (!nb) return -1;
                ss->tx = nb;
                ss->tx_cap = LWS_PRE + n + 1;
            }
            memcpy(ss->tx + LWS_PRE, text, n);
            free(text);
            ss->outq_head = (ss->outq_head + 1) % SERVER_OUTQ;
            ss->outq_n--;
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
        if (ss->authed && !session_wants_frame(ss)) ss->behind_since_ms = 0; /* caught up */
        if (ss->outq_n > 0 || ss->closing || (ss->authed && session_wants_frame(ss))) lws_callback_on_writable(wsi);
        return 0;
    }
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED: {
        /* The compute thread published: hand every session the newest result. */
        if (!s) return 0;
        lc_published *p = lc_compute_take_newer(s->compute, &s->pub_seq);
        if (!p) return 0;
        for (lc_session *o = s->sessions; o; o = o->next) {
            lc_published_release(s->compute, o->frame); /* a newer frame replaces an unsent one */
            o->frame = lc_published_ref(s->compute, p);
            o->frame_seq = s->pub_seq;
            if (session_wants_frame(o)) {
                if (o->behind_since_ms == 0) o->behind_since_ms = lc_clock_ms();
                lws_callback_on_writable(o->wsi);
            }
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
    if (reason == LWS_CALLBACK_HTTP && s) {
        const char *uri = in;
        char body[8192];
        int n = -1;
        if (!strcmp(uri, "/healthz")) {
            n = snprintf(body, sizeof body, "ok revision %llu\n", (unsigned long long)s->state.revision);
        } else if (!strcmp(uri, "/metrics")) {
            n = 0;
            http_append(body, sizeof body, &n,
                        "# TYPE lucent_clients gauge\nlucent_clients %u\n"
                        "# TYPE lucent_revision gauge\nlucent_revision %llu\n"
                        "# TYPE lucent_frames_sent_total counter\nlucent_frames_sent_total %llu\n"
                        "# TYPE lucent_bytes_sent_total counter\nlucent_bytes_sent_total %llu\n"
                        "# TYPE lucent_messages_received_total counter\nlucent_messages_received_total %llu\n"
                        "# TYPE lucent_relights_total counter\nlucent_relights_total %llu\n",
                        s->n_sessions, (unsigned long long)s->state.revision, (unsigned long long)s->frames_sent,
                        (unsigned long long)s->bytes_sent, (unsigned long long)s->messages_in,
                        (unsigned long long)lc_compute_count(s->compute));
            uint64_t hist[LC_COMPUTE_BUCKETS];
            double sum_ms;
            lc_compute_histogram(s->compute, hist, &sum_ms);
            http_append(body, sizeof body, &n, "# TYPE lucent_relight_ms histogram\n");
            for (int b = 0; b < LC_COMPUTE_BUCKETS - 1; b++)
                http_append(body, sizeof body, &n, "lucent_relight_ms_bucket{le=\"%g\"} %llu\n", lc_compute_bucket_ms[b],
                            (unsigned long long)hist[b]);
            http_append(body, sizeof body, &n,
                        "lucent_relight_ms_bucket{le=\"+Inf\"} %llu\nlucent_relight_ms_sum %.3f\n"
                        "lucent_relight_ms_count %llu\n# TYPE lucent_errors_total counter\n",
                        (unsigned long long)hist[LC_COMPUTE_BUCKETS - 1], sum_ms,
                        (unsigned long long)hist[LC_COMPUTE_BUCKETS - 1]);
            for (int i = 0; i < 32 && s->error_codes[i][0]; i++)
                http_append(body, sizeof body, &n, "lucent_errors_total{code=\"%s\"} %llu\n", s->error_codes[i],
                            (unsigned long long)s->errors[i]);
        }
        if (n >= 0) {
            unsigned char buf[LWS_PRE + 8192 + 512], *start = buf + LWS_PRE, *p = start, *end = buf + sizeof buf;
            if (lws_add_http_common_headers(wsi, HTTP_STATUS_OK, "text/plain; version=0.0.4", (lws_filepos_t)n, &p,
                                            end) ||
                lws_finalize_write_http_header(wsi, start, &p, end))
                return 1;
            memcpy(p, body, (size_t)n);
            if (lws_write(wsi, p, (size_t)n, LWS_WRITE_HTTP_FINAL) != n) return 1;
            return lws_http_transaction_completed(wsi) ? -1 : 0;
        }
    }
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}

/* Once a second: hello timeouts, everysec fsync, rate-limited streams. */
static void server_tick(lws_sorted_usec_list_t *sul) {
    lc_server *s = lws_container_of(sul, lc_server, tick);
    double now = lc_clock_ms();
    for (lc_session *ss = s->sessions; ss; ss = ss->next) {
        if (!ss->authed && !ss->closing && now - ss->connected_ms > s->cfg->hello_timeout * 1000.0) {
            lc_proto_id none = {0};
            session_error(s, ss, &none, "hello_required", "", "no hello within the time limit");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "hello timeout");
        }
        if (ss->authed && session_wants_frame(ss)) {
            /* A client that cannot take frames (its socket is full) must not hold the others
             * back or grow memory: past the limit it is dropped, without a close handshake
             * it could not read anyway. */
            if (ss->behind_since_ms > 0 && now - ss->behind_since_ms > s->cfg->slow_timeout * 1000.0) {
                lc_warn("server", "client '%s' left frames unread for %d s; dropping it (1008)", ss->client,
                        s->cfg->slow_timeout);
                lws_close_reason(ss->wsi, LWS_CLOSE_STATUS_POLICY_VIOLATION, (unsigned char *)"too slow", 8);
                lws_set_timeout(ss->wsi, PENDING_TIMEOUT_USER_OK, LWS_TO_KILL_ASYNC);
                ss->behind_since_ms = 0;
                continue;
            }
            lws_callback_on_writable(ss->wsi);
        }
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

/* SIGHUP: parse the configuration again and apply what can change while running. */
static void server_reload(lc_server *s) {
    static lc_config next;
    char err[512], restart[512];
    if (lc_config_load(&next, s->argc, s->argv, err, sizeof err) != 0) {
        lc_error("server", "SIGHUP: configuration not reloaded: %s", err);
        return;
    }
    lc_config_apply_reloadable(s->cfg, &next, restart, sizeof restart);
    s->limits.max_message = (size_t)s->cfg->max_message;
    s->limits.max_depth = s->cfg->max_depth;
    s->limits.max_batch = (uint32_t)s->cfg->max_batch;
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
    /* --recover: the snapshot plus the journal's valid prefix; the journal reports what it drops. */
    s.journal = cfg->recover
                    ? lc_journal_recover(cfg->state_dir, (lc_fsync_mode)cfg->fsync_mode, &s.state, NULL, err, sizeof err)
                    : lc_journal_open(cfg->state_dir, (lc_fsync_mode)cfg->fsync_mode, &s.state, err, sizeof err);
    if (!s.journal) {
        lc_error("server", "%s", err);
        goto done;
    }
    lc_info("server", "state restored from %s: revision %llu, %u lights, %u objects", cfg->state_dir,
            (unsigned long long)s.state.revision, s.state.n_lights, s.state.n_objects);
    s.asset_names = calloc(s.v->n_assets + 1, sizeof *s.asset_names);
    s.material_names = calloc(s.v->n_materials + 1, sizeof *s.material_names);
    if (!s.asset_names || !s.material_names) goto done;
    for (uint32_t i = 0; i < s.v->n_assets; i++) s.asset_names[i] = s.v->assets[i].name;
    for (uint32_t i = 0; i < s.v->n_materials; i++) s.material_names[i] = s.v->materials[i].name;

    lws_set_log_level(LLL_ERR | LLL_WARN, NULL);
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
    info.options = LWS_SERVER_OPTION_VALIDATE_UTF8 | LWS_SERVER_OPTION_HTTP_HEADERS_SECURITY_BEST_PRACTICES_ENFORCE;
    info.pt_serv_buf_size = 65536;
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
    if (s.ctx) {
        lws_sul_cancel(&s.tick);
        lws_context_destroy(s.ctx); /* closes remaining sessions: they release their frames */
    }
    lc_compute_stop(s.compute);
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
