/* surfel_refine: spends part of the surfel budget where the caches see surfaces that no surfel
 * of their own represents (bake option --surfel-refine).
 *
 * Equal-area surfels leave small features (mouldings, ledges, capitals, chair legs) below
 * their spacing without a surfel; a probe hit there is attributed to the nearest surfel of
 * another surface, whose radiosity differs (on Sponza 31% darker on average: the first
 * bounce's −9.5% "surfel attribution" in bench/fidelity.md). Refinement casts a few pilot
 * rays from every cache, finds the hits whose nearest surfel lies on another surface (normal
 * more than LC_REFINE_NORMAL_DEG away, or the hit off the surfel's plane by more than
 * LC_REFINE_PLANE of the surfel spacing), and places the extra surfels on the triangles of
 * those hits, in proportion to their count, over a few rounds (each round re-tests the hits
 * against the surfels so far).
 *
 * The surfels then no longer share one area: each surfel's area becomes the surface area
 * attributed to it (area samples over every triangle, each given to its nearest surfel by the
 * probe rays' own rule, lc_surfel_hash_nearest), so the total stays the surface area and a
 * node's mean radiosity stays area-weighted. Deterministic for a seed and any thread count
 * (integer counts, fixed sequences). */
#ifndef LC_SURFEL_REFINE_H
#define LC_SURFEL_REFINE_H
#include <stddef.h>
#include <stdint.h>

#include "bake/rt.h"
#include "bake/scene.h"
#include "lcb/lcb.h"

#define LC_REFINE_NORMAL_DEG 25.0
#define LC_REFINE_PLANE 0.15

typedef struct lc_surfel_refine_params {
    uint32_t extra;        /* surfels to add */
    uint32_t rounds;       /* the extra surfels are placed over this many rounds */
    uint32_t pilot_rays;   /* per cache and round */
    uint32_t area_samples; /* per surfel, for the areas */
    uint64_t seed;
    int threads;
} lc_surfel_refine_params;

typedef struct lc_surfel_refine_stats {
    uint64_t pilot_hits;       /* front-face pilot hits of the first round */
    double misplaced_before;   /* share of them whose nearest surfel is on another surface */
    double misplaced_after;    /* the same against the final surfels (a last pilot pass) */
    uint32_t added;            /* extra surfels placed on misplaced hits' triangles */
    uint32_t filled;           /* the rest of p->extra, placed by area (no misplaced hit asked for them) */
    double area_min, area_max; /* of the final surfels, relative to the mean */
} lc_surfel_refine_stats;

/* Adds p->extra surfels to *surfels / *tri (both malloc'd, grown here; *n updated): on the
 * misplaced hits' triangles, the rest by area; then sets every surfel's area as above. caches: the bake's caches after relocation (texel
 * caches cast over their hemisphere, grid caches over the sphere; caches inside geometry none).
 * Returns 0, or -1 with err set (out of memory; *surfels / *tri stay valid and owned by the
 * caller). */
int lc_surfels_refine(const lc_rt *rt, const lc_scene *scene, const lc_lcb_cache *caches, uint32_t n_caches,
                      const lc_surfel_refine_params *p, lc_lcb_surfel **surfels, uint32_t **tri, uint32_t *n,
                      lc_surfel_refine_stats *stats, char *err, size_t errlen);

#endif
