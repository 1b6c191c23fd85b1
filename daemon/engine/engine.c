/* engine: the relight front. Validates state, decides what changed, computes each surfel's
 * direct radiosity (lights with Embree shadow rays against the static scene and the placed
 * dynamic objects, emission, sky through a per-surfel visibility transfer), then hands the
 * transport to the backend. Runs on the caller's (compute) thread; parallel inside. */
#include "engine/engine.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "engine/dnrt.h"
#include "engine/drt.h"
#include "engine/embree_device.h"
#include "engine/lightmap_filter.h"
#include "engine/scene_math.h"
#include "engine/transport.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/ray_offset.h"
#include "util/rng.h"
#include "util/sh.h"

#define ENGINE_AREA_SAMPLES 16 /* shadow rays per area light per surfel */
#define ENGINE_SKY_RAYS 64     /* visibility rays per surfel for the sky transfer */

struct lc_engine {
    const lc_lcb *bake;
    const lc_lcb_view *v;
    const lc_transport_ops *ops;
    void *impl;
    float scene_eps; /* ray offset scaled to the scene (lc_ray_lift_scene) */
    int threads;     /* the parallel-for's workers (0 = all cores), the creator's setting */
    /* Embree: static geometry in its own scene, each asset in its own scene, and a top
     * scene of instances rebuilt when the objects change. */
    RTCDevice device;
    RTCScene static_scene;
    RTCScene *asset_scenes;
    RTCScene top;
    /* Derived per-surfel data. */
    float *e_direct;   /* n_surfels*3: irradiance from lights (visibility included) */
    float *sky_t;      /* n_surfels*9: cosine-weighted visibility projected on L2 SH */
    float *b0;         /* n_surfels*3 */
    float *object_pos; /* n_objects*3 */
    int sky_valid;
    /* The last applied state (deep copies) for change detection. */
    lc_engine_light *lights;
    uint32_t n_lights;
    lc_engine_object *objects;
    uint32_t n_objects;
    float *emission; /* n_materials*3 */
    lc_engine_environment env;
    lc_engine_settings settings;
    int have_state;
    int reset_next; /* lc_engine_reset_feedback: the next relight starts without carried light */
    lc_dnrt *dnrt;  /* placed objects in the indirect light (dnrt.h) */
    /* Clutter operators (drt.h), owned; `clutter_active` are those that applied in the last
     * relight (a prefix-free subset, in attach order), `clutter_dirty` when the set changed. */
    lc_drt_ops **clutter;
    uint32_t n_clutter, clutter_cap;
    lc_drt_ops **clutter_active;
    uint32_t n_clutter_active;
    int clutter_dirty;
    lc_engine_object *dnrt_objects; /* the state's objects with active clutter out of DNRT */
    lc_lmfilter *lmfilter;          /* same-surface 3x3 smoothing of the lightmap (lightmap_filter.h) */
    float *lightmap;                /* W*H*3: the filtered lightmap the frame points at */
    lc_engine_frame frame;
    lc_engine_interrupt_fn interrupt; /* lc_engine_set_interrupt */
    void *interrupt_arg;
};

lc_engine_settings lc_engine_default_settings(const lc_lcb *bake) {
    const lc_lcb_view *v = lc_lcb_get(bake);
    lc_engine_settings s = {.bounces = 1,
                            .bands = v->sh_bands ? v->sh_bands : 3,
                            .progressive = 1,
                            .chroma_compression = 0,
                            .chroma_bands = v->sh_bands ? v->sh_bands : 3,
                            .sh_lightmap = 0,
                            .dnrt = 1,
                            .dnrt_blockers = 1,
                            .solver = lc_engine_default_solver(v)};
    return s;
}

uint32_t lc_engine_default_solver(const lc_lcb_view *v) {
    return v->links_per_cache > 0 ? LC_SOLVER_PIC : LC_SOLVER_PROBES;
}

/* --- Embree scenes ------------------------------------------------------------------------- */

static RTCScene engine_mesh_scene(RTCDevice dev, const void *vertices, size_t vstride, uint32_t nv, const void *indices,
                                  size_t istride, uint32_t nt) {
    RTCScene sc = rtcNewScene(dev);
    rtcSetSceneFlags(sc, RTC_SCENE_FLAG_ROBUST);
    if (nt > 0) {
        RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
        /* Shared buffers straight from the mapping: each vertex record has >= 16 readable
         * bytes from its position (normal follows), which Embree's SIMD loads need. */
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices, 0, vstride, nv);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices, 0, istride, nt);
        rtcCommitGeometry(g);
        rtcAttachGeometry(sc, g);
        rtcReleaseGeometry(g);
    }
    rtcCommitScene(sc);
    return sc;
}

static void engine_build_top(lc_engine *e, const lc_engine_object *objects, uint32_t n) {
    if (e->top) rtcReleaseScene(e->top);
    e->top = rtcNewScene(e->device);
    RTCGeometry inst = rtcNewGeometry(e->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(inst, e->static_scene);
    float id[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
    rtcSetGeometryTransform(inst, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, id);
    rtcCommitGeometry(inst);
    rtcAttachGeometry(e->top, inst);
    rtcReleaseGeometry(inst);
    for (uint32_t i = 0; i < n; i++) {
        if (!objects[i].visible) continue;
        RTCGeometry g = rtcNewGeometry(e->device, RTC_GEOMETRY_TYPE_INSTANCE);
        rtcSetGeometryInstancedScene(g, e->asset_scenes[objects[i].asset]);
        float m[12];
        lc_sm_object_matrix(&objects[i], m);
        rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, m);
        rtcCommitGeometry(g);
        rtcAttachGeometry(e->top, g);
        rtcReleaseGeometry(g);
    }
    rtcCommitScene(e->top);
}

/* --- create / release ------------------------------------------------------------------------ */

void lc_engine_release(lc_engine *e) {
    if (!e) return;
    if (e->impl) e->ops->release(e->impl);
    if (e->top) rtcReleaseScene(e->top);
    if (e->asset_scenes) {
        for (uint32_t i = 0; i < e->v->n_assets; i++)
            if (e->asset_scenes[i]) rtcReleaseScene(e->asset_scenes[i]);
        free(e->asset_scenes);
    }
    if (e->static_scene) rtcReleaseScene(e->static_scene);
    if (e->device) rtcReleaseDevice(e->device);
    free(e->e_direct);
    free(e->sky_t);
    free(e->b0);
    free(e->object_pos);
    free(e->lights);
    free(e->objects);
    free(e->emission);
    lc_lmfilter_release(e->lmfilter);
    lc_dnrt_release(e->dnrt);
    for (uint32_t i = 0; i < e->n_clutter; i++) lc_drt_ops_release(e->clutter[i]);
    free(e->clutter);
    free(e->clutter_active);
    free(e->dnrt_objects);
    free(e->lightmap);
    free(e);
}

const char *lc_engine_backend_name(const lc_engine *e) { return e->ops->name; }

lc_backend_kind lc_engine_backend(const lc_engine *e) {
    return e->ops == &lc_transport_egl ? LC_BACKEND_EGL : LC_BACKEND_CPU;
}

lc_engine *lc_engine_create(const lc_lcb *bake, lc_backend_kind kind, int threads, char *err, size_t errlen) {
    lc_engine *e = calloc(1, sizeof *e);
    if (!e) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    e->bake = bake;
    e->v = lc_lcb_get(bake);
    const lc_lcb_view *v = e->v;
    e->threads = threads;
    e->scene_eps = lc_embree_scene_epsilon(v);
    e->device = lc_embree_device_new(threads, "engine", err, errlen);
    if (!e->device) goto err;
    e->static_scene = engine_mesh_scene(e->device, v->vertices, sizeof(lc_lcb_vertex), v->n_vertices, v->triangles,
                                        sizeof(lc_lcb_triangle), v->n_triangles);
    e->asset_scenes = calloc(v->n_assets ? v->n_assets : 1, sizeof *e->asset_scenes);
    if (!e->asset_scenes) goto oom;
    for (uint32_t i = 0; i < v->n_assets; i++) {
        const lc_lcb_asset *a = &v->assets[i];
        e->asset_scenes[i] = engine_mesh_scene(
            e->device, v->asset_vertices + a->first_vertex, sizeof(lc_lcb_asset_vertex), a->vertex_count,
            v->asset_indices + 3 * (size_t)a->first_triangle, 3 * sizeof(uint32_t), a->triangle_count);
    }
    engine_build_top(e, NULL, 0);
    if (rtcGetDeviceError(e->device) != RTC_ERROR_NONE) {
        lc_set_err(err, errlen, "embree: building the scene failed (see log)");
        goto err;
    }
    e->e_direct = calloc((size_t)v->n_surfels * 3, sizeof(float));
    e->b0 = calloc((size_t)v->n_surfels * 3, sizeof(float));
    e->emission = calloc((size_t)(v->n_materials ? v->n_materials : 1) * 3, sizeof(float));
    if (!e->e_direct || !e->b0 || !e->emission) goto oom;
    e->lightmap = malloc(((size_t)v->lightmap_width * v->lightmap_height + 1) * 3 * sizeof(float));
    if (!e->lightmap) goto oom;
    if (!(e->lmfilter = lc_lmfilter_create(v, err, errlen))) goto err;
    if (!(e->dnrt = lc_dnrt_create(v, err, errlen))) goto err;

    /* Backend: AUTO tries EGL on a hardware device only (on llvmpipe the CPU backend is faster;
     * docs/ARCHITECTURE.md, Performance). */
    char berr[512] = "";
    if (kind == LC_BACKEND_EGL || kind == LC_BACKEND_AUTO) {
        e->ops = &lc_transport_egl;
        e->impl = e->ops->create(v, kind == LC_BACKEND_AUTO ? -1 : threads, berr, sizeof berr);
        if (!e->impl) {
            if (kind == LC_BACKEND_EGL) {
                lc_set_err(err, errlen, "egl backend: %s", berr);
                goto err;
            }
            lc_info("engine", "backend auto: using cpu (%s)", berr);
        }
    }
    if (!e->impl) {
        e->ops = &lc_transport_cpu;
        e->impl = e->ops->create(v, threads, err, errlen);
        if (!e->impl) goto err;
    }
    lc_info("engine", "relight backend: %s (%u surfels, %u caches, %u links/cache)", e->ops->name, v->n_surfels,
            v->n_caches, v->links_per_cache);
    return e;
oom:
    lc_set_err(err, errlen, "out of memory creating the relight engine");
err:
    lc_engine_release(e);
    return NULL;
}

/* --- validation ------------------------------------------------------------------------------ */

static int engine_finite(const float *x, int n, double limit) {
    for (int i = 0; i < n; i++)
        if (!isfinite(x[i]) || fabs(x[i]) > limit) return 0;
    return 1;
}

static float engine_len(const float d[3]) { return sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]); }

int lc_engine_validate_state(const lc_engine *e, const lc_engine_state *st, char *err, size_t errlen) {
    if (lc_engine_check_state(e->v, st, err, errlen) != 0) return -1;
    return lc_engine_check_solver(e->v, lc_engine_backend(e), st->settings.solver, err, errlen);
}

int lc_engine_check_solver(const lc_lcb_view *v, lc_backend_kind backend, uint32_t solver, char *err, size_t errlen) {
    (void)backend; /* both backends run both solvers */
    if (solver >= LC_SOLVER_COUNT) {
        lc_set_err(err, errlen, "/settings/solver: unknown solver %u", solver);
        return -1;
    }
    if (solver == LC_SOLVER_PROBES && !v->probe_header) {
        lc_set_err(err, errlen,
                   "/settings/solver: this bake has no probes solver (bake it with lucent-bake bake --solver probes "
                   "or both)");
        return -1;
    }
    if (solver == LC_SOLVER_PIC && v->links_per_cache == 0) {
        lc_set_err(err, errlen, "/settings/solver: this bake has no PIC links (baked with --solver probes)");
        return -1;
    }
    return 0;
}

int lc_engine_check_state(const lc_lcb_view *v, const lc_engine_state *st, char *err, size_t errlen) {
    if (st->n_lights > LC_ENGINE_MAX_LIGHTS || (st->n_lights && !st->lights)) {
        lc_set_err(err, errlen, "/lights: at most %d lights", LC_ENGINE_MAX_LIGHTS);
        return -1;
    }
    for (uint32_t i = 0; i < st->n_lights; i++) {
        const lc_engine_light *l = &st->lights[i];
#define LIGHT_FAIL(field, ...)                                       \
    do {                                                             \
        char why[160];                                               \
        snprintf(why, sizeof why, __VA_ARGS__);                      \
        lc_set_err(err, errlen, "/lights/%u/%s: %s", i, field, why); \
        return -1;                                                   \
    } while (0)
        if ((unsigned)l->type > LC_ENGINE_LIGHT_AREA) LIGHT_FAIL("type", "unknown light type %d", (int)l->type);
        if (!engine_finite(l->color, 3, 1e6) || l->color[0] < 0 || l->color[1] < 0 || l->color[2] < 0)
            LIGHT_FAIL("color", "must be 3 finite numbers >= 0");
        if (!isfinite(l->intensity) || l->intensity < 0 || l->intensity > 1e9)
            LIGHT_FAIL("intensity", "must be finite in [0, 1e9]");
        if (!isfinite(l->range) || l->range < 0 || l->range > 1e6) LIGHT_FAIL("range", "must be finite in [0, 1e6]");
        if (!engine_finite(l->position, 3, 1e6)) LIGHT_FAIL("position", "must be 3 finite numbers within 1e6");
        if (l->type != LC_ENGINE_LIGHT_POINT &&
            (!engine_finite(l->direction, 3, 1e6) || engine_len(l->direction) < 1e-6f))
            LIGHT_FAIL("direction", "must be a finite non-zero vector");
        if (l->type == LC_ENGINE_LIGHT_SPOT &&
            (!(l->inner_cone >= 0) || !(l->inner_cone <= l->outer_cone) || !(l->outer_cone <= (float)M_PI_2)))
            LIGHT_FAIL("outerConeAngle", "need 0 <= innerConeAngle <= outerConeAngle <= pi/2");
        if (l->type == LC_ENGINE_LIGHT_AREA) {
            if ((unsigned)l->shape > LC_AREA_DISC) LIGHT_FAIL("shape", "must be quad or disc");
            int nsize = l->shape == LC_AREA_QUAD ? 2 : 1;
            for (int k = 0; k < nsize; k++)
                if (!isfinite(l->size[k]) || !(l->size[k] > 0) || l->size[k] > 1e4)
                    LIGHT_FAIL("size", "must be finite in (0, 1e4] metres");
            if (l->shape == LC_AREA_QUAD && (!engine_finite(l->tangent, 3, 1e6) || engine_len(l->tangent) < 1e-6f))
                LIGHT_FAIL("tangent", "must be a finite non-zero vector");
        }
#undef LIGHT_FAIL
    }
    if (st->n_objects > LC_ENGINE_MAX_OBJECTS || (st->n_objects && !st->objects)) {
        lc_set_err(err, errlen, "/objects: at most %d objects", LC_ENGINE_MAX_OBJECTS);
        return -1;
    }
    for (uint32_t i = 0; i < st->n_objects; i++) {
        const lc_engine_object *o = &st->objects[i];
        if (o->asset >= v->n_assets) {
            lc_set_err(err, errlen, "/objects/%u/asset: index %u, the bake has %u assets", i, o->asset, v->n_assets);
            return -1;
        }
        if (!engine_finite(o->translation, 3, 1e6)) {
            lc_set_err(err, errlen, "/objects/%u/translation: must be 3 finite numbers within 1e6", i);
            return -1;
        }
        float q = sqrtf(o->rotation[0] * o->rotation[0] + o->rotation[1] * o->rotation[1] +
                        o->rotation[2] * o->rotation[2] + o->rotation[3] * o->rotation[3]);
        if (!engine_finite(o->rotation, 4, 1e6) || !(q > 1e-6f)) {
            lc_set_err(err, errlen, "/objects/%u/rotation: must be a finite non-zero quaternion", i);
            return -1;
        }
        for (int k = 0; k < 3; k++)
            if (!isfinite(o->scale[k]) || fabsf(o->scale[k]) < 1e-6f || fabsf(o->scale[k]) > 1e4f) {
                lc_set_err(err, errlen, "/objects/%u/scale: each component must be finite, |s| in [1e-6, 1e4]", i);
                return -1;
            }
    }
    if (st->material_emission)
        for (uint32_t m = 0; m < v->n_materials; m++) {
            const float *em = st->material_emission + 3 * (size_t)m;
            if (!engine_finite(em, 3, 1e7) || em[0] < 0 || em[1] < 0 || em[2] < 0) {
                lc_set_err(err, errlen, "/materials/%u/emission: must be 3 finite numbers in [0, 1e7]", m);
                return -1;
            }
        }
    const lc_engine_environment *env = &st->environment;
    if ((unsigned)env->kind > LC_ENV_SH || !engine_finite(env->color, 3, 1e7) ||
        !engine_finite(&env->sh[0][0], 27, 1e7) || !isfinite(env->intensity) || env->intensity < 0 ||
        env->intensity > 1e7) {
        lc_set_err(err, errlen, "/environment: kind, color, sh and intensity must be finite (intensity in [0, 1e7])");
        return -1;
    }
    const lc_engine_settings *s = &st->settings;
    if (s->bounces > 16) {
        lc_set_err(err, errlen, "/settings/bounces: %u is outside 0..16", s->bounces);
        return -1;
    }
    if (s->bands < 1 || s->bands > LC_SH_MAX_BANDS) {
        lc_set_err(err, errlen, "/settings/bands: %u is outside 1..%d", s->bands, LC_SH_MAX_BANDS);
        return -1;
    }
    if (s->chroma_compression && (s->chroma_bands < 1 || s->chroma_bands > s->bands)) {
        lc_set_err(err, errlen, "/settings/chroma_bands: %u is outside 1..bands (%u)", s->chroma_bands, s->bands);
        return -1;
    }
    if (s->grid_cells > LC_GRID_NEEDED) {
        lc_set_err(err, errlen, "/settings/grid_cells: %u is neither all (0) nor needed (1)", s->grid_cells);
        return -1;
    }
    return lc_engine_check_solver(v, LC_BACKEND_AUTO, s->solver, err, errlen);
}

/* --- direct light ---------------------------------------------------------------------------- */

typedef struct {
    lc_engine *e;
    const lc_engine_light *lights;
    uint32_t n_lights;
} engine_direct_job;

/* Irradiance from the lights at a surface point (unit normal n), shadow rays against the
 * top scene from the point lifted along n; `key` seeds the area lights' samples (a surfel's
 * index; clutter elements count from 2^31). */
static void engine_direct_point(const engine_direct_job *job, const float pos[3], const float n[3], uint64_t key,
                                float acc[3]) {
    const lc_engine *e = job->e;
    float org[3] = {pos[0] + n[0] * e->scene_eps, pos[1] + n[1] * e->scene_eps, pos[2] + n[2] * e->scene_eps};
    acc[0] = acc[1] = acc[2] = 0;
    for (uint32_t li = 0; li < job->n_lights; li++) {
        const lc_engine_light *l = &job->lights[li];
        float scale = l->intensity;
        if (l->type == LC_ENGINE_LIGHT_DIRECTIONAL) {
            float dl = engine_len(l->direction);
            float w[3] = {-l->direction[0] / dl, -l->direction[1] / dl, -l->direction[2] / dl};
            float cosn = n[0] * w[0] + n[1] * w[1] + n[2] * w[2];
            if (cosn <= 0 || lc_embree_occluded(e->top, org, w, INFINITY)) continue;
            for (int k = 0; k < 3; k++) acc[k] += scale * l->color[k] * cosn;
        } else if (l->type == LC_ENGINE_LIGHT_AREA) {
            /* Stratified samples over the emitter, one shadow ray each. */
            lc_sm_area_frame fr = lc_sm_area_frame_of(l);
            const float *ln = fr.n;
            lc_rng rng = lc_rng_seed(0xA5EA, ((uint64_t)li << 32) | key);
            float sum = 0;
            for (int j = 0; j < ENGINE_AREA_SAMPLES; j++) {
                float u = ((float)(j % 4) + lc_rng_float(&rng)) * 0.25f;
                float w = ((float)(j / 4) + lc_rng_float(&rng)) * 0.25f;
                float p[3], d[3];
                lc_sm_area_point(l, &fr, u, w, p);
                for (int k = 0; k < 3; k++) d[k] = p[k] - org[k];
                float d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                if (!(d2 > 1e-12f)) continue;
                float dist = sqrtf(d2);
                for (int k = 0; k < 3; k++) d[k] /= dist;
                float cos_s = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
                float cos_l = -(ln[0] * d[0] + ln[1] * d[1] + ln[2] * d[2]);
                if (cos_s <= 0 || cos_l <= 0) continue;
                if (lc_embree_occluded(e->top, org, d, lc_ray_shadow_tfar(dist, e->scene_eps))) continue;
                sum += cos_s * cos_l / d2 * lc_sm_range_window(d2, l->range);
            }
            float g = scale * sum * fr.area / ENGINE_AREA_SAMPLES;
            for (int k = 0; k < 3; k++) acc[k] += g * l->color[k];
        } else { /* point, spot */
            float d[3] = {l->position[0] - org[0], l->position[1] - org[1], l->position[2] - org[2]};
            float d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if (!(d2 > 1e-12f)) continue;
            float dist = sqrtf(d2);
            for (int k = 0; k < 3; k++) d[k] /= dist;
            float cosn = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
            if (cosn <= 0) continue;
            float att = lc_sm_range_window(d2, l->range) / d2;
            if (l->type == LC_ENGINE_LIGHT_SPOT) att *= lc_sm_spot_cone(l, d);
            if (att <= 0) continue;
            if (lc_embree_occluded(e->top, org, d, lc_ray_shadow_tfar(dist, e->scene_eps))) continue;
            for (int k = 0; k < 3; k++) acc[k] += scale * l->color[k] * cosn * att;
        }
    }
}

static void engine_direct_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const engine_direct_job *job = ctx;
    const lc_lcb_view *v = job->e->v;
    for (size_t s = begin; s < end; s++)
        engine_direct_point(job, v->surfels[s].position, v->surfels[s].normal, s, job->e->e_direct + 3 * s);
}

/* The same direct light at one clutter object's patch elements (drt.h). */
typedef struct {
    engine_direct_job job;
    lc_drt_elements el;
    uint64_t key0;
} engine_clutter_job;

static void engine_clutter_direct_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const engine_clutter_job *cj = ctx;
    for (size_t i = begin; i < end; i++)
        engine_direct_point(&cj->job, cj->el.positions + 3 * i, cj->el.normals + 3 * i, cj->key0 + i,
                            cj->el.e_direct + 3 * i);
}

/* Cosine-weighted visibility of the sky projected on L2 SH, per surfel (PRT transfer). */
static void engine_sky_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    lc_engine *e = ctx;
    const lc_lcb_view *v = e->v;
    for (size_t s = begin; s < end; s++) {
        const lc_lcb_surfel *sf = &v->surfels[s];
        float nx = sf->normal[0], ny = sf->normal[1], nz = sf->normal[2];
        /* Orthonormal basis around n (Duff et al.). */
        float sign = copysignf(1.0f, nz), a = -1.0f / (sign + nz), b = nx * ny * a;
        float t[3] = {1.0f + sign * nx * nx * a, sign * b, -sign * nx}, bt[3] = {b, sign + ny * ny * a, -ny};
        float org[3] = {sf->position[0] + nx * e->scene_eps, sf->position[1] + ny * e->scene_eps,
                        sf->position[2] + nz * e->scene_eps};
        float acc[9] = {0};
        lc_rng rng = lc_rng_seed(0x5C1, s);
        float rot = lc_rng_float(&rng);
        for (int j = 0; j < ENGINE_SKY_RAYS; j++) {
            /* Cosine-weighted Fibonacci hemisphere, rotated per surfel. */
            float u = ((float)j + 0.5f) / ENGINE_SKY_RAYS;
            float phi = 2.0f * (float)M_PI * ((float)j * 0.618034f + rot);
            float r = sqrtf(u), z = sqrtf(1.0f - u);
            float lx = r * cosf(phi), ly = r * sinf(phi);
            float d[3] = {lx * t[0] + ly * bt[0] + z * nx, lx * t[1] + ly * bt[1] + z * ny,
                          lx * t[2] + ly * bt[2] + z * nz};
            if (lc_embree_occluded(e->top, org, d, INFINITY)) continue;
            float y[9];
            lc_sh_eval_fast(3, d[0], d[1], d[2], y);
            for (int k = 0; k < 9; k++) acc[k] += y[k];
        }
        for (int k = 0; k < 9; k++) e->sky_t[9 * s + k] = acc[k] * (float)M_PI / ENGINE_SKY_RAYS;
    }
}

/* --- relight ----------------------------------------------------------------------------------- */

static int engine_copy_state(lc_engine *e, const lc_engine_state *st) {
    lc_engine_light *l = NULL;
    lc_engine_object *o = NULL;
    if (st->n_lights) {
        l = malloc(st->n_lights * sizeof *l);
        if (!l) return -1;
        memcpy(l, st->lights, st->n_lights * sizeof *l);
    }
    if (st->n_objects) {
        o = malloc(st->n_objects * sizeof *o);
        if (!o) {
            free(l);
            return -1;
        }
        memcpy(o, st->objects, st->n_objects * sizeof *o);
    }
    free(e->lights);
    free(e->objects);
    e->lights = l;
    e->n_lights = st->n_lights;
    e->objects = o;
    e->n_objects = st->n_objects;
    return 0;
}

/* The objects' ray-tracing instances and SH sample points (each asset's bounds centre,
 * transformed); the sky transfer must be redone. -1 out of memory. */
static int engine_place_objects(lc_engine *e, const lc_engine_state *st) {
    engine_build_top(e, st->objects, st->n_objects);
    float *pos = realloc(e->object_pos, (st->n_objects ? st->n_objects : 1) * 3 * sizeof(float));
    if (!pos) return -1;
    e->object_pos = pos;
    for (uint32_t i = 0; i < st->n_objects; i++) {
        const lc_lcb_asset *a = &e->v->assets[st->objects[i].asset];
        float c[3], m[12];
        for (int k = 0; k < 3; k++) c[k] = 0.5f * (a->bounds_min[k] + a->bounds_max[k]);
        lc_sm_object_matrix(&st->objects[i], m);
        lc_sm_transform_point(m, c, pos + 3 * (size_t)i);
    }
    e->sky_valid = 0;
    return 0;
}

/* Objects in the indirect light (dnrt.h): their receivers when objects (or the switches)
 * change, the direct light on them when the lights change too. `objects` are the state's,
 * with clutter whose operators apply taken out (engine_clutter_reconcile). */
static int engine_dnrt_update(lc_engine *e, const lc_engine_state *st, const lc_engine_object *objects, int first,
                              int objects_changed, int lights_changed, char *err, size_t errlen) {
    int switches_changed =
        first || st->settings.dnrt != e->settings.dnrt || st->settings.dnrt_blockers != e->settings.dnrt_blockers;
    if ((objects_changed || switches_changed) &&
        lc_dnrt_place(e->dnrt, objects, st->n_objects, e->object_pos, &st->settings, e->static_scene, e->scene_eps, err,
                      errlen) != 0)
        return -1;
    if (objects_changed || switches_changed || lights_changed)
        lc_dnrt_direct(e->dnrt, st->lights, st->n_lights, e->top, e->scene_eps, objects);
    return 0;
}

/* --- clutter operators (drt.h) ------------------------------------------------------------------ */

int lc_engine_clutter_attach(lc_engine *e, lc_drt_ops *ops, char *err, size_t errlen) {
    lc_engine_clutter_detach(e, lc_drt_ops_object(ops)->id);
    if (e->n_clutter == e->clutter_cap) {
        uint32_t cap = e->clutter_cap ? 2 * e->clutter_cap : 4;
        lc_drt_ops **a = realloc(e->clutter, cap * sizeof *a),
                   **b = a ? realloc(e->clutter_active, cap * sizeof *b) : NULL;
        if (a) e->clutter = a;
        if (b) e->clutter_active = b;
        if (!a || !b) {
            lc_drt_ops_release(ops);
            lc_set_err(err, errlen, "out of memory attaching clutter operators");
            return -1;
        }
        e->clutter_cap = cap;
    }
    e->clutter[e->n_clutter++] = ops;
    e->clutter_dirty = 1;
    return 0;
}

void lc_engine_clutter_detach(lc_engine *e, const char *object_id) {
    for (uint32_t i = 0; i < e->n_clutter; i++) {
        if (strcmp(lc_drt_ops_object(e->clutter[i])->id, object_id) != 0) continue;
        for (uint32_t k = 0; k < e->n_clutter_active; k++)
            if (e->clutter_active[k] == e->clutter[i]) {
                memmove(e->clutter_active + k, e->clutter_active + k + 1,
                        (e->n_clutter_active - k - 1) * sizeof *e->clutter_active);
                e->n_clutter_active--;
                break;
            }
        lc_drt_ops_release(e->clutter[i]);
        memmove(e->clutter + i, e->clutter + i + 1, (e->n_clutter - i - 1) * sizeof *e->clutter);
        e->n_clutter--;
        e->clutter_dirty = 1;
        return;
    }
}

int lc_engine_clutter_info(const lc_engine *e, const char *object_id, lc_drt_info *info) {
    for (uint32_t k = 0; k < e->n_clutter_active; k++)
        if (strcmp(lc_drt_ops_object(e->clutter_active[k])->id, object_id) == 0) {
            if (info) *info = lc_drt_ops_info(e->clutter_active[k]);
            return 1;
        }
    return 0;
}

int lc_engine_clutter_active(const lc_engine *e, const char *object_id) {
    return lc_engine_clutter_info(e, object_id, NULL);
}

/* Releases the operators whose object moved, hid or left; the rest apply, and their objects
 * leave DNRT (*dnrt_objects: the objects DNRT gets). -1 out of memory. */
static int engine_clutter_reconcile(lc_engine *e, const lc_engine_state *st, const lc_engine_object **dnrt_objects) {
    *dnrt_objects = st->objects;
    e->n_clutter_active = 0;
    for (uint32_t i = 0; i < e->n_clutter;) {
        const lc_engine_object *want = lc_drt_ops_object(e->clutter[i]), *found = NULL;
        for (uint32_t k = 0; k < st->n_objects && !found; k++)
            if (strcmp(st->objects[k].id, want->id) == 0) found = &st->objects[k];
        if (!found || !found->visible || found->clutter_off || !lc_drt_ops_match(e->clutter[i], found)) {
            lc_drt_ops_release(e->clutter[i]);
            memmove(e->clutter + i, e->clutter + i + 1, (e->n_clutter - i - 1) * sizeof *e->clutter);
            e->n_clutter--;
            e->clutter_dirty = 1;
            continue;
        }
        e->clutter_active[e->n_clutter_active++] = e->clutter[i++];
    }
    if (!e->n_clutter_active) return 0;
    lc_engine_object *o = realloc(e->dnrt_objects, (st->n_objects ? st->n_objects : 1) * sizeof *o);
    if (!o) return -1;
    e->dnrt_objects = o;
    memcpy(o, st->objects, st->n_objects * sizeof *o);
    for (uint32_t k = 0; k < st->n_objects; k++)
        if (lc_engine_clutter_active(e, o[k].id)) o[k].dnrt_off = 1;
    *dnrt_objects = o;
    return 0;
}

/* The direct light at every active clutter object's patch elements. */
static void engine_clutter_direct(lc_engine *e, const lc_engine_state *st) {
    uint64_t key0 = 1ull << 31;
    for (uint32_t i = 0; i < e->n_clutter_active; i++) {
        engine_clutter_job cj = {{e, st->lights, st->n_lights}, lc_drt_elements_get(e->clutter_active[i]), key0};
        lc_parallel_for(e->threads, cj.el.n, 64, engine_clutter_direct_range, &cj);
        lc_drt_elements_lit(e->clutter_active[i]);
        key0 += cj.el.n;
    }
}

/* B0 = pi * emission + albedo * (direct + sky) per surfel; the sky transfer is computed once. */
static int engine_compute_b0(lc_engine *e, const lc_engine_state *st, const float *emission, char *err, size_t errlen) {
    const lc_lcb_view *v = e->v;
    int sky_on = st->environment.kind != LC_ENV_NONE && st->environment.intensity > 0;
    if (sky_on && !e->sky_valid) {
        if (!e->sky_t) e->sky_t = calloc((size_t)v->n_surfels * 9, sizeof(float));
        if (!e->sky_t) {
            lc_set_err(err, errlen, "out of memory for the sky transfer");
            return -1;
        }
        lc_parallel_for(e->threads, v->n_surfels, 256, engine_sky_range, e);
        e->sky_valid = 1;
    }
    /* Sky radiance SH (L2). */
    float sky[9][3] = {{0}};
    if (sky_on) {
        if (st->environment.kind == LC_ENV_CONSTANT)
            for (int k = 0; k < 3; k++) sky[0][k] = st->environment.color[k] * (float)sqrt(4.0 * M_PI);
        else memcpy(sky, st->environment.sh, sizeof sky);
        for (int j = 0; j < 9; j++)
            for (int k = 0; k < 3; k++) sky[j][k] *= st->environment.intensity;
    }
    for (uint32_t s = 0; s < v->n_surfels; s++) {
        const lc_lcb_surfel *sf = &v->surfels[s];
        for (int k = 0; k < 3; k++) {
            float es = 0;
            if (sky_on)
                for (int j = 0; j < 9; j++) es += sky[j][k] * e->sky_t[9 * (size_t)s + j];
            float em = st->material_emission ? emission[3 * sf->material + k] : sf->emission[k];
            e->b0[3 * s + k] = (float)M_PI * em + sf->albedo[k] * (e->e_direct[3 * s + k] + fmaxf(0.0f, es));
        }
    }
    return 0;
}

void lc_engine_reset_feedback(lc_engine *e) { e->reset_next = 1; }

void lc_engine_set_interrupt(lc_engine *e, lc_engine_interrupt_fn fn, void *arg) {
    e->interrupt = fn;
    e->interrupt_arg = arg;
}

int lc_engine_relight(lc_engine *e, const lc_engine_state *st, const lc_engine_frame **frame, char *err,
                      size_t errlen) {
    const lc_lcb_view *v = e->v;
    if (lc_engine_validate_state(e, st, err, errlen) != 0) return -1;
    double t0 = lc_clock_ms();

    /* What changed since the last relight. */
    size_t nm = (size_t)v->n_materials * 3;
    float *emission = malloc((nm ? nm : 1) * sizeof(float));
    if (!emission) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    for (uint32_t m = 0; m < v->n_materials; m++)
        for (int k = 0; k < 3; k++)
            emission[3 * m + k] =
                st->material_emission ? st->material_emission[3 * m + k] : v->materials[m].emission[k];
    int first = !e->have_state;
    int lights_changed = first || st->n_lights != e->n_lights ||
        (st->n_lights && memcmp(st->lights, e->lights, st->n_lights * sizeof *st->lights) != 0);
    int objects_changed = first || st->n_objects != e->n_objects ||
        (st->n_objects && memcmp(st->objects, e->objects, st->n_objects * sizeof *st->objects) != 0);
    int emission_changed = first || memcmp(emission, e->emission, nm * sizeof(float)) != 0;
    int env_changed = first || memcmp(&st->environment, &e->env, sizeof st->environment) != 0;
    int settings_changed = first || memcmp(&st->settings, &e->settings, sizeof st->settings) != 0;
    const lc_engine_object *dnrt_objects;
    if (engine_clutter_reconcile(e, st, &dnrt_objects) != 0) {
        free(emission);
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    int clutter_changed = e->clutter_dirty;
    if (!(lights_changed || objects_changed || emission_changed || env_changed || settings_changed ||
          clutter_changed) &&
        !st->settings.progressive) {
        free(emission);
        e->frame.revision = st->revision;
        e->frame.stages_run = 0;
        for (int i = 0; i < LC_STAGE_COUNT; i++) e->frame.stage_ms[i] = 0;
        e->frame.total_ms = lc_clock_ms() - t0;
        *frame = &e->frame;
        return 0;
    }
    if (objects_changed && engine_place_objects(e, st) != 0) {
        free(emission);
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }

    double td = lc_clock_ms();
    if (engine_dnrt_update(e, st, dnrt_objects, first, objects_changed || clutter_changed, lights_changed, err,
                           errlen) != 0) {
        free(emission);
        return -1;
    }
    const lc_dnrt_frame *dnrt = lc_dnrt_frame_get(e->dnrt);
    double dnrt_ms = lc_clock_ms() - td;
    td = lc_clock_ms();
    if (lights_changed || objects_changed || clutter_changed) engine_clutter_direct(e, st);
    double drt_ms = lc_clock_ms() - td;

    double t1 = lc_clock_ms();
    uint32_t stages_run = 0;
    if (lights_changed || objects_changed) {
        engine_direct_job job = {e, st->lights, st->n_lights};
        lc_parallel_for(e->threads, v->n_surfels, 256, engine_direct_range, &job);
        stages_run |= 1u << LC_STAGE_DIRECT;
    }
    if (engine_compute_b0(e, st, emission, err, errlen) != 0) {
        free(emission);
        return -1;
    }
    double t2 = lc_clock_ms();

    lc_transport_input in = {.b0 = e->b0,
                             .settings = st->settings,
                             .reset_feedback = !st->settings.progressive || first || e->reset_next,
                             .object_pos = e->object_pos,
                             .n_objects = st->n_objects,
                             .dnrt = dnrt->n_objects ? dnrt : NULL,
                             .drt = e->clutter_active,
                             .n_drt = e->n_clutter_active,
                             .interrupt = e->interrupt,
                             .interrupt_arg = e->interrupt_arg};
    lc_engine_frame fr;
    memset(&fr, 0, sizeof fr);
    int rc = e->ops->run(e->impl, &in, &fr, err, errlen);
    if (rc != 0) { /* interrupted too: the last state stays the one to compare with */
        free(emission);
        return rc == LC_ENGINE_INTERRUPTED ? rc : -1;
    }
    if (engine_copy_state(e, st) != 0) {
        free(emission);
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    free(e->emission);
    e->emission = emission;
    e->env = st->environment;
    e->settings = st->settings;
    e->have_state = 1;
    e->reset_next = 0;
    fr.lightmap_width = v->lightmap_width;
    fr.lightmap_height = v->lightmap_height;
    double tf = lc_clock_ms();
    lc_lmfilter_apply(e->lmfilter, fr.lightmap, e->lightmap, e->threads);
    fr.stage_ms[LC_STAGE_LIGHTMAP] += lc_clock_ms() - tf; /* the filter is part of the lightmap */
    fr.lightmap = e->lightmap;
    fr.sh_bands = st->settings.bands;
    fr.sh_stride = LC_SH_MAX_COEFFS; /* both backends keep full-size records */
    fr.n_caches = v->n_caches;
    memcpy(fr.grid_dims, v->grid_dims, sizeof fr.grid_dims);
    memcpy(fr.grid_origin, v->grid_origin, sizeof fr.grid_origin);
    fr.grid_cell = v->grid_cell;
    fr.grid_complete = st->settings.grid_cells == LC_GRID_ALL;
    fr.n_objects = st->n_objects;
    fr.stage_ms[LC_STAGE_DIRECT] = t2 - t1;
    /* The transport always runs its stages (chroma only when compressing). */
    stages_run |= (1u << LC_STAGE_BOUNCE) | (1u << LC_STAGE_PULL) | (1u << LC_STAGE_GATHER) |
        (1u << LC_STAGE_LIGHTMAP) | (1u << LC_STAGE_GRID) | (1u << LC_STAGE_OBJECTS);
    if (st->settings.chroma_compression && st->settings.chroma_bands < st->settings.bands)
        stages_run |= 1u << LC_STAGE_CHROMA;
    fr.stage_ms[LC_STAGE_DNRT] += dnrt_ms;
    fr.dnrt_objects = dnrt->n_objects;
    fr.dnrt_receivers = dnrt->n_receivers;
    if (dnrt->n_objects) stages_run |= 1u << LC_STAGE_DNRT;
    fr.stage_ms[LC_STAGE_DRT] += drt_ms;
    fr.drt_objects = e->n_clutter_active;
    for (uint32_t i = 0; i < e->n_clutter_active; i++)
        fr.drt_receivers += lc_drt_ops_info(e->clutter_active[i]).receivers;
    if (e->n_clutter_active) stages_run |= 1u << LC_STAGE_DRT;
    e->clutter_dirty = 0;
    fr.stages_run = stages_run;
    fr.revision = st->revision;
    fr.total_ms = lc_clock_ms() - t0;
    e->frame = fr;
    *frame = &e->frame;
    return 0;
}
