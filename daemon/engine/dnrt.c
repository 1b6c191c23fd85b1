/* dnrt: placed objects in the indirect light (dnrt.h). Runs on the engine's (compute)
 * thread. */
#include "engine/dnrt.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "engine/embree_device.h"
#include "engine/scene_math.h"
#include "util/log.h"
#include "util/ray_offset.h"
#include "util/sh.h"

#define DNRT_BIN_AXIS 64      /* bins along the caches' longest extent */
#define DNRT_MAX_BINS 300000u /* cap on the spatial index (65^3 at most) */
#define DNRT_TAPER 0.2f       /* fraction of the outer radius the effect fades over */
#define DNRT_BLOCKER_RAYS 4
#define DNRT_AREA_SAMPLES 16
#define DNRT_VALUES 36 /* per receiver: T 9 x RGB, K 9 */

typedef struct {
    uint32_t *targets;
    float *dirs, *values;
    uint32_t n, cap;
} dnrt_list;

typedef struct {
    lc_engine_object key; /* the object as its receivers were found (valid = 1) */
    int blockers, valid, used;
    dnrt_list caches;
} dnrt_slot;

static void dnrt_list_free(dnrt_list *l) {
    free(l->targets);
    free(l->dirs);
    free(l->values);
    memset(l, 0, sizeof *l);
}

static int dnrt_list_reserve(dnrt_list *l, uint32_t n) {
    if (n <= l->cap) return 0;
    uint32_t cap = l->cap ? l->cap : 256;
    while (cap < n) cap *= 2;
    uint32_t *t = realloc(l->targets, (size_t)cap * sizeof *t);
    if (t) l->targets = t;
    float *dr = t ? realloc(l->dirs, (size_t)cap * 3 * sizeof *dr) : NULL;
    if (dr) l->dirs = dr;
    float *va = dr ? realloc(l->values, (size_t)cap * DNRT_VALUES * sizeof *va) : NULL;
    if (va) l->values = va;
    if (!va) return -1;
    l->cap = cap;
    return 0;
}

/* Appends src[first, first + n) to l. */
static int dnrt_list_append(dnrt_list *l, const dnrt_list *src, uint32_t first, uint32_t n) {
    if (!n) return 0; /* nothing to copy, and either list may still have no arrays (memcpy's NULL) */
    if (dnrt_list_reserve(l, l->n + n) != 0) return -1;
    memcpy(l->targets + l->n, src->targets + first, (size_t)n * sizeof *l->targets);
    memcpy(l->dirs + 3 * (size_t)l->n, src->dirs + 3 * (size_t)first, (size_t)n * 3 * sizeof *l->dirs);
    memcpy(l->values + (size_t)l->n * DNRT_VALUES, src->values + (size_t)first * DNRT_VALUES,
           (size_t)n * DNRT_VALUES * sizeof *l->values);
    l->n += n;
    return 0;
}

struct lc_dnrt {
    const lc_lcb_view *v;
    /* Spatial index: caches by bin (CSR), bins of `bin` metres from `origin`. */
    float origin[3], bin;
    uint32_t bdims[3];
    uint32_t *bin_start; /* bdims product + 1 */
    uint32_t *bin_cache;
    /* The placement: every object's receivers, the frame's arrays. */
    lc_dnrt_object *objects;
    uint32_t n_objects, cap_objects;
    dnrt_list all;
    /* Each placed object's cache receivers by id, kept while it does not move: moving one
     * object of many finds only its receivers again. */
    dnrt_slot *slots;
    uint32_t n_slots, cap_slots;
    lc_dnrt_frame frame;
};

/* --- create / release ------------------------------------------------------------------------ */

void lc_dnrt_release(lc_dnrt *d) {
    if (!d) return;
    free(d->bin_start);
    free(d->bin_cache);
    free(d->objects);
    dnrt_list_free(&d->all);
    for (uint32_t i = 0; i < d->n_slots; i++) dnrt_list_free(&d->slots[i].caches);
    free(d->slots);
    free(d);
}

static uint32_t dnrt_bin_of(const lc_dnrt *d, const float p[3], int axis) {
    float g = (p[axis] - d->origin[axis]) / d->bin;
    if (!(g > 0)) return 0;
    uint32_t i = (uint32_t)g;
    return i >= d->bdims[axis] ? d->bdims[axis] - 1 : i;
}

static size_t dnrt_bin_index(const lc_dnrt *d, uint32_t x, uint32_t y, uint32_t z) {
    return x + (size_t)d->bdims[0] * (y + (size_t)d->bdims[1] * z);
}

/* Caches into bins (counting sort): a sphere query visits only the bins it overlaps. */
static int dnrt_build_bins(lc_dnrt *d) {
    const lc_lcb_view *v = d->v;
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t c = 0; c < v->n_caches; c++)
        for (int k = 0; k < 3; k++) {
            lo[k] = fminf(lo[k], v->caches[c].position[k]);
            hi[k] = fmaxf(hi[k], v->caches[c].position[k]);
        }
    float ext = fmaxf(fmaxf(hi[0] - lo[0], hi[1] - lo[1]), hi[2] - lo[2]);
    d->bin = fmaxf(ext / DNRT_BIN_AXIS, 1e-3f);
    size_t nb = 1;
    for (int k = 0; k < 3; k++) {
        d->origin[k] = lo[k];
        d->bdims[k] = (uint32_t)((hi[k] - lo[k]) / d->bin) + 1;
        nb *= d->bdims[k];
    }
    if (nb > DNRT_MAX_BINS) return -1; /* cannot happen with 64 bins on the longest axis */
    d->bin_start = calloc(nb + 1, sizeof *d->bin_start);
    d->bin_cache = malloc(((size_t)v->n_caches + 1) * sizeof *d->bin_cache);
    if (!d->bin_start || !d->bin_cache) return -1;
    for (uint32_t c = 0; c < v->n_caches; c++) {
        const float *p = v->caches[c].position;
        d->bin_start[dnrt_bin_index(d, dnrt_bin_of(d, p, 0), dnrt_bin_of(d, p, 1), dnrt_bin_of(d, p, 2)) + 1]++;
    }
    for (size_t b = 0; b < nb; b++) d->bin_start[b + 1] += d->bin_start[b];
    uint32_t *fill = malloc((nb + 1) * sizeof *fill);
    if (!fill) return -1;
    memcpy(fill, d->bin_start, (nb + 1) * sizeof *fill);
    for (uint32_t c = 0; c < v->n_caches; c++) {
        const float *p = v->caches[c].position;
        d->bin_cache[fill[dnrt_bin_index(d, dnrt_bin_of(d, p, 0), dnrt_bin_of(d, p, 1), dnrt_bin_of(d, p, 2))]++] = c;
    }
    free(fill);
    return 0;
}

lc_dnrt *lc_dnrt_create(const lc_lcb_view *v, char *err, size_t errlen) {
    lc_dnrt *d = calloc(1, sizeof *d);
    if (!d) goto oom;
    d->v = v;
    if (v->n_transfers && v->n_caches && dnrt_build_bins(d) != 0) goto oom;
    return d;
oom:
    lc_dnrt_release(d);
    lc_set_err(err, errlen, "out of memory for the DNRT index of %u caches", v->n_caches);
    return NULL;
}

/* --- the transfer grid ----------------------------------------------------------------------- */

/* T and K of transfer `t` at asset-local point p (dnrt.h: trilinear, projected onto the inner
 * cube outside it, 1/d^2 beyond, the taper), into out[36]. 0 outside the outer volume. */
static int dnrt_transfer_at(const lc_lcb_view *v, const lc_lcb_transfer *t, const float p[3], float out[36]) {
    float rel[3] = {p[0] - t->center[0], p[1] - t->center[1], p[2] - t->center[2]};
    float r = sqrtf(rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]);
    if (!(r < t->outer_radius)) return 0;
    float m = fmaxf(fmaxf(fabsf(rel[0]), fabsf(rel[1])), fabsf(rel[2]));
    float s = m > t->half_extent ? t->half_extent / m : 1.0f;
    const int dims = (int)t->dims, nc = (int)t->coeffs, nv = nc * 4;
    int i0[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        float g = (rel[k] * s + t->half_extent) / (2.0f * t->half_extent) * (float)(dims - 1);
        g = g < 0 ? 0 : g > (float)(dims - 1) ? (float)(dims - 1) : g;
        i0[k] = (int)g;
        if (i0[k] > dims - 2) i0[k] = dims - 2;
        f[k] = g - (float)i0[k];
    }
    float acc[DNRT_VALUES] = {0};
    const int8_t *base = v->transfer_data + t->data_offset;
    for (int corner = 0; corner < 8; corner++) {
        float w = 1;
        size_t idx = 0, mul = 1;
        for (int k = 0; k < 3; k++) {
            int bit = (corner >> k) & 1;
            w *= bit ? f[k] : 1 - f[k];
            idx += (size_t)(i0[k] + bit) * mul;
            mul *= (size_t)dims;
        }
        if (w == 0) continue;
        const int8_t *q = base + idx * (size_t)nv;
        for (int c = 0; c < nv; c++) acc[c] += w * (float)q[c];
    }
    float g = fmaxf(r, t->radius) / t->radius;
    float taper = (t->outer_radius - r) / (DNRT_TAPER * t->outer_radius);
    float k = (taper < 1 ? taper : 1.0f) / (127.0f * g * g);
    memset(out, 0, DNRT_VALUES * sizeof(float));
    for (int j = 0; j < nc; j++) {
        for (int ch = 0; ch < 3; ch++) out[3 * j + ch] = acc[3 * j + ch] * k * t->t_scale[3 * j + ch];
        out[27 + j] = acc[3 * nc + j] * k * t->k_scale[j];
    }
    return 1;
}

/* --- placement ------------------------------------------------------------------------------- */

static void dnrt_invert3(const float m[12], float inv[9]) { /* m column-major 3x4; inv row-major */
    float a = m[0], b = m[3], c = m[6], d = m[1], e = m[4], f = m[7], g = m[2], h = m[5], i = m[8];
    float det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
    float s = 1.0f / det;
    inv[0] = (e * i - f * h) * s, inv[1] = (c * h - b * i) * s, inv[2] = (b * f - c * e) * s;
    inv[3] = (f * g - d * i) * s, inv[4] = (a * i - c * g) * s, inv[5] = (c * d - a * f) * s;
    inv[6] = (d * h - e * g) * s, inv[7] = (b * g - a * h) * s, inv[8] = (a * e - b * d) * s;
}

/* The fraction of DNRT_BLOCKER_RAYS rays from p to points around the object's centre that
 * no static geometry stops. */
static float dnrt_unblocked(RTCScene sc, const float p[3], const float center[3], float radius, float eps) {
    float to[3] = {center[0] - p[0], center[1] - p[1], center[2] - p[2]};
    float dist = lc_sm_len(to);
    if (!(dist > eps)) return 1.0f;
    for (int k = 0; k < 3; k++) to[k] /= dist;
    float a[3] = {fabsf(to[0]) < 0.9f ? 1.0f : 0.0f, fabsf(to[0]) < 0.9f ? 0.0f : 1.0f, 0}, u[3], w[3];
    lc_sm_cross(to, a, u);
    float ul = lc_sm_len(u);
    for (int k = 0; k < 3; k++) u[k] /= ul;
    lc_sm_cross(to, u, w);
    static const float offs[DNRT_BLOCKER_RAYS][2] = {{0.5f, 0}, {-0.5f, 0}, {0, 0.5f}, {0, -0.5f}};
    int open = 0;
    for (int r = 0; r < DNRT_BLOCKER_RAYS; r++) {
        float q[3], dir[3];
        for (int k = 0; k < 3; k++) q[k] = center[k] + radius * (offs[r][0] * u[k] + offs[r][1] * w[k]) - p[k];
        float l = lc_sm_len(q);
        for (int k = 0; k < 3; k++) dir[k] = q[k] / l;
        open += !lc_embree_occluded(sc, p, dir, l);
    }
    return (float)open / DNRT_BLOCKER_RAYS;
}

typedef struct {
    const lc_lcb_transfer *t;
    float m[12], inv[9];            /* placement and the inverse of its linear part */
    float center[3], radius, outer; /* world */
    int blockers;
    RTCScene sc;
    float eps;
} dnrt_placing;

/* One receiver at world point p (normal n, or NULL for the full sphere) into l. */
static int dnrt_add_receiver(const lc_dnrt *d, const dnrt_placing *pl, dnrt_list *l, uint32_t target, const float p[3],
                             const float *n) {
    float dir[3] = {pl->center[0] - p[0], pl->center[1] - p[1], pl->center[2] - p[2]};
    float dist = lc_sm_len(dir);
    if (!(dist > 1e-6f)) return 0;
    for (int k = 0; k < 3; k++) dir[k] /= dist;
    if (n && lc_sm_dot(n, dir) <= 0) return 0;
    float rel[3] = {p[0] - pl->m[9], p[1] - pl->m[10], p[2] - pl->m[11]}, local[3];
    for (int k = 0; k < 3; k++)
        local[k] = pl->inv[3 * k] * rel[0] + pl->inv[3 * k + 1] * rel[1] + pl->inv[3 * k + 2] * rel[2];
    float val[DNRT_VALUES];
    if (!dnrt_transfer_at(d->v, pl->t, local, val)) return 0;
    if (pl->blockers) {
        float org[3];
        for (int k = 0; k < 3; k++) org[k] = p[k] + (n ? n[k] * pl->eps : 0);
        float vis = dnrt_unblocked(pl->sc, org, pl->center, pl->radius, pl->eps);
        if (vis == 0) return 0;
        for (int c = 0; c < DNRT_VALUES; c++) val[c] *= vis;
    }
    if (dnrt_list_reserve(l, l->n + 1) != 0) return -1;
    uint32_t r = l->n++;
    l->targets[r] = target;
    memcpy(l->dirs + 3 * (size_t)r, dir, sizeof dir);
    memcpy(l->values + (size_t)r * DNRT_VALUES, val, sizeof val);
    return 0;
}

void lc_dnrt_grid_corners(const lc_lcb_view *v, const float p[3], uint32_t corner[8], float w[8]) {
    int i0[3];
    float f[3];
    for (int k = 0; k < 3; k++) {
        float g = (p[k] - v->grid_origin[k]) / v->grid_cell, maxg = (float)(v->grid_dims[k] - 1);
        g = !(g > 0) ? 0 : g > maxg ? maxg : g;
        i0[k] = (int)floorf(g);
        if (i0[k] > (int)v->grid_dims[k] - 2) i0[k] = (int)v->grid_dims[k] - 2;
        if (i0[k] < 0) i0[k] = 0;
        f[k] = v->grid_dims[k] > 1 ? g - (float)i0[k] : 0;
    }
    for (int c = 0; c < 8; c++) {
        size_t idx[3];
        w[c] = 1;
        for (int k = 0; k < 3; k++) {
            int bit = (c >> k) & 1;
            idx[k] = (size_t)(i0[k] + bit) < v->grid_dims[k] ? (size_t)(i0[k] + bit) : v->grid_dims[k] - 1;
            w[c] *= bit ? f[k] : 1 - f[k];
        }
        corner[c] = v->grid[idx[0] + v->grid_dims[0] * (idx[1] + v->grid_dims[1] * idx[2])];
    }
}

/* The caches in one object's outer volume that it changes, into l. */
static int dnrt_find_caches(const lc_dnrt *d, const dnrt_placing *pl, dnrt_list *l) {
    const lc_lcb_view *v = d->v;
    uint32_t lo[3], hi[3];
    for (int k = 0; k < 3; k++) {
        float a[3] = {pl->center[0], pl->center[1], pl->center[2]};
        a[k] -= pl->outer;
        lo[k] = dnrt_bin_of(d, a, k);
        a[k] += 2 * pl->outer;
        hi[k] = dnrt_bin_of(d, a, k);
    }
    float r2 = pl->outer * pl->outer;
    for (uint32_t z = lo[2]; z <= hi[2]; z++)
        for (uint32_t y = lo[1]; y <= hi[1]; y++)
            for (uint32_t x = lo[0]; x <= hi[0]; x++) {
                size_t b = dnrt_bin_index(d, x, y, z);
                for (uint32_t i = d->bin_start[b]; i < d->bin_start[b + 1]; i++) {
                    uint32_t c = d->bin_cache[i];
                    const lc_lcb_cache *cc = &v->caches[c];
                    if (cc->flags & LC_CACHE_INSIDE) continue;
                    float dx = cc->position[0] - pl->center[0], dy = cc->position[1] - pl->center[1],
                          dz = cc->position[2] - pl->center[2];
                    if (dx * dx + dy * dy + dz * dz >= r2) continue;
                    int texel = (cc->flags & LC_CACHE_TEXEL) != 0;
                    if (dnrt_add_receiver(d, pl, l, c, cc->position, texel ? cc->normal : NULL) != 0) return -1;
                }
            }
    return 0;
}

/* The slot of object o (by id), kept or new; NULL out of memory. hint: its index last time. */
static dnrt_slot *dnrt_slot_of(lc_dnrt *d, const lc_engine_object *o, uint32_t hint) {
    if (hint < d->n_slots && !strcmp(d->slots[hint].key.id, o->id)) return &d->slots[hint];
    for (uint32_t i = 0; i < d->n_slots; i++)
        if (!strcmp(d->slots[i].key.id, o->id)) return &d->slots[i];
    if (d->n_slots == d->cap_slots) {
        uint32_t cap = d->cap_slots ? 2 * d->cap_slots : 16;
        dnrt_slot *ns = realloc(d->slots, cap * sizeof *ns);
        if (!ns) return NULL;
        d->slots = ns;
        d->cap_slots = cap;
    }
    dnrt_slot *sl = &d->slots[d->n_slots++];
    memset(sl, 0, sizeof *sl);
    memcpy(sl->key.id, o->id, sizeof sl->key.id);
    return sl;
}

/* Slots of objects no longer placed go. */
static void dnrt_slots_sweep(lc_dnrt *d) {
    uint32_t k = 0;
    for (uint32_t i = 0; i < d->n_slots; i++) {
        if (!d->slots[i].used) {
            dnrt_list_free(&d->slots[i].caches);
            continue;
        }
        d->slots[i].used = 0;
        d->slots[k++] = d->slots[i];
    }
    d->n_slots = k;
}

/* Object i's placement record and receivers: its caches (found again only when it moved),
 * then the other objects' SH points. */
static int dnrt_place_one(lc_dnrt *d, const lc_engine_object *objects, uint32_t n, const float *object_pos, uint32_t i,
                          const lc_engine_settings *st, RTCScene sc, float eps) {
    const lc_engine_object *o = &objects[i];
    const lc_lcb_transfer *t = lc_lcb_asset_transfer(d->v, o->asset);
    dnrt_placing pl = {.t = t, .blockers = st->dnrt_blockers, .sc = sc, .eps = eps};
    lc_sm_object_matrix(o, pl.m);
    dnrt_invert3(pl.m, pl.inv);
    lc_sm_transform_point(pl.m, t->center, pl.center);
    float smax = fmaxf(fmaxf(fabsf(o->scale[0]), fabsf(o->scale[1])), fabsf(o->scale[2]));
    pl.radius = t->radius * smax;
    pl.outer = t->outer_radius * smax;
    lc_dnrt_object *dob = &d->objects[d->n_objects];
    memset(dob, 0, sizeof *dob);
    dob->object = i;
    dob->coeffs = t->coeffs;
    memcpy(dob->center, pl.center, sizeof dob->center);
    float r[9]; /* the rotation (with any reflection) of the placement, row-major */
    for (int col = 0; col < 3; col++) {
        float l = lc_sm_len(pl.m + 3 * col);
        for (int row = 0; row < 3; row++) r[3 * row + col] = pl.m[3 * col + row] / l;
    }
    lc_sh_rotation_l2(r, dob->to_local);
    lc_dnrt_grid_corners(d->v, object_pos + 3 * (size_t)i, dob->corner, dob->corner_w);
    dnrt_slot *sl = dnrt_slot_of(d, o, d->n_objects);
    if (!sl) return -1;
    sl->used = 1;
    if (!sl->valid || sl->blockers != st->dnrt_blockers || memcmp(&sl->key, o, sizeof *o) != 0) {
        sl->valid = 0;
        sl->caches.n = 0;
        if (dnrt_find_caches(d, &pl, &sl->caches) != 0) return -1;
        sl->key = *o;
        sl->blockers = st->dnrt_blockers;
        sl->valid = 1;
    }
    dob->first = d->all.n;
    if (dnrt_list_append(&d->all, &sl->caches, 0, sl->caches.n) != 0) return -1;
    for (uint32_t j = 0; j < n; j++) {
        if (j == i || !objects[j].visible) continue;
        if (dnrt_add_receiver(d, &pl, &d->all, LC_DNRT_OBJECT_RECEIVER | j, object_pos + 3 * (size_t)j, NULL) != 0)
            return -1;
    }
    dob->count = d->all.n - dob->first;
    d->n_objects++;
    return 0;
}

int lc_dnrt_place(lc_dnrt *d, const lc_engine_object *objects, uint32_t n, const float *object_pos,
                  const lc_engine_settings *st, RTCScene static_scene, float eps, char *err, size_t errlen) {
    const lc_lcb_view *v = d->v;
    d->n_objects = 0;
    d->all.n = 0;
    if (st->dnrt && v->n_transfers && v->n_caches) {
        for (uint32_t i = 0; i < n; i++) {
            const lc_engine_object *o = &objects[i];
            if (!lc_lcb_asset_transfer(v, o->asset) || !o->visible || o->dnrt_off) continue;
            if (d->n_objects == d->cap_objects) {
                uint32_t cap = d->cap_objects ? 2 * d->cap_objects : 16;
                lc_dnrt_object *no = realloc(d->objects, cap * sizeof *no);
                if (!no) goto oom;
                d->objects = no;
                d->cap_objects = cap;
            }
            if (dnrt_place_one(d, objects, n, object_pos, i, st, static_scene, eps) != 0) goto oom;
        }
    }
    dnrt_slots_sweep(d);
    d->frame = (lc_dnrt_frame){.objects = d->objects,
                               .n_objects = d->n_objects,
                               .targets = d->all.targets,
                               .dirs = d->all.dirs,
                               .values = d->all.values,
                               .n_receivers = d->all.n,
                               .generation = d->frame.generation + 1,
                               .placement = d->frame.placement + 1};
    return 0;
oom:
    d->n_objects = d->all.n = 0;
    for (uint32_t i = 0; i < d->n_slots; i++) d->slots[i].used = d->slots[i].valid ? 1 : 0;
    dnrt_slots_sweep(d);
    d->frame = (lc_dnrt_frame){.generation = d->frame.generation + 1, .placement = d->frame.placement + 1};
    lc_set_err(err, errlen, "out of memory placing objects for DNRT");
    return -1;
}

const lc_dnrt_frame *lc_dnrt_frame_get(const lc_dnrt *d) { return &d->frame; }

/* --- direct light on the objects ------------------------------------------------------------- */

static void dnrt_add_lobe(float c[27], const float l[3], float vis, const float e[3]) {
    float y[9];
    lc_sh_eval_fast(3, l[0], l[1], l[2], y);
    static const float a[9] = {(float)M_PI,           (float)(2 * M_PI / 3), (float)(2 * M_PI / 3),
                               (float)(2 * M_PI / 3), (float)(M_PI / 4),     (float)(M_PI / 4),
                               (float)(M_PI / 4),     (float)(M_PI / 4),     (float)(M_PI / 4)};
    for (int j = 0; j < 9; j++)
        for (int ch = 0; ch < 3; ch++) c[3 * j + ch] += a[j] * y[j] * vis * e[ch];
}

/* The share of five rays toward `target` (a point, or a direction when dir_only) from the
 * light side of the bounding sphere that reach it: outside the sphere and moving away from
 * it, so the object never shadows itself. */
static float dnrt_light_visibility(RTCScene sc, const float c[3], float radius, const float l[3], const float *target,
                                   float eps) {
    float a[3] = {fabsf(l[0]) < 0.9f ? 1.0f : 0.0f, fabsf(l[0]) < 0.9f ? 0.0f : 1.0f, 0}, u[3], w[3];
    lc_sm_cross(l, a, u);
    float ul = lc_sm_len(u);
    for (int k = 0; k < 3; k++) u[k] /= ul;
    lc_sm_cross(l, u, w);
    static const float offs[5][2] = {{0, 0}, {0.5f, 0}, {-0.5f, 0}, {0, 0.5f}, {0, -0.5f}};
    int open = 0;
    for (int r = 0; r < 5; r++) {
        float q[3], dir[3], tfar = INFINITY;
        for (int k = 0; k < 3; k++) q[k] = c[k] + radius * (1.001f * l[k] + offs[r][0] * u[k] + offs[r][1] * w[k]);
        if (target) {
            for (int k = 0; k < 3; k++) dir[k] = target[k] - q[k];
            float dl = lc_sm_len(dir);
            if (!(dl > eps)) {
                open++;
                continue;
            }
            for (int k = 0; k < 3; k++) dir[k] /= dl;
            tfar = lc_ray_shadow_tfar(dl, eps);
        } else memcpy(dir, l, sizeof dir);
        open += !lc_embree_occluded(sc, q, dir, tfar);
    }
    return (float)open / 5.0f;
}

static void dnrt_direct_one(lc_dnrt_object *dob, float radius, const lc_engine_light *lights, uint32_t n_lights,
                            RTCScene sc, float eps) {
    memset(dob->c_dir, 0, sizeof dob->c_dir);
    const float *c = dob->center;
    for (uint32_t li = 0; li < n_lights; li++) {
        const lc_engine_light *l = &lights[li];
        float e[3], dir[3];
        if (l->type == LC_ENGINE_LIGHT_DIRECTIONAL) {
            float dl = lc_sm_len(l->direction);
            for (int k = 0; k < 3; k++) dir[k] = -l->direction[k] / dl, e[k] = l->intensity * l->color[k];
            dnrt_add_lobe(dob->c_dir, dir, dnrt_light_visibility(sc, c, radius, dir, NULL, eps), e);
        } else if (l->type == LC_ENGINE_LIGHT_AREA) {
            lc_sm_area_frame fr = lc_sm_area_frame_of(l);
            for (int j = 0; j < DNRT_AREA_SAMPLES; j++) {
                float p[3];
                lc_sm_area_point(l, &fr, ((float)(j % 4) + 0.5f) * 0.25f, ((float)(j / 4) + 0.5f) * 0.25f, p);
                for (int k = 0; k < 3; k++) dir[k] = p[k] - c[k];
                float d2 = lc_sm_dot(dir, dir), dist = sqrtf(d2);
                if (!(dist > radius)) continue;
                for (int k = 0; k < 3; k++) dir[k] /= dist;
                float cos_l = -lc_sm_dot(fr.n, dir);
                if (cos_l <= 0) continue;
                float g = l->intensity * cos_l * fr.area / DNRT_AREA_SAMPLES / d2 * lc_sm_range_window(d2, l->range);
                for (int k = 0; k < 3; k++) e[k] = g * l->color[k];
                dnrt_add_lobe(dob->c_dir, dir, dnrt_light_visibility(sc, c, radius, dir, p, eps), e);
            }
        } else { /* point, spot */
            for (int k = 0; k < 3; k++) dir[k] = l->position[k] - c[k];
            float d2 = lc_sm_dot(dir, dir), dist = sqrtf(d2);
            if (!(dist > radius)) continue; /* a light inside the object: it lights no receiver */
            for (int k = 0; k < 3; k++) dir[k] /= dist;
            float att = lc_sm_range_window(d2, l->range) / d2;
            if (l->type == LC_ENGINE_LIGHT_SPOT) att *= lc_sm_spot_cone(l, dir);
            if (att <= 0) continue;
            for (int k = 0; k < 3; k++) e[k] = l->intensity * l->color[k] * att;
            dnrt_add_lobe(dob->c_dir, dir, dnrt_light_visibility(sc, c, radius, dir, l->position, eps), e);
        }
    }
}

void lc_dnrt_direct(lc_dnrt *d, const lc_engine_light *lights, uint32_t n_lights, RTCScene scene, float eps,
                    const lc_engine_object *objects) {
    d->frame.generation++;
    for (uint32_t i = 0; i < d->n_objects; i++) {
        lc_dnrt_object *dob = &d->objects[i];
        const lc_engine_object *o = &objects[dob->object];
        const lc_lcb_transfer *t = lc_lcb_asset_transfer(d->v, o->asset);
        float smax = fmaxf(fmaxf(fabsf(o->scale[0]), fabsf(o->scale[1])), fabsf(o->scale[2]));
        dnrt_direct_one(dob, t->radius * smax, lights, n_lights, scene, eps);
    }
}

/* --- per pass -------------------------------------------------------------------------------- */

typedef struct {
    const lc_dnrt_frame *f;
    const lc_dnrt_target *tg;
    const lc_dnrt_object *ob;
    float cl[9][3], ct[9][3]; /* incident SH, and with the direct light, in the asset's frame */
    int bands;
} dnrt_apply_job;

/* Receivers [first + begin, first + end) of one object. Serial: a fork-join over a few
 * thousand receivers cost more than it saved on this 2-core machine when other work ran
 * (10 objects: 1.9 -> 60 ms). */
static void dnrt_apply_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    static const float a[9] = {(float)M_PI,           (float)(2 * M_PI / 3), (float)(2 * M_PI / 3),
                               (float)(2 * M_PI / 3), (float)(M_PI / 4),     (float)(M_PI / 4),
                               (float)(M_PI / 4),     (float)(M_PI / 4),     (float)(M_PI / 4)};
    const dnrt_apply_job *job = ctx;
    const lc_dnrt_frame *f = job->f;
    const lc_dnrt_target *tg = job->tg;
    const int nc = (int)job->ob->coeffs;
    for (size_t r = job->ob->first + begin; r < job->ob->first + end; r++) {
        uint32_t target = f->targets[r];
        const float *val = f->values + r * DNRT_VALUES, *d = f->dirs + 3 * r;
        int is_object = (target & LC_DNRT_OBJECT_RECEIVER) != 0;
        if (is_object ? !tg->object_delta : tg->fresh && !tg->fresh[target]) continue;
        float x[3];
        for (int ch = 0; ch < 3; ch++) {
            float s = 0;
            for (int i = 0; i < nc; i++) s += job->ct[i][ch] * val[3 * i + ch] - job->cl[i][ch] * val[27 + i];
            x[ch] = s;
        }
        float y[LC_SH_MAX_COEFFS];
        if (is_object) {
            float *od = tg->object_delta + 27 * (size_t)(target & ~LC_DNRT_OBJECT_RECEIVER);
            lc_sh_eval_fast(3, d[0], d[1], d[2], y);
            for (int j = 0; j < 9; j++)
                for (int ch = 0; ch < 3; ch++) od[3 * j + ch] += a[j] * y[j] * x[ch];
            continue;
        }
        int texel = target < tg->n_texel_caches;
        int lo = texel ? tg->texel_lo : 0, hi = texel ? tg->texel_nc : tg->grid_nc;
        lc_sh_eval_fast(job->bands, d[0], d[1], d[2], y);
        float *sh = tg->cache_sh + (size_t)target * tg->stride * 3;
        for (int j = lo; j < hi; j++)
            for (int ch = 0; ch < 3; ch++) sh[3 * j + ch] += y[j] * x[ch];
    }
}

void lc_dnrt_apply(const lc_dnrt_frame *f, const float *c_world, const lc_dnrt_target *tg) {
    const int max_nc = tg->texel_nc > tg->grid_nc ? tg->texel_nc : tg->grid_nc;
    dnrt_apply_job job = {.f = f, .tg = tg, .bands = 1};
    while (job.bands * job.bands < max_nc) job.bands++;
    /* Objects one after the other: two may change the same cache. */
    for (uint32_t oi = 0; oi < f->n_objects; oi++) {
        const lc_dnrt_object *ob = &f->objects[oi];
        const float *cw = c_world + 27 * (size_t)oi;
        job.ob = ob;
        for (uint32_t i = 0; i < ob->coeffs; i++)
            for (int ch = 0; ch < 3; ch++) {
                float s = 0, sd = 0;
                for (int j = 0; j < 9; j++) {
                    s += ob->to_local[i][j] * cw[3 * j + ch];
                    sd += ob->to_local[i][j] * ob->c_dir[3 * j + ch];
                }
                job.cl[i][ch] = s;
                job.ct[i][ch] = s + sd;
            }
        dnrt_apply_range(&job, 0, ob->count, 0);
    }
}
