/* ref: the Embree path tracer that gives the engine's ground truth (the quantity and the
 * estimator are defined in ref.h). One scene per lc_ref: the static mesh (geometry 0) and the
 * placed dynamic objects flattened to world space (geometry 1). */
#include "ref/ref.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine/embree_device.h"
#include "engine/scene_math.h"
#include "util/clock.h"
#include "util/crc32.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/ray_offset.h"
#include "util/rng.h"
#include "util/sh.h"

#define REF_GEOM_STATIC 0u
#define REF_GEOM_OBJECTS 1u

struct lc_ref {
    const lc_lcb *bake;
    const lc_lcb_view *v;
    float eps;         /* ray offset scaled to the scene, as the engine's (lc_ray_lift_scene) */
    int threads;       /* the parallel-for's workers (0 = all cores), the creator's setting */
    float surfel_area; /* mean surfel area: the bake's spacing (exposure reweighs surfels, not the sum) */
    /* State (copied). */
    lc_engine_light *lights;
    uint32_t n_lights;
    int sky_on;
    float sky[9][3]; /* radiance SH x intensity */
    float *emission; /* n_materials*3 nits */
    float *albedo;   /* n_materials*3: clamped base colour, or (textured) the mean surfel albedo */
    uint8_t *textured;
    /* Objects, world space. */
    float *obj_pos; /* 4 floats per vertex (Embree reads 16 bytes) */
    float *obj_alb; /* 3 per vertex */
    uint32_t *obj_idx;
    uint32_t n_obj_vertices, n_obj_tris;
    /* Emissive static triangles: power CDF, and per triangle P_t / A_t (0 = not emissive). */
    uint32_t n_emit;
    uint32_t *emit_tri;
    double *emit_cdf; /* n_emit + 1 */
    float *emit_pdf;  /* n_triangles: probability of picking the triangle / its area */
    /* Surfels sorted by grid cell, for the textured-albedo lookup. */
    float cell_inv, cell_origin[3];
    uint64_t *sk_key;
    uint32_t *sk_item;
    uint64_t *cell_key; /* open-addressing table: cell key + 1 (0 = empty) */
    uint32_t *cell_start, *cell_count;
    uint32_t cell_mask;
    float *tri_albedo; /* n_triangles*3: small textured triangles' albedo (NAN = look up per hit) */
    /* Embree. */
    RTCDevice device;
    RTCScene scene;
};

lc_ref_settings lc_ref_default_settings(void) {
    lc_ref_settings s = {.spp = 4096,
                         .batch_spp = 256,
                         .target_stderr = 0,
                         .floor_frac = 0.05,
                         .max_bounces = 32,
                         .rr_depth = 3,
                         .seed = 1,
                         .threads = 0,
                         .texels = 1,
                         .grid = 1,
                         .quiet = 0,
                         .texel_at = LC_REF_TEXEL_AT_SURFACE};
    return s;
}

const char *lc_ref_texel_at_name(int texel_at) {
    return texel_at == LC_REF_TEXEL_AT_SURFACE ? "surface" : texel_at == LC_REF_TEXEL_AT_CACHE ? "cache" : "unknown";
}

/* --- small vector helpers ------------------------------------------------------------------ */

static inline float ref_dot(const float a[3], const float b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static inline float ref_len(const float a[3]) { return sqrtf(ref_dot(a, a)); }
static inline void ref_cross(const float a[3], const float b[3], float o[3]) {
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}
static inline void ref_normalize(float a[3]) {
    float l = ref_len(a);
    if (l > 0) a[0] /= l, a[1] /= l, a[2] /= l;
}
/* Orthonormal basis around unit n (Duff et al.). */
static inline void ref_basis(const float n[3], float t[3], float b[3]) {
    float s = copysignf(1.0f, n[2]), a = -1.0f / (s + n[2]), c = n[0] * n[1] * a;
    t[0] = 1.0f + s * n[0] * n[0] * a, t[1] = s * c, t[2] = -s * n[0];
    b[0] = c, b[1] = s + n[1] * n[1] * a, b[2] = -n[1];
}
static inline void ref_cosine_dir(const float n[3], lc_rng *rng, float d[3], float *cos_out) {
    float u = lc_rng_float(rng), w = lc_rng_float(rng);
    float r = sqrtf(u), phi = 2.0f * (float)M_PI * w, z = sqrtf(fmaxf(0.0f, 1.0f - u));
    float t[3], b[3];
    ref_basis(n, t, b);
    float x = r * cosf(phi), y = r * sinf(phi);
    for (int k = 0; k < 3; k++) d[k] = x * t[k] + y * b[k] + z * n[k];
    ref_normalize(d);
    *cos_out = z;
}
static inline void ref_sphere_dir(lc_rng *rng, float d[3]) {
    float z = 1.0f - 2.0f * lc_rng_float(rng), phi = 2.0f * (float)M_PI * lc_rng_float(rng);
    float r = sqrtf(fmaxf(0.0f, 1.0f - z * z));
    d[0] = r * cosf(phi), d[1] = r * sinf(phi), d[2] = z;
}

/* --- Embree queries ------------------------------------------------------------------------- */

typedef struct {
    float t, u, v;
    uint32_t geom, prim;
} ref_hit;

static int ref_intersect(const lc_ref *r, const float org[3], const float dir[3], ref_hit *h) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rh.ray.org_x = org[0], rh.ray.org_y = org[1], rh.ray.org_z = org[2];
    rh.ray.dir_x = dir[0], rh.ray.dir_y = dir[1], rh.ray.dir_z = dir[2];
    rh.ray.tnear = 0, rh.ray.tfar = INFINITY, rh.ray.time = 0, rh.ray.mask = ~0u, rh.ray.id = 0, rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(r->scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return 0;
    h->t = rh.ray.tfar, h->u = rh.hit.u, h->v = rh.hit.v, h->geom = rh.hit.geomID, h->prim = rh.hit.primID;
    return 1;
}

/* Static triangle corners. */
static inline void ref_tri(const lc_ref *r, uint32_t t, const float **a, const float **b, const float **c) {
    const lc_lcb_triangle *tr = &r->v->triangles[t];
    *a = r->v->vertices[tr->v[0]].position;
    *b = r->v->vertices[tr->v[1]].position;
    *c = r->v->vertices[tr->v[2]].position;
}

/* Winding-defined unit normal (CCW front faces) and area of a triangle. */
static inline float ref_tri_normal(const float *a, const float *b, const float *c, float n[3]) {
    float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    ref_cross(e1, e2, n);
    float l = ref_len(n);
    if (l > 0) n[0] /= l, n[1] /= l, n[2] /= l;
    return 0.5f * l;
}

/* --- textured albedo: nearest surfel of the material ------------------------------------------ */

static inline uint64_t ref_cell_key(int32_t x, int32_t y, int32_t z) {
    return ((uint64_t)(uint32_t)(x + (1 << 20)) & 0x1FFFFF) << 42 |
        ((uint64_t)(uint32_t)(y + (1 << 20)) & 0x1FFFFF) << 21 | ((uint64_t)(uint32_t)(z + (1 << 20)) & 0x1FFFFF);
}

static int ref_sk_cmp(const void *a, const void *b) {
    const uint64_t *x = a, *y = b;
    return x[0] < y[0] ? -1 : x[0] > y[0] ? 1 : (x[1] < y[1] ? -1 : x[1] > y[1]);
}

static inline uint32_t ref_cell_slot(const lc_ref *r, uint64_t key) { return (uint32_t)(lc_mix64(key) & r->cell_mask); }

/* The surfels of a cell: [*first, *first + count) in sk_item. Returns count (0 = empty cell). */
static inline uint32_t ref_cell_find(const lc_ref *r, uint64_t key, uint32_t *first) {
    for (uint32_t slot = ref_cell_slot(r, key);; slot = (slot + 1) & r->cell_mask) {
        if (r->cell_key[slot] == 0) return 0;
        if (r->cell_key[slot] == key + 1) {
            *first = r->cell_start[slot];
            return r->cell_count[slot];
        }
    }
}

static int ref_surfels_index(lc_ref *r) {
    const lc_lcb_view *v = r->v;
    uint32_t n = v->n_surfels;
    if (n == 0) return 0;
    float lo[3] = {INFINITY, INFINITY, INFINITY};
    for (uint32_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) lo[k] = fminf(lo[k], v->surfels[i].position[k]);
    float cell = 2.0f * sqrtf(fmaxf(r->surfel_area, 1e-12f));
    r->cell_inv = 1.0f / cell;
    memcpy(r->cell_origin, lo, sizeof lo);
    uint64_t *pairs = malloc((size_t)n * 2 * sizeof *pairs);
    r->sk_key = malloc((size_t)n * sizeof *r->sk_key);
    r->sk_item = malloc((size_t)n * sizeof *r->sk_item);
    if (!pairs || !r->sk_key || !r->sk_item) {
        free(pairs);
        return -1;
    }
    for (uint32_t i = 0; i < n; i++) {
        const float *p = v->surfels[i].position;
        pairs[2 * i] =
            ref_cell_key((int32_t)floorf((p[0] - lo[0]) * r->cell_inv), (int32_t)floorf((p[1] - lo[1]) * r->cell_inv),
                         (int32_t)floorf((p[2] - lo[2]) * r->cell_inv));
        pairs[2 * i + 1] = i;
    }
    qsort(pairs, n, 2 * sizeof *pairs, ref_sk_cmp);
    for (uint32_t i = 0; i < n; i++) {
        r->sk_key[i] = pairs[2 * i];
        r->sk_item[i] = (uint32_t)pairs[2 * i + 1];
    }
    free(pairs);
    uint32_t size = 16;
    while (size < 2 * n) size *= 2;
    r->cell_mask = size - 1;
    r->cell_key = calloc(size, sizeof *r->cell_key);
    r->cell_start = calloc(size, sizeof *r->cell_start);
    r->cell_count = calloc(size, sizeof *r->cell_count);
    if (!r->cell_key || !r->cell_start || !r->cell_count) return -1;
    for (uint32_t i = 0; i < n;) {
        uint32_t j = i;
        while (j < n && r->sk_key[j] == r->sk_key[i]) j++;
        uint32_t slot = ref_cell_slot(r, r->sk_key[i]);
        while (r->cell_key[slot]) slot = (slot + 1) & r->cell_mask;
        r->cell_key[slot] = r->sk_key[i] + 1;
        r->cell_start[slot] = i;
        r->cell_count[slot] = j - i;
        i = j;
    }
    return 0;
}

/* Albedo of the nearest surfel of `material` facing like n (within 60 degrees) near p:
 * 3x3x3 cells, then 5x5x5; the material's mean surfel albedo when none is found. */
static void ref_surfel_albedo(const lc_ref *r, uint32_t material, const float p[3], const float n[3], float out[3]) {
    const lc_lcb_view *v = r->v;
    int32_t c[3];
    for (int k = 0; k < 3; k++) c[k] = (int32_t)floorf((p[k] - r->cell_origin[k]) * r->cell_inv);
    for (int rad = 1; rad <= 2; rad++) {
        uint32_t best = LC_NONE;
        float best_d2 = INFINITY;
        for (int dz = -rad; dz <= rad; dz++)
            for (int dy = -rad; dy <= rad; dy++)
                for (int dx = -rad; dx <= rad; dx++) {
                    if (rad == 2 && abs(dx) <= 1 && abs(dy) <= 1 && abs(dz) <= 1) continue;
                    uint64_t key = ref_cell_key(c[0] + dx, c[1] + dy, c[2] + dz);
                    uint32_t first = 0, count = ref_cell_find(r, key, &first);
                    for (uint32_t i = first; i < first + count; i++) {
                        const lc_lcb_surfel *s = &v->surfels[r->sk_item[i]];
                        if (s->material != material || ref_dot(s->normal, n) < 0.5f) continue;
                        float d[3] = {s->position[0] - p[0], s->position[1] - p[1], s->position[2] - p[2]};
                        float d2 = ref_dot(d, d);
                        if (d2 < best_d2 || (d2 == best_d2 && r->sk_item[i] < best)) {
                            best_d2 = d2;
                            best = r->sk_item[i];
                        }
                    }
                }
        if (best != LC_NONE) {
            memcpy(out, v->surfels[best].albedo, 3 * sizeof(float));
            return;
        }
    }
    memcpy(out, r->albedo + 3 * (size_t)material, 3 * sizeof(float));
}

/* Small textured triangles (area below 4 surfels') hold one albedo: the surfel nearest their
 * centroid. Hits on them would all search the same, often distant, surfels. */
static void ref_tri_albedo_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    lc_ref *r = ctx;
    const lc_lcb_view *v = r->v;
    float limit = 4.0f * r->surfel_area;
    for (size_t t = begin; t < end; t++) {
        float *out = r->tri_albedo + 3 * t;
        out[0] = out[1] = out[2] = NAN;
        const lc_lcb_triangle *tr = &v->triangles[t];
        if (!r->textured[tr->material]) continue;
        const float *a = v->vertices[tr->v[0]].position, *b = v->vertices[tr->v[1]].position,
                    *c = v->vertices[tr->v[2]].position;
        float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]}, n[3];
        ref_cross(e1, e2, n);
        float area = 0.5f * ref_len(n);
        if (!(area < limit)) continue;
        ref_normalize(n);
        float p[3] = {(a[0] + b[0] + c[0]) / 3, (a[1] + b[1] + c[1]) / 3, (a[2] + b[2] + c[2]) / 3};
        ref_surfel_albedo(r, tr->material, p, n, out);
    }
}

/* --- surface interaction ---------------------------------------------------------------------- */

typedef struct {
    float p[3], ng[3], ns[3]; /* position, winding normal, shading normal (front side) */
    float albedo[3];
    const float *emission; /* NULL: none */
    float emit_pdf;        /* NEE pick probability / area of this triangle (0: not sampled) */
    int backface;
} ref_surface;

static void ref_surface_at(const lc_ref *r, const ref_hit *h, const float dir[3], ref_surface *s) {
    float b1 = h->u, b2 = h->v, b0 = 1.0f - b1 - b2;
    s->emission = NULL;
    s->emit_pdf = 0;
    if (h->geom == REF_GEOM_STATIC) {
        const lc_lcb_triangle *tr = &r->v->triangles[h->prim];
        const lc_lcb_vertex *va = &r->v->vertices[tr->v[0]], *vb = &r->v->vertices[tr->v[1]],
                            *vc = &r->v->vertices[tr->v[2]];
        ref_tri_normal(va->position, vb->position, vc->position, s->ng);
        for (int k = 0; k < 3; k++) {
            s->p[k] = b0 * va->position[k] + b1 * vb->position[k] + b2 * vc->position[k];
            s->ns[k] = b0 * va->normal[k] + b1 * vb->normal[k] + b2 * vc->normal[k];
        }
        ref_normalize(s->ns);
        /* As the bake's surfels: shading normals that disagree with the winding fall back to it. */
        if (ref_dot(s->ns, s->ns) < 0.5f || ref_dot(s->ns, s->ng) <= 0) memcpy(s->ns, s->ng, sizeof s->ns);
        uint32_t m = tr->material;
        if (r->textured[m] && !isnan(r->tri_albedo[3 * (size_t)h->prim]))
            memcpy(s->albedo, r->tri_albedo + 3 * (size_t)h->prim, sizeof s->albedo);
        else if (r->textured[m]) ref_surfel_albedo(r, m, s->p, s->ns, s->albedo);
        else memcpy(s->albedo, r->albedo + 3 * (size_t)m, sizeof s->albedo);
        const float *em = r->emission + 3 * (size_t)m;
        if (em[0] > 0 || em[1] > 0 || em[2] > 0) {
            s->emission = em;
            s->emit_pdf = r->emit_pdf[h->prim];
        }
    } else {
        const uint32_t *ix = r->obj_idx + 3 * (size_t)h->prim;
        const float *a = r->obj_pos + 4 * (size_t)ix[0], *b = r->obj_pos + 4 * (size_t)ix[1],
                    *c = r->obj_pos + 4 * (size_t)ix[2];
        ref_tri_normal(a, b, c, s->ng);
        memcpy(s->ns, s->ng, sizeof s->ns);
        for (int k = 0; k < 3; k++) {
            s->p[k] = b0 * a[k] + b1 * b[k] + b2 * c[k];
            s->albedo[k] = b0 * r->obj_alb[3 * (size_t)ix[0] + k] + b1 * r->obj_alb[3 * (size_t)ix[1] + k] +
                b2 * r->obj_alb[3 * (size_t)ix[2] + k];
            s->albedo[k] = fminf(fmaxf(s->albedo[k], 0.0f), 0.99f);
        }
    }
    s->backface = ref_dot(dir, s->ng) > 0;
}

/* --- lights ------------------------------------------------------------------------------------ */

/* Irradiance at org (already lifted off the surface) with normal n from the analytic lights,
 * shadowed (one sample per area light). Directions below the geometric plane ng do not count. */
static void ref_direct(const lc_ref *r, const float org[3], const float n[3], const float ng[3], lc_rng *rng,
                       float out[3], uint64_t *rays) {
    out[0] = out[1] = out[2] = 0;
    for (uint32_t li = 0; li < r->n_lights; li++) {
        const lc_engine_light *l = &r->lights[li];
        float scale = l->intensity;
        if (l->type == LC_ENGINE_LIGHT_DIRECTIONAL) {
            float dl = ref_len(l->direction);
            float w[3] = {-l->direction[0] / dl, -l->direction[1] / dl, -l->direction[2] / dl};
            float cosn = ref_dot(n, w);
            if (cosn <= 0 || ref_dot(ng, w) <= 0) continue;
            (*rays)++;
            if (lc_embree_occluded(r->scene, org, w, INFINITY)) continue;
            for (int k = 0; k < 3; k++) out[k] += scale * l->color[k] * cosn;
        } else if (l->type == LC_ENGINE_LIGHT_AREA) {
            lc_sm_area_frame fr = lc_sm_area_frame_of(l);
            const float *ln = fr.n;
            float u = lc_rng_float(rng), w = lc_rng_float(rng);
            float p[3], d[3];
            lc_sm_area_point(l, &fr, u, w, p);
            for (int k = 0; k < 3; k++) d[k] = p[k] - org[k];
            float d2 = ref_dot(d, d);
            if (!(d2 > 1e-12f)) continue;
            float dist = sqrtf(d2);
            for (int k = 0; k < 3; k++) d[k] /= dist;
            float cos_s = ref_dot(n, d), cos_l = -ref_dot(ln, d);
            if (cos_s <= 0 || cos_l <= 0 || ref_dot(ng, d) <= 0) continue;
            (*rays)++;
            if (lc_embree_occluded(r->scene, org, d, lc_ray_shadow_tfar(dist, r->eps))) continue;
            float g = scale * fr.area * cos_s * cos_l / d2 * lc_sm_range_window(d2, l->range);
            for (int k = 0; k < 3; k++) out[k] += g * l->color[k];
        } else { /* point, spot */
            float d[3] = {l->position[0] - org[0], l->position[1] - org[1], l->position[2] - org[2]};
            float d2 = ref_dot(d, d);
            if (!(d2 > 1e-12f)) continue;
            float dist = sqrtf(d2);
            for (int k = 0; k < 3; k++) d[k] /= dist;
            float cosn = ref_dot(n, d);
            if (cosn <= 0 || ref_dot(ng, d) <= 0) continue;
            float att = lc_sm_range_window(d2, l->range) / d2;
            if (l->type == LC_ENGINE_LIGHT_SPOT) att *= lc_sm_spot_cone(l, d);
            if (att <= 0) continue;
            (*rays)++;
            if (lc_embree_occluded(r->scene, org, d, lc_ray_shadow_tfar(dist, r->eps))) continue;
            for (int k = 0; k < 3; k++) out[k] += scale * l->color[k] * cosn * att;
        }
    }
}

/* One light sample toward the emissive triangles. Returns 1 with the unit direction d, the
 * emitted radiance, and the solid-angle pdf when the sample reaches x unoccluded from its
 * front side; n is the hemisphere (NULL: the full sphere), ng the geometric plane (NULL: none). */
static int ref_emit_sample(const lc_ref *r, const float org[3], const float *n, const float *ng, lc_rng *rng,
                           float d[3], const float **le, float *pdf, float *dist_out, uint64_t *rays) {
    if (r->n_emit == 0) return 0;
    double u = lc_rng_float(rng) * r->emit_cdf[r->n_emit];
    uint32_t lo = 0, hi = r->n_emit - 1;
    while (lo < hi) { /* first j with cdf[j + 1] > u */
        uint32_t mid = (lo + hi) / 2;
        if (r->emit_cdf[mid + 1] > u) hi = mid;
        else lo = mid + 1;
    }
    uint32_t t = r->emit_tri[lo];
    const float *a, *b, *c;
    ref_tri(r, t, &a, &b, &c);
    float su = sqrtf(lc_rng_float(rng)), w = lc_rng_float(rng);
    float b1 = su * (1.0f - w), b2 = su * w, b0 = 1.0f - b1 - b2;
    float p[3], ln[3];
    for (int k = 0; k < 3; k++) p[k] = b0 * a[k] + b1 * b[k] + b2 * c[k];
    ref_tri_normal(a, b, c, ln);
    for (int k = 0; k < 3; k++) d[k] = p[k] - org[k];
    float d2 = ref_dot(d, d);
    if (!(d2 > 1e-12f)) return 0;
    float dist = sqrtf(d2);
    for (int k = 0; k < 3; k++) d[k] /= dist;
    float cos_l = -ref_dot(ln, d);
    if (cos_l <= 1e-6f) return 0;
    if (n && ref_dot(n, d) <= 0) return 0;
    if (ng && ref_dot(ng, d) <= 0) return 0;
    (*rays)++;
    if (lc_embree_occluded(r->scene, org, d, lc_ray_shadow_tfar(dist, r->eps))) return 0;
    *le = r->emission + 3 * (size_t)r->v->triangles[t].material;
    *pdf = r->emit_pdf[t] * d2 / cos_l;
    if (dist_out) *dist_out = dist;
    return 1;
}

static inline void ref_sky(const lc_ref *r, const float d[3], float out[3]) {
    float y[9];
    lc_sh_eval_fast(3, d[0], d[1], d[2], y);
    for (int k = 0; k < 3; k++) {
        float s = 0;
        for (int j = 0; j < 9; j++) s += r->sky[j][k] * y[j];
        out[k] = s;
    }
}

/* --- the path ---------------------------------------------------------------------------------- */

typedef struct {
    uint32_t max_bounces, rr_depth;
} ref_path_cfg;

/* Radiance arriving at org along dir (the ray was sampled with solid-angle pdf `pdf_dir` by a
 * vertex that also did light sampling, for the MIS weight of emitters hit). The ray leaves a
 * cache (depth -1: an escape sees nothing) or a surface. */
static void ref_trace(const lc_ref *r, const ref_path_cfg *cfg, const float org_in[3], const float dir_in[3],
                      float pdf_dir, lc_rng *rng, float L[3], uint64_t *rays) {
    float org[3] = {org_in[0], org_in[1], org_in[2]}, dir[3] = {dir_in[0], dir_in[1], dir_in[2]};
    float T[3] = {1, 1, 1};
    float pdf_prev = pdf_dir;
    L[0] = L[1] = L[2] = 0;
    for (uint32_t depth = 0;; depth++) { /* depth = index of the surface about to be hit */
        ref_hit h;
        (*rays)++;
        if (!ref_intersect(r, org, dir, &h)) {
            if (depth > 0 && r->sky_on) {
                float s[3];
                ref_sky(r, dir, s);
                for (int k = 0; k < 3; k++) L[k] += T[k] * s[k];
            }
            return;
        }
        ref_surface s;
        ref_surface_at(r, &h, dir, &s);
        if (s.backface) return; /* one-sided surfaces: the back is black */
        if (s.emission) {
            float w = 1.0f;
            if (s.emit_pdf > 0) {
                float cos_l = -ref_dot(s.ng, dir);
                float pl = cos_l > 1e-6f ? s.emit_pdf * h.t * h.t / cos_l : INFINITY;
                w = pdf_prev / (pdf_prev + pl);
            }
            for (int k = 0; k < 3; k++) L[k] += T[k] * s.emission[k] * w;
        }
        /* Bounce limit N counted as the engine counts passes: emission reaches the cache after
         * at most N reflections, light from the lights and the sky (part of B0) after N + 1. */
        float rho_max = fmaxf(s.albedo[0], fmaxf(s.albedo[1], s.albedo[2]));
        if (!(rho_max > 0)) return;
        float x[3];
        for (int k = 0; k < 3; k++) x[k] = s.p[k] + s.ng[k] * r->eps;
        int further = depth + 1 <= cfg->max_bounces;
        /* Next events: analytic lights and emitters, reflected with albedo / pi. */
        float e[3];
        ref_direct(r, x, s.ns, s.ng, rng, e, rays);
        float ld[3];
        const float *le;
        float pl;
        if (further && ref_emit_sample(r, x, s.ns, s.ng, rng, ld, &le, &pl, NULL, rays)) {
            float cs = ref_dot(s.ns, ld), pb = cs / (float)M_PI;
            float g = cs / (pl + pb); /* cos * (pl / (pl + pb)) / pl */
            for (int k = 0; k < 3; k++) e[k] += le[k] * g;
        }
        for (int k = 0; k < 3; k++) L[k] += T[k] * s.albedo[k] / (float)M_PI * e[k];
        if (!further && !r->sky_on) return;
        /* Continue: cosine sampling about the shading normal; below the geometric plane = 0. */
        float cs;
        ref_cosine_dir(s.ns, rng, dir, &cs);
        if (ref_dot(dir, s.ng) <= 0 || !(cs > 0)) return;
        for (int k = 0; k < 3; k++) T[k] *= s.albedo[k];
        if (!further) { /* the last pass: only the sky this surface sees */
            (*rays)++;
            if (lc_embree_occluded(r->scene, x, dir, INFINITY)) return;
            float sky[3];
            ref_sky(r, dir, sky);
            for (int k = 0; k < 3; k++) L[k] += T[k] * sky[k];
            return;
        }
        if (depth + 1 >= cfg->rr_depth) {
            float q = fminf(0.95f, rho_max);
            if (lc_rng_float(rng) >= q) return;
            for (int k = 0; k < 3; k++) T[k] /= q;
        }
        pdf_prev = cs / (float)M_PI;
        memcpy(org, x, sizeof org);
    }
}

/* One sample of the irradiance at lifted origin org (unit normal n): a light sample toward the
 * emitters and a cosine-sampled path, combined by MIS. block (may be NULL) blocks the first
 * segment of both: a blocked light sample or first ray gives nothing. */
static void ref_sample_blocked(const lc_ref *r, const ref_path_cfg *cfg, const float org[3], const float n[3],
                               lc_ref_block_fn block, void *block_ctx, lc_rng *rng, float E[3], uint64_t *rays) {
    E[0] = E[1] = E[2] = 0;
    float d[3], dist = INFINITY;
    const float *le;
    float pl;
    if (ref_emit_sample(r, org, n, NULL, rng, d, &le, &pl, &dist, rays) && !(block && block(block_ctx, org, d, dist))) {
        float c = ref_dot(n, d), pb = c / (float)M_PI;
        float g = c / (pl + pb);
        for (int k = 0; k < 3; k++) E[k] += le[k] * g;
    }
    float cs, L[3];
    ref_cosine_dir(n, rng, d, &cs);
    if (!(cs > 0)) return;
    if (block) {
        ref_hit h;
        (*rays)++;
        if (block(block_ctx, org, d, ref_intersect(r, org, d, &h) ? h.t : INFINITY)) return;
    }
    ref_trace(r, cfg, org, d, cs / (float)M_PI, rng, L, rays);
    for (int k = 0; k < 3; k++) E[k] += (float)M_PI * L[k];
}

/* One sample of the irradiance at a texel cache (lifted origin org, unit normal n). */
static void ref_sample_texel(const lc_ref *r, const ref_path_cfg *cfg, const float org[3], const float n[3],
                             lc_rng *rng, float E[3], uint64_t *rays) {
    ref_sample_blocked(r, cfg, org, n, NULL, NULL, rng, E, rays);
}

void lc_ref_irradiance_sample(const lc_ref *r, const float org[3], const float n[3], uint32_t max_bounces,
                              uint32_t rr_depth, lc_ref_block_fn block, void *block_ctx, lc_rng *rng, float E[3],
                              uint64_t *rays) {
    ref_path_cfg cfg = {max_bounces, rr_depth};
    ref_sample_blocked(r, &cfg, org, n, block, block_ctx, rng, E, rays);
}

/* One sample of the incident radiance SH (9 x RGB) at a grid point. */
static void ref_sample_grid(const lc_ref *r, const ref_path_cfg *cfg, const float org[3], lc_rng *rng, float sh[27],
                            uint64_t *rays) {
    memset(sh, 0, 27 * sizeof(float));
    const float pb = (float)(1.0 / (4.0 * M_PI));
    float d[3], y[9];
    const float *le;
    float pl;
    if (ref_emit_sample(r, org, NULL, NULL, rng, d, &le, &pl, NULL, rays)) {
        float g = 1.0f / (pl + pb);
        lc_sh_eval_fast(3, d[0], d[1], d[2], y);
        for (int j = 0; j < 9; j++)
            for (int k = 0; k < 3; k++) sh[3 * j + k] += le[k] * g * y[j];
    }
    float L[3];
    ref_sphere_dir(rng, d);
    ref_trace(r, cfg, org, d, pb, rng, L, rays);
    lc_sh_eval_fast(3, d[0], d[1], d[2], y);
    for (int j = 0; j < 9; j++)
        for (int k = 0; k < 3; k++) sh[3 * j + k] += (float)(4.0 * M_PI) * y[j] * L[k];
}

/* The camera's path: full illumination along a ray from the eye. Unlike ref_trace (the engine's
 * indirect quantity) the environment is seen by every escaping ray, the first included, an
 * emitter seen directly counts in full, and every path is cut at max_depth reflections for
 * every kind of light alike (emitters, lights, sky). */
void lc_ref_radiance(const lc_ref *r, const float org_in[3], const float dir_in[3], uint32_t max_depth,
                     uint32_t rr_depth, lc_rng *rng, float L[3], uint64_t *rays) {
    lc_ref_radiance_ex(r, org_in, dir_in, max_depth, rr_depth, 1, rng, L, rays);
}

void lc_ref_radiance_ex(const lc_ref *r, const float org_in[3], const float dir_in[3], uint32_t max_depth,
                        uint32_t rr_depth, int sky_first, lc_rng *rng, float L[3], uint64_t *rays) {
    float org[3] = {org_in[0], org_in[1], org_in[2]}, dir[3] = {dir_in[0], dir_in[1], dir_in[2]};
    float T[3] = {1, 1, 1};
    float pdf_prev = 0; /* 0: the eye's ray, which light sampling cannot produce */
    L[0] = L[1] = L[2] = 0;
    for (uint32_t depth = 0;; depth++) { /* depth = reflections before the surface about to be hit */
        ref_hit h;
        (*rays)++;
        if (!ref_intersect(r, org, dir, &h)) {
            if (r->sky_on && (depth > 0 || sky_first)) {
                float s[3];
                ref_sky(r, dir, s);
                for (int k = 0; k < 3; k++) L[k] += T[k] * s[k];
            }
            return;
        }
        ref_surface s;
        ref_surface_at(r, &h, dir, &s);
        if (s.backface) return; /* one-sided surfaces, as the reference's: the back is black */
        if (s.emission) {
            float w = 1.0f;
            if (s.emit_pdf > 0 && pdf_prev > 0) {
                float cos_l = -ref_dot(s.ng, dir);
                float pl = cos_l > 1e-6f ? s.emit_pdf * h.t * h.t / cos_l : INFINITY;
                w = pdf_prev / (pdf_prev + pl);
            }
            for (int k = 0; k < 3; k++) L[k] += T[k] * s.emission[k] * w;
        }
        float rho_max = fmaxf(s.albedo[0], fmaxf(s.albedo[1], s.albedo[2]));
        if (depth >= max_depth || !(rho_max > 0)) return;
        float x[3];
        for (int k = 0; k < 3; k++) x[k] = s.p[k] + s.ng[k] * r->eps;
        /* Next events: the analytic lights and one emitter sample (MIS), reflected with albedo / pi. */
        float e[3], ld[3], pl;
        const float *le;
        ref_direct(r, x, s.ns, s.ng, rng, e, rays);
        if (ref_emit_sample(r, x, s.ns, s.ng, rng, ld, &le, &pl, NULL, rays)) {
            float cs = ref_dot(s.ns, ld), pb = cs / (float)M_PI;
            float g = cs / (pl + pb);
            for (int k = 0; k < 3; k++) e[k] += le[k] * g;
        }
        for (int k = 0; k < 3; k++) L[k] += T[k] * s.albedo[k] / (float)M_PI * e[k];
        /* Continue: cosine sampling about the shading normal; below the geometric plane = 0. */
        float cs;
        ref_cosine_dir(s.ns, rng, dir, &cs);
        if (ref_dot(dir, s.ng) <= 0 || !(cs > 0)) return;
        for (int k = 0; k < 3; k++) T[k] *= s.albedo[k];
        if (depth + 1 >= rr_depth) {
            float q = fminf(0.95f, rho_max);
            if (lc_rng_float(rng) >= q) return;
            for (int k = 0; k < 3; k++) T[k] /= q;
        }
        pdf_prev = cs / (float)M_PI;
        memcpy(org, x, sizeof org);
    }
}

int lc_ref_first_hit(const lc_ref *r, const float org[3], const float dir[3], float *t, float ng[3]) {
    ref_hit h;
    if (!ref_intersect(r, org, dir, &h)) return 0;
    *t = h.t;
    if (h.geom == REF_GEOM_STATIC) {
        const float *a, *b, *c;
        ref_tri(r, h.prim, &a, &b, &c);
        ref_tri_normal(a, b, c, ng);
    } else {
        const uint32_t *ix = r->obj_idx + 3 * (size_t)h.prim;
        ref_tri_normal(r->obj_pos + 4 * (size_t)ix[0], r->obj_pos + 4 * (size_t)ix[1], r->obj_pos + 4 * (size_t)ix[2],
                       ng);
    }
    return 1;
}

float lc_ref_eps(const lc_ref *r) { return r->eps; }

void lc_ref_irradiance(lc_ref *r, const float p[3], const float n[3], uint32_t spp, uint64_t seed, double mean[3],
                       double stderr_out[3]) {
    ref_path_cfg cfg = {32, 3};
    float nn[3] = {n[0], n[1], n[2]};
    ref_normalize(nn);
    float org[3];
    for (int k = 0; k < 3; k++) org[k] = p[k] + nn[k] * r->eps;
    double s[3] = {0}, q[3] = {0};
    uint64_t rays = 0;
    lc_rng rng = lc_rng_seed(seed, 0x1AB5);
    for (uint32_t i = 0; i < spp; i++) {
        float e[3];
        ref_sample_texel(r, &cfg, org, nn, &rng, e, &rays);
        for (int k = 0; k < 3; k++) s[k] += e[k], q[k] += (double)e[k] * e[k];
    }
    for (int k = 0; k < 3; k++) {
        mean[k] = spp ? s[k] / spp : 0;
        double var = spp > 1 ? (q[k] - spp * mean[k] * mean[k]) / (spp - 1) : 0;
        stderr_out[k] = spp ? sqrt(fmax(var, 0) / spp) : 0;
    }
}

void lc_ref_b0_power(lc_ref *r, uint32_t samples, uint64_t seed, double power[3], double stderr_out[3]) {
    const lc_lcb_view *v = r->v;
    double *cdf = malloc(((size_t)v->n_triangles + 1) * sizeof *cdf);
    for (int k = 0; k < 3; k++) {
        power[k] = 0;
        if (stderr_out) stderr_out[k] = 0;
    }
    if (!cdf || v->n_triangles == 0 || samples == 0) {
        free(cdf);
        return;
    }
    cdf[0] = 0;
    for (uint32_t t = 0; t < v->n_triangles; t++) {
        const float *a, *b, *c;
        float n[3];
        ref_tri(r, t, &a, &b, &c);
        cdf[t + 1] = cdf[t] + ref_tri_normal(a, b, c, n);
    }
    double total = cdf[v->n_triangles], s[3] = {0}, q[3] = {0};
    lc_rng rng = lc_rng_seed(seed, 0xB0B0);
    uint64_t rays = 0;
    for (uint32_t i = 0; i < samples; i++) {
        double u = ((double)i + lc_rng_float(&rng)) / samples * total; /* stratified by area */
        uint32_t lo = 0, hi = v->n_triangles - 1;
        while (lo < hi) {
            uint32_t mid = (lo + hi) / 2;
            if (cdf[mid + 1] > u) hi = mid;
            else lo = mid + 1;
        }
        const lc_lcb_triangle *tr = &v->triangles[lo];
        float su = sqrtf(lc_rng_float(&rng)), w = lc_rng_float(&rng);
        ref_hit h = {.t = 1, .u = su * (1.0f - w), .v = su * w, .geom = REF_GEOM_STATIC, .prim = lo};
        const float *a, *b, *c;
        float ng[3], dir[3];
        ref_tri(r, lo, &a, &b, &c);
        ref_tri_normal(a, b, c, ng);
        for (int k = 0; k < 3; k++) dir[k] = -ng[k];
        ref_surface sf;
        ref_surface_at(r, &h, dir, &sf);
        float x[3], e[3];
        for (int k = 0; k < 3; k++) x[k] = sf.p[k] + sf.ng[k] * r->eps;
        ref_direct(r, x, sf.ns, sf.ng, &rng, e, &rays);
        if (r->sky_on) { /* one cosine sample of the sky this point sees */
            float d[3], cs, sky[3];
            ref_cosine_dir(sf.ns, &rng, d, &cs);
            if (ref_dot(d, sf.ng) > 0 && !lc_embree_occluded(r->scene, x, d, INFINITY)) {
                ref_sky(r, d, sky);
                for (int k = 0; k < 3; k++) e[k] += (float)M_PI * sky[k];
            }
        }
        const float *em = r->emission + 3 * (size_t)tr->material;
        for (int k = 0; k < 3; k++) {
            double b0 = M_PI * em[k] + sf.albedo[k] * e[k];
            s[k] += b0;
            q[k] += b0 * b0;
        }
    }
    for (int k = 0; k < 3; k++) {
        double m = s[k] / samples, var = samples > 1 ? (q[k] - samples * m * m) / (samples - 1) : 0;
        power[k] = m * total;
        if (stderr_out) stderr_out[k] = sqrt(fmax(var, 0) / samples) * total; /* iid bound (stratified: lower) */
    }
    free(cdf);
}

/* --- create / release ------------------------------------------------------------------------- */

void lc_ref_release(lc_ref *r) {
    if (!r) return;
    if (r->scene) rtcReleaseScene(r->scene);
    if (r->device) rtcReleaseDevice(r->device);
    free(r->lights);
    free(r->emission);
    free(r->albedo);
    free(r->textured);
    free(r->obj_pos);
    free(r->obj_alb);
    free(r->obj_idx);
    free(r->emit_tri);
    free(r->emit_cdf);
    free(r->emit_pdf);
    free(r->sk_key);
    free(r->sk_item);
    free(r->cell_key);
    free(r->cell_start);
    free(r->cell_count);
    free(r->tri_albedo);
    free(r);
}

int lc_ref_threads(const lc_ref *r) { return r->threads; }

static int ref_build_objects(lc_ref *r, const lc_engine_state *st) {
    const lc_lcb_view *v = r->v;
    uint64_t nv = 0, nt = 0;
    for (uint32_t i = 0; i < st->n_objects; i++) {
        if (!st->objects[i].visible) continue;
        nv += v->assets[st->objects[i].asset].vertex_count;
        nt += v->assets[st->objects[i].asset].triangle_count;
    }
    if (nt == 0) return 0;
    if (nv > UINT32_MAX / 4 || nt > UINT32_MAX / 3) return -1;
    r->obj_pos = malloc((size_t)(nv + 1) * 4 * sizeof(float));
    r->obj_alb = malloc((size_t)nv * 3 * sizeof(float));
    r->obj_idx = malloc((size_t)nt * 3 * sizeof(uint32_t));
    if (!r->obj_pos || !r->obj_alb || !r->obj_idx) return -1;
    uint32_t bv = 0, bt = 0;
    for (uint32_t i = 0; i < st->n_objects; i++) {
        const lc_engine_object *o = &st->objects[i];
        if (!o->visible) continue;
        const lc_lcb_asset *a = &v->assets[o->asset];
        float m[12];
        lc_sm_object_matrix(o, m);
        float det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[3] * (m[1] * m[8] - m[2] * m[7]) +
            m[6] * (m[1] * m[5] - m[2] * m[4]);
        for (uint32_t k = 0; k < a->vertex_count; k++) {
            const lc_lcb_asset_vertex *av = &v->asset_vertices[a->first_vertex + k];
            float *p = r->obj_pos + 4 * (size_t)(bv + k);
            lc_sm_transform_point(m, av->position, p);
            p[3] = 0;
            memcpy(r->obj_alb + 3 * (size_t)(bv + k), av->albedo, 3 * sizeof(float));
        }
        for (uint32_t k = 0; k < a->triangle_count; k++) {
            const uint32_t *src = v->asset_indices + 3 * ((size_t)a->first_triangle + k);
            uint32_t *dst = r->obj_idx + 3 * (size_t)(bt + k);
            dst[0] = bv + src[0];
            dst[1] = bv + (det < 0 ? src[2] : src[1]); /* a mirroring transform keeps fronts outside */
            dst[2] = bv + (det < 0 ? src[1] : src[2]);
        }
        bv += a->vertex_count;
        bt += a->triangle_count;
    }
    r->n_obj_vertices = bv;
    r->n_obj_tris = bt;
    return 0;
}

static int ref_build_emitters(lc_ref *r) {
    const lc_lcb_view *v = r->v;
    r->emit_pdf = calloc(v->n_triangles ? v->n_triangles : 1, sizeof *r->emit_pdf);
    r->emit_tri = malloc((v->n_triangles ? v->n_triangles : 1) * sizeof *r->emit_tri);
    r->emit_cdf = malloc(((size_t)v->n_triangles + 1) * sizeof *r->emit_cdf);
    if (!r->emit_pdf || !r->emit_tri || !r->emit_cdf) return -1;
    r->emit_cdf[0] = 0;
    for (uint32_t t = 0; t < v->n_triangles; t++) {
        const float *em = r->emission + 3 * (size_t)v->triangles[t].material;
        double power = (double)em[0] + em[1] + em[2];
        if (!(power > 0)) continue;
        const float *a, *b, *c;
        ref_tri(r, t, &a, &b, &c);
        float n[3];
        double area = ref_tri_normal(a, b, c, n);
        if (!(area > 0)) continue;
        r->emit_tri[r->n_emit] = t;
        r->emit_cdf[r->n_emit + 1] = r->emit_cdf[r->n_emit] + power * area;
        r->n_emit++;
    }
    double total = r->emit_cdf[r->n_emit];
    for (uint32_t j = 0; j < r->n_emit; j++) {
        uint32_t t = r->emit_tri[j];
        const float *a, *b, *c;
        ref_tri(r, t, &a, &b, &c);
        float n[3];
        double area = ref_tri_normal(a, b, c, n);
        r->emit_pdf[t] = (float)((r->emit_cdf[j + 1] - r->emit_cdf[j]) / total / area);
    }
    return 0;
}

lc_ref *lc_ref_create(const lc_lcb *bake, const lc_engine_state *st, int threads, char *err, size_t errlen) {
    lc_ref *r = calloc(1, sizeof *r);
    if (!r) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    r->bake = bake;
    r->v = lc_lcb_get(bake);
    const lc_lcb_view *v = r->v;
    r->threads = threads;
    r->eps = lc_embree_scene_epsilon(v);
    double area_sum = 0;
    for (uint32_t i = 0; i < v->n_surfels; i++) area_sum += v->surfels[i].area;
    r->surfel_area = v->n_surfels ? (float)(area_sum / v->n_surfels) : 0.0f;
    for (uint32_t i = 0; i < st->n_objects; i++)
        if (st->objects[i].asset >= v->n_assets) {
            lc_set_err(err, errlen, "/objects/%u/asset: index %u, the bake has %u assets", i, st->objects[i].asset,
                       v->n_assets);
            goto fail;
        }

    /* State: lights, sky, emission. */
    if (st->n_lights) {
        r->lights = malloc(st->n_lights * sizeof *r->lights);
        if (!r->lights) goto oom;
        memcpy(r->lights, st->lights, st->n_lights * sizeof *r->lights);
        r->n_lights = st->n_lights;
    }
    r->sky_on = st->environment.kind != LC_ENV_NONE && st->environment.intensity > 0;
    if (r->sky_on) {
        if (st->environment.kind == LC_ENV_CONSTANT)
            for (int k = 0; k < 3; k++) r->sky[0][k] = st->environment.color[k] * (float)sqrt(4.0 * M_PI);
        else memcpy(r->sky, st->environment.sh, sizeof r->sky);
        for (int j = 0; j < 9; j++)
            for (int k = 0; k < 3; k++) r->sky[j][k] *= st->environment.intensity;
    }
    size_t nm = v->n_materials ? v->n_materials : 1;
    r->emission = calloc(nm * 3, sizeof(float));
    r->albedo = calloc(nm * 3, sizeof(float));
    r->textured = calloc(nm, 1);
    double *asum = calloc(nm * 4, sizeof(double));
    if (!r->emission || !r->albedo || !r->textured || !asum) {
        free(asum);
        goto oom;
    }
    for (uint32_t s = 0; s < v->n_surfels; s++) {
        const lc_lcb_surfel *sf = &v->surfels[s];
        for (int k = 0; k < 3; k++) asum[4 * sf->material + k] += sf->albedo[k];
        asum[4 * sf->material + 3] += 1;
    }
    for (uint32_t m = 0; m < v->n_materials; m++) {
        const lc_lcb_material *mt = &v->materials[m];
        r->textured[m] = (mt->flags & 1u) != 0;
        for (int k = 0; k < 3; k++) {
            r->emission[3 * m + k] = st->material_emission ? st->material_emission[3 * m + k] : mt->emission[k];
            float a = fminf(fmaxf(mt->base_color[k], 0.0f), 0.99f);
            if (r->textured[m] && asum[4 * m + 3] > 0) a = (float)(asum[4 * m + k] / asum[4 * m + 3]);
            r->albedo[3 * m + k] = a;
        }
    }
    free(asum);
    if (ref_surfels_index(r) != 0 || ref_build_emitters(r) != 0) goto oom;
    r->tri_albedo = malloc(((size_t)v->n_triangles + 1) * 3 * sizeof(float));
    if (!r->tri_albedo) goto oom;
    lc_parallel_for(r->threads, v->n_triangles, 1024, ref_tri_albedo_range, r);
    if (ref_build_objects(r, st) != 0) goto oom;

    /* Embree: one scene, static mesh (geometry 0) and objects (geometry 1). */
    r->device = lc_embree_device_new(threads, "ref", err, errlen);
    if (!r->device) goto fail;
    r->scene = rtcNewScene(r->device);
    rtcSetSceneFlags(r->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(r->scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry g = rtcNewGeometry(r->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, v->vertices, 0, sizeof(lc_lcb_vertex),
                               v->n_vertices);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, v->triangles, 0, sizeof(lc_lcb_triangle),
                               v->n_triangles);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(r->scene, g, REF_GEOM_STATIC);
    rtcReleaseGeometry(g);
    if (r->n_obj_tris) {
        g = rtcNewGeometry(r->device, RTC_GEOMETRY_TYPE_TRIANGLE);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, r->obj_pos, 0, 4 * sizeof(float),
                                   r->n_obj_vertices);
        rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, r->obj_idx, 0, 3 * sizeof(uint32_t),
                                   r->n_obj_tris);
        rtcCommitGeometry(g);
        rtcAttachGeometryByID(r->scene, g, REF_GEOM_OBJECTS);
        rtcReleaseGeometry(g);
    }
    rtcCommitScene(r->scene);
    if (rtcGetDeviceError(r->device) != RTC_ERROR_NONE) {
        lc_set_err(err, errlen, "embree: building the scene failed (see log)");
        goto fail;
    }
    return r;
oom:
    lc_set_err(err, errlen, "out of memory building the reference scene");
fail:
    lc_ref_release(r);
    return NULL;
}

uint32_t lc_ref_cache_crc(const lc_lcb_view *v) {
    uint32_t crc = 0;
    for (uint32_t c = 0; c < v->n_caches; c++) {
        const lc_lcb_cache *ca = &v->caches[c];
        crc = lc_crc32(crc, ca->position, sizeof ca->position);
        crc = lc_crc32(crc, ca->normal, sizeof ca->normal);
        crc = lc_crc32(crc, &ca->flags, sizeof ca->flags);
        crc = lc_crc32(crc, &ca->index, sizeof ca->index);
    }
    return crc;
}

/* --- render ------------------------------------------------------------------------------------ */

/* A job: one texel cache or one grid cell, with its running sums. */
typedef struct {
    uint32_t cache;
    uint32_t cell; /* grid cell, or LC_NONE for a texel cache */
    uint32_t n;    /* samples so far */
    int done;
    float p[3], nrm[3]; /* texel: the evaluation point (before the lift) and its unit normal */
    double sum[27];     /* texel: RGB irradiance; grid: radiance SH */
    double sq[27];
    double sqy; /* squared luminance (texel: E; grid: coefficient 0) */
    uint64_t rays;
} ref_job;

typedef struct {
    const lc_ref *r;
    const lc_ref_settings *s;
    ref_job *jobs;
    const uint32_t *active;
    uint32_t pass, batch;
    lc_progress *progress;
} ref_pass_ctx;

static void ref_pass_range(void *vctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const ref_pass_ctx *ctx = vctx;
    const lc_ref *r = ctx->r;
    ref_path_cfg cfg = {ctx->s->max_bounces, ctx->s->rr_depth};
    for (size_t i = begin; i < end; i++) {
        ref_job *j = &ctx->jobs[ctx->active[i]];
        const lc_lcb_cache *ca = &r->v->caches[j->cache];
        uint64_t stream = ((uint64_t)ctx->active[i] << 20) ^ ctx->pass;
        lc_rng rng = lc_rng_seed(ctx->s->seed, stream);
        uint32_t nb = ctx->batch;
        if (ctx->s->target_stderr <= 0 && j->n + nb > ctx->s->spp) nb = ctx->s->spp - j->n;
        if (j->cell == LC_NONE) {
            const float *n = j->nrm;
            float org[3];
            for (int k = 0; k < 3; k++) org[k] = j->p[k] + n[k] * r->eps;
            for (uint32_t s = 0; s < nb; s++) {
                float e[3];
                ref_sample_texel(r, &cfg, org, n, &rng, e, &j->rays);
                for (int k = 0; k < 3; k++) j->sum[k] += e[k], j->sq[k] += (double)e[k] * e[k];
                double y = lc_ref_luminance(e);
                j->sqy += y * y;
            }
        } else {
            for (uint32_t s = 0; s < nb; s++) {
                float sh[27];
                ref_sample_grid(r, &cfg, ca->position, &rng, sh, &j->rays);
                for (int k = 0; k < 27; k++) j->sum[k] += sh[k], j->sq[k] += (double)sh[k] * sh[k];
                double y = lc_ref_luminance(sh);
                j->sqy += y * y;
            }
        }
        j->n += nb;
        lc_progress_add(ctx->progress, 1);
    }
}

/* Mean luminance and its standard error. */
static void ref_job_lum(const ref_job *j, double *mean, double *se) {
    if (j->n == 0) {
        *mean = *se = 0;
        return;
    }
    double my = (0.2126 * j->sum[0] + 0.7152 * j->sum[1] + 0.0722 * j->sum[2]) / j->n;
    double var = j->n > 1 ? (j->sqy - j->n * my * my) / (j->n - 1) : 0;
    *mean = my;
    *se = sqrt(fmax(var, 0) / j->n);
}

static int ref_dcmp(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void ref_stats(const ref_job *jobs, uint32_t first, uint32_t count, lc_ref_stats *st, double *scratch) {
    memset(st, 0, sizeof *st);
    st->n = count;
    if (!count) return;
    double ymax = 0;
    st->spp_min = UINT32_MAX;
    for (uint32_t i = 0; i < count; i++) {
        const ref_job *j = &jobs[first + i];
        double m, se;
        ref_job_lum(j, &m, &se);
        ymax = fmax(ymax, m);
        st->samples += j->n;
        st->spp_min = j->n < st->spp_min ? j->n : st->spp_min;
        st->spp_max = j->n > st->spp_max ? j->n : st->spp_max;
    }
    st->spp_mean = (double)st->samples / count;
    uint32_t nb = 0;
    double sum = 0;
    for (uint32_t i = 0; i < count; i++) {
        double m, se;
        ref_job_lum(&jobs[first + i], &m, &se);
        if (!(m > 0.01 * ymax) || !(m > 0)) continue;
        double rel = se / m;
        scratch[nb++] = rel;
        sum += rel;
        st->max_rel_stderr = fmax(st->max_rel_stderr, rel);
    }
    st->n_bright = nb;
    if (nb) {
        qsort(scratch, nb, sizeof *scratch, ref_dcmp);
        st->mean_rel_stderr = sum / nb;
        uint32_t k = (uint32_t)ceil(0.95 * nb);
        st->p95_rel_stderr = scratch[k ? k - 1 : 0];
    }
}

void lc_ref_result_free(lc_ref_result *res) {
    if (!res) return;
    free(res->lightmap);
    free(res->lightmap_stderr);
    free(res->texel_mask);
    free(res->grid_sh);
    free(res->grid_sh_stderr);
    free(res->grid_mask);
    free(res->texel_surface);
    free(res->texel_moved);
    memset(res, 0, sizeof *res);
}

/* The texel jobs' evaluation points: the texels' surface points (out->texel_surface, also kept
 * for the comparison's blotch and spacing metrics) or, with LC_REF_TEXEL_AT_CACHE and for a
 * texel no triangle holds, the cache's position and normal. */
static int ref_texel_jobs(const lc_ref *r, const lc_ref_settings *s, ref_job *jobs, uint32_t n_texel,
                          lc_ref_result *out, char *err, size_t errlen) {
    const lc_lcb_view *v = r->v;
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    out->texel_at = s->texel_at == LC_REF_TEXEL_AT_CACHE ? LC_REF_TEXEL_AT_CACHE : LC_REF_TEXEL_AT_SURFACE;
    out->unmoved_offset_max = 0;
    out->texel_surface = malloc((texels * LC_REF_SURFACE_STRIDE + 1) * sizeof(float));
    out->texel_moved = calloc(texels + 1, 1);
    if (!out->texel_surface || !out->texel_moved) {
        lc_set_err(err, errlen, "out of memory for %zu texel surface points", texels);
        return -1;
    }
    if (lc_ref_bake_texels(v, out->texel_surface, out->texel_moved, &out->surface_stats, err, errlen) != 0) return -1;
    for (uint32_t c = 0; c < n_texel; c++) {
        const lc_lcb_cache *ca = &v->caches[c];
        ref_job *j = &jobs[c];
        *j = (ref_job){.cache = c, .cell = LC_NONE};
        memcpy(j->p, ca->position, sizeof j->p);
        memcpy(j->nrm, ca->normal, sizeof j->nrm);
        ref_normalize(j->nrm);
        const float *sf = ca->index < texels ? out->texel_surface + LC_REF_SURFACE_STRIDE * (size_t)ca->index : NULL;
        if (!sf || isnan(sf[0])) continue;
        if (!(ca->flags & LC_CACHE_MOVED)) {
            float d[3] = {sf[0] - ca->position[0], sf[1] - ca->position[1], sf[2] - ca->position[2]};
            out->unmoved_offset_max = fmax(out->unmoved_offset_max, ref_len(d));
        }
        if (out->texel_at != LC_REF_TEXEL_AT_SURFACE) continue;
        memcpy(j->p, sf, sizeof j->p);
        memcpy(j->nrm, sf + 3, sizeof j->nrm);
    }
    return 0;
}

/* Lightmap and grid from the finished jobs. */
static void ref_fill_outputs(const lc_ref *r, const ref_job *jobs, uint32_t n_texel, uint32_t n_jobs,
                             lc_ref_result *out) {
    const lc_lcb_view *v = r->v;
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    uint32_t cells = v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    /* Lightmap: each texel shows its cache, as the engine's (dilated texels copy it). */
    out->width = v->lightmap_width;
    out->height = v->lightmap_height;
    for (size_t i = 0; i < texels; i++) {
        uint32_t c = v->lightmap[i];
        if (c == LC_NONE || c >= n_texel) continue;
        const ref_job *j = &jobs[c];
        for (int k = 0; k < 3; k++) {
            double m = j->n ? j->sum[k] / j->n : 0;
            double var = j->n > 1 ? (j->sq[k] - j->n * m * m) / (j->n - 1) : 0;
            out->lightmap[3 * i + k] = (float)m;
            out->lightmap_stderr[3 * i + k] = (float)sqrt(fmax(var, 0) / (j->n ? j->n : 1));
        }
        out->texel_mask[i] = v->caches[c].index == i ? 1 : 2;
    }
    /* Grid: radiance SH -> irradiance SH (A_l). */
    memcpy(out->grid_dims, v->grid_dims, sizeof out->grid_dims);
    memcpy(out->grid_origin, v->grid_origin, sizeof out->grid_origin);
    out->grid_cell = v->grid_cell;
    out->n_cells = cells;
    static const double A[9] = {M_PI,     2 * M_PI / 3, 2 * M_PI / 3, 2 * M_PI / 3, M_PI / 4,
                                M_PI / 4, M_PI / 4,     M_PI / 4,     M_PI / 4};
    for (uint32_t i = n_texel; i < n_jobs; i++) {
        const ref_job *j = &jobs[i];
        float *o = out->grid_sh + 27 * (size_t)j->cell, *oe = out->grid_sh_stderr + 27 * (size_t)j->cell;
        for (int k = 0; k < 27; k++) {
            double m = j->n ? j->sum[k] / j->n : 0;
            double var = j->n > 1 ? (j->sq[k] - j->n * m * m) / (j->n - 1) : 0;
            o[k] = (float)(A[k / 3] * m);
            oe[k] = (float)(A[k / 3] * sqrt(fmax(var, 0) / (j->n ? j->n : 1)));
        }
        out->grid_mask[j->cell] = 1;
    }
}

int lc_ref_render(lc_ref *r, const lc_ref_settings *s, lc_ref_result *out, char *err, size_t errlen) {
    const lc_lcb_view *v = r->v;
    memset(out, 0, sizeof *out);
    if (s->spp < 1 || s->batch_spp < 1) {
        lc_set_err(err, errlen, "reference: spp and batch must be >= 1");
        return -1;
    }
    double t0 = lc_clock_ms();
    uint32_t n_texel = s->texels ? v->n_texel_caches : 0;
    uint32_t cells = v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    uint32_t n_grid = 0;
    if (s->grid)
        for (uint32_t i = 0; i < cells; i++)
            if (!(v->caches[v->grid[i]].flags & LC_CACHE_INSIDE)) n_grid++;
    uint32_t n_jobs = n_texel + n_grid;
    ref_job *jobs = calloc(n_jobs ? n_jobs : 1, sizeof *jobs);
    uint32_t *active = malloc((n_jobs ? n_jobs : 1) * sizeof *active);
    double *scratch = malloc((n_jobs ? n_jobs : 1) * sizeof *scratch);
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    out->lightmap = calloc(texels * 3 + 1, sizeof(float));
    out->lightmap_stderr = calloc(texels * 3 + 1, sizeof(float));
    out->texel_mask = calloc(texels + 1, 1);
    out->grid_sh = calloc((size_t)cells * 27 + 1, sizeof(float));
    out->grid_sh_stderr = calloc((size_t)cells * 27 + 1, sizeof(float));
    out->grid_mask = calloc((size_t)cells + 1, 1);
    if (!jobs || !active || !scratch || !out->lightmap || !out->lightmap_stderr || !out->texel_mask || !out->grid_sh ||
        !out->grid_sh_stderr || !out->grid_mask) {
        lc_set_err(err, errlen, "out of memory for %u reference jobs", n_jobs);
        goto err;
    }
    out->texel_at = LC_REF_TEXEL_AT_UNKNOWN;
    out->unmoved_offset_max = -1;
    if (n_texel && ref_texel_jobs(r, s, jobs, n_texel, out, err, errlen) != 0) goto err;
    uint32_t g = n_texel;
    if (s->grid)
        for (uint32_t i = 0; i < cells; i++)
            if (!(v->caches[v->grid[i]].flags & LC_CACHE_INSIDE)) jobs[g++] = (ref_job){.cache = v->grid[i], .cell = i};

    /* Passes of batch_spp samples over the caches that still need them. */
    uint32_t n_active = n_jobs;
    for (uint32_t i = 0; i < n_jobs; i++) active[i] = i;
    for (uint32_t pass = 0; n_active > 0; pass++) {
        char stage[64];
        snprintf(stage, sizeof stage, "reference pass %u", pass + 1);
        ref_pass_ctx ctx = {r, s, jobs, active, pass, s->batch_spp, NULL};
        if (!s->quiet) ctx.progress = lc_progress_begin(stage, n_active);
        lc_parallel_for(r->threads, n_active, 1, ref_pass_range, &ctx);
        lc_progress_end(ctx.progress);
        /* Convergence: the spp cap, or (adaptive) the target standard error. */
        double ymax[2] = {0, 0};
        for (uint32_t i = 0; i < n_jobs; i++) {
            double m, se;
            ref_job_lum(&jobs[i], &m, &se);
            int kind = jobs[i].cell != LC_NONE;
            ymax[kind] = fmax(ymax[kind], m);
        }
        uint32_t next = 0;
        for (uint32_t a = 0; a < n_active; a++) {
            ref_job *j = &jobs[active[a]];
            int more = j->n < s->spp;
            if (more && s->target_stderr > 0) {
                double m, se;
                ref_job_lum(j, &m, &se);
                double floor_y = s->floor_frac * ymax[j->cell != LC_NONE];
                more = se > s->target_stderr * fmax(m, floor_y);
            }
            if (more) active[next++] = active[a];
            else j->done = 1;
        }
        if (!s->quiet && s->target_stderr > 0 && next)
            lc_info("ref", "pass %u: %u of %u caches above the target standard error", pass + 1, next, n_jobs);
        n_active = next;
    }

    ref_fill_outputs(r, jobs, n_texel, n_jobs, out);
    ref_stats(jobs, 0, n_texel, &out->texel_stats, scratch);
    ref_stats(jobs, n_texel, n_grid, &out->grid_stats, scratch);
    for (uint32_t i = 0; i < n_jobs; i++) out->rays += jobs[i].rays;
    out->cache_crc = lc_ref_cache_crc(v);
    out->max_bounces = s->max_bounces;
    out->seconds = (lc_clock_ms() - t0) / 1000.0;
    free(jobs);
    free(active);
    free(scratch);
    return 0;
err:
    free(jobs);
    free(active);
    free(scratch);
    lc_ref_result_free(out);
    return -1;
}
