/* surfel_refine: extra surfels where caches see surfaces without their own (surfel_refine.h). */
#include "bake/surfel_refine.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bake/surfels.h"
#include "lcb/surfel_hash.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/rng.h"
#include "util/vec.h"

/* A triangle takes at most this many times its equal-area share of extra surfels per round
 * (plus one), so a tiny triangle hit by many rays gets a surfel, not a heap of them. */
#define REFINE_MAX_DENSITY 4.0
/* Area samples per triangle, at least: a triangle far smaller than the sample spacing still
 * gives its area to the surfels nearest it. */
#define REFINE_MIN_SAMPLES 4
/* A surfel no area sample reaches (another surfel is nearer on every triangle) keeps this
 * share of the mean area: it stays in the tree without taking another surface's light. */
#define REFINE_AREA_FLOOR 0.01

typedef struct {
    const lc_rt *rt;
    const lc_scene *scene;
    const lc_lcb_cache *caches;
    uint32_t n_caches;
    const lc_lcb_surfel *surfels;
    const lc_surfel_hash *hash;
    uint32_t rays;
    uint64_t seed;
    float plane_tol, cos_tol;
    uint32_t *misplaced;   /* per triangle: pilot hits attributed to another surface (atomic) */
    uint64_t *thread_hits; /* per worker: front-face hits, then misplaced ones (2 each) */
} refine_pilot_ctx;

/* 1 when surfel s (LC_NONE: none) does not represent the surface at hit point p (geometric
 * normal ng): another orientation, or another plane. */
static int refine_misplaced(const refine_pilot_ctx *c, uint32_t s, const float p[3], const float ng[3]) {
    if (s == LC_NONE) return 1;
    const lc_lcb_surfel *x = &c->surfels[s];
    if (x->normal[0] * ng[0] + x->normal[1] * ng[1] + x->normal[2] * ng[2] < c->cos_tol) return 1;
    float d = 0;
    for (int a = 0; a < 3; a++) d += (p[a] - x->position[a]) * x->normal[a];
    return fabsf(d) > c->plane_tol;
}

/* Pilot rays of caches [begin, end): a spherical Fibonacci set over the texel cache's
 * hemisphere or the grid cache's sphere, rotated per cache and round (the probe rays' layout,
 * links.c, with its own rotation). */
static void refine_pilot_range(void *ctx, size_t begin, size_t end, int thread) {
    refine_pilot_ctx *c = ctx;
    uint64_t hits = 0, misplaced = 0;
    for (size_t i = begin; i < end; i++) {
        const lc_lcb_cache *cache = &c->caches[i];
        if (cache->flags & LC_CACHE_INSIDE) continue;
        const int hemisphere = (cache->flags & LC_CACHE_TEXEL) != 0;
        lc_rng rng = lc_rng_seed(c->seed ^ 0x5EF1ull, i);
        float rot = lc_rng_float(&rng);
        lc_vec3 nrm = lc_v3_load(cache->normal), t = lc_v3(1, 0, 0), b = lc_v3(0, 1, 0);
        if (hemisphere) lc_v3_basis(nrm, &t, &b);
        for (uint32_t j = 0; j < c->rays; j++) {
            float z = hemisphere ? 1.0f - ((float)j + 0.5f) / c->rays : 1.0f - 2.0f * ((float)j + 0.5f) / c->rays;
            float r = sqrtf(fmaxf(0.0f, 1.0f - z * z)), phi = 2.0f * (float)M_PI * ((float)j * 0.6180339887f + rot);
            float d[3] = {r * cosf(phi), r * sinf(phi), z};
            if (hemisphere)
                lc_v3_store(d, lc_v3_add(lc_v3_add(lc_v3_scale(t, d[0]), lc_v3_scale(b, d[1])), lc_v3_scale(nrm, z)));
            lc_hit hit;
            if (!lc_rt_intersect(c->rt, cache->position, d, 0.0f, INFINITY, &hit) || hit.backface) continue;
            float p[3];
            for (int a = 0; a < 3; a++) p[a] = cache->position[a] + d[a] * hit.t;
            hits++;
            uint32_t s = lc_surfel_hash_nearest(c->hash, c->surfels, p, hit.ng, d);
            if (!refine_misplaced(c, s, p, hit.ng)) continue;
            misplaced++;
            if (c->misplaced) __atomic_fetch_add(&c->misplaced[hit.prim], 1u, __ATOMIC_RELAXED);
        }
    }
    c->thread_hits[2 * thread] += hits;
    c->thread_hits[2 * thread + 1] += misplaced;
}

/* One pilot pass (round `round`) against surfels[0, n): per-triangle misplaced counts into
 * misplaced (NULL: only count). Returns the share of front-face hits misplaced, *hits_out the
 * hits; -1 out of memory. */
static double refine_pilot(refine_pilot_ctx *c, const lc_lcb_surfel *surfels, uint32_t n, uint32_t round, int threads,
                           uint32_t *misplaced, uint64_t *hits_out) {
    lc_surfel_hash hash;
    if (lc_surfel_hash_build(&hash, surfels, n) != 0) return -1;
    const int nt = lc_parallel_threads(threads);
    uint64_t *th = calloc(2 * (size_t)nt, sizeof *th);
    if (!th) {
        lc_surfel_hash_free(&hash);
        return -1;
    }
    double mean_area = 0;
    for (uint32_t i = 0; i < n; i++) mean_area += surfels[i].area;
    mean_area /= n;
    refine_pilot_ctx r = *c;
    r.surfels = surfels;
    r.hash = &hash;
    r.seed = c->seed ^ lc_mix64(round + 1);
    r.plane_tol = (float)(LC_REFINE_PLANE * sqrt(mean_area));
    r.misplaced = misplaced;
    r.thread_hits = th;
    lc_parallel_for(threads, c->n_caches, 64, refine_pilot_range, &r);
    uint64_t hits = 0, bad = 0;
    for (int t = 0; t < nt; t++) hits += th[2 * t], bad += th[2 * t + 1];
    free(th);
    lc_surfel_hash_free(&hash);
    *hits_out = hits;
    return hits ? (double)bad / (double)hits : 0.0;
}

/* Appends up to `want` surfels over the triangles in proportion to weights[] (the equal-area
 * walk of surfels.c over these weights), each triangle capped at REFINE_MAX_DENSITY times its
 * share of the current mean area, plus one. *next_halton: the Halton index of the next surfel.
 * Returns the number added, -1 out of memory. */
static int64_t refine_add(const lc_scene *scene, double area, const double *weights, uint32_t want,
                          lc_lcb_surfel **surfels, uint32_t **tri, uint32_t *n, const float rot[2],
                          uint64_t *next_halton) {
    const lc_mesh *m = &scene->mesh;
    double weight = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++) weight += weights[t];
    if (weight <= 0 || want == 0) return 0;
    const double per = weight / want, mean_area = area / *n;
    lc_lcb_surfel *ns = realloc(*surfels, ((size_t)*n + want) * sizeof *ns);
    if (ns) *surfels = ns;
    uint32_t *nt = realloc(*tri, ((size_t)*n + want) * sizeof *nt);
    if (nt) *tri = nt;
    if (!ns || !nt) return -1;
    double cum = 0;
    uint32_t added = 0;
    for (uint32_t t = 0; t < m->n_triangles && added < want; t++) {
        if (!(weights[t] > 0)) continue;
        double before = floor(cum / per);
        cum += weights[t];
        double k = floor(cum / per) - before, at = lc_mesh_triangle_area(m, t);
        if (!(isfinite(at) && at > 0)) continue;
        const double cap = 1.0 + floor(REFINE_MAX_DENSITY * at / mean_area);
        const uint32_t count = (uint32_t)fmin(fmin(k, cap), (double)(want - added));
        for (uint32_t j = 0; j < count; j++, added++) {
            float b1, b2;
            lc_surfel_halton_bary((*next_halton)++, rot, &b1, &b2);
            lc_surfel_init(scene, t, b1, b2, (float)mean_area, &ns[*n + added]);
            nt[*n + added] = t;
        }
    }
    *n += added;
    return added;
}

typedef struct {
    const lc_scene *scene;
    const lc_lcb_surfel *surfels;
    const lc_surfel_hash *hash;
    const uint64_t *first; /* per triangle: its first area sample (n_triangles + 1) */
    const double *total;   /* the surface area */
    float rot[2];
    uint64_t *share; /* per surfel: attributed area in units of total / 2^40 (atomic, so exact) */
} refine_area_ctx;

static void refine_area_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    refine_area_ctx *c = ctx;
    const lc_mesh *m = &c->scene->mesh;
    for (size_t t = begin; t < end; t++) {
        const uint64_t k = c->first[t + 1] - c->first[t];
        if (!k) continue;
        const uint64_t unit = (uint64_t)llround(lc_mesh_triangle_area(m, (uint32_t)t) / (double)k / *c->total * 0x1p40);
        const uint32_t *ix = m->index + 3 * t;
        lc_vec3 v0 = lc_v3_load(m->position + 3 * (size_t)ix[0]);
        lc_vec3 ng = lc_v3_norm(lc_v3_cross(lc_v3_sub(lc_v3_load(m->position + 3 * (size_t)ix[1]), v0),
                                            lc_v3_sub(lc_v3_load(m->position + 3 * (size_t)ix[2]), v0)));
        float ngf[3], dir[3];
        lc_v3_store(ngf, ng);
        lc_v3_store(dir, lc_v3_scale(ng, -1.0f));
        for (uint64_t j = c->first[t]; j < c->first[t + 1]; j++) {
            float b1, b2, p[3], nrm[3];
            lc_surfel_halton_bary(j, c->rot, &b1, &b2);
            lc_mesh_interpolate(m, (uint32_t)t, b1, b2, p, nrm);
            uint32_t s = lc_surfel_hash_nearest(c->hash, c->surfels, p, ngf, dir);
            if (s != LC_NONE) __atomic_fetch_add(&c->share[s], unit, __ATOMIC_RELAXED);
        }
    }
}

/* Each surfel's area := the surface area its nearest-surfel region covers. Every triangle
 * with area gets max(REFINE_MIN_SAMPLES, its equal-area share of samples_per_surfel * n)
 * samples, each carrying an equal part of the triangle's area, so small triangles count at
 * their true area. A surfel no sample reaches keeps REFINE_AREA_FLOOR of the mean; the total
 * is the surface area. -1 out of memory. */
static int refine_areas(const lc_scene *scene, double total, lc_lcb_surfel *surfels, uint32_t n,
                        uint32_t samples_per_surfel, const float rot[2], int threads, lc_surfel_refine_stats *st) {
    const lc_mesh *m = &scene->mesh;
    uint64_t *first = malloc(((size_t)m->n_triangles + 1) * sizeof *first);
    uint64_t *share = calloc(n, sizeof *share);
    lc_surfel_hash hash;
    int hashed = 0, rc = -1;
    if (!first || !share || lc_surfel_hash_build(&hash, surfels, n) != 0) goto done;
    hashed = 1;
    const double a = total / ((double)samples_per_surfel * n);
    first[0] = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double at = lc_mesh_triangle_area(m, t);
        uint64_t k = isfinite(at) && at > 0 ? (uint64_t)fmax(REFINE_MIN_SAMPLES, ceil(at / a)) : 0;
        first[t + 1] = first[t] + k;
    }
    refine_area_ctx c = {scene, surfels, &hash, first, &total, {rot[0], rot[1]}, share};
    lc_parallel_for(threads, m->n_triangles, 256, refine_area_range, &c);
    const double unit = total * 0x1p-40, mean = total / n, floor_a = REFINE_AREA_FLOOR * mean;
    double sum = 0;
    for (uint32_t i = 0; i < n; i++) sum += share[i] ? (double)share[i] * unit : floor_a;
    st->area_min = INFINITY;
    st->area_max = 0;
    for (uint32_t i = 0; i < n; i++) {
        double ai = (share[i] ? (double)share[i] * unit : floor_a) * total / sum;
        surfels[i].area = (float)ai;
        st->area_min = fmin(st->area_min, ai / mean);
        st->area_max = fmax(st->area_max, ai / mean);
    }
    rc = 0;
done:
    if (hashed) lc_surfel_hash_free(&hash);
    free(first);
    free(share);
    return rc;
}

int lc_surfels_refine(const lc_rt *rt, const lc_scene *scene, const lc_lcb_cache *caches, uint32_t n_caches,
                      const lc_surfel_refine_params *p, lc_lcb_surfel **surfels, uint32_t **tri, uint32_t *n,
                      lc_surfel_refine_stats *stats, char *err, size_t errlen) {
    memset(stats, 0, sizeof *stats);
    const lc_mesh *m = &scene->mesh;
    const double area = lc_mesh_total_area(m); /* the import drops non-finite triangles */
    uint32_t *misplaced = calloc(m->n_triangles ? m->n_triangles : 1, sizeof *misplaced);
    double *weights = malloc((m->n_triangles ? m->n_triangles : 1) * sizeof *weights);
    if (!misplaced || !weights) goto oom;
    refine_pilot_ctx c = {.rt = rt,
                          .scene = scene,
                          .caches = caches,
                          .n_caches = n_caches,
                          .rays = p->pilot_rays,
                          .seed = p->seed,
                          .cos_tol = (float)cos(LC_REFINE_NORMAL_DEG * M_PI / 180.0)};
    lc_rng rng = lc_rng_seed(p->seed, 0x5EF2u);
    float rot[2] = {lc_rng_float(&rng), lc_rng_float(&rng)};
    uint64_t next_halton = lc_rng_next(&rng) & 0xFFFFFu, hits;
    const uint32_t rounds = p->rounds ? p->rounds : 1;
    for (uint32_t r = 0; r < rounds && stats->added < p->extra; r++) {
        memset(misplaced, 0, (size_t)m->n_triangles * sizeof *misplaced);
        double share = refine_pilot(&c, *surfels, *n, r, p->threads, misplaced, &hits);
        if (share < 0) goto oom;
        if (r == 0) stats->pilot_hits = hits, stats->misplaced_before = share;
        uint32_t want = (uint32_t)(((uint64_t)p->extra * (r + 1)) / rounds) - stats->added;
        for (uint32_t t = 0; t < m->n_triangles; t++) weights[t] = misplaced[t];
        int64_t added = refine_add(scene, area, weights, want, surfels, tri, n, rot, &next_halton);
        if (added < 0) goto oom;
        stats->added += (uint32_t)added;
    }
    /* What no misplaced hit asked for (every surface seen has its surfels) goes by area, so the
     * bake keeps --surfels. */
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double at = lc_mesh_triangle_area(m, t);
        weights[t] = isfinite(at) && at > 0 ? at : 0;
    }
    for (int pass = 0; pass < 4 && stats->added + stats->filled < p->extra; pass++) {
        int64_t filled = refine_add(scene, area, weights, p->extra - stats->added - stats->filled, surfels, tri, n, rot,
                                    &next_halton);
        if (filled < 0) goto oom;
        stats->filled += (uint32_t)filled;
    }
    if (refine_areas(scene, area, *surfels, *n, p->area_samples, rot, p->threads, stats) != 0) goto oom;
    stats->misplaced_after = refine_pilot(&c, *surfels, *n, rounds, p->threads, NULL, &hits);
    if (stats->misplaced_after < 0) goto oom;
    free(misplaced);
    free(weights);
    return 0;
oom:
    free(misplaced);
    free(weights);
    lc_set_err(err, errlen, "surfel refinement: out of memory (lower --surfels or --surfel-refine)");
    return -1;
}
