/* test_sparse: LightSkin sparse points and per-vertex tables (bake/sparse.h) against brute
 * force. Points: N per asset for a cube (24 vertices, far fewer than N), a UV sphere and a
 * single triangle; every point on the surface (distance to the nearest triangle < 1e-5 x the
 * size), its normal unit and that triangle's; even spacing (min nearest-neighbour distance
 * >= 0.5 x the mean); radii = the largest distance to the vertices of the point's Voronoi
 * region (brute force), sqrt(A / (pi N)) for empty regions; deterministic for a seed.
 * Tables: the 8 nearest by brute force and eq. 12 recomputed; a vertex at a point with its
 * normal takes that point first with the largest weight; a back-facing point gets weight 0;
 * fewer than 8 points repeat with weight 0; all back-facing falls back to the nearest. A
 * 100k-vertex sphere times the bake's cost (< 1 s for points and tables). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/sparse.h"
#include "check.h"
#include "util/clock.h"

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(undefined_behavior_sanitizer)
#define SANITIZED 1
#endif
#endif
#ifndef SANITIZED
#define SANITIZED 0
#endif

typedef struct mesh {
    lc_lcb_asset_vertex *v;
    uint32_t *idx;
    uint32_t nv, nt;
    double size; /* bounding-box diagonal */
} mesh;

static void mesh_free(mesh *m) {
    free(m->v);
    free(m->idx);
    memset(m, 0, sizeof *m);
}

static void mesh_alloc(mesh *m, uint32_t nv, uint32_t nt) {
    m->v = calloc(nv, sizeof *m->v);
    m->idx = calloc(3 * (size_t)nt, sizeof *m->idx);
    m->nv = nv, m->nt = nt;
}

/* The unit cube [0,1]^3 as 6 faces of 4 vertices with the face normal (as cube.obj imports). */
static void make_cube(mesh *m) {
    mesh_alloc(m, 24, 12);
    for (int f = 0; f < 6; f++) {
        int ax = f / 2, s = f % 2, u = (ax + 1) % 3, w = (ax + 2) % 3;
        for (int c = 0; c < 4; c++) {
            lc_lcb_asset_vertex *x = &m->v[4 * f + c];
            x->position[ax] = (float)s;
            x->position[u] = (float)(c == 1 || c == 2);
            x->position[w] = (float)(c >= 2);
            x->normal[ax] = s ? 1.0f : -1.0f;
        }
        /* counter-clockwise seen from outside: (u, w) is right-handed with +ax */
        static const uint32_t pos[6] = {0, 1, 2, 0, 2, 3}, neg[6] = {0, 2, 1, 0, 3, 2};
        for (int k = 0; k < 6; k++) m->idx[6 * f + k] = 4 * (uint32_t)f + (s ? pos[k] : neg[k]);
    }
    m->size = sqrt(3.0);
}

/* A UV sphere of radius r, nu x (nv_ + 1) vertices, smooth normals, outward faces. */
static void make_sphere(mesh *m, float r, int nu, int nvr) {
    mesh_alloc(m, (uint32_t)(nu * (nvr + 1)), (uint32_t)(2 * nu * (nvr - 1)));
    for (int j = 0; j <= nvr; j++)
        for (int i = 0; i < nu; i++) {
            double th = M_PI * j / nvr, ph = 2 * M_PI * i / nu;
            lc_lcb_asset_vertex *x = &m->v[j * nu + i];
            double n[3] = {sin(th) * cos(ph), cos(th), sin(th) * sin(ph)};
            for (int k = 0; k < 3; k++) x->position[k] = (float)(r * n[k]), x->normal[k] = (float)n[k];
        }
    uint32_t t = 0;
    for (int j = 0; j < nvr; j++)
        for (int i = 0; i < nu; i++) {
            uint32_t a = (uint32_t)(j * nu + i), b = (uint32_t)(j * nu + (i + 1) % nu), c = a + (uint32_t)nu,
                     d = b + (uint32_t)nu;
            if (j > 0) m->idx[3 * t] = a, m->idx[3 * t + 1] = b, m->idx[3 * t + 2] = c, t++;
            if (j < nvr - 1) m->idx[3 * t] = b, m->idx[3 * t + 1] = d, m->idx[3 * t + 2] = c, t++;
        }
    m->size = 2 * sqrt(3.0) * r;
}

static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Distance from p to triangle abc (Ericson, Real-Time Collision Detection 5.1.5). */
static double tri_dist(const float *pf, const float *af, const float *bf, const float *cf) {
    double p[3], a[3], b[3], c[3], ab[3], ac[3], ap[3], q[3];
    for (int k = 0; k < 3; k++) p[k] = pf[k], a[k] = af[k], b[k] = bf[k], c[k] = cf[k];
    for (int k = 0; k < 3; k++) ab[k] = b[k] - a[k], ac[k] = c[k] - a[k], ap[k] = p[k] - a[k];
    double d1 = dot3(ab, ap), d2 = dot3(ac, ap), d3, d4, d5, d6, bp[3], cp[3];
    for (int k = 0; k < 3; k++) bp[k] = p[k] - b[k], cp[k] = p[k] - c[k];
    d3 = dot3(ab, bp), d4 = dot3(ac, bp), d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    double va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
    if (d1 <= 0 && d2 <= 0) memcpy(q, a, sizeof q);
    else if (d3 >= 0 && d4 <= d3) memcpy(q, b, sizeof q);
    else if (d6 >= 0 && d5 <= d6) memcpy(q, c, sizeof q);
    else if (vc <= 0 && d1 >= 0 && d3 <= 0)
        for (int k = 0; k < 3; k++) q[k] = a[k] + d1 / (d1 - d3) * ab[k];
    else if (vb <= 0 && d2 >= 0 && d6 <= 0)
        for (int k = 0; k < 3; k++) q[k] = a[k] + d2 / (d2 - d6) * ac[k];
    else if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        for (int k = 0; k < 3; k++) q[k] = b[k] + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c[k] - b[k]);
    else {
        double den = 1 / (va + vb + vc), v = vb * den, w = vc * den;
        for (int k = 0; k < 3; k++) q[k] = a[k] + ab[k] * v + ac[k] * w;
    }
    double d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
    return sqrt(dot3(d, d));
}

static void tri_normal(const mesh *m, uint32_t t, double n[3]) {
    const float *a = m->v[m->idx[3 * t]].position, *b = m->v[m->idx[3 * t + 1]].position,
                *c = m->v[m->idx[3 * t + 2]].position;
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = e1[1] * e2[2] - e1[2] * e2[1], n[1] = e1[2] * e2[0] - e1[0] * e2[2], n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    double l = sqrt(dot3(n, n));
    for (int k = 0; k < 3; k++) n[k] /= l;
}

static double mesh_area(const mesh *m) {
    double a = 0;
    for (uint32_t t = 0; t < m->nt; t++) {
        const float *p = m->v[m->idx[3 * t]].position, *q = m->v[m->idx[3 * t + 1]].position,
                    *r = m->v[m->idx[3 * t + 2]].position;
        double e1[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]}, e2[3] = {r[0] - p[0], r[1] - p[1], r[2] - p[2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        a += 0.5 * sqrt(dot3(n, n));
    }
    return a;
}

static double d2f(const float *a, const float *b) {
    double dx = (double)a[0] - b[0], dy = (double)a[1] - b[1], dz = (double)a[2] - b[2];
    return dx * dx + dy * dy + dz * dz;
}

/* Every point on the surface with its triangle's normal. */
static void check_on_surface(const char *label, const mesh *m, const lc_lcb_sparse_point *p, uint32_t n) {
    uint32_t off = 0, bad_normal = 0;
    double worst = 0;
    for (uint32_t i = 0; i < n; i++) {
        double best = INFINITY, nl = sqrt(d2f(p[i].normal, (const float[3]){0, 0, 0}));
        int normal_ok = 0;
        for (uint32_t t = 0; t < m->nt; t++) {
            double d = tri_dist(p[i].position, m->v[m->idx[3 * t]].position, m->v[m->idx[3 * t + 1]].position,
                                m->v[m->idx[3 * t + 2]].position);
            best = fmin(best, d);
            if (d < 1e-5 * m->size) {
                double tn[3], pn[3] = {p[i].normal[0], p[i].normal[1], p[i].normal[2]};
                tri_normal(m, t, tn);
                normal_ok |= dot3(tn, pn) > 1 - 1e-6;
            }
        }
        worst = fmax(worst, best);
        off += best >= 1e-5 * m->size;
        bad_normal += !normal_ok || fabs(nl - 1) > 1e-6;
    }
    CHECK(off == 0, "%s: %u of %u points off the surface (worst %.3g, size %.3g)", label, off, n, worst, m->size);
    CHECK(bad_normal == 0, "%s: %u points without a unit normal equal to their triangle's", label, bad_normal);
}

/* Spacing and radii by brute force; returns min / mean nearest-neighbour distance. */
static double check_spacing_radii(const char *label, const mesh *m, const lc_lcb_sparse_point *p, uint32_t n,
                                  const lc_sparse_stats *st) {
    double sum = 0, lo = INFINITY;
    for (uint32_t i = 0; i < n; i++) {
        double best = INFINITY;
        for (uint32_t j = 0; j < n; j++)
            if (j != i) best = fmin(best, d2f(p[i].position, p[j].position));
        sum += sqrt(best), lo = fmin(lo, sqrt(best));
    }
    double mean = sum / n;
    CHECK(lo >= 0.5 * mean, "%s: min spacing %.4g < 0.5 x mean %.4g", label, lo, mean);
    CHECK_NEAR(st->min_spacing, lo, 1e-5);
    CHECK_NEAR(st->mean_spacing, mean, 1e-5);
    double *rmax = calloc(n, sizeof *rmax);
    for (uint32_t v = 0; v < m->nv; v++) {
        uint32_t best = 0;
        for (uint32_t j = 1; j < n; j++)
            if (d2f(m->v[v].position, p[j].position) < d2f(m->v[v].position, p[best].position)) best = j;
        rmax[best] = fmax(rmax[best], sqrt(d2f(m->v[v].position, p[best].position)));
    }
    double fallback = sqrt(mesh_area(m) / (M_PI * n));
    uint32_t empty = 0, bad = 0;
    for (uint32_t i = 0; i < n; i++) {
        double want = rmax[i] > 0 ? rmax[i] : fallback;
        empty += rmax[i] == 0;
        bad += fabs(p[i].radius - want) > 1e-5 * fmax(want, 1e-3) || !(p[i].radius > 0);
    }
    CHECK(bad == 0, "%s: %u radii differ from the Voronoi-region maximum / sqrt(A/(pi N)) = %.4g", label, bad,
          fallback);
    CHECK(st->empty_regions == empty, "%s: %u empty regions, brute force %u", label, st->empty_regions, empty);
    free(rmax);
    fprintf(stderr, "%s: %u points, spacing min/mean %.3f (%.4g / %.4g), %u empty regions, %.2f ms\n", label, n,
            lo / mean, lo, mean, empty, st->seconds * 1e3);
    return lo / mean;
}

static void test_points(const char *label, const mesh *m, uint32_t n) {
    lc_lcb_sparse_point *p = calloc(n, sizeof *p), *q = calloc(n, sizeof *q);
    lc_sparse_stats st;
    char err[256] = "";
    CHECK(lc_sparse_points(m->v, m->nv, m->idx, m->nt, n, 7, 3, p, &st, err, sizeof err) == 0, "%s: %s", label, err);
    CHECK_NEAR(st.area, mesh_area(m), 1e-9);
    CHECK(st.candidates == n * LC_SPARSE_CANDIDATES, "%s: %u candidates", label, st.candidates);
    uint32_t wrong_asset = 0;
    for (uint32_t i = 0; i < n; i++) wrong_asset += p[i].asset != 3;
    CHECK(wrong_asset == 0, "%s: every point names asset 3", label);
    check_on_surface(label, m, p, n);
    if (n > 1) check_spacing_radii(label, m, p, n, &st);
    CHECK(lc_sparse_points(m->v, m->nv, m->idx, m->nt, n, 7, 3, q, NULL, err, sizeof err) == 0, "%s again", label);
    CHECK(!memcmp(p, q, n * sizeof *p), "%s: same seed, same points", label);
    CHECK(lc_sparse_points(m->v, m->nv, m->idx, m->nt, n, 8, 3, q, NULL, err, sizeof err) == 0, "%s seed 8", label);
    CHECK(memcmp(p, q, n * sizeof *p) != 0, "%s: another seed, other points", label);
    free(p);
    free(q);
}

/* --- tables -------------------------------------------------------------------------------- */

/* Brute-force table of vertex v over points p (eq. 12, normalised, fallback nearest). */
static void brute_table(const lc_lcb_asset_vertex *v, const lc_lcb_sparse_point *p, uint32_t np,
                        lc_lcb_sparse_vertex *r) {
    uint32_t idx[8];
    double d2[8];
    uint32_t found = 0;
    for (uint32_t j = 0; j < np; j++) {
        double d = d2f(v->position, p[j].position);
        uint32_t k = found < 8 ? found++ : 8;
        if (k == 8 && !(d < d2[7])) continue;
        if (k == 8) k = 7;
        for (; k > 0 && d < d2[k - 1]; k--) d2[k] = d2[k - 1], idx[k] = idx[k - 1];
        d2[k] = d, idx[k] = j;
    }
    double nl = sqrt(d2f(v->normal, (const float[3]){0, 0, 0})), w[8], sum = 0, dmax = sqrt(d2[found - 1]);
    for (uint32_t k = 0; k < 8; k++) {
        if (k >= found) {
            r->index[k] = (uint16_t)idx[0], w[k] = 0;
            continue;
        }
        double c = 0;
        for (int a = 0; a < 3; a++) c += v->normal[a] / nl * p[idx[k]].normal[a];
        w[k] = (dmax > 0 ? 1 - sqrt(d2[k]) / dmax : 1) * fmin(fmax(c, 0), 1);
        r->index[k] = (uint16_t)idx[k];
        sum += w[k];
    }
    for (int k = 0; k < 8; k++) r->weight[k] = sum > 0 ? (float)(w[k] / sum) : (k == 0);
}

/* Tables of `stride`-th vertices against brute force: same indices (up to ties), weights. */
static void check_tables(const char *label, const mesh *m, const lc_lcb_sparse_point *p, uint32_t np,
                         const lc_lcb_sparse_vertex *t, uint32_t stride) {
    uint32_t bad_idx = 0, bad_w = 0, bad_sum = 0, n = 0;
    for (uint32_t i = 0; i < m->nv; i += stride, n++) {
        lc_lcb_sparse_vertex r;
        brute_table(&m->v[i], p, np, &r);
        double sum = 0;
        for (int k = 0; k < 8; k++) {
            double dg = d2f(m->v[i].position, p[t[i].index[k]].position),
                   db = d2f(m->v[i].position, p[r.index[k]].position);
            bad_idx += t[i].index[k] != r.index[k] && fabs(dg - db) > 1e-9 * fmax(db, 1e-12);
            bad_w += fabs(t[i].weight[k] - r.weight[k]) > 1e-5;
            sum += t[i].weight[k];
        }
        bad_sum += fabs(sum - 1) > 1e-5;
    }
    CHECK(bad_idx == 0, "%s: %u nearest-point indices differ from brute force (%u vertices)", label, bad_idx, n);
    CHECK(bad_w == 0, "%s: %u weights differ from eq. 12 by brute force", label, bad_w);
    CHECK(bad_sum == 0, "%s: %u vertices' weights do not sum to 1", label, bad_sum);
}

static void test_tables_sphere(void) {
    mesh m;
    make_sphere(&m, 0.5f, 48, 24);
    enum { N = 256 };
    static lc_lcb_sparse_point p[N];
    lc_lcb_sparse_vertex *t = calloc(m.nv, sizeof *t);
    char err[256] = "";
    lc_sparse_stats st;
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, m.nt, N, 1, 0, p, NULL, err, sizeof err) == 0, "points: %s", err);
    CHECK(lc_sparse_vertex_table(m.v, m.nv, p, N, t, &st, err, sizeof err) == 0, "table: %s", err);
    check_tables("sphere", &m, p, N, t, 1);
    /* a vertex at point 17 with its normal: point 17 first, the largest weight */
    lc_lcb_asset_vertex at = {{0}, {0}, {0}};
    memcpy(at.position, p[17].position, sizeof at.position);
    memcpy(at.normal, p[17].normal, sizeof at.normal);
    lc_lcb_sparse_vertex r;
    CHECK(lc_sparse_vertex_table(&at, 1, p, N, &r, NULL, err, sizeof err) == 0, "at 17: %s", err);
    CHECK(r.index[0] == 17, "a vertex at point 17 takes it first (%u)", r.index[0]);
    for (int k = 1; k < 8; k++)
        CHECK(r.weight[0] > r.weight[k], "weight[0] %g > weight[%d] %g", r.weight[0], k, r.weight[k]);
    CHECK(r.weight[7] == 0, "the farthest of the 8 has weight 0 (d = d_max): %g", r.weight[7]);
    free(t);
    mesh_free(&m);
}

/* Hand-made points around a vertex at the origin with normal +z. */
static void test_tables_cases(void) {
    lc_lcb_sparse_point p[10];
    memset(p, 0, sizeof p);
    for (int i = 0; i < 10; i++) {
        p[i].position[0] = 0.1f * (float)(i + 1);
        p[i].normal[2] = 1;
        p[i].radius = 0.05f;
    }
    p[2].normal[2] = -1; /* faces away */
    lc_lcb_asset_vertex v = {{0, 0, 0}, {0, 0, 2}, {0}};
    lc_lcb_sparse_vertex r;
    char err[256] = "";
    lc_sparse_stats st;
    CHECK(lc_sparse_vertex_table(&v, 1, p, 10, &r, &st, err, sizeof err) == 0, "table: %s", err);
    /* nearest 8: points 0..7, d_j = 0.1 (j+1), d_max = 0.8: w_j = 1 - (j+1)/8, w_2 = 0 */
    double sum = 0;
    for (int j = 0; j < 8; j++) sum += j == 2 ? 0 : 1 - (j + 1) / 8.0;
    for (int j = 0; j < 8; j++) {
        CHECK(r.index[j] == j, "index[%d] = %u", j, r.index[j]);
        CHECK_NEAR(r.weight[j], j == 2 ? 0 : (1 - (j + 1) / 8.0) / sum, 1e-6);
    }
    CHECK(r.weight[2] == 0, "the back-facing point has weight 0 (%g)", r.weight[2]);
    CHECK(st.fallback_vertices == 0, "no fallback");
    /* three points: the nearest repeated with weight 0 */
    CHECK(lc_sparse_vertex_table(&v, 1, p, 3, &r, &st, err, sizeof err) == 0, "table of 3: %s", err);
    for (int j = 3; j < 8; j++)
        CHECK(r.index[j] == 0 && r.weight[j] == 0, "slot %d: %u / %g", j, r.index[j], r.weight[j]);
    /* d = 0.1, 0.2, 0.3 (back-facing): w = 2/3, 1/3, 0 -> 2/3, 1/3 normalised to sum 1 */
    CHECK_NEAR(r.weight[0], 2.0 / 3, 1e-6);
    CHECK_NEAR(r.weight[1], 1.0 / 3, 1e-6);
    /* every point back-facing: the nearest alone, weight 1 */
    for (int i = 0; i < 10; i++) p[i].normal[2] = -1;
    CHECK(lc_sparse_vertex_table(&v, 1, p, 10, &r, &st, err, sizeof err) == 0, "all away: %s", err);
    CHECK(r.index[0] == 0 && r.weight[0] == 1, "fallback: nearest with weight 1 (%u, %g)", r.index[0], r.weight[0]);
    for (int j = 1; j < 8; j++) CHECK(r.weight[j] == 0, "fallback: weight[%d] = %g", j, r.weight[j]);
    CHECK(st.fallback_vertices == 1, "the fallback is counted (%u)", st.fallback_vertices);
    /* a single point: index 0, weight 1 (d = d_max, the all-zero fallback) */
    p[0].normal[2] = 1;
    CHECK(lc_sparse_vertex_table(&v, 1, p, 1, &r, &st, err, sizeof err) == 0, "one point: %s", err);
    CHECK(r.index[0] == 0 && r.weight[0] == 1, "one point: weight 1");
}

static void test_errors(void) {
    mesh m;
    make_cube(&m);
    lc_lcb_sparse_point p[4];
    char err[256];
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, m.nt, 0, 1, 0, p, NULL, err, sizeof err) == -1 && strstr(err, "0 points"),
          "0 points refused: %s", err);
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, m.nt, 65536, 1, 0, p, NULL, err, sizeof err) == -1 &&
              strstr(err, "65536 points"),
          "65536 points refused: %s", err);
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, 0, 4, 1, 0, p, NULL, err, sizeof err) == -1 && strstr(err, "0 triangles"),
          "no triangles refused: %s", err);
    m.idx[7] = 24;
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, m.nt, 4, 1, 0, p, NULL, err, sizeof err) == -1 &&
              strstr(err, "triangle 2 index 24"),
          "index out of range named: %s", err);
    m.idx[7] = 0;
    m.v[5].position[1] = NAN;
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, m.nt, 4, 1, 0, p, NULL, err, sizeof err) == -1 &&
              strstr(err, "vertex 5 position"),
          "non-finite vertex named: %s", err);
    mesh_free(&m);
    uint32_t flat[3] = {0, 0, 0};
    make_cube(&m);
    CHECK(lc_sparse_points(m.v, m.nv, flat, 1, 4, 1, 0, p, NULL, err, sizeof err) == -1 && strstr(err, "no area"),
          "no area refused: %s", err);
    lc_lcb_sparse_vertex r;
    CHECK(lc_sparse_vertex_table(m.v, 1, p, 0, &r, NULL, err, sizeof err) == -1 && strstr(err, "got 0"),
          "table of 0 points refused: %s", err);
    mesh_free(&m);
}

/* A 100k-vertex sphere: points and tables in well under a second (the bake runs them per asset). */
static void test_timing(void) {
    mesh m;
    make_sphere(&m, 1.0f, 400, 250);
    enum { N = 256 };
    static lc_lcb_sparse_point p[N];
    lc_lcb_sparse_vertex *t = calloc(m.nv, sizeof *t);
    lc_sparse_stats ps, ts;
    char err[256] = "";
    double t0 = lc_clock_ms();
    CHECK(lc_sparse_points(m.v, m.nv, m.idx, m.nt, N, 1, 0, p, &ps, err, sizeof err) == 0, "points: %s", err);
    CHECK(lc_sparse_vertex_table(m.v, m.nv, p, N, t, &ts, err, sizeof err) == 0, "table: %s", err);
    double ms = lc_clock_ms() - t0, limit = SANITIZED ? 20000 : 1000;
    fprintf(stderr, "timing: %u vertices, %u triangles, %u points: points %.1f ms, tables %.1f ms (limit %.0f ms)\n",
            m.nv, m.nt, N, ps.seconds * 1e3, ts.seconds * 1e3, limit);
    CHECK(ms < limit, "points + tables for %u vertices took %.0f ms", m.nv, ms);
    check_tables("sphere 100k", &m, p, N, t, 97);
    free(t);
    mesh_free(&m);
}

int main(void) {
    mesh m;
    make_cube(&m);
    test_points("cube", &m, 256);
    test_points("cube 1", &m, 1);
    mesh_free(&m);
    make_sphere(&m, 0.5f, 48, 24);
    test_points("sphere", &m, 256);
    test_points("sphere 2000", &m, 2000);
    mesh_free(&m);
    mesh_alloc(&m, 3, 1); /* one triangle: far fewer vertices and triangles than points */
    m.v[1].position[0] = 2, m.v[2].position[1] = 1;
    for (int i = 0; i < 3; i++) m.v[i].normal[2] = 1;
    m.idx[0] = 0, m.idx[1] = 1, m.idx[2] = 2;
    m.size = sqrt(5.0);
    test_points("triangle", &m, 256);
    mesh_free(&m);
    test_tables_sphere();
    test_tables_cases();
    test_errors();
    test_timing();
    CHECK_DONE();
}
