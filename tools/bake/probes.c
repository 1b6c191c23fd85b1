/* probes: the bake half of the probes solver (probes.h has the method). Runs on the bake's
 * thread; the stages fan out with lc_parallel_for. */
#include "bake/probes.h"

#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "lcb/surfel_hash.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/ray_offset.h"
#include "util/rng.h"
#include "util/sh.h"
#include "util/vec.h"

#define PB_MIN_SUPPORT 4u            /* a receiver uses at least this many probes, however far */
#define PB_TEST_DIRS 26              /* placement test rays: the cube's faces, edges and corners */
#define PB_MAX_PROBES 4096           /* the target count at most */
#define PB_RECEIVERS_PER_PROBE 400.0 /* the automatic count's floor: a probe per this many texel caches */
#define PB_GRID_ROWS 9               /* a grid cache's rows: its L2 irradiance SH */
#define PB_MAX_CANDIDATES 64         /* probes a receiver's support is chosen from (2 x overlaps, at most) */

/* The SH basis of a relight or receiver direction: the closed forms up to 4 bands (faster, and
 * what the runtime's GL shaders use), lc_sh_eval's recurrences above. */
static void pb_sh_eval(int bands, const float d[3], float *out) {
    if (bands <= 4) lc_sh_eval_fast(bands, d[0], d[1], d[2], out);
    else lc_sh_eval(bands, d, out);
}

/* --- the job ------------------------------------------------------------------------------- */

/* A receiver: a cache with its supporting probes and its rows' values, each row
 * n_sup x coeffs (probe-major) at a stride of overlaps x coeffs. */
typedef struct {
    uint32_t cache;
    uint32_t n_rows; /* 1 (texel), 9 (grid) or 0 (inside geometry) */
    uint32_t n_sup;
    uint32_t first_row; /* into pb_job.rows */
} pb_recv;

/* A receiver's unseen rays by surfel: n_surfels entries per row, row after row (the weights
 * differ per row of a grid cache, the surfels do not). n_surfels UINT32_MAX: out of memory. */
typedef struct {
    lc_lcb_probe_unseen *e;
    uint32_t n_surfels;
} pb_unseen;

/* A row before compression: which receiver and coefficient, where (for the split). */
typedef struct {
    uint32_t recv, coeff, group;
    float pos[3];
} pb_row;

typedef struct {
    const lc_rt *rt;
    const lc_lcb_surfel *surfels;
    uint32_t n_surfels;
    const lc_lcb_cache *caches;
    uint32_t n_caches, n_texel; /* n_texel: the texel caches among them */
    const lc_probebake_params *prm;
    lc_surfel_hash hash;
    uint32_t coeffs;
    double band_w2[LC_SH_MAX_COEFFS]; /* per coefficient: the SVD's column weight squared */
    lc_vec3 bmin, bmax;
    /* placement */
    float *cand; /* candidates' positions, 3 each */
    uint8_t *cand_ok;
    uint32_t n_cand_grid;
    lc_lcb_probe *probes;
    uint32_t n_probes;
    float radius;
    /* transport */
    pb_recv *recv;
    uint32_t *sup; /* per receiver: overlaps probe indices */
    float *sup_w;  /* ... and their kernel weights */
    float *vals;   /* per row: overlaps x coeffs */
    size_t row_stride;
    pb_row *rows;
    uint32_t n_rows;
    uint64_t *ray_count; /* per receiver */
    uint64_t *orphans;   /* per receiver */
    uint32_t n_recv;
    pb_unseen *unseen;      /* per receiver (empty where prm->unseen skips its kind) */
    void *hit_scratch;      /* per thread: receiver_rays hits (pb_hit) */
    uint32_t *pair_scratch; /* per thread: receiver_rays x 2 (pb_unseen_gather) */
    lc_progress *progress;
} pb_job;

static float pb_kernel(float t) { return t >= 1.0f ? 0.0f : (2.0f * t - 3.0f) * t * t + 1.0f; }

static float pb_dist2(const float a[3], const float b[3]) {
    float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return dx * dx + dy * dy + dz * dz;
}

/* --- 1. placement -------------------------------------------------------------------------- */

static void pb_test_dir(int i, float d[3]) {
    int k = 0;
    for (int x = -1; x <= 1; x++)
        for (int y = -1; y <= 1; y++)
            for (int z = -1; z <= 1; z++) {
                if (!x && !y && !z) continue;
                if (k++ == i) {
                    float len = sqrtf((float)(x * x + y * y + z * z));
                    d[0] = x / len, d[1] = y / len, d[2] = z / len;
                    return;
                }
            }
}

typedef struct {
    pb_job *j;
    float h; /* candidate spacing */
    int relaxed;
} pb_place_ctx;

/* A candidate is kept when no test ray sees a back face (not inside) and the nearest surface
 * is between h/4 and 2h away (thesis 3.2.2.1: empty, next to a surface). Open space (over a
 * roof, under the sky) keeps its probes: grid cells there are lit by what they see. */
static void pb_place_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    pb_place_ctx *pc = ctx;
    pb_job *j = pc->j;
    for (size_t i = begin; i < end; i++) {
        const float *p = j->cand + 3 * i;
        int inside = 0, escaped = 0;
        float dmin = INFINITY;
        for (int k = 0; k < PB_TEST_DIRS && !inside; k++) {
            float d[3];
            pb_test_dir(k, d);
            lc_hit hit;
            if (!lc_rt_intersect(j->rt, p, d, 0.0f, INFINITY, &hit)) {
                escaped++;
                continue;
            }
            if (hit.backface) inside = 1;
            dmin = fminf(dmin, hit.t);
        }
        int ok = !inside && escaped < PB_TEST_DIRS;
        if (!pc->relaxed) ok = ok && dmin >= 0.25f * pc->h && dmin <= 2.0f * pc->h;
        j->cand_ok[i] = (uint8_t)ok;
    }
}

/* Weighted elimination: the densest candidate goes (ties: the later one) until `target`
 * remain. Densities within 2 rho, updated as neighbours go. */
static uint32_t pb_thin(const float *pos, uint32_t n, uint32_t target, float rho, uint8_t *keep) {
    float r = 2.0f * rho, r2 = r * r;
    double *dens = calloc(n ? n : 1, sizeof *dens);
    if (!dens) return 0;
    for (uint32_t a = 0; a < n; a++)
        for (uint32_t b = a + 1; b < n; b++) {
            float d2 = pb_dist2(pos + 3 * a, pos + 3 * b);
            if (d2 >= r2) continue;
            double w = pb_kernel(sqrtf(d2) / r);
            dens[a] += w, dens[b] += w;
        }
    uint32_t left = n;
    for (uint32_t a = 0; a < n; a++) keep[a] = 1;
    while (left > target) {
        uint32_t worst = LC_NONE;
        for (uint32_t a = 0; a < n; a++)
            if (keep[a] && (worst == LC_NONE || dens[a] >= dens[worst])) worst = a;
        keep[worst] = 0;
        left--;
        for (uint32_t b = 0; b < n; b++) {
            if (!keep[b]) continue;
            float d2 = pb_dist2(pos + 3 * worst, pos + 3 * b);
            if (d2 < r2) dens[b] -= pb_kernel(sqrtf(d2) / r);
        }
    }
    free(dens);
    return left;
}

static int pb_place(pb_job *j, char *err, size_t errlen) {
    const lc_probebake_params *prm = j->prm;
    lc_vec3 ext = lc_v3_sub(j->bmax, j->bmin);
    double ex = fmax(ext.x, 1e-3), ey = fmax(ext.y, 1e-3), ez = fmax(ext.z, 1e-3), volume = ex * ey * ez;
    /* Auto: the density, but at least one probe per PB_RECEIVERS_PER_PROBE texel caches (a
     * furnished room's volume gives too few: the conference room 8, 43.6% error; 64, 22.5%). */
    double by_receivers = ceil((double)j->n_texel / PB_RECEIVERS_PER_PROBE);
    double want =
        prm->count ? prm->count : fmin(PB_MAX_PROBES, fmax(8.0, fmax(round(volume * prm->density), by_receivers)));
    uint32_t target = (uint32_t)want;
    float rho = (float)cbrt(volume / want), h = 0.5f * rho;
    uint32_t dims[3] = {(uint32_t)fmax(1, ceil(ex / h)), (uint32_t)fmax(1, ceil(ey / h)),
                        (uint32_t)fmax(1, ceil(ez / h))};
    size_t n = (size_t)dims[0] * dims[1] * dims[2];
    if (n > 4000000) {
        lc_set_err(err, errlen, "probes: %zu placement voxels; lower --probes", n);
        return -1;
    }
    j->cand = malloc(n * 3 * sizeof(float));
    j->cand_ok = malloc(n);
    if (!j->cand || !j->cand_ok) goto oom;
    for (uint32_t z = 0, i = 0; z < dims[2]; z++)
        for (uint32_t y = 0; y < dims[1]; y++)
            for (uint32_t x = 0; x < dims[0]; x++, i++) {
                j->cand[3 * i + 0] = j->bmin.x + (float)((x + 0.5) * ex / dims[0]);
                j->cand[3 * i + 1] = j->bmin.y + (float)((y + 0.5) * ey / dims[1]);
                j->cand[3 * i + 2] = j->bmin.z + (float)((z + 0.5) * ez / dims[2]);
            }
    uint32_t kept = 0;
    for (int relaxed = 0; relaxed < 2 && kept == 0; relaxed++) { /* relaxed: any free voxel */
        pb_place_ctx pc = {j, h, relaxed};
        lc_parallel_for(prm->threads, n, 16, pb_place_range, &pc);
        kept = 0;
        for (size_t i = 0; i < n; i++)
            if (j->cand_ok[i]) memmove(j->cand + 3 * kept++, j->cand + 3 * i, 3 * sizeof(float));
    }
    j->n_cand_grid = kept;
    if (kept == 0) {
        lc_set_err(err, errlen, "probes: no free space inside the scene for a probe (is the mesh closed inside out?)");
        return -1;
    }
    uint8_t *keep = malloc(kept);
    if (!keep) goto oom;
    uint32_t left = kept <= target ? kept : pb_thin(j->cand, kept, target, rho, keep);
    if (kept <= target) memset(keep, 1, kept);
    j->probes = calloc(left ? left : 1, sizeof *j->probes);
    if (!left || !j->probes) {
        free(keep);
        goto oom;
    }
    for (uint32_t i = 0, k = 0; i < kept; i++)
        if (keep[i]) memcpy(j->probes[k++].position, j->cand + 3 * i, 3 * sizeof(float));
    j->n_probes = left;
    free(keep);
    return 0;
oom:
    lc_set_err(err, errlen, "probes: out of memory placing probes");
    return -1;
}

/* --- 2. relight rays ----------------------------------------------------------------------- */

typedef struct {
    pb_job *j;
    uint32_t *hits;
} pb_relight_ctx;

static void pb_relight_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    pb_relight_ctx *rc = ctx;
    pb_job *j = rc->j;
    const uint32_t n = j->prm->relight_rays;
    for (size_t p = begin; p < end; p++) {
        const float *o = j->probes[p].position;
        for (uint32_t k = 0; k < n; k++) {
            float d[3];
            lc_probe_ray_dir(k, n, d);
            lc_hit hit;
            uint32_t s = LC_NONE;
            if (lc_rt_intersect(j->rt, o, d, 0.0f, INFINITY, &hit) && !hit.backface) {
                float y[3] = {o[0] + d[0] * hit.t, o[1] + d[1] * hit.t, o[2] + d[2] * hit.t};
                s = lc_surfel_hash_nearest(&j->hash, j->surfels, y, hit.ng, d);
            }
            rc->hits[p * n + k] = s;
        }
    }
}

/* --- 3. support ------------------------------------------------------------------------------ */

/* The nearest `want` probes to p, nearest first (insertion into a short sorted list). */
static uint32_t pb_nearest(const pb_job *j, const float p[3], uint32_t want, uint32_t *idx, float *d2) {
    uint32_t n = 0;
    for (uint32_t i = 0; i < j->n_probes; i++) {
        float e = pb_dist2(p, j->probes[i].position);
        if (n == want && e >= d2[n - 1]) continue;
        uint32_t at = n < want ? n++ : n - 1;
        while (at > 0 && d2[at - 1] > e) {
            d2[at] = d2[at - 1];
            idx[at] = idx[at - 1];
            at--;
        }
        d2[at] = e;
        idx[at] = i;
    }
    return n;
}

/* The support radius: the mean distance from (a sample of) the texel caches to their
 * overlaps-th nearest probe. */
static float pb_support_radius(const pb_job *j) {
    uint32_t want = j->prm->overlaps < j->n_probes ? j->prm->overlaps : j->n_probes;
    uint32_t idx[LC_LCB_PROBE_MAX_RANK];
    float d2[LC_LCB_PROBE_MAX_RANK];
    uint32_t step = j->n_texel > 4096 ? j->n_texel / 4096 : 1, seen = 0;
    double sum = 0;
    uint32_t used = 0;
    for (uint32_t c = 0; c < j->n_caches; c++) {
        if (!(j->caches[c].flags & LC_CACHE_TEXEL) || seen++ % step) continue;
        uint32_t got = pb_nearest(j, j->caches[c].position, want, idx, d2);
        sum += sqrt(d2[got - 1]);
        used++;
    }
    return used ? (float)(sum / used) : 1.0f;
}

/* --- 4. transport ------------------------------------------------------------------------- */

/* A receiver ray's hit: where, its surface's normal (facing the receiver), the weights of the
 * rows it feeds, and which candidate probes see it. */
typedef struct {
    float y[3], ng[3], dir[3];
    float out_w[PB_GRID_ROWS];
    uint64_t seen;   /* bit i: candidate i sees y */
    uint32_t surfel; /* an unseen ray's surfel (pb_transport_one), else LC_NONE */
} pb_hit;

/* Whether the probe at pp sees hit y (in front of its surface, nothing between). */
static int pb_sees(const pb_job *j, const float pp[3], const pb_hit *h, uint64_t *rays) {
    float to[3] = {pp[0] - h->y[0], pp[1] - h->y[1], pp[2] - h->y[2]};
    float dist = sqrtf(to[0] * to[0] + to[1] * to[1] + to[2] * to[2]);
    float pm = fmaxf(fabsf(h->y[0]), fmaxf(fabsf(h->y[1]), fabsf(h->y[2]))), lift = lc_ray_lift_point(pm);
    if (!j->prm->visibility) return dist > lift;
    if (dist <= lift || to[0] * h->ng[0] + to[1] * h->ng[1] + to[2] * h->ng[2] <= 0) return 0; /* behind y */
    float org[3] = {h->y[0] + h->ng[0] * lift, h->y[1] + h->ng[1] * lift, h->y[2] + h->ng[2] * lift};
    float d[3] = {to[0] / dist, to[1] / dist, to[2] / dist};
    (*rays)++;
    return !lc_rt_occluded(j->rt, org, d, 0.0f, dist - lift);
}

/* The receiver's rays (cosine-weighted hemisphere for a texel cache, the sphere for a grid
 * cache) and the front faces they hit, with each hit's row weights. Returns the hits. */
static uint32_t pb_trace(const pb_job *j, const lc_lcb_cache *c, pb_hit *hits, uint64_t *rays) {
    const uint32_t m = j->prm->receiver_rays;
    const int texel = (c->flags & LC_CACHE_TEXEL) != 0;
    lc_vec3 n = lc_v3_load(c->normal), t = lc_v3(1, 0, 0), b = lc_v3(0, 1, 0), org = lc_v3_load(c->position);
    if (texel) {
        n = lc_v3_norm(n);
        lc_v3_basis(n, &t, &b);
        float pm = fmaxf(fabsf(org.x), fmaxf(fabsf(org.y), fabsf(org.z)));
        org = lc_v3_add(org, lc_v3_scale(n, lc_ray_lift_point(pm)));
    }
    float o3[3];
    lc_v3_store(o3, org);
    lc_rng rng = lc_rng_seed(j->prm->seed ^ 0x5052424Full, (uint64_t)(c - j->caches));
    float rot = lc_rng_float(&rng);
    uint32_t n_hits = 0;
    for (uint32_t k = 0; k < m; k++) {
        float u = ((float)k + 0.5f) / (float)m, phi = 2.0f * (float)M_PI * ((float)k * 0.6180339887f + rot);
        float z = texel ? sqrtf(1.0f - u) : 1.0f - 2.0f * u;
        float s = sqrtf(fmaxf(0.0f, 1.0f - z * z)), x = s * cosf(phi), y = s * sinf(phi);
        float d[3];
        lc_v3_store(
            d, texel ? lc_v3_add(lc_v3_add(lc_v3_scale(t, x), lc_v3_scale(b, y)), lc_v3_scale(n, z)) : lc_v3(x, y, z));
        lc_hit hit;
        (*rays)++;
        if (!lc_rt_intersect(j->rt, o3, d, 0.0f, INFINITY, &hit) || hit.backface) continue;
        pb_hit *h = &hits[n_hits++];
        for (int a = 0; a < 3; a++) h->y[a] = o3[a] + d[a] * hit.t, h->ng[a] = hit.ng[a], h->dir[a] = d[a];
        h->seen = 0;
        h->surfel = LC_NONE;
        if (texel) {
            h->out_w[0] = (float)M_PI / (float)m; /* cosine-weighted: E = pi/m sum L */
        } else {                                  /* E_lm = A_l L_lm, L_lm = 4 pi/m sum L y_lm(d) */
            float yd[9];
            lc_sh_eval_fast(3, d[0], d[1], d[2], yd);
            for (int o = 0; o < PB_GRID_ROWS; o++)
                h->out_w[o] = (float)(4.0 * M_PI / m * lc_sh_cosine_factor(o == 0 ? 0 : o < 4 ? 1 : 2)) * yd[o];
        }
    }
    return n_hits;
}

/* The support among the candidates (nearest first, d2 their squared distances): those within
 * the radius that see any hit (the thesis's support, less the useless), then, while there is
 * room, the candidate that sees the most hits no chosen probe sees (a probe further away may
 * be the only one to see under a table), at least PB_MIN_SUPPORT. Writes the chosen candidates'
 * indices (into the candidate list) to pick; returns how many. */
static uint32_t pb_choose(const pb_job *j, const pb_hit *hits, uint32_t n_hits, const float *d2, uint32_t n_cand,
                          uint32_t *pick) {
    uint32_t n = 0, want = j->prm->overlaps < n_cand ? j->prm->overlaps : n_cand;
    uint64_t chosen = 0, covered_any = 0;
    for (uint32_t h = 0; h < n_hits; h++) covered_any |= hits[h].seen;
    for (uint32_t i = 0; i < n_cand && n < want; i++)
        if (d2[i] < j->radius * j->radius && (covered_any >> i & 1)) pick[n++] = i, chosen |= 1ull << i;
    while (n < want) {
        uint32_t best = LC_NONE, best_new = 0;
        for (uint32_t i = 0; i < n_cand; i++) {
            if (chosen >> i & 1) continue;
            uint32_t fresh = 0;
            for (uint32_t h = 0; h < n_hits; h++) fresh += (hits[h].seen >> i & 1) && !(hits[h].seen & chosen);
            if (fresh > best_new) best = i, best_new = fresh;
        }
        if (best == LC_NONE) break;
        pick[n++] = best, chosen |= 1ull << best;
    }
    uint32_t at_least = PB_MIN_SUPPORT < n_cand ? PB_MIN_SUPPORT : n_cand;
    if (at_least > j->prm->overlaps) at_least = j->prm->overlaps; /* the row holds overlaps probes */
    for (uint32_t i = 0; i < n_cand && n < at_least; i++)
        if (!(chosen >> i & 1)) pick[n++] = i, chosen |= 1ull << i;
    return n;
}

/* One receiver: its hits, the candidates' visibility, its support and weights, then each
 * hit shared by the chosen probes that see it (the thesis's K_ij, with the cosine); an
 * unseen hit gets its surfel when prm->unseen asks for its kind. Returns the hits. */
static uint32_t pb_transport_one(pb_job *j, uint32_t ri, pb_hit *hits) {
    pb_recv *r = &j->recv[ri];
    const lc_lcb_cache *c = &j->caches[r->cache];
    uint32_t cand[PB_MAX_CANDIDATES], pick[PB_MAX_CANDIDATES];
    float d2[PB_MAX_CANDIDATES];
    uint32_t want = 2 * j->prm->overlaps < PB_MAX_CANDIDATES ? 2 * j->prm->overlaps : PB_MAX_CANDIDATES;
    uint32_t n_cand = pb_nearest(j, c->position, want, cand, d2);
    uint32_t n_hits = pb_trace(j, c, hits, &j->ray_count[ri]);
    for (uint32_t h = 0; h < n_hits; h++)
        for (uint32_t i = 0; i < n_cand; i++)
            if (pb_sees(j, j->probes[cand[i]].position, &hits[h], &j->ray_count[ri])) hits[h].seen |= 1ull << i;
    uint32_t n_sup = pb_choose(j, hits, n_hits, d2, n_cand, pick);
    const int gather_unseen =
        j->prm->unseen == LC_PROBE_UNSEEN_ALL || (j->prm->unseen == LC_PROBE_UNSEEN_GRID && r->n_rows != 1);
    uint32_t *sup = j->sup + (size_t)ri * j->prm->overlaps;
    float w[PB_MAX_CANDIDATES], rx = j->radius;
    for (uint32_t i = 0; i < n_sup; i++) rx = fmaxf(rx, 1.25f * sqrtf(d2[pick[i]]));
    for (uint32_t i = 0; i < n_sup; i++) {
        sup[i] = cand[pick[i]];
        w[i] = pb_kernel(sqrtf(d2[pick[i]]) / rx);
    }
    r->n_sup = n_sup;
    float *vals = j->vals + (size_t)r->first_row * j->row_stride, ysh[LC_SH_MAX_COEFFS];
    const uint32_t nc = j->coeffs;
    for (uint32_t h = 0; h < n_hits; h++) {
        float wsum = 0;
        for (uint32_t i = 0; i < n_sup; i++) wsum += (hits[h].seen >> pick[i] & 1) ? w[i] : 0;
        if (wsum <= 0) {
            j->orphans[ri]++;
            if (gather_unseen)
                hits[h].surfel = lc_surfel_hash_nearest(&j->hash, j->surfels, hits[h].y, hits[h].ng, hits[h].dir);
            continue;
        }
        for (uint32_t i = 0; i < n_sup; i++) {
            if (!(hits[h].seen >> pick[i] & 1) || w[i] <= 0) continue;
            const float *pp = j->probes[sup[i]].position;
            float psi[3] = {hits[h].y[0] - pp[0], hits[h].y[1] - pp[1], hits[h].y[2] - pp[2]}; /* probe -> y */
            float len = sqrtf(psi[0] * psi[0] + psi[1] * psi[1] + psi[2] * psi[2]);
            for (int k = 0; k < 3; k++) psi[k] /= len;
            pb_sh_eval((int)j->prm->sh_bands, psi, ysh);
            float share = w[i] / wsum;
            for (uint32_t o = 0; o < r->n_rows; o++) {
                float f = share * hits[h].out_w[o];
                if (f == 0) continue;
                float *dst = vals + o * j->row_stride + (size_t)i * nc;
                for (uint32_t k = 0; k < nc; k++) dst[k] += f * ysh[k];
            }
        }
    }
    return n_hits;
}

/* (surfel, hit) pairs of unseen rays, by surfel then hit: the sums run in one order. */
static int pb_pair_cmp(const void *a, const void *b) {
    const uint32_t *x = a, *y = b;
    if (x[0] != y[0]) return x[0] < y[0] ? -1 : 1;
    return (x[1] > y[1]) - (x[1] < y[1]);
}

/* The receiver's unseen rays (pb_transport_one marked their surfels), summed per surfel into
 * each row's weights: the ray's share of the row over pi (the surfel's radiance is B / pi).
 * pairs: receiver_rays x 2 scratch. */
static void pb_unseen_gather(pb_job *j, uint32_t ri, const pb_hit *hits, uint32_t n_hits, uint32_t *pairs) {
    const pb_recv *r = &j->recv[ri];
    uint32_t n = 0;
    for (uint32_t h = 0; h < n_hits; h++)
        if (hits[h].surfel != LC_NONE) pairs[2 * n] = hits[h].surfel, pairs[2 * n + 1] = h, n++;
    if (!n) return;
    qsort(pairs, n, 2 * sizeof *pairs, pb_pair_cmp);
    uint32_t n_surf = 0;
    for (uint32_t i = 0; i < n; i++) n_surf += i == 0 || pairs[2 * i] != pairs[2 * i - 2];
    lc_lcb_probe_unseen *e = calloc((size_t)n_surf * r->n_rows, sizeof *e);
    if (!e) {
        j->unseen[ri].n_surfels = UINT32_MAX;
        return;
    }
    for (uint32_t i = 0, s = 0; i < n; i++) {
        if (i > 0 && pairs[2 * i] != pairs[2 * i - 2]) s++;
        const pb_hit *h = &hits[pairs[2 * i + 1]];
        for (uint32_t o = 0; o < r->n_rows; o++) {
            e[(size_t)o * n_surf + s].surfel = pairs[2 * i];
            e[(size_t)o * n_surf + s].weight += h->out_w[o] * (float)M_1_PI;
        }
    }
    j->unseen[ri] = (pb_unseen){e, n_surf};
}

static void pb_transport_range(void *ctx, size_t begin, size_t end, int thread) {
    pb_job *j = ctx;
    pb_hit *hits = (pb_hit *)j->hit_scratch + (size_t)thread * j->prm->receiver_rays;
    uint32_t *pairs = j->pair_scratch + (size_t)thread * j->prm->receiver_rays * 2;
    for (size_t i = begin; i < end; i++) {
        uint32_t n_hits = pb_transport_one(j, (uint32_t)i, hits);
        if (j->prm->unseen) pb_unseen_gather(j, (uint32_t)i, hits, n_hits, pairs);
    }
    lc_progress_add(j->progress, end - begin);
}

/* Receivers and rows: every cache with a place to gather from (not inside geometry). */
static int pb_receivers(pb_job *j) {
    uint32_t n_recv = 0, n_rows = 0;
    for (uint32_t c = 0; c < j->n_caches; c++) {
        if (j->caches[c].flags & LC_CACHE_INSIDE) continue;
        n_recv++;
        n_rows += (j->caches[c].flags & LC_CACHE_TEXEL) ? 1 : PB_GRID_ROWS;
    }
    const size_t ov = j->prm->overlaps;
    j->row_stride = ov * j->coeffs;
    j->recv = calloc(n_recv ? n_recv : 1, sizeof *j->recv);
    j->sup = calloc(n_recv * ov + 1, sizeof *j->sup);
    j->sup_w = calloc(n_recv * ov + 1, sizeof *j->sup_w);
    j->rows = calloc(n_rows ? n_rows : 1, sizeof *j->rows);
    j->vals = calloc((size_t)n_rows * j->row_stride + 1, sizeof *j->vals);
    j->ray_count = calloc(n_recv + 1, sizeof *j->ray_count);
    j->orphans = calloc(n_recv + 1, sizeof *j->orphans);
    j->unseen = calloc(n_recv + 1, sizeof *j->unseen);
    if (!j->recv || !j->sup || !j->sup_w || !j->rows || !j->vals || !j->ray_count || !j->orphans || !j->unseen)
        return -1;
    j->n_recv = n_recv;
    for (uint32_t c = 0, ri = 0, row = 0; c < j->n_caches; c++) {
        const lc_lcb_cache *cc = &j->caches[c];
        if (cc->flags & LC_CACHE_INSIDE) continue;
        pb_recv *r = &j->recv[ri];
        r->cache = c;
        r->first_row = row;
        r->n_rows = (cc->flags & LC_CACHE_TEXEL) ? 1 : PB_GRID_ROWS;
        for (uint32_t k = 0; k < r->n_rows; k++, row++) {
            pb_row *pr = &j->rows[row];
            pr->recv = ri;
            pr->coeff = k;
            pr->group = (cc->flags & LC_CACHE_TEXEL) ? 0 : 1 + k;
            memcpy(pr->pos, cc->position, sizeof pr->pos);
        }
        ri++;
    }
    j->n_rows = n_rows;
    return (int)n_recv;
}

/* --- 5. compression ---------------------------------------------------------------------- */

/* A cluster being compressed: rows [lo, hi) of the order array. */
typedef struct {
    uint32_t lo, hi;
    int ok;          /* compressed within the error (or cannot split) */
    uint32_t rank;   /* kept */
    double error;    /* relative Frobenius */
    uint32_t *probe; /* its probes, sorted */
    uint32_t n_probe;
    float *basis; /* rank x n_probe*coeffs */
    float *u;     /* (hi - lo) x rank */
} pb_cluster;

typedef struct {
    pb_job *j;
    const uint32_t *order; /* rows, grouped, each cluster contiguous */
    pb_cluster *cl;
} pb_compress_ctx;

static int pb_u32_cmp(const void *a, const void *b) {
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* The dot product of two rows over the probes they share. */
static double pb_row_dot(const pb_job *j, const pb_row *a, const pb_row *b) {
    const pb_recv *ra = &j->recv[a->recv], *rb = &j->recv[b->recv];
    const uint32_t *sa = j->sup + (size_t)a->recv * j->prm->overlaps, *sb = j->sup + (size_t)b->recv * j->prm->overlaps;
    const float *va = j->vals + (size_t)(ra->first_row + a->coeff) * j->row_stride;
    const float *vb = j->vals + (size_t)(rb->first_row + b->coeff) * j->row_stride;
    double s = 0;
    for (uint32_t x = 0; x < ra->n_sup; x++)
        for (uint32_t y = 0; y < rb->n_sup; y++) {
            if (sa[x] != sb[y]) continue;
            const float *p = va + (size_t)x * j->coeffs, *q = vb + (size_t)y * j->coeffs;
            for (uint32_t c = 0; c < j->coeffs; c++) s += j->band_w2[c] * p[c] * q[c];
        }
    return s;
}

/* Truncated SVD of one cluster through the eigenvectors of its Gram matrix: U = the top
 * eigenvectors, S V^T = U^T A, and the error from the dropped eigenvalues (= s_i^2). The Gram
 * matrix weighs band l's columns by (l + 1)^-band_weight, so rank goes where the light is
 * (and not to the rows' Monte Carlo noise in the high bands); the basis stored is U^T A
 * unweighted, the exact projection. */
static int pb_compress_one(pb_job *j, const uint32_t *order, pb_cluster *cl) {
    const uint32_t n = cl->hi - cl->lo, nc = j->coeffs, ov = j->prm->overlaps;
    const uint32_t want = n < j->prm->max_rank ? n : j->prm->max_rank;
    double *g = malloc((size_t)n * n * sizeof *g), *w = malloc((size_t)n * sizeof *w);
    double *z = malloc((size_t)n * want * sizeof *z);
    lapack_int *isuppz = malloc(2 * (size_t)want * sizeof *isuppz);
    cl->probe = malloc((size_t)n * ov * sizeof *cl->probe);
    int rc = -1;
    if (!g || !w || !z || !isuppz || !cl->probe) goto out;
    double trace = 0;
    for (uint32_t a = 0; a < n; a++) {
        const pb_row *ra = &j->rows[order[cl->lo + a]];
        for (uint32_t b = a; b < n; b++) g[(size_t)a * n + b] = pb_row_dot(j, ra, &j->rows[order[cl->lo + b]]);
        trace += g[(size_t)a * n + a];
    }
    lapack_int found = 0;
    if (trace > 0 &&
        LAPACKE_dsyevr(LAPACK_ROW_MAJOR, 'V', 'I', 'U', (lapack_int)n, g, (lapack_int)n, 0, 0,
                       (lapack_int)(n - want + 1), (lapack_int)n, 0.0, &found, w, z, (lapack_int)want, isuppz) != 0)
        goto out;
    /* eigenvalues ascending: the largest is w[found-1], its vector column found-1 */
    double kept = 0;
    cl->rank = 1;
    cl->error = trace > 0 ? 1.0 : 0.0;
    for (uint32_t s = 1; s <= (uint32_t)found; s++) {
        kept += fmax(0.0, w[found - s]);
        cl->rank = s;
        cl->error = sqrt(fmax(0.0, trace - kept) / trace);
        if (cl->error <= j->prm->svd_error) break;
    }
    cl->ok = cl->error <= j->prm->svd_error || n <= j->prm->max_rank;
    /* the cluster's probes, and each row's columns among them */
    uint32_t np = 0;
    for (uint32_t a = 0; a < n; a++) {
        const pb_row *ra = &j->rows[order[cl->lo + a]];
        memcpy(cl->probe + np, j->sup + (size_t)ra->recv * ov, j->recv[ra->recv].n_sup * sizeof *cl->probe);
        np += j->recv[ra->recv].n_sup;
    }
    qsort(cl->probe, np, sizeof *cl->probe, pb_u32_cmp);
    uint32_t uniq = 0;
    for (uint32_t i = 0; i < np; i++)
        if (!uniq || cl->probe[uniq - 1] != cl->probe[i]) cl->probe[uniq++] = cl->probe[i];
    cl->n_probe = uniq;
    const uint32_t rank = cl->rank, cols = uniq * nc;
    cl->u = calloc((size_t)n * rank, sizeof *cl->u);
    cl->basis = calloc((size_t)rank * cols, sizeof *cl->basis);
    if (!cl->u || !cl->basis) goto out;
    for (uint32_t a = 0; a < n && trace > 0; a++)
        for (uint32_t s = 0; s < rank; s++) cl->u[(size_t)a * rank + s] = (float)z[(size_t)a * want + (found - 1 - s)];
    for (uint32_t a = 0; a < n; a++) { /* S V^T = U^T A, row by row */
        const pb_row *ra = &j->rows[order[cl->lo + a]];
        const pb_recv *rr = &j->recv[ra->recv];
        const uint32_t *sup = j->sup + (size_t)ra->recv * ov;
        const float *va = j->vals + (size_t)(rr->first_row + ra->coeff) * j->row_stride;
        for (uint32_t x = 0; x < rr->n_sup; x++) {
            uint32_t col =
                (uint32_t)((uint32_t *)bsearch(&sup[x], cl->probe, uniq, sizeof *cl->probe, pb_u32_cmp) - cl->probe) *
                nc;
            for (uint32_t s = 0; s < rank; s++) {
                float uas = cl->u[(size_t)a * rank + s];
                float *dst = cl->basis + (size_t)s * cols + col;
                for (uint32_t c = 0; c < nc; c++) dst[c] += uas * va[(size_t)x * nc + c];
            }
        }
    }
    rc = 0;
out:
    free(g);
    free(w);
    free(z);
    free(isuppz);
    return rc;
}

static void pb_cluster_free(pb_cluster *cl) {
    free(cl->probe);
    free(cl->basis);
    free(cl->u);
    cl->probe = NULL, cl->basis = NULL, cl->u = NULL;
}

static void pb_compress_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    pb_compress_ctx *cc = ctx;
    for (size_t i = begin; i < end; i++) {
        pb_cluster *cl = &cc->cl[i];
        if (cl->ok) continue;                                         /* accepted in an earlier round */
        if (pb_compress_one(cc->j, cc->order, cl) != 0) cl->rank = 0; /* out of memory: reported by the caller */
        lc_progress_add(cc->j->progress, cl->hi - cl->lo);
    }
}

/* The split of rows [lo, hi) of `order`: the midpoint of the widest axis of their bounding
 * box, or the median when that leaves a side empty. Returns the first row of the upper half. */
static uint32_t pb_split(const pb_job *j, uint32_t *order, uint32_t lo, uint32_t hi) {
    float mn[3] = {INFINITY, INFINITY, INFINITY}, mx[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = lo; i < hi; i++)
        for (int k = 0; k < 3; k++) {
            mn[k] = fminf(mn[k], j->rows[order[i]].pos[k]);
            mx[k] = fmaxf(mx[k], j->rows[order[i]].pos[k]);
        }
    int axis = 0;
    for (int k = 1; k < 3; k++)
        if (mx[k] - mn[k] > mx[axis] - mn[axis]) axis = k;
    float mid = 0.5f * (mn[axis] + mx[axis]);
    uint32_t a = lo, b = hi; /* stable-enough partition: order only matters for determinism */
    while (a < b) {
        if (j->rows[order[a]].pos[axis] < mid) a++;
        else {
            uint32_t t = order[a];
            order[a] = order[--b];
            order[b] = t;
        }
    }
    if (a == lo || a == hi) a = lo + (hi - lo) / 2; /* all at one point */
    return a;
}

/* Splits, in place, every cluster not accepted (oversized_only: only those over
 * cluster_rows, which need no SVD to know). From the back, so the halves stay in row order.
 * Returns how many split, or -1 out of memory. */
static int pb_split_clusters(const pb_job *j, uint32_t *order, pb_cluster **clp, uint32_t *n, uint32_t *cap,
                             int oversized_only) {
    uint32_t more = 0;
    for (uint32_t i = 0; i < *n; i++)
        more += !(*clp)[i].ok && (!oversized_only || (*clp)[i].hi - (*clp)[i].lo > j->prm->cluster_rows);
    if (*n + more > *cap) {
        uint32_t ncap = 2 * (*n + more);
        pb_cluster *g = realloc(*clp, ncap * sizeof *g);
        if (!g) return -1;
        memset(g + *cap, 0, (ncap - *cap) * sizeof *g);
        *clp = g, *cap = ncap;
    }
    pb_cluster *cl = *clp;
    for (uint32_t i = *n; i-- > 0;) {
        if (cl[i].ok || (oversized_only && cl[i].hi - cl[i].lo <= j->prm->cluster_rows)) continue;
        uint32_t lo = cl[i].lo, hi = cl[i].hi, mid = pb_split(j, order, lo, hi);
        pb_cluster_free(&cl[i]);
        memmove(cl + i + 2, cl + i + 1, (*n - i - 1) * sizeof *cl);
        cl[i] = (pb_cluster){.lo = lo, .hi = mid};
        cl[i + 1] = (pb_cluster){.lo = mid, .hi = hi};
        (*n)++;
    }
    return (int)more;
}

/* Rounds: the clusters not yet accepted are halved down to cluster_rows, compressed (in
 * parallel), and the ones over the error split for the next round. Clusters stay in row
 * order, so the result does not depend on the schedule. *out_n clusters, owned by the caller. */
static pb_cluster *pb_compress(pb_job *j, uint32_t *order, uint32_t *out_n, char *err, size_t errlen) {
    uint32_t cap = 64, n = 0;
    pb_cluster *cl = calloc(cap, sizeof *cl);
    if (!cl) goto oom;
    for (uint32_t lo = 0; lo < j->n_rows;) { /* the first cut: each group alone */
        uint32_t hi = lo;
        while (hi < j->n_rows && j->rows[order[hi]].group == j->rows[order[lo]].group) hi++;
        if (n == cap) {
            pb_cluster *g = realloc(cl, 2 * cap * sizeof *cl);
            if (!g) goto oom;
            memset(g + cap, 0, cap * sizeof *g);
            cl = g, cap *= 2;
        }
        cl[n++] = (pb_cluster){.lo = lo, .hi = hi};
        lo = hi;
    }
    j->progress = lc_progress_begin("probes: compress", j->n_rows);
    for (;;) {
        int got;
        while ((got = pb_split_clusters(j, order, &cl, &n, &cap, 1)) > 0) {
        }
        if (got < 0) goto oom;
        pb_compress_ctx cc = {j, order, cl};
        lc_parallel_for(j->prm->threads, n, 1, pb_compress_range, &cc);
        uint32_t failed = 0;
        for (uint32_t i = 0; i < n; i++) {
            if (!cl[i].ok && cl[i].rank == 0) {
                lc_set_err(err, errlen, "probes: out of memory (or LAPACK failed) compressing a cluster of %u rows",
                           cl[i].hi - cl[i].lo);
                goto fail;
            }
            failed += !cl[i].ok;
        }
        if (!failed) break;
        if (pb_split_clusters(j, order, &cl, &n, &cap, 0) < 0) goto oom;
    }
    lc_progress_end(j->progress);
    j->progress = NULL;
    *out_n = n;
    return cl;
oom:
    lc_set_err(err, errlen, "probes: out of memory compressing");
fail:
    lc_progress_end(j->progress);
    j->progress = NULL;
    for (uint32_t i = 0; cl && i < n; i++) pb_cluster_free(&cl[i]);
    free(cl);
    return NULL;
}

/* Groups first (texel rows, then the grid's coefficient 0..8), each in cache order. */
static int pb_order_cmp(const void *a, const void *b, void *ctx) {
    const pb_row *rows = ctx;
    const pb_row *x = &rows[*(const uint32_t *)a], *y = &rows[*(const uint32_t *)b];
    if (x->group != y->group) return x->group < y->group ? -1 : 1;
    return (*(const uint32_t *)a > *(const uint32_t *)b) - (*(const uint32_t *)a < *(const uint32_t *)b);
}

/* PRUF/PRUS in the file's row order: each row's entries from its receiver's unseen rays. */
static int pb_assemble_unseen(const pb_job *j, const uint32_t *order, lc_probebake *out) {
    uint64_t n = 0;
    for (uint32_t r = 0; r < j->n_rows; r++) n += j->unseen[j->rows[order[r]].recv].n_surfels;
    if (n > UINT32_MAX) return -1; /* PRUF's offsets are 32-bit */
    out->unseen_first = malloc(((size_t)j->n_rows + 1) * sizeof *out->unseen_first);
    out->unseen = malloc((n + 1) * sizeof *out->unseen);
    if (!out->unseen_first || !out->unseen) return -1;
    uint32_t at = 0;
    for (uint32_t r = 0; r < j->n_rows; r++) {
        const pb_row *pr = &j->rows[order[r]];
        const pb_unseen *u = &j->unseen[pr->recv];
        out->unseen_first[r] = at;
        if (u->n_surfels)
            memcpy(out->unseen + at, u->e + (size_t)pr->coeff * u->n_surfels, u->n_surfels * sizeof *u->e);
        at += u->n_surfels;
    }
    out->unseen_first[j->n_rows] = at;
    out->n_unseen = at;
    return 0;
}

/* The file's arrays from the accepted clusters. */
static int pb_assemble(pb_job *j, const uint32_t *order, pb_cluster *cl, uint32_t n_cl, lc_probebake *out) {
    uint64_t n_cp = 0, n_basis = 0, n_u = 0;
    uint32_t max_rank = 1;
    double rank_sum = 0, worst = 0;
    for (uint32_t i = 0; i < n_cl; i++) {
        n_cp += cl[i].n_probe;
        n_basis += (uint64_t)cl[i].rank * cl[i].n_probe * j->coeffs;
        n_u += (uint64_t)(cl[i].hi - cl[i].lo) * cl[i].rank;
        if (cl[i].rank > max_rank) max_rank = cl[i].rank;
        rank_sum += cl[i].rank;
        if (cl[i].error > worst) worst = cl[i].error;
    }
    out->clusters = calloc(n_cl ? n_cl : 1, sizeof *out->clusters);
    out->cluster_probes = malloc((n_cp + 1) * sizeof *out->cluster_probes);
    out->basis = malloc((n_basis + 1) * sizeof *out->basis);
    out->u = malloc((n_u + 1) * sizeof *out->u);
    out->rows = calloc((size_t)j->n_rows + 1, sizeof *out->rows);
    if (!out->clusters || !out->cluster_probes || !out->basis || !out->u || !out->rows) return -1;
    uint64_t at_p = 0, at_b = 0, at_u = 0;
    for (uint32_t i = 0; i < n_cl; i++) {
        const pb_cluster *c = &cl[i];
        const uint32_t rows = c->hi - c->lo;
        lc_lcb_probe_cluster *pc = &out->clusters[i];
        *pc = (lc_lcb_probe_cluster){.first_row = c->lo,
                                     .n_rows = rows,
                                     .first_probe = (uint32_t)at_p,
                                     .n_probes = c->n_probe,
                                     .rank = c->rank,
                                     .basis_offset = at_b,
                                     .u_offset = at_u};
        memcpy(out->cluster_probes + at_p, c->probe, c->n_probe * sizeof *c->probe);
        size_t nb = (size_t)c->rank * c->n_probe * j->coeffs, nu = (size_t)rows * c->rank;
        memcpy(out->basis + at_b, c->basis, nb * sizeof *c->basis);
        memcpy(out->u + at_u, c->u, nu * sizeof *c->u);
        at_p += c->n_probe, at_b += nb, at_u += nu;
        for (uint32_t r = c->lo; r < c->hi; r++) {
            const pb_row *pr = &j->rows[order[r]];
            out->rows[r] = (lc_lcb_probe_row){.cache = j->recv[pr->recv].cache, .coeff = pr->coeff};
        }
    }
    if (j->prm->unseen && pb_assemble_unseen(j, order, out) != 0) return -1;
    out->n_cluster_probes = n_cp, out->n_basis = n_basis, out->n_u = n_u;
    out->header.n_clusters = n_cl;
    out->header.n_rows = j->n_rows;
    out->header.max_rank = max_rank;
    out->mean_rank = n_cl ? rank_sum / n_cl : 0;
    out->worst_error = worst;
    return 0;
}

static int pb_check_params(const lc_probebake_params *p, char *err, size_t errlen) {
    if (p->count > PB_MAX_PROBES || (!p->count && !(p->density > 0)))
        lc_set_err(err, errlen, "probes: --probes must be 0..%d (0 with a positive --probe-density)", PB_MAX_PROBES);
    else if (p->relight_rays < 1 || p->relight_rays > 65536)
        lc_set_err(err, errlen, "probes: --probe-relight-rays must be 1..65536");
    else if (p->sh_bands < 1 || p->sh_bands > LC_LCB_PROBE_MAX_BANDS)
        lc_set_err(err, errlen, "probes: --probe-bands must be 1..%d", LC_LCB_PROBE_MAX_BANDS);
    else if (p->overlaps < 1 || p->overlaps > 64) lc_set_err(err, errlen, "probes: --probe-overlaps must be 1..64");
    else if (p->receiver_rays < 1) lc_set_err(err, errlen, "probes: --probe-receiver-rays must be >= 1");
    else if (p->max_rank < 1 || p->max_rank > LC_LCB_PROBE_MAX_RANK)
        lc_set_err(err, errlen, "probes: --probe-rank must be 1..%d", LC_LCB_PROBE_MAX_RANK);
    else if (p->cluster_rows < p->max_rank || p->cluster_rows > 8192)
        lc_set_err(err, errlen, "probes: --probe-cluster must be --probe-rank..8192");
    else if (!(p->svd_error >= 0 && p->svd_error < 1))
        lc_set_err(err, errlen, "probes: --probe-svd-error must be in [0, 1)");
    else return 0;
    return -1;
}

static void pb_job_release(pb_job *j) {
    lc_surfel_hash_free(&j->hash);
    free(j->cand);
    free(j->cand_ok);
    free(j->probes);
    free(j->recv);
    free(j->sup);
    free(j->sup_w);
    free(j->vals);
    free(j->rows);
    free(j->ray_count);
    free(j->orphans);
    for (uint32_t i = 0; j->unseen && i < j->n_recv; i++) free(j->unseen[i].e);
    free(j->unseen);
    free(j->hit_scratch);
    free(j->pair_scratch);
}

/* Stages 4-5 and their statistics, after placement and the relight rays. */
static int pb_transport_and_compress(pb_job *j, lc_probebake *out, double *t0, char *err, size_t errlen) {
    int n_recv = pb_receivers(j);
    if (n_recv < 0) goto oom;
    const size_t n_threads = (size_t)lc_parallel_threads(j->prm->threads);
    j->hit_scratch = malloc(n_threads * j->prm->receiver_rays * sizeof(pb_hit));
    j->pair_scratch = malloc(n_threads * j->prm->receiver_rays * 2 * sizeof *j->pair_scratch);
    if (!j->hit_scratch || !j->pair_scratch) goto oom;
    j->progress = lc_progress_begin("probes: transport", (uint64_t)n_recv);
    lc_parallel_for(j->prm->threads, (size_t)n_recv, 4, pb_transport_range, j);
    lc_progress_end(j->progress);
    j->progress = NULL;
    uint64_t rays = 0, orphans[2] = {0, 0}, n_kind[2] = {0, 0}, sup = 0;
    for (int i = 0; i < n_recv; i++) {
        if (j->unseen[i].n_surfels == UINT32_MAX) goto oom;
        int grid = j->recv[i].n_rows != 1;
        rays += j->ray_count[i], orphans[grid] += j->orphans[i], n_kind[grid]++;
        sup += j->recv[i].n_sup;
    }
    out->rays += rays;
    for (int k = 0; k < 2; k++)
        out->orphan_fraction[k] = n_kind[k] ? (double)orphans[k] / ((double)n_kind[k] * j->prm->receiver_rays) : 0;
    out->mean_probes_used = n_recv ? (double)sup / n_recv : 0;
    double t = lc_clock_ms() * 1e-3;
    out->seconds[2] = t - *t0, *t0 = t;
    uint32_t *order = malloc(((size_t)j->n_rows + 1) * sizeof *order);
    if (!order) goto oom;
    for (uint32_t i = 0; i < j->n_rows; i++) order[i] = i;
    qsort_r(order, j->n_rows, sizeof *order, pb_order_cmp, j->rows);
    uint32_t n_cl = 0;
    pb_cluster *cl = j->n_rows ? pb_compress(j, order, &n_cl, err, errlen) : NULL;
    if (j->n_rows && !cl) {
        free(order);
        return -1;
    }
    int rc = pb_assemble(j, order, cl, n_cl, out);
    for (uint32_t i = 0; i < n_cl; i++) pb_cluster_free(&cl[i]);
    free(cl);
    free(order);
    if (rc != 0) goto oom;
    out->seconds[3] = lc_clock_ms() * 1e-3 - *t0;
    return 0;
oom:
    lc_set_err(err, errlen, "probes: out of memory (lower --probe-overlaps or --probe-bands)");
    return -1;
}

int lc_probebake_run(const lc_rt *rt, const float bmin[3], const float bmax[3], const lc_lcb_surfel *surfels,
                     uint32_t n_surfels, const lc_lcb_cache *caches, uint32_t n_caches, const lc_probebake_params *prm,
                     lc_probebake *out, char *err, size_t errlen) {
    memset(out, 0, sizeof *out);
    if (pb_check_params(prm, err, errlen) != 0) return -1;
    pb_job j = {.rt = rt,
                .surfels = surfels,
                .n_surfels = n_surfels,
                .caches = caches,
                .n_caches = n_caches,
                .prm = prm,
                .coeffs = prm->sh_bands * prm->sh_bands,
                .bmin = lc_v3_load(bmin),
                .bmax = lc_v3_load(bmax)};
    for (uint32_t c = 0; c < n_caches; c++) j.n_texel += (caches[c].flags & LC_CACHE_TEXEL) != 0;
    for (uint32_t l = 0; l < prm->sh_bands; l++) /* (l + 1)^-p: the error counted where radiance has its energy */
        for (uint32_t m = 0; m <= 2 * l; m++) j.band_w2[l * l + m] = pow(l + 1.0, -2.0 * prm->band_weight);
    double t0 = lc_clock_ms() * 1e-3;
    if (n_surfels && lc_surfel_hash_build(&j.hash, surfels, n_surfels) != 0) goto oom;
    if (pb_place(&j, err, errlen) != 0) goto fail;
    out->n_candidates = j.n_cand_grid;
    double t = lc_clock_ms() * 1e-3;
    out->seconds[0] = t - t0, t0 = t;
    out->hits = malloc(((size_t)j.n_probes * prm->relight_rays + 1) * sizeof *out->hits);
    if (!out->hits) goto oom;
    pb_relight_ctx rc = {&j, out->hits};
    lc_parallel_for(prm->threads, j.n_probes, 1, pb_relight_range, &rc);
    out->rays += (uint64_t)j.n_probes * prm->relight_rays + (uint64_t)j.n_cand_grid * PB_TEST_DIRS;
    j.radius = pb_support_radius(&j);
    t = lc_clock_ms() * 1e-3;
    out->seconds[1] = t - t0, t0 = t;
    if (pb_transport_and_compress(&j, out, &t0, err, errlen) != 0) goto fail;
    out->probes = j.probes; /* ownership moves to the result */
    j.probes = NULL;
    out->header.n_probes = j.n_probes;
    out->header.n_rays = prm->relight_rays;
    out->header.sh_bands = prm->sh_bands;
    out->header.overlaps = prm->overlaps;
    out->header.receiver_rays = prm->receiver_rays;
    out->header.support_radius = j.radius;
    out->header.svd_error = (float)prm->svd_error;
    pb_job_release(&j);
    return 0;
oom:
    lc_set_err(err, errlen, "probes: out of memory");
fail:
    pb_job_release(&j);
    lc_probebake_release(out);
    return -1;
}

void lc_probebake_release(lc_probebake *b) {
    free(b->probes);
    free(b->hits);
    free(b->clusters);
    free(b->cluster_probes);
    free(b->basis);
    free(b->rows);
    free(b->u);
    free(b->unseen_first);
    free(b->unseen);
    memset(b, 0, sizeof *b);
}

int lc_probebake_transport(const lc_rt *rt, const lc_lcb_probe *probes, uint32_t n_probes, float radius,
                           const lc_lcb_cache *cache, const lc_probebake_params *prm, float *rows, uint32_t *sup) {
    lc_probebake_params one = *prm;
    one.unseen = LC_PROBE_UNSEEN_OFF;
    char err[128];
    if (n_probes == 0 || (cache->flags & LC_CACHE_INSIDE) || pb_check_params(&one, err, sizeof err) != 0) return -1;
    pb_recv recv = {.cache = 0, .n_rows = (cache->flags & LC_CACHE_TEXEL) ? 1 : PB_GRID_ROWS};
    uint64_t ray_count = 0, orphans = 0;
    pb_job j = {.rt = rt,
                .caches = cache,
                .n_caches = 1,
                .prm = &one,
                .coeffs = one.sh_bands * one.sh_bands,
                .probes = (lc_lcb_probe *)probes, /* read only: stage 4 does not place */
                .n_probes = n_probes,
                .radius = radius,
                .recv = &recv,
                .sup = sup,
                .vals = rows,
                .row_stride = (size_t)one.overlaps * one.sh_bands * one.sh_bands,
                .ray_count = &ray_count,
                .orphans = &orphans,
                .n_recv = 1};
    pb_hit *hits = malloc(one.receiver_rays * sizeof *hits);
    if (!hits) return -1;
    memset(rows, 0, recv.n_rows * j.row_stride * sizeof *rows);
    pb_transport_one(&j, 0, hits);
    free(hits);
    return (int)recv.n_sup;
}
