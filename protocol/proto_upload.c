/* proto_upload: MR upload frames (PROTOCOL.md §8.4); see lucent_upload.h. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "lucent_upload.h"
#include "util/crc32.h"
#include "util/half.h"

static int upload_fail(lc_proto_error *err, lc_proto_errcode code, const char *pointer, const char *fmt, ...) {
    memset(err, 0, sizeof *err);
    lc_proto_error_set_code(err, code);
    snprintf(err->pointer, sizeof err->pointer, "%s", pointer);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
    return -1;
}

static uint16_t rd16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
static uint32_t rd32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static uint64_t rd64(const uint8_t *p) { return rd32(p) | (uint64_t)rd32(p + 4) << 32; }
static float rdf(const uint8_t *p) {
    uint32_t u = rd32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}
static void wr16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v, p[1] = (uint8_t)(v >> 8); }
static void wr32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static void wrf(uint8_t *p, float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    wr32(p, u);
}

size_t lc_upload_depth_bytes(const lc_upload_header *h) { return (size_t)h->width * h->height * 2; }
size_t lc_upload_color_bytes(const lc_upload_header *h) {
    return (size_t)h->width * h->height * (h->color_encoding == LC_COLOR_RGB8_SRGB ? 3 : 6);
}

/* The header's fields into h, each checked (§8.4), before any plane is looked at. */
static int upload_header(const uint8_t *b, lc_upload_header *h, const lc_upload_expect *exp, lc_proto_error *err) {
    memset(h, 0, sizeof *h);
    if (rd32(b) != LC_UPLOAD_MAGIC) return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/magic", "magic is not LCU1");
    if (rd16(b + 4) != 1)
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/version", "upload version %u, expected 1", rd16(b + 4));
    if (b[6] != 1) return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/kind", "kind %u, expected 1 (rgbd)", b[6]);
    if (b[7] & ~1u)
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/flags", "reserved flag bits set (0x%02x)", b[7]);
    if (rd16(b + 8) != LC_UPLOAD_HEADER_SIZE)
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/header_size", "header size %u, expected 128",
                           rd16(b + 8));
    int reserved = rd16(b + 10) != 0;
    for (int i = 33; i < 36; i++) reserved |= b[i] != 0;
    for (int i = 96; i < 124; i++) reserved |= b[i] != 0;
    if (reserved) return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/reserved", "reserved header bytes must be 0");
    h->has_confidence = b[7] & 1;
    h->sequence = rd32(b + 12);
    h->capture_us = rd64(b + 16);
    h->width = rd16(b + 24);
    h->height = rd16(b + 26);
    h->depth_encoding = b[28];
    h->color_encoding = b[29];
    h->depth_zlib = b[30], h->confidence_zlib = b[31], h->color_zlib = b[32];
    if (h->sequence == 0) return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/sequence", "sequence must be >= 1");
    if (h->width < 8 || h->width > 1024 || (exp && h->width != exp->width))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/width", "width %u (the session's is %u)", h->width,
                           exp ? exp->width : 0);
    if (h->height < 8 || h->height > 1024 || (size_t)h->width * h->height > LC_UPLOAD_MAX_PIXELS ||
        (exp && h->height != exp->height))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/height", "height %u (the session's is %u)", h->height,
                           exp ? exp->height : 0);
    if ((h->depth_encoding != LC_DEPTH_U16MM && h->depth_encoding != LC_DEPTH_F16M) ||
        (exp && h->depth_encoding != exp->depth_encoding))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/depth_encoding", "depth encoding %u", h->depth_encoding);
    if ((h->color_encoding != LC_COLOR_RGB8_SRGB && h->color_encoding != LC_COLOR_RGB16F_LINEAR) ||
        (exp && h->color_encoding != exp->color_encoding))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/color_encoding", "colour encoding %u",
                           h->color_encoding);
    static const char *const comp_ptr[3] = {"/header/depth_compression", "/header/confidence_compression",
                                            "/header/color_compression"};
    for (int i = 0; i < 3; i++)
        if (b[30 + i] > 1 || (i == 1 && !h->has_confidence && b[31]))
            return upload_fail(err, LC_ERR_FRAME_INVALID, comp_ptr[i], "compression %u (0 none, 1 zlib)", b[30 + i]);
    h->fx = rdf(b + 36), h->fy = rdf(b + 40), h->cx = rdf(b + 44), h->cy = rdf(b + 48);
    if (!(h->fx > 0 && h->fx <= 1e5f))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/fx", "fx must be in (0, 1e5]");
    if (!(h->fy > 0 && h->fy <= 1e5f))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/fy", "fy must be in (0, 1e5]");
    if (!(h->cx >= -(float)h->width && h->cx <= 2.0f * h->width))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/cx", "cx must be in [-width, 2 width]");
    if (!(h->cy >= -(float)h->height && h->cy <= 2.0f * h->height))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/cy", "cy must be in [-height, 2 height]");
    for (int i = 0; i < 3; i++) {
        h->translation[i] = rdf(b + 52 + 4 * i);
        if (!(fabsf(h->translation[i]) <= 1e6f))
            return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/translation",
                               "translation must be finite, |t| <= 1e6");
    }
    double n2 = 0;
    for (int i = 0; i < 4; i++) {
        h->rotation[i] = rdf(b + 64 + 4 * i);
        n2 += (double)h->rotation[i] * h->rotation[i];
    }
    if (!(n2 >= 0.81 && n2 <= 1.21))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/rotation",
                           "rotation must be a unit quaternion (norm 0.9..1.1)");
    for (int i = 0; i < 4; i++) h->rotation[i] = (float)(h->rotation[i] / sqrt(n2));
    h->exposure = rdf(b + 80);
    if (!(h->exposure > 0 && h->exposure <= 1e7f))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/exposure", "exposure must be in (0, 1e7]");
    return 0;
}

/* One plane: raw (exact size) or zlib inflating to exactly `raw` bytes. */
static int upload_plane(const uint8_t *src, size_t sent, int zlib_on, size_t raw, uint8_t **dst, const char *name,
                        lc_proto_error *err) {
    char ptr[32];
    *dst = malloc(raw ? raw : 1);
    if (!*dst) return upload_fail(err, LC_ERR_INTERNAL, "", "out of memory");
    if (!zlib_on) {
        if (sent != raw) {
            snprintf(ptr, sizeof ptr, "/header/%s_bytes", name);
            return upload_fail(err, LC_ERR_FRAME_INVALID, ptr, "the %s plane has %zu bytes, its size is %zu", name,
                               sent, raw);
        }
        memcpy(*dst, src, raw);
        return 0;
    }
    snprintf(ptr, sizeof ptr, "/%s/zlib", name);
    z_stream z;
    memset(&z, 0, sizeof z);
    if (inflateInit(&z) != Z_OK) return upload_fail(err, LC_ERR_INTERNAL, "", "zlib init failed");
    z.next_in = (Bytef *)src;
    z.avail_in = (uInt)sent;
    z.next_out = *dst;
    z.avail_out = (uInt)raw;
    int rc = inflate(&z, Z_FINISH);
    size_t out = raw - z.avail_out, left = z.avail_in;
    inflateEnd(&z);
    if (rc != Z_STREAM_END || out != raw || left)
        return upload_fail(err, LC_ERR_FRAME_INVALID, ptr,
                           "the %s plane's zlib stream is corrupt or does not inflate to exactly %zu bytes", name, raw);
    return 0;
}

void lc_upload_frame_release(lc_upload_frame *f) {
    if (!f) return;
    free(f->depth);
    free(f->confidence);
    free(f->color);
    f->depth = f->confidence = f->color = NULL;
}

int lc_upload_parse(const uint8_t *buf, size_t len, const lc_upload_expect *exp, lc_upload_frame *out,
                    lc_proto_error *err) {
    memset(out, 0, sizeof *out);
    size_t max = exp ? exp->max_frame : LC_UPLOAD_MAX_FRAME_DEFAULT;
    if (len > max)
        return upload_fail(err, LC_ERR_FRAME_TOO_LARGE, "/frame/length", "the frame has %zu bytes, the limit is %zu",
                           len, max);
    if (!buf || len < LC_UPLOAD_HEADER_SIZE)
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/frame/length", "%zu bytes: shorter than the 128-byte header",
                           len);
    lc_upload_header h;
    if (upload_header(buf, &h, exp, err) != 0) return -1;
    uint64_t sizes[3] = {rd32(buf + 84), rd32(buf + 88), rd32(buf + 92)};
    if (!h.has_confidence && sizes[1])
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/confidence_bytes", "no confidence plane, but %llu bytes",
                           (unsigned long long)sizes[1]);
    if (LC_UPLOAD_HEADER_SIZE + sizes[0] + sizes[1] + sizes[2] != len)
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/frame/length",
                           "%zu bytes, the header says 128 + %llu + %llu + %llu", len, (unsigned long long)sizes[0],
                           (unsigned long long)sizes[1], (unsigned long long)sizes[2]);
    uint32_t crc = lc_crc32(lc_crc32(0, buf, 124), buf + LC_UPLOAD_HEADER_SIZE, len - LC_UPLOAD_HEADER_SIZE);
    if (crc != rd32(buf + 124))
        return upload_fail(err, LC_ERR_FRAME_INVALID, "/header/crc",
                           "CRC-32 mismatch (0x%08x in the header, 0x%08x computed)", rd32(buf + 124), crc);
    const uint8_t *p = buf + LC_UPLOAD_HEADER_SIZE;
    size_t px = (size_t)h.width * h.height;
    out->h = h;
    if (upload_plane(p, sizes[0], h.depth_zlib, lc_upload_depth_bytes(&h), &out->depth, "depth", err) != 0) goto err;
    p += sizes[0];
    if (h.has_confidence && upload_plane(p, sizes[1], h.confidence_zlib, px, &out->confidence, "confidence", err) != 0)
        goto err;
    p += sizes[1];
    if (upload_plane(p, sizes[2], h.color_zlib, lc_upload_color_bytes(&h), &out->color, "color", err) != 0) goto err;
    return 0;
err:
    lc_upload_frame_release(out);
    return -1;
}

/* A plane as sent: raw or deflated (level 1: the client's CPU is a phone's). */
static int upload_pack(const void *raw, size_t n, int zlib_on, uint8_t **out, size_t *out_len) {
    if (!zlib_on) {
        *out = malloc(n ? n : 1);
        if (!*out) return -1;
        memcpy(*out, raw, n);
        *out_len = n;
        return 0;
    }
    uLongf cap = compressBound((uLong)n);
    *out = malloc(cap);
    if (!*out || compress2(*out, &cap, raw, (uLong)n, 1) != Z_OK) return -1;
    *out_len = cap;
    return 0;
}

int lc_upload_encode(const lc_upload_header *h, const void *depth, const void *confidence, const void *color,
                     uint8_t **out, size_t *out_len, char *err, size_t errlen) {
    uint8_t *planes[3] = {NULL, NULL, NULL};
    size_t lens[3] = {0, 0, 0};
    int rc = -1;
    *out = NULL;
    if ((confidence != NULL) != (h->has_confidence != 0)) {
        snprintf(err, errlen, "confidence plane given iff has_confidence");
        goto done;
    }
    size_t px = (size_t)h->width * h->height;
    if (upload_pack(depth, lc_upload_depth_bytes(h), h->depth_zlib, &planes[0], &lens[0]) != 0 ||
        (confidence && upload_pack(confidence, px, h->confidence_zlib, &planes[1], &lens[1]) != 0) ||
        upload_pack(color, lc_upload_color_bytes(h), h->color_zlib, &planes[2], &lens[2]) != 0) {
        snprintf(err, errlen, "out of memory compressing the planes");
        goto done;
    }
    size_t total = LC_UPLOAD_HEADER_SIZE + lens[0] + lens[1] + lens[2];
    uint8_t *b = calloc(1, total);
    if (!b) {
        snprintf(err, errlen, "out of memory");
        goto done;
    }
    wr32(b, LC_UPLOAD_MAGIC);
    wr16(b + 4, 1);
    b[6] = 1;
    b[7] = h->has_confidence ? 1 : 0;
    wr16(b + 8, LC_UPLOAD_HEADER_SIZE);
    wr32(b + 12, h->sequence);
    wr32(b + 16, (uint32_t)h->capture_us);
    wr32(b + 20, (uint32_t)(h->capture_us >> 32));
    wr16(b + 24, h->width);
    wr16(b + 26, h->height);
    b[28] = h->depth_encoding, b[29] = h->color_encoding;
    b[30] = h->depth_zlib ? 1 : 0, b[31] = confidence && h->confidence_zlib ? 1 : 0, b[32] = h->color_zlib ? 1 : 0;
    wrf(b + 36, h->fx), wrf(b + 40, h->fy), wrf(b + 44, h->cx), wrf(b + 48, h->cy);
    for (int i = 0; i < 3; i++) wrf(b + 52 + 4 * i, h->translation[i]);
    for (int i = 0; i < 4; i++) wrf(b + 64 + 4 * i, h->rotation[i]);
    wrf(b + 80, h->exposure);
    uint8_t *p = b + LC_UPLOAD_HEADER_SIZE;
    for (int i = 0; i < 3; i++) {
        wr32(b + 84 + 4 * i, (uint32_t)lens[i]);
        if (lens[i]) memcpy(p, planes[i], lens[i]);
        p += lens[i];
    }
    wr32(b + 124, lc_crc32(lc_crc32(0, b, 124), b + LC_UPLOAD_HEADER_SIZE, total - LC_UPLOAD_HEADER_SIZE));
    *out = b;
    *out_len = total;
    rc = 0;
done:
    for (int i = 0; i < 3; i++) free(planes[i]);
    return rc;
}

void lc_upload_depth_metres(const lc_upload_frame *f, float *out) {
    size_t n = (size_t)f->h.width * f->h.height;
    for (size_t i = 0; i < n; i++) {
        uint16_t v = rd16(f->depth + 2 * i);
        float z = f->h.depth_encoding == LC_DEPTH_U16MM ? v * 1e-3f : lc_half_to_float(v);
        out[i] = z > 0 && isfinite(z) ? z : 0;
    }
}

static float upload_srgb_eotf(float v) { return v <= 0.04045f ? v / 12.92f : powf((v + 0.055f) / 1.055f, 2.4f); }

void lc_upload_radiance(const lc_upload_frame *f, float *rgb_out) {
    size_t n = (size_t)f->h.width * f->h.height * 3;
    if (f->h.color_encoding == LC_COLOR_RGB8_SRGB) {
        float lut[256];
        for (int i = 0; i < 256; i++) lut[i] = upload_srgb_eotf(i / 255.0f) * f->h.exposure;
        for (size_t i = 0; i < n; i++) rgb_out[i] = lut[f->color[i]];
        return;
    }
    for (size_t i = 0; i < n; i++) {
        float v = lc_half_to_float(rd16(f->color + 2 * i));
        rgb_out[i] = isfinite(v) && v > 0 ? v * f->h.exposure : 0;
    }
}

void lc_upload_confidence(const lc_upload_frame *f, float *out) {
    size_t n = (size_t)f->h.width * f->h.height;
    for (size_t i = 0; i < n; i++) out[i] = f->confidence ? f->confidence[i] / 255.0f : 1.0f;
}
