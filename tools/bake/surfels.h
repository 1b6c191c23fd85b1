/* surfels: equal-area samples over all static surfaces. Triangles are sampled in proportion
 * to area (area carried across small triangles until it spawns a surfel), positions from a
 * Halton sequence, then relaxed on the tangent plane (repelled from nearest neighbours,
 * staying on their triangle). Every surfel has the same area; their total equals the
 * surface area. */
#ifndef LC_SURFELS_H
#define LC_SURFELS_H
#include <stddef.h>
#include <stdint.h>

#include "bake/scene.h"
#include "lcb/lcb.h"

typedef struct lc_surfel_params {
    uint32_t target_count; /* approximate number of surfels */
    uint32_t relax_iterations;
    uint64_t seed;
    int threads; /* parallel-for workers, 0 = all cores (the result does not depend on it) */
} lc_surfel_params;

/* Generates surfels (lc_lcb_surfel records; cache = LC_NONE, filled later). *out malloc'd,
 * caller frees. *triangle_out (optional, malloc'd) gets each surfel's source triangle.
 * Returns 0 or -1 with err set. */
int lc_surfels_generate(const lc_scene *scene, const lc_surfel_params *params, lc_lcb_surfel **out,
                        uint32_t **triangle_out, uint32_t *n_out, char *err, size_t errlen);

/* One surfel on triangle tri at barycentrics (b1, b2): position, normal, albedo, emission
 * and material from the scene; cache = LC_NONE. */
void lc_surfel_init(const lc_scene *scene, uint32_t tri, float b1, float b2, float area, lc_lcb_surfel *out);

/* Point i of the 2D Halton sequence (bases 2, 3), rotated by rot (Cranley-Patterson), warped
 * to uniform barycentrics (b1, b2) on a triangle. */
void lc_surfel_halton_bary(uint64_t i, const float rot[2], float *b1, float *b2);

#endif
