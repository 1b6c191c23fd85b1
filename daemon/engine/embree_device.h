/* embree_device: the Embree set-up every runtime ray caster (the relight engine, the
 * reference path tracer) shares: the device and the ray offset for a bake's scale. */
#ifndef LC_EMBREE_DEVICE_H
#define LC_EMBREE_DEVICE_H
#include <embree3/rtcore.h>
#include <stddef.h>

#include "lcb/lcb.h"

/* A device with `threads` worker threads (0 = Embree's default) whose errors are logged
 * under `module` (a string that outlives the device). NULL with err set on failure. */
RTCDevice lc_embree_device_new(int threads, const char *module, char *err, size_t errlen);

/* The runtime ray lift for this bake: lc_ray_lift_scene (util/ray_offset.h) of the largest
 * |vertex coordinate| of the static mesh; the engine and the reference both take it. */
float lc_embree_scene_epsilon(const lc_lcb_view *v);

/* 1 when something in `sc` lies on the ray org + t*dir, 0 < t < tfar (a shadow or
 * visibility query; the caller has lifted org off its surface). Inline: it is the shadow
 * rays' hot loop in both callers. */
static inline int lc_embree_occluded(RTCScene sc, const float org[3], const float dir[3], float tfar) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay ray = {.org_x = org[0],
                         .org_y = org[1],
                         .org_z = org[2],
                         .tnear = 0,
                         .dir_x = dir[0],
                         .dir_y = dir[1],
                         .dir_z = dir[2],
                         .time = 0,
                         .tfar = tfar,
                         .mask = ~0u,
                         .id = 0,
                         .flags = 0};
    rtcOccluded1(sc, &ctx, &ray);
    return ray.tfar < 0;
}

#endif
