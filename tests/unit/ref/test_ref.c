/* lc_ref, the path-traced reference, against closed forms (each texel within a few standard
 * errors of the exact value, plus a small margin for float offsets):
 *  - a uniformly emitting closed box of albedo rho: E = pi Le / (1 - rho) at every texel and
 *    every grid cell, for any normal (infinitely many bounces);
 *  - a small emitting patch above a floor: E = pi Le F, F the point-to-rectangle form factor;
 *  - a surfel pair (two facing patches): one patch lit by the emitter (closed form), the
 *    emitter's texels lit by what the other patch reflects (quadrature of the closed form);
 *  - a floor lit by a directional light, with a black patch above it casting a shadow: the
 *    patch's texels see rho E_sun (F_floor - F_shadow); the same floor under a point light
 *    (quadrature); lights reach the lightmap only through surfaces;
 *  - results do not depend on the thread count. */
#include <math.h>

#include "check.h"
#include "engine/engine_fixture.h"
#include "ref/ref.h"
#include "util/sh.h"

#if defined(__SANITIZE_ADDRESS__)
#define REF_TEST_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define REF_TEST_SANITIZED 1
#endif
#endif
#ifndef REF_TEST_SANITIZED
#define REF_TEST_SANITIZED 0
#endif
/* Samples per cache: sanitizer builds run ~10x slower; fewer samples, wider error bars. */
#define REF_SPP(n) (REF_TEST_SANITIZED ? (n) / 4 : (n))

/* Form factor from a differential area to a parallel rectangle [0,x]x[0,z] at height c, one
 * corner above the point; odd in x and z so rectangles anywhere follow by superposition. */
static double ff_corner(double x, double z, double c) {
    double X = fabs(x) / c, Z = fabs(z) / c;
    double f = (X / sqrt(1 + X * X) * atan(Z / sqrt(1 + X * X)) + Z / sqrt(1 + Z * Z) * atan(X / sqrt(1 + Z * Z))) /
        (2 * M_PI);
    return (x < 0 ? -1 : 1) * (z < 0 ? -1 : 1) * f;
}
/* Point at (px, pz) facing a parallel rectangle [x0,x1]x[z0,z1] at distance c. */
static double ff_rect(double px, double pz, double x0, double x1, double z0, double z1, double c) {
    x0 -= px, x1 -= px, z0 -= pz, z1 -= pz;
    return ff_corner(x1, z1, c) - ff_corner(x0, z1, c) - ff_corner(x1, z0, c) + ff_corner(x0, z0, c);
}

/* Per-texel agreement: combined z-score of the sum, and per-texel bounds. */
typedef struct {
    double sum_d, sum_var, sum_exact;
    int n, outliers;
    double worst_z;
} agree;

static void agree_add(agree *a, double got, double se, double exact) {
    double d = got - exact;
    a->sum_d += d;
    a->sum_var += se * se;
    a->sum_exact += exact;
    a->n++;
    double z = fabs(d) / (5 * se + 0.01 * fabs(exact) + 1e-9);
    if (z > 1) a->outliers++;
    if (z > a->worst_z) a->worst_z = z;
}

static void agree_check(const agree *a, const char *what, double margin) {
    CHECK(a->n > 20, "%s: only %d texels compared", what, a->n);
    double tol = 3 * sqrt(a->sum_var) + margin * a->sum_exact;
    CHECK(fabs(a->sum_d) <= tol, "%s: mean error %.5f (%.3f%%), allowed %.5f (3 sigma %.5f)", what, a->sum_d / a->n,
          100 * a->sum_d / a->sum_exact, tol / a->n, 3 * sqrt(a->sum_var) / a->n);
    CHECK(a->outliers <= a->n / 100, "%s: %d of %d texels beyond 5 sigma + 1%% (worst %.2fx the bound)", what,
          a->outliers, a->n, a->worst_z);
    fprintf(stderr, "%s: %d texels, mean rel error %+.4f%%, 3-sigma of the mean %.4f%%\n", what, a->n,
            100 * a->sum_d / a->sum_exact, 100 * 3 * sqrt(a->sum_var) / a->sum_exact);
}

/* Renders with the fixture's bake and state. */
static int render(const fixture *f, const lc_engine_state *st, uint32_t spp, int grid, int threads,
                  lc_ref_result *res) {
    char err[256];
    lc_ref *r = lc_ref_create(f->bake, st, threads, err, sizeof err);
    if (!r) {
        fprintf(stderr, "lc_ref_create: %s\n", err);
        return -1;
    }
    lc_ref_settings s = lc_ref_default_settings();
    s.spp = spp;
    s.batch_spp = spp;
    s.grid = grid;
    s.quiet = 1;
    s.threads = threads;
    int rc = lc_ref_render(r, &s, res, err, sizeof err);
    if (rc != 0) fprintf(stderr, "lc_ref_render: %s\n", err);
    lc_ref_release(r);
    return rc;
}

static const char *small_bake[] = {"--surfels",
                                   "1024",
                                   "--links",
                                   "16",
                                   "--node-samples",
                                   "4",
                                   "--final-samples",
                                   "4",
                                   "--probe-rays",
                                   "64",
                                   "--atlas-size",
                                   "64",
                                   "--grid-max-dim",
                                   "4",
                                   NULL};

static void test_closed_box(void) {
    static char obj[1 << 16];
    obj[0] = 0;
    fixture_inward_box(obj, sizeof obj, 1.0f, 4, "wall", 1);
    const char *mtl = "newmtl wall\nKd 0.5 0.5 0.5\nKe 1 1 1\n";
    const char *flags[] = {"--surfels",
                           "1024",
                           "--links",
                           "16",
                           "--node-samples",
                           "4",
                           "--final-samples",
                           "4",
                           "--probe-rays",
                           "64",
                           "--atlas-size",
                           "32",
                           "--grid-max-dim",
                           "5",
                           NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "closed box bake failed");
        return;
    }
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    lc_ref_result res;
    if (render(&f, &st, REF_SPP(1024), 1, 0, &res) != 0) {
        CHECK(0, "closed box render failed");
        fixture_release(&f);
        return;
    }
    const double expect = M_PI * 1.0 / (1.0 - 0.5);
    agree a = {0};
    for (uint32_t c = 0; c < f.v->n_texel_caches; c++) {
        uint32_t i = f.v->caches[c].index;
        agree_add(&a, res.lightmap[3 * i], res.lightmap_stderr[3 * i], expect);
    }
    agree_check(&a, "closed box texels", 0.002);
    /* Grid: interior cells, irradiance for six normals (each exactly pi Le / (1 - rho)). */
    agree g = {0};
    for (uint32_t i = 0; i < res.n_cells; i++) {
        const float *p = f.v->caches[f.v->grid[i]].position;
        if (!res.grid_mask[i] || p[0] < 0.05f || p[0] > 0.95f || p[1] < 0.05f || p[1] > 0.95f || p[2] < 0.05f ||
            p[2] > 0.95f)
            continue;
        const float *sh = res.grid_sh + 27 * (size_t)i, *se = res.grid_sh_stderr + 27 * (size_t)i;
        for (int axis = 0; axis < 6; axis++) {
            float d[3] = {0, 0, 0}, y[9];
            d[axis / 2] = axis % 2 ? -1.0f : 1.0f;
            lc_sh_eval(3, d, y);
            double e = 0, var = 0;
            for (int j = 0; j < 9; j++) {
                e += sh[3 * j] * y[j];
                var += (double)se[3 * j] * se[3 * j] * y[j] * y[j]; /* coefficients' errors, as if independent */
            }
            agree_add(&g, e, sqrt(var), expect);
        }
        /* Isotropic: the band-1 and band-2 coefficients vanish. */
        for (int j = 1; j < 9; j++)
            CHECK(fabs(sh[3 * j]) < 5 * se[3 * j] + 0.01 * expect, "closed box cell %u: c_%d = %.4f (stderr %.4f)", i,
                  j, sh[3 * j], se[3 * j]);
    }
    agree_check(&g, "closed box grid", 0.003);
    CHECK(res.texel_stats.mean_rel_stderr > 0 && res.texel_stats.mean_rel_stderr < 0.05,
          "closed box: mean relative stderr %.4f", res.texel_stats.mean_rel_stderr);
    lc_ref_result_free(&res);
    fixture_release(&f);
}

static void test_patch(void) {
    const char *obj = "usemtl floor\nv -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\nf 1 2 3 4\n"
                      "usemtl lamp\nv -0.15 1 -0.15\nv 0.15 1 -0.15\nv 0.15 1 0.15\nv -0.15 1 0.15\nf 5 6 7 8\n";
    const char *mtl = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n";
    fixture f;
    if (fixture_bake(&f, obj, mtl, small_bake) != 0) {
        CHECK(0, "patch bake failed");
        return;
    }
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    lc_ref_result res;
    if (render(&f, &st, REF_SPP(1024), 0, 0, &res) != 0) {
        CHECK(0, "patch render failed");
        fixture_release(&f);
        return;
    }
    agree a = {0};
    int lamp_texels = 0;
    for (uint32_t c = 0; c < f.v->n_texel_caches; c++) {
        const lc_lcb_cache *ca = &f.v->caches[c];
        uint32_t i = ca->index;
        if (ca->normal[1] > 0.99f && ca->position[1] < 0.01f) {
            double exact = M_PI * 10.0 *
                ff_rect(ca->position[0], ca->position[2], -0.15, 0.15, -0.15, 0.15, 1.0 - ca->position[1]);
            agree_add(&a, res.lightmap[3 * i], res.lightmap_stderr[3 * i], exact);
        } else if (ca->normal[1] < -0.99f) {
            lamp_texels++; /* lit by the floor's reflection: see the surfel pair */
        }
    }
    agree_check(&a, "patch form factor", 0.002);
    CHECK(lamp_texels > 0, "no lamp texels");
    lc_ref_result_free(&res);
    fixture_release(&f);
}

static void test_surfel_pair(void) {
    /* Emitter A (side 0.2, black) at y = 0.5 facing down; receiver B (side 0.2, albedo 0.8) at
     * y = 0 facing up. B sees A only (exact); A sees B's reflection, E_B varying over B. */
    const double h = 0.5, a2 = 0.1, rho = 0.8, le = 50;
    const char *obj = "usemtl recv\nv -0.1 0 -0.1\nv -0.1 0 0.1\nv 0.1 0 0.1\nv 0.1 0 -0.1\nf 1 2 3 4\n"
                      "usemtl lamp\nv -0.1 0.5 -0.1\nv 0.1 0.5 -0.1\nv 0.1 0.5 0.1\nv -0.1 0.5 0.1\nf 5 6 7 8\n";
    const char *mtl = "newmtl recv\nKd 0.8 0.8 0.8\nnewmtl lamp\nKd 0 0 0\nKe 50 50 50\n";
    const char *flags[] = {"--surfels",
                           "1024",
                           "--links",
                           "16",
                           "--node-samples",
                           "4",
                           "--final-samples",
                           "4",
                           "--probe-rays",
                           "64",
                           "--atlas-size",
                           "32",
                           "--grid-max-dim",
                           "3",
                           NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "surfel pair bake failed");
        return;
    }
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    lc_ref_result res;
    if (render(&f, &st, REF_SPP(8192), 0, 0, &res) != 0) {
        CHECK(0, "surfel pair render failed");
        fixture_release(&f);
        return;
    }
    agree ab = {0}, aa = {0};
    const int N = 60;
    for (uint32_t c = 0; c < f.v->n_texel_caches; c++) {
        const lc_lcb_cache *ca = &f.v->caches[c];
        uint32_t i = ca->index;
        const float *p = ca->position;
        if (ca->normal[1] > 0.99f) {
            double exact = M_PI * le * ff_rect(p[0], p[2], -a2, a2, -a2, a2, h - p[1]);
            agree_add(&ab, res.lightmap[3 * i], res.lightmap_stderr[3 * i], exact);
        } else if (ca->normal[1] < -0.99f) {
            /* E_A(x) = int_B (rho / pi) E_B(y) cos cos / d^2 dA, midpoint rule over B. */
            double sum = 0, da = (2 * a2 / N) * (2 * a2 / N);
            for (int jz = 0; jz < N; jz++)
                for (int jx = 0; jx < N; jx++) {
                    double yx = -a2 + (jx + 0.5) * 2 * a2 / N, yz = -a2 + (jz + 0.5) * 2 * a2 / N;
                    double eb = M_PI * le * ff_rect(yx, yz, -a2, a2, -a2, a2, h);
                    double dx = yx - p[0], dz = yz - p[2], dy = p[1];
                    double d2 = dx * dx + dy * dy + dz * dz;
                    sum += rho / M_PI * eb * (dy * dy) / (d2 * d2) * da;
                }
            agree_add(&aa, res.lightmap[3 * i], res.lightmap_stderr[3 * i], sum);
        }
    }
    agree_check(&ab, "surfel pair: receiver (direct from the emitter)", 0.002);
    agree_check(&aa, "surfel pair: emitter (one bounce off the receiver)", 0.005);
    lc_ref_result_free(&res);
    fixture_release(&f);
}

static void test_lights(void) {
    /* Floor 4 x 4 (albedo 0.5) and a black 0.6 x 0.6 patch at y = 1 facing down. */
    const char *obj = "usemtl floor\nv -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\nf 1 2 3 4\n"
                      "usemtl black\nv -0.3 1 -0.3\nv 0.3 1 -0.3\nv 0.3 1 0.3\nv -0.3 1 0.3\nf 5 6 7 8\n";
    const char *mtl = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl black\nKd 0 0 0\n";
    fixture f;
    if (fixture_bake(&f, obj, mtl, small_bake) != 0) {
        CHECK(0, "lights bake failed");
        return;
    }
    /* 1. Sun straight down, 1000 lux: the floor gets 1000 lux except the patch's shadow. */
    lc_engine_light sun = {.id = "sun",
                           .type = LC_ENGINE_LIGHT_DIRECTIONAL,
                           .color = {1, 1, 1},
                           .intensity = 1000,
                           .direction = {0, -1, 0}};
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.lights = &sun;
    st.n_lights = 1;
    lc_ref_result res;
    if (render(&f, &st, REF_SPP(2048), 0, 0, &res) != 0) {
        CHECK(0, "sun render failed");
        fixture_release(&f);
        return;
    }
    agree a = {0};
    for (uint32_t c = 0; c < f.v->n_texel_caches; c++) {
        const lc_lcb_cache *ca = &f.v->caches[c];
        uint32_t i = ca->index;
        if (ca->normal[1] < -0.99f) {
            double c0 = ca->position[1];
            double ff = ff_rect(ca->position[0], ca->position[2], -2, 2, -2, 2, c0) -
                ff_rect(ca->position[0], ca->position[2], -0.3, 0.3, -0.3, 0.3, c0);
            agree_add(&a, res.lightmap[3 * i], res.lightmap_stderr[3 * i], 0.5 * 1000 * ff);
        } else {
            /* The floor sees only the black patch: its lightmap is empty (direct sun is not in it). */
            CHECK(res.lightmap[3 * i] == 0, "floor texel %u under the sun: %g, expected 0", c, res.lightmap[3 * i]);
        }
    }
    agree_check(&a, "sun: patch texels (floor reflection minus the shadow)", 0.003);
    lc_ref_result_free(&res);

    /* 2. Point light (100 cd) at y = 0.5 under the patch: the floor gets I h / d^3. */
    lc_engine_light pt = {
        .id = "bulb", .type = LC_ENGINE_LIGHT_POINT, .color = {1, 1, 1}, .intensity = 100, .position = {0, 0.5f, 0}};
    st.lights = &pt;
    if (render(&f, &st, REF_SPP(2048), 0, 0, &res) != 0) {
        CHECK(0, "point render failed");
        fixture_release(&f);
        return;
    }
    agree b = {0};
    const int N = 200;
    int done = 0;
    for (uint32_t c = 0; c < f.v->n_texel_caches && done < 60; c++) {
        const lc_lcb_cache *ca = &f.v->caches[c];
        if (ca->normal[1] > -0.99f) continue;
        const float *p = ca->position;
        double sum = 0, da = (4.0 / N) * (4.0 / N);
        for (int jz = 0; jz < N; jz++)
            for (int jx = 0; jx < N; jx++) {
                double yx = -2 + (jx + 0.5) * 4.0 / N, yz = -2 + (jz + 0.5) * 4.0 / N;
                double r2 = yx * yx + yz * yz + 0.25;
                double ef = 100 * 0.5 / (r2 * sqrt(r2)); /* I cos / d^2 with cos = h / d */
                double dx = yx - p[0], dz = yz - p[2], dy = p[1];
                double d2 = dx * dx + dy * dy + dz * dz;
                sum += 0.5 / M_PI * ef * (dy * dy) / (d2 * d2) * da;
            }
        agree_add(&b, res.lightmap[3 * ca->index], res.lightmap_stderr[3 * ca->index], sum);
        done++;
    }
    agree_check(&b, "point light: patch texels (floor reflection)", 0.003);
    lc_ref_result_free(&res);

    /* 3. The same render on 1 and 2 threads: identical bytes. */
    lc_ref_result r1, r2;
    if (render(&f, &st, 16, 1, 1, &r1) == 0 && render(&f, &st, 16, 1, 2, &r2) == 0) {
        size_t texels = (size_t)r1.width * r1.height;
        CHECK(memcmp(r1.lightmap, r2.lightmap, texels * 3 * sizeof(float)) == 0, "lightmap differs across threads");
        CHECK(memcmp(r1.grid_sh, r2.grid_sh, (size_t)r1.n_cells * 27 * sizeof(float)) == 0,
              "grid differs across threads");
        lc_ref_result_free(&r1);
        lc_ref_result_free(&r2);
    } else {
        CHECK(0, "determinism renders failed");
    }
    fixture_release(&f);
}

int main(void) {
    test_closed_box();
    test_patch();
    test_surfel_pair();
    test_lights();
    CHECK_DONE();
}
