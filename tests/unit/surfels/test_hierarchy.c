/* Hierarchy invariants (both methods), determinism across thread counts, AAC vs kd-tree
 * quality on a structured scene, and timing at 128k surfels (printed, not asserted). */
#include <stdint.h>
#include <time.h>

#include "bake/hierarchy.h"
#include "check.h"
#include "util/parallel.h"
#include "util/rng.h"

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void set_normal(lc_lcb_surfel *s, float x, float y, float z) {
    s->normal[0] = x;
    s->normal[1] = y;
    s->normal[2] = z;
}

/* Random positions in a 3x1x2 box, random unit normals, random areas. */
static lc_lcb_surfel *make_random(uint32_t n, uint64_t seed) {
    lc_lcb_surfel *s = calloc(n, sizeof *s);
    lc_rng r = lc_rng_seed(seed, 0);
    for (uint32_t i = 0; i < n; i++) {
        s[i].position[0] = 3 * lc_rng_float(&r);
        s[i].position[1] = lc_rng_float(&r);
        s[i].position[2] = 2 * lc_rng_float(&r);
        float z = 2 * lc_rng_float(&r) - 1, phi = 6.2831853f * lc_rng_float(&r), rr = sqrtf(fmaxf(0, 1 - z * z));
        set_normal(&s[i], rr * cosf(phi), rr * sinf(phi), z);
        s[i].area = 0.001f + 0.01f * lc_rng_float(&r);
        s[i].material = i;
        s[i].cache = LC_NONE;
    }
    return s;
}

/* Two parallel facing walls (x = 0 facing +x, x = 1 facing -x) and a floor (y = 0, +y),
 * each 1 x 1 m, jittered grid samples, equal areas. */
static lc_lcb_surfel *make_structured(uint32_t n, uint64_t seed) {
    lc_lcb_surfel *s = calloc(n, sizeof *s);
    lc_rng r = lc_rng_seed(seed, 1);
    for (uint32_t i = 0; i < n; i++) {
        float u = lc_rng_float(&r), v = lc_rng_float(&r);
        switch (i % 3) {
        case 0: /* floor */
            s[i].position[0] = u;
            s[i].position[1] = 0;
            s[i].position[2] = v;
            set_normal(&s[i], 0, 1, 0);
            break;
        case 1:
            s[i].position[0] = 0;
            s[i].position[1] = u;
            s[i].position[2] = v;
            set_normal(&s[i], 1, 0, 0);
            break;
        default:
            s[i].position[0] = 1;
            s[i].position[1] = u;
            s[i].position[2] = v;
            set_normal(&s[i], -1, 0, 0);
            break;
        }
        s[i].area = 3.0f / (float)n;
        s[i].material = i;
        s[i].cache = LC_NONE;
    }
    return s;
}

/* A corridor: walls 4 m long, 1 m high, only 0.5 m apart (x = 0 facing +x, x = 0.5 facing
 * -x) over a 0.5 x 4 m floor. Median splits along the corridor soon pair the opposite walls;
 * the PIC metric's normal term should keep them apart longer. */
static lc_lcb_surfel *make_corridor(uint32_t n, uint64_t seed) {
    lc_lcb_surfel *s = calloc(n, sizeof *s);
    lc_rng r = lc_rng_seed(seed, 2);
    for (uint32_t i = 0; i < n; i++) {
        float u = lc_rng_float(&r), v = lc_rng_float(&r);
        float *p = s[i].position;
        switch (i % 3) {
        case 0:
            p[0] = 0.5f * u, p[1] = 0, p[2] = 4 * v;
            set_normal(&s[i], 0, 1, 0);
            break;
        case 1:
            p[0] = 0, p[1] = u, p[2] = 4 * v;
            set_normal(&s[i], 1, 0, 0);
            break;
        default:
            p[0] = 0.5f, p[1] = u, p[2] = 4 * v;
            set_normal(&s[i], -1, 0, 0);
            break;
        }
        s[i].area = 10.0f / (float)n;
        s[i].cache = LC_NONE;
    }
    return s;
}

/* Counts violated invariants (also reported through CHECK when `report`). */
static int verify(const lc_lcb_surfel *orig, const lc_lcb_surfel *s, uint32_t n, const lc_hierarchy *h,
                  const uint32_t *perm, int report, const char *what) {
    int bad = 0;
#define V(cond, ...)                          \
    do {                                      \
        if (report) CHECK(cond, __VA_ARGS__); \
        if (!(cond)) bad++;                   \
    } while (0)
    V(h->n_nodes == 2 * n - 1, "%s: %u nodes for %u surfels", what, h->n_nodes, n);
    if (h->n_nodes != 2 * n - 1) return bad;
    V(h->n_levels >= 1 && h->levels[0] == 0 && h->levels[h->n_levels] == h->n_nodes, "%s: level bounds", what);
    for (uint32_t l = 0; l < h->n_levels; l++) V(h->levels[l] < h->levels[l + 1], "%s: empty level %u", what, l);
    V(h->levels[1] == 1, "%s: root level holds %u nodes", what, h->levels[1]);

    /* perm */
    uint8_t *seen = calloc(n, 1);
    int perm_ok = 1;
    for (uint32_t i = 0; i < n && perm; i++) {
        if (perm[i] >= n || seen[perm[i]]) perm_ok = 0;
        else seen[perm[i]] = 1;
    }
    V(perm_ok, "%s: perm is not a permutation", what);
    if (perm_ok && perm) {
        int same = 1;
        for (uint32_t i = 0; i < n; i++)
            if (memcmp(&s[i], &orig[perm[i]], sizeof *s) != 0) same = 0;
        V(same, "%s: surfels[i] != original[perm[i]]", what);
    }

    const lc_lcb_node *nd = h->nodes;
    uint32_t *parents = calloc(h->n_nodes, sizeof *parents);
    memset(seen, 0, n);
    uint32_t level = 0;
    double sum_area = 0;
    for (uint32_t i = 0; i < n; i++) sum_area += s[i].area;
    V(nd[0].first_surfel == 0 && nd[0].surfel_count == n, "%s: root range", what);
    V(fabs(nd[0].area - sum_area) <= 1e-5 * sum_area, "%s: root area %g vs %g", what, nd[0].area, sum_area);
    int bfs_ok = 1, range_ok = 1, attr_ok = 1, radius_ok = 1, leaf_ok = 1;
    for (uint32_t i = 0; i < h->n_nodes; i++) {
        while (level < h->n_levels && i >= h->levels[level + 1]) level++;
        const lc_lcb_node *x = &nd[i];
        if (x->first_surfel >= n || x->surfel_count == 0 || x->first_surfel + x->surfel_count > n) {
            range_ok = 0;
            continue;
        }
        if (x->child[0] == LC_NONE || x->child[1] == LC_NONE) {
            if (x->child[0] != x->child[1] || x->surfel_count != 1) leaf_ok = 0;
            if (x->surfel_count == 1) {
                if (seen[x->first_surfel]) leaf_ok = 0;
                seen[x->first_surfel] = 1;
                const lc_lcb_surfel *p = &s[x->first_surfel];
                if (memcmp(x->center, p->position, sizeof x->center) != 0 || x->area != p->area ||
                    memcmp(x->normal, p->normal, sizeof x->normal) != 0)
                    attr_ok = 0;
            }
        } else {
            uint32_t a = x->child[0], b = x->child[1];
            if (a >= h->n_nodes || b >= h->n_nodes || a <= i || b <= i) {
                bfs_ok = 0;
                continue;
            }
            /* children on the next level */
            if (level + 2 > h->n_levels || a < h->levels[level + 1] || b >= h->levels[level + 2]) bfs_ok = 0;
            parents[a]++;
            parents[b]++;
            const lc_lcb_node *ca = &nd[a], *cb = &nd[b];
            if (ca->first_surfel != x->first_surfel || cb->first_surfel != ca->first_surfel + ca->surfel_count ||
                ca->surfel_count + cb->surfel_count != x->surfel_count)
                range_ok = 0;
            double A = (double)ca->area + cb->area;
            if (fabs(x->area - A) > 1e-5 * A) attr_ok = 0;
            for (int c = 0; c < 3; c++) {
                double cc = (ca->area * (double)ca->center[c] + cb->area * (double)cb->center[c]) / A;
                double nn = (ca->area * (double)ca->normal[c] + cb->area * (double)cb->normal[c]) / A;
                if (fabs(cc - x->center[c]) > 1e-5 || fabs(nn - x->normal[c]) > 1e-5) attr_ok = 0;
            }
        }
        for (uint32_t j = x->first_surfel; j < x->first_surfel + x->surfel_count; j++) {
            double d = 0;
            for (int c = 0; c < 3; c++) {
                double e = (double)s[j].position[c] - x->center[c];
                d += e * e;
            }
            d = sqrt(d) + sqrt(s[j].area / M_PI);
            if (d > x->radius) radius_ok = 0;
        }
    }
    int parent_ok = parents[0] == 0;
    for (uint32_t i = 1; i < h->n_nodes; i++)
        if (parents[i] != 1) parent_ok = 0;
    int all_leaves = 1;
    for (uint32_t i = 0; i < n; i++)
        if (!seen[i]) all_leaves = 0;
    V(bfs_ok, "%s: children not after parents on the next level", what);
    V(parent_ok, "%s: a node is not referenced exactly once", what);
    V(range_ok, "%s: child ranges do not partition the parent's", what);
    V(leaf_ok && all_leaves, "%s: leaves malformed or a surfel not referenced by exactly one leaf", what);
    V(attr_ok, "%s: node center/area/normal inconsistent with children", what);
    V(radius_ok, "%s: radius does not cover all surfels", what);
    free(parents);
    free(seen);
#undef V
    return bad;
}

static void run_case(lc_lcb_surfel *(*make)(uint32_t, uint64_t), uint32_t n, lc_hierarchy_method m, const char *name) {
    char what[96], err[256] = "";
    snprintf(what, sizeof what, "%s n=%u %s", name, n, m == LC_HIERARCHY_AAC ? "aac" : "kd");
    lc_lcb_surfel *orig = make(n, 7), *s1 = malloc(sizeof *s1 * n), *s2 = malloc(sizeof *s2 * n);
    memcpy(s1, orig, sizeof *s1 * n);
    memcpy(s2, orig, sizeof *s2 * n);
    lc_hierarchy h1 = {0}, h2 = {0};
    uint32_t *p1 = NULL, *p2 = NULL;
    int rc1 = lc_hierarchy_build(s1, n, m, 1, &h1, &p1, err, sizeof err);
    CHECK(rc1 == 0, "%s: build failed: %s", what, err);
    int rc2 = lc_hierarchy_build(s2, n, m, 2, &h2, &p2, err, sizeof err);
    CHECK(rc2 == 0, "%s: build failed: %s", what, err);
    if (rc1 == 0 && rc2 == 0) {
        verify(orig, s1, n, &h1, p1, 1, what);
        CHECK(h1.n_nodes == h2.n_nodes && h1.n_levels == h2.n_levels &&
                  memcmp(h1.nodes, h2.nodes, sizeof *h1.nodes * h1.n_nodes) == 0 &&
                  memcmp(h1.levels, h2.levels, sizeof *h1.levels * (h1.n_levels + 1)) == 0 &&
                  memcmp(p1, p2, sizeof *p1 * n) == 0 && memcmp(s1, s2, sizeof *s1 * n) == 0,
              "%s: result differs between 1 and 2 threads", what);
        /* the verifier must catch broken trees */
        if (n >= 3) {
            lc_hierarchy bad = h1;
            bad.nodes = malloc(sizeof *bad.nodes * h1.n_nodes);
            memcpy(bad.nodes, h1.nodes, sizeof *bad.nodes * h1.n_nodes);
            bad.nodes[0].radius *= 0.5f;
            CHECK(verify(orig, s1, n, &bad, p1, 0, what) > 0, "%s: verifier missed a shrunk radius", what);
            memcpy(bad.nodes, h1.nodes, sizeof *bad.nodes * h1.n_nodes);
            uint32_t t = bad.nodes[0].child[0];
            bad.nodes[0].child[0] = bad.nodes[0].child[1];
            bad.nodes[0].child[1] = t;
            CHECK(verify(orig, s1, n, &bad, p1, 0, what) > 0, "%s: verifier missed swapped children", what);
            free(bad.nodes);
        }
    }
    lc_hierarchy_release(&h1);
    lc_hierarchy_release(&h2);
    free(p1);
    free(p2);
    free(orig);
    free(s1);
    free(s2);
}

static double build_quality(lc_lcb_surfel *(*make)(uint32_t, uint64_t), uint32_t n, lc_hierarchy_method m,
                            double *secs) {
    char err[256] = "";
    lc_lcb_surfel *s = make(n, 3);
    lc_hierarchy h = {0};
    double t0 = now_s();
    int rc = lc_hierarchy_build(s, n, m, 0, &h, NULL, err, sizeof err);
    *secs = now_s() - t0;
    CHECK(rc == 0, "build failed: %s", err);
    double q = rc == 0 ? lc_hierarchy_quality(s, &h) : 1e30;
    if (rc == 0)
        fprintf(stderr, "  n=%u %s: %.3f s, %u levels, quality %.6f\n", n, m == LC_HIERARCHY_AAC ? "aac" : "kd ", *secs,
                h.n_levels, q);
    lc_hierarchy_release(&h);
    free(s);
    return q;
}

/* A flush ceiling lamp (Cornell-box-like): a 2 x 2 m ceiling at y = 2 facing down, its
 * central 0.5 x 0.4 m patch an emissive material, other surfels non-emissive (two
 * materials), plus a floor. The AAC emission term must give the lamp its own subtree: some
 * node holds exactly the lamp surfels (without the term the lamp was clustered with the
 * ceiling and no node was lamp-only). Returns the number of lamp surfels. */
static uint32_t flush_lamp_case(uint32_t n, int *lamp_only_root, uint32_t *pure_nodes) {
    lc_lcb_surfel *s = calloc(n, sizeof *s);
    lc_rng r = lc_rng_seed(7, 3);
    uint32_t n_lamp = 0;
    for (uint32_t i = 0; i < n; i++) {
        float u = 2 * lc_rng_float(&r), v = 2 * lc_rng_float(&r);
        int ceiling = i % 2;
        s[i].position[0] = u, s[i].position[1] = ceiling ? 2.0f : 0.0f, s[i].position[2] = v;
        set_normal(&s[i], 0, ceiling ? -1.0f : 1.0f, 0);
        s[i].area = 8.0f / (float)n;
        s[i].material = ceiling ? 0 : 2;
        s[i].cache = LC_NONE;
        if (ceiling && fabsf(u - 1) < 0.25f && fabsf(v - 1) < 0.2f) {
            s[i].material = 1;
            s[i].emission[0] = 17, s[i].emission[1] = 12, s[i].emission[2] = 4;
            n_lamp++;
        }
    }
    lc_hierarchy h = {0};
    char err[256] = "";
    CHECK(lc_hierarchy_build(s, n, LC_HIERARCHY_AAC, 0, &h, NULL, err, sizeof err) == 0, "flush lamp: %s", err);
    *lamp_only_root = 0;
    *pure_nodes = 0;
    for (uint32_t i = 0; i < h.n_nodes; i++) {
        const lc_lcb_node *nd = &h.nodes[i];
        uint32_t lamp = 0;
        for (uint32_t j = nd->first_surfel; j < nd->first_surfel + nd->surfel_count; j++) lamp += s[j].material == 1;
        if (lamp == nd->surfel_count && nd->surfel_count > 1) (*pure_nodes)++;
        if (lamp == n_lamp && nd->surfel_count == n_lamp) *lamp_only_root = 1;
    }
    lc_hierarchy_release(&h);
    free(s);
    return n_lamp;
}

int main(void) {
    char err[256] = "";
    lc_hierarchy h = {0};
    lc_lcb_surfel one = {.position = {1, 2, 3}, .normal = {0, 1, 0}, .area = 0.5f};
    CHECK(lc_hierarchy_build(&one, 0, LC_HIERARCHY_AAC, 0, &h, NULL, err, sizeof err) == -1, "n = 0 must fail");
    CHECK(strstr(err, "n") != NULL, "error names the parameter: %s", err);
    CHECK(lc_hierarchy_build(&one, 1, LC_HIERARCHY_KDTREE, 0, &h, NULL, err, sizeof err) == 0, "n = 1: %s", err);
    CHECK(h.n_nodes == 1 && h.n_levels == 1 && h.nodes[0].child[0] == LC_NONE && h.nodes[0].surfel_count == 1 &&
              fabsf(h.nodes[0].radius - sqrtf(0.5f / (float)M_PI)) < 1e-6f,
          "n = 1: single leaf root");
    lc_hierarchy_release(&h);
    lc_lcb_surfel nan = one;
    nan.position[1] = NAN;
    CHECK(lc_hierarchy_build(&nan, 1, LC_HIERARCHY_AAC, 0, &h, NULL, err, sizeof err) == -1, "NaN position must fail");

    const uint32_t sizes[] = {1, 2, 3, 1000, 50000};
    for (int m = 0; m < 2; m++)
        for (size_t i = 0; i < sizeof sizes / sizeof *sizes; i++) {
            run_case(make_random, sizes[i], (lc_hierarchy_method)m, "random");
            run_case(make_structured, sizes[i], (lc_hierarchy_method)m, "structured");
            run_case(make_corridor, sizes[i], (lc_hierarchy_method)m, "corridor");
        }

    /* Coincident positions: Morton codes all equal, kd keys all tied. */
    {
        lc_lcb_surfel *s = make_structured(500, 1);
        for (uint32_t i = 0; i < 500; i++) s[i].position[0] = s[i].position[1] = s[i].position[2] = 0.25f;
        lc_lcb_surfel *c = malloc(sizeof *c * 500);
        for (int m = 0; m < 2; m++) {
            memcpy(c, s, sizeof *c * 500);
            uint32_t *perm = NULL;
            int rc = lc_hierarchy_build(c, 500, (lc_hierarchy_method)m, 0, &h, &perm, err, sizeof err);
            CHECK(rc == 0, "coincident: %s", err);
            if (rc == 0) verify(s, c, 500, &h, perm, 1, "coincident");
            lc_hierarchy_release(&h);
            free(perm);
        }
        free(c);
        free(s);
    }

    /* Emitters get their own subtree. */
    for (uint32_t n = 2000; n <= 32000; n *= 4) {
        int root = 0;
        uint32_t pure = 0, n_lamp = flush_lamp_case(n, &root, &pure);
        fprintf(stderr, "flush lamp n=%u: %u lamp surfels, lamp-only subtree %s, %u pure internal lamp nodes\n", n,
                n_lamp, root ? "yes" : "no", pure);
        CHECK(n_lamp > 10, "flush lamp n=%u: too few lamp surfels (%u)", n, n_lamp);
        CHECK(root, "flush lamp n=%u: no node holds exactly the %u lamp surfels", n, n_lamp);
    }

    fprintf(stderr, "quality (area-weighted mean PIC merge cost, lower is better):\n");
    double t;
    fprintf(stderr, " corridor (facing walls 0.5 m apart + floor):\n");
    double qa = build_quality(make_corridor, 30000, LC_HIERARCHY_AAC, &t);
    double qk = build_quality(make_corridor, 30000, LC_HIERARCHY_KDTREE, &t);
    CHECK(qa <= qk, "AAC quality %g should not be worse than kd-tree %g", qa, qk);
    fprintf(stderr, " random normals:\n");
    qa = build_quality(make_random, 30000, LC_HIERARCHY_AAC, &t);
    qk = build_quality(make_random, 30000, LC_HIERARCHY_KDTREE, &t);
    CHECK(qa <= qk, "AAC quality %g should not be worse than kd-tree %g", qa, qk);
    fprintf(stderr, " open unit box (walls 1 m apart + floor; printed only):\n");
    build_quality(make_structured, 30000, LC_HIERARCHY_AAC, &t);
    build_quality(make_structured, 30000, LC_HIERARCHY_KDTREE, &t);
    fprintf(stderr, "timing:\n");
    double ta32, tk32, ta128, tk128;
    build_quality(make_corridor, 32768, LC_HIERARCHY_AAC, &ta32);
    build_quality(make_corridor, 32768, LC_HIERARCHY_KDTREE, &tk32);
    build_quality(make_corridor, 131072, LC_HIERARCHY_AAC, &ta128);
    build_quality(make_corridor, 131072, LC_HIERARCHY_KDTREE, &tk128);
    build_quality(make_random, 131072, LC_HIERARCHY_AAC, &t);
    build_quality(make_random, 131072, LC_HIERARCHY_KDTREE, &t);
    CHECK_DONE();
}
