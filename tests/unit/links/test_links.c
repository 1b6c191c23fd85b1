/* links: the cut covers the visible scene (closed box: 2 pi / 4 pi), solid angles and form
 * factors of a single patch match the analytic values, blockers remove links, results are
 * deterministic across thread counts, link packing round-trips. The hierarchy comes from a
 * small test-only kd builder so this test does not depend on hierarchy.c. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/hierarchy.h"
#include "bake/links.h"
#include "bake/rt.h"
#include "bake/surfels.h"
#include "check.h"
#include "util/half.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/rng.h"
#include "util/sh.h"
#include "util/vec.h"

/* --- geometry helpers ------------------------------------------------------------------------ */

typedef struct {
    lc_mesh mesh;
    uint32_t cap_v, cap_t;
    lc_lcb_surfel *surfels;
    uint32_t n_surfels, cap_s;
} world;

static void world_free(world *w) {
    free(w->mesh.position);
    free(w->mesh.normal);
    free(w->mesh.index);
    free(w->mesh.material);
    free(w->surfels);
    memset(w, 0, sizeof *w);
}

/* Frame (t, b) with t x b = n, so quads built on it face n. */
static void frame(lc_vec3 n, lc_vec3 *t, lc_vec3 *b) {
    lc_v3_basis(n, t, b);
    if (lc_v3_dot(lc_v3_cross(*t, *b), n) < 0) {
        lc_vec3 x = *t;
        *t = *b;
        *b = x;
    }
}

/* Square of side `size` centred at c facing n, split into sub x sub quads (2 triangles each). */
static void add_quad(world *w, lc_vec3 c, lc_vec3 n, float size_u, float size_v, int sub) {
    lc_vec3 t, b;
    frame(n, &t, &b);
    lc_mesh *m = &w->mesh;
    uint32_t nv = (uint32_t)((sub + 1) * (sub + 1)), nt = (uint32_t)(2 * sub * sub);
    if (m->n_vertices + nv > w->cap_v) {
        w->cap_v = (m->n_vertices + nv) * 2;
        m->position = realloc(m->position, (size_t)w->cap_v * 3 * sizeof(float));
        m->normal = realloc(m->normal, (size_t)w->cap_v * 3 * sizeof(float));
    }
    if (m->n_triangles + nt > w->cap_t) {
        w->cap_t = (m->n_triangles + nt) * 2;
        m->index = realloc(m->index, (size_t)w->cap_t * 3 * sizeof(uint32_t));
        m->material = realloc(m->material, (size_t)w->cap_t * sizeof(uint32_t));
    }
    uint32_t base = m->n_vertices;
    for (int j = 0; j <= sub; j++)
        for (int i = 0; i <= sub; i++) {
            float u = ((float)i / sub - 0.5f) * size_u, v = ((float)j / sub - 0.5f) * size_v;
            lc_vec3 p = lc_v3_add(c, lc_v3_add(lc_v3_scale(t, u), lc_v3_scale(b, v)));
            lc_v3_store(&m->position[3 * m->n_vertices], p);
            lc_v3_store(&m->normal[3 * m->n_vertices], n);
            m->n_vertices++;
        }
    for (int j = 0; j < sub; j++)
        for (int i = 0; i < sub; i++) {
            uint32_t a = base + (uint32_t)(j * (sub + 1) + i), bb = a + 1, cc = a + (uint32_t)(sub + 1), d = cc + 1;
            uint32_t *ix = &m->index[3 * m->n_triangles];
            ix[0] = a, ix[1] = bb, ix[2] = d;
            ix[3] = a, ix[4] = d, ix[5] = cc;
            m->material[m->n_triangles] = m->material[m->n_triangles + 1] = 0;
            m->n_triangles += 2;
        }
}

/* sub x sub surfels at the cell centres of the same square. */
static void add_surfels(world *w, lc_vec3 c, lc_vec3 n, float size, int sub) {
    lc_vec3 t, b;
    frame(n, &t, &b);
    uint32_t need = w->n_surfels + (uint32_t)(sub * sub);
    if (need > w->cap_s) {
        w->cap_s = need * 2;
        w->surfels = realloc(w->surfels, (size_t)w->cap_s * sizeof *w->surfels);
    }
    float cell = size / sub;
    for (int j = 0; j < sub; j++)
        for (int i = 0; i < sub; i++) {
            lc_lcb_surfel *s = &w->surfels[w->n_surfels++];
            memset(s, 0, sizeof *s);
            float u = ((float)i + 0.5f) * cell - 0.5f * size, v = ((float)j + 0.5f) * cell - 0.5f * size;
            lc_v3_store(s->position, lc_v3_add(c, lc_v3_add(lc_v3_scale(t, u), lc_v3_scale(b, v))));
            lc_v3_store(s->normal, n);
            s->albedo[0] = s->albedo[1] = s->albedo[2] = 0.5f;
            s->area = cell * cell;
            s->cache = LC_NONE;
        }
}

/* Unit cube [0,1]^3 with inward-facing walls, 8x8 quads and sub x sub surfels per wall. */
static void build_closed_box(world *w, int sub) {
    static const float faces[6][6] = {
        {0.5f, 0, 0.5f, 0, 1, 0},  {0.5f, 1, 0.5f, 0, -1, 0}, {0, 0.5f, 0.5f, 1, 0, 0},
        {1, 0.5f, 0.5f, -1, 0, 0}, {0.5f, 0.5f, 0, 0, 0, 1},  {0.5f, 0.5f, 1, 0, 0, -1},
    };
    for (int f = 0; f < 6; f++) {
        lc_vec3 c = lc_v3_load(faces[f]), n = lc_v3_load(faces[f] + 3);
        add_quad(w, c, n, 1, 1, 8);
        add_surfels(w, c, n, 1, sub);
    }
}

/* --- test-only hierarchy: median kd split, BFS node order, surfels reordered to DFS ---------- */

static int kd_axis;
static int kd_cmp(const void *a, const void *b) {
    float x = ((const lc_lcb_surfel *)a)->position[kd_axis], y = ((const lc_lcb_surfel *)b)->position[kd_axis];
    return (x > y) - (x < y);
}

static uint32_t kd_build(lc_lcb_surfel *s, uint32_t first, uint32_t count, lc_lcb_node *nodes, uint32_t *n) {
    uint32_t id = (*n)++;
    lc_lcb_node *nd = &nodes[id];
    memset(nd, 0, sizeof *nd);
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double c[3] = {0, 0, 0}, nn[3] = {0, 0, 0}, area = 0;
    for (uint32_t i = first; i < first + count; i++) {
        for (int a = 0; a < 3; a++) {
            lo[a] = fminf(lo[a], s[i].position[a]);
            hi[a] = fmaxf(hi[a], s[i].position[a]);
            c[a] += s[i].area * s[i].position[a];
            nn[a] += s[i].area * s[i].normal[a];
        }
        area += s[i].area;
    }
    double r = 0;
    for (int a = 0; a < 3; a++) nd->center[a] = (float)(c[a] / area), nd->normal[a] = (float)(nn[a] / area);
    for (uint32_t i = first; i < first + count; i++) {
        double d2 = 0;
        for (int a = 0; a < 3; a++) d2 += pow(s[i].position[a] - nd->center[a], 2);
        r = fmax(r, sqrt(d2));
    }
    nd->area = (float)area;
    nd->radius = (float)r * 1.0001f + 1e-6f;
    nd->first_surfel = first;
    nd->surfel_count = count;
    nd->child[0] = nd->child[1] = LC_NONE;
    if (count > 1) {
        int axis = 0;
        for (int a = 1; a < 3; a++)
            if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
        kd_axis = axis;
        qsort(s + first, count, sizeof *s, kd_cmp);
        uint32_t half = count / 2;
        uint32_t l = kd_build(s, first, half, nodes, n);
        uint32_t rr = kd_build(s, first + half, count - half, nodes, n);
        nodes[id].child[0] = l;
        nodes[id].child[1] = rr;
    }
    return id;
}

static void tree_build(lc_lcb_surfel *s, uint32_t n, lc_hierarchy *h) {
    uint32_t total = 2 * n - 1, cnt = 0;
    lc_lcb_node *dfs = malloc(total * sizeof *dfs);
    kd_build(s, 0, n, dfs, &cnt);
    /* Renumber breadth-first so node 0 is the root and children follow parents. */
    uint32_t *queue = malloc(total * sizeof *queue), *map = malloc(total * sizeof *map);
    uint32_t head = 0, tail = 0;
    queue[tail++] = 0;
    while (head < tail) {
        uint32_t id = queue[head];
        map[id] = head++;
        for (int k = 0; k < 2; k++)
            if (dfs[id].child[k] != LC_NONE) queue[tail++] = dfs[id].child[k];
    }
    h->nodes = malloc(total * sizeof *h->nodes);
    for (uint32_t i = 0; i < total; i++) {
        lc_lcb_node nd = dfs[queue[i]];
        for (int k = 0; k < 2; k++)
            if (nd.child[k] != LC_NONE) nd.child[k] = map[nd.child[k]];
        h->nodes[i] = nd;
    }
    h->n_nodes = total;
    h->levels = NULL;
    h->n_levels = 0;
    free(dfs);
    free(queue);
    free(map);
}

/* --- link helpers ---------------------------------------------------------------------------- */

static lc_rt *make_rt(const world *w) {
    char err[256];
    lc_rt *rt = lc_rt_create(&w->mesh, 2, err, sizeof err);
    CHECK(rt != NULL, "rt: %s", err);
    return rt;
}

static lc_lcb_cache texel_cache(lc_vec3 p, lc_vec3 n) {
    lc_lcb_cache c;
    memset(&c, 0, sizeof c);
    lc_v3_store(c.position, p);
    lc_v3_store(c.normal, n);
    c.flags = LC_CACHE_TEXEL;
    return c;
}

static lc_lcb_cache grid_cache(lc_vec3 p) {
    lc_lcb_cache c;
    memset(&c, 0, sizeof c);
    lc_v3_store(c.position, p);
    c.flags = LC_CACHE_GRID;
    return c;
}

/* Sum of link solid angles (factor * pi * A_node) of cache ci. */
static double cache_omega(const lc_hierarchy *h, const lc_lcb_link *links, uint32_t L, uint32_t ci) {
    double s = 0;
    for (uint32_t k = 0; k < L; k++) {
        const lc_lcb_link *lk = &links[(size_t)ci * L + k];
        s += (double)lk->factor * M_PI * h->nodes[lk->node].area;
    }
    return s;
}

/* Irradiance at normal n from radiance 1 on every linked surface, through the link cones.
 * For a texel cache all linked light lies in the upper hemisphere where max(0, cos) = cos,
 * a pure band-1 function whose SH gain is 2 * A_1 (A_1 = lc_sh_cosine_factor(1)); band 1
 * of each cone is h_1(cos alpha) * y_1m(dir), so this is exact up to the cone fit. */
static double cache_irradiance(const lc_hierarchy *h, const lc_lcb_link *links, uint32_t L, uint32_t ci,
                               const float n[3]) {
    double l1[3] = {0, 0, 0};
    float yn[4];
    lc_sh_eval(2, n, yn);
    for (uint32_t k = 0; k < L; k++) {
        const lc_lcb_link *lk = &links[(size_t)ci * L + k];
        if (lk->factor == 0) continue;
        float dir[3], ca, y[4];
        lc_link_unpack(lk->dir_cone, dir, &ca);
        double omega = (double)lk->factor * M_PI * h->nodes[lk->node].area;
        lc_sh_eval(2, dir, y);
        for (int m = 0; m < 3; m++) l1[m] += omega * lc_sh_cone_ratio(1, ca) * y[1 + m];
    }
    double e = 0;
    for (int m = 0; m < 3; m++) e += 2.0 * lc_sh_cosine_factor(1) * l1[m] * yn[1 + m];
    return e;
}

/* Exact solid angle of an a x b rectangle seen on its axis from distance d. */
static double rect_solid_angle(double a, double b, double d) {
    return 4.0 * asin(a * b / sqrt((a * a + 4 * d * d) * (b * b + 4 * d * d)));
}

/* Form factor from a differential area to a parallel a x b rectangle centred on its normal
 * at distance d: four corner rectangles of the classic closed form. */
static double rect_form_factor(double a, double b, double d) {
    double x = a / (2 * d), y = b / (2 * d);
    double sx = sqrt(1 + x * x), sy = sqrt(1 + y * y);
    double corner = (x / sx * atan(y / sx) + y / sy * atan(x / sy)) / (2 * M_PI);
    return 4 * corner;
}

/* --- tests ------------------------------------------------------------------------------------ */

static void test_pack_roundtrip(void) {
    lc_rng r = lc_rng_seed(7, 0);
    double worst_dir = 0, worst_a = 0;
    for (int i = 0; i < 20000; i++) {
        float z = 1 - 2 * lc_rng_float(&r), phi = 6.2831853f * lc_rng_float(&r);
        float s = sqrtf(fmaxf(0, 1 - z * z));
        float d[3] = {s * cosf(phi), s * sinf(phi), z}, alpha = (float)M_PI * lc_rng_float(&r);
        if (i < 6) { /* the axes, where the octahedral fold has its seams */
            memset(d, 0, sizeof d);
            d[i / 2] = i % 2 ? -1.0f : 1.0f;
        }
        float o[3], ca;
        lc_link_unpack(lc_link_pack(d, alpha), o, &ca);
        double dot = fmin(1.0, (double)d[0] * o[0] + (double)d[1] * o[1] + (double)d[2] * o[2]);
        worst_dir = fmax(worst_dir, acos(dot) * 180 / M_PI);
        worst_a = fmax(worst_a, fabs(acos(fmin(1.0, fmax(-1.0, (double)ca))) - alpha) * 180 / M_PI);
    }
    fprintf(stderr, "pack: worst direction error %.4f deg, worst alpha error %.4f deg\n", worst_dir, worst_a);
    CHECK(worst_dir < 0.1, "direction error %.4f deg", worst_dir);
    CHECK(worst_a < 0.7, "alpha error %.4f deg", worst_a);
}

static void test_surfel_solid_angle(void) {
    lc_lcb_surfel s;
    memset(&s, 0, sizeof s);
    s.normal[2] = 1;
    s.area = 1e-4f;
    float p[3] = {0, 0, 2}, up[3] = {0, 0, -1}, zero[3] = {0, 0, 0};
    double w = lc_links_surfel_solid_angle(&s, p, zero);
    CHECK_NEAR(w, 1e-4 / 4.0, 1e-3); /* far field: A / d^2 */
    /* disc of radius r at distance d: 2 pi (1 - d / sqrt(d^2 + r^2)) */
    s.area = (float)M_PI;
    CHECK_NEAR(lc_links_surfel_solid_angle(&s, p, zero), 2 * M_PI * (1 - 2 / sqrt(5.0)), 1e-5);
    s.area = 1e-4f;
    CHECK(lc_links_surfel_solid_angle(&s, p, up) > 0, "facing texel cache sees it");
    float down[3] = {0, 0, 1};
    CHECK(lc_links_surfel_solid_angle(&s, p, down) == 0, "behind the cache plane");
    float below[3] = {0, 0, -2};
    CHECK(lc_links_surfel_solid_angle(&s, below, zero) == 0, "surfel faces away");
    float side[3] = {1, 0, 1};
    CHECK_NEAR(lc_links_surfel_solid_angle(&s, side, zero), 1e-4 * cos(M_PI / 4) / 2.0, 1e-3);
    float inplane[3] = {1, 0, 0}, inplane_n[3] = {0, 0, 1};
    CHECK(lc_links_surfel_solid_angle(&s, inplane, inplane_n) == 0, "grazing / same plane");
}

static void test_closed_box(void) {
    world w = {0};
    build_closed_box(&w, 16);
    lc_hierarchy h;
    tree_build(w.surfels, w.n_surfels, &h);
    lc_rt *rt = make_rt(&w);
    if (!rt) return;
    lc_lcb_cache caches[10];
    uint32_t nc = 0;
    caches[nc++] = texel_cache(lc_v3(0.5f, 0, 0.5f), lc_v3(0, 1, 0));
    caches[nc++] = texel_cache(lc_v3(0.3f, 0.7f, 1), lc_v3(0, 0, -1));
    caches[nc++] = texel_cache(lc_v3(1, 0.25f, 0.6f), lc_v3(-1, 0, 0));
    caches[nc++] = texel_cache(lc_v3(0.8f, 1, 0.2f), lc_v3(0, -1, 0));
    caches[nc++] = texel_cache(lc_v3(0, 0.6f, 0.4f), lc_v3(1, 0, 0));
    uint32_t n_texel = nc;
    caches[nc++] = grid_cache(lc_v3(0.5f, 0.5f, 0.5f));
    caches[nc++] = grid_cache(lc_v3(0.3f, 0.6f, 0.7f));
    caches[nc++] = grid_cache(lc_v3(0.8f, 0.2f, 0.25f));
    lc_link_params prm = {256, 8, 16, 0, 42, 0, NULL, 0};
    lc_lcb_link *links = calloc((size_t)nc * prm.links_per_cache, sizeof *links);
    lc_link_stats st;
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, nc, &prm, links, NULL, &st) == 0, "build");
    double worst = 0;
    for (uint32_t c = 0; c < nc; c++) {
        double om = cache_omega(&h, links, prm.links_per_cache, c);
        double expect = c < n_texel ? 2 * M_PI : 4 * M_PI;
        fprintf(stderr, "closed box cache %u (%s): sum omega %.4f, expected %.4f (%.2f%%)\n", c,
                c < n_texel ? "texel" : "grid", om, expect, 100 * (om / expect - 1));
        CHECK(fabs(om / expect - 1) < 0.03, "cache %u: omega %.4f vs %.4f", c, om, expect);
        worst = fmax(worst, fabs(om / expect - 1));
        /* Order and padding: node-sorted visible links, then padding. */
        int padding = 0, sorted = 1;
        for (uint32_t k = 0; k < prm.links_per_cache; k++) {
            const lc_lcb_link *lk = &links[(size_t)c * prm.links_per_cache + k];
            if (lk->factor == 0) {
                padding = 1;
                CHECK(lk->node == 0 && lk->dir_cone == 0, "padding link is zero");
            } else {
                CHECK(!padding, "link after padding");
                if (k > 0 && links[(size_t)c * prm.links_per_cache + k - 1].factor > 0)
                    sorted &= links[(size_t)c * prm.links_per_cache + k - 1].node < lk->node;
            }
        }
        CHECK(sorted, "cache %u links sorted by node", c);
    }
    fprintf(stderr, "closed box: worst %.2f%%, mean links %.1f, mean omega %.3f, rays %llu\n", 100 * worst,
            st.mean_links_used, st.mean_solid_angle, (unsigned long long)st.rays);
    CHECK(st.rays > 0 && st.mean_links_used > 1, "stats filled");

    /* Fewer links: coarse nodes are sampled, not enumerated; the sum stays close. */
    lc_link_params coarse = {32, 8, 16, 0, 42, 0, NULL, 0};
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, nc, &coarse, links, NULL, &st) == 0, "build");
    for (uint32_t c = 0; c < nc; c++) {
        double om = cache_omega(&h, links, coarse.links_per_cache, c);
        double expect = c < n_texel ? 2 * M_PI : 4 * M_PI;
        fprintf(stderr, "closed box, 32 links, cache %u: %.2f%%\n", c, 100 * (om / expect - 1));
        CHECK(fabs(om / expect - 1) < 0.08, "32 links: cache %u omega %.4f vs %.4f", c, om, expect);
    }

    /* A cache flagged inside gets padding only. */
    caches[0].flags |= LC_CACHE_INSIDE;
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, 1, &coarse, links, NULL, NULL) == 0, "build");
    int zero = 1;
    for (uint32_t k = 0; k < coarse.links_per_cache; k++)
        zero &= links[k].factor == 0 && links[k].node == 0 && links[k].dir_cone == 0;
    CHECK(zero, "inside cache has padding links only");
    free(links);
    lc_rt_release(rt);
    free(h.nodes);
    world_free(&w);
}

/* One square patch (side a, 16x16 surfels) at z = 0 facing +z; caches on its axis. */
static void test_patch(void) {
    const float a = 0.5f;
    world w = {0};
    add_quad(&w, lc_v3(0, 0, 0), lc_v3(0, 0, 1), a, a, 2);
    add_surfels(&w, lc_v3(0, 0, 0), lc_v3(0, 0, 1), a, 16);
    lc_hierarchy h;
    tree_build(w.surfels, w.n_surfels, &h);
    lc_rt *rt = make_rt(&w);
    if (!rt) return;
    const float dists[3] = {1.0f, 0.5f, 0.3f};
    lc_lcb_cache caches[6];
    for (int i = 0; i < 3; i++) {
        caches[2 * i] = grid_cache(lc_v3(0, 0, dists[i]));
        caches[2 * i + 1] = texel_cache(lc_v3(0, 0, dists[i]), lc_v3(0, 0, -1));
    }
    lc_link_params prm = {32, 8, 16, 3, 9, 0, NULL, 0};
    uint32_t L = prm.links_per_cache, nsh = prm.sh_bands * prm.sh_bands;
    lc_lcb_link *links = calloc((size_t)6 * L, sizeof *links);
    uint16_t *sh = calloc((size_t)6 * L * nsh, sizeof *sh);
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, 6, &prm, links, sh, NULL) == 0, "build");
    for (int i = 0; i < 3; i++) {
        double d = dists[i];
        double om_exact = rect_solid_angle(a, a, d);
        double om_grid = cache_omega(&h, links, L, 2 * i), om_texel = cache_omega(&h, links, L, 2 * i + 1);
        double e_exact = M_PI * rect_form_factor(a, a, d);
        double e_links = cache_irradiance(&h, links, L, 2 * i + 1, caches[2 * i + 1].normal);
        fprintf(stderr,
                "patch d=%.1f: omega exact %.5f grid %.5f (%.2f%%) texel %.5f (%.2f%%); "
                "irradiance exact %.5f links %.5f (%.2f%%)\n",
                d, om_exact, om_grid, 100 * (om_grid / om_exact - 1), om_texel, 100 * (om_texel / om_exact - 1),
                e_exact, e_links, 100 * (e_links / e_exact - 1));
        CHECK(fabs(om_grid / om_exact - 1) < 0.02, "grid omega at d=%g: %.5f vs %.5f", d, om_grid, om_exact);
        CHECK(fabs(om_texel / om_exact - 1) < 0.02, "texel omega at d=%g: %.5f vs %.5f", d, om_texel, om_exact);
        CHECK(fabs(e_links / e_exact - 1) < 0.03, "irradiance at d=%g: %.5f vs %.5f", d, e_links, e_exact);
        /* SH links: band 0 is the solid angle again (c_0 = omega y_0 / (pi A)), and band-1
         * irradiance agrees with the cone links. */
        double om_sh = 0, e_sh = 0;
        float yn[4];
        lc_sh_eval(2, caches[2 * i + 1].normal, yn);
        for (uint32_t k = 0; k < L; k++) {
            size_t li = (size_t)(2 * i + 1) * L + k;
            double scale = M_PI * h.nodes[links[li].node].area;
            om_sh += lc_half_to_float(sh[li * nsh]) * scale / 0.28209479177387814;
            for (int m = 0; m < 3; m++)
                e_sh += 2 * lc_sh_cosine_factor(1) * lc_half_to_float(sh[li * nsh + 1 + m]) * scale * yn[1 + m];
        }
        CHECK(fabs(om_sh / om_exact - 1) < 0.02, "SH omega at d=%g: %.5f vs %.5f", d, om_sh, om_exact);
        CHECK(fabs(e_sh / e_exact - 1) < 0.03, "SH irradiance at d=%g: %.5f vs %.5f", d, e_sh, e_exact);
    }
    free(links);
    free(sh);
    lc_rt_release(rt);
    free(h.nodes);
    world_free(&w);
}

/* A blocker between cache and patch removes the links; half a blocker halves the sum. */
static void test_occlusion(void) {
    const float a = 0.5f, d = 1.0f;
    for (int variant = 0; variant < 2; variant++) {
        world w = {0};
        add_quad(&w, lc_v3(0, 0, 0), lc_v3(0, 0, 1), a, a, 2);
        add_surfels(&w, lc_v3(0, 0, 0), lc_v3(0, 0, 1), a, 16);
        if (variant == 0) /* full blocker halfway, larger than the patch's shadow */
            add_quad(&w, lc_v3(0, 0, d / 2), lc_v3(0, 0, 1), a, a, 1);
        else /* covers x < 0 as seen from the cache: shadows exactly the patch's left half */
            add_quad(&w, lc_v3(-a / 2, 0, d / 2), lc_v3(0, 0, -1), a, a, 1);
        lc_hierarchy h;
        tree_build(w.surfels, w.n_surfels, &h);
        lc_rt *rt = make_rt(&w);
        if (!rt) return;
        lc_lcb_cache caches[2] = {grid_cache(lc_v3(0, 0, d)), texel_cache(lc_v3(0, 0, d), lc_v3(0, 0, -1))};
        lc_link_params prm = {32, 8, 16, 0, 5, 0, NULL, 0};
        lc_lcb_link *links = calloc((size_t)2 * prm.links_per_cache, sizeof *links);
        CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, 2, &prm, links, NULL, NULL) == 0, "build");
        double full = rect_solid_angle(a, a, d);
        for (int c = 0; c < 2; c++) {
            double om = cache_omega(&h, links, prm.links_per_cache, (uint32_t)c);
            if (variant == 0) {
                int nonzero = 0;
                for (uint32_t k = 0; k < prm.links_per_cache; k++)
                    nonzero += links[(size_t)c * prm.links_per_cache + k].factor > 0;
                fprintf(stderr, "blocked patch, cache %d: %d links, omega %.6f\n", c, nonzero, om);
                CHECK(nonzero == 0, "blocked: cache %d has %d links", c, nonzero);
            } else {
                fprintf(stderr, "half-blocked patch, cache %d: omega %.5f, half of exact %.5f\n", c, om, full / 2);
                CHECK(fabs(om / (full / 2) - 1) < 0.03, "half blocked: %.5f vs %.5f", om, full / 2);
            }
        }
        free(links);
        lc_rt_release(rt);
        free(h.nodes);
        world_free(&w);
    }
}

/* Same bytes with 1 and 2 threads (and on a rerun). */
static void test_determinism(void) {
    world w = {0};
    build_closed_box(&w, 12);
    add_quad(&w, lc_v3(0.5f, 0.4f, 0.5f), lc_v3(0, 1, 0), 0.4f, 0.4f, 1); /* an occluder inside */
    add_quad(&w, lc_v3(0.5f, 0.4f, 0.5f), lc_v3(0, -1, 0), 0.4f, 0.4f, 1);
    lc_hierarchy h;
    tree_build(w.surfels, w.n_surfels, &h);
    lc_rt *rt = make_rt(&w);
    if (!rt) return;
    enum { NC = 200 };
    lc_lcb_cache caches[NC];
    lc_rng r = lc_rng_seed(3, 1);
    for (int i = 0; i < NC; i++) {
        lc_vec3 p =
            lc_v3(0.05f + 0.9f * lc_rng_float(&r), 0.05f + 0.9f * lc_rng_float(&r), 0.05f + 0.9f * lc_rng_float(&r));
        if (i % 2) {
            p.y = 0;
            caches[i] = texel_cache(p, lc_v3(0, 1, 0));
        } else {
            caches[i] = grid_cache(p);
        }
    }
    lc_link_params prm = {24, 4, 8, 2, 77, 64, NULL, 0};
    size_t nl = (size_t)NC * prm.links_per_cache, ns = nl * 4;
    lc_lcb_link *a = calloc(nl, sizeof *a), *b = calloc(nl, sizeof *b);
    uint16_t *sa = calloc(ns, sizeof *sa), *sb = calloc(ns, sizeof *sb);
    lc_link_stats st1, st2;
    uint32_t *seen1 = calloc(w.n_surfels, sizeof *seen1), *seen2 = calloc(w.n_surfels, sizeof *seen2);
    prm.threads = 1;
    prm.surfel_seen = seen1;
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, NC, &prm, a, sa, &st1) == 0, "build 1");
    prm.threads = 2;
    prm.surfel_seen = seen2;
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, NC, &prm, b, sb, &st2) == 0, "build 2");
    prm.surfel_seen = NULL;
    CHECK(memcmp(seen1, seen2, w.n_surfels * sizeof *seen1) == 0, "surfel_seen identical for 1 and 2 threads");
    uint64_t seen_sum = 0, seen_max = 0;
    for (uint32_t i = 0; i < w.n_surfels; i++) {
        seen_sum += seen1[i];
        if (seen1[i] > seen_max) seen_max = seen1[i];
    }
    CHECK(seen_sum > 0 && seen_max <= NC, "surfel_seen counts caches (sum %llu, max %llu of %d caches)",
          (unsigned long long)seen_sum, (unsigned long long)seen_max, NC);
    free(seen1);
    free(seen2);
    CHECK(memcmp(a, b, nl * sizeof *a) == 0, "links identical for 1 and 2 threads");
    CHECK(memcmp(sa, sb, ns * sizeof *sa) == 0, "link SH identical for 1 and 2 threads");
    CHECK(st1.rays == st2.rays && st1.mean_solid_angle == st2.mean_solid_angle, "stats identical");
    /* Another seed changes the sampled estimates (the test can tell). */
    prm.seed = 78;
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, caches, NC, &prm, b, sb, NULL) == 0, "build 3");
    CHECK(memcmp(a, b, nl * sizeof *a) != 0, "another seed gives other links");
    free(a);
    free(b);
    free(sa);
    free(sb);
    lc_rt_release(rt);
    free(h.nodes);
    world_free(&w);
}

static void test_bad_params(void) {
    world w = {0};
    add_quad(&w, lc_v3(0, 0, 0), lc_v3(0, 0, 1), 1, 1, 1);
    add_surfels(&w, lc_v3(0, 0, 0), lc_v3(0, 0, 1), 1, 2);
    lc_hierarchy h;
    tree_build(w.surfels, w.n_surfels, &h);
    lc_rt *rt = make_rt(&w);
    if (!rt) return;
    lc_lcb_cache c = grid_cache(lc_v3(0, 0, 1));
    lc_lcb_link links[8];
    uint16_t sh[8 * 81];
    lc_link_params zero_links = {0, 8, 16, 0, 1, 0, NULL, 0};
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, &c, 1, &zero_links, links, NULL, NULL) == -1,
          "links_per_cache 0 rejected");
    lc_link_params bands9 = {8, 8, 16, 9, 1, 0, NULL, 0};
    CHECK(lc_links_build(rt, w.surfels, w.n_surfels, &h, &c, 1, &bands9, links, sh, NULL) == -1, "9 SH bands rejected");
    lc_rt_release(rt);
    free(h.nodes);
    world_free(&w);
}

/* The real pipeline pieces (lc_surfels_generate, lc_hierarchy_build with both methods) on the
 * closed box: the cut still covers the visible sphere / hemisphere. */
static void test_closed_box_real(void) {
    world w = {0};
    build_closed_box(&w, 1); /* surfels from lc_surfels_generate instead of the grid */
    free(w.surfels);
    w.surfels = NULL;
    w.n_surfels = 0;
    lc_scene scene;
    memset(&scene, 0, sizeof scene);
    scene.mesh = w.mesh;
    lc_material mat;
    memset(&mat, 0, sizeof mat);
    snprintf(mat.name, sizeof mat.name, "grey");
    mat.base_color[0] = mat.base_color[1] = mat.base_color[2] = 0.5f;
    mat.base_texture = -1;
    scene.materials = &mat;
    scene.n_materials = 1;
    lc_scene_update_bounds(&scene);
    char err[256];
    lc_surfel_params sp = {3000, 2, 5, 0};
    uint32_t n = 0;
    lc_lcb_surfel *surfels = NULL;
    CHECK(lc_surfels_generate(&scene, &sp, &surfels, NULL, &n, err, sizeof err) == 0, "surfels: %s", err);
    lc_rt *rt = make_rt(&w);
    if (!surfels || !rt) goto done;
    lc_lcb_cache caches[4] = {
        texel_cache(lc_v3(0.5f, 0, 0.5f), lc_v3(0, 1, 0)),
        texel_cache(lc_v3(1, 0.3f, 0.6f), lc_v3(-1, 0, 0)),
        grid_cache(lc_v3(0.5f, 0.5f, 0.5f)),
        grid_cache(lc_v3(0.3f, 0.7f, 0.6f)),
    };
    lc_link_params prm = {512, 8, 16, 0, 42, 0, NULL, 0};
    lc_lcb_link *links = calloc((size_t)4 * prm.links_per_cache, sizeof *links);
    for (int method = 0; method < 2; method++) {
        lc_hierarchy h;
        memset(&h, 0, sizeof h);
        CHECK(lc_hierarchy_build(surfels, n, method ? LC_HIERARCHY_KDTREE : LC_HIERARCHY_AAC, 0, &h, NULL, err,
                                 sizeof err) == 0,
              "hierarchy: %s", err);
        if (!h.nodes) continue;
        CHECK(lc_links_build(rt, surfels, n, &h, caches, 4, &prm, links, NULL, NULL) == 0, "build");
        for (uint32_t c = 0; c < 4; c++) {
            double om = cache_omega(&h, links, prm.links_per_cache, c), expect = c < 2 ? 2 * M_PI : 4 * M_PI;
            fprintf(stderr, "real surfels (%u), %s, cache %u: sum omega %.4f expected %.4f (%.2f%%)\n", n,
                    method ? "kd-tree" : "AAC", c, om, expect, 100 * (om / expect - 1));
            CHECK(fabs(om / expect - 1) < 0.03, "%s cache %u: %.4f vs %.4f", method ? "kd" : "aac", c, om, expect);
        }
        lc_hierarchy_release(&h);
    }
    free(links);
done:
    lc_rt_release(rt);
    free(surfels);
    world_free(&w);
}

/* The lossless-transport bound gathers B straight from the probe rays' surfels: radiosity 1
 * on every wall of a closed box gives E = 1 at every texel cache (L = 1/pi over the whole
 * hemisphere); radiosity on the floor only gives B x the point-to-rectangle form factor at
 * the ceiling's centre. Grid and inside caches get 0. */
static void test_gather_bound(void) {
    world w = {0};
    build_closed_box(&w, 16);
    lc_rt *rt = make_rt(&w);
    if (!rt) return;
    lc_lcb_cache caches[6];
    caches[0] = texel_cache(lc_v3(0.5f, 1, 0.5f), lc_v3(0, -1, 0)); /* ceiling centre */
    caches[1] = texel_cache(lc_v3(0.3f, 0.7f, 1), lc_v3(0, 0, -1));
    caches[2] = texel_cache(lc_v3(1, 0.25f, 0.6f), lc_v3(-1, 0, 0));
    caches[3] = texel_cache(lc_v3(0.1f, 0, 0.9f), lc_v3(0, 1, 0));
    caches[4] = grid_cache(lc_v3(0.5f, 0.5f, 0.5f));
    caches[5] = texel_cache(lc_v3(0.5f, 0, 0.5f), lc_v3(0, 1, 0));
    caches[5].flags |= LC_CACHE_INSIDE;
    float *b = malloc((size_t)w.n_surfels * 3 * sizeof *b), e[6 * 3];
    for (uint32_t i = 0; i < 3 * w.n_surfels; i++) b[i] = 1.0f;
    CHECK(lc_links_gather_bound(rt, w.surfels, w.n_surfels, caches, 6, 1024, 7, 0, b, e) == 0, "gather");
    for (int c = 0; c < 4; c++)
        for (int k = 0; k < 3; k++)
            CHECK(fabsf(e[3 * c + k] - 1.0f) < 0.01f, "uniform box: cache %d E %.4f", c, e[3 * c + k]);
    for (int k = 0; k < 6; k++) CHECK(e[12 + k] == 0.0f, "grid and inside caches get 0 (%d: %g)", k, e[12 + k]);
    for (uint32_t i = 0; i < w.n_surfels; i++) {
        int floor = w.surfels[i].normal[1] > 0.5f;
        b[3 * i] = floor ? 2.0f : 0.0f, b[3 * i + 1] = floor ? 1.0f : 0.0f, b[3 * i + 2] = 0.0f;
    }
    CHECK(lc_links_gather_bound(rt, w.surfels, w.n_surfels, caches, 1, 4096, 7, 0, b, e) == 0, "gather floor");
    double ff = rect_form_factor(1, 1, 1);
    CHECK(fabs(e[0] / (2 * ff) - 1) < 0.02 && fabs(e[1] / ff - 1) < 0.02 && e[2] == 0.0f,
          "lit floor seen from the ceiling: E (%.4f %.4f %.4f) vs B x F = (%.4f %.4f 0)", e[0], e[1], e[2], 2 * ff, ff);
    CHECK(lc_links_gather_bound(rt, w.surfels, w.n_surfels, caches, 1, 0, 7, 0, b, e) == -1, "no probe rays: error");
    CHECK(lc_links_gather_bound(rt, w.surfels, w.n_surfels, caches, 1, 64, 7, 0, NULL, e) == -1, "no radiosity: error");
    free(b);
    lc_rt_release(rt);
    world_free(&w);
}

/* lc_links_texel_surfels: in the closed box every ray hits a wall, so a texel cache's weights
 * (cos x solid angle per ray / pi, summed per surfel) sum to the cosine-weighted hemisphere's
 * 1; each list is in strictly increasing surfel order with positive weights; an inside cache
 * gets none; sum weight x B is the bound at the same rays and seed; 1 and 2 threads give the
 * same bytes. */
static void test_texel_surfels(void) {
    world w = {0};
    build_closed_box(&w, 16);
    lc_rt *rt = make_rt(&w);
    if (!rt) return;
    lc_lcb_cache caches[4];
    caches[0] = texel_cache(lc_v3(0.5f, 1, 0.5f), lc_v3(0, -1, 0));
    caches[1] = texel_cache(lc_v3(0.3f, 0.7f, 1), lc_v3(0, 0, -1));
    caches[2] = texel_cache(lc_v3(0.5f, 0, 0.5f), lc_v3(0, 1, 0));
    caches[2].flags |= LC_CACHE_INSIDE;
    caches[3] = texel_cache(lc_v3(1, 0.25f, 0.6f), lc_v3(-1, 0, 0));
    uint32_t *first[2] = {NULL, NULL};
    lc_lcb_surfel_weight *list[2] = {NULL, NULL};
    uint64_t n[2] = {0, 0};
    for (int t = 0; t < 2; t++)
        CHECK(lc_links_texel_surfels(rt, w.surfels, w.n_surfels, caches, 4, 512, 7, t + 1, &first[t], &list[t],
                                     &n[t]) == 0,
              "texel surfels, %d threads", t + 1);
    float *b = malloc((size_t)w.n_surfels * 3 * sizeof *b), bound[4 * 3];
    if (!first[0] || !first[1] || !b) goto done;
    CHECK(n[0] == n[1] && memcmp(first[0], first[1], 5 * sizeof *first[0]) == 0 &&
              memcmp(list[0], list[1], n[0] * sizeof *list[0]) == 0,
          "1 and 2 threads give the same lists");
    CHECK(first[0][0] == 0 && first[0][4] == n[0] && first[0][3] == first[0][2], "offsets; the inside cache has none");
    for (uint32_t c = 0; c < 4; c++) {
        double sum = 0;
        int order = 1;
        for (uint32_t k = first[0][c]; k < first[0][c + 1]; k++) {
            sum += list[0][k].weight;
            order &= list[0][k].weight > 0 && (k == first[0][c] || list[0][k].surfel > list[0][k - 1].surfel);
        }
        CHECK(order, "cache %u: surfels in increasing order, weights > 0", c);
        if (c != 2) CHECK(fabs(sum - 1) < 0.01, "cache %u: weights sum to %.4f, the hemisphere's 1", c, sum);
    }
    for (uint32_t i = 0; i < w.n_surfels; i++) {
        int floor = w.surfels[i].normal[1] > 0.5f;
        b[3 * i] = floor ? 2.0f : 0.25f, b[3 * i + 1] = floor ? 1.0f : 0.5f, b[3 * i + 2] = 0.0f;
    }
    CHECK(lc_links_gather_bound(rt, w.surfels, w.n_surfels, caches, 4, 512, 7, 0, b, bound) == 0, "bound");
    for (uint32_t c = 0; c < 4; c++)
        for (int k = 0; k < 3; k++) {
            double e = 0;
            for (uint32_t j = first[0][c]; j < first[0][c + 1]; j++)
                e += (double)list[0][j].weight * b[3 * list[0][j].surfel + k];
            CHECK(fabs(e - bound[3 * c + k]) <= 1e-5 * (1 + fabs(e)), "cache %u channel %d: lists %.6f, bound %.6f", c,
                  k, e, bound[3 * c + k]);
        }
    uint32_t *f0 = NULL;
    lc_lcb_surfel_weight *l0 = NULL;
    uint64_t n0 = 1;
    CHECK(lc_links_texel_surfels(rt, w.surfels, w.n_surfels, caches, 4, 0, 7, 1, &f0, &l0, &n0) == -1 && !f0 && !l0 &&
              n0 == 0,
          "no rays: error, nothing returned");
done:
    for (int t = 0; t < 2; t++) {
        free(first[t]);
        free(list[t]);
    }
    free(b);
    lc_rt_release(rt);
    world_free(&w);
}

int main(void) {
    lc_progress_set_enabled(0);
    test_pack_roundtrip();
    test_surfel_solid_angle();
    test_closed_box();
    test_patch();
    test_occlusion();
    test_determinism();
    test_bad_params();
    test_closed_box_real();
    test_gather_bound();
    test_texel_surfels();
    CHECK_DONE();
}
