/* mr_gl: LightSkin's gather and occlusion on GL compute (gpu/mr_gl.h, the lc_mr_set_gl hook of engine/mr.h)
 * against the CPU: every output of lc_mr_compute (vpl, point_out, sh) on random lights and points
 * with glossy and occlusion on and off; the radiant wall of test_mr.c on the GPU path; a GL
 * failure returns -1 with a message. Skips (77) when no EGL context can be had. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "engine/mr.h"
#include "gpu/mr_gl.h"

#define NL 600
#define NP 300
#define NO 4

static double rnd(unsigned *s) {
    *s = *s * 1664525u + 1013904223u;
    return (*s >> 8) / 16777216.0;
}

/* Lights on a 2 m box's walls facing inwards, points on small objects inside. */
static void scene(unsigned seed, lc_mr_light *l, lc_mr_point *p, uint32_t *obj, float (*centres)[3]) {
    for (int j = 0; j < NL; j++) {
        int axis = j % 3, side = (j / 3) % 2 ? 1 : -1;
        for (int k = 0; k < 3; k++) l[j].position[k] = (float)(2 * rnd(&seed) - 1), l[j].normal[k] = 0;
        l[j].position[axis] = (float)side;
        l[j].normal[axis] = (float)-side;
        l[j].normal[(axis + 1) % 3] = (float)(0.3 * (rnd(&seed) - 0.5));
        l[j].area = (float)(0.001 + 0.01 * rnd(&seed));
        for (int k = 0; k < 3; k++) l[j].radiosity[k] = (float)(10 * rnd(&seed));
    }
    for (int o = 0; o < NO; o++)
        for (int k = 0; k < 3; k++) centres[o][k] = (float)(0.8 * rnd(&seed) - 0.4);
    for (int i = 0; i < NP; i++) {
        obj[i] = (uint32_t)(i % NO);
        float n[3], len = 0;
        for (int k = 0; k < 3; k++) n[k] = (float)(2 * rnd(&seed) - 1), len += n[k] * n[k];
        len = sqrtf(len);
        for (int k = 0; k < 3; k++) {
            p[i].normal[k] = n[k] / len;
            p[i].position[k] = centres[obj[i]][k] + 0.15f * n[k] / len;
        }
        p[i].radius = 0.03f;
    }
}

/* |a - b| <= tol max(|a|, |b|, floor_frac * the largest |value| of that field over all records):
 * the largest such ratio over n floats in records of `stride` floats (*field: where). Near-zero
 * sums of terms of both signs (a position coordinate near 0, a variance after cancellation) keep
 * the float sums' absolute error, not a relative one: the floor measures them on their field's
 * scale. */
static double worst(const float *a, const float *b, size_t n, size_t stride, double floor_frac, int *field) {
    double fmaxv[64] = {0}, w = 0;
    for (size_t i = 0; i < n; i++) fmaxv[i % stride] = fmax(fmaxv[i % stride], fmax(fabs(a[i]), fabs(b[i])));
    for (size_t i = 0; i < n; i++) {
        double m = fmax(fmax(fabs(a[i]), fabs(b[i])), floor_frac * fmaxv[i % stride]);
        double r = m > 0 ? fabs((double)a[i] - b[i]) / m : 0;
        if (r > w) w = r, *field = (int)(i % stride);
    }
    return w;
}

static void compare(lc_mr_gl *g, int glossy, int occlusion) {
    static lc_mr_light l[NL];
    static lc_mr_point p[NP];
    static uint32_t obj[NP];
    static float centres[NO][3], sh[2][NO][27];
    static lc_mr_vpl v[2][NP];
    static lc_mr_point_out po[2][NP];
    scene(7u + (unsigned)(2 * glossy + occlusion), l, p, obj, centres);
    lc_mr_camera cam = {.translation = {0.1f, 0.2f, 0.9f}, .rotation = {0, 0, 0, 1}};
    lc_mr_params prm = lc_mr_params_default();
    prm.glossy = glossy, prm.occlusion = occlusion;
    char err[512] = "";
    for (int b = 0; b < 2; b++) {
        lc_mr *m = lc_mr_create(0);
        lc_mr_set_gl(m, b ? g : NULL);
        int rc = lc_mr_set_lights(m, &cam, l, NL, &prm, err, sizeof err);
        if (rc == 0)
            rc = lc_mr_compute(m, p, NP, obj, NO, (const float(*)[3])centres, v[b], po[b], sh[b], err, sizeof err);
        CHECK(rc == 0, "%s compute (glossy %d, occlusion %d): %s", b ? "GL" : "CPU", glossy, occlusion, err);
        lc_mr_release(m);
    }
    /* floors: 1 % of each field's largest value */
    int f_e = -1, f_v = -1, f_sh = -1;
    double w_e = worst(&po[0][0].e_d[0], &po[1][0].e_d[0], sizeof po[0] / (sizeof(float)),
                       sizeof po[0][0] / (sizeof(float)), 1e-2, &f_e);
    double w_v = worst(&v[0][0].i_d[0], &v[1][0].i_d[0], sizeof v[0] / (sizeof(float)),
                       sizeof v[0][0] / (sizeof(float)), 1e-2, &f_v);
    double w_sh = worst(&sh[0][0][0], &sh[1][0][0], sizeof sh[0] / (sizeof(float)), 27, 1e-2, &f_sh);
    int lit = 0;
    int shaded = 0;
    for (int i = 0; i < NP; i++) {
        lit += po[0][i].e_d[0] > 0 && (!glossy || po[0][i].e_s[0] > 0);
        shaded += po[0][i].occ_d > 0.01f;
    }
    CHECK(!occlusion || shaded > NP / 10, "too few occluded points (%d) to test the occlusion", shaded);
    fprintf(stderr,
            "glossy %d occlusion %d: worst relative difference point_out %.2e (float %d) vpl %.2e (float %d) "
            "sh %.2e (%d lit, %d occluded)\n",
            glossy, occlusion, w_e, f_e, w_v, f_v, w_sh, lit, shaded);
    CHECK(lit > NP / 4, "too few lit points (%d) for the comparison to mean anything", lit);
    /* Diffuse: 1e-4. Glossy: 1e-3: cos^k g (k = 16) multiplies cos g's float rounding by k and a
     * few lights near the mirror direction carry l_s, so the float sums keep ~1e-4..5e-4 there. */
    double tol = glossy ? 1e-3 : 1e-4;
    CHECK(w_e <= tol, "point_out: %.3e (float %d)", w_e, f_e);
    CHECK(w_v <= tol, "vpl: %.3e (float %d)", w_v, f_v);
    CHECK(w_sh == 0, "sh (CPU in both): %.3e", w_sh);
}

/* Past llvmpipe's 65535-iteration loop limit and the dispatch chunks (LC_MR_GL_CHUNK): 70 000
 * lights at 64 points, then 17 000 points (occluders in two chunks); each against the CPU. Before
 * the chunks, the lights past ~64k were silently dropped (E 3-50 % low). */
static void test_chunks(lc_mr_gl *g) {
    const uint32_t cases[2][2] = {{70000, 64}, {256, LC_MR_GL_CHUNK + 616}};
    for (int c = 0; c < 2; c++) {
        uint32_t nl = cases[c][0], np = cases[c][1];
        unsigned seed = 3;
        lc_mr_light *l = calloc(nl, sizeof *l);
        lc_mr_point *p = calloc(np, sizeof *p);
        uint32_t *obj = calloc(np, sizeof *obj);
        lc_mr_point_out *po[2] = {calloc(np, sizeof *po[0]), calloc(np, sizeof *po[1])};
        lc_mr_vpl *v = calloc(np, sizeof *v);
        float centre[1][3] = {{0, 0, 0}};
        CHECK(l && p && obj && po[0] && po[1] && v, "out of memory");
        if (!l || !p || !obj || !po[0] || !po[1] || !v) goto next;
        for (uint32_t j = 0; j < nl; j++) {
            l[j].position[0] = (float)(4 * rnd(&seed) - 2), l[j].position[1] = (float)(4 * rnd(&seed) - 2);
            l[j].position[2] = 2.0f, l[j].normal[2] = -1.0f, l[j].area = 16.0f / (float)nl;
            l[j].radiosity[0] = l[j].radiosity[1] = l[j].radiosity[2] = (float)(1 + rnd(&seed));
        }
        for (uint32_t i = 0; i < np; i++) { /* a 1 m slab of points facing the lights */
            p[i].position[0] = (float)(rnd(&seed) - 0.5), p[i].position[1] = (float)(rnd(&seed) - 0.5);
            p[i].position[2] = (float)(rnd(&seed) - 0.5), p[i].normal[2] = 1.0f, p[i].radius = 0.01f;
        }
        lc_mr_camera cam = {.translation = {0, 0, 3}, .rotation = {0, 0, 0, 1}};
        lc_mr_params prm = lc_mr_params_default();
        char err[512] = "";
        for (int b = 0; b < 2; b++) {
            lc_mr *m = lc_mr_create(0);
            lc_mr_set_gl(m, b ? g : NULL);
            int rc = lc_mr_set_lights(m, &cam, l, nl, &prm, err, sizeof err);
            if (rc == 0)
                rc = lc_mr_compute(m, p, np, obj, 1, (const float(*)[3])centre, v, po[b], NULL, err, sizeof err);
            CHECK(rc == 0, "%u lights x %u points on %s: %s", nl, np, b ? "GL" : "CPU", err);
            lc_mr_release(m);
        }
        /* E_d's floor: 10 % of the largest (most points are nearly fully occluded, where E (1 - o)
         * turns o's 1e-6 into a large relative difference of a small E) */
        double we = 0, wo = 0, emax = 0;
        int shaded = 0;
        for (uint32_t i = 0; i < np; i++) emax = fmax(emax, po[0][i].e_d[0]);
        for (uint32_t i = 0; i < np; i++) {
            for (int k = 0; k < 3; k++)
                we = fmax(we, fabs(po[1][i].e_d[k] - po[0][i].e_d[k]) / fmax(fabs(po[0][i].e_d[k]), 0.1 * emax));
            wo = fmax(wo, fabs(po[1][i].occ_d - po[0][i].occ_d));
            shaded += po[0][i].occ_d > 0.01f;
        }
        fprintf(stderr, "%u lights x %u points: E_d worst relative difference %.2e, occ_d worst %.2e (%d occluded)\n",
                nl, np, we, wo, shaded);
        CHECK(we <= 1e-4, "%u lights x %u points: E_d %.3e", nl, np, we);
        CHECK(wo <= 1e-4, "%u lights x %u points: occ_d %.3e", nl, np, wo);
        CHECK(c == 0 || shaded > (int)np / 10, "too few occluded points (%d)", shaded);
    next:
        free(l), free(p), free(obj), free(po[0]), free(po[1]), free(v);
    }
}

static double rect_form_factor(double hx, double hy, double d) {
    double x = hx / d, y = hy / d;
    double c = (x / sqrt(1 + x * x) * atan(y / sqrt(1 + x * x)) + y / sqrt(1 + y * y) * atan(x / sqrt(1 + y * y))) /
        (2 * M_PI);
    return 4 * c;
}

/* test_mr.c's radiant wall at 256x192 on the GPU: within 2 % of pi L F. */
static void test_wall(lc_mr_gl *g) {
    const uint32_t w = 256, h = 192;
    const float z = 2.0f, L = 50.0f, f = 0.78f * (float)w;
    float *depth = malloc((size_t)w * h * sizeof *depth), *rad = malloc((size_t)w * h * 3 * sizeof *rad);
    for (size_t i = 0; i < (size_t)w * h; i++) {
        depth[i] = z;
        rad[3 * i] = rad[3 * i + 1] = rad[3 * i + 2] = L;
    }
    lc_mr_camera cam = {
        .width = w, .height = h, .fx = f, .fy = f, .cx = w / 2.0f, .cy = h / 2.0f, .rotation = {0, 0, 0, 1}};
    lc_mr_params p = lc_mr_params_default();
    p.max_lights = LC_MR_MAX_LIGHTS;
    p.occlusion = 0;
    lc_mr *m = lc_mr_create(0);
    lc_mr_set_gl(m, g);
    char err[512] = "";
    double e = -1;
    int rc = lc_mr_set_frame(m, &cam, depth, rad, NULL, &p, err, sizeof err);
    lc_mr_point pt = {.position = {0, 0, -1}, .normal = {0, 0, -1}, .radius = 0.01f};
    uint32_t obj = 0;
    float centre[1][3] = {{0, 0, -1}};
    lc_mr_vpl v;
    lc_mr_point_out po;
    if (rc == 0) rc = lc_mr_compute(m, &pt, 1, &obj, 1, (const float(*)[3])centre, &v, &po, NULL, err, sizeof err);
    CHECK(rc == 0, "wall on GL: %s", err);
    if (rc == 0) {
        double want = M_PI * L * rect_form_factor(w / 2.0 / f * z, h / 2.0 / f * z, z - 1);
        e = po.e_d[1] / want - 1;
        fprintf(stderr, "wall %ux%u on GL (%u lights): E relative error %+.4f%%\n", w, h, lc_mr_light_count(m),
                100 * e);
        CHECK(fabs(e) <= 0.02, "wall: %.4f", e);
    }
    /* A GL failure: -1 with a message naming mr_gl; the CPU then computes the same frame. */
    lc_mr_gl_inject_failure(g);
    err[0] = 0;
    rc = lc_mr_compute(m, &pt, 1, &obj, 1, (const float(*)[3])centre, &v, &po, NULL, err, sizeof err);
    CHECK(rc == -1 && strstr(err, "mr_gl"), "a GL failure: rc %d, err '%s'", rc, err);
    lc_mr_set_gl(m, NULL);
    rc = lc_mr_compute(m, &pt, 1, &obj, 1, (const float(*)[3])centre, &v, &po, NULL, err, sizeof err);
    CHECK(rc == 0 && po.e_d[1] > 0, "the CPU after a GL failure: %s", err);
    /* Without lights the occlusion is the first GL stage: its failure is reported the same way. */
    lc_mr_set_gl(m, g);
    lc_mr_point two[2] = {pt, {.position = {0, 0, -1.5f}, .normal = {0, 0, 1}, .radius = 0.01f}};
    uint32_t objs[2] = {0, 0};
    lc_mr_vpl v2[2];
    p.occlusion = 1;
    rc = lc_mr_set_lights(m, &cam, NULL, 0, &p, err, sizeof err);
    lc_mr_gl_inject_failure(g);
    if (rc == 0) rc = lc_mr_compute(m, two, 2, objs, 1, (const float(*)[3])centre, v2, NULL, NULL, err, sizeof err);
    CHECK(rc == -1 && strstr(err, "mr_gl/occlusion"), "a GL occlusion failure: rc %d, err '%s'", rc, err);
    lc_mr_release(m);
    free(depth);
    free(rad);
}

int main(void) {
    char err[512] = "";
    lc_mr_gl *g = lc_mr_gl_create(err, sizeof err);
    if (!g && strstr(err, "mr_gather")) {
        CHECK(0, "the shader does not build: %s", err);
        CHECK_DONE();
    }
    if (!g) {
        fprintf(stderr, "SKIP: no EGL context: %s\n", err);
        return CHECK_SKIP_RC;
    }
    for (int variant = 0; variant < 2; variant++) {
        if (variant) {
            lc_mr_gl_release(g);
            g = lc_mr_gl_create_variant(0, err, sizeof err);
            CHECK(g != NULL, "the direct variant: %s", err);
            if (!g) break;
        }
        fprintf(stderr, "%s\n", lc_mr_gl_description(g));
        for (int glossy = 0; glossy < 2; glossy++)
            for (int occ = 0; occ < 2; occ++) compare(g, glossy, occ);
        test_wall(g);
        if (variant == 0) test_chunks(g); /* the default variant (seconds on llvmpipe) */
    }
    lc_mr_gl_release(g);
    CHECK_DONE();
}
