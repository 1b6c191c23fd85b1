/* test_uvgen: lightmap UV generation. Every generated atlas is checked independently:
 * no texel centre inside two triangles, conservative chart footprints >= padding apart and
 * from the border, uv1 in [0, 1], usage in (0, 1], every chart owns a texel centre,
 * determinism; plus chart counts, atlas-size mode, errors and speed. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bake/uvgen.h"
#include "check.h"

/* ---- mesh building ---------------------------------------------------------------------- */

typedef struct {
    lc_mesh m;
    uint32_t cap_v, cap_t;
} builder;

static uint32_t add_v(builder *b, double x, double y, double z, double nx, double ny, double nz) {
    if (b->m.n_vertices == b->cap_v) {
        b->cap_v = b->cap_v ? 2 * b->cap_v : 64;
        b->m.position = realloc(b->m.position, 3 * sizeof(float) * b->cap_v);
        b->m.normal = realloc(b->m.normal, 3 * sizeof(float) * b->cap_v);
        b->m.uv0 = realloc(b->m.uv0, 2 * sizeof(float) * b->cap_v);
    }
    uint32_t v = b->m.n_vertices++;
    float *p = b->m.position + 3 * (size_t)v, *n = b->m.normal + 3 * (size_t)v;
    p[0] = (float)x, p[1] = (float)y, p[2] = (float)z;
    double l = sqrt(nx * nx + ny * ny + nz * nz);
    if (l == 0) l = 1, nz = 1;
    n[0] = (float)(nx / l), n[1] = (float)(ny / l), n[2] = (float)(nz / l);
    b->m.uv0[2 * (size_t)v] = (float)x;
    b->m.uv0[2 * (size_t)v + 1] = (float)z;
    return v;
}

static void add_t(builder *b, uint32_t a, uint32_t c, uint32_t d) {
    if (b->m.n_triangles == b->cap_t) {
        b->cap_t = b->cap_t ? 2 * b->cap_t : 64;
        b->m.index = realloc(b->m.index, 3 * sizeof(uint32_t) * b->cap_t);
        b->m.material = realloc(b->m.material, sizeof(uint32_t) * b->cap_t);
    }
    uint32_t t = b->m.n_triangles++;
    b->m.index[3 * (size_t)t] = a, b->m.index[3 * (size_t)t + 1] = c, b->m.index[3 * (size_t)t + 2] = d;
    b->m.material[t] = t % 3;
}

/* quad p0 + s*e1 + t*e2, CCW seen from e1 x e2 */
static void add_quad(builder *b, const double p0[3], const double e1[3], const double e2[3]) {
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    uint32_t v[4];
    for (int k = 0; k < 4; k++) {
        double s = (k == 1 || k == 2), t = (k >= 2);
        v[k] = add_v(b, p0[0] + s * e1[0] + t * e2[0], p0[1] + s * e1[1] + t * e2[1], p0[2] + s * e1[2] + t * e2[2],
                     n[0], n[1], n[2]);
    }
    add_t(b, v[0], v[1], v[2]);
    add_t(b, v[0], v[2], v[3]);
}

static lc_mesh make_box(double sx, double sy, double sz) {
    builder b = {0};
    double o[3] = {0, 0, 0}, X[3] = {sx, 0, 0}, Y[3] = {0, sy, 0}, Z[3] = {0, 0, sz};
    double ox[3] = {sx, 0, 0}, oy[3] = {0, sy, 0}, oz[3] = {0, 0, sz};
    add_quad(&b, o, Y, X);  /* z = 0, normal -z */
    add_quad(&b, oz, X, Y); /* z = sz, +z */
    add_quad(&b, o, Z, Y);  /* x = 0, -x */
    add_quad(&b, ox, Y, Z); /* x = sx, +x */
    add_quad(&b, o, X, Z);  /* y = 0, -y */
    add_quad(&b, oy, Z, X); /* y = sy, +y */
    return b.m;
}

static lc_mesh make_sphere(int seg, int stacks, double r) {
    builder b = {0};
    for (int i = 0; i <= stacks; i++)
        for (int j = 0; j <= seg; j++) {
            double th = M_PI * i / stacks, ph = 2 * M_PI * j / seg;
            double x = sin(th) * cos(ph), y = cos(th), z = sin(th) * sin(ph);
            add_v(&b, r * x, r * y, r * z, x, y, z);
        }
    for (int i = 0; i < stacks; i++)
        for (int j = 0; j < seg; j++) {
            uint32_t a = i * (seg + 1) + j, c = a + seg + 1;
            if (i != 0) add_t(&b, a, a + 1, c);
            if (i != stacks - 1) add_t(&b, a + 1, c + 1, c);
        }
    return b.m;
}

/* Helicoid strip of `turns` turns: nearly flat, so one chart by angle, but its planar
 * projection covers the annulus `turns` times. */
static lc_mesh make_helicoid(double turns, int steps_per_turn) {
    builder b = {0};
    int n = (int)(turns * steps_per_turn);
    double pitch = 0.15;
    for (int i = 0; i <= n; i++) {
        double a = 2 * M_PI * i / steps_per_turn;
        for (int k = 0; k < 2; k++) {
            double r = k ? 1.0 : 0.5;
            add_v(&b, r * cos(a), pitch * a / (2 * M_PI), r * sin(a), 0, 1, 0);
        }
    }
    for (int i = 0; i < n; i++) {
        uint32_t a = 2 * i, c = a + 2;
        /* CCW seen from +y: angle grows from +x towards +z, i.e. clockwise from above; wind accordingly */
        add_t(&b, a, c, a + 1);
        add_t(&b, a + 1, c, c + 1);
    }
    return b.m;
}

static uint64_t rng_state = 0x12345678u;
static double rnd(void) {
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}

static lc_mesh make_tiny(int n) {
    builder b = {0};
    for (int i = 0; i < n; i++) {
        double c[3] = {rnd(), rnd(), rnd()}, s = 0.002 + 0.01 * rnd();
        uint32_t v[3];
        for (int k = 0; k < 3; k++) v[k] = add_v(&b, c[0] + s * rnd(), c[1] + s * rnd(), c[2] + s * rnd(), 0, 0, 0);
        add_t(&b, v[0], v[1], v[2]);
    }
    return b.m;
}

static lc_mesh make_two_quads(void) {
    builder b = {0};
    double p0[3] = {0, 0, 0}, p1[3] = {2, 0, 0}, e1[3] = {0, 0, 1}, e2[3] = {1, 0, 0};
    add_quad(&b, p0, e1, e2);
    add_quad(&b, p1, e1, e2);
    return b.m;
}

/* Bumpy height field: ~2*n*n triangles with many charts. */
static lc_mesh make_terrain(int n) {
    builder b = {0};
    for (int i = 0; i <= n; i++)
        for (int j = 0; j <= n; j++) {
            double x = (double)i / n * 10, z = (double)j / n * 10;
            double y = 0.3 * sin(3 * x) * cos(2.5 * z) + 0.1 * sin(11 * x + 7 * z);
            add_v(&b, x, y, z, 0, 1, 0);
        }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            uint32_t a = i * (n + 1) + j, c = a + n + 1;
            add_t(&b, a, a + 1, c);
            add_t(&b, a + 1, c + 1, c);
        }
    return b.m;
}

/* 1 x 1 plate (normal +y) on an n x n grid; every third cell holds a pyramid of height
 * `h` cells (4 faces at atan(2h) from the plate), sharing the cell's edges. */
static lc_mesh make_studded_plate(int n, double h) {
    builder b = {0};
    double c = 1.0 / n;
    for (int i = 0; i <= n; i++)
        for (int j = 0; j <= n; j++) add_v(&b, i * c, 0, j * c, 0, 1, 0);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            uint32_t a = i * (n + 1) + j, d = a + n + 1; /* a (i,j), a+1 (i,j+1), d (i+1,j), d+1 */
            if (i % 3 == 1 && j % 3 == 1) {
                uint32_t t = add_v(&b, (i + 0.5) * c, h * c, (j + 0.5) * c, 0, 1, 0);
                add_t(&b, a, a + 1, t);
                add_t(&b, a + 1, d + 1, t);
                add_t(&b, d + 1, d, t);
                add_t(&b, d, a, t);
            } else {
                add_t(&b, a, a + 1, d);
                add_t(&b, a + 1, d + 1, d);
            }
        }
    return b.m;
}

/* n x n quads of a flat 1 x 1 grid, each with its own four vertices jittered by `jitter`
 * metres: an asset with cracks. */
static lc_mesh make_cracked_grid(int n, double jitter) {
    builder b = {0};
    double c = 1.0 / n;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            uint32_t v[4];
            for (int k = 0; k < 4; k++) {
                double x = (i + (k == 1 || k == 2)) * c, z = (j + (k >= 2)) * c;
                v[k] =
                    add_v(&b, x + jitter * (rnd() - 0.5), jitter * (rnd() - 0.5), z + jitter * (rnd() - 0.5), 0, 1, 0);
            }
            add_t(&b, v[0], v[3], v[2]);
            add_t(&b, v[0], v[2], v[1]);
        }
    return b.m;
}

/* A strip bent by `deg` degrees around the z axis, in `seg` flat segments. */
static lc_mesh make_arc(double deg, int seg) {
    builder b = {0};
    for (int i = 0; i <= seg; i++) {
        double a = deg * M_PI / 180 * i / seg;
        add_v(&b, sin(a), cos(a), 0, sin(a), cos(a), 0);
        add_v(&b, sin(a), cos(a), 1, sin(a), cos(a), 0);
    }
    for (int i = 0; i < seg; i++) {
        uint32_t a = 2 * i, c = a + 2;
        add_t(&b, a, a + 1, c);
        add_t(&b, c, a + 1, c + 1);
    }
    return b.m;
}

static lc_mesh copy_mesh(const lc_mesh *s) {
    lc_mesh m = *s;
    m.position = malloc(12 * (size_t)s->n_vertices);
    memcpy(m.position, s->position, 12 * (size_t)s->n_vertices);
    m.normal = malloc(12 * (size_t)s->n_vertices);
    memcpy(m.normal, s->normal, 12 * (size_t)s->n_vertices);
    m.uv0 = malloc(8 * (size_t)s->n_vertices);
    memcpy(m.uv0, s->uv0, 8 * (size_t)s->n_vertices);
    m.uv1 = NULL;
    m.index = malloc(12 * (size_t)s->n_triangles);
    memcpy(m.index, s->index, 12 * (size_t)s->n_triangles);
    m.material = malloc(4 * (size_t)s->n_triangles);
    memcpy(m.material, s->material, 4 * (size_t)s->n_triangles);
    return m;
}

/* ---- independent verification ---------------------------------------------------------- */

static void tri_uv(const lc_mesh *m, uint32_t t, uint32_t W, uint32_t H, double x[3], double y[3]) {
    for (int k = 0; k < 3; k++) {
        uint32_t v = m->index[3 * (size_t)t + k];
        x[k] = (double)m->uv1[2 * (size_t)v] * W;
        y[k] = (double)m->uv1[2 * (size_t)v + 1] * H;
    }
}

static double orient(double ax, double ay, double bx, double by, double px, double py) {
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

static int find(uint32_t *p, uint32_t a) {
    while (p[a] != a) a = p[a] = p[p[a]];
    return (int)a;
}

typedef struct {
    uint64_t key;
    uint32_t v;
} kv;

static int cmp(const void *pa, const void *pb) {
    const kv *a = pa, *b = pb;
    if (a->key != b->key) return (a->key > b->key) - (a->key < b->key);
    return (a->v > b->v) - (a->v < b->v);
}

typedef struct {
    uint32_t n_components, double_covered, footprint_clash, gap_violations, border_violations, chartless;
    uint64_t footprint_texels;
} verify_result;

/* Checks the atlas independently of uvgen's own bookkeeping. Charts = components of
 * triangles sharing a uv1 position (exact), which is how a chart's seam-split vertices meet. */
static verify_result verify(const lc_mesh *m, uint32_t W, uint32_t H, uint32_t pad) {
    verify_result r = {0};
    uint32_t *parent = malloc(sizeof(uint32_t) * m->n_triangles);
    for (uint32_t t = 0; t < m->n_triangles; t++) parent[t] = t;
    /* weld by uv1 bits via sorting (vertex, key) */
    kv *k = malloc(sizeof(kv) * m->n_vertices);
    for (uint32_t v = 0; v < m->n_vertices; v++) {
        uint32_t a, b;
        memcpy(&a, &m->uv1[2 * (size_t)v], 4);
        memcpy(&b, &m->uv1[2 * (size_t)v + 1], 4);
        k[v] = (kv){((uint64_t)a << 32) | b, v};
    }
    qsort(k, m->n_vertices, sizeof(kv), cmp);
    uint32_t *canon = malloc(sizeof(uint32_t) * m->n_vertices);
    for (uint32_t i = 0; i < m->n_vertices; i++)
        canon[k[i].v] = (i > 0 && k[i].key == k[i - 1].key) ? canon[k[i - 1].v] : k[i].v;
    uint32_t *vt = malloc(sizeof(uint32_t) * m->n_vertices);
    memset(vt, 0xFF, sizeof(uint32_t) * m->n_vertices);
    for (uint32_t t = 0; t < m->n_triangles; t++)
        for (int c = 0; c < 3; c++) {
            uint32_t v = canon[m->index[3 * (size_t)t + c]];
            if (vt[v] == 0xFFFFFFFFu) vt[v] = t;
            else parent[find(parent, t)] = (uint32_t)find(parent, vt[v]);
        }
    uint32_t *comp = malloc(sizeof(uint32_t) * m->n_triangles);
    for (uint32_t t = 0; t < m->n_triangles; t++) comp[t] = (uint32_t)find(parent, t);
    for (uint32_t t = 0; t < m->n_triangles; t++) r.n_components += comp[t] == t;

    /* 1. centres strictly inside two triangles; centres per component */
    uint8_t *cover = calloc((size_t)W * H, 1);
    uint8_t *has_centre = calloc(m->n_triangles, 1);
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double x[3], y[3];
        tri_uv(m, t, W, H, x, y);
        double area = orient(x[0], y[0], x[1], y[1], x[2], y[2]);
        if (area == 0) continue;
        double s = area > 0 ? 1 : -1;
        int x0 = (int)floor(fmin(x[0], fmin(x[1], x[2]))), x1 = (int)ceil(fmax(x[0], fmax(x[1], x[2])));
        int y0 = (int)floor(fmin(y[0], fmin(y[1], y[2]))), y1 = (int)ceil(fmax(y[0], fmax(y[1], y[2])));
        for (int ty = y0 < 0 ? 0 : y0; ty <= y1 && ty < (int)H; ty++)
            for (int tx = x0 < 0 ? 0 : x0; tx <= x1 && tx < (int)W; tx++) {
                double px = tx + 0.5, py = ty + 0.5;
                double a = s * orient(x[1], y[1], x[2], y[2], px, py), b = s * orient(x[2], y[2], x[0], y[0], px, py),
                       c = s * orient(x[0], y[0], x[1], y[1], px, py);
                if (a >= 0 && b >= 0 && c >= 0) has_centre[comp[t]] = 1;
                if (a > 0 && b > 0 && c > 0) {
                    if (cover[(size_t)ty * W + tx]) r.double_covered++;
                    cover[(size_t)ty * W + tx] = 1;
                }
            }
    }
    for (uint32_t t = 0; t < m->n_triangles; t++)
        if (comp[t] == t && !has_centre[t]) r.chartless++;

    /* 2. conservative footprints labelled by component */
    uint32_t *label = malloc(sizeof(uint32_t) * (size_t)W * H);
    memset(label, 0xFF, sizeof(uint32_t) * (size_t)W * H);
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double x[3], y[3];
        tri_uv(m, t, W, H, x, y);
        double area = orient(x[0], y[0], x[1], y[1], x[2], y[2]), s = area >= 0 ? 1 : -1;
        int x0 = (int)floor(fmin(x[0], fmin(x[1], x[2]))), x1 = (int)floor(fmax(x[0], fmax(x[1], x[2])));
        int y0 = (int)floor(fmin(y[0], fmin(y[1], y[2]))), y1 = (int)floor(fmax(y[0], fmax(y[1], y[2])));
        for (int ty = y0 < 0 ? 0 : y0; ty <= y1 && ty < (int)H; ty++)
            for (int tx = x0 < 0 ? 0 : x0; tx <= x1 && tx < (int)W; tx++) {
                int in = 1;
                for (int e = 0; e < 3 && in && area != 0; e++) {
                    double best = -INFINITY;
                    for (int q = 0; q < 4; q++)
                        best = fmax(
                            best, s * orient(x[e], y[e], x[(e + 1) % 3], y[(e + 1) % 3], tx + (q & 1), ty + (q >> 1)));
                    if (best < 0) in = 0; /* touching (== 0) counts as in */
                }
                if (!in) continue;
                uint32_t *l = &label[(size_t)ty * W + tx];
                if (*l != 0xFFFFFFFFu && *l != comp[t]) r.footprint_clash++;
                *l = comp[t];
            }
    }
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            uint32_t l = label[(size_t)y * W + x];
            if (l == 0xFFFFFFFFu) continue;
            r.footprint_texels++;
            if (x < pad || y < pad || x >= W - pad || y >= H - pad) r.border_violations++;
            for (int dy = -(int)pad; dy <= (int)pad; dy++)
                for (int dx = -(int)pad; dx <= (int)pad; dx++) {
                    int nx = (int)x + dx, ny = (int)y + dy;
                    if (nx < 0 || ny < 0 || nx >= (int)W || ny >= (int)H) continue;
                    uint32_t o = label[(size_t)ny * W + nx];
                    if (o != 0xFFFFFFFFu && o != l) r.gap_violations++;
                }
        }
    free(parent);
    free(k);
    free(canon);
    free(vt);
    free(comp);
    free(cover);
    free(has_centre);
    free(label);
    return r;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int expect_growth; /* run_case: the charts cannot fit atlas_size, it must grow */

/* Runs uvgen twice on copies, checks determinism and the atlas; returns the stats. */
static lc_uv_stats run_case(const char *name, const lc_mesh *src, lc_uv_params p, int check_pack) {
    lc_mesh a = copy_mesh(src), b = copy_mesh(src);
    lc_uv_stats sa = {0}, sb = {0};
    char err[256] = "";
    double t0 = now();
    int rc = lc_uvgen(&a, &p, &sa, err, sizeof err);
    double t1 = now();
    CHECK(rc == 0, "%s: lc_uvgen failed: %s", name, err);
    if (rc != 0) {
        lc_mesh_release(&a);
        lc_mesh_release(&b);
        return sa;
    }
    fprintf(stderr, "%s: %u tris -> %u charts, %ux%u, %.2f texels/m, usage %.1f%%, %.3f s\n", name, a.n_triangles,
            sa.n_charts, sa.width, sa.height, sa.texels_per_metre, sa.usage * 100, t1 - t0);
    CHECK(lc_uvgen(&b, &p, &sb, err, sizeof err) == 0, "%s: second run: %s", name, err);
    CHECK(a.n_vertices == b.n_vertices && a.n_triangles == b.n_triangles, "%s: deterministic sizes", name);
    if (a.n_vertices == b.n_vertices) {
        CHECK(memcmp(a.uv1, b.uv1, 8 * (size_t)a.n_vertices) == 0, "%s: uv1 deterministic", name);
        CHECK(memcmp(a.index, b.index, 12 * (size_t)a.n_triangles) == 0, "%s: index deterministic", name);
    }
    CHECK(sa.n_charts == sb.n_charts && sa.width == sb.width && sa.height == sb.height, "%s: stats deterministic",
          name);
    CHECK(a.n_triangles == src->n_triangles, "%s: triangle count kept", name);
    CHECK(memcmp(a.material, src->material, 4 * (size_t)src->n_triangles) == 0, "%s: materials kept", name);
    /* triangles keep their corners' positions in order */
    uint32_t moved = 0;
    for (size_t i = 0; i < 3 * (size_t)a.n_triangles; i++)
        if (memcmp(a.position + 3 * (size_t)a.index[i], src->position + 3 * (size_t)src->index[i], 12) != 0) moved++;
    CHECK(moved == 0, "%s: %u corners changed position", name, moved);
    uint32_t bad_uv = 0;
    for (size_t i = 0; i < 2 * (size_t)a.n_vertices; i++)
        if (!(a.uv1[i] >= 0.0f && a.uv1[i] <= 1.0f)) bad_uv++;
    CHECK(bad_uv == 0, "%s: %u uv1 values outside [0, 1]", name, bad_uv);
    CHECK(sa.usage > 0 && sa.usage <= 1, "%s: usage %g in (0, 1]", name, sa.usage);
    CHECK(sa.width % 4 == 0 && sa.height % 4 == 0, "%s: atlas %ux%u multiple of 4", name, sa.width, sa.height);
    if (p.atlas_size && p.texels_per_metre == 0 && !expect_growth && sa.texels_per_metre > p.min_texels_per_metre)
        CHECK(sa.width == p.atlas_size && sa.height == p.atlas_size, "%s: atlas %ux%u honours atlas_size %u", name,
              sa.width, sa.height, p.atlas_size);
    if (expect_growth)
        CHECK(sa.width > p.atlas_size && sa.width == sa.height && sa.width <= 8192, "%s: atlas %ux%u grown from %u",
              name, sa.width, sa.height, p.atlas_size);
    if (check_pack) {
        verify_result v = verify(&a, sa.width, sa.height, p.padding);
        CHECK(v.double_covered == 0, "%s: %u texel centres inside two triangles", name, v.double_covered);
        CHECK(v.footprint_clash == 0, "%s: %u texels in two charts' footprints", name, v.footprint_clash);
        CHECK(v.gap_violations == 0, "%s: %u footprint texel pairs closer than padding %u", name, v.gap_violations,
              p.padding);
        CHECK(v.border_violations == 0, "%s: %u footprint texels within padding of the border", name,
              v.border_violations);
        CHECK(v.chartless == 0, "%s: %u charts own no texel centre", name, v.chartless);
        CHECK(v.n_components >= sa.n_charts, "%s: %u uv components < %u charts", name, v.n_components, sa.n_charts);
        CHECK_NEAR(sa.usage, (double)v.footprint_texels / ((double)sa.width * sa.height), 0.02);
    }
    lc_mesh_release(&a);
    lc_mesh_release(&b);
    return sa;
}

static void test_errors(void) {
    char err[256];
    lc_uv_stats s;
    lc_mesh cube = make_box(1, 1, 1);
    lc_uv_params ok = {.atlas_size = 64, .padding = 2, .chart_angle_deg = 30};
    lc_mesh empty = {0};
    CHECK(lc_uvgen(&empty, &ok, &s, err, sizeof err) == -1 && strstr(err, "empty"), "empty mesh: %s", err);
    lc_uv_params p = ok;
    p.padding = 1;
    CHECK(lc_uvgen(&cube, &p, &s, err, sizeof err) == -1 && strstr(err, "padding"), "padding: %s", err);
    p = ok;
    p.chart_angle_deg = 90;
    CHECK(lc_uvgen(&cube, &p, &s, err, sizeof err) == -1 && strstr(err, "chart_angle_deg"), "angle: %s", err);
    p = ok;
    p.chart_angle_deg = NAN;
    CHECK(lc_uvgen(&cube, &p, &s, err, sizeof err) == -1 && strstr(err, "chart_angle_deg"), "angle NaN: %s", err);
    p = ok;
    p.atlas_size = 0;
    CHECK(lc_uvgen(&cube, &p, &s, err, sizeof err) == -1 && strstr(err, "atlas_size"), "no mode: %s", err);
    p = ok;
    p.texels_per_metre = -3;
    CHECK(lc_uvgen(&cube, &p, &s, err, sizeof err) == -1 && strstr(err, "texels_per_metre"), "density: %s", err);
    p = ok;
    p.texels_per_metre = 1e6;
    CHECK(lc_uvgen(&cube, &p, &s, err, sizeof err) == -1 && strstr(err, "texels_per_metre"), "huge density: %s", err);
    float keep = cube.position[4];
    cube.position[4] = NAN;
    CHECK(lc_uvgen(&cube, &ok, &s, err, sizeof err) == -1 && strstr(err, "finite"), "NaN: %s", err);
    cube.position[4] = keep;
    /* more charts than even an 8192 atlas holds at padding 64 (each needs >= 65x65 texels) */
    lc_mesh many = make_tiny(16000);
    p = ok;
    p.padding = 64;
    CHECK(lc_uvgen(&many, &p, &s, err, sizeof err) == -1 && strstr(err, "atlas_size") && strstr(err, "8192"),
          "too many charts for any atlas: %s", err);
    lc_mesh_release(&many);
    CHECK(lc_uvgen_measure(&cube, &ok, &s, err, sizeof err) == -1 && strstr(err, "uv1"), "measure w/o uv1: %s", err);
    lc_mesh_release(&cube);
}

static void test_measure(void) {
    lc_mesh cube = make_box(1, 1, 1);
    lc_uv_params p = {.atlas_size = 128, .padding = 2, .chart_angle_deg = 30};
    lc_uv_stats s, g;
    char err[256];
    CHECK(lc_uvgen(&cube, &p, &g, err, sizeof err) == 0, "uvgen: %s", err);
    CHECK(lc_uvgen_measure(&cube, &p, &s, err, sizeof err) == 0, "measure: %s", err);
    CHECK(s.width == 128 && s.height == 128, "measure atlas %ux%u", s.width, s.height);
    CHECK_NEAR(s.usage, g.usage, 1e-9);
    CHECK_NEAR(s.texels_per_metre, g.texels_per_metre, 0.05);
    lc_uv_params d = {.texels_per_metre = 10, .padding = 2, .chart_angle_deg = 30};
    CHECK(lc_uvgen_measure(&cube, &d, &s, err, sizeof err) == 0, "measure density: %s", err);
    CHECK(s.width == 28 && s.height == 28, "sqrt(6) * 10 -> 28, got %u", s.width); /* 24.5 -> 28 */
    lc_mesh_release(&cube);
}

/* Fit mode with a minimum density: a 40 m box fitted into 64x64 would get ~0.6 texels/m; with
 * min_texels_per_metre 2 the charts are packed at 2 texels/m (the atlas grows), while a box
 * that fits above the minimum keeps atlas_size exactly. The same for an asset's own uv1. */
static void test_min_density(void) {
    lc_mesh hall = make_box(40, 10, 40);
    lc_uv_params p = {.atlas_size = 64, .min_texels_per_metre = 2, .padding = 2, .chart_angle_deg = 30};
    lc_uv_stats s = run_case("hall/min-density", &hall, p, 1);
    CHECK(s.texels_per_metre == 2 && s.width > 64, "hall packed %ux%u at %.3f texels/m, expected the minimum 2",
          s.width, s.height, s.texels_per_metre);
    /* the box's 4000 m^2 at 2 texels/m: at least 16000 footprint texels */
    CHECK(s.usage * s.width * s.height >= 16000, "hall footprint %g texels < 4000 m^2 x 4",
          s.usage * s.width * s.height);
    lc_mesh small = make_box(1, 1, 1);
    s = run_case("cube/min-density-unused", &small, p, 1);
    CHECK(s.width == 64 && s.texels_per_metre > 2, "a 1 m cube keeps 64x64 (%ux%u, %.1f texels/m)", s.width, s.height,
          s.texels_per_metre);
    /* the hall's own uv1 (as an asset would bring them), measured at atlas 64: grown too */
    lc_mesh own = copy_mesh(&hall);
    lc_uv_params fit = {.atlas_size = 64, .padding = 2, .chart_angle_deg = 30};
    lc_uv_stats g, m;
    char err[256];
    CHECK(lc_uvgen(&own, &fit, &g, err, sizeof err) == 0, "uvgen: %s", err);
    CHECK(lc_uvgen_measure(&own, &p, &m, err, sizeof err) == 0, "measure: %s", err);
    CHECK(m.texels_per_metre >= 1.99 && m.texels_per_metre < 2.2 && m.width > 64,
          "own uv1 measured with the minimum: %ux%u at %.3f texels/m (fit gave %.3f)", m.width, m.height,
          m.texels_per_metre, g.texels_per_metre);
    lc_mesh_release(&own);
    lc_mesh_release(&small);
    lc_mesh_release(&hall);
}

/* One chart that mixes tilts (density mode, 2 texels/m, chart angle 45): a 4 x 4 m floor and a
 * 4 x 1 m strip rising at 35 degrees from its edge. Scaled by the chart's average stretch the
 * strip's texels were 8% farther apart than 0.5 m; scaled by the 90% quantile no texel is. */
static void test_mixed_tilt(void) {
    builder b = {0};
    const double c = cos(35 * M_PI / 180), sn = sin(35 * M_PI / 180);
    double o[3] = {0, 0, 0}, zf[3] = {0, 0, 4}, x4[3] = {4, 0, 0}, top[3] = {0, 0, 4}, up[3] = {0, sn, c};
    add_quad(&b, o, zf, x4);
    add_quad(&b, top, up, x4);
    lc_uv_params p = {.texels_per_metre = 2, .padding = 2, .chart_angle_deg = 45};
    lc_uv_stats s;
    char err[256];
    CHECK(lc_uvgen(&b.m, &p, &s, err, sizeof err) == 0, "uvgen: %s", err);
    fprintf(stderr, "mixed tilt: %u chart(s), texel spacing mean %.4f p95 %.4f max %.4f m\n", s.n_charts,
            s.spacing_mean, s.spacing_p95, s.spacing_max);
    CHECK(s.n_charts == 1, "floor and strip in one chart (%u)", s.n_charts);
    CHECK(s.spacing_max <= 0.5 * 1.001 && s.spacing_p95 <= 0.5 * 1.001,
          "no texel more than 0.5 m apart: p95 %.4f, max %.4f", s.spacing_p95, s.spacing_max);
    CHECK(s.spacing_mean > 0.4, "the chart is not scaled more than it needs (mean %.4f m)", s.spacing_mean);
    lc_mesh_release(&b.m);
}

int main(void) {
    test_errors();
    test_mixed_tilt();
    test_measure();
    test_min_density();

    lc_uv_params atlas = {.atlas_size = 256, .padding = 2, .chart_angle_deg = 30};
    lc_uv_params dens = {.texels_per_metre = 40, .padding = 3, .chart_angle_deg = 30};

    lc_mesh cube = make_box(1, 1, 1);
    lc_uv_stats s = run_case("cube/atlas", &cube, atlas, 1);
    CHECK(s.n_charts == 6, "cube at 30 degrees: %u charts, expected 6", s.n_charts);
    s = run_case("cube/density", &cube, dens, 1);
    CHECK(s.n_charts == 6, "cube density: %u charts", s.n_charts);
    CHECK(s.texels_per_metre == 40, "density kept");
    /* covered area ~ area * density^2: footprints include the partial border texels */
    CHECK(s.usage * s.width * s.height > 6 * 40 * 40 && s.usage * s.width * s.height < 6 * 42 * 42,
          "cube footprint texels %g vs 6*40^2", s.usage * s.width * s.height);
    lc_mesh_release(&cube);

    lc_mesh sph = make_sphere(32, 32, 1);
    CHECK(sph.n_triangles > 1900 && sph.n_triangles < 2100, "sphere %u triangles", sph.n_triangles);
    s = run_case("sphere/atlas", &sph, atlas, 1);
    CHECK(s.n_charts > 12, "sphere: %u charts, expected many", s.n_charts);
    lc_uv_params big = atlas;
    big.atlas_size = 1024;
    big.padding = 4;
    run_case("sphere/atlas1024", &sph, big, 1);
    run_case("sphere/density", &sph, dens, 1);
    lc_uv_params wide = atlas;
    wide.chart_angle_deg = 80; /* big charts: average normal may be unsafe, seed fallback */
    run_case("sphere/80deg", &sph, wide, 1);
    lc_mesh_release(&sph);

    lc_mesh hel = make_helicoid(2.5, 48);
    s = run_case("helicoid/atlas", &hel, atlas, 1);
    CHECK(s.n_charts >= 3, "helicoid must be split: %u charts", s.n_charts);
    run_case("helicoid/density", &hel, dens, 1);
    lc_mesh_release(&hel);

    lc_mesh tiny = make_tiny(3000);
    s = run_case("tiny/atlas", &tiny, (lc_uv_params){.atlas_size = 1024, .padding = 2, .chart_angle_deg = 45}, 1);
    CHECK(s.n_charts == 3000, "tiny: %u charts", s.n_charts);
    run_case("tiny/density", &tiny, (lc_uv_params){.texels_per_metre = 100, .padding = 2, .chart_angle_deg = 45}, 1);
    lc_mesh_release(&tiny);

    /* growth: 3000 disconnected charts cannot fit 64x64 with padding 2 (>= 9 texels each) */
    lc_mesh tiny64 = make_tiny(3000);
    expect_growth = 1;
    s = run_case("tiny/atlas64-grown", &tiny64, (lc_uv_params){.atlas_size = 64, .padding = 2, .chart_angle_deg = 45},
                 1);
    CHECK(s.n_charts == 3000 && s.width % 4 == 0 && s.width >= 164, "grown: %u charts in %ux%u", s.n_charts, s.width,
          s.height);
    s = run_case("tiny/atlas64-grown-pad4", &tiny64,
                 (lc_uv_params){.atlas_size = 64, .padding = 4, .chart_angle_deg = 45}, 1);
    lc_mesh sph8 = make_sphere(32, 32, 1);
    run_case("sphere/atlas16-grown", &sph8, (lc_uv_params){.atlas_size = 16, .padding = 8, .chart_angle_deg = 30}, 1);
    expect_growth = 0;
    lc_mesh_release(&sph8);
    lc_mesh_release(&tiny64);

    /* merging: pyramids (faces at 63 degrees) far below a texel join the plate's chart; at a
     * density where they span many texels they keep their own charts */
    lc_mesh plate = make_studded_plate(30, 1.0);
    s = run_case("studs/atlas64", &plate, (lc_uv_params){.atlas_size = 64, .padding = 2, .chart_angle_deg = 30}, 1);
    CHECK(s.n_charts == 1, "sub-texel pyramids merged into the plate: %u charts", s.n_charts);
    s = run_case("studs/density300", &plate,
                 (lc_uv_params){.texels_per_metre = 300, .padding = 2, .chart_angle_deg = 30}, 1);
    CHECK(s.n_charts > 300, "pyramids of many texels keep their faces: %u charts", s.n_charts);
    lc_mesh_release(&plate);

    /* welding: quads with cracks of ~1e-7 of the extent form one chart */
    lc_mesh cracked = make_cracked_grid(6, 2e-7);
    s = run_case("cracked", &cracked, atlas, 1);
    CHECK(s.n_charts == 1, "cracked grid welded: %u charts", s.n_charts);
    lc_mesh_release(&cracked);
    /* ... but real gaps (1e-3 of the extent) are not welded */
    cracked = make_cracked_grid(3, 0);
    for (uint32_t v = 0; v < cracked.n_vertices; v++) cracked.position[3 * v] += (float)(1e-3 * (v / 4));
    s = run_case("gaps", &cracked, atlas, 1);
    CHECK(s.n_charts == 9, "9 separate quads: %u charts", s.n_charts);
    lc_mesh_release(&cracked);

    /* running average normal: an 80 degree bend is one chart at 45 degrees (against the seed
     * normal it took two) */
    lc_mesh arc = make_arc(80, 16);
    s = run_case("arc80", &arc, (lc_uv_params){.atlas_size = 128, .padding = 2, .chart_angle_deg = 45}, 1);
    CHECK(s.n_charts == 1, "80 degree arc at 45 degrees: %u charts", s.n_charts);
    lc_mesh_release(&arc);

    lc_mesh two = make_two_quads();
    s = run_case("two-quads", &two, atlas, 1);
    CHECK(s.n_charts == 2, "two disconnected coplanar quads: %u charts", s.n_charts);
    lc_mesh_release(&two);

    lc_mesh ter = make_terrain(40);
    run_case("terrain-3k", &ter, (lc_uv_params){.atlas_size = 512, .padding = 2, .chart_angle_deg = 20}, 1);
    lc_mesh_release(&ter);

    /* speed: ~330k triangles (conference-room scale) */
    ter = make_terrain(406);
    double t0 = now();
    s = run_case("terrain-330k", &ter, (lc_uv_params){.atlas_size = 2048, .padding = 2, .chart_angle_deg = 20}, 1);
    fprintf(stderr, "terrain-330k incl. two runs and verification: %.2f s\n", now() - t0);
    lc_mesh_release(&ter);

    CHECK_DONE();
}
