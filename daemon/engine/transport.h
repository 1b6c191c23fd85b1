/* transport: the light-transport half of a relight, behind one interface with a CPU and an
 * EGL/GL implementation. Given each surfel's direct radiosity B0 (emission + reflected
 * direct light + sky), it runs the PIC pipeline:
 *
 *   repeat bounces + 1 times:
 *     B[s]    = B0[s] + albedo[s] * E_ind[s]                      (feedback; E_ind starts at 0,
 *                                                                   or the last relight's if progressive)
 *     flux    = B * area at the leaves, pulled up the tree         (pull)
 *     L_c,lm  = sum over the cache's used links of
 *               flux[node] * factor * h_l(cos alpha) * y_lm(dir)   (gather; radiance SH)
 *     E_ind[s]= irradiance at surfel s's cache for the cache normal (feedback)
 *   (after each gather, placed objects change the caches around them: engine/dnrt.h, then
 *    clutter operators add their deltas: engine/drt.h)
 *   lightmap texel = irradiance of its cache; grid = L2 irradiance SH; objects = trilinear grid
 *
 * Irradiance from a cache's radiance SH for normal n:
 *   texel caches (links only in front of the surface): E = (4pi/3) sum_m L_1m y_1m(n),
 *     exact for light confined to the front hemisphere (band 1 carries all of it);
 *   grid caches (full sphere): E = sum_{l<=2} A_l sum_m L_lm y_lm(n), A = (pi, 2pi/3, pi/4).
 * With bands == 1 a texel cache falls back to E = 2 pi L_00 y_00 (uniform front hemisphere). */
#ifndef LC_TRANSPORT_H
#define LC_TRANSPORT_H
#include <stddef.h>

#include "engine/dnrt.h"
#include "engine/drt.h"
#include "engine/engine.h"

typedef struct lc_transport_input {
    const float *b0; /* n_surfels*3 */
    lc_engine_settings settings;
    int reset_feedback;      /* forget the previous relight's indirect light */
    const float *object_pos; /* n_objects*3 world positions to sample the grid at */
    uint32_t n_objects;
    const lc_dnrt_frame *dnrt; /* objects in the indirect light, applied after each gather; NULL = none */
    lc_drt_ops *const *drt;    /* clutter operators (engine/drt.h), applied after DNRT in each pass */
    uint32_t n_drt;
    lc_engine_interrupt_fn interrupt; /* NULL = never; see lc_engine_set_interrupt */
    void *interrupt_arg;
} lc_transport_input;

typedef struct lc_transport_ops {
    const char *name;
    /* Returns an implementation handle or NULL with err set. The view must outlive it. */
    void *(*create)(const lc_lcb_view *v, int threads, char *err, size_t errlen);
    void (*release)(void *impl);
    /* Fills the frame's output array pointers (owned by impl, valid until the next run;
     * records are LC_SH_MAX_COEFFS coefficients wide) and the stage timings BOUNCE..DNRT.
     * The engine fills the dimensions. */
    int (*run)(void *impl, const lc_transport_input *in, lc_engine_frame *frame, char *err, size_t errlen);
    /* run returns LC_ENGINE_INTERRUPTED when in->interrupt stopped it before a feedback pass. */
} lc_transport_ops;

/* Bands a texel cache gathers. Its irradiance reads band 1 only (band 0 with one band), so
 * the higher bands are not gathered there unless the per-texel SH lightmap is asked for:
 * at 3 bands this drops 5 of 9 coefficients at every texel-cache link. The cache_sh of a
 * texel cache holds zeros above these bands. Both backends use it (identical outputs). */
static inline int lc_transport_texel_bands(const lc_engine_settings *st) {
    return st->sh_lightmap || st->bands < 2 ? (int)st->bands : 2;
}

/* Texel caches without the SH lightmap carry band 1 only: the irradiance for their normal
 * and the feedback to their surfels (for the surfel's normal) read nothing else. Band 1 is
 * linear in the node flux with lighting-independent weights per link,
 *   L_1m += flux[node] * w_m,  w_m = factor * h_1(cos alpha) * y_1m(dir),
 * so the CPU backend precomputes the three w_m per texel-cache link at load and gathers
 * with 9 multiply-adds per link instead of decoding the direction and evaluating the SH
 * basis; the GL backend keeps its SH evaluation and clears band 0. Identical results. */
static inline int lc_transport_texel_band1(const lc_engine_settings *st) { return !st->sh_lightmap && st->bands >= 2; }

/* A bake's texel surfel lists (TSGF/TSGW) replace the links at texel caches unless the SH
 * lightmap is asked for: a list gives the irradiance for the cache normal, not its radiance's
 * directions. Both backends, both reading it here. */
static inline int lc_transport_texel_surfels(const lc_lcb_view *v, const lc_engine_settings *st) {
    return v->texel_surfels_first != NULL && !st->sh_lightmap;
}

/* A texel cache's irradiance E (RGB, for its unit normal n) as the radiance SH a gather leaves
 * there: band 1 a cosine lobe about n (bands >= 2), else band 0, so that the lightmap's
 * 4pi/3 sum_m L_1m y_1m(n) (or band 0's 2pi y_0 L_00) and the feedback read back E. Writes only
 * those coefficients of dst ([coeff][3]); the caller zeroes the rest. */
static inline void lc_transport_texel_store(float *dst, const float n[3], uint32_t bands, const float e[3]) {
    if (bands < 2) {
        const float s = 1.0f / (float)(2.0 * 3.14159265358979323846 * 0.282094791774);
        for (int k = 0; k < 3; k++) dst[k] = e[k] * s;
        return;
    }
    const float y[3] = {0.488602511903f * n[1], 0.488602511903f * n[2], 0.488602511903f * n[0]};
    for (int m = 0; m < 3; m++)
        for (int k = 0; k < 3; k++) dst[3 * (1 + m) + k] = e[k] * y[m];
}

/* Chroma compression is on only when it drops bands: Co/Cg get chroma_bands < bands. */
static inline int lc_transport_chroma(const lc_engine_settings *st) {
    return st->chroma_compression && st->chroma_bands < st->bands;
}

extern const lc_transport_ops lc_transport_cpu;
extern const lc_transport_ops lc_transport_egl;

/* --- shared by both backends (engine/transport.c) ----------------------------------------- */

/* The h_l(cos alpha) table for the 256 quantised cone angles, 8 bands each: the CPU gather's
 * lookup and the GL backend's upload (one table, so both weigh a link the same). */
void lc_transport_cone_table(float table[256][8]);

/* The settings a run refuses (err names the field): bands outside 1..LC_SH_MAX_BANDS. */
int lc_transport_check_settings(const lc_engine_settings *st, char *err, size_t errlen);

/* The host arrays a backend publishes in each frame, laid out the same by both (cache and
 * lightmap SH records LC_SH_MAX_COEFFS coefficients wide), so either backend's frame reads
 * the same way. Owned by the backend; the frame borrows them until the next run. */
typedef struct lc_transport_outputs {
    float *radiosity;   /* n_surfels*3: B of the last pass */
    float *flux;        /* n_nodes*3: pulled flux of the last pass (YCoCg when compressing) */
    float *cache_sh;    /* n_caches*LC_SH_MAX_COEFFS*3 */
    float *lightmap;    /* W*H*3 */
    float *lightmap_sh; /* W*H*LC_SH_MAX_COEFFS*3, allocated on first use */
    float *grid_sh;     /* cells*27 */
    float *object_sh;   /* object_cap*27, grown on demand */
    uint32_t object_cap;
} lc_transport_outputs;

/* Allocates every array but the SH lightmap and the objects', zeroed; -1 out of memory
 * (nothing left allocated). */
int lc_transport_outputs_alloc(lc_transport_outputs *o, const lc_lcb_view *v);
void lc_transport_outputs_release(lc_transport_outputs *o);
/* Room for n_objects objects' SH; -1 with err ("<backend> transport: out of memory ..."). */
int lc_transport_reserve_objects(lc_transport_outputs *o, uint32_t n_objects, const char *backend, char *err,
                                 size_t errlen);
/* The SH lightmap: each texel's cache SH (zeros for empty texels), from o->cache_sh. A
 * per-texel copy on the host is cheaper than a GPU read-back of W*H records. -1 with err. */
int lc_transport_fill_lightmap_sh(lc_transport_outputs *o, const lc_lcb_view *v, const char *backend, char *err,
                                  size_t errlen);
/* The caches a pass must compute (need: n_caches bytes, 1 = compute): in an intermediate
 * pass those some surfel reads (`feedback`, per cache) and the DNRT objects' grid corners;
 * in the last pass also every texel cache (the lightmap) and every object's corners (its
 * SH), or everything under settings.grid_cells ALL. Returns how many. Both backends gather
 * exactly these, so their outputs agree and NEEDED changes no output but the grid's. */
uint32_t lc_transport_needed(const lc_lcb_view *v, const uint8_t *feedback, const lc_transport_input *in, int last,
                             uint8_t *need);
/* Under settings.grid_cells NEEDED, zeroes the grid cells whose cache was not computed. */
void lc_transport_clear_unneeded_cells(lc_transport_outputs *o, const lc_lcb_view *v, const uint8_t *need);

/* Points the frame's output arrays at o (the engine front fills the dimensions). */
void lc_transport_publish(const lc_transport_outputs *o, const lc_engine_settings *st, lc_engine_frame *fr);

#endif
