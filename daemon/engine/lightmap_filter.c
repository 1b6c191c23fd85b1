#include "engine/lightmap_filter.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"

typedef struct lmf_tap {
    uint32_t texel;
    float weight;
} lmf_tap;

struct lc_lmfilter {
    uint32_t texels;
    uint32_t *start; /* texels + 1: texel t reads taps [start[t], start[t + 1]) */
    lmf_tap *taps;
    uint32_t filtered; /* texels with at least one neighbour */
};

/* The cache of texel t if t owns it (not a dilated copy) and the bake did not move it. */
static const lc_lcb_cache *lmf_owner(const lc_lcb_view *v, uint32_t t) {
    uint32_t c = v->lightmap[t];
    if (c == LC_NONE || c >= v->n_texel_caches) return NULL;
    const lc_lcb_cache *k = &v->caches[c];
    if (k->index != t || (k->flags & LC_CACHE_MOVED) || !(k->flags & LC_CACHE_TEXEL)) return NULL;
    return k;
}

static float lmf_dist(const lc_lcb_cache *a, const lc_lcb_cache *b) {
    float d[3] = {a->position[0] - b->position[0], a->position[1] - b->position[1], a->position[2] - b->position[2]};
    return sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
}

static int lmf_coplanar(const lc_lcb_cache *a, const lc_lcb_cache *b) {
    const float cos_max = 0.9063078f; /* 25 degrees */
    return a->normal[0] * b->normal[0] + a->normal[1] * b->normal[1] + a->normal[2] * b->normal[2] >= cos_max;
}

/* Taps of owner texel (x, y) into out (up to 9); returns the count. */
static uint32_t lmf_texel_taps(const lc_lcb_view *v, uint32_t x, uint32_t y, const lc_lcb_cache *self, lmf_tap *out) {
    const uint32_t W = v->lightmap_width, H = v->lightmap_height;
    const lc_lcb_cache *nb[9] = {0};
    float dist[9] = {0}, nearest = INFINITY;
    for (int dy = -1; dy <= 1; dy++)
        for (int dx = -1; dx <= 1; dx++) {
            int k = (dy + 1) * 3 + dx + 1;
            long nx = (long)x + dx, ny = (long)y + dy;
            if (k == 4 || nx < 0 || ny < 0 || nx >= (long)W || ny >= (long)H) continue;
            const lc_lcb_cache *n = lmf_owner(v, (uint32_t)ny * W + (uint32_t)nx);
            if (!n || !lmf_coplanar(self, n)) continue;
            nb[k] = n;
            dist[k] = lmf_dist(self, n);
            if ((dx == 0 || dy == 0) && dist[k] < nearest) nearest = dist[k];
        }
    uint32_t n_taps = 0;
    out[n_taps++] = (lmf_tap){y * W + x, 4.0f};
    if (!(nearest < INFINITY) || !(nearest > 0)) return n_taps;
    for (int k = 0; k < 9; k++) {
        if (!nb[k]) continue;
        int diagonal = k == 0 || k == 2 || k == 6 || k == 8;
        if (dist[k] > 1.5f * nearest * (diagonal ? 1.4142136f : 1.0f)) continue;
        out[n_taps++] = (lmf_tap){nb[k]->index, diagonal ? 1.0f : 2.0f};
    }
    float sum = 0;
    for (uint32_t i = 0; i < n_taps; i++) sum += out[i].weight;
    for (uint32_t i = 0; i < n_taps; i++) out[i].weight /= sum;
    return n_taps;
}

lc_lmfilter *lc_lmfilter_create(const lc_lcb_view *v, char *err, size_t errlen) {
    const uint32_t W = v->lightmap_width, H = v->lightmap_height;
    const size_t texels = (size_t)W * H;
    lc_lmfilter *f = calloc(1, sizeof *f);
    uint32_t *own_taps = NULL; /* per texel: its owner's first tap, for dilated copies */
    if (!f) goto oom;
    f->texels = (uint32_t)texels;
    f->start = malloc((texels + 1) * sizeof *f->start);
    f->taps = malloc((texels ? texels : 1) * 9 * sizeof *f->taps);
    own_taps = malloc((texels ? texels : 1) * 2 * sizeof *own_taps);
    if (!f->start || !f->taps || !own_taps) goto oom;
    /* Owners first (each texel's taps at a fixed slot t*9), then every texel's range. */
    for (size_t t = 0; t < texels; t++) {
        own_taps[2 * t] = own_taps[2 * t + 1] = 0;
        uint32_t c = v->lightmap[t];
        if (c == LC_NONE || c >= v->n_caches) continue;
        const lc_lcb_cache *k = &v->caches[c];
        if (k->index != t) continue; /* a dilated copy: below */
        lmf_tap *slot = f->taps + 9 * t;
        uint32_t n = 0;
        if (lmf_owner(v, (uint32_t)t)) n = lmf_texel_taps(v, (uint32_t)(t % W), (uint32_t)(t / W), k, slot);
        else slot[n++] = (lmf_tap){(uint32_t)t, 1.0f};
        f->filtered += n > 1;
        own_taps[2 * t] = (uint32_t)(9 * t);
        own_taps[2 * t + 1] = n;
    }
    /* Compact: texel t reads its owner's taps (its own, or its cache's texel's). */
    lmf_tap *packed = malloc((texels ? texels : 1) * 9 * sizeof *packed);
    if (!packed) goto oom;
    uint32_t used = 0;
    for (size_t t = 0; t < texels; t++) {
        f->start[t] = used;
        uint32_t c = v->lightmap[t];
        if (c == LC_NONE || c >= v->n_caches) continue;
        uint32_t owner = v->caches[c].index;
        if (owner >= texels) continue;
        uint32_t first = own_taps[2 * owner], n = own_taps[2 * owner + 1];
        memcpy(packed + used, f->taps + first, n * sizeof *packed);
        used += n;
    }
    f->start[texels] = used;
    free(f->taps);
    f->taps = packed;
    free(own_taps);
    return f;
oom:
    lc_set_err(err, errlen, "out of memory for the lightmap filter (%zu texels)", texels);
    free(own_taps);
    lc_lmfilter_release(f);
    return NULL;
}

/* Luminance (Rec. 709). */
static float lmf_luma(const float *c) { return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2]; }

typedef struct {
    const lc_lmfilter *f;
    const float *in;
    float *out;
} lmf_job;

static void lmf_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const lmf_job *job = ctx;
    const lc_lmfilter *f = job->f;
    const float *in = job->in;
    float *out = job->out;
    const float inv_sigma2 = 1.0f / (LC_LMFILTER_RANGE * LC_LMFILTER_RANGE);
    for (size_t t = begin; t < end; t++) {
        uint32_t first = f->start[t], end = f->start[t + 1];
        float *o = out + 3 * (size_t)t;
        if (first == end) {
            o[0] = o[1] = o[2] = 0;
            continue;
        }
        /* taps[first] is the texel's owner itself: the range weight compares with it */
        const float *self = in + 3 * (size_t)f->taps[first].texel;
        float y0 = lmf_luma(self), r = 0, g = 0, b = 0, wsum = 0;
        for (uint32_t i = first; i < end; i++) {
            const float *s = in + 3 * (size_t)f->taps[i].texel;
            float w = f->taps[i].weight;
            if (i > first) {
                float d = (lmf_luma(s) - y0) / fmaxf(y0, 1e-20f);
                w *= expf(-d * d * inv_sigma2);
            }
            r += w * s[0];
            g += w * s[1];
            b += w * s[2];
            wsum += w;
        }
        o[0] = r / wsum;
        o[1] = g / wsum;
        o[2] = b / wsum;
    }
}

void lc_lmfilter_apply(const lc_lmfilter *f, const float *in, float *out, int threads) {
    lmf_job job = {f, in, out};
    lc_parallel_for(threads, f->texels, 2048, lmf_range, &job);
}

uint32_t lc_lmfilter_filtered_texels(const lc_lmfilter *f) { return f ? f->filtered : 0; }

void lc_lmfilter_release(lc_lmfilter *f) {
    if (!f) return;
    free(f->start);
    free(f->taps);
    free(f);
}
