/* exposure: weigh each surfel by how widely the caches see it (bake option --exposure).
 *
 * A link carries its node's mean radiosity, weighted by the stored surfel areas; a cache
 * sees the node weighted by each surfel's visible solid angle. Surfels the caches rarely
 * see (buried under a column base, in crevices) still pull a node's mean toward their own,
 * usually darker, radiosity, which biases the first bounce low. With exposure the stored surfel area becomes the effective
 * area a_i * u_i / mean(u), u_i the number of caches whose probe rays hit surfel i (floored
 * at LC_EXPOSURE_FLOOR of the mean so every weight stays positive); the total is kept. With
 * unequal surfel areas (--surfel-refine) the mean is scaled to each surfel's area, since a
 * larger surfel catches more caches' rays: the weight is how widely the surface is seen. Node
 * areas are recomputed and every link factor (visible solid angle / (pi * node area)) and
 * LKSH record rescaled, so a link's solid angle is unchanged and its node mean becomes
 * exposure-weighted. Runtimes need no change: they use the area only through
 * flux = B * area and the factor. Opt-in: it lowers the mean error and bias but raises the
 * p95 (docs/ARCHITECTURE.md, Decisions: "Exposure weights"). */
#ifndef LC_EXPOSURE_H
#define LC_EXPOSURE_H
#include <stdint.h>

#include "bake/hierarchy.h"
#include "lcb/lcb.h"

#define LC_EXPOSURE_FLOOR 0.01

typedef struct lc_exposure_stats {
    uint32_t unseen;    /* surfels no cache sees */
    double unseen_area; /* their geometric area, m^2 */
} lc_exposure_stats;

/* seen: n_surfels counts (lc_link_params.surfel_seen). Rewrites surfels[].area, the
 * hierarchy's node areas, links[].factor and link_sh (NULL, or n_links * nsh halves).
 * Deterministic (sequential sums in surfel order). Returns 0, or -1 if nothing is seen. */
int lc_exposure_apply(const uint32_t *seen, lc_lcb_surfel *surfels, uint32_t n_surfels, lc_hierarchy *h,
                      lc_lcb_link *links, uint64_t n_links, uint16_t *link_sh, uint32_t nsh, lc_exposure_stats *stats);

#endif
