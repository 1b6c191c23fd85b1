/* lightmap_filter: a 3x3 smoothing of the lightmap over texels of one surface.
 *
 * Each texel cache gathers its own cut of the hierarchy, so neighbouring texels differ by
 * more than the light does (issue 16: neighbour-to-neighbour variation 11.9% against the
 * reference's 9.1% on the Cornell box). The filter averages each texel with its 8 neighbours
 * (binomial weights 4 / 2 / 1, renormalised) that lie on the same surface: texels owning their
 * cache, normals within 25 degrees, and no farther than 1.5 x the texel's nearest 4-neighbour
 * (diagonals x sqrt 2), so chart seams, creases and texels far apart in the world are left out.
 * Texels whose cache the bake moved out of geometry keep their own value and are nobody's
 * neighbour. Dilated texels (sharing another texel's cache) take their owner's filtered value.
 *
 * A neighbour also weighs less the more its light differs (the range weight below), so real
 * edges of the light stay sharp. Only the irradiance lightmap is filtered, not the optional
 * SH lightmap. Measured (bench/fidelity.md, issue 16): Cornell mean 6.70 -> 5.89%, p95 17.2 ->
 * 15.2%, blotch ratio 1.31 -> 1.07; Sponza at 0.5 m texels 21.17 -> 21.07% (without the range
 * weight Sponza went to 36%: a 3x3 blur over 1.5 m mixes real edges).
 *
 * The taps are built once from the bake (positions and normals of the texel caches); applying
 * them is W*H x at most 9 multiply-adds per channel, on the CPU after either backend.
 * Ownership: the filter copies what it needs; the view need not outlive it. */
#ifndef LC_LIGHTMAP_FILTER_H
#define LC_LIGHTMAP_FILTER_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

typedef struct lc_lmfilter lc_lmfilter;

/* Range of the value weight: a neighbour differing by d (relative luminance) weighs
 * exp(-(d / range)^2) of its spatial weight, so real edges of the light stay. */
#ifndef LC_LMFILTER_RANGE
#define LC_LMFILTER_RANGE 0.2f
#endif

/* NULL with err on out of memory. */
lc_lmfilter *lc_lmfilter_create(const lc_lcb_view *v, char *err, size_t errlen);
/* out = filtered in (both W*H*3; must not alias), on `threads` threads (0 = all cores;
 * lc_parallel_for). */
void lc_lmfilter_apply(const lc_lmfilter *f, const float *in, float *out, int threads);
/* Texels that have neighbours (for tests and logs). */
uint32_t lc_lmfilter_filtered_texels(const lc_lmfilter *f);
void lc_lmfilter_release(lc_lmfilter *f);

#endif
