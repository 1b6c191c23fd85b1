/* lc_ref_texel_surfaces, the reference's own texel surface points, against closed forms on
 * hand-built meshes: an affine uv -> position map (a quad of two triangles) gives every texel
 * centre's point exactly, barycentric vertex normals, the winding normal where the vertex
 * normals face the other way, the nearest triangle (clamped barycentrics) for a centre outside
 * every triangle, and the texel spacing; then the spacing statistics. */
#include <math.h>
#include <stdlib.h>

#include "check.h"
#include "ref/ref.h"

static lc_lcb_vertex vtx(float u, float v, float px, float py, float pz, float nx, float ny, float nz) {
    float l = sqrtf(nx * nx + ny * ny + nz * nz);
    lc_lcb_vertex o = {{px, py, pz}, {nx / l, ny / l, nz / l}, {u, v}};
    return o;
}

static void check_normal(const float *got, const double want_unnorm[3], const char *what, uint32_t x, uint32_t y) {
    double l =
        sqrt(want_unnorm[0] * want_unnorm[0] + want_unnorm[1] * want_unnorm[1] + want_unnorm[2] * want_unnorm[2]);
    for (int k = 0; k < 3; k++)
        CHECK(fabs(got[k] - want_unnorm[k] / l) <= 1e-5, "%s texel (%u, %u) normal[%d] = %.7f, expected %.7f", what, x,
              y, k, got[k], want_unnorm[k] / l);
}

/* 8 x 4 texels. Left half (u in [0, 0.5]): a quad of two triangles mapped affinely to the
 * 2 m x 1 m rectangle pos = (4u, 0, v) (winding normal -y) with tilted vertex normals. Right
 * half: one triangle uv (0.5, 0) (1, 0) (0.5, 1) on the plane x = 3 (winding normal +x) whose
 * vertex normals point to -x, so the winding normal wins. The upper-right corner of the right
 * half lies outside every triangle. */
static void test_lookup(void) {
    const uint32_t W = 8, H = 4;
    lc_lcb_vertex v[7] = {
        vtx(0.0f, 0.0f, 0, 0, 0, 0, -1, 0),    vtx(0.5f, 0.0f, 2, 0, 0, 0.3f, -1, 0),
        vtx(0.5f, 1.0f, 2, 0, 1, 0, -1, 0.3f), vtx(0.0f, 1.0f, 0, 0, 1, 0, -1, 0),
        vtx(0.5f, 0.0f, 3, 0, 0, -1, 0, 0),    vtx(1.0f, 0.0f, 3, 1, 0, -1, 0.2f, 0),
        vtx(0.5f, 1.0f, 3, 0, 2, -1, 0, 0),
    };
    lc_lcb_triangle t[3] = {{{0, 1, 3}, 0}, {{1, 2, 3}, 0}, {{4, 5, 6}, 0}};
    uint8_t want[8 * 4];
    for (uint32_t i = 0; i < W * H; i++) want[i] = i != 9; /* texel (1, 1) not asked for */
    float out[8 * 4 * LC_REF_SURFACE_STRIDE];
    lc_ref_surface_stats st;
    char err[256] = "";
    CHECK(lc_ref_texel_surfaces(v, 7, t, 3, W, H, want, out, &st, err, sizeof err) == 0, "lookup: %s", err);
    CHECK(st.texels == W * H - 1, "texels %u", st.texels);
    CHECK(st.missing == 0, "missing %u", st.missing);
    uint32_t outside = 0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            const float *s = out + LC_REF_SURFACE_STRIDE * (y * W + x);
            double u = (x + 0.5) / W, w = (y + 0.5) / H;
            if (!want[y * W + x]) {
                CHECK(isnan(s[0]) && isnan(s[6]), "texel not asked for has a point");
                continue;
            }
            if (u < 0.5) { /* the quad: exact affine point */
                CHECK(fabs(s[0] - 4 * u) <= 1e-5 && fabs(s[1]) <= 1e-5 && fabs(s[2] - w) <= 1e-5,
                      "quad texel (%u, %u) at (%g, %g, %g), expected (%g, 0, %g)", x, y, s[0], s[1], s[2], 4 * u, w);
                /* barycentrics of the containing triangle (in uv units of the half: a = 2u) */
                double a = 2 * u, n[3] = {0, 0, 0}, b[4];
                if (a + w < 1) b[0] = 1 - a - w, b[1] = a, b[2] = 0, b[3] = w;
                else b[0] = 0, b[1] = 1 - w, b[2] = a + w - 1, b[3] = 1 - a;
                for (int j = 0; j < 4; j++)
                    for (int k = 0; k < 3; k++) n[k] += b[j] * v[j].normal[k];
                check_normal(s + 3, n, "quad", x, y);
                CHECK_NEAR(s[6], sqrt(1.0 / 8.0), 1e-6); /* 1 m^2 over 0.25 x 32 texels^2 */
            } else if ((u - 0.5) * 2 + w <= 1) {         /* the right triangle, inside */
                double a = (u - 0.5) * 2;                /* b(v5) = a, b(v6) = w */
                CHECK(fabs(s[0] - 3) <= 1e-5 && fabs(s[1] - a) <= 1e-5 && fabs(s[2] - 2 * w) <= 1e-5,
                      "triangle texel (%u, %u) at (%g, %g, %g)", x, y, s[0], s[1], s[2]);
                check_normal(s + 3, (double[3]){1, 0, 0}, "winding", x, y);
                CHECK_NEAR(s[6], sqrt(1.0 / 8.0), 1e-6);
            } else {
                outside++;
                /* Nearest uv point: on the hypotenuse (8, 0)-(4, 4) in texel units, or on the
                 * quad's edge x = 4, whichever is closer. */
                double px = x + 0.5, py = y + 0.5, d_hyp = (px + py - 8) / sqrt(2.0), d_quad = px - 4;
                if (d_hyp < d_quad) {
                    double qx = px - (px + py - 8) / 2, tt = (8 - qx) / 4; /* (8,0) + tt (-4, 4) */
                    double want_p[3] = {3, 1 - tt, 2 * tt};
                    CHECK(fabs(s[0] - want_p[0]) <= 1e-5 && fabs(s[1] - want_p[1]) <= 1e-5 &&
                              fabs(s[2] - want_p[2]) <= 1e-5,
                          "outside texel (%u, %u) at (%g, %g, %g), expected (%g, %g, %g)", x, y, s[0], s[1], s[2],
                          want_p[0], want_p[1], want_p[2]);
                }
            }
        }
    CHECK(outside > 0 && st.outside == outside, "outside: %u counted, %u expected", st.outside, outside);
    /* A vertex index out of range names the field. */
    t[1].v[2] = 99;
    CHECK(lc_ref_texel_surfaces(v, 7, t, 3, W, H, NULL, out, &st, err, sizeof err) != 0 &&
              strstr(err, "triangles[1].v[2]") != NULL,
          "bad vertex index: '%s'", err);
}

/* A 2 m x 2 m quad mapped to the whole uv square at 8 x 8: texels 0.25 m apart. */
static void test_spacing(void) {
    lc_lcb_vertex v[4] = {vtx(0, 0, 0, 0, 0, 0, 1, 0), vtx(1, 0, 2, 0, 0, 0, 1, 0), vtx(1, 1, 2, 0, -2, 0, 1, 0),
                          vtx(0, 1, 0, 0, -2, 0, 1, 0)};
    lc_lcb_triangle t[2] = {{{0, 1, 2}, 0}, {{0, 2, 3}, 0}};
    float out[64 * LC_REF_SURFACE_STRIDE];
    lc_ref_surface_stats st;
    char err[256] = "";
    CHECK(lc_ref_texel_surfaces(v, 4, t, 2, 8, 8, NULL, out, &st, err, sizeof err) == 0, "lookup: %s", err);
    CHECK(st.texels == 64 && st.outside == 0 && st.missing == 0, "stats %u %u %u", st.texels, st.outside, st.missing);
    for (int i = 0; i < 64; i++) CHECK_NEAR(out[LC_REF_SURFACE_STRIDE * i + 6], 0.25, 1e-6);
    /* winding (0,0,0) (2,0,0) (2,0,-2): normal +y, as the vertex normals */
    CHECK_NEAR(out[4], 1.0, 1e-6);
    lc_ref_spacing sp;
    CHECK(lc_ref_spacing_stats(out, 8, 8, 0.5, &sp) == 0, "spacing stats");
    CHECK(sp.n == 64, "spacing over %u texels", sp.n);
    CHECK_NEAR(sp.mean, 0.25, 1e-6);
    CHECK_NEAR(sp.p50, 0.25, 1e-6);
    CHECK_NEAR(sp.p95, 0.25, 1e-6);
    CHECK_NEAR(sp.max, 0.25, 1e-6);
    CHECK(sp.share_over == 0, "share over 0.5 m: %g", sp.share_over);
    /* Mixed: half the texels 1 m apart (edited in), the share and percentiles follow. */
    for (int i = 0; i < 32; i++) out[LC_REF_SURFACE_STRIDE * i + 6] = 1.0f;
    out[LC_REF_SURFACE_STRIDE * 40 + 6] = NAN; /* no surface point: not counted */
    CHECK(lc_ref_spacing_stats(out, 8, 8, 0.5, &sp) == 0, "spacing stats");
    CHECK(sp.n == 63, "spacing over %u texels", sp.n);
    CHECK_NEAR(sp.mean, (32 * 1.0 + 31 * 0.25) / 63, 1e-6);
    CHECK_NEAR(sp.p50, 1.0, 1e-6); /* the 32nd of 63 sorted: 31 x 0.25 then 1.0 */
    CHECK_NEAR(sp.share_over, 32.0 / 63, 1e-9);
    for (int i = 0; i < 64; i++) out[LC_REF_SURFACE_STRIDE * i + 6] = NAN;
    CHECK(lc_ref_spacing_stats(out, 8, 8, 0.5, &sp) != 0, "no texel: must fail");
}

int main(void) {
    test_lookup();
    test_spacing();
    CHECK_DONE();
}
