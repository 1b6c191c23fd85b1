#include "bake/rt.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

struct lc_rt {
    RTCDevice device;
    RTCScene scene;
    const lc_mesh *mesh;
};

static void rt_embree_error(void *user, enum RTCError code, const char *str) {
    (void)user;
    lc_error("rt", "embree error %d: %s", (int)code, str ? str : "");
}

lc_rt *lc_rt_create(const lc_mesh *mesh, int threads, char *err, size_t errlen) {
    lc_rt *rt = calloc(1, sizeof *rt);
    if (!rt) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    char config[64] = "";
    if (threads > 0) snprintf(config, sizeof config, "threads=%d", threads);
    rt->device = rtcNewDevice(config[0] ? config : NULL);
    if (!rt->device) {
        lc_set_err(err, errlen, "rtcNewDevice failed (error %d)", (int)rtcGetDeviceError(NULL));
        goto err;
    }
    rtcSetDeviceErrorFunction(rt->device, rt_embree_error, NULL);
    rt->mesh = mesh;
    rt->scene = rtcNewScene(rt->device);
    rtcSetSceneFlags(rt->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(rt->scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = rtcNewGeometry(rt->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    /* Embree copies into its own buffers here, so the mesh layout need not be padded. */
    float *vb = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                        mesh->n_vertices);
    unsigned *ib = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                           mesh->n_triangles);
    if (!vb || !ib) {
        rtcReleaseGeometry(geom);
        lc_set_err(err, errlen, "embree could not allocate geometry buffers (%u vertices, %u triangles)",
                   mesh->n_vertices, mesh->n_triangles);
        goto err;
    }
    memcpy(vb, mesh->position, (size_t)mesh->n_vertices * 3 * sizeof(float));
    memcpy(ib, mesh->index, (size_t)mesh->n_triangles * 3 * sizeof(unsigned));
    rtcCommitGeometry(geom);
    rtcAttachGeometry(rt->scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(rt->scene);
    if (rtcGetDeviceError(rt->device) != RTC_ERROR_NONE) {
        lc_set_err(err, errlen, "embree scene build failed (see log)");
        goto err;
    }
    return rt;
err:
    lc_rt_release(rt);
    return NULL;
}

void lc_rt_release(lc_rt *rt) {
    if (!rt) return;
    if (rt->scene) rtcReleaseScene(rt->scene);
    if (rt->device) rtcReleaseDevice(rt->device);
    free(rt);
}

const lc_mesh *lc_rt_mesh(const lc_rt *rt) { return rt->mesh; }

int lc_rt_intersect(const lc_rt *rt, const float org[3], const float dir[3], float tnear, float tfar, lc_hit *hit) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rh.ray.org_x = org[0];
    rh.ray.org_y = org[1];
    rh.ray.org_z = org[2];
    rh.ray.dir_x = dir[0];
    rh.ray.dir_y = dir[1];
    rh.ray.dir_z = dir[2];
    rh.ray.tnear = tnear;
    rh.ray.tfar = tfar;
    rh.ray.time = 0;
    rh.ray.mask = ~0u; /* a zero mask never hits */
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rt->scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return 0;
    hit->t = rh.ray.tfar;
    hit->prim = rh.hit.primID;
    hit->b1 = rh.hit.u;
    hit->b2 = rh.hit.v;
    /* Our own winding-defined normal, independent of Embree's Ng sign convention. */
    lc_mesh_triangle_normal(rt->mesh, hit->prim, hit->ng);
    hit->backface = dir[0] * hit->ng[0] + dir[1] * hit->ng[1] + dir[2] * hit->ng[2] > 0;
    return 1;
}

int lc_rt_occluded(const lc_rt *rt, const float org[3], const float dir[3], float tnear, float tfar) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRay ray;
    ray.org_x = org[0];
    ray.org_y = org[1];
    ray.org_z = org[2];
    ray.dir_x = dir[0];
    ray.dir_y = dir[1];
    ray.dir_z = dir[2];
    ray.tnear = tnear;
    ray.tfar = tfar;
    ray.time = 0;
    ray.mask = ~0u;
    ray.id = 0;
    ray.flags = 0;
    rtcOccluded1(rt->scene, &ctx, &ray);
    return ray.tfar < 0; /* set to -inf on a hit */
}
