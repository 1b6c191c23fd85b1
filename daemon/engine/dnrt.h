/* dnrt: placed objects in the indirect light (Deferred Neighboring Radiance Transfer,
 * ../shared/papers/dnrt-deferred-neighboring-radiance-transfer.txt), in texel space.
 *
 * For each placed object whose asset has a transfer grid (lcb.h, lc_lcb_transfer) the
 * engine finds, when objects move, the receivers inside its outer volume: texel caches
 * facing it, grid caches, and the other objects' SH sample points. Each receiver keeps the
 * grid's T and K at its position (trilinear; outside the inner cube the value at the cube's
 * surface along the ray from the centre, times 1/d^2; a linear taper over the last 20% of
 * the outer radius so the edge leaves no ring), the unit direction d to the object's
 * centre and, optionally, the fraction of rays from it to the object that no static
 * geometry blocks (a wall between them).
 *
 * At every transport pass, after the gather and before the surfels' feedback reads the
 * caches (so further bounces see the object), with the object's incident irradiance SH c
 * (the grid at its centre, rotated into the asset's frame) and c_tot = c + its direct light:
 *   X = sum_j c_tot_j T_j - sum_j c_j K_j         (RGB; the change of irradiance facing d)
 * is added to each receiving cache's radiance SH as a source from direction d,
 *   L_lm += X y_lm(d),
 * which gives texel caches E(n) = X (d.n) (the paper's (n_o.n_r)+ factor, receivers facing
 * away are not listed) and grid caches the L2 lobe of X (d.n)+. An object's own SH is the
 * grid without any object's change plus the other objects' changes at its centre, so it
 * never shadows itself. One bounce of the object's light, as the paper; its effect on the
 * static scene's further bounces comes from lucent's feedback. Rigid objects; the
 * intermediate-normal approximation (A5) is the paper's.
 *
 * Threads: used by the engine's (compute) thread only. Ownership: the module borrows the
 * bake view; the frame it returns is valid until the next place/direct/release. */
#ifndef LC_DNRT_H
#define LC_DNRT_H
#include <embree3/rtcore.h>
#include <stddef.h>
#include <stdint.h>

#include "engine/engine.h"

#define LC_DNRT_OBJECT_RECEIVER 0x80000000u /* target = this | object index: an object's SH */

typedef struct lc_dnrt_object {
    uint32_t object; /* index in the state's objects */
    uint32_t coeffs; /* 4 or 9: its asset's transfer */
    float to_local[9][9];
    float center[3]; /* world */
    float c_dir[27]; /* the direct light's irradiance SH at the object (world, RGB per coefficient) */
    uint32_t first;  /* receivers [first, first + count) */
    uint32_t count;
    uint32_t corner[8]; /* the grid caches its SH sample reads (trilinear corners) */
    float corner_w[8];
} lc_dnrt_object;

typedef struct lc_dnrt_frame {
    const lc_dnrt_object *objects;
    uint32_t n_objects;
    const uint32_t *targets; /* per receiver: cache index or LC_DNRT_OBJECT_RECEIVER | object */
    const float *dirs;       /* per receiver: 3 floats */
    const float *values;     /* per receiver: 36 floats, T (coeff-major RGB) at [0, 27), K at [27, 36) */
    uint32_t n_receivers;
    uint64_t generation; /* changes whenever the contents do (each place and direct): for backends' uploads */
    uint64_t placement;  /* changes only when the receivers do (each place): their upload */
} lc_dnrt_frame;

typedef struct lc_dnrt lc_dnrt;

/* Spatial index over the bake's caches (only when some asset has transfer data). NULL with
 * err on out of memory. */
lc_dnrt *lc_dnrt_create(const lc_lcb_view *v, char *err, size_t errlen);
void lc_dnrt_release(lc_dnrt *d);

/* Receivers for the objects as placed (object_pos: each object's SH sample point, world),
 * with the global and per-object switches; blockers: rays against `static_scene` (lifted by
 * eps). -1 with err on out of memory (the previous placement is kept). */
int lc_dnrt_place(lc_dnrt *d, const lc_engine_object *objects, uint32_t n, const float *object_pos,
                  const lc_engine_settings *st, RTCScene static_scene, float eps, char *err, size_t errlen);

/* The direct light arriving at each placed object (shadow rays from the light side of its
 * bounding sphere against `scene`: the static mesh and the other objects); `objects` are
 * the ones lc_dnrt_place was given. */
void lc_dnrt_direct(lc_dnrt *d, const lc_engine_light *lights, uint32_t n_lights, RTCScene scene, float eps,
                    const lc_engine_object *objects);

/* The current placement; n_objects 0 when nothing applies. */
const lc_dnrt_frame *lc_dnrt_frame_get(const lc_dnrt *d);

/* Where the sums go, for a transport backend: the cache SH records (stride coefficients
 * each, RGB interleaved), which coefficients a texel or grid cache carries, and which
 * caches hold this pass's values (fresh[c] != 0; NULL = all). */
typedef struct lc_dnrt_target {
    float *cache_sh;
    size_t stride;
    uint32_t n_texel_caches;
    int texel_lo, texel_nc; /* texel caches: coefficients [lo, nc) */
    int grid_nc;            /* grid caches: [0, nc) */
    const uint8_t *fresh;
    float *object_delta; /* n_objects*27: L2 irradiance SH added at object receivers, or NULL */
} lc_dnrt_target;

/* The grid caches and weights of the trilinear sample at p (clamped to the lattice) that
 * both backends take an object's SH from. */
void lc_dnrt_grid_corners(const lc_lcb_view *v, const float p[3], uint32_t corner[8], float w[8]);

/* X for every receiver of every object and its sum into the target (see the top). c_world:
 * per placed object (frame order), its incident irradiance SH from the grid (27 floats). */
void lc_dnrt_apply(const lc_dnrt_frame *f, const float *c_world, const lc_dnrt_target *tg);

#endif
