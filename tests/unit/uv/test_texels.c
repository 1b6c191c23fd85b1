/* test_texels: lightmap texel caches. Exact coverage on hand-made UVs (incl. centres lying
 * exactly on shared edges and vertices: each counted once), linear position mapping,
 * texel-ordered output, overlap handling, area ~ density^2, the footprint fill (rasterize
 * alone) and dilation covering every bilinear read inside a triangle, determinism across
 * thread counts, the Cornell box, and speed at conference-room scale. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bake/texels.h"
#include "bake/uvgen.h"
#include "check.h"

/* Every run but the determinism check's second one (1 thread) uses 2. */
#define TEXELS_TEST_THREADS 2

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---- scene building ------------------------------------------------------------------- */

typedef struct {
    lc_scene s;
    uint32_t cap_v, cap_t;
} builder;

static void init(builder *b) {
    memset(b, 0, sizeof *b);
    b->s.n_materials = 3;
    b->s.materials = calloc(3, sizeof(lc_material));
    const float col[3][3] = {{0.7f, 0.7f, 0.7f}, {0.6f, 0.1f, 0.1f}, {0.1f, 0.6f, 0.1f}};
    for (int i = 0; i < 3; i++) {
        memcpy(b->s.materials[i].base_color, col[i], sizeof col[i]);
        b->s.materials[i].base_texture = -1;
    }
}

static uint32_t add_v(builder *b, double x, double y, double z, double nx, double ny, double nz, double u, double v) {
    lc_mesh *m = &b->s.mesh;
    if (m->n_vertices == b->cap_v) {
        b->cap_v = b->cap_v ? 2 * b->cap_v : 64;
        m->position = realloc(m->position, 12 * (size_t)b->cap_v);
        m->normal = realloc(m->normal, 12 * (size_t)b->cap_v);
        m->uv0 = realloc(m->uv0, 8 * (size_t)b->cap_v);
        m->uv1 = realloc(m->uv1, 8 * (size_t)b->cap_v);
    }
    uint32_t i = m->n_vertices++;
    double l = sqrt(nx * nx + ny * ny + nz * nz);
    float *p = m->position + 3 * (size_t)i, *n = m->normal + 3 * (size_t)i;
    p[0] = (float)x, p[1] = (float)y, p[2] = (float)z;
    n[0] = (float)(nx / l), n[1] = (float)(ny / l), n[2] = (float)(nz / l);
    m->uv0[2 * (size_t)i] = m->uv0[2 * (size_t)i + 1] = 0;
    m->uv1[2 * (size_t)i] = (float)u, m->uv1[2 * (size_t)i + 1] = (float)v;
    return i;
}

static void add_t(builder *b, uint32_t a, uint32_t c, uint32_t d, uint32_t mat) {
    lc_mesh *m = &b->s.mesh;
    if (m->n_triangles == b->cap_t) {
        b->cap_t = b->cap_t ? 2 * b->cap_t : 64;
        m->index = realloc(m->index, 12 * (size_t)b->cap_t);
        m->material = realloc(m->material, 4 * (size_t)b->cap_t);
    }
    uint32_t t = m->n_triangles++;
    m->index[3 * (size_t)t] = a, m->index[3 * (size_t)t + 1] = c, m->index[3 * (size_t)t + 2] = d;
    m->material[t] = mat;
}

/* Quad in the y = 0 plane (normal +y) with world (x, z) = ((u - u0) / su, (v - v0) / sv)
 * over uv rect [u0, u1] x [v0, v1]; diagonal from (u0, v0) to (u1, v1) or the other one. */
static void add_uv_quad(builder *b, double u0, double v0, double u1, double v1, double size, int other_diag) {
    uint32_t q[4];
    double us[4] = {u0, u1, u1, u0}, vs[4] = {v0, v0, v1, v1};
    for (int k = 0; k < 4; k++)
        q[k] = add_v(b, (us[k] - u0) / (u1 - u0) * size, 0, (vs[k] - v0) / (v1 - v0) * size, 0, 1, 0, us[k], vs[k]);
    if (!other_diag) {
        add_t(b, q[0], q[2], q[1], 0);
        add_t(b, q[0], q[3], q[2], 0);
    } else {
        add_t(b, q[0], q[3], q[1], 0);
        add_t(b, q[1], q[3], q[2], 0);
    }
}

/* Rasterizes and returns the cache count (-1 on failure); lm/caches released. */
static long count_caches(const lc_scene *s, uint32_t W, uint32_t H) {
    lc_lightmap lm;
    lc_lcb_cache *c = NULL;
    uint32_t n = 0;
    char err[256];
    if (lc_texels_rasterize(s, W, H, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) != 0) return -1;
    free(c);
    lc_lightmap_release(&lm);
    return n;
}

/* Sum over triangles rasterized alone (a view of one triangle): equals the joint count iff no
 * centre is claimed by two triangles. */
static long sum_single(const lc_scene *s, uint32_t W, uint32_t H) {
    long sum = 0;
    for (uint32_t t = 0; t < s->mesh.n_triangles; t++) {
        lc_scene one = *s;
        one.mesh.index = s->mesh.index + 3 * (size_t)t;
        one.mesh.material = s->mesh.material + t;
        one.mesh.n_triangles = 1;
        long c = count_caches(&one, W, H);
        if (c < 0) return -1;
        sum += c;
    }
    return sum;
}

static void test_quad_exact(void) {
    builder b;
    init(&b);
    add_uv_quad(&b, 0.1, 0.1, 0.9, 0.9, 1.0, 0);
    lc_lightmap lm;
    lc_lcb_cache *c = NULL;
    uint32_t n = 0;
    char err[256];
    CHECK(lc_texels_rasterize(&b.s, 10, 10, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) == 0, "rasterize: %s",
          err);
    CHECK(n == 64 && lm.n_covered == 64, "quad [0.1,0.9]^2 on 10x10: %u caches, expected 8*8", n);
    uint32_t bad_order = 0, bad_map = 0, bad_pos = 0, bad_attr = 0;
    for (uint32_t i = 0; i < n; i++) {
        if (i && c[i].index <= c[i - 1].index) bad_order++;
        if (lm.texel_cache[c[i].index] != i) bad_map++;
        uint32_t x = c[i].index % 10, y = c[i].index / 10;
        double px = ((x + 0.5) / 10 - 0.1) / 0.8, pz = ((y + 0.5) / 10 - 0.1) / 0.8;
        if (fabs(c[i].position[0] - px) > 1e-5 || fabs(c[i].position[1]) > 1e-6 || fabs(c[i].position[2] - pz) > 1e-5)
            bad_pos++;
        if (c[i].flags != LC_CACHE_TEXEL || fabsf(c[i].normal[1] - 1) > 1e-6f || fabsf(c[i].albedo[0] - 0.7f) > 1e-6f)
            bad_attr++;
    }
    CHECK(bad_order == 0, "%u caches out of texel order", bad_order);
    CHECK(bad_map == 0, "%u texels not pointing at their cache", bad_map);
    CHECK(bad_pos == 0, "%u positions off the linear map", bad_pos);
    CHECK(bad_attr == 0, "%u caches with wrong flags/normal/albedo", bad_attr);
    /* a few closed-form positions */
    CHECK(c[0].index == 11, "first texel (1, 1): %u", c[0].index);
    CHECK_NEAR(c[0].position[0], 0.0625, 1e-6);
    CHECK_NEAR(c[63].position[2], 0.9375, 1e-6);
    /* the border ring touches the quad's footprint (texels 1..8): the fill takes it, each
     * texel from its nearest covered texel */
    uint32_t empty = 0, bad_fill = 0;
    for (uint32_t i = 0; i < 100; i++) {
        uint32_t x = i % 10, y = i / 10, cx = x < 1 ? 1 : x > 8 ? 8 : x, cy = y < 1 ? 1 : y > 8 ? 8 : y;
        if (lm.texel_cache[i] == LC_NONE) empty++;
        else if (c[lm.texel_cache[i]].index != cy * 10 + cx) bad_fill++;
    }
    CHECK(empty == 0 && lm.n_dilated == 36, "%u empty texels, %u filled, expected 0 and 36", empty, lm.n_dilated);
    CHECK(bad_fill == 0, "%u border texels not filled from the nearest covered texel", bad_fill);

    /* appending keeps earlier caches and offsets indices */
    lc_lightmap lm2;
    uint32_t n2 = n;
    CHECK(lc_texels_rasterize(&b.s, 10, 10, TEXELS_TEST_THREADS, &lm2, &c, &n2, err, sizeof err) == 0, "append: %s",
          err);
    CHECK(n2 == 128 && lm2.texel_cache[11] == 64 && c[64].index == 11, "append: n %u, texel 11 -> %u", n2,
          lm2.texel_cache[11]);
    free(c);
    lc_lightmap_release(&lm);
    lc_lightmap_release(&lm2);
    lc_scene_release(&b.s);
}

static void test_fill_rule(void) {
    /* centres (x + 0.5) / 8 = 0.0625 + x / 8: quad borders, the shared edge and both
     * diagonals pass exactly through texel centres */
    const double lo = 0.0625, hi = 0.9375, mid = 0.5625;
    for (int diag = 0; diag < 2; diag++) {
        builder b;
        init(&b);
        add_uv_quad(&b, lo, lo, mid, hi, 1, diag);
        add_uv_quad(&b, mid, lo, hi, hi, 1, !diag);
        long joint = count_caches(&b.s, 8, 8), single = sum_single(&b.s, 8, 8);
        /* 8 centres per axis on the closed range, one border of each pair owned: 7 x 7 */
        CHECK(joint == 49, "two quads on centre lines (diag %d): %ld texels, expected 49", diag, joint);
        CHECK(single == joint, "diag %d: per-triangle sum %ld != %ld (a centre counted twice)", diag, single, joint);
        lc_scene_release(&b.s);
    }
    /* full [0,1]^2 with the diagonal through every (i, i) centre */
    for (int diag = 0; diag < 2; diag++) {
        builder b;
        init(&b);
        add_uv_quad(&b, 0, 0, 1, 1, 1, diag);
        long joint = count_caches(&b.s, 8, 8), single = sum_single(&b.s, 8, 8);
        CHECK(joint == 64 && single == 64, "diagonal through centres: %ld joint, %ld summed, expected 64", joint,
              single);
        lc_scene_release(&b.s);
    }
    /* a fan of 8 triangles around a vertex sitting exactly on a centre, both windings */
    for (int flip = 0; flip < 2; flip++) {
        builder b;
        init(&b);
        double cx = 4.5 / 8, cy = 3.5 / 8, r = 2.0 / 8;
        uint32_t centre = add_v(&b, 0, 0, 0, 0, 1, 0, cx, cy), ring[8];
        for (int k = 0; k < 8; k++) {
            double a = 2 * M_PI * k / 8; /* ring vertices on centre lines too (k even) */
            ring[k] = add_v(&b, cos(a), 0, sin(a), 0, 1, 0, cx + r * round(cos(a) * 1e6) / 1e6,
                            cy + r * round(sin(a) * 1e6) / 1e6);
        }
        for (int k = 0; k < 8; k++) {
            if (flip) add_t(&b, centre, ring[(k + 1) % 8], ring[k], 0);
            else add_t(&b, centre, ring[k], ring[(k + 1) % 8], 0);
        }
        long joint = count_caches(&b.s, 8, 8), single = sum_single(&b.s, 8, 8);
        CHECK(joint == single, "fan (flip %d): joint %ld != per-triangle sum %ld", flip, joint, single);
        lc_lightmap lm;
        lc_lcb_cache *c = NULL;
        uint32_t n = 0;
        char err[256];
        CHECK(lc_texels_rasterize(&b.s, 8, 8, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) == 0, "fan: %s", err);
        CHECK(lm.texel_cache[3 * 8 + 4] != LC_NONE, "fan centre texel (4, 3) must be covered once");
        free(c);
        lc_lightmap_release(&lm);
        lc_scene_release(&b.s);
    }
}

/* Two adjacent triangles of a sub-texel chart from the conference room (316^2 atlas), a few
 * float ulps across and ~0.4/4096 texel from the centre of texel (68, 134): no float
 * triangle holds that centre. A 1/4096-texel snapping grid moved vertices onto it and
 * flipped one triangle, so both claimed it ("covered by more than one triangle"). */
static void test_tiny_chart(void) {
    builder b;
    init(&b);
    uint32_t v71 = add_v(&b, 0, 0, 0, 0, 1, 0, 0.216771752, 0.425632656);
    uint32_t v60 = add_v(&b, 1e-5, 0, 0, 0, 1, 0, 0.216771767, 0.425632536);
    uint32_t v58 = add_v(&b, 0, 0, 1e-5, 0, 1, 0, 0.216771901, 0.425632477);
    uint32_t v69 = add_v(&b, 1e-5, 0, 1e-5, 0, 1, 0, 0.216771901, 0.425632596);
    add_t(&b, v71, v60, v58, 0);
    add_t(&b, v69, v71, v58, 0);
    long joint = count_caches(&b.s, 316, 316), single = sum_single(&b.s, 316, 316);
    CHECK(joint == 0 && single == 0, "tiny chart: %ld joint, %ld summed centres, expected 0 (exact float UVs)", joint,
          single);
    lc_scene_release(&b.s);
}

static void test_overlap_and_errors(void) {
    builder b;
    init(&b);
    /* two triangles, identical uv1, different positions: the first keeps the texels */
    uint32_t a0 = add_v(&b, 0, 0, 0, 0, 1, 0, 0.1, 0.1), a1 = add_v(&b, 1, 0, 0, 0, 1, 0, 0.9, 0.1),
             a2 = add_v(&b, 0, 0, 1, 0, 1, 0, 0.1, 0.9);
    uint32_t b0 = add_v(&b, 5, 1, 0, 0, 1, 0, 0.1, 0.1), b1 = add_v(&b, 6, 1, 0, 0, 1, 0, 0.9, 0.1),
             b2 = add_v(&b, 5, 1, 1, 0, 1, 0, 0.1, 0.9);
    add_t(&b, a0, a2, a1, 1);
    add_t(&b, b0, b2, b1, 2);
    lc_lightmap lm;
    lc_lcb_cache *c = NULL;
    uint32_t n = 0;
    char err[256];
    CHECK(lc_texels_rasterize(&b.s, 16, 16, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) == 0, "overlap: %s",
          err);
    uint32_t from_second = 0;
    for (uint32_t i = 0; i < n; i++) from_second += c[i].position[0] > 2 || fabsf(c[i].albedo[1] - 0.6f) < 1e-6f;
    CHECK(n > 0 && from_second == 0, "overlap: %u of %u caches from the later triangle", from_second, n);
    free(c);
    c = NULL;
    lc_lightmap_release(&lm);
    CHECK(lc_texels_rasterize(&b.s, 0, 16, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) == -1 &&
              strstr(err, "size"),
          "size 0: %s", err);
    free(b.s.mesh.uv1);
    b.s.mesh.uv1 = NULL;
    CHECK(lc_texels_rasterize(&b.s, 16, 16, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) == -1 &&
              strstr(err, "uv1"),
          "no uv1: %s", err);
    lc_scene_release(&b.s);
}

/* ---- generated atlases ------------------------------------------------------------------ */

static void make_box(builder *b, const double lo[3], const double hi[3], int inward) {
    /* 6 faces as quads, outward (or inward for a room) */
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            int u = (axis + 1) % 3, v = (axis + 2) % 3;
            double n[3] = {0, 0, 0};
            n[axis] = (side ? 1 : -1) * (inward ? -1 : 1);
            uint32_t q[4];
            for (int k = 0; k < 4; k++) {
                double p[3];
                p[axis] = side ? hi[axis] : lo[axis];
                p[u] = (k == 1 || k == 2) ? hi[u] : lo[u];
                p[v] = (k >= 2) ? hi[v] : lo[v];
                q[k] = add_v(b, p[0], p[1], p[2], n[0], n[1], n[2], 0, 0);
            }
            /* (u, v) is right-handed with axis: CCW seen from +axis */
            int ccw_pos = (n[axis] > 0);
            uint32_t mat = axis == 0 ? 1 + side : 0;
            if (ccw_pos) {
                add_t(b, q[0], q[1], q[2], mat);
                add_t(b, q[0], q[2], q[3], mat);
            } else {
                add_t(b, q[0], q[2], q[1], mat);
                add_t(b, q[0], q[3], q[2], mat);
            }
        }
}

static void make_sphere(builder *b, int seg, int stacks, double r) {
    uint32_t base = b->s.mesh.n_vertices;
    for (int i = 0; i <= stacks; i++)
        for (int j = 0; j <= seg; j++) {
            double th = M_PI * i / stacks, ph = 2 * M_PI * j / seg;
            double x = sin(th) * cos(ph), y = cos(th), z = sin(th) * sin(ph);
            add_v(b, r * x, r * y, r * z, x, y, z, 0, 0);
        }
    for (int i = 0; i < stacks; i++)
        for (int j = 0; j < seg; j++) {
            uint32_t a = base + i * (seg + 1) + j, c = a + seg + 1;
            if (i != 0) add_t(b, a, a + 1, c, 0);
            if (i != stacks - 1) add_t(b, a + 1, c + 1, c, 0);
        }
}

/* Closed conservative footprint of all triangles (texels whose closed square touches one),
 * from the float uv1 independently of texels.c. */
static uint8_t *footprint(const lc_scene *s, uint32_t W, uint32_t H) {
    const lc_mesh *m = &s->mesh;
    uint8_t *fp = calloc((size_t)W * H, 1);
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double x[3], y[3];
        for (int k = 0; k < 3; k++) {
            uint32_t v = m->index[3 * (size_t)t + k];
            x[k] = (double)m->uv1[2 * (size_t)v] * W;
            y[k] = (double)m->uv1[2 * (size_t)v + 1] * H;
        }
        double area = (x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]), sg = area >= 0 ? 1 : -1;
        int x0 = (int)floor(fmin(x[0], fmin(x[1], x[2]))), x1 = (int)floor(fmax(x[0], fmax(x[1], x[2])));
        int y0 = (int)floor(fmin(y[0], fmin(y[1], y[2]))), y1 = (int)floor(fmax(y[0], fmax(y[1], y[2])));
        for (int ty = y0; ty <= y1; ty++)
            for (int tx = x0; tx <= x1; tx++) {
                int in = 1;
                for (int e = 0; e < 3 && in; e++) {
                    double best = -INFINITY;
                    for (int q = 0; q < 4; q++) {
                        double px = tx + (q & 1), py = ty + (q >> 1);
                        int f = (e + 1) % 3;
                        best = fmax(best, sg * ((x[f] - x[e]) * (py - y[e]) - (y[f] - y[e]) * (px - x[e])));
                    }
                    if (best < 0) in = 0;
                }
                if (in && tx >= 0 && ty >= 0 && tx < (int)W && ty < (int)H) fp[(size_t)ty * W + tx] = 1;
            }
    }
    return fp;
}

/* Every texel a triangle touches (conservative) is filled, and bilinear reads at points
 * sampled inside every triangle (a barycentric grid incl. the edges) only touch filled
 * texels: no exception, also at needle tips. */
static void check_bilinear(const char *name, const lc_scene *s, const uint32_t *texel_cache, uint32_t W, uint32_t H) {
    uint64_t taps = 0;
    const lc_mesh *m = &s->mesh;
    uint32_t empty_fp = 0, empty_bilinear = 0;
    uint8_t *fp = footprint(s, W, H);
    for (size_t i = 0; i < (size_t)W * H; i++) empty_fp += fp[i] && texel_cache[i] == LC_NONE;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double x[3], y[3];
        for (int k = 0; k < 3; k++) {
            uint32_t v = m->index[3 * (size_t)t + k];
            x[k] = (double)m->uv1[2 * (size_t)v] * W;
            y[k] = (double)m->uv1[2 * (size_t)v + 1] * H;
        }
        const int S = 12;
        for (int i = 0; i <= S; i++)
            for (int j = 0; i + j <= S; j++) {
                double b1 = (double)i / S, b2 = (double)j / S, b0 = 1 - b1 - b2;
                double px = b0 * x[0] + b1 * x[1] + b2 * x[2] - 0.5, py = b0 * y[0] + b1 * y[1] + b2 * y[2] - 0.5;
                int fx = (int)floor(px), fy = (int)floor(py);
                for (int q = 0; q < 4; q++) {
                    int tx = fx + (q & 1), ty = fy + (q >> 1);
                    taps++;
                    if (tx < 0 || ty < 0 || tx >= (int)W || ty >= (int)H || texel_cache[(size_t)ty * W + tx] == LC_NONE)
                        empty_bilinear++;
                }
            }
    }
    CHECK(empty_fp == 0, "%s: %u footprint texels empty", name, empty_fp);
    CHECK(empty_bilinear == 0, "%s: %u of %llu bilinear taps read empty texels", name, empty_bilinear,
          (unsigned long long)taps);
    free(fp);
}

/* Fill provenance: a texel filled by rasterize copies a covered texel of its own footprint
 * component (charts' closed footprints are >= padding apart, so components never join two
 * charts); for a ring texel, the component of one of its footprint neighbours. Returns the
 * largest Chebyshev distance to the source. */
static uint32_t check_fill_source(const char *name, const lc_scene *s, const lc_lightmap *lm, const lc_lcb_cache *c) {
    const uint32_t W = lm->width, H = lm->height;
    const size_t N = (size_t)W * H;
    uint8_t *fp = footprint(s, W, H);
    uint32_t *comp = malloc(N * sizeof *comp), *stack = malloc(N * sizeof *stack), n_comp = 0;
    for (size_t i = 0; i < N; i++) comp[i] = UINT32_MAX;
    for (size_t i = 0; i < N; i++) { /* 8-connected labelling */
        if (!fp[i] || comp[i] != UINT32_MAX) continue;
        size_t top = 0;
        stack[top++] = (uint32_t)i;
        comp[i] = n_comp;
        while (top) {
            uint32_t j = stack[--top];
            long x = j % W, y = j / W;
            for (long dy = -1; dy <= 1; dy++)
                for (long dx = -1; dx <= 1; dx++) {
                    long nx = x + dx, ny = y + dy;
                    if (nx < 0 || ny < 0 || nx >= (long)W || ny >= (long)H) continue;
                    size_t k = (size_t)ny * W + (size_t)nx;
                    if (fp[k] && comp[k] == UINT32_MAX) {
                        comp[k] = n_comp;
                        stack[top++] = (uint32_t)k;
                    }
                }
        }
        n_comp++;
    }
    uint32_t bad = 0, far = 0;
    for (size_t i = 0; i < N; i++) {
        if (lm->texel_cache[i] == LC_NONE) continue;
        uint32_t o = c[lm->texel_cache[i]].index;
        if (o == i) continue;
        long x = (long)(i % W), y = (long)(i / W), d = labs((long)(o % W) - x);
        if (labs((long)(o / W) - y) > d) d = labs((long)(o / W) - y);
        if ((uint32_t)d > far) far = (uint32_t)d;
        int ok = 0;
        for (long dy = -1; dy <= 1 && !ok; dy++)
            for (long dx = -1; dx <= 1 && !ok; dx++) {
                long nx = x + dx, ny = y + dy;
                if (nx < 0 || ny < 0 || nx >= (long)W || ny >= (long)H) continue;
                size_t k = (size_t)ny * W + (size_t)nx;
                ok = fp[k] && comp[k] == comp[o];
            }
        if (!ok) bad++;
    }
    CHECK(bad == 0, "%s: %u filled texels copy a cache from outside their footprint component", name, bad);
    free(fp);
    free(comp);
    free(stack);
    return far;
}

/* uvgen + rasterize + dilate with all the invariants; returns covered texels. */
static uint32_t run_atlas(const char *name, builder *b, lc_uv_params p, int per_triangle) {
    p.threads = TEXELS_TEST_THREADS;
    lc_uv_stats st;
    char err[256];
    CHECK(lc_uvgen(&b->s.mesh, &p, &st, err, sizeof err) == 0, "%s: uvgen: %s", name, err);
    lc_lightmap lm;
    lc_lcb_cache *c = NULL;
    uint32_t n = 0;
    double t0 = now();
    CHECK(lc_texels_rasterize(&b->s, st.width, st.height, TEXELS_TEST_THREADS, &lm, &c, &n, err, sizeof err) == 0,
          "%s: %s", name, err);
    double t1 = now();
    const uint32_t W = st.width, H = st.height, n_fill = lm.n_dilated;
    /* rasterize alone already covers every bilinear read, from the right chart */
    check_bilinear(name, &b->s, lm.texel_cache, W, H);
    uint32_t far = check_fill_source(name, &b->s, &lm, c);
    uint32_t *before = malloc(4 * (size_t)W * H);
    memcpy(before, lm.texel_cache, 4 * (size_t)W * H);
    double t2 = now();
    lc_texels_dilate(&lm, 2, TEXELS_TEST_THREADS);
    double t3 = now();
    fprintf(stderr,
            "%s: %u tris, %ux%u, %u covered, %u filled (source up to %u texels away), %u dilated; "
            "rasterize %.3f s, dilate %.3f s\n",
            name, b->s.mesh.n_triangles, W, H, lm.n_covered, n_fill, far, lm.n_dilated - n_fill, t1 - t0, t3 - t2);
    CHECK(n == lm.n_covered && n > 0, "%s: %u caches, %u covered", name, n, lm.n_covered);
    /* owners and fill unchanged; a dilated texel copies the cache of a texel within 2 that
     * had it before dilation */
    uint32_t bad = 0, dil = 0, fill = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) {
        if (before[i] != LC_NONE) {
            fill += c[before[i]].index != i;
            if (lm.texel_cache[i] != before[i]) bad++;
        } else if (lm.texel_cache[i] != LC_NONE) {
            dil++;
            long x = (long)(i % W), y = (long)(i / W);
            int ok = 0;
            for (long dy = -2; dy <= 2 && !ok; dy++)
                for (long dx = -2; dx <= 2 && !ok; dx++)
                    if (x + dx >= 0 && y + dy >= 0 && x + dx < (long)W && y + dy < (long)H)
                        ok = before[(size_t)(y + dy) * W + (size_t)(x + dx)] == lm.texel_cache[i];
            if (!ok) bad++;
        }
    }
    CHECK(bad == 0 && fill == n_fill && fill + dil == lm.n_dilated,
          "%s: %u bad dilated texels, %u + %u vs n_dilated %u (%u from rasterize)", name, bad, fill, dil, lm.n_dilated,
          n_fill);
    uint32_t bad_cache = 0;
    for (uint32_t i = 0; i < n; i++) {
        float l =
            sqrtf(c[i].normal[0] * c[i].normal[0] + c[i].normal[1] * c[i].normal[1] + c[i].normal[2] * c[i].normal[2]);
        if (fabsf(l - 1) > 1e-4f || !isfinite(c[i].position[0]) || (i && c[i].index <= c[i - 1].index)) bad_cache++;
    }
    CHECK(bad_cache == 0, "%s: %u malformed caches", name, bad_cache);
    /* determinism: same bytes with one thread as with two */
    lc_lightmap lm2;
    lc_lcb_cache *c2 = NULL;
    uint32_t n2 = 0;
    CHECK(lc_texels_rasterize(&b->s, st.width, st.height, 1, &lm2, &c2, &n2, err, sizeof err) == 0, "%s", err);
    lc_texels_dilate(&lm2, 2, 1);
    CHECK(n2 == n && memcmp(c, c2, sizeof *c * n) == 0 &&
              memcmp(lm.texel_cache, lm2.texel_cache, 4 * (size_t)st.width * st.height) == 0,
          "%s: deterministic", name);
    if (per_triangle) {
        long single = sum_single(&b->s, st.width, st.height);
        CHECK(single == (long)n, "%s: per-triangle sum %ld != %u (texel counted twice)", name, single, n);
    }
    free(before);
    free(c);
    free(c2);
    lc_lightmap_release(&lm);
    lc_lightmap_release(&lm2);
    return n;
}

static void test_generated(void) {
    builder b;
    init(&b);
    double lo[3] = {0, 0, 0}, hi[3] = {1, 2, 0.5};
    make_box(&b, lo, hi, 0);
    uint32_t n =
        run_atlas("box/density32", &b, (lc_uv_params){.texels_per_metre = 32, .padding = 2, .chart_angle_deg = 30}, 1);
    double expect = 2 * (1 * 2 + 1 * 0.5 + 2 * 0.5) * 32 * 32;
    CHECK(fabs(n - expect) < 0.03 * expect, "box: %u texels vs area * density^2 = %.0f", n, expect);
    lc_scene_release(&b.s);

    init(&b);
    make_sphere(&b, 32, 32, 1);
    run_atlas("sphere/256", &b, (lc_uv_params){.atlas_size = 256, .padding = 2, .chart_angle_deg = 30}, 1);
    lc_scene_release(&b.s);

    init(&b);
    make_sphere(&b, 48, 40, 0.5);
    make_box(&b, (double[3]){1, 0, 0}, (double[3]){1.3, 0.2, 0.7}, 0);
    run_atlas("sphere+box/density", &b, (lc_uv_params){.texels_per_metre = 60, .padding = 2, .chart_angle_deg = 45}, 0);
    lc_scene_release(&b.s);
}

static void test_cornell(void) {
    char path[1024];
    check_source_path("scenes/cornell-box/cornell-box.obj", path, sizeof path);
    lc_scene s;
    memset(&s, 0, sizeof s);
    char err[512] = "";
    lc_import_params ip = {.scale = 1, .flip_winding = 0};
    builder b;
    init(&b);
    if (lc_scene_import(path, &ip, &s, err, sizeof err) == 0 && s.mesh.n_triangles > 0) {
        fprintf(stderr, "cornell: imported %u triangles\n", s.mesh.n_triangles);
        lc_scene_release(&b.s);
        b.s = s;
        free(b.s.mesh.uv1);
        b.s.mesh.uv1 = NULL;
    } else {
        /* import not available: an inward box room with two blocks stands in */
        fprintf(stderr, "cornell: import unavailable (%s); using a built box\n", err);
        make_box(&b, (double[3]){0, 0, 0}, (double[3]){0.556, 0.549, 0.559}, 1);
        make_box(&b, (double[3]){0.13, 0, 0.07}, (double[3]){0.29, 0.165, 0.23}, 0);
        make_box(&b, (double[3]){0.27, 0, 0.25}, (double[3]){0.43, 0.33, 0.41}, 0);
    }
    run_atlas("cornell/128", &b, (lc_uv_params){.atlas_size = 128, .padding = 2, .chart_angle_deg = 45}, 1);
    lc_scene_release(&b.s);
}

static void test_speed(void) {
    builder b;
    init(&b);
    int n = 406; /* ~330k triangles */
    for (int i = 0; i <= n; i++)
        for (int j = 0; j <= n; j++) {
            double x = (double)i / n * 10, z = (double)j / n * 10;
            add_v(&b, x, 0.3 * sin(3 * x) * cos(2.5 * z) + 0.1 * sin(11 * x + 7 * z), z, 0, 1, 0, 0, 0);
        }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            uint32_t a = i * (n + 1) + j, c = a + n + 1;
            add_t(&b, a, a + 1, c, 0);
            add_t(&b, a + 1, c + 1, c, 0);
        }
    run_atlas("terrain-330k/2048", &b, (lc_uv_params){.atlas_size = 2048, .padding = 2, .chart_angle_deg = 20}, 0);
    lc_scene_release(&b.s);
}

int main(void) {
    test_quad_exact();
    test_fill_rule();
    test_tiny_chart();
    test_overlap_and_errors();
    test_generated();
    test_cornell();
    test_speed();
    CHECK_DONE();
}
