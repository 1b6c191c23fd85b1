/* LightSkin (engine/mr.h) against closed forms: the disc form factor (exact on its axis, the
 * exact parallel-disc formula off it, the point limit), the renormalisation identity, a
 * uniformly radiant wall seen by a synthetic RGB-D camera against pi L F(point -> rectangle)
 * as the capture's resolution grows, the disc occlusion (and its documented double
 * occlusion), and the per-object irradiance SH inside a uniformly radiant sphere. */
#include <math.h>
#include <stdlib.h>

#include "check.h"
#include "engine/mr.h"

static double rnd(unsigned *s) {
    *s = *s * 1664525u + 1013904223u;
    return (*s >> 8) / 16777216.0;
}

/* The exact form factor from an element to a parallel, coaxially facing disc of radius r,
 * centre h above the element's plane and a off its normal line. */
static double exact_parallel_disc(double r, double h, double a) {
    double H = h / a, R = r / a, Z = 1 + H * H + R * R;
    return 0.5 * (1 - (Z - 2 * R * R) / sqrt(Z * Z - 4 * R * R));
}

static void test_form_factor(void) {
    float x[3] = {0, 0, 0}, n[3] = {0, 0, 1}, down[3] = {0, 0, -1};
    for (double r = 0.1; r < 3; r *= 2.5) {
        float l[3] = {0, 0, 1.5f};
        CHECK_NEAR(lc_mr_disc_form_factor(x, n, l, down, (float)(r * r)), r * r / (r * r + 2.25), 1e-5);
    }
    /* off axis: eq. 3 against the exact formula; the errors of eq. 3 the seed notes list */
    const double cases[4][4] = {{0.1, 1, 1, -0.007}, {0.5, 1, 0.5, -0.090}, {0.5, 1, 1, -0.157}, {1, 1, 1, -0.397}};
    for (int i = 0; i < 4; i++) {
        double r = cases[i][0], h = cases[i][1], a = cases[i][2];
        float l[3] = {(float)a, 0, (float)h};
        double f3 = lc_mr_disc_form_factor(x, n, l, down, (float)(r * r));
        double ex = exact_parallel_disc(r, h, a);
        CHECK(fabs((f3 / ex - 1) - cases[i][3]) < 0.003, "r %g h %g a %g: eq. 3 error %.4f, expected %.3f", r, h, a,
              f3 / ex - 1, cases[i][3]);
    }
    /* the small-disc limit: A cos cos / (pi d^2) */
    float l[3] = {0.6f, 0.2f, 0.9f}, nl[3] = {-0.3f, 0, -1};
    float len = sqrtf(nl[0] * nl[0] + nl[2] * nl[2]);
    nl[0] /= len, nl[2] /= len;
    double d2 = 0.36 + 0.04 + 0.81, d = sqrt(d2), area = 1e-6;
    double ci = 0.9 / d, cj = -(nl[0] * 0.6 + nl[2] * 0.9) / d;
    CHECK_NEAR(lc_mr_disc_form_factor(x, n, l, nl, (float)(area / M_PI)), area * ci * cj / (M_PI * d2), 1e-4);
    /* a light behind the receiver, or facing away, gives nothing */
    float below[3] = {0, 0, -1}, up[3] = {0, 0, 1};
    CHECK(lc_mr_disc_form_factor(x, n, below, up, 0.01f) == 0, "behind the receiver");
    float above[3] = {0, 0, 1};
    CHECK(lc_mr_disc_form_factor(x, n, above, up, 0.01f) == 0, "disc facing away");
}

static void mirror(const float d[3], const float n[3], float o[3]) {
    float k = 2 * (d[0] * n[0] + d[1] * n[1] + d[2] * n[2]);
    for (int i = 0; i < 3; i++) o[i] = k * n[i] - d[i];
}

static void unit(float v[3]) {
    float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int i = 0; i < 3; i++) v[i] /= l;
}

/* Eq. 11: a point light I at l gives E at x again, diffuse and glossy, for random light sets;
 * E_d equals the brute-force sum of eq. 4. */
static void test_renormalisation(void) {
    unsigned seed = 7;
    lc_mr *m = lc_mr_create(1);
    lc_mr_params p = lc_mr_params_default();
    p.occlusion = 0;
    p.spec_exponent = 20;
    for (int trial = 0; trial < 20; trial++) {
        lc_mr_light lights[64];
        for (int j = 0; j < 64; j++) {
            lc_mr_light *L = &lights[j];
            for (int k = 0; k < 3; k++) L->position[k] = (float)(rnd(&seed) * 4 - 2);
            L->position[2] = (float)(1 + rnd(&seed) * 2);
            for (int k = 0; k < 3; k++) L->normal[k] = (float)(rnd(&seed) - 0.5);
            L->normal[2] = -1;
            unit(L->normal);
            L->area = (float)(0.001 + 0.01 * rnd(&seed));
            for (int k = 0; k < 3; k++) L->radiosity[k] = (float)(10 * rnd(&seed));
        }
        lc_mr_camera cam = {.translation = {0.3f, -0.5f, 3}, .rotation = {0, 0, 0, 1}};
        char err[256];
        CHECK(lc_mr_set_lights(m, &cam, lights, 64, &p, err, sizeof err) == 0, "%s", err);
        lc_mr_point pt = {
            .position = {0, 0, 0}, .normal = {(float)(rnd(&seed) - 0.5) * 0.5f, 0.1f, 1}, .radius = 0.05f};
        unit(pt.normal);
        uint32_t obj = 0;
        float centre[1][3] = {{0, 0, 0}};
        lc_mr_vpl v;
        lc_mr_point_out po;
        float sh[1][27];
        CHECK(lc_mr_compute(m, &pt, 1, &obj, 1, (const float(*)[3])centre, &v, &po, sh, err, sizeof err) == 0, "%s",
              err);
        double brute = 0;
        for (int j = 0; j < 64; j++)
            brute += lights[j].radiosity[1] *
                lc_mr_disc_form_factor(pt.position, pt.normal, lights[j].position, lights[j].normal,
                                       lights[j].area / (float)M_PI);
        CHECK_NEAR(po.e_d[1], brute, 1e-4);
        float dd[3] = {v.l_d[0], v.l_d[1], v.l_d[2]};
        float dist2 = dd[0] * dd[0] + dd[1] * dd[1] + dd[2] * dd[2];
        unit(dd);
        float cosd = dd[0] * pt.normal[0] + dd[1] * pt.normal[1] + dd[2] * pt.normal[2];
        for (int k = 0; k < 3; k++) CHECK_NEAR(v.i_d[k] * cosd / dist2, po.e_d[k], 1e-5);
        /* glossy: cos^k between the mirror of the light direction and the camera */
        float ds[3] = {v.l_s[0], v.l_s[1], v.l_s[2]}, ms[3], view[3] = {0.3f, -0.5f, 3};
        float sdist2 = ds[0] * ds[0] + ds[1] * ds[1] + ds[2] * ds[2];
        unit(ds);
        unit(view);
        mirror(ds, pt.normal, ms);
        float cg = ms[0] * view[0] + ms[1] * view[1] + ms[2] * view[2];
        double lobe = cg > 0 ? pow(cg, p.spec_exponent) : 0;
        for (int k = 0; k < 3; k++) CHECK_NEAR(v.i_s[k] * lobe / sdist2, po.e_s[k], 1e-4);
    }
    lc_mr_release(m);
}

/* A point facing a parallel rectangle [-hx, hx] x [-hy, hy] at distance d, on its axis. */
static double rect_form_factor(double hx, double hy, double d) {
    double x = hx / d, y = hy / d;
    double c = (x / sqrt(1 + x * x) * atan(y / sqrt(1 + x * x)) + y / sqrt(1 + y * y) * atan(x / sqrt(1 + y * y))) /
        (2 * M_PI);
    return 4 * c;
}

/* The camera at the origin looking down -Z sees a uniformly radiant wall filling its image at
 * 2 m; the sparse point 1 m in front of the wall faces it. */
static double wall_error(uint32_t w, uint32_t h, int filter) {
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
    p.filter = filter;
    p.occlusion = 0;
    lc_mr *m = lc_mr_create(0);
    char err[256];
    double e = -1;
    if (lc_mr_set_frame(m, &cam, depth, rad, NULL, &p, err, sizeof err) == 0) {
        lc_mr_point pt = {.position = {0, 0, -1}, .normal = {0, 0, -1}, .radius = 0.01f};
        uint32_t obj = 0;
        float centre[1][3] = {{0, 0, -1}};
        lc_mr_vpl v;
        lc_mr_point_out po;
        if (lc_mr_compute(m, &pt, 1, &obj, 1, (const float(*)[3])centre, &v, &po, NULL, err, sizeof err) == 0) {
            double want = M_PI * L * rect_form_factor(w / 2.0 / f * z, h / 2.0 / f * z, z - 1);
            e = po.e_d[1] / want - 1;
        }
    }
    CHECK(e != -1, "%ux%u: %s", w, h, err);
    lc_mr_release(m);
    free(depth);
    free(rad);
    return e;
}

static void test_wall(void) {
    const uint32_t sizes[4][2] = {{64, 48}, {128, 96}, {256, 192}, {640, 480}};
    double errs[4];
    for (int i = 0; i < 4; i++) {
        errs[i] = wall_error(sizes[i][0], sizes[i][1], 1);
        fprintf(stderr, "wall %ux%u: E relative error %+.4f%%\n", sizes[i][0], sizes[i][1], 100 * errs[i]);
    }
    CHECK(fabs(errs[2]) <= 0.02, "256x192: %.4f", errs[2]);
    CHECK(fabs(errs[3]) <= fabs(errs[0]) + 1e-4, "converges with resolution: %.4f at 640x480, %.4f at 64x48", errs[3],
          errs[0]);
    CHECK(fabs(wall_error(128, 96, 0) - errs[1]) < 1e-3, "the filter leaves a plane at constant depth alone");
}

/* Occlusion: a disc between the point and a light darkens it; one behind the point does
 * nothing; two in line darken more than one (the paper's double occlusion, §6). */
static double occluded(int n_occ, float occ_z) {
    lc_mr *m = lc_mr_create(1);
    lc_mr_params p = lc_mr_params_default();
    p.glossy = 0;
    lc_mr_light lights[16];
    for (int j = 0; j < 16; j++)
        lights[j] = (lc_mr_light){.position = {0.6f * (j % 4) - 0.9f, 0.6f * (j / 4) - 0.9f, 2},
                                  .normal = {0, 0, -1},
                                  .area = 4e-4f,
                                  .radiosity = {100, 100, 100}};
    lc_mr_camera cam = {.rotation = {0, 0, 0, 1}};
    char err[256];
    lc_mr_set_lights(m, &cam, lights, 16, &p, err, sizeof err);
    lc_mr_point pts[3] = {{.position = {0, 0, 0}, .normal = {0, 0, 1}, .radius = 0.01f},
                          {.position = {0, 0, occ_z}, .normal = {0, 0, -1}, .radius = 0.15f},
                          {.position = {0, 0, occ_z + 0.3f}, .normal = {0, 0, -1}, .radius = 0.15f}};
    uint32_t obj[3] = {0, 1, 2};
    float centres[3][3] = {{0, 0, 0}, {0, 0, occ_z}, {0, 0, occ_z + 0.3f}};
    lc_mr_vpl v[3];
    lc_mr_point_out po[3];
    lc_mr_compute(m, pts, (uint32_t)(1 + n_occ), obj, 3, (const float(*)[3])centres, v, po, NULL, err, sizeof err);
    lc_mr_release(m);
    return po[0].occ_d;
}

static void test_occlusion(void) {
    double none = occluded(0, 1), one = occluded(1, 1), two = occluded(2, 0.6f), behind = occluded(1, -1);
    fprintf(stderr, "occlusion: one disc %.3f, two in line %.3f\n", one, two);
    CHECK(none == 0, "no occluder: o = %g", none);
    CHECK(one > 0.05 && one < 0.9, "a disc between point and light: o = %g", one);
    CHECK(behind == 0, "a disc behind the point's plane: o = %g", behind);
    CHECK(two > one, "two discs in line darken more (double occlusion): %g vs %g", two, one);
}

/* Inside a uniformly radiant sphere every direction sees radiance B/pi: E(n) = B for all n. */
static void test_object_sh(void) {
    enum { N = 4000 };
    lc_mr_light *lights = malloc(N * sizeof *lights);
    const double R = 1.0, B = 30;
    for (int j = 0; j < N; j++) { /* a Fibonacci sphere of equal-area discs, facing the centre */
        double zc = 1 - (2 * j + 1.0) / N, rr = sqrt(1 - zc * zc), ph = j * M_PI * (3 - sqrt(5.0));
        float d[3] = {(float)(rr * cos(ph)), (float)(rr * sin(ph)), (float)zc};
        lights[j] = (lc_mr_light){.position = {(float)R * d[0], (float)R * d[1], (float)R * d[2]},
                                  .normal = {-d[0], -d[1], -d[2]},
                                  .area = (float)(4 * M_PI * R * R / N),
                                  .radiosity = {(float)B, (float)B, (float)B}};
    }
    lc_mr *m = lc_mr_create(1);
    lc_mr_params p = lc_mr_params_default();
    lc_mr_camera cam = {.rotation = {0, 0, 0, 1}};
    char err[256];
    lc_mr_set_lights(m, &cam, lights, N, &p, err, sizeof err);
    lc_mr_point pt = {.position = {0.1f, 0, 0}, .normal = {1, 0, 0}, .radius = 0.01f};
    uint32_t obj = 0;
    float centre[1][3] = {{0, 0, 0}}, sh[1][27];
    lc_mr_vpl v;
    CHECK(lc_mr_compute(m, &pt, 1, &obj, 1, (const float(*)[3])centre, &v, NULL, sh, err, sizeof err) == 0, "%s", err);
    /* E(n) = sum c_i y_i(n); band 0 alone must hold it: c0 y0 = B, bands 1-2 vanish */
    double y0 = 0.5 * sqrt(1 / M_PI);
    CHECK_NEAR(sh[0][1] * y0, B, 0.02);
    for (int i = 1; i < 9; i++)
        CHECK(fabs(sh[0][3 * i + 1]) < 0.02 * B, "c%d = %g (should vanish)", i, sh[0][3 * i + 1]);
    lc_mr_release(m);
    free(lights);
}

/* Per-stage cost at the size (printed, not asserted: timings are not tests): a 256x192
 * frame at the default light budget, 1024 sparse points in 4 objects. */
static void print_cost(void) {
    const uint32_t w = 256, h = 192, n = 1024;
    float *depth = malloc(w * h * sizeof *depth), *rad = malloc(w * h * 3 * sizeof *rad);
    for (uint32_t i = 0; i < w * h; i++) {
        depth[i] = 2.0f + 0.2f * sinf((float)(i % w) * 0.05f);
        rad[3 * i] = rad[3 * i + 1] = rad[3 * i + 2] = 40;
    }
    lc_mr_camera cam = {.width = w, .height = h, .fx = 200, .fy = 200, .cx = 128, .cy = 96, .rotation = {0, 0, 0, 1}};
    lc_mr_params p = lc_mr_params_default();
    lc_mr_point *pts = malloc(n * sizeof *pts);
    uint32_t *obj = malloc(n * sizeof *obj);
    lc_mr_vpl *v = malloc(n * sizeof *v);
    float centres[4][3], sh[4][27];
    unsigned seed = 3;
    for (uint32_t k = 0; k < 4; k++) centres[k][0] = 0.3f * k - 0.45f, centres[k][1] = 0, centres[k][2] = -1;
    for (uint32_t i = 0; i < n; i++) {
        float d[3] = {(float)rnd(&seed) - 0.5f, (float)rnd(&seed) - 0.5f, (float)rnd(&seed) - 0.5f};
        unit(d);
        obj[i] = i % 4;
        for (int c = 0; c < 3; c++) pts[i].position[c] = centres[obj[i]][c] + 0.1f * d[c], pts[i].normal[c] = d[c];
        pts[i].radius = 0.02f;
    }
    lc_mr *m = lc_mr_create(0);
    char err[256];
    for (int rep = 0; rep < 3; rep++) {
        lc_mr_set_frame(m, &cam, depth, rad, NULL, &p, err, sizeof err);
        lc_mr_compute(m, pts, n, obj, 4, (const float(*)[3])centres, v, NULL, sh, err, sizeof err);
    }
    lc_mr_timings t;
    lc_mr_stats(m, &t);
    fprintf(stderr,
            "cost 256x192, %u lights (block %u), %u points: filter %.2f lights %.2f gather %.2f occlusion %.2f "
            "normalise %.2f sh %.2f ms, total %.2f ms\n",
            t.lights, t.block, n, t.filter_ms, t.lights_ms, t.gather_ms, t.occlusion_ms, t.normalise_ms, t.sh_ms,
            t.filter_ms + t.lights_ms + t.gather_ms + t.occlusion_ms + t.normalise_ms + t.sh_ms);
    lc_mr_release(m);
    free(depth), free(rad), free(pts), free(obj), free(v);
}

int main(void) {
    print_cost();
    test_form_factor();
    test_renormalisation();
    test_wall();
    test_occlusion();
    test_object_sh();
    CHECK_DONE();
}
