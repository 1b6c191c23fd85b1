/* texels: lightmap texel caches (see texels.h).
 *
 * Rasterization works on uv1 * size in fixed point with 2^-40 texel steps: every float uv1
 * of magnitude >= 2^-17 converts exactly (a float has 24 significant bits, the size 14), so
 * edge functions (128-bit) decide exactly what the float UVs say. An earlier 1/4096-texel
 * grid rounded sub-snap triangles of tiny charts onto texel centres and flipped some, so
 * centres got claimed twice although no float triangle held them twice. A shared edge
 * evaluates to exactly opposite values in its two triangles and the top-left style tie rule
 * gives each texel centre to exactly one of them. Ownership is decided serially in triangle
 * order (lowest triangle wins on overlapping asset UVs), then caches are built row-parallel
 * in texel (y-major) order, which is deterministic.
 *
 * Footprint fill: a bilinear read at a point p inside a triangle touches texels within one
 * texel (Chebyshev) of a texel whose square overlaps the triangle at p. At needle tips such
 * squares can lie far from any covered centre, so rasterize also marks every texel whose
 * square overlaps a triangle (its footprint) and fills the empty ones, plus the 1-ring
 * around all footprint texels, from the nearest covered texel by a layered 8-neighbour BFS
 * that only travels through footprint texels (charts' footprints are >= padding apart, so
 * it never crosses into another chart). Reads anywhere inside a triangle of a chart that
 * owns a texel centre then never touch an empty texel, before any lc_texels_dilate pass. */
#include "bake/texels.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"

#define TEXELS_SHIFT 40
#define TEXELS_SUB ((int64_t)1 << TEXELS_SHIFT) /* fixed-point steps per texel */
#define TEXELS_MAX_SIZE 16384u

/* mask bits per texel */
#define TEXELS_FOOT 1u    /* square overlaps a triangle (or owns a centre) */
#define TEXELS_PENDING 2u /* queued in the current BFS layer: not yet a source */

typedef __int128 texels_i128; /* coordinates < 2^57, so edge products fit */

typedef struct {
    int64_t x[3], y[3]; /* texel units * TEXELS_SUB */
    texels_i128 area;   /* twice the signed area, in those units; may be 0 */
} texels_tri;

/* Converts triangle t's uv1 to fixed point; 0 when not finite. */
static int texels_setup(const lc_mesh *m, uint32_t t, uint32_t W, uint32_t H, texels_tri *out) {
    for (int k = 0; k < 3; k++) {
        uint32_t v = m->index[3 * (size_t)t + k];
        double u = m->uv1[2 * (size_t)v], w = m->uv1[2 * (size_t)v + 1];
        if (!isfinite(u) || !isfinite(w)) return 0;
        /* clamp far-off UVs (assets) so coordinates stay below 2^57 */
        u = fmin(fmax(u, -4.0), 5.0);
        w = fmin(fmax(w, -4.0), 5.0);
        /* u * W is exact in a double (24 + 14 bits), the scaling by 2^40 too; the cast only
         * truncates |uv| < 2^-17, consistently per vertex */
        out->x[k] = (int64_t)(u * W * 0x1p40);
        out->y[k] = (int64_t)(w * H * 0x1p40);
    }
    out->area = (texels_i128)(out->x[1] - out->x[0]) * (out->y[2] - out->y[0]) -
        (texels_i128)(out->y[1] - out->y[0]) * (out->x[2] - out->x[0]);
    return 1;
}

/* Edge function of edge a->b at p: >0 on the left (CCW interior). */
static texels_i128 texels_edge(const texels_tri *r, int a, int b, int64_t px, int64_t py) {
    return (texels_i128)(r->x[b] - r->x[a]) * (py - r->y[a]) - (texels_i128)(r->y[b] - r->y[a]) * (px - r->x[a]);
}

/* Tie rule for a centre exactly on an edge whose direction (after orienting the triangle
 * positively) is (dx, dy): exactly one of d and -d qualifies, so shared edges and vertices
 * are never claimed twice nor dropped. */
static int texels_owns_edge(int64_t dx, int64_t dy) { return dy > 0 || (dy == 0 && dx < 0); }

/* Weights w[k] (of vertex k) at texel centre (x, y); 1 when the centre is inside. */
static int texels_inside(const texels_tri *r, int64_t px, int64_t py, texels_i128 w[3]) {
    int s = r->area > 0 ? 1 : -1;
    for (int k = 0; k < 3; k++) {
        int a = (k + 1) % 3, b = (k + 2) % 3; /* edge opposite vertex k */
        w[k] = texels_edge(r, a, b, px, py);
        texels_i128 e = s * w[k];
        if (e < 0) return 0;
        if (e == 0 && !texels_owns_edge(s * (r->x[b] - r->x[a]), s * (r->y[b] - r->y[a]))) return 0;
    }
    return 1;
}

static int64_t texels_floordiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

static int64_t texels_clamp(int64_t v, int64_t lo, int64_t hi) { return v < lo ? lo : v > hi ? hi : v; }

/* Marks in mask the texels whose square overlaps triangle r: open square against the open
 * triangle by separating axes (x, y, three edge normals). A triangle of zero area (a segment
 * or point) marks the closed squares it touches, so it still has a footprint. */
static void texels_footprint(const texels_tri *r, uint32_t W, uint32_t H, uint8_t *mask) {
    const int64_t S = TEXELS_SUB;
    int64_t lo_x = r->x[0], hi_x = r->x[0], lo_y = r->y[0], hi_y = r->y[0];
    for (int k = 1; k < 3; k++) {
        lo_x = r->x[k] < lo_x ? r->x[k] : lo_x;
        hi_x = r->x[k] > hi_x ? r->x[k] : hi_x;
        lo_y = r->y[k] < lo_y ? r->y[k] : lo_y;
        hi_y = r->y[k] > hi_y ? r->y[k] : hi_y;
    }
    const int closed = r->area == 0;
    /* squares [t S, (t + 1) S] overlapping [lo, hi]: open, or touching when closed */
    int64_t x0 = closed ? -texels_floordiv(-lo_x, S) - 1 : texels_floordiv(lo_x, S);
    int64_t x1 = closed ? texels_floordiv(hi_x, S) : -texels_floordiv(-hi_x, S) - 1;
    int64_t y0 = closed ? -texels_floordiv(-lo_y, S) - 1 : texels_floordiv(lo_y, S);
    int64_t y1 = closed ? texels_floordiv(hi_y, S) : -texels_floordiv(-hi_y, S) - 1;
    x0 = texels_clamp(x0, 0, (int64_t)W);
    y0 = texels_clamp(y0, 0, (int64_t)H);
    x1 = texels_clamp(x1, -1, (int64_t)W - 1);
    y1 = texels_clamp(y1, -1, (int64_t)H - 1);
    if (x0 > x1 || y0 > y1) return;
    /* per edge E(X, Y) = ca X + cb Y + c (>= 0 inside): its max over a square is E at the
     * square's min corner + off, its min is max - span; stepped incrementally per texel */
    texels_i128 ca[3], cb[3], off[3], span[3], row[3], A = r->area < 0 ? -r->area : r->area;
    int ne = 0;
    int s = r->area < 0 ? -1 : 1;
    for (int k = 0; k < 3; k++) {
        int a = (k + 1) % 3, b = (k + 2) % 3;
        int64_t dx = r->x[b] - r->x[a], dy = r->y[b] - r->y[a];
        if (closed) { /* one non-zero edge spans the segment's line */
            if (ne || (dx == 0 && dy == 0)) continue;
            for (int j = k + 1; j < 3; j++) { /* the longest edge, for the clearest direction */
                int a2 = (j + 1) % 3, b2 = (j + 2) % 3;
                int64_t dx2 = r->x[b2] - r->x[a2], dy2 = r->y[b2] - r->y[a2];
                if (llabs(dx2) + llabs(dy2) > llabs(dx) + llabs(dy)) dx = dx2, dy = dy2, a = a2;
            }
        }
        ca[ne] = -(texels_i128)s * dy;
        cb[ne] = (texels_i128)s * dx;
        off[ne] = ((ca[ne] > 0 ? ca[ne] : 0) + (cb[ne] > 0 ? cb[ne] : 0)) * S;
        span[ne] = ((ca[ne] > 0 ? ca[ne] : -ca[ne]) + (cb[ne] > 0 ? cb[ne] : -cb[ne])) * S;
        row[ne] = ca[ne] * (x0 * S - r->x[a]) + cb[ne] * (y0 * S - r->y[a]) + off[ne];
        ne++;
    }
    for (int64_t y = y0; y <= y1; y++) {
        texels_i128 e[3] = {0, 0, 0};
        for (int k = 0; k < ne; k++) e[k] = row[k];
        uint8_t *out = mask + (size_t)y * W;
        for (int64_t x = x0; x <= x1; x++) {
            int in = 1;
            for (int k = 0; k < ne; k++) {
                in &= closed ? e[k] >= 0 && e[k] - span[k] <= 0 : e[k] > 0 && e[k] - span[k] < A;
                e[k] += ca[k] * S;
            }
            if (in) out[x] |= TEXELS_FOOT;
        }
        for (int k = 0; k < ne; k++) row[k] += cb[k] * S;
    }
}

/* Gives triangle t (r, non-zero area) every free texel centre inside it (same test as
 * texels_inside, stepped incrementally along rows); centres already owned count as contested. */
static void texels_claim(const texels_tri *r, uint32_t t, uint32_t W, uint32_t H, uint32_t *owner, uint8_t *mask,
                         uint64_t *contested, uint32_t *first_contested) {
    const int64_t S = TEXELS_SUB;
    int64_t lo_x = r->x[0], hi_x = r->x[0], lo_y = r->y[0], hi_y = r->y[0];
    for (int k = 1; k < 3; k++) {
        lo_x = r->x[k] < lo_x ? r->x[k] : lo_x;
        hi_x = r->x[k] > hi_x ? r->x[k] : hi_x;
        lo_y = r->y[k] < lo_y ? r->y[k] : lo_y;
        hi_y = r->y[k] > hi_y ? r->y[k] : hi_y;
    }
    /* texels whose centre x*S + S/2 lies in [lo, hi] */
    int64_t x0 = -texels_floordiv(-(lo_x - S / 2), S), x1 = texels_floordiv(hi_x - S / 2, S);
    int64_t y0 = -texels_floordiv(-(lo_y - S / 2), S), y1 = texels_floordiv(hi_y - S / 2, S);
    x0 = texels_clamp(x0, 0, (int64_t)W);
    y0 = texels_clamp(y0, 0, (int64_t)H);
    x1 = texels_clamp(x1, -1, (int64_t)W - 1);
    y1 = texels_clamp(y1, -1, (int64_t)H - 1);
    if (x0 > x1 || y0 > y1) return;
    const int s = r->area > 0 ? 1 : -1;
    texels_i128 ca[3], cb[3], row[3];
    int owns[3];
    for (int k = 0; k < 3; k++) {
        int a = (k + 1) % 3, b = (k + 2) % 3; /* edge opposite vertex k */
        int64_t dx = s * (r->x[b] - r->x[a]), dy = s * (r->y[b] - r->y[a]);
        ca[k] = -(texels_i128)dy;
        cb[k] = dx;
        owns[k] = texels_owns_edge(dx, dy);
        row[k] = ca[k] * (x0 * S + S / 2 - r->x[a]) + cb[k] * (y0 * S + S / 2 - r->y[a]);
    }
    for (int64_t y = y0; y <= y1; y++) {
        texels_i128 e0 = row[0], e1 = row[1], e2 = row[2];
        for (int64_t x = x0; x <= x1; x++, e0 += ca[0] * S, e1 += ca[1] * S, e2 += ca[2] * S) {
            if (!(e0 > 0 || (e0 == 0 && owns[0])) || !(e1 > 0 || (e1 == 0 && owns[1])) ||
                !(e2 > 0 || (e2 == 0 && owns[2])))
                continue;
            size_t i = (size_t)y * W + (size_t)x;
            if (owner[i] != LC_NONE) {
                if (!*contested) *first_contested = t;
                ++*contested;
                continue;
            }
            owner[i] = t;
            mask[i] |= TEXELS_FOOT; /* a BFS source, whatever the footprint rounding says */
        }
        for (int k = 0; k < 3; k++) row[k] += cb[k] * S;
    }
}

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
            texels_tri r; /* an owner is finite with non-zero area */
            texels_i128 w[3] = {0, 0, 0};
            texels_setup(m, t, j->W, j->H, &r);
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

/* ---- footprint fill --------------------------------------------------------------------- */

/* fixed neighbour order; the first among equally near sources wins (as in dilation) */
static const int texels_dx[8] = {-1, 0, 1, -1, 1, -1, 0, 1}, texels_dy[8] = {-1, -1, -1, 0, 0, 1, 1, 1};

/* Queues the empty, unqueued 8-neighbours of texel i. 0, or -1 when out of memory. */
static int texels_push_ring(uint32_t W, uint32_t H, size_t i, uint8_t *mask, const uint32_t *cache, uint32_t **list,
                            size_t *n, size_t *cap) {
    int64_t x = (int64_t)(i % W), y = (int64_t)(i / W);
    for (int k = 0; k < 8; k++) {
        int64_t nx = x + texels_dx[k], ny = y + texels_dy[k];
        if (nx < 0 || ny < 0 || nx >= (int64_t)W || ny >= (int64_t)H) continue;
        size_t ni = (size_t)(ny * (int64_t)W + nx);
        if (cache[ni] != LC_NONE || (mask[ni] & TEXELS_PENDING)) continue;
        if (*n == *cap) {
            size_t cap2 = *cap ? 2 * *cap : 4096;
            uint32_t *l2 = realloc(*list, cap2 * sizeof *l2);
            if (!l2) return -1;
            *list = l2;
            *cap = cap2;
        }
        mask[ni] |= TEXELS_PENDING;
        (*list)[(*n)++] = (uint32_t)ni;
    }
    return 0;
}

/* Layered BFS from the covered texels (src[i] = i) over footprint texels: each layer's
 * texels take the cache of the filled footprint neighbour with the nearest source (ties:
 * neighbour order), reading only earlier layers, so the result does not depend on queue
 * order. Only footprint texels pass the fill on; the ring around them is filled but stops.
 * Serial: the fill is a thin band along chart borders. Adds the filled count to *filled;
 * 0, or -1 when out of memory. */
static int texels_spread(uint32_t W, uint32_t H, uint8_t *mask, uint32_t *cache, uint32_t *src, uint64_t *filled) {
    const size_t N = (size_t)W * H;
    uint32_t *list = NULL;
    size_t n = 0, cap = 0;
    int rc = -1;
    for (size_t i = 0; i < N; i++) src[i] = cache[i] != LC_NONE ? (uint32_t)i : LC_NONE;
    for (size_t i = 0; i < N; i++)
        if (cache[i] != LC_NONE && texels_push_ring(W, H, i, mask, cache, &list, &n, &cap) != 0) goto err;
    size_t begin = 0;
    while (begin < n) {
        const size_t end = n;
        for (size_t q = begin; q < end; q++) {
            size_t i = list[q];
            int64_t x = (int64_t)(i % W), y = (int64_t)(i / W), best = INT64_MAX;
            size_t pick = 0;
            for (int k = 0; k < 8; k++) {
                int64_t nx = x + texels_dx[k], ny = y + texels_dy[k];
                if (nx < 0 || ny < 0 || nx >= (int64_t)W || ny >= (int64_t)H) continue;
                size_t ni = (size_t)(ny * (int64_t)W + nx);
                if (cache[ni] == LC_NONE || (mask[ni] & (TEXELS_PENDING | TEXELS_FOOT)) != TEXELS_FOOT) continue;
                int64_t sx = (int64_t)(src[ni] % W) - x, sy = (int64_t)(src[ni] / W) - y;
                if (sx * sx + sy * sy < best) {
                    best = sx * sx + sy * sy;
                    pick = ni;
                }
            }
            /* always found: i was queued by a filled footprint texel of an earlier layer */
            cache[i] = cache[pick];
            src[i] = src[pick];
        }
        for (size_t q = begin; q < end; q++) mask[list[q]] &= (uint8_t)~TEXELS_PENDING;
        for (size_t q = begin; q < end; q++)
            if ((mask[list[q]] & TEXELS_FOOT) && texels_push_ring(W, H, list[q], mask, cache, &list, &n, &cap) != 0)
                goto err;
        *filled += end - begin;
        begin = end;
    }
    /* only a chart owning no texel centre (sub-texel, or lost to float uv1 rounding) has
     * footprint texels the fill cannot reach */
    size_t orphans = 0;
    for (size_t i = 0; i < N; i++) orphans += (mask[i] & TEXELS_FOOT) && cache[i] == LC_NONE;
    if (orphans) lc_debug("texels", "%zu footprint texels stay empty: their chart owns no texel centre", orphans);
    rc = 0;
err:
    for (size_t q = 0; q < n; q++) mask[list[q]] &= (uint8_t)~TEXELS_PENDING;
    free(list);
    return rc;
}

int lc_texels_rasterize(const lc_scene *scene, uint32_t width, uint32_t height, int threads, lc_lightmap *lm,
                        lc_lcb_cache **caches, uint32_t *n_caches, char *err, size_t errlen) {
    uint32_t *owner = NULL, *row_count = NULL, *texel_cache = NULL;
    uint8_t *mask = NULL;
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
        lc_set_err(err, errlen, "texels: lightmap size %ux%u is out of range [1, %u]", width, height, TEXELS_MAX_SIZE);
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
    mask = calloc(N, 1);
    if (!owner || !row_count || !texel_cache || !mask) goto oom;
    memset(owner, 0xFF, N * sizeof *owner);

    /* ownership: serial in triangle order, so the lowest triangle keeps a contested centre */
    uint64_t contested = 0;
    uint32_t first_contested = LC_NONE;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        texels_tri r;
        if (!texels_setup(m, t, width, height, &r)) continue;
        texels_footprint(&r, width, height, mask);
        if (r.area == 0) continue;
        texels_claim(&r, t, width, height, owner, mask, &contested, &first_contested);
    }
    if (contested)
        lc_warn("texels",
                "%llu texel centres are covered by more than one triangle (overlapping lightmap UVs, "
                "first at triangle %u); the lowest triangle keeps each",
                (unsigned long long)contested, first_contested);

    texels_job job = {scene, width, height, owner, row_count, texel_cache, NULL, 0};
    lc_parallel_for(threads, height, 16, texels_count_rows, &job);
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
    lc_parallel_for(threads, height, 8, texels_fill_rows, &job);
    /* owners are final: owner becomes the BFS's source-texel array */
    uint64_t filled = 0;
    if (texels_spread(width, height, mask, texel_cache, owner, &filled) != 0) goto oom;
    *n_caches = base + n;
    memset(lm, 0, sizeof *lm);
    lm->width = width;
    lm->height = height;
    lm->texel_cache = texel_cache;
    lm->n_covered = n;
    lm->n_dilated = (uint32_t)filled;
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
    free(mask);
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

void lc_texels_dilate(lc_lightmap *lm, uint32_t passes, int threads) {
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
        lc_parallel_for(threads, lm->height, 16, texels_dilate_rows, &job);
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
