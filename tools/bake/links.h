/* links: for each cache, the links_per_cache most important hierarchy nodes by visible
 * solid angle, chosen by refining a cut top-down (the node with the largest estimated
 * visible solid angle is split first). A node's visible solid angle is estimated two ways:
 *  - near field: probe rays cast from the cache over its hemisphere/sphere; each ray that
 *    hits a front face is attributed to the nearest surfel there, so a node's solid angle
 *    is (rays landing in its subtree) x (solid angle per ray) — exact in aggregate, right
 *    next to walls and corners where per-surfel area formulas fail;
 *  - far field (nodes small in angle, see LC_LINKS_NEAR_HITS): the sum of sampled
 *    surfels' disc solid angles, each checked with an Embree ray — precise for small
 *    distant nodes (emitters) that few probe rays would find.
 * Each link stores node, factor = visible solid angle / (pi * node area), the mean
 * direction and a cone whose band-1 ratio matches the spread of the visible samples. */
#ifndef LC_LINKS_H
#define LC_LINKS_H
#include <stdint.h>

#include "bake/hierarchy.h"
#include "bake/rt.h"
#include "lcb/lcb.h"

typedef struct lc_link_params {
    uint32_t links_per_cache; /* n_L */
    uint32_t node_samples;    /* surfels sampled per node while refining */
    uint32_t final_samples;   /* surfels sampled per linked node for the final factor */
    uint32_t sh_bands;        /* > 0: also project each link's transport into SH (LKSH) */
    uint64_t seed;
    uint32_t probe_rays; /* near-field probe rays per cache; 0 = far-field estimate only */
    /* Optional output (NULL = not wanted): n_surfels counters, zeroed by the caller; each
     * cache adds 1 to every surfel its probe rays hit (see bake/exposure.h). */
    uint32_t *surfel_seen;
    int threads; /* parallel-for workers, 0 = all cores (the result does not depend on it) */
} lc_link_params;

/* A node is near (probe-ray estimate) when the cache is within 2 bounding radii of its
 * centre, or its bounding sphere spans the solid angle of LC_LINKS_NEAR_HITS probe rays;
 * smaller nodes (distant emitters) take the surfel-area estimate, which few probe rays
 * would find only noisily. */
#define LC_LINKS_NEAR_HITS 8.0f

typedef struct lc_link_stats {
    double mean_links_used;  /* links with factor > 0, mean over caches */
    double mean_solid_angle; /* sum of link solid angles per cache, mean */
    uint64_t rays;
} lc_link_stats;

/* links: n_caches * links_per_cache records (caller allocates). link_sh: NULL or
 * n_caches * links_per_cache * sh_bands^2 halves. Caches flagged LC_CACHE_INSIDE get
 * padding links only. Deterministic for a seed regardless of thread count. */
int lc_links_build(const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels, const lc_hierarchy *h,
                   const lc_lcb_cache *caches, uint32_t n_caches, const lc_link_params *params, lc_lcb_link *links,
                   uint16_t *link_sh, lc_link_stats *stats);

/* The lossless-transport bound, a diagnostic: each texel cache's irradiance (W/m^2, RGB, for
 * its normal) gathered straight from the surfels its probe rays hit,
 *   E = sum over hits of B(hit surfel) / pi * cos * (solid angle per ray),
 * with the bake's ray stratification and hit attribution — the quantity the links compress, without
 * the compression. An engine solution can get no closer to the truth than this through its
 * surfels; lucent-ref fidelity reports it beside the engine. radiosity: n_surfels x 3;
 * irradiance: n_caches x 3 (grid and inside caches get 0). threads: parallel-for workers
 * (0 = all cores). Returns 0, or -1 (logged). */
int lc_links_gather_bound(const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels, const lc_lcb_cache *caches,
                          uint32_t n_caches, uint32_t probe_rays, uint64_t seed, int threads, const float *radiosity,
                          float *irradiance);

/* Per texel cache, the surfels its RAYS hemisphere rays hit with their weights (the bound's
 * stratification, hit attribution and weights: E = sum weight x B is the bound at RAYS rays):
 * *first_out n_texel_caches + 1 offsets into *entries_out (*n_out entries), each list in surfel
 * order; inside caches get none. The engine then gathers texel caches per surfel (TSGF/TSGW).
 * Deterministic for a seed regardless of threads. The caller frees both. Returns 0, or -1
 * (logged). */
int lc_links_texel_surfels(const lc_rt *rt, const lc_lcb_surfel *surfels, uint32_t n_surfels,
                           const lc_lcb_cache *caches, uint32_t n_texel_caches, uint32_t rays, uint64_t seed,
                           int threads, uint32_t **first_out, lc_lcb_surfel_weight **entries_out, uint64_t *n_out);

/* Visible solid angle of surfel s seen from point p (disc approximation, no visibility):
 * cos(theta_s) * 2 pi (1 - d / sqrt(d^2 + A / pi)); 0 when the surfel faces away.
 * For texel caches (normal n != 0) also 0 when the surfel lies behind the cache's plane. */
double lc_links_surfel_solid_angle(const lc_lcb_surfel *s, const float p[3], const float n[3]);

#endif
