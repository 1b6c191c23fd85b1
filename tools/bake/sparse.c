/* sparse: LightSkin sparse points and per-vertex nearest-point tables (bake/sparse.h). */
#include "bake/sparse.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/clock.h"
#include "util/log.h"
#include "util/rng.h"

#define SP_RINGS_MAX 8    /* ring search depth before a query scans every item */
#define SP_ELIM_ALPHA 8   /* Yuksel's weight exponent */
#define SP_ELIM_BETA 0.65 /* weight limiting: r_min = r_max (1 - (N/M)^gamma) beta */
#define SP_ELIM_GAMMA 1.5
#define SP_CELL_MIN_FRACTION 1e-6 /* grid cells at least this fraction of the extent */

/* --- a hashed uniform grid over 3-float items, with exact k-nearest queries ------------------ */

typedef struct sp_grid {
    const float *p; /* 3 per item, borrowed */
    uint32_t n;
    double lo[3], cell;
    uint32_t mask;  /* buckets - 1 */
    uint32_t *head; /* per bucket: first item or LC_NONE */
    uint32_t *next; /* per item */
    int32_t *key;   /* 3 per item: its cell */
} sp_grid;

static void sp_grid_free(sp_grid *g) {
    free(g->head), free(g->next), free(g->key);
    memset(g, 0, sizeof *g);
}

static void sp_cell_of(const sp_grid *g, const float x[3], int32_t c[3]) {
    for (int k = 0; k < 3; k++) {
        double t = floor(((double)x[k] - g->lo[k]) / g->cell);
        c[k] = (int32_t)(t < -1e9 ? -1e9 : t > 1e9 ? 1e9 : t);
    }
}

static uint32_t sp_hash(const sp_grid *g, const int32_t c[3]) {
    return ((uint32_t)c[0] * 73856093u ^ (uint32_t)c[1] * 19349663u ^ (uint32_t)c[2] * 83492791u) & g->mask;
}

static float sp_d2(const float a[3], const float b[3]) {
    float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return dx * dx + dy * dy + dz * dz;
}

/* The grid over p[0..n) with cells of `cell` metres (raised to a millionth of the extent so
 * cell coordinates stay small). Returns 0 or -1 (out of memory). */
static int sp_grid_build(sp_grid *g, const float *p, uint32_t n, double cell) {
    memset(g, 0, sizeof *g);
    g->p = p, g->n = n;
    double hi[3] = {-INFINITY, -INFINITY, -INFINITY}, extent = 0;
    for (int k = 0; k < 3; k++) g->lo[k] = INFINITY;
    for (uint32_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            g->lo[k] = fmin(g->lo[k], p[3 * (size_t)i + k]), hi[k] = fmax(hi[k], p[3 * (size_t)i + k]);
    for (int k = 0; k < 3; k++) extent = fmax(extent, n ? hi[k] - g->lo[k] : 0);
    g->cell = fmax(cell, fmax(extent * SP_CELL_MIN_FRACTION, 1e-12));
    uint32_t buckets = 1;
    while (buckets < 2 * (uint64_t)n && buckets < (1u << 30)) buckets <<= 1;
    g->mask = buckets - 1;
    g->head = malloc((size_t)buckets * sizeof *g->head);
    g->next = malloc((n ? n : 1) * sizeof *g->next);
    g->key = malloc((n ? n : 1) * 3 * sizeof *g->key);
    if (!g->head || !g->next || !g->key) {
        sp_grid_free(g);
        return -1;
    }
    memset(g->head, 0xFF, (size_t)buckets * sizeof *g->head);
    for (uint32_t i = n; i-- > 0;) { /* pushed in reverse: each bucket lists ascending indices */
        int32_t *c = g->key + 3 * (size_t)i;
        sp_cell_of(g, p + 3 * (size_t)i, c);
        uint32_t h = sp_hash(g, c);
        g->next[i] = g->head[h];
        g->head[h] = i;
    }
    return 0;
}

/* The k nearest items so far, nearest first, ties by index. */
typedef struct sp_best {
    uint32_t k, found;
    uint32_t idx[LC_SPARSE_NEIGHBOURS];
    float d2[LC_SPARSE_NEIGHBOURS];
} sp_best;

static int sp_before(float d2, uint32_t i, float d2b, uint32_t ib) { return d2 < d2b || (d2 == d2b && i < ib); }

static void sp_best_add(sp_best *b, uint32_t i, float d2) {
    if (b->found == b->k && !sp_before(d2, i, b->d2[b->k - 1], b->idx[b->k - 1])) return;
    uint32_t j = b->found < b->k ? b->found++ : b->k - 1;
    for (; j > 0 && sp_before(d2, i, b->d2[j - 1], b->idx[j - 1]); j--)
        b->d2[j] = b->d2[j - 1], b->idx[j] = b->idx[j - 1];
    b->d2[j] = d2, b->idx[j] = i;
}

static void sp_visit(const sp_grid *g, const int32_t c[3], const float q[3], uint32_t skip, sp_best *b) {
    for (uint32_t i = g->head[sp_hash(g, c)]; i != LC_NONE; i = g->next[i]) {
        const int32_t *kc = g->key + 3 * (size_t)i;
        if (i == skip || kc[0] != c[0] || kc[1] != c[1] || kc[2] != c[2]) continue; /* hash neighbours */
        sp_best_add(b, i, sp_d2(q, g->p + 3 * (size_t)i));
    }
}

/* The k (<= 8) nearest items to q other than `skip` (LC_NONE: none), exactly: rings of cells
 * around q's until the k-th is closer than anything outside them, else a scan. */
static void sp_knn(const sp_grid *g, const float q[3], uint32_t k, uint32_t skip, sp_best *b) {
    uint32_t avail = g->n - (skip < g->n ? 1 : 0);
    b->k = k < avail ? k : avail;
    b->found = 0;
    if (b->k == 0) return;
    int32_t c0[3];
    sp_cell_of(g, q, c0);
    for (int r = 0; r <= SP_RINGS_MAX; r++) {
        for (int dz = -r; dz <= r; dz++)
            for (int dy = -r; dy <= r; dy++) {
                int face = dz == -r || dz == r || dy == -r || dy == r;
                for (int dx = -r; dx <= r; dx += face || r == 0 ? 1 : 2 * r) {
                    int32_t c[3] = {c0[0] + dx, c0[1] + dy, c0[2] + dz};
                    sp_visit(g, c, q, skip, b);
                }
            }
        double reach = (double)r * g->cell;
        if (b->found == b->k && (double)b->d2[b->k - 1] <= reach * reach) return;
    }
    b->found = 0;
    for (uint32_t i = 0; i < g->n; i++)
        if (i != skip) sp_best_add(b, i, sp_d2(q, g->p + 3 * (size_t)i));
}

/* A cell size for n points spread over a surface inside their bounding box: twice the spacing
 * that the box's surface area would give (so the 8 nearest usually lie within one ring). */
static double sp_cell_for(const float *p, uint32_t n) {
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            lo[k] = fminf(lo[k], p[3 * (size_t)i + k]), hi[k] = fmaxf(hi[k], p[3 * (size_t)i + k]);
    double e[3];
    for (int k = 0; k < 3; k++) e[k] = n ? (double)hi[k] - lo[k] : 0;
    double s = 2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]);
    return n ? 2 * sqrt(s / n) : 1;
}

/* --- candidates and sample elimination -------------------------------------------------------- */

static void sp_tri(const lc_lcb_asset_vertex *v, const uint32_t *t, double e1[3], double e2[3], double nrm[3]) {
    const float *a = v[t[0]].position, *b = v[t[1]].position, *c = v[t[2]].position;
    for (int k = 0; k < 3; k++) e1[k] = (double)b[k] - a[k], e2[k] = (double)c[k] - a[k];
    nrm[0] = e1[1] * e2[2] - e1[2] * e2[1];
    nrm[1] = e1[2] * e2[0] - e1[0] * e2[2];
    nrm[2] = e1[0] * e2[1] - e1[1] * e2[0];
}

/* m candidates: triangle by area (cdf, nt + 1 entries), uniform inside it. */
static void sp_candidates(const lc_lcb_asset_vertex *v, const uint32_t *idx, uint32_t nt, const double *cdf, uint32_t m,
                          lc_rng *rng, float *cp, uint32_t *ctri) {
    for (uint32_t i = 0; i < m; i++) {
        double x = ((double)(lc_rng_next(rng) >> 11) * 0x1p-53) * cdf[nt];
        uint32_t lo = 0, hi = nt - 1; /* the first triangle whose cdf end exceeds x: never one without area */
        while (lo < hi) {
            uint32_t mid = lo + (hi - lo) / 2;
            if (cdf[mid + 1] <= x) lo = mid + 1;
            else hi = mid;
        }
        const uint32_t *t = idx + 3 * (size_t)lo;
        double e1[3], e2[3], nrm[3];
        sp_tri(v, t, e1, e2, nrm);
        double su = sqrt((double)(lc_rng_next(rng) >> 11) * 0x1p-53), r2 = (double)(lc_rng_next(rng) >> 11) * 0x1p-53;
        double b1 = su * (1 - r2), b2 = su * r2; /* uniform barycentrics (Osada et al.) */
        for (int k = 0; k < 3; k++) cp[3 * (size_t)i + k] = (float)(v[t[0]].position[k] + b1 * e1[k] + b2 * e2[k]);
        ctri[i] = lo;
    }
}

typedef struct sp_elim {
    const sp_grid *g;
    double r2max, rmin; /* the weights' reach (2 r_max) and the limit */
    double *w;
    uint32_t *heap, *pos, size;
    uint8_t *alive;
} sp_elim;

static double sp_weight(const sp_elim *e, double d) {
    if (d >= e->r2max) return 0;
    double t = 1 - fmax(d, e->rmin) / e->r2max, t2 = t * t, t4 = t2 * t2;
    return t4 * t4; /* alpha = 8 */
}

static int sp_heap_above(const sp_elim *e, uint32_t a, uint32_t b) {
    return e->w[a] > e->w[b] || (e->w[a] == e->w[b] && a < b);
}

static void sp_heap_swap(sp_elim *e, uint32_t i, uint32_t j) {
    uint32_t t = e->heap[i];
    e->heap[i] = e->heap[j], e->heap[j] = t;
    e->pos[e->heap[i]] = i, e->pos[e->heap[j]] = j;
}

static void sp_heap_down(sp_elim *e, uint32_t i) {
    for (;;) {
        uint32_t l = 2 * i + 1, r = l + 1, top = i;
        if (l < e->size && sp_heap_above(e, e->heap[l], e->heap[top])) top = l;
        if (r < e->size && sp_heap_above(e, e->heap[r], e->heap[top])) top = r;
        if (top == i) return;
        sp_heap_swap(e, i, top);
        i = top;
    }
}

/* Adds sign x the weight of every alive neighbour j of i to w[j] (sign -1: i was removed,
 * the neighbours sink in the heap), or, with sign 0, sums them into w[i]. */
static void sp_neighbours(sp_elim *e, uint32_t i, int sign) {
    const sp_grid *g = e->g;
    const int32_t *c0 = g->key + 3 * (size_t)i;
    const float *q = g->p + 3 * (size_t)i;
    for (int dz = -1; dz <= 1; dz++)
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int32_t c[3] = {c0[0] + dx, c0[1] + dy, c0[2] + dz};
                for (uint32_t j = g->head[sp_hash(g, c)]; j != LC_NONE; j = g->next[j]) {
                    const int32_t *kc = g->key + 3 * (size_t)j;
                    if (j == i || !e->alive[j] || kc[0] != c[0] || kc[1] != c[1] || kc[2] != c[2]) continue;
                    double w = sp_weight(e, sqrt((double)sp_d2(q, g->p + 3 * (size_t)j)));
                    if (w == 0) continue;
                    if (sign == 0) {
                        e->w[i] += w;
                    } else {
                        e->w[j] -= w;
                        sp_heap_down(e, e->pos[j]);
                    }
                }
            }
}

/* Removes the candidate with the largest weight until n remain (alive[] marks them). */
static int sp_eliminate(const float *cp, uint32_t m, uint32_t n, double area, uint8_t *alive) {
    double rmax = sqrt(area / (2 * sqrt(3.0) * n));
    sp_grid g;
    sp_elim e = {.r2max = 2 * rmax, .rmin = rmax * (1 - pow((double)n / m, SP_ELIM_GAMMA)) * SP_ELIM_BETA};
    e.w = calloc(m, sizeof *e.w);
    e.heap = malloc(m * sizeof *e.heap);
    e.pos = malloc(m * sizeof *e.pos);
    e.alive = alive;
    int rc = -1;
    if (!e.w || !e.heap || !e.pos || sp_grid_build(&g, cp, m, e.r2max) != 0) goto out;
    e.g = &g;
    memset(alive, 1, m);
    for (uint32_t i = 0; i < m; i++) sp_neighbours(&e, i, 0);
    for (uint32_t i = 0; i < m; i++) e.heap[i] = i, e.pos[i] = i;
    e.size = m;
    for (uint32_t i = m / 2; i-- > 0;) sp_heap_down(&e, i);
    while (e.size > n) {
        uint32_t top = e.heap[0];
        sp_heap_swap(&e, 0, e.size - 1);
        e.size--;
        sp_heap_down(&e, 0);
        alive[top] = 0;
        sp_neighbours(&e, top, -1);
    }
    sp_grid_free(&g);
    rc = 0;
out:
    free(e.w), free(e.heap), free(e.pos);
    return rc;
}

/* --- points ------------------------------------------------------------------------------------ */

/* Radii (§3.3) and the spacing statistics of the n points at p. */
static int sp_radii(const lc_lcb_asset_vertex *v, uint32_t nv, const float *p, uint32_t n, double area,
                    lc_lcb_sparse_point *out, lc_sparse_stats *st) {
    sp_grid g;
    float *rmax = calloc(n, sizeof *rmax);
    if (!rmax || sp_grid_build(&g, p, n, sp_cell_for(p, n)) != 0) {
        free(rmax);
        return -1;
    }
    sp_best b;
    for (uint32_t i = 0; i < nv; i++) {
        sp_knn(&g, v[i].position, 1, LC_NONE, &b);
        float d = sqrtf(b.d2[0]);
        if (d > rmax[b.idx[0]]) rmax[b.idx[0]] = d;
    }
    float fallback = (float)sqrt(area / (M_PI * n));
    double sum = 0, lo = INFINITY;
    st->empty_regions = 0;
    for (uint32_t i = 0; i < n; i++) {
        out[i].radius = rmax[i] > 0 ? rmax[i] : fallback;
        st->empty_regions += rmax[i] > 0 ? 0 : 1;
        sp_knn(&g, p + 3 * (size_t)i, 1, i, &b);
        double d = b.found ? sqrt((double)b.d2[0]) : 0;
        sum += d, lo = fmin(lo, d);
    }
    st->min_spacing = n > 1 ? lo : 0;
    st->mean_spacing = n > 1 ? sum / n : 0;
    sp_grid_free(&g);
    free(rmax);
    return 0;
}

int lc_sparse_points(const lc_lcb_asset_vertex *v, uint32_t nv, const uint32_t *idx, uint32_t nt, uint32_t n,
                     uint32_t seed, uint32_t asset, lc_lcb_sparse_point *out, lc_sparse_stats *st, char *err,
                     size_t errlen) {
    double t0 = lc_clock_ms();
    double *cdf = NULL;
    float *cp = NULL, *pp = NULL;
    uint32_t *ctri = NULL;
    uint8_t *alive = NULL;
    lc_sparse_stats local;
    if (!st) st = &local;
    memset(st, 0, sizeof *st);
    if (!v || !idx || !out || n < 1 || n > LC_SPARSE_MAX_POINTS || nt == 0) {
        lc_set_err(err, errlen,
                   "sparse points: need 1..%u points and an asset with triangles (got %u points, %u "
                   "triangles)",
                   LC_SPARSE_MAX_POINTS, n, nt);
        return -1;
    }
    for (uint32_t i = 0; i < nv; i++)
        if (!isfinite(v[i].position[0]) || !isfinite(v[i].position[1]) || !isfinite(v[i].position[2])) {
            lc_set_err(err, errlen, "sparse points: vertex %u position is not finite", i);
            return -1;
        }
    for (uint64_t k = 0; k < 3 * (uint64_t)nt; k++)
        if (idx[k] >= nv) {
            lc_set_err(err, errlen, "sparse points: triangle %llu index %u >= %u vertices", (unsigned long long)(k / 3),
                       idx[k], nv);
            return -1;
        }
    uint32_t m = n * LC_SPARSE_CANDIDATES;
    cdf = malloc(((size_t)nt + 1) * sizeof *cdf);
    cp = malloc((size_t)m * 3 * sizeof *cp);
    ctri = malloc((size_t)m * sizeof *ctri);
    alive = malloc(m);
    pp = malloc((size_t)n * 3 * sizeof *pp);
    int rc = -1;
    if (!cdf || !cp || !ctri || !alive || !pp) goto oom;
    cdf[0] = 0;
    for (uint32_t t = 0; t < nt; t++) {
        double e1[3], e2[3], nrm[3];
        sp_tri(v, idx + 3 * (size_t)t, e1, e2, nrm);
        cdf[t + 1] = cdf[t] + 0.5 * sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
    }
    st->area = cdf[nt];
    if (!(st->area > 0) || !isfinite(st->area)) {
        lc_set_err(err, errlen, "sparse points: the asset's %u triangles have no area", nt);
        goto out;
    }
    lc_rng rng = lc_rng_seed(seed, 0x5350415253450000ull + asset); /* "SPARSE" stream per asset */
    sp_candidates(v, idx, nt, cdf, m, &rng, cp, ctri);
    if (sp_eliminate(cp, m, n, st->area, alive) != 0) goto oom;
    st->candidates = m;
    uint32_t o = 0;
    for (uint32_t i = 0; i < m && o < n; i++) {
        if (!alive[i]) continue;
        lc_lcb_sparse_point *q = &out[o];
        double e1[3], e2[3], nrm[3];
        sp_tri(v, idx + 3 * (size_t)ctri[i], e1, e2, nrm);
        double len = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
        q->asset = asset;
        for (int k = 0; k < 3; k++) {
            q->position[k] = pp[3 * (size_t)o + k] = cp[3 * (size_t)i + k];
            q->normal[k] = (float)(nrm[k] / len);
        }
        o++;
    }
    if (o != n || sp_radii(v, nv, pp, n, st->area, out, st) != 0) goto oom;
    st->seconds = (lc_clock_ms() - t0) * 1e-3;
    rc = 0;
    goto out;
oom:
    lc_set_err(err, errlen, "sparse points: out of memory for %u points (%u candidates)", n, m);
out:
    free(cdf), free(cp), free(ctri), free(alive), free(pp);
    return rc;
}

/* --- tables ------------------------------------------------------------------------------------ */

/* Eq. 12 for one vertex from its nearest points b (normal nv unit or zero). */
static int sp_weights(const sp_best *b, const float nv[3], const lc_lcb_sparse_point *pts, lc_lcb_sparse_vertex *r) {
    float dmax = sqrtf(b->d2[b->found - 1]), sum = 0;
    for (uint32_t j = 0; j < LC_SPARSE_NEIGHBOURS; j++) {
        if (j >= b->found) {
            r->index[j] = (uint16_t)b->idx[0], r->weight[j] = 0;
            continue;
        }
        const float *nj = pts[b->idx[j]].normal;
        float dot = nv[0] * nj[0] + nv[1] * nj[1] + nv[2] * nj[2];
        float near = dmax > 0 ? 1 - sqrtf(b->d2[j]) / dmax : 1;
        float w = fmaxf(near, 0) * fminf(fmaxf(dot, 0), 1);
        r->index[j] = (uint16_t)b->idx[j], r->weight[j] = w;
        sum += w;
    }
    if (!(sum > 0)) {
        for (int j = 0; j < LC_SPARSE_NEIGHBOURS; j++) r->weight[j] = 0;
        r->weight[0] = 1;
        return 1;
    }
    for (int j = 0; j < LC_SPARSE_NEIGHBOURS; j++) r->weight[j] /= sum;
    return 0;
}

int lc_sparse_vertex_table(const lc_lcb_asset_vertex *v, uint32_t nv, const lc_lcb_sparse_point *pts, uint32_t np,
                           lc_lcb_sparse_vertex *out, lc_sparse_stats *st, char *err, size_t errlen) {
    double t0 = lc_clock_ms();
    lc_sparse_stats local;
    if (!st) st = &local;
    st->fallback_vertices = 0;
    if ((!v && nv) || !pts || (!out && nv) || np < 1 || np > LC_SPARSE_MAX_POINTS) {
        lc_set_err(err, errlen, "sparse table: need 1..%u points (got %u) and the vertices", LC_SPARSE_MAX_POINTS, np);
        return -1;
    }
    sp_grid g = {0};
    int rc = -1;
    float *p = malloc((size_t)np * 3 * sizeof *p);
    if (!p) goto oom;
    for (uint32_t i = 0; i < np; i++) memcpy(p + 3 * (size_t)i, pts[i].position, 3 * sizeof *p);
    if (sp_grid_build(&g, p, np, sp_cell_for(p, np)) != 0) goto oom;
    for (uint32_t i = 0; i < nv; i++) {
        if (!isfinite(v[i].position[0]) || !isfinite(v[i].position[1]) || !isfinite(v[i].position[2])) {
            lc_set_err(err, errlen, "sparse table: vertex %u position is not finite", i);
            goto out;
        }
        const float *n0 = v[i].normal;
        float len = sqrtf(n0[0] * n0[0] + n0[1] * n0[1] + n0[2] * n0[2]), n[3] = {0, 0, 0};
        if (isfinite(len) && len > 1e-20f)
            for (int k = 0; k < 3; k++) n[k] = n0[k] / len;
        sp_best b;
        sp_knn(&g, v[i].position, LC_SPARSE_NEIGHBOURS, LC_NONE, &b);
        st->fallback_vertices += (uint32_t)sp_weights(&b, n, pts, &out[i]);
    }
    st->seconds = (lc_clock_ms() - t0) * 1e-3;
    rc = 0;
    goto out;
oom:
    lc_set_err(err, errlen, "sparse table: out of memory for %u points", np);
out:
    sp_grid_free(&g);
    free(p);
    return rc;
}
