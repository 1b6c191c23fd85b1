/* The comparison tool on synthetic data with known errors: mean / p50 / p95 / max over the
 * texels that own their cache and exceed the brightness threshold; the grid metric; the
 * heat map; the reference directory round trip (float32, exact). */
#include <math.h>
#include <stdlib.h>
#include <unistd.h>

#include "check.h"
#include "ref/ref.h"

static void test_lightmap_stats(void) {
    /* 16 x 8 texels: 100 owners with reference 2.0 and relative errors 0.00, 0.01, ..., 0.99
     * (alternating sign), plus texels that must not count: dilated copies (mask 2), empty
     * texels (mask 0), and dark owners (below 1% of the brightest) with huge errors. */
    const uint32_t w = 16, h = 8, n = w * h;
    float ref[16 * 8 * 3], app[16 * 8 * 3], se[16 * 8 * 3], img[16 * 8];
    uint8_t mask[16 * 8];
    int k = 0;
    for (uint32_t i = 0; i < n; i++) {
        float r = 2.0f, a = 2.0f;
        mask[i] = 1;
        if (i < 100) {
            float e = (float)k / 100.0f * (k % 2 ? -1.0f : 1.0f);
            a = r * (1 + e);
            k++;
        } else if (i < 110) {
            mask[i] = 2, a = 50; /* dilated copy */
        } else if (i < 120) {
            mask[i] = 0, a = 50; /* empty */
        } else {
            r = 0.01f, a = 1.0f; /* dark: 0.5% of the brightest, error 99x */
        }
        for (int c = 0; c < 3; c++) {
            ref[3 * i + c] = r;
            app[3 * i + c] = a;
            se[3 * i + c] = 0.02f * r;
        }
    }
    lc_ref_errstats s;
    CHECK(lc_ref_compare_lightmap(app, ref, se, mask, w, h, 0.01, &s, img) == 0, "compare failed");
    CHECK(s.n == 100, "compared %u texels, expected 100", s.n);
    CHECK(s.n_total == 108, "candidates %u, expected 108 (100 bright + 8 dark owners)", s.n_total);
    CHECK_NEAR(s.mean, 0.495, 1e-5);
    CHECK_NEAR(s.p50, 0.49, 1e-5); /* nearest rank: the 50th of 100 sorted */
    CHECK_NEAR(s.p95, 0.94, 1e-5); /* the 95th */
    CHECK_NEAR(s.max, 0.99, 1e-5);
    CHECK_NEAR(s.ref_noise, 0.02, 1e-5);
    /* Signed: +0, -0.01, +0.02, ... : sum = (0 + 2 + ... + 98 - 1 - 3 - ... - 99) / 100 = -0.5. */
    CHECK_NEAR(s.mean_signed, -0.005, 1e-5);
    CHECK_NEAR(s.bias, -0.005, 1e-5);
    CHECK(isnan(img[105]) && isnan(img[115]) && isnan(img[125]), "excluded texels must be NAN in the error image");
    CHECK_NEAR(img[3], -0.03, 1e-5);
    /* A threshold of 0: the dark owners count too (error 99). */
    CHECK(lc_ref_compare_lightmap(app, ref, NULL, mask, w, h, 0.0, &s, NULL) == 0, "compare failed");
    CHECK(s.n == 108 && fabs(s.max - 99) < 1e-3, "threshold 0: n %u max %g", s.n, s.max);
    /* Nothing above the threshold: an error, not a zero. */
    CHECK(lc_ref_compare_lightmap(app, ref, NULL, mask, w, h, 2.0, &s, NULL) != 0, "empty set must fail");
    /* The heat map writes. */
    char dir[] = "/tmp/lc_ref_cmp_XXXXXX", path[128], err[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    snprintf(path, sizeof path, "%s/heat.png", dir);
    CHECK(lc_ref_write_heatmap(path, img, w, h, 0.5, 4, err, sizeof err) == 0, "heat map: %s", err);
    CHECK(access(path, R_OK) == 0, "heat map missing");
    unlink(path);
    rmdir(dir);
}

static void test_grid_stats(void) {
    /* 10 cells: isotropic reference E = 3 (c_0 = 3 / y_00); approximations off by +10% in c_0
     * (so every direction is off by 10%), and one cell with a band-1 term that averages out
     * over opposite directions but not in |dE| (0.3 y_1(d) * ...). Cell 9 is inside (mask 0). */
    const uint32_t cells = 10;
    float ref[10 * 27] = {0}, app[10 * 27] = {0};
    uint8_t mask[10];
    const float c0 = 3.0f / 0.282094791774f;
    for (uint32_t c = 0; c < cells; c++) {
        mask[c] = c < 9;
        for (int k = 0; k < 3; k++) {
            ref[27 * c + k] = c0;
            app[27 * c + k] = c < 8 ? 1.1f * c0 : c0;
        }
    }
    /* Cell 8: E_a(d) = 3 + 0.6 d_z for the axis directions, 3 +- 0.6/sqrt(3) on the diagonals. */
    for (int k = 0; k < 3; k++) app[27 * 8 + 3 * 2 + k] = 0.6f / 0.488602511903f;
    lc_ref_errstats s;
    float err[10];
    CHECK(lc_ref_compare_grid(app, ref, NULL, mask, cells, 0.01, &s, err) == 0, "grid compare failed");
    CHECK(s.n == 9, "compared %u cells, expected 9", s.n);
    CHECK_NEAR(err[0], 0.1, 1e-5);
    double expect8 = (2 * 0.6 + 8 * 0.6 / sqrt(3.0)) / (14 * 3.0);
    CHECK_NEAR(err[8], expect8, 1e-5);
    CHECK(isnan(err[9]), "inside cell must be NAN");
    CHECK_NEAR(s.max, 0.1, 1e-5);
    CHECK_NEAR(s.mean, (8 * 0.1 + expect8) / 9, 1e-5);
}

static void test_roundtrip(void) {
    lc_ref_result a = {0}, b;
    a.width = 5, a.height = 3;
    a.n_cells = 4;
    a.grid_dims[0] = 2, a.grid_dims[1] = 2, a.grid_dims[2] = 1;
    a.grid_cell = 0.25f;
    a.lightmap = calloc(15 * 3, sizeof(float));
    a.lightmap_stderr = calloc(15 * 3, sizeof(float));
    a.texel_mask = calloc(15, 1);
    a.grid_sh = calloc(4 * 27, sizeof(float));
    a.grid_sh_stderr = calloc(4 * 27, sizeof(float));
    a.grid_mask = calloc(4, 1);
    for (int i = 0; i < 45; i++)
        a.lightmap[i] = 1.0f / 3.0f + (float)i * 1.2345678e-3f, a.lightmap_stderr[i] = 1e-7f * i;
    for (int i = 0; i < 15; i++) a.texel_mask[i] = (uint8_t)(i % 3);
    for (int i = 0; i < 108; i++) a.grid_sh[i] = (float)i / 7.0f, a.grid_sh_stderr[i] = (float)i / 700.0f;
    a.grid_mask[1] = 1;
    a.texel_stats.mean_rel_stderr = 0.0123;
    a.cache_crc = 0xDEADBEEFu;
    a.texel_at = LC_REF_TEXEL_AT_CACHE;
    a.texel_surface = malloc(15 * LC_REF_SURFACE_STRIDE * sizeof(float));
    a.texel_moved = calloc(15, 1);
    for (int i = 0; i < 15 * LC_REF_SURFACE_STRIDE; i++) a.texel_surface[i] = i % 11 == 3 ? NAN : 0.1f * i - 2.0f;
    a.texel_moved[4] = a.texel_moved[7] = 1;
    a.surface_stats = (lc_ref_surface_stats){12, 2, 1};
    a.unmoved_offset_max = 2.5e-7;
    char dir[] = "/tmp/lc_ref_rt_XXXXXX", err[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    CHECK(lc_ref_write(dir, &a, "{\"note\": 1}", err, sizeof err) == 0, "write: %s", err);
    CHECK(lc_ref_read(dir, &b, err, sizeof err) == 0, "read: %s", err);
    if (b.lightmap) {
        CHECK(b.width == 5 && b.height == 3 && b.n_cells == 4, "dims %ux%u cells %u", b.width, b.height, b.n_cells);
        CHECK(memcmp(a.lightmap, b.lightmap, 45 * sizeof(float)) == 0, "lightmap not exact (float32 EXR)");
        CHECK(memcmp(a.lightmap_stderr, b.lightmap_stderr, 45 * sizeof(float)) == 0, "stderr not exact");
        CHECK(memcmp(a.texel_mask, b.texel_mask, 15) == 0, "mask differs");
        CHECK(memcmp(a.grid_sh, b.grid_sh, 108 * sizeof(float)) == 0, "grid differs");
        CHECK(memcmp(a.grid_mask, b.grid_mask, 4) == 0, "grid mask differs");
        CHECK(b.cache_crc == 0xDEADBEEFu, "cache crc %08x", b.cache_crc);
        CHECK_NEAR(b.texel_stats.mean_rel_stderr, 0.0123, 1e-9);
        CHECK_NEAR(b.grid_cell, 0.25, 1e-7);
        CHECK(b.texel_at == LC_REF_TEXEL_AT_CACHE, "texel_at %d", b.texel_at);
        CHECK(b.texel_surface && memcmp(a.texel_surface, b.texel_surface, 15 * LC_REF_SURFACE_STRIDE * 4) == 0,
              "texel surfaces differ");
        CHECK(b.texel_moved && memcmp(a.texel_moved, b.texel_moved, 15) == 0, "moved mask differs");
        CHECK(b.surface_stats.texels == 12 && b.surface_stats.outside == 2 && b.surface_stats.missing == 1,
              "surface stats %u %u %u", b.surface_stats.texels, b.surface_stats.outside, b.surface_stats.missing);
        CHECK_NEAR(b.unmoved_offset_max, 2.5e-7, 1e-9);
    }
    lc_ref_result_free(&b);
    /* A directory that is not a reference is refused with a message. */
    CHECK(lc_ref_read("/nonexistent-lc-ref", &b, err, sizeof err) != 0 && err[0], "missing dir must fail");
    const char *names[] = {"reference.json",          "reference_lightmap.exr", "reference_lightmap_stderr.exr",
                           "reference_texels.bin",    "reference_grid.bin",     "reference_grid_stderr.bin",
                           "reference_grid_mask.bin", "reference_surface.bin",  "reference_moved.bin"};
    for (size_t i = 0; i < sizeof names / sizeof *names; i++) {
        char path[128];
        snprintf(path, sizeof path, "%s/%s", dir, names[i]);
        unlink(path);
    }
    rmdir(dir);
    lc_ref_result_free(&a);
}

/* The moved / unmoved rows: one threshold and one scale for all rows; dark texels counted, and
 * the engine's light on them in abs_err_vs_mean. */
static void test_subset_rows(void) {
    /* 10 owners: reference 1.0 for 0..7 (engine 1.1), 0.005 for 8..9 (dark: below 1% of 1.0...
     * the brightest is texel 0 at 2.0, threshold 0.02); engine 0.5 on the dark ones. Moved: 6..9. */
    float ref[10 * 3], app[10 * 3];
    uint8_t mask[10], moved[10];
    for (int i = 0; i < 10; i++) {
        float r = i == 0 ? 2.0f : i < 8 ? 1.0f : 0.005f, a = i < 8 ? 1.1f * r : 0.5f;
        for (int c = 0; c < 3; c++) ref[3 * i + c] = r, app[3 * i + c] = a;
        mask[i] = 1;
        moved[i] = i >= 6;
    }
    lc_ref_errstats all, mv, um;
    CHECK(lc_ref_compare_lightmap(app, ref, NULL, mask, 10, 1, 0.01, &all, NULL) == 0, "all");
    CHECK(lc_ref_compare_lightmap_subset(app, ref, NULL, mask, moved, 1, 10, 1, 0.01, &mv, NULL) == 0, "moved");
    CHECK(lc_ref_compare_lightmap_subset(app, ref, NULL, mask, moved, 0, 10, 1, 0.01, &um, NULL) == 0, "unmoved");
    CHECK(all.n == 8 && mv.n == 2 && um.n == 6, "compared %u / %u / %u", all.n, mv.n, um.n);
    CHECK(all.n_total == 10 && mv.n_total == 4 && um.n_total == 6, "candidates %u / %u / %u", all.n_total, mv.n_total,
          um.n_total);
    CHECK_NEAR(mv.threshold, 0.02, 1e-7);
    CHECK_NEAR(um.threshold, 0.02, 1e-7);
    CHECK(mv.n_dark == 2 && mv.n_dark_lit == 2 && um.n_dark == 0 && all.n_dark == 2, "dark %u lit %u / %u / %u",
          mv.n_dark, mv.n_dark_lit, um.n_dark, all.n_dark);
    CHECK_NEAR(mv.mean, 0.1, 1e-6);
    double scale = (2.0 + 7 * 1.0) / 8; /* mean reference over the whole lightmap's compared texels */
    CHECK_NEAR(mv.ref_mean, scale, 1e-6);
    CHECK_NEAR(um.ref_mean, scale, 1e-6);
    /* moved: two texels off by 0.1, two dark ones lit 0.495 too bright */
    CHECK_NEAR(mv.abs_err_vs_mean, (2 * 0.1 + 2 * 0.495) / 4 / scale, 1e-6);
    CHECK_NEAR(um.abs_err_vs_mean, (0.2 + 5 * 0.1) / 6 / scale, 1e-6);
    /* A subset with candidates but none bright: -1, the dark counts still set. */
    for (int i = 0; i < 10; i++) moved[i] = i >= 8;
    CHECK(lc_ref_compare_lightmap_subset(app, ref, NULL, mask, moved, 1, 10, 1, 0.01, &mv, NULL) != 0,
          "all-dark subset must report nothing compared");
    CHECK(mv.n == 0 && mv.n_total == 2 && mv.n_dark_lit == 2 && mv.abs_err_vs_mean > 0, "all-dark subset: %u %u %u",
          mv.n, mv.n_total, mv.n_dark_lit);
}

/* Fills an image of w x h with v(x, y) in every channel. */
static void fill(float *img, uint32_t w, uint32_t h, float (*v)(uint32_t, uint32_t)) {
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++)
            for (int c = 0; c < 3; c++) img[3 * (y * w + x) + c] = v(x, y);
}
static float v_const(uint32_t x, uint32_t y) { return (void)x, (void)y, 3.0f; }
static float v_check12(uint32_t x, uint32_t y) { return (x + y) % 2 ? 2.0f : 1.0f; }
static float v_check15(uint32_t x, uint32_t y) { return (x + y) % 2 ? 1.5f : 1.0f; }

/* The blotch metric: 0 on a constant image, 2/3 on a checkerboard of 1 and 2 (|1 - 2| / 1.5);
 * pairs across a seam (normals apart, or points far apart) do not count. */
static void test_blotch(void) {
    enum { W = 8, H = 6 };
    float a[W * H * 3], r[W * H * 3], se[W * H * 3], surf[W * H * LC_REF_SURFACE_STRIDE];
    uint8_t mask[W * H];
    for (int i = 0; i < W * H; i++) mask[i] = 1;
    for (int i = 0; i < W * H * 3; i++) se[i] = 0.01f;
    /* a flat surface: texels 0.1 m apart on the plane y = 0, normal +y */
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            float *s = surf + LC_REF_SURFACE_STRIDE * (y * W + x);
            s[0] = 0.1f * x, s[1] = 0, s[2] = 0.1f * y, s[3] = 0, s[4] = 1, s[5] = 0, s[6] = 0.1f;
        }
    const uint32_t all_pairs = (W - 1) * H + W * (H - 1);
    lc_ref_blotch b;
    fill(a, W, H, v_const);
    fill(r, W, H, v_const);
    CHECK(lc_ref_blotch_metric(a, r, se, mask, surf, W, H, 0.0, &b) == 0, "constant");
    CHECK(b.pairs == all_pairs && b.approx == 0 && b.reference == 0 && b.ratio == 0, "constant: %u %g %g", b.pairs,
          b.approx, b.reference);
    CHECK_NEAR(b.ref_noise, 0.01 / 3, 1e-6);
    fill(a, W, H, v_check12);
    CHECK(lc_ref_blotch_metric(a, r, NULL, mask, NULL, W, H, 0.0, &b) == 0, "checker, no surface");
    CHECK(b.pairs == all_pairs, "pairs %u", b.pairs);
    CHECK_NEAR(b.approx, 2.0 / 3.0, 1e-6);
    fill(r, W, H, v_check15);
    CHECK(lc_ref_blotch_metric(a, r, NULL, mask, surf, W, H, 0.0, &b) == 0, "checker vs checker");
    CHECK_NEAR(b.approx, 2.0 / 3.0, 1e-6);
    CHECK_NEAR(b.reference, 0.4, 1e-6); /* 0.5 / 1.25 */
    CHECK_NEAR(b.ratio, (2.0 / 3.0) / 0.4, 1e-6);
    /* A seam: the right half (x >= 4) turned 90 degrees (normal +x): the H pairs across it go. */
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 4; x < W; x++) {
            float *s = surf + LC_REF_SURFACE_STRIDE * (y * W + x);
            s[3] = 1, s[4] = 0;
        }
    CHECK(lc_ref_blotch_metric(a, r, NULL, mask, surf, W, H, 0.0, &b) == 0 && b.pairs == all_pairs - H,
          "normal seam: %u pairs, expected %u", b.pairs, all_pairs - H);
    /* Points apart: row 0 moved 1 m away (beyond 2 x 0.1 m): the W pairs between rows 0 and 1 go too. */
    for (uint32_t x = 0; x < W; x++) surf[LC_REF_SURFACE_STRIDE * x + 1] = 1.0f;
    CHECK(lc_ref_blotch_metric(a, r, NULL, mask, surf, W, H, 0.0, &b) == 0 && b.pairs == all_pairs - H - W,
          "distance seam: %u pairs, expected %u", b.pairs, all_pairs - H - W);
    /* Dark reference texels (threshold) and non-owners (mask 2) leave with their pairs. */
    mask[0] = 2; /* corner: 2 pairs, one already gone with row 0's */
    CHECK(lc_ref_blotch_metric(a, r, NULL, mask, NULL, W, H, 0.0, &b) == 0 && b.pairs == all_pairs - 2,
          "mask: %u pairs", b.pairs);
    CHECK(lc_ref_blotch_metric(a, r, NULL, mask, NULL, W, H, 1.2, &b) != 0, "every pair has a texel of 1.0: none");
}

/* The uv heat map: the diverging scale, copies into covered texels, transparent empty ones. */
static void test_heatmap_uv(void) {
    /* 4 x 2:  row 0: -max, 0, +max/2, NAN (covered: copies +max/2, its only compared neighbour)
     *         row 1: empty, empty, NAN (owner: the texels above-left and above are both one step
     *         away, the first in row order wins: white), empty */
    float e[8] = {-0.5f, 0.0f, 0.25f, NAN, NAN, NAN, NAN, NAN};
    uint8_t mask[8] = {1, 1, 1, 2, 0, 0, 1, 0}, rgba[8 * 4];
    CHECK(lc_ref_heatmap_uv(e, mask, 4, 2, 0.5, rgba) == 0, "heat map");
    const uint8_t want[8][4] = {{0, 0, 255, 255}, {255, 255, 255, 255}, {255, 128, 128, 255}, {255, 128, 128, 255},
                                {0, 0, 0, 0},     {0, 0, 0, 0},         {255, 255, 255, 255}, {0, 0, 0, 0}};
    for (int i = 0; i < 8; i++)
        CHECK(!memcmp(rgba + 4 * i, want[i], 4), "texel %d: %u %u %u %u, expected %u %u %u %u", i, rgba[4 * i],
              rgba[4 * i + 1], rgba[4 * i + 2], rgba[4 * i + 3], want[i][0], want[i][1], want[i][2], want[i][3]);
    /* Saturation (and infinity: a lit texel the reference says is dark), and a covered texel
     * that reaches no compared one: grey. */
    float e2[4] = {2.0f, INFINITY, -INFINITY, NAN};
    uint8_t m2[4] = {1, 1, 1, 1}, m3[4] = {0, 0, 0, 1};
    CHECK(lc_ref_heatmap_uv(e2, m2, 4, 1, 0.5, rgba) == 0, "heat map");
    CHECK(rgba[0] == 255 && rgba[1] == 0 && rgba[4] == 255 && rgba[5] == 0 && rgba[8] == 0 && rgba[10] == 255,
          "saturation");
    float e3[4] = {NAN, NAN, NAN, NAN};
    CHECK(lc_ref_heatmap_uv(e3, m3, 4, 1, 0.5, rgba) == 0, "heat map");
    CHECK(rgba[12] == 128 && rgba[13] == 128 && rgba[15] == 255 && rgba[3] == 0, "lone covered texel: grey");
    char dir[] = "/tmp/lc_ref_uv_XXXXXX", path[128], err[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    snprintf(path, sizeof path, "%s/uv.png", dir);
    CHECK(lc_ref_write_heatmap_uv(path, e, mask, 4, 2, 0.5, err, sizeof err) == 0, "write: %s", err);
    CHECK(access(path, R_OK) == 0, "uv heat map missing");
    unlink(path);
    rmdir(dir);
}

int main(void) {
    test_subset_rows();
    test_blotch();
    test_heatmap_uv();
    test_lightmap_stats();
    test_grid_stats();
    test_roundtrip();
    CHECK_DONE();
}
