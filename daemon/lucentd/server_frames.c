/* server_frames: lucent/1 binary frames for one client (see server_frames.h). Runs on the
 * service thread; nothing here touches sockets, so the encoding is tested on fake
 * publications (tests/unit/daemon/test_frames.c). */
#include "server_frames.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/half.h"

/* A publication's lightmap in one encoding (see lc_frames.lm_encoded). */
typedef struct lc_encoded_lightmap {
    int valid;
    uint64_t pub_seq; /* the publication it encodes */
    uint8_t *words;   /* W*H texels as on the wire */
    size_t cap;
    int crc_valid; /* crc: lc_frame_body_crc of a keyframe of words, once one was sent */
    uint32_t crc;
} lc_encoded_lightmap;

/* One lightmap delta: what takes a client copy in state `from_state` to publication
 * `pub_seq` (whole tiles, or residuals). Two clients in the same state hold identical copies
 * (the same keyframe, then the same deltas), so they share it: its tiles, payload and CRC are
 * computed once per publication, not once per client. State 0 names no shared copy. */
typedef struct lc_delta_memo {
    int valid, keyframe; /* keyframe: not smaller than one; send that instead */
    uint64_t from_state, pub_seq, to_state;
    uint32_t tile; /* the tile side and threshold it was computed with */
    float thr;
    uint32_t *tiles, n_tiles;
    uint32_t *moved, n_moved; /* residuals: the texels (y*W+x) that get their new value */
    uint8_t *payload;
    size_t payload_len, payload_cap;
    uint32_t body_crc; /* lc_frame_body_crc of tiles + payload */
} lc_delta_memo;

struct lc_frames {
    /* The lightmap of one publication encoded once per encoding, shared by every client's
     * keyframes, tiles and residuals (100 clients: one encode per frame, not 100). */
    lc_encoded_lightmap lm_encoded[4]; /* index: lc_encoding */
    lc_delta_memo lm_residual[4];      /* the last residual delta computed per encoding */
    lc_delta_memo lm_tiles[4];         /* the last whole-tile delta computed per encoding */
    uint64_t delta_states;             /* ids handed to copies made by deltas (< 2^62) */
    int peak_valid;                    /* peak: the brightest channel of publication peak_pub_seq */
    uint64_t peak_pub_seq;
    float peak;
};

lc_frames *lc_frames_create(void) { return calloc(1, sizeof(lc_frames)); }

void lc_frames_release(lc_frames *f) {
    if (!f) return;
    for (int e = 0; e < 4; e++) {
        free(f->lm_encoded[e].words);
        lc_delta_memo *memos[2] = {&f->lm_residual[e], &f->lm_tiles[e]};
        for (int k = 0; k < 2; k++) {
            free(memos[k]->tiles);
            free(memos[k]->moved);
            free(memos[k]->payload);
        }
    }
    free(f);
}

void lc_frames_copy_release(lc_frames_copy *cp) {
    free(cp->lm_sent);
    free(cp->lm_held);
    free(cp->out);
    memset(cp, 0, sizeof *cp);
}

/* Grows a reused buffer (a copy's frame buffer, a memo's payload) to at least need bytes. */
static int frames_grow(uint8_t **buf, size_t *cap, size_t need) {
    if (need <= *cap) return 0;
    uint8_t *nb = realloc(*buf, need);
    if (!nb) return -1;
    *buf = nb;
    *cap = need;
    return 0;
}

static int frames_out_reserve(lc_frames_copy *cp, size_t need) { return frames_grow(&cp->out, &cp->out_cap, need); }

static void frames_encode_texel(lc_encoding enc, const float *t, uint8_t *o) {
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

/* The delta tile side: the configured one, or (0 = auto) the largest of 32, 16, 8 that still
 * cuts the lightmap into at least 64 tiles, so small lightmaps get deltas worth sending. */
uint32_t lc_frames_tile_size(int configured, uint32_t w, uint32_t h) {
    if (configured > 0) return (uint32_t)configured;
    uint32_t t = 32;
    while (t > 8 && lc_tiles_count(w, h, t) < 64) t /= 2;
    return t;
}

/* fmaxf's result (a NaN argument loses to a number) without libm's call: the per-texel tests
 * below run a few million times per frame with 10 clients, and gcc only inlines fmaxf under
 * -ffinite-math-only. */
static inline float frames_maxf(float a, float b) { return (a > b || b != b) ? a : b; }

/* 1 when texel i of `now` moved by more than thr (relative to the texel's brightest channel,
 * at least floor_v) from `sent`: a dim channel (the blue of a warm light) must not make a
 * texel dirty for changes nobody can see. */
static int frames_texel_moved(const float *now, const float *sent, size_t i, float thr, float floor_v) {
    const float *a = now + 3 * i, *b = sent + 3 * i;
    float ref = frames_maxf(frames_maxf(frames_maxf(a[0], a[1]), frames_maxf(a[2], b[0])),
                            frames_maxf(frames_maxf(b[1], b[2]), floor_v));
    for (int c = 0; c < 3; c++)
        if (fabsf(a[c] - b[c]) > thr * ref) return 1;
    return 0;
}

/* The lightmap of j->frame in `enc` (W*H texels as on the wire), encoded on first use per
 * publication and kept until the next one. NULL when out of memory. */
static const uint8_t *frames_lightmap_words(lc_frames *f, const lc_frames_job *j, lc_encoding enc) {
    const lc_published *p = j->frame;
    const size_t texels = (size_t)p->lm_w * p->lm_h, tb = lc_frame_texel_bytes(enc);
    lc_encoded_lightmap *e = &f->lm_encoded[enc];
    if (e->valid && e->pub_seq == j->pub_seq) return e->words;
    if (texels * tb > e->cap) {
        uint8_t *n = realloc(e->words, texels * tb);
        if (!n) return NULL;
        e->words = n;
        e->cap = texels * tb;
    }
    for (size_t i = 0; i < texels; i++) frames_encode_texel(enc, p->lightmap + 3 * i, e->words + i * tb);
    e->valid = 1;
    e->crc_valid = 0;
    e->pub_seq = j->pub_seq;
    return e->words;
}

/* The brightest channel of j->frame's lightmap (0 for none brighter), computed once per
 * publication and shared by every client's delta. */
static float frames_lightmap_peak(lc_frames *f, const lc_frames_job *j) {
    if (f->peak_valid && f->peak_pub_seq == j->pub_seq) return f->peak;
    const lc_published *p = j->frame;
    const size_t n = (size_t)p->lm_w * p->lm_h * 3;
    float peak = 0;
    for (size_t i = 0; i < n; i++) peak = frames_maxf(peak, p->lightmap[i]);
    f->peak = peak;
    f->peak_pub_seq = j->pub_seq;
    f->peak_valid = 1;
    return peak;
}

/* The tiles where some texel of j->frame moved by more than thr from cp->lm_sent, into tiles
 * (capacity: every tile); returns their count and the texels they cover in *texels_out. */
static uint32_t frames_dirty_tiles(const lc_frames_copy *cp, const lc_frames_job *j, uint32_t S, float thr,
                                   float floor_v, uint32_t *tiles, size_t *texels_out) {
    const lc_published *p = j->frame;
    const uint32_t W = p->lm_w, H = p->lm_h, T = lc_tiles_count(W, H, S);
    uint32_t n = 0;
    *texels_out = 0;
    for (uint32_t t = 0; t < T; t++) {
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(W, H, S, t, &x0, &y0, &x1, &y1);
        int dirty = 0;
        for (uint32_t y = y0; y < y1 && !dirty; y++)
            for (uint32_t x = x0; x < x1 && !dirty; x++)
                dirty = frames_texel_moved(p->lightmap, cp->lm_sent, (size_t)y * W + x, thr, floor_v);
        if (dirty) {
            tiles[n++] = t;
            *texels_out += (size_t)(x1 - x0) * (y1 - y0);
        }
    }
    return n;
}

/* The CRC of the frame body (tile table + payload) m's frames carry. */
static uint32_t frames_body_crc(const lc_delta_memo *m) {
    lc_frame_header h = {.tile_count = m->n_tiles, .payload_length = (uint32_t)m->payload_len};
    return lc_frame_body_crc(&h, m->tiles, m->payload);
}

/* Invalidates m and fills its tile list with the tiles dirty against cp->lm_sent (and the texels
 * they cover in *texels_out). */
static int frames_memo_tiles(lc_delta_memo *m, const lc_frames_copy *cp, const lc_frames_job *j, uint32_t S, float thr,
                             float floor_v, size_t *texels_out) {
    m->valid = 0;
    uint32_t *tiles = realloc(m->tiles, (size_t)lc_tiles_count(j->frame->lm_w, j->frame->lm_h, S) * sizeof *tiles);
    if (!tiles) return -1;
    m->tiles = tiles;
    m->n_tiles = frames_dirty_tiles(cp, j, S, thr, floor_v, m->tiles, texels_out);
    return 0;
}

/* Computes into m the whole-tile delta that takes a client whose copy was encoded from
 * cp->lm_sent to j->frame: the dirty tiles and their texels from `words`. m->keyframe when it
 * would not be smaller than a keyframe. The caller sets m's key fields. */
static int frames_tiles_compute(lc_delta_memo *m, const lc_frames_copy *cp, const lc_frames_job *j,
                                const uint8_t *words, size_t tb, uint32_t S, float thr, float floor_v) {
    const lc_published *p = j->frame;
    const uint32_t W = p->lm_w, H = p->lm_h;
    size_t delta_texels;
    if (frames_memo_tiles(m, cp, j, S, thr, floor_v, &delta_texels) != 0) return -1;
    m->payload_len = delta_texels * tb;
    m->keyframe = m->payload_len + 4 * (size_t)m->n_tiles >= (size_t)W * H * tb; /* no smaller than a keyframe */
    if (!m->keyframe) {
        if (frames_grow(&m->payload, &m->payload_cap, m->payload_len) != 0) return -1;
        uint8_t *o = m->payload;
        for (uint32_t k = 0; k < m->n_tiles; k++) {
            uint32_t x0, y0, x1, y1;
            lc_tile_rect(W, H, S, m->tiles[k], &x0, &y0, &x1, &y1);
            for (uint32_t y = y0; y < y1; y++, o += (size_t)(x1 - x0) * tb)
                memcpy(o, words + ((size_t)y * W + x0) * tb, (size_t)(x1 - x0) * tb);
        }
        m->body_crc = frames_body_crc(m);
    }
    m->valid = 1;
    return 0;
}

/* Commits a whole-tile delta to the session: the client's copy now holds j->frame's texels in
 * m's tiles. */
static void frames_commit_tiles(lc_frames_copy *cp, const lc_delta_memo *m, const lc_frames_job *j, uint32_t S) {
    const lc_published *p = j->frame;
    for (uint32_t k = 0; k < m->n_tiles; k++) {
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(p->lm_w, p->lm_h, S, m->tiles[k], &x0, &y0, &x1, &y1);
        for (uint32_t y = y0; y < y1; y++) {
            size_t i = (size_t)y * p->lm_w + x0;
            memcpy(cp->lm_sent + 3 * i, p->lightmap + 3 * i, (size_t)(x1 - x0) * 3 * sizeof(float));
        }
    }
    cp->lm_sent_state = m->to_state;
}

/* Computes into m the residual delta (PROTOCOL.md §6.2.1) that takes a client holding
 * cp->lm_held to j->frame: the dirty tiles; in them, texels that moved get their new value
 * (`words`), the others keep the client's (residual 0); zlib-compressed. m->keyframe when it
 * would not be smaller than a keyframe. The caller sets m's key fields. */
static int frames_residual_compute(lc_delta_memo *m, const lc_frames_copy *cp, const lc_frames_job *j, lc_encoding enc,
                                   const uint8_t *words, uint32_t S, float thr, float floor_v) {
    const lc_published *p = j->frame;
    const uint32_t W = p->lm_w, H = p->lm_h;
    const size_t texels = (size_t)W * H, tb = lc_frame_texel_bytes(enc);
    size_t delta_texels;
    if (frames_memo_tiles(m, cp, j, S, thr, floor_v, &delta_texels) != 0) return -1;
    const size_t raw_len = delta_texels * tb, table = 4 * (size_t)m->n_tiles;
    uint8_t *raw = malloc(raw_len ? raw_len : 1);
    uint32_t *moved = realloc(m->moved, (delta_texels ? delta_texels : 1) * sizeof *moved);
    if (moved) m->moved = moved;
    if (!raw || !moved || frames_grow(&m->payload, &m->payload_cap, lc_residual_deflate_bound(raw_len)) != 0) {
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
                if (frames_texel_moved(p->lightmap, cp->lm_sent, i, thr, floor_v)) {
                    lc_residual_make(enc, words + i * tb, cp->lm_held + i * tb, 1, raw + k * tb);
                    moved[m->n_moved++] = (uint32_t)i;
                } else {
                    memset(raw + k * tb, 0, tb);
                }
            }
    }
    m->payload_len = m->n_tiles ? lc_residual_deflate(raw, raw_len, m->payload, m->payload_cap) : 0;
    free(raw);
    m->keyframe = m->n_tiles && (m->payload_len == 0 || table + m->payload_len >= texels * tb);
    m->body_crc = frames_body_crc(m);
    m->valid = 1;
    return 0;
}

/* Commits a residual delta to the session: the client will hold the moved texels' new values. */
static void frames_commit_residual(lc_frames_copy *cp, const lc_delta_memo *m, const lc_frames_job *j,
                                   const uint8_t *words, size_t tb) {
    const float *lightmap = j->frame->lightmap;
    for (uint32_t k = 0; k < m->n_moved; k++) {
        size_t i = m->moved[k];
        memcpy(cp->lm_held + i * tb, words + i * tb, tb);
        memcpy(cp->lm_sent + 3 * i, lightmap + 3 * i, 3 * sizeof(float));
    }
    cp->lm_held_state = m->to_state;
    cp->lm_sent_state = 0; /* lm_sent as residuals left it: no whole-tile delta is shared from it */
}

/* A keyframe of `words` for the session: its copy becomes j->frame's lightmap. */
static void frames_commit_keyframe(lc_frames_copy *cp, const lc_frames_job *j, lc_encoding enc, const uint8_t *words) {
    const lc_published *p = j->frame;
    const size_t texels = (size_t)p->lm_w * p->lm_h, tb = lc_frame_texel_bytes(enc);
    if (cp->lm_sent_texels != texels) {
        free(cp->lm_sent);
        cp->lm_sent = malloc(texels * 3 * sizeof(float));
        cp->lm_sent_texels = cp->lm_sent ? texels : 0;
    }
    cp->lm_sent_state = 0;
    if (cp->lm_sent) {
        memcpy(cp->lm_sent, p->lightmap, texels * 3 * sizeof(float));
        cp->lm_sent_state = 1ull << 63 | j->pub_seq; /* a copy made from a keyframe is named by its publication */
    }
    if (j->residual) {
        if (cp->lm_held_bytes != texels * tb) {
            free(cp->lm_held);
            cp->lm_held = malloc(texels * tb);
            cp->lm_held_bytes = cp->lm_held ? texels * tb : 0;
        }
        if (cp->lm_held) memcpy(cp->lm_held, words, texels * tb);
        /* the encoded copy also depends on the encoding */
        cp->lm_held_state = 1ull << 63 | j->pub_seq << 2 | (uint64_t)enc;
    }
}

/* 1 when a lightmap frame for this copy must be a keyframe whatever the delta: the copy holds
 * none of this size yet, or the stream's keyframe interval is due. */
static int frames_lightmap_keyframe_due(const lc_frames_copy *cp, const lc_frames_job *j) {
    const size_t texels = (size_t)j->frame->lm_w * j->frame->lm_h, tb = lc_frame_texel_bytes(j->enc);
    return !cp->lm_sent || cp->lm_sent_texels != texels || (j->residual && cp->lm_held_bytes != texels * tb) ||
        (j->sequence - 1) % (uint64_t)j->keyframe_interval == 0;
}

/* 1 when memo m already holds the delta from copy state `from` to j's publication. */
static int frames_memo_serves(const lc_delta_memo *m, uint64_t from, const lc_frames_job *j) {
    return from && m->valid && m->from_state == from && m->pub_seq == j->pub_seq && m->tile == j->tile &&
        m->thr == (float)j->delta_threshold;
}

int lc_frames_would_deflate(const lc_frames *f, const lc_frames_copy *cp, const lc_frames_job *j) {
    if (j->stream != LC_STREAM_LIGHTMAP || !j->residual || j->force_key || frames_lightmap_keyframe_due(cp, j))
        return 0;
    return !frames_memo_serves(&f->lm_residual[j->enc], cp->lm_held_state, j);
}

/* Lightmap frame: a keyframe when forced, first, every keyframe_interval frames or when the
 * delta would not be smaller; otherwise a delta of the tiles where some texel moved by more
 * than delta_threshold (relative) from what this client last received: whole tiles, or
 * residuals when the client subscribed to them. Sessions holding the same copy (same state
 * id) share one delta per publication (its tiles, payload and CRC): subscribers in step cost
 * one computation per frame, not one each; keyframes share the encoded lightmap and its CRC. */
static size_t frames_encode_lightmap(lc_frames *f, lc_frames_copy *cp, const lc_frames_job *j, lc_frame_header *h,
                                     int force_key) {
    const lc_published *p = j->frame;
    const uint32_t S = j->tile;
    const lc_encoding enc = (lc_encoding)h->encoding;
    const size_t texels = (size_t)p->lm_w * p->lm_h, tb = lc_frame_texel_bytes(enc);
    const int residual_sub = j->residual;
    const uint8_t *words = frames_lightmap_words(f, j, enc);
    if (!words) return 0;
    int key = force_key || frames_lightmap_keyframe_due(cp, j);
    const lc_delta_memo *delta = NULL;
    if (!key) {
        const float thr = (float)j->delta_threshold, floor_v = 1e-3f * frames_lightmap_peak(f, j);
        lc_delta_memo *m = residual_sub ? &f->lm_residual[enc] : &f->lm_tiles[enc];
        const uint64_t from = residual_sub ? cp->lm_held_state : cp->lm_sent_state;
        if (!frames_memo_serves(m, from, j)) {
            int rc = residual_sub ? frames_residual_compute(m, cp, j, enc, words, S, thr, floor_v)
                                  : frames_tiles_compute(m, cp, j, words, tb, S, thr, floor_v);
            if (rc != 0) return 0;
            /* the key frames_memo_serves compares */
            m->from_state = from;
            m->pub_seq = j->pub_seq;
            m->tile = S;
            m->thr = thr;
            m->to_state = ++f->delta_states;
        }
        key = m->keyframe;
        if (!key) delta = m;
    }
    const uint32_t *tiles = NULL;
    const uint8_t *payload = words;
    uint32_t body_crc;
    if (key) {
        h->flags = LC_FRAME_KEYFRAME;
        h->tile_count = 0;
        h->payload_length = (uint32_t)(texels * tb);
        lc_encoded_lightmap *e = &f->lm_encoded[enc];
        if (!e->crc_valid) {
            e->crc = lc_frame_body_crc(h, NULL, words);
            e->crc_valid = 1;
        }
        body_crc = e->crc;
    } else { /* a residual subscriber's delta without tiles goes as an empty whole-tile delta */
        h->flags = LC_FRAME_DELTA | (residual_sub && delta->n_tiles ? LC_FRAME_RESIDUAL : 0);
        h->tile_count = delta->n_tiles;
        h->payload_length = (uint32_t)delta->payload_len;
        tiles = delta->tiles;
        payload = delta->payload;
        body_crc = delta->body_crc;
    }
    size_t len = LC_FRAME_HEADER_SIZE + 4 * (size_t)h->tile_count + h->payload_length;
    if (frames_out_reserve(cp, j->pre + len) != 0) return 0;
    /* the frame will be written: the client's copy follows it */
    if (key) frames_commit_keyframe(cp, j, enc, words);
    else if (residual_sub) frames_commit_residual(cp, delta, j, words, tb);
    else frames_commit_tiles(cp, delta, j, S);
    return lc_frame_write_body_crc(h, tiles, payload, body_crc, cp->out + j->pre, len);
}

size_t lc_frames_encode(lc_frames *f, lc_frames_copy *cp, const lc_frames_job *j) {
    const int stream = j->stream, force_key = j->force_key;
    const lc_published *p = j->frame;
    lc_encoding enc = j->enc;
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = (uint8_t)stream;
    h.encoding = (uint8_t)enc;
    h.flags = LC_FRAME_KEYFRAME;
    h.revision = p->revision;
    h.sequence = j->sequence;
    h.timestamp_us = p->timestamp_us;
    h.pass = p->pass;
    h.converged = (uint8_t)p->converged;
    if (stream == LC_STREAM_LIGHTMAP) {
        h.width = p->lm_w;
        h.height = p->lm_h;
        h.depth = 1;
        h.tile_size = j->tile;
        return frames_encode_lightmap(f, cp, j, &h, force_key);
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
    if (frames_out_reserve(cp, j->pre + 2 * (LC_FRAME_HEADER_SIZE + payload_len) + 64) != 0) return 0;
    /* The payload is staged after the frame area, then framed into place. */
    uint8_t *stage = cp->out + j->pre + LC_FRAME_HEADER_SIZE + payload_len + 32, *o = stage;
    const float *src = stream == LC_STREAM_SHGRID ? p->grid_sh : p->object_sh;
    for (size_t k = 0; k < count; k++) {
        const float *mr = NULL;
        int add = 0;
        if (stream == LC_STREAM_OBJECTS) {
            memset(o, 0, 64);
            memcpy(o, p->object_ids[k], strnlen(p->object_ids[k], 64));
            o += 64;
            if (j->mr_light) mr = j->mr_light(j->mr_ctx, p->object_ids[k], &add);
        }
        for (int c = 0; c < 27; c++, o += per) {
            float v = mr ? mr[c] + (add ? src[27 * k + c] : 0.0f) : src[27 * k + c];
            if (per == 2) {
                uint16_t hv = lc_half_from_float(v);
                memcpy(o, &hv, 2);
            } else {
                memcpy(o, &v, 4);
            }
        }
    }
    return lc_frame_write(&h, NULL, stage, cp->out + j->pre, LC_FRAME_HEADER_SIZE + payload_len);
}

size_t lc_frames_encode_vpl(lc_frames_copy *cp, const lc_frames_vpl_object *objects, uint32_t n_objects,
                            lc_encoding enc, uint64_t revision, uint64_t sequence, uint64_t timestamp_us, size_t pre) {
    size_t per = lc_frame_sh_value_bytes(enc), points = 0;
    for (uint32_t i = 0; i < n_objects; i++) points += objects[i].n_points;
    size_t payload_len = (size_t)n_objects * 72 + points * 12 * per;
    if (!per || payload_len > UINT32_MAX / 2) return 0;
    lc_frame_header h = {.version = 1,
                         .stream = LC_STREAM_MR_VPL,
                         .encoding = (uint8_t)enc,
                         .flags = LC_FRAME_KEYFRAME,
                         .converged = 1,
                         .revision = revision,
                         .sequence = sequence,
                         .timestamp_us = timestamp_us,
                         .width = n_objects,
                         .height = (uint32_t)points,
                         .depth = 1,
                         .payload_length = (uint32_t)payload_len};
    if (frames_out_reserve(cp, pre + 2 * (LC_FRAME_HEADER_SIZE + payload_len) + 64) != 0) return 0;
    uint8_t *stage = cp->out + pre + LC_FRAME_HEADER_SIZE + payload_len + 32, *o = stage;
    for (uint32_t i = 0; i < n_objects; i++) {
        memset(o, 0, 72);
        memcpy(o, objects[i].id, strnlen(objects[i].id, 64));
        uint32_t n = objects[i].n_points;
        memcpy(o + 64, &n, 4);
        o += 72;
        for (size_t v = 0; v < (size_t)n * 12; v++, o += per) {
            float x = objects[i].records[v];
            if (per == 2) {
                uint16_t hv = lc_half_from_float(x);
                memcpy(o, &hv, 2);
            } else {
                memcpy(o, &x, 4);
            }
        }
    }
    return lc_frame_write(&h, NULL, stage, cp->out + pre, LC_FRAME_HEADER_SIZE + payload_len);
}
