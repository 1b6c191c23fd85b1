/* MR upload frames (PROTOCOL.md §8.4): encode -> parse round trips for every encoding and
 * compression, decoded values against hand-computed ones, and every malformed field named. */
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#include "check.h"
#include "lucent_upload.h"
#include "util/half.h"

enum { W = 16, H = 12, PX = W * H };

static lc_upload_header base_header(int depth_enc, int color_enc, int zl, int conf) {
    lc_upload_header h = {.sequence = 3,
                          .capture_us = 0x123456789aull,
                          .width = W,
                          .height = H,
                          .depth_encoding = (uint8_t)depth_enc,
                          .color_encoding = (uint8_t)color_enc,
                          .depth_zlib = (uint8_t)zl,
                          .confidence_zlib = (uint8_t)(zl && conf),
                          .color_zlib = (uint8_t)zl,
                          .has_confidence = (uint8_t)conf,
                          .fx = 20,
                          .fy = 21,
                          .cx = 8,
                          .cy = 6,
                          .translation = {1, 2, 3},
                          .rotation = {0, 0, 0, 1},
                          .exposure = 100};
    return h;
}

static uint8_t depth_plane[PX * 2], conf_plane[PX], color_plane[PX * 6];

static void fill_planes(int depth_enc, int color_enc) {
    for (int i = 0; i < PX; i++) {
        uint16_t d = depth_enc == LC_DEPTH_U16MM ? (uint16_t)(1500 + i) : lc_half_from_float(0.25f);
        memcpy(depth_plane + 2 * i, &d, 2);
        conf_plane[i] = (uint8_t)(i * 7);
    }
    if (color_enc == LC_COLOR_RGB8_SRGB)
        for (int i = 0; i < PX * 3; i++) color_plane[i] = 188;
    else
        for (int i = 0; i < PX * 3; i++) {
            uint16_t v = lc_half_from_float(0.5f);
            memcpy(color_plane + 2 * i, &v, 2);
        }
}

static void test_round_trips(void) {
    for (int de = 1; de <= 2; de++)
        for (int ce = 1; ce <= 2; ce++)
            for (int zl = 0; zl <= 1; zl++)
                for (int conf = 0; conf <= 1; conf++) {
                    lc_upload_header h = base_header(de, ce, zl, conf);
                    fill_planes(de, ce);
                    uint8_t *buf;
                    size_t len;
                    char err[128];
                    CHECK(lc_upload_encode(&h, depth_plane, conf ? conf_plane : NULL, color_plane, &buf, &len, err,
                                           sizeof err) == 0,
                          "%s", err);
                    lc_upload_expect ex = {W, H, (uint8_t)de, (uint8_t)ce, 1 << 20};
                    lc_upload_frame f;
                    lc_proto_error e;
                    int rc = lc_upload_parse(buf, len, &ex, &f, &e);
                    CHECK(rc == 0, "de %d ce %d zlib %d conf %d: %s %s %s", de, ce, zl, conf, e.code, e.pointer,
                          e.message);
                    if (rc == 0) {
                        CHECK(f.h.sequence == 3 && f.h.capture_us == 0x123456789aull, "header fields");
                        CHECK(!memcmp(f.depth, depth_plane, PX * 2), "depth plane bit-exact");
                        CHECK(!memcmp(f.color, color_plane, lc_upload_color_bytes(&f.h)), "colour plane bit-exact");
                        CHECK(conf ? f.confidence && !memcmp(f.confidence, conf_plane, PX) : !f.confidence,
                              "confidence");
                        float depth[PX], rad[PX * 3], cf[PX];
                        lc_upload_depth_metres(&f, depth);
                        lc_upload_radiance(&f, rad);
                        lc_upload_confidence(&f, cf);
                        CHECK_NEAR(depth[0], de == LC_DEPTH_U16MM ? 1.5 : 0.25, 1e-6);
                        /* sRGB 188 -> 0.50289 linear; half 0.5; times exposure 100 */
                        CHECK_NEAR(rad[5], ce == LC_COLOR_RGB8_SRGB ? 50.289 : 50.0, 1e-3);
                        CHECK_NEAR(cf[1], conf ? 7 / 255.0 : 1.0, 1e-6);
                        lc_upload_frame_release(&f);
                        lc_upload_frame_release(&f); /* idempotent */
                    }
                    free(buf);
                }
}

/* A good frame's bytes, broken at one offset, the CRC fixed again unless the CRC is the point. */
static void expect_bad(size_t off, const void *val, size_t n, const char *pointer, int fix_crc) {
    lc_upload_header h = base_header(1, 2, 0, 0);
    fill_planes(1, 2);
    uint8_t *buf;
    size_t len;
    char err[128];
    lc_upload_encode(&h, depth_plane, NULL, color_plane, &buf, &len, err, sizeof err);
    memcpy(buf + off, val, n);
    if (fix_crc) {
        uint32_t crc = (uint32_t)crc32(crc32(0, buf, 124), buf + 128, (uInt)(len - 128));
        memcpy(buf + 124, &crc, 4);
    }
    lc_upload_expect ex = {W, H, 1, 2, 1 << 20};
    lc_upload_frame f;
    lc_proto_error e;
    CHECK(lc_upload_parse(buf, len, &ex, &f, &e) == -1 && !strcmp(e.code, "frame_invalid") &&
              !strcmp(e.pointer, pointer),
          "offset %zu: %s %s (%s), expected %s", off, e.code, e.pointer, e.message, pointer);
    free(buf);
}

static void test_bad_fields(void) {
    uint32_t u32;
    uint16_t u16;
    uint8_t u8;
    float fl;
    u32 = 0x3146434C, expect_bad(0, &u32, 4, "/header/magic", 1);
    u16 = 2, expect_bad(4, &u16, 2, "/header/version", 1);
    u8 = 9, expect_bad(6, &u8, 1, "/header/kind", 1);
    u8 = 0x80, expect_bad(7, &u8, 1, "/header/flags", 1);
    u16 = 64, expect_bad(8, &u16, 2, "/header/header_size", 1);
    u8 = 1, expect_bad(33, &u8, 1, "/header/reserved", 1);
    u8 = 1, expect_bad(100, &u8, 1, "/header/reserved", 1);
    u32 = 0, expect_bad(12, &u32, 4, "/header/sequence", 1);
    u16 = W + 1, expect_bad(24, &u16, 2, "/header/width", 1);
    u16 = H - 1, expect_bad(26, &u16, 2, "/header/height", 1);
    u8 = 2, expect_bad(28, &u8, 1, "/header/depth_encoding", 1);
    u8 = 1, expect_bad(29, &u8, 1, "/header/color_encoding", 1);
    u8 = 7, expect_bad(30, &u8, 1, "/header/depth_compression", 1);
    u8 = 1, expect_bad(31, &u8, 1, "/header/confidence_compression", 1);
    fl = 0, expect_bad(36, &fl, 4, "/header/fx", 1);
    fl = NAN, expect_bad(40, &fl, 4, "/header/fy", 1);
    fl = 1e6f, expect_bad(44, &fl, 4, "/header/cx", 1);
    fl = -1e6f, expect_bad(48, &fl, 4, "/header/cy", 1);
    fl = 1e7f, expect_bad(56, &fl, 4, "/header/translation", 1);
    fl = INFINITY, expect_bad(76, &fl, 4, "/header/rotation", 1);
    fl = 0, expect_bad(80, &fl, 4, "/header/exposure", 1);
    u32 = 0, expect_bad(124, &u32, 4, "/header/crc", 0);
    u32 = 10, expect_bad(84, &u32, 4, "/frame/length", 1);
    u32 = 5, expect_bad(88, &u32, 4, "/header/confidence_bytes", 1);
    float zero[4] = {0, 0, 0, 0};
    expect_bad(64, zero, 16, "/header/rotation", 1);
}

/* zlib planes: corrupt, inflating to too little or too much, trailing bytes; sizes; limits. */
static void test_planes_and_limits(void) {
    lc_upload_header h = base_header(1, 2, 1, 0);
    fill_planes(1, 2);
    uint8_t *buf;
    size_t len;
    char err[128];
    lc_upload_encode(&h, depth_plane, NULL, color_plane, &buf, &len, err, sizeof err);
    lc_upload_expect ex = {W, H, 1, 2, 1 << 20};
    lc_upload_frame f;
    lc_proto_error e;
    buf[128 + 3] ^= 0x55;
    uint32_t crc = (uint32_t)crc32(crc32(0, buf, 124), buf + 128, (uInt)(len - 128));
    memcpy(buf + 124, &crc, 4);
    CHECK(lc_upload_parse(buf, len, &ex, &f, &e) == -1 && !strcmp(e.pointer, "/depth/zlib"), "corrupt zlib: %s",
          e.pointer);
    free(buf);
    /* a zlib depth plane of the wrong raw size (too short, too long) */
    for (int delta = -2; delta <= 2; delta += 4) {
        uint8_t raw[PX * 2 + 2] = {0};
        uLongf cl = compressBound(sizeof raw);
        uint8_t *z = malloc(cl);
        compress2(z, &cl, raw, (uLong)(PX * 2 + delta), 1);
        size_t total = 128 + cl + PX * 6;
        uint8_t *b = calloc(1, total);
        lc_upload_header h2 = base_header(1, 2, 0, 0);
        uint8_t *good;
        size_t glen;
        lc_upload_encode(&h2, depth_plane, NULL, color_plane, &good, &glen, err, sizeof err);
        memcpy(b, good, 128);
        b[30] = 1;
        uint32_t dl = (uint32_t)cl;
        memcpy(b + 84, &dl, 4);
        memcpy(b + 128, z, cl);
        memcpy(b + 128 + cl, color_plane, PX * 6);
        crc = (uint32_t)crc32(crc32(0, b, 124), b + 128, (uInt)(total - 128));
        memcpy(b + 124, &crc, 4);
        CHECK(lc_upload_parse(b, total, &ex, &f, &e) == -1 && !strcmp(e.pointer, "/depth/zlib"),
              "zlib inflating %+d bytes: %s", delta, e.pointer);
        free(b), free(z), free(good);
    }
    h = base_header(1, 2, 0, 0);
    lc_upload_encode(&h, depth_plane, NULL, color_plane, &buf, &len, err, sizeof err);
    ex.max_frame = len - 1;
    CHECK(lc_upload_parse(buf, len, &ex, &f, &e) == -1 && !strcmp(e.code, "frame_too_large"), "too large: %s", e.code);
    CHECK(lc_upload_parse(buf, 100, NULL, &f, &e) == -1 && !strcmp(e.pointer, "/frame/length"), "short: %s", e.pointer);
    CHECK(lc_upload_parse(buf, len, NULL, &f, &e) == 0, "no expectation: %s", e.message);
    lc_upload_frame_release(&f);
    free(buf);
}

int main(void) {
    test_round_trips();
    test_bad_fields();
    test_planes_and_limits();
    CHECK_DONE();
}
