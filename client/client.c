/* liblucent-client: lucent/1 over libwebsockets (see lucent_client.h for the contract).
 *
 * Thread: everything runs on the caller's thread. lws work happens only inside
 * client_service(), called by the blocking entry points; a 20 ms sul tick bounds each
 * lws_service() wait so deadlines and reconnect timers are checked often enough.
 *
 * Text messages are dispatched as they complete (client_on_text): the welcome, the reply to
 * the one pending user request (matched by id), replies to the library's own requests (ids
 * starting with "lc~": hello, resubscriptions, resync snapshots), everything else to the
 * on_message callback. Binary frames go through the stream's lc_client_view. */
#include "lucent_client.h"

#include <cjson/cJSON.h>
#include <libwebsockets.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "lucent_proto.h"
#include "util/half.h"

#define CLIENT_TICK_US (20 * LWS_US_PER_MS)
#define CLIENT_MAX_MESSAGE (256u << 20) /* largest frame we reassemble (a 4k f32 lightmap is 192 MiB) */
#define CLIENT_MAX_TEXT (16u << 20)
#define CLIENT_ID_PREFIX "lc~" /* ids of the library's own requests */
#define CLIENT_STREAMS 5       /* indexed by LC_CLIENT_LIGHTMAP..LC_CLIENT_MR_VPL (0 unused) */

/* ------------------------------------------------------------------------------------------
 * Views: a client-side copy of one stream
 * ---------------------------------------------------------------------------------------- */

struct lc_client_view {
    int have_key;   /* a keyframe was applied since create/reset */
    uint16_t flags; /* of the last applied frame */
    int pass, converged;
    int stream, encoding;
    uint64_t revision, sequence, server_time_us, client_time_us;
    uint32_t width, height, depth, tile_size;
    float *values; /* value_count floats */
    size_t value_count, value_cap;
    char **object_ids; /* objects and mr.vpl streams: width strings */
    uint32_t n_object_ids;
    uint32_t *object_points; /* mr.vpl: width point counts */
    uint8_t *words;          /* lightmap: the texels as received, encoded (residual deltas add to them) */
    size_t words_len, words_cap;
    int words_encoding;
    uint32_t *tiles; /* tiles of the last applied delta */
    uint32_t tile_count, tile_cap;
    const uint8_t *raw; /* last applied frame (borrowed: valid while the caller keeps it) */
    size_t raw_len;
};

static void set_err(char *err, size_t errlen, const char *fmt, ...) {
    if (!err || !errlen) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
}

static uint64_t client_realtime_us(void) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

static long long client_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

lc_client_view *lc_client_view_create(void) { return calloc(1, sizeof(lc_client_view)); }

static void view_free_ids(lc_client_view *v) {
    for (uint32_t i = 0; i < v->n_object_ids; i++) free(v->object_ids[i]);
    free(v->object_ids);
    free(v->object_points);
    v->object_ids = NULL;
    v->object_points = NULL;
    v->n_object_ids = 0;
}

void lc_client_view_reset(lc_client_view *v) {
    if (!v) return;
    v->have_key = 0;
    v->tile_count = 0;
    v->raw = NULL;
    v->raw_len = 0;
}

void lc_client_view_release(lc_client_view *v) {
    if (!v) return;
    view_free_ids(v);
    free(v->values);
    free(v->words);
    free(v->tiles);
    free(v);
}

static uint32_t get_u32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static float get_f32(const uint8_t *p) {
    uint32_t u = get_u32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* Decodes one lightmap texel into rgb. */
static void decode_texel(int encoding, const uint8_t *p, float *rgb) {
    switch (encoding) {
    case LC_ENC_RGB9E5: lc_rgb9e5_decode(get_u32(p), rgb); break;
    case LC_ENC_RGBA16F:
        for (int k = 0; k < 3; k++) rgb[k] = lc_half_to_float((uint16_t)(p[2 * k] | p[2 * k + 1] << 8));
        break;
    default:
        for (int k = 0; k < 3; k++) rgb[k] = get_f32(p + 4 * k);
        break;
    }
}

static float decode_sh_value(int encoding, const uint8_t *p) {
    return encoding == LC_ENC_RGBA16F ? lc_half_to_float((uint16_t)(p[0] | p[1] << 8)) : get_f32(p);
}

static int view_reserve(lc_client_view *v, size_t count) {
    if (count > v->value_cap) {
        float *n = realloc(v->values, count * sizeof(float));
        if (!n) return -1;
        v->values = n;
        v->value_cap = count;
    }
    v->value_count = count;
    return 0;
}

static void view_fill_out(const lc_client_view *v, lc_client_frame *out) {
    memset(out, 0, sizeof *out);
    out->stream = v->stream;
    out->encoding = v->encoding;
    out->keyframe = v->flags == LC_FRAME_KEYFRAME;
    out->residual = (v->flags & LC_FRAME_RESIDUAL) != 0;
    out->pass = v->pass;
    out->converged = v->converged;
    out->revision = v->revision;
    out->sequence = v->sequence;
    out->server_time_us = v->server_time_us;
    out->client_time_us = v->client_time_us;
    out->width = v->width;
    out->height = v->height;
    out->depth = v->depth;
    out->tile_size = v->tile_size;
    out->tile_count = v->tile_count;
    out->tiles = v->tile_count ? v->tiles : NULL;
    out->values = v->values;
    out->value_count = v->value_count;
    int ids = v->stream == LC_CLIENT_OBJECTS || v->stream == LC_CLIENT_MR_VPL;
    out->object_ids = ids ? (const char *const *)v->object_ids : NULL;
    out->object_points = v->stream == LC_CLIENT_MR_VPL ? v->object_points : NULL;
    out->raw = v->raw;
    out->raw_len = v->raw_len;
}

static int apply_lightmap(lc_client_view *v, const lc_frame_header *h, const uint8_t *tiles, const uint8_t *payload,
                          char *err, size_t errlen) {
    size_t tb = lc_frame_texel_bytes((lc_encoding)h->encoding);
    if (h->flags == LC_FRAME_KEYFRAME) {
        size_t texels = (size_t)h->width * h->height;
        if (texels > SIZE_MAX / 3 / sizeof(float) || view_reserve(v, texels * 3) != 0) {
            set_err(err, errlen, "lightmap %ux%u does not fit in memory", h->width, h->height);
            return -1;
        }
        for (size_t i = 0; i < texels; i++) decode_texel(h->encoding, payload + i * tb, v->values + 3 * i);
        v->tile_count = 0;
        v->words_len = 0; /* no encoded copy until it is complete */
        if (texels * tb > v->words_cap) {
            uint8_t *n = realloc(v->words, texels * tb);
            if (!n) return 0; /* the values are fine; residual deltas will ask for a keyframe */
            v->words = n;
            v->words_cap = texels * tb;
        }
        memcpy(v->words, payload, texels * tb);
        v->words_len = texels * tb;
        v->words_encoding = h->encoding;
        return 0;
    }
    if (h->width != v->width || h->height != v->height || v->stream != LC_CLIENT_LIGHTMAP) {
        set_err(err, errlen, "delta for a %ux%u lightmap, the copy is %ux%u", h->width, h->height, v->width, v->height);
        return -2;
    }
    if (h->tile_count > v->tile_cap) {
        uint32_t *n = realloc(v->tiles, (size_t)h->tile_count * sizeof *n);
        if (!n) {
            set_err(err, errlen, "out of memory");
            return -1;
        }
        v->tiles = n;
        v->tile_cap = h->tile_count;
    }
    const size_t words_len = (size_t)h->width * h->height * tb;
    const int residual = (h->flags & LC_FRAME_RESIDUAL) != 0;
    int words_ok = v->words_len == words_len && v->words_encoding == h->encoding;
    uint8_t *inflated = NULL;
    if (residual) {
        if (!words_ok) {
            set_err(err, errlen, "residual delta without an encoded %s copy",
                    lc_proto_encoding_name((lc_encoding)h->encoding));
            return -2;
        }
        size_t expect = lc_frame_tile_texels(h, tiles) * tb;
        inflated = malloc(expect ? expect : 1);
        if (!inflated || lc_residual_inflate(payload, h->payload_length, inflated, expect) != 0) {
            free(inflated);
            set_err(err, errlen, "bad frame: the residual payload does not inflate to %zu bytes", expect);
            return -1;
        }
        payload = inflated;
    }
    const uint8_t *p = payload;
    for (uint32_t i = 0; i < h->tile_count; i++) {
        uint32_t t = get_u32(tiles + 4 * (size_t)i), x0, y0, x1, y1;
        v->tiles[i] = t;
        lc_tile_rect(h->width, h->height, h->tile_size, t, &x0, &y0, &x1, &y1);
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++, p += tb) {
                size_t at = (size_t)y * h->width + x;
                if (residual) lc_residual_apply((lc_encoding)h->encoding, v->words + at * tb, p, 1);
                else if (words_ok) memcpy(v->words + at * tb, p, tb);
                decode_texel(h->encoding, residual ? v->words + at * tb : p, v->values + 3 * at);
            }
    }
    if (!words_ok) v->words_len = 0; /* a delta in another encoding: the encoded copy is gone */
    free(inflated);
    v->tile_count = h->tile_count;
    return 0;
}

static int apply_sh(lc_client_view *v, const lc_frame_header *h, const uint8_t *payload, char *err, size_t errlen) {
    size_t vb = lc_frame_sh_value_bytes((lc_encoding)h->encoding);
    if (h->flags != LC_FRAME_KEYFRAME) {
        set_err(err, errlen, "%s frames are keyframes only", h->stream == LC_STREAM_SHGRID ? "shgrid" : "objects");
        return -1;
    }
    size_t samples = h->stream == LC_STREAM_SHGRID ? (size_t)h->width * h->height * h->depth : h->width;
    if (samples > SIZE_MAX / 27 / sizeof(float) || view_reserve(v, samples * 27) != 0) {
        set_err(err, errlen, "frame does not fit in memory");
        return -1;
    }
    const uint8_t *p = payload;
    if (h->stream == LC_STREAM_OBJECTS) {
        view_free_ids(v);
        v->object_ids = calloc(samples ? samples : 1, sizeof(char *));
        if (!v->object_ids) {
            set_err(err, errlen, "out of memory");
            return -1;
        }
        v->n_object_ids = (uint32_t)samples;
    }
    for (size_t s = 0; s < samples; s++) {
        if (h->stream == LC_STREAM_OBJECTS) {
            char id[LC_PROTO_ID_MAX + 1];
            memcpy(id, p, LC_PROTO_ID_MAX);
            id[LC_PROTO_ID_MAX] = 0;
            v->object_ids[s] = strdup(id);
            if (!v->object_ids[s]) {
                set_err(err, errlen, "out of memory");
                return -1;
            }
            p += LC_PROTO_ID_MAX;
        }
        for (int k = 0; k < 27; k++, p += vb) v->values[s * 27 + (size_t)k] = decode_sh_value(h->encoding, p);
    }
    v->tile_count = 0;
    return 0;
}

/* mr.vpl (PROTOCOL.md §8.7): the records of all objects in order, ids and point counts;
 * lc_frame_parse checked the blocks against the length and the height. */
static int apply_vpl(lc_client_view *v, const lc_frame_header *h, const uint8_t *payload, char *err, size_t errlen) {
    size_t vb = lc_frame_sh_value_bytes((lc_encoding)h->encoding), at = 0, rec = 0;
    /* height <= payload_length / 24 (each record has 12 values of 2 or 4 bytes): no overflow */
    if (view_reserve(v, (size_t)h->height * LC_FRAME_MR_VPL_VALUES) != 0) {
        set_err(err, errlen, "frame does not fit in memory");
        return -1;
    }
    view_free_ids(v);
    v->object_ids = calloc(h->width ? h->width : 1, sizeof(char *));
    v->object_points = calloc(h->width ? h->width : 1, sizeof(uint32_t));
    if (!v->object_ids || !v->object_points) goto oom;
    v->n_object_ids = h->width;
    for (uint32_t i = 0; i < h->width; i++) {
        char id[LC_PROTO_ID_MAX + 1];
        uint32_t n;
        const uint8_t *p;
        if (lc_frame_mr_vpl_next(h, payload, &at, id, &n, &p) != 0 || n > h->height - rec) {
            set_err(err, errlen, "bad frame: mr.vpl block %u", i);
            return -1;
        }
        if (!(v->object_ids[i] = strdup(id))) goto oom;
        v->object_points[i] = n;
        for (size_t k = 0; k < (size_t)n * LC_FRAME_MR_VPL_VALUES; k++, p += vb)
            v->values[rec * LC_FRAME_MR_VPL_VALUES + k] = decode_sh_value(h->encoding, p);
        rec += n;
    }
    v->tile_count = 0;
    return 0;
oom:
    set_err(err, errlen, "out of memory");
    return -1;
}

int lc_client_view_apply(lc_client_view *v, const uint8_t *frame, size_t len, lc_client_frame *out, char *err,
                         size_t errlen) {
    lc_frame_header h;
    const uint8_t *tiles, *payload;
    lc_proto_error pe;
    if (!v || !frame) {
        set_err(err, errlen, "bad arguments");
        return -1;
    }
    if (lc_frame_parse(frame, len, &h, &tiles, &payload, &pe) != 0) {
        set_err(err, errlen, "bad frame: %s", pe.message);
        return -1;
    }
    if (h.stream < LC_STREAM_LIGHTMAP || h.stream > LC_STREAM_MR_VPL) {
        set_err(err, errlen, "bad frame: unknown stream %u", h.stream);
        return -1;
    }
    if (h.stream != LC_STREAM_LIGHTMAP && !lc_frame_sh_value_bytes((lc_encoding)h.encoding)) {
        set_err(err, errlen, "bad frame: encoding %u not allowed for SH", h.encoding);
        return -1;
    }
    if (v->have_key && h.stream != (uint8_t)v->stream) {
        set_err(err, errlen, "bad frame: stream %u in a view of stream %d", h.stream, v->stream);
        return -1;
    }
    int key = h.flags == LC_FRAME_KEYFRAME;
    if (v->have_key && h.revision < v->revision) {
        set_err(err, errlen, "bad frame: revision went back from %llu to %llu", (unsigned long long)v->revision,
                (unsigned long long)h.revision);
        return -1;
    }
    if (!key) {
        if (!v->have_key) {
            set_err(err, errlen, "delta frame without a preceding keyframe");
            return -2;
        }
        if (h.sequence != v->sequence + 1) {
            set_err(err, errlen, "sequence gap: %llu after %llu", (unsigned long long)h.sequence,
                    (unsigned long long)v->sequence);
            v->have_key = 0; /* the copy is stale until the next keyframe */
            return -2;
        }
    }
    int r = h.stream == LC_STREAM_LIGHTMAP ? apply_lightmap(v, &h, tiles, payload, err, errlen)
        : h.stream == LC_STREAM_MR_VPL     ? apply_vpl(v, &h, payload, err, errlen)
                                           : apply_sh(v, &h, payload, err, errlen);
    if (r != 0) {
        if (r == -1 && key) v->have_key = 0; /* a half-written keyframe */
        return r;
    }
    v->have_key = 1;
    v->flags = h.flags;
    v->pass = h.pass;
    v->converged = h.converged;
    v->stream = h.stream;
    v->encoding = h.encoding;
    v->revision = h.revision;
    v->sequence = h.sequence;
    v->server_time_us = h.timestamp_us;
    v->client_time_us = client_realtime_us();
    v->width = h.width;
    v->height = h.height;
    v->depth = h.depth;
    v->tile_size = h.tile_size;
    v->raw = frame;
    v->raw_len = len;
    if (out) view_fill_out(v, out);
    return 0;
}

/* ------------------------------------------------------------------------------------------
 * The connection
 * ---------------------------------------------------------------------------------------- */

typedef struct client_msg {
    struct client_msg *next;
    size_t len;
    int binary;         /* an upload frame (lc_client_send_binary), else text */
    unsigned char *buf; /* LWS_PRE + len */
} client_msg;

typedef enum {
    CONN_IDLE = 0, /* no socket (before the first attempt, or waiting to retry) */
    CONN_OPENING,  /* TCP/TLS/WebSocket handshake or hello sent, no welcome yet */
    CONN_OPEN,     /* welcome received */
    CONN_DEAD,     /* closed for good */
} conn_state;

typedef struct client_sub {
    int active;
    int encoding;
    double max_rate;
} client_sub;

struct lc_client {
    struct lws_context *ctx;
    struct lws *wsi;
    lws_sorted_usec_list_t tick;
    conn_state state;
    char reason[256]; /* why the last connection ended / failed */
    int refused;      /* the server refused hello: never retry */
    int closing;      /* lc_client_close in progress: no callbacks */

    /* options (strings owned) */
    char *url, *token, *name, *ca_file, *capabilities;
    int timeout_ms, insecure, reconnect, backoff_min_ms, backoff_max_ms, max_retries;
    int tls;
    char host[256], path[512], origin[300];
    int port;

    /* reconnect */
    int attempts; /* consecutive failed attempts */
    int backoff_ms;
    long long retry_at; /* monotonic ms of the next attempt (CONN_IDLE) */

    client_msg *txq, *txq_tail; /* outgoing text, FIFO */

    /* reassembly of the current incoming message */
    uint8_t *rx;
    size_t rxlen, rxcap;
    int rx_binary, rx_overflow;

    char *welcome;
    char *hello_error; /* the server's reply when it refused hello */

    /* the one pending user request */
    int pending;
    cJSON *pending_id; /* NULL: match the next reply */
    char *reply;
    int reply_done;

    long long next_id;
    unsigned resync_seq;
    int resync_pending;

    client_sub subs[CLIENT_STREAMS];
    lc_client_view *views[CLIENT_STREAMS];
    unsigned long view_frames[CLIENT_STREAMS]; /* frames applied per stream (wait_frame freshness) */
    uint8_t *view_raw[CLIENT_STREAMS];         /* owned copy of each view's last frame */

    lc_client_callbacks cb;
    lc_client_stats stats;
};

void lc_client_options_init(lc_client_options *o) {
    memset(o, 0, sizeof *o);
    o->timeout_ms = 5000;
    o->backoff_min_ms = 100;
    o->backoff_max_ms = 5000;
}

static char *dupstr(const char *s) { return strdup(s ? s : ""); }

static void client_notify(lc_client *c, int event, const char *reason) {
    if (!c->closing && c->cb.on_connection) c->cb.on_connection(c, event, reason ? reason : "", c->cb.user);
}

static void txq_clear(lc_client *c) {
    while (c->txq) {
        client_msg *m = c->txq;
        c->txq = m->next;
        free(m->buf);
        free(m);
    }
    c->txq_tail = NULL;
}

/* Queues a message (text, or binary when `binary`); `front` puts it first (hello must
 * precede everything). */
static int txq_push_kind(lc_client *c, const void *text, size_t n, int front, int binary) {
    client_msg *m = calloc(1, sizeof *m);
    unsigned char *b = m ? malloc(LWS_PRE + n) : NULL;
    if (!b) {
        free(m);
        return -1;
    }
    memcpy(b + LWS_PRE, text, n);
    m->buf = b;
    m->len = n;
    m->binary = binary;
    if (front) {
        m->next = c->txq;
        c->txq = m;
        if (!c->txq_tail) c->txq_tail = m;
    } else {
        if (c->txq_tail) c->txq_tail->next = m;
        else c->txq = m;
        c->txq_tail = m;
    }
    if (c->wsi && c->state != CONN_IDLE) lws_callback_on_writable(c->wsi);
    return 0;
}

static int txq_push(lc_client *c, const char *text, size_t n, int front) { return txq_push_kind(c, text, n, front, 0); }

static int txq_push_json(lc_client *c, cJSON *o, int front) {
    char *t = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    if (!t) return -1;
    int r = txq_push(c, t, strlen(t), front);
    free(t);
    return r;
}

static const char *json_str(const cJSON *o, const char *k) {
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, k);
    return cJSON_IsString(v) ? v->valuestring : NULL;
}

static int ids_equal(const cJSON *a, const cJSON *b) {
    if (!a || !b) return 0;
    if (cJSON_IsNumber(a) && cJSON_IsNumber(b)) return a->valuedouble == b->valuedouble;
    if (cJSON_IsString(a) && cJSON_IsString(b)) return strcmp(a->valuestring, b->valuestring) == 0;
    return 0;
}

/* The subscribe request for a stream; `encoding` may carry LC_CLIENT_RESIDUAL. */
static cJSON *subscribe_json(int stream, int encoding, double max_rate) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "type", "subscribe");
    cJSON_AddStringToObject(o, "stream", lc_proto_stream_name((lc_stream)stream));
    int enc = encoding & ~LC_CLIENT_RESIDUAL;
    if (enc) cJSON_AddStringToObject(o, "encoding", lc_proto_encoding_name((lc_encoding)enc));
    if (encoding & LC_CLIENT_RESIDUAL) cJSON_AddStringToObject(o, "delta", "residual");
    if (max_rate > 0) cJSON_AddNumberToObject(o, "max_rate", max_rate);
    return o;
}

static int send_subscribe(lc_client *c, int stream) {
    cJSON *o = subscribe_json(stream, c->subs[stream].encoding, c->subs[stream].max_rate);
    char id[32];
    snprintf(id, sizeof id, CLIENT_ID_PREFIX "sub-%d", stream);
    cJSON_AddStringToObject(o, "id", id);
    return txq_push_json(c, o, 0);
}

/* Asks for keyframes of every subscribed stream (after a gap or a bad frame); one at a time. */
static void request_resync(lc_client *c) {
    if (c->resync_pending || c->state != CONN_OPEN) return;
    cJSON *o = cJSON_CreateObject();
    char id[32];
    snprintf(id, sizeof id, CLIENT_ID_PREFIX "resync-%u", ++c->resync_seq);
    cJSON_AddStringToObject(o, "type", "snapshot");
    cJSON_AddStringToObject(o, "id", id);
    if (txq_push_json(c, o, 0) == 0) {
        c->resync_pending = 1;
        c->stats.resyncs++;
    }
}

/* Thread: caller's (inside lws_service). Handles one complete text message. */
static void client_on_text(lc_client *c, char *text) {
    cJSON *o = cJSON_Parse(text);
    const char *type = o ? json_str(o, "type") : NULL;
    const cJSON *id = o ? cJSON_GetObjectItemCaseSensitive(o, "id") : NULL;
    const char *sid = cJSON_IsString(id) ? id->valuestring : NULL;
    int is_error = type && strcmp(type, "error") == 0;

    if (type && strcmp(type, "welcome") == 0 && c->state == CONN_OPENING) {
        free(c->welcome);
        c->welcome = text;
        text = NULL;
        c->state = CONN_OPEN;
        c->attempts = 0;
        c->backoff_ms = c->backoff_min_ms;
        c->resync_pending = 0;
        for (int s = 1; s < CLIENT_STREAMS; s++) {
            if (c->views[s]) lc_client_view_reset(c->views[s]);
            if (c->subs[s].active) send_subscribe(c, s);
        }
        client_notify(c, LC_CLIENT_CONNECTED, "welcome received");
    } else if (c->state == CONN_OPENING && is_error) {
        /* hello refused (unauthorized, bad hello): permanent */
        free(c->hello_error);
        c->hello_error = text;
        text = NULL;
        c->refused = 1;
    } else if (sid && strncmp(sid, CLIENT_ID_PREFIX, strlen(CLIENT_ID_PREFIX)) == 0) {
        /* replies to our own requests: only errors are worth telling the application */
        if (strncmp(sid, CLIENT_ID_PREFIX "resync-", 10) == 0) c->resync_pending = 0;
        if (is_error && !c->closing && c->cb.on_message) c->cb.on_message(c, text, c->cb.user);
    } else {
        int is_reply = is_error || (type && (!strcmp(type, "ok") || !strcmp(type, "state") || !strcmp(type, "pong")));
        /* an error without an id answers a request the server could not read (bad_json) */
        int match = c->pending && !c->reply_done && is_reply &&
            (c->pending_id ? (ids_equal(id, c->pending_id) || (is_error && !id)) : 1);
        if (match) {
            c->reply = text;
            text = NULL;
            c->reply_done = 1;
        } else if (!c->closing && c->cb.on_message) c->cb.on_message(c, text, c->cb.user);
    }
    cJSON_Delete(o);
    free(text);
}

/* Thread: caller's (inside lws_service). Applies one complete binary frame. */
static void client_on_binary(lc_client *c, uint8_t *data, size_t len) {
    c->stats.bytes += len;
    int stream = len > 6 ? data[6] : 0;
    if (stream < 1 || stream >= CLIENT_STREAMS) {
        c->stats.bad_frames++;
        free(data);
        request_resync(c);
        return;
    }
    if (!c->views[stream] && !(c->views[stream] = lc_client_view_create())) {
        free(data);
        return;
    }
    char err[256];
    lc_client_frame f;
    int r = lc_client_view_apply(c->views[stream], data, len, &f, err, sizeof err);
    if (r != 0) {
        free(data);
        if (r == -1) c->stats.bad_frames++;
        request_resync(c);
        return;
    }
    free(c->view_raw[stream]); /* the view now points at `data` */
    c->view_raw[stream] = data;
    c->view_frames[stream]++;
    c->stats.frames++;
    if (f.keyframe) {
        c->stats.keyframes++;
        c->resync_pending = 0;
    } else c->stats.deltas++;
    if (!c->closing && c->cb.on_frame) c->cb.on_frame(c, &f, c->cb.user);
}

static void client_connection_lost(lc_client *c, const char *why) {
    if (why != c->reason) snprintf(c->reason, sizeof c->reason, "%s", why);
    int was_open = c->state == CONN_OPEN;
    c->wsi = NULL;
    txq_clear(c);
    c->rxlen = 0;
    if (c->reconnect && !c->refused && !c->closing && (c->max_retries <= 0 || c->attempts < c->max_retries)) {
        c->state = CONN_IDLE;
        if (!was_open) c->attempts++;
        int jitter = c->backoff_ms / 5;
        c->retry_at = client_now_ms() + c->backoff_ms + (jitter ? rand() % (jitter + 1) : 0);
        c->backoff_ms = c->backoff_ms * 2 > c->backoff_max_ms ? c->backoff_max_ms : c->backoff_ms * 2;
        c->stats.reconnects += was_open;
        client_notify(c, LC_CLIENT_RECONNECTING, c->reason);
    } else {
        c->state = CONN_DEAD;
        client_notify(c, LC_CLIENT_DISCONNECTED, c->reason);
    }
}

static int client_rx_append(lc_client *c, const void *in, size_t len) {
    if (c->rx_overflow) return 0;
    size_t limit = c->rx_binary ? CLIENT_MAX_MESSAGE : CLIENT_MAX_TEXT;
    if (c->rxlen + len + 1 > limit) {
        c->rx_overflow = 1;
        return 0;
    }
    if (c->rxlen + len + 1 > c->rxcap) {
        size_t cap = c->rxcap ? c->rxcap : 4096;
        while (cap < c->rxlen + len + 1) cap *= 2;
        uint8_t *r = realloc(c->rx, cap);
        if (!r) {
            c->rx_overflow = 1;
            return 0;
        }
        c->rx = r;
        c->rxcap = cap;
    }
    memcpy(c->rx + c->rxlen, in, len);
    c->rxlen += len;
    return 0;
}

/* Hands the reassembled message over (ownership moves to the handler). */
static void client_rx_complete(lc_client *c) {
    if (c->rx_overflow) {
        c->stats.bad_frames += c->rx_binary;
        if (c->rx_binary) request_resync(c);
        c->rxlen = 0;
        return;
    }
    uint8_t *msg = malloc(c->rxlen + 1);
    if (!msg) {
        c->rxlen = 0;
        return;
    }
    memcpy(msg, c->rx, c->rxlen);
    msg[c->rxlen] = 0;
    size_t n = c->rxlen;
    c->rxlen = 0;
    if (c->rx_binary) client_on_binary(c, msg, n);
    else client_on_text(c, (char *)msg);
}

static int client_lws_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    struct lws_context *ctx = lws_get_context(wsi);
    lc_client *c = ctx ? lws_context_user(ctx) : NULL;
    /* callbacks of a connection we already gave up on (c->wsi moved on) are ignored */
    if (!c || (c->wsi && wsi != c->wsi)) return lws_callback_http_dummy(wsi, reason, user, in, len);
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        if (c->state == CONN_OPENING) {
            char why[300];
            const char *what = in ? (const char *)in : "(unknown)";
            snprintf(why, sizeof why, "cannot connect to %s: %s%s", c->url, what,
                     c->tls && strstr(what, "SSL") ? " (is the server certificate trusted? give a CA file, or "
                                                     "accept self-signed certificates with insecure)"
                                                   : "");
            client_connection_lost(c, why);
        }
        return 0;
    case LWS_CALLBACK_CLIENT_ESTABLISHED:
        if (c->txq) lws_callback_on_writable(wsi);
        break;
    case LWS_CALLBACK_CLIENT_WRITEABLE: {
        client_msg *m = c->txq;
        if (!m) break;
        c->txq = m->next;
        if (!c->txq) c->txq_tail = NULL;
        int n = lws_write(wsi, m->buf + LWS_PRE, m->len, m->binary ? LWS_WRITE_BINARY : LWS_WRITE_TEXT);
        size_t mlen = m->len;
        free(m->buf);
        free(m);
        if (n < (int)mlen) {
            snprintf(c->reason, sizeof c->reason, "write failed");
            return -1;
        }
        if (c->txq) lws_callback_on_writable(wsi);
        break;
    }
    case LWS_CALLBACK_CLIENT_RECEIVE:
        if (lws_is_first_fragment(wsi)) {
            c->rxlen = 0;
            c->rx_overflow = 0;
            c->rx_binary = lws_frame_is_binary(wsi);
        }
        client_rx_append(c, in, len);
        if (lws_is_final_fragment(wsi)) client_rx_complete(c);
        break;
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        if (in && len >= 2) {
            const unsigned char *p = in;
            snprintf(c->reason, sizeof c->reason, "server closed the connection (%d%s%.*s)", (p[0] << 8) | p[1],
                     len > 2 ? ": " : "", (int)(len - 2), (const char *)p + 2);
        } else snprintf(c->reason, sizeof c->reason, "server closed the connection");
        break;
    case LWS_CALLBACK_CLIENT_CLOSED:
        if (c->state == CONN_OPENING || c->state == CONN_OPEN)
            client_connection_lost(c, c->reason[0] ? c->reason : "connection closed");
        break;
    default: break;
    }
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}

/* LC_PROTO_WS_TX_PACKET_MAX: a 640x480 MR upload (2.4 MB) left in 38 pieces before,
 * acknowledged after 55-60 ms (p50), now 47-49. */
static const struct lws_protocols client_protocols[] = {
    {LC_PROTO_SUBPROTOCOL, client_lws_callback, 0, 65536, 0, NULL, LC_PROTO_WS_TX_PACKET_MAX},
    {NULL, NULL, 0, 0, 0, NULL, 0},
};

static void client_tick(lws_sorted_usec_list_t *sul) {
    lc_client *c = lws_container_of(sul, lc_client, tick);
    lws_sul_schedule(c->ctx, 0, &c->tick, client_tick, CLIENT_TICK_US);
}

static int client_parse_url(lc_client *c, const char *url, char *err, size_t errlen) {
    const char *p = url;
    if (strncmp(p, "ws://", 5) == 0) p += 5;
    else if (strncmp(p, "wss://", 6) == 0) {
        p += 6;
        c->tls = 1;
    } else {
        set_err(err, errlen, "unsupported URL '%s' (expected ws://host:port/ or wss://host:port/)", url);
        return -1;
    }
    const char *hend = p;
    if (*hend == '[') { /* [v6]:port */
        while (*hend && *hend != ']') hend++;
        if (*hend) hend++;
    } else
        while (*hend && *hend != ':' && *hend != '/') hend++;
    size_t hl = (size_t)(hend - p);
    if (hl == 0 || hl >= sizeof c->host) {
        set_err(err, errlen, "bad host in URL '%s'", url);
        return -1;
    }
    memcpy(c->host, p, hl);
    c->host[hl] = 0;
    c->port = c->tls ? 443 : 80;
    p = hend;
    if (*p == ':') {
        char *e;
        long port = strtol(p + 1, &e, 10);
        if (e == p + 1 || port <= 0 || port > 65535) {
            set_err(err, errlen, "bad port in URL '%s'", url);
            return -1;
        }
        c->port = (int)port;
        p = e;
    }
    if (*p && *p != '/') {
        set_err(err, errlen, "bad URL '%s'", url);
        return -1;
    }
    snprintf(c->path, sizeof c->path, "%s", *p ? p : "/");
    snprintf(c->origin, sizeof c->origin, "%s:%d", c->host, c->port);
    return 0;
}

/* Starts one connection attempt: queues hello first, then asks lws to connect. */
static int client_start_attempt(lc_client *c) {
    txq_clear(c);
    c->reason[0] = 0;
    cJSON *h = cJSON_CreateObject();
    cJSON_AddStringToObject(h, "type", "hello");
    cJSON_AddStringToObject(h, "id", CLIENT_ID_PREFIX "hello");
    cJSON_AddStringToObject(h, "client", c->name[0] ? c->name : "liblucent-client");
    cJSON_AddStringToObject(h, "token", c->token);
    if (c->capabilities[0]) { /* "mr,other": PROTOCOL.md §8.1 */
        cJSON *caps = cJSON_AddArrayToObject(h, "capabilities");
        char buf[256];
        snprintf(buf, sizeof buf, "%s", c->capabilities);
        for (char *save = NULL, *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save))
            cJSON_AddItemToArray(caps, cJSON_CreateString(t));
    }
    if (txq_push_json(c, h, 1) != 0) return -1;
    c->state = CONN_OPENING;

    struct lws_client_connect_info ci;
    memset(&ci, 0, sizeof ci);
    ci.context = c->ctx;
    ci.address = c->host;
    ci.port = c->port;
    ci.path = c->path;
    ci.host = c->origin;
    ci.origin = c->origin;
    ci.protocol = LC_PROTO_SUBPROTOCOL;
    ci.pwsi = &c->wsi;
    if (c->tls) {
        ci.ssl_connection = LCCSCF_USE_SSL;
        ci.alpn = "http/1.1";
        if (c->insecure)
            ci.ssl_connection |= LCCSCF_ALLOW_SELFSIGNED | LCCSCF_SKIP_SERVER_CERT_HOSTNAME_CHECK |
                LCCSCF_ALLOW_EXPIRED | LCCSCF_ALLOW_INSECURE;
    }
    if (!lws_client_connect_via_info(&ci) && c->state == CONN_OPENING) {
        c->wsi = NULL;
        client_connection_lost(c, "cannot start the connection");
        return -1;
    }
    return 0;
}

/* Runs the event loop once (bounded by the tick) and the reconnect timer. */
static int client_service(lc_client *c) {
    if (c->state == CONN_IDLE && c->reconnect && client_now_ms() >= c->retry_at) client_start_attempt(c);
    if (c->state == CONN_DEAD) return -1;
    if (lws_service(c->ctx, 0) < 0) return -1;
    return 0;
}

lc_client *lc_client_open(const lc_client_options *o, char *err, size_t errlen) {
    if (!o || !o->url) {
        set_err(err, errlen, "no URL given");
        return NULL;
    }
    lc_client *c = calloc(1, sizeof *c);
    if (!c) {
        set_err(err, errlen, "out of memory");
        return NULL;
    }
    c->url = dupstr(o->url);
    c->token = dupstr(o->token);
    c->name = dupstr(o->name);
    c->capabilities = dupstr(o->capabilities);
    c->ca_file = o->ca_file ? dupstr(o->ca_file) : NULL;
    c->timeout_ms = o->timeout_ms > 0 ? o->timeout_ms : 5000;
    c->insecure = o->insecure;
    c->reconnect = o->reconnect;
    c->backoff_min_ms = o->backoff_min_ms > 0 ? o->backoff_min_ms : 100;
    c->backoff_max_ms = o->backoff_max_ms >= c->backoff_min_ms ? o->backoff_max_ms : c->backoff_min_ms;
    c->backoff_ms = c->backoff_min_ms;
    c->max_retries = o->max_retries;
    c->next_id = 1;
    if (!c->url || !c->token || !c->name || !c->capabilities || (o->ca_file && !c->ca_file)) {
        set_err(err, errlen, "out of memory");
        goto err;
    }
    if (client_parse_url(c, c->url, err, errlen) != 0) goto err;

    lws_set_log_level(0, NULL);
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = client_protocols;
    info.user = c;
    info.timeout_secs = (unsigned)((c->timeout_ms + 999) / 1000);
    info.gid = -1;
    info.uid = -1;
    if (c->tls) {
        info.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
        info.client_ssl_ca_filepath = c->ca_file;
    }
    c->ctx = lws_create_context(&info);
    if (!c->ctx) {
        set_err(err, errlen, "cannot create the libwebsockets context");
        goto err;
    }
    lws_sul_schedule(c->ctx, 0, &c->tick, client_tick, CLIENT_TICK_US);

    /* the first connection is synchronous: welcome, refusal or failure within the timeout */
    int saved_reconnect = c->reconnect;
    c->reconnect = 0;
    long long deadline = client_now_ms() + c->timeout_ms;
    client_start_attempt(c);
    while (c->state == CONN_OPENING && client_now_ms() < deadline)
        if (client_service(c) != 0) break;
    c->reconnect = saved_reconnect;
    if (c->state == CONN_OPEN) return c;
    if (c->hello_error) {
        cJSON *e = cJSON_Parse(c->hello_error);
        set_err(err, errlen, "server error %s: %s", json_str(e, "code") ? json_str(e, "code") : "?",
                json_str(e, "message") ? json_str(e, "message") : "");
        cJSON_Delete(e);
    } else if (c->state == CONN_OPENING) set_err(err, errlen, "%s: timed out waiting for the server's welcome", c->url);
    else set_err(err, errlen, "%s", c->reason[0] ? c->reason : "connection failed");
err:
    lc_client_close(c);
    return NULL;
}

lc_client *lc_client_connect(const char *url, const char *token, const char *name, int timeout_ms, char *err,
                             size_t errlen) {
    lc_client_options o;
    lc_client_options_init(&o);
    o.url = url;
    o.token = token;
    o.name = name;
    if (timeout_ms > 0) o.timeout_ms = timeout_ms;
    return lc_client_open(&o, err, errlen);
}

void lc_client_set_callbacks(lc_client *c, const lc_client_callbacks *cb) {
    if (!c) return;
    if (cb) c->cb = *cb;
    else memset(&c->cb, 0, sizeof c->cb);
}

/* Services until the connection is open (reconnecting if needed) or the deadline. */
static int client_wait_open(lc_client *c, long long deadline, char *err, size_t errlen) {
    while (c->state != CONN_OPEN) {
        if (c->state == CONN_DEAD || !c->reconnect) {
            set_err(err, errlen, "%s", c->reason[0] ? c->reason : "not connected");
            return -1;
        }
        if (client_now_ms() >= deadline) {
            set_err(err, errlen, "not connected (%s)", c->reason[0] ? c->reason : "reconnecting");
            return -1;
        }
        if (client_service(c) != 0 && c->state == CONN_DEAD) {
            set_err(err, errlen, "%s", c->reason[0] ? c->reason : "connection lost");
            return -1;
        }
    }
    return 0;
}

int lc_client_request(lc_client *c, const char *json_request, char **reply_json, int timeout_ms, char *err,
                      size_t errlen) {
    if (reply_json) *reply_json = NULL;
    if (!c || !json_request || c->pending) {
        set_err(err, errlen, c && c->pending ? "a request is already pending (not re-entrant)" : "bad arguments");
        return -1;
    }
    long long deadline = client_now_ms() + (timeout_ms > 0 ? timeout_ms : c->timeout_ms);
    if (client_wait_open(c, deadline, err, errlen) != 0) return -1;

    cJSON *req = cJSON_Parse(json_request);
    char *text = NULL;
    c->pending_id = NULL;
    if (cJSON_IsObject(req)) {
        cJSON *id = cJSON_GetObjectItemCaseSensitive(req, "id");
        if (!id) {
            id = cJSON_AddNumberToObject(req, "id", (double)c->next_id++);
            text = cJSON_PrintUnformatted(req);
        }
        c->pending_id = cJSON_Duplicate(id, 0);
    }
    cJSON_Delete(req);
    const char *send = text ? text : json_request;
    int r = txq_push(c, send, strlen(send), 0);
    free(text);
    if (r != 0) {
        cJSON_Delete(c->pending_id);
        c->pending_id = NULL;
        set_err(err, errlen, "out of memory");
        return -1;
    }
    c->pending = 1;
    c->reply_done = 0;
    c->reply = NULL;
    int rc = -1;
    for (;;) {
        if (c->reply_done) break;
        if (c->state != CONN_OPEN) {
            set_err(err, errlen, "%s", c->reason[0] ? c->reason : "connection lost");
            goto out;
        }
        if (client_now_ms() >= deadline) {
            set_err(err, errlen, "timed out waiting for the server's reply");
            goto out;
        }
        client_service(c);
    }
    cJSON *o = cJSON_Parse(c->reply);
    const char *type = o ? json_str(o, "type") : NULL;
    rc = type && strcmp(type, "error") == 0 ? 1 : 0;
    if (rc == 1)
        set_err(err, errlen, "server error %s: %s", json_str(o, "code") ? json_str(o, "code") : "?",
                json_str(o, "message") ? json_str(o, "message") : "");
    cJSON_Delete(o);
    if (reply_json) {
        *reply_json = c->reply;
        c->reply = NULL;
    }
out:
    free(c->reply);
    c->reply = NULL;
    cJSON_Delete(c->pending_id);
    c->pending_id = NULL;
    c->pending = 0;
    c->reply_done = 0;
    return rc;
}

int lc_client_subscribe(lc_client *c, int stream, int encoding, double max_rate, char *err, size_t errlen) {
    int enc = encoding & ~LC_CLIENT_RESIDUAL;
    if (!c || stream < 1 || stream >= CLIENT_STREAMS || enc < 0 || enc > LC_CLIENT_F32 ||
        ((encoding & LC_CLIENT_RESIDUAL) && stream != LC_CLIENT_LIGHTMAP) || !(max_rate >= 0) || !isfinite(max_rate)) {
        set_err(err, errlen, "bad arguments (stream %d, encoding %d)", stream, encoding);
        return -1;
    }
    cJSON *o = subscribe_json(stream, encoding, max_rate);
    char *t = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    if (!t) {
        set_err(err, errlen, "out of memory");
        return -1;
    }
    /* the server sends the keyframe right after the ok: the copy starts over */
    if (c->views[stream]) lc_client_view_reset(c->views[stream]);
    int r = lc_client_request(c, t, NULL, 0, err, errlen);
    free(t);
    if (r == 0) {
        c->subs[stream].active = 1;
        c->subs[stream].encoding = encoding;
        c->subs[stream].max_rate = max_rate;
    }
    return r;
}

int lc_client_unsubscribe(lc_client *c, int stream, char *err, size_t errlen) {
    if (!c || stream < 1 || stream >= CLIENT_STREAMS) {
        set_err(err, errlen, "bad stream %d", stream);
        return -1;
    }
    char t[96];
    snprintf(t, sizeof t, "{\"type\":\"unsubscribe\",\"stream\":\"%s\"}", lc_proto_stream_name((lc_stream)stream));
    int r = lc_client_request(c, t, NULL, 0, err, errlen);
    if (r == 0) c->subs[stream].active = 0;
    return r;
}

int lc_client_send_binary(lc_client *c, const void *data, size_t len, char *err, size_t errlen) {
    if (!c || !data || !len) {
        set_err(err, errlen, "%s", "no data");
        return -1;
    }
    if (c->state != CONN_OPEN) {
        set_err(err, errlen, "not connected: %s", c->reason[0] ? c->reason : "no welcome yet");
        return -1;
    }
    if (txq_push_kind(c, data, len, 0, 1) != 0) {
        set_err(err, errlen, "%s", "out of memory");
        return -1;
    }
    return 0;
}

int lc_client_poll(lc_client *c, int timeout_ms) {
    if (!c || c->pending) return -1;
    long long deadline = client_now_ms() + (timeout_ms > 0 ? timeout_ms : 0);
    do {
        if (client_service(c) != 0 && c->state == CONN_DEAD) return -1;
    } while (client_now_ms() < deadline);
    return c->state == CONN_DEAD ? -1 : 0;
}

int lc_client_latest_frame(const lc_client *c, int stream, lc_client_frame *out) {
    if (!c || stream < 1 || stream >= CLIENT_STREAMS || !c->views[stream] || !c->views[stream]->have_key) return -1;
    if (out) view_fill_out(c->views[stream], out);
    return 0;
}

int lc_client_wait_frame(lc_client *c, int stream, uint64_t min_revision, int fresh_only, int timeout_ms,
                         lc_client_frame *out, char *err, size_t errlen) {
    if (!c || stream < 1 || stream >= CLIENT_STREAMS || c->pending) {
        set_err(err, errlen, "bad arguments");
        return -1;
    }
    unsigned long start = c->view_frames[stream];
    long long deadline = client_now_ms() + (timeout_ms > 0 ? timeout_ms : c->timeout_ms);
    for (;;) {
        lc_client_view *v = c->views[stream];
        if (v && v->have_key && v->revision >= min_revision && (!fresh_only || c->view_frames[stream] > start)) {
            if (out) view_fill_out(v, out);
            return 0;
        }
        if (c->state == CONN_DEAD) {
            set_err(err, errlen, "%s", c->reason[0] ? c->reason : "connection closed");
            return -1;
        }
        if (client_now_ms() >= deadline) {
            set_err(err, errlen, "timed out waiting for a %s frame", lc_proto_stream_name((lc_stream)stream));
            return -1;
        }
        client_service(c);
    }
}

const char *lc_client_welcome(const lc_client *c) { return c ? c->welcome : NULL; }

int lc_client_connected(const lc_client *c) { return c && c->state == CONN_OPEN; }

void lc_client_get_stats(const lc_client *c, lc_client_stats *out) {
    if (!out) return;
    if (c) *out = c->stats;
    else memset(out, 0, sizeof *out);
}

void lc_client_close(lc_client *c) {
    if (!c) return;
    c->closing = 1;
    if (c->ctx) {
        lws_sul_cancel(&c->tick);
        lws_context_destroy(c->ctx); /* closes the connection */
    }
    txq_clear(c);
    for (int s = 0; s < CLIENT_STREAMS; s++) {
        lc_client_view_release(c->views[s]);
        free(c->view_raw[s]);
    }
    cJSON_Delete(c->pending_id);
    free(c->reply);
    free(c->rx);
    free(c->welcome);
    free(c->hello_error);
    free(c->url);
    free(c->token);
    free(c->name);
    free(c->capabilities);
    free(c->ca_file);
    free(c);
}

/* ------------------------------------------------------------------------------------------
 * SH helpers
 * ---------------------------------------------------------------------------------------- */

void lc_sh9_irradiance(const float sh[27], const float normal[3], float rgb_out[3]) {
    double x = normal[0], y = normal[1], z = normal[2];
    double len = sqrt(x * x + y * y + z * z);
    if (len > 0) {
        x /= len;
        y /= len;
        z /= len;
    }
    /* real orthonormal basis, i = l*l + l + m, band 1 = sqrt(3/4pi) (y, z, x) (PROTOCOL.md §2.3) */
    const double basis[9] = {
        0.28209479177387814,
        0.48860251190291992 * y,
        0.48860251190291992 * z,
        0.48860251190291992 * x,
        1.09254843059207907 * x * y,
        1.09254843059207907 * y * z,
        0.31539156525252001 * (3 * z * z - 1),
        1.09254843059207907 * x * z,
        0.54627421529603954 * (x * x - y * y),
    };
    for (int ch = 0; ch < 3; ch++) {
        double e = 0;
        for (int i = 0; i < 9; i++) e += basis[i] * sh[3 * i + ch];
        rgb_out[ch] = e > 0 ? (float)e : 0.0f;
    }
}

void lc_sh9_to_planar(const float interleaved[27], float planar[27]) {
    for (int i = 0; i < 9; i++)
        for (int ch = 0; ch < 3; ch++) planar[9 * ch + i] = interleaved[3 * i + ch];
}

void lc_sh9_to_interleaved(const float planar[27], float interleaved[27]) {
    for (int i = 0; i < 9; i++)
        for (int ch = 0; ch < 3; ch++) interleaved[3 * i + ch] = planar[9 * ch + i];
}

void lc_sh9_irradiance_to_radiance(const float irradiance[27], float radiance[27]) {
    /* clamped-cosine convolution per band: pi, 2pi/3, pi/4 */
    static const double band_scale[3] = {3.14159265358979323846, 2.09439510239319549, 0.78539816339744831};
    for (int i = 0; i < 9; i++) {
        int l = i == 0 ? 0 : (i < 4 ? 1 : 2);
        for (int ch = 0; ch < 3; ch++) radiance[3 * i + ch] = (float)(irradiance[3 * i + ch] / band_scale[l]);
    }
}

/* Basis constants of lc_sh9_irradiance (y_i = sh9_k[i] * polynomial_i, polynomials 1, y, z, x, xy,
 * yz, 3z^2-1, xz, x^2-y^2) and the clamped-cosine factor A_l of each coefficient. */
static const double sh9_k[9] = {0.28209479177387814, 0.48860251190291992, 0.48860251190291992,
                                0.48860251190291992, 1.09254843059207907, 1.09254843059207907,
                                0.31539156525252001, 1.09254843059207907, 0.54627421529603954};
static const double sh9_a[9] = {3.14159265358979323846, 2.09439510239319549, 2.09439510239319549,
                                2.09439510239319549,    0.78539816339744831, 0.78539816339744831,
                                0.78539816339744831,    0.78539816339744831, 0.78539816339744831};

void lc_sh9_to_unity(const float irradiance[27], float unity[27]) {
    /* Unity's SphericalHarmonicsL2 is premultiplied (HDRP SphericalHarmonicMath.UndoCosineRescaling:
     * A_l * y_lm constant / pi), so ShadeSH9 sums sh[c, i] * polynomial_i(n_unity) = E / pi. glTF
     * (x, y, z) is Unity (-x, y, z): the polynomials odd in x (x, xy, xz) change sign. */
    static const double mirror_x[9] = {1, 1, 1, -1, -1, 1, 1, -1, 1};
    for (int i = 0; i < 9; i++)
        for (int ch = 0; ch < 3; ch++)
            unity[9 * ch + i] = (float)(irradiance[3 * i + ch] * sh9_k[i] * mirror_x[i] / 3.14159265358979323846);
}

void lc_sh9_to_arcore(const float irradiance[27], float arcore[27]) {
    /* Radiance SH (divided by A_l) in ARCore's basis, whose y, x, yz, xz functions carry a minus
     * sign (hello_ar's sphericalHarmonicFactors: -0.325735 for 1 and 3, -0.273137 for 5 and 7).
     * Without the signs the lighting comes out turned by pi about +Z (x and y mirrored). Same axes
     * as glTF (right-handed, +Y up): no axis change. */
    static const double sign[9] = {1, -1, 1, -1, 1, -1, 1, -1, 1};
    for (int i = 0; i < 9; i++)
        for (int ch = 0; ch < 3; ch++) arcore[3 * i + ch] = (float)(irradiance[3 * i + ch] * sign[i] / sh9_a[i]);
}

void lc_sh9_to_threejs(const float irradiance[27], float threejs[27]) {
    lc_sh9_irradiance_to_radiance(irradiance, threejs);
}

void lc_sh9_to_arkit(const float irradiance[27], float arkit[27]) { lc_sh9_to_planar(irradiance, arkit); }
