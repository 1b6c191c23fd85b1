/* grid: lattice layout rules (explicit cell, max_dim, padding, cap) and cache placement. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/grid.h"
#include "check.h"

/* The lattice must cover [bmin, bmax] padded by half a cell on every side, centred. */
static void check_covers(const lc_grid *g, const float bmin[3], const float bmax[3]) {
    for (int a = 0; a < 3; a++) {
        double lo = g->origin[a], hi = g->origin[a] + (double)(g->dims[a] - 1) * g->cell;
        CHECK(lo <= bmin[a] - 0.5 * g->cell + 1e-4, "axis %d: first sample %.4f not half a cell below %.4f", a, lo,
              (double)bmin[a]);
        CHECK(hi >= bmax[a] + 0.5 * g->cell - 1e-4, "axis %d: last sample %.4f not half a cell above %.4f", a, hi,
              (double)bmax[a]);
        /* ... and not more than a cell more than needed: one sample fewer would not cover. */
        CHECK(hi - lo < (bmax[a] - bmin[a]) + 2 * g->cell + 1e-4, "axis %d: lattice too large", a);
        CHECK_NEAR(0.5 * (lo + hi), 0.5 * (bmin[a] + bmax[a]), 1e-5);
    }
}

static void test_layout(void) {
    char err[256];
    lc_grid g;
    const float bmin[3] = {-2, 0, -1}, bmax[3] = {8, 4, 1};

    /* Explicit cell: 10 / 1 -> 12 samples along x (10 + 2 half-cell pads), 6 along y, 4 along z. */
    CHECK(lc_grid_layout(bmin, bmax, 1.0, 64, 0, &g, err, sizeof err) == 0, "layout: %s", err);
    CHECK(g.cell == 1.0f, "cell %g", (double)g.cell);
    CHECK(g.dims[0] == 12 && g.dims[1] == 6 && g.dims[2] == 4, "dims %u %u %u", g.dims[0], g.dims[1], g.dims[2]);
    check_covers(&g, bmin, bmax);
    /* Non-multiple extent rounds up. */
    CHECK(lc_grid_layout(bmin, bmax, 0.75, 64, 0, &g, err, sizeof err) == 0, "layout: %s", err);
    CHECK(g.dims[0] == 16 && g.dims[1] == 8 && g.dims[2] == 5, "dims %u %u %u", g.dims[0], g.dims[1], g.dims[2]);
    check_covers(&g, bmin, bmax);

    /* cell = 0: max_dim samples along the longest axis (x). */
    CHECK(lc_grid_layout(bmin, bmax, 0.0, 32, 0, &g, err, sizeof err) == 0, "layout: %s", err);
    CHECK(g.dims[0] == 32, "max_dim along x: %u", g.dims[0]);
    CHECK(g.dims[1] <= 32 && g.dims[2] <= 32, "other axes not longer");
    CHECK_NEAR(g.cell, 10.0 / 30.0, 1e-6);
    check_covers(&g, bmin, bmax);
    /* ... cell > 0 wins over max_dim. */
    CHECK(lc_grid_layout(bmin, bmax, 2.0, 32, 0, &g, err, sizeof err) == 0, "layout: %s", err);
    CHECK(g.cell == 2.0f && g.dims[0] == 7, "cell wins: cell %g dims %u", (double)g.cell, g.dims[0]);

    /* Cap: the cell grows until the total fits. */
    CHECK(lc_grid_layout(bmin, bmax, 0.05, 0, 5000, &g, err, sizeof err) == 0, "layout: %s", err);
    uint64_t total = (uint64_t)g.dims[0] * g.dims[1] * g.dims[2];
    fprintf(stderr, "capped: cell %.4f dims %u %u %u = %llu\n", (double)g.cell, g.dims[0], g.dims[1], g.dims[2],
            (unsigned long long)total);
    CHECK(total <= 5000, "capped total %llu", (unsigned long long)total);
    CHECK(total > 5000 / 2, "cap not overshot by much (%llu)", (unsigned long long)total);
    CHECK(g.cell > 0.05f, "cell grew");
    check_covers(&g, bmin, bmax);

    /* Flat bounds (a floor plane) still get a lattice of >= 2 samples per axis. */
    const float fmin[3] = {0, 1, 0}, fmax[3] = {4, 1, 4};
    CHECK(lc_grid_layout(fmin, fmax, 0.0, 10, 0, &g, err, sizeof err) == 0, "layout: %s", err);
    CHECK(g.dims[0] == 10 && g.dims[2] == 10 && g.dims[1] == 2, "flat dims %u %u %u", g.dims[0], g.dims[1], g.dims[2]);
    check_covers(&g, fmin, fmax);

    /* Errors name the parameter. */
    CHECK(lc_grid_layout(bmin, bmax, -1.0, 32, 0, &g, err, sizeof err) == -1 && strstr(err, "cell"), "%s", err);
    CHECK(lc_grid_layout(bmin, bmax, 0.0, 2, 0, &g, err, sizeof err) == -1 && strstr(err, "max_dim"), "%s", err);
    CHECK(lc_grid_layout(bmin, bmax, 1.0, 32, 4, &g, err, sizeof err) == -1 && strstr(err, "max_samples"), "%s", err);
    const float bad[3] = {0, NAN, 0};
    CHECK(lc_grid_layout(bad, bmax, 1.0, 32, 0, &g, err, sizeof err) == -1 && strstr(err, "bounds"), "%s", err);
    CHECK(lc_grid_layout(bmax, bmin, 1.0, 32, 0, &g, err, sizeof err) == -1 && strstr(err, "bounds"), "%s", err);
}

static void test_place(void) {
    char err[256];
    lc_grid g = {{1, 2, 3}, 0.5f, {3, 4, 5}};
    /* Two existing texel caches: grid caches are appended after them. */
    lc_lcb_cache *caches = calloc(2, sizeof *caches);
    caches[0].flags = caches[1].flags = LC_CACHE_TEXEL;
    caches[1].index = 77;
    uint32_t n = 2, *cell = NULL;
    CHECK(lc_grid_place(&g, &caches, &n, &cell, err, sizeof err) == 0, "place: %s", err);
    CHECK(n == 2 + 60, "n %u", n);
    CHECK(caches[1].flags == LC_CACHE_TEXEL && caches[1].index == 77, "existing caches kept");
    int ok = 1;
    for (uint32_t z = 0, i = 0; z < 5; z++)
        for (uint32_t y = 0; y < 4; y++)
            for (uint32_t x = 0; x < 3; x++, i++) {
                const lc_lcb_cache *c = &caches[cell[i]];
                ok &= cell[i] == 2 + i;
                ok &= c->flags == LC_CACHE_GRID && c->index == i;
                ok &=
                    c->position[0] == 1 + 0.5f * x && c->position[1] == 2 + 0.5f * y && c->position[2] == 3 + 0.5f * z;
                ok &= c->normal[0] == 0 && c->normal[1] == 0 && c->normal[2] == 0;
                ok &= c->albedo[0] == 0 && c->albedo[1] == 0 && c->albedo[2] == 0;
            }
    CHECK(ok, "grid caches: x fastest, index = sample, position = origin + i * cell, zero normal/albedo");
    free(cell);
    free(caches);

    /* From nothing. */
    caches = NULL;
    n = 0;
    lc_grid one = {{0, 0, 0}, 1, {1, 1, 1}};
    CHECK(lc_grid_place(&one, &caches, &n, &cell, err, sizeof err) == 0 && n == 1 && cell[0] == 0, "single");
    free(cell);
    free(caches);
    lc_grid empty = {{0, 0, 0}, 1, {0, 3, 3}};
    caches = NULL;
    n = 0;
    CHECK(lc_grid_place(&empty, &caches, &n, &cell, err, sizeof err) == -1 && strstr(err, "dims"), "%s", err);
}

int main(void) {
    test_layout();
    test_place();
    CHECK_DONE();
}
