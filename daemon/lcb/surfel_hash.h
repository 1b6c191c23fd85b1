/* surfel_hash: a bake's surfels bucketed on a uniform grid (an open-addressing hash of
 * cells), to map a ray's hit point to the surfel it landed on. The bake's probe rays
 * (tools/bake/links.c) and the engine's clutter operators (engine/drt.h) attribute hits the
 * same way through it.
 *
 * Threads: build on one thread; lookups are read-only and may run on any number at once.
 * Ownership: the hash copies nothing but indices; the surfels must outlive its lookups. */
#ifndef LC_SURFEL_HASH_H
#define LC_SURFEL_HASH_H
#include <stdint.h>

#include "lcb/lcb.h"

typedef struct lc_surfel_hash {
    float origin[3], inv_cell;
    uint32_t mask;  /* table size - 1 */
    uint64_t *keys; /* cell key + 1 (0 = empty slot) */
    uint32_t *start, *count;
    uint32_t *items; /* surfel indices grouped by cell */
} lc_surfel_hash;

/* Cells of 1.5 x sqrt(mean surfel area), about 2 surfels per cell on a plane. -1 out of
 * memory (nothing left allocated). */
int lc_surfel_hash_build(lc_surfel_hash *h, const lc_lcb_surfel *surfels, uint32_t n);
void lc_surfel_hash_free(lc_surfel_hash *h);

/* Distance to a surfel counts its plane offset this many times more than its tangential
 * distance: a hit on a floor beside a ledge goes to a floor surfel, not to the nearer surfel
 * on the ledge's top. */
#define LC_SURFEL_HASH_PLANE_WEIGHT 10.0f

/* The nearest surfel to hit point p that faces the ray (direction dir) and lies on a surface
 * oriented like the hit (geometric normal ng within 60 degrees, so the two sides of a thin
 * wall stay apart), searching 3x3x3 then 7x7x7 cells; failing that the nearest at all;
 * LC_NONE if none nearby. Nearest: squared distance plus LC_SURFEL_HASH_PLANE_WEIGHT times
 * the squared offset from the surfel's plane. Ties go to the lower index (deterministic). */
uint32_t lc_surfel_hash_nearest(const lc_surfel_hash *h, const lc_lcb_surfel *surfels, const float p[3],
                                const float ng[3], const float dir[3]);

#endif
