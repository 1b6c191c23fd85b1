/* relocate: moves caches that sit inside or behind geometry out of it (thesis §5.1.4).
 * From each cache, test rays are cast (texel caches: hemisphere around the normal; grid
 * caches: full sphere). If at least `backface_fraction` of the rays that hit something hit a
 * back face, the cache moves along the shortest back-facing ray to just past that surface
 * (+ offset); a grid cache then moves on along that face's normal by grid_clearance, or half
 * the free distance there if less. A grid cache that is still inside after moving is flagged
 * LC_CACHE_INSIDE. */
#ifndef LC_RELOCATE_H
#define LC_RELOCATE_H
#include <stdint.h>

#include "bake/rt.h"
#include "lcb/lcb.h"

typedef struct lc_relocate_params {
    uint32_t rays;         /* test rays per cache */
    double texel_fraction; /* back-face fraction that triggers a move, texel caches (0.6) */
    double grid_fraction;  /* same for grid caches (0.8, misses ignored) */
    double offset;         /* metres past the back face */
    double grid_clearance; /* metres a moved grid cache then keeps from that face (0: offset only) */
    uint64_t seed;
    int threads; /* parallel-for workers, 0 = all cores (the result does not depend on it) */
} lc_relocate_params;

typedef struct lc_relocate_stats {
    uint32_t moved, inside;
} lc_relocate_stats;

void lc_relocate_caches(const lc_rt *rt, lc_lcb_cache *caches, uint32_t n, const lc_relocate_params *params,
                        lc_relocate_stats *stats);

#endif
