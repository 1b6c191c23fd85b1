#include "bake/links.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "lcb/surfel_hash.h"
#include "util/half.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/ray_offset.h"
#include "util/rng.h"
#include "util/sh.h"
#include "util/vec.h"

/* Priority of a node whose samples were all occluded but which has unsampled surfels: a
 * fraction of its unoccluded estimate, so it is refined only when budget is left over. */
#define LINKS_OCCLUDED_PRIORITY 0.05

/* Refinement priority = visible solid angle x (1 + LINKS_SPREAD_K x CV), CV the coefficient
 * of variation of the per-surfel visible solid angle w over the node's sampled surfels
 * (occluded, back-facing and below-horizon samples count as w = 0). A link carries the
 * node's area-weighted mean radiosity, the cache sees the w-weighted mean: the two differ
 * by Cov(w, B) / mean(w) <= CV(w) x std(B). A node seen evenly (CV = 0) is exact whatever
 * its radiosity; a partly hidden, horizon-clipped or very oblique one is what to split
 * (docs/ARCHITECTURE.md, Decisions: "the cut splits unevenly seen nodes first"). */
#define LINKS_SPREAD_K 1.0

/* Stream salts: refinement and the final estimate use independent jitter. */
#define LINKS_PASS_REFINE 0x5EF1E5ull
#define LINKS_PASS_FINAL 0xF17A1ull

double lc_links_surfel_solid_angle(const lc_lcb_surfel *s, const float p[3], const float n[3]) {
    double v[3] = {(double)s->position[0] - p[0], (double)s->position[1] - p[1], (double)s->position[2] - p[2]};
    double d2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if (!(d2 > 0) || !(s->area > 0)) return 0;
    double d = sqrt(d2);
    /* The surfel faces p when its normal points toward p. */
    double cos_s = -(v[0] * s->normal[0] + v[1] * s->normal[1] + v[2] * s->normal[2]) / d;
    if (cos_s <= 0) return 0;
    if (n[0] != 0 || n[1] != 0 || n[2] != 0) {
        /* Same-surface surfels sit in the cache plane up to float noise; keep them out. */
        double pm = fmax(fabs(p[0]), fmax(fabs(p[1]), fabs(p[2])));
        double eps = 1e-5 * (1.0 + pm);
        double nl = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
        if ((v[0] * n[0] + v[1] * n[1] + v[2] * n[2]) / nl <= eps) return 0;
    }
    double r2 = s->area / M_PI;
    double h = sqrt(d2 + r2);
    /* 1 - d/h written without cancellation for distant surfels. */
    return cos_s * 2.0 * M_PI * r2 / (h * (h + d));
}

/* --- per-cache estimation ------------------------------------------------------------------ */

typedef struct {
    double omega; /* estimated visible solid angle */
    double unocc; /* the same without visibility */
    double m[3];  /* sum of w * h1 * dir over visible samples */
    double wsum;  /* sum of visible w (unscaled) */
    double w2sum; /* sum of visible w^2 (unscaled): the spread of w over the samples */
    uint32_t n;   /* samples taken (occluded and back-facing ones count with w = 0) */
} links_est;

typedef struct {
    double prio;
    uint32_t node;
    links_est est;
} links_item;

typedef struct {
    uint32_t surfel;
    float dir[3];
} links_hit;

typedef struct {
    links_item *heap; /* refinable (internal) nodes of the cut */
    uint32_t n_heap;
    links_hit *hits; /* this cache's probe hits, sorted by surfel */
    uint32_t n_hits;
    double *cum;      /* prefix sums of hit directions: 3 * (n_hits + 1) */
    double ray_omega; /* solid angle per probe ray */
    links_item *done; /* leaves of the cut */
    uint32_t n_done;
    lc_lcb_link *tmp_links;
    float *tmp_sh;
    uint32_t *order;
} links_scratch;

typedef struct {
    const lc_rt *rt;
    const lc_lcb_surfel *surfels;
    uint32_t n_surfels;
    const lc_hierarchy *h;
    const lc_lcb_cache *caches;
    const lc_link_params *prm;
    lc_lcb_link *links;
    uint16_t *link_sh;
    links_scratch *scratch; /* one per thread */
    uint32_t *used;         /* per cache: links with factor > 0 */
    double *omega;          /* per cache: sum of link solid angles */
    uint64_t *rays;         /* per cache */
    lc_progress *progress;
    lc_surfel_hash hash;
} links_ctx;

typedef struct {
    float p[3];   /* cache position (solid-angle reference) */
    float n[3];   /* unit normal, zero for grid caches */
    float org[3]; /* ray origin */
    uint32_t cache;
    uint64_t rays;
} links_cache;

static int links_hit_cmp(const void *a, const void *b) {
    const links_hit *x = a, *y = b;
    if (x->surfel != y->surfel) return x->surfel < y->surfel ? -1 : 1;
    for (int k = 0; k < 3; k++)
        if (x->dir[k] != y->dir[k]) return x->dir[k] < y->dir[k] ? -1 : 1;
    return 0;
}

/* Casts the cache's probe rays (stratified: a spherical Fibonacci set over the hemisphere
 * or sphere, rotated per cache) and keeps the front-face hits, sorted by surfel. */
static void links_probe(const links_ctx *ctx, links_scratch *sc, links_cache *lc, int hemisphere) {
    const uint32_t n = ctx->prm->probe_rays;
    sc->n_hits = 0;
    sc->ray_omega = (hemisphere ? 2.0 : 4.0) * M_PI / n;
    lc_rng rng = lc_rng_seed(ctx->prm->seed ^ 0x9B0BEull, lc->cache);
    float rot = lc_rng_float(&rng);
    lc_vec3 nrm = lc_v3_load(lc->n), t = lc_v3(1, 0, 0), b = lc_v3(0, 1, 0);
    if (hemisphere) lc_v3_basis(nrm, &t, &b);
    for (uint32_t j = 0; j < n; j++) {
        float z = hemisphere ? 1.0f - ((float)j + 0.5f) / n : 1.0f - 2.0f * ((float)j + 0.5f) / n;
        float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
        float phi = 2.0f * (float)M_PI * ((float)j * 0.6180339887f + rot);
        float x = r * cosf(phi), y = r * sinf(phi);
        float d[3];
        if (hemisphere) {
            lc_vec3 v = lc_v3_add(lc_v3_add(lc_v3_scale(t, x), lc_v3_scale(b, y)), lc_v3_scale(nrm, z));
            lc_v3_store(d, v);
        } else {
            d[0] = x, d[1] = y, d[2] = z;
        }
        lc_hit hit;
        lc->rays++;
        if (!lc_rt_intersect(ctx->rt, lc->org, d, 0.0f, INFINITY, &hit) || hit.backface) continue;
        float p[3] = {lc->org[0] + d[0] * hit.t, lc->org[1] + d[1] * hit.t, lc->org[2] + d[2] * hit.t};
        uint32_t s = lc_surfel_hash_nearest(&ctx->hash, ctx->surfels, p, hit.ng, d);
        if (s == LC_NONE) continue;
        links_hit *h = &sc->hits[sc->n_hits++];
        h->surfel = s;
        memcpy(h->dir, d, sizeof d);
    }
    qsort(sc->hits, sc->n_hits, sizeof *sc->hits, links_hit_cmp);
    if (ctx->prm->surfel_seen) /* integer sums: the same counts for any thread schedule */
        for (uint32_t i = 0; i < sc->n_hits; i++)
            if (i == 0 || sc->hits[i].surfel != sc->hits[i - 1].surfel)
                __atomic_fetch_add(&ctx->prm->surfel_seen[sc->hits[i].surfel], 1u, __ATOMIC_RELAXED);
    sc->cum[0] = sc->cum[1] = sc->cum[2] = 0;
    for (uint32_t i = 0; i < sc->n_hits; i++)
        for (int a = 0; a < 3; a++) sc->cum[3 * (i + 1) + a] = sc->cum[3 * i + a] + sc->hits[i].dir[a];
}

static uint32_t links_lower_bound(const links_scratch *sc, uint32_t surfel) {
    uint32_t lo = 0, hi = sc->n_hits;
    while (lo < hi) {
        uint32_t mid = (lo + hi) / 2;
        if (sc->hits[mid].surfel < surfel) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* Near-field estimate from the probe rays landing in node's surfel range. Returns 0 for a
 * far node (the caller then samples surfels): the split is geometric, not by hit count, so
 * it does not select on the noise of either estimate. */
static int links_probe_estimate(const links_ctx *ctx, const links_scratch *sc, const links_cache *lc, uint32_t node,
                                links_est *e, double *sh, int bands) {
    if (!ctx->prm->probe_rays) return 0;
    const lc_lcb_node *nd = &ctx->h->nodes[node];
    float d2 = 0;
    for (int a = 0; a < 3; a++) d2 += (nd->center[a] - lc->p[a]) * (nd->center[a] - lc->p[a]);
    float r = nd->radius + sqrtf(nd->area / nd->surfel_count / (float)M_PI);
    /* Near: the cache is inside or close to the node's bounding sphere, or the sphere spans
     * the solid angle of LC_LINKS_NEAR_HITS probe rays. (The bounding sphere, not the
     * surfel-area estimate, decides: that estimate runs low for grazing and close surfels,
     * exactly the ones that must go to the rays.) */
    if (d2 > 4.0f * r * r && (float)M_PI * r * r < LC_LINKS_NEAR_HITS * (float)sc->ray_omega * d2) return 0;
    uint32_t lo = links_lower_bound(sc, nd->first_surfel),
             hi = links_lower_bound(sc, nd->first_surfel + nd->surfel_count);
    memset(e, 0, sizeof *e);
    e->omega = e->unocc = e->wsum = (hi - lo) * sc->ray_omega;
    for (int a = 0; a < 3; a++) e->m[a] = (sc->cum[3 * hi + a] - sc->cum[3 * lo + a]) * sc->ray_omega;
    if (sh) {
        memset(sh, 0, (size_t)bands * bands * sizeof *sh);
        for (uint32_t i = lo; i < hi; i++) {
            float y[LC_SH_MAX_COEFFS];
            lc_sh_eval(bands, sc->hits[i].dir, y);
            for (int k = 0; k < bands * bands; k++) sh[k] += y[k] * sc->ray_omega;
        }
    }
    return 1;
}

/* Estimates the visible solid angle of node from the cache with k stratified surfel samples.
 * sh (optional, bands^2 doubles) receives sum of w * h_l * y_lm(dir), scaled like omega. */
static links_est links_estimate(const links_ctx *ctx, links_cache *lc, uint32_t node, uint32_t k, uint64_t pass,
                                double *sh, int bands) {
    links_est e = {0};
    const lc_lcb_node *nd = &ctx->h->nodes[node];
    uint32_t first = nd->first_surfel, count = nd->surfel_count;
    if (first >= ctx->n_surfels) return e;
    if (count > ctx->n_surfels - first) count = ctx->n_surfels - first;
    if (count == 0 || k == 0) return e;
    uint32_t taken = count <= k ? count : k;
    lc_rng rng = lc_rng_seed(ctx->prm->seed ^ pass, ((uint64_t)lc->cache << 32) | node);
    double stratum = (double)count / (double)taken;
    double sum_unocc = 0;
    if (sh) memset(sh, 0, (size_t)bands * bands * sizeof *sh);
    for (uint32_t j = 0; j < taken; j++) {
        uint32_t idx = j;
        if (taken < count) {
            idx = (uint32_t)(((double)j + lc_rng_float(&rng)) * stratum);
            if (idx >= count) idx = count - 1;
        }
        const lc_lcb_surfel *s = &ctx->surfels[first + idx];
        double w = lc_links_surfel_solid_angle(s, lc->p, lc->n);
        if (w <= 0) continue;
        sum_unocc += w;
        float dir[3] = {s->position[0] - lc->org[0], s->position[1] - lc->org[1], s->position[2] - lc->org[2]};
        float dist = sqrtf(dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]);
        if (!(dist > 0)) continue;
        dir[0] /= dist, dir[1] /= dist, dir[2] /= dist;
        /* Visible when nothing is hit before the surfel, or the first hit lands on the surfel's
         * own disc: a shadow ray stopped short of the surfel misses at grazing angles, where
         * the surfel's own plane (or its neighbour's) is hit just before the endpoint. */
        float r_s = sqrtf(s->area / (float)M_PI);
        lc_hit hit;
        lc->rays++;
        if (lc_rt_intersect(ctx->rt, lc->org, dir, 0.0f, dist + r_s, &hit) && hit.t < dist) {
            float q[3] = {lc->org[0] + dir[0] * hit.t - s->position[0], lc->org[1] + dir[1] * hit.t - s->position[1],
                          lc->org[2] + dir[2] * hit.t - s->position[2]};
            if (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] > 2.25f * r_s * r_s) continue;
        }
        /* The surfel as a uniform cone of the same solid angle: its band-1 ratio keeps the
         * mean direction length honest for surfels close to the cache. */
        double cos_a = 1.0 - w / (2.0 * M_PI);
        if (cos_a < -1) cos_a = -1;
        double h1 = 0.5 * (1.0 + cos_a);
        e.wsum += w;
        e.w2sum += w * w;
        for (int a = 0; a < 3; a++) e.m[a] += w * h1 * dir[a];
        if (sh) {
            float y[LC_SH_MAX_COEFFS];
            lc_sh_eval(bands, dir, y);
            for (int l = 0; l < bands; l++) {
                double hl = w * lc_sh_cone_ratio(l, cos_a);
                for (int i = l * l; i < (l + 1) * (l + 1); i++) sh[i] += hl * y[i];
            }
        }
    }
    e.n = taken;
    e.omega = e.wsum * stratum;
    e.unocc = sum_unocc * stratum;
    if (sh)
        for (int i = 0; i < bands * bands; i++) sh[i] *= stratum;
    return e;
}

/* Max-heap on priority; ties go to the smaller node index so the cut is deterministic. */
static int links_before(const links_item *a, const links_item *b) {
    return a->prio > b->prio || (a->prio == b->prio && a->node < b->node);
}

static void links_heap_push(links_scratch *sc, const links_item *it) {
    uint32_t i = sc->n_heap++;
    sc->heap[i] = *it;
    while (i > 0) {
        uint32_t parent = (i - 1) / 2;
        if (!links_before(&sc->heap[i], &sc->heap[parent])) break;
        links_item t = sc->heap[i];
        sc->heap[i] = sc->heap[parent];
        sc->heap[parent] = t;
        i = parent;
    }
}

static links_item links_heap_pop(links_scratch *sc) {
    links_item top = sc->heap[0];
    sc->heap[0] = sc->heap[--sc->n_heap];
    uint32_t i = 0;
    for (;;) {
        uint32_t l = 2 * i + 1, r = l + 1, best = i;
        if (l < sc->n_heap && links_before(&sc->heap[l], &sc->heap[best])) best = l;
        if (r < sc->n_heap && links_before(&sc->heap[r], &sc->heap[best])) best = r;
        if (best == i) break;
        links_item t = sc->heap[i];
        sc->heap[i] = sc->heap[best];
        sc->heap[best] = t;
        i = best;
    }
    return top;
}

/* Adds node to the cut (heap if refinable, else done list). Returns 1 when kept. */
static int links_consider(const links_ctx *ctx, links_scratch *sc, links_cache *lc, uint32_t node) {
    const lc_lcb_node *nd = &ctx->h->nodes[node];
    if (lc->n[0] != 0 || lc->n[1] != 0 || lc->n[2] != 0) {
        /* Whole bounding sphere behind the cache plane: every surfel gets w = 0. */
        double dz = (nd->center[0] - lc->p[0]) * lc->n[0] + (nd->center[1] - lc->p[1]) * lc->n[1] +
            (nd->center[2] - lc->p[2]) * lc->n[2];
        if (dz + nd->radius <= 0) return 0;
    }
    uint32_t k = ctx->prm->node_samples;
    links_item it;
    memset(&it, 0, sizeof it);
    it.node = node;
    int probed = links_probe_estimate(ctx, sc, lc, node, &it.est, NULL, 0);
    if (!probed) it.est = links_estimate(ctx, lc, node, k, LINKS_PASS_REFINE, NULL, 0);
    /* Spread of w (see LINKS_SPREAD_K): near nodes take their solid angle from the probe
     * rays, so they are sampled too, for the spread only. No visible sample at all: the
     * largest CV n samples can show. */
    links_est sp = it.est;
    if (probed) sp = links_estimate(ctx, lc, node, k, LINKS_PASS_REFINE, NULL, 0);
    double cv = 0;
    if (sp.n > 1)
        cv = sp.wsum > 0 ? sqrt(fmax(0.0, sp.n * sp.w2sum / (sp.wsum * sp.wsum) - 1.0)) : sqrt((double)sp.n - 1.0);
    int internal = nd->child[0] != LC_NONE && nd->child[1] != LC_NONE && nd->child[0] < ctx->h->n_nodes &&
        nd->child[1] < ctx->h->n_nodes;
    int exhaustive = nd->surfel_count <= k && !probed;
    if (it.est.omega > 0) {
        it.prio = it.est.omega * (1.0 + LINKS_SPREAD_K * cv);
    } else {
        if (exhaustive || !internal) return 0; /* every surfel was tested and none is visible */
        it.prio = LINKS_OCCLUDED_PRIORITY * it.est.unocc;
    }
    if (internal) links_heap_push(sc, &it);
    else sc->done[sc->n_done++] = it;
    return 1;
}

static int links_by_node(const void *a, const void *b) {
    uint32_t x = ((const lc_lcb_link *)a)->node, y = ((const lc_lcb_link *)b)->node;
    return (x > y) - (x < y);
}

/* Position, unit normal (zero for grid caches) and ray origin of cache ci. Returns 1 for a
 * texel cache (a normal: hemisphere rays), 0 for a grid cache. */
static int links_cache_setup(const links_ctx *ctx, uint32_t ci, links_cache *lc) {
    const lc_lcb_cache *c = &ctx->caches[ci];
    memset(lc, 0, sizeof *lc);
    lc->cache = ci;
    lc_vec3 p = lc_v3_load(c->position), n = lc_v3_load(c->normal);
    float nlen = lc_v3_len(n);
    n = nlen > 1e-6f ? lc_v3_scale(n, 1.0f / nlen) : lc_v3(0, 0, 0);
    float pm = fmaxf(fabsf(p.x), fmaxf(fabsf(p.y), fabsf(p.z)));
    /* Texel caches sit on their surface: lift the ray origin off it (float noise grows with |p|). */
    float lift = lc_ray_lift_point(pm);
    lc_v3_store(lc->p, p);
    lc_v3_store(lc->n, n);
    lc_v3_store(lc->org, lc_v3_add(p, lc_v3_scale(n, lift)));
    return nlen > 1e-6f;
}

static void links_one_cache(const links_ctx *ctx, links_scratch *sc, uint32_t ci) {
    const lc_link_params *prm = ctx->prm;
    const uint32_t L = prm->links_per_cache;
    const int bands = (int)prm->sh_bands;
    const int nsh = bands * bands;
    lc_lcb_link *out = &ctx->links[(size_t)ci * L];
    uint16_t *out_sh = ctx->link_sh ? &ctx->link_sh[(size_t)ci * L * nsh] : NULL;
    const lc_lcb_cache *c = &ctx->caches[ci];
    for (uint32_t i = 0; i < L; i++) out[i] = (lc_lcb_link){0, 0.0f, 0};
    if (out_sh) memset(out_sh, 0, (size_t)L * nsh * sizeof *out_sh);
    ctx->used[ci] = 0;
    ctx->omega[ci] = 0;
    ctx->rays[ci] = 0;
    if ((c->flags & LC_CACHE_INSIDE) || ctx->h->n_nodes == 0 || ctx->n_surfels == 0) return;

    links_cache lc;
    int texel = links_cache_setup(ctx, ci, &lc);

    sc->n_heap = sc->n_done = 0;
    sc->n_hits = 0;
    if (prm->probe_rays) links_probe(ctx, sc, &lc, texel);
    uint32_t cut = links_consider(ctx, sc, &lc, 0);
    while (sc->n_heap > 0 && cut < L) {
        links_item it = links_heap_pop(sc);
        const lc_lcb_node *nd = &ctx->h->nodes[it.node];
        cut--;
        cut += (uint32_t)links_consider(ctx, sc, &lc, nd->child[0]);
        cut += (uint32_t)links_consider(ctx, sc, &lc, nd->child[1]);
    }
    /* The cut is heap + done. Every node in it is re-estimated with fresh samples: the cut keeps
     * exactly the nodes whose refinement estimate came out low, so summing those estimates
     * (or skipping the unseen nodes) would bias the total low. A node whose refinement
     * estimate used every surfel (and no SH is wanted) is already exact and is reused. */
    for (uint32_t i = 0; i < sc->n_heap; i++) sc->done[sc->n_done++] = sc->heap[i];
    sc->n_heap = 0;
    uint32_t used = 0;
    double omega_sum = 0, omega_near = 0, omega_far = 0;
    double sh[LC_SH_MAX_COEFFS];
    for (uint32_t i = 0; i < sc->n_done; i++) {
        const links_item *it = &sc->done[i];
        const lc_lcb_node *nd = &ctx->h->nodes[it->node];
        links_est e = it->est;
        int exact = nd->surfel_count <= prm->node_samples && nd->surfel_count <= prm->final_samples;
        int near = links_probe_estimate(ctx, sc, &lc, it->node, &e, out_sh ? sh : NULL, bands);
        if (near) {
            /* near field: the probe rays already give the final numbers */
        } else if (!exact || out_sh) {
            e = links_estimate(ctx, &lc, it->node, prm->final_samples, LINKS_PASS_FINAL, out_sh ? sh : NULL, bands);
        }
        if (!(e.omega > 0) || !(nd->area > 0)) continue;
        double mlen = sqrt(e.m[0] * e.m[0] + e.m[1] * e.m[1] + e.m[2] * e.m[2]) / e.wsum;
        float dir[3] = {0, 0, 1};
        if (mlen > 0) {
            double inv = 1.0 / (mlen * e.wsum);
            for (int a = 0; a < 3; a++) dir[a] = (float)(e.m[a] * inv);
        }
        /* A uniform cone of half-angle alpha has mean resultant length (1 + cos alpha) / 2. */
        double cos_a = 2.0 * mlen - 1.0;
        if (cos_a > 1) cos_a = 1;
        if (cos_a < -1) cos_a = -1;
        double norm = 1.0 / (M_PI * nd->area);
        lc_lcb_link *lk = &sc->tmp_links[used];
        lk->node = it->node;
        lk->factor = (float)(e.omega * norm);
        lk->dir_cone = lc_link_pack(dir, (float)acos(cos_a));
        if (!(lk->factor > 0)) continue; /* underflowed to zero: a padding link in all but name */
        if (out_sh)
            for (int j = 0; j < nsh; j++) sc->tmp_sh[(size_t)used * nsh + j] = (float)(sh[j] * norm);
        omega_sum += e.omega;
        if (near) omega_near += e.omega;
        else omega_far += e.omega;
        sc->order[used] = (uint32_t)near; /* reused below as the permutation */
        used++;
    }
    /* The probe rays count the cache's visible solid angle without bias; the far-field
     * surfel estimates run a few percent low (next to walls, at grazing angles). Scale
     * the far links so the total matches the probe count; their relative weights — what
     * makes small emitters precise — stay as estimated. */
    if (prm->probe_rays && omega_far > 0) {
        double total = sc->n_hits * sc->ray_omega;
        double scale = (total - omega_near) / omega_far;
        if (scale > 0.5 && scale < 2.0) {
            for (uint32_t i = 0; i < used; i++)
                if (!sc->order[i]) {
                    sc->tmp_links[i].factor = (float)(sc->tmp_links[i].factor * scale);
                    if (out_sh)
                        for (int j = 0; j < nsh; j++) sc->tmp_sh[(size_t)i * nsh + j] *= (float)scale;
                }
            omega_sum = omega_near + omega_far * scale;
        }
    }
    /* Node order for memory locality at runtime; SH rows follow through a permutation. */
    if (out_sh) {
        for (uint32_t i = 0; i < used; i++) sc->order[i] = i;
        for (uint32_t i = 1; i < used; i++) { /* insertion sort by node: n_L is small */
            uint32_t v = sc->order[i], j = i;
            while (j > 0 && sc->tmp_links[sc->order[j - 1]].node > sc->tmp_links[v].node) {
                sc->order[j] = sc->order[j - 1];
                j--;
            }
            sc->order[j] = v;
        }
        for (uint32_t i = 0; i < used; i++) {
            out[i] = sc->tmp_links[sc->order[i]];
            for (int j = 0; j < nsh; j++)
                out_sh[(size_t)i * nsh + j] = lc_half_from_float(sc->tmp_sh[(size_t)sc->order[i] * nsh + j]);
        }
    } else {
        qsort(sc->tmp_links, used, sizeof *sc->tmp_links, links_by_node);
        memcpy(out, sc->tmp_links, (size_t)used * sizeof *out);
    }
    ctx->used[ci] = used;
    ctx->omega[ci] = omega_sum;
    ctx->rays[ci] = lc.rays;
}

static void links_range(void *arg, size_t begin, size_t end, int thread) {
    const links_ctx *ctx = arg;
    for (size_t i = begin; i < end; i++) links_one_cache(ctx, &ctx->scratch[thread], (uint32_t)i);
    lc_progress_add(ctx->progress, end - begin);
}

int lc_links_build(const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels, const lc_hierarchy *h,
                   const lc_lcb_cache *caches, uint32_t n_caches, const lc_link_params *params, lc_lcb_link *links,
                   uint16_t *link_sh, lc_link_stats *stats) {
    links_ctx ctx = {0};
    int threads = lc_parallel_threads(params ? params->threads : 0), rc = -1;
    if (stats) memset(stats, 0, sizeof *stats);
    if (!rt || !h || !params || (!links && n_caches) || (!surfels && n_surfels) || (!caches && n_caches)) {
        lc_error("links", "lc_links_build: NULL argument");
        return -1;
    }
    if (params->links_per_cache == 0 || params->node_samples == 0 || params->final_samples == 0) {
        lc_error("links", "links_per_cache, node_samples and final_samples must be > 0 (got %u, %u, %u)",
                 params->links_per_cache, params->node_samples, params->final_samples);
        return -1;
    }
    if (link_sh && (params->sh_bands < 1 || params->sh_bands > LC_SH_MAX_BANDS)) {
        lc_error("links", "sh_bands must be in 1..%d when link SH is requested (got %u)", LC_SH_MAX_BANDS,
                 params->sh_bands);
        return -1;
    }
    const uint32_t L = params->links_per_cache;
    const size_t nsh = link_sh ? (size_t)params->sh_bands * params->sh_bands : 0;
    ctx = (links_ctx){rt,      surfels, n_surfels, h,    caches, params, links,
                      link_sh, NULL,    NULL,      NULL, NULL,   NULL,   {{0, 0, 0}, 0, 0, NULL, NULL, NULL, NULL}};
    ctx.scratch = calloc((size_t)threads, sizeof *ctx.scratch);
    ctx.used = calloc(n_caches ? n_caches : 1, sizeof *ctx.used);
    ctx.omega = calloc(n_caches ? n_caches : 1, sizeof *ctx.omega);
    ctx.rays = calloc(n_caches ? n_caches : 1, sizeof *ctx.rays);
    if (!ctx.scratch || !ctx.used || !ctx.omega || !ctx.rays) {
        lc_error("links", "out of memory for per-cache results (%u caches)", n_caches);
        goto err;
    }
    for (int t = 0; t < threads; t++) {
        links_scratch *sc = &ctx.scratch[t];
        /* Each split removes one node and adds at most two: the cut never exceeds L + 1. */
        sc->heap = malloc((size_t)(L + 2) * sizeof *sc->heap);
        sc->done = malloc((size_t)(L + 2) * sizeof *sc->done);
        sc->tmp_links = malloc((size_t)(L + 2) * sizeof *sc->tmp_links);
        sc->order = malloc((size_t)(L + 2) * sizeof *sc->order);
        sc->tmp_sh = nsh ? malloc((size_t)(L + 2) * nsh * sizeof *sc->tmp_sh) : NULL;
        sc->hits = malloc(((size_t)params->probe_rays + 1) * sizeof *sc->hits);
        sc->cum = malloc(3 * ((size_t)params->probe_rays + 1) * sizeof *sc->cum);
        if (!sc->heap || !sc->done || !sc->tmp_links || !sc->order || (nsh && !sc->tmp_sh) || !sc->hits || !sc->cum) {
            lc_error("links", "out of memory for link scratch (%u links per cache)", L);
            goto err;
        }
    }
    if (params->probe_rays && n_surfels && lc_surfel_hash_build(&ctx.hash, surfels, n_surfels) != 0) {
        lc_error("links", "out of memory for the surfel hash (%u surfels)", n_surfels);
        goto err;
    }
    ctx.progress = lc_progress_begin("links", n_caches);
    lc_parallel_for(threads, n_caches, 16, links_range, &ctx);
    lc_progress_end(ctx.progress);
    if (stats && n_caches) {
        double used = 0, omega = 0;
        for (uint32_t i = 0; i < n_caches; i++) {
            used += ctx.used[i];
            omega += ctx.omega[i];
            stats->rays += ctx.rays[i];
        }
        stats->mean_links_used = used / n_caches;
        stats->mean_solid_angle = omega / n_caches;
    }
    rc = 0;
err: /* also the success path: scratch is freed either way */
    if (ctx.scratch)
        for (int t = 0; t < threads; t++) {
            free(ctx.scratch[t].heap);
            free(ctx.scratch[t].done);
            free(ctx.scratch[t].tmp_links);
            free(ctx.scratch[t].order);
            free(ctx.scratch[t].tmp_sh);
            free(ctx.scratch[t].hits);
            free(ctx.scratch[t].cum);
        }
    lc_surfel_hash_free(&ctx.hash);
    free(ctx.scratch);
    free(ctx.used);
    free(ctx.omega);
    free(ctx.rays);
    return rc;
}

/* --- per-surfel gathers: the lossless-transport bound and the texel surfel lists --------------- */

/* The cache's probe hits (sorted by surfel) merged per surfel: weight = sum over its hits of
 * cos * (solid angle per ray) / pi, the irradiance per unit of the surfel's radiosity. Writes at
 * most sc->n_hits entries, in surfel order; returns how many. */
static uint32_t links_surfel_weights(const links_scratch *sc, const links_cache *lc, lc_lcb_surfel_weight *out) {
    uint32_t n = 0;
    const double scale = sc->ray_omega / M_PI;
    for (uint32_t h = 0; h < sc->n_hits; h++) {
        const float *d = sc->hits[h].dir;
        float w = (float)((d[0] * lc->n[0] + d[1] * lc->n[1] + d[2] * lc->n[2]) * scale);
        if (n && out[n - 1].surfel == sc->hits[h].surfel) out[n - 1].weight += w;
        else out[n++] = (lc_lcb_surfel_weight){sc->hits[h].surfel, w};
    }
    return n;
}

/* Per thread, the probe-ray scratch and an entry list; the surfel hash. */
typedef struct {
    links_ctx ctx;
    lc_link_params prm;
    lc_lcb_surfel_weight **entries; /* per thread: probe_rays entries (the bound's list) */
    int threads;
} links_surfel_job;

static void links_surfel_job_free(links_surfel_job *j) {
    if (j->ctx.scratch)
        for (int t = 0; t < j->threads; t++) {
            free(j->ctx.scratch[t].hits);
            free(j->ctx.scratch[t].cum);
        }
    if (j->entries)
        for (int t = 0; t < j->threads; t++) free(j->entries[t]);
    free(j->entries);
    free(j->ctx.scratch);
    lc_surfel_hash_free(&j->ctx.hash);
}

static int links_surfel_job_init(links_surfel_job *j, const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels,
                                 const lc_lcb_cache *caches, uint32_t probe_rays, uint64_t seed, int want_threads) {
    memset(j, 0, sizeof *j);
    j->threads = lc_parallel_threads(want_threads);
    j->prm = (lc_link_params){
        .links_per_cache = 1, .node_samples = 1, .final_samples = 1, .seed = seed, .probe_rays = probe_rays};
    links_ctx *ctx = &j->ctx;
    ctx->rt = rt, ctx->surfels = surfels, ctx->n_surfels = n_surfels, ctx->caches = caches, ctx->prm = &j->prm;
    ctx->scratch = calloc((size_t)j->threads, sizeof *ctx->scratch);
    j->entries = calloc((size_t)j->threads, sizeof *j->entries);
    if (!ctx->scratch || !j->entries) goto oom;
    for (int t = 0; t < j->threads; t++) {
        ctx->scratch[t].hits = malloc(((size_t)probe_rays + 1) * sizeof *ctx->scratch[t].hits);
        ctx->scratch[t].cum = malloc(3 * ((size_t)probe_rays + 1) * sizeof *ctx->scratch[t].cum);
        j->entries[t] = malloc(((size_t)probe_rays + 1) * sizeof *j->entries[t]);
        if (!ctx->scratch[t].hits || !ctx->scratch[t].cum || !j->entries[t]) goto oom;
    }
    if (lc_surfel_hash_build(&ctx->hash, surfels, n_surfels) != 0) goto oom;
    return 0;
oom:
    lc_error("links", "out of memory for the per-surfel gather (%u probe rays, %u surfels)", probe_rays, n_surfels);
    links_surfel_job_free(j);
    return -1;
}

/* Casts cache ci's hemisphere rays; writes its (surfel, weight) list to out (room for
 * probe_rays entries) and returns its length. */
static uint32_t links_surfel_list(links_surfel_job *j, uint32_t ci, int thread, lc_lcb_surfel_weight *out) {
    links_cache lc;
    if ((j->ctx.caches[ci].flags & LC_CACHE_INSIDE) || !links_cache_setup(&j->ctx, ci, &lc)) return 0;
    links_probe(&j->ctx, &j->ctx.scratch[thread], &lc, 1);
    return links_surfel_weights(&j->ctx.scratch[thread], &lc, out);
}

typedef struct {
    links_surfel_job *job;
    const float *radiosity;
    float *irradiance;
} links_bound_job;

static void links_bound_range(void *arg, size_t begin, size_t end, int thread) {
    const links_bound_job *b = arg;
    for (size_t i = begin; i < end; i++) {
        lc_lcb_surfel_weight *e = b->job->entries[thread];
        uint32_t n = links_surfel_list(b->job, (uint32_t)i, thread, e);
        double acc[3] = {0, 0, 0};
        for (uint32_t k = 0; k < n; k++)
            for (int ch = 0; ch < 3; ch++) acc[ch] += (double)e[k].weight * b->radiosity[3 * (size_t)e[k].surfel + ch];
        for (int ch = 0; ch < 3; ch++) b->irradiance[3 * i + ch] = (float)acc[ch];
    }
}

int lc_links_gather_bound(const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels, const lc_lcb_cache *caches,
                          uint32_t n_caches, uint32_t probe_rays, uint64_t seed, int want_threads,
                          const float *radiosity, float *irradiance) {
    if (!rt || !surfels || !n_surfels || (n_caches && (!caches || !irradiance)) || !radiosity || !probe_rays) {
        lc_error("links", "lc_links_gather_bound: NULL argument, no surfels or no probe rays");
        return -1;
    }
    links_surfel_job job;
    if (links_surfel_job_init(&job, rt, surfels, n_surfels, caches, probe_rays, seed, want_threads) != 0) return -1;
    links_bound_job b = {&job, radiosity, irradiance};
    lc_parallel_for(job.threads, n_caches, 16, links_bound_range, &b);
    links_surfel_job_free(&job);
    return 0;
}

typedef struct {
    links_surfel_job *job;
    uint32_t rays;
    lc_lcb_surfel_weight *lists; /* rays entries per texel cache */
    uint32_t *count;
    lc_progress *progress;
} links_texel_job;

static void links_texel_range(void *arg, size_t begin, size_t end, int thread) {
    const links_texel_job *t = arg;
    for (size_t i = begin; i < end; i++) {
        t->count[i] = links_surfel_list(t->job, (uint32_t)i, thread, t->lists + i * t->rays);
    }
    lc_progress_add(t->progress, end - begin);
}

int lc_links_texel_surfels(const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels,
                           const lc_lcb_cache *caches, uint32_t n_texel_caches, uint32_t rays, uint64_t seed,
                           int threads, uint32_t **first_out, lc_lcb_surfel_weight **entries_out, uint64_t *n_out) {
    *first_out = NULL;
    *entries_out = NULL;
    *n_out = 0;
    if (!rt || !surfels || !n_surfels || (n_texel_caches && !caches) || !rays) {
        lc_error("links", "lc_links_texel_surfels: NULL argument, no surfels or no rays");
        return -1;
    }
    links_surfel_job job;
    if (links_surfel_job_init(&job, rt, surfels, n_surfels, caches, rays, seed, threads) != 0) return -1;
    int rc = -1;
    uint32_t *first = malloc(((size_t)n_texel_caches + 1) * sizeof *first);
    uint32_t *count = malloc(((size_t)n_texel_caches + 1) * sizeof *count);
    lc_lcb_surfel_weight *lists = malloc((size_t)n_texel_caches * rays * sizeof *lists + 1);
    if (!first || !count || !lists) {
        lc_error("links", "out of memory for the texel surfel lists (%u texel caches x %u rays)", n_texel_caches, rays);
        goto done;
    }
    links_texel_job t = {&job, rays, lists, count, lc_progress_begin("texel surfel lists", n_texel_caches)};
    lc_parallel_for(job.threads, n_texel_caches, 16, links_texel_range, &t);
    lc_progress_end(t.progress);
    uint64_t n = 0;
    for (uint32_t i = 0; i < n_texel_caches; i++) {
        first[i] = (uint32_t)n;
        memmove(lists + n, lists + (size_t)i * rays, (size_t)count[i] * sizeof *lists); /* n <= i * rays */
        n += count[i];
        if (n > UINT32_MAX) {
            lc_error("links", "texel surfel lists: over 2^32 entries; lower --texel-gather-rays");
            goto done;
        }
    }
    first[n_texel_caches] = (uint32_t)n;
    lc_lcb_surfel_weight *shrunk = realloc(lists, (size_t)n * sizeof *lists + 1);
    *entries_out = shrunk ? shrunk : lists;
    lists = NULL;
    *first_out = first;
    first = NULL;
    *n_out = n;
    rc = 0;
done:
    links_surfel_job_free(&job);
    free(first);
    free(count);
    free(lists);
    return rc;
}
