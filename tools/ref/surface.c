/* surface: where each lightmap texel lies on the mesh, found by the reference itself from the
 * bake's static triangles and their lightmap UVs (uv1), independently of the bake's texel
 * rasterizer (see ref.h, "texel surface points"). Triangles are binned in a uniform grid over
 * the texel raster by their uv bounding boxes; each wanted texel centre looks for a triangle
 * whose uv contains it in its own cell, else takes the triangle with the nearest uv point
 * (clamped barycentrics), searching rings of cells outward. Everything in double. Then the
 * texel spacing statistics over those points. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ref/ref.h"
#include "util/log.h"

#define SURF_CELL 4u                  /* texels per grid cell side */
#define SURF_MAX_TEXELS (1u << 28)    /* cap on W*H (the output is 7 floats per texel) */
#define SURF_MAX_ENTRIES (1ull << 28) /* cap on triangle-in-cell entries */
#define SURF_INSIDE_TOL 1e-9          /* barycentric slack for centres on an edge */

typedef struct {
    uint32_t gw, gh; /* cells */
    uint32_t *start; /* gw*gh + 1, CSR offsets into tri */
    uint32_t *tri;   /* triangle indices, ascending within a cell */
    double *uv;      /* n_triangles*6: corners in texel units (u W, v H) */
    uint8_t *valid;  /* n_triangles: finite, non-degenerate uv */
} surf_grid;

static void surf_grid_free(surf_grid *g) {
    free(g->start);
    free(g->tri);
    free(g->uv);
    free(g->valid);
    memset(g, 0, sizeof *g);
}

/* The cells a valid triangle's uv box overlaps (clamped); 0 when outside the raster. */
static int surf_tri_cells(const surf_grid *g, const double *c, uint32_t *x0, uint32_t *y0, uint32_t *x1, uint32_t *y1) {
    double lo_u = fmin(c[0], fmin(c[2], c[4])), hi_u = fmax(c[0], fmax(c[2], c[4]));
    double lo_v = fmin(c[1], fmin(c[3], c[5])), hi_v = fmax(c[1], fmax(c[3], c[5]));
    double gw = g->gw * (double)SURF_CELL, gh = g->gh * (double)SURF_CELL;
    if (hi_u < 0 || hi_v < 0 || lo_u > gw || lo_v > gh) return 0;
    *x0 = (uint32_t)fmax(0, floor(lo_u / SURF_CELL));
    *y0 = (uint32_t)fmax(0, floor(lo_v / SURF_CELL));
    *x1 = (uint32_t)fmin(g->gw - 1, floor(hi_u / SURF_CELL));
    *y1 = (uint32_t)fmin(g->gh - 1, floor(hi_v / SURF_CELL));
    return 1;
}

static int surf_grid_build(const lc_lcb_vertex *vt, uint32_t n_vertices, const lc_lcb_triangle *tris, uint32_t n_tris,
                           uint32_t w, uint32_t h, surf_grid *g, char *err, size_t errlen) {
    memset(g, 0, sizeof *g);
    g->gw = (w + SURF_CELL - 1) / SURF_CELL;
    g->gh = (h + SURF_CELL - 1) / SURF_CELL;
    size_t cells = (size_t)g->gw * g->gh;
    g->start = calloc(cells + 1, sizeof *g->start);
    g->uv = malloc(((size_t)n_tris * 6 + 1) * sizeof *g->uv);
    g->valid = calloc((size_t)n_tris + 1, 1);
    if (!g->start || !g->uv || !g->valid) goto oom;
    uint64_t entries = 0;
    for (int pass = 0; pass < 2; pass++) {
        for (uint32_t t = 0; t < n_tris; t++) {
            double *c = g->uv + 6 * (size_t)t;
            if (pass == 0) {
                int ok = 1;
                for (int k = 0; k < 3 && ok; k++) {
                    uint32_t vi = tris[t].v[k];
                    if (vi >= n_vertices) {
                        lc_set_err(err, errlen, "triangles[%u].v[%d]: vertex %u of %u", t, k, vi, n_vertices);
                        goto fail;
                    }
                    c[2 * k] = (double)vt[vi].uv1[0] * w;
                    c[2 * k + 1] = (double)vt[vi].uv1[1] * h;
                    ok = isfinite(c[2 * k]) && isfinite(c[2 * k + 1]);
                }
                double d = (c[2] - c[0]) * (c[5] - c[1]) - (c[3] - c[1]) * (c[4] - c[0]);
                g->valid[t] = ok && d != 0 && isfinite(d);
            }
            uint32_t x0, y0, x1, y1;
            if (!g->valid[t] || !surf_tri_cells(g, c, &x0, &y0, &x1, &y1)) continue;
            for (uint32_t y = y0; y <= y1; y++)
                for (uint32_t x = x0; x <= x1; x++) {
                    size_t cell = (size_t)y * g->gw + x;
                    if (pass == 0) g->start[cell + 1]++, entries++;
                    else g->tri[g->start[cell]++] = t;
                }
        }
        if (pass == 0) {
            if (entries > SURF_MAX_ENTRIES) {
                lc_set_err(err, errlen, "lightmap uv grid: %llu triangle entries, the cap is %llu",
                           (unsigned long long)entries, (unsigned long long)SURF_MAX_ENTRIES);
                goto fail;
            }
            for (size_t i = 0; i < cells; i++) g->start[i + 1] += g->start[i];
            g->tri = malloc((size_t)(entries + 1) * sizeof *g->tri);
            if (!g->tri) goto oom;
        }
    }
    /* The fill advanced each start to the next cell's: shift back. */
    for (size_t i = cells; i > 0; i--) g->start[i] = g->start[i - 1];
    g->start[0] = 0;
    return 0;
oom:
    lc_set_err(err, errlen, "out of memory for the lightmap uv grid (%u triangles)", n_tris);
fail:
    surf_grid_free(g);
    return -1;
}

/* Barycentrics (b1, b2) of point (px, py) in the triangle's uv; b0 = 1 - b1 - b2. */
static void surf_bary(const double *c, double px, double py, double *b1, double *b2) {
    double ex = c[2] - c[0], ey = c[3] - c[1], fx = c[4] - c[0], fy = c[5] - c[1];
    double d = ex * fy - ey * fx, qx = px - c[0], qy = py - c[1];
    *b1 = (qx * fy - qy * fx) / d;
    *b2 = (ex * qy - ey * qx) / d;
}

/* Squared uv distance from (px, py) to the triangle, with the barycentrics of the nearest
 * point (the point itself when inside). */
static double surf_nearest(const double *c, double px, double py, double b[3]) {
    double b1, b2;
    surf_bary(c, px, py, &b1, &b2);
    if (b1 >= 0 && b2 >= 0 && b1 + b2 <= 1) {
        b[0] = 1 - b1 - b2, b[1] = b1, b[2] = b2;
        return 0;
    }
    double best = INFINITY;
    b[0] = 1, b[1] = b[2] = 0; /* a corner, should every distance be NaN (a degenerate uv triangle) */
    for (int e = 0; e < 3; e++) {
        int i = e, j = (e + 1) % 3;
        double ax = c[2 * i], ay = c[2 * i + 1], dx = c[2 * j] - ax, dy = c[2 * j + 1] - ay;
        double len2 = dx * dx + dy * dy;
        double t = len2 > 0 ? ((px - ax) * dx + (py - ay) * dy) / len2 : 0;
        t = t < 0 ? 0 : t > 1 ? 1 : t;
        double qx = ax + t * dx - px, qy = ay + t * dy - py, d2 = qx * qx + qy * qy;
        if (d2 < best) {
            best = d2;
            b[0] = b[1] = b[2] = 0;
            b[i] = 1 - t, b[j] = t;
        }
    }
    return best;
}

/* Offers the triangles of cell (x, y) (skipped when outside the grid) as the nearest. */
static void surf_scan_cell(const surf_grid *g, int64_t x, int64_t y, double px, double py, uint32_t *best,
                           double *best_d2, double b[3]) {
    if (x < 0 || y < 0 || x >= g->gw || y >= g->gh) return;
    size_t k = (size_t)y * g->gw + (size_t)x;
    for (uint32_t i = g->start[k]; i < g->start[k + 1]; i++) {
        double bb[3], d2 = surf_nearest(g->uv + 6 * (size_t)g->tri[i], px, py, bb);
        if (d2 < *best_d2 || (d2 == *best_d2 && g->tri[i] < *best)) {
            *best_d2 = d2, *best = g->tri[i];
            memcpy(b, bb, sizeof bb);
        }
    }
}

/* The triangle holding texel centre (px, py): *outside = 0 when its uv contains the centre,
 * else the nearest. Returns the triangle or LC_NONE (no valid triangle in the grid). */
static uint32_t surf_find(const surf_grid *g, double px, double py, double b[3], int *outside) {
    b[0] = 1, b[1] = b[2] = 0;
    uint32_t cx = (uint32_t)(px / SURF_CELL), cy = (uint32_t)(py / SURF_CELL);
    if (cx >= g->gw) cx = g->gw - 1;
    if (cy >= g->gh) cy = g->gh - 1;
    size_t cell = (size_t)cy * g->gw + cx;
    for (uint32_t i = g->start[cell]; i < g->start[cell + 1]; i++) {
        const double *c = g->uv + 6 * (size_t)g->tri[i];
        double b1, b2;
        surf_bary(c, px, py, &b1, &b2);
        if (b1 >= -SURF_INSIDE_TOL && b2 >= -SURF_INSIDE_TOL && 1 - b1 - b2 >= -SURF_INSIDE_TOL) {
            b[0] = 1 - b1 - b2, b[1] = b1, b[2] = b2;
            *outside = 0;
            return g->tri[i];
        }
    }
    /* Rings of cells outward; ring r lies at least (r - 1) cells away from the centre. */
    *outside = 1;
    uint32_t best = LC_NONE, rmax = g->gw > g->gh ? g->gw : g->gh;
    double best_d2 = INFINITY;
    if (g->start[(size_t)g->gw * g->gh] == 0) return LC_NONE;
    for (uint32_t r = 0; r <= rmax; r++) {
        double reach = r > 0 ? (double)(r - 1) * SURF_CELL : 0;
        if (best != LC_NONE && reach * reach > best_d2) break;
        int64_t lo_x = (int64_t)cx - r, hi_x = (int64_t)cx + r, lo_y = (int64_t)cy - r, hi_y = (int64_t)cy + r;
        for (int64_t y = lo_y; y <= hi_y; y++) {
            int edge_row = y == lo_y || y == hi_y;
            /* the ring's perimeter: whole top and bottom rows, the two end cells of the others */
            for (int64_t x = lo_x; x <= hi_x; x += edge_row || r == 0 ? 1 : 2 * (int64_t)r)
                surf_scan_cell(g, x, y, px, py, &best, &best_d2, b);
        }
    }
    return best;
}

/* Point, normal (the bake's rule: the interpolated vertex normal, or the winding normal when
 * that is degenerate or points to the other side) and spacing of triangle t at b. */
static void surf_eval(const lc_lcb_vertex *vt, const lc_lcb_triangle *tr, const double *uv, const double b[3],
                      float out[LC_REF_SURFACE_STRIDE]) {
    const float *p[3], *n[3];
    for (int k = 0; k < 3; k++) p[k] = vt[tr->v[k]].position, n[k] = vt[tr->v[k]].normal;
    double e1[3], e2[3], g[3], ns[3];
    for (int k = 0; k < 3; k++) {
        out[k] = (float)(b[0] * p[0][k] + b[1] * p[1][k] + b[2] * p[2][k]);
        ns[k] = b[0] * n[0][k] + b[1] * n[1][k] + b[2] * n[2][k];
        e1[k] = (double)p[1][k] - p[0][k];
        e2[k] = (double)p[2][k] - p[0][k];
    }
    g[0] = e1[1] * e2[2] - e1[2] * e2[1];
    g[1] = e1[2] * e2[0] - e1[0] * e2[2];
    g[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double gl = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
    double nl = sqrt(ns[0] * ns[0] + ns[1] * ns[1] + ns[2] * ns[2]);
    int use_g = !(nl > 0) || (ns[0] * g[0] + ns[1] * g[1] + ns[2] * g[2]) <= 0;
    for (int k = 0; k < 3; k++) out[3 + k] = (float)(use_g ? (gl > 0 ? g[k] / gl : 0) : ns[k] / nl);
    double uv_area = 0.5 * fabs((uv[2] - uv[0]) * (uv[5] - uv[1]) - (uv[3] - uv[1]) * (uv[4] - uv[0]));
    out[6] = (float)sqrt(0.5 * gl / uv_area);
}

int lc_ref_texel_surfaces(const lc_lcb_vertex *vertices, uint32_t n_vertices, const lc_lcb_triangle *triangles,
                          uint32_t n_triangles, uint32_t width, uint32_t height, const uint8_t *want, float *out,
                          lc_ref_surface_stats *stats, char *err, size_t errlen) {
    memset(stats, 0, sizeof *stats);
    size_t texels = (size_t)width * height;
    if (!width || !height || texels > SURF_MAX_TEXELS) {
        lc_set_err(err, errlen, "lightmap %ux%u: texel surfaces need 1..%u texels", width, height, SURF_MAX_TEXELS);
        return -1;
    }
    for (size_t i = 0; i < texels * LC_REF_SURFACE_STRIDE; i++) out[i] = NAN;
    surf_grid g;
    if (surf_grid_build(vertices, n_vertices, triangles, n_triangles, width, height, &g, err, errlen) != 0) return -1;
    for (size_t i = 0; i < texels; i++) {
        if (want && !want[i]) continue;
        stats->texels++;
        double b[3];
        int outside = 0;
        uint32_t t = surf_find(&g, (double)(i % width) + 0.5, (double)(i / width) + 0.5, b, &outside);
        if (t == LC_NONE) {
            stats->missing++;
            continue;
        }
        stats->outside += (uint32_t)outside;
        surf_eval(vertices, &triangles[t], g.uv + 6 * (size_t)t, b, out + LC_REF_SURFACE_STRIDE * i);
    }
    surf_grid_free(&g);
    return 0;
}

int lc_ref_bake_texels(const lc_lcb_view *v, float *surface, uint8_t *moved, lc_ref_surface_stats *stats, char *err,
                       size_t errlen) {
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    uint8_t *want = calloc(texels + 1, 1);
    if (!want) {
        lc_set_err(err, errlen, "out of memory for %zu texels", texels);
        return -1;
    }
    if (moved) memset(moved, 0, texels);
    for (uint32_t c = 0; c < v->n_texel_caches; c++) {
        const lc_lcb_cache *ca = &v->caches[c];
        if (!(ca->flags & LC_CACHE_TEXEL) || ca->index >= texels) continue;
        want[ca->index] = 1;
        if (moved) moved[ca->index] = (ca->flags & LC_CACHE_MOVED) != 0;
    }
    int rc = lc_ref_texel_surfaces(v->vertices, v->n_vertices, v->triangles, v->n_triangles, v->lightmap_width,
                                   v->lightmap_height, want, surface, stats, err, errlen);
    free(want);
    return rc;
}

/* --- texel spacing statistics ------------------------------------------------------------------- */

static int surf_cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Nearest-rank percentile of sorted x[0..n). */
static double surf_rank(const double *x, uint32_t n, double q) {
    uint32_t k = (uint32_t)ceil(q * n);
    return x[k ? k - 1 : 0];
}

int lc_ref_spacing_stats(const float *surface, uint32_t width, uint32_t height, double over_m, lc_ref_spacing *out) {
    memset(out, 0, sizeof *out);
    out->over_m = over_m;
    size_t texels = (size_t)width * height;
    double *s = malloc((texels ? texels : 1) * sizeof *s), sum = 0;
    if (!s) return -1;
    uint32_t n = 0, over = 0;
    for (size_t i = 0; i < texels; i++) {
        double d = surface[LC_REF_SURFACE_STRIDE * i + 6];
        if (!isfinite(d)) continue;
        s[n++] = d;
        sum += d;
        over += d > over_m;
    }
    if (n) {
        qsort(s, n, sizeof *s, surf_cmp_double);
        out->n = n;
        out->mean = sum / n;
        out->p50 = surf_rank(s, n, 0.50);
        out->p95 = surf_rank(s, n, 0.95);
        out->max = s[n - 1];
        out->share_over = (double)over / n;
    }
    free(s);
    return n ? 0 : -1;
}

char *lc_ref_spacing_json(const lc_ref_spacing *s) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "texels", s->n);
    cJSON_AddNumberToObject(o, "mean", s->mean);
    cJSON_AddNumberToObject(o, "p50", s->p50);
    cJSON_AddNumberToObject(o, "p95", s->p95);
    cJSON_AddNumberToObject(o, "max", s->max);
    cJSON_AddNumberToObject(o, "over_m", s->over_m);
    cJSON_AddNumberToObject(o, "share_over", s->share_over);
    char *text = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    return text;
}
