/* transfer: the DNRT transfer grid of a dynamic-object asset (Deferred Neighboring Radiance
 * Transfer, ../shared/papers/dnrt-deferred-neighboring-radiance-transfer.txt §5.1): for every
 * vertex of a regular grid around the asset, in its own frame, how much light the asset
 * reflects toward the vertex (T, RGB, per SH coefficient of its incident irradiance) and how
 * much of the surrounding field it blocks (K, per SH coefficient of the field). What is
 * stored, and how a receiver's change of irradiance follows from it: lc_lcb_transfer in
 * lcb/lcb.h. The runtime is daemon/engine/dnrt.h.
 *
 * Sampling (not in the paper, which does not give it): rays uniform in the cone of the
 * asset's bounding sphere seen from the vertex (every ray aims at the asset; weight = the
 * cone's solid angle / rays x cos to the centre), stratified in cos and azimuth with a
 * per-vertex rotation; vertices inside the bounding sphere sample the whole sphere.
 * Vertices whose rays mostly hit back faces are inside the asset: they are filled from
 * their outside neighbours (DRT's inpainting), so trilinear lookups next to the surface
 * do not blend in values from inside. Deterministic for a seed. */
#ifndef LC_TRANSFER_H
#define LC_TRANSFER_H
#include <stddef.h>
#include <stdint.h>

#include "bake/scene.h"
#include "lcb/lcb.h"

typedef struct lc_transfer_params {
    int dims;     /* grid vertices per axis, 2..64 (paper: 32) */
    int coeffs;   /* SH coefficients per term, 4 or 9 (paper: 4) */
    int rays;     /* rays per vertex */
    float extent; /* inner volume half side, in bounding-sphere radii */
    float outer;  /* outer radius (where the effect ends) / inner half side */
    int threads;  /* 0 = all cores */
    uint32_t seed;
} lc_transfer_params;

typedef struct lc_transfer_stats {
    double seconds;
    uint32_t inside_vertices; /* filled from their neighbours */
    uint64_t bytes;           /* quantised values */
} lc_transfer_stats;

/* Bakes the grid of `asset` (its mesh and materials as imported, asset-local metres). Fills
 * *hdr (all but hdr->asset and hdr->data_offset, which the caller sets) and *values
 * (malloc'd, lc_lcb_transfer_bytes(hdr) bytes; the caller frees it). Returns 0, or -1 with
 * err set (bad parameters, an asset without triangles, out of memory). */
int lc_transfer_bake(const lc_scene *asset, const lc_transfer_params *p, lc_lcb_transfer *hdr, int8_t **values,
                     lc_transfer_stats *stats, char *err, size_t errlen);

#endif
