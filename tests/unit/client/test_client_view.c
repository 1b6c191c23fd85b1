/* liblucent-client without a network: frames built with liblucent-proto are applied to a
 * view (keyframes, tile deltas, every encoding, objects, gaps, corruption) and the SH helpers
 * are checked against closed forms. */
#include <stdint.h>

#include "check.h"
#include "lucent_client.h"
#include "lucent_proto.h"
#include "util/half.h"

#define W 40 /* not a multiple of the tile size: edge tiles are clipped */
#define H 24
#define TILE 16

static uint8_t frame_buf[1 << 20];
static uint8_t payload_buf[1 << 20];

static void texel_value(uint32_t x, uint32_t y, int gen, float rgb[3]) {
    rgb[0] = 0.25f * (float)(x + 1) + (float)gen;
    rgb[1] = 0.125f * (float)(y + 1);
    rgb[2] = (float)((x * 7 + y * 3) % 11) / 8.0f + 0.5f * (float)gen;
}

static size_t put_texel(uint8_t *p, int enc, const float rgb[3]) {
    if (enc == LC_ENC_RGB9E5) {
        uint32_t v = lc_rgb9e5_encode(rgb);
        memcpy(p, &v, 4);
        return 4;
    }
    if (enc == LC_ENC_RGBA16F) {
        uint16_t hv[4] = {lc_half_from_float(rgb[0]), lc_half_from_float(rgb[1]), lc_half_from_float(rgb[2]),
                          lc_half_from_float(1.0f)};
        memcpy(p, hv, 8);
        return 8;
    }
    memcpy(p, rgb, 12);
    return 12;
}

static size_t lightmap_frame(int enc, int key, uint64_t seq, uint64_t rev, int gen, const uint32_t *tiles,
                             uint32_t nt) {
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = LC_STREAM_LIGHTMAP;
    h.encoding = (uint8_t)enc;
    h.flags = key ? LC_FRAME_KEYFRAME : LC_FRAME_DELTA;
    h.revision = rev;
    h.sequence = seq;
    h.timestamp_us = 123456789;
    h.width = W;
    h.height = H;
    h.depth = 1;
    h.tile_size = TILE;
    size_t n = 0;
    float rgb[3];
    if (key) {
        for (uint32_t y = 0; y < H; y++)
            for (uint32_t x = 0; x < W; x++) {
                texel_value(x, y, gen, rgb);
                n += put_texel(payload_buf + n, enc, rgb);
            }
    } else {
        h.tile_count = nt;
        for (uint32_t i = 0; i < nt; i++) {
            uint32_t x0, y0, x1, y1;
            lc_tile_rect(W, H, TILE, tiles[i], &x0, &y0, &x1, &y1);
            for (uint32_t y = y0; y < y1; y++)
                for (uint32_t x = x0; x < x1; x++) {
                    texel_value(x, y, gen, rgb);
                    n += put_texel(payload_buf + n, enc, rgb);
                }
        }
    }
    h.payload_length = (uint32_t)n;
    return lc_frame_write(&h, tiles, payload_buf, frame_buf, sizeof frame_buf);
}

static int in_tiles(uint32_t x, uint32_t y, const uint32_t *tiles, uint32_t nt) {
    uint32_t tw = (W + TILE - 1) / TILE;
    uint32_t t = (y / TILE) * tw + x / TILE;
    for (uint32_t i = 0; i < nt; i++)
        if (tiles[i] == t) return 1;
    return 0;
}

/* Max relative error of the view against generation gen (or gen_new inside tiles). */
static double lightmap_error(const lc_client_frame *f, int gen, int gen_new, const uint32_t *tiles, uint32_t nt) {
    double worst = 0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            float want[3];
            texel_value(x, y, in_tiles(x, y, tiles, nt) ? gen_new : gen, want);
            for (int k = 0; k < 3; k++) {
                double got = f->values[3 * ((size_t)y * W + x) + (size_t)k];
                double e = fabs(got - want[k]) / fmax(fabs(want[k]), 1e-3);
                if (e > worst) worst = e;
            }
        }
    return worst;
}

static void test_lightmap_encodings(void) {
    const double tol[4] = {0, 1.0 / 256, 1.0 / 1024, 0}; /* rgb9e5: 9-bit mantissa; half: 11-bit */
    for (int enc = LC_ENC_RGB9E5; enc <= LC_ENC_F32; enc++) {
        lc_client_view *v = lc_client_view_create();
        lc_client_frame f;
        char err[256];
        size_t n = lightmap_frame(enc, 1, 1, 10, 0, NULL, 0);
        CHECK(n > 0, "frame built");
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "keyframe enc %d: %s", enc, err);
        CHECK(f.keyframe && f.width == W && f.height == H && f.revision == 10 && f.sequence == 1 &&
                  f.value_count == (size_t)W * H * 3 && f.server_time_us == 123456789 && f.raw == frame_buf,
              "keyframe fields (enc %d)", enc);
        CHECK(lightmap_error(&f, 0, 0, NULL, 0) <= tol[enc], "keyframe values enc %d err %g", enc,
              lightmap_error(&f, 0, 0, NULL, 0));
        /* a delta with two tiles (one clipped at the right edge) */
        const uint32_t tiles[2] = {1, 5};
        n = lightmap_frame(enc, 0, 2, 11, 3, tiles, 2);
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "delta enc %d: %s", enc, err);
        CHECK(!f.keyframe && f.tile_count == 2 && f.tiles[0] == 1 && f.tiles[1] == 5 && f.revision == 11,
              "delta fields");
        CHECK(lightmap_error(&f, 0, 3, tiles, 2) <= tol[enc], "delta applied enc %d err %g", enc,
              lightmap_error(&f, 0, 3, tiles, 2));
        lc_client_view_release(v);
    }
    /* f32 is bit-exact */
    lc_client_view *v = lc_client_view_create();
    lc_client_frame f;
    size_t n = lightmap_frame(LC_ENC_F32, 1, 1, 1, 0, NULL, 0);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, NULL, 0) == 0, "f32 keyframe");
    CHECK(memcmp(f.values, frame_buf + LC_FRAME_HEADER_SIZE, (size_t)W * H * 12) == 0, "f32 bit-exact");
    lc_client_view_release(v);
}

/* A residual delta (PROTOCOL.md §6.2.1) taking the texels of `tiles` from generation
 * held_gen[i] (tile i) to gen; `cut` bytes are dropped from the inflated residual (to build
 * a malformed frame). */
static size_t residual_frame(int enc, uint64_t seq, uint64_t rev, const int *held_gen, int gen, const uint32_t *tiles,
                             uint32_t nt, size_t cut) {
    static uint8_t raw[1 << 16];
    size_t n = 0;
    float rgb[3];
    uint8_t held[12], now[12];
    for (uint32_t i = 0; i < nt; i++) {
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(W, H, TILE, tiles[i], &x0, &y0, &x1, &y1);
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++) {
                texel_value(x, y, held_gen[i], rgb);
                size_t tb = put_texel(held, enc, rgb);
                texel_value(x, y, gen, rgb);
                put_texel(now, enc, rgb);
                lc_residual_make((lc_encoding)enc, now, held, 1, raw + n);
                n += tb;
            }
    }
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = LC_STREAM_LIGHTMAP;
    h.encoding = (uint8_t)enc;
    h.flags = LC_FRAME_DELTA | LC_FRAME_RESIDUAL;
    h.revision = rev;
    h.sequence = seq;
    h.width = W;
    h.height = H;
    h.depth = 1;
    h.tile_size = TILE;
    h.tile_count = nt;
    h.payload_length = (uint32_t)lc_residual_deflate(raw, n - cut, payload_buf, sizeof payload_buf);
    return lc_frame_write(&h, tiles, payload_buf, frame_buf, sizeof frame_buf);
}

static void test_lightmap_residual(void) {
    const double tol[4] = {0, 1.0 / 256, 1.0 / 1024, 0};
    for (int enc = LC_ENC_RGB9E5; enc <= LC_ENC_F32; enc++) {
        lc_client_view *v = lc_client_view_create();
        lc_client_frame f;
        char err[256];
        const uint32_t t15[2] = {1, 5}, t2[1] = {2}, t125[3] = {1, 2, 5};
        const int held0[2] = {0, 0}, held_mixed[3] = {3, 5, 3};
        size_t n = residual_frame(enc, 1, 10, held0, 3, t15, 2, 0);
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -2, "residual before a keyframe: %s", err);
        n = lightmap_frame(enc, 1, 1, 10, 0, NULL, 0);
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "keyframe enc %d: %s", enc, err);
        n = residual_frame(enc, 2, 11, held0, 3, t15, 2, 0);
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "residual enc %d: %s", enc, err);
        CHECK(!f.keyframe && f.residual && f.tile_count == 2 && f.tiles[1] == 5, "residual frame fields");
        CHECK(lightmap_error(&f, 0, 3, t15, 2) <= tol[enc], "residual applied enc %d err %g", enc,
              lightmap_error(&f, 0, 3, t15, 2));
        /* a plain delta in between keeps the encoded copy current */
        n = lightmap_frame(enc, 0, 3, 12, 5, t2, 1);
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0 && !f.residual, "plain delta: %s", err);
        n = residual_frame(enc, 4, 13, held_mixed, 7, t125, 3, 0);
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "second residual: %s", err);
        CHECK(lightmap_error(&f, 0, 7, t125, 3) <= tol[enc], "residual over mixed history enc %d err %g", enc,
              lightmap_error(&f, 0, 7, t125, 3));
        /* an inflated residual one texel short: malformed, and the view is unchanged */
        const int held7[3] = {7, 7, 7};
        n = residual_frame(enc, 5, 14, held7, 9, t125, 3, lc_frame_texel_bytes((lc_encoding)enc));
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -1 && strstr(err, "inflate"), "short: %s",
              err);
        n = residual_frame(enc, 5, 14, held7, 9, t125, 3, 0);
        err[0] = 0;
        CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0 &&
                  lightmap_error(&f, 0, 9, t125, 3) <= tol[enc],
              "the view was unchanged by the bad frame: %s", err);
        lc_client_view_release(v);
    }
    /* a keyframe in another encoding: the residual (rgb9e5) has no copy to apply to */
    lc_client_view *v = lc_client_view_create();
    char err[256];
    size_t n = lightmap_frame(LC_ENC_F32, 1, 1, 1, 0, NULL, 0);
    CHECK(lc_client_view_apply(v, frame_buf, n, NULL, err, sizeof err) == 0, "f32 keyframe");
    const uint32_t t1[1] = {1};
    n = residual_frame(LC_ENC_RGB9E5, 2, 2, (const int[1]){0}, 1, t1, 1, 0);
    CHECK(lc_client_view_apply(v, frame_buf, n, NULL, err, sizeof err) == -2 && strstr(err, "copy"),
          "encoding switch: %s", err);
    lc_client_view_release(v);
}

static void test_lightmap_errors(void) {
    lc_client_view *v = lc_client_view_create();
    lc_client_frame f;
    char err[256];
    const uint32_t tiles[1] = {2};
    size_t n = lightmap_frame(LC_ENC_F32, 0, 1, 1, 1, tiles, 1);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -2 && strstr(err, "keyframe"),
          "delta before keyframe needs a keyframe: %s", err);
    n = lightmap_frame(LC_ENC_F32, 1, 1, 5, 0, NULL, 0);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "keyframe");
    /* corrupt one payload byte: CRC mismatch, view unchanged */
    n = lightmap_frame(LC_ENC_F32, 0, 2, 6, 9, tiles, 1);
    frame_buf[n - 1] ^= 0x40;
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -1 && strstr(err, "CRC"), "CRC: %s", err);
    CHECK(lc_client_latest_frame(NULL, 1, &f) == -1, "no client no frame");
    /* a gap: sequence 3 after 1 */
    n = lightmap_frame(LC_ENC_F32, 0, 3, 6, 9, tiles, 1);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -2 && strstr(err, "gap"), "gap: %s", err);
    /* after the gap even the right next sequence is refused until a keyframe */
    n = lightmap_frame(LC_ENC_F32, 0, 4, 6, 9, tiles, 1);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -2, "stale until keyframe");
    n = lightmap_frame(LC_ENC_F32, 1, 5, 7, 2, NULL, 0);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0 && lightmap_error(&f, 2, 2, NULL, 0) == 0,
          "keyframe recovers");
    /* revision going back */
    n = lightmap_frame(LC_ENC_F32, 1, 6, 3, 2, NULL, 0);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -1 && strstr(err, "revision"),
          "revision back: %s", err);
    /* truncations never crash and never apply */
    n = lightmap_frame(LC_ENC_F32, 1, 6, 8, 1, NULL, 0);
    for (size_t cut = 0; cut < n; cut += 97)
        CHECK(lc_client_view_apply(v, frame_buf, cut, &f, NULL, 0) == -1, "truncated at %zu", cut);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0 && f.revision == 8, "full frame");
    lc_client_view_release(v);
}

static void test_sh_streams(void) {
    /* shgrid 3x2x2 f32, then objects (2, half) */
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = LC_STREAM_SHGRID;
    h.encoding = LC_ENC_F32;
    h.flags = LC_FRAME_KEYFRAME;
    h.revision = 4;
    h.sequence = 1;
    h.width = 3;
    h.height = 2;
    h.depth = 2;
    float vals[12 * 27];
    for (int i = 0; i < 12 * 27; i++) vals[i] = (float)i * 0.01f - 1.0f;
    h.payload_length = sizeof vals;
    size_t n = lc_frame_write(&h, NULL, vals, frame_buf, sizeof frame_buf);
    lc_client_view *v = lc_client_view_create();
    lc_client_frame f;
    char err[256];
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "shgrid: %s", err);
    CHECK(f.value_count == 12 * 27 && memcmp(f.values, vals, sizeof vals) == 0 && f.depth == 2, "shgrid values");
    lc_client_view_release(v);

    v = lc_client_view_create();
    h.stream = LC_STREAM_OBJECTS;
    h.encoding = LC_ENC_RGBA16F;
    h.width = 2;
    h.height = 1;
    h.depth = 1;
    uint8_t *p = payload_buf;
    const char *ids[2] = {"chair", "zeta-with-a-long-name"};
    for (int o = 0; o < 2; o++) {
        memset(p, 0, 64);
        memcpy(p, ids[o], strlen(ids[o]));
        p += 64;
        for (int k = 0; k < 27; k++, p += 2) {
            uint16_t hv = lc_half_from_float((float)(o * 27 + k) * 0.5f);
            memcpy(p, &hv, 2);
        }
    }
    h.payload_length = (uint32_t)(p - payload_buf);
    n = lc_frame_write(&h, NULL, payload_buf, frame_buf, sizeof frame_buf);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == 0, "objects: %s", err);
    CHECK(f.width == 2 && f.object_ids && strcmp(f.object_ids[0], "chair") == 0 &&
              strcmp(f.object_ids[1], "zeta-with-a-long-name") == 0,
          "object ids");
    CHECK(f.values[27 + 5] == 16.0f && f.values[0] == 0.0f, "object values %g", f.values[27 + 5]);
    /* SH streams refuse rgb9e5 */
    h.encoding = LC_ENC_RGB9E5;
    n = lc_frame_write(&h, NULL, payload_buf, frame_buf, sizeof frame_buf);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, NULL, 0) == -1, "rgb9e5 SH refused");
    lc_client_view_release(v);
}

static void test_sh_helpers(void) {
    /* constant irradiance E0 in every direction: c0 = E0 / Y00 */
    float sh[27] = {0}, rgb[3];
    const double y00 = 0.28209479177387814;
    for (int ch = 0; ch < 3; ch++) sh[ch] = (float)((1.0 + ch) / y00);
    const float up[3] = {0, 3, 0};
    lc_sh9_irradiance(sh, up, rgb);
    CHECK_NEAR(rgb[0], 1.0, 1e-6);
    CHECK_NEAR(rgb[2], 3.0, 1e-6);
    /* light arriving from +z (radiance a delta of unit irradiance): cosine-convolved SH
     * c_lm = A_l y_lm(+z), so E(+z) = sum_l A_l y_l0(+z)^2 = 1/4 + 1/2 + 5/16 (L2 lobe) */
    float d[27] = {0};
    const double a0 = 3.141592653589793, a1 = 2.0943951023931953, a2 = 0.7853981633974483;
    const double yz[9] = {y00, 0, 0.48860251190291992, 0, 0, 0, 0.31539156525252001 * 2, 0, 0};
    for (int i = 0; i < 9; i++) {
        double a = i == 0 ? a0 : (i < 4 ? a1 : a2);
        for (int ch = 0; ch < 3; ch++) d[3 * i + ch] = (float)(a * yz[i]);
    }
    const float nz[3] = {0, 0, 1}, nmz[3] = {0, 0, -1};
    lc_sh9_irradiance(d, nz, rgb);
    CHECK_NEAR(rgb[1], (a0 * y00 * y00 + a1 * yz[2] * yz[2] + a2 * yz[6] * yz[6]), 1e-5);
    CHECK_NEAR(rgb[1], 1.0625 * 1.0, 1e-4);
    lc_sh9_irradiance(d, nmz, rgb);
    CHECK(rgb[1] >= 0 && rgb[1] < 0.07, "back side nearly dark: %g", rgb[1]);
    /* irradiance -> radiance divides by A_l */
    float rad[27];
    lc_sh9_irradiance_to_radiance(d, rad);
    CHECK_NEAR(rad[0], y00, 1e-6);
    CHECK_NEAR(rad[3 * 2 + 1], yz[2], 1e-6);
    CHECK_NEAR(rad[3 * 6 + 2], yz[6], 1e-6);
    /* planar order round trip and layout */
    float in[27], planar[27], back[27];
    for (int i = 0; i < 27; i++) in[i] = (float)i;
    lc_sh9_to_planar(in, planar);
    CHECK(planar[0] == 0 && planar[1] == 3 && planar[9] == 1 && planar[18 + 8] == 26, "planar layout");
    lc_sh9_to_interleaved(planar, back);
    CHECK(memcmp(in, back, sizeof in) == 0, "round trip");
}

int main(void) {
    test_lightmap_encodings();
    test_lightmap_errors();
    test_lightmap_residual();
    test_sh_streams();
    test_sh_helpers();
    CHECK_DONE();
}
