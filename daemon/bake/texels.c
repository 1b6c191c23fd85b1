/* texels: lightmap texel caches (see texels.h).
 *
 * Rasterization snaps uv1 to a fixed-point grid (1/4096 texel) so edge functions are exact
 * integers: a shared edge evaluates to exactly opposite values in its two triangles and the
 * top-left style tie rule gives each texel centre to exactly one of them. Ownership is
 * decided serially in triangle order (lowest triangle wins on overlapping asset UVs), then
 * caches are built row-parallel in texel (y-major) order, which is deterministic. */
#include "bake/texels.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"

#define TEXELS_SUB 4096 /* sub-texel steps per texel */
#define TEXELS_MAX_SIZE 16384u

typedef struct {
    int64_t x[3], y[3];
    int64_t area; /* twice the signed area, in sub-texel units */
} texels_tri;

/* Snaps triangle t's uv1 to the fixed-point grid; 0 when degenerate or not finite. */
static int texels_setup(const lc_mesh *m, uint32_t t, uint32_t W, uint32_t H, texels_tri *out) {
    for (int k = 0; k < 3; k++) {
        uint32_t v = m->index[3 * (size_t)t + k];
        double u = m->uv1[2 * (size_t)v], w = m->uv1[2 * (size_t)v + 1];
        if (!isfinite(u) || !isfinite(w)) return 0;
        /* clamp far-off UVs (assets) so the integer products below cannot overflow */
        u = fmin(fmax(u, -4.0), 5.0);
        w = fmin(fmax(w, -4.0), 5.0);
        out->x[k] = llround(u * W * TEXELS_SUB);
        out->y[k] = llround(w * H * TEXELS_SUB);
    }
    out->area = (out->x[1] - out->x[0]) * (out->y[2] - out->y[0]) - (out->y[1] - out->y[0]) * (out->x[2] - out->x[0]);
    return out->area != 0;
}

/* Edge function of edge a->b at p: >0 on the left (CCW interior). */
static int64_t texels_edge(const texels_tri *r, int a, int b, int64_t px, int64_t py) {
    return (r->x[b] - r->x[a]) * (py - r->y[a]) - (r->y[b] - r->y[a]) * (px - r->x[a]);
}

/* Tie rule for a centre exactly on an edge whose direction (after orienting the triangle
 * positively) is (dx, dy): exactly one of d and -d qualifies, so shared edges and vertices
 * are never claimed twice nor dropped. */
static int texels_owns_edge(int64_t dx, int64_t dy) { return dy > 0 || (dy == 0 && dx < 0); }

/* Weights w[k] (of vertex k) at texel centre (x, y); 1 when the centre is inside. */
static int texels_inside(const texels_tri *r, int64_t px, int64_t py, int64_t w[3]) {
    int64_t s = r->area > 0 ? 1 : -1;
    for (int k = 0; k < 3; k++) {
        int a = (k + 1) % 3, b = (k + 2) % 3; /* edge opposite vertex k */
        w[k] = texels_edge(r, a, b, px, py);
        int64_t e = s * w[k];
        if (e < 0) return 0;
        if (e == 0 && !texels_owns_edge(s * (r->x[b] - r->x[a]), s * (r->y[b] - r->y[a]))) return 0;
    }
    return 1;
}

static int64_t texels_floordiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

typedef struct {
    const lc_scene *scene;
    uint32_t W, H;
    const uint32_t *owner;
    uint32_t *row_count; /* H + 1, prefix sums after the count pass */
    uint32_t *texel_cache;
    lc_lcb_cache *out; /* first texel cache */
    uint32_t base;
} texels_job;

static void texels_count_rows(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    texels_job *j = ctx;
    for (size_t y = begin; y < end; y++) {
        uint32_t n = 0;
        const uint32_t *row = j->owner + y * j->W;
        for (uint32_t x = 0; x < j->W; x++) n += row[x] != LC_NONE;
        j->row_count[y + 1] = n;
    }
}

static void texels_fill_rows(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    texels_job *j = ctx;
    const lc_mesh *m = &j->scene->mesh;
    for (size_t y = begin; y < end; y++) {
        uint32_t k = j->row_count[y];
        for (uint32_t x = 0; x < j->W; x++) {
            size_t ti = y * j->W + x;
            uint32_t t = j->owner[ti];
            if (t == LC_NONE) {
                j->texel_cache[ti] = LC_NONE;
                continue;
            }
            texels_tri r;
            int64_t w[3] = {0, 0, 0};
            if (texels_setup(m, t, j->W, j->H, &r))
                texels_inside(&r, (int64_t)x * TEXELS_SUB + TEXELS_SUB / 2, (int64_t)y * TEXELS_SUB + TEXELS_SUB / 2, w);
            float b1 = (float)((double)w[1] / (double)r.area), b2 = (float)((double)w[2] / (double)r.area);
            lc_lcb_cache *c = &j->out[k];
            memset(c, 0, sizeof *c);
            lc_mesh_interpolate(m, t, b1, b2, c->position, c->normal);
            lc_scene_albedo(j->scene, t, b1, b2, c->albedo);
            c->flags = LC_CACHE_TEXEL;
            c->index = (uint32_t)ti;
            j->texel_cache[ti] = j->base + k;
            k++;
        }
    }
}

int lc_texels_rasterize(const lc_scene *scene, uint32_t width, uint32_t height, lc_lightmap *lm,
                        lc_lcb_cache **caches, uint32_t *n_caches, char *err, size_t errlen) {
    uint32_t *owner = NULL, *row_count = NULL, *texel_cache = NULL;
    int rc = -1;
    if (!scene || !lm || !caches || !n_caches) {
        lc_set_err(err, errlen, "texels: scene, lightmap and cache outputs are required");
        return -1;
    }
    const lc_mesh *m = &scene->mesh;
    if (!m->uv1 || !m->index) {
        lc_set_err(err, errlen, "texels: the mesh has no lightmap UVs (uv1); run uvgen first");
        return -1;
    }
    if (width == 0 || height == 0 || width > TEXELS_MAX_SIZE || height > TEXELS_MAX_SIZE) {
        lc_set_err(err, errlen, "texels: lightmap size %ux%u is out of range [1, %u]", width, height,
                   TEXELS_MAX_SIZE);
        return -1;
    }
    for (size_t i = 0; i < 3 * (size_t)m->n_triangles; i++)
        if (m->index[i] >= m->n_vertices) {
            lc_set_err(err, errlen, "texels: mesh index of triangle %zu is out of range", i / 3);
            return -1;
        }
    const size_t N = (size_t)width * height;
    owner = malloc(N * sizeof *owner);
    row_count = calloc((size_t)height + 1, sizeof *row_count);
    texel_cache = malloc(N * sizeof *texel_cache);
    if (!owner || !row_count || !texel_cache) goto oom;
    memset(owner, 0xFF, N * sizeof *owner);

    /* ownership: serial in triangle order, so the lowest triangle keeps a contested centre */
    uint64_t contested = 0;
    uint32_t first_contested = LC_NONE;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        texels_tri r;
        if (!texels_setup(m, t, width, height, &r)) continue;
        int64_t lo_x = r.x[0], hi_x = r.x[0], lo_y = r.y[0], hi_y = r.y[0];
        for (int k = 1; k < 3; k++) {
            lo_x = r.x[k] < lo_x ? r.x[k] : lo_x;
            hi_x = r.x[k] > hi_x ? r.x[k] : hi_x;
            lo_y = r.y[k] < lo_y ? r.y[k] : lo_y;
            hi_y = r.y[k] > hi_y ? r.y[k] : hi_y;
        }
        /* texels whose centre x*S + S/2 lies in [lo, hi] */
        int64_t x0 = -texels_floordiv(-(lo_x - TEXELS_SUB / 2), TEXELS_SUB), x1 = texels_floordiv(hi_x - TEXELS_SUB / 2, TEXELS_SUB);
        int64_t y0 = -texels_floordiv(-(lo_y - TEXELS_SUB / 2), TEXELS_SUB), y1 = texels_floordiv(hi_y - TEXELS_SUB / 2, TEXELS_SUB);
        if (x0 < 0) x0 = 0;
        if (y0 < 0) y0 = 0;
        if (x1 > (int64_t)width - 1) x1 = (int64_t)width - 1;
        if (y1 > (int64_t)height - 1) y1 = (int64_t)height - 1;
        for (int64_t y = y0; y <= y1; y++)
            for (int64_t x = x0; x <= x1; x++) {
                int64_t w[3];
                if (!texels_inside(&r, x * TEXELS_SUB + TEXELS_SUB / 2, y * TEXELS_SUB + TEXELS_SUB / 2, w)) continue;
                uint32_t *o = &owner[(size_t)y * width + (size_t)x];
                if (*o != LC_NONE) {
                    if (!contested) first_contested = t;
                    contested++;
                    continue;
                }
                *o = t;
            }
    }
    if (contested)
        lc_warn("texels", "%llu texel centres are covered by more than one triangle (overlapping lightmap UVs, "
                "first at triangle %u); the lowest triangle keeps each",
                (unsigned long long)contested, first_contested);

    texels_job job = {scene, width, height, owner, row_count, texel_cache, NULL, 0};
    lc_parallel_for(height, 16, texels_count_rows, &job);
    for (uint32_t y = 0; y < height; y++) row_count[y + 1] += row_count[y];
    uint32_t n = row_count[height];
    uint32_t base = *caches ? *n_caches : 0;
    if ((uint64_t)base + n > UINT32_MAX - 1) {
        lc_set_err(err, errlen, "texels: %u + %u caches exceed the 32-bit cache index", base, n);
        goto err;
    }
    lc_lcb_cache *all = realloc(*caches, ((size_t)base + n + (base + n == 0)) * sizeof *all);
    if (!all) goto oom;
    *caches = all;
    job.out = all + base;
    job.base = base;
    lc_parallel_for(height, 8, texels_fill_rows, &job);
    *n_caches = base + n;
    memset(lm, 0, sizeof *lm);
    lm->width = width;
    lm->height = height;
    lm->texel_cache = texel_cache;
    lm->n_covered = n;
    texel_cache = NULL;
    rc = 0;
    if (0) {
    oom:
        lc_set_err(err, errlen, "texels: out of memory for a %ux%u lightmap", width, height);
    }
err:
    free(owner);
    free(row_count);
    free(texel_cache);
    return rc;
}

/* ---- dilation --------------------------------------------------------------------------- */

typedef struct {
    uint32_t W, H;
    const uint32_t *prev_cache, *prev_src; /* src: texel whose cache it is (for distance) */
    uint32_t *next_cache, *next_src;
    uint32_t *row_filled;
} texels_dilate_job;

static void texels_dilate_rows(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    /* fixed neighbour order; the first among equally near sources wins */
    static const int dx[8] = {-1, 0, 1, -1, 1, -1, 0, 1}, dy[8] = {-1, -1, -1, 0, 0, 1, 1, 1};
    texels_dilate_job *j = ctx;
    const int64_t W = j->W, H = j->H;
    for (size_t yy = begin; yy < end; yy++) {
        int64_t y = (int64_t)yy;
        uint32_t filled = 0;
        for (int64_t x = 0; x < W; x++) {
            size_t i = (size_t)(y * W + x);
            j->next_cache[i] = j->prev_cache[i];
            j->next_src[i] = j->prev_src[i];
            if (j->prev_cache[i] != LC_NONE) continue;
            int64_t best = INT64_MAX;
            size_t pick = 0;
            for (int k = 0; k < 8; k++) {
                int64_t nx = x + dx[k], ny = y + dy[k];
                if (nx < 0 || ny < 0 || nx >= W || ny >= H) continue;
                size_t ni = (size_t)(ny * W + nx);
                if (j->prev_cache[ni] == LC_NONE) continue;
                int64_t sx = (int64_t)(j->prev_src[ni] % j->W), sy = (int64_t)(j->prev_src[ni] / j->W);
                int64_t d2 = (sx - x) * (sx - x) + (sy - y) * (sy - y);
                if (d2 < best) {
                    best = d2;
                    pick = ni;
                }
            }
            if (best == INT64_MAX) continue;
            j->next_cache[i] = j->prev_cache[pick];
            j->next_src[i] = j->prev_src[pick];
            filled++;
        }
        j->row_filled[yy] = filled;
    }
}

void lc_texels_dilate(lc_lightmap *lm, uint32_t passes) {
    if (!lm || !lm->texel_cache || passes == 0 || lm->width == 0 || lm->height == 0) return;
    const size_t N = (size_t)lm->width * lm->height;
    uint32_t *cache2 = malloc(N * sizeof *cache2), *src = malloc(N * sizeof *src), *src2 = malloc(N * sizeof *src2);
    uint32_t *row_filled = calloc(lm->height, sizeof *row_filled);
    if (!cache2 || !src || !src2 || !row_filled) {
        lc_warn("texels", "out of memory for dilation of a %ux%u lightmap; seams stay undilated", lm->width,
                lm->height);
        goto err;
    }
    /* texels filled before this call count as their own source */
    for (size_t i = 0; i < N; i++) src[i] = lm->texel_cache[i] != LC_NONE ? (uint32_t)i : LC_NONE;
    uint32_t *cur = lm->texel_cache, *cur_src = src, *nxt = cache2, *nxt_src = src2;
    for (uint32_t p = 0; p < passes; p++) {
        texels_dilate_job job = {lm->width, lm->height, cur, cur_src, nxt, nxt_src, row_filled};
        lc_parallel_for(lm->height, 16, texels_dilate_rows, &job);
        uint64_t filled = 0;
        for (uint32_t y = 0; y < lm->height; y++) filled += row_filled[y];
        lm->n_dilated += (uint32_t)filled;
        uint32_t *t = cur;
        cur = nxt;
        nxt = t;
        t = cur_src;
        cur_src = nxt_src;
        nxt_src = t;
        if (filled == 0) break;
    }
    if (cur != lm->texel_cache) { /* result lives in the scratch buffer: hand it over */
        cache2 = lm->texel_cache;
        lm->texel_cache = cur;
    }
err:
    free(cache2);
    free(src);
    free(src2);
    free(row_filled);
}

void lc_lightmap_release(lc_lightmap *lm) {
    if (!lm) return;
    free(lm->texel_cache);
    memset(lm, 0, sizeof *lm);
}
