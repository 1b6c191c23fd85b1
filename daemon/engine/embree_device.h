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

#endif
