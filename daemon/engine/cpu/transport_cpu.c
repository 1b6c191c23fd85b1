/* transport_cpu: the reference implementation of the transport pipeline (transport.h) in
 * C11 with lc_parallel_for across caches. Runs on the engine's (compute) thread. */
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "engine/probes.h"
#include "engine/transport.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/sh.h"

#define TCPU_MAX_COEFFS LC_SH_MAX_COEFFS

typedef struct tcpu {
    const lc_lcb_view *v;
    uint32_t cells;
    uint32_t coeff_cap;       /* bands^2 the buffers are sized for */
    lc_transport_outputs out; /* what the frame publishes; cache SH at a stride of coeff_cap */
    float *e_ind;             /* n_surfels*3, kept across runs for progressive feedback */
    uint8_t *feedback_cache;  /* per cache: some surfel reads it */
    uint32_t *feedback_list;  /* those caches */
    uint32_t n_feedback;
    uint8_t *need;       /* per cache: this pass computes it (lc_transport_needed) */
    uint32_t *need_list; /* those caches, for a last pass under grid_cells NEEDED */
    float *texel_w;      /* n_texel_caches*links_per_cache*3: tcpu_texel_weights */
    float *dnrt_c;       /* DNRT objects' incident SH, 27 each */
    size_t dnrt_cap;
    uint32_t *dnrt_list; /* their corner caches outside the feedback list */
    uint32_t n_dnrt_list, dnrt_list_cap;
    float cone[256][8];
    int threads;       /* the parallel-for's workers: the engine's setting */
    lc_probes *probes; /* the probes solver, made on first use (settings.solver probes) */
} tcpu;

static void tcpu_texel_weights(const lc_lcb_view *v, const float cone[256][8], float *out);

static void tcpu_release(void *impl) {
    tcpu *t = impl;
    if (!t) return;
    lc_transport_outputs_release(&t->out);
    free(t->e_ind);
    free(t->feedback_cache);
    free(t->feedback_list);
    free(t->need);
    free(t->need_list);
    free(t->texel_w);
    free(t->dnrt_c);
    free(t->dnrt_list);
    lc_probes_release(t->probes);
    free(t);
}

static void *tcpu_create(const lc_lcb_view *v, int threads, char *err, size_t errlen) {
    tcpu *t = calloc(1, sizeof *t);
    if (!t) goto oom;
    t->v = v;
    t->threads = threads;
    t->cells = v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    t->coeff_cap = LC_SH_MAX_COEFFS;
    if (lc_transport_outputs_alloc(&t->out, v) != 0) goto oom;
    t->e_ind = calloc((size_t)v->n_surfels * 3, sizeof(float));
    t->feedback_cache = calloc(v->n_caches ? v->n_caches : 1, 1);
    t->feedback_list = calloc(v->n_caches ? v->n_caches : 1, sizeof(uint32_t));
    t->need = calloc(v->n_caches ? v->n_caches : 1, 1);
    t->need_list = calloc(v->n_caches ? v->n_caches : 1, sizeof(uint32_t));
    t->texel_w = malloc(((size_t)v->n_texel_caches * v->links_per_cache * 3 + 1) * sizeof(float));
    if (!t->e_ind || !t->feedback_cache || !t->feedback_list || !t->need || !t->need_list || !t->texel_w) goto oom;
    for (uint32_t s = 0; s < v->n_surfels; s++)
        if (v->surfels[s].cache != LC_NONE) t->feedback_cache[v->surfels[s].cache] = 1;
    for (uint32_t c = 0; c < v->n_caches; c++)
        if (t->feedback_cache[c]) t->feedback_list[t->n_feedback++] = c;
    lc_transport_cone_table(t->cone);
    tcpu_texel_weights(v, t->cone, t->texel_w);
    return t;
oom:
    tcpu_release(t);
    lc_set_err(err, errlen, "cpu transport: out of memory for %u caches x %u SH coefficients", v->n_caches,
               (unsigned)LC_SH_MAX_COEFFS);
    return NULL;
}

/* --- pull ------------------------------------------------------------------------------------ */

/* Leaves hold B * area; internal nodes the sum of their children. BFS order puts children
 * after parents, so one reverse sweep pulls everything up. */
static void tcpu_pull(tcpu *t) {
    const lc_lcb_view *v = t->v;
    for (uint32_t i = v->n_nodes; i-- > 0;) {
        const lc_lcb_node *nd = &v->nodes[i];
        float *f = t->out.flux + 3 * (size_t)i;
        if (nd->child[0] == LC_NONE) {
            const lc_lcb_surfel *s = &v->surfels[nd->first_surfel];
            const float *b = t->out.radiosity + 3 * (size_t)nd->first_surfel;
            for (int k = 0; k < 3; k++) f[k] = b[k] * s->area;
        } else {
            const float *a = t->out.flux + 3 * (size_t)nd->child[0], *b = t->out.flux + 3 * (size_t)nd->child[1];
            for (int k = 0; k < 3; k++) f[k] = a[k] + b[k];
        }
    }
}

/* --- gather ---------------------------------------------------------------------------------- */

typedef struct {
    tcpu *t;
    const uint32_t *list; /* cache indices, or NULL = all caches */
    int bands, chroma_bands;
    int chroma;                   /* flux is YCoCg: Co/Cg use chroma_bands only */
    int texel_bands;              /* bands gathered at texel caches (see lc_transport_texel_bands) */
    int texel_band1;              /* texel caches: band 1 from the precomputed weights (lc_transport_texel_band1) */
    int texel_surfels;            /* texel caches from their surfel lists (lc_transport_texel_surfels) */
    const lc_transport_input *in; /* its interrupt, asked once per range */
    atomic_int *interrupted;      /* set once the interrupt said stop: the other ranges skip */
} tcpu_gather_job;

/* Any of the relight's threads: whether to stop this relight now (lc_engine_set_interrupt). */
static int tcpu_interrupted(const lc_transport_input *in, atomic_int *interrupted) {
    if (!in->interrupt) return 0;
    if (atomic_load_explicit(interrupted, memory_order_relaxed)) return 1;
    if (!in->interrupt(in->interrupt_arg)) return 0;
    atomic_store_explicit(interrupted, 1, memory_order_relaxed);
    return 1;
}

static inline void tcpu_oct_decode(uint32_t packed, float d[3]) {
    float u = (float)(packed & 0xFFFu) * (2.0f / 4095.0f) - 1.0f;
    float w = (float)((packed >> 12) & 0xFFFu) * (2.0f / 4095.0f) - 1.0f;
    float z = 1.0f - fabsf(u) - fabsf(w);
    if (z < 0) {
        float uu = (1 - fabsf(w)) * (u >= 0 ? 1.0f : -1.0f);
        float ww = (1 - fabsf(u)) * (w >= 0 ? 1.0f : -1.0f);
        u = uu;
        w = ww;
    }
    float inv = 1.0f / sqrtf(u * u + w * w + z * z);
    d[0] = u * inv;
    d[1] = w * inv;
    d[2] = z * inv;
}

/* The band-1 weights w_m of transport.h for every texel cache (caches [0, n_texel_caches)):
 * out[3 * (cache * links_per_cache + k) + m - 1] for m = 1..3 (y, z, x), 0 for padding. */
static void tcpu_texel_weights(const lc_lcb_view *v, const float cone[256][8], float *out) {
    const uint32_t nl = v->links_per_cache;
    const float k1 = 0.488602511903f; /* y_1m = k1 (y, z, x) */
    for (uint32_t c = 0; c < v->n_texel_caches; c++) {
        float *w = out + (size_t)c * nl * 3;
        memset(w, 0, (size_t)nl * 3 * sizeof *w);
        const lc_lcb_link *lk = v->links + (size_t)c * nl;
        for (uint32_t k = 0; k < v->caches[c].link_count; k++) {
            float d[3];
            tcpu_oct_decode(lk[k].dir_cone, d);
            float f = lk[k].factor * cone[lk[k].dir_cone >> 24][1] * k1;
            w[3 * k + 0] = f * d[1];
            w[3 * k + 1] = f * d[2];
            w[3 * k + 2] = f * d[0];
        }
    }
}

#define TCPU_BLOCK 16

/* The gather's AVX2 clone is picked by an ifunc resolver at load time; ThreadSanitizer's
 * instrumentation of that resolver runs before its runtime is up and crashes, so the TSan
 * build keeps one plain version. */
#if defined(__SANITIZE_THREAD__)
#define TCPU_CLONES
#else
#define TCPU_CLONES __attribute__((target_clones("avx2", "default")))
#endif

/* Blocked gather for bands <= 4, the common case: links in blocks of 16 as structure-of-
 * arrays so the octahedral decode, the SH basis and the accumulation vectorise; per-lane
 * partial sums avoid float reductions (which the compiler may not reorder). Built for AVX2
 * and a baseline, chosen at load time. Writes acc[channel][coefficient]. */
TCPU_CLONES static void tcpu_gather_blocked(const tcpu *t, const lc_lcb_link *lk, uint32_t used, int bands, int ncc,
                                            float acc[3][16]) {
    float lane[3][16][TCPU_BLOCK];
    memset(lane, 0, sizeof lane);
    const int nc = bands * bands;
    for (uint32_t k0 = 0; k0 < used; k0 += TCPU_BLOCK) {
        uint32_t n = used - k0 < TCPU_BLOCK ? used - k0 : TCPU_BLOCK;
        float p0[TCPU_BLOCK], p1[TCPU_BLOCK], p2[TCPU_BLOCK], hl[4][TCPU_BLOCK];
        float dx[TCPU_BLOCK], dy[TCPU_BLOCK], dz[TCPU_BLOCK];
        uint32_t packed[TCPU_BLOCK];
        for (uint32_t i = 0; i < TCPU_BLOCK; i++) { /* gathers: not vectorised, kept apart */
            if (i < n) {
                const lc_lcb_link *l = &lk[k0 + i];
                const float *phi = t->out.flux + 3 * (size_t)l->node;
                p0[i] = phi[0] * l->factor;
                p1[i] = phi[1] * l->factor;
                p2[i] = phi[2] * l->factor;
                packed[i] = l->dir_cone;
                const float *h = t->cone[l->dir_cone >> 24];
                for (int b = 0; b < 4; b++) hl[b][i] = h[b];
            } else {
                p0[i] = p1[i] = p2[i] = 0;
                packed[i] = 0;
                for (int b = 0; b < 4; b++) hl[b][i] = 0;
            }
        }
        for (uint32_t i = 0; i < TCPU_BLOCK; i++) { /* octahedral decode, branch-free */
            float u = (float)(packed[i] & 0xFFFu) * (2.0f / 4095.0f) - 1.0f;
            float w = (float)((packed[i] >> 12) & 0xFFFu) * (2.0f / 4095.0f) - 1.0f;
            float z = 1.0f - fabsf(u) - fabsf(w);
            float fold = z < 0 ? -z : 0.0f;
            u += u >= 0 ? -fold : fold;
            w += w >= 0 ? -fold : fold;
            float inv = 1.0f / sqrtf(u * u + w * w + z * z);
            dx[i] = u * inv;
            dy[i] = w * inv;
            dz[i] = z * inv;
        }
        /* Only the bands in use: the higher bands are most of the per-link work. */
        float y[16][TCPU_BLOCK];
        for (uint32_t i = 0; i < TCPU_BLOCK; i++) {
            float x = dx[i], yy = dy[i], z = dz[i];
            y[0][i] = 0.282094791774f * hl[0][i];
            y[1][i] = 0.488602511903f * yy * hl[1][i];
            y[2][i] = 0.488602511903f * z * hl[1][i];
            y[3][i] = 0.488602511903f * x * hl[1][i];
        }
        if (bands >= 3)
            for (uint32_t i = 0; i < TCPU_BLOCK; i++) {
                float x = dx[i], yy = dy[i], z = dz[i];
                y[4][i] = 1.092548430592f * x * yy * hl[2][i];
                y[5][i] = 1.092548430592f * yy * z * hl[2][i];
                y[6][i] = 0.315391565253f * (3.0f * z * z - 1.0f) * hl[2][i];
                y[7][i] = 1.092548430592f * x * z * hl[2][i];
                y[8][i] = 0.546274215296f * (x * x - yy * yy) * hl[2][i];
            }
        if (bands >= 4)
            for (uint32_t i = 0; i < TCPU_BLOCK; i++) {
                float x = dx[i], yy = dy[i], z = dz[i], z2 = z * z;
                y[9][i] = 0.590043589927f * yy * (3.0f * x * x - yy * yy) * hl[3][i];
                y[10][i] = 2.890611442641f * x * yy * z * hl[3][i];
                y[11][i] = 0.457045799464f * yy * (5.0f * z2 - 1.0f) * hl[3][i];
                y[12][i] = 0.373176332590f * z * (5.0f * z2 - 3.0f) * hl[3][i];
                y[13][i] = 0.457045799464f * x * (5.0f * z2 - 1.0f) * hl[3][i];
                y[14][i] = 1.445305721321f * z * (x * x - yy * yy) * hl[3][i];
                y[15][i] = 0.590043589927f * x * (x * x - 3.0f * yy * yy) * hl[3][i];
            }
        for (int j = 0; j < nc; j++)
            for (uint32_t i = 0; i < TCPU_BLOCK; i++) lane[0][j][i] += y[j][i] * p0[i];
        for (int j = 0; j < ncc; j++)
            for (uint32_t i = 0; i < TCPU_BLOCK; i++) {
                lane[1][j][i] += y[j][i] * p1[i];
                lane[2][j][i] += y[j][i] * p2[i];
            }
    }
    for (int ch = 0; ch < 3; ch++)
        for (int j = 0; j < 16; j++) {
            float sum = 0;
            if (j < nc)
                for (uint32_t i = 0; i < TCPU_BLOCK; i++) sum += lane[ch][j][i];
            acc[ch][j] = sum;
        }
}

/* A texel cache's band 1 from the precomputed weights (transport.h): acc[channel][1..3];
 * sixteen partial sums per accumulator, like the blocked gather. */
static void tcpu_gather_texel(const tcpu *t, const lc_lcb_link *lk, const float *w, uint32_t used, float acc[3][16]) {
    float lane[3][3][TCPU_BLOCK];
    memset(lane, 0, sizeof lane);
    for (uint32_t k0 = 0; k0 < used; k0 += TCPU_BLOCK) {
        uint32_t n = used - k0 < TCPU_BLOCK ? used - k0 : TCPU_BLOCK;
        for (uint32_t i = 0; i < n; i++) {
            const float *phi = t->out.flux + 3 * (size_t)lk[k0 + i].node, *wk = w + 3 * (size_t)(k0 + i);
            for (int ch = 0; ch < 3; ch++)
                for (int m = 0; m < 3; m++) lane[ch][m][i] += phi[ch] * wk[m];
        }
    }
    for (int ch = 0; ch < 3; ch++) {
        acc[ch][0] = 0;
        for (int m = 0; m < 3; m++) {
            float sum = 0;
            for (uint32_t i = 0; i < TCPU_BLOCK; i++) sum += lane[ch][m][i];
            acc[ch][1 + m] = sum;
        }
    }
}

/* Any bands (1..8): one link at a time through the generic SH evaluation. */
static void tcpu_gather_generic(const tcpu *t, const lc_lcb_link *lk, uint32_t used, int bands, int ncc,
                                float acc[3][TCPU_MAX_COEFFS]) {
    static const int band_of[TCPU_MAX_COEFFS] = {0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4,
                                                 4, 4, 4, 5, 5, 5, 5, 5, 5, 5, 5, 5, 5, 5, 6, 6, 6, 6, 6, 6, 6, 6,
                                                 6, 6, 6, 6, 6, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7};
    const int nc = bands * bands;
    memset(acc, 0, 3 * TCPU_MAX_COEFFS * sizeof(float));
    for (uint32_t k = 0; k < used; k++) {
        const float *phi = t->out.flux + 3 * (size_t)lk[k].node;
        float d[3], y[TCPU_MAX_COEFFS];
        tcpu_oct_decode(lk[k].dir_cone, d);
        lc_sh_eval_fast(bands, d[0], d[1], d[2], y);
        const float *h = t->cone[lk[k].dir_cone >> 24];
        float f = lk[k].factor;
        float p0 = phi[0] * f, p1 = phi[1] * f, p2 = phi[2] * f;
        for (int j = 0; j < nc; j++) {
            float w = h[band_of[j]] * y[j];
            acc[0][j] += w * p0;
            if (j < ncc) {
                acc[1][j] += w * p1;
                acc[2][j] += w * p2;
            }
        }
    }
}

/* A texel cache from its surfel list (TSGF/TSGW): E = sum weight x B, stored as
 * lc_transport_texel_store; out holds nc coefficients. Four partial sums per channel: one
 * sum's chain of dependent adds bounded this loop (Sponza's gather 16.2 -> 14.4 ms). */
static void tcpu_gather_texel_surfels(const tcpu *t, uint32_t c, int bands, float *out) {
    enum { LANES = 4 };
    const lc_lcb_view *v = t->v;
    const lc_lcb_surfel_weight *w = v->texel_surfels + v->texel_surfels_first[c];
    const uint32_t n = v->texel_surfels_first[c + 1] - v->texel_surfels_first[c];
    const float *rad = t->out.radiosity;
    float lane[3][LANES] = {{0}};
    uint32_t k = 0;
    for (; k + LANES <= n; k += LANES)
        for (int i = 0; i < LANES; i++) {
            const float *b = rad + 3 * (size_t)w[k + i].surfel, f = w[k + i].weight;
            lane[0][i] += f * b[0];
            lane[1][i] += f * b[1];
            lane[2][i] += f * b[2];
        }
    for (; k < n; k++) {
        const float *b = rad + 3 * (size_t)w[k].surfel, f = w[k].weight;
        lane[0][0] += f * b[0];
        lane[1][0] += f * b[1];
        lane[2][0] += f * b[2];
    }
    float e[3];
    for (int ch = 0; ch < 3; ch++) e[ch] = (lane[ch][0] + lane[ch][1]) + (lane[ch][2] + lane[ch][3]);
    memset(out, 0, (size_t)bands * bands * 3 * sizeof *out);
    lc_transport_texel_store(out, v->caches[c].normal, (uint32_t)bands, e);
}

static void tcpu_gather_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const tcpu_gather_job *job = ctx;
    tcpu *t = job->t;
    const lc_lcb_view *v = t->v;
    if (job->in && tcpu_interrupted(job->in, job->interrupted)) return;
    const int nc = job->bands * job->bands;
    const int ncc_all = job->chroma ? job->chroma_bands * job->chroma_bands : nc;
    const uint32_t nl = v->links_per_cache;
    for (size_t i = begin; i < end; i++) {
        uint32_t c = job->list ? job->list[i] : (uint32_t)i;
        if (job->texel_surfels && c < v->n_texel_caches) {
            tcpu_gather_texel_surfels(t, c, job->bands, t->out.cache_sh + (size_t)c * t->coeff_cap * 3);
            continue;
        }
        const lc_lcb_link *lk = lc_lcb_cache_links(v, c, NULL);
        uint32_t used = v->caches[c].link_count;
        const int bands = (v->caches[c].flags & LC_CACHE_TEXEL) ? job->texel_bands : job->bands;
        const int ncu = bands * bands, ncc = ncc_all < ncu ? ncc_all : ncu;
        float acc[3][TCPU_MAX_COEFFS];
        if (job->texel_band1 && c < v->n_texel_caches) {
            float a16[3][16];
            tcpu_gather_texel(t, lk, t->texel_w + (size_t)c * nl * 3, used, a16);
            for (int ch = 0; ch < 3; ch++) memcpy(acc[ch], a16[ch], 4 * sizeof(float));
        } else if (bands <= 4) {
            float a16[3][16];
            tcpu_gather_blocked(t, lk, used, bands, ncc, a16);
            for (int ch = 0; ch < 3; ch++) memcpy(acc[ch], a16[ch], sizeof a16[ch]);
        } else {
            tcpu_gather_generic(t, lk, used, bands, ncc, acc);
        }
        float *out = t->out.cache_sh + (size_t)c * t->coeff_cap * 3;
        for (int j = 0; j < nc; j++) {
            if (j >= ncu) { /* bands this cache does not carry */
                out[3 * j + 0] = out[3 * j + 1] = out[3 * j + 2] = 0;
                continue;
            }
            float a = acc[0][j], b = j < ncc ? acc[1][j] : 0, g = j < ncc ? acc[2][j] : 0;
            if (job->chroma) { /* Y, Co, Cg -> RGB (Malvar-Sullivan YCoCg-R, linear) */
                float tt = a - g;
                out[3 * j + 1] = a + g;
                out[3 * j + 2] = tt - b;
                out[3 * j + 0] = tt + b;
            } else {
                out[3 * j + 0] = a;
                out[3 * j + 1] = b;
                out[3 * j + 2] = g;
            }
        }
    }
}

/* --- irradiance ------------------------------------------------------------------------------ */

/* Irradiance at a cache for normal n (see transport.h for the two formulas). */
static inline void tcpu_irradiance(const float *sh, int bands, int texel, const float n[3], float e[3]) {
    float y[16];
    lc_sh_eval_fast(bands < 3 ? bands : 3, n[0], n[1], n[2], y);
    if (texel) {
        if (bands < 2) {
            for (int k = 0; k < 3; k++) e[k] = fmaxf(0.0f, (float)(2.0 * M_PI) * sh[k] * y[0]);
            return;
        }
        const float w = (float)(4.0 * M_PI / 3.0);
        for (int k = 0; k < 3; k++) e[k] = fmaxf(0.0f, w * (sh[3 + k] * y[1] + sh[6 + k] * y[2] + sh[9 + k] * y[3]));
        return;
    }
    static const float a[3] = {(float)M_PI, (float)(2.0 * M_PI / 3.0), (float)(M_PI / 4.0)};
    int nc = bands >= 3 ? 9 : bands * bands;
    for (int k = 0; k < 3; k++) {
        float s = 0;
        for (int j = 0; j < nc; j++) s += a[j == 0 ? 0 : j < 4 ? 1 : 2] * sh[3 * j + k] * y[j];
        e[k] = fmaxf(0.0f, s);
    }
}

typedef struct {
    tcpu *t;
    int bands;
} tcpu_feedback_job;

static void tcpu_feedback_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const tcpu_feedback_job *job = ctx;
    tcpu *t = job->t;
    const lc_lcb_view *v = t->v;
    for (size_t s = begin; s < end; s++) {
        const lc_lcb_surfel *sf = &v->surfels[s];
        float *e = t->e_ind + 3 * s;
        if (sf->cache == LC_NONE) {
            e[0] = e[1] = e[2] = 0;
            continue;
        }
        const float *sh = t->out.cache_sh + (size_t)sf->cache * t->coeff_cap * 3;
        tcpu_irradiance(sh, job->bands, (v->caches[sf->cache].flags & LC_CACHE_TEXEL) != 0, sf->normal, e);
    }
}

/* The grid's L2 irradiance SH at p: trilinear over the corner caches, each cosine-convolved
 * as the grid output is (tcpu_grid), from the caches as they are now. */
static void tcpu_grid_sample(const tcpu *t, const uint32_t corner[8], const float w[8], int bands, float out[27]) {
    static const float a[9] = {(float)M_PI,           (float)(2 * M_PI / 3), (float)(2 * M_PI / 3),
                               (float)(2 * M_PI / 3), (float)(M_PI / 4),     (float)(M_PI / 4),
                               (float)(M_PI / 4),     (float)(M_PI / 4),     (float)(M_PI / 4)};
    int nc9 = bands >= 3 ? 9 : bands * bands;
    memset(out, 0, 27 * sizeof(float));
    for (int c = 0; c < 8; c++) {
        if (w[c] == 0) continue;
        const float *sh = t->out.cache_sh + (size_t)corner[c] * t->coeff_cap * 3;
        for (int j = 0; j < nc9; j++)
            for (int k = 0; k < 3; k++) {
                float g = a[j] * sh[3 * j + k];
                out[3 * j + k] += w[c] * g;
            }
    }
}

/* --- passes ---------------------------------------------------------------------------------- */

/* B = B0 + albedo E_ind at every surfel. */
static void tcpu_radiosity(tcpu *t, const float *b0) {
    const lc_lcb_view *v = t->v;
    for (uint32_t s = 0; s < v->n_surfels; s++) {
        const float *alb = v->surfels[s].albedo;
        for (int k = 0; k < 3; k++) t->out.radiosity[3 * s + k] = b0[3 * s + k] + alb[k] * t->e_ind[3 * s + k];
    }
}

/* The pull is linear, so chroma compression converts once at the nodes: RGB -> Y, Co, Cg. */
static void tcpu_to_ycocg(tcpu *t) {
    for (uint32_t i = 0; i < t->v->n_nodes; i++) {
        float *f = t->out.flux + 3 * (size_t)i;
        float co = (f[0] - f[2]) * 0.5f, tt = f[2] + co, cg = (f[1] - tt) * 0.5f;
        f[0] = tt + cg;
        f[1] = co;
        f[2] = cg;
    }
}

/* Lightmap: each texel shows its cache's irradiance for the cache normal. */
static int tcpu_lightmap(tcpu *t, const lc_engine_settings *st, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    const size_t cap = t->coeff_cap, texels = (size_t)v->lightmap_width * v->lightmap_height;
    for (size_t i = 0; i < texels; i++) {
        uint32_t c = v->lightmap[i];
        float *e = t->out.lightmap + 3 * i;
        if (c == LC_NONE) {
            e[0] = e[1] = e[2] = 0;
            continue;
        }
        tcpu_irradiance(t->out.cache_sh + (size_t)c * cap * 3, (int)st->bands, 1, v->caches[c].normal, e);
    }
    return st->sh_lightmap ? lc_transport_fill_lightmap_sh(&t->out, v, "cpu", err, errlen) : 0;
}

/* Grid: cosine-convolved L2 irradiance SH per sample. */
static void tcpu_grid(tcpu *t, int bands) {
    const lc_lcb_view *v = t->v;
    static const float a[9] = {(float)M_PI,           (float)(2 * M_PI / 3), (float)(2 * M_PI / 3),
                               (float)(2 * M_PI / 3), (float)(M_PI / 4),     (float)(M_PI / 4),
                               (float)(M_PI / 4),     (float)(M_PI / 4),     (float)(M_PI / 4)};
    int nc9 = bands >= 3 ? 9 : bands * bands;
    for (uint32_t i = 0; i < t->cells; i++) {
        uint32_t c = v->grid[i];
        float *g = t->out.grid_sh + (size_t)i * 27;
        memset(g, 0, 27 * sizeof(float));
        const float *sh = t->out.cache_sh + (size_t)c * t->coeff_cap * 3;
        for (int j = 0; j < nc9; j++)
            for (int k = 0; k < 3; k++) g[3 * j + k] = a[j] * sh[3 * j + k];
    }
}

/* Objects: each one's L2 irradiance SH, trilinear in the grid at its position, from the
 * caches before any object's change (DNRT adds the other objects' changes after). */
static int tcpu_objects(tcpu *t, const lc_transport_input *in, int bands, char *err, size_t errlen) {
    if (lc_transport_reserve_objects(&t->out, in->n_objects, "cpu", err, errlen) != 0) return -1;
    for (uint32_t i = 0; i < in->n_objects; i++) {
        uint32_t corner[8];
        float w[8];
        lc_dnrt_grid_corners(t->v, in->object_pos + 3 * (size_t)i, corner, w);
        tcpu_grid_sample(t, corner, w, bands, t->out.object_sh + 27 * (size_t)i);
    }
    return 0;
}

/* DNRT after a pass's gather (engine/dnrt.h): each object's incident SH from its corner
 * caches (gathered in intermediate passes too), then the receivers' sums; in the last pass
 * the other objects' changes go into the objects' SH. */
static int tcpu_dnrt(tcpu *t, const lc_transport_input *in, int last, char *err, size_t errlen) {
    const lc_dnrt_frame *f = in->dnrt;
    const lc_engine_settings *st = &in->settings;
    if ((size_t)f->n_objects * 27 > t->dnrt_cap) {
        float *c = realloc(t->dnrt_c, (size_t)f->n_objects * 27 * sizeof *c);
        if (!c) {
            lc_set_err(err, errlen, "cpu transport: out of memory for %u objects' SH", f->n_objects);
            return -1;
        }
        t->dnrt_c = c;
        t->dnrt_cap = (size_t)f->n_objects * 27;
    }
    for (uint32_t i = 0; i < f->n_objects; i++)
        tcpu_grid_sample(t, f->objects[i].corner, f->objects[i].corner_w, (int)st->bands, t->dnrt_c + 27 * (size_t)i);
    int tb = lc_transport_texel_bands(st);
    lc_dnrt_target tg = {.cache_sh = t->out.cache_sh,
                         .stride = t->coeff_cap,
                         .n_texel_caches = t->v->n_texel_caches,
                         .texel_lo = lc_transport_texel_band1(st) ? 1 : 0,
                         .texel_nc = tb * tb,
                         .grid_nc = (int)(st->bands * st->bands),
                         .fresh = last ? NULL : t->feedback_cache,
                         .object_delta = last ? t->out.object_sh : NULL};
    lc_dnrt_apply(f, t->dnrt_c, &tg);
    return 0;
}

/* The corner caches of the DNRT objects that intermediate passes do not gather anyway. */
static int tcpu_dnrt_corner_list(tcpu *t, const lc_dnrt_frame *f, char *err, size_t errlen) {
    uint32_t need = f->n_objects * 8;
    if (need > t->dnrt_list_cap) {
        uint32_t *l = realloc(t->dnrt_list, need * sizeof *l);
        if (!l) {
            lc_set_err(err, errlen, "cpu transport: out of memory for %u objects", f->n_objects);
            return -1;
        }
        t->dnrt_list = l;
        t->dnrt_list_cap = need;
    }
    t->n_dnrt_list = 0;
    for (uint32_t i = 0; i < f->n_objects; i++)
        for (int k = 0; k < 8; k++) {
            uint32_t c = f->objects[i].corner[k];
            int seen = t->feedback_cache[c];
            for (uint32_t j = 0; j < t->n_dnrt_list && !seen; j++) seen = t->dnrt_list[j] == c;
            if (!seen) t->dnrt_list[t->n_dnrt_list++] = c;
        }
    return 0;
}

/* Clutter operators after DNRT (engine/drt.h): intermediate passes change only the caches
 * they gathered, the last pass all. */
static void tcpu_drt(tcpu *t, const lc_transport_input *in, int last) {
    const lc_engine_settings *st = &in->settings;
    int tb = lc_transport_texel_bands(st);
    lc_drt_target tg = {.node_flux = t->out.flux,
                        .flux_ycocg = lc_transport_chroma(st),
                        .cache_sh = t->out.cache_sh,
                        .stride = t->coeff_cap,
                        .n_texel_caches = t->v->n_texel_caches,
                        .texel_lo = lc_transport_texel_band1(st) ? 1 : 0,
                        .texel_nc = tb * tb,
                        .grid_nc = (int)(st->bands * st->bands),
                        .fresh = last ? NULL : t->feedback_cache};
    lc_drt_apply(in->drt, in->n_drt, &tg);
}

/* --- run ------------------------------------------------------------------------------------- */

static int tcpu_run(void *impl, const lc_transport_input *in, lc_engine_frame *fr, char *err, size_t errlen) {
    tcpu *t = impl;
    const lc_lcb_view *v = t->v;
    const lc_engine_settings *st = &in->settings;
    int bands = (int)st->bands;
    int chroma = lc_transport_chroma(st);
    if (lc_transport_check_settings(st, err, errlen) != 0) return -1;
    double t1;
    if (in->reset_feedback) memset(t->e_ind, 0, (size_t)v->n_surfels * 3 * sizeof(float));
    double ms_pull = 0, ms_gather = 0, ms_bounce = 0, ms_dnrt = 0, ms_drt = 0;
    if (in->dnrt && tcpu_dnrt_corner_list(t, in->dnrt, err, errlen) != 0) return -1;
    const int probes = st->solver == LC_SOLVER_PROBES;
    if (probes && !t->probes && !(t->probes = lc_probes_create(v, err, errlen))) return -1;

    atomic_int interrupted = 0;
    for (uint32_t pass = 0; pass <= st->bounces; pass++) {
        int last = pass == st->bounces;
        if (tcpu_interrupted(in, &interrupted)) return LC_ENGINE_INTERRUPTED;
        t1 = lc_clock_ms();
        tcpu_radiosity(t, in->b0);
        double t2 = lc_clock_ms();
        ms_bounce += t2 - t1;
        tcpu_pull(t);
        if (chroma) tcpu_to_ycocg(t);
        double t3 = lc_clock_ms();
        ms_pull += t3 - t2;
        /* Intermediate passes only need the caches some surfel reads; the last one every
         * cache, or under grid_cells NEEDED the texel caches and what reads the grid. */
        tcpu_gather_job job = {t,
                               last ? NULL : t->feedback_list,
                               bands,
                               (int)st->chroma_bands,
                               chroma,
                               lc_transport_texel_bands(st),
                               lc_transport_texel_band1(st),
                               lc_transport_texel_surfels(v, st),
                               in,
                               &interrupted};
        uint32_t n_gather = last ? v->n_caches : t->n_feedback;
        if (probes || (last && st->grid_cells == LC_GRID_NEEDED)) {
            n_gather = lc_transport_needed(v, t->feedback_cache, in, last, t->need);
            if (!probes) {
                for (uint32_t c = 0, n = 0; c < v->n_caches; c++)
                    if (t->need[c]) t->need_list[n++] = c;
                job.list = t->need_list;
            }
        }
        if (probes) /* clusters holding a needed row; the DNRT corners included */
            lc_probes_gather(t->probes, t->out.radiosity, (uint32_t)bands, t->out.cache_sh, t->coeff_cap, t->need,
                             t->threads);
        else lc_parallel_for(t->threads, n_gather, 64, tcpu_gather_range, &job);
        /* Past here a pass writes the carried light (feedback): stop before it or not at all. */
        if (tcpu_interrupted(in, &interrupted)) return LC_ENGINE_INTERRUPTED;
        job.in = NULL; /* the DNRT's few caches below gather whole */
        double t4 = lc_clock_ms();
        ms_gather += t4 - t3;
        if (last) { /* the objects' SH before any object changes the caches */
            if (tcpu_objects(t, in, bands, err, errlen) != 0) return -1;
            double t5 = lc_clock_ms();
            fr->stage_ms[LC_STAGE_OBJECTS] = t5 - t4;
            t4 = t5;
        }
        if (in->dnrt) {
            if (!last && t->n_dnrt_list && !probes) {
                job.list = t->dnrt_list; /* a few caches: on this thread (a fork-join costs more) */
                tcpu_gather_range(&job, 0, t->n_dnrt_list, 0);
            }
            if (tcpu_dnrt(t, in, last, err, errlen) != 0) return -1;
            double t5 = lc_clock_ms();
            ms_dnrt += t5 - t4;
            t4 = t5;
        }
        if (in->n_drt) {
            tcpu_drt(t, in, last);
            double t5 = lc_clock_ms();
            ms_drt += t5 - t4;
            t4 = t5;
        }
        /* Feedback for the next pass (and, progressive, for the next relight). */
        tcpu_feedback_job fj = {t, bands};
        lc_parallel_for(t->threads, v->n_surfels, 1024, tcpu_feedback_range, &fj);
        ms_bounce += lc_clock_ms() - t4;
    }
    fr->stage_ms[LC_STAGE_BOUNCE] = ms_bounce;
    fr->stage_ms[LC_STAGE_PULL] = ms_pull;
    fr->stage_ms[LC_STAGE_GATHER] = ms_gather;
    fr->stage_ms[LC_STAGE_CHROMA] = 0;

    t1 = lc_clock_ms();
    if (tcpu_lightmap(t, st, err, errlen) != 0) return -1;
    double t2 = lc_clock_ms();
    fr->stage_ms[LC_STAGE_LIGHTMAP] = t2 - t1;
    tcpu_grid(t, bands);
    if (st->grid_cells == LC_GRID_NEEDED) lc_transport_clear_unneeded_cells(&t->out, v, t->need);
    fr->stage_ms[LC_STAGE_GRID] = lc_clock_ms() - t2;
    fr->stage_ms[LC_STAGE_DNRT] = ms_dnrt;
    fr->stage_ms[LC_STAGE_DRT] = ms_drt;
    lc_transport_publish(&t->out, st, fr);
    return 0;
}

const lc_transport_ops lc_transport_cpu = {"cpu", tcpu_create, tcpu_release, tcpu_run};
