#include "bake/relocate.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"
#include "util/ray_offset.h"
#include "util/rng.h"
#include "util/vec.h"

enum { RELOC_KEEP = 0, RELOC_MOVED = 1, RELOC_INSIDE = 2 };

typedef struct {
    const lc_rt *rt;
    lc_lcb_cache *caches;
    const lc_relocate_params *params;
    uint8_t *outcome; /* per cache, so the stats need no shared counters */
    float eps;        /* ray origin offset for texel caches */
} reloc_ctx;

typedef struct {
    uint32_t hits, back;
    float best_t; /* shortest back-facing hit */
    lc_vec3 best_dir;
    lc_vec3 best_ng; /* that hit's geometric normal: points to the side the cache moves out to */
} reloc_probe;

/* Casts `rays` stratified directions (Fibonacci spiral, randomly rotated per cache and pass)
 * over the hemisphere around axis (hemi) or the full sphere. */
static reloc_probe reloc_cast(const reloc_ctx *ctx, lc_vec3 org, lc_vec3 axis, int hemi, uint64_t stream) {
    reloc_probe pr = {0, 0, FLT_MAX, {0, 0, 0}, {0, 0, 0}};
    uint32_t n = ctx->params->rays;
    lc_rng rng = lc_rng_seed(ctx->params->seed, stream);
    float u = lc_rng_float(&rng), v = lc_rng_float(&rng);
    if (!hemi) { /* random frame for the sphere so grid caches do not share one pattern */
        float z = 1 - 2 * lc_rng_float(&rng), phi = 6.2831853f * lc_rng_float(&rng);
        float r = sqrtf(fmaxf(0, 1 - z * z));
        axis = lc_v3(r * cosf(phi), r * sinf(phi), z);
    }
    lc_vec3 t, b;
    lc_v3_basis(axis, &t, &b);
    const float golden = 0.6180339887f;
    for (uint32_t i = 0; i < n; i++) {
        float z = hemi ? 1 - ((float)i + u) / (float)n : 1 - 2 * ((float)i + u) / (float)n;
        float f = (float)i * golden + v;
        float phi = 6.2831853f * (f - floorf(f));
        float r = sqrtf(fmaxf(0, 1 - z * z));
        lc_vec3 d =
            lc_v3_add(lc_v3_add(lc_v3_scale(t, r * cosf(phi)), lc_v3_scale(b, r * sinf(phi))), lc_v3_scale(axis, z));
        d = lc_v3_norm(d);
        float o[3], dd[3];
        lc_v3_store(o, org);
        lc_v3_store(dd, d);
        lc_hit hit;
        if (!lc_rt_intersect(ctx->rt, o, dd, 0.0f, INFINITY, &hit)) continue;
        pr.hits++;
        if (hit.backface) {
            pr.back++;
            if (hit.t < pr.best_t) {
                pr.best_t = hit.t;
                pr.best_dir = d;
                pr.best_ng = lc_v3_load(hit.ng);
            }
        }
    }
    return pr;
}

/* A grid cache pushed just past a surface sees that surface's light over its whole lower
 * hemisphere through the one or two surfels under it; clearance moves it further along the
 * surface's normal (as DDGI offsets probes), at most half the free distance in front of it. */
static lc_vec3 reloc_clear(const reloc_ctx *ctx, lc_vec3 at, lc_vec3 ng) {
    float clearance = (float)ctx->params->grid_clearance;
    if (clearance <= 0) return at;
    float o[3], d[3];
    lc_v3_store(o, at);
    lc_v3_store(d, ng);
    lc_hit hit;
    if (lc_rt_intersect(ctx->rt, o, d, 0.0f, INFINITY, &hit)) clearance = fminf(clearance, 0.5f * hit.t);
    return lc_v3_add(at, lc_v3_scale(ng, clearance));
}

static void reloc_range(void *arg, size_t begin, size_t end, int thread) {
    (void)thread;
    const reloc_ctx *ctx = arg;
    const lc_relocate_params *prm = ctx->params;
    for (size_t i = begin; i < end; i++) {
        lc_lcb_cache *c = &ctx->caches[i];
        ctx->outcome[i] = RELOC_KEEP;
        if (c->flags & LC_CACHE_INSIDE) continue;
        lc_vec3 p = lc_v3_load(c->position), n = lc_v3_load(c->normal);
        float nlen = lc_v3_len(n);
        int texel = nlen > 1e-6f;
        uint64_t stream = (uint64_t)i * 2;
        if (texel) {
            n = lc_v3_scale(n, 1.0f / nlen);
            lc_vec3 org = lc_v3_add(p, lc_v3_scale(n, ctx->eps));
            reloc_probe pr = reloc_cast(ctx, org, n, 1, stream);
            /* Escaping rays count against moving: a texel that sees the sky is not buried. */
            if (pr.back == 0 || (double)pr.back < prm->texel_fraction * (double)prm->rays) continue;
            lc_v3_store(c->position, lc_v3_add(org, lc_v3_scale(pr.best_dir, pr.best_t + (float)prm->offset)));
            c->flags |= LC_CACHE_MOVED;
            ctx->outcome[i] = RELOC_MOVED;
        } else {
            reloc_probe pr = reloc_cast(ctx, p, n, 0, stream);
            if (pr.back == 0 || (double)pr.back < prm->grid_fraction * (double)pr.hits) continue;
            lc_vec3 moved = lc_v3_add(p, lc_v3_scale(pr.best_dir, pr.best_t + (float)prm->offset));
            moved = reloc_clear(ctx, moved, pr.best_ng);
            reloc_probe again = reloc_cast(ctx, moved, n, 0, stream + 1);
            if (again.back > 0 && (double)again.back >= prm->grid_fraction * (double)again.hits) {
                c->flags |= LC_CACHE_INSIDE; /* position stays where it was */
                ctx->outcome[i] = RELOC_INSIDE;
            } else {
                lc_v3_store(c->position, moved);
                c->flags |= LC_CACHE_MOVED;
                ctx->outcome[i] = RELOC_MOVED;
            }
        }
    }
}

void lc_relocate_caches(const lc_rt *rt, lc_lcb_cache *caches, uint32_t n, const lc_relocate_params *params,
                        lc_relocate_stats *stats) {
    uint8_t *outcome = NULL;
    if (stats) memset(stats, 0, sizeof *stats);
    if (n == 0 || params->rays == 0) return;
    outcome = calloc(n, 1);
    if (!outcome) {
        lc_error("relocate", "out of memory for %u caches; caches left in place", n);
        goto err;
    }
    /* Ray offset: 0.1 mm, grown with the scene's coordinate magnitude so it stays above float
     * precision for large scenes (lc_ray_lift_relocate). */
    const lc_mesh *mesh = lc_rt_mesh(rt);
    float amax = 0;
    for (uint32_t v = 0; v < 3 * mesh->n_vertices; v++) amax = fmaxf(amax, fabsf(mesh->position[v]));
    reloc_ctx ctx = {rt, caches, params, outcome, lc_ray_lift_relocate(amax)};
    lc_parallel_for(params->threads, n, 64, reloc_range, &ctx);
    if (stats)
        for (uint32_t i = 0; i < n; i++) {
            stats->moved += outcome[i] == RELOC_MOVED;
            stats->inside += outcome[i] == RELOC_INSIDE;
        }
err:
    free(outcome);
}
