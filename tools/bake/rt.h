/* rt: Embree 3 ray queries against the static scene (create/commit once, then query from
 * any thread). Opaque handle; release with lc_rt_release(). */
#ifndef LC_RT_H
#define LC_RT_H
#include <stddef.h>
#include <stdint.h>

#include "bake/scene.h"

typedef struct lc_rt lc_rt;

typedef struct lc_hit {
    float t;       /* distance along the unit direction */
    uint32_t prim; /* triangle index in the mesh */
    float b1, b2;  /* barycentrics (point = (1-b1-b2) v0 + b1 v1 + b2 v2) */
    float ng[3];   /* unit geometric normal of the triangle (winding-defined) */
    int backface;  /* the ray hit the back side: dot(dir, ng) > 0 */
} lc_hit;

/* Builds a BVH over mesh (which must stay alive and unchanged until release). threads = 0:
 * all cores. Returns NULL with err set. */
lc_rt *lc_rt_create(const lc_mesh *mesh, int threads, char *err, size_t errlen);
void lc_rt_release(lc_rt *rt);

/* Closest hit along org + t*dir, t in (tnear, tfar). dir must be unit. Returns 1 on hit. */
int lc_rt_intersect(const lc_rt *rt, const float org[3], const float dir[3], float tnear, float tfar, lc_hit *hit);
/* Any hit in (tnear, tfar). Returns 1 when occluded. */
int lc_rt_occluded(const lc_rt *rt, const float org[3], const float dir[3], float tnear, float tfar);

const lc_mesh *lc_rt_mesh(const lc_rt *rt);

#endif
