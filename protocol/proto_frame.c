/* proto_frame: lucent/1 binary data frames (PROTOCOL.md §6), RGB9E5 and lightmap tiles.
 * Byte order is written and read explicitly (little-endian on any host). */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include <zlib.h>

#include "lucent_proto.h"
#include "util/crc32.h"
#include "util/half.h"

#define PROTO_FRAME_CRC_OFFSET 60
#define PROTO_OBJECT_ID_BYTES 64
#define PROTO_SH_VALUES 27

static void proto_put16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static void proto_put32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static void proto_put64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static uint16_t proto_get16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }

static uint32_t proto_get32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t proto_get64(const uint8_t *p) { return (uint64_t)proto_get32(p) | (uint64_t)proto_get32(p + 4) << 32; }

size_t lc_frame_texel_bytes(lc_encoding e) {
    switch (e) {
    case LC_ENC_RGB9E5: return 4;
    case LC_ENC_RGBA16F: return 8;
    case LC_ENC_F32: return 12;
    default: return 0;
    }
}

size_t lc_frame_sh_value_bytes(lc_encoding e) {
    switch (e) {
    case LC_ENC_RGBA16F: return 2;
    case LC_ENC_F32: return 4;
    default: return 0;
    }
}

uint32_t lc_tiles_count(uint32_t w, uint32_t h, uint32_t s) {
    if (!s) return 0;
    uint64_t n = (uint64_t)((w + (uint64_t)s - 1) / s) * ((h + (uint64_t)s - 1) / s);
    return n > UINT32_MAX ? UINT32_MAX : (uint32_t)n;
}

void lc_tile_rect(uint32_t w, uint32_t h, uint32_t s, uint32_t t, uint32_t *x0, uint32_t *y0, uint32_t *x1,
                  uint32_t *y1) {
    *x0 = *y0 = *x1 = *y1 = 0;
    if (!s || !w || !h) return;
    uint64_t tw = (w + (uint64_t)s - 1) / s;
    uint64_t ax = (t % tw) * s, ay = (t / tw) * s;
    /* tiles past the image clip to an empty rectangle */
    if (ax > w) ax = w;
    if (ay > h) ay = h;
    uint64_t bx = ax + s < w ? ax + s : w, by = ay + s < h ? ay + s : h;
    *x0 = (uint32_t)ax;
    *y0 = (uint32_t)ay;
    *x1 = (uint32_t)bx;
    *y1 = (uint32_t)by;
}

/* Writes the frame without its CRC; returns the length, 0 if it does not fit. */
static size_t proto_frame_put(const lc_frame_header *h, const uint32_t *tiles, const void *payload, uint8_t *out,
                              size_t cap) {
    if (!h || !out) return 0;
    uint64_t total = LC_FRAME_HEADER_SIZE + (uint64_t)h->tile_count * 4 + h->payload_length;
    if (total > cap || (h->tile_count && !tiles) || (h->payload_length && !payload)) return 0;
    uint8_t *p = out;
    proto_put32(p + 0, LC_FRAME_MAGIC);
    proto_put16(p + 4, h->version ? h->version : 1);
    p[6] = h->stream;
    p[7] = h->encoding;
    proto_put16(p + 8,
                (uint16_t)((h->flags & 7u) | (h->converged ? LC_FRAME_CONVERGED_BIT : 0) |
                           ((unsigned)h->pass << LC_FRAME_PASS_SHIFT)));
    proto_put16(p + 10, LC_FRAME_HEADER_SIZE);
    proto_put32(p + 12, h->tile_count);
    proto_put64(p + 16, h->revision);
    proto_put64(p + 24, h->sequence);
    proto_put64(p + 32, h->timestamp_us);
    proto_put32(p + 40, h->width);
    proto_put32(p + 44, h->height);
    proto_put32(p + 48, h->depth);
    proto_put32(p + 52, h->tile_size);
    proto_put32(p + 56, h->payload_length);
    for (uint32_t i = 0; i < h->tile_count; i++) proto_put32(p + LC_FRAME_HEADER_SIZE + 4 * (size_t)i, tiles[i]);
    if (h->payload_length) memcpy(p + LC_FRAME_HEADER_SIZE + 4 * (size_t)h->tile_count, payload, h->payload_length);
    return (size_t)total;
}

size_t lc_frame_write(const lc_frame_header *h, const uint32_t *tiles, const void *payload, uint8_t *out, size_t cap) {
    size_t total = proto_frame_put(h, tiles, payload, out, cap);
    if (!total) return 0;
    /* CRC over bytes 0..59, then everything after the header */
    uint32_t crc = lc_crc32(0, out, PROTO_FRAME_CRC_OFFSET);
    crc = lc_crc32(crc, out + LC_FRAME_HEADER_SIZE, total - LC_FRAME_HEADER_SIZE);
    proto_put32(out + PROTO_FRAME_CRC_OFFSET, crc);
    return total;
}

uint32_t lc_frame_body_crc(const lc_frame_header *h, const uint32_t *tiles, const void *payload) {
    uint32_t crc = 0;
    uint8_t le[256]; /* the table as written (little-endian), a chunk at a time */
    for (uint32_t i = 0; i < h->tile_count;) {
        uint32_t n = 0;
        for (; n < sizeof le / 4 && i < h->tile_count; n++, i++) proto_put32(le + 4 * n, tiles[i]);
        crc = lc_crc32(crc, le, 4 * (size_t)n);
    }
    return h->payload_length ? lc_crc32(crc, payload, h->payload_length) : crc;
}

size_t lc_frame_write_body_crc(const lc_frame_header *h, const uint32_t *tiles, const void *payload, uint32_t body_crc,
                               uint8_t *out, size_t cap) {
    size_t total = proto_frame_put(h, tiles, payload, out, cap);
    if (!total) return 0;
    uint32_t crc = lc_crc32(0, out, PROTO_FRAME_CRC_OFFSET);
    crc = (uint32_t)crc32_combine(crc, body_crc, (z_off_t)(total - LC_FRAME_HEADER_SIZE));
    proto_put32(out + PROTO_FRAME_CRC_OFFSET, crc);
    return total;
}

static int proto_bad(lc_proto_error *err, const char *fmt, const char *detail) {
    if (err) {
        snprintf(err->code, sizeof err->code, "bad_frame");
        err->pointer[0] = 0;
        snprintf(err->message, sizeof err->message, fmt, detail);
    }
    return -1;
}

/* a * b, saturating at UINT64_MAX (any such product exceeds every real length) */
static uint64_t proto_mul(uint64_t a, uint64_t b) {
    if (a && b > (UINT64_MAX / 2) / a) return UINT64_MAX;
    return a * b;
}

/* §8.7: `width` blocks of 64-byte id, u32 P, u32 0, P records; the P sum to `height`. The
 * payload length was checked against the frame length; this walks the blocks inside it. */
static int proto_mr_vpl_check(const lc_frame_header *h, int key, const uint8_t *pl, lc_proto_error *err) {
    size_t vb = lc_frame_sh_value_bytes((lc_encoding)h->encoding);
    if (!vb) return proto_bad(err, "%s", "bad mr.vpl encoding");
    if (!key) return proto_bad(err, "%s", "mr.vpl sends keyframes only");
    if (h->tile_size) return proto_bad(err, "%s", "tile size must be 0 for mr.vpl");
    if (h->depth != 1) return proto_bad(err, "%s", "mr.vpl: depth must be 1");
    uint64_t at = 0, points = 0, rec = LC_FRAME_MR_VPL_VALUES * vb;
    for (uint32_t i = 0; i < h->width; i++) {
        if (h->payload_length - at < LC_FRAME_MR_VPL_BLOCK_HEADER)
            return proto_bad(err, "%s", "mr.vpl: payload length does not match the objects");
        uint32_t p = proto_get32(pl + at + PROTO_OBJECT_ID_BYTES);
        if (proto_get32(pl + at + PROTO_OBJECT_ID_BYTES + 4))
            return proto_bad(err, "%s", "mr.vpl: reserved word is not 0");
        at += LC_FRAME_MR_VPL_BLOCK_HEADER;
        if (p > (h->payload_length - at) / rec)
            return proto_bad(err, "%s", "mr.vpl: payload length does not match the point counts");
        at += p * rec;
        points += p;
    }
    if (points != h->height) return proto_bad(err, "%s", "mr.vpl: point counts do not sum to the height");
    if (at != h->payload_length) return proto_bad(err, "%s", "payload length does not match the stream");
    return 0;
}

size_t lc_frame_mr_vpl_block_bytes(lc_encoding e, uint32_t points) {
    size_t vb = lc_frame_sh_value_bytes(e);
    if (!vb) return 0;
    return LC_FRAME_MR_VPL_BLOCK_HEADER + (size_t)points * LC_FRAME_MR_VPL_VALUES * vb;
}

size_t lc_frame_mr_vpl_block(lc_encoding e, const char *id, uint32_t points, const float *records, uint8_t *out,
                             size_t cap) {
    size_t n = lc_frame_mr_vpl_block_bytes(e, points), vb = lc_frame_sh_value_bytes(e);
    if (!n || n > cap || !out || (points && !records)) return 0;
    memset(out, 0, PROTO_OBJECT_ID_BYTES);
    if (id) memcpy(out, id, strnlen(id, PROTO_OBJECT_ID_BYTES));
    proto_put32(out + PROTO_OBJECT_ID_BYTES, points);
    proto_put32(out + PROTO_OBJECT_ID_BYTES + 4, 0);
    uint8_t *o = out + LC_FRAME_MR_VPL_BLOCK_HEADER;
    for (size_t k = 0; k < (size_t)points * LC_FRAME_MR_VPL_VALUES; k++, o += vb) {
        float v = records[k];
        if (vb == 2) {
            proto_put16(o, lc_half_from_float(v));
        } else {
            uint32_t bits;
            memcpy(&bits, &v, 4);
            proto_put32(o, bits);
        }
    }
    return n;
}

int lc_frame_mr_vpl_next(const lc_frame_header *h, const uint8_t *payload, size_t *at, char id[LC_PROTO_ID_MAX + 1],
                         uint32_t *points, const uint8_t **records) {
    if (!h || !payload || !at || h->stream != LC_STREAM_MR_VPL) return -1;
    size_t vb = lc_frame_sh_value_bytes((lc_encoding)h->encoding), len = h->payload_length;
    if (!vb || *at > len || len - *at < LC_FRAME_MR_VPL_BLOCK_HEADER) return -1;
    const uint8_t *b = payload + *at;
    uint32_t p = proto_get32(b + PROTO_OBJECT_ID_BYTES);
    size_t rec = LC_FRAME_MR_VPL_VALUES * vb;
    if (p > (len - *at - LC_FRAME_MR_VPL_BLOCK_HEADER) / rec) return -1;
    if (id) {
        size_t n = strnlen((const char *)b, PROTO_OBJECT_ID_BYTES);
        memcpy(id, b, n);
        id[n] = 0;
    }
    if (points) *points = p;
    if (records) *records = b + LC_FRAME_MR_VPL_BLOCK_HEADER;
    *at += LC_FRAME_MR_VPL_BLOCK_HEADER + (size_t)p * rec;
    return 0;
}

int lc_frame_parse(const uint8_t *data, size_t len, lc_frame_header *h, const uint8_t **tile_table,
                   const uint8_t **payload, lc_proto_error *err) {
    lc_frame_header tmp;
    if (!h) h = &tmp;
    memset(h, 0, sizeof *h);
    if (tile_table) *tile_table = NULL;
    if (payload) *payload = NULL;
    if (err) memset(err, 0, sizeof *err);
    if (!data || len < LC_FRAME_HEADER_SIZE) return proto_bad(err, "%s", "shorter than the 64-byte header");
    if (proto_get32(data) != LC_FRAME_MAGIC) return proto_bad(err, "%s", "bad magic");
    h->version = proto_get16(data + 4);
    h->stream = data[6];
    h->encoding = data[7];
    uint16_t flags = proto_get16(data + 8);
    h->flags = flags & 7u; /* bits 4-7 are reserved: ignored, for forward compatibility */
    h->converged = (flags & LC_FRAME_CONVERGED_BIT) != 0;
    h->pass = (uint8_t)(flags >> LC_FRAME_PASS_SHIFT);
    uint16_t hsize = proto_get16(data + 10);
    h->tile_count = proto_get32(data + 12);
    h->revision = proto_get64(data + 16);
    h->sequence = proto_get64(data + 24);
    h->timestamp_us = proto_get64(data + 32);
    h->width = proto_get32(data + 40);
    h->height = proto_get32(data + 44);
    h->depth = proto_get32(data + 48);
    h->tile_size = proto_get32(data + 52);
    h->payload_length = proto_get32(data + 56);
    h->crc = proto_get32(data + 60);
    if (h->version != 1) return proto_bad(err, "%s", "unsupported version");
    if (hsize != LC_FRAME_HEADER_SIZE) return proto_bad(err, "%s", "header size is not 64");
    uint64_t total = LC_FRAME_HEADER_SIZE + (uint64_t)h->tile_count * 4 + h->payload_length;
    if (total != len) return proto_bad(err, "%s", "length does not match tile count and payload length");
    uint32_t crc = lc_crc32(0, data, PROTO_FRAME_CRC_OFFSET);
    crc = lc_crc32(crc, data + LC_FRAME_HEADER_SIZE, len - LC_FRAME_HEADER_SIZE);
    if (crc != h->crc) return proto_bad(err, "%s", "CRC mismatch");

    if (h->flags != LC_FRAME_KEYFRAME && h->flags != LC_FRAME_DELTA && h->flags != (LC_FRAME_DELTA | LC_FRAME_RESIDUAL))
        return proto_bad(err, "%s", "flags must be keyframe, delta or delta + residual");
    int key = h->flags == LC_FRAME_KEYFRAME, residual = (h->flags & LC_FRAME_RESIDUAL) != 0;
    if (residual && h->stream != LC_STREAM_LIGHTMAP) return proto_bad(err, "%s", "residual deltas are lightmap only");
    if (key && h->tile_count) return proto_bad(err, "%s", "a keyframe has no tile table");
    const uint8_t *tiles = data + LC_FRAME_HEADER_SIZE;
    uint64_t expect;
    switch (h->stream) {
    case LC_STREAM_LIGHTMAP: {
        size_t tb = lc_frame_texel_bytes((lc_encoding)h->encoding);
        if (!tb) return proto_bad(err, "%s", "bad lightmap encoding");
        if (!h->width || !h->height || h->depth != 1) return proto_bad(err, "%s", "bad lightmap dimensions");
        if (key) {
            expect = proto_mul(proto_mul(h->width, h->height), tb);
            break;
        }
        if (!h->tile_size) return proto_bad(err, "%s", "a delta needs a tile size");
        uint64_t ntiles = (uint64_t)((h->width + (uint64_t)h->tile_size - 1) / h->tile_size) *
            ((h->height + (uint64_t)h->tile_size - 1) / h->tile_size);
        expect = 0;
        for (uint32_t i = 0; i < h->tile_count; i++) {
            uint32_t t = proto_get32(tiles + 4 * (size_t)i), x0, y0, x1, y1;
            if (t >= ntiles) return proto_bad(err, "%s", "tile index outside the image");
            if (i && t <= proto_get32(tiles + 4 * (size_t)(i - 1)))
                return proto_bad(err, "%s", "tile indices not strictly ascending");
            lc_tile_rect(h->width, h->height, h->tile_size, t, &x0, &y0, &x1, &y1);
            uint64_t bytes = proto_mul(proto_mul(x1 - x0, y1 - y0), tb);
            if (residual) continue;                 /* its payload is compressed: the inflate checks the size */
            if (bytes > h->payload_length - expect) /* also keeps the sum from wrapping */
                return proto_bad(err, "%s", "payload length does not match the tiles");
            expect += bytes;
        }
        if (residual) {
            if (!h->tile_count || !h->payload_length) return proto_bad(err, "%s", "an empty residual delta");
            expect = h->payload_length;
        }
        break;
    }
    case LC_STREAM_SHGRID:
    case LC_STREAM_OBJECTS: {
        size_t vb = lc_frame_sh_value_bytes((lc_encoding)h->encoding);
        if (!vb) return proto_bad(err, "%s", "bad SH encoding");
        if (!key) return proto_bad(err, "%s", "SH streams send keyframes only");
        if (h->tile_size) return proto_bad(err, "%s", "tile size must be 0 for SH streams");
        if (h->stream == LC_STREAM_SHGRID) {
            if (!h->width || !h->height || !h->depth) return proto_bad(err, "%s", "bad grid dimensions");
            expect = proto_mul(proto_mul(proto_mul(h->width, h->height), h->depth), PROTO_SH_VALUES * vb);
        } else {
            if (h->height != 1 || h->depth != 1) return proto_bad(err, "%s", "objects: height and depth must be 1");
            expect = proto_mul(h->width, PROTO_OBJECT_ID_BYTES + PROTO_SH_VALUES * vb);
        }
        break;
    }
    case LC_STREAM_MR_VPL:
        if (proto_mr_vpl_check(h, key, tiles + 4 * (size_t)h->tile_count, err) < 0) return -1;
        expect = h->payload_length;
        break;
    default: return proto_bad(err, "%s", "unknown stream");
    }
    if (expect != h->payload_length) return proto_bad(err, "%s", "payload length does not match the stream");
    if (tile_table) *tile_table = tiles;
    if (payload) *payload = tiles + 4 * (size_t)h->tile_count;
    return 0;
}

/* --- RGB9E5: EXT_texture_shared_exponent, N = 9, B = 15, Emax = 31 ----------------------- */

#define PROTO_E5_N 9
#define PROTO_E5_B 15
#define PROTO_E5_MAX 65408.0 /* (2^9 - 1) / 2^9 * 2^(31 - 15) */

static double proto_e5_clamp(float v) {
    if (!(v > 0)) return 0; /* negatives and NaN */
    return v > PROTO_E5_MAX ? PROTO_E5_MAX : (double)v;
}

/* 2^k exactly, for k in [-1022, 1023]: the scales below are powers of two, so building them from
 * bits (and multiplying by the inverse) gives the bytes frexp/ldexp/division gave, 4x faster
 * (a server encodes every texel of every published lightmap). */
static inline double proto_pow2(int k) {
    uint64_t bits = (uint64_t)(k + 1023) << 52;
    double d;
    memcpy(&d, &bits, sizeof d);
    return d;
}

uint32_t lc_rgb9e5_encode(const float rgb[3]) {
    double r = proto_e5_clamp(rgb[0]), g = proto_e5_clamp(rgb[1]), b = proto_e5_clamp(rgb[2]);
    double m = r > g ? r : g;
    m = m > b ? m : b;
    int fl = -PROTO_E5_B - 1; /* floor(log2(m)), at least -B-1 */
    if (m > 0) {
        uint64_t bits; /* m is a normal double: its exponent field is floor(log2(m)) + 1023 */
        memcpy(&bits, &m, sizeof bits);
        int e = (int)(bits >> 52) - 1023;
        if (e > fl) fl = e;
    }
    int exp = fl + 1 + PROTO_E5_B;
    /* round(m / 2^(exp - B - N)) needs a 10th bit: one exponent up */
    if ((uint32_t)(m * proto_pow2(PROTO_E5_B + PROTO_E5_N - exp) + 0.5) >= (1u << PROTO_E5_N)) exp++;
    const double inv_scale = proto_pow2(PROTO_E5_B + PROTO_E5_N - exp);
    uint32_t rs = (uint32_t)(r * inv_scale + 0.5), gs = (uint32_t)(g * inv_scale + 0.5),
             bs = (uint32_t)(b * inv_scale + 0.5);
    return rs | gs << 9 | bs << 18 | (uint32_t)exp << 27;
}

void lc_rgb9e5_decode(uint32_t v, float rgb[3]) {
    const double scale = proto_pow2((int)(v >> 27) - PROTO_E5_B - PROTO_E5_N);
    rgb[0] = (float)((v & 0x1FF) * scale);
    rgb[1] = (float)(((v >> 9) & 0x1FF) * scale);
    rgb[2] = (float)(((v >> 18) & 0x1FF) * scale);
}

/* --- residual deltas (§6.2.1) --------------------------------------------------------------- */

/* The fields of one encoded texel: words of `word_bytes` (little-endian), each cut into
 * fields at the given bit offsets and widths; rgba16f and f32 have one field per word. */
typedef struct {
    size_t word_bytes, words;
    int n_fields;
    uint8_t offset[4], width[4];
} proto_residual_layout;

static int proto_residual_layout_of(lc_encoding e, proto_residual_layout *l) {
    static const proto_residual_layout rgb9e5 = {4, 1, 4, {0, 9, 18, 27}, {9, 9, 9, 5}}, rgba16f = {2, 4, 1, {0}, {16}},
                                       f32 = {4, 3, 1, {0}, {32}};
    switch (e) {
    case LC_ENC_RGB9E5: *l = rgb9e5; return 0;
    case LC_ENC_RGBA16F: *l = rgba16f; return 0;
    case LC_ENC_F32: *l = f32; return 0;
    }
    return -1;
}

static uint32_t proto_get_word(const uint8_t *p, size_t bytes) { return bytes == 2 ? proto_get16(p) : proto_get32(p); }

static void proto_put_word(uint8_t *p, size_t bytes, uint32_t v) {
    if (bytes == 2) proto_put16(p, (uint16_t)v);
    else proto_put32(p, v);
}

void lc_residual_make(lc_encoding e, const uint8_t *now, const uint8_t *held, size_t texels, uint8_t *out) {
    proto_residual_layout l;
    if (proto_residual_layout_of(e, &l) != 0) return;
    for (size_t w = 0; w < texels * l.words; w++) {
        size_t at = w * l.word_bytes;
        uint32_t a = proto_get_word(now + at, l.word_bytes), b = proto_get_word(held + at, l.word_bytes), r = 0;
        for (int f = 0; f < l.n_fields; f++) {
            uint64_t mask = (1ull << l.width[f]) - 1;
            uint64_t d = (((uint64_t)a >> l.offset[f]) - ((uint64_t)b >> l.offset[f])) & mask;
            uint64_t zz = ((d << 1) & mask) ^ ((d >> (l.width[f] - 1)) ? mask : 0); /* zigzag */
            r |= (uint32_t)(zz << l.offset[f]);
        }
        proto_put_word(out + at, l.word_bytes, r);
    }
}

void lc_residual_apply(lc_encoding e, uint8_t *held, const uint8_t *residual, size_t texels) {
    proto_residual_layout l;
    if (proto_residual_layout_of(e, &l) != 0) return;
    for (size_t w = 0; w < texels * l.words; w++) {
        size_t at = w * l.word_bytes;
        uint32_t b = proto_get_word(held + at, l.word_bytes), z = proto_get_word(residual + at, l.word_bytes), v = 0;
        for (int f = 0; f < l.n_fields; f++) {
            uint64_t mask = (1ull << l.width[f]) - 1, zf = ((uint64_t)z >> l.offset[f]) & mask;
            uint64_t d = (zf >> 1) ^ ((zf & 1) ? mask : 0); /* unzigzag, modulo 2^w */
            v |= (uint32_t)(((((uint64_t)b >> l.offset[f]) + d) & mask) << l.offset[f]);
        }
        proto_put_word(held + at, l.word_bytes, v);
    }
}

size_t lc_residual_deflate_bound(size_t n) { return (size_t)compressBound((uLong)n); }

size_t lc_residual_deflate(const uint8_t *in, size_t n, uint8_t *out, size_t cap) {
    uLongf len = (uLongf)cap;
    /* The fastest level: the service thread deflates once per client per frame, and higher
     * levels save little on residuals (docs/ARCHITECTURE.md, Decisions). */
    if (n > UINT32_MAX || compress2(out, &len, in, (uLong)n, Z_BEST_SPEED) != Z_OK) return 0;
    return (size_t)len;
}

int lc_residual_inflate(const uint8_t *in, size_t n, uint8_t *out, size_t expect) {
    if (n > UINT32_MAX || expect > UINT32_MAX) return -1;
    z_stream z;
    memset(&z, 0, sizeof z);
    if (inflateInit(&z) != Z_OK) return -1;
    z.next_in = (Bytef *)(uintptr_t)in; /* zlib's API is not const-correct; it does not write */
    z.avail_in = (uInt)n;
    z.next_out = out;
    z.avail_out = (uInt)expect;
    int r = inflate(&z, Z_FINISH);
    int ok = r == Z_STREAM_END && z.avail_in == 0 && z.total_out == expect;
    inflateEnd(&z);
    return ok ? 0 : -1;
}

size_t lc_frame_tile_texels(const lc_frame_header *h, const uint8_t *tile_table) {
    size_t n = 0;
    for (uint32_t i = 0; i < h->tile_count; i++) {
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(h->width, h->height, h->tile_size, proto_get32(tile_table + 4 * (size_t)i), &x0, &y0, &x1, &y1);
        n += (size_t)(x1 - x0) * (y1 - y0);
    }
    return n;
}
