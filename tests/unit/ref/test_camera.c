/* lucent-ref camera's closed forms that need no scene:
 *  - the camera is three.js's PerspectiveCamera + lookAt: basis, pixel centres, and the
 *    projection of a world point back to the pixel whose ray passes through it;
 *  - the flags the camera refuses, each error naming its flag;
 *  - the tone maps (LinearToneMapping, NeutralToneMapping = Khronos PBR Neutral, values
 *    computed independently from the published formula) and the 8-bit sRGB transfer. */
#include <math.h>

#include "check.h"
#include "ref/ref.h"

static lc_ref_camera camera(float ex, float ey, float ez, float tx, float ty, float tz, double fov, uint32_t w,
                            uint32_t h) {
    lc_ref_camera c = {{ex, ey, ez}, {tx, ty, tz}, {0, 1, 0}, fov, w, h};
    return c;
}

static void test_basis(void) {
    char err[256];
    lc_ref_camera_basis b;
    /* Looking down -z (three.js's default view): right = +x, up = +y. */
    lc_ref_camera c = camera(0, 0, 0, 0, 0, -1, 90, 2, 2);
    CHECK(lc_ref_camera_setup(&c, &b, err, sizeof err) == 0, "%s", err);
    CHECK_NEAR(b.right[0], 1, 1e-12);
    CHECK_NEAR(b.up[1], 1, 1e-12);
    CHECK_NEAR(b.forward[2], -1, 1e-12);
    CHECK_NEAR(b.tan_y, 1, 1e-12);
    float d[3];
    /* Pixel (0, 0) of a 2x2 image, centre (0.5, 0.5): NDC (-0.5, 0.5). */
    lc_ref_camera_ray(&b, 2, 2, 0.5, 0.5, d);
    double n = sqrt(0.25 + 0.25 + 1);
    CHECK_NEAR(d[0], -0.5 / n, 1e-6);
    CHECK_NEAR(d[1], 0.5 / n, 1e-6);
    CHECK_NEAR(d[2], -1 / n, 1e-6);
    /* Looking down +z (the Cornell view): right = -x, so +x appears on the left. */
    c = camera(0.278f, 0.273f, -0.8f, 0.278f, 0.273f, 0, 39.3, 160, 120);
    CHECK(lc_ref_camera_setup(&c, &b, err, sizeof err) == 0, "%s", err);
    CHECK_NEAR(b.right[0], -1, 1e-12);
    CHECK_NEAR(b.tan_x, tan(39.3 * M_PI / 360) * 160 / 120, 1e-12);
}

/* A world point seen through pixel (i, j): project it with three.js's view and projection
 * matrices and check that the ray through the resulting image point hits it. */
static void test_projection(void) {
    char err[256];
    lc_ref_camera c = camera(1, 2, 3, -0.5f, 0.25f, 0.1f, 50, 640, 480);
    c.up[0] = 0.2f, c.up[1] = 1, c.up[2] = -0.1f;
    lc_ref_camera_basis b;
    CHECK(lc_ref_camera_setup(&c, &b, err, sizeof err) == 0, "%s", err);
    const double pts[3][3] = {{0, 0, 0}, {-1, 0.5, -1}, {0.3, 1.2, 0.4}};
    for (int p = 0; p < 3; p++) {
        double v[3], cam[3];
        for (int k = 0; k < 3; k++) v[k] = pts[p][k] - c.eye[k];
        cam[0] = v[0] * b.right[0] + v[1] * b.right[1] + v[2] * b.right[2];
        cam[1] = v[0] * b.up[0] + v[1] * b.up[1] + v[2] * b.up[2];
        cam[2] = -(v[0] * b.forward[0] + v[1] * b.forward[1] + v[2] * b.forward[2]); /* camera looks down -z */
        double f = 1 / tan(50 * M_PI / 360), aspect = 640.0 / 480.0;
        double ndc_x = f / aspect * cam[0] / -cam[2], ndc_y = f * cam[1] / -cam[2];
        double px = (ndc_x + 1) / 2 * 640, py = (1 - ndc_y) / 2 * 480;
        float d[3];
        lc_ref_camera_ray(&b, 640, 480, px, py, d);
        /* The angle between the ray and the point, from the cross product (float directions). */
        double x[3] = {d[1] * v[2] - d[2] * v[1], d[2] * v[0] - d[0] * v[2], d[0] * v[1] - d[1] * v[0]};
        double sin_a = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) / sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        double fwd = d[0] * v[0] + d[1] * v[1] + d[2] * v[2];
        CHECK(sin_a < 1e-6 && fwd > 0, "point %d: ray through (%.2f, %.2f) is %.3g rad off it", p, px, py, sin_a);
    }
}

static void test_refusals(void) {
    char err[256];
    lc_ref_camera_basis b;
    struct {
        lc_ref_camera c;
        const char *flag;
    } bad[] = {
        {camera(0, 0, 0, 0, 0, -1, 0, 64, 48), "--fov"},    {camera(0, 0, 0, 0, 0, -1, 180, 64, 48), "--fov"},
        {camera(0, 0, 0, 0, 0, -1, NAN, 64, 48), "--fov"},  {camera(0, 0, 0, 0, 0, -1, 50, 0, 48), "--width"},
        {camera(0, 0, 0, 0, 0, -1, 50, 64, 0), "--height"}, {camera(1, 2, 3, 1, 2, 3, 50, 64, 48), "--target"},
        {camera(0, 0, 0, 0, 5, 0, 50, 64, 48), "--up"},     {camera(NAN, 0, 0, 0, 0, -1, 50, 64, 48), "--eye"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        err[0] = 0;
        CHECK(lc_ref_camera_setup(&bad[i].c, &b, err, sizeof err) != 0, "case %zu accepted", i);
        CHECK(strstr(err, bad[i].flag) != NULL, "case %zu: '%s' does not name %s", i, err, bad[i].flag);
    }
}

static void test_tonemap(void) {
    double o[3];
    /* Linear: exposure, then clamp. */
    lc_ref_tonemap(LC_REF_TONEMAP_NONE, 2.0, (const float[3]){0.25f, 0.75f, -1}, o);
    CHECK_NEAR(o[0], 0.5, 1e-12);
    CHECK_NEAR(o[1], 1.0, 1e-12);
    CHECK_NEAR(o[2], 0.0, 1e-12);
    /* Neutral, against the formula evaluated independently (Python, double precision). */
    static const float in[5][3] = {
        {0.5f, 0.5f, 0.5f}, {2, 1, 0.05f}, {0.1f, 0.7f, 0.3f}, {10, 10, 10}, {0.9f, 0.02f, 0.01f}};
    static const double want[5][3] = {{0.46, 0.46, 0.46},
                                      {0.960155642, 0.535698918, 0.132465030},
                                      {0.06, 0.66, 0.26},
                                      {0.993898305, 0.993898305, 0.993898305},
                                      {0.844586847, 0.015799151, 0.006381109}};
    for (int i = 0; i < 5; i++) {
        lc_ref_tonemap(LC_REF_TONEMAP_NEUTRAL, 1.0, in[i], o);
        for (int k = 0; k < 3; k++) CHECK_NEAR(o[k], want[i][k], 2e-7);
    }
    /* Exposure multiplies before the curve. */
    lc_ref_tonemap(LC_REF_TONEMAP_NEUTRAL, 4.0, (const float[3]){0.125f, 0.125f, 0.125f}, o);
    CHECK_NEAR(o[0], 0.46, 1e-7);
    /* sRGB OETF, rounded: 0.5 -> 187.52 -> 188; the linear segment's end 0.0031308 -> 10.31 -> 10. */
    CHECK(lc_ref_srgb8(0.5) == 188, "%u", lc_ref_srgb8(0.5));
    CHECK(lc_ref_srgb8(0.0031308) == 10, "%u", lc_ref_srgb8(0.0031308));
    CHECK(lc_ref_srgb8(0.001) == 3, "%u", lc_ref_srgb8(0.001));
    CHECK(lc_ref_srgb8(0) == 0 && lc_ref_srgb8(1) == 255 && lc_ref_srgb8(7) == 255 && lc_ref_srgb8(-1) == 0 &&
              lc_ref_srgb8(NAN) == 0,
          "ends");
    CHECK(lc_ref_srgb8(0.2) == 124, "%u", lc_ref_srgb8(0.2)); /* 1.055 * 0.2^(1/2.4) - 0.055 = 0.48453 */
}

int main(void) {
    test_basis();
    test_projection();
    test_refusals();
    test_tonemap();
    CHECK_DONE();
}
