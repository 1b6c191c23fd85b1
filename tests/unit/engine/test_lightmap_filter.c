/* The lightmap filter on a hand-built view: an 8x8 lightmap whose left half is a floor (normal
 * +y) and right half a wall (normal +x) meeting at a crease, texels 0.1 m apart. A constant
 * field stays constant; +-5% checkerboard noise on the floor shrinks; a step of 2x inside the
 * floor stays a step (the range weight); floor and wall do not mix; a moved cache keeps its
 * value; a dilated texel shows its owner's filtered value; empty texels stay 0. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "check.h"
#include "engine/lightmap_filter.h"

enum { W = 8, H = 8, N = W * H };

static lc_lcb_cache caches[N];
static uint32_t lightmap[N];

static lc_lcb_view make_view(void) {
    uint32_t n = 0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            uint32_t t = y * W + x;
            lightmap[t] = LC_NONE;
            if (x == 7 && y == 7) continue; /* empty */
            if (x == 6 && y == 7) {         /* dilated: shows the cache of (6, 6) */
                lightmap[t] = LC_NONE - 1;  /* patched below */
                continue;
            }
            lc_lcb_cache *c = &caches[n];
            memset(c, 0, sizeof *c);
            c->flags = LC_CACHE_TEXEL;
            c->index = t;
            if (x < 4) { /* floor: x along x, y along z */
                c->position[0] = 0.1f * (float)x;
                c->position[2] = 0.1f * (float)y;
                c->normal[1] = 1;
            } else { /* wall at x = 0.35 m, going up */
                c->position[0] = 0.35f;
                c->position[1] = 0.1f * (float)(x - 3);
                c->position[2] = 0.1f * (float)y;
                c->normal[0] = -1;
            }
            if (x == 1 && y == 1) c->flags |= LC_CACHE_MOVED;
            lightmap[t] = n++;
        }
    lightmap[7 * W + 6] = lightmap[6 * W + 6];
    lc_lcb_view v;
    memset(&v, 0, sizeof v);
    v.caches = caches;
    v.n_caches = v.n_texel_caches = n;
    v.lightmap = lightmap;
    v.lightmap_width = W;
    v.lightmap_height = H;
    return v;
}

static void fill(float *img, float (*f)(uint32_t x, uint32_t y)) {
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++)
            for (int k = 0; k < 3; k++) img[3 * (y * W + x) + k] = lightmap[y * W + x] == LC_NONE ? 0 : f(x, y);
}

static float constant(uint32_t x, uint32_t y) { return (void)x, (void)y, 2.0f; }
static float checker(uint32_t x, uint32_t y) { return x < 4 ? ((x + y) % 2 ? 1.05f : 0.95f) : 3.0f; }
static float step(uint32_t x, uint32_t y) { return (void)x, y < 4 ? 1.0f : 2.0f; }
static float ramp_wall(uint32_t x, uint32_t y) { return (void)y, x < 4 ? 1.0f : 10.0f; }

int main(void) {
    lc_lcb_view v = make_view();
    char err[256];
    lc_lmfilter *f = lc_lmfilter_create(&v, err, sizeof err);
    CHECK(f != NULL, "create: %s", err);
    if (!f) CHECK_DONE();
    float in[3 * N], out[3 * N];

    fill(in, constant);
    lc_lmfilter_apply(f, in, out, 1);
    float worst = 0;
    for (int t = 0; t < N; t++)
        if (lightmap[t] != LC_NONE) worst = fmaxf(worst, fabsf(out[3 * t] - 2.0f));
    CHECK(worst < 1e-6f, "a constant field stays constant (worst %g)", worst);
    CHECK(out[3 * 63] == 0 && out[3 * 63 + 1] == 0, "the empty texel stays 0");

    fill(in, checker);
    lc_lmfilter_apply(f, in, out, 1);
    double dev = 0;
    int n = 0;
    for (uint32_t y = 1; y < H - 1; y++)
        for (uint32_t x = 1; x < 3; x++) {
            if (x == 1 && y == 1) continue;
            dev += fabs(out[3 * (y * W + x)] - 1.0);
            n++;
        }
    CHECK(dev / n < 0.02, "floor noise of +-5%% shrinks to %.4f", dev / n);
    CHECK(out[3 * (1 * W + 1)] == in[3 * (1 * W + 1)], "the moved cache keeps its value");
    CHECK(fabsf(out[3 * (3 * W + 4)] - 3.0f) < 1e-6f, "the wall next to the noisy floor stays 3 (%g)",
          out[3 * (3 * W + 4)]);
    CHECK(out[3 * (7 * W + 6)] == out[3 * (6 * W + 6)], "the dilated texel shows its owner's filtered value");

    fill(in, step);
    lc_lmfilter_apply(f, in, out, 1);
    CHECK(out[3 * (3 * W + 2)] < 1.01f && out[3 * (4 * W + 2)] > 1.98f, "a 2x step stays a step (%g | %g)",
          out[3 * (3 * W + 2)], out[3 * (4 * W + 2)]);

    fill(in, ramp_wall);
    lc_lmfilter_apply(f, in, out, 1);
    CHECK(fabsf(out[3 * (4 * W + 3)] - 1.0f) < 1e-6f && fabsf(out[3 * (4 * W + 4)] - 10.0f) < 1e-6f,
          "floor and wall do not mix across the crease (%g | %g)", out[3 * (4 * W + 3)], out[3 * (4 * W + 4)]);
    CHECK(lc_lmfilter_filtered_texels(f) > 40, "%u texels filtered", lc_lmfilter_filtered_texels(f));
    lc_lmfilter_release(f);
    CHECK_DONE();
}
