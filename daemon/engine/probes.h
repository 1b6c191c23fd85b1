/* probes: the runtime of the probes solver (the method: tools/bake/probes.h; the data and
 * the three equations: lcb/lcb.h, "The probes solver"). It stands in for PIC's pull and
 * gather: from the surfels' radiosity B it writes every receiving cache's radiance SH in the
 * layout the gather would, so DNRT, DRT, the lightmap, the grid, the objects and the feedback
 * that follow are the same code for both solvers:
 *   texel cache, irradiance E for its normal n: band 1 L_1m = E y_1m(n), which the texel
 *     irradiance (4 pi / 3) sum_m L_1m y_1m(n) turns back into E (band 0 = E / (2 pi y_00)
 *     with one band); a surfel reading the cache for its own normal n_s gets E (n . n_s);
 *   grid cache, L2 irradiance SH E_j: L_j = E_j / A_l, the grid output's A_l L_j gives E_j.
 * Caches without rows (inside geometry) read zero. The per-texel SH lightmap therefore
 * carries only that cosine lobe under this solver.
 *
 * Threads: create/release on the engine's thread; lc_probes_gather runs there and fans out
 * with lc_parallel_for. Ownership: the handle borrows the view (which must outlive it) and
 * owns its scratch. */
#ifndef LC_PROBES_H
#define LC_PROBES_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

typedef struct lc_probes lc_probes;

/* NULL with err set when the bake has no probes solver or memory runs out. */
lc_probes *lc_probes_create(const lc_lcb_view *v, char *err, size_t errlen);
void lc_probes_release(lc_probes *p);

/* One pass from radiosity (n_surfels x 3): the rows' values, written into cache_sh (records
 * of `stride` coefficients x 3 channels) for the first `bands`^2 coefficients (band 0 only
 * when bands is 1); coefficients above what a cache carries are zeroed. need (n_caches
 * bytes, lc_transport_needed) picks the clusters holding a row of a needed cache; NULL =
 * all. The caches of clusters skipped read zero. */
void lc_probes_gather(lc_probes *p, const float *radiosity, uint32_t bands, float *cache_sh, uint32_t stride,
                      const uint8_t *need, int threads);

/* active[c] = 1 when cluster c holds a row of a cache with need[cache] set (0 otherwise);
 * returns how many are. Both backends choose their clusters with it. */
uint32_t lc_probes_active_clusters(const lc_lcb_view *v, const uint8_t *need, uint32_t *active);

/* The relight rays' SH table both backends use: out[k * bands^2 + j] = y_j(dir_k) x
 * (4 pi / n_rays) / pi, so lambda = sum_k out[k] B[hit k] (n_rays x bands^2 floats). */
void lc_probes_ray_sh(const lc_lcb_probe_header *h, float *out);

/* The probes' radiance SH of the last gather: n_probes x 3 x coeffs (each channel's
 * coefficients contiguous). */
const float *lc_probes_sh(const lc_probes *p);

#endif
