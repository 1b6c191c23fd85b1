/* drt: clutter that stays (Delta Radiance Transfer,
 * ../shared/papers/delta-radiance-transfer.txt, in lucent's surfel-hierarchy basis; the
 * mapping is ../shared/notes/seed-techniques.md section 3).
 *
 * For an object placed and left, a builder casts rays once for that placement and produces
 * delta operators that the transport then applies at every pass, so the clutter's indirect
 * shadow and bounce are texel-accurate instead of DNRT's grid approximation:
 *
 *   patches   the object's surface in ~`patches` pieces of constant radiosity (each asset
 *             triangle split k x k, or small triangles grouped by cell and facing): DRT's
 *             per-face constant basis. Each patch has direct-light sample points (elements,
 *             lit by the engine's direct stage like static surfels) and a gather (C_b): rays
 *             from its elements to the static scene's nodes (and to the object's own
 *             patches), E_p = sum w flux[source].
 *   receivers texel and grid caches within radius_factor bounding radii of the object, with
 *             a line of sight to it: `rays` rays per cache aimed at its bounding sphere (the
 *             whole hemisphere or sphere when the cache is inside that sphere). A ray that
 *             hits the object before the static scene
 *               - blocks what it reached before (DeltaU_b, anti-radiance): a negative entry on
 *                 the node holding the static hit (the largest ancestor of the hit surfel's
 *                 leaf subtending less than node_angle), weight -Omega y_lm(w)/(pi A_node);
 *               - sees the patch it hit (DeltaU_c): +Omega y_lm(w)/(pi A_patch) on the patch.
 *             Per receiver the entries are merged by source; texel caches keep bands 0-1,
 *             grid caches bands 0-2. An outer taper (the last 20% of the radius) leaves no
 *             ring.
 *   inpaint   texel caches inside or under the object (at least inpaint_threshold of their
 *             rays hit its back faces or hit it within a texel's spacing) take the average of
 *             valid lightmap neighbours on the same surface, after the deltas (the paper's
 *             "average Ubar, not DeltaU", which is the same thing here since it is linear).
 *
 * At each pass, after the gather (lc_drt_apply): patch E from this pass's node flux, patch
 * radiosity B_p = rho_p (E_direct + E_gather), then every receiver's cache SH gains
 *   L_lm += sum_entries flux[source] w_lm
 * with flux[patch] = B_p A_p, then the inpainted caches are filled. Further bounces see the
 * clutter through lucent's feedback (surfels read their caches), so its shadow and colour
 * reach every bounce, as the seed notes propose beyond the paper's single bounce.
 *
 * Operators are relative to the static scene: other objects are not in their rays (DNRT and
 * the direct stage cover those), and a clutter object is taken out of DNRT while its
 * operators apply.
 *
 * Threads: a builder is used by one thread at a time (lucentd's clutter worker) and runs its
 * rays on `threads` workers; it never touches an engine. Operators are handed to the engine
 * (lc_engine_clutter_attach), which then owns them and uses them on its own thread only. */
#ifndef LC_DRT_H
#define LC_DRT_H
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "engine/engine.h"

#define LC_DRT_PATCH 0x80000000u /* source = this | patch index: one of the object's own patches */

typedef struct lc_drt_settings {
    uint32_t rays;           /* per receiving cache (the paper's 1024) */
    uint32_t patch_rays;     /* per patch, for its gather (C_b) */
    uint32_t patches;        /* target patches per object */
    float radius_factor;     /* receivers within this many bounding radii of the centre */
    float node_angle;        /* radians: blocked light goes to the largest node smaller than this */
    float inpaint_threshold; /* fraction of a texel cache's rays inside the object that marks it covered */
} lc_drt_settings;

/* rays 1024, patch_rays 256, patches 128, radius_factor 6, node_angle 0.12, inpaint 0.5. */
lc_drt_settings lc_drt_default_settings(void);
/* -1 with err naming the field (e.g. "clutter_rays: 0 is outside 16..65536"). */
int lc_drt_check_settings(const lc_drt_settings *s, char *err, size_t errlen);

typedef struct lc_drt_builder lc_drt_builder;
typedef struct lc_drt_ops lc_drt_ops;

/* A builder over a validated bake: its own Embree device and static scene, the surfel hash
 * that attributes hits, the node tree's parents. threads 0 = all cores. NULL with err. */
lc_drt_builder *lc_drt_builder_create(const lc_lcb_view *v, int threads, char *err, size_t errlen);
void lc_drt_builder_release(lc_drt_builder *b);

/* Builds the operators for `object` as placed (its asset must be in the bake: the caller
 * validated the state). `cancel`, when not NULL, is polled between batches of receivers:
 * non-zero abandons the build (returns 1, *out NULL), so a newer placement never waits for
 * an outdated one. 0 and *out (owned by the caller) or -1 with err (out of memory). */
int lc_drt_build(lc_drt_builder *b, const lc_engine_object *object, const lc_drt_settings *s, const atomic_int *cancel,
                 lc_drt_ops **out, char *err, size_t errlen);
void lc_drt_ops_release(lc_drt_ops *ops);

/* What a build made, for logs, lucent-bench and the protocol's event. */
typedef struct lc_drt_info {
    uint32_t patches, elements;
    uint32_t receivers, texel_receivers, grid_receivers, inpainted;
    uint64_t entries; /* receiver entries (negative and positive) */
    uint64_t rays;    /* rays cast in the build, all kinds */
    size_t bytes;     /* the operators' memory */
    double build_ms;  /* wall time of lc_drt_build */
} lc_drt_info;
lc_drt_info lc_drt_ops_info(const lc_drt_ops *ops);
/* The object (id, asset, placement) the operators were built for. */
const lc_engine_object *lc_drt_ops_object(const lc_drt_ops *ops);

/* 1 when the operators were built for exactly this object's id, asset and placement (the
 * transform compared bit for bit: any move makes them stale). */
int lc_drt_ops_match(const lc_drt_ops *ops, const lc_engine_object *object);
/* 1 when a and b are the same object in the same placement (id, asset, transform). */
int lc_drt_same_placement(const lc_engine_object *a, const lc_engine_object *b);

/* --- runtime (the engine's thread) ---------------------------------------------------------- */

/* The direct-light sample points of the patches, world space, for the engine's direct stage:
 * element i at positions[3i], unit normal normals[3i]; it writes irradiance (RGB) into
 * e_direct[3i] (lc_drt_elements_lit then averages them per patch). */
typedef struct lc_drt_elements {
    uint32_t n;
    const float *positions, *normals;
    float *e_direct;
} lc_drt_elements;
lc_drt_elements lc_drt_elements_get(lc_drt_ops *ops);
/* After the engine filled e_direct: the patches' direct irradiance (area-weighted means). */
void lc_drt_elements_lit(lc_drt_ops *ops);

/* Where the deltas go, for a transport backend (the layout of lc_dnrt_target). */
typedef struct lc_drt_target {
    const float *node_flux; /* n_nodes*3: this pass's pulled flux */
    int flux_ycocg;         /* node_flux is YCoCg (chroma compression); caches are RGB */
    float *cache_sh;
    size_t stride;
    uint32_t n_texel_caches;
    int texel_lo, texel_nc; /* texel caches: coefficients [lo, nc), nc <= 4 is used */
    int grid_nc;            /* grid caches: [0, nc), nc <= 9 is used */
    const uint8_t *fresh;   /* caches holding this pass's gather (fresh[c] != 0); NULL = all */
} lc_drt_target;

/* The operators' arrays, for a backend that applies them itself (transport_gl). A receiver's
 * entries are e4[first, first+count) for a texel cache (cache < n_texel_caches), else e9; a
 * patch p gathers gather[gather_first[p], gather_first[p+1]); a covered cache takes the mean
 * of inpaint_from[first, first+count). The backend writes patch_b / patch_flux back after a
 * run, so lc_drt_patch_radiosity and a later CPU run see them. */
typedef struct {
    uint32_t source; /* node, or LC_DRT_PATCH | patch */
    float w[4];      /* bands 0-1 */
} lc_drt_entry4;
typedef struct {
    uint32_t source;
    float w[9]; /* bands 0-2 */
} lc_drt_entry9;
typedef struct {
    uint32_t cache;
    uint32_t first, count;
} lc_drt_receiver;
typedef struct {
    uint32_t source;
    float w; /* E_p += w * flux[source] */
} lc_drt_gather;
typedef struct {
    uint32_t cache;
    uint32_t first, count; /* into inpaint_from */
} lc_drt_inpaint;
typedef struct lc_drt_arrays {
    uint64_t serial; /* unique per build in this process */
    uint32_t n_patches;
    const float *patch_albedo, *patch_area; /* 3 floats / 1 per patch */
    const float *patch_e_direct;            /* this relight's (lc_drt_elements_lit) */
    float *patch_b, *patch_flux;            /* the state between passes and relights */
    const uint32_t *patch_gather_first;     /* n_patches + 1 */
    const lc_drt_gather *gather;
    const lc_drt_receiver *receivers;
    uint32_t n_receivers;
    const lc_drt_entry4 *e4;
    const lc_drt_entry9 *e9;
    const lc_drt_inpaint *inpaint;
    uint32_t n_inpaint;
    const uint32_t *inpaint_from;
    uint32_t n_inpaint_from;
} lc_drt_arrays;
lc_drt_arrays lc_drt_arrays_get(lc_drt_ops *ops);

/* One pass of every attached operator set, in order (see the top). */
void lc_drt_apply(lc_drt_ops *const *ops, uint32_t n, const lc_drt_target *tg);

/* The last pass's patch radiosity B (n_patches*3, W/m^2), for tests and the objects' shading. */
const float *lc_drt_patch_radiosity(const lc_drt_ops *ops, uint32_t *n_patches);

#endif
