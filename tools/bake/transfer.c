/* transfer: the DNRT transfer grid of an asset (transfer.h). Runs on the bake's thread,
 * parallel over grid vertices. */
#include "bake/transfer.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bake/rt.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/rng.h"
#include "util/sh.h"

#define TRANSFER_MAX_VALUES 36 /* 9 coefficients x (3 T + 1 K) */

typedef struct {
    const lc_scene *asset;
    const lc_rt *rt;
    const lc_transfer_params *p;
    float center[3], radius, half;
    int nv;        /* values per vertex: coeffs * 4 */
    float *values; /* dims^3 * nv, before normalisation and quantisation */
    uint8_t *inside;
} transfer_job;

static void transfer_vertex_pos(const transfer_job *j, size_t idx, float p[3]) {
    size_t d = (size_t)j->p->dims, ijk[3] = {idx % d, (idx / d) % d, idx / (d * d)};
    for (int k = 0; k < 3; k++) p[k] = j->center[k] - j->half + 2.0f * j->half * (float)ijk[k] / (float)(d - 1);
}

/* An orthonormal frame (t, b) around unit n. */
static void transfer_frame(const float n[3], float t[3], float b[3]) {
    float a[3] = {fabsf(n[0]) < 0.9f ? 1.0f : 0.0f, fabsf(n[0]) < 0.9f ? 0.0f : 1.0f, 0};
    float d = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
    for (int k = 0; k < 3; k++) t[k] = a[k] - d * n[k];
    float l = sqrtf(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
    for (int k = 0; k < 3; k++) t[k] /= l;
    b[0] = n[1] * t[2] - n[2] * t[1];
    b[1] = n[2] * t[0] - n[0] * t[2];
    b[2] = n[0] * t[1] - n[1] * t[0];
}

/* The hit's shading normal, turned to face the ray's origin. */
static void transfer_hit_normal(const lc_mesh *m, const lc_hit *h, const float dir[3], float n[3]) {
    const uint32_t *tri = m->index + 3 * (size_t)h->prim;
    float b0 = 1.0f - h->b1 - h->b2;
    for (int k = 0; k < 3; k++)
        n[k] = b0 * m->normal[3 * (size_t)tri[0] + k] + h->b1 * m->normal[3 * (size_t)tri[1] + k] +
            h->b2 * m->normal[3 * (size_t)tri[2] + k];
    float l = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(l > 1e-12f)) {
        memcpy(n, h->ng, 3 * sizeof(float));
        l = 1;
    }
    float s = (n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]) > 0 ? -1.0f / l : 1.0f / l;
    for (int k = 0; k < 3; k++) n[k] *= s;
}

static void transfer_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const transfer_job *j = ctx;
    const int nc = j->p->coeffs, rays = j->p->rays;
    const lc_mesh *m = &j->asset->mesh;
    for (size_t idx = begin; idx < end; idx++) {
        float p[3], no[3], t[3], b[3];
        transfer_vertex_pos(j, idx, p);
        for (int k = 0; k < 3; k++) no[k] = j->center[k] - p[k];
        float d = sqrtf(no[0] * no[0] + no[1] * no[1] + no[2] * no[2]);
        if (d > 1e-6f * j->radius)
            for (int k = 0; k < 3; k++) no[k] /= d;
        else no[0] = 0, no[1] = 1, no[2] = 0;
        transfer_frame(no, t, b);
        /* Outside the bounding sphere: the cone it subtends; inside: the whole sphere. */
        int cone = d > j->radius * 1.0001f;
        float cos_max = cone ? sqrtf(1.0f - (j->radius / d) * (j->radius / d)) : -1.0f;
        float omega = 2.0f * (float)M_PI * (1.0f - cos_max);
        lc_rng rng = lc_rng_seed(j->p->seed ^ 0xD4E7u, idx);
        float rot = lc_rng_float(&rng);
        float acc[TRANSFER_MAX_VALUES] = {0};
        int back = 0, hits = 0;
        for (int r = 0; r < rays; r++) {
            float u = ((float)r + lc_rng_float(&rng)) / (float)rays;
            float ct = 1.0f - u * (1.0f - cos_max), st = sqrtf(fmaxf(0.0f, 1.0f - ct * ct));
            float phi = 2.0f * (float)M_PI * ((float)r * 0.6180339887f + rot);
            float lx = st * cosf(phi), ly = st * sinf(phi);
            float w[3] = {lx * t[0] + ly * b[0] + ct * no[0], lx * t[1] + ly * b[1] + ct * no[1],
                          lx * t[2] + ly * b[2] + ct * no[2]};
            lc_hit h;
            if (!lc_rt_intersect(j->rt, p, w, 0.0f, INFINITY, &h)) continue;
            hits++;
            back += h.backface;
            if (ct <= 0) continue; /* (w . n_o)+ */
            float weight = omega / (float)rays * ct / (float)M_PI;
            float ns[3], rho[3], ys[9], yw[9];
            transfer_hit_normal(m, &h, w, ns);
            lc_scene_albedo(j->asset, h.prim, h.b1, h.b2, rho);
            lc_sh_eval_fast(nc == 9 ? 3 : 2, ns[0], ns[1], ns[2], ys);
            lc_sh_eval_fast(nc == 9 ? 3 : 2, w[0], w[1], w[2], yw);
            for (int c = 0; c < nc; c++) {
                for (int ch = 0; ch < 3; ch++) acc[3 * c + ch] += weight * rho[ch] * ys[c];
                acc[3 * nc + c] += weight * yw[c];
            }
        }
        j->inside[idx] = !cone && hits > 0 && 2 * back >= rays;
        memcpy(j->values + idx * (size_t)j->nv, acc, (size_t)j->nv * sizeof(float));
    }
}

/* Inside vertices take the mean of their outside (or already filled) 6-neighbours, front by
 * front, so the field next to the surface continues the outside's. */
static uint32_t transfer_fill_inside(transfer_job *j) {
    const size_t d = (size_t)j->p->dims, n = d * d * d, nv = (size_t)j->nv;
    uint32_t filled_total = 0;
    uint8_t *next = malloc(n);
    if (!next) return 0;
    for (int pass = 0; pass < 3 * j->p->dims; pass++) {
        memcpy(next, j->inside, n);
        uint32_t filled = 0;
        for (size_t idx = 0; idx < n; idx++) {
            if (!j->inside[idx]) continue;
            size_t x = idx % d, y = (idx / d) % d, z = idx / (d * d);
            size_t nb[6];
            int k = 0;
            if (x > 0) nb[k++] = idx - 1;
            if (x + 1 < d) nb[k++] = idx + 1;
            if (y > 0) nb[k++] = idx - d;
            if (y + 1 < d) nb[k++] = idx + d;
            if (z > 0) nb[k++] = idx - d * d;
            if (z + 1 < d) nb[k++] = idx + d * d;
            float sum[TRANSFER_MAX_VALUES] = {0};
            int cnt = 0;
            for (int i = 0; i < k; i++) {
                if (j->inside[nb[i]]) continue;
                for (size_t c = 0; c < nv; c++) sum[c] += j->values[nb[i] * nv + c];
                cnt++;
            }
            if (!cnt) continue;
            for (size_t c = 0; c < nv; c++) j->values[idx * nv + c] = sum[c] / (float)cnt;
            next[idx] = 0;
            filled++;
        }
        memcpy(j->inside, next, n);
        filled_total += filled;
        if (!filled) break;
    }
    free(next);
    return filled_total;
}

/* Multiplies by g (lcb.h), then quantises with one scale per coefficient and channel. */
static void transfer_quantise(const transfer_job *j, lc_lcb_transfer *hdr, int8_t *out) {
    const size_t n = (size_t)j->p->dims * j->p->dims * j->p->dims, nv = (size_t)j->nv;
    const int nc = j->p->coeffs;
    float maxabs[TRANSFER_MAX_VALUES] = {0};
    for (size_t idx = 0; idx < n; idx++) {
        float p[3];
        transfer_vertex_pos(j, idx, p);
        float dx = p[0] - j->center[0], dy = p[1] - j->center[1], dz = p[2] - j->center[2];
        float r = fmaxf(sqrtf(dx * dx + dy * dy + dz * dz), j->radius) / j->radius;
        float *v = j->values + idx * nv;
        for (size_t c = 0; c < nv; c++) {
            v[c] *= r * r;
            maxabs[c] = fmaxf(maxabs[c], fabsf(v[c]));
        }
    }
    memset(hdr->t_scale, 0, sizeof hdr->t_scale);
    memset(hdr->k_scale, 0, sizeof hdr->k_scale);
    for (int c = 0; c < nc; c++) {
        for (int ch = 0; ch < 3; ch++) hdr->t_scale[3 * c + ch] = maxabs[3 * c + ch];
        hdr->k_scale[c] = maxabs[3 * nc + c];
    }
    for (size_t idx = 0; idx < n; idx++)
        for (size_t c = 0; c < nv; c++) {
            float s = maxabs[c];
            out[idx * nv + c] = s > 0 ? (int8_t)lrintf(j->values[idx * nv + c] / s * 127.0f) : 0;
        }
}

int lc_transfer_bake(const lc_scene *asset, const lc_transfer_params *p, lc_lcb_transfer *hdr, int8_t **values,
                     lc_transfer_stats *stats, char *err, size_t errlen) {
    double t0 = lc_clock_ms();
    transfer_job j;
    memset(&j, 0, sizeof j);
    lc_rt *rt = NULL;
    int8_t *out = NULL;
    *values = NULL;
    if (p->dims < 2 || p->dims > 64 || (p->coeffs != 4 && p->coeffs != 9) || p->rays < 1 || p->rays > 65536 ||
        !(p->extent >= 1 && p->extent <= 100) || !(p->outer >= 1 && p->outer <= 100)) {
        lc_set_err(err, errlen, "transfer: dims 2..64, coeffs 4|9, rays 1..65536, extent and outer 1..100");
        return -1;
    }
    const lc_mesh *m = &asset->mesh;
    if (m->n_triangles == 0) {
        lc_set_err(err, errlen, "transfer: the asset has no triangles");
        return -1;
    }
    /* Bounding sphere: the box centre and the farthest vertex from it. */
    float r2 = 0;
    for (int k = 0; k < 3; k++) j.center[k] = 0.5f * (asset->bounds_min[k] + asset->bounds_max[k]);
    for (uint32_t v = 0; v < m->n_vertices; v++) {
        const float *q = m->position + 3 * (size_t)v;
        float dx = q[0] - j.center[0], dy = q[1] - j.center[1], dz = q[2] - j.center[2];
        r2 = fmaxf(r2, dx * dx + dy * dy + dz * dz);
    }
    j.radius = sqrtf(r2);
    if (!(j.radius > 0)) {
        lc_set_err(err, errlen, "transfer: the asset has zero size");
        return -1;
    }
    j.half = p->extent * j.radius;
    j.asset = asset;
    j.p = p;
    j.nv = p->coeffs * 4;
    const size_t n = (size_t)p->dims * p->dims * p->dims;
    j.values = malloc(n * (size_t)j.nv * sizeof(float));
    j.inside = calloc(n, 1);
    out = malloc(n * (size_t)j.nv);
    if (!j.values || !j.inside || !out) {
        lc_set_err(err, errlen, "transfer: out of memory for %zu grid vertices", n);
        goto err;
    }
    if (!(rt = lc_rt_create(m, p->threads, err, errlen))) goto err;
    j.rt = rt;
    lc_parallel_for(p->threads, n, 64, transfer_range, &j);
    uint32_t inside = 0;
    for (size_t i = 0; i < n; i++) inside += j.inside[i];
    transfer_fill_inside(&j);
    memset(hdr, 0, sizeof *hdr);
    hdr->dims = (uint32_t)p->dims;
    hdr->coeffs = (uint32_t)p->coeffs;
    hdr->rays = (uint32_t)p->rays;
    memcpy(hdr->center, j.center, sizeof hdr->center);
    hdr->radius = j.radius;
    hdr->half_extent = j.half;
    hdr->outer_radius = j.half * p->outer;
    transfer_quantise(&j, hdr, out);
    lc_rt_release(rt);
    free(j.values);
    free(j.inside);
    *values = out;
    if (stats) {
        stats->seconds = (lc_clock_ms() - t0) * 1e-3;
        stats->inside_vertices = inside;
        stats->bytes = lc_lcb_transfer_bytes(hdr);
    }
    return 0;
err:
    lc_rt_release(rt);
    free(j.values);
    free(j.inside);
    free(out);
    return -1;
}
