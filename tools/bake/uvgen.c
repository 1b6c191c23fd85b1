/* uvgen: lightmap UV generation (see uvgen.h).
 *
 * Pipeline: weld vertices within 1e-6 of the scene extent -> edge adjacency -> region-grow
 * charts (BFS, normal within chart_angle of the chart's running area-weighted normal, kept
 * only if every triangle is within it of the final normal, else regrown against the seed
 * normal) -> project every chart onto the plane of its area-weighted normal, rotate to the
 * minimum-area bounding rectangle, landscape -> exact 2D overlap test (separating axes on a
 * per-chart grid); an overlapping chart is bisected along its longest 3D axis and re-split
 * into connected pieces until nothing overlaps -> merge charts into edge-adjacent ones,
 * smallest first, when the union still projects without flips or overlap and saves atlas
 * texels (most charts of real scenes are sub-texel bevels and mouldings whose padding costs
 * more than they do) -> project and check the merged charts the same way -> choose the
 * density (given, or binary search to fit atlas_size, growing the atlas when the charts
 * cannot fit it at all) -> skyline or shelf packing with padding -> rewrite the mesh with one
 * vertex per (original vertex, chart) and uv1 filled.
 *
 * Placement detail: a chart's largest triangle has its incentre put exactly on a texel
 * centre, so every chart owns at least one texel whatever its size. The chart's
 * conservative footprint (texels its triangles touch) is known from its extent and that
 * sub-texel offset, so packing reserves footprint + padding and charts can never bleed into
 * each other (gaps >= padding texels, also to the atlas border). */
#include "bake/uvgen.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"

#define UVGEN_MAX_ATLAS 16384u
#define UVGEN_MAX_PADDING 64u
/* Slack for float rounding of uv1 (in texels) when reserving footprints. */
#define UVGEN_SLACK 2e-3
/* Vertices closer than this fraction of the scene extent are one vertex for chart topology. */
#define UVGEN_WELD_TOL 1e-6
/* Merging: max normal deviation of any triangle from a merged chart's projection normal
 * (steep ones are only allowed within the UVGEN_MERGE_SQUASH texel budget, so this only lets
 * sub-texel bevels join), passes over all charts, neighbours tried per chart. */
#define UVGEN_MERGE_MAX_DEG 88.0
#define UVGEN_MERGE_PASSES 3
#define UVGEN_MERGE_TRIES 4
/* Past its work budget, merging only tries unions up to this many triangles. */
#define UVGEN_MERGE_SMALL_UNION 4096u
/* Texels (in units of one chart's padding overhead) a merge may squash beyond the chart angle. */
#define UVGEN_MERGE_SQUASH 2.0
/* Atlas growth when the charts cannot fit atlas_size: ~x1.25 steps up to this side. */
#define UVGEN_GROW_MAX 8192u

typedef struct {
    uint32_t start, count; /* range in the triangle order array */
    int dead;              /* split into sub-charts */
    int fixed;             /* project onto ref (a merge chose it), not the average normal */
    double ref[3];         /* every triangle is within the chart angle of this normal (merged
                            * charts: within UVGEN_MERGE_MAX_DEG) */
    double U[3], V[3];     /* in-plane axes (a rotation of the projection plane basis) */
    double umin, vmin;     /* local origin in (U, V) metres */
    double w, h;           /* extent in metres, w >= h */
    double au, av;         /* anchor: incentre of the largest triangle, chart-local metres */
    /* placement at the chosen density */
    int rot;         /* rotated 90 degrees in the atlas */
    double fx, fy;   /* sub-texel offset of the chart's min corner inside its rect */
    uint32_t fw, fh; /* footprint rect in texels */
    uint32_t x, y;   /* rect origin in the atlas */
} uvgen_chart;

typedef struct {
    uint64_t key;
    uint32_t tri;
} uvgen_edge;

typedef struct {
    uint32_t fw, fh, id;
} uvgen_item;

/* ---- small double vector helpers ---------------------------------------------------- */

/* fmin/fmax are library calls with NaN rules; inputs here are finite */
static inline double uvgen_min(double a, double b) { return a < b ? a : b; }
static inline double uvgen_max(double a, double b) { return a > b ? a : b; }

static void uvgen_load(const lc_mesh *m, uint32_t v, double out[3]) {
    const float *p = m->position + 3 * (size_t)v;
    out[0] = p[0];
    out[1] = p[1];
    out[2] = p[2];
}

static double uvgen_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void uvgen_cross(const double a[3], const double b[3], double out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static int uvgen_normalize(double v[3]) {
    double l = sqrt(uvgen_dot(v, v));
    if (!(l > 0) || !isfinite(l)) return 0;
    v[0] /= l;
    v[1] /= l;
    v[2] /= l;
    return 1;
}

/* Unnormalized 3D cross of triangle edges (|c| = 2 area) and squared longest edge. */
static void uvgen_tri_cross(const lc_mesh *m, uint32_t t, double c[3], double *max_e2) {
    const uint32_t *ix = m->index + 3 * (size_t)t;
    double a[3], b[3], d[3], e1[3], e2[3], e3[3];
    uvgen_load(m, ix[0], a);
    uvgen_load(m, ix[1], b);
    uvgen_load(m, ix[2], d);
    for (int k = 0; k < 3; k++) {
        e1[k] = b[k] - a[k];
        e2[k] = d[k] - a[k];
        e3[k] = d[k] - b[k];
    }
    uvgen_cross(e1, e2, c);
    double m2 = fmax(uvgen_dot(e1, e1), fmax(uvgen_dot(e2, e2), uvgen_dot(e3, e3)));
    if (max_e2) *max_e2 = m2;
}

/* ---- welding ------------------------------------------------------------------------- */

static uint64_t uvgen_hash(uint64_t a, uint64_t b, uint64_t c) {
    uint64_t h = a * 0x9E3779B97F4A7C15ull;
    h ^= (h >> 29) ^ (b * 0xC2B2AE3D27D4EB4Full);
    h ^= (h >> 31) ^ (c * 0x165667B19E3779F9ull);
    h ^= h >> 33;
    h *= 0xFF51AFD7ED558CCDull;
    h ^= h >> 33;
    return h;
}

/* weld[v] = lowest earlier representative vertex within q (per axis) of v, else v itself.
 * Assets often have cracks (duplicated vertices a rounding error apart) that would otherwise
 * split charts; q is a tiny fraction of the scene extent. Representatives live in a hash of
 * q-sized cells; the 27 cells around v are searched, so welding is independent of where cell
 * boundaries fall. Charts are projected (and uv1 computed) from the representative's
 * position, so a cracked edge is one edge in the atlas too, not two a sub-texel sliver
 * apart that would read as an overlap. */
static int uvgen_weld(const lc_mesh *m, uint32_t *weld) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t v = 0; v < m->n_vertices; v++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], m->position[3 * (size_t)v + k]);
            hi[k] = fmax(hi[k], m->position[3 * (size_t)v + k]);
        }
    double ext = fmax(hi[0] - lo[0], fmax(hi[1] - lo[1], hi[2] - lo[2]));
    double q = UVGEN_WELD_TOL * ext;
    if (!(q > 0)) q = 1; /* a single point: everything welds */
    size_t cap = 16;
    while (cap < 2 * (size_t)m->n_vertices) cap <<= 1;
    uint32_t *table = malloc(cap * sizeof *table);
    if (!table) return -1;
    memset(table, 0xFF, cap * sizeof *table);
    for (uint32_t v = 0; v < m->n_vertices; v++) {
        const float *p = m->position + 3 * (size_t)v;
        int64_t cell[3];
        for (int k = 0; k < 3; k++) cell[k] = (int64_t)floor((p[k] - lo[k]) / q);
        uint32_t best = LC_NONE;
        for (int n = 0; n < 27; n++) {
            int64_t c[3] = {cell[0] + n % 3 - 1, cell[1] + n / 3 % 3 - 1, cell[2] + n / 9 - 1};
            size_t s = (size_t)uvgen_hash((uint64_t)c[0], (uint64_t)c[1], (uint64_t)c[2]) & (cap - 1);
            for (; table[s] != LC_NONE; s = (s + 1) & (cap - 1)) {
                uint32_t o = table[s];
                const float *r = m->position + 3 * (size_t)o;
                int same = 1, near = 1;
                for (int k = 0; k < 3; k++) {
                    same &= (int64_t)floor((r[k] - lo[k]) / q) == c[k];
                    near &= fabs((double)r[k] - p[k]) <= q;
                }
                if (same && near && o < best) best = o;
            }
        }
        if (best != LC_NONE) {
            weld[v] = best;
            continue;
        }
        weld[v] = v;
        size_t s = (size_t)uvgen_hash((uint64_t)cell[0], (uint64_t)cell[1], (uint64_t)cell[2]) & (cap - 1);
        while (table[s] != LC_NONE) s = (s + 1) & (cap - 1);
        table[s] = v;
    }
    free(table);
    return 0;
}

/* Stable LSD radix sort of edges by key (input is in triangle order, so ties stay sorted by
 * triangle: the adjacency order, hence the chart order, is deterministic). */
static int uvgen_sort_edges(uvgen_edge *e, size_t n) {
    uvgen_edge *tmp = malloc(n * sizeof *tmp);
    if (!tmp) return -1;
    uint64_t all_or = 0;
    for (size_t i = 0; i < n; i++) all_or |= e[i].key;
    uvgen_edge *src = e, *dst = tmp;
    for (int shift = 0; shift < 64; shift += 8) {
        if (((all_or >> shift) & 0xFF) == 0) continue;
        size_t count[257] = {0};
        for (size_t i = 0; i < n; i++) count[((src[i].key >> shift) & 0xFF) + 1]++;
        for (int k = 0; k < 256; k++) count[k + 1] += count[k];
        for (size_t i = 0; i < n; i++) dst[count[(src[i].key >> shift) & 0xFF]++] = src[i];
        uvgen_edge *s = src;
        src = dst;
        dst = s;
    }
    if (src != e) memcpy(e, src, n * sizeof *e);
    free(tmp);
    return 0;
}

/* Triangle adjacency in CSR form: triangles sharing a welded edge. Non-manifold edges with
 * many triangles are chained rather than fully connected (keeps it linear). */
static int uvgen_adjacency(const lc_mesh *m, const uint32_t *weld, uint32_t **adj_start, uint32_t **adj) {
    size_t ne = 3 * (size_t)m->n_triangles;
    uvgen_edge *e = malloc(ne * sizeof *e);
    uint32_t *start = calloc((size_t)m->n_triangles + 1, sizeof *start);
    uint32_t *list = NULL;
    if (!e || !start) goto err;
    size_t n = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++)
        for (int k = 0; k < 3; k++) {
            uint32_t a = weld[m->index[3 * (size_t)t + k]], b = weld[m->index[3 * (size_t)t + (k + 1) % 3]];
            if (a == b) continue;
            if (a > b) {
                uint32_t s = a;
                a = b;
                b = s;
            }
            e[n++] = (uvgen_edge){((uint64_t)a << 32) | b, t};
        }
    if (uvgen_sort_edges(e, n) != 0) goto err;
    for (int pass = 0; pass < 2; pass++) {
        if (pass == 1) {
            for (uint32_t t = 0; t < m->n_triangles; t++) start[t + 1] += start[t];
            list = malloc(((size_t)start[m->n_triangles] + 1) * sizeof *list);
            if (!list) goto err;
        }
        uint32_t *fill = NULL;
        if (pass == 1) {
            fill = malloc(((size_t)m->n_triangles + 1) * sizeof *fill);
            if (!fill) goto err;
            memcpy(fill, start, ((size_t)m->n_triangles + 1) * sizeof *fill);
        }
        for (size_t i = 0; i < n;) {
            size_t j = i + 1;
            while (j < n && e[j].key == e[i].key) j++;
            size_t k = j - i;
            for (size_t a = i; a < j; a++)
                for (size_t b = i; b < j; b++) {
                    if (a == b || e[a].tri == e[b].tri) continue;
                    if (k > 16 && b != a + 1 && a != b + 1) continue;
                    if (pass == 0) start[e[a].tri + 1]++;
                    else list[fill[e[a].tri]++] = e[b].tri;
                }
            i = j;
        }
        free(fill);
    }
    free(e);
    *adj_start = start;
    *adj = list;
    return 0;
err:
    free(e);
    free(start);
    free(list);
    return -1;
}

/* ---- projection ---------------------------------------------------------------------- */

typedef struct {
    double x, y;
} uvgen_pt;

static int uvgen_pt_cmp(const void *pa, const void *pb) {
    const uvgen_pt *a = pa, *b = pb;
    if (a->x != b->x) return a->x < b->x ? -1 : 1;
    if (a->y != b->y) return a->y < b->y ? -1 : 1;
    return 0;
}

static double uvgen_orient(uvgen_pt o, uvgen_pt a, uvgen_pt b) {
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

/* Andrew's monotone chain; pts sorted in place; hull written to out (CCW), returns size. */
static size_t uvgen_hull(uvgen_pt *pts, size_t n, uvgen_pt *out) {
    qsort(pts, n, sizeof *pts, uvgen_pt_cmp);
    if (n < 3) {
        for (size_t i = 0; i < n; i++) out[i] = pts[i];
        return n;
    }
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        while (k >= 2 && uvgen_orient(out[k - 2], out[k - 1], pts[i]) <= 0) k--;
        out[k++] = pts[i];
    }
    for (size_t i = n - 1, lo = k + 1; i-- > 0;) {
        while (k >= lo && uvgen_orient(out[k - 2], out[k - 1], pts[i]) <= 0) k--;
        out[k++] = pts[i];
    }
    return k > 1 ? k - 1 : k;
}

typedef struct {
    const lc_mesh *m;
    const uint32_t *weld; /* welded vertex ids */
    const double *tri_n;  /* unit normal per triangle (0 for degenerate) */
    const uint8_t *degen; /* degenerate in 3D */
    uint32_t *order;      /* triangles, each chart a contiguous range */
    double *cu, *cv;      /* corner coordinates per order position */
    double cos_flip;
    int threads; /* parallel-for workers: lc_uv_params.threads */
} uvgen_ctx;

static void uvgen_basis(const double n[3], double t[3], double b[3]) {
    double s = copysign(1.0, n[2]);
    double a = -1.0 / (s + n[2]);
    double c = n[0] * n[1] * a;
    t[0] = 1.0 + s * n[0] * n[0] * a;
    t[1] = s * c;
    t[2] = -s * n[0];
    b[0] = c;
    b[1] = s + n[1] * n[1] * a;
    b[2] = -n[1];
}

static void uvgen_project_corners(const uvgen_ctx *cx, uvgen_chart *c, const double U[3], const double V[3]) {
    for (uint32_t i = c->start; i < c->start + c->count; i++) {
        const uint32_t *ix = cx->m->index + 3 * (size_t)cx->order[i];
        for (int k = 0; k < 3; k++) {
            double p[3];
            uvgen_load(cx->m, cx->weld[ix[k]], p);
            cx->cu[3 * (size_t)i + k] = uvgen_dot(p, U);
            cx->cv[3 * (size_t)i + k] = uvgen_dot(p, V);
        }
    }
}

/* Chooses the chart's projection frame and fills U, V, umin, vmin, w, h, au, av and the
 * corner coordinates. Returns -1 on allocation failure. Thread-safe per chart. */
static int uvgen_project(const uvgen_ctx *cx, uvgen_chart *c) {
    const lc_mesh *m = cx->m;
    double N[3] = {0, 0, 0};
    for (uint32_t i = c->start; i < c->start + c->count; i++) {
        double cr[3];
        uvgen_tri_cross(m, cx->order[i], cr, NULL);
        if (cx->degen[cx->order[i]]) continue;
        for (int k = 0; k < 3; k++) N[k] += cr[k];
    }
    int ok = !c->fixed && uvgen_normalize(N);
    /* The area-weighted normal projects with least distortion, but may be up to twice the
     * chart angle away from some triangle; fall back to the seed normal (within the chart
     * angle of every triangle, < 90 degrees) rather than risk a flipped triangle. */
    for (uint32_t i = c->start; ok && i < c->start + c->count; i++) {
        uint32_t t = cx->order[i];
        if (!cx->degen[t] && uvgen_dot(cx->tri_n + 3 * (size_t)t, N) < cx->cos_flip) ok = 0;
    }
    if (!ok) memcpy(N, c->ref, sizeof N);
    double T[3], B[3];
    uvgen_basis(N, T, B);
    uvgen_project_corners(cx, c, T, B);

    /* Minimum-area bounding rectangle: one side is collinear with a hull edge. Hull input is
     * deduplicated by welded vertex (a small hash set) so the sort sees each point once. */
    size_t nc = 3 * (size_t)c->count, cap = 16;
    while (cap < 2 * nc) cap <<= 1;
    uint32_t *set = malloc(cap * sizeof *set);
    uvgen_pt *pts = malloc(nc * sizeof *pts), *hull = malloc((2 * nc + 2) * sizeof *hull);
    if (!set || !pts || !hull) {
        free(set);
        free(pts);
        free(hull);
        return -1;
    }
    memset(set, 0xFF, cap * sizeof *set);
    size_t np = 0;
    for (size_t i = 0; i < nc; i++) {
        uint32_t wv = cx->weld[cx->m->index[3 * (size_t)cx->order[c->start + i / 3] + i % 3]];
        size_t h = (size_t)(wv * 0x9E3779B1u) & (cap - 1);
        while (set[h] != LC_NONE && set[h] != wv) h = (h + 1) & (cap - 1);
        if (set[h] == wv) continue;
        set[h] = wv;
        pts[np++] = (uvgen_pt){cx->cu[3 * (size_t)c->start + i], cx->cv[3 * (size_t)c->start + i]};
    }
    free(set);
    size_t nh = uvgen_hull(pts, np, hull);
    double best_area = INFINITY, ex = 1, ey = 0, bw = 0, bh = 0;
    size_t step = nh > 256 ? nh / 256 : 1; /* bounded cost on huge hulls */
    for (size_t i = 0; i < nh; i += step) {
        uvgen_pt a = hull[i], b = hull[(i + 1) % nh];
        double dx = b.x - a.x, dy = b.y - a.y, l = sqrt(dx * dx + dy * dy);
        if (!(l > 0)) continue;
        dx /= l;
        dy /= l;
        double u0 = INFINITY, u1 = -INFINITY, v0 = INFINITY, v1 = -INFINITY;
        for (size_t j = 0; j < nh; j++) {
            double u = hull[j].x * dx + hull[j].y * dy, v = hull[j].y * dx - hull[j].x * dy;
            u0 = uvgen_min(u0, u);
            u1 = uvgen_max(u1, u);
            v0 = uvgen_min(v0, v);
            v1 = uvgen_max(v1, v);
        }
        double area = (u1 - u0) * (v1 - v0);
        if (area < best_area * (1 - 1e-9)) {
            best_area = area;
            ex = dx;
            ey = dy;
            bw = u1 - u0;
            bh = v1 - v0;
        }
    }
    free(pts);
    free(hull);
    /* U = rotation of T, B by the chosen direction (keeps handedness); landscape. */
    for (int k = 0; k < 3; k++) {
        c->U[k] = ex * T[k] + ey * B[k];
        c->V[k] = -ey * T[k] + ex * B[k];
    }
    if (bh > bw) {
        for (int k = 0; k < 3; k++) {
            double u = c->U[k];
            c->U[k] = c->V[k];
            c->V[k] = -u;
        }
    }
    uvgen_project_corners(cx, c, c->U, c->V);
    double u0 = INFINITY, u1 = -INFINITY, v0 = INFINITY, v1 = -INFINITY;
    double best = -1;
    uint32_t big = c->start;
    for (uint32_t i = c->start; i < c->start + c->count; i++) {
        const double *u = cx->cu + 3 * (size_t)i, *v = cx->cv + 3 * (size_t)i;
        for (int k = 0; k < 3; k++) {
            u0 = fmin(u0, u[k]);
            u1 = fmax(u1, u[k]);
            v0 = fmin(v0, v[k]);
            v1 = fmax(v1, v[k]);
        }
        double a = (u[1] - u[0]) * (v[2] - v[0]) - (v[1] - v[0]) * (u[2] - u[0]);
        if (a > best) {
            best = a;
            big = i;
        }
    }
    c->umin = u0;
    c->vmin = v0;
    c->w = u1 - u0;
    c->h = v1 - v0;
    const double *u = cx->cu + 3 * (size_t)big, *v = cx->cv + 3 * (size_t)big;
    double l0 = hypot(u[1] - u[2], v[1] - v[2]), l1 = hypot(u[2] - u[0], v[2] - v[0]),
           l2 = hypot(u[0] - u[1], v[0] - v[1]), ls = l0 + l1 + l2;
    if (ls > 0) {
        c->au = (l0 * u[0] + l1 * u[1] + l2 * u[2]) / ls - u0;
        c->av = (l0 * v[0] + l1 * v[1] + l2 * v[2]) / ls - v0;
    } else {
        c->au = u[0] - u0;
        c->av = v[0] - v0;
    }
    return 0;
}

/* ---- overlap ------------------------------------------------------------------------- */

/* 1 when triangles i and j (order positions, both CCW) share interior area beyond eps. */
static int uvgen_tri_overlap(const uvgen_ctx *cx, uint32_t i, uint32_t j, double eps) {
    const double *U[2] = {cx->cu + 3 * (size_t)i, cx->cu + 3 * (size_t)j};
    const double *V[2] = {cx->cv + 3 * (size_t)i, cx->cv + 3 * (size_t)j};
    for (int s = 0; s < 2; s++) {
        const double *au = U[s], *av = V[s], *bu = U[1 - s], *bv = V[1 - s];
        for (int k = 0; k < 3; k++) {
            double px = au[k], py = av[k], dx = au[(k + 1) % 3] - px, dy = av[(k + 1) % 3] - py;
            double l = sqrt(dx * dx + dy * dy);
            if (!(l > 0)) continue;
            double mx = -INFINITY;
            for (int q = 0; q < 3; q++) mx = uvgen_max(mx, dx * (bv[q] - py) - dy * (bu[q] - px));
            if (mx <= eps * l) return 0; /* separating axis */
        }
    }
    return 1;
}

/* Returns 1 when the chart overlaps itself or has a flipped triangle, 0 when clean, -1 on
 * allocation failure. Candidate pairs come from a uniform grid over the chart. */
static int uvgen_chart_overlaps(const uvgen_ctx *cx, const uvgen_chart *c) {
    if (c->count < 2) return 0;
    double ext = fmax(c->w, c->h);
    if (!(ext > 0)) return 0;
    double eps = 1e-9 * ext, area_eps = 1e-12 * ext * ext;
    /* flips */
    for (uint32_t i = c->start; i < c->start + c->count; i++) {
        const double *u = cx->cu + 3 * (size_t)i, *v = cx->cv + 3 * (size_t)i;
        double a = (u[1] - u[0]) * (v[2] - v[0]) - (v[1] - v[0]) * (u[2] - u[0]);
        if (a < -area_eps && !cx->degen[cx->order[i]]) return 1;
    }
    double cell = sqrt(fmax(c->w * c->h, ext * ext * 1e-6) / c->count);
    uint32_t gx = (uint32_t)fmin(fmax(ceil(c->w / cell), 1), 1024),
             gy = (uint32_t)fmin(fmax(ceil(c->h / cell), 1), 1024);
    double sx = gx / fmax(c->w, 1e-300), sy = gy / fmax(c->h, 1e-300);
    size_t ncell = (size_t)gx * gy;
    uint32_t *start = calloc(ncell + 1, sizeof *start), *items = NULL;
    uint32_t *box = malloc(4 * (size_t)c->count * sizeof *box);
    double *rb = malloc(4 * (size_t)c->count * sizeof *rb); /* real boxes, for a cheap reject */
    int result = -1;
    if (!start || !box || !rb) goto err;
    for (uint32_t i = 0; i < c->count; i++) {
        const double *u = cx->cu + 3 * (size_t)(c->start + i), *v = cx->cv + 3 * (size_t)(c->start + i);
        double a = (u[1] - u[0]) * (v[2] - v[0]) - (v[1] - v[0]) * (u[2] - u[0]);
        if (a <= area_eps) { /* degenerate: covers no texel centre */
            box[4 * i] = 1;
            box[4 * i + 2] = 0;
            continue;
        }
        double lo_u = uvgen_min(u[0], uvgen_min(u[1], u[2])) - c->umin,
               hi_u = uvgen_max(u[0], uvgen_max(u[1], u[2])) - c->umin;
        double lo_v = uvgen_min(v[0], uvgen_min(v[1], v[2])) - c->vmin,
               hi_v = uvgen_max(v[0], uvgen_max(v[1], v[2])) - c->vmin;
        rb[4 * i] = lo_u;
        rb[4 * i + 1] = lo_v;
        rb[4 * i + 2] = hi_u;
        rb[4 * i + 3] = hi_v;
        uint32_t x0 = (uint32_t)fmin(fmax(floor(lo_u * sx), 0), gx - 1),
                 x1 = (uint32_t)fmin(fmax(floor(hi_u * sx), 0), gx - 1);
        uint32_t y0 = (uint32_t)fmin(fmax(floor(lo_v * sy), 0), gy - 1),
                 y1 = (uint32_t)fmin(fmax(floor(hi_v * sy), 0), gy - 1);
        box[4 * i] = x0;
        box[4 * i + 1] = y0;
        box[4 * i + 2] = x1;
        box[4 * i + 3] = y1;
        for (uint32_t y = y0; y <= y1; y++)
            for (uint32_t x = x0; x <= x1; x++) start[(size_t)y * gx + x + 1]++;
    }
    for (size_t k = 0; k < ncell; k++) start[k + 1] += start[k];
    items = malloc(((size_t)start[ncell] + 1) * sizeof *items);
    if (!items) goto err;
    for (uint32_t i = 0; i < c->count; i++) {
        if (box[4 * i] > box[4 * i + 2]) continue;
        for (uint32_t y = box[4 * i + 1]; y <= box[4 * i + 3]; y++)
            for (uint32_t x = box[4 * i]; x <= box[4 * i + 2]; x++) items[start[(size_t)y * gx + x]++] = i;
    }
    for (size_t k = ncell; k > 0; k--) start[k] = start[k - 1];
    start[0] = 0;
    result = 0;
    for (uint32_t y = 0; y < gy && !result; y++)
        for (uint32_t x = 0; x < gx && !result; x++) {
            size_t cidx = (size_t)y * gx + x;
            for (uint32_t a = start[cidx]; a < start[cidx + 1] && !result; a++)
                for (uint32_t b = a + 1; b < start[cidx + 1]; b++) {
                    uint32_t i = items[a], j = items[b];
                    /* test each pair once: in the cell holding the min corner of their boxes' overlap */
                    uint32_t ox = box[4 * i] > box[4 * j] ? box[4 * i] : box[4 * j];
                    uint32_t oy = box[4 * i + 1] > box[4 * j + 1] ? box[4 * i + 1] : box[4 * j + 1];
                    if (ox != x || oy != y) continue;
                    if (rb[4 * i] >= rb[4 * j + 2] - eps || rb[4 * j] >= rb[4 * i + 2] - eps ||
                        rb[4 * i + 1] >= rb[4 * j + 3] - eps || rb[4 * j + 1] >= rb[4 * i + 3] - eps)
                        continue; /* boxes at most touch: no interior overlap */
                    if (uvgen_tri_overlap(cx, c->start + i, c->start + j, eps)) {
                        result = 1;
                        break;
                    }
                }
        }
err:
    free(start);
    free(items);
    free(box);
    free(rb);
    return result;
}

typedef struct {
    const uvgen_ctx *cx;
    uvgen_chart *charts;
    int8_t *verdict; /* 1 overlap (split it), 0 clean, -1 out of memory */
} uvgen_round;

static void uvgen_check_charts(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    uvgen_round *r = ctx;
    for (size_t i = begin; i < end; i++) {
        if (uvgen_project(r->cx, &r->charts[i]) != 0) {
            r->verdict[i] = -1;
            continue;
        }
        r->verdict[i] = (int8_t)uvgen_chart_overlaps(r->cx, &r->charts[i]);
    }
}

/* ---- splitting ----------------------------------------------------------------------- */

typedef struct {
    double key;
    uint32_t tri;
} uvgen_keyed;

static int uvgen_keyed_cmp(const void *pa, const void *pb) {
    const uvgen_keyed *a = pa, *b = pb;
    if (a->key != b->key) return a->key < b->key ? -1 : 1;
    return (a->tri > b->tri) - (a->tri < b->tri);
}

/* Splits chart c (by value: the array may move) into halves along its longest 3D axis, then
 * into connected components of each half; appends them to *charts. */
static int uvgen_split(uvgen_ctx *cx, uvgen_chart c, const uint32_t *adj_start, const uint32_t *adj, uint32_t *mark,
                       uint32_t *stamp, uvgen_chart **charts, uint32_t *n_charts, uint32_t *cap_charts) {
    uvgen_keyed *k = malloc((size_t)c.count * sizeof *k);
    uint32_t *tmp = malloc((size_t)c.count * sizeof *tmp);
    int rc = -1;
    if (!k || !tmp) goto err;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < c.count; i++) {
        const uint32_t *ix = cx->m->index + 3 * (size_t)cx->order[c.start + i];
        for (int a = 0; a < 3; a++) {
            double s = 0;
            for (int q = 0; q < 3; q++) s += cx->m->position[3 * (size_t)ix[q] + a];
            lo[a] = fmin(lo[a], s / 3);
            hi[a] = fmax(hi[a], s / 3);
        }
    }
    int axis = 0;
    for (int a = 1; a < 3; a++)
        if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    for (uint32_t i = 0; i < c.count; i++) {
        uint32_t t = cx->order[c.start + i];
        const uint32_t *ix = cx->m->index + 3 * (size_t)t;
        double s = 0;
        for (int q = 0; q < 3; q++) s += cx->m->position[3 * (size_t)ix[q] + axis];
        k[i] = (uvgen_keyed){s, t};
    }
    qsort(k, c.count, sizeof *k, uvgen_keyed_cmp);
    uint32_t half = c.count / 2, out = 0;
    for (int side = 0; side < 2; side++) {
        uint32_t b = side ? half : 0, e = side ? c.count : half;
        uint32_t in_stamp = ++*stamp, done_stamp = ++*stamp;
        for (uint32_t i = b; i < e; i++) mark[k[i].tri] = in_stamp;
        for (uint32_t i = b; i < e; i++) {
            if (mark[k[i].tri] != in_stamp) continue;
            uint32_t first = out;
            mark[k[i].tri] = done_stamp;
            tmp[out++] = k[i].tri;
            for (uint32_t q = first; q < out; q++) {
                uint32_t t = tmp[q];
                for (uint32_t a = adj_start[t]; a < adj_start[t + 1]; a++)
                    if (mark[adj[a]] == in_stamp) {
                        mark[adj[a]] = done_stamp;
                        tmp[out++] = adj[a];
                    }
            }
            if (*n_charts == *cap_charts) {
                uint32_t nc = *cap_charts * 2;
                uvgen_chart *p = realloc(*charts, (size_t)nc * sizeof *p);
                if (!p) goto err;
                *charts = p;
                *cap_charts = nc;
            }
            uvgen_chart sub = {0};
            sub.start = c.start + first;
            sub.count = out - first;
            memcpy(sub.ref, c.ref, sizeof sub.ref);
            sub.fixed = c.fixed;
            (*charts)[(*n_charts)++] = sub;
        }
    }
    memcpy(cx->order + c.start, tmp, (size_t)c.count * sizeof *tmp);
    rc = 0;
err:
    free(k);
    free(tmp);
    return rc;
}

/* Projects charts[*n_charts..] rounds: all pending charts are checked in parallel (each
 * touches only its own range), then the overlapping ones are split serially and their pieces
 * form the next round. Dead charts are dropped at the end. -1 on out of memory. */
static int uvgen_resolve(uvgen_ctx *cx, uvgen_chart **charts, uint32_t *n_charts, uint32_t *cap_charts,
                         const uint32_t *adj_start, const uint32_t *adj, uint32_t *mark, uint32_t *stamp) {
    int8_t *verdict = NULL;
    int rc = -1;
    for (uint32_t round_begin = 0; round_begin < *n_charts;) {
        uint32_t round_end = *n_charts;
        int8_t *v = realloc(verdict, round_end - round_begin);
        if (!v) goto err;
        verdict = v;
        uvgen_round job = {cx, *charts + round_begin, verdict};
        lc_parallel_for(cx->threads, round_end - round_begin, 4, uvgen_check_charts, &job);
        for (uint32_t i = round_begin; i < round_end; i++) {
            int ov = verdict[i - round_begin];
            if (ov < 0) goto err;
            if (ov) {
                (*charts)[i].dead = 1;
                if (uvgen_split(cx, (*charts)[i], adj_start, adj, mark, stamp, charts, n_charts, cap_charts) != 0)
                    goto err;
            }
        }
        round_begin = round_end;
    }
    uint32_t k = 0;
    for (uint32_t i = 0; i < *n_charts; i++)
        if (!(*charts)[i].dead) (*charts)[k++] = (*charts)[i];
    *n_charts = k;
    rc = 0;
err:
    free(verdict);
    return rc;
}

/* ---- merging ------------------------------------------------------------------------- */

/* Footprint + padding texels a chart of extent w x h (metres) costs at density d. */
static double uvgen_cost_texels(double w, double h, double d, uint32_t pad) {
    return (w * d + 1 + pad) * (h * d + 1 + pad);
}

/* Density the atlas would get for these charts (each w[i] x h[i] metres), assuming rects
 * fill ~80% of it: solves sum((w d + 1 + p)(h d + 1 + p)) = 0.8 W^2. Never below half the
 * density of the whole area packed perfectly: with too many charts the estimate collapses
 * (merging fixes that) and would let merges squash large surfaces. */
static double uvgen_density_estimate(const double *w, const double *h, const uint8_t *alive, uint32_t n, uint32_t W,
                                     uint32_t pad, double total_area) {
    double floor_d = 0.5 * W / sqrt(total_area);
    double a = 0, b = 0, c = -0.8 * W * (double)W, k = 1.0 + pad;
    for (uint32_t i = 0; i < n; i++) {
        if (!alive[i]) continue;
        a += w[i] * h[i];
        b += (w[i] + h[i]) * k;
        c += k * k;
    }
    if (c >= 0 || !(a > 0)) return floor_d;
    return fmax(floor_d, (-b + sqrt(b * b - 4 * a * c)) / (2 * a));
}

typedef struct {
    double cost;
    uint32_t chart;
} uvgen_cand;

static int uvgen_cand_cmp(const void *pa, const void *pb) {
    const uvgen_cand *a = pa, *b = pb;
    if (a->cost != b->cost) return a->cost < b->cost ? -1 : 1;
    return (a->chart > b->chart) - (a->chart < b->chart);
}

typedef struct {
    uint32_t *head, *tail, *next, *chart_of, *slot, *slot_stamp, *area_n; /* area_n: triangles */
    double *area, *nsum, *pn, *w, *h, *tri_a;                             /* pn: projection normal of merged charts */
    double *beyond;        /* area beyond the chart angle of its normal */
    uint64_t work, budget; /* triangles projected by trials, and the cap */
    uint8_t *alive, *merged;
    uvgen_keyed *sorted; /* scratch: live charts by area, per pass */
    uvgen_cand *cand;    /* scratch: one chart's neighbours */
    uint32_t stamp;      /* slot_stamp of the chart being scored */
} uvgen_merge_state;

/* Tries to merge chart b into chart a (a keeps its id). The merged chart projects onto the
 * area-weighted normal of the two, or failing that onto the bisector of their normals (a
 * small box corner, a bevel), with every triangle within UVGEN_MERGE_MAX_DEG of it (no flips
 * and no overlap, both checked exactly); it must cost no more atlas texels than the two apart
 * at density d, and the area it newly puts beyond the chart angle may cover only a few
 * texels (a tiny bevel may be squashed, a wall may not). Uses cx's order/cu/cv as scratch. 1 merged, 0 not,
 * -1 out of memory. */
static int uvgen_try_merge(uvgen_ctx *cx, uvgen_merge_state *st, uint32_t a, uint32_t b, double d, uint32_t pad,
                           double cos_a) {
    double cos_max = cos(UVGEN_MERGE_MAX_DEG * M_PI / 180.0);
    double na[3], nb[3], N[2][3];
    memcpy(na, st->nsum + 3 * (size_t)a, sizeof na);
    memcpy(nb, st->nsum + 3 * (size_t)b, sizeof nb);
    if (!uvgen_normalize(na) || !uvgen_normalize(nb)) return 0;
    for (int k = 0; k < 3; k++) {
        N[0][k] = st->nsum[3 * (size_t)a + k] + st->nsum[3 * (size_t)b + k];
        N[1][k] = na[k] + nb[k];
    }
    int n_try = uvgen_normalize(N[0]) ? 1 : 0;
    if (uvgen_normalize(N[1]) && (!n_try || uvgen_dot(N[0], N[1]) < 1 - 1e-6)) {
        if (!n_try) memcpy(N[0], N[1], sizeof N[0]);
        n_try++;
    }
    /* Each trial re-projects the union: a huge chart with countless tiny neighbours would be
     * quadratic, so past a work budget only small unions are tried. */
    if (st->work > st->budget && st->area_n[a] + st->area_n[b] > UVGEN_MERGE_SMALL_UNION) return 0;
    uint32_t n = 0;
    for (int side = 0; side < 2; side++)
        for (uint32_t t = st->head[side ? b : a]; t != LC_NONE; t = st->next[t]) cx->order[n++] = t;
    st->work += n;
    for (int k = 0; k < n_try; k++) {
        double beyond = 0;
        int ok = 1;
        for (uint32_t i = 0; i < n && ok; i++) {
            uint32_t t = cx->order[i];
            if (cx->degen[t]) continue;
            double c = uvgen_dot(cx->tri_n + 3 * (size_t)t, N[k]);
            if (c < cos_max) ok = 0;
            if (c < cos_a) beyond += st->tri_a[t];
        }
        /* budget per merge: what this merge newly squashes (each merge saves about one
         * chart's padding overhead) */
        if (!ok || (beyond - st->beyond[a] - st->beyond[b]) * d * d > UVGEN_MERGE_SQUASH * (1 + pad) * (1 + pad))
            continue;
        uvgen_chart c = {0};
        c.count = n;
        c.fixed = 1;
        memcpy(c.ref, N[k], sizeof c.ref);
        if (uvgen_project(cx, &c) != 0) return -1;
        if (uvgen_cost_texels(c.w, c.h, d, pad) >
            uvgen_cost_texels(st->w[a], st->h[a], d, pad) + uvgen_cost_texels(st->w[b], st->h[b], d, pad))
            continue;
        int ov = uvgen_chart_overlaps(cx, &c);
        if (ov < 0) return -1;
        if (ov) continue;
        for (uint32_t t = st->head[b]; t != LC_NONE; t = st->next[t]) st->chart_of[t] = a;
        st->next[st->tail[a]] = st->head[b];
        st->tail[a] = st->tail[b];
        st->area[a] += st->area[b];
        st->area_n[a] += st->area_n[b];
        st->beyond[a] = beyond;
        for (int q = 0; q < 3; q++) st->nsum[3 * (size_t)a + q] += st->nsum[3 * (size_t)b + q];
        memcpy(st->pn + 3 * (size_t)a, N[k], 3 * sizeof(double));
        st->merged[a] = 1;
        st->w[a] = c.w;
        st->h[a] = c.h;
        st->alive[b] = 0;
        return 1;
    }
    return 0;
}

/* Allocates the merge state for n charts over T triangles (the arrays uvgen_merge_init does
 * not fill start zeroed). -1 out of memory, with whatever was allocated left for the free. */
static int uvgen_merge_state_alloc(uvgen_merge_state *st, uint32_t n, uint32_t T) {
    st->head = malloc((size_t)n * sizeof *st->head);
    st->tail = malloc((size_t)n * sizeof *st->tail);
    st->pn = malloc(3 * (size_t)n * sizeof *st->pn);
    st->area_n = malloc((size_t)n * sizeof *st->area_n);
    st->budget = 32 * (uint64_t)T + (1u << 20);
    st->beyond = calloc(n, sizeof *st->beyond);
    st->merged = calloc(n, 1);
    st->slot = malloc((size_t)n * sizeof *st->slot);
    st->slot_stamp = calloc(n, sizeof *st->slot_stamp);
    st->next = malloc((size_t)T * sizeof *st->next);
    st->chart_of = malloc((size_t)T * sizeof *st->chart_of);
    st->area = calloc(n, sizeof *st->area);
    st->nsum = calloc(3 * (size_t)n, sizeof *st->nsum);
    st->w = malloc((size_t)n * sizeof *st->w);
    st->h = malloc((size_t)n * sizeof *st->h);
    st->tri_a = malloc((size_t)T * sizeof *st->tri_a);
    st->alive = malloc(n);
    st->sorted = malloc((size_t)n * sizeof *st->sorted);
    st->cand = malloc((size_t)n * sizeof *st->cand);
    if (!st->head || !st->tail || !st->pn || !st->area_n || !st->beyond || !st->merged || !st->slot ||
        !st->slot_stamp || !st->next || !st->chart_of || !st->area || !st->nsum || !st->w || !st->h || !st->tri_a ||
        !st->alive || !st->sorted || !st->cand)
        return -1;
    return 0;
}

static void uvgen_merge_state_free(uvgen_merge_state *st) {
    free(st->head);
    free(st->tail);
    free(st->pn);
    free(st->area_n);
    free(st->beyond);
    free(st->merged);
    free(st->slot);
    free(st->slot_stamp);
    free(st->next);
    free(st->chart_of);
    free(st->area);
    free(st->nsum);
    free(st->w);
    free(st->h);
    free(st->tri_a);
    free(st->alive);
    free(st->sorted);
    free(st->cand);
}

/* The state of the n grown charts: each chart's triangles as a linked list, its area, normal
 * sum, extent and the area beyond the chart angle of its normal. Returns the total area. */
static double uvgen_merge_init(const uvgen_ctx *cx, uvgen_merge_state *st, const uvgen_chart *charts, uint32_t n,
                               double cos_a) {
    const lc_mesh *m = cx->m;
    for (uint32_t i = 0; i < n; i++) {
        const uvgen_chart *c = &charts[i];
        st->alive[i] = 1;
        st->w[i] = c->w;
        st->area_n[i] = c->count;
        st->h[i] = c->h;
        st->head[i] = cx->order[c->start];
        st->tail[i] = cx->order[c->start + c->count - 1];
        for (uint32_t q = c->start; q < c->start + c->count; q++) {
            uint32_t t = cx->order[q];
            double cr[3];
            uvgen_tri_cross(m, t, cr, NULL);
            st->tri_a[t] = 0.5 * sqrt(uvgen_dot(cr, cr));
            st->chart_of[t] = i;
            st->next[t] = q + 1 < c->start + c->count ? cx->order[q + 1] : LC_NONE;
            st->area[i] += st->tri_a[t];
            if (!cx->degen[t])
                for (int k = 0; k < 3; k++) st->nsum[3 * (size_t)i + k] += cr[k];
        }
    }
    double total_area = 0;
    for (uint32_t i = 0; i < n; i++) {
        total_area += st->area[i];
        double N[3];
        memcpy(N, st->nsum + 3 * (size_t)i, sizeof N);
        if (!uvgen_normalize(N)) continue;
        for (uint32_t t = st->head[i]; t != LC_NONE; t = st->next[t])
            if (!cx->degen[t] && uvgen_dot(cx->tri_n + 3 * (size_t)t, N) < cos_a) st->beyond[i] += st->tri_a[t];
    }
    return total_area;
}

/* Chart s's edge neighbours into st->cand, cheapest first: cost = normal deviation, then how
 * little of s's boundary each shares. Returns how many. */
static uint32_t uvgen_merge_candidates(const uvgen_ctx *cx, uvgen_merge_state *st, uint32_t s,
                                       const uint32_t *adj_start, const uint32_t *adj) {
    const lc_mesh *m = cx->m;
    uvgen_cand *cand = st->cand;
    /* neighbours with the length of boundary shared with each */
    uint32_t nc = 0;
    double shared_all = 0;
    st->stamp++;
    for (uint32_t t = st->head[s]; t != LC_NONE; t = st->next[t]) {
        const uint32_t *it = m->index + 3 * (size_t)t;
        uint32_t wt[3] = {cx->weld[it[0]], cx->weld[it[1]], cx->weld[it[2]]};
        for (uint32_t e = adj_start[t]; e < adj_start[t + 1]; e++) {
            uint32_t nb = adj[e], o = st->chart_of[nb];
            if (o == s) continue;
            const uint32_t *in = m->index + 3 * (size_t)nb;
            uint32_t common[2], k = 0;
            for (int x = 0; x < 3 && k < 2; x++)
                for (int y = 0; y < 3; y++)
                    if (wt[x] == cx->weld[in[y]]) {
                        common[k++] = wt[x];
                        break;
                    }
            double len = 0;
            if (k == 2) {
                double p0[3], p1[3];
                uvgen_load(m, common[0], p0);
                uvgen_load(m, common[1], p1);
                len = sqrt((p0[0] - p1[0]) * (p0[0] - p1[0]) + (p0[1] - p1[1]) * (p0[1] - p1[1]) +
                           (p0[2] - p1[2]) * (p0[2] - p1[2]));
            }
            if (st->slot_stamp[o] != st->stamp) {
                st->slot_stamp[o] = st->stamp;
                st->slot[o] = nc;
                cand[nc++] = (uvgen_cand){0, o};
            }
            cand[st->slot[o]].cost += len;
            shared_all += len;
        }
    }
    double ns_[3];
    memcpy(ns_, st->nsum + 3 * (size_t)s, sizeof ns_);
    int ok_s = uvgen_normalize(ns_);
    for (uint32_t i = 0; i < nc; i++) {
        double no[3], dev = 1;
        memcpy(no, st->nsum + 3 * (size_t)cand[i].chart, sizeof no);
        if (ok_s && uvgen_normalize(no)) dev = 1 - uvgen_dot(ns_, no);
        double frac = shared_all > 0 ? cand[i].cost / shared_all : 0;
        cand[i].cost = dev + 0.5 * (1 - frac);
    }
    qsort(cand, nc, sizeof *cand, uvgen_cand_cmp);
    return nc;
}

/* One merge pass at density dd over the ns live charts, smallest first, each trying up to
 * UVGEN_MERGE_TRIES neighbours. Returns how many merged, or -1 out of memory. */
static int64_t uvgen_merge_pass(uvgen_ctx *cx, uvgen_merge_state *st, uint32_t ns, const uint32_t *adj_start,
                                const uint32_t *adj, double dd, uint32_t pad, double cos_a) {
    uint32_t merged = 0;
    for (uint32_t si = 0; si < ns; si++) {
        uint32_t s = st->sorted[si].tri; /* a chart id here */
        if (!st->alive[s]) continue;
        uint32_t nc = uvgen_merge_candidates(cx, st, s, adj_start, adj);
        for (uint32_t i = 0, tries = 0; i < nc && tries < UVGEN_MERGE_TRIES && st->alive[s]; i++) {
            uint32_t o = st->cand[i].chart;
            if (!st->alive[o]) continue;
            tries++;
            /* the larger keeps its id (relabelling the smaller stays cheap) */
            uint32_t keep = st->area[o] > st->area[s] || (st->area[o] == st->area[s] && o < s) ? o : s;
            int r = uvgen_try_merge(cx, st, keep, keep == o ? s : o, dd, pad, cos_a);
            if (r < 0) return -1;
            merged += (uint32_t)r;
        }
    }
    return merged;
}

/* Rewrites cx->order and *charts with the alive charts of the n as contiguous ranges. -1
 * out of memory. */
static int uvgen_merge_collect(uvgen_ctx *cx, const uvgen_merge_state *st, uvgen_chart **charts, uint32_t *n_charts,
                               uint32_t n, uint32_t alive) {
    uvgen_chart *out = malloc((size_t)(alive ? alive : 1) * sizeof *out);
    if (!out) return -1;
    uint32_t k = 0, pos = 0;
    for (uint32_t i = 0; i < n; i++) {
        if (!st->alive[i]) continue;
        uvgen_chart c = {0};
        c.start = pos;
        for (uint32_t t = st->head[i]; t != LC_NONE; t = st->next[t]) cx->order[pos++] = t;
        c.count = pos - c.start;
        if (st->merged[i]) {
            memcpy(c.ref, st->pn + 3 * (size_t)i, sizeof c.ref);
            c.fixed = 1;
        } else { /* unmerged: its own reference (the chart angle bound holds) */
            memcpy(c.ref, (*charts)[i].ref, sizeof c.ref);
            c.fixed = (*charts)[i].fixed;
        }
        out[k++] = c;
    }
    free(*charts);
    *charts = out;
    *n_charts = k;
    return 0;
}

/* Merges small charts into edge-adjacent ones, smallest first, each trying its neighbours by
 * cost (normal deviation, then how little of its boundary they share). Rewrites cx->order
 * and *charts (n_charts in and out) with the merged charts as contiguous ranges; they still
 * need projecting. d: the density (0: estimate it for atlas W). */
static int uvgen_merge(uvgen_ctx *cx, uvgen_chart **charts, uint32_t *n_charts, const uint32_t *adj_start,
                       const uint32_t *adj, double d, uint32_t W, uint32_t pad, double cos_a) {
    const uint32_t T = cx->m->n_triangles, n = *n_charts;
    uvgen_merge_state st = {0};
    int rc = -1;
    if (uvgen_merge_state_alloc(&st, n, T) != 0) goto err;
    double total_area = uvgen_merge_init(cx, &st, *charts, n, cos_a);
    uint32_t alive = n;
    for (int pass = 0; pass < UVGEN_MERGE_PASSES; pass++) {
        double dd = d > 0 ? d : uvgen_density_estimate(st.w, st.h, st.alive, n, W, pad, total_area);
        uint32_t ns = 0;
        for (uint32_t i = 0; i < n; i++)
            if (st.alive[i]) st.sorted[ns++] = (uvgen_keyed){st.area[i], i};
        qsort(st.sorted, ns, sizeof *st.sorted, uvgen_keyed_cmp);
        int64_t merged = uvgen_merge_pass(cx, &st, ns, adj_start, adj, dd, pad, cos_a);
        if (merged < 0) goto err;
        alive -= (uint32_t)merged;
        lc_debug("uvgen", "merge pass %d at %.3g texels/m: %u of %u charts merged", pass, dd, (uint32_t)merged, ns);
        if (merged * 100 < ns) break; /* converged */
    }
    if (uvgen_merge_collect(cx, &st, charts, n_charts, n, alive) != 0) goto err;
    rc = 0;
err:
    uvgen_merge_state_free(&st);
    return rc;
}

/* ---- packing ------------------------------------------------------------------------- */

/* Footprint rect of chart c at density d (rotation already chosen). The anchor lands on a
 * texel centre; the min corner sits at (fx, fy) in [SLACK, 1 + SLACK) inside the rect. */
static void uvgen_footprint(uvgen_chart *c, double d) {
    double w = c->rot ? c->h : c->w, h = c->rot ? c->w : c->h;
    double au = c->rot ? c->h - c->av : c->au, av = c->rot ? c->au : c->av;
    double fx = 0.5 - au * d, fy = 0.5 - av * d;
    fx -= floor(fx);
    fy -= floor(fy);
    if (fx < UVGEN_SLACK) fx += 1;
    if (fy < UVGEN_SLACK) fy += 1;
    c->fx = fx;
    c->fy = fy;
    /* clamped: an absurd density must fail packing, not overflow the cast */
    double fw = floor(fx + w * d + UVGEN_SLACK) + 1, fh = floor(fy + h * d + UVGEN_SLACK) + 1;
    c->fw = fw > 1e9 ? 1000000000u : (uint32_t)fw;
    c->fh = fh > 1e9 ? 1000000000u : (uint32_t)fh;
}

static int uvgen_item_cmp(const void *pa, const void *pb) {
    const uvgen_item *a = pa, *b = pb;
    if (a->fh != b->fh) return a->fh > b->fh ? -1 : 1;
    if (a->fw != b->fw) return a->fw > b->fw ? -1 : 1;
    return (a->id > b->id) - (a->id < b->id);
}

typedef struct {
    uint32_t x, y, w; /* skyline segment: [x, x + w) is free from height y up */
} uvgen_seg;

/* Footprints at density d, rotated when too wide, sorted tallest first into items. 0, or
 * -1 when a chart is wider than W or taller than max_h with padding. */
static int uvgen_pack_items(uvgen_chart *ch, uint32_t n, uvgen_item *items, double d, uint32_t W, uint32_t max_h,
                            uint32_t pad, int allow_rot) {
    for (uint32_t i = 0; i < n; i++) {
        ch[i].rot = 0;
        uvgen_footprint(&ch[i], d);
        if (allow_rot && ch[i].fw + 2 * pad > W) { /* too wide: stand it up */
            ch[i].rot = 1;
            uvgen_footprint(&ch[i], d);
        }
        if ((uint64_t)ch[i].fw + 2 * pad > W || (uint64_t)ch[i].fh + 2 * pad > max_h) return -1;
        items[i] = (uvgen_item){ch[i].fw, ch[i].fh, i};
    }
    qsort(items, n, sizeof *items, uvgen_item_cmp);
    return 0;
}

/* Shelf placement of sorted items into width W; height used or UINT32_MAX past max_h. */
static uint32_t uvgen_shelf(uvgen_chart *ch, uint32_t n, const uvgen_item *items, uint32_t W, uint32_t max_h,
                            uint32_t pad) {
    uint64_t x = pad, y = pad, shelf = 0;
    for (uint32_t i = 0; i < n; i++) {
        uvgen_chart *c = &ch[items[i].id];
        uint64_t rw = (uint64_t)c->fw + pad, rh = (uint64_t)c->fh + pad;
        if (x + rw > W) {
            y += shelf;
            x = pad;
            shelf = 0;
        }
        if (y + rh > max_h) return UINT32_MAX;
        c->x = (uint32_t)x;
        c->y = (uint32_t)y;
        x += rw;
        if (rh > shelf) shelf = rh;
    }
    return (uint32_t)(y + shelf);
}

/* Skyline bottom-left placement of sorted items: each goes where its top ends lowest
 * (leftmost on ties), so short charts fill the steps beside tall ones instead of the space
 * above them on a shelf. sky: scratch for n + 2 segments. Height used or UINT32_MAX. */
static uint32_t uvgen_skyline(uvgen_chart *ch, uint32_t n, const uvgen_item *items, uvgen_seg *sky, uint32_t W,
                              uint32_t max_h, uint32_t pad) {
    uint32_t ns = 1, top = pad;
    sky[0] = (uvgen_seg){pad, pad, W - pad};
    for (uint32_t i = 0; i < n; i++) {
        uvgen_chart *c = &ch[items[i].id];
        uint32_t rw = c->fw + pad, rh = c->fh + pad; /* both fit: checked by uvgen_pack_items */
        uint32_t best = UINT32_MAX, best_y = UINT32_MAX;
        for (uint32_t s = 0; s < ns && sky[s].x + rw <= W; s++) {
            uint32_t y = 0, end = sky[s].x + rw;
            for (uint32_t k = s; k < ns && sky[k].x < end; k++) y = sky[k].y > y ? sky[k].y : y;
            if (y < best_y) {
                best_y = y;
                best = s;
            }
        }
        if (best == UINT32_MAX || (uint64_t)best_y + rh > max_h) return UINT32_MAX;
        uint32_t x = sky[best].x, end = x + rw;
        c->x = x;
        c->y = best_y;
        if (best_y + rh > top) top = best_y + rh;
        /* replace the covered segments by the new one; trim a partly covered last one */
        uint32_t k = best;
        while (k < ns && sky[k].x + sky[k].w <= end) k++;
        uvgen_seg tail = {0, 0, 0};
        int has_tail = k < ns && sky[k].x < end;
        if (has_tail) {
            tail = (uvgen_seg){end, sky[k].y, sky[k].x + sky[k].w - end};
            k++;
        }
        uvgen_seg repl[2] = {{x, best_y + rh, rw}, tail};
        uint32_t nr = has_tail ? 2 : 1;
        memmove(sky + best + nr, sky + k, (ns - k) * sizeof *sky);
        memcpy(sky + best, repl, nr * sizeof *sky);
        ns = ns - (k - best) + nr;
        /* merge equal-height neighbours around the new segment */
        uint32_t lo = best > 0 ? best - 1 : 0, hi = best + nr < ns ? best + nr : ns - 1;
        for (uint32_t j = hi; j > lo; j--)
            if (sky[j - 1].y == sky[j].y) {
                sky[j - 1].w += sky[j].w;
                memmove(sky + j, sky + j + 1, (ns - j - 1) * sizeof *sky);
                ns--;
            }
    }
    return top;
}

/* Packs at density d into width W: skyline and shelves both, keeping the lower (neither
 * wins everywhere: shelves suit a few similar charts). Rects are footprint + padding (the
 * border supplies the first padding). Returns the height used (incl. border padding), or
 * UINT32_MAX when a chart is wider than the atlas or the height passes max_h. Integer-only
 * placement, so deterministic. */
static uint32_t uvgen_pack(uvgen_chart *ch, uint32_t n, uvgen_item *items, uvgen_seg *sky, double d, uint32_t W,
                           uint32_t max_h, uint32_t pad, int allow_rot) {
    if (uvgen_pack_items(ch, n, items, d, W, max_h, pad, allow_rot) != 0) return UINT32_MAX;
    uint32_t hs = uvgen_shelf(ch, n, items, W, max_h, pad);
    uint32_t hk = uvgen_skyline(ch, n, items, sky, W, hs == UINT32_MAX ? max_h : hs, pad);
    if (hk != UINT32_MAX) return hk;
    return hs == UINT32_MAX ? UINT32_MAX : uvgen_shelf(ch, n, items, W, max_h, pad);
}

static uint32_t uvgen_round4(double v) {
    if (v < 4) v = 4;
    if (v > UVGEN_MAX_ATLAS + 4.0) v = UVGEN_MAX_ATLAS + 4.0;
    uint32_t u = (uint32_t)ceil(v);
    return (u + 3) & ~3u;
}

typedef struct {
    double spacing, texels;
} uvgen_spacing;

static int uvgen_spacing_cmp(const void *a, const void *b) {
    double x = ((const uvgen_spacing *)a)->spacing, y = ((const uvgen_spacing *)b)->spacing;
    return (x > y) - (x < y);
}

/* The value below which fraction q of the weight (texels) lies; sorts v. n >= 1. */
static double uvgen_weighted_quantile(uvgen_spacing *v, uint32_t n, double total, double q) {
    qsort(v, n, sizeof *v, uvgen_spacing_cmp);
    double acc = 0;
    uint32_t k = 0;
    for (; k + 1 < n && (acc += v[k].texels) < q * total; k++) {
    }
    return v[k].spacing;
}

/* Areas of a triangle in space (given its corners: the stretch scaling reads the welded
 * positions, uvgen_tri_cross the mesh's) and in a plane. */
static double uvgen_area3(const double p[3][3]) {
    double e1[3], e2[3], c[3];
    for (int a = 0; a < 3; a++) {
        e1[a] = p[1][a] - p[0][a];
        e2[a] = p[2][a] - p[0][a];
    }
    uvgen_cross(e1, e2, c);
    return 0.5 * sqrt(uvgen_dot(c, c));
}
static double uvgen_area2(const double x[3], const double y[3]) {
    return 0.5 * fabs((x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]));
}

/* ---- stretch compensation ---------------------------------------------------------------- */

/* A chart projected onto its plane loses area where its triangles tilt away from the plane
 * (up to the chart angle: 1/cos 45 = 1.41 at most), so its texels would lie farther apart on the
 * surface than the density says. Each chart is scaled by sqrt(world area / projected area) of
 * its tilted triangles: the ratio below which UVGEN_STRETCH_QUANTILE of its projected area lies
 * (at most UVGEN_STRETCH_MAX), so nearly every texel covers at most 1/d^2 of the surface. Sponza
 * at 2 texels/m: half the texels were more than 0.5 m apart before any scaling; with the chart's
 * average ratio Sibenik's p95 stayed at 0.555 m (its charts mix tilts). */
#define UVGEN_STRETCH_MAX 2.0
#define UVGEN_STRETCH_QUANTILE 0.90
static int uvgen_compensate_stretch(const uvgen_ctx *cx, uvgen_chart *fin, uint32_t n) {
    uint32_t most = 0;
    for (uint32_t i = 0; i < n; i++) most = fin[i].count > most ? fin[i].count : most;
    uvgen_spacing *tri = malloc(((size_t)most + 1) * sizeof *tri); /* spacing = area ratio here */
    if (!tri) return -1;
    for (uint32_t i = 0; i < n; i++) {
        uvgen_chart *c = &fin[i];
        double proj = 0;
        uint32_t m = 0;
        for (uint32_t q = c->start; q < c->start + c->count; q++) {
            double pa = uvgen_area2(cx->cu + 3 * (size_t)q, cx->cv + 3 * (size_t)q), p[3][3];
            for (int k = 0; k < 3; k++) uvgen_load(cx->m, cx->weld[cx->m->index[3 * (size_t)cx->order[q] + k]], p[k]);
            double wa = uvgen_area3(p);
            if (!(pa > 0) || !(wa > 0)) continue;
            tri[m].spacing = wa / pa;
            tri[m].texels = pa;
            proj += pa;
            m++;
        }
        if (!m || !(proj > 0)) continue;
        double ratio = uvgen_weighted_quantile(tri, m, proj, UVGEN_STRETCH_QUANTILE);
        if (!(ratio > 1)) continue;
        double sc = fmin(sqrt(ratio), UVGEN_STRETCH_MAX);
        for (int a = 0; a < 3; a++) {
            c->U[a] *= sc;
            c->V[a] *= sc;
        }
        c->umin *= sc;
        c->vmin *= sc;
        c->w *= sc;
        c->h *= sc;
        c->au *= sc;
        c->av *= sc;
        for (uint32_t q = 3 * c->start; q < 3 * (c->start + c->count); q++) {
            cx->cu[q] *= sc;
            cx->cv[q] *= sc;
        }
    }
    free(tri);
    return 0;
}

/* ---- conservative footprint (usage) ----------------------------------------------------- */

/* Marks texels whose closed square touches triangle (x[k], y[k]) (texel units) in bitmap.
 * Per edge, the square corner farthest inside is a fixed offset, so each texel costs three
 * linear evaluations. A tiny tolerance keeps touching squares in (conservative). */
static void uvgen_conservative(const double *x, const double *y, uint8_t *bits, int64_t W, int64_t H) {
    double area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]);
    double s = area < 0 ? -1 : 1;
    double lox = x[0] < x[1] ? x[0] : x[1], hix = x[0] > x[1] ? x[0] : x[1];
    double loy = y[0] < y[1] ? y[0] : y[1], hiy = y[0] > y[1] ? y[0] : y[1];
    lox = x[2] < lox ? x[2] : lox;
    hix = x[2] > hix ? x[2] : hix;
    loy = y[2] < loy ? y[2] : loy;
    hiy = y[2] > hiy ? y[2] : hiy;
    int64_t x0 = (int64_t)floor(lox - 1e-6), x1 = (int64_t)floor(hix + 1e-6);
    int64_t y0 = (int64_t)floor(loy - 1e-6), y1 = (int64_t)floor(hiy + 1e-6);
    if (x0 < 0) x0 = 0;
    if (y0 < 0) y0 = 0;
    if (x1 > W - 1) x1 = W - 1;
    if (y1 > H - 1) y1 = H - 1;
    /* f_k(X, Y) = a X + b Y + c >= 0 inside; max over the square at (tx, ty) = f_k(tx, ty) + off */
    double ea[3], eb[3], ec[3];
    int ne = 0;
    for (int k = 0; k < 3 && area != 0; k++) {
        double px = x[k], py = y[k], dx = x[(k + 1) % 3] - px, dy = y[(k + 1) % 3] - py;
        double a = -s * dy, b = s * dx;
        double off = (a > 0 ? a : 0) + (b > 0 ? b : 0);
        ea[ne] = a;
        eb[ne] = b;
        ec[ne] = -a * px - b * py + off + 1e-6 * sqrt(dx * dx + dy * dy);
        ne++;
    }
    for (int64_t ty = y0; ty <= y1; ty++)
        for (int64_t tx = x0; tx <= x1; tx++) {
            int in = 1;
            for (int k = 0; k < ne; k++)
                if (ea[k] * (double)tx + eb[k] * (double)ty + ec[k] < 0) {
                    in = 0;
                    break;
                }
            if (in) bits[ty * W + tx] = 1;
        }
}

/* ---- parameters ---------------------------------------------------------------------- */

static int uvgen_check(const lc_mesh *mesh, const lc_uv_params *p, int need_uv1, char *err, size_t errlen) {
    if (!mesh || !p) {
        lc_set_err(err, errlen, "uvgen: mesh and params are required");
        return -1;
    }
    if (mesh->n_triangles == 0 || mesh->n_vertices == 0 || !mesh->position || !mesh->index) {
        lc_set_err(err, errlen, "uvgen: the mesh is empty (no triangles); import a scene with geometry");
        return -1;
    }
    if (!isfinite(p->texels_per_metre) || p->texels_per_metre < 0 || p->texels_per_metre > 1e7) {
        lc_set_err(err, errlen, "uvgen: texels_per_metre %g is invalid; use a finite density > 0 or 0 with atlas_size",
                   p->texels_per_metre);
        return -1;
    }
    if (p->texels_per_metre == 0 && (p->atlas_size < 8 || p->atlas_size > UVGEN_MAX_ATLAS)) {
        lc_set_err(err, errlen, "uvgen: atlas_size %u is out of range [8, %u] (and texels_per_metre is 0)",
                   p->atlas_size, UVGEN_MAX_ATLAS);
        return -1;
    }
    if (p->padding < 2 || p->padding > UVGEN_MAX_PADDING) {
        lc_set_err(err, errlen, "uvgen: padding %u is out of range [2, %u] texels", p->padding, UVGEN_MAX_PADDING);
        return -1;
    }
    if (!need_uv1 && !(p->chart_angle_deg > 0 && p->chart_angle_deg < 90)) {
        lc_set_err(err, errlen, "uvgen: chart_angle_deg %g must be in (0, 90) degrees", p->chart_angle_deg);
        return -1;
    }
    for (size_t i = 0; i < 3 * (size_t)mesh->n_triangles; i++)
        if (mesh->index[i] >= mesh->n_vertices) {
            lc_set_err(err, errlen, "uvgen: mesh index %u of triangle %zu is out of range (%u vertices)",
                       mesh->index[i], i / 3, mesh->n_vertices);
            return -1;
        }
    for (size_t i = 0; i < 3 * (size_t)mesh->n_vertices; i++)
        if (!isfinite(mesh->position[i])) {
            lc_set_err(err, errlen, "uvgen: mesh position of vertex %zu is not finite; drop it at import", i / 3);
            return -1;
        }
    if (need_uv1) {
        if (!mesh->uv1) {
            lc_set_err(err, errlen, "uvgen: the mesh has no uv1 to measure; generate lightmap UVs instead");
            return -1;
        }
        for (size_t i = 0; i < 2 * (size_t)mesh->n_vertices; i++)
            if (!isfinite(mesh->uv1[i])) {
                lc_set_err(err, errlen, "uvgen: uv1 of vertex %zu is not finite", i / 2);
                return -1;
            }
    }
    return 0;
}

/* ---- lc_uvgen ------------------------------------------------------------------------- */

typedef struct {
    uint32_t v, chart, corner;
} uvgen_corner;

static int uvgen_corner_cmp(const void *pa, const void *pb) {
    const uvgen_corner *a = pa, *b = pb;
    if (a->v != b->v) return a->v < b->v ? -1 : 1;
    if (a->chart != b->chart) return a->chart < b->chart ? -1 : 1;
    return (a->corner > b->corner) - (a->corner < b->corner);
}

/* Sets the message every allocation failure of lc_uvgen gives; returns -1. */
static int uvgen_oom(const lc_mesh *mesh, char *err, size_t errlen) {
    lc_set_err(err, errlen, "uvgen: out of memory for %u triangles", mesh->n_triangles);
    return -1;
}

/* Unit normal per triangle into tri_n (degenerate ones flagged instead); returns the mesh's
 * surface area. */
static double uvgen_triangle_normals(const lc_mesh *mesh, double *tri_n, uint8_t *degen) {
    double total_area = 0;
    for (uint32_t t = 0; t < mesh->n_triangles; t++) {
        double c[3], e2;
        uvgen_tri_cross(mesh, t, c, &e2);
        double l = sqrt(uvgen_dot(c, c));
        total_area += 0.5 * l;
        /* near-collinear triangles have no reliable normal: they join any neighbour chart */
        if (!(l > 1e-12 * e2) || !(l > 0)) {
            degen[t] = 1;
            continue;
        }
        for (int k = 0; k < 3; k++) tri_n[3 * (size_t)t + k] = c[k] / l;
    }
    return total_area;
}

/* Grows chart c (c->start, c->ref set) by BFS from seed s over unassigned triangles within
 * the chart angle, appending them to cx->order from c->start; *n_order is where it ends. On
 * pass 0 first against the running area-weighted normal (charts follow gentle curvature up to
 * twice the angle), kept only if every triangle is within the angle of the final normal;
 * else regrown against the seed normal (the bound holds by construction). Pass 1 (degenerate
 * seeds) takes only degenerate neighbours. */
static void uvgen_grow_chart(const uvgen_ctx *cx, const uint32_t *adj_start, const uint32_t *adj, uint32_t *chart_of,
                             uint32_t s, int pass, double cos_a, uint32_t chart, uvgen_chart *c, uint32_t *n_order) {
    const lc_mesh *mesh = cx->m;
    const double *tri_n = cx->tri_n;
    const uint8_t *degen = cx->degen;
    uint32_t *order = cx->order;
    for (int mode = pass == 0 ? 0 : 1; mode < 2; mode++) {
        *n_order = c->start;
        chart_of[s] = chart;
        order[(*n_order)++] = s;
        double sum[3], avg[3];
        uvgen_tri_cross(mesh, s, sum, NULL);
        memcpy(avg, c->ref, sizeof avg);
        for (uint32_t q = c->start; q < *n_order; q++) {
            uint32_t t = order[q];
            for (uint32_t a = adj_start[t]; a < adj_start[t + 1]; a++) {
                uint32_t nb = adj[a];
                if (chart_of[nb] != LC_NONE) continue;
                if (!degen[nb]) {
                    if (pass == 1 || uvgen_dot(tri_n + 3 * (size_t)nb, avg) < cos_a) continue;
                    if (mode == 0) {
                        double cr[3];
                        uvgen_tri_cross(mesh, nb, cr, NULL);
                        for (int k = 0; k < 3; k++) sum[k] += cr[k];
                        memcpy(avg, sum, sizeof avg);
                        if (!uvgen_normalize(avg)) memcpy(avg, c->ref, sizeof avg);
                    }
                }
                chart_of[nb] = chart;
                order[(*n_order)++] = nb;
            }
        }
        if (mode == 1) break;
        int ok = 1;
        for (uint32_t q = c->start; q < *n_order && ok; q++) {
            uint32_t t = order[q];
            if (!degen[t] && uvgen_dot(tri_n + 3 * (size_t)t, avg) < cos_a) ok = 0;
        }
        if (ok) {
            memcpy(c->ref, avg, sizeof c->ref);
            break;
        }
        for (uint32_t q = c->start; q < *n_order; q++) chart_of[order[q]] = LC_NONE;
    }
    c->count = *n_order - c->start;
}

/* Stage 1, charts: BFS from the lowest unassigned triangle; non-degenerate seeds first. Fills
 * chart_of and cx->order; *charts grows (capacity *cap_charts). -1 out of memory. */
static int uvgen_grow_charts(const uvgen_ctx *cx, const uint32_t *adj_start, const uint32_t *adj, uint32_t *chart_of,
                             double cos_a, uvgen_chart **charts, uint32_t *n_charts, uint32_t *cap_charts) {
    const uint32_t T = cx->m->n_triangles;
    uint32_t n_order = 0;
    memset(chart_of, 0xFF, (size_t)T * sizeof *chart_of);
    for (int pass = 0; pass < 2; pass++)
        for (uint32_t s = 0; s < T; s++) {
            if (chart_of[s] != LC_NONE || (pass == 0 && cx->degen[s])) continue;
            uvgen_chart c = {0};
            c.start = n_order;
            if (pass == 0) memcpy(c.ref, cx->tri_n + 3 * (size_t)s, sizeof c.ref);
            else c.ref[2] = 1;
            uvgen_grow_chart(cx, adj_start, adj, chart_of, s, pass, cos_a, *n_charts, &c, &n_order);
            if (*n_charts == *cap_charts) {
                *cap_charts *= 2;
                uvgen_chart *p = realloc(*charts, *cap_charts * sizeof *p);
                if (!p) return -1;
                *charts = p;
            }
            (*charts)[(*n_charts)++] = c;
        }
    return 0;
}

/* Stages 3 + 4 at a given density d: the atlas width is searched for a square-ish packing of
 * the n charts (final placement in fin), *W x *H its size. -1 with err when none fits. */
static int uvgen_pack_at_density(uvgen_chart *fin, uint32_t n, uvgen_item *items, uvgen_seg *sky, double d,
                                 uint32_t pad, uint32_t *W, uint32_t *H, char *err, size_t errlen) {
    double est = 0; /* texels incl. padding, to choose a square-ish width */
    for (uint32_t i = 0; i < n; i++) est += (fin[i].w * d + 2 + pad) * (fin[i].h * d + 2 + pad);
    if (est > (double)UVGEN_MAX_ATLAS * UVGEN_MAX_ATLAS) {
        lc_set_err(err, errlen, "uvgen: texels_per_metre %g needs about %.0f texels, more than a %ux%u atlas; lower it",
                   d, est, UVGEN_MAX_ATLAS, UVGEN_MAX_ATLAS);
        return -1;
    }
    uint32_t best_w = 0, best_h = 0;
    double try_w = sqrt(est) + pad;
    for (uint32_t i = 0; i < n; i++) try_w = fmax(try_w, fin[i].w * d + 4 + 2 * pad);
    for (int it = 0; it < 4; it++) {
        uint32_t w = uvgen_round4(try_w);
        uint32_t used = uvgen_pack(fin, n, items, sky, d, w, UVGEN_MAX_ATLAS, pad, 0);
        uint32_t h = used == UINT32_MAX ? UINT32_MAX : uvgen_round4(used);
        if (used == UINT32_MAX) { /* too wide a chart or too tall: widen */
            try_w = w * 1.5;
            continue;
        }
        if (!best_w || (uint64_t)w * h < (uint64_t)best_w * best_h ||
            ((uint64_t)w * h == (uint64_t)best_w * best_h && abs((int)w - (int)h) < abs((int)best_w - (int)best_h))) {
            best_w = w;
            best_h = h;
        }
        if (h <= w + w / 8 && w <= h + h / 8) break; /* square enough */
        try_w = sqrt((double)w * h);
    }
    if (!best_w || best_w > UVGEN_MAX_ATLAS || best_h > UVGEN_MAX_ATLAS) {
        lc_set_err(err, errlen, "uvgen: texels_per_metre %g does not fit a %ux%u atlas; lower it", d, UVGEN_MAX_ATLAS,
                   UVGEN_MAX_ATLAS);
        return -1;
    }
    *W = best_w;
    *H = best_h;
    uvgen_pack(fin, n, items, sky, d, *W, *H, pad, 0); /* final placement */
    return 0;
}

/* Stages 3 + 4 in an atlas of params->atlas_size (grown if the charts cannot fit it): the
 * highest density that packs, by bisection; area = the larger of the charts' rects and the
 * surface. *W x *H the atlas, *d the density. -1 with err when even the grown atlas is full. */
static int uvgen_pack_in_atlas(uvgen_chart *fin, uint32_t n, uvgen_item *items, uvgen_seg *sky,
                               const lc_uv_params *params, double area, uint32_t *W_out, uint32_t *H_out, double *d,
                               char *err, size_t errlen) {
    const uint32_t pad = params->padding;
    uint32_t W, H;
    W = H = params->atlas_size;
    /* At 1e-4 of the ideal density every chart is a texel or two: if they do not fit
     * then, no density does; grow the atlas (a bake with default settings must not fail
     * on a scene with many small parts). Growing only until they barely fit would leave
     * nothing but padding: a grown atlas keeps the requested atlas_size^2 texels free
     * beside the charts' minimal footprints (rows above them), for their content. */
    double hi = W / sqrt(area), lo = hi * 1e-4;
    if (uvgen_pack(fin, n, items, sky, lo, W, H, pad, 1) == UINT32_MAX) {
        for (;;) {
            if (W >= UVGEN_GROW_MAX) {
                lc_set_err(err, errlen,
                           "uvgen: %u charts with padding %u cannot fit atlas_size %u, even grown to %u; raise "
                           "chart_angle_deg or lower padding",
                           n, pad, params->atlas_size, W);
                return -1;
            }
            W = H = uvgen_round4(fmin(W * 1.25, UVGEN_GROW_MAX));
            hi = W / sqrt(area);
            lo = hi * 1e-4;
            uint64_t room = ((uint64_t)params->atlas_size * params->atlas_size + W - 1) / W;
            uint32_t max_h = W < UVGEN_GROW_MAX ? (uint32_t)(H > room ? H - room : 0) : H;
            if (uvgen_pack(fin, n, items, sky, lo, W, max_h, pad, 1) != UINT32_MAX) break;
        }
    }
    if (W != params->atlas_size)
        lc_warn("uvgen",
                "atlas grown from %u to %u to hold %u charts; raise --atlas-size or --chart-angle, or give the "
                "asset a second UV set, to avoid this",
                params->atlas_size, W, n);
    if (uvgen_pack(fin, n, items, sky, hi, W, H, pad, 1) != UINT32_MAX) lo = hi;
    for (int it = 0; it < 60 && hi > lo * 1.0005; it++) {
        double mid = sqrt(lo * hi);
        if (uvgen_pack(fin, n, items, sky, mid, W, H, pad, 1) != UINT32_MAX) lo = mid;
        else hi = mid;
    }
    *d = lo;
    uvgen_pack(fin, n, items, sky, *d, W, H, pad, 1);
    *W_out = W;
    *H_out = H;
    return 0;
}

/* The mesh's vertex arrays after the rewrite: one vertex per (original vertex, chart). */
typedef struct {
    float *pos, *nrm, *uv0, *uv1;
    uint32_t *idx;
    size_t nv;
} uvgen_remesh;

static void uvgen_remesh_free(uvgen_remesh *r) {
    free(r->pos);
    free(r->nrm);
    free(r->uv0);
    free(r->uv1);
    free(r->idx);
    memset(r, 0, sizeof *r);
}

/* Every triangle corner sorted by (vertex, chart, corner): a counting sort by vertex (stable:
 * corners of a vertex stay in triangle order), then each vertex's short run by chart. -1 out
 * of memory. */
static int uvgen_sort_corners(const lc_mesh *mesh, const uint32_t *chart_of, uvgen_corner *corners) {
    const size_t nc = 3 * (size_t)mesh->n_triangles;
    uint32_t *vstart = calloc((size_t)mesh->n_vertices + 1, sizeof *vstart);
    if (!vstart) return -1;
    for (size_t i = 0; i < nc; i++) vstart[mesh->index[i] + 1]++;
    for (uint32_t v = 0; v < mesh->n_vertices; v++) vstart[v + 1] += vstart[v];
    for (size_t i = 0; i < nc; i++)
        corners[vstart[mesh->index[i]]++] = (uvgen_corner){mesh->index[i], chart_of[i / 3], (uint32_t)i};
    free(vstart);
    for (size_t i = 0; i < nc;) {
        size_t j = i + 1;
        while (j < nc && corners[j].v == corners[i].v) j++;
        for (size_t a = i + 1; a < j; a++) /* insertion sort: runs are a few corners */
            for (size_t b = a; b > i && uvgen_corner_cmp(&corners[b - 1], &corners[b]) > 0; b--) {
                uvgen_corner t = corners[b];
                corners[b] = corners[b - 1];
                corners[b - 1] = t;
            }
        i = j;
    }
    return 0;
}

/* Stage 5, rewrite: one vertex per (original vertex, chart), in (vertex, chart) order, its
 * uv1 from the chart's placement at density d in the W x H atlas. -1 with err. */
static int uvgen_split_vertices(const uvgen_ctx *cx, const uvgen_chart *fin, const uint32_t *chart_of, double d,
                                uint32_t W, uint32_t H, uvgen_remesh *rm, char *err, size_t errlen) {
    const lc_mesh *mesh = cx->m;
    const size_t nc = 3 * (size_t)mesh->n_triangles;
    int rc = -1;
    uvgen_corner *corners = malloc(nc * sizeof *corners);
    rm->idx = malloc(nc * sizeof *rm->idx);
    if (!corners || !rm->idx || uvgen_sort_corners(mesh, chart_of, corners) != 0) {
        uvgen_oom(mesh, err, errlen);
        goto err;
    }
    size_t nv = 0;
    for (size_t i = 0; i < nc; i++)
        if (i == 0 || corners[i].v != corners[i - 1].v || corners[i].chart != corners[i - 1].chart) nv++;
    if (nv > UINT32_MAX - 1) {
        lc_set_err(err, errlen, "uvgen: splitting vertices along seams exceeds 2^32 vertices");
        goto err;
    }
    rm->nv = nv;
    rm->pos = malloc(3 * nv * sizeof *rm->pos);
    rm->uv1 = malloc(2 * nv * sizeof *rm->uv1);
    if (mesh->normal) rm->nrm = malloc(3 * nv * sizeof *rm->nrm);
    if (mesh->uv0) rm->uv0 = malloc(2 * nv * sizeof *rm->uv0);
    if (!rm->pos || !rm->uv1 || (mesh->normal && !rm->nrm) || (mesh->uv0 && !rm->uv0)) {
        uvgen_oom(mesh, err, errlen);
        goto err;
    }
    size_t cur = (size_t)-1;
    for (size_t i = 0; i < nc; i++) {
        const uvgen_corner *k = &corners[i];
        if (i == 0 || k->v != corners[i - 1].v || k->chart != corners[i - 1].chart) {
            cur++;
            memcpy(rm->pos + 3 * cur, mesh->position + 3 * (size_t)k->v, 3 * sizeof(float));
            if (rm->nrm) memcpy(rm->nrm + 3 * cur, mesh->normal + 3 * (size_t)k->v, 3 * sizeof(float));
            if (rm->uv0) memcpy(rm->uv0 + 2 * cur, mesh->uv0 + 2 * (size_t)k->v, 2 * sizeof(float));
            const uvgen_chart *c = &fin[k->chart];
            double p[3];
            uvgen_load(mesh, cx->weld[k->v], p);
            double lu = uvgen_dot(p, c->U) - c->umin, lv = uvgen_dot(p, c->V) - c->vmin;
            if (c->rot) {
                double t = lu;
                lu = c->h - lv;
                lv = t;
            }
            double X = c->x + c->fx + lu * d, Y = c->y + c->fy + lv * d;
            rm->uv1[2 * cur] = (float)fmin(fmax(X / W, 0.0), 1.0);
            rm->uv1[2 * cur + 1] = (float)fmin(fmax(Y / H, 0.0), 1.0);
        }
        rm->idx[k->corner] = (uint32_t)cur;
    }
    rc = 0;
err:
    free(corners);
    return rc;
}

/* Stage 6, usage: texels under the charts' conservative footprints, per chart over its own
 * rect (footprints are disjoint) into *used. -1 out of memory. */
static int uvgen_usage(const uvgen_chart *fin, uint32_t n, const uint32_t *order, const uvgen_remesh *rm, uint32_t W,
                       uint32_t H, uint64_t *used) {
    size_t max_rect = 1;
    for (uint32_t i = 0; i < n; i++) {
        size_t r = (size_t)fin[i].fw * fin[i].fh;
        if (r > max_rect) max_rect = r;
    }
    uint8_t *bits = malloc(max_rect);
    if (!bits) return -1;
    *used = 0;
    for (uint32_t i = 0; i < n; i++) {
        const uvgen_chart *c = &fin[i];
        memset(bits, 0, (size_t)c->fw * c->fh);
        for (uint32_t q = c->start; q < c->start + c->count; q++) {
            uint32_t t = order[q];
            double x[3], y[3];
            for (int k = 0; k < 3; k++) {
                uint32_t v = rm->idx[3 * (size_t)t + k];
                x[k] = (double)rm->uv1[2 * (size_t)v] * W - c->x;
                y[k] = (double)rm->uv1[2 * (size_t)v + 1] * H - c->y;
            }
            uvgen_conservative(x, y, bits, c->fw, c->fh);
        }
        for (size_t k = 0; k < (size_t)c->fw * c->fh; k++) *used += bits[k];
    }
    free(bits);
    return 0;
}

/* The mesh takes the rewritten arrays (rm is left empty). */
static void uvgen_remesh_install(lc_mesh *mesh, uvgen_remesh *rm) {
    free(mesh->position);
    free(mesh->normal);
    free(mesh->uv0);
    free(mesh->uv1);
    free(mesh->index);
    mesh->position = rm->pos;
    mesh->normal = rm->nrm;
    mesh->uv0 = rm->uv0;
    mesh->uv1 = rm->uv1;
    mesh->index = rm->idx;
    mesh->n_vertices = (uint32_t)rm->nv;
    memset(rm, 0, sizeof *rm);
}

int lc_uvgen(lc_mesh *mesh, const lc_uv_params *params, lc_uv_stats *stats, char *err, size_t errlen) {
    if (uvgen_check(mesh, params, 0, err, errlen) != 0) return -1;
    const uint32_t T = mesh->n_triangles, pad = params->padding;
    int rc = -1;
    uint32_t *weld = NULL, *adj_start = NULL, *adj = NULL, *order = NULL, *chart_of = NULL;
    uint32_t *mark = NULL;
    double *tri_n = NULL, *cu = NULL, *cv = NULL;
    uint8_t *degen = NULL;
    uvgen_chart *charts = NULL, *fin = NULL;
    uvgen_item *items = NULL;
    uvgen_seg *sky = NULL;
    uvgen_remesh rm = {0};

    weld = malloc((size_t)mesh->n_vertices * sizeof *weld);
    tri_n = calloc(3 * (size_t)T, sizeof *tri_n);
    degen = calloc(T, 1);
    order = malloc((size_t)T * sizeof *order);
    chart_of = malloc((size_t)T * sizeof *chart_of);
    mark = calloc(T, sizeof *mark);
    cu = malloc(3 * (size_t)T * sizeof *cu);
    cv = malloc(3 * (size_t)T * sizeof *cv);
    if (!weld || !tri_n || !degen || !order || !chart_of || !mark || !cu || !cv) goto oom;
    if (uvgen_weld(mesh, weld) != 0 || uvgen_adjacency(mesh, weld, &adj_start, &adj) != 0) goto oom;

    double total_area = uvgen_triangle_normals(mesh, tri_n, degen);
    if (!(total_area > 0)) {
        lc_set_err(err, errlen, "uvgen: the mesh has zero surface area (all %u triangles degenerate)", T);
        goto err;
    }

    /* 1. charts */
    uvgen_ctx cx = {mesh, weld, tri_n, degen, order, cu, cv, 0.02, params->threads};
    uint32_t cap_charts = 64, n_charts = 0;
    charts = malloc(cap_charts * sizeof *charts);
    if (!charts) goto oom;
    double cos_a = cos(params->chart_angle_deg * M_PI / 180.0);
    if (uvgen_grow_charts(&cx, adj_start, adj, chart_of, cos_a, &charts, &n_charts, &cap_charts) != 0) goto oom;

    /* 2. project; split overlapping charts until none overlap (sub-charts are appended);
     * merge small charts into neighbours; project and check the merged ones the same way. */
    uint32_t stamp = 0;
    if (uvgen_resolve(&cx, &charts, &n_charts, &cap_charts, adj_start, adj, mark, &stamp) != 0) goto oom;
    uint32_t n_grown = n_charts;
    if (uvgen_merge(&cx, &charts, &n_charts, adj_start, adj, params->texels_per_metre, params->atlas_size, pad,
                    cos_a) != 0)
        goto oom;
    cap_charts = n_charts ? n_charts : 1;
    if (uvgen_resolve(&cx, &charts, &n_charts, &cap_charts, adj_start, adj, mark, &stamp) != 0) goto oom;
    lc_debug("uvgen", "%u charts grown, %u after merging", n_grown, n_charts);
    uint32_t n_final = n_charts;
    fin = charts;
    charts = NULL;
    items = malloc((size_t)(n_final ? n_final : 1) * sizeof *items);
    sky = malloc(((size_t)n_final + 2) * sizeof *sky);
    if (!items || !sky) goto oom;
    for (uint32_t i = 0; i < n_final; i++)
        for (uint32_t q = fin[i].start; q < fin[i].start + fin[i].count; q++) chart_of[order[q]] = i;

    /* 3 + 4. density and packing */
    double rect_area = 0;
    for (uint32_t i = 0; i < n_final; i++) rect_area += fin[i].w * fin[i].h;
    uint32_t W = 0, H = 0;
    double d = params->texels_per_metre;
    if (d <= 0) { /* fit atlas_size: one density for every chart, as projected */
        if (uvgen_pack_in_atlas(fin, n_final, items, sky, params, fmax(rect_area, total_area), &W, &H, &d, err,
                                errlen) != 0)
            goto err;
        if (d < params->min_texels_per_metre) {
            lc_info("uvgen", "%ux%u gives %.2f texels/m, below the minimum %.2f: the atlas grows to fit that density",
                    W, H, d, params->min_texels_per_metre);
            d = -params->min_texels_per_metre; /* density mode below */
        }
    }
    if (params->texels_per_metre > 0 || d < 0) { /* a density on the surface: charts compensated for tilt */
        d = fabs(d);
        if (uvgen_compensate_stretch(&cx, fin, n_final) != 0) goto oom;
        if (uvgen_pack_at_density(fin, n_final, items, sky, d, pad, &W, &H, err, errlen) != 0) goto err;
    }

    /* 5. rewrite; 6. usage */
    if (uvgen_split_vertices(&cx, fin, chart_of, d, W, H, &rm, err, errlen) != 0) goto err;
    uint64_t used = 0;
    if (uvgen_usage(fin, n_final, order, &rm, W, H, &used) != 0) goto oom;
    uvgen_remesh_install(mesh, &rm);
    if (stats) {
        stats->n_charts = n_final;
        stats->width = W;
        stats->height = H;
        stats->texels_per_metre = d;
        stats->usage = (double)used / ((double)W * H);
        if (lc_uv_texel_spacing(mesh, W, H, stats) != 0) goto oom;
    }
    rc = 0;
    if (0) {
    oom:
        uvgen_oom(mesh, err, errlen);
    }
err:
    free(weld);
    free(adj_start);
    free(adj);
    free(order);
    free(chart_of);
    free(mark);
    free(tri_n);
    free(cu);
    free(cv);
    free(degen);
    free(charts);
    free(fin);
    free(items);
    free(sky);
    uvgen_remesh_free(&rm);
    return rc;
}

/* ---- lc_uvgen_measure ------------------------------------------------------------------ */

int lc_uv_texel_spacing(const lc_mesh *mesh, uint32_t W, uint32_t H, lc_uv_stats *stats) {
    uvgen_spacing *sp = malloc(((size_t)mesh->n_triangles + 1) * sizeof *sp);
    if (!sp) return -1;
    uint32_t n = 0;
    double total = 0, sum = 0;
    for (uint32_t t = 0; t < mesh->n_triangles; t++) {
        const uint32_t *ix = mesh->index + 3 * (size_t)t;
        double c[3], x[3], y[3];
        for (int k = 0; k < 3; k++) {
            x[k] = (double)mesh->uv1[2 * (size_t)ix[k]] * W;
            y[k] = (double)mesh->uv1[2 * (size_t)ix[k] + 1] * H;
        }
        uvgen_tri_cross(mesh, t, c, NULL);
        double world = 0.5 * sqrt(uvgen_dot(c, c)), texels = uvgen_area2(x, y);
        if (!(texels > 0) || !(world > 0)) continue;
        sp[n].spacing = sqrt(world / texels);
        sp[n].texels = texels;
        total += texels;
        sum += texels * sp[n].spacing;
        n++;
    }
    stats->spacing_mean = stats->spacing_p95 = stats->spacing_max = 0;
    if (n && total > 0) {
        stats->spacing_mean = sum / total;
        stats->spacing_p95 = uvgen_weighted_quantile(sp, n, total, 0.95);
        stats->spacing_max = sp[n - 1].spacing; /* sorted by the quantile */
    }
    free(sp);
    return 0;
}

int lc_uvgen_measure(const lc_mesh *mesh, const lc_uv_params *params, lc_uv_stats *stats, char *err, size_t errlen) {
    if (uvgen_check(mesh, params, 1, err, errlen) != 0) return -1;
    double area = lc_mesh_total_area(mesh);
    if (!(area > 0)) {
        lc_set_err(err, errlen, "uvgen: the mesh has zero surface area");
        return -1;
    }
    uint32_t W, H;
    double uv_frac = 0; /* uv area of the triangles in the unit square */
    for (uint32_t t = 0; t < mesh->n_triangles; t++) {
        const uint32_t *ix = mesh->index + 3 * (size_t)t;
        const float *a = mesh->uv1 + 2 * (size_t)ix[0], *b = mesh->uv1 + 2 * (size_t)ix[1],
                    *c = mesh->uv1 + 2 * (size_t)ix[2];
        uv_frac += 0.5 * fabs((double)(b[0] - a[0]) * (c[1] - a[1]) - (double)(b[1] - a[1]) * (c[0] - a[0]));
    }
    double side = 0; /* atlas side for a density, 0: atlas_size */
    if (params->texels_per_metre > 0) side = sqrt(area) * params->texels_per_metre;
    else if (params->min_texels_per_metre > 0 && uv_frac > 0 &&
             params->atlas_size * sqrt(uv_frac / area) < params->min_texels_per_metre)
        side = params->min_texels_per_metre * sqrt(area / uv_frac); /* the asset's charts at the minimum */
    if (side > 0) {
        if (side > UVGEN_MAX_ATLAS) {
            lc_set_err(err, errlen, "uvgen: the lightmap density needs a %.0f texel atlas (max %u); lower it", side,
                       UVGEN_MAX_ATLAS);
            return -1;
        }
        W = H = uvgen_round4(side);
    } else {
        W = H = params->atlas_size;
    }
    uint8_t *bits = calloc((size_t)W * H, 1);
    if (!bits) {
        lc_set_err(err, errlen, "uvgen: out of memory for a %ux%u coverage map", W, H);
        return -1;
    }
    double uv_area = 0;
    for (uint32_t t = 0; t < mesh->n_triangles; t++) {
        double x[3], y[3];
        for (int k = 0; k < 3; k++) {
            uint32_t v = mesh->index[3 * (size_t)t + k];
            x[k] = (double)mesh->uv1[2 * (size_t)v] * W;
            y[k] = (double)mesh->uv1[2 * (size_t)v + 1] * H;
        }
        uv_area += 0.5 * fabs((x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]));
        uvgen_conservative(x, y, bits, W, H);
    }
    uint64_t used = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) used += bits[i];
    free(bits);
    if (stats) {
        stats->n_charts = 0; /* charts are the asset's own; not counted */
        stats->width = W;
        stats->height = H;
        stats->texels_per_metre = params->texels_per_metre > 0 ? params->texels_per_metre : sqrt(uv_area / area);
        stats->usage = (double)used / ((double)W * H);
        if (lc_uv_texel_spacing(mesh, W, H, stats) != 0) {
            lc_set_err(err, errlen, "uvgen: out of memory measuring the texel spacing");
            return -1;
        }
    }
    return 0;
}
