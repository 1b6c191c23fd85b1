/* embree_device (see embree_device.h). */
#include "engine/embree_device.h"

#include <math.h>
#include <stdio.h>

#include "util/log.h"
#include "util/ray_offset.h"

static void embree_device_error(void *user, enum RTCError code, const char *str) {
    lc_error((const char *)user, "embree error %d: %s", (int)code, str ? str : "");
}

RTCDevice lc_embree_device_new(int threads, const char *module, char *err, size_t errlen) {
    char config[32] = "";
    if (threads > 0) snprintf(config, sizeof config, "threads=%d", threads);
    RTCDevice d = rtcNewDevice(config[0] ? config : NULL);
    if (!d) {
        lc_set_err(err, errlen, "embree: rtcNewDevice failed (error %d)", (int)rtcGetDeviceError(NULL));
        return NULL;
    }
    rtcSetDeviceErrorFunction(d, embree_device_error, (void *)module);
    return d;
}

float lc_embree_scene_epsilon(const lc_lcb_view *v) {
    float extent = 0;
    for (uint32_t i = 0; i < v->n_vertices; i++)
        for (int k = 0; k < 3; k++) extent = fmaxf(extent, fabsf(v->vertices[i].position[k]));
    return lc_ray_lift_scene(extent);
}
