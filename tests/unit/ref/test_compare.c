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

int main(void) {
    test_lightmap_stats();
    test_grid_stats();
    test_roundtrip();
    CHECK_DONE();
}
