/* probes: the probes solver's runtime (probes.h). Runs on the engine's thread. */
#include "engine/probes.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "engine/transport.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/sh.h"

struct lc_probes {
    const lc_lcb_view *v;
    uint32_t coeffs;
    float *ray_sh;    /* n_rays x coeffs: y_j(dir_k) x (4 pi / n_rays) / pi */
    float *lambda;    /* n_probes x coeffs x 3 */
    float *basis_out; /* per cluster rank x 3, at b_off */
    uint64_t *b_off;  /* per cluster */
    uint32_t *active; /* per cluster: lc_probes_active_clusters */
    uint32_t *list;   /* the active clusters of this gather */
    uint32_t n_list;
    float *cache_sh;  /* the gather's target (borrowed for one call) */
    const float *rad; /* the gather's radiosity (borrowed for one call) */
    uint32_t bands, stride;
};

lc_probes *lc_probes_create(const lc_lcb_view *v, char *err, size_t errlen) {
    const lc_lcb_probe_header *h = v->probe_header;
    if (!h) {
        lc_set_err(err, errlen,
                   "probes solver: the bake has none (bake with lucent-bake bake --solver probes or both)");
        return NULL;
    }
    lc_probes *p = calloc(1, sizeof *p);
    if (!p) goto oom;
    p->v = v;
    p->coeffs = h->sh_bands * h->sh_bands;
    p->ray_sh = malloc((size_t)h->n_rays * p->coeffs * sizeof *p->ray_sh);
    p->lambda = malloc((size_t)h->n_probes * p->coeffs * 3 * sizeof *p->lambda);
    p->b_off = malloc(((size_t)h->n_clusters + 1) * sizeof *p->b_off);
    p->active = malloc(((size_t)h->n_clusters + 1) * sizeof *p->active);
    p->list = malloc(((size_t)h->n_clusters + 1) * sizeof *p->list);
    if (!p->ray_sh || !p->lambda || !p->b_off || !p->active || !p->list) goto oom;
    lc_probes_ray_sh(h, p->ray_sh);
    uint64_t at = 0;
    for (uint32_t c = 0; c < h->n_clusters; c++) {
        p->b_off[c] = at;
        at += (uint64_t)v->probe_clusters[c].rank * 3;
    }
    p->basis_out = malloc((at + 1) * sizeof *p->basis_out);
    if (!p->basis_out) goto oom;
    return p;
oom:
    lc_probes_release(p);
    lc_set_err(err, errlen, "probes solver: out of memory");
    return NULL;
}

void lc_probes_ray_sh(const lc_lcb_probe_header *h, float *out) {
    const uint32_t nc = h->sh_bands * h->sh_bands;
    float y[LC_SH_MAX_COEFFS];
    for (uint32_t k = 0; k < h->n_rays; k++) {
        float d[3];
        lc_probe_ray_dir(k, h->n_rays, d);
        lc_sh_eval((int)h->sh_bands, d, y);
        for (uint32_t j = 0; j < nc; j++) out[(size_t)k * nc + j] = y[j] * 4.0f / (float)h->n_rays;
    }
}

void lc_probes_release(lc_probes *p) {
    if (!p) return;
    free(p->ray_sh);
    free(p->lambda);
    free(p->basis_out);
    free(p->b_off);
    free(p->active);
    free(p->list);
    free(p);
}

const float *lc_probes_sh(const lc_probes *p) { return p->lambda; }

/* lambda[p][j] = sum_k B[hit] / pi * y_j(dir_k) * 4 pi / n_rays */
static void probes_sh_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    lc_probes *p = ctx;
    const lc_lcb_probe_header *h = p->v->probe_header;
    const uint32_t nc = p->coeffs;
    for (size_t i = begin; i < end; i++) {
        float *lam = p->lambda + i * nc * 3;
        memset(lam, 0, (size_t)nc * 3 * sizeof *lam);
        const uint32_t *hits = p->v->probe_hits + i * h->n_rays;
        for (uint32_t k = 0; k < h->n_rays; k++) {
            if (hits[k] == LC_NONE) continue;
            const float *b = p->rad + 3 * (size_t)hits[k], *ys = p->ray_sh + (size_t)k * nc;
            for (uint32_t j = 0; j < nc; j++) {
                lam[j] += ys[j] * b[0];
                lam[nc + j] += ys[j] * b[1];
                lam[2 * nc + j] += ys[j] * b[2];
            }
        }
    }
}

/* A cluster's row value into its cache's record (probes.h: how each kind of cache holds it). */
static void probes_store(const lc_probes *p, const lc_lcb_probe_row *row, const float e[3]) {
    const lc_lcb_cache *c = &p->v->caches[row->cache];
    float *dst = p->cache_sh + (size_t)row->cache * p->stride * 3;
    if (c->flags & LC_CACHE_TEXEL) {
        lc_transport_texel_store(dst, c->normal, p->bands, e);
        return;
    }
    uint32_t j = row->coeff;
    if (j >= p->bands * p->bands) return;
    const float inv_a = (float)(1.0 / lc_sh_cosine_factor(j == 0 ? 0 : j < 4 ? 1 : 2));
    for (int k = 0; k < 3; k++) dst[3 * j + k] = e[k] * inv_a;
}

uint32_t lc_probes_active_clusters(const lc_lcb_view *v, const uint8_t *need, uint32_t *active) {
    const lc_lcb_probe_header *h = v->probe_header;
    uint32_t n = 0;
    for (uint32_t c = 0; c < h->n_clusters; c++) {
        const lc_lcb_probe_cluster *cl = &v->probe_clusters[c];
        uint32_t on = 0;
        for (uint32_t i = 0; i < cl->n_rows && !on; i++) on = need[v->probe_rows[cl->first_row + i].cache];
        active[c] = on;
        n += on;
    }
    return n;
}

/* The row's unseen rays, straight from the surfels they hit (lcb.h: PRUF/PRUS). */
static void probes_add_unseen(const lc_probes *p, uint32_t row, float e[3]) {
    const lc_lcb_view *v = p->v;
    for (uint32_t k = v->probe_unseen_first[row]; k < v->probe_unseen_first[row + 1]; k++) {
        const lc_lcb_probe_unseen *u = &v->probe_unseen[k];
        const float *b = p->rad + 3 * (size_t)u->surfel;
        e[0] += u->weight * b[0];
        e[1] += u->weight * b[1];
        e[2] += u->weight * b[2];
    }
}

/* Per active cluster: b = (S V^T) lambda, then each row's U . b (plus its unseen rays). */
static void probes_cluster_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    lc_probes *p = ctx;
    const lc_lcb_view *v = p->v;
    const uint32_t nc = p->coeffs;
    for (size_t li = begin; li < end; li++) {
        const uint32_t ci = p->list[li];
        const lc_lcb_probe_cluster *cl = &v->probe_clusters[ci];
        const uint32_t *probes = v->probe_cluster_probes + cl->first_probe;
        const uint32_t cols = cl->n_probes * nc;
        float *b = p->basis_out + p->b_off[ci];
        for (uint32_t r = 0; r < cl->rank; r++) {
            const float *row = v->probe_basis + cl->basis_offset + (size_t)r * cols;
            /* 8 lanes per channel, summed at the end: vectorises without reassociating */
            float a[3][8] = {{0}};
            for (uint32_t q = 0; q < cl->n_probes; q++) {
                const float *lam = p->lambda + (size_t)probes[q] * nc * 3, *w = row + (size_t)q * nc;
                uint32_t j = 0;
                for (; j + 8 <= nc; j += 8)
                    for (int l = 0; l < 8; l++) {
                        a[0][l] += w[j + l] * lam[j + l];
                        a[1][l] += w[j + l] * lam[nc + j + l];
                        a[2][l] += w[j + l] * lam[2 * nc + j + l];
                    }
                for (int l = 0; j < nc; j++, l++) {
                    a[0][l] += w[j] * lam[j];
                    a[1][l] += w[j] * lam[nc + j];
                    a[2][l] += w[j] * lam[2 * nc + j];
                }
            }
            for (int ch = 0; ch < 3; ch++)
                b[3 * r + ch] =
                    ((a[ch][0] + a[ch][1]) + (a[ch][2] + a[ch][3])) + ((a[ch][4] + a[ch][5]) + (a[ch][6] + a[ch][7]));
        }
        for (uint32_t i = 0; i < cl->n_rows; i++) {
            const float *u = v->probe_u + cl->u_offset + (size_t)i * cl->rank;
            float e[3] = {0, 0, 0};
            for (uint32_t r = 0; r < cl->rank; r++) {
                e[0] += u[r] * b[3 * r + 0];
                e[1] += u[r] * b[3 * r + 1];
                e[2] += u[r] * b[3 * r + 2];
            }
            if (v->probe_unseen_first) probes_add_unseen(p, cl->first_row + i, e);
            probes_store(p, &v->probe_rows[cl->first_row + i], e);
        }
    }
}

void lc_probes_gather(lc_probes *p, const float *radiosity, uint32_t bands, float *cache_sh, uint32_t stride,
                      const uint8_t *need, int threads) {
    const lc_lcb_view *v = p->v;
    const uint32_t nc = bands * bands;
    for (uint32_t c = 0; c < v->n_caches; c++)
        memset(cache_sh + (size_t)c * stride * 3, 0, (size_t)nc * 3 * sizeof *cache_sh);
    p->rad = radiosity;
    p->cache_sh = cache_sh;
    p->bands = bands;
    p->stride = stride;
    p->n_list = 0;
    if (need) lc_probes_active_clusters(v, need, p->active);
    for (uint32_t c = 0; c < v->probe_header->n_clusters; c++)
        if (!need || p->active[c]) p->list[p->n_list++] = c;
    lc_parallel_for(threads, v->probe_header->n_probes, 4, probes_sh_range, p);
    lc_parallel_for(threads, p->n_list, 4, probes_cluster_range, p);
    p->rad = NULL;
    p->cache_sh = NULL;
}
