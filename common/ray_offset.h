/* ray_offset: every ray offset lucent uses, one named function per purpose, in one place.
 *
 * Why offsets: a ray leaving a surface point computed in float can hit that same surface at
 * t ~ 0 (self-intersection, "shadow acne"), and a shadow ray aimed at a point on a surface
 * (an emitter) can hit that surface just before arriving. Float spacing grows with the
 * coordinates (one ulp is |x| x 2^-23 ~ 1.2e-7 |x|), so each lift is 0.1 mm plus a multiple
 * of the coordinate magnitude. Units: metres.
 *
 * The bake's formulas are part of the bake's bytes (same seed, same .lcb): changing one
 * changes every bake. The runtime one is shared by the engine and the reference path tracer
 * so the reference measures the engine's quantity, not a different offset. */
#ifndef LC_RAY_OFFSET_H
#define LC_RAY_OFFSET_H
#include <math.h>

/* Bake rays from a point on a surface (texel caches' link and bound probes, the buried-surfel
 * test): 0.1 mm plus ~8 ulps of the point's own largest |coordinate| `pm`, so each origin
 * clears its own rounding whatever else the scene holds. */
static inline float lc_ray_lift_point(float pm) { return 1e-4f + 1e-6f * pm; }

/* Bake relocation test rays from texel caches: the larger of 0.1 mm and ~84 ulps of the
 * scene's largest |coordinate| `amax`, one value for the whole scene. It errs wide because a
 * ray leaving along the normal that re-hits the cache's own surface reads as a back face,
 * and back faces are what move a cache. */
static inline float lc_ray_lift_relocate(float amax) { return fmaxf(1e-4f, amax * 1e-5f); }

/* Runtime rays from a surface (the engine's direct light and sky rays from surfels; the
 * reference's texel caches and path vertices): 0.1 mm plus ~17 ulps of the scene's largest
 * |coordinate| `extent` (lc_embree_scene_epsilon), one value per bake. */
static inline float lc_ray_lift_scene(float extent) { return 1e-4f + 2e-6f * extent; }

/* Far end of a shadow ray toward a light point or an emitter sample `dist` away from an
 * origin lifted by `lift`: short by 1e-4 of the distance (its float error) and by the lift,
 * so a light lying on a surface (an area light on the ceiling, an emitting triangle) is not
 * shadowed by that surface. */
static inline float lc_ray_shadow_tfar(float dist, float lift) { return dist * (1.0f - 1e-4f) - lift; }

#endif
