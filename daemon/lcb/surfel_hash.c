/* surfel_hash: hit point -> surfel (surfel_hash.h). */
#include "lcb/surfel_hash.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static inline uint64_t surfel_hash_cell_key(int32_t x, int32_t y, int32_t z) {
    return ((uint64_t)(uint32_t)(x + (1 << 20)) & 0x1FFFFF) | (((uint64_t)(uint32_t)(y + (1 << 20)) & 0x1FFFFF) << 21) |
        (((uint64_t)(uint32_t)(z + (1 << 20)) & 0x1FFFFF) << 42);
}

static inline uint32_t surfel_hash_slot(const lc_surfel_hash *h, uint64_t key) {
    uint64_t x = key * 0x9E3779B97F4A7C15ull;
    return (uint32_t)(x >> 32) & h->mask;
}

void lc_surfel_hash_free(lc_surfel_hash *h) {
    free(h->keys);
    free(h->start);
    free(h->count);
    free(h->items);
    memset(h, 0, sizeof *h);
}

typedef struct {
    uint64_t key;
    uint32_t surfel;
} surfel_hash_keyed;

static int surfel_hash_keyed_cmp(const void *a, const void *b) {
    const surfel_hash_keyed *x = a, *y = b;
    if (x->key != y->key) return x->key < y->key ? -1 : 1;
    return (x->surfel > y->surfel) - (x->surfel < y->surfel);
}

int lc_surfel_hash_build(lc_surfel_hash *h, const lc_lcb_surfel *surfels, uint32_t n) {
    memset(h, 0, sizeof *h);
    surfel_hash_keyed *kv = malloc((size_t)n * sizeof *kv);
    if (!kv) return -1;
    float lo[3] = {INFINITY, INFINITY, INFINITY};
    double mean_area = 0;
    for (uint32_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) lo[a] = fminf(lo[a], surfels[i].position[a]);
        mean_area += surfels[i].area;
    }
    mean_area /= n;
    /* ~2 surfels per cell on a plane: the nearest surfel lies in the 27 cells around a hit. */
    float cell = (float)(1.5 * sqrt(mean_area));
    if (!(cell > 0)) cell = 1e-3f;
    h->inv_cell = 1.0f / cell;
    memcpy(h->origin, lo, sizeof lo);
    for (uint32_t i = 0; i < n; i++) {
        int32_t c[3];
        for (int a = 0; a < 3; a++) c[a] = (int32_t)floorf((surfels[i].position[a] - lo[a]) * h->inv_cell);
        kv[i] = (surfel_hash_keyed){surfel_hash_cell_key(c[0], c[1], c[2]), i};
    }
    qsort(kv, n, sizeof *kv, surfel_hash_keyed_cmp);
    uint32_t cells = 0;
    for (uint32_t i = 0; i < n; i++) cells += i == 0 || kv[i].key != kv[i - 1].key;
    uint32_t size = 16;
    while (size < 2 * cells) size <<= 1;
    h->mask = size - 1;
    h->keys = calloc(size, sizeof *h->keys);
    h->start = calloc(size, sizeof *h->start);
    h->count = calloc(size, sizeof *h->count);
    h->items = malloc((size_t)n * sizeof *h->items);
    if (!h->keys || !h->start || !h->count || !h->items) {
        free(kv);
        lc_surfel_hash_free(h);
        return -1;
    }
    for (uint32_t i = 0; i < n; i++) {
        h->items[i] = kv[i].surfel;
        if (i > 0 && kv[i].key == kv[i - 1].key) continue;
        uint32_t slot = surfel_hash_slot(h, kv[i].key);
        while (h->keys[slot]) slot = (slot + 1) & h->mask;
        h->keys[slot] = kv[i].key + 1;
        h->start[slot] = i;
        uint32_t j = i;
        while (j < n && kv[j].key == kv[i].key) j++;
        h->count[slot] = j - i;
    }
    free(kv);
    return 0;
}

/* Nearest surfel to a probe hit that faces the ray origin and lies on a surface oriented
 * like the hit (so the two sides of a thin wall stay apart); LC_NONE if none nearby. */
uint32_t lc_surfel_hash_nearest(const lc_surfel_hash *h, const lc_lcb_surfel *surfels, const float p[3],
                                const float ng[3], const float dir[3]) {
    int32_t c[3];
    for (int a = 0; a < 3; a++) c[a] = (int32_t)floorf((p[a] - h->origin[a]) * h->inv_cell);
    for (int strict = 1; strict >= 0; strict--) {
        for (int r = 1; r <= 3; r += 2) { /* 3x3x3, then 7x7x7 for sparse spots */
            uint32_t best = LC_NONE;
            float best_d2 = INFINITY;
            for (int dz = -r; dz <= r; dz++)
                for (int dy = -r; dy <= r; dy++)
                    for (int dx = -r; dx <= r; dx++) {
                        if (r == 3 && abs(dx) <= 1 && abs(dy) <= 1 && abs(dz) <= 1) continue;
                        uint64_t key = surfel_hash_cell_key(c[0] + dx, c[1] + dy, c[2] + dz);
                        uint32_t slot = surfel_hash_slot(h, key);
                        while (h->keys[slot] && h->keys[slot] != key + 1) slot = (slot + 1) & h->mask;
                        if (!h->keys[slot]) continue;
                        for (uint32_t k = 0; k < h->count[slot]; k++) {
                            uint32_t si = h->items[h->start[slot] + k];
                            const lc_lcb_surfel *s = &surfels[si];
                            if (strict) {
                                float facing = -(s->normal[0] * dir[0] + s->normal[1] * dir[1] + s->normal[2] * dir[2]);
                                float along = s->normal[0] * ng[0] + s->normal[1] * ng[1] + s->normal[2] * ng[2];
                                if (facing <= 0 || along < 0.5f) continue;
                            }
                            float d2 = 0, plane = 0;
                            for (int a = 0; a < 3; a++) {
                                d2 += (s->position[a] - p[a]) * (s->position[a] - p[a]);
                                plane += (p[a] - s->position[a]) * s->normal[a];
                            }
                            d2 += LC_SURFEL_HASH_PLANE_WEIGHT * plane * plane;
                            if (d2 < best_d2 || (d2 == best_d2 && si < best)) {
                                best_d2 = d2;
                                best = si;
                            }
                        }
                    }
            if (best != LC_NONE) return best;
        }
    }
    return LC_NONE;
}
