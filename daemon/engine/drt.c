/* drt: clutter operators (drt.h): the builder (any one thread, rays on its workers) and the
 * per-pass application (the engine's thread). */
#include "engine/drt.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine/embree_device.h"
#include "engine/scene_math.h"
#include "lcb/surfel_hash.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/rng.h"
#include "util/sh.h"
#include "util/vec.h"

#define DRT_BATCH 64        /* receivers per parallel work item (the cancel flag is read per item) */
#define DRT_TAPER 0.2f      /* the outer fraction of the radius over which the deltas fade out */
#define DRT_INPAINT_RINGS 3 /* lightmap rings searched for an inpainted texel's neighbours */
#define DRT_MAX_SUBDIV 16   /* a large triangle is split at most 16 x 16 */

lc_drt_settings lc_drt_default_settings(void) {
    lc_drt_settings s = {.rays = 1024,
                         .patch_rays = 256,
                         .patches = 128,
                         .radius_factor = 6.0f,
                         .node_angle = 0.12f,
                         .inpaint_threshold = 0.5f};
    return s;
}

int lc_drt_check_settings(const lc_drt_settings *s, char *err, size_t errlen) {
    if (s->rays < 16 || s->rays > 65536) {
        lc_set_err(err, errlen, "clutter_rays: %u is outside 16..65536", s->rays);
        return -1;
    }
    if (s->patch_rays < 16 || s->patch_rays > 65536) {
        lc_set_err(err, errlen, "clutter_patch_rays: %u is outside 16..65536", s->patch_rays);
        return -1;
    }
    if (s->patches < 1 || s->patches > 65536) {
        lc_set_err(err, errlen, "clutter_patches: %u is outside 1..65536", s->patches);
        return -1;
    }
    if (!(s->radius_factor >= 1.5f && s->radius_factor <= 64.0f)) {
        lc_set_err(err, errlen, "clutter_radius_factor: %g is outside 1.5..64", (double)s->radius_factor);
        return -1;
    }
    if (!(s->node_angle > 0.0f && s->node_angle <= 1.0f)) {
        lc_set_err(err, errlen, "clutter_node_angle: %g is outside (0, 1] radians", (double)s->node_angle);
        return -1;
    }
    if (!(s->inpaint_threshold > 0.0f && s->inpaint_threshold <= 1.0f)) {
        lc_set_err(err, errlen, "clutter_inpaint_threshold: %g is outside (0, 1]", (double)s->inpaint_threshold);
        return -1;
    }
    return 0;
}

/* --- the operators ---------------------------------------------------------------------------- */

typedef lc_drt_entry4 drt_entry4;
typedef lc_drt_entry9 drt_entry9;
typedef lc_drt_receiver drt_receiver;
typedef lc_drt_gather drt_gather;
typedef lc_drt_inpaint drt_inpaint;

struct lc_drt_ops {
    lc_engine_object object; /* the placement it was built for */
    uint32_t n_patches;
    float *patch_albedo, *patch_area, *patch_e_direct, *patch_b, *patch_flux; /* per patch, 3 floats (area 1) */
    uint32_t *patch_gather_first;                                             /* n_patches + 1 */
    drt_gather *gather;
    uint32_t n_elements;
    float *el_pos, *el_normal, *el_e_direct; /* 3 floats each */
    float *el_area;
    uint32_t *el_patch;
    drt_receiver *receivers;
    uint32_t n_receivers;
    drt_entry4 *e4;
    drt_entry9 *e9;
    uint64_t n_e4, n_e9;
    drt_inpaint *inpaint;
    uint32_t n_inpaint;
    uint32_t *inpaint_from;
    uint32_t n_inpaint_from;
    lc_drt_info info;
    uint64_t serial; /* unique per build in this process (a backend's upload key) */
};

void lc_drt_ops_release(lc_drt_ops *o) {
    if (!o) return;
    free(o->patch_albedo);
    free(o->patch_area);
    free(o->patch_e_direct);
    free(o->patch_b);
    free(o->patch_flux);
    free(o->patch_gather_first);
    free(o->gather);
    free(o->el_pos);
    free(o->el_normal);
    free(o->el_e_direct);
    free(o->el_area);
    free(o->el_patch);
    free(o->receivers);
    free(o->e4);
    free(o->e9);
    free(o->inpaint);
    free(o->inpaint_from);
    free(o);
}

lc_drt_info lc_drt_ops_info(const lc_drt_ops *o) { return o->info; }

const lc_engine_object *lc_drt_ops_object(const lc_drt_ops *o) { return &o->object; }

int lc_drt_ops_match(const lc_drt_ops *o, const lc_engine_object *obj) {
    return lc_drt_same_placement(&o->object, obj);
}

int lc_drt_same_placement(const lc_engine_object *a, const lc_engine_object *obj) {
    return strcmp(a->id, obj->id) == 0 && a->asset == obj->asset &&
        memcmp(a->translation, obj->translation, sizeof a->translation) == 0 &&
        memcmp(a->rotation, obj->rotation, sizeof a->rotation) == 0 &&
        memcmp(a->scale, obj->scale, sizeof a->scale) == 0;
}

lc_drt_elements lc_drt_elements_get(lc_drt_ops *o) {
    lc_drt_elements e = {o->n_elements, o->el_pos, o->el_normal, o->el_e_direct};
    return e;
}

void lc_drt_elements_lit(lc_drt_ops *o) {
    memset(o->patch_e_direct, 0, (size_t)o->n_patches * 3 * sizeof(float));
    for (uint32_t i = 0; i < o->n_elements; i++)
        for (int k = 0; k < 3; k++)
            o->patch_e_direct[3 * o->el_patch[i] + k] += o->el_e_direct[3 * i + k] * o->el_area[i];
    for (uint32_t p = 0; p < o->n_patches; p++)
        for (int k = 0; k < 3; k++) o->patch_e_direct[3 * p + k] /= o->patch_area[p];
}

lc_drt_arrays lc_drt_arrays_get(lc_drt_ops *o) {
    lc_drt_arrays a = {o->serial,
                       o->n_patches,
                       o->patch_albedo,
                       o->patch_area,
                       o->patch_e_direct,
                       o->patch_b,
                       o->patch_flux,
                       o->patch_gather_first,
                       o->gather,
                       o->receivers,
                       o->n_receivers,
                       o->e4,
                       o->e9,
                       o->inpaint,
                       o->n_inpaint,
                       o->inpaint_from,
                       o->n_inpaint_from};
    return a;
}

const float *lc_drt_patch_radiosity(const lc_drt_ops *o, uint32_t *n_patches) {
    *n_patches = o->n_patches;
    return o->patch_b;
}

/* --- the builder ------------------------------------------------------------------------------- */

struct lc_drt_builder {
    const lc_lcb_view *v;
    int threads;
    float eps;
    RTCDevice device;
    RTCScene static_scene;
    lc_surfel_hash hash;
    uint32_t *surfel_leaf; /* per surfel: the leaf node holding it */
    uint32_t *parent;      /* per node: LC_NONE at the root */
    uint32_t *texel_cache; /* per lightmap texel: its cache, LC_NONE when empty */
    float *texel_spacing;  /* per texel cache: distance to its nearest 4-neighbour's cache (m) */
};

void lc_drt_builder_release(lc_drt_builder *b) {
    if (!b) return;
    if (b->static_scene) rtcReleaseScene(b->static_scene);
    if (b->device) rtcReleaseDevice(b->device);
    lc_surfel_hash_free(&b->hash);
    free(b->surfel_leaf);
    free(b->parent);
    free(b->texel_cache);
    free(b->texel_spacing);
    free(b);
}

static RTCScene drt_mesh_scene(RTCDevice dev, const void *vertices, size_t vstride, uint32_t nv, const void *indices,
                               size_t istride, uint32_t nt) {
    RTCScene sc = rtcNewScene(dev);
    rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST);
    if (nt > 0) {
        RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices, 0, vstride, nv);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices, 0, istride, nt);
        rtcCommitGeometry(g);
        rtcAttachGeometry(sc, g);
        rtcReleaseGeometry(g);
    }
    rtcCommitScene(sc);
    return sc;
}

/* Each texel cache's spacing to its lightmap neighbours: the distance a contact is judged by. */
static void drt_texel_spacing(lc_drt_builder *b) {
    const lc_lcb_view *v = b->v;
    const uint32_t W = v->lightmap_width, H = v->lightmap_height;
    for (uint32_t c = 0; c < v->n_texel_caches; c++) {
        uint32_t t = v->caches[c].index, x = t % W, y = t / W;
        const int dx[4] = {1, -1, 0, 0}, dy[4] = {0, 0, 1, -1};
        float best = INFINITY;
        for (int k = 0; k < 4; k++) {
            int nx = (int)x + dx[k], ny = (int)y + dy[k];
            if (nx < 0 || ny < 0 || nx >= (int)W || ny >= (int)H) continue;
            uint32_t o = b->texel_cache[(size_t)ny * W + (size_t)nx];
            if (o == LC_NONE) continue;
            const float *p = v->caches[c].position, *q = v->caches[o].position;
            float d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
            best = fminf(best, lc_sm_len(d));
        }
        b->texel_spacing[c] = isfinite(best) ? best : 0.0f;
    }
}

lc_drt_builder *lc_drt_builder_create(const lc_lcb_view *v, int threads, char *err, size_t errlen) {
    lc_drt_builder *b = calloc(1, sizeof *b);
    if (!b) goto oom;
    b->v = v;
    b->threads = threads;
    b->eps = lc_embree_scene_epsilon(v);
    b->device = lc_embree_device_new(threads, "drt", err, errlen);
    if (!b->device) goto err;
    b->static_scene = drt_mesh_scene(b->device, v->vertices, sizeof(lc_lcb_vertex), v->n_vertices, v->triangles,
                                     sizeof(lc_lcb_triangle), v->n_triangles);
    if (rtcGetDeviceError(b->device) != RTC_ERROR_NONE) {
        lc_set_err(err, errlen, "drt: embree could not build the static scene (see log)");
        goto err;
    }
    if (v->n_surfels && lc_surfel_hash_build(&b->hash, v->surfels, v->n_surfels) != 0) goto oom;
    b->surfel_leaf = malloc(((size_t)v->n_surfels + 1) * sizeof *b->surfel_leaf);
    b->parent = malloc(((size_t)v->n_nodes + 1) * sizeof *b->parent);
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    b->texel_cache = malloc((texels + 1) * sizeof *b->texel_cache);
    b->texel_spacing = malloc(((size_t)v->n_texel_caches + 1) * sizeof *b->texel_spacing);
    if (!b->surfel_leaf || !b->parent || !b->texel_cache || !b->texel_spacing) goto oom;
    for (uint32_t s = 0; s < v->n_surfels; s++) b->surfel_leaf[s] = LC_NONE;
    for (uint32_t n = 0; n < v->n_nodes; n++) b->parent[n] = LC_NONE;
    for (uint32_t n = 0; n < v->n_nodes; n++) {
        const lc_lcb_node *nd = &v->nodes[n];
        if (nd->child[0] == LC_NONE) {
            for (uint32_t s = nd->first_surfel; s < nd->first_surfel + nd->surfel_count; s++) b->surfel_leaf[s] = n;
        } else {
            b->parent[nd->child[0]] = n;
            if (nd->child[1] != LC_NONE) b->parent[nd->child[1]] = n;
        }
    }
    for (size_t t = 0; t < texels; t++) b->texel_cache[t] = LC_NONE;
    for (uint32_t c = 0; c < v->n_texel_caches; c++) b->texel_cache[v->caches[c].index] = c;
    drt_texel_spacing(b);
    return b;
oom:
    lc_set_err(err, errlen, "drt: out of memory creating the clutter builder");
err:
    lc_drt_builder_release(b);
    return NULL;
}

/* --- one build: the placed object ---------------------------------------------------------------- */

typedef struct {
    uint32_t patch; /* grouped triangles: their patch; split ones: the first of k*k */
    uint32_t k;     /* 0 = grouped */
} drt_tri;

typedef struct {
    const lc_drt_builder *b;
    const lc_drt_settings *s;
    lc_drt_ops *o;
    const atomic_int *cancel;
    RTCScene clutter; /* the object's triangles in world space */
    float *wv;        /* its world vertices, 3 floats each (+1 padding for Embree) */
    const uint32_t *idx;
    uint32_t n_tris;
    float *tri_normal; /* per triangle, world, unit, winding-defined (mirror transforms flipped) */
    drt_tri *tris;
    float center[3], radius, reach;
    /* receivers */
    uint32_t *cand; /* candidate caches */
    uint32_t n_cand;
    void **cand_entries; /* per candidate: its merged entries (entry4 or entry9), malloc'd */
    uint32_t *cand_count;
    uint8_t *cand_inside;
    uint64_t *thread_rays;
    drt_gather **patch_entries; /* per patch, malloc'd */
    uint32_t *patch_count;
    uint32_t n_patch_entries;
    int failed;
} drt_job;

typedef struct {
    float t, u, v;
    uint32_t prim;
    int hit, backface;
    float ng[3];
} drt_hit;

static void drt_intersect(RTCScene sc, const float org[3], const float dir[3], float tfar, const float *vertices,
                          size_t vstride_floats, const uint32_t *indices, size_t istride, drt_hit *h) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    memset(&rh, 0, sizeof rh);
    rh.ray.org_x = org[0], rh.ray.org_y = org[1], rh.ray.org_z = org[2];
    rh.ray.dir_x = dir[0], rh.ray.dir_y = dir[1], rh.ray.dir_z = dir[2];
    rh.ray.tnear = 0;
    rh.ray.tfar = tfar;
    rh.ray.mask = ~0u;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(sc, &ctx, &rh);
    h->hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    if (!h->hit) return;
    h->t = rh.ray.tfar;
    h->u = rh.hit.u;
    h->v = rh.hit.v;
    h->prim = rh.hit.primID;
    if (vertices) { /* the static mesh: our own winding-defined normal, as the bake's rays */
        const uint32_t *t = indices + istride * h->prim;
        const float *a = vertices + vstride_floats * t[0], *b = vertices + vstride_floats * t[1],
                    *c = vertices + vstride_floats * t[2];
        float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        lc_sm_cross(e1, e2, h->ng);
        float l = lc_sm_len(h->ng);
        for (int k = 0; k < 3; k++) h->ng[k] = l > 0 ? h->ng[k] / l : 0;
    }
    h->backface = lc_sm_dot(dir, h->ng) > 0;
}

static void drt_hit_static(const drt_job *j, const float org[3], const float dir[3], float tfar, drt_hit *h) {
    const lc_lcb_view *v = j->b->v;
    drt_intersect(j->b->static_scene, org, dir, tfar, v->vertices[0].position, sizeof(lc_lcb_vertex) / sizeof(float),
                  &v->triangles[0].v[0], sizeof(lc_lcb_triangle) / sizeof(uint32_t), h);
}

static void drt_hit_clutter(const drt_job *j, const float org[3], const float dir[3], float tfar, drt_hit *h) {
    drt_intersect(j->clutter, org, dir, tfar, NULL, 0, NULL, 0, h);
    if (h->hit) {
        memcpy(h->ng, j->tri_normal + 3 * (size_t)h->prim, sizeof h->ng);
        h->backface = lc_sm_dot(dir, h->ng) > 0;
    }
}

/* The patch a clutter hit lands in: the triangle's group, or its sub-triangle of k x k. */
static uint32_t drt_patch_of(const drt_job *j, uint32_t prim, float u, float v) {
    const drt_tri *t = &j->tris[prim];
    if (t->k == 0) return t->patch;
    int k = (int)t->k;
    float fu = u * (float)k, fv = v * (float)k;
    int i = (int)fu, jj = (int)fv;
    if (i > k - 1) i = k - 1;
    if (jj > k - 1) jj = k - 1;
    if (i + jj > k - 1) jj = k - 1 - i;
    int upper = (fu - (float)i) + (fv - (float)jj) > 1.0f && i + jj <= k - 2;
    return t->patch + (uint32_t)(2 * k * i - i * i + 2 * jj + upper);
}

/* The node a static hit's light is attributed to: the hit surfel's leaf, then up while the
 * parent still subtends less than node_angle from `from`. LC_NONE when no surfel is near. */
static uint32_t drt_node_of(const drt_job *j, const float from[3], const float p[3], const float ng[3],
                            const float dir[3]) {
    const lc_lcb_view *v = j->b->v;
    uint32_t s = lc_surfel_hash_nearest(&j->b->hash, v->surfels, p, ng, dir);
    if (s == LC_NONE) return LC_NONE;
    uint32_t n = j->b->surfel_leaf[s];
    if (n == LC_NONE) return LC_NONE;
    for (;;) {
        uint32_t up = j->b->parent[n];
        if (up == LC_NONE) break;
        const lc_lcb_node *nd = &v->nodes[up];
        float d[3] = {nd->center[0] - from[0], nd->center[1] - from[1], nd->center[2] - from[2]};
        float dist = lc_sm_len(d);
        if (!(nd->radius < j->s->node_angle * dist)) break;
        n = up;
    }
    return n;
}

/* The object in world space: vertices, triangle normals, bounding sphere, the Embree scene. */
static int drt_place(drt_job *j, const lc_engine_object *obj) {
    const lc_lcb_view *v = j->b->v;
    const lc_lcb_asset *a = &v->assets[obj->asset];
    float m[12];
    lc_sm_object_matrix(obj, m);
    float det =
        m[0] * (m[4] * m[8] - m[7] * m[5]) - m[3] * (m[1] * m[8] - m[7] * m[2]) + m[6] * (m[1] * m[5] - m[4] * m[2]);
    j->idx = v->asset_indices + 3 * (size_t)a->first_triangle;
    j->n_tris = a->triangle_count;
    j->wv = malloc(((size_t)a->vertex_count * 3 + 4) * sizeof(float));
    j->tri_normal = malloc(((size_t)j->n_tris * 3 + 3) * sizeof(float));
    j->tris = calloc((size_t)j->n_tris + 1, sizeof *j->tris);
    if (!j->wv || !j->tri_normal || !j->tris) return -1;
    for (uint32_t i = 0; i < a->vertex_count; i++)
        lc_sm_transform_point(m, v->asset_vertices[a->first_vertex + i].position, j->wv + 3 * (size_t)i);
    for (int k = 0; k < 3; k++) j->center[k] = 0.5f * (a->bounds_min[k] + a->bounds_max[k]);
    float c[3];
    lc_sm_transform_point(m, j->center, c);
    memcpy(j->center, c, sizeof c);
    j->radius = 0;
    for (uint32_t i = 0; i < a->vertex_count; i++) {
        const float *p = j->wv + 3 * (size_t)i;
        float d[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
        j->radius = fmaxf(j->radius, lc_sm_len(d));
    }
    j->radius = fmaxf(j->radius * 1.001f, 1e-4f);
    j->reach = j->s->radius_factor * j->radius;
    for (uint32_t t = 0; t < j->n_tris; t++) {
        const float *p0 = j->wv + 3 * (size_t)j->idx[3 * t], *p1 = j->wv + 3 * (size_t)j->idx[3 * t + 1],
                    *p2 = j->wv + 3 * (size_t)j->idx[3 * t + 2];
        float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]},
              e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
        float n[3];
        lc_sm_cross(e1, e2, n);
        float l = lc_sm_len(n) * (det < 0 ? -1.0f : 1.0f);
        for (int k = 0; k < 3; k++) j->tri_normal[3 * t + k] = l != 0 ? n[k] / l : 0;
    }
    j->clutter = drt_mesh_scene(j->b->device, j->wv, 3 * sizeof(float), a->vertex_count, j->idx, 3 * sizeof(uint32_t),
                                j->n_tris);
    return rtcGetDeviceError(j->b->device) == RTC_ERROR_NONE ? 0 : -1;
}

static float drt_tri_area(const drt_job *j, uint32_t t) {
    const float *p0 = j->wv + 3 * (size_t)j->idx[3 * t], *p1 = j->wv + 3 * (size_t)j->idx[3 * t + 1],
                *p2 = j->wv + 3 * (size_t)j->idx[3 * t + 2];
    float e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]}, e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
    float n[3];
    lc_sm_cross(e1, e2, n);
    return 0.5f * lc_sm_len(n);
}

/* A point of triangle t at barycentrics (u along p1, w along p2), and its albedo. */
static void drt_tri_point(const drt_job *j, uint32_t t, float u, float w, float p[3], float albedo[3]) {
    const lc_lcb_view *v = j->b->v;
    const uint32_t *ix = j->idx + 3 * (size_t)t;
    const float *p0 = j->wv + 3 * (size_t)ix[0], *p1 = j->wv + 3 * (size_t)ix[1], *p2 = j->wv + 3 * (size_t)ix[2];
    for (int k = 0; k < 3; k++) p[k] = (1 - u - w) * p0[k] + u * p1[k] + w * p2[k];
    uint32_t base = v->assets[j->o->object.asset].first_vertex;
    const float *a0 = v->asset_vertices[base + ix[0]].albedo, *a1 = v->asset_vertices[base + ix[1]].albedo,
                *a2 = v->asset_vertices[base + ix[2]].albedo;
    for (int k = 0; k < 3; k++) albedo[k] = (1 - u - w) * a0[k] + u * a1[k] + w * a2[k];
}

typedef struct {
    uint64_t key;
    uint32_t tri;
} drt_keyed;

static int drt_keyed_cmp(const void *a, const void *b) {
    const drt_keyed *x = a, *y = b;
    if (x->key != y->key) return x->key < y->key ? -1 : 1;
    return (x->tri > y->tri) - (x->tri < y->tri);
}

/* The cell-and-facing key that groups small triangles into one patch. */
static uint64_t drt_group_key(const drt_job *j, uint32_t t, float cell) {
    float c[3], alb[3];
    drt_tri_point(j, t, 1.0f / 3, 1.0f / 3, c, alb);
    const float *n = j->tri_normal + 3 * (size_t)t;
    int axis = fabsf(n[0]) >= fabsf(n[1]) && fabsf(n[0]) >= fabsf(n[2]) ? 0 : fabsf(n[1]) >= fabsf(n[2]) ? 1 : 2;
    uint64_t facing = (uint64_t)(2 * axis + (n[axis] < 0));
    uint64_t key = facing;
    for (int k = 0; k < 3; k++) {
        int64_t q = (int64_t)floorf((c[k] - j->center[k]) / cell) + (1 << 19);
        key = key << 20 | ((uint64_t)q & 0xFFFFF);
    }
    return key;
}

/* Sub-triangle s of a k x k split (drt_patch_of's numbering): the barycentrics of its centroid. */
static void drt_sub_centroid(int k, int s, float *u, float *w) {
    for (int i = 0; i < k; i++) {
        int row = 2 * (k - i) - 1;
        if (s >= row) {
            s -= row;
            continue;
        }
        int jj = s / 2, upper = s % 2;
        *u = ((float)i + (upper ? 2.0f : 1.0f) / 3.0f) / (float)k;
        *w = ((float)jj + (upper ? 2.0f : 1.0f) / 3.0f) / (float)k;
        return;
    }
    *u = *w = 1.0f / 3;
}

static void drt_add_element(drt_job *j, uint32_t e, uint32_t t, float u, float w, float area, uint32_t patch) {
    lc_drt_ops *o = j->o;
    float alb[3];
    drt_tri_point(j, t, u, w, o->el_pos + 3 * (size_t)e, alb);
    memcpy(o->el_normal + 3 * (size_t)e, j->tri_normal + 3 * (size_t)t, 3 * sizeof(float));
    o->el_area[e] = area;
    o->el_patch[e] = patch;
    o->patch_area[patch] += area;
    for (int k = 0; k < 3; k++) o->patch_albedo[3 * patch + k] += alb[k] * area;
}

/* Patches and their elements (drt.h: large triangles split, small ones grouped). */
static int drt_patches(drt_job *j) {
    lc_drt_ops *o = j->o;
    double total = 0;
    for (uint32_t t = 0; t < j->n_tris; t++) total += drt_tri_area(j, t);
    float target = (float)(total / j->s->patches);
    if (!(target > 0)) target = 1e-8f;
    drt_keyed *small = malloc(((size_t)j->n_tris + 1) * sizeof *small);
    if (!small) return -1;
    uint32_t n_small = 0, n_patches = 0, n_el = 0;
    for (uint32_t t = 0; t < j->n_tris; t++) {
        float a = drt_tri_area(j, t);
        if (!(a > 0)) {
            j->tris[t] = (drt_tri){LC_NONE, 0};
            continue;
        }
        if (a >= 0.5f * target) {
            long k = lrintf(sqrtf(a / target));
            k = k < 1 ? 1 : k > DRT_MAX_SUBDIV ? DRT_MAX_SUBDIV : k;
            j->tris[t] = (drt_tri){n_patches, (uint32_t)k};
            n_patches += (uint32_t)(k * k);
            n_el += (uint32_t)(k * k);
        } else {
            small[n_small++] = (drt_keyed){drt_group_key(j, t, sqrtf(target)), t};
            n_el++;
        }
    }
    qsort(small, n_small, sizeof *small, drt_keyed_cmp);
    for (uint32_t i = 0; i < n_small; i++) {
        if (i == 0 || small[i].key != small[i - 1].key) n_patches++;
        j->tris[small[i].tri] = (drt_tri){n_patches - 1, 0};
    }
    o->n_patches = n_patches;
    o->n_elements = n_el;
    size_t np = (size_t)n_patches + 1, ne = (size_t)n_el + 1;
    o->patch_albedo = calloc(np * 3, sizeof(float));
    o->patch_area = calloc(np, sizeof(float));
    o->patch_e_direct = calloc(np * 3, sizeof(float));
    o->patch_b = calloc(np * 3, sizeof(float));
    o->patch_flux = calloc(np * 3, sizeof(float));
    o->el_pos = malloc(ne * 3 * sizeof(float));
    o->el_normal = malloc(ne * 3 * sizeof(float));
    o->el_e_direct = calloc(ne * 3, sizeof(float));
    o->el_area = malloc(ne * sizeof(float));
    o->el_patch = malloc(ne * sizeof(uint32_t));
    if (!o->patch_albedo || !o->patch_area || !o->patch_e_direct || !o->patch_b || !o->patch_flux || !o->el_pos ||
        !o->el_normal || !o->el_e_direct || !o->el_area || !o->el_patch) {
        free(small);
        return -1;
    }
    uint32_t e = 0;
    for (uint32_t t = 0; t < j->n_tris; t++) {
        const drt_tri *tr = &j->tris[t];
        if (tr->patch == LC_NONE) continue;
        float a = drt_tri_area(j, t);
        if (tr->k == 0) {
            drt_add_element(j, e++, t, 1.0f / 3, 1.0f / 3, a, tr->patch);
            continue;
        }
        int k = (int)tr->k;
        for (int s = 0; s < k * k; s++) {
            float u, w;
            drt_sub_centroid(k, s, &u, &w);
            drt_add_element(j, e++, t, u, w, a / (float)(k * k), tr->patch + (uint32_t)s);
        }
    }
    for (uint32_t p = 0; p < n_patches; p++)
        for (int k = 0; k < 3; k++) o->patch_albedo[3 * p + k] /= o->patch_area[p];
    free(small);
    return 0;
}

/* --- rays ------------------------------------------------------------------------------------- */

typedef struct {
    uint32_t source;
    float sign_omega; /* +Omega (clutter seen) or -Omega (static light blocked) */
    float dir[3];
} drt_record;

static int drt_record_cmp(const void *a, const void *b) {
    const drt_record *x = a, *y = b;
    if (x->source != y->source) return x->source < y->source ? -1 : 1;
    if (x->sign_omega != y->sign_omega) return x->sign_omega < y->sign_omega ? -1 : 1;
    for (int k = 0; k < 3; k++)
        if (x->dir[k] != y->dir[k]) return x->dir[k] < y->dir[k] ? -1 : 1;
    return 0;
}

static float drt_source_area(const drt_job *j, uint32_t source) {
    return source & LC_DRT_PATCH ? j->o->patch_area[source & ~LC_DRT_PATCH] : j->b->v->nodes[source].area;
}

/* Direction i of n: a spherical Fibonacci set over the cap z >= zmin around `axis`, rotated. */
static void drt_cap_dir(const float axis[3], float zmin, uint32_t i, uint32_t n, float rot, float d[3]) {
    lc_vec3 a = lc_v3_load(axis), t, b;
    lc_v3_basis(a, &t, &b);
    float z = 1.0f - (1.0f - zmin) * ((float)i + 0.5f) / (float)n;
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    float phi = 2.0f * (float)M_PI * ((float)i * 0.6180339887f + rot);
    lc_vec3 w = lc_v3_add(lc_v3_add(lc_v3_scale(t, r * cosf(phi)), lc_v3_scale(b, r * sinf(phi))), lc_v3_scale(a, z));
    lc_v3_store(d, lc_v3_norm(w));
}

/* One patch's gather (C_b): cosine-weighted rays from its elements (area-proportional), each
 * 1 / (N A_source) of the source's flux per unit irradiance. */
static void drt_patch_range(void *ctx, size_t begin, size_t end, int thread) {
    drt_job *j = ctx;
    lc_drt_ops *o = j->o;
    const uint32_t n = j->s->patch_rays;
    drt_record *rec = malloc((size_t)n * sizeof *rec);
    if (!rec) {
        j->failed = 1;
        return;
    }
    for (size_t p = begin; p < end; p++) {
        if (j->cancel && atomic_load_explicit(j->cancel, memory_order_relaxed)) break;
        /* its elements: a scan (patches are few, elements a few per patch) */
        uint32_t m = 0;
        lc_rng rng = lc_rng_seed(0xD27C, p);
        double acc = 0, step = (double)o->patch_area[p] / n, next = step * lc_rng_float(&rng);
        for (uint32_t e = 0; e < o->n_elements && m < n; e++) {
            if (o->el_patch[e] != p) continue;
            acc += o->el_area[e];
            const float *en = o->el_normal + 3 * (size_t)e;
            float org[3];
            for (int k = 0; k < 3; k++) org[k] = o->el_pos[3 * e + k] + en[k] * j->b->eps;
            while (next < acc && m < n) {
                next += step;
                float u1 = lc_rng_float(&rng), u2 = lc_rng_float(&rng);
                float r = sqrtf(u1), phi = 2.0f * (float)M_PI * u2;
                lc_vec3 t, b, nn = lc_v3_load(en);
                lc_v3_basis(nn, &t, &b);
                float d[3];
                lc_v3_store(
                    d,
                    lc_v3_norm(lc_v3_add(lc_v3_add(lc_v3_scale(t, r * cosf(phi)), lc_v3_scale(b, r * sinf(phi))),
                                         lc_v3_scale(nn, sqrtf(fmaxf(0.0f, 1.0f - u1))))));
                j->thread_rays[thread]++;
                drt_hit hc, hs;
                drt_hit_clutter(j, org, d, INFINITY, &hc);
                drt_hit_static(j, org, d, hc.hit ? hc.t : INFINITY, &hs);
                uint32_t src = LC_NONE;
                if (hs.hit) {
                    if (!hs.backface) {
                        float hp[3] = {org[0] + d[0] * hs.t, org[1] + d[1] * hs.t, org[2] + d[2] * hs.t};
                        src = drt_node_of(j, org, hp, hs.ng, d);
                    }
                } else if (hc.hit && !hc.backface) {
                    src = LC_DRT_PATCH | drt_patch_of(j, hc.prim, hc.u, hc.v);
                }
                if (src != LC_NONE) rec[m] = (drt_record){src, 1.0f, {0, 0, 0}};
                else rec[m] = (drt_record){LC_NONE, 0.0f, {0, 0, 0}};
                m++;
            }
        }
        qsort(rec, m, sizeof *rec, drt_record_cmp);
        uint32_t groups = 0;
        for (uint32_t i = 0; i < m; i++)
            if (rec[i].source != LC_NONE && (i == 0 || rec[i].source != rec[i - 1].source)) groups++;
        drt_gather *g = malloc(((size_t)groups + 1) * sizeof *g);
        if (!g) {
            j->failed = 1;
            break;
        }
        uint32_t k = 0;
        for (uint32_t i = 0; i < m; i++) {
            if (rec[i].source == LC_NONE) continue;
            if (i == 0 || rec[i].source != rec[i - 1].source) g[k++] = (drt_gather){rec[i].source, 0.0f};
            g[k - 1].w += 1.0f / ((float)m * drt_source_area(j, rec[i].source));
        }
        j->patch_entries[p] = g;
        j->patch_count[p] = k;
    }
    free(rec);
}

/* Merges a receiver's ray records by source into SH entries (nc coefficients: 4 or 9). */
static void *drt_merge(const drt_job *j, drt_record *rec, uint32_t m, int nc, float taper, uint32_t *count) {
    qsort(rec, m, sizeof *rec, drt_record_cmp);
    uint32_t groups = 0;
    for (uint32_t i = 0; i < m; i++) groups += i == 0 || rec[i].source != rec[i - 1].source;
    *count = groups;
    size_t esize = nc == 4 ? sizeof(drt_entry4) : sizeof(drt_entry9);
    unsigned char *out = calloc((size_t)groups + 1, esize);
    if (!out) return NULL;
    uint32_t k = 0;
    float *w = NULL;
    for (uint32_t i = 0; i < m; i++) {
        if (i == 0 || rec[i].source != rec[i - 1].source) {
            unsigned char *e = out + esize * k++;
            memcpy(e, &rec[i].source, sizeof(uint32_t));
            w = (float *)(e + offsetof(drt_entry4, w));
        }
        float y[9];
        lc_sh_eval_fast(nc == 4 ? 2 : 3, rec[i].dir[0], rec[i].dir[1], rec[i].dir[2], y);
        float f = rec[i].sign_omega * taper / ((float)M_PI * drt_source_area(j, rec[i].source));
        for (int c = 0; c < nc; c++) w[c] += f * y[c];
    }
    return out;
}

/* The receivers' rays (drt.h): per candidate cache, aimed at the bounding sphere from
 * outside it, the whole hemisphere (texel) or sphere (grid) from inside. */
static void drt_receiver_one(drt_job *j, uint32_t ci, drt_record *rec, int thread) {
    const lc_lcb_view *v = j->b->v;
    uint32_t c = j->cand[ci];
    const lc_lcb_cache *cc = &v->caches[c];
    int texel = c < v->n_texel_caches;
    float p[3], dv[3];
    memcpy(p, cc->position, sizeof p);
    for (int k = 0; k < 3; k++) dv[k] = j->center[k] - p[k];
    float d = lc_sm_len(dv);
    float org[3];
    for (int k = 0; k < 3; k++) org[k] = p[k] + (texel ? cc->normal[k] * j->b->eps : 0.0f);
    float axis[3], zmin;
    int outside = d > j->radius * 1.02f;
    if (outside) {
        for (int k = 0; k < 3; k++) axis[k] = dv[k] / d;
        float s = j->radius / d;
        zmin = sqrtf(fmaxf(0.0f, 1.0f - s * s));
    } else if (texel) {
        memcpy(axis, cc->normal, sizeof axis);
        zmin = 0.0f;
    } else {
        axis[0] = 0, axis[1] = 0, axis[2] = 1;
        zmin = -1.0f;
    }
    const uint32_t n = j->s->rays;
    float omega = 2.0f * (float)M_PI * (1.0f - zmin) / (float)n;
    float contact = texel ? 1.5f * j->b->texel_spacing[c] : 0.0f;
    if (!(contact > 0)) contact = 0.02f * j->radius;
    lc_rng rng = lc_rng_seed(0xD27E, c);
    float rot = lc_rng_float(&rng);
    uint32_t m = 0, above = 0, inside = 0;
    for (uint32_t i = 0; i < n; i++) {
        float dir[3];
        drt_cap_dir(axis, zmin, i, n, rot, dir);
        if (texel && lc_sm_dot(dir, cc->normal) <= 0) continue;
        above++;
        j->thread_rays[thread]++;
        drt_hit hc, hs;
        drt_hit_clutter(j, org, dir, INFINITY, &hc);
        if (!hc.hit) continue;
        drt_hit_static(j, org, dir, hc.t, &hs);
        if (hs.hit) continue; /* the static scene hides the clutter here */
        if (hc.backface || hc.t < contact) inside++;
        drt_hit_static(j, org, dir, INFINITY, &hs);
        j->thread_rays[thread]++;
        if (hs.hit && !hs.backface) {
            float hp[3] = {org[0] + dir[0] * hs.t, org[1] + dir[1] * hs.t, org[2] + dir[2] * hs.t};
            uint32_t node = drt_node_of(j, p, hp, hs.ng, dir);
            if (node != LC_NONE) rec[m++] = (drt_record){node, -omega, {dir[0], dir[1], dir[2]}};
        }
        if (!hc.backface)
            rec[m++] =
                (drt_record){LC_DRT_PATCH | drt_patch_of(j, hc.prim, hc.u, hc.v), omega, {dir[0], dir[1], dir[2]}};
    }
    /* Covered: a texel cache is filled from its neighbours; a grid cache inside the object
     * keeps the static light (nothing reads it but trilinear samples next to the object). */
    int covered = !outside && above > 0 && (float)inside >= j->s->inpaint_threshold * (float)above;
    j->cand_inside[ci] = (uint8_t)(covered && texel);
    if (covered || m == 0) return;
    float taper = (j->reach - d) / (DRT_TAPER * j->reach);
    taper = taper < 0 ? 0 : taper > 1 ? 1 : taper;
    j->cand_entries[ci] = drt_merge(j, rec, m, texel ? 4 : 9, taper, &j->cand_count[ci]);
    if (!j->cand_entries[ci]) j->failed = 1;
}

static void drt_receiver_range(void *ctx, size_t begin, size_t end, int thread) {
    drt_job *j = ctx;
    drt_record *rec = malloc(2 * (size_t)j->s->rays * sizeof *rec);
    if (!rec) {
        j->failed = 1;
        return;
    }
    for (size_t b = begin; b < end; b++) {
        if (j->cancel && atomic_load_explicit(j->cancel, memory_order_relaxed)) break;
        size_t hi = (b + 1) * DRT_BATCH < j->n_cand ? (b + 1) * DRT_BATCH : j->n_cand;
        for (size_t ci = b * DRT_BATCH; ci < hi; ci++) drt_receiver_one(j, (uint32_t)ci, rec, thread);
    }
    free(rec);
}

/* Caches within reach that can see the sphere (texel caches: not wholly below their horizon). */
static int drt_candidates(drt_job *j) {
    const lc_lcb_view *v = j->b->v;
    j->cand = malloc(((size_t)v->n_caches + 1) * sizeof *j->cand);
    if (!j->cand) return -1;
    for (uint32_t c = 0; c < v->n_caches; c++) {
        const lc_lcb_cache *cc = &v->caches[c];
        if (cc->flags & LC_CACHE_INSIDE) continue;
        float dv[3] = {j->center[0] - cc->position[0], j->center[1] - cc->position[1], j->center[2] - cc->position[2]};
        if (lc_sm_len(dv) >= j->reach) continue;
        if (c < v->n_texel_caches && lc_sm_dot(dv, cc->normal) < -j->radius) continue;
        j->cand[j->n_cand++] = c;
    }
    j->cand_entries = calloc((size_t)j->n_cand + 1, sizeof *j->cand_entries);
    j->cand_count = calloc((size_t)j->n_cand + 1, sizeof *j->cand_count);
    j->cand_inside = calloc((size_t)j->n_cand + 1, 1);
    return j->cand_entries && j->cand_count && j->cand_inside ? 0 : -1;
}

/* --- assembly ---------------------------------------------------------------------------------- */

/* The covered texel caches' neighbours: the nearest lightmap ring (up to 3) holding texel
 * caches that are not covered, face the same way and lie on the same surface nearby. */
static int drt_inpaint_lists(drt_job *j) {
    const lc_lcb_view *v = j->b->v;
    lc_drt_ops *o = j->o;
    const uint32_t W = v->lightmap_width, H = v->lightmap_height;
    uint8_t *covered = calloc((size_t)v->n_texel_caches + 1, 1);
    uint32_t n_cov = 0;
    if (!covered) return -1;
    for (uint32_t i = 0; i < j->n_cand; i++)
        if (j->cand_inside[i]) covered[j->cand[i]] = 1, n_cov++;
    const uint32_t per = (2 * DRT_INPAINT_RINGS + 1) * (2 * DRT_INPAINT_RINGS + 1);
    o->inpaint = malloc(((size_t)n_cov + 1) * sizeof *o->inpaint);
    o->inpaint_from = malloc(((size_t)n_cov * per + 1) * sizeof *o->inpaint_from);
    if (!o->inpaint || !o->inpaint_from) {
        free(covered);
        return -1;
    }
    for (uint32_t i = 0; i < j->n_cand; i++) {
        if (!j->cand_inside[i]) continue;
        uint32_t c = j->cand[i];
        const lc_lcb_cache *cc = &v->caches[c];
        int x = (int)(cc->index % W), y = (int)(cc->index / W);
        float spacing = j->b->texel_spacing[c] > 0 ? j->b->texel_spacing[c] : j->radius;
        drt_inpaint *ip = &o->inpaint[o->n_inpaint];
        ip->cache = c;
        ip->first = o->n_inpaint_from;
        ip->count = 0;
        for (int r = 1; r <= DRT_INPAINT_RINGS && ip->count == 0; r++)
            for (int dy = -r; dy <= r; dy++)
                for (int dx = -r; dx <= r; dx++) {
                    if (abs(dx) != r && abs(dy) != r) continue;
                    int nx = x + dx, ny = y + dy;
                    if (nx < 0 || ny < 0 || nx >= (int)W || ny >= (int)H) continue;
                    uint32_t q = j->b->texel_cache[(size_t)ny * W + (size_t)nx];
                    if (q == LC_NONE || covered[q] || (v->caches[q].flags & LC_CACHE_INSIDE)) continue;
                    const lc_lcb_cache *qc = &v->caches[q];
                    float dd[3] = {qc->position[0] - cc->position[0], qc->position[1] - cc->position[1],
                                   qc->position[2] - cc->position[2]};
                    if (lc_sm_dot(qc->normal, cc->normal) < 0.9f || lc_sm_len(dd) > 2.0f * (float)r * spacing) continue;
                    o->inpaint_from[o->n_inpaint_from++] = q;
                    ip->count++;
                }
        if (ip->count) o->n_inpaint++; /* none near: left as gathered (the paper's failure case) */
    }
    free(covered);
    return 0;
}

/* The receivers' entries into the operators' arrays, in cache order. */
static int drt_collect(drt_job *j) {
    const lc_lcb_view *v = j->b->v;
    lc_drt_ops *o = j->o;
    uint32_t nr = 0;
    for (uint32_t i = 0; i < j->n_cand; i++) {
        if (!j->cand_count[i]) continue;
        nr++;
        if (j->cand[i] < v->n_texel_caches) o->n_e4 += j->cand_count[i];
        else o->n_e9 += j->cand_count[i];
    }
    o->receivers = malloc(((size_t)nr + 1) * sizeof *o->receivers);
    o->e4 = malloc((o->n_e4 + 1) * sizeof *o->e4);
    o->e9 = malloc((o->n_e9 + 1) * sizeof *o->e9);
    if (!o->receivers || !o->e4 || !o->e9) return -1;
    uint64_t k4 = 0, k9 = 0;
    for (uint32_t i = 0; i < j->n_cand; i++) {
        uint32_t n = j->cand_count[i], c = j->cand[i];
        if (!n) continue;
        int texel = c < v->n_texel_caches;
        o->receivers[o->n_receivers++] = (drt_receiver){c, (uint32_t)(texel ? k4 : k9), n};
        if (texel) {
            memcpy(o->e4 + k4, j->cand_entries[i], (size_t)n * sizeof *o->e4);
            k4 += n;
            o->info.texel_receivers++;
        } else {
            memcpy(o->e9 + k9, j->cand_entries[i], (size_t)n * sizeof *o->e9);
            k9 += n;
            o->info.grid_receivers++;
        }
    }
    uint32_t total = 0;
    for (uint32_t p = 0; p < o->n_patches; p++) total += j->patch_count[p];
    o->patch_gather_first = malloc(((size_t)o->n_patches + 1) * sizeof *o->patch_gather_first);
    o->gather = malloc(((size_t)total + 1) * sizeof *o->gather);
    if (!o->patch_gather_first || !o->gather) return -1;
    uint32_t g = 0;
    for (uint32_t p = 0; p < o->n_patches; p++) {
        o->patch_gather_first[p] = g;
        if (j->patch_count[p]) memcpy(o->gather + g, j->patch_entries[p], j->patch_count[p] * sizeof *o->gather);
        g += j->patch_count[p];
    }
    o->patch_gather_first[o->n_patches] = g;
    return 0;
}

static void drt_job_free(drt_job *j) {
    if (j->clutter) rtcReleaseScene(j->clutter);
    free(j->wv);
    free(j->tri_normal);
    free(j->tris);
    if (j->cand_entries)
        for (uint32_t i = 0; i < j->n_cand; i++) free(j->cand_entries[i]);
    free(j->cand_entries);
    free(j->cand);
    free(j->cand_count);
    free(j->cand_inside);
    free(j->thread_rays);
    if (j->patch_entries)
        for (uint32_t p = 0; p < j->n_patch_entries; p++) free(j->patch_entries[p]);
    free(j->patch_entries);
    free(j->patch_count);
}

static size_t drt_ops_bytes(const lc_drt_ops *o) {
    return sizeof *o + (size_t)o->n_patches * (11 * sizeof(float) + sizeof(uint32_t)) +
        (size_t)o->patch_gather_first[o->n_patches] * sizeof(drt_gather) +
        (size_t)o->n_elements * (10 * sizeof(float) + sizeof(uint32_t)) +
        (size_t)o->n_receivers * sizeof(drt_receiver) + o->n_e4 * sizeof(drt_entry4) + o->n_e9 * sizeof(drt_entry9) +
        (size_t)o->n_inpaint * sizeof(drt_inpaint) + (size_t)o->n_inpaint_from * sizeof(uint32_t);
}

int lc_drt_build(lc_drt_builder *b, const lc_engine_object *object, const lc_drt_settings *s, const atomic_int *cancel,
                 lc_drt_ops **out, char *err, size_t errlen) {
    *out = NULL;
    double t0 = lc_clock_ms();
    if (lc_drt_check_settings(s, err, errlen) != 0) return -1;
    if (object->asset >= b->v->n_assets) {
        lc_set_err(err, errlen, "drt: asset %u is not in the bake (%u assets)", object->asset, b->v->n_assets);
        return -1;
    }
    drt_job j = {.b = b, .s = s, .cancel = cancel};
    int rc = -1, nthreads = lc_parallel_threads(b->threads);
    j.o = calloc(1, sizeof *j.o);
    if (!j.o) goto oom;
    j.o->object = *object;
    static atomic_uint_fast64_t drt_serials; /* builders may run on several threads */
    j.o->serial = atomic_fetch_add(&drt_serials, 1) + 1;
    j.thread_rays = calloc((size_t)nthreads, sizeof *j.thread_rays);
    if (!j.thread_rays || drt_place(&j, object) != 0 || drt_patches(&j) != 0) goto oom;
    j.patch_entries = calloc((size_t)j.o->n_patches + 1, sizeof *j.patch_entries);
    j.patch_count = calloc((size_t)j.o->n_patches + 1, sizeof *j.patch_count);
    j.n_patch_entries = j.o->n_patches;
    if (!j.patch_entries || !j.patch_count || drt_candidates(&j) != 0) goto oom;
    lc_parallel_for(b->threads, j.o->n_patches, 4, drt_patch_range, &j);
    lc_parallel_for(b->threads, (j.n_cand + DRT_BATCH - 1) / DRT_BATCH, 1, drt_receiver_range, &j);
    if (cancel && atomic_load(cancel)) {
        rc = 1;
        goto done;
    }
    if (j.failed || drt_inpaint_lists(&j) != 0 || drt_collect(&j) != 0) goto oom;
    lc_drt_info *in = &j.o->info;
    in->patches = j.o->n_patches;
    in->elements = j.o->n_elements;
    in->receivers = j.o->n_receivers;
    in->inpainted = j.o->n_inpaint;
    in->entries = j.o->n_e4 + j.o->n_e9;
    for (int t = 0; t < nthreads; t++) in->rays += j.thread_rays[t];
    in->bytes = drt_ops_bytes(j.o);
    in->build_ms = lc_clock_ms() - t0;
    *out = j.o;
    j.o = NULL;
    rc = 0;
    goto done;
oom:
    lc_set_err(err, errlen, "drt: out of memory building the clutter operators of object '%s'", object->id);
done:
    drt_job_free(&j);
    lc_drt_ops_release(j.o);
    return rc;
}

/* --- runtime ----------------------------------------------------------------------------------- */

/* A source's flux in RGB: a static node's (converted back when the pass runs in YCoCg) or a
 * patch's. */
static inline void drt_source_flux(const lc_drt_ops *o, const lc_drt_target *tg, uint32_t source, float f[3]) {
    if (source & LC_DRT_PATCH) {
        memcpy(f, o->patch_flux + 3 * (size_t)(source & ~LC_DRT_PATCH), 3 * sizeof(float));
        return;
    }
    const float *x = tg->node_flux + 3 * (size_t)source;
    if (tg->flux_ycocg) { /* Y, Co, Cg -> RGB (transport_cpu's inverse) */
        float tt = x[0] - x[2];
        f[0] = tt + x[1];
        f[1] = x[0] + x[2];
        f[2] = tt - x[1];
    } else {
        memcpy(f, x, 3 * sizeof(float));
    }
}

/* Patch radiosity from the direct light and this pass's gather (its own patches at their
 * previous values: one more bounce inside the object per pass). */
static void drt_patches_pass(lc_drt_ops *o, const lc_drt_target *tg) {
    for (uint32_t p = 0; p < o->n_patches; p++) {
        float e[3] = {o->patch_e_direct[3 * p], o->patch_e_direct[3 * p + 1], o->patch_e_direct[3 * p + 2]};
        for (uint32_t g = o->patch_gather_first[p]; g < o->patch_gather_first[p + 1]; g++) {
            float f[3];
            drt_source_flux(o, tg, o->gather[g].source, f);
            for (int k = 0; k < 3; k++) e[k] += o->gather[g].w * f[k];
        }
        for (int k = 0; k < 3; k++) o->patch_b[3 * p + k] = o->patch_albedo[3 * p + k] * fmaxf(0.0f, e[k]);
    }
    for (uint32_t p = 0; p < o->n_patches; p++)
        for (int k = 0; k < 3; k++) o->patch_flux[3 * p + k] = o->patch_b[3 * p + k] * o->patch_area[p];
}

static void drt_receivers_pass(const lc_drt_ops *o, const lc_drt_target *tg) {
    for (uint32_t r = 0; r < o->n_receivers; r++) {
        const drt_receiver *rc = &o->receivers[r];
        if (tg->fresh && !tg->fresh[rc->cache]) continue;
        float *sh = tg->cache_sh + (size_t)rc->cache * tg->stride * 3;
        if (rc->cache < tg->n_texel_caches) {
            int hi = tg->texel_nc < 4 ? tg->texel_nc : 4;
            for (uint32_t i = 0; i < rc->count; i++) {
                const drt_entry4 *e = &o->e4[rc->first + i];
                float f[3];
                drt_source_flux(o, tg, e->source, f);
                for (int c = tg->texel_lo; c < hi; c++)
                    for (int k = 0; k < 3; k++) sh[3 * c + k] += e->w[c] * f[k];
            }
        } else {
            int hi = tg->grid_nc < 9 ? tg->grid_nc : 9;
            for (uint32_t i = 0; i < rc->count; i++) {
                const drt_entry9 *e = &o->e9[rc->first + i];
                float f[3];
                drt_source_flux(o, tg, e->source, f);
                for (int c = 0; c < hi; c++)
                    for (int k = 0; k < 3; k++) sh[3 * c + k] += e->w[c] * f[k];
            }
        }
    }
}

/* Covered texel caches take their neighbours' mean (all coefficients a texel cache carries). */
static void drt_inpaint_pass(const lc_drt_ops *o, const lc_drt_target *tg) {
    const size_t rec = tg->stride * 3;
    for (uint32_t i = 0; i < o->n_inpaint; i++) {
        const drt_inpaint *ip = &o->inpaint[i];
        if (tg->fresh && !tg->fresh[ip->cache]) continue;
        float *dst = tg->cache_sh + (size_t)ip->cache * rec;
        size_t n = (size_t)tg->texel_nc * 3;
        memset(dst, 0, n * sizeof(float));
        float w = 1.0f / (float)ip->count;
        for (uint32_t k = 0; k < ip->count; k++) {
            const float *src = tg->cache_sh + (size_t)o->inpaint_from[ip->first + k] * rec;
            for (size_t c = 0; c < n; c++) dst[c] += w * src[c];
        }
    }
}

void lc_drt_apply(lc_drt_ops *const *ops, uint32_t n, const lc_drt_target *tg) {
    for (uint32_t i = 0; i < n; i++) {
        drt_patches_pass(ops[i], tg);
        drt_receivers_pass(ops[i], tg);
    }
    /* after every object's deltas, so a fill never reads a neighbour another object changes later */
    for (uint32_t i = 0; i < n; i++) drt_inpaint_pass(ops[i], tg);
}
